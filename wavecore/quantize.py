"""Dead-zone scalar quantization of wavelet subbands, weighted by the synthesis basis norms.

These filters are not orthogonal (``NOTES.md``): an error ``e`` in one coefficient becomes an
error of ``e · ‖g‖`` in the reconstruction, where ``g`` is that coefficient's synthesis basis
function.  To spend bits where they matter, every subband gets its own step,

    step_b = step / ‖g_b‖,

with ``‖g_b‖`` the root-mean-square basis norm of the band (:func:`wavecore.basis_norms`); this
makes the reconstruction error of every band about ``step² / 12`` per coefficient, which is the
equal-slope allocation for mean squared error at high rate.

The quantizer is a dead-zone uniform one: ``q = sign(x) · floor(|x| / step_b + rounding)``
with ``rounding < 1/2``, so the zero bin is wider than the others (small coefficients, mostly
noise, cost nothing).  The decoder puts a nonzero ``q`` back at ``sign(q) · (|q| + offset) ·
step_b``, with ``offset`` the centroid of a Laplacian fitted to the band's own histogram of
indices (:func:`reconstruction_offset`): wavelet details are peaked, so their centroids sit below
the bin middles, and since both sides compute the offset from the integers it costs no bits.

Everything the decoder needs is in ``params``, a JSON-serialisable dict, listed from the coarse
end so that a prefix of the layout (a coarse decode) can be dequantized on its own.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Sequence
from decimal import ROUND_FLOOR, Decimal, localcontext
from typing import Any

import numpy as np
from numba import njit

from . import _kernels
from .adjoint import synthesis_adjoint
from .errors import InvalidLength, InvalidParameter
from .filters import CACHE_CLEARERS, get_wavelet
from .layout import as_levels, from_levels
from .multilevel import waverec, waverec2
from .norms import basis_norms, mean_squared_norms
from .transform import run_calls, run_rows, run_slices

__all__ = [
    "ClosedLoopFit",
    "OpenLoopDistortion",
    "band_weight_margins",
    "dequantize_bands",
    "quantize_bands",
    "reconstruction_offset",
]

#: ``rounding`` of the dead-zone quantizer: 0.5 would be plain rounding; smaller widens the zero
#: bin.  Tuned on the scikit-image test pictures (0.22 to 0.32 are within 0.05 dB; 0.38 is
#: 0.1 dB worse for bspline2, with the closed loop deciding the values of what is kept).
DEFAULT_ROUNDING = 0.27
#: The coarsest band is smooth and dense: it is quantized with plain rounding.
APPROX_ROUNDING = 0.5
#: Largest magnitude of a quantized integer (int32 with room for arithmetic in the coder).
MAX_INDEX = 2**30
QUANTIZER_NAME = "deadzone"
#: Closed-loop iterations by default: the gain levels off after about six (see ``refine``).
REFINE_ITERATIONS = 6
#: Above this many coefficients the default is no refinement (a 1024 × 1024 grey image, or
#: 590 × 590 RGB, is about the limit), to keep large encodes fast.
REFINE_MAX_COEFFICIENTS = 1 << 20


def _fine_lengths(levels: list[list[np.ndarray]], axes: Sequence[int]) -> list[int]:
    """The fine length along each transformed axis: coarse plus every level's details."""
    lengths = []
    for index, axis in enumerate(axes):
        n = levels[0][0].shape[axis]
        for bands in levels[1:]:
            # The band that is a detail along ``axis`` alone: band 0 for axis 0 (cH is "da"),
            # band 1 for axis 1 (cV is "ad"); a 1-D level has one band.
            n += bands[index if len(bands) > 1 else 0].shape[axis]
        lengths.append(int(n))
    return lengths


@functools.lru_cache(maxsize=512)
def _rms_norms(n: int, wavelet: str, boundary: str, level: int) -> tuple[float, float]:
    """RMS coarse and detail basis norms of one axis and level: the rate searches ask for the
    same ones at every trial step (a few milliseconds each time at 512²)."""
    norms = basis_norms(n, wavelet, boundary, level)
    return float(np.sqrt(np.mean(norms[0] ** 2))), float(np.sqrt(np.mean(norms[1] ** 2)))


def _band_norms(
    levels: list[list[np.ndarray]],
    wavelet: str,
    boundary: str | Sequence[str],
    axes: Sequence[int],
) -> list[list[float]]:
    """Root-mean-square synthesis basis norm of every band, laid out like ``levels``."""
    count = len(levels) - 1
    bounds = [boundary] * len(axes) if isinstance(boundary, str) else list(boundary)
    if len(bounds) != len(axes):
        msg = f"need one boundary per axis ({len(axes)}), not {bounds!r}"
        raise InvalidParameter(msg)
    lengths = _fine_lengths(levels, axes)
    if count == 0:
        return [[1.0]]
    if len(axes) == 1:
        rms = [
            _rms_norms(int(lengths[0]), wavelet, str(bounds[0]), lvl) for lvl in range(count, 0, -1)
        ]
        return [[rms[0][0]]] + [[detail] for _, detail in rms]
    # Two axes: the square root of the product of the axes' mean squares, so that norms whose
    # squares are exact (Haar's powers of two) come out exact, not an ulp off from a product of
    # two rounded square roots (which put Haar's weights 2**-6 and 2**-7 a few ulps from a
    # change of digit, and made 3.1 store six of them).
    means = [
        [mean_squared_norms(int(n), wavelet, str(b), lvl) for lvl in range(count, 0, -1)]
        for n, b in zip(lengths, bounds, strict=True)
    ]
    out: list[list[float]] = [[math.sqrt(means[0][0][0] * means[1][0][0])]]
    for (a0, d0), (a1, d1) in zip(means[0], means[1], strict=True):
        # cH ("da"), cV ("ad"), cD ("dd")
        out.append([math.sqrt(d0 * a1), math.sqrt(a0 * d1), math.sqrt(d0 * d1)])
    return out


def band_weights(
    coeffs: Sequence[Any],
    *,
    wavelet: str,
    boundary: str | Sequence[str],
    axes: Sequence[int] = (0, 1),
) -> list[list[float]]:
    """Each band's step relative to the global one (``quantize_bands``' ``params["weights"]``).

    The reciprocal of the RMS norm of the band's synthesis basis functions, to four significant
    digits (they are stored in the header, and the encoder uses the rounded values too); listed
    from the coarse end, ``[[cA], [level L bands], ...]``.
    """
    norms = _band_norms(as_levels(coeffs), wavelet, boundary, tuple(int(a) for a in axes))
    return [[float(f"{_unrounded_weight(norm):.4g}") for norm in level] for level in norms]


def _unrounded_weight(norm: float) -> float:
    return 1.0 / max(norm, 1e-12)


def band_weight_margins(
    coeffs: Sequence[Any],
    *,
    wavelet: str,
    boundary: str | Sequence[str],
    axes: Sequence[int] = (0, 1),
) -> list[list[float]]:
    """How far each band's weight is from flipping a digit: the distance of its unrounded
    value from the nearest rounding boundary of :func:`band_weights`' four significant digits,
    relative to the value, laid out as ``band_weights``' result.

    The norms are sums computed in floating point, so another machine (another SIMD width,
    another summation order) may get them a few ulps apart.  A weight whose margin is far
    larger than that rounds to the same four digits everywhere; a bundle that derives the
    weights from the plan instead of storing them stores those whose margin is small
    (``docs/bundle-format.md``, *The binary header in 3.1*).

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import wavedec2
    >>> coeffs = wavedec2(np.zeros((34, 34)), level=2)
    >>> margins = band_weight_margins(coeffs, wavelet="bspline2", boundary="open")
    >>> [len(level) for level in margins], all(0 <= m < 1e-3 for lv in margins for m in lv)
    ([1, 3, 3], True)
    """
    norms = _band_norms(as_levels(coeffs), wavelet, boundary, tuple(int(a) for a in axes))
    return [[_rounding_margin(_unrounded_weight(norm)) for norm in level] for level in norms]


def _rounding_margin(value: float) -> float:
    """Relative distance of a positive ``value`` from the nearest point where its four
    significant digits change (``d.ddd5 · 10**e``), in exact decimal arithmetic."""
    exact = Decimal(value)  # the binary value, exactly
    with localcontext() as context:
        context.prec = 80
        unit = Decimal(10) ** (exact.adjusted() - 3)
        scaled = exact / unit  # in [1000, 10000)
        fraction = scaled - scaled.to_integral_value(rounding=ROUND_FLOOR)
        distance = abs(fraction - Decimal("0.5"))
        # Just above a power of ten the decade below is ten times finer: 999.95 rounds up.
        distance = min(distance, scaled - Decimal("999.95"))
        return float(distance * unit / exact)


def _check_step(step: Any) -> float:
    if isinstance(step, bool) or not isinstance(step, int | float | np.integer | np.floating):
        msg = f"step must be a positive number, not {step!r}"
        raise InvalidParameter(msg)
    if not (math.isfinite(float(step)) and float(step) > 0):
        msg = f"step must be a positive finite number, not {step!r}"
        raise InvalidParameter(msg)
    return float(step)


def quantize_bands(
    coeffs: Sequence[Any],
    step: float,
    *,
    wavelet: str,
    boundary: str | Sequence[str],
    axes: Sequence[int] = (0, 1),
    rounding: float = DEFAULT_ROUNDING,
    refine: int | None = None,
) -> tuple[list[Any], dict[str, Any]]:
    """Quantize a decomposition to integers, band by band, in closed loop.

    Parameters
    ----------
    coeffs : list
        ``wavedec2`` layout ``[cA, (cH, cV, cD), ...]`` or ``wavedec`` layout ``[cA, cD, ...]``
        (coarse first).  Bands may carry trailing axes (colour channels, point coordinates).
    step : float
        The step in the *reconstruction's* units: every band's own step is ``step`` divided by
        the RMS norm of its synthesis basis functions.
    wavelet, boundary
        Those of the decomposition (they fix the basis norms).
    axes : sequence of int
        The transformed axes: ``(0, 1)`` for ``wavedec2`` layouts, ``(0,)`` for ``wavedec``.
    rounding : float
        Dead-zone parameter in ``(0, 0.5]``: a detail becomes nonzero from
        ``(1 - rounding) · step_b`` on.
    refine : int, optional
        Iterations of the closed-loop refinement (0 turns it off; ``None``, the default, runs
        ``REFINE_ITERATIONS`` for decompositions of up to ``REFINE_MAX_COEFFICIENTS``
        coefficients and none beyond, where its cost, a synthesis and its adjoint per
        iteration, would dominate the encoder): with the dead zone's choice
        of which details stay nonzero fixed, the kept coefficients are re-fitted by least
        squares to the *reconstruction* (preconditioned conjugate gradients with the exact
        adjoint of the synthesis) and quantized again.  The analysis coefficients of a
        non-orthogonal transform are the best ones only when nothing is dropped; once the dead
        zone drops details, the least-squares fit of the rest is better (about +1 dB for
        ``bspline2`` at the same rate; ``cdf97`` is nearly orthogonal and gains little).

    Returns
    -------
    qcoeffs : list
        ``int32`` arrays in the same layout.
    params : dict
        JSON-serialisable: ``name``, ``step``, ``rounding`` and per-band ``weights`` (band step
        = ``step · weight``), listed from the coarse end (``[[cA], [level L bands], ...]``).

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import wavedec2, waverec2
    >>> image = np.random.default_rng(0).random((34, 34)) * 255
    >>> coeffs = wavedec2(image, level=2)
    >>> q, params = quantize_bands(coeffs, 2.0, wavelet="bspline2", boundary="open")
    >>> q[0].dtype, len(params["weights"])
    (dtype('int32'), 3)
    >>> back = dequantize_bands(q, params, wavelet="bspline2", boundary="open")
    >>> bool(np.sqrt(np.mean((waverec2(back) - image) ** 2)) < 2.0)
    True
    """
    step = _check_step(step)
    if not 0.0 < float(rounding) <= 0.5:
        msg = f"rounding must be in (0, 0.5], not {rounding!r}"
        raise InvalidParameter(msg)
    axes = tuple(int(a) for a in axes)
    levels = as_levels(coeffs)
    weights = band_weights(coeffs, wavelet=wavelet, boundary=boundary, axes=axes)
    out_levels: list[list[np.ndarray]] = []
    jobs: list[
        tuple[np.ndarray, float, float, np.ndarray]
    ] = []  # flat values, 1/step, rounding, out
    for index, (bands, level_weights) in enumerate(zip(levels, weights, strict=True)):
        band_rounding = APPROX_ROUNDING if index == 0 else float(rounding)
        level_q = []
        for band, weight in zip(bands, level_weights, strict=True):
            values = np.ascontiguousarray(band, dtype=np.float64)
            q = np.empty(values.shape, dtype=np.int32)
            band_step = step * weight
            if not band_step >= sys.float_info.min:  # subnormal: its inverse overflows
                msg = f"step {step!r} is too small: a band's step, {band_step!r}, is subnormal"
                raise InvalidParameter(msg)
            jobs.append((values.reshape(-1), 1.0 / band_step, band_rounding, q.reshape(-1)))
            level_q.append(q)
        out_levels.append(level_q)
    _quantize_all(jobs)
    params = {
        "name": QUANTIZER_NAME,
        "step": step,
        "weights": weights,
        "rounding": float(rounding),
    }
    if refine is None:
        total = sum(band.size for level in levels for band in level)
        refine = REFINE_ITERATIONS if total <= REFINE_MAX_COEFFICIENTS else 0
    if isinstance(refine, bool) or not isinstance(refine, int | np.integer) or refine < 0:
        msg = f"refine must be a number of iterations >= 0, not {refine!r}"
        raise InvalidParameter(msg)
    if refine and len(levels) > 1:
        fitted = _refine(coeffs, levels, out_levels, params, wavelet, boundary, axes, refine)
        if fitted is not None:
            out_levels = _requantize(fitted[0], out_levels, params)
    return from_levels(coeffs, out_levels), params


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"quantizer parameter {what} must be a number, not {value!r}"
        raise InvalidParameter(msg)
    if not math.isfinite(float(value)):
        msg = f"quantizer parameter {what} must be finite, not {value!r}"
        raise InvalidParameter(msg)
    return float(value)


def dequantize_bands(
    qcoeffs: Sequence[Any],
    params: dict[str, Any],
    *,
    wavelet: str,
    boundary: str | Sequence[str],
    axes: Sequence[int] = (0, 1),
    out: Sequence[Any] | None = None,
) -> list[Any]:
    """Turn quantized integers back into coefficients (the inverse of :func:`quantize_bands`).

    ``qcoeffs`` may be a prefix of the layout (``[cA, level L, ..., level k+1]``): ``params``
    describes the bands from the coarse end.  ``wavelet``, ``boundary`` and ``axes`` are accepted
    for symmetry with :func:`quantize_bands`; the steps stored in ``params`` are all the
    decoder needs.  ``out``, in the same layout, gives arrays to write the coefficients into
    (each band that is ``float64``, C-contiguous, writeable and of its band's shape; a new
    array for any other): an encoder's own coefficients once it no longer needs them, so that
    a full-size picture's dequantization does not fault in fresh memory.

    Raises
    ------
    InvalidParameter
        If ``params`` does not describe these bands (it may come from an untrusted header).

    Examples
    --------
    >>> import numpy as np
    >>> q = [np.array([[3, -1], [0, 2]], dtype=np.int32)]
    >>> params = {"name": "deadzone", "step": 0.5, "weights": [[1.0]], "rounding": 0.4}
    >>> dequantize_bands(q, params, wavelet="haar", boundary="open")[0]
    array([[ 1.5, -0.5],
           [ 0. ,  1. ]])
    """
    del wavelet, boundary, axes  # the steps are stored; see the docstring
    if not isinstance(params, dict) or params.get("name") != QUANTIZER_NAME:
        msg = f"quantizer parameters must be a dict with name {QUANTIZER_NAME!r}"
        raise InvalidParameter(msg)
    step = _number(params.get("step"), "step")
    rounding = _number(params.get("rounding"), "rounding")
    if not (step > 0 and 0 < rounding <= 0.5):
        msg = f"quantizer step {step!r} or rounding {rounding!r} out of range"
        raise InvalidParameter(msg)
    weights = params.get("weights")
    levels = as_levels(qcoeffs)
    if not isinstance(weights, list) or len(weights) < len(levels):
        msg = f"quantizer parameters describe fewer levels than the {len(levels)} given"
        raise InvalidParameter(msg)
    targets = None if out is None else as_levels(out)
    out_levels = []
    jobs: list[tuple[np.ndarray, bool, float, np.ndarray]] = []  # flat q, detail?, step, out
    for index, bands in enumerate(levels):
        level_weights = weights[index]
        if not isinstance(level_weights, list) or len(level_weights) != len(bands):
            msg = f"quantizer weights of level entry {index} do not match its {len(bands)} bands"
            raise InvalidParameter(msg)
        restored = []
        for k, (band, weight) in enumerate(zip(bands, level_weights, strict=True)):
            band_step = step * _number(weight, "weight")
            q = np.asarray(band)
            if q.dtype.kind not in "iu":
                msg = f"quantized coefficients must be integers, not {q.dtype}"
                raise InvalidParameter(msg)
            values = _writable_target(targets, index, k, q.shape)
            jobs.append((np.ravel(q), index > 0, band_step, values.reshape(-1)))
            restored.append(values)
        out_levels.append(restored)
    _dequantize_all(jobs, rounding)
    return from_levels(qcoeffs, out_levels)


def _writable_target(
    targets: list[list[np.ndarray]] | None, index: int, k: int, shape: tuple[int, ...]
) -> np.ndarray:
    """Band ``k`` of level entry ``index`` of ``targets`` if the dequantizer can write into it
    as it is (float64, C-contiguous, writeable, ``shape``), else a new array."""
    if targets is not None and index < len(targets) and k < len(targets[index]):
        target = targets[index][k]
        if (
            target.dtype == np.float64
            and target.shape == shape
            and target.flags.c_contiguous
            and target.flags.writeable
        ):
            return target
    return np.empty(shape, dtype=np.float64)


def reconstruction_offset(q: np.ndarray, rounding: float) -> float:
    """Where in its bin a nonzero index goes back, relative to ``|q|``, from the band's histogram.

    Details are close to Laplacian, and an exponential density looks the same in every bin, so
    one number describes them all: ``theta = P(|q| >= 2 | |q| >= 1)`` is the density's decay over
    one bin width.  The centroid of ``exp(-a t)`` on ``[0, 1)`` with ``exp(-a) = theta`` is
    ``1/a - theta / (1 - theta)``; the bin of ``|q|`` starts at ``|q| - rounding``.  Encoder and
    decoder compute it from the same integers, so it costs no bits.

    Examples
    --------
    >>> import numpy as np
    >>> q = np.array([0, 1, 1, 1, 1, 2, -1, 3])  # theta = 2 / 7: steeply decaying
    >>> bool(-0.4 < reconstruction_offset(q, 0.4) < 0.5 - 0.4)  # below the bin's middle
    True
    """
    flat = np.ravel(q)
    counts: list[tuple[int, int]] = []
    # In slices over the threads: the counts are integers, so their sum is the one-pass count
    # exactly (about 1 ms of serial time for each finest band of a 2048² RGB picture).
    run_rows(
        lambda lo, hi: counts.append(_kernels.count_ones_and_more(flat[lo:hi])),
        flat.size,
        flat.size,
    )
    return _offset_from_counts(
        sum(int(ones) for ones, _ in counts), sum(int(more) for _, more in counts), rounding
    )


def _offset_from_counts(ones: int, more: int, rounding: float) -> float:
    """:func:`reconstruction_offset` from the band's counts of ``|q| == 1`` and ``|q| >= 2``."""
    if ones + more == 0:
        return 0.5 - rounding
    theta = min(max(more / (ones + more), 0.02), 0.98)
    a = -math.log(theta)
    return 1.0 / a - theta / (1.0 - theta) - rounding


# --------------------------------------------------------------------------------------------
# Closed loop: least squares on the kept coefficients, with the adjoint of the synthesis
# --------------------------------------------------------------------------------------------


def _adjoint(
    residual: np.ndarray, bank_name: str, bounds: list[str], axes: tuple[int, ...], count: int
) -> list[list[np.ndarray]]:
    """``S.T @ residual`` for the synthesis ``S`` of ``count`` levels, in ``levels`` layout."""
    return as_levels(synthesis_adjoint(residual, bank_name, bounds, count, axes))


def _synthesis(
    levels: list[list[np.ndarray]], wavelet: str, bounds: list[str], axes: tuple[int, ...]
) -> np.ndarray:
    if len(axes) == 1:
        return waverec([lv[0] for lv in levels], wavelet, bounds[0], axis=axes[0])
    return waverec2([levels[0][0], *(tuple(lv) for lv in levels[1:])], wavelet, bounds, axes)


@functools.lru_cache(maxsize=256)
def _adjoint_covers(
    shape: tuple[int, ...],
    bank_name: str,
    bounds: tuple[str, ...],
    axes: tuple[int, ...],
    count: int,
) -> bool:
    """Whether the adjoint runs on this layout (else it raises): tried once per layout, not
    once per closed loop (a whole adjoint each time)."""
    _adjoint(np.zeros(shape), bank_name, list(bounds), axes, count)
    return True


def _refine(
    template: Sequence[Any],
    levels: list[list[np.ndarray]],
    q_levels: list[list[np.ndarray]],
    params: dict[str, Any],
    wavelet: str,
    boundary: str | Sequence[str],
    axes: tuple[int, ...],
    iterations: int,
    start: tuple[list[list[np.ndarray]], np.ndarray] | None = None,
) -> tuple[list[list[np.ndarray]], np.ndarray] | None:
    """Least-squares re-fit of the kept coefficients to the reconstruction: the fitted values
    (zero where the dead zone dropped the detail) and the reconstruction they fit, or None
    where the closed loop cannot run.  ``start``, an earlier result of the same coefficients,
    is where the iterations start (and its reconstruction is not synthesised again)."""
    bank = get_wavelet(wavelet)
    bounds = [boundary] * len(axes) if isinstance(boundary, str) else list(boundary)
    if len(axes) not in (1, 2) or any(a != i for i, a in enumerate(axes)):
        return None  # only the leading-axes layouts of wavedec and wavedec2
    if start is not None:
        target = start[1]
    else:
        try:
            target = _synthesis(levels, bank.name, bounds, axes)
            _adjoint_covers(target.shape, bank.name, tuple(bounds), axes, len(levels) - 1)
        except (InvalidLength, InvalidParameter, ValueError):
            return None  # a size the adjoint tables do not cover: keep the open-loop result
    flat_q = [band for level in q_levels for band in level]
    shape_of = [len(level) for level in q_levels]
    steps = [params["step"] * w for level in params["weights"] for w in level]
    deq = dequantize_bands(
        from_levels(template, q_levels), params, wavelet=wavelet, boundary=boundary, axes=axes
    )
    flat_c = [np.asarray(band, dtype=np.float64) for level in as_levels(deq) for band in level]
    keep = [np.ones(flat_q[0].shape, dtype=bool)] + [band != 0 for band in flat_q[1:]]
    precondition = [(s / params["step"]) ** 2 for s in steps]  # 1 / norm² of each band

    def nest(flat: list[np.ndarray]) -> list[list[np.ndarray]]:
        out, start = [], 0
        for size in shape_of:
            out.append(flat[start : start + size])
            start += size
        return out

    # A short curve's layout: its synthesis as one dense matrix, cheaper than the level-by-level
    # calls (the same integers; a curve set's wavelet form 1.6x faster).
    dense = (
        _dense_synthesis(tuple(len(b) for b in flat_q), bank.name, bounds[0])
        if len(axes) == 1
        else None
    )

    def synthesize(flat: list[np.ndarray]) -> np.ndarray:
        if dense is not None:
            return np.asarray(dense[0] @ np.concatenate(flat))
        return _synthesis(nest(flat), bank.name, bounds, axes)

    def adjoint(image: np.ndarray) -> list[np.ndarray]:
        if dense is not None:
            return list(np.split(dense[0].T @ image, dense[1]))
        return [b for lv in _adjoint(image, bank.name, bounds, axes, len(levels) - 1) for b in lv]

    def normal(direction: list[np.ndarray]) -> list[np.ndarray]:
        back = adjoint(synthesize(direction))
        return [k * b for k, b in zip(keep, back, strict=True)]

    def dot(a: list[np.ndarray], b: list[np.ndarray]) -> float:
        return float(sum(float((u * v).sum()) for u, v in zip(a, b, strict=True)))

    if start is not None:
        # A warm start (a fit at a step close by): its values where it has them.
        flat_s = [np.asarray(band, dtype=np.float64) for level in start[0] for band in level]
        flat_c = [np.where(v != 0, v, c) for v, c in zip(flat_s, flat_c, strict=True)]
    coefficients = [c * k for c, k in zip(flat_c, keep, strict=True)]
    current = synthesize(coefficients)
    residual = [k * g for k, g in zip(keep, adjoint(target - current), strict=True)]
    scaled = [r * w for r, w in zip(residual, precondition, strict=True)]
    direction = [s.copy() for s in scaled]
    rz = dot(residual, scaled)
    for _ in range(iterations):
        if rz <= 0:
            break
        product = normal(direction)
        curvature = dot(direction, product)
        if curvature <= 0:
            break
        alpha = rz / curvature
        coefficients = [c + alpha * d for c, d in zip(coefficients, direction, strict=True)]
        residual = [r - alpha * p for r, p in zip(residual, product, strict=True)]
        scaled = [r * w for r, w in zip(residual, precondition, strict=True)]
        rz_next = dot(residual, scaled)
        direction = [s + (rz_next / rz) * d for s, d in zip(scaled, direction, strict=True)]
        rz = rz_next
    return nest(coefficients), target


#: The longest 1-D layout whose synthesis the closed loop holds as a dense matrix.
_DENSE_LOOP_LENGTH = 128


@functools.lru_cache(maxsize=64)
def _dense_synthesis(
    lengths: tuple[int, ...], bank_name: str, boundary: str
) -> tuple[np.ndarray, list[int]] | None:
    total = sum(lengths)
    if total > _DENSE_LOOP_LENGTH or len(lengths) < 2:
        return None
    identity = np.eye(total)
    cuts = list(np.cumsum(lengths)[:-1])
    bands = np.split(identity, cuts)
    matrix = waverec(bands, bank_name, boundary, axis=0)
    return np.ascontiguousarray(matrix), cuts


CACHE_CLEARERS.append(_dense_synthesis.cache_clear)  # keyed by a wavelet's name


def _requantize(
    fitted: list[list[np.ndarray]], q_levels: list[list[np.ndarray]], params: dict[str, Any]
) -> list[list[np.ndarray]]:
    """The closed loop's integers: ``fitted`` quantized where ``q_levels`` (the dead zone's
    integers at ``params``' step) is nonzero, with the reconstruction offsets of those."""
    rounding = float(params["rounding"])
    out = []
    for index, (values, q_bands, weights) in enumerate(
        zip(fitted, q_levels, params["weights"], strict=True)
    ):
        bands = []
        for value, q, weight in zip(values, q_bands, weights, strict=True):
            step = params["step"] * weight
            offset = 0.0 if index == 0 else reconstruction_offset(q, rounding)
            magnitude = np.maximum(np.round(np.abs(value) / step - offset), 0.0)
            np.minimum(magnitude, MAX_INDEX, out=magnitude)
            kept = np.copysign(magnitude, value)
            bands.append((kept if index == 0 else np.where(q != 0, kept, 0.0)).astype(np.int32))
        out.append(bands)
    return out


class ClosedLoopFit:
    """The closed loop (``quantize_bands(..., refine=iterations)``) at one step, kept so that
    steps close to it can be quantized from the same least-squares fit without running it again.

    At its own step, :meth:`quantize` gives exactly ``quantize_bands``' closed-loop result.  At
    another step the fitted values are quantized with that step, keeping the details that both
    the fit and the dead zone at the new step keep: the fit moves little between close steps,
    so this is close to a closed loop there, for the cost of an open loop.  Rate control uses
    it to correct a closed loop's small miss of a quality target.

    Parameters
    ----------
    coeffs, step, wavelet, boundary, axes, rounding
        As for :func:`quantize_bands`.
    iterations : int
        The closed loop's iterations (``REFINE_ITERATIONS`` by default).
    start : ClosedLoopFit, optional
        A fit of the same coefficients at a step close by, to start from (a warm start): its
        values are most of the way to this step's, so fewer iterations do, and the
        reconstruction they fit is not synthesised again.
    """

    def __init__(
        self,
        coeffs: Sequence[Any],
        step: float,
        *,
        wavelet: str,
        boundary: str | Sequence[str],
        axes: Sequence[int] = (0, 1),
        rounding: float = DEFAULT_ROUNDING,
        iterations: int = REFINE_ITERATIONS,
        start: ClosedLoopFit | None = None,
    ) -> None:
        self.coeffs, self.step = coeffs, _check_step(step)
        self._options: dict[str, Any] = {
            "wavelet": wavelet,
            "boundary": boundary,
            "axes": tuple(int(a) for a in axes),
            "rounding": rounding,
        }
        q, params = quantize_bands(coeffs, self.step, refine=0, **self._options)
        self._open = (q, params)  # the dead zone at the fit's own step
        levels, q_levels = as_levels(coeffs), as_levels(q)
        self._fitted: tuple[list[list[np.ndarray]], np.ndarray] | None = None
        if iterations and len(levels) > 1:
            self._fitted = _refine(
                coeffs, levels, q_levels, params, wavelet, boundary, self._options["axes"],
                iterations, None if start is None else start._fitted,
            )  # fmt: skip
        # Which details the fit kept: at other steps only these may stay (a detail the fit
        # dropped was compensated by its neighbours, so adding it back would count it twice).
        self._kept = [[band != 0 for band in bands] for bands in q_levels]

    def quantize(self, step: float) -> tuple[list[Any], dict[str, Any]]:
        """The integers and parameters at ``step`` (see the class docstring)."""
        if step == self.step:
            q, params = self._open
        else:
            q, params = quantize_bands(self.coeffs, _check_step(step), refine=0, **self._options)
        if self._fitted is None:
            return q, params
        q_levels = [
            [
                band if index == 0 else np.where(kept, band, 0)
                for band, kept in zip(bands, mask, strict=True)
            ]
            for index, (bands, mask) in enumerate(zip(as_levels(q), self._kept, strict=True))
        ]
        fitted = _requantize(self._fitted[0], q_levels, params)
        return from_levels(self.coeffs, fitted), params


def _quantize_all(jobs: list[tuple[np.ndarray, float, float, np.ndarray]]) -> None:
    """The dead-zone quantizer's compiled pass over every band (flat values, inverse step,
    rounding, flat output) in one parallel region: one hand-off for all the bands, and the
    small ones run beside the large ones instead of alone on the calling thread.  Elementwise,
    so the integers do not depend on the slicing (or on the thread count)."""

    def run(item: int, lo: int, hi: int) -> None:
        values, inverse_step, rounding, out = jobs[item]
        _kernels.deadzone_quantize(values[lo:hi], inverse_step, rounding, MAX_INDEX, out[lo:hi])

    run_slices([job[0].size for job in jobs], run)


def _dequantize_all(
    jobs: list[tuple[np.ndarray, bool, float, np.ndarray]], rounding: float
) -> None:
    """Dequantize every band (flat integers, whether a detail band, band step, flat output) in
    two parallel regions: the detail bands' counts for their offsets
    (:func:`reconstruction_offset`: whole numbers, whatever the slicing), then the values."""
    details = [k for k, job in enumerate(jobs) if job[1]]
    counts = np.zeros((len(jobs), 2), dtype=np.int64)
    parts: list[tuple[int, int, int]] = []

    def count(item: int, lo: int, hi: int) -> None:
        ones, more = _kernels.count_ones_and_more(jobs[details[item]][0][lo:hi])
        parts.append((details[item], int(ones), int(more)))

    run_slices([jobs[k][0].size for k in details], count)
    for item, ones, more in parts:
        counts[item] += (ones, more)
    offsets = [
        _offset_from_counts(int(counts[k, 0]), int(counts[k, 1]), rounding) if job[1] else 0.0
        for k, job in enumerate(jobs)
    ]

    def run(item: int, lo: int, hi: int) -> None:
        q, _, step, out = jobs[item]
        _kernels.dequantize(q[lo:hi], offsets[item], step, out[lo:hi])

    run_slices([job[0].size for job in jobs], run)


# --------------------------------------------------------------------------------------------
# The open loop's squared error, predicted in the coefficient domain
# --------------------------------------------------------------------------------------------


@njit(nogil=True, cache=True)
def _deadzone_error_terms(values, channels, inverse_step, rounding, largest):
    """One pass of the dead-zone quantizer's error terms over a flat band, in step units.

    ``values`` interleaves ``channels`` channels (a band's trailing axis).  Returns the
    counts of ``|q| == 1`` and ``|q| >= 2`` and, per channel, ``(dropped, residual,
    residual2)``: the sum of ``(v / step)**2`` over the values quantized to zero and, over the
    nonzero ones, the sums of ``r`` and ``r**2`` with ``r = |v| / step - |q|``, and their
    number.  The squared error with the decoder's offset ``o`` is then ``dropped + residual2 -
    2 o residual + number · o**2`` (times ``step**2``), for any ``o``: so one pass serves the
    offset, which the decoder derives from the counts, as well.
    """
    sums = np.zeros((4, channels))
    ones = 0.0
    more = 0.0
    for c in range(channels):
        dropped = 0.0
        residual = 0.0
        residual2 = 0.0
        nonzero = 0.0
        for k in range(c, values.size, channels):
            scaled = abs(values[k]) * inverse_step
            q = min(np.floor(scaled + rounding), largest)
            # Selects rather than branches, so that the loop vectorises.
            kept = 1.0 if q > 0.0 else 0.0
            r = (scaled - q) * kept
            dropped += scaled * scaled * (1.0 - kept)
            residual += r
            residual2 += r * r
            nonzero += kept
            ones += 1.0 if q == 1.0 else 0.0
        sums[0, c] = dropped
        sums[1, c] = residual
        sums[2, c] = residual2
        sums[3, c] = nonzero
        more += nonzero
    more -= ones
    return int(ones), int(more), sums


#: Bands smaller than this are summed on the calling thread (a thread hand-off costs more).
_THREADED_TERMS = 1 << 17
#: Slices of a band at least that large: a fixed count, so that the sums do not depend on the
#: thread count, and enough for the pool to balance them on a few cores.
_TERMS_PIECES = 8


def _band_error_terms(
    values: np.ndarray, channels: int, band_step: float, rounding: float
) -> tuple[int, int, np.ndarray]:
    """``_deadzone_error_terms`` over a flat band, in slices of whole pixels over the threads
    (so that each value's channel is its index modulo ``channels``), added up.

    The float sums depend on where the slices end and on the order they are added in, so
    both follow from the band's size alone: the predicted error, and the steps that the
    quality search picks from it, are the same on any number of threads."""
    pixels = values.size // channels
    pieces = 1 if values.size < _THREADED_TERMS else min(pixels, _TERMS_PIECES)
    edges = [pixels * k // pieces for k in range(pieces + 1)]
    parts: list[Any] = [None] * pieces

    def run(piece: int) -> None:
        chunk = values[edges[piece] * channels : edges[piece + 1] * channels]
        parts[piece] = _deadzone_error_terms(chunk, channels, 1.0 / band_step, rounding, MAX_INDEX)

    if pieces == 1:
        run(0)
    else:
        run_calls([functools.partial(run, piece) for piece in range(pieces)])
    sums = np.zeros((4, channels))
    for part in parts:  # in the slices' order
        sums += part[2]
    return sum(p[0] for p in parts), sum(p[1] for p in parts), sums


class OpenLoopDistortion:
    """The open-loop quantizer's squared error at any step, from the coefficients alone.

    An error ``e`` in a coefficient becomes ``e · ‖g‖`` in the reconstruction (module
    docstring), and quantization errors are close to uncorrelated, so the reconstruction's
    summed squared error is close to ``Σ_b ‖g_b‖² Σ_i (x_i - x̂_i)²`` over the bands: one
    compiled pass over the coefficients per step (with the decoder's reconstruction offsets),
    no synthesis.  Rate control uses it to predict a step's PSNR, scaled by a ratio to what
    the decoded picture really measures (close to one; the closed loop's lower).

    Parameters
    ----------
    coeffs : list
        The decomposition, as for :func:`quantize_bands`.
    wavelet, boundary, axes
        As for :func:`quantize_bands` (they fix the band weights).
    rounding : float
        The detail bands' dead-zone parameter.
    channel_gains : sequence of float, optional
        For bands with a trailing channel axis: how much a squared error in each channel
        counts (after a colour transform, the squared column norms of its inverse); the
        trailing axes are flattened to the channels.  Default: all count once.
    """

    def __init__(
        self,
        coeffs: Sequence[Any],
        *,
        wavelet: str,
        boundary: str | Sequence[str],
        axes: Sequence[int] = (0, 1),
        rounding: float = DEFAULT_ROUNDING,
        channel_gains: Sequence[float] | None = None,
    ) -> None:
        self._gains = None if channel_gains is None else np.asarray(channel_gains, dtype=float)
        weights = band_weights(coeffs, wavelet=wavelet, boundary=boundary, axes=axes)
        self._bands: list[tuple[np.ndarray, float, float, bool]] = []
        for index, (bands, level_weights) in enumerate(
            zip(as_levels(coeffs), weights, strict=True)
        ):
            band_rounding = APPROX_ROUNDING if index == 0 else float(rounding)
            for band, weight in zip(bands, level_weights, strict=True):
                values = np.ascontiguousarray(band, dtype=np.float64).reshape(-1)
                self._bands.append((values, float(weight), band_rounding, index == 0))
        self.rounding = float(rounding)

    def __call__(self, step: float) -> float:
        """The summed squared error of the reconstruction at ``step`` (predicted)."""
        step = _check_step(step)
        total = 0.0
        channels = 1 if self._gains is None else self._gains.size
        small = [
            k
            for k, (values, _, _, _) in enumerate(self._bands)
            if self._gains is None and values.size < _THREADED_TERMS
        ]
        terms: list[Any] = [None] * len(self._bands)

        def band_terms(k: int) -> None:
            values, weight, band_rounding, _ = self._bands[k]
            band_step = step * weight
            terms[k] = _deadzone_error_terms(values, 1, 1.0 / band_step, band_rounding, MAX_INDEX)

        # The small bands' passes (each whole, as on one thread) in one parallel region, the
        # largest first; their results are added up below in the bands' order, so the sum is
        # the same to the last bit.  A 512² grey picture's bands are all small: its quality
        # search ran its 262 144 values a prediction on the calling thread.
        if sum(self._bands[k][0].size for k in small) >= _THREADED_TERMS:
            small.sort(key=lambda k: -self._bands[k][0].size)
            run_calls([functools.partial(band_terms, k) for k in small])
        else:
            for k in small:
                band_terms(k)
        for k, (values, weight, band_rounding, coarse) in enumerate(self._bands):
            if terms[k] is not None:
                # One channel, a band not worth threads of its own: one compiled call and
                # float arithmetic, the same operations as below (a 512² picture's quality
                # search spent a quarter of its prediction time around the calls).
                ones, more, sums = terms[k]
                offset = 0.0 if coarse else _offset_from_counts(ones, more, band_rounding)
                dropped, residual, residual2, nonzero = (float(v) for v in sums[:, 0])
                total += dropped + residual2 - 2.0 * offset * residual + nonzero * offset**2
                continue
            ones, more, sums = _band_error_terms(values, channels, step * weight, band_rounding)
            dropped, residual, residual2, nonzero = sums
            # The decoder's offset comes from the band's counts, over all its channels.
            offset = 0.0 if coarse else _offset_from_counts(ones, more, band_rounding)
            per_channel = dropped + residual2 - 2.0 * offset * residual + nonzero * offset**2
            total += float(per_channel.sum() if self._gains is None else per_channel @ self._gains)
        # Each band's error is in units of its own step, ``step · weight``, and its basis norm
        # is ``1 / weight``: every band's squared error is in units of ``step**2``.
        return total * step * step
