"""Plain ASGI middleware: security headers, the body-size limit, enforced while streaming, and
the metrics."""

from __future__ import annotations

import time

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .errors import CLIENT_CLOSED, BodyTooLarge, Problem, send_problem

#: The methods that get their own label; any other is counted as "other", so that made-up
#: methods cannot create one time series each (series are never freed).
KNOWN_METHODS = frozenset(
    ("GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", "TRACE", "CONNECT")
)


def method_label(method: str) -> str:
    """The ``method`` label of a request.

    >>> method_label("POST"), method_label("BREW")
    ('POST', 'other')
    """
    return method if method in KNOWN_METHODS else "other"


#: On every answer: a browser takes each for the type it is sent as, never a guess.
NOSNIFF = (b"x-content-type-options", b"nosniff")
#: On the API's answers (``/v1/``): opened in a browser (a form may post to the API from any
#: page), an SVG or any other answer runs nothing and loads nothing.
API_CSP = (b"content-security-policy", b"default-src 'none'; sandbox")


class SecurityHeadersMiddleware:
    """Add :data:`NOSNIFF` to every answer, and :data:`API_CSP` to the API's.

    The pages set their own policy (``/``, ``/redoc``); the API's answers are data, but an SVG
    answered to a form a hostile page posted is shown by the browser at this server's origin.
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        extra = [NOSNIFF]
        if scope.get("path", "").startswith("/v1/"):
            extra.append(API_CSP)

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                names = {name.lower() for name, _ in message.get("headers", [])}
                added = [header for header in extra if header[0] not in names]
                message = {**message, "headers": [*message.get("headers", []), *added]}
            await send(message)

        await self.app(scope, receive, send_with_headers)


class BodyLimitMiddleware:
    """Refuse bodies over ``limit`` bytes: at once by ``Content-Length``, else while reading.

    The body is never read into memory first: the count is kept on each chunk as the route
    pulls it, and the first chunk past the limit raises :class:`BodyTooLarge` (a 413).
    """

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        for name, value in scope["headers"]:
            if name == b"content-length":
                try:
                    declared = int(value)
                except ValueError:
                    declared = -1
                if declared > self.limit:
                    detail = (
                        f"the request body is {declared} bytes; the limit is {self.limit} "
                        "bytes (WAVECORE_MAX_UPLOAD_BYTES)"
                    )
                    # closed after the answer: the rest of the body is not read for nothing
                    closing = {"Connection": "close"}
                    await send_problem(
                        scope, send, Problem("body-too-large", detail, headers=closing)
                    )
                    return
        received = 0

        async def limited() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:
                    raise BodyTooLarge(self.limit)
            return message

        await self.app(scope, limited, send)


class Metrics:
    """The Prometheus metrics of one app (its own registry, so tests can build many apps)."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "wavecore_http_requests",
            "HTTP requests by route, method and status.",
            ["route", "method", "status"],
            registry=self.registry,
        )
        self.duration = Histogram(
            "wavecore_http_request_duration_seconds",
            "Time from the request's arrival to its last response byte.",
            ["route"],
            buckets=(0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60),
            registry=self.registry,
        )
        self.bytes_in = Counter(
            "wavecore_http_request_body_bytes",
            "Request body bytes received.",
            ["route"],
            registry=self.registry,
        )
        self.bytes_out = Counter(
            "wavecore_http_response_body_bytes",
            "Response body bytes sent.",
            ["route"],
            registry=self.registry,
        )
        self.errors = Counter(
            "wavecore_http_errors",
            "Problem responses by kind (the end of the problem's type URN).",
            ["kind"],
            registry=self.registry,
        )
        self.in_flight = Gauge(
            "wavecore_requests_in_flight",
            "Admitted /v1/ requests (working or waiting for a thread).",
            registry=self.registry,
        )
        self.answer_bytes = Gauge(
            "wavecore_answer_bytes_held",
            "Bytes of answers over 1 MiB held while their clients read them "
            "(at most WAVECORE_ANSWER_MEMORY_BYTES, or one answer).",
            registry=self.registry,
        )


def route_label(scope: Scope) -> str:
    """The path template of the route that served (or would have served) this request.

    A request refused before routing (a client that left while its body was read) is counted
    under its path when that path is one of the app's documented operations; the label is never
    the client's raw, unbounded path.
    """
    route = getattr(scope.get("route"), "path", None)
    if route is not None:
        return str(route)
    app = scope.get("app")
    openapi = getattr(app, "openapi", None)
    if openapi is not None and scope.get("path") in openapi().get("paths", {}):
        return str(scope["path"])
    return "unmatched"


class MetricsMiddleware:
    """Count every request: route, status, duration, bytes in and out, problems by kind."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500
        bytes_in = 0
        bytes_out = 0

        async def counting_receive() -> Message:
            nonlocal bytes_in
            message = await receive()
            if message["type"] == "http.request":
                bytes_in += len(message.get("body", b""))
            return message

        async def counting_send(message: Message) -> None:
            nonlocal status, bytes_out
            if message["type"] == "http.response.start":
                status = message["status"]
            elif message["type"] == "http.response.body":
                bytes_out += len(message.get("body", b""))
            await send(message)

        try:
            await self.app(scope, counting_receive, counting_send)
        finally:
            state = scope.get("state", {})
            if state.get("client_left") and bytes_out == 0:
                status = CLIENT_CLOSED
            route = route_label(scope)
            m = self.metrics
            m.requests.labels(route, method_label(scope["method"]), str(status)).inc()
            m.duration.labels(route).observe(time.perf_counter() - start)
            m.bytes_in.labels(route).inc(bytes_in)
            m.bytes_out.labels(route).inc(bytes_out)
            kind = scope.get("state", {}).get("problem_kind")
            if kind is not None:
                m.errors.labels(kind).inc()
