"""``POST /v1/surfaces/encode``: a JSON grid or an uploaded ``.npy``, a bundle out."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from fastapi import APIRouter, Depends, Request
from fastapi.responses import Response
from starlette.datastructures import UploadFile

import wavecore

from .. import cost
from ..deps import (
    BUNDLE_MEDIA_TYPE,
    check_array,
    parse_model,
    problem_responses,
    read_json_bytes,
    read_npy,
    reject_unknown_query,
    settings_of,
)
from ..errors import Problem
from ..intake import parse_json_body
from ..schemas import SurfaceEncodeRequest, SurfaceOptions, SurfaceUploadParams
from ..settings import Settings
from ..work import run_work

router = APIRouter(
    prefix="/v1/surfaces", tags=["surfaces"], dependencies=[Depends(reject_unknown_query)]
)

_UPLOAD_SCHEMA = {
    "type": "object",
    "required": ["file"],
    "properties": {
        "file": {"type": "string", "format": "binary", "description": "A .npy (U, V[, d])"},
        "closed": {"type": "string", "description": 'e.g. "true,false" or "[true, false]"'},
        "level": {"type": "integer", "minimum": 0},
        "keep": {"type": "number", "minimum": 0, "maximum": 1},
        "quality": {"type": "number", "exclusiveMinimum": 0},
    },
}


def _limits(settings: Settings) -> dict[str, Any]:
    return {
        "ndim": (2, 3),
        "max_count": settings.max_grid_points,
        "max_dim": settings.max_dimension,
        "point_axes": 2,
    }


def encode_json_job(body: bytes | bytearray, settings: Settings) -> tuple[bytes, dict[str, str]]:
    """A JSON surface: parse, check the cost, encode (all on a worker)."""
    options, arrays = parse_json_body(body, SurfaceOptions, {"grid": (2, 3)})
    grid = check_array(arrays["grid"], "grid", **_limits(settings))
    return _encode(grid, options.model_dump(exclude_none=True), settings)


def encode_npy_job(
    data: bytes, options: dict[str, Any], settings: Settings
) -> tuple[bytes, dict[str, str]]:
    """An uploaded ``.npy`` surface: read (header first), check the cost, encode."""
    max_values = settings.max_grid_points * settings.max_dimension
    grid = read_npy(data, "file", max_elements=max_values)
    grid = check_array(grid, "file", **_limits(settings))
    return _encode(grid, options, settings)


def _encode(
    grid: np.ndarray, options: dict[str, Any], settings: Settings
) -> tuple[bytes, dict[str, str]]:
    options["closed"] = tuple(options.get("closed", (False, False)))
    cost.check_grid(grid.shape, options["closed"], options.get("level"), settings)
    bundle = wavecore.encode_surface(grid, **options)
    info = wavecore.inspect(bundle)
    psnr = info.get("psnr")
    headers = {
        "X-Wavecore-Bytes": str(len(bundle)),
        "X-Wavecore-Ratio": f"{grid.nbytes / len(bundle):.3f}",
        "X-Wavecore-PSNR": "inf" if psnr is None else f"{psnr:.4g}",
    }
    return bundle, headers


def _closed_field(text: str) -> Any:
    text = text.strip()
    if text.startswith("["):
        try:
            return json.loads(text)
        except (ValueError, RecursionError):  # the model's validation names the field
            return text
    return [part.strip() for part in text.split(",")]


@router.post(
    "/encode",
    response_class=Response,
    summary="Encode a surface (JSON grid or .npy upload) into a bundle",
    openapi_extra={
        "requestBody": {
            "required": True,
            "content": {
                "application/json": {"schema": SurfaceEncodeRequest.model_json_schema()},
                "multipart/form-data": {"schema": _UPLOAD_SCHEMA},
            },
        }
    },
    responses={
        200: {"content": {BUNDLE_MEDIA_TYPE: {}}, "description": "The bundle."},
        **problem_responses(413, 415, 422, 503),
    },
)
async def encode_surface(request: Request) -> Response:
    """Send JSON (`grid` as U rows of V points, or a U × V height field; `closed` per
    axis) or a multipart form with a `.npy` file in `file` and the same fields.  Coded to
    40 dB against the data range unless `keep` or `quality` says otherwise."""
    settings = settings_of(request)
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if content_type == "multipart/form-data":
        async with request.form(max_files=1, max_fields=8) as form:
            upload = form.get("file")
            if not isinstance(upload, UploadFile):
                raise Problem(
                    "invalid-parameter",
                    "the form needs a .npy file in the field 'file'",
                    errors=[{"loc": ["body", "file"], "msg": "missing", "type": "missing"}],
                )
            fields = {k: v for k, v in form.items() if k != "file" and isinstance(v, str)}
            if "closed" in fields:
                fields["closed"] = _closed_field(fields["closed"])
            params = parse_model(SurfaceUploadParams, {k: v for k, v in fields.items() if v})
            data = await upload.read()
        options = params.model_dump(exclude_none=True)
        bundle, headers = await run_work(request, encode_npy_job, data, options, settings)
    else:
        body = await read_json_bytes(request)
        bundle, headers = await run_work(request, encode_json_job, body, settings)
    return Response(bundle, media_type=BUNDLE_MEDIA_TYPE, headers=headers)
