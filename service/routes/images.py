"""``POST /v1/images/encode``: an image file in, a bundle out."""

from __future__ import annotations

import io
import warnings
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, Depends, File, Form, Request, UploadFile
from fastapi.responses import Response
from PIL import Image

import wavecore

from .. import cost
from ..deps import BUNDLE_MEDIA_TYPE, problem_responses, reject_unknown_query, settings_of
from ..imaging import read_image
from ..settings import Settings
from ..work import run_work

router = APIRouter(
    prefix="/v1/images", tags=["images"], dependencies=[Depends(reject_unknown_query)]
)


def _format(value: float | None) -> str:
    if value is None:
        return "inf"
    return f"{value:.4g}" if np.isfinite(value) else str(value)


#: Channels after ``read_image``'s conversion, by Pillow mode (at most, for the cost check).
_MODE_CHANNELS = {"1": 1, "L": 1, "I": 1, "F": 1, "LA": 2, "La": 2, "P": 4, "PA": 4}


def _header_size(data: bytes) -> tuple[int, int, int] | None:
    """Width, height and channels from the file's header, or None when Pillow cannot tell
    (``read_image`` then answers with the precise problem)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as image:
                width, height = image.size
                mode = image.mode
    except Exception:
        return None
    channels = _MODE_CHANNELS.get(mode, 1 if mode.startswith("I;16") else 4)
    return width, height, channels


def encode_job(
    data: bytes, options: dict[str, Any], settings: Settings
) -> tuple[bytes, dict[str, str]]:
    """Check the cost from the header, decode the file, encode: all on a worker."""
    size = _header_size(data)
    if size is not None and size[0] * size[1] <= settings.max_pixels:
        cost.check_image(*size, options, settings)
    image = read_image(data, max_pixels=settings.max_pixels)
    bundle = wavecore.encode_image(image, **options)
    info = wavecore.inspect(bundle)
    height, width = image.shape[:2]
    headers = {
        "X-Wavecore-Bytes": str(len(bundle)),
        "X-Wavecore-Bpp": f"{8 * len(bundle) / (height * width):.4f}",
        "X-Wavecore-Ratio": f"{image.nbytes / len(bundle):.3f}",
        # None when the bundle is exact (lossless): an infinite PSNR.
        "X-Wavecore-PSNR": _format(info.get("psnr")),
        "X-Wavecore-Shape": "x".join(str(s) for s in image.shape),
        "X-Wavecore-Dtype": str(image.dtype),
        # The wavelet coded with: wavelet="auto" names its choice here.
        "X-Wavecore-Wavelet": str(info["wavelet"]),
        # 2, 4, …: a picture enlarged by pixel replication, coded as its source (1: any other).
        "X-Wavecore-Replicated": str(info.get("replicated", 1)),
    }
    return bundle, headers


@router.post(
    "/encode",
    response_class=Response,
    summary="Encode an image file into a bundle",
    responses={
        200: {
            "content": {BUNDLE_MEDIA_TYPE: {}},
            "description": "The bundle, with its measured figures in X-Wavecore-* headers.",
        },
        **problem_responses(413, 415, 422, 503),
    },
)
async def encode_image(
    request: Request,
    file: Annotated[UploadFile, File(description="PNG, JPEG, TIFF, BMP, WebP, … (Pillow)")],
    wavelet: Annotated[
        str,
        Form(
            description="auto (default: cdf97, the best measured rate–distortion on "
            "photographs, or haar for pictures of mostly flat 2 × 2 blocks such as "
            "pixel-replicated or two-tone graphics), cdf97, bspline2 (the paper's, smooth) or "
            "haar"
        ),
    ] = "auto",
    level: Annotated[int | None, Form(ge=0, description="Levels; empty picks up to 5")] = None,
    keep: Annotated[
        float | None, Form(ge=0, le=1, allow_inf_nan=False, description="Fraction kept")
    ] = None,
    quality: Annotated[
        float | None, Form(gt=0, allow_inf_nan=False, description="Target PSNR (dB)")
    ] = None,
    bpp: Annotated[
        float | None, Form(gt=0, allow_inf_nan=False, description="Target bits per pixel")
    ] = None,
    lossless: Annotated[bool, Form(description="Bit-exact (8/16-bit images)")] = False,
    effort: Annotated[
        Literal["default", "max", "fast"],
        Form(
            description="With lossless: default (the lossless coder, smaller than JPEG XL e7; "
            "max is the same) or fast (the block coder: a few % bigger, quicker, regions by "
            "blocks)"
        ),
    ] = "default",
) -> Response:
    """The image is coded to `quality=40` dB unless `keep`, `quality`, `bpp` or `lossless`
    say otherwise (at most one of them).  The response headers carry the bundle's size
    (`X-Wavecore-Bytes`), bits per pixel, compression ratio against the raw pixels and the
    encoder's measured PSNR (`inf` when lossless)."""
    options: dict[str, Any] = {"wavelet": wavelet, "level": level, "lossless": lossless}
    if effort != "default":  # only then, so that the default call is the library's default
        options["effort"] = effort
    for name, value in (("keep", keep), ("quality", quality), ("bpp", bpp)):
        if value is not None:
            options[name] = value
    data = await file.read()
    bundle, headers = await run_work(request, encode_job, data, options, settings_of(request))
    return Response(bundle, media_type=BUNDLE_MEDIA_TYPE, headers=headers)
