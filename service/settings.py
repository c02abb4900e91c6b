"""Every limit and knob of the service, in one object read from ``WAVECORE_*`` variables.

>>> Settings(max_upload_bytes=1024).max_upload_bytes
1024
"""

from __future__ import annotations

import os

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


def _default_threads() -> int:
    # The transform's compiled loops release the GIL, so one thread per core keeps every core
    # busy; more threads would only add memory (each holds a whole decoded image).
    return max(1, os.cpu_count() or 1)


class Settings(BaseSettings):
    """The service's settings; each field is read from ``WAVECORE_<FIELD NAME>``.

    The defaults let 64 concurrent clients all succeed on one process: ``threads`` requests
    are worked on at once and up to ``queue_size`` more wait for a thread; past that, requests
    get an immediate 503 with ``Retry-After``.  The worst-case memory of one process is about
    ``(threads + queue_size) × max_upload_bytes`` for waiting bodies (uploads larger than 1 MiB
    are spooled to disk) plus ``threads ×`` the working memory of the largest allowed image.
    """

    model_config = SettingsConfigDict(env_prefix="WAVECORE_", extra="forbid", frozen=True)

    # Request bodies
    max_upload_bytes: int = Field(
        default=20 * 1024 * 1024, ge=1, description="Largest request body."
    )
    max_pixels: int = Field(
        # Coding needs about 80 bytes of memory per sample (pixel × channel): a 2048 × 2048 RGB
        # image peaks near 1 GiB above idle, so this default bounds one request to that.
        default=2048 * 2048,
        ge=1,
        description="Largest image (width × height); also Pillow's decompression-bomb limit.",
    )
    max_points: int = Field(default=200_000, ge=1, description="Most points in a curve.")
    max_grid_points: int = Field(
        default=1024 * 1024, ge=1, description="Most grid points in a surface (U × V)."
    )
    max_dimension: int = Field(
        default=3, ge=1, description="Most coordinates per curve/surface point."
    )

    # Work
    threads: int = Field(
        default_factory=_default_threads, ge=1, description="Requests encoded/decoded at once."
    )
    queue_size: int = Field(default=64, ge=0, description="Requests that may wait for a thread.")
    request_timeout: float = Field(
        default=120.0, gt=0, description="Seconds a request may wait and work before it gets a 503."
    )
    retry_after: int = Field(
        default=2, ge=0, description="The Retry-After (seconds) sent with a 503."
    )

    # Process (used by ``wavecore serve``)
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    workers: int = Field(
        default=1, ge=1, description="uvicorn worker processes (one per pod is best)."
    )

    @model_validator(mode="after")
    def _capacity(self) -> Settings:
        if self.threads + self.queue_size < 1:
            msg = "threads + queue_size must be at least 1"
            raise ValueError(msg)
        return self

    @property
    def capacity(self) -> int:
        """Requests admitted at once (working plus waiting)."""
        return self.threads + self.queue_size
