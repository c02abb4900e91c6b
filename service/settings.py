"""Every limit and knob of the service, in one object read from ``WAVECORE_*`` variables.

>>> Settings(max_upload_bytes=1024).max_upload_bytes
1024
"""

from __future__ import annotations

import os
from typing import Any

from pydantic import AliasChoices, Field, ValidationError, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


def _default_concurrency() -> int:
    # One worker process per core keeps every core busy; more would only add memory (each
    # worker holds a whole decoded image while it codes).
    return max(1, os.cpu_count() or 1)


class SettingsError(ValueError):
    """A ``WAVECORE_*`` variable has a value the service cannot use; the message is one line
    that names the variable, its value and what is accepted."""


class Settings(BaseSettings):
    """The service's settings; each field is read from ``WAVECORE_<FIELD NAME>``.

    The defaults let 64 concurrent clients all succeed on one process: ``concurrency`` jobs
    are worked on at once, each in its own worker process, and up to ``queue_size`` more wait
    for a worker; past that, requests get an immediate 503 with ``Retry-After``.  A request
    takes its slot only once its whole body has arrived (within ``body_timeout``).  Bodies
    read and not yet answered total at most ``(concurrency + queue_size) × max_upload_bytes``
    (up to 1 MiB each in memory, the rest on disk); the workers need ``concurrency ×`` the
    working memory of the largest allowed image (docs/deploy.md).

    ``concurrency`` is read from ``WAVECORE_CONCURRENCY``, or from its old spelling
    ``WAVECORE_THREADS`` when that is the only one set (``WAVECORE_THREADS`` is also the
    library's own thread count, inside each worker).
    """

    model_config = SettingsConfigDict(
        env_prefix="WAVECORE_", extra="forbid", frozen=True, populate_by_name=True
    )

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

    body_timeout: float = Field(
        default=30.0,
        gt=0,
        description="Seconds a request's whole body may take to arrive before it gets a 408.",
    )

    send_timeout: float = Field(
        default=30.0,
        gt=0,
        description="Seconds a client may go without reading any of an answer of more than "
        "1 MiB (the request keeps its slot meanwhile; the whole answer within the request "
        "timeout) before its connection is closed.",
    )
    answer_memory_bytes: int = Field(
        default=512 * 1024 * 1024,
        ge=0,
        description="Bytes of answers of more than 1 MiB that the server holds at once while "
        "their clients read them; an answer that would pass it cuts the newest answers of a "
        "client that would still hold more, else gets a 503 (one answer alone is always "
        "sent).  0: no limit.",
    )
    header_timeout: float = Field(
        default=10.0,
        gt=0,
        description="Seconds a request's headers may take to arrive (from the connection, or "
        "from its first byte after the previous response) before the connection is closed.",
    )
    max_connections: int = Field(
        default=1000,
        ge=1,
        description="Open connections per server process (at most half its file-descriptor "
        "limit); past it a new connection gets a 503 and is closed.",
    )

    # Work
    concurrency: int = Field(
        default_factory=_default_concurrency,
        ge=1,
        # No env_prefix for aliases: both spellings are written out; the first one set wins.
        validation_alias=AliasChoices("WAVECORE_CONCURRENCY", "WAVECORE_THREADS"),
        description="Requests encoded/decoded at once: the worker processes.",
    )
    queue_size: int = Field(default=64, ge=0, description="Requests that may wait for a worker.")
    request_timeout: float = Field(
        default=120.0,
        gt=0,
        description="Seconds a request may wait and work (after its body is in) before a 503; "
        "its worker is then ended and replaced.",
    )
    worker_memory_bytes: int = Field(
        default=0,
        ge=0,
        description="Address-space limit (RLIMIT_AS) of each worker process; 0: none.  A job "
        "that needs more gets a 413.",
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

    @model_validator(mode="before")
    @classmethod
    def _old_keyword(cls, data: Any) -> Any:
        # ``Settings(threads=2)``: the keyword of the field's old name still works.
        # It wins over the environment, as any keyword does: the sources are merged by now,
        # under the field's first alias.
        if isinstance(data, dict) and "threads" in data:
            data = dict(data)
            threads = data.pop("threads")
            if "concurrency" not in data:
                data.pop("WAVECORE_THREADS", None)
                data["WAVECORE_CONCURRENCY"] = threads
        return data

    @property
    def threads(self) -> int:
        """The old name of :attr:`concurrency`."""
        return self.concurrency

    @property
    def capacity(self) -> int:
        """Requests admitted at once (working plus waiting)."""
        return self.concurrency + self.queue_size

    @classmethod
    def from_env(cls, **overrides: Any) -> Settings:
        """The settings from ``WAVECORE_*`` variables, or a one-line :class:`SettingsError`.

        >>> import os
        >>> os.environ["WAVECORE_QUEUE_SIZE"] = "many"
        >>> try:
        ...     Settings.from_env()
        ... except SettingsError as exc:
        ...     print(exc)  # doctest: +ELLIPSIS
        WAVECORE_QUEUE_SIZE='many': Input should be a valid integer...
        >>> del os.environ["WAVECORE_QUEUE_SIZE"]
        """
        try:
            return cls(**overrides)
        except ValidationError as exc:
            raise SettingsError(_one_line(exc)) from None


def _environ_upper() -> set[str]:
    return {key.upper() for key in os.environ}


def _one_line(exc: ValidationError) -> str:
    """The first problem of a validation error as ``VARIABLE='value': what is wrong``."""
    error = exc.errors(include_url=False)[0]
    name = str(error["loc"][0]) if error["loc"] else ""
    if name and not name.upper().startswith("WAVECORE_"):
        name = "WAVECORE_" + name.upper()
    name = name.upper() or "WAVECORE_*"
    if name == "WAVECORE_CONCURRENCY" and name not in _environ_upper():
        name = "WAVECORE_THREADS"  # the value came from the old spelling
    more = len(exc.errors()) - 1
    tail = f" (and {more} more)" if more else ""
    return f"{name}={error.get('input')!r}: {error['msg']}{tail}"
