"""``POST /v1/grids/encode``: a ``.npy`` or (Geo)TIFF height field or volume, a bundle out."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, File, Form, Request, UploadFile
from fastapi.responses import Response

import wavecore

from .. import cost
from ..deps import BUNDLE_MEDIA_TYPE, problem_responses, reject_unknown_query, settings_of
from ..errors import Problem
from ..gridfiles import GridFileError, read_grid_file
from ..settings import Settings
from ..work import run_work

router = APIRouter(prefix="/v1/grids", tags=["grids"], dependencies=[Depends(reject_unknown_query)])


def _figure(value: float | None) -> str:
    if value is None:
        return "none"
    return f"{value:.6g}"


def encode_job(
    data: bytes, options: dict[str, Any], settings: Settings
) -> tuple[bytes, dict[str, str]]:
    """Read the file (its header first), check the cost, encode: all on a worker."""
    max_values = settings.max_grid_points * settings.max_dimension
    try:
        grid = read_grid_file(data, "file", max_elements=max_values)
    except GridFileError as exc:
        errors = [{"loc": ["body", "file"], "msg": str(exc), "type": "value_error"}]
        raise Problem(exc.kind, str(exc), errors=errors) from None
    if grid.ndim not in (2, 3):
        msg = f"file has shape {list(grid.shape)}; a grid is (H, W) or a volume (D, H, W)"
        errors = [{"loc": ["body", "file"], "msg": msg, "type": "value_error"}]
        raise Problem("invalid-parameter", msg, errors=errors)
    cost.check_grid_data(grid.shape, options.get("level"), settings)
    bundle = wavecore.encode_grid(grid, **options)
    info = wavecore.inspect(bundle)
    headers = {
        "X-Wavecore-Bytes": str(len(bundle)),
        "X-Wavecore-Ratio": f"{grid.nbytes / len(bundle):.3f}",
        "X-Wavecore-Max-Error": _figure(info["largest_error"]),
        "X-Wavecore-RMSE": _figure(info["rmse"]),
        "X-Wavecore-Bound": _figure(info["max_error"]),
        "X-Wavecore-Shape": "x".join(str(s) for s in grid.shape),
        "X-Wavecore-Dtype": np.dtype(grid.dtype).name,
    }
    return bundle, headers


@router.post(
    "/encode",
    response_class=Response,
    summary="Encode a height field or a volume (.npy, GeoTIFF or 16-bit TIFF) into a bundle",
    responses={
        200: {
            "content": {BUNDLE_MEDIA_TYPE: {}},
            "description": "The bundle, with its measured figures in X-Wavecore-* headers.",
        },
        **problem_responses(413, 415, 422, 503),
    },
)
async def encode_grid(
    request: Request,
    file: Annotated[
        UploadFile,
        File(description="A .npy (H, W) or (D, H, W) array, or a (Geo)TIFF height map"),
    ],
    wavelet: Annotated[
        str | None, Form(description="cdf97 (default), bspline2 (the paper's) or haar")
    ] = None,
    level: Annotated[int | None, Form(ge=0, description="Levels; empty picks up to 5")] = None,
    max_error: Annotated[
        float | None,
        Form(ge=0, allow_inf_nan=False, description="Largest absolute error, on every sample"),
    ] = None,
    rmse: Annotated[
        float | None, Form(gt=0, allow_inf_nan=False, description="Target RMSE")
    ] = None,
    psnr: Annotated[
        float | None, Form(gt=0, allow_inf_nan=False, description="Target PSNR (dB, range)")
    ] = None,
    bpp: Annotated[
        float | None, Form(gt=0, allow_inf_nan=False, description="Bits per sample")
    ] = None,
    lossless: Annotated[bool, Form(description="Bit-exact (integer grids)")] = False,
) -> Response:
    """At most one of `max_error`, `rmse`, `psnr`, `bpp` and `lossless`; without one the
    grid is coded to a largest error of 0.001 × its range.  NaN cells (and a GeoTIFF's
    no-data cells) decode as NaN.  The response headers carry the bundle's size, the
    compression ratio against the raw samples, and the encoder's measured largest error and
    RMSE (`X-Wavecore-Max-Error`, `X-Wavecore-RMSE`) and the bound that holds
    (`X-Wavecore-Bound`, `none` without one)."""
    options: dict[str, Any] = {"level": level, "lossless": lossless}
    named = (
        ("wavelet", wavelet),
        ("max_error", max_error),
        ("rmse", rmse),
        ("psnr", psnr),
        ("bpp", bpp),
    )
    for name, value in named:
        if value is not None:
            options[name] = value
    data = await file.read()
    bundle, headers = await run_work(request, encode_job, data, options, settings_of(request))
    return Response(bundle, media_type=BUNDLE_MEDIA_TYPE, headers=headers)
