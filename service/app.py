"""The app factory: ``uvicorn --factory service.app:create_app``.

Nothing happens at import time: the settings are read, the work pool is sized and Pillow's
pixel limit is set when :func:`create_app` runs, so that tests build apps with their own limits.
The worker processes start, warm, during the app's start-up (its lifespan): a server answers
only once they are ready.

>>> app = create_app(Settings(max_upload_bytes=1000))
>>> app.state.settings.max_upload_bytes
1000
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles
from fastapi_offline import FastAPIOffline

import wavecore

from . import errors
from .imaging import set_pixel_limit
from .middleware import BodyLimitMiddleware, Metrics, MetricsMiddleware, SecurityHeadersMiddleware
from .routes import bundles, curves, docs, grids, health, images, pages, surfaces
from .settings import Settings
from .work import AdmissionMiddleware, WorkPool

STATIC = Path(__file__).resolve().parent / "static"

DESCRIPTION = """\
Wavelet compression with the local filters of quadratic B-spline wavelets (Samavati & Bartels).

Encode an image, a curve or a surface into a *bundle*; send a bundle back with `keep` and
`level` to get a reconstruction with fewer details or at a coarser resolution.

Errors are `application/problem+json` (RFC 9457); their `type` is
`urn:wavecore:problem:<kind>`.
"""


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the service with ``settings`` (default: read from ``WAVECORE_*`` variables).

    Raises :class:`~service.settings.SettingsError` (one line naming the variable) when a
    ``WAVECORE_*`` variable has a bad value.
    """
    settings = settings or Settings.from_env()
    set_pixel_limit(settings.max_pixels)
    pool = WorkPool(settings)

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        # uvicorn's own lifecycle logger, so that the lines appear beside "Waiting for
        # application startup." with uvicorn's log configuration.
        log = logging.getLogger("uvicorn.error")
        log.info("starting %d warm worker processes", settings.concurrency)
        began = time.monotonic()
        await asyncio.to_thread(pool.start)
        log.info("workers ready in %.1f s", time.monotonic() - began)
        try:
            yield
        finally:
            pool.shutdown()

    # FastAPI with /docs (Swagger UI) and /redoc whose scripts and styles are served from this
    # server (fastapi-offline ships them), so that the docs work offline and fetch nothing from
    # a CDN; the page's "API docs" link goes to /docs. /redoc is routes/docs.py's.
    app = FastAPIOffline(
        redoc_url=None,
        title="wavecore",
        version=wavecore.__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.pool = pool
    app.state.metrics = Metrics()
    errors.install(app)
    for module in (images, curves, surfaces, grids, bundles, health, pages, docs):
        app.include_router(module.router)
    if STATIC.is_dir():
        app.mount("/static", StaticFiles(directory=STATIC), name="static")
    # Added innermost first: metrics see everything; the size limit applies while admission
    # reads the whole body (within WAVECORE_BODY_TIMEOUT), and only then takes a work slot.
    app.add_middleware(AdmissionMiddleware, pool=pool)
    app.add_middleware(BodyLimitMiddleware, limit=settings.max_upload_bytes)
    app.add_middleware(MetricsMiddleware, metrics=app.state.metrics)
    app.add_middleware(SecurityHeadersMiddleware)  # outermost: on every answer, refusals too
    return app
