"""The sample domain: the transform both ways, colour, dtype, the exact scaling of huge or tiny
floats, and the error metrics (PSNR, largest error) that the rate control measures."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._kernels import (
    colour_to_floats,
    colour_to_integers,
    finite_floats,
    squared_and_largest_error,
    squared_and_largest_integer_error,
)
from ..colour import KLT_PREFIX, YCBCR_INVERSE_MATRIX, YCBCR_MATRIX, klt_matrix
from ..errors import InvalidParameter
from ..filters import get_wavelet
from ..transform import run_rows, synthesis_2d_integers
from .plan import Plan, fit
from .stages import Transform, WaveletTransform, get_colour

#: Float data whose largest magnitude lies outside ``[2**-256, 2**256]`` is coded in a scaled
#: domain, multiplied by an exact power of two (recorded as the header's ``scale``), so that
#: squares, sums and steps never overflow or underflow; ordinary data is coded unscaled, as
#: before (its bundles do not change).
_UNSCALED_EXPONENT = 256
_LARGEST_FLOAT = float(np.finfo(np.float64).max)


def decompose(plan: Plan, data: np.ndarray) -> list[Any]:
    """The plan's transform of the (colour-transformed, fitted) samples."""
    return plan.transform.forward(data, plan.levels)


def reconstruct(plan: Plan, coeffs: list[Any]) -> np.ndarray:
    """The plan's inverse transform (before cropping and the inverse colour transform)."""
    return plan.transform.inverse(coeffs, plan)


def reconstruct_finished(
    plan: Plan, coeffs: list[Any], level: int = 0, transform: Transform | None = None
) -> np.ndarray:
    """``finish(plan, transform.inverse(coeffs, plan), level)``: the decoded samples.

    ``transform`` defaults to the plan's.  For the common picture (an integer dtype, a wavelet
    transform over both axes, the full resolution) the last level's synthesis runs fused with
    the crop and the colour and rounding pass, and writes the integers directly: the fine
    picture in float64 (a 2048² RGB one is 100 MB of fresh pages, faulted in on every call)
    is never made.  The same values either way.
    """
    transform = plan.transform if transform is None else transform
    coeffs = list(coeffs)
    fused = _fused_last_level(plan, coeffs, level, transform)
    if fused is not None:
        return fused
    return finish(plan, transform.inverse(coeffs, plan), level)


def _fused_last_level(
    plan: Plan, coeffs: list[Any], level: int, transform: Any
) -> np.ndarray | None:
    colour = get_colour({"id": plan.colour})
    if (
        level != 0
        or plan.kind != "image"
        or plan.scale
        or not isinstance(transform, WaveletTransform)
        or len(transform.boundary) != 2
        or len(coeffs) < 2
        or np.dtype(plan.dtype).kind not in "iu"
        or (colour.inverse_matrix is None and plan.colour != "none")
    ):
        return None
    last = coeffs[-1]
    if not isinstance(last, tuple | list) or len(last) != 3 or any(b is None for b in last):
        return None
    # The coarser levels as the transform does them; then the finest level, fused.
    coarse = coeffs[0] if len(coeffs) == 2 else transform.inverse(coeffs[:-1], plan)
    coarse = np.asarray(coarse)
    (before0, after0), (before1, after1) = plan.pads
    m0, m1 = plan.fitted[0], plan.fitted[1]
    window = ((before0, m0 - after0), (before1, m1 - after1))
    out = synthesis_2d_integers(
        (coarse, last[1], last[0], last[2]),  # (cH, cV, cD) are the (da, ad, dd) bands
        get_wavelet(transform.wavelet),
        (transform.boundary[0], transform.boundary[1]),
        window,
        np.dtype(plan.dtype),
        colour.inverse_matrix,
    )
    if out is None:  # not fusable after all: the finest level as the transform does it
        return finish(plan, transform.inverse([coarse, last], plan), level)
    if out.shape != tuple(plan.shape):
        return None
    if plan.opaque:  # as finish does
        out[..., -1] = _opaque_value(out.dtype)
    return out


def finish(plan: Plan, data: np.ndarray, level: int) -> np.ndarray:
    """Transformed-domain samples → the caller's array: crop, inverse colour, shape, dtype."""
    out = _finish_samples(plan, data, level)
    if plan.opaque:
        # An opaque alpha channel comes back exactly opaque, whatever the quantizer did to it:
        # a picture that was opaque must not turn faintly translucent.
        out[..., -1] = _opaque_value(out.dtype)
    return out


def _opaque_value(dtype: np.dtype[Any]) -> float:
    return float(np.iinfo(dtype).max) if dtype.kind in "iu" else 1.0


def is_opaque(arr: np.ndarray) -> bool:
    """An image whose alpha channel (the last of 2 or 4) is fully opaque: the dtype's largest
    value for integers, 1.0 for floats."""
    if arr.ndim != 3 or arr.shape[2] not in (2, 4):
        return False
    return bool(np.all(arr[..., -1] == _opaque_value(arr.dtype)))


def _finish_samples(plan: Plan, data: np.ndarray, level: int) -> np.ndarray:
    cropped = plan.transform.crop(data, plan, level)
    colour = get_colour({"id": plan.colour})
    if colour.inverse_matrix is not None and np.dtype(plan.dtype).kind in "iu":
        # The common case, in one pass: colour matrix, rounding and clipping together.
        return to_integers(np.asarray(cropped, dtype=np.float64), plan.dtype, colour.inverse_matrix)
    cropped = colour.inverse(cropped)
    if len(plan.shape) == 1:  # a 1-D curve (a time series) was coded as (n, 1)
        cropped = cropped[:, 0]
    if plan.scale:
        # Clipped first, so that a value just past the largest float does not become infinite.
        limit = math.ldexp(_LARGEST_FLOAT, -plan.scale) if plan.scale > 0 else math.inf
        cropped = np.ldexp(np.clip(cropped, -limit, limit), plan.scale)
    return cast(cropped, plan.dtype)


def scaled(arr: np.ndarray) -> tuple[np.ndarray, int]:
    """``(arr × 2**-scale, scale)``: float data brought near magnitude 1 when it is huge or tiny.

    A power of two is exact (no rounding, short of underflow far below the peak), so any finite
    float64 round-trips within the requested target, from subnormals to ``±1.7e308``.
    """
    if arr.dtype.kind != "f":
        return arr, 0
    largest = np.max(np.abs(arr))
    if largest == 0:
        return arr, 0
    exponent = int(np.frexp(largest)[1])
    if abs(exponent) <= _UNSCALED_EXPONENT:
        return arr, 0
    if not -1073 <= exponent <= 1024:  # only a longdouble gets here: it comes back as float64
        msg = (
            f"the data's largest magnitude, {largest!r}, is outside the float64 range that a "
            "bundle stores (5e-324 to 1.8e308 for the largest magnitude)"
        )
        raise InvalidParameter(msg)
    return np.ldexp(arr, -exponent).astype(np.float64), exponent


def scaled_tolerance(tolerance: float, scale: int) -> float:
    """A distance in the original's units → the coded units (``tolerance × 2**-scale``)."""
    if not scale:
        return tolerance
    try:
        scaled = math.ldexp(tolerance, -scale)
    except OverflowError:
        return _LARGEST_FLOAT
    if scaled == 0.0:
        msg = (
            f"tolerance {tolerance!r} is below what float64 can resolve for points as large as "
            f"2**{scale}; ask for a larger tolerance"
        )
        raise InvalidParameter(msg)
    return scaled


def unscaled(value: float, scale: int) -> float:
    """A scaled-domain distance back in the original's units (capped at the largest float)."""
    try:
        return min(math.ldexp(value, scale), _LARGEST_FLOAT)
    except OverflowError:
        return _LARGEST_FLOAT


def to_integers(data: np.ndarray, dtype: str, matrix: np.ndarray | None) -> np.ndarray:
    """Float64 ``(H, W)`` or ``(H, W, C)`` samples rounded and clipped into an integer dtype
    (NaN → 0), after ``matrix`` on the first three channels when given: one compiled pass in
    threads, where NumPy made five full-size float64 temporaries."""
    info = np.iinfo(dtype)
    src = data if data.ndim == 3 else data[:, :, None]
    out = np.empty(src.shape, dtype=dtype)
    colours = YCBCR_INVERSE_MATRIX if matrix is None else matrix  # unused when matrix is None
    lo, hi = float(info.min), float(info.max)
    run_rows(
        lambda a, b: colour_to_integers(src, colours, matrix is not None, lo, hi, out, a, b),
        src.shape[0],
        src.size,
    )
    return out.reshape(data.shape)


def ycbcr_from(rgb: np.ndarray, matrix: np.ndarray = YCBCR_MATRIX) -> np.ndarray:
    """``ycbcr_forward(rgb.astype(float64))`` (or another forward ``matrix`` on the first three
    channels), by one compiled pass in threads."""
    if rgb.dtype in _UNCOMPILED_DTYPES:
        out = rgb.astype(np.float64)
        out[..., :3] = out[..., :3] @ matrix.T
        return out
    out = np.empty(rgb.shape, dtype=np.float64)
    run_rows(lambda lo, hi: colour_to_floats(rgb, matrix, out, lo, hi), rgb.shape[0], rgb.size)
    return out


def forward_matrix(colour: str) -> np.ndarray | None:
    """The lossy colour transform's forward matrix (``ycbcr`` or a per-picture
    ``klt:...``), or None for any other colour."""
    if colour == "ycbcr":
        return YCBCR_MATRIX
    if colour.startswith(KLT_PREFIX):
        return klt_matrix(colour)
    return None


def fitted_samples(
    arr: np.ndarray,
    colour: str,
    level: int | None,
    wavelet: str,
    boundary: Sequence[str],
    most: int,
) -> tuple[np.ndarray, tuple[tuple[int, int], ...], int]:
    """``fit(ycbcr_from(arr, matrix) if colour is ycbcr or a matrix else arr.astype(float64),
    ...)``, the same
    values, with the colour transform (or the conversion to float64) written straight into the
    fitted array: the unpadded float64 picture is never made, nor its pages faulted in (a 2048²
    RGB picture's are 100 MB, tens of milliseconds of kernel time on two threads at once)."""
    matrix = forward_matrix(colour)
    if matrix is not None and arr.dtype in _UNCOMPILED_DTYPES:
        return fit(ycbcr_from(arr, matrix), level, wavelet, boundary, most)
    if matrix is not None:
        forward = matrix

        def convert(out: np.ndarray, lo: int, hi: int) -> None:
            colour_to_floats(arr, forward, out, lo, hi)

    else:
        columns = arr.shape[1]

        def convert(out: np.ndarray, lo: int, hi: int) -> None:
            out[lo:hi, :columns] = arr[lo:hi]  # assignment casts as astype(float64) does

    return fit(arr, level, wavelet, boundary, most, convert=convert)


def cast(data: np.ndarray, dtype: str) -> np.ndarray:
    target = np.dtype(dtype)
    if target.kind in "iu" and data.dtype == np.float64 and data.ndim in (2, 3):
        return to_integers(data, dtype, None)
    if target.kind in "iu" and data.dtype.kind in "iu" and target.itemsize <= 4:
        # Integers (the lossless path) clipped as integers: the float64 route below gives
        # the same values (every integer that survives the clip is exact in float64), after
        # four full-size passes instead of two.
        info = np.iinfo(target)
        return np.clip(data, info.min, info.max).astype(target)
    if target.kind in "iu":
        info = np.iinfo(target)
        values = np.nan_to_num(np.asarray(data, dtype=np.float64), nan=0.0)
        return np.clip(np.rint(values), info.min, info.max).astype(target)
    rows_of = data.ndim == 2 or (data.ndim == 3 and data.flags.c_contiguous)
    if target.kind == "f" and target.itemsize in (4, 8) and data.dtype == np.float64 and rows_of:
        # The same values in one compiled pass over the threads (_kernels.finite_floats).
        largest = float(np.finfo(target).max)
        rows = data if data.ndim == 2 else data.reshape(-1, data.shape[-1])
        out = np.empty(rows.shape, dtype=target)
        run_rows(lambda a, b: finite_floats(rows, largest, out, a, b), rows.shape[0], rows.size)
        return out.reshape(data.shape)
    values = np.nan_to_num(np.asarray(data, dtype=np.float64))
    if target.itemsize < 8:
        # A float16/float32 original near its dtype's largest value may decode a little beyond
        # it: saturate, rather than turn it into infinity.
        largest = float(np.finfo(target).max)
        values = np.clip(values, -largest, largest)
    return values.astype(target, copy=False)  # values is already a new array


#: Dtypes the compiled loops do not take (NumPy handles them instead).
_UNCOMPILED_DTYPES = {np.dtype(np.float16), np.dtype(np.longdouble)}


def measure_errors(
    plan: Plan, original: np.ndarray, decoded: np.ndarray
) -> tuple[float | None, float]:
    """(PSNR in dB or None when exact, largest error: per sample, or per point for curves).

    An image's alpha channel (the last of 2 or 4) that decodes exactly, as an opaque one does,
    is left out: counting its zero errors would lift the PSNR above what the colours get (an
    opaque RGBA picture coded to 35 dB showed 33.77 dB on its RGB).  So the quality targets
    hold on the colour channels, and the figure is the one a viewer of the colours measures.
    """
    if (
        plan.kind == "image"
        and decoded.ndim == 3
        and decoded.shape[2] in (2, 4)
        and np.array_equal(decoded[..., -1], original[..., -1])
    ):
        decoded, original = decoded[..., :-1], original[..., :-1]
    per_point = plan.kind == "curve" and decoded.ndim == 2
    if not per_point and {decoded.dtype, original.dtype}.isdisjoint(_UNCOMPILED_DTYPES):
        # One compiled pass: pictures are large, and the rate searches measure them often.
        total, largest = _squared_and_largest_error(
            np.ascontiguousarray(decoded).ravel(), np.ascontiguousarray(original).ravel()
        )
        return _psnr(plan, float(total) / decoded.size), float(largest)
    diff = decoded.astype(np.float64) - original.astype(np.float64)
    magnitude = np.linalg.norm(diff, axis=1) if per_point else np.abs(diff)
    return _psnr(plan, float(np.mean(diff * diff))), float(np.max(magnitude))


def _squared_and_largest_error(decoded: np.ndarray, original: np.ndarray) -> tuple[float, float]:
    """``squared_and_largest_error``, in slices over the threads when that gives the same bits.

    Integer samples have integer squared errors; while their total stays below 2**53 every
    partial sum is exact, so any slicing adds up to the one-pass total, bit for bit (the PSNR
    written in the header must not depend on the thread count).  Floats keep one pass.
    """
    if decoded.dtype.kind in "iub" and original.dtype.kind in "iub":
        spans = [_integer_span(decoded.dtype), _integer_span(original.dtype)]
        widest = float(max(spans))
        if widest * widest * max(decoded.size, 1) < 2.0**53:
            parts: list[tuple[int, int]] = []
            run_rows(
                lambda lo, hi: parts.append(
                    squared_and_largest_integer_error(decoded[lo:hi], original[lo:hi])
                ),
                decoded.size,
                decoded.size,
            )
            return float(sum(int(p[0]) for p in parts)), float(max(int(p[1]) for p in parts))
    total, largest = squared_and_largest_error(decoded, original)
    return float(total), float(largest)


def _integer_span(dtype: np.dtype[Any]) -> int:
    """The largest difference of two values of an integer (or boolean) dtype."""
    if dtype.kind == "b":
        return 1
    info = np.iinfo(dtype)
    return int(info.max) - int(info.min)


def _psnr(plan: Plan, mse: float) -> float | None:
    """PSNR in dB against the plan's peak, or None when exact."""
    if mse == 0.0:
        return None
    # In logarithms, so that no square or ratio overflows or underflows; an error too large
    # for a float still gives a (very low) finite figure.
    mse = min(mse, _LARGEST_FLOAT) if mse == mse else _LARGEST_FLOAT
    db = 20.0 * math.log10(max(plan.peak, 1e-300)) - 10.0 * math.log10(mse)
    # Rounded down, so that the recorded value never claims more than was measured.
    return math.floor(db * 1e4) / 1e4


def peak_of(arr: np.ndarray, dtype: str, kind: str) -> float:
    if dtype == "uint8":
        return 255.0
    if dtype == "uint16":
        return 65535.0
    lo, hi = float(arr.min()), float(arr.max())
    if kind == "image" and lo >= 0.0 and hi <= 1.0:
        return 1.0
    span = hi - lo
    return span if span > 0 else max(abs(hi), 1.0)
