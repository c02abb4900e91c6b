"""``POST /v1/bundles/reconstruct`` and ``POST /v1/bundles/inspect``.

The bundle comes as the raw body (``application/vnd.wavecore.bundle``, or any type) or as the
field ``bundle`` of a multipart form.  ``keep``, ``level`` and ``format`` come from the query
string (or, in a form, from fields of those names).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.datastructures import UploadFile

import wavecore
from wavecore.io import curve_set_file

from .. import cost
from ..deps import (
    BUNDLE_MEDIA_TYPE,
    NPY_MEDIA_TYPE,
    array_answer,
    jsonable,
    npy_bytes,
    parse_model,
    problem_responses,
    reject_unknown_query,
    settings_of,
)
from ..errors import Problem
from ..imaging import IMAGE_FORMATS, encode_array
from ..schemas import PointsResult, ReconstructParams
from ..settings import Settings
from ..work import run_work

router = APIRouter(
    prefix="/v1/bundles", tags=["bundles"], dependencies=[Depends(reject_unknown_query)]
)

_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            BUNDLE_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}},
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["bundle"],
                    "properties": {"bundle": {"type": "string", "format": "binary"}},
                }
            },
        },
    }
}

#: Accept media type → format, in the order they are tried.
_ACCEPT = {
    NPY_MEDIA_TYPE: "npy",
    "application/octet-stream": "npy",
    "image/png": "png",
    "image/webp": "webp",
    "image/tiff": "tiff",
    "application/json": "json",
    "application/geo+json": "geojson",
    "image/svg+xml": "svg",
}
#: What a curve set (``kind`` ``curves``) can be written as, with its media type.
CURVE_FILE_FORMATS = {
    "geojson": "application/geo+json",
    "svg": "image/svg+xml",
    "json": "application/json",
}


async def _read_bundle(request: Request) -> tuple[bytes, dict[str, str]]:
    """The bundle bytes and, for a form, its other string fields."""
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if content_type == "multipart/form-data":
        async with request.form(max_files=1, max_fields=8) as form:
            upload = form.get("bundle")
            if not isinstance(upload, UploadFile):
                msg = "the form needs the bundle file in the field 'bundle'"
                errors = [{"loc": ["body", "bundle"], "msg": "missing", "type": "missing"}]
                raise Problem("invalid-parameter", msg, errors=errors)
            fields = {k: v for k, v in form.items() if isinstance(v, str) and v}
            return await upload.read(), fields
    return await request.body(), {}


def _choose_format(requested: str | None, kind: str, accept: str, own: str = "json") -> str:
    if kind == "curves":  # the format it was read from first
        allowed: tuple[str, ...] = (own, *(f for f in CURVE_FILE_FORMATS if f != own))
    elif kind == "image":
        allowed = ("png", "webp", "tiff", "npy")
    elif kind == "grid":  # NaN cells have no JSON form: npy first
        allowed = ("npy", "json")
    else:
        allowed = ("json", "npy")
    if requested is not None:
        if requested not in allowed:
            msg = f"a {kind} can be reconstructed as {', '.join(allowed)}, not {requested}"
            raise Problem("not-acceptable", msg)
        return requested
    for media_type, fmt in _ACCEPT.items():
        if media_type in accept and fmt in allowed:
            return fmt
    return allowed[0]


def _reconstruct_curves(
    bundle: bytes, info: dict[str, Any], requested: str | None, accept: str, settings: Settings
) -> tuple[bytes, str, dict[str, str]]:
    """A curve set written as GeoJSON, SVG or curve JSON (its own format by default)."""
    too_long = [n for n in info["points"] if n > settings.max_points]
    if too_long or max(info["dims"], default=1) > settings.max_dimension:
        msg = (
            f"the bundle decodes to curves of up to {max(info['points'], default=0)} points of "
            f"{max(info['dims'], default=1)} coordinates, more than this server's limits of "
            f"{settings.max_points} points and {settings.max_dimension} coordinates"
        )
        raise Problem("bundle-too-large", msg)
    samples = sum(
        cost.CURVE_FACTOR * n * (d + 1) for n, d in zip(info["points"], info["dims"], strict=True)
    )
    samples += cost.CURVE_DECODE_CURVE_SAMPLES * int(info["count"])
    metadata = int(info.get("metadata_bytes", 0))
    samples += cost.CURVE_METADATA_SAMPLES_PER_BYTE * metadata
    what = f"a bundle of {info['count']} curves" + (
        f" with {metadata} bytes of metadata" if metadata else ""
    )
    cost.check(samples, what, settings)
    curveset = wavecore.decode_curves(bundle)
    own = (curveset.metadata or {}).get("format", "json")
    fmt = _choose_format(requested, "curves", accept, own if own in CURVE_FILE_FORMATS else "json")
    headers = {"X-Wavecore-Kind": "curves", "X-Wavecore-Curves": str(info["count"])}
    return curve_set_file(curveset, fmt), CURVE_FILE_FORMATS[fmt], headers


def _check_declared_size(info: dict[str, Any], settings: Settings) -> None:
    """Refuse a bundle that declares more than an upload may hold (413), before decoding it.

    A bundle is small, but what it decodes to is as large as its header says: without this a
    few hundred crafted bytes could ask for the library's limit (2**27 samples, gigabytes of
    working memory) on every request.
    """
    shape, kind = info["shape"], info["kind"]
    if kind == "image":
        count, limit, what = shape[0] * shape[1], settings.max_pixels, "pixels"
        size = f"a {shape[1]} × {shape[0]} image"
    elif kind == "curve":
        count, limit, what = shape[0], settings.max_points, "points"
        size = f"a curve of {shape[0]} points"
    elif kind == "grid":  # a height field or a volume: every value counts
        count, limit, what = (
            math.prod(shape),
            settings.max_grid_points * settings.max_dimension,
            "values",
        )
        size = f"a {' × '.join(map(str, shape))} grid"
    else:
        count, limit, what = shape[0] * shape[1], settings.max_grid_points, "grid points"
        size = f"a {shape[0]} × {shape[1]} surface"
    if count > limit:
        msg = f"the bundle decodes to {size}, more than this server's limit of {limit} {what}"
        raise Problem("bundle-too-large", msg)
    vector = kind not in ("image", "grid") and len(shape) > (1 if kind == "curve" else 2)
    if vector and shape[-1] > settings.max_dimension:
        msg = (
            f"the bundle decodes to {shape[-1]}-D points, more than this server's limit of "
            f"{settings.max_dimension} coordinates"
        )
        raise Problem("bundle-too-large", msg)


def parse_region(text: str | None) -> tuple[slice, ...] | None:
    """``"Y0:Y1,X0:X1"`` (NumPy's slice syntax per axis, a step allowed, ends optional) as
    slices; a ``Problem`` naming the part that is not one."""
    if text is None:
        return None
    out = []
    for part in text.split(","):
        bounds = part.strip().split(":")
        try:
            if not 2 <= len(bounds) <= 3:
                raise ValueError(part)
            out.append(slice(*[int(b) if b.strip() else None for b in bounds]))
        except ValueError:
            msg = (
                f"region {text[:80]!r}: {part.strip()[:40]!r} is not start:stop or "
                "start:stop:step with whole numbers (e.g. region=0:256,512:768)"
            )
            raise Problem("invalid-parameter", msg) from None
    return tuple(out)


def reconstruct_job(
    bundle: bytes,
    keep: float | None,
    level: int,
    requested: str | None,
    accept: str,
    settings: Settings,
    region: tuple[slice, ...] | None = None,
) -> tuple[bytes, str, dict[str, str]]:
    info = wavecore.inspect(bundle)
    if info["kind"] == "curves":
        if (keep is not None and keep < 1.0) or level or region is not None:
            msg = (
                "a curve set decodes whole, at its guaranteed tolerance: keep, level and region "
                "do not apply to it"
            )
            raise Problem("invalid-parameter", msg)
        return _reconstruct_curves(bundle, info, requested, accept, settings)
    _check_declared_size(info, settings)
    cost.check_bundle(info, settings)
    kind = info["kind"]
    fmt = _choose_format(requested, kind, accept)
    arr = wavecore.decode(bundle, keep=keep, level=level, region=region)
    headers = {
        "X-Wavecore-Kind": kind,
        "X-Wavecore-Shape": "x".join(str(s) for s in arr.shape),
        "X-Wavecore-Dtype": str(arr.dtype),
    }
    if fmt == "npy":
        return npy_bytes(arr), NPY_MEDIA_TYPE, headers
    if kind == "image":
        return encode_array(arr, fmt), IMAGE_FORMATS[fmt], headers
    field = "points" if kind == "curve" else "grid"  # PointsResult / GridResult
    return array_answer(kind, arr, field), "application/json", headers


@router.post(
    "/reconstruct",
    response_class=Response,
    summary="Decode a bundle, optionally keeping fewer details or at a coarser level",
    openapi_extra=_BODY,
    responses={
        200: {
            "content": {
                "image/png": {},
                "image/webp": {},
                "image/tiff": {},
                NPY_MEDIA_TYPE: {},
                "application/json": {"schema": PointsResult.model_json_schema()},
                "application/geo+json": {},
                "image/svg+xml": {},
            },
            "description": "Images as PNG (default), WebP, TIFF or .npy; curves and surfaces "
            "as JSON (default) or .npy; curve sets as GeoJSON, SVG or curve JSON (default: "
            "the format they were read from).",
        },
        **problem_responses(400, 406, 413, 422, 503),
    },
)
async def reconstruct(
    request: Request,
    keep: Annotated[
        float | None,
        Query(ge=0, le=1, allow_inf_nan=False, description="Fraction of stored details kept"),
    ] = None,
    level: Annotated[int, Query(ge=0, description="0: full size; k: k levels coarser")] = 0,
    format: Annotated[
        Literal["png", "webp", "tiff", "npy", "json", "geojson", "svg"] | None,
        Query(
            description="Output format; default by kind (a curve set: the format it was read "
            "from), or by the Accept header"
        ),
    ] = None,
    region: Annotated[
        str | None,
        Query(
            max_length=200,
            description="Only this part of the result, as rows,cols in NumPy's slice syntax "
            "(e.g. 0:256,512:768; a grid volume takes depth,rows,cols) at the given level: "
            "only the code-blocks that reach it are decoded",
        ),
    ] = None,
) -> Response:
    """`keep` drops the smallest stored details at decode time (0.4 removes the smallest
    60 %); `level=k` returns the coarse approximation after k levels (about n / 2^k per side),
    from the bundle's first chunks only; `region=Y0:Y1,X0:X1` returns that window of it,
    decoding only the code-blocks it needs."""
    bundle, fields = await _read_bundle(request)
    if fields:
        params = parse_model(
            ReconstructParams,
            {"keep": keep, "level": level, "format": format, "region": region}
            | {k: v for k, v in fields.items() if k in ReconstructParams.model_fields},
        )
        keep, level, format, region = params.keep, params.level, params.format, params.region
    accept = request.headers.get("accept", "")
    body, media_type, headers = await run_work(
        request,
        reconstruct_job,
        bundle,
        keep,
        level,
        format,
        accept,
        settings_of(request),
        parse_region(region),
    )
    return Response(body, media_type=media_type, headers=headers)


def inspect_job(bundle: bytes) -> Any:
    return jsonable(wavecore.inspect(bundle))


@router.post(
    "/inspect",
    summary="Describe a bundle without decoding it",
    openapi_extra=_BODY,
    responses=problem_responses(400, 413, 503),
)
async def inspect(request: Request) -> JSONResponse:
    """`wavecore.inspect`: kind, shape, dtype, wavelet, levels, the encoder's measured PSNR and
    largest error, total and header bytes, and per chunk (coarse to fine) its level, subband
    shapes and bytes.  Non-finite numbers are given as strings (`"inf"`)."""
    bundle, _ = await _read_bundle(request)
    info = await run_work(request, inspect_job, bundle)
    return JSONResponse(info)
