"""Peer codecs configured as their best users configure them, and the Bjøntegaard delta rate.

Used by ``benchmarks/rate_distortion.py --peers`` (lossy) and ``benchmarks/lossless.py``.

Lossy peers (each swept over its own quality knob, then interpolated at exact rates):

* OpenJPEG through Pillow: irreversible 9/7, the colour transform on (``mct=1``), a raw
  codestream (``no_jp2=True``, no JP2 box overhead), 6 resolutions, one layer at a given ratio;
* JPEG through Pillow (libjpeg-turbo): ``optimize=True``, 4:2:0 and 4:4:4 (grey has no
  chroma, so only one JPEG curve);
* WebP through Pillow: ``method=6`` (its slowest, best);
* AVIF through Pillow (libavif, Pillow ≥ 11.2): ``speed=6``, 4:2:0 and 4:4:4 (grey: 4:0:0);
* JPEG XL through ``imagecodecs`` (libjxl): ``effort=7`` (libjxl's default), swept over
  ``distance``.  imagecodecs is the maintained binding that ships libjxl in its wheels.

Lossless peers: PNG ``optimize=True``, WebP lossless (``method=6``), JPEG XL lossless effort 7,
OpenJPEG reversible 5/3 with ``mct=1`` as a raw codestream.

Rates are whole files in bits per pixel (``8 × bytes / (H × W)``, all channels); PSNR is over
all samples with peak 255; SSIM is scikit-image's (``data_range=255``, over the channels for
colour).
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from PIL import Image, features
from scipy.interpolate import PchipInterpolator
from skimage.metrics import structural_similarity

#: The exact rates every curve is interpolated at (bits per pixel), log-spaced over 0.25–2.
EXACT_RATES = tuple(float(r) for r in np.geomspace(0.25, 2.0, 7))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(255.0**2 / mse)


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    channel_axis = -1 if a.ndim == 3 else None
    return float(structural_similarity(a, b, data_range=255, channel_axis=channel_axis))


def _pillow(image: np.ndarray, fmt: str, **options: Any) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format=fmt, **options)
    return buffer.getvalue()


def _decode(blob: bytes, like: np.ndarray) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(blob)).convert("L" if like.ndim == 2 else "RGB"))


def _openjpeg(image: np.ndarray, ratio: float) -> bytes:
    return _pillow(
        image,
        "JPEG2000",
        quality_mode="rates",
        quality_layers=[ratio],
        irreversible=True,
        num_resolutions=6,
        mct=int(image.ndim == 3),
        no_jp2=True,
    )


def _jxl_encode(image: np.ndarray, distance: float) -> bytes:
    import imagecodecs

    return bytes(imagecodecs.jpegxl_encode(image, effort=7, distance=distance))


def _jxl_decode(blob: bytes, like: np.ndarray) -> np.ndarray:
    import imagecodecs

    out = np.asarray(imagecodecs.jpegxl_decode(blob))
    return out.reshape(like.shape)


def avif_available() -> bool:
    return bool(features.check("avif"))


def jxl_available() -> bool:
    try:
        import imagecodecs

        return bool(imagecodecs.JPEGXL.available)
    except (ImportError, AttributeError):
        return False


#: codec name -> (the knob's sweep, encode(image, knob) -> bytes, decode(bytes, like) -> array)
Lossy = tuple[tuple[float, ...], Callable[[np.ndarray, float], bytes], Callable[..., np.ndarray]]


def lossy_peers(colour: bool) -> dict[str, Lossy]:
    """The lossy peers for a grey or a colour picture (4:4:4 variants only for colour)."""
    qualities = (*(float(q) for q in range(2, 99, 4)), 100.0)
    channels = 3 if colour else 1
    # OpenJPEG's knob is the compression ratio against the raw 8-bit samples.
    ratios = tuple(8 * channels / r for r in np.geomspace(0.18, 2.8, 18))
    peers: dict[str, Lossy] = {
        "OpenJPEG": (ratios, _openjpeg, _decode),
        "JPEG 4:2:0": (
            qualities,
            lambda im, q: _pillow(im, "JPEG", quality=int(q), optimize=True, subsampling=2),
            _decode,
        ),
    }
    if colour:
        peers["JPEG 4:4:4"] = (
            qualities,
            lambda im, q: _pillow(im, "JPEG", quality=int(q), optimize=True, subsampling=0),
            _decode,
        )
    peers["WebP m6"] = (
        qualities,
        lambda im, q: _pillow(im, "WEBP", quality=int(q), method=6),
        _decode,
    )
    if avif_available():
        # A grey picture is coded monochrome (4:0:0), as a user of a grey picture would.
        first = "4:2:0" if colour else "4:0:0"
        peers["AVIF s6"] = (
            qualities,
            lambda im, q: _pillow(im, "AVIF", quality=int(q), speed=6, subsampling=first),
            _decode,
        )
        if colour:
            peers["AVIF s6 4:4:4"] = (
                qualities,
                lambda im, q: _pillow(im, "AVIF", quality=int(q), speed=6, subsampling="4:4:4"),
                _decode,
            )
    if jxl_available():
        # libjxl accepts distances up to 25; 0.05 is close to lossless.
        distances = tuple(float(d) for d in np.geomspace(0.05, 25.0, 22))
        peers["JPEG XL e7"] = (distances, _jxl_encode, _jxl_decode)
    return peers


def sweep(image: np.ndarray, peer: Lossy) -> list[tuple[float, float, float]]:
    """(bpp, PSNR, SSIM) of every point of the peer's knob sweep, sorted by rate."""
    knobs, encode, decode = peer
    pixels = image.shape[0] * image.shape[1]
    points = []
    for knob in knobs:
        blob = encode(image, knob)
        decoded = decode(blob, image)
        points.append((8 * len(blob) / pixels, psnr(decoded, image), ssim(decoded, image)))
    return sorted(points)


def at_rates(
    points: list[tuple[float, float, float]], rates: tuple[float, ...] = EXACT_RATES
) -> list[tuple[float, float]]:
    """(PSNR, SSIM) at each exact rate, interpolated piecewise-cubically over log-rate.

    Points out of order (a knob step that made the file larger and worse) are dropped so the
    curve is increasing; a rate outside the swept range gives NaN rather than an extrapolation.
    """
    kept: list[tuple[float, float, float]] = []
    for point in points:
        if not math.isfinite(point[1]):  # a knob at its top may be lossless: no PSNR to fit
            continue
        if kept and (point[0] <= kept[-1][0] or point[1] <= kept[-1][1]):
            continue
        kept.append(point)
    log_rates = np.log([p[0] for p in kept])
    psnr_curve = PchipInterpolator(log_rates, [p[1] for p in kept], extrapolate=False)
    ssim_curve = PchipInterpolator(log_rates, [p[2] for p in kept], extrapolate=False)
    out = []
    for rate in rates:
        x = math.log(rate)
        out.append((float(psnr_curve(x)), float(ssim_curve(x))))
    return out


def bd_rate(rates: tuple[float, ...], reference: list[float], test: list[float]) -> float:
    """Bjøntegaard delta rate of ``test`` against ``reference``, in percent.

    Both curves are PSNRs at the same ``rates``.  Log-rate is interpolated as a piecewise-cubic
    (monotone, PCHIP) function of PSNR, as in the usual piecewise-cubic variant of VCEG-M33, and
    integrated over the PSNR range both curves cover; the mean difference is turned back into a
    rate ratio.  Negative: ``test`` needs fewer bits for the same PSNR.
    """
    log_rates = np.log(rates)
    ok_ref = np.isfinite(reference)
    ok_test = np.isfinite(test)
    if ok_ref.sum() < 2 or ok_test.sum() < 2:
        return math.nan
    ref_q, ref_r = np.asarray(reference)[ok_ref], log_rates[ok_ref]
    test_q, test_r = np.asarray(test)[ok_test], log_rates[ok_test]
    low = max(ref_q.min(), test_q.min())
    high = min(ref_q.max(), test_q.max())
    if not high > low:
        return math.nan
    ref_curve = PchipInterpolator(ref_q, ref_r)
    test_curve = PchipInterpolator(test_q, test_r)
    difference = (test_curve.integrate(low, high) - ref_curve.integrate(low, high)) / (high - low)
    return float(100.0 * (math.exp(difference) - 1.0))


#: Lossless peers: name -> (encode(image) -> bytes, decode(bytes, like) -> array).
def lossless_peers(colour: bool) -> dict[str, tuple[Callable[..., bytes], Callable[..., Any]]]:
    peers: dict[str, tuple[Callable[..., bytes], Callable[..., Any]]] = {
        "PNG": (lambda im: _pillow(im, "PNG", optimize=True), _decode),
        "WebP lossless": (
            lambda im: _pillow(im, "WEBP", lossless=True, quality=100, method=6),
            _decode,
        ),
        "OpenJPEG lossless": (
            lambda im: _pillow(
                im, "JPEG2000", irreversible=False, mct=int(colour), no_jp2=True, num_resolutions=6
            ),
            _decode,
        ),
    }
    if jxl_available():
        import imagecodecs

        peers["JPEG XL e7"] = (
            lambda im: bytes(imagecodecs.jpegxl_encode(im, lossless=True, effort=7)),
            _jxl_decode,
        )
    return peers
