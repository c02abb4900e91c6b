"""Every error the service sends, as RFC 9457 ``application/problem+json``, in one place.

A problem has ``type`` (a URN naming the kind, listed in ``PROBLEMS``), ``title``, ``status``
and ``detail``; validation problems add ``errors`` (``loc``, ``msg``, ``type`` per field).
``wavecore``'s own exceptions map by class: ``BundleError`` → 400, any other
``WavecoreError`` (a bad parameter) → 422.  Nothing a client sends can produce a 500: a
``MemoryError`` anywhere in a request is a 503 ``insufficient-memory`` problem, a client that
leaves before its body is in is logged at info level and counted with status 499, and any
other unexpected exception is logged and answered with a plain 500 problem without internals.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect
from starlette.responses import Response
from starlette.types import Scope, Send

import wavecore

log = logging.getLogger("service")

PROBLEM_JSON = "application/problem+json"

#: kind → (status, title).  The ``type`` of a problem is ``urn:wavecore:problem:<kind>``.
PROBLEMS: dict[str, tuple[int, str]] = {
    "invalid-bundle": (400, "The bundle cannot be decoded"),
    "bad-request": (400, "Bad request"),
    "not-found": (404, "Not found"),
    "method-not-allowed": (405, "Method not allowed"),
    "not-acceptable": (406, "No acceptable output format"),
    "body-timeout": (408, "Request body too slow"),
    "body-too-large": (413, "Request body too large"),
    "too-costly": (413, "Request would cost more than this server allows"),
    "image-too-large": (413, "Image too large"),
    "bundle-too-large": (413, "Bundle decodes to too much data"),
    "out-of-memory": (413, "Request needs more memory than a worker has"),
    "unsupported-media-type": (415, "Unsupported media type"),
    "validation-error": (422, "Invalid request"),
    "invalid-parameter": (422, "Invalid parameter"),
    "overloaded": (503, "Server busy"),
    "insufficient-memory": (503, "Not enough memory for this request now"),
    "timeout": (503, "Request took too long"),
    "worker-lost": (503, "The worker coding the request stopped"),
    "internal-error": (500, "Internal server error"),
}


def problem_type(kind: str) -> str:
    """The ``type`` URI of a problem kind.

    >>> problem_type("invalid-bundle")
    'urn:wavecore:problem:invalid-bundle'
    """
    return f"urn:wavecore:problem:{kind}"


class Problem(Exception):
    """Raise anywhere in a request to answer with that problem.

    >>> Problem("image-too-large", "40000 × 40000 pixels").status
    413
    """

    def __init__(
        self,
        kind: str,
        detail: str,
        *,
        headers: dict[str, str] | None = None,
        errors: list[dict[str, Any]] | None = None,
    ) -> None:
        super().__init__(detail)
        self.kind = kind
        self.status, self.title = PROBLEMS[kind]
        self.detail = detail
        self.headers = headers or {}
        self.errors = errors

    def __reduce__(self) -> tuple[Any, ...]:
        # Jobs may run in worker processes: a problem raised there is pickled back whole
        # (Exception's default pickling would call Problem(detail) and lose the kind).
        return (_rebuild_problem, (self.kind, self.detail, self.headers, self.errors))


def _rebuild_problem(
    kind: str, detail: str, headers: dict[str, str], errors: list[dict[str, Any]] | None
) -> Problem:
    return Problem(kind, detail, headers=headers, errors=errors)


#: The status the metrics give a request whose client left before it was answered (nginx's).
CLIENT_CLOSED = 499


def client_left(request: Request) -> Response:
    """A client that closed the connection mid-request: an info line, not an error.

    Nothing reaches the client; the response only gives the metrics their status (499).
    """
    log.info("client left during %s %s", request.method, request.url.path)
    return Response(status_code=CLIENT_CLOSED)


class BodyTooLarge(StarletteHTTPException):
    """Raised from inside the body stream, so FastAPI's form parser passes it on untouched."""

    def __init__(self, limit: int) -> None:
        super().__init__(
            413,
            f"the request body is larger than the limit of {limit} bytes",
            headers={"Connection": "close"},  # the rest of the body is not read
        )


def problem_response(problem: Problem, request: Request | None = None) -> JSONResponse:
    body: dict[str, Any] = {
        "type": problem_type(problem.kind),
        "title": problem.title,
        "status": problem.status,
        "detail": problem.detail,
    }
    if request is not None:
        body["instance"] = request.url.path
    if problem.errors is not None:
        body["errors"] = problem.errors
    response = JSONResponse(
        body, status_code=problem.status, headers=problem.headers, media_type=PROBLEM_JSON
    )
    # The metrics middleware counts errors by kind from this attribute of the scope.
    if request is not None:
        request.scope.setdefault("state", {})["problem_kind"] = problem.kind
    return response


async def send_problem(scope: Scope, send: Send, problem: Problem) -> None:
    """Answer from plain ASGI middleware, before any route ran."""
    scope.setdefault("state", {})["problem_kind"] = problem.kind
    body = json.dumps(
        {
            "type": problem_type(problem.kind),
            "title": problem.title,
            "status": problem.status,
            "detail": problem.detail,
            "instance": scope.get("path", ""),
        }
    ).encode()
    headers = [
        (b"content-type", PROBLEM_JSON.encode()),
        (b"content-length", str(len(body)).encode()),
        *((k.lower().encode(), v.encode()) for k, v in problem.headers.items()),
    ]
    await send({"type": "http.response.start", "status": problem.status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


def _safe(value: Any) -> Any:
    """JSON-safe: validation inputs may hold NaN, bytes or arbitrary objects."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, str | int | float | bool) or value is None:
        return value
    if isinstance(value, list | tuple):
        return [_safe(v) for v in value[:10]]
    return repr(value)[:200]


def validation_problem(raw: Sequence[Any], *, prefix: tuple[str, ...] = ()) -> Problem:
    """A 422 problem from Pydantic's error list; ``errors`` keeps ``loc``/``msg``/``type``."""
    errors = [
        {
            "loc": [*prefix, *(_safe(p) for p in e.get("loc", ()))],
            "msg": e.get("msg", ""),
            "type": e.get("type", "value_error"),
        }
        for e in raw
    ]
    if any(e["type"] == "json_invalid" for e in errors):
        detail = "the body is not valid JSON: " + "; ".join(e["msg"] for e in errors)
    else:
        detail = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'][1:] or e['loc'])}: {e['msg']}" for e in errors
        )
    return Problem("validation-error", detail[:2000], errors=errors[:50])


_HTTP_KINDS = {
    400: "bad-request",
    404: "not-found",
    405: "method-not-allowed",
    406: "not-acceptable",
    413: "body-too-large",
    415: "unsupported-media-type",
    422: "validation-error",
    503: "overloaded",
}


def install(app: FastAPI) -> None:
    """Register the handlers that turn every exception into a problem response."""

    @app.exception_handler(Problem)
    async def _problem(request: Request, exc: Problem) -> JSONResponse:
        return problem_response(exc, request)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        return problem_response(validation_problem(exc.errors()), request)

    @app.exception_handler(wavecore.BundleError)
    async def _bundle(request: Request, exc: wavecore.BundleError) -> JSONResponse:
        return problem_response(Problem("invalid-bundle", str(exc)), request)

    @app.exception_handler(wavecore.WavecoreError)
    async def _wavecore(request: Request, exc: wavecore.WavecoreError) -> JSONResponse:
        return problem_response(Problem("invalid-parameter", str(exc)), request)

    @app.exception_handler(ClientDisconnect)
    async def _disconnect(request: Request, exc: ClientDisconnect) -> Response:
        return client_left(request)

    @app.exception_handler(MemoryError)
    async def _memory(request: Request, exc: MemoryError) -> JSONResponse:
        log.warning("out of memory on %s %s", request.method, request.url.path)
        msg = (
            "the server ran out of memory for this request; retry later, or send a smaller "
            "input (docs/deploy.md, 'Memory per request')"
        )
        headers = {"Retry-After": str(request.app.state.settings.retry_after)}
        return problem_response(Problem("insufficient-memory", msg, headers=headers), request)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> Response:
        if isinstance(exc.__cause__, ClientDisconnect):  # FastAPI wraps form-reading errors
            return client_left(request)
        kind = _HTTP_KINDS.get(exc.status_code)
        if kind is None:
            problem = Problem("bad-request", str(exc.detail))
            problem.status, problem.title = exc.status_code, str(exc.detail)
        else:
            problem = Problem(kind, str(exc.detail), headers=dict(exc.headers or {}))
        return problem_response(problem, request)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return problem_response(
            Problem("internal-error", "the server failed; the error has been logged"), request
        )
