"""``POST /v1/curves/encode`` and ``POST /v1/curves/transfer``.

The JSON body is read as bytes and parsed by the job, on a worker (``service.intake``): a
20 MB body never blocks the event loop, and never becomes millions of Python floats.

``/v1/curves/encode`` also takes curve files: an ``application/geo+json`` body (GeoJSON) or an
``image/svg+xml`` one (SVG), coded as one curve set (``wavecore.encode_curves``) with the file's
structure kept; ``tolerance``, ``wavelet`` and ``level`` then come from the query string.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import Response

import wavecore
from wavecore.io import svg as svg_io

from .. import cost
from ..deps import (
    BUNDLE_MEDIA_TYPE,
    array_answer,
    check_array,
    json_body_openapi,
    problem_responses,
    read_json_bytes,
    reject_unknown_query,
    settings_of,
)
from ..errors import Problem
from ..intake import parse_json_body
from ..schemas import (
    CurveEncodeRequest,
    CurveOptions,
    PointsResult,
    TransferOptions,
    TransferRequest,
)
from ..settings import Settings
from ..work import run_work

router = APIRouter(
    prefix="/v1/curves", tags=["curves"], dependencies=[Depends(reject_unknown_query)]
)


def _limits(settings: Settings) -> dict[str, Any]:
    return {"ndim": (2,), "max_count": settings.max_points, "max_dim": settings.max_dimension}


def encode_job(body: bytes | bytearray, settings: Settings) -> tuple[bytes, dict[str, str]]:
    """Parse, check the cost, encode: the whole of ``POST /v1/curves/encode`` off the loop."""
    options, arrays = parse_json_body(body, CurveOptions, {"points": (2,)})
    points = check_array(arrays["points"], "points", **_limits(settings))
    cost.check_curve(
        len(points), points.shape[1], options.closed, options.level, options.wavelet, settings
    )
    bundle = wavecore.encode_curve(points, **options.model_dump(exclude_none=True))
    info = wavecore.inspect(bundle)
    headers = {
        "X-Wavecore-Bytes": str(len(bundle)),
        "X-Wavecore-Ratio": f"{points.nbytes / len(bundle):.3f}",
        "X-Wavecore-Max-Error": f"{info.get('max_error') or 0.0:.6g}",
    }
    return bundle, headers


#: Curve file media types → the format ``wavecore.encode_curve_file`` reads.
CURVE_FILE_TYPES = {"application/geo+json": "geojson", "image/svg+xml": "svg"}

#: The GeoJSON body as /docs shows it: a GeoJSON object (RFC 7946) of any type; the reader
#: checks the rest and names the place of a mistake.
_GEOJSON_SCHEMA = {
    "type": "object",
    "required": ["type"],
    "properties": {
        "type": {
            "type": "string",
            "enum": [
                "FeatureCollection",
                "Feature",
                "GeometryCollection",
                "LineString",
                "MultiLineString",
                "Polygon",
                "MultiPolygon",
            ],
        }
    },
    "description": "A GeoJSON document (RFC 7946): every line and ring becomes one curve.",
}
_SVG_SCHEMA = {
    "type": "string",
    "description": "An SVG document: every subpath of every shape becomes one curve.",
}


def _encode_body_openapi() -> dict[str, Any]:
    """The JSON body of one curve, and the two curve-file bodies (GeoJSON and SVG)."""
    extra = json_body_openapi(CurveEncodeRequest)
    content = extra["requestBody"]["content"]
    content["application/geo+json"] = {"schema": _GEOJSON_SCHEMA}
    content["image/svg+xml"] = {"schema": _SVG_SCHEMA}
    return extra


def curve_file_job(
    body: bytes,
    fmt: str,
    tolerance: float | None,
    wavelet: str | None,
    level: int | None,
    settings: Settings,
    method: str | None = None,
) -> tuple[bytes, dict[str, str]]:
    """Read a GeoJSON or SVG body, check its cost, code it as one curve set.

    An SVG's cost is checked twice: before it is parsed (its parse time, estimated by
    ``scan_svg`` with every ``<use>`` expanded, and the fewest points and curves it gives),
    then with the points and curves it gave.  Its parse time counts in both, a microsecond
    a sample (the scale of ``cost.CURVE_SET_POINT_SAMPLES``)."""
    parse = 0
    if fmt == "svg":
        try:
            work = svg_io.scan_svg(body, limit=cost.sample_limit(settings))
        except wavecore.InvalidParameter as exc:
            raise Problem("invalid-parameter", f"{fmt}: {exc}"[:600]) from None
        parse = work.microseconds
        seconds = f"{work.microseconds / 1e6:.1f} s"
        cost.check(
            parse + cost.curve_set_samples(work.points, work.curves),
            f"an SVG of {work.curves} curves of {work.points} points or more, {seconds} to parse,"
            if work.points
            else f"an SVG that takes over {seconds} to parse",
            settings,
        )

    def check(data: Any) -> None:
        for index, points in enumerate(data.curves):
            if len(points) > settings.max_points:
                msg = (
                    f"curve {index} has {len(points)} points, more than this server's limit of "
                    f"{settings.max_points}"
                )
                raise Problem("too-costly", msg)
        memory = sum(cost.CURVE_FACTOR * len(c) * (c.shape[1] + 1) for c in data.curves)
        total = sum(len(c) for c in data.curves)
        samples = max(memory, parse + cost.curve_set_samples(total, len(data.curves)))
        cost.check(samples, f"{len(data.curves)} curves of {total} points", settings)

    try:
        bundle = wavecore.encode_curve_file(
            body,
            fmt,
            tolerance=tolerance,
            wavelet=wavelet,
            level=level,
            check=check,
            max_points=cost.sample_limit(settings) // (3 * cost.CURVE_FACTOR),
            method=method,
        )
    except wavecore.InvalidParameter as exc:
        raise Problem("invalid-parameter", f"{fmt}: {exc}"[:600]) from None
    info = wavecore.inspect(bundle)
    headers = {
        "X-Wavecore-Bytes": str(len(bundle)),
        "X-Wavecore-Ratio": f"{len(body) / len(bundle):.3f}",
        "X-Wavecore-Max-Error": f"{info['tolerance']:.6g}",
        "X-Wavecore-Curves": str(info["count"]),
    }
    return bundle, headers


@router.post(
    "/encode",
    response_class=Response,
    summary="Encode a curve, or a GeoJSON or SVG file of curves, into a bundle",
    openapi_extra=_encode_body_openapi(),
    responses={
        200: {"content": {BUNDLE_MEDIA_TYPE: {}}, "description": "The bundle."},
        **problem_responses(413, 415, 422, 503),
    },
)
async def encode_curve(
    request: Request,
    tolerance: Annotated[
        float | None,
        Query(gt=0, allow_inf_nan=False, description="GeoJSON/SVG bodies: the guaranteed bound"),
    ] = None,
    wavelet: Annotated[
        Literal["bspline2", "haar", "cdf97"] | None,
        Query(description="GeoJSON/SVG bodies: the wavelet (default bspline2)"),
    ] = None,
    level: Annotated[
        int | None, Query(ge=0, le=24, description="GeoJSON/SVG bodies: the most levels")
    ] = None,
    method: Annotated[
        Literal["auto", "wavelet", "vertex"] | None,
        Query(
            description="GeoJSON/SVG bodies: the curve-set form (default auto: the smaller of "
            "the wavelet form and the vertex form; docs/curves.md)"
        ),
    ] = None,
) -> Response:
    """Without `keep` or `tolerance` the largest point deviation is 1e-3 × the bounding box's
    diagonal.  `X-Wavecore-Max-Error` gives the measured largest deviation.

    A GeoJSON (`application/geo+json`) or SVG (`image/svg+xml`) body is coded as one curve set:
    every line, ring and subpath a curve, every point within `tolerance` (query) both ways,
    features, properties and paint kept; `X-Wavecore-Max-Error` is then the guaranteed bound."""
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    settings = settings_of(request)
    if content_type in CURVE_FILE_TYPES:
        fmt = CURVE_FILE_TYPES[content_type]
        data = await request.body()
        bundle, headers = await run_work(
            request, curve_file_job, data, fmt, tolerance, wavelet, level, settings, method
        )
        return Response(bundle, media_type=BUNDLE_MEDIA_TYPE, headers=headers)
    body = await read_json_bytes(request)
    bundle, headers = await run_work(request, encode_job, body, settings)
    return Response(bundle, media_type=BUNDLE_MEDIA_TYPE, headers=headers)


def transfer_job(body: bytes | bytearray, settings: Settings) -> bytes:
    """Parse, check the level and the cost, transfer, write the JSON answer."""
    options, arrays = parse_json_body(body, TransferOptions, {"source": (2,), "base": (2,)})
    source = check_array(arrays["source"], "source", **_limits(settings))
    base = check_array(arrays["base"], "base", **_limits(settings))
    cost.check_transfer(len(source), source.shape[1], options.closed, options.level, settings)
    result = np.asarray(
        wavecore.transfer_details(source, base, closed=options.closed, level=options.level)
    )
    if result.dtype.kind == "f" and not np.all(np.isfinite(result)):
        msg = "the transfer gives NaN or infinite values; scale the curves to smaller numbers"
        raise Problem("invalid-parameter", msg)
    return array_answer("curve", result, "points")


@router.post(
    "/transfer",
    response_class=Response,
    summary="Put one curve's details onto another coarse curve (the paper's figure 1)",
    openapi_extra=json_body_openapi(TransferRequest),
    responses={
        200: {
            "content": {"application/json": {"schema": PointsResult.model_json_schema()}},
            "description": "The new curve.",
        },
        **problem_responses(413, 415, 422, 503),
    },
)
async def transfer(request: Request) -> Response:
    """Decomposes `source`, replaces its coarse curve by `base` (re-sampled by arc length to
    the coarse length) and reconstructs with `source`'s details: the new curve has as many
    points as `source`."""
    body = await read_json_bytes(request)
    answer = await run_work(request, transfer_job, body, settings_of(request))
    return Response(answer, media_type="application/json")
