"""Small helpers shared by the routes: settings, body reading, array checks, responses."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import orjson
from fastapi import Request
from pydantic import BaseModel, ValidationError

from .errors import PROBLEM_JSON, Problem, validation_problem
from .gridfiles import GridFileError, check_npy_length, read_npy_header
from .schemas import ProblemDetails
from .settings import Settings

BUNDLE_MEDIA_TYPE = "application/vnd.wavecore.bundle"
NPY_MEDIA_TYPE = "application/x-npy"


def settings_of(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def reject_unknown_query(request: Request) -> None:
    """Answer 400 when the query string names a parameter the route does not read.

    The image and grid routes take their options as form fields, and the surface route takes
    them in the body: a ``?bpp=0.5`` there would otherwise be dropped without a word.
    """
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return
    known: set[str] = set()
    pending = [dependant]
    while pending:  # the route's own parameters and those of its dependencies
        current = pending.pop()
        known.update(param.alias for param in current.query_params)
        pending.extend(current.dependencies)
    unknown = sorted(set(request.query_params) - known)
    if unknown:
        names = ", ".join(repr(name) for name in unknown)
        accepted = ", ".join(sorted(known)) or "none"
        raise Problem(
            "bad-request",
            f"unknown query parameter {names} for {request.url.path}: its query parameters are "
            f"{accepted}; options of multipart routes go in form fields, and of JSON routes in "
            "the body",
        )


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for the problems a route can answer with."""
    return {
        status: {
            "model": ProblemDetails,
            "content": {PROBLEM_JSON: {"schema": ProblemDetails.model_json_schema()}},
        }
        for status in statuses
    }


#: Media types a JSON body may come with (none at all is taken as JSON too).
JSON_MEDIA_TYPES = ("application/json", "")


def json_body_openapi(model: type[BaseModel]) -> dict[str, Any]:
    """``openapi_extra`` documenting a JSON body the route reads as bytes (for /docs and
    schemathesis): the route itself declares no body parameter, so FastAPI parses nothing."""
    return {
        "requestBody": {
            "required": True,
            "content": {"application/json": {"schema": model.model_json_schema()}},
        }
    }


async def read_json_bytes(request: Request) -> bytearray:
    """The raw body of a JSON request (415 for another media type).

    Only the bytes are read here, on the event loop (bounded by ``WAVECORE_MAX_UPLOAD_BYTES``
    as they stream in); parsing is the job's, on a worker.  The chunks go straight into one
    buffer, so the body is held once (``Request.body()`` joins a list of chunks: twice).
    """
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if content_type not in JSON_MEDIA_TYPES and not content_type.endswith("+json"):
        msg = f"send the body as application/json, not {content_type}"
        raise Problem("unsupported-media-type", msg)
    body = bytearray()
    async for chunk in request.stream():
        body += chunk
    return body


def parse_model(model: type[BaseModel], data: bytes | dict[str, Any]) -> Any:
    """Validate JSON bytes (or form fields) against ``model``; a 422 problem on failure."""
    try:
        if isinstance(data, bytes):
            return model.model_validate_json(data)
        return model.model_validate(data)
    except ValidationError as exc:
        raise validation_problem(exc.errors(include_url=False), prefix=("body",)) from None


def check_array(
    arr: np.ndarray,
    name: str,
    *,
    ndim: Sequence[int],
    max_count: int,
    max_dim: int,
    point_axes: int = 1,
) -> np.ndarray:
    """Check rank, point count (over the first ``point_axes`` axes), coordinates, finiteness."""
    if arr.ndim not in ndim:
        msg = f"{name} has shape {list(arr.shape)}; expected {' or '.join(map(str, ndim))} axes"
        raise Problem("invalid-parameter", msg, errors=_err(name, msg))
    axes = point_axes
    count = math.prod(arr.shape[:axes])
    if count > max_count or count == 0:
        msg = f"{name} has {count} points; between 1 and {max_count} are accepted"
        raise Problem("invalid-parameter", msg, errors=_err(name, msg))
    if arr.ndim > axes and not 1 <= arr.shape[-1] <= max_dim:
        msg = f"{name} has {arr.shape[-1]} coordinates per point; 1 to {max_dim} are accepted"
        raise Problem("invalid-parameter", msg, errors=_err(name, msg))
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        msg = f"{name} holds NaN or infinite values"
        raise Problem("invalid-parameter", msg, errors=_err(name, msg))
    return arr


def _err(name: str, msg: str) -> list[dict[str, Any]]:
    return [{"loc": ["body", name], "msg": msg, "type": "value_error"}]


def read_npy(data: bytes, name: str, *, max_elements: int) -> np.ndarray:
    """Load a ``.npy`` file safely: header checked before anything is allocated, no pickles."""
    try:
        shape, _fortran, dtype, offset = read_npy_header(data, name)
    except GridFileError as exc:
        raise Problem(exc.kind, str(exc)) from None
    if dtype.kind not in "biuf" or dtype.fields is not None:
        msg = f"{name} has dtype {dtype}; a numeric (bool, integer or float) array is needed"
        raise Problem("invalid-parameter", msg, errors=_err(name, msg))
    size = math.prod(shape)
    if size > max_elements:
        msg = f"{name} has {size} values; the limit is {max_elements}"
        raise Problem("invalid-parameter", msg, errors=_err(name, msg))
    try:
        check_npy_length(data, offset, shape, dtype, name)
    except GridFileError as exc:
        raise Problem(exc.kind, str(exc)) from None
    arr = np.load(io.BytesIO(data), allow_pickle=False)
    if dtype.kind != "f":
        return np.asarray(arr, dtype=np.float64)
    # A big-endian file (">f8", written on another machine) becomes native: the compiled
    # kernels take native byte order only.
    return arr.astype(arr.dtype.newbyteorder("="), copy=False)


def npy_bytes(arr: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, arr, allow_pickle=False)
    return out.getvalue()


def array_answer(kind: str, arr: np.ndarray, field: str, *, origin: str = "the bundle") -> bytes:
    """The JSON answer ``{"kind", "shape", "dtype", field: nested lists}`` of an array.

    orjson writes the numbers straight from the array (no Python float per value: a list of
    200 000 points costs a third of the time and under half of the memory of ``tolist()`` and
    a Pydantic dump), exactly (shortest round-trip form).  NaN or infinite values, which JSON
    cannot carry, are a problem that points at ``format=npy``.
    """
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        msg = f"{origin} decodes to NaN or infinite values; ask for format=npy to get them"
        raise Problem("invalid-bundle", msg)
    native = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("="))
    answer = {"kind": kind, "shape": list(native.shape), "dtype": str(native.dtype), field: native}
    return orjson.dumps(answer, option=orjson.OPT_SERIALIZE_NUMPY)


def jsonable(value: Any) -> Any:
    """Plain JSON types, with non-finite floats as strings ("inf", "nan")."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, bytes):
        return value.hex()
    return value
