"""Fixtures of the service tests: in-process apps (httpx's ASGI transport) and the live server.

``client`` is parametrised over both, so that every round trip runs in process *and* through a
real uvicorn process on 127.0.0.1 (``live_server`` in ``tests/conftest.py``).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterator
from typing import Any

import httpx
import pytest

pytest.importorskip("service.app", reason="the service extra is not installed")

from service.app import create_app
from service.settings import Settings


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(autouse=True)
def _pillow_pixel_limit() -> Iterator[None]:
    """Put back Pillow's process-wide bomb limit, which every in-process app sets from its
    settings: a small ``max_pixels`` here would refuse other tests' pictures afterwards."""
    from PIL import Image

    saved = Image.MAX_IMAGE_PIXELS
    yield
    Image.MAX_IMAGE_PIXELS = saved


def asgi_client(**settings: Any) -> httpx.AsyncClient:
    """A client of a fresh in-process app with these settings."""
    app = create_app(Settings(**settings))
    transport = httpx.ASGITransport(app=app)
    return httpx.AsyncClient(transport=transport, base_url="http://testserver", timeout=120)


@pytest.fixture(params=["asgi", "live"])
async def client(request: pytest.FixtureRequest) -> AsyncIterator[httpx.AsyncClient]:
    """The service with default settings: in process, then a real uvicorn process."""
    if request.param == "asgi":
        async with asgi_client() as c:
            yield c
    else:
        url = request.getfixturevalue("live_server")
        async with httpx.AsyncClient(base_url=url, timeout=120) as c:
            yield c


@pytest.fixture
def make_client() -> Callable[..., httpx.AsyncClient]:
    return asgi_client
