"""``POST /v1/curves/encode`` and ``POST /v1/curves/transfer``."""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter, Request
from fastapi.responses import Response

import wavecore

from ..deps import BUNDLE_MEDIA_TYPE, as_points, finite_list, problem_responses, settings_of
from ..schemas import CurveEncodeRequest, PointsResult, TransferRequest
from ..work import run_work

router = APIRouter(prefix="/v1/curves", tags=["curves"])


def _encode(points: np.ndarray, options: dict[str, Any]) -> tuple[bytes, dict[str, str]]:
    bundle = wavecore.encode_curve(points, **options)
    info = wavecore.inspect(bundle)
    headers = {
        "X-Wavecore-Bytes": str(len(bundle)),
        "X-Wavecore-Ratio": f"{points.nbytes / len(bundle):.3f}",
        "X-Wavecore-Max-Error": f"{info.get('max_error') or 0.0:.6g}",
    }
    return bundle, headers


@router.post(
    "/encode",
    response_class=Response,
    summary="Encode a curve into a bundle",
    responses={
        200: {"content": {BUNDLE_MEDIA_TYPE: {}}, "description": "The bundle."},
        **problem_responses(413, 422, 503),
    },
)
async def encode_curve(request: Request, body: CurveEncodeRequest) -> Response:
    """Without `keep` or `tolerance` the largest point deviation is 1e-3 × the bounding box's
    diagonal.  `X-Wavecore-Max-Error` gives the measured largest deviation."""
    settings = settings_of(request)
    points = as_points(
        body.points,
        "points",
        ndim=(2,),
        max_count=settings.max_points,
        max_dim=settings.max_dimension,
    )
    options = body.model_dump(exclude={"points"}, exclude_none=True)
    bundle, headers = await run_work(request, _encode, points, options)
    return Response(bundle, media_type=BUNDLE_MEDIA_TYPE, headers=headers)


def _transfer(source: np.ndarray, base: np.ndarray, closed: bool, level: int | None) -> Any:
    return wavecore.transfer_details(source, base, closed=closed, level=level)


@router.post(
    "/transfer",
    summary="Put one curve's details onto another coarse curve (the paper's figure 1)",
    responses=problem_responses(413, 422, 503),
)
async def transfer(request: Request, body: TransferRequest) -> PointsResult:
    """Decomposes `source`, replaces its coarse curve by `base` (re-sampled by arc length to
    the coarse length) and reconstructs with `source`'s details: the new curve has as many
    points as `source`."""
    settings = settings_of(request)
    limits = {"ndim": (2,), "max_count": settings.max_points, "max_dim": settings.max_dimension}
    source = as_points(body.source, "source", **limits)  # type: ignore[arg-type]
    base = as_points(body.base, "base", **limits)  # type: ignore[arg-type]
    result = await run_work(request, _transfer, source, base, body.closed, body.level)
    arr = np.asarray(result)
    return PointsResult(shape=list(arr.shape), dtype=str(arr.dtype), points=finite_list(arr))
