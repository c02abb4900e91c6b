"""The codec: the one module that composes the coding stages into bundles, and back.

``encode_image`` / ``encode_curve`` / ``encode_surface`` run

    front end (shape, dtype, colour, size fitting) → transform → threshold (``keep``) →
    quantize → entropy code → bundle,

and :func:`decode` runs the same path backwards, as far as the requested resolution level needs.

Contract notes for the owners of ``quantize.py`` and ``entropy.py`` (read by them):

* ``dequantize_bands`` is called with a *prefix* of the layout, ``[cA, level L, ..., level k+1]``,
  when ``decode(..., level=k)`` asks for a coarse image, so ``params`` must describe the bands
  from the coarse end (per-level lists indexed from ``cA``), and nothing may be recomputed from
  the shape of the finest band that is handed in.
* ``decode_levels`` is likewise given only the first ``L - k + 1`` chunks and shapes.
* Everything in ``params`` must survive a JSON round trip (it is stored in the bundle header),
  and the decoder side must treat it as untrusted: a crafted header can hold any JSON there.
  As a last line of defence :func:`decode` turns any exception other than ``BundleError`` that
  escapes the decoding stages into a ``BundleError``, but please raise ``BundleError`` yourself.
* The lossless path hands ``encode_levels`` the integer LeGall 5/3 / integer Haar coefficients
  (``int32``, magnitudes up to about 2**20 for 16-bit RGB) with no quantizer.
* ``bpp`` counts the whole bundle, header included, and ``params`` live in the header (stored
  deflated): a float with 17 significant digits costs about 10 bytes even deflated, so rounding
  steps to ~6 significant digits (and quantizing with the rounded value) buys bits at low rates.
* Golden bundles (``tests/golden``) are decoded in every test run: once they are committed, a
  coder or quantizer whose old bitstreams/params no longer decode the same needs a new name (or
  a version key in ``params``), never a silent change behind the old one.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import curvesets
from . import lossless as _lossless
from ._kernels import (
    colour_to_floats,
    colour_to_integers,
    largest_scaled,
    log_histogram_counts,
    squared_and_largest_error,
    top_octave,
)
from .arguments import as_native, closed_flags
from .bundle import DTYPES, MAX_ELEMENTS, Bundle, read_bundle, write_bundle
from .colour import (
    YCBCR_INVERSE_MATRIX,
    YCBCR_MATRIX,
    rct_forward,
    rct_inverse,
    ycbcr_forward,
    ycbcr_inverse,
)
from .entropy import decode_levels, encode_levels
from .errors import BundleError, InvalidLength, InvalidParameter
from .filters import get_wavelet
from .multilevel import valid_length, wavedec, wavedec2, waverec, waverec2
from .quantize import (
    APPROX_ROUNDING,
    DEFAULT_ROUNDING,
    REFINE_MAX_COEFFICIENTS,
    band_weights,
    dequantize_bands,
    quantize_bands,
)
from .resample import crop_padding, pad_to_fit
from .threshold import check_share, remove_smallest
from .transform import run_rows

__all__ = ["decode", "encode_curve", "encode_image", "encode_surface", "inspect"]

#: Without ``keep``/``quality``/``bpp``, images and surfaces are coded to this PSNR (dB).
DEFAULT_QUALITY = 40.0
#: Without ``keep``/``tolerance``, curves are coded to this fraction of their bounding-box
#: diagonal as the largest point deviation.
DEFAULT_RELATIVE_TOLERANCE = 1e-3
#: With ``keep``, the quantizer step, relative to the peak: fine enough (about 60 dB) that the
#: thresholding decides what is lost.
KEEP_RELATIVE_STEP = 1.0 / 512.0
DEFAULT_CODER = "context"
LOSSLESS_WAVELET = "reversible"
_MAX_IMAGE_LEVELS = 5
_MAX_CURVE_LEVELS = 8
_SEARCH_STEPS = 18
_BPP_EVALUATIONS = 24
_MODEL_EVALUATIONS = 24
_QUALITY_EVALUATIONS = 24
_QUALITY_SLACK_DB = 0.02  # quality searches stop within this much above the target
#: The closed-loop quantizer's squared error, relative to the open loop's at the same step
#: (measured 0.78-0.89 for ``bspline2`` and 0.97-1.0 for ``cdf97`` on scikit-image's pictures at
#: 30-48 dB): where the quality search aims its first closed-loop quantization, from a search of
#: the ten times cheaper open loop.
_TYPICAL_REFINED_RATIO = {"bspline2": 0.81, "cdf97": 0.985}
_OTHER_REFINED_RATIO = 0.9
#: Brackets narrower than this (relative) hold a jump of the error, not a slope: stop there.
_QUALITY_STEP_RESOLUTION = 2e-4
_HEADER_GUESS = 600.0  # bytes, for the size estimate before the real coder has run
_OCTAVE_BINS = 64  # the size estimate's magnitude histograms: bins per octave,
_OCTAVES = 48  # and octaves below each band's largest magnitude
#: What the context coder typically writes, relative to the first-order estimate (0.7-0.9 on
#: scikit-image's pictures): where the bpp search aims its first real coding.
_TYPICAL_CODED_RATIO = 0.8
_PAD_ALLOWANCE = 64  # padded length <= 2 × length + this (the default levels stay far below)
_LONGEST_FLOAT = 1.2345678901234567e-300  # 23 characters, the longest repr of a positive float
#: Float data whose largest magnitude lies outside ``[2**-256, 2**256]`` is coded in a scaled
#: domain, multiplied by an exact power of two (recorded as the header's ``scale``), so that
#: squares, sums and steps never overflow or underflow; ordinary data is coded unscaled, as
#: before (its bundles do not change).
_UNSCALED_EXPONENT = 256
_LARGEST_FLOAT = float(np.finfo(np.float64).max)


# --------------------------------------------------------------------------------------------
# Validation of the caller's arguments
# --------------------------------------------------------------------------------------------


def _positive(value: Any, name: str, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        msg = f"{name} must be a positive number ({what}), not {value!r}"
        raise InvalidParameter(msg)
    if not (math.isfinite(float(value)) and float(value) > 0):
        msg = f"{name} must be a positive finite number ({what}), not {value!r}"
        raise InvalidParameter(msg)
    return float(value)


def _one_of(**targets: Any) -> None:
    given = [name for name, value in targets.items() if value is not None]
    if len(given) > 1:
        msg = f"give at most one of {', '.join(targets)}, not {' and '.join(given)}"
        raise InvalidParameter(msg)


def _level_arg(level: Any) -> int | None:
    if level is None:
        return None
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        msg = f"level must be None or an integer >= 0, not {level!r}"
        raise InvalidParameter(msg)
    if level > 30:
        msg = f"level {level} is more than 30; no input is that large"
        raise InvalidParameter(msg)
    return int(level)


def _as_array(data: Any, name: str) -> np.ndarray:
    arr = np.asarray(as_native(data))
    if arr.dtype == np.bool_ or arr.dtype.kind not in "uif":
        msg = f"{name} must hold real numbers (integers or floats), not {arr.dtype}"
        raise InvalidParameter(msg)
    if arr.size == 0:
        msg = f"{name} is empty (shape {arr.shape})"
        raise InvalidParameter(msg)
    if arr.size > MAX_ELEMENTS:
        msg = f"{name} has {arr.size} elements, more than the bundle limit {MAX_ELEMENTS}"
        raise InvalidParameter(msg)
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        msg = f"{name} holds NaN or infinite values; only finite numbers can be encoded"
        raise InvalidParameter(msg)
    return arr


def _dtype_name(arr: np.ndarray, name: str, *, integer_only: bool = False) -> str:
    allowed = ("uint8", "uint16") if integer_only else DTYPES
    if arr.dtype.name in allowed:
        return arr.dtype.name
    if not integer_only and arr.dtype.kind == "f":
        return "float64"  # longdouble: no wider float is portable, so it comes back as float64
    msg = f"{name} has dtype {arr.dtype}; expected one of {', '.join(allowed)}"
    raise InvalidParameter(msg)


# --------------------------------------------------------------------------------------------
# The plan: everything the header records about how the data was transformed
# --------------------------------------------------------------------------------------------


@dataclass
class _Plan:
    kind: str
    shape: tuple[int, ...]
    dtype: str
    wavelet: str
    boundary: tuple[str, ...]
    levels: int
    colour: str
    pads: tuple[tuple[int, int], ...]
    fitted: tuple[int, ...]
    peak: float
    lifting: tuple[str, ...] = ()  # lossless only: the reversible filter per level, finest first
    scale: int = 0  # the coded values are the original's times 2**-scale (see _scaled)
    opaque: bool = False  # an image whose alpha channel is fully opaque (see _finish)

    @property
    def axes(self) -> tuple[int, ...]:
        return (0,) if len(self.boundary) == 1 else (0, 1)

    def header(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "shape": list(self.shape),
            "dtype": self.dtype,
            "fit": "pad" if any(after or before for before, after in self.pads) else "none",
            "pads": [list(p) for p in self.pads],
            "fitted": list(self.fitted),
            "wavelet": self.wavelet,
            "boundary": list(self.boundary),
            "levels": self.levels,
            "colour": self.colour,
            "peak": self.peak,
            **({"lifting": list(self.lifting)} if self.wavelet == LOSSLESS_WAVELET else {}),
            **({"scale": self.scale} if self.scale else {}),
            **({"opaque": True} if self.opaque else {}),
        }


def _band_shapes(plan: _Plan) -> list[Any]:
    """Subband shapes in ``wavedec``/``wavedec2`` layout, computed without any allocation."""
    if plan.wavelet == LOSSLESS_WAVELET:
        return _lossless.band_shapes(plan.fitted, plan.levels, plan.axes)
    bank = get_wavelet(plan.wavelet)
    rules = [bank.rule(b) for b in plan.boundary]
    current = list(plan.fitted)
    details: list[Any] = []
    for _ in range(plan.levels):
        coarse, fine = list(current), list(current)
        for a, rule in zip(plan.axes, rules, strict=True):
            coarse[a] = rule.coarse_length(current[a])
            fine[a] = rule.detail_length(current[a])
        if len(plan.axes) == 1:
            details.append(tuple(fine))
        else:
            cH, cV = list(coarse), list(coarse)
            cH[0], cV[1] = fine[0], fine[1]
            details.append((tuple(cH), tuple(cV), tuple(fine)))
        current = coarse
    return [tuple(current), *reversed(details)]


def _default_level(sizes: Sequence[int], most: int) -> int:
    smallest = min(sizes)
    return max(1, min(most, math.floor(math.log2(max(smallest, 8) / 4))))


def _fit(
    data: np.ndarray, plan_level: int | None, wavelet: str, boundary: Sequence[str], most: int
) -> tuple[np.ndarray, tuple[tuple[int, int], ...], int]:
    axes = (0,) if len(boundary) == 1 else (0, 1)
    level = plan_level
    if level is None:
        level = _default_level([data.shape[a] for a in axes], most)
    for axis in axes:
        n = data.shape[axis]
        fitted = valid_length(n, level, boundary[axes.index(axis)], wavelet)
        if fitted > _padded_limit(n):
            msg = (
                f"level {level} is too deep for length {n} (axis {axis}): it would pad it to "
                f"{fitted}, more than {_padded_limit(n)}; give a smaller level"
            )
            raise InvalidParameter(msg)
    padded, pads = pad_to_fit(data, level, axes=axes, boundary=list(boundary), wavelet=wavelet)
    return padded, tuple((int(b), int(a)) for b, a in pads), level


def _padded_limit(n: int) -> int:
    """The longest padded length a bundle may declare for an original length ``n``.

    Bounding the padding keeps what a decoder allocates proportional to the original's size,
    so a tiny bundle cannot ask for a huge grid by declaring many levels.
    """
    return 2 * n + _PAD_ALLOWANCE


# --------------------------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------------------------


def _decompose(plan: _Plan, data: np.ndarray) -> list[Any]:
    if len(plan.axes) == 1:
        return wavedec(data, plan.wavelet, plan.boundary[0], plan.levels, axis=0)
    return wavedec2(data, plan.wavelet, list(plan.boundary), plan.levels, axes=(0, 1))


def _reconstruct(plan: _Plan, coeffs: list[Any]) -> np.ndarray:
    if len(plan.axes) == 1:
        return waverec(coeffs, plan.wavelet, plan.boundary[0], axis=0)
    return waverec2(coeffs, plan.wavelet, list(plan.boundary), axes=(0, 1))


def _finish(plan: _Plan, data: np.ndarray, level: int) -> np.ndarray:
    """Transformed-domain samples → the caller's array: crop, inverse colour, shape, dtype."""
    out = _finish_samples(plan, data, level)
    if plan.opaque:
        # An opaque alpha channel comes back exactly opaque, whatever the quantizer did to it:
        # a picture that was opaque must not turn faintly translucent.
        out[..., -1] = _opaque_value(out.dtype)
    return out


def _opaque_value(dtype: np.dtype[Any]) -> float:
    return float(np.iinfo(dtype).max) if dtype.kind in "iu" else 1.0


def _is_opaque(arr: np.ndarray) -> bool:
    """An image whose alpha channel (the last of 2 or 4) is fully opaque: the dtype's largest
    value for integers, 1.0 for floats."""
    if arr.ndim != 3 or arr.shape[2] not in (2, 4):
        return False
    return bool(np.all(arr[..., -1] == _opaque_value(arr.dtype)))


def _finish_samples(plan: _Plan, data: np.ndarray, level: int) -> np.ndarray:
    if plan.wavelet == LOSSLESS_WAVELET:
        cropped = data  # the 5/3 lifting fits every size; nothing was padded
    else:
        cropped = crop_padding(
            data,
            plan.pads,
            axes=plan.axes,
            level=level,
            boundary=list(plan.boundary),
            wavelet=plan.wavelet,
        )
    if plan.colour == "ycbcr" and np.dtype(plan.dtype).kind in "iu":
        # The common case, in one pass: colour matrix, rounding and clipping together.
        return _to_integers(np.asarray(cropped, dtype=np.float64), plan.dtype, YCBCR_INVERSE_MATRIX)
    if plan.colour == "ycbcr":
        cropped = ycbcr_inverse(cropped)
    elif plan.colour == "rct":
        cropped = rct_inverse(cropped)
    if len(plan.shape) == 1:  # a 1-D curve (a time series) was coded as (n, 1)
        cropped = cropped[:, 0]
    if plan.scale:
        # Clipped first, so that a value just past the largest float does not become infinite.
        limit = math.ldexp(_LARGEST_FLOAT, -plan.scale) if plan.scale > 0 else math.inf
        cropped = np.ldexp(np.clip(cropped, -limit, limit), plan.scale)
    return _cast(cropped, plan.dtype)


def _scaled(arr: np.ndarray) -> tuple[np.ndarray, int]:
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


def _scaled_tolerance(tolerance: float, scale: int) -> float:
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


def _unscaled(value: float, scale: int) -> float:
    """A scaled-domain distance back in the original's units (capped at the largest float)."""
    try:
        return min(math.ldexp(value, scale), _LARGEST_FLOAT)
    except OverflowError:
        return _LARGEST_FLOAT


def _to_integers(data: np.ndarray, dtype: str, matrix: np.ndarray | None) -> np.ndarray:
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


def _ycbcr_from(rgb: np.ndarray) -> np.ndarray:
    """``ycbcr_forward(rgb.astype(float64))``, by one compiled pass in threads."""
    if rgb.dtype in _UNCOMPILED_DTYPES:
        return ycbcr_forward(rgb.astype(np.float64))
    out = np.empty(rgb.shape, dtype=np.float64)
    run_rows(
        lambda lo, hi: colour_to_floats(rgb, YCBCR_MATRIX, out, lo, hi), rgb.shape[0], rgb.size
    )
    return out


def _cast(data: np.ndarray, dtype: str) -> np.ndarray:
    target = np.dtype(dtype)
    if target.kind in "iu" and data.dtype == np.float64 and data.ndim in (2, 3):
        return _to_integers(data, dtype, None)
    if target.kind in "iu":
        info = np.iinfo(target)
        values = np.nan_to_num(np.asarray(data, dtype=np.float64), nan=0.0)
        return np.clip(np.rint(values), info.min, info.max).astype(target)
    values = np.nan_to_num(np.asarray(data, dtype=np.float64))
    if target.itemsize < 8:
        # A float16/float32 original near its dtype's largest value may decode a little beyond
        # it: saturate, rather than turn it into infinity.
        largest = float(np.finfo(target).max)
        values = np.clip(values, -largest, largest)
    return values.astype(target)


#: Dtypes the compiled loops do not take (NumPy handles them instead).
_UNCOMPILED_DTYPES = {np.dtype(np.float16), np.dtype(np.longdouble)}


def _errors(plan: _Plan, original: np.ndarray, decoded: np.ndarray) -> tuple[float | None, float]:
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
            parts: list[tuple[float, float]] = []
            run_rows(
                lambda lo, hi: parts.append(
                    squared_and_largest_error(decoded[lo:hi], original[lo:hi])
                ),
                decoded.size,
                decoded.size,
            )
            return sum(p[0] for p in parts), max(p[1] for p in parts)
    total, largest = squared_and_largest_error(decoded, original)
    return float(total), float(largest)


def _integer_span(dtype: np.dtype[Any]) -> int:
    """The largest difference of two values of an integer (or boolean) dtype."""
    if dtype.kind == "b":
        return 1
    info = np.iinfo(dtype)
    return int(info.max) - int(info.min)


def _psnr(plan: _Plan, mse: float) -> float | None:
    """PSNR in dB against the plan's peak, or None when exact."""
    if mse == 0.0:
        return None
    # In logarithms, so that no square or ratio overflows or underflows; an error too large
    # for a float still gives a (very low) finite figure.
    mse = min(mse, _LARGEST_FLOAT) if mse == mse else _LARGEST_FLOAT
    db = 20.0 * math.log10(max(plan.peak, 1e-300)) - 10.0 * math.log10(mse)
    # Rounded down, so that the recorded value never claims more than was measured.
    return math.floor(db * 1e4) / 1e4


def _peak(arr: np.ndarray, dtype: str, kind: str) -> float:
    if dtype == "uint8":
        return 255.0
    if dtype == "uint16":
        return 65535.0
    lo, hi = float(arr.min()), float(arr.max())
    if kind == "image" and lo >= 0.0 and hi <= 1.0:
        return 1.0
    span = hi - lo
    return span if span > 0 else max(abs(hi), 1.0)


class _LossyEncoder:
    """Holds one decomposition and codes it at any step, for the rate-control searches.

    The last quantization and entropy coding are cached, so the searches' final bundle does not
    redo them.
    """

    def __init__(self, plan: _Plan, original: np.ndarray, transformed: np.ndarray) -> None:
        self.plan = plan
        self.original = original
        self.coeffs = _decompose(plan, transformed)
        self.kept = self.coeffs
        self.kept_fraction = 1.0
        self.vector_axis = -1 if plan.kind != "image" else None
        self._quantized: tuple[tuple[float, float], list[Any], dict[str, Any]] | None = None
        self._coded: tuple[tuple[float, float], list[bytes], dict[str, Any]] | None = None
        self._estimates: dict[tuple[float, float], float] = {}
        self._open_loop: dict[tuple[float, float], float] = {}
        self._errors_at: dict[tuple[float, float], tuple[float | None, float]] = {}
        self._histogram_cache: tuple[float, list[tuple[np.ndarray, np.ndarray, float]]] | None = (
            None
        )

    def keep(self, fraction: float) -> None:
        if fraction == self.kept_fraction:
            return
        self.kept_fraction = fraction
        self.kept = remove_smallest(
            self.coeffs,
            1.0 - fraction,
            wavelet=self.plan.wavelet,
            boundary=list(self.plan.boundary),
            axes=self.plan.axes,
            vector_axis=self.vector_axis,
        )

    def _quantize_bands(self, step: float, **options: Any) -> tuple[list[Any], dict[str, Any]]:
        return quantize_bands(
            self.kept,
            step,
            wavelet=self.plan.wavelet,
            boundary=list(self.plan.boundary),
            axes=self.plan.axes,
            **options,
        )

    def quantize(self, step: float) -> tuple[list[Any], dict[str, Any]]:
        key = (step, self.kept_fraction)
        if self._quantized is None or self._quantized[0] != key:
            q, params = self._quantize_bands(step)
            self._quantized = (key, q, params)
        return self._quantized[1], self._quantized[2]

    def code(self, step: float) -> tuple[list[bytes], dict[str, Any]]:
        key = (step, self.kept_fraction)
        if self._coded is None or self._coded[0] != key:
            chunks, cparams = encode_levels(self.quantize(step)[0], coder=DEFAULT_CODER)
            self._coded = (key, chunks, cparams)
        return self._coded[1], self._coded[2]

    def reconstruct(self, qcoeffs: list[Any], qparams: dict[str, Any]) -> np.ndarray:
        coeffs = dequantize_bands(
            qcoeffs,
            qparams,
            wavelet=self.plan.wavelet,
            boundary=list(self.plan.boundary),
            axes=self.plan.axes,
        )
        decoded = _finish(self.plan, _reconstruct(self.plan, coeffs), 0)
        if self.plan.scale:
            # Measured on exactly what decode returns (subnormals rounded, the largest values
            # saturated), brought back to the coded units, where the squares cannot overflow.
            decoded = np.ldexp(decoded, -self.plan.scale)
        return decoded

    def refines(self) -> bool:
        """Whether :meth:`quantize` runs the closed loop (small decompositions of images)."""
        total = sum(
            sum(np.size(band) for band in entry) if isinstance(entry, tuple | list) else entry.size
            for entry in self.kept
        )
        return total <= REFINE_MAX_COEFFICIENTS

    def open_loop_mse(self, step: float) -> float:
        """The squared error at ``step`` without the closed-loop refinement (a model for it).

        It costs a quantization and a synthesis, against the closed loop's dozen of syntheses
        and adjoints; the cached closed-loop quantization is left alone.
        """
        key = (step, self.kept_fraction)
        if key not in self._open_loop:
            q, params = self._quantize_bands(step, refine=0)
            psnr = _errors(self.plan, self.original, self.reconstruct(q, params))[0]
            peak2 = self.plan.peak**2
            self._open_loop[key] = 0.0 if psnr is None else peak2 * 10.0 ** (-psnr / 10.0)
        return self._open_loop[key]

    def quality(self, step: float) -> tuple[float, float]:
        """(PSNR, max error) at ``step``; an exact result counts as infinite PSNR."""
        psnr, max_error = self._measured(step)
        return (math.inf if psnr is None else psnr), max_error

    def _measured(self, step: float) -> tuple[float | None, float]:
        """The errors at ``step``, kept for the final bundle's header (no second synthesis)."""
        key = (step, self.kept_fraction)
        if key not in self._errors_at:
            q, params = self.quantize(step)
            self._errors_at[key] = _errors(self.plan, self.original, self.reconstruct(q, params))
        return self._errors_at[key]

    def _assemble(self, step: float, errors: tuple[float | None, float] | None) -> bytes:
        qparams = self.quantize(step)[1]
        chunks, cparams = self.code(step)
        if errors is None:
            errors = self._measured(step)
        header = self.plan.header()
        header.update(
            quantizer=str(qparams.get("name", "deadzone")),
            qparams=qparams,
            coder=str(cparams.get("coder", DEFAULT_CODER)),
            cparams=cparams,
            psnr=errors[0],
            max_error=_unscaled(errors[1], self.plan.scale),
        )
        return write_bundle(header, chunks)

    def bundle(self, step: float) -> bytes:
        """The bundle at ``step``, with its measured PSNR and largest error in the header."""
        return self._assemble(step, None)

    def size_bound(self, step: float) -> float:
        """An upper bound on ``len(self.bundle(step))`` that skips measuring the errors.

        The placeholders are floats with the longest JSON form, so the real header can only
        be shorter (by at most a few dozen bytes).
        """
        return float(len(self._assemble(step, (_LONGEST_FLOAT, _LONGEST_FLOAT))))

    def size_estimate(self, step: float) -> float:
        """A cheap stand-in for :meth:`size_bound`: first-order entropy of every band, in bytes.

        From a histogram of each band's magnitudes (in its quantizer's units) in 1/64-octave
        bins, made once: an estimate at any step then costs microseconds, not a quantization.
        The bpp search uses it to choose where to run the real coder.
        """
        key = (step, self.kept_fraction)
        if key not in self._estimates:
            bits = 0.0
            for counts, centres, rounding in self._histograms():
                indices = np.floor(centres / step + rounding)
                histogram = np.bincount(
                    np.minimum(indices, 255).astype(np.int64), weights=counts, minlength=256
                )
                present = histogram[histogram > 0]
                bits -= float(np.sum(present * np.log2(present / counts.sum())))
                beyond = indices > 255  # larger magnitudes by their bit length
                bits += 1.2 * float(np.sum(counts[beyond] * np.log2(indices[beyond])))
                bits += float(counts[indices >= 1].sum())  # a bit per sign
            self._estimates[key] = bits / 8.0 + _HEADER_GUESS
        return self._estimates[key]

    def _histograms(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Per band: bin counts, bin centres (magnitude / band weight) and dead-zone rounding."""
        if self._histogram_cache is None or self._histogram_cache[0] != self.kept_fraction:
            levels = band_weights(
                self.kept,
                wavelet=self.plan.wavelet,
                boundary=list(self.plan.boundary),
                axes=self.plan.axes,
            )
            out = []
            for index, (entry, weights) in enumerate(zip(self.kept, levels, strict=True)):
                bands = entry if isinstance(entry, tuple | list) else (entry,)
                rounding = APPROX_ROUNDING if index == 0 else DEFAULT_ROUNDING
                for band, weight in zip(bands, weights, strict=True):
                    values = np.ascontiguousarray(band, dtype=np.float64).reshape(-1)
                    counts, top = _log_histogram(values, 1.0 / weight)
                    octave, step = np.divmod(np.arange(counts.size), _OCTAVE_BINS)
                    centres = 2.0 ** (top - _OCTAVES + octave - 1) * (
                        2.0 + (2 * step + 1) / _OCTAVE_BINS
                    )  # the middle of each bin, halfway along its mantissa range
                    centres[0] = 0.0  # everything tiny, zeros included
                    used = counts > 0
                    out.append((counts[used].astype(np.float64), centres[used], rounding))
            self._histogram_cache = (self.kept_fraction, out)
        return self._histogram_cache[1]


def _log_histogram(values: np.ndarray, scale: float) -> tuple[np.ndarray, int]:
    """``_kernels.log_histogram(values, scale, _OCTAVE_BINS, _OCTAVES)`` in slices over the
    threads: a largest value, then counts, both exact whatever the slicing (a maximum, and
    integer counts added up)."""
    parts: list[Any] = []
    run_rows(
        lambda lo, hi: parts.append(largest_scaled(values[lo:hi], scale)), values.size, values.size
    )
    top = int(top_octave(max(parts, default=0.0)))
    parts.clear()
    run_rows(
        lambda lo, hi: parts.append(
            log_histogram_counts(values[lo:hi], scale, _OCTAVE_BINS, _OCTAVES, top)
        ),
        values.size,
        values.size,
    )
    return np.sum(parts, axis=0), top


class _Search:
    """Finds the step whose measured value is as large as allowed (``value <= bound``).

    ``measure(step)`` is a positive value that grows or shrinks with the step roughly like a
    power law (bundle size ~ step**-1, squared error ~ step**2).  The search keeps the largest
    value within the bound and the smallest beyond it, interpolates between them in log-log
    (the secant method, clamped so both brackets move), and before it has both extrapolates
    with the expected exponent, at most a factor 16 per step (or asks ``guide(step, value)``
    for the next step, when given).  It stops once a value lies in ``[enough, bound]``.
    """

    def __init__(
        self,
        measure: Callable[[float], float],
        bound: float,
        enough: float,
        slope: float,
        low: float,
        high: float,
        guide: Callable[[float, float], float] | None = None,
        aim: float | None = None,
        resolution: float = 0.0,
    ) -> None:
        self.measure, self.bound, self.enough = measure, bound, enough
        self.guide = guide
        self.resolution = resolution
        if aim is None:
            aim = math.sqrt(bound * enough) if enough > 0 else bound
        self.aim = max(aim, 1e-300)
        self.slope, self.low, self.high = slope, low, high
        self.within: tuple[float, float] | None = None  # (step, value) with value <= bound
        self.beyond: tuple[float, float] | None = None  # (step, value) with value > bound
        self.last: tuple[float, float] | None = None
        # The bracket the secant narrows: the latest evaluations on either side between the
        # two.  Where the value is not monotone in the step (the quantizer's error can dip
        # when the step grows), the largest value within is not always the bracket's end.
        self.inner: tuple[float, float] | None = None
        self.outer: tuple[float, float] | None = None

    def done(self) -> bool:
        return self.within is not None and self.within[1] >= self.enough

    def evaluate(self, step: float) -> float:
        value = max(self.measure(step), 1e-300)
        self.last = (step, value)
        bracketed = self.inner is not None and self.outer is not None
        if value <= self.bound:
            if self.within is None or value > self.within[1]:
                self.within = (step, value)
            if self._narrows(step) if bracketed else self.within == (step, value):
                self.inner = (step, value)
        else:
            if self.beyond is None or value < self.beyond[1]:
                self.beyond = (step, value)
            if self._narrows(step) if bracketed else self.beyond == (step, value):
                self.outer = (step, value)
        return value

    def _narrows(self, step: float) -> bool:
        assert self.inner is not None and self.outer is not None
        return min(self.inner[0], self.outer[0]) < step < max(self.inner[0], self.outer[0])

    def next_step(self) -> float | None:
        if self.inner is not None and self.outer is not None:
            (s0, v0), (s1, v1) = self.inner, self.outer
            if s0 == s1 or abs(math.log(s1 / s0)) <= self.resolution:
                return None
            t = 0.5
            if v0 != v1:
                t = (math.log(self.aim) - math.log(v0)) / (math.log(v1) - math.log(v0))
            t = min(max(t, 0.1), 0.9)
            step = math.exp(math.log(s0) + t * (math.log(s1) - math.log(s0)))
            return None if step in (s0, s1) else step
        assert self.last is not None
        s, v = self.last
        if self.guide is not None:
            step = min(max(self.guide(s, v), self.low), self.high)
            if step != s:
                return step  # else the guide is stuck: extrapolate as without it
        exponent = (math.log(self.aim) - math.log(v)) / self.slope
        step = s * math.exp(min(max(exponent, -math.log(16)), math.log(16)))
        step = min(max(step, self.low), self.high)
        return None if step == s else step

    def run(self, start: float, evaluations: int) -> None:
        step: float | None = start
        for _ in range(evaluations):
            if step is None:
                return
            self.evaluate(step)
            if self.done():
                return
            step = self.next_step()


def _largest_step(ok: Callable[[float], bool], low: float, high: float) -> float:
    """The largest step in ``[low, high]`` (log scale) for which ``ok`` holds; ``ok(low)`` must."""
    if ok(high):
        return high
    for _ in range(_SEARCH_STEPS):
        mid = math.sqrt(low * high)
        if ok(mid):
            low = mid
        else:
            high = mid
    return low


def _encode_lossy(
    plan: _Plan,
    original: np.ndarray,
    transformed: np.ndarray,
    *,
    keep: float | None,
    quality: float | None,
    bpp: float | None,
    tolerance: float | None,
) -> bytes:
    encoder = _LossyEncoder(plan, original, transformed)
    low, high = plan.peak * 2.0**-20, plan.peak * 4.0
    if keep is not None:
        encoder.keep(keep)
        return encoder.bundle(plan.peak * KEEP_RELATIVE_STEP)
    if tolerance is not None:
        return _encode_to_tolerance(encoder, tolerance, low, high)
    if bpp is not None:
        return _encode_to_bpp(encoder, bpp, low, high)
    return _encode_to_quality(encoder, DEFAULT_QUALITY if quality is None else quality, low, high)


def _encode_to_quality(encoder: _LossyEncoder, target: float, low: float, high: float) -> bytes:
    """The largest step whose PSNR meets ``target`` (and exceeds it by at most ~0.02 dB)."""
    peak2 = encoder.plan.peak**2

    def mse(step: float) -> float:
        psnr = encoder.quality(step)[0]
        return 0.0 if math.isinf(psnr) else peak2 * 10.0 ** (-psnr / 10.0)

    bound = peak2 * 10.0 ** (-target / 10.0)
    enough = bound * 10.0 ** (-_QUALITY_SLACK_DB / 10.0)
    # A uniform quantizer's error is step**2 / 12: the first guess.
    first = min(max(math.sqrt(12.0 * bound), low), high)
    if not encoder.refines():
        search = _Search(mse, bound, enough, 2.0, low, high, resolution=_QUALITY_STEP_RESOLUTION)
        search.run(first, _QUALITY_EVALUATIONS)
    else:
        # The closed loop costs about ten open-loop quantizations, and its error is the open
        # loop's times a ratio that changes slowly with the step: scale the open-loop error by
        # the latest measured ratio (a typical one to begin with), solve that model for the
        # step, and run the closed loop only there, until its errors bracket the target; then
        # they alone are interpolated.  Usually two closed-loop quantizations, against four.
        ratio = _TYPICAL_REFINED_RATIO.get(encoder.plan.wavelet, _OTHER_REFINED_RATIO)

        def scaled_model_step(step: float, value: float | None) -> float:
            nonlocal ratio
            if value is not None:
                model_value = encoder.open_loop_mse(step)
                if value > 0 and model_value > 0:
                    ratio = value / model_value
            model = _Search(
                lambda s: encoder.open_loop_mse(s) * ratio, bound, enough, 2.0, low, high
            )
            model.run(step, _MODEL_EVALUATIONS)
            return (model.within or model.last or (low, 0.0))[0]

        search = _Search(
            mse,
            bound,
            enough,
            2.0,
            low,
            high,
            guide=scaled_model_step,
            resolution=_QUALITY_STEP_RESOLUTION,
        )
        search.run(scaled_model_step(first, None), _QUALITY_EVALUATIONS)
    if search.within is None or encoder.quality(search.within[0])[0] < target:
        best = encoder.quality(low)[0]
        if best < target:
            msg = (
                f"quality {target} dB cannot be reached for this data (the finest quantizer "
                f"gives {best:.2f} dB); ask for less, or use lossless=True for 8/16-bit images"
            )
            raise InvalidParameter(msg)
        step = _largest_step(lambda s: encoder.quality(s)[0] >= target, low, high)
    else:
        step = search.within[0]
    return encoder.bundle(step)


def _encode_to_tolerance(
    encoder: _LossyEncoder, tolerance: float, low: float, high: float
) -> bytes:
    if encoder.quality(low)[1] > tolerance:
        msg = (
            f"tolerance {tolerance} cannot be met (the finest quantizer leaves a deviation of "
            f"{encoder.quality(low)[1]:.3g}); ask for a larger tolerance"
        )
        raise InvalidParameter(msg)
    step = _largest_step(lambda s: encoder.quality(s)[1] <= tolerance, low, high)
    while True:  # verify on the decoded bundle, and tighten until the guarantee holds
        data = encoder.bundle(step)
        decoded = decode(data)
        if encoder.plan.scale:
            decoded = np.ldexp(decoded, -encoder.plan.scale)
        if _errors(encoder.plan, encoder.original, decoded)[1] <= tolerance or step <= low:
            return data
        step /= 2


def _encode_to_bpp(encoder: _LossyEncoder, bpp: float, low: float, high: float) -> bytes:
    """The bundle closest below ``bpp`` (whole bundle, header included), within 3 % of it.

    The cheap size estimate (first-order entropy), scaled by how the real coder compares with
    it, chooses each step to code for real (usually one or two codings); once the real sizes
    bracket the budget they are interpolated.  If the size jumps between two neighbouring
    steps, the finer one is trimmed by removing its least important details.
    """
    plan = encoder.plan
    pixels = plan.shape[0] * plan.shape[1]
    budget = math.floor(bpp * pixels / 8.0)
    # Aim at 99.3 % of the budget, and stop at anything from 97.5 % (the promise is 97 %; the
    # real header is at most 2 × 23 bytes shorter than the bound): each miss costs a coding.
    enough = min(budget, max(math.ceil(0.97 * bpp * pixels / 8.0) + 48, math.ceil(0.975 * budget)))
    aim = 0.993 * budget
    if budget < 64:  # not even a header fits: say what the smallest bundle would be
        enough = budget = 0
    # The cheap model (first-order entropy) over-estimates what the context coder writes, by a
    # factor that depends on the picture: scale it by the latest measured ratio (a typical one
    # to begin with) and solve the scaled model for the next step to code for real, until the
    # real sizes bracket the budget; then the real sizes alone are interpolated.
    ratio = _TYPICAL_CODED_RATIO

    def scaled_model_step(step: float, value: float | None) -> float:
        nonlocal ratio
        if value is not None:
            ratio = value / encoder.size_estimate(step)
        # The model only points the way, so a looser window will do for it.
        model = _Search(
            lambda s: encoder.size_estimate(s) * ratio, budget, 0.985 * budget, -1.0, low, high
        )
        model.run(step, _MODEL_EVALUATIONS)
        return (model.within or model.last or (high, 0.0))[0]

    real = _Search(
        encoder.size_bound, budget, enough, -1.0, low, high, guide=scaled_model_step, aim=aim
    )
    real.run(scaled_model_step(plan.peak / 16.0, None), _BPP_EVALUATIONS)
    if real.within is None:
        real.evaluate(high)
        if real.within is None:
            smallest = len(encoder.bundle(high))
            msg = (
                f"bpp {bpp} is below what this image can be coded in: the smallest bundle is "
                f"{smallest} bytes = {8 * smallest / pixels:.4f} bpp (header included)"
            )
            raise InvalidParameter(msg)
        real.run(real.next_step() or high, _BPP_EVALUATIONS)
    fits = (real.within[0], int(real.within[1])) if real.within is not None else (high, 0)
    if fits[1] < enough and real.beyond is not None:
        # The size jumps between two neighbouring steps (many coefficients cross a bin edge
        # together, e.g. on pixel-repeated images): take the finer step and drop its least
        # important details, which lowers the size smoothly, until the bundle fits.
        fits = _fill_by_removal(encoder, real.beyond[0], fits, budget, enough)
    return encoder.bundle(fits[0])


def _fill_by_removal(
    encoder: _LossyEncoder, step: float, fits: tuple[float, int], budget: int, enough: int
) -> tuple[float, int]:
    best_removed: float | None = None
    few, many = 0.0, 1.0  # fractions of details removed: too big, small enough
    for _ in range(_SEARCH_STEPS):
        removed = (few + many) / 2
        encoder.keep(1.0 - removed)
        size = encoder.size_bound(step)
        if size <= budget:
            many = removed
            if size > fits[1]:
                fits, best_removed = (step, int(size)), removed
            if size >= enough:
                break
        else:
            few = removed
    encoder.keep(1.0 - (best_removed if best_removed is not None else 0.0))
    return fits


def _refuses_as_parameter(encoder: Callable[..., bytes]) -> Callable[..., bytes]:
    """An encoder's ``BundleError`` (say, a header past the format's limits) is its input's
    fault: raise it as ``InvalidParameter``, so that callers (the service) never mistake an
    encode for a bad bundle."""

    @functools.wraps(encoder)
    def checked(*args: Any, **kwargs: Any) -> bytes:
        try:
            return encoder(*args, **kwargs)
        except BundleError as exc:
            msg = f"this input cannot be stored in a bundle: {exc}"
            raise InvalidParameter(msg) from exc

    return checked


@_refuses_as_parameter
def encode_image(
    image: Any,
    *,
    wavelet: str = "cdf97",
    level: int | None = None,
    keep: float | None = None,
    quality: float | None = None,
    bpp: float | None = None,
    lossless: bool = False,
) -> bytes:
    """Encode an image into a bundle.

    Parameters
    ----------
    image : array_like
        ``(H, W)`` grey or ``(H, W, C)`` with ``C`` from 1 to 4 (grey, grey + alpha, RGB, RGBA);
        ``uint8``, ``uint16`` or float, any byte order and layout.  Any finite float works,
        subnormals to ``±1.7e308`` (coded in an exactly scaled domain, the header's
        ``scale``).  An alpha channel that decodes exactly, as an opaque one always does, is
        left out of ``quality`` and of the recorded PSNR, which are then the colour channels'.
    wavelet : str
        The wavelet for lossy coding: ``"cdf97"`` by default, the one that wins the measured
        rate–distortion on photographs (docs/benchmarks.md); ``"bspline2"`` (the paper's,
        smooth, with interpolated ends), ``"haar"`` or an alias (see
        :func:`wavecore.wavelet_names`).  The bundle records it, so any bundle decodes alike.
    level : int, optional
        Decomposition levels; ``None`` picks up to 5, keeping the coarsest band at least about
        4 pixels a side.  Any image size works: the image is edge-padded to a size that fits,
        and the padding is recorded and cropped again.
    keep : float, optional
        Fraction of detail coefficients kept (the smallest ``1 - keep`` by their effect on the
        reconstruction are removed), quantized finely (about 60 dB).
    quality : float, optional
        Target PSNR in dB, met or exceeded (measured on the decoded image, in the original
        dtype, against the dtype's peak: 255, 65535, or 1 for floats in ``[0, 1]``, else the
        data range).
    bpp : float, optional
        Target bits per pixel: ``8 × len(bundle) / (H × W)``, header included; never exceeded
        and within 3 % below.
    lossless : bool
        Code bit-exactly (``uint8``/``uint16`` only) with the reversible LeGall 5/3 integer
        lifting and the reversible colour transform; ``wavelet`` is then not used.

    With none of ``keep``/``quality``/``bpp`` the image is coded to ``quality=40`` dB.

    Returns
    -------
    bytes
        The bundle (see :mod:`wavecore.bundle`).

    Examples
    --------
    >>> import numpy as np
    >>> image = (np.add.outer(np.arange(40), np.arange(30)) * 3).astype(np.uint8)
    >>> bundle = encode_image(image, quality=35)
    >>> out = decode(bundle)
    >>> out.shape, out.dtype, inspect(bundle)["psnr"] >= 35
    ((40, 30), dtype('uint8'), True)
    >>> bool(np.array_equal(decode(encode_image(image, lossless=True)), image))
    True
    """
    _one_of(keep=keep, quality=quality, bpp=bpp)
    arr = _as_array(image, "image")
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and not 1 <= arr.shape[2] <= 4):
        msg = f"image must be (H, W) or (H, W, C) with 1 to 4 channels, not shape {arr.shape}"
        raise InvalidParameter(msg)
    level = _level_arg(level)
    if lossless:
        if keep is not None or quality is not None or bpp is not None:
            msg = "lossless=True cannot be combined with keep, quality or bpp"
            raise InvalidParameter(msg)
        return _encode_lossless(arr, level)
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    quality = None if quality is None else _positive(quality, "quality", "a PSNR in dB")
    bpp = None if bpp is None else _positive(bpp, "bpp", "bits per pixel")
    dtype = _dtype_name(arr, "image")
    arr, scale = _scaled(arr)
    colour = "ycbcr" if arr.ndim == 3 and arr.shape[2] >= 3 else "none"
    data = _ycbcr_from(arr) if colour == "ycbcr" else arr.astype(np.float64)
    bank = get_wavelet(wavelet)
    # Images use the paper's endpoint-interpolating rows; a wavelet without them (cdf97's
    # symmetric extension) uses its own non-periodic boundary.
    boundary = ("open", "open") if "open" in bank.rules else (next(iter(bank.rules)),) * 2
    fitted, pads, levels = _fit(data, level, bank.name, boundary, _MAX_IMAGE_LEVELS)
    plan = _Plan(
        "image",
        arr.shape,
        dtype,
        bank.name,
        boundary,
        levels,
        colour,
        pads,
        fitted.shape,
        _peak(arr, dtype, "image"),
        scale=scale,
        opaque=_is_opaque(arr),
    )
    return _encode_lossy(plan, arr, fitted, keep=keep, quality=quality, bpp=bpp, tolerance=None)


def _encode_lossless(arr: np.ndarray, level: int | None) -> bytes:
    dtype = _dtype_name(arr, "image", integer_only=True)
    colour = "rct" if arr.ndim == 3 and arr.shape[2] >= 3 else "none"
    data = rct_forward(arr) if colour == "rct" else arr.astype(np.int64)
    # At most as many levels as leave every subband non-empty (5/3 fits any size unpadded).
    deepest = min(arr.shape[:2]).bit_length() - 1
    if level is None:
        level = min(_default_level(arr.shape[:2], _MAX_IMAGE_LEVELS), deepest)
    elif level > deepest:
        msg = (
            f"level {level} is too deep for a lossless {arr.shape[0]}×{arr.shape[1]} image: "
            f"at most {deepest} levels leave every subband non-empty"
        )
        raise InvalidParameter(msg)
    # First-order entropy only guides the choice of filters (the context coder ranks them
    # differently), so code the choice with and without the closed bspline2 and keep the smaller.
    choices = []
    for candidates in (("legall53", "haar"), _lossless.FILTERS):
        lifting = _lossless.choose_filters(data, level, (0, 1), candidates)
        if lifting not in choices:
            choices.append(lifting)
    bundles = [_lossless_bundle(arr, data, dtype, colour, level, lifting) for lifting in choices]
    return min(bundles, key=len)


def _lossless_bundle(
    arr: np.ndarray, data: np.ndarray, dtype: str, colour: str, level: int, lifting: list[str]
) -> bytes:
    plan = _Plan(
        "image",
        arr.shape,
        dtype,
        LOSSLESS_WAVELET,
        ("symmetric", "symmetric"),
        level,
        colour,
        ((0, 0), (0, 0)),
        arr.shape,
        _peak(arr, dtype, "image"),
        tuple(lifting),
    )
    coeffs = _lossless.forward(data, level, (0, 1), lifting)
    chunks, cparams = encode_levels(coeffs, coder=DEFAULT_CODER)
    header = plan.header()
    header.update(
        quantizer="none",
        qparams={},
        coder=str(cparams.get("coder", DEFAULT_CODER)),
        cparams=cparams,
        psnr=None,
        max_error=0.0,
    )
    return write_bundle(header, chunks)


@_refuses_as_parameter
def encode_curve(
    points: Any,
    *,
    closed: bool | None = None,
    level: int | None = None,
    keep: float | None = None,
    tolerance: float | None = None,
    wavelet: str = "bspline2",
    boundary: str | None = None,
) -> bytes:
    """Encode a curve, ``(n, d)`` points (or ``(n,)`` samples), into a bundle.

    Parameters
    ----------
    points : array_like
        The points in order, any ``n >= 1`` and ``d >= 1``, any finite values (huge or tiny
        floats are coded in an exactly scaled domain).  The curve is extended at its end to
        a length that fits (``wavecore.pad_to_fit``: repeated last point when open, a straight
        blend back to the first point when closed); the decoder gives back exactly ``n`` points.
    closed : bool, optional
        A closed curve (periodic boundary) or an open one (endpoint interpolating, the
        default).
    level : int, optional
        Levels; ``None`` picks up to 8, keeping at least about 4 coarse points.
    keep : float, optional
        Fraction of detail vectors kept (the rest, smallest effect first, removed).
    tolerance : float, optional
        The largest allowed distance between an original point and its decoded point; verified
        on the decoded bundle.  Default: ``1e-3`` × the bounding-box diagonal.
    wavelet : str
        ``"bspline2"`` (the paper's, smooth; the default), ``"haar"`` (piecewise constant: a
        staircase once details are dropped) or ``"cdf97"``.
    boundary : {"open", "closed"}, optional
        The same choice as ``closed``, spelled as elsewhere in the library: ``"closed"`` is
        ``closed=True``.  Give either; both is accepted only when they agree.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    >>> circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    >>> bundle = encode_curve(circle, closed=True, tolerance=1e-3)
    >>> out = decode(bundle)
    >>> out.shape, bool(np.max(np.linalg.norm(out - circle, axis=1)) <= 1e-3)
    ((50, 2), True)
    """
    _one_of(keep=keep, tolerance=tolerance)
    arr = _as_array(points, "points")
    if arr.ndim not in (1, 2):
        msg = f"points must be (n, d) or (n,), not shape {arr.shape}"
        raise InvalidParameter(msg)
    (is_closed,) = closed_flags(closed, boundary, 1)
    level = _level_arg(level)
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    dtype = _dtype_name(arr, "points")
    arr, scale = _scaled(arr)
    data = arr.astype(np.float64).reshape(arr.shape[0], -1)
    boundaries = ("closed",) if is_closed else ("open",)
    bank = get_wavelet(wavelet)
    fitted, pads, levels = _fit(data, level, bank.name, boundaries, _MAX_CURVE_LEVELS)
    diagonal = float(np.linalg.norm(data.max(axis=0) - data.min(axis=0)))
    plan = _Plan(
        "curve",
        arr.shape,
        dtype,
        bank.name,
        boundaries,
        levels,
        "none",
        pads,
        fitted.shape,
        _peak(data, dtype, "curve"),
        scale=scale,
    )
    if keep is None:
        if tolerance is None:
            tolerance = DEFAULT_RELATIVE_TOLERANCE * (diagonal if diagonal > 0 else 1.0)
        else:  # in the coded (scaled) units
            tolerance = _scaled_tolerance(_positive(tolerance, "tolerance", "a distance"), scale)
    return _encode_lossy(plan, arr, fitted, keep=keep, quality=None, bpp=None, tolerance=tolerance)


@_refuses_as_parameter
def encode_surface(
    grid: Any,
    *,
    closed: tuple[bool, bool] | None = None,
    level: int | None = None,
    keep: float | None = None,
    quality: float | None = None,
    wavelet: str = "bspline2",
    boundary: str | tuple[str, str] | None = None,
) -> bytes:
    """Encode a surface, a ``(U, V, d)`` grid of points or a ``(U, V)`` height field.

    Parameters
    ----------
    grid : array_like
        The grid; each of the two grid axes is padded to a length that fits and cropped again.
        Any finite values (huge or tiny floats are coded in an exactly scaled domain).
    closed : pair of bool, optional
        Per grid axis, periodic (``True``, e.g. the circles of a surface of revolution) or open
        (the default).
    level : int, optional
        Levels; ``None`` picks up to 5.
    keep : float, optional
        Fraction of detail vectors kept.
    quality : float, optional
        Target PSNR in dB against the data range (largest minus smallest value), met or
        exceeded.  Default: 40 dB.
    wavelet : str
        ``"bspline2"`` (the paper's, the default), ``"haar"``, ``"cdf97"`` or an alias (see
        :func:`wavecore.wavelet_names`); the bundle records it.
    boundary : str or pair of str, optional
        The same choice as ``closed``, spelled ``"open"`` / ``"closed"`` (one for both axes, or
        one per axis).  Give either; both is accepted only when they agree.

    Examples
    --------
    >>> import numpy as np
    >>> u, v = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 24), indexing="ij")
    >>> bundle = encode_surface(np.sin(3 * u) * np.cos(2 * v), quality=50)
    >>> decode(bundle).shape, inspect(bundle)["psnr"] >= 50
    ((20, 24), True)
    """
    _one_of(keep=keep, quality=quality)
    arr = _as_array(grid, "grid")
    if arr.ndim not in (2, 3):
        msg = f"grid must be (U, V) or (U, V, d), not shape {arr.shape}"
        raise InvalidParameter(msg)
    flags = closed_flags(closed, boundary, 2)
    level = _level_arg(level)
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    quality = None if quality is None else _positive(quality, "quality", "a PSNR in dB")
    dtype = _dtype_name(arr, "grid")
    arr, scale = _scaled(arr)
    data = arr.astype(np.float64)
    bank = get_wavelet(wavelet)
    boundaries = tuple("closed" if c else "open" for c in flags)
    fitted, pads, levels = _fit(data, level, bank.name, boundaries, _MAX_IMAGE_LEVELS)
    plan = _Plan(
        "surface",
        arr.shape,
        dtype,
        bank.name,
        boundaries,
        levels,
        "none",
        pads,
        fitted.shape,
        _peak(data, dtype, "surface"),
        scale=scale,
    )
    return _encode_lossy(plan, arr, fitted, keep=keep, quality=quality, bpp=None, tolerance=None)


# --------------------------------------------------------------------------------------------
# Decoding
# --------------------------------------------------------------------------------------------


def _plan_from_header(header: dict[str, Any]) -> _Plan:
    """Check the kind-specific consistency of a (generically valid) header."""
    kind, shape, fitted = header["kind"], tuple(header["shape"]), tuple(header["fitted"])
    boundary, pads, levels = tuple(header["boundary"]), header["pads"], header["levels"]
    ranks = {"image": (2, 3), "curve": (1, 2), "surface": (2, 3)}[kind]
    axes_count = 1 if kind == "curve" else 2
    if len(shape) not in ranks or len(boundary) != axes_count:
        msg = f"header: a {kind} cannot have shape {list(shape)} and {len(boundary)} boundaries"
        raise BundleError(msg)
    expected = list(shape) if len(shape) > 1 else [shape[0], 1]
    for axis, (before, after) in enumerate(pads):
        expected[axis] += before + after
    if list(fitted) != expected:
        msg = f"header field 'fitted' is {list(fitted)}; shape and pads make it {expected}"
        raise BundleError(msg)
    for axis in range(axes_count):
        if fitted[axis] > _padded_limit(expected[axis] - sum(pads[axis])):
            msg = f"header field 'pads' pads axis {axis} far beyond its length: {pads[axis]}"
            raise BundleError(msg)
    if kind == "image" and len(shape) == 3 and shape[2] > 4:
        msg = f"header: an image has at most 4 channels, not {shape[2]}"
        raise BundleError(msg)
    colour = header["colour"]
    if colour != "none" and (kind != "image" or len(shape) != 3 or shape[2] < 3):
        msg = f"header: colour transform {colour!r} needs an image with 3 or 4 channels"
        raise BundleError(msg)
    wavelet = header["wavelet"]
    if wavelet == LOSSLESS_WAVELET:
        if kind != "image" or colour == "ycbcr" or header["dtype"] not in ("uint8", "uint16"):
            msg = "header: the lossless wavelet is only for uint8/uint16 images"
            raise BundleError(msg)
        if any(b != "symmetric" for b in boundary):
            msg = f"header field 'boundary' must be symmetric for lossless, not {list(boundary)}"
            raise BundleError(msg)
        if any(before or after for before, after in pads):
            msg = "header: a lossless bundle is never padded"
            raise BundleError(msg)
        lifting = header.get("lifting")
        if (
            not isinstance(lifting, list)
            or len(lifting) != levels
            or any(name not in _lossless.FILTERS for name in lifting)
        ):
            msg = (
                f"header field 'lifting' must list one of {list(_lossless.FILTERS)} per level "
                f"({levels}), not {str(lifting)[:80]}"
            )
            raise BundleError(msg)
        sizes = list(fitted[:2])
        for index, name in enumerate(lifting):
            if name == "bspline2" and any(n % 2 for n in sizes):
                msg = (
                    f"header field 'lifting': level {index + 1} has odd sizes {sizes} for bspline2"
                )
                raise BundleError(msg)
            sizes = [(n + 1) // 2 for n in sizes]
    else:
        lifting = []  # the key means nothing for the other wavelets: ignored, as unknown keys are
        try:
            bank = get_wavelet(wavelet)
            for axis, b in enumerate(boundary):
                if not bank.rule(b).fits(fitted[axis], levels):
                    msg = f"length {fitted[axis]} does not fit {levels} levels"
                    raise InvalidLength(msg)
        except InvalidParameter as exc:
            msg = f"header: wavelet {wavelet!r}, boundary {list(boundary)}, levels: {exc}"
            raise BundleError(msg) from exc
    # The header names each stage twice (its name, and again inside its parameters): the two
    # must agree, or a reader that trusts either would be misled.
    coder = header["cparams"].get("coder")
    if header["coder"] != coder:
        msg = f"header field 'coder' is {header['coder']!r}, but 'cparams' names {coder!r}"
        raise BundleError(msg[:200])
    quantizer = "none" if wavelet == LOSSLESS_WAVELET else header["qparams"].get("name")
    if header["quantizer"] != quantizer:
        msg = f"header field 'quantizer' is {header['quantizer']!r}; expected {quantizer!r}"
        raise BundleError(msg[:200])
    return _Plan(
        kind,
        shape,
        header["dtype"],
        wavelet,
        boundary,
        levels,
        colour,
        tuple((int(b), int(a)) for b, a in pads),
        fitted,
        float(header["peak"]),
        tuple(lifting),
        _scale_from_header(header),
        _opaque_from_header(header, kind, shape),
    )


def _opaque_from_header(header: dict[str, Any], kind: str, shape: tuple[int, ...]) -> bool:
    """The optional ``opaque`` key (format 1.2): the alpha channel decodes fully opaque."""
    opaque = header.get("opaque", False)
    if opaque is not False and (
        opaque is not True or kind != "image" or len(shape) != 3 or shape[2] not in (2, 4)
    ):
        msg = f"header field 'opaque' must be true, and only for images with alpha, not {opaque!r}"
        raise BundleError(msg[:200])
    return bool(opaque)


def _scale_from_header(header: dict[str, Any]) -> int:
    """The optional ``scale`` key (format 1.2): decoded values are multiplied by 2**scale."""
    scale = int(header.get("scale", 0))  # its type and range are checked by check_header
    if scale and np.dtype(header["dtype"]).kind != "f":
        msg = f"header field 'scale' is {scale}, but only float data is ever scaled"
        raise BundleError(msg)
    return scale


def _open(bundle: Any) -> tuple[Bundle, _Plan]:
    if not isinstance(bundle, bytes | bytearray | memoryview):
        msg = f"a bundle must be bytes, not {type(bundle).__name__}"
        raise BundleError(msg)
    parsed = read_bundle(bundle)
    try:
        return parsed, _plan_from_header(parsed.header)
    except BundleError:
        raise
    except Exception as exc:
        # A field combination the checks above did not foresee: still the bundle's fault, and
        # the promise is "an array or BundleError" for any bytes.
        msg = f"header: inconsistent fields ({type(exc).__name__}: {exc})"
        raise BundleError(msg[:300]) from exc


def decode(
    bundle: Any, *, keep: float | None = None, level: int = 0, drop_levels: int | None = None
) -> np.ndarray:
    """Decode a bundle back into an array of the original's shape and dtype.

    Parameters
    ----------
    bundle : bytes
        What ``encode_image``/``encode_curve``/``encode_surface`` returned, or any bytes: the
        result is an array or a :class:`~wavecore.errors.BundleError`, never another error.
    keep : float, optional
        Keep only this fraction of the stored detail coefficients (the smallest by effect
        removed): a smoother, cheaper-looking reconstruction from the same bundle.
    level : int
        ``0`` for full resolution; ``k`` for the coarse approximation after ``k`` levels,
        cropped to the original's extent (about ``ceil(n / 2**k)`` samples per side), decoded
        from the first ``L - k + 1`` chunks only, so a truncated bundle still gives it.
        Note that this counts levels *dropped*, where ``encode_*(level=L)`` counts levels
        made; ``drop_levels`` says so in its name.
    drop_levels : int, optional
        The same as ``level``, under a name that says what it does: leave out the
        ``drop_levels`` finest levels of detail.  Give one of the two (both only when equal).

    Returns
    -------
    numpy.ndarray
        ``level=0``: the original's shape and dtype.  ``level=k``: a smaller array of the same
        dtype, with the same channel/coordinate axis.

    Raises
    ------
    BundleError
        For anything wrong with the bytes.
    InvalidParameter
        For a bad ``keep`` or a ``level`` deeper than the bundle's.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.random.default_rng(0).integers(0, 256, (33, 47), dtype=np.uint8)
    >>> bundle = encode_image(image, lossless=True, level=3)
    >>> decode(bundle, level=2).shape, decode(bundle, drop_levels=2).shape
    ((9, 12), (9, 12))
    """
    if curvesets.is_curve_set(bundle):  # encode_curves' bundles: a list of (n_i, d) arrays
        return curvesets.decode_curves(bundle).curves  # type: ignore[return-value]
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        msg = f"level must be an integer >= 0, not {level!r}"
        raise InvalidParameter(msg)
    if drop_levels is not None:
        if (
            isinstance(drop_levels, bool)
            or not isinstance(drop_levels, int | np.integer)
            or drop_levels < 0
        ):
            msg = f"drop_levels must be None or an integer >= 0, not {drop_levels!r}"
            raise InvalidParameter(msg)
        if level not in (0, drop_levels):
            msg = f"drop_levels={drop_levels} and level={level} disagree; give one of them"
            raise InvalidParameter(msg)
        level = drop_levels
    parsed, plan = _open(bundle)
    if level > plan.levels:
        msg = f"level {level} is deeper than the bundle's {plan.levels} levels"
        raise InvalidParameter(msg)
    try:
        return _decode(parsed, plan, keep, int(level))
    except BundleError:
        raise
    except MemoryError as exc:
        msg = f"not enough memory to decode a bundle of {plan.fitted} samples"
        raise BundleError(msg) from exc
    except Exception as exc:
        # The header passed its checks but its parameters are still inconsistent (a crafted
        # bundle with a valid CRC): whatever a stage tripped over, the bundle is what is wrong.
        msg = f"corrupt bundle: {type(exc).__name__}: {exc}"
        raise BundleError(msg) from exc


def _decode(parsed: Bundle, plan: _Plan, keep: float | None, level: int) -> np.ndarray:
    count = plan.levels - level + 1
    chunks = [parsed.chunk(i) for i in range(count)]
    for index, chunk in enumerate(chunks):
        if not chunk:  # every coder writes a few bytes even for all-zero bands
            msg = f"chunk {index} is empty; no encoder writes an empty chunk"
            raise BundleError(msg)
    shapes = _band_shapes(plan)[:count]
    header = parsed.header
    with np.errstate(all="ignore"):
        qcoeffs = decode_levels(chunks, shapes, header["cparams"])
        if plan.wavelet == LOSSLESS_WAVELET:
            if keep is not None and keep < 1.0 and len(qcoeffs) > 1:
                return _decode_lossless_keep(plan, qcoeffs, keep, level)
            data = _lossless.inverse(qcoeffs, plan.axes, plan.lifting)
            return _finish(plan, data, level)
        try:
            coeffs = dequantize_bands(
                qcoeffs,
                header["qparams"],
                wavelet=plan.wavelet,
                boundary=list(plan.boundary),
                axes=plan.axes,
            )
        except InvalidParameter as exc:
            msg = f"header field 'qparams' does not fit the bundle: {exc}"
            raise BundleError(msg[:300]) from exc
        if keep is not None and keep < 1.0 and len(coeffs) > 1:
            coeffs = remove_smallest(
                coeffs,
                1.0 - keep,
                wavelet=plan.wavelet,
                boundary=list(plan.boundary),
                axes=plan.axes,
                vector_axis=None if plan.kind == "image" else -1,
            )
        return _finish(plan, _reconstruct(plan, coeffs), level)


def _decode_lossless_keep(plan: _Plan, qcoeffs: list[Any], keep: float, level: int) -> np.ndarray:
    """``keep`` on a lossless bundle: drop the smallest integer details, then invert exactly."""
    kept = remove_smallest(
        [np.asarray(qcoeffs[0], dtype=np.float64), *qcoeffs[1:]],
        1.0 - keep,
        wavelet="haar",  # 5/3 norms are not tabulated; rank by plain magnitude instead
        weighted=False,
        axes=plan.axes,
        vector_axis=None,
    )
    ints: list[Any] = [np.asarray(qcoeffs[0])]
    for bands in kept[1:]:
        ints.append(tuple(np.asarray(b).astype(np.int64) for b in bands))
    return _finish(plan, _lossless.inverse(ints, plan.axes, plan.lifting), level)


def inspect(bundle: Any) -> dict[str, Any]:
    """Describe a bundle without decoding it.

    Returns
    -------
    dict
        ``version``, ``kind``, ``shape``, ``dtype``, ``wavelet``, ``boundary``, ``levels``,
        ``colour``, ``lossless``, ``quantizer``, ``coder``, ``psnr`` (the encoder's measured
        PSNR in dB, ``None`` when exact), ``max_error``, ``total_bytes``, ``header_bytes``,
        ``peak`` (in the original's units), ``scale`` (the power of two the values were
        coded under, ``0`` for all but huge or tiny floats), ``bpp`` (images), ``chunks``
        (one entry per chunk, coarse to fine: its resolution ``level``, its subband
        ``shapes``, its ``bytes`` and whether it is ``present``), and ``header`` (the raw
        header).

    Examples
    --------
    >>> import numpy as np
    >>> info = inspect(encode_image(np.zeros((16, 16), np.uint8), lossless=True, level=2))
    >>> info["levels"], [c["level"] for c in info["chunks"]], info["lossless"]
    (2, [2, 1, 0], True)
    """
    if curvesets.is_curve_set(bundle):
        return curvesets.inspect_curves(bundle)
    parsed, plan = _open(bundle)
    header = parsed.header
    try:
        shapes = _band_shapes(plan)
    except Exception as exc:  # a crafted header that passed every check; see decode
        msg = f"corrupt bundle: {type(exc).__name__}: {exc}"
        raise BundleError(msg) from exc
    chunks = []
    for index, (entry, chunk) in enumerate(zip(shapes, parsed.chunks, strict=True)):
        band_shapes = (
            [list(entry)] if index == 0 or len(plan.axes) == 1 else [list(s) for s in entry]
        )
        chunks.append(
            {
                "level": plan.levels - index,
                "bands": ["cA"]
                if index == 0
                else (["cD"] if len(plan.axes) == 1 else ["cH", "cV", "cD"]),
                "shapes": band_shapes,
                "bytes": len(chunk) if chunk is not None else None,
                "present": chunk is not None,
            }
        )
    payload = sum(len(c) for c in parsed.chunks if c is not None)
    total = len(bundle)
    info: dict[str, Any] = {
        "version": f"{parsed.version[0]}.{parsed.version[1]}",
        "kind": plan.kind,
        "shape": list(plan.shape),
        "dtype": plan.dtype,
        "wavelet": plan.wavelet,
        "boundary": list(plan.boundary),
        "levels": plan.levels,
        "colour": plan.colour,
        "lossless": plan.wavelet == LOSSLESS_WAVELET,
        "quantizer": header["quantizer"],
        "coder": header["coder"],
        "psnr": header["psnr"],
        "max_error": header["max_error"],
        "peak": _unscaled(plan.peak, plan.scale),
        "scale": plan.scale,
        "total_bytes": total,
        "header_bytes": total - payload,
        "chunks": chunks,
        "header": header,
    }
    if plan.kind == "image":
        info["bpp"] = 8.0 * total / (plan.shape[0] * plan.shape[1])
    return info
