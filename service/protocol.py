"""uvicorn's HTTP/1.1 protocol (h11) with guards against idle and slow connections.

uvicorn closes a kept-alive connection that stays idle, but not one that never finishes a
request's headers: a connection that sends nothing, or a byte now and then (slowloris), is
kept for ever.  A client that opens a few thousand of them uses up the worker's file
descriptors; then no one else is accepted, and asyncio logs every failed ``accept`` (measured:
1 100 idle sockets against a limit of 1 024 descriptors stopped ``/healthz``, and the log grew
by 2.5 million lines in 30 s).  ``wavecore serve`` runs uvicorn with :class:`GuardedH11Protocol`:

- **header deadline**: each request's headers must be in within ``header_timeout`` seconds
  (``WAVECORE_HEADER_TIMEOUT``, default 10) of the connection being opened, or of its first
  byte after the previous response; else the connection is closed.  The body has its own
  deadline (``body_timeout``) and so does reading a large answer (``send_timeout``), both
  in :mod:`service.work`;
- **connection cap**: past ``max_connections`` open connections (``WAVECORE_MAX_CONNECTIONS``,
  default 1 000), a new connection gets a ``503`` with ``Retry-After`` and is closed at once.
  The cap and the listen backlog (how many sockets asyncio accepts at once, a quarter of the
  setting) together take at most half the process's descriptor limit, so they do not run out.

A reverse proxy in front (an ingress) usually does the same; these hold without one.
"""

from __future__ import annotations

import asyncio
import resource
from functools import lru_cache

from uvicorn.protocols.http.h11_impl import H11Protocol

from .settings import Settings

__all__ = ["GuardedH11Protocol", "connection_limits"]


@lru_cache(maxsize=1)
def connection_limits() -> tuple[float, int, int]:
    """``(header_timeout, max_connections, backlog)``: the settings' deadline; the listen
    backlog, a quarter of the settings' cap (at least 64: a shorter queue drops connections
    that a burst of clients opens at once); and the cap, lowered so that it and the backlog
    take at most half the descriptor limit (asyncio accepts a backlog's worth before any is
    refused; the other half is for files, pipes and workers)."""
    settings = Settings.from_env()
    backlog = max(64, min(2048, settings.max_connections // 4))
    cap = settings.max_connections
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY:
        cap = max(1, min(cap, soft // 2 - backlog))
    return settings.header_timeout, cap, backlog


@lru_cache(maxsize=1)
def _busy_response() -> bytes:
    """The 503 a connection past the cap gets (made once: a flood of them must cost little)."""
    retry_after = Settings.from_env().retry_after
    body = b'{"type":"urn:wavecore:problem:overloaded","title":"Too many connections","status":503}'
    return (
        b"HTTP/1.1 503 Service Unavailable\r\n"
        b"Content-Type: application/problem+json\r\n"
        + f"Retry-After: {retry_after}\r\nContent-Length: {len(body)}\r\n".encode()
        + b"Connection: close\r\n\r\n"
        + body
    )


class GuardedH11Protocol(H11Protocol):
    """:class:`uvicorn.protocols.http.h11_impl.H11Protocol` with a deadline for each request's
    headers and a cap on open connections (see the module's docstring)."""

    _header_deadline: asyncio.TimerHandle | None = None
    _waiting_cycle: object = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        timeout, cap, _ = connection_limits()
        if len(self.connections) > cap:
            transport.write(_busy_response())
            transport.close()
            return
        self._arm_header_deadline(timeout)

    def data_received(self, data: bytes) -> None:
        if self._header_deadline is None and (
            self.cycle is None or self.cycle.response_complete
        ):  # the first bytes of the next request on a kept-alive connection
            self._arm_header_deadline(connection_limits()[0])
        super().data_received(data)
        if self.cycle is not self._waiting_cycle:  # the headers are in: a new request began
            self._disarm_header_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_header_deadline()
        super().connection_lost(exc)

    def _arm_header_deadline(self, timeout: float) -> None:
        self._waiting_cycle = self.cycle
        self._header_deadline = self.loop.call_later(timeout, self._headers_too_slow)

    def _disarm_header_deadline(self) -> None:
        if self._header_deadline is not None:
            self._header_deadline.cancel()
            self._header_deadline = None

    def _headers_too_slow(self) -> None:
        self._header_deadline = None
        if self.cycle is self._waiting_cycle and not self.transport.is_closing():
            self.transport.close()
