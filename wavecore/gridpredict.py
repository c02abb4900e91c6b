"""Error-bounded coding of a grid by multilevel interpolation: the core of a ``max_error`` grid.

A wavelet code spreads each coefficient's quantization error over many samples, so its
pointwise errors are nearly Gaussian: to bound the largest at ``t`` its RMSE must sit well below
``t``, or the samples beyond ``t`` (several per cent) must be listed and corrected, and either
costs 5-10 % more bytes than SZ3 on smooth fields (docs/benchmarks.md, Grids, before this
module).  This coder quantizes *in the loop* instead, so each sample's error is its own
quantization error, uniform in ``[-t, t]`` and never beyond:

* **Lifting predictions, without the update step.**  The grid is visited from a coarse lattice
  (stride ``2**L``) to the finest.  At stride ``s`` the new samples are those with an odd
  multiple of ``s`` on at least one axis; they come in groups by which axes are odd (one odd
  axis first, then two, then three), and each is predicted from the already decoded samples
  around it: by default the mean of the 4-point cubic interpolations (``(-1, 9, 9, -1) / 16``,
  the Deslauriers-Dubuc predictor of an interpolating wavelet's lifting step) along each of its
  odd axes (linear or constant at the edges).  Samples with two or three odd axes thus get two
  or three independent predictions, which is what lets this beat SZ3's one-axis-at-a-time
  order (1-3 % fewer bytes on the benchmark's field and volume, estimated from the residuals'
  entropy).  Each large group fits its own weights of the linear and cubic interpolations by
  least squares on a sample of its lines (a few float32 in the stream): a further 0.5-1.5 %.
* **Quantized in the loop.**  The residual ``x - p`` becomes ``q = round((x - p) / 2t)``, and the
  sample is reconstructed as ``p + 2t q`` *before* it predicts the next ones, so the decoder's
  predictions are the encoder's, bit for bit (one compiled kernel's float64 arithmetic, in
  the same order, without fastmath).
  Integer grids predict in whole numbers and use the odd step ``2t + 1``: exact arithmetic.
  A sample whose reconstruction, cast to the grid's dtype, still misses the bound (a bound near
  the dtype's resolution, huge values) is stored exactly instead.
* **Entropy coded.**  Each group's integers are range coded (constriction, as the codec's
  coders) under that group's own static histogram: small values directly, larger ones as a
  quarter-octave magnitude class whose low bits are stored as they are.  Contexts on the neighbours'
  values were measured and gained under 1 % on the benchmark's fields: the residuals of a
  stationary field are nearly independent.

Missing (NaN) cells are never coded: their residual is taken as 0, so the decoder fills them by
interpolation and they cost almost nothing.  Every sample is visited once, by a numba kernel
(one call per group), so the cost is linear, and a volume is predicted along all three axes
(or along its last two only: ``axes=(1, 2)``, the slice mode).

The stream (little-endian)::

    offset  size  field
    0       8     step (float64)
    8       1     flags: 1 integer arithmetic, 2 fine levels in tiles
    9       1     predicted axes (bit k set: axis k)
    10      20    lengths of the five sections (uint32 each)
    30            the five sections: the fitted weights (float32, ``2c - 1`` per group of at
                  least ``_FIT_MIN`` samples and ``c`` odd axes), per group the present symbols
                  and their counts (varints, deflated), the range coder's words, the low bits
                  of the large residuals (packed, most significant first), the exact values
                  (the dtype, deflated)
    ...           with flag 2 (tiles), the tile section: log2 of the tile side and of the
                  largest tiled stride (a byte each), per tile the lengths of its range coder
                  words, low bits and exact values (varints), then those parts, tile by tile

With flag 2 the groups of stride up to the largest tiled one (the fine levels) are not in the
range coder's words, low bits and exact values of the five sections but in the tiles: each
tile (C order; ``side`` samples along each predicted axis) holds its samples of every such
group, group by group in coding order and in C order inside a group, under the group's table.
A window then decodes the tiles its predictions reach, each up to the finest group it needs
(:func:`decode_predictive_window`).  Grids of one tile are never tiled.
"""

from __future__ import annotations

import itertools
import math
import struct
import zlib
from collections.abc import Iterator
from typing import Any

import constriction
import numpy as np
from numba import njit

from .errors import BundleError
from .inflate import inflate
from .threshold import kth_smallest

__all__ = [
    "decode_predictive",
    "decode_predictive_window",
    "encode_predictive",
    "fixed_bytes",
    "is_tiled_stream",
]

_HEAD = struct.Struct("<dBBIIIII")
_FLAG_INTEGER = 1
_FLAG_TILED = 2
#: A class is a bit length ``b + 1`` (``b`` = 4 … 53) and the two bits after the leading one,
#: so that a class spans a quarter of an octave: uniform low bits inside so narrow a class lose
#: little (a whole octave per class cost 1.3 % more on the benchmark's field).
_DIRECT = 16
_FIRST_CLASS_BITS = 4  # 2**4 = _DIRECT: the first classes hold 16..31
_TOP_BITS = 2
_CLASSES = (54 - _FIRST_CLASS_BITS) << _TOP_BITS  # zigzagged residuals below 2**54
_EXACT = _DIRECT + _CLASSES  # the symbol of a sample stored exactly
_CHUNK_BITS = 20  # low bits are range coded in uniform pieces of at most this many bits
#: Residuals beyond this many steps are stored exactly (float64 keeps integers exact to 2**53).
_LARGEST_MULTIPLE = 2.0**52


def _group_patterns(axes: tuple[int, ...]) -> list[tuple[int, ...]]:
    """The sets of odd axes, in coding order: one odd axis first, then two, then three."""
    return [odd for k in range(1, len(axes) + 1) for odd in itertools.combinations(axes, k)]


def _groups(
    shape: tuple[int, ...], axes: tuple[int, ...]
) -> Iterator[tuple[int, tuple[int, ...], tuple[slice, ...]]]:
    """``(stride, odd axes, slices of the group's samples)`` in coding order, the coarsest
    lattice (stride ``2**L``, predicted as 0) first."""
    longest = max(shape[a] for a in axes)
    levels = max(0, math.ceil(math.log2(longest))) if longest > 1 else 0
    top = 1 << levels
    yield (
        top,
        (),
        tuple(slice(0, None, top) if k in axes else slice(None) for k in range(len(shape))),
    )
    patterns = _group_patterns(axes)
    for level in range(levels - 1, -1, -1):
        s = 1 << level
        for odd in patterns:
            if any(shape[a] <= s for a in odd):
                continue
            slices = tuple(
                slice(None)
                if k not in axes
                else slice(s, None, 2 * s)
                if k in odd
                else slice(0, None, 2 * s)
                for k in range(len(shape))
            )
            yield s, odd, slices


# The kernels work on 3-D arrays (a field is viewed as (1, H, W)).  ``odd`` has one flag per
# axis; ``starts``/``strides`` describe the group's samples on each axis.  Encoder and decoder
# share :func:`_prediction`, so their float64 arithmetic is the same, operation for operation
# (no fastmath: no reassociation, no fused multiply-add).


@njit(nogil=True, cache=True, inline="always")
def _along(y: np.ndarray, at: int, i: int, n: int, d: int, s: int) -> tuple[float, float]:
    """The linear and the cubic interpolation at flat index ``at`` (coordinate ``i`` of ``n``
    on the axis whose flat step is ``d`` per ``s`` samples) from the samples at ``±s`` and
    ``±3s``: the cubic is the linear one when ``3s`` reaches past an edge, and both are the
    left sample past the last one."""
    left = y[at - d]
    if i + s >= n:
        return left, left
    right = y[at + d]
    linear = 0.5 * (left + right)
    if i < 3 * s or i + 3 * s >= n:
        return linear, linear
    # (a product by 1/16, a power of two, is the exact quotient, and cheaper)
    return linear, (9.0 * (left + right) - (y[at - 3 * d] + y[at + 3 * d])) * 0.0625


@njit(nogil=True, cache=True, inline="always")
def _interpolations(
    y: np.ndarray,
    at: int,
    i0: int,
    i1: int,
    i2: int,
    shape: tuple[int, int, int],
    odd: np.ndarray,
    s: int,
    linear: np.ndarray,
    cubic: np.ndarray,
) -> None:
    """``linear[k]`` and ``cubic[k]`` along the ``k``-th odd axis."""
    n0, n1, n2 = shape
    k = 0
    if odd[0]:
        linear[k], cubic[k] = _along(y, at, i0, n0, s * n1 * n2, s)
        k += 1
    if odd[1]:
        linear[k], cubic[k] = _along(y, at, i1, n1, s * n2, s)
        k += 1
    if odd[2]:
        linear[k], cubic[k] = _along(y, at, i2, n2, s, s)


@njit(nogil=True, cache=True, inline="always")
def _prediction(
    y: np.ndarray,
    at: int,
    i0: int,
    i1: int,
    i2: int,
    shape: tuple[int, int, int],
    odd0: bool,
    odd1: bool,
    odd2: bool,
    count: int,
    s: int,
    integer: bool,
    w0: float,
    w1: float,
    w2: float,
    w3: float,
    w4: float,
) -> float:
    """The last odd axis's linear interpolation, plus weights times the other axes' linear
    ones less it (``count - 1`` weights), plus weights times each axis's cubic less its linear
    one (``count`` weights); all ``1 / count`` is the mean of the cubic ones.  Written out per
    count, in scalars: the encoder's hot loop."""
    total = 0.0
    if count > 0:
        n0, n1, n2 = shape
        la = lb = lc = ca = cb = cc = 0.0
        k = 0
        if odd0:
            la, ca = _along(y, at, i0, n0, s * n1 * n2, s)
            k = 1
        if odd1:
            if k == 0:
                la, ca = _along(y, at, i1, n1, s * n2, s)
            else:
                lb, cb = _along(y, at, i1, n1, s * n2, s)
            k += 1
        if odd2:
            if k == 0:
                la, ca = _along(y, at, i2, n2, s, s)
            elif k == 1:
                lb, cb = _along(y, at, i2, n2, s, s)
            else:
                lc, cc = _along(y, at, i2, n2, s, s)
        if count == 1:
            total = la + w0 * (ca - la)
        elif count == 2:
            total = lb + w0 * (la - lb)
            total += w1 * (ca - la)
            total += w2 * (cb - lb)
        else:
            total = lc + w0 * (la - lc)
            total += w1 * (lb - lc)
            total += w2 * (ca - la)
            total += w3 * (cb - lb)
            total += w4 * (cc - lc)
        if integer:
            total = np.rint(total)
    # The last use of ``y`` is unconditional (a sample written back as it is), so that numba
    # prunes the reference count it takes on ``y`` when inlining this: with early returns and
    # reads in branches it counted ``y`` up and down at every sample (0.76-0.86x the encoder's
    # CPU without it).  One exit, one ``np.rint``: the same values.
    y[at] = y[at]
    return total


@njit(nogil=True, cache=True)
def _padded(weights: np.ndarray) -> tuple[float, float, float, float, float]:
    out = np.zeros(5)
    out[: weights.size] = weights
    return out[0], out[1], out[2], out[3], out[4]


@njit(nogil=True, cache=True)
def _normal_equations(
    y: np.ndarray,
    x: np.ndarray,
    missing: np.ndarray,
    shape: tuple[int, int, int],
    odd: np.ndarray,
    starts: np.ndarray,
    strides: np.ndarray,
    s: int,
    every: int,
    gram: np.ndarray,
    moments: np.ndarray,
) -> None:
    """The least-squares system of the group's weights (see :func:`_prediction`), over every
    ``every``-th line of the group: enough samples for a handful of weights, at little cost."""
    count = 0
    for a in range(3):
        count += 1 if odd[a] else 0
    size = 2 * count - 1
    linear = np.empty(3)
    cubic = np.empty(3)
    features = np.empty(size)
    n0, n1, n2 = shape
    has_missing = missing.size > 0
    for i0 in range(starts[0], n0, strides[0]):
        for i1 in range(starts[1], n1, strides[1] * every):
            row = (i0 * n1 + i1) * n2
            for i2 in range(starts[2], n2, strides[2]):
                at = row + i2
                if has_missing and missing[at]:
                    continue
                _interpolations(y, at, i0, i1, i2, shape, odd, s, linear, cubic)
                last = linear[count - 1]
                for k in range(count - 1):
                    features[k] = linear[k] - last
                for k in range(count):
                    features[count - 1 + k] = cubic[k] - linear[k]
                target = x[at] - last
                for j in range(size):
                    moments[j] += features[j] * target
                    for k in range(size):
                        gram[j, k] += features[j] * features[k]


@njit(nogil=True, cache=True)
def _encode_lines(
    y: np.ndarray,
    missing: np.ndarray,
    shape: tuple[int, int, int],
    odd: np.ndarray,
    starts: np.ndarray,
    strides: np.ndarray,
    s: int,
    step: float,
    integer: bool,
    cast: int,
    allowed: float,
    lo: float,
    hi: float,
    lines: tuple[int, int],
    symbols: np.ndarray,
    first: int,
    packed: np.ndarray,
    pack_state: np.ndarray,
    remainders: np.ndarray,
    stats: np.ndarray,
    weights: np.ndarray,
    counts: np.ndarray,
    tile_side: np.ndarray,
    tile_counts: np.ndarray,
    tile_bases: np.ndarray,
    tile_states: np.ndarray,
) -> int:
    """Predict, quantize and reconstruct lines ``lines[0]`` to ``lines[1] - 1`` of one group
    (its samples along the last axis, in coding order), in place: ``y`` holds the values to
    code where nothing is coded yet, and each sample is overwritten by what the decoder will
    reconstruct once it is coded (the predictions read only coded samples).  Writes the
    symbols from ``symbols[first]`` on; returns how many samples were stored exactly (their
    symbol ``_EXACT``), and counts the symbols in ``counts`` (the group's histogram).

    The low bits of large residuals are appended to ``packed`` (``pack_state``: bytes written,
    pending bits, their count; the caller leaves room for 53 bits a sample), most significant
    first, or stored in ``remainders[k]`` when that is not empty (for a caller that checks the
    bound itself and may still turn samples into exact ones).  With more than one tile
    (``tile_states`` has a row per tile; ``tile_side`` and ``tile_counts`` per axis of the 3-D
    view) they go instead to their tile's stream in ``packed`` (from ``tile_bases[t]`` on,
    its state in ``tile_states[t]``), the caller leaving room for 53 bits a sample of each
    tile.  ``cast``: 0 float64, 1 float32, 2 integers clipped to ``[lo, hi]``, 3 a check left
    to the caller.  ``stats`` gathers the squared errors and the largest error of what the
    decoder returns (cast 0-2).
    """
    count = 0
    for a in range(3):
        count += 1 if odd[a] else 0
    _, n1, n2 = shape
    inverse = 1.0 / step
    o0, o1, o2 = odd[0], odd[1], odd[2]
    w0, w1, w2, w3, w4 = _padded(weights)
    has_missing = missing.size > 0
    keep_remainders = remainders.size > 0
    position, pending, pending_count = pack_state[0], pack_state[1], pack_state[2]
    # Scalars, not stats[0] and stats[1], in the loop: the compiler cannot tell that ``stats``
    # is not ``y``, and would store and reload them at every sample.  Same sums, same order.
    squares, worst = stats[0], stats[1]
    per_line = (n1 - starts[1] + strides[1] - 1) // strides[1]
    tiled = tile_states.shape[0] > 1
    exact_count = 0
    k = first
    for line in range(lines[0], lines[1]):
        i0 = starts[0] + (line // per_line) * strides[0]
        i1 = starts[1] + (line % per_line) * strides[1]
        row = (i0 * n1 + i1) * n2
        line_tiles = ((i0 // tile_side[0]) * tile_counts[1] + i1 // tile_side[1]) * tile_counts[2]
        for i2 in range(starts[2], n2, strides[2]):
            at = row + i2
            target = y[at]
            p = _prediction(
                y, at, i0, i1, i2, shape, o0, o1, o2, count, s, integer, w0, w1, w2, w3, w4
            )
            if has_missing and missing[at]:
                y[at] = p
                symbols[k] = 0
                counts[0] += 1
                k += 1
                continue
            # The product by 1/step may round a residual to the neighbouring multiple
            # in a tie; the check below still holds every sample to the bound.
            m = np.rint((target - p) * inverse)
            ok = abs(m) <= _LARGEST_MULTIPLE
            value = p + m * step if ok else target
            if ok and cast != 3:
                if cast == 1:
                    returned = float(np.float32(value))
                elif cast == 2:
                    returned = min(max(np.rint(value), lo), hi)
                else:
                    returned = value
                error = abs(returned - target)
                ok = error <= allowed
                if ok:
                    squares += error * error
                    worst = max(worst, error)
            if not ok:  # y[at] keeps the target, stored exactly
                symbols[k] = _EXACT
                counts[_EXACT] += 1
                exact_count += 1
                k += 1
                continue
            y[at] = value
            q = np.int64(m)
            z = 2 * q if q >= 0 else -2 * q - 1
            if z < _DIRECT:
                symbols[k] = z
                counts[z] += 1
            else:
                b = 0
                while (z >> (b + 1)) > 0:
                    b += 1
                low = b - _TOP_BITS
                top = (z >> low) & ((1 << _TOP_BITS) - 1)
                symbol = _DIRECT + ((b - _FIRST_CLASS_BITS) << _TOP_BITS) + top
                symbols[k] = symbol
                counts[symbol] += 1
                bits = z & ((np.int64(1) << low) - 1)
                if keep_remainders:
                    remainders[k - first] = bits
                elif tiled:
                    _append_bits(
                        packed, tile_bases, tile_states, line_tiles + i2 // tile_side[2], bits, low
                    )
                else:
                    pending = (pending << low) | bits
                    pending_count += low
                    while pending_count >= 8:
                        pending_count -= 8
                        packed[position] = (pending >> pending_count) & 0xFF
                        position += 1
                    pending &= (np.int64(1) << pending_count) - 1
            k += 1
    pack_state[0], pack_state[1], pack_state[2] = position, pending, pending_count
    stats[0], stats[1] = squares, worst
    return exact_count


@njit(nogil=True, cache=True)
def _append_bits(
    packed: np.ndarray, bases: np.ndarray, states: np.ndarray, tile: int, bits: Any, width: int
) -> None:
    """Append the ``width`` low bits ``bits`` to tile ``tile``'s stream in ``packed`` (from
    ``bases[tile]`` on; ``states[tile]``: bytes written, pending bits, their count)."""
    position, pending, count = states[tile, 0], states[tile, 1], states[tile, 2]
    pending = (pending << width) | bits
    count += width
    base = bases[tile]
    while count >= 8:
        count -= 8
        packed[base + position] = (pending >> count) & 0xFF
        position += 1
    pending &= (np.int64(1) << count) - 1
    states[tile, 0], states[tile, 1], states[tile, 2] = position, pending, count


@njit(nogil=True, cache=True)
def _symbol_indices(symbols: np.ndarray, lookup: np.ndarray, out: np.ndarray) -> None:
    """``out[k] = lookup[symbols[k]]``: the range coder's indices into a group's present
    symbols (numpy's fancy indexing took a tenth of the encoder's time)."""
    for k in range(symbols.size):
        out[k] = lookup[symbols[k]]


@njit(nogil=True, cache=True)
def _decode_group(
    y: np.ndarray,
    shape: tuple[int, int, int],
    odd: np.ndarray,
    starts: np.ndarray,
    strides: np.ndarray,
    s: int,
    step: float,
    integer: bool,
    multiples: np.ndarray,
    exact: np.ndarray,
    values: np.ndarray,
    weights: np.ndarray,
) -> None:
    """The inverse of :func:`_encode_lines`: ``values[k]`` where ``exact[k]``."""
    count = 0
    for a in range(3):
        count += 1 if odd[a] else 0
    n0, n1, n2 = shape
    o0, o1, o2 = odd[0], odd[1], odd[2]
    w0, w1, w2, w3, w4 = _padded(weights)
    k = 0
    for i0 in range(starts[0], n0, strides[0]):
        for i1 in range(starts[1], n1, strides[1]):
            row = (i0 * n1 + i1) * n2
            for i2 in range(starts[2], n2, strides[2]):
                at = row + i2
                if exact[k]:
                    y[at] = values[k]
                else:
                    p = _prediction(
                        y, at, i0, i1, i2, shape, o0, o1, o2, count, s, integer, w0, w1, w2, w3, w4
                    )
                    y[at] = p + float(multiples[k]) * step
                k += 1


@njit(nogil=True, cache=True)
def _decode_group_box(
    y: np.ndarray,
    shape: tuple[int, int, int],
    odd: np.ndarray,
    starts: np.ndarray,
    strides: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    counts: np.ndarray,
    s: int,
    step: float,
    integer: bool,
    multiples: np.ndarray,
    exact: np.ndarray,
    values: np.ndarray,
    weights: np.ndarray,
) -> None:
    """:func:`_decode_group` on the group's samples inside ``[lo, hi)`` (per axis of the 3-D
    view) only; ``counts`` is the group's shape, to index its residuals."""
    count = 0
    for a in range(3):
        count += 1 if odd[a] else 0
    _, n1, n2 = shape
    o0, o1, o2 = odd[0], odd[1], odd[2]
    w0, w1, w2, w3, w4 = _padded(weights)
    first = np.empty(3, dtype=np.int64)
    last = np.empty(3, dtype=np.int64)
    for a in range(3):
        first[a] = min(max(-((starts[a] - lo[a]) // strides[a]), 0), counts[a])
        last[a] = min(max(-((starts[a] - hi[a]) // strides[a]), 0), counts[a])
    for j0 in range(first[0], last[0]):
        i0 = starts[0] + j0 * strides[0]
        for j1 in range(first[1], last[1]):
            i1 = starts[1] + j1 * strides[1]
            row = (i0 * n1 + i1) * n2
            base = (j0 * counts[1] + j1) * counts[2]
            for j2 in range(first[2], last[2]):
                i2 = starts[2] + j2 * strides[2]
                at = row + i2
                k = base + j2
                if exact[k]:
                    y[at] = values[k]
                else:
                    p = _prediction(
                        y, at, i0, i1, i2, shape, o0, o1, o2, count, s, integer, w0, w1, w2, w3, w4
                    )
                    y[at] = p + float(multiples[k]) * step


#: Groups of at least this many samples get least-squares weights of their own (stored as
#: float32, ``2 c - 1`` for ``c`` odd axes); smaller ones use the mean of the cubic
#: interpolations.  Fitted weights took 0.5-1 % fewer bytes on the benchmark's grids.
_FIT_MIN = 1024
#: About this many samples of a group enter its fit (every ``k``-th line).
_FIT_SAMPLES = 4096


def _default_weights(count: int) -> np.ndarray:
    return np.full(max(2 * count - 1, 1), 1.0 / max(count, 1))


def _fitted_weights(
    y_flat: np.ndarray,
    x_flat: np.ndarray,
    missing_flat: np.ndarray,
    shape3: tuple[int, int, int],
    odd_flags: np.ndarray,
    starts: np.ndarray,
    strides: np.ndarray,
    s: int,
    size: int,
) -> np.ndarray:
    """The group's least-squares weights, rounded to float32 (as stored); the mean of the
    cubic interpolations when the system is singular."""
    count = int(odd_flags.sum())
    n = 2 * count - 1
    gram = np.zeros((n, n))
    moments = np.zeros(n)
    every = max(1, size // _FIT_SAMPLES)
    _normal_equations(
        y_flat, x_flat, missing_flat, shape3, odd_flags, starts, strides, s, every, gram, moments
    )
    default = _default_weights(count)
    # Values near the float64 limit overflow the sums to inf: the solve then gives NaNs, and
    # the default weights are taken below (quietly: NumPy would warn).
    with np.errstate(over="ignore", invalid="ignore"):
        ridge = 1e-9 * float(np.trace(gram)) + 1e-300
        try:
            weights = np.linalg.solve(gram + ridge * np.eye(n), moments)
        except np.linalg.LinAlgError:
            return default
    if not np.all(np.isfinite(weights)) or np.abs(weights).max() > 1e6:
        return default
    return weights.astype(np.float32).astype(np.float64)


def _layout(slices: tuple[slice, ...], odd: tuple[int, ...], ndim: int) -> tuple[np.ndarray, ...]:
    """The kernels' ``odd``, ``starts`` and ``strides`` of a group, on the 3-D view."""
    pad = 3 - ndim
    odd_flags = np.zeros(3, dtype=np.bool_)
    starts = np.zeros(3, dtype=np.int64)
    strides = np.ones(3, dtype=np.int64)
    for k, item in enumerate(slices):
        starts[pad + k] = item.start or 0
        strides[pad + k] = item.step or 1
        odd_flags[pad + k] = k in odd
    return odd_flags, starts, strides


def _shape3(shape: tuple[int, ...]) -> tuple[int, int, int]:
    full = (1,) * (3 - len(shape)) + tuple(shape)
    return (int(full[0]), int(full[1]), int(full[2]))


def _to_dtype(values: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    """Float64 samples → the grid's dtype, as the decoder does it (rounded and clipped for
    integers, saturated for narrow floats)."""
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), float(info.min), float(info.max)).astype(dtype)
    if dtype.itemsize < 8:
        largest = float(np.finfo(dtype).max)
        return np.clip(values, -largest, largest).astype(dtype)
    return values.astype(dtype)


# --------------------------------------------------------------------------------------------
# Symbols
# --------------------------------------------------------------------------------------------


def _write_varints(values: Any) -> bytes:
    out = bytearray()
    for value in values:
        value = int(value)
        while value >= 0x80:
            out.append((value & 0x7F) | 0x80)
            value >>= 7
        out.append(value)
    return bytes(out)


class _Reader:
    """Varints from a byte string, with clear errors when it runs out."""

    def __init__(self, data: bytes) -> None:
        self.data, self.position = data, 0

    def varint(self) -> int:
        value, shift = 0, 0
        while True:
            if self.position >= len(self.data) or shift > 63:
                msg = "grid interpolation tables are truncated"
                raise BundleError(msg)
            byte = self.data[self.position]
            self.position += 1
            value |= (byte & 0x7F) << shift
            shift += 7
            if byte < 0x80:
                return value


def _model(counts: np.ndarray) -> Any:
    return constriction.stream.model.Categorical(counts / counts.sum(), perfect=False)


@njit(nogil=True, cache=True)
def _pack_bits(values: np.ndarray, widths: np.ndarray, out: np.ndarray, state: np.ndarray) -> None:
    """Append the low ``widths[k]`` bits of ``values[k]`` (where ``widths[k] > 0``) to ``out``,
    most significant first; ``state`` holds (bytes written, pending bits, their count)."""
    position, pending, count = state[0], state[1], state[2]
    for k in range(values.size):
        width = widths[k]
        if width == 0:
            continue
        pending = (pending << width) | (values[k] & ((np.int64(1) << width) - 1))
        count += width
        while count >= 8:
            count -= 8
            out[position] = (pending >> count) & 0xFF
            position += 1
        pending &= (np.int64(1) << count) - 1
    state[0], state[1], state[2] = position, pending, count


@njit(nogil=True, cache=True)
def _unpack_bits(
    data: np.ndarray, widths: np.ndarray, values: np.ndarray, state: np.ndarray
) -> bool:
    """The inverse of :func:`_pack_bits`; ``state`` holds the bit position.  False when the
    data runs out."""
    position = state[0]
    total = data.size * 8
    for k in range(widths.size):
        width = widths[k]
        if width == 0:
            continue
        if position + width > total:
            return False
        value = np.int64(0)
        for _ in range(width):
            value = (value << 1) | ((data[position >> 3] >> (7 - (position & 7))) & 1)
            position += 1
        values[k] = value
    state[0] = position
    return True


# --------------------------------------------------------------------------------------------
# Tiles: the fine levels cut by region, so that a window decodes from its own tiles
# --------------------------------------------------------------------------------------------

#: The tile side on the predicted axes, by how many there are (a field's 256 × 256, a volume's
#: 64 × 64 × 64), doubled until there are at most ``_MOST_TILES``: each tile costs each tiled
#: group a range coder call and a few array operations, some 50 µs, in the encoder and in a
#: whole decode (128 × 128 tiles made the whole decode of a 1024² field 1.7x slower).
_TILE_SIDE = {1: 65536, 2: 256, 3: 64}
_MOST_TILES = 64
#: Groups of stride up to ``side / _TILED_SHARE`` are coded by tiles (at least 32 samples a
#: tile along each axis); coarser ones, under 0.2 % of the samples, stay whole: a window
#: decodes them whole at little cost, where tiles of them would each cost a range coder call
#: in every tile their wide reach touches (a 64² window of a 1024² field: 15 ms with tiles
#: down to 1/8 of the side, most of it in such calls).
_TILED_SHARE = 32


class _Tiling:
    """Tiles of ``side`` samples on the predicted axes (a non-predicted axis is not cut); the
    groups of stride ``s <= top`` (and some odd axis) are coded tile by tile, each tile's
    symbols of every such group, in coding order, in a stream of its own."""

    def __init__(self, shape: tuple[int, ...], axes: tuple[int, ...], side: int, top: int):
        self.shape, self.axes, self.side, self.top = tuple(shape), tuple(axes), side, top
        self.counts = tuple(-(-n // side) if k in axes else 1 for k, n in enumerate(shape))
        self.size = math.prod(self.counts)

    @classmethod
    def choose(cls, shape: tuple[int, ...], axes: tuple[int, ...]) -> _Tiling | None:
        """The tiling of a grid larger than one tile on some predicted axis, else None."""
        side = _TILE_SIDE[len(axes)]
        if all(shape[a] <= side for a in axes):
            return None
        while math.prod(-(-shape[a] // side) for a in axes) > _MOST_TILES:
            side *= 2
        return cls(shape, axes, side, side // _TILED_SHARE)

    def tiled(self, s: int, odd: tuple[int, ...]) -> bool:
        return bool(odd) and s <= self.top

    def blocks(self, slices: tuple[slice, ...]) -> list[tuple[int, tuple[slice, ...]]]:
        """``(tile, block)`` of a group: ``block`` indexes the group's samples (as an array of
        the group's shape) that lie in the tile; tiles in C order, empty blocks left out."""
        per_axis: list[list[tuple[int, int]]] = []
        for k, (item, n) in enumerate(zip(slices, self.shape, strict=True)):
            start, _, step = item.indices(n)
            m = len(range(start, n, step))
            if k not in self.axes:
                per_axis.append([(0, m)])
                continue
            bounds = []
            for t in range(self.counts[k]):
                lo = min(max(-(-(t * self.side - start) // step), 0), m)
                hi = min(max(-(-(min((t + 1) * self.side, n) - start) // step), 0), m)
                bounds.append((lo, hi))
            per_axis.append(bounds)
        out = []
        for tile, ranges in enumerate(itertools.product(*per_axis)):
            if all(hi > lo for lo, hi in ranges):
                out.append((tile, tuple(slice(lo, hi) for lo, hi in ranges)))
        return out

    def tile_box(self, tile: int) -> tuple[tuple[int, int], ...]:
        """The samples ``[lo, hi)`` per axis that ``tile`` covers."""
        index = np.unravel_index(tile, self.counts)
        return tuple(
            (int(t) * self.side, min((int(t) + 1) * self.side, n)) if k in self.axes else (0, n)
            for k, (t, n) in enumerate(zip(index, self.shape, strict=True))
        )


class _TileWriter:
    """The tiled groups' symbols, low bits and exact values, one stream per tile.

    The low bits of all tiles share one byte array (``packed``, tile ``t``'s from
    ``bases[t]`` on, ``capacity[t]`` bytes), filled by the encoder's kernel as it codes a
    group in C order (a tile's samples of a group come in its block's C order): room is
    reserved band by band for the samples each tile gets, so that no array of the group's
    size holds the low bits or their widths.
    """

    def __init__(self, tiling: _Tiling) -> None:
        self.tiling = tiling
        self.encoders = [constriction.stream.queue.RangeEncoder() for _ in range(tiling.size)]
        self.packed = np.zeros(0, dtype=np.uint8)
        self.bases = np.zeros(tiling.size, dtype=np.int64)
        self.capacity = np.zeros(tiling.size, dtype=np.int64)
        self.states = np.zeros((tiling.size, 3), dtype=np.int64)
        self.exact: list[list[np.ndarray]] = [[] for _ in range(tiling.size)]
        pad = 3 - len(tiling.shape)
        self.side3 = np.array(
            [1] * pad
            + [tiling.side if k in tiling.axes else max(n, 1) for k, n in enumerate(tiling.shape)],
            dtype=np.int64,
        )
        self.counts3 = np.array([1] * pad + list(tiling.counts), dtype=np.int64)

    def reserve(self, needed: np.ndarray) -> None:
        """Room for ``needed[t]`` more bytes in each tile's low bits (capacities doubled)."""
        want = self.states[:, 0] + needed
        short = want > self.capacity
        if not short.any():
            return
        capacity = np.where(short, np.maximum(want, 2 * self.capacity), self.capacity)
        bases = np.concatenate([[0], np.cumsum(capacity)[:-1]]).astype(np.int64)
        packed = np.zeros(int(capacity.sum()), dtype=np.uint8)
        for tile in range(self.tiling.size):
            used = int(self.states[tile, 0])
            if used:
                old = int(self.bases[tile])
                packed[bases[tile] : bases[tile] + used] = self.packed[old : old + used]
        self.packed, self.bases, self.capacity = packed, bases, capacity

    def reserve_lines(
        self,
        starts: np.ndarray,
        strides: np.ndarray,
        group_shape3: tuple[int, int, int],
        lines: tuple[int, int],
    ) -> None:
        """Room for 53 bits a sample of each tile's share of lines ``lines[0]`` to
        ``lines[1] - 1`` of a group (its layout on the 3-D view: ``starts``, ``strides``)."""
        line = np.arange(lines[0], lines[1], dtype=np.int64)
        i0 = starts[0] + (line // group_shape3[1]) * strides[0]
        i1 = starts[1] + (line % group_shape3[1]) * strides[1]
        c1, c2 = int(self.counts3[1]), int(self.counts3[2])
        line_tiles = (i0 // self.side3[0]) * c1 + i1 // self.side3[1]
        per_row = np.bincount(line_tiles, minlength=int(self.counts3[0]) * c1)
        side, start, step, m = int(self.side3[2]), int(starts[2]), int(strides[2]), group_shape3[2]
        columns = np.array(
            [
                min(max(-(-(min((t + 1) * side, start + m * step) - start) // step), 0), m)
                - min(max(-(-(t * side - start) // step), 0), m)
                for t in range(c2)
            ],
            dtype=np.int64,
        )
        samples = np.outer(per_row, columns).reshape(-1)
        self.reserve(np.where(samples > 0, samples * 7 + 16, 0))

    def add_bits(
        self,
        group_shape: tuple[int, ...],
        slices: tuple[slice, ...],
        symbols: np.ndarray,
        remainders: np.ndarray,
    ) -> None:
        """A group's low bits from ``remainders`` (the group's size), tile by tile: for a
        caller that kept them (a float16 grid's bound is checked after the coding)."""
        large = (symbols >= _DIRECT) & (symbols != _EXACT)
        widths = np.where(large, ((symbols.astype(np.int64) - _DIRECT) >> _TOP_BITS) + 2, 0)
        for tile, block in self.tiling.blocks(slices):
            tile_widths = np.ascontiguousarray(widths.reshape(group_shape)[block]).reshape(-1)
            low_bits = int(tile_widths.sum())
            if not low_bits:
                continue
            needed = np.zeros(self.tiling.size, dtype=np.int64)
            needed[tile] = low_bits // 8 + 16
            self.reserve(needed)
            values = np.ascontiguousarray(remainders.reshape(group_shape)[block]).reshape(-1)
            base = int(self.bases[tile])
            out = self.packed[base : base + int(self.capacity[tile])]
            _pack_bits(values, tile_widths, out, self.states[tile])

    def add_symbols(
        self,
        slices: tuple[slice, ...],
        symbols: np.ndarray,
        lookup: np.ndarray,
        model: Any,
        indices: np.ndarray,
        values: np.ndarray | None,
    ) -> None:
        """A group's symbols (its shape), coded tile by tile with ``model`` (None: a single
        symbol, nothing coded), and its exact values from ``values`` (the grid's samples of the
        group, exact ones holding their value; None: there are none)."""
        for tile, block in self.tiling.blocks(slices):
            if model is None and values is None:
                break
            block_symbols = np.ascontiguousarray(symbols[block]).reshape(-1)
            if model is not None:
                # In pieces: the same words as one call (the coder's state carries over).
                for first in range(0, block_symbols.size, _BAND):
                    piece = block_symbols[first : first + _BAND]
                    _symbol_indices(piece, lookup, indices)
                    self.encoders[tile].encode(indices[: piece.size], model)
            if values is not None:
                chosen = block_symbols == _EXACT
                if chosen.any():
                    self.exact[tile].append(values[block].reshape(-1)[chosen])

    def finish(self, dtype: np.dtype[Any]) -> bytes:
        """The tile section: the tile side and largest tiled stride (log2, a byte each), the
        three lengths of each tile's parts (varints), then each tile's range coder words, low
        bits and exact values (the dtype, little-endian)."""
        lengths: list[int] = []
        parts: list[bytes] = []
        for tile in range(self.tiling.size):
            words = self.encoders[tile].get_compressed().tobytes()
            position, pending, count = (int(v) for v in self.states[tile])
            base = int(self.bases[tile])
            low = self.packed[base : base + position].tobytes()
            if count:
                low += bytes([(pending << (8 - count)) & 0xFF])
            exact = b""
            if self.exact[tile]:
                values = _to_dtype(np.concatenate(self.exact[tile]), dtype)
                exact = values.astype(dtype.newbyteorder("<")).tobytes()
            lengths += [len(words), len(low), len(exact)]
            parts += [words, low, exact]
        head = bytes([self.tiling.side.bit_length() - 1, self.tiling.top.bit_length() - 1])
        return head + _write_varints(lengths) + b"".join(parts)


# --------------------------------------------------------------------------------------------
# Encoding and decoding
# --------------------------------------------------------------------------------------------


#: The encoder codes a group's lines in bands of about this many samples: the room it leaves
#: for their low bits (53 bits a sample at most) and the range coder's index array follow the
#: band, not the chunk.
_BAND = 1 << 14


def encode_predictive(
    original: np.ndarray,
    missing: np.ndarray,
    dtype: np.dtype[Any],
    bound: float,
    axes: tuple[int, ...],
    *,
    integer: bool | None = None,
    overwrite: bool = False,
    tiles: bool = True,
) -> tuple[bytes, float, float]:
    """Code ``original`` (the grid's values, 2-D or 3-D, float64 or a narrower float or
    integer dtype whose values float64 holds exactly; ``missing`` marks the NaN cells, whose
    values are ignored) so that every other sample decodes within ``bound``; predicted along
    ``axes``.

    Returns the stream, and the sum of the squared errors and the largest error of what
    :func:`decode_predictive` returns for it, over the cells not missing.  ``integer``
    (the default for integer dtypes) predicts in whole numbers with the step ``2 floor(t) + 1``:
    for whole-number values only.  ``overwrite=True`` lets the coder work in ``original``
    itself when it is a C-contiguous float64 array (it is left holding the decoder's values):
    no copy of the grid.  ``tiles`` codes the fine levels of a grid larger than one tile by
    tiles (:class:`_Tiling`), so that a window decodes from its tiles alone.

    Memory: the coder works in place in one float64 grid (the decoder's reconstruction
    replaces each value as it is coded), and its scratch is one byte a sample of the largest
    group (the symbols, whose histogram precedes their coding) and a band of ``_BAND`` samples
    (with tiles, the tiles' low bits are reserved band by band too).
    """
    if integer is None:
        integer = dtype.kind in "iu"
    if integer:
        allowed = float(math.floor(bound))
        step = float(2 * min(allowed, 2.0**40) + 1)
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        lo, hi, cast = float(info.min), float(info.max), 2
    else:
        lo, hi = 0.0, 0.0
        cast = {8: 0, 4: 1}.get(dtype.itemsize, 3)
    if not integer:
        allowed = bound
        step = min(2.0 * bound, 1e300)
    shape = original.shape
    in_place = (
        overwrite
        and cast != 3  # float16's check below compares with the values after coding
        and original.dtype == np.float64
        and original.flags.c_contiguous
        and original.flags.writeable
    )
    # The values to code, overwritten by the reconstruction as the coding goes.
    y = original if in_place else np.array(original, dtype=np.float64, order="C")
    shape3 = _shape3(shape)
    y_flat = y.reshape(-1)
    missing_flat = (
        np.ascontiguousarray(missing).reshape(-1) if missing.any() else np.zeros(0, np.bool_)
    )
    encoder = constriction.stream.queue.RangeEncoder()
    tables: list[int] = []
    exact_values: list[np.ndarray] = []
    groups = list(_groups(shape, axes))
    largest = max(y[slices].size for _, _, slices in groups)
    # _EXACT < 256: a symbol is one byte.
    symbols = np.empty(largest, dtype=np.uint8)
    lookup = np.zeros(_EXACT + 1, dtype=np.int32)
    indices = np.empty(_BAND, dtype=np.int32)
    stats = np.zeros(2, dtype=np.float64)
    packed = np.zeros(1024, dtype=np.uint8)
    pack_state = np.zeros(3, dtype=np.int64)
    no_remainders = np.zeros(0, dtype=np.int64)
    stored_weights: list[np.ndarray] = []
    # One tile: the kernel packs into ``packed`` at ``pack_state``.
    one_tile = np.ones(3, dtype=np.int64)
    one_base = np.zeros(1, dtype=np.int64)
    one_state = np.zeros((1, 3), dtype=np.int64)
    tiling = _Tiling.choose(shape, axes) if tiles else None
    tile_writer = _TileWriter(tiling) if tiling is not None else None
    for s, odd, slices in groups:
        tiled = tile_writer is not None and tile_writer.tiling.tiled(s, odd)
        odd_flags, starts, strides = _layout(slices, odd, len(shape))
        group_shape = y[slices].shape
        size = math.prod(group_shape)
        group_symbols = symbols[:size]
        count = len(odd)
        weights = _default_weights(count)
        if count and size >= _FIT_MIN:
            weights = _fitted_weights(
                y_flat, y_flat, missing_flat, shape3, odd_flags, starts, strides, s, size
            )
            stored_weights.append(weights.astype("<f4"))
        per_line = _shape3(group_shape)[2]
        lines = size // per_line if per_line else 0
        band = max(lines, 1) if cast == 3 else max(1, _BAND // max(per_line, 1))
        remainders = np.zeros(size, dtype=np.int64) if cast == 3 else no_remainders
        counts = np.zeros(_EXACT + 1, dtype=np.int64)
        exact_count = 0
        for first_line in range(0, lines, band):
            last_line = min(first_line + band, lines)
            if tile_writer is not None and tiled:
                if cast != 3:
                    tile_writer.reserve_lines(
                        starts, strides, _shape3(group_shape), (first_line, last_line)
                    )
                target_bits, target_bases, target_states = (
                    tile_writer.packed,
                    tile_writer.bases,
                    tile_writer.states,
                )
                tile_side, tile_counts = tile_writer.side3, tile_writer.counts3
            else:
                needed = int(pack_state[0]) + (last_line - first_line) * per_line * 7 + 16
                if packed.size < needed:
                    grown = np.zeros(max(needed, 2 * packed.size), dtype=np.uint8)
                    grown[: int(pack_state[0])] = packed[: int(pack_state[0])]
                    packed = grown
                target_bits, target_bases, target_states = packed, one_base, one_state
                tile_side, tile_counts = one_tile, one_tile
            exact_count += _encode_lines(
                y_flat,
                missing_flat,
                shape3,
                odd_flags,
                starts,
                strides,
                s,
                step,
                integer,
                cast,
                allowed,
                lo,
                hi,
                (first_line, last_line),
                group_symbols,
                first_line * per_line,
                target_bits,
                pack_state,
                remainders,
                stats,
                weights,
                counts,
                tile_side,
                tile_counts,
                target_bases,
                target_states,
            )
        if cast == 3:  # float16: the bound checked here, on the cast numpy does
            decoded = y[slices].reshape(-1)
            target = original[slices].reshape(-1)
            error = np.abs(_to_dtype(decoded, dtype).astype(np.float64) - target)
            bad = ~(error <= allowed) & (group_symbols != _EXACT)
            if missing_flat.size:
                bad &= ~missing[slices].reshape(-1)
            if bad.any():
                decoded[bad] = target[bad]
                y[slices] = decoded.reshape(y[slices].shape)
                group_symbols[bad] = _EXACT
                exact_count += int(np.count_nonzero(bad))
                counts = np.bincount(group_symbols, minlength=_EXACT + 1)
            if tile_writer is not None and tiled:
                tile_writer.add_bits(group_shape, slices, group_symbols, remainders)
            else:
                large = (group_symbols >= _DIRECT) & (group_symbols != _EXACT)
                widths = np.where(
                    large, ((group_symbols.astype(np.int64) - _DIRECT) >> _TOP_BITS) + 2, 0
                )
                needed = int(pack_state[0]) + int(widths.sum()) // 8 + 16
                if packed.size < needed:
                    grown = np.zeros(needed, dtype=np.uint8)
                    grown[: int(pack_state[0])] = packed[: int(pack_state[0])]
                    packed = grown
                _pack_bits(remainders, widths, packed, pack_state)
        present = np.flatnonzero(counts)
        tables.append(present.size)
        previous = 0
        for symbol in present.tolist():
            tables += [symbol - previous, int(counts[symbol])]
            previous = symbol
        if tile_writer is not None and tiled:
            lookup[present] = np.arange(present.size, dtype=np.int32)
            # An exact sample's place in y still holds its value.
            tile_writer.add_symbols(
                slices,
                group_symbols.reshape(group_shape),
                lookup,
                _model(counts[present].astype(np.float64)) if present.size > 1 else None,
                indices,
                y[slices] if exact_count else None,
            )
            continue
        if exact_count:
            # An exact sample's place in y still holds its value.
            exact_values.append(y[slices].reshape(-1)[group_symbols == _EXACT])
        if present.size > 1:
            lookup[present] = np.arange(present.size, dtype=np.int32)
            model = _model(counts[present].astype(np.float64))
            # In pieces: the same words as one call (the coder's state carries over), without
            # an int32 copy of the whole group.
            for first in range(0, size, _BAND):
                piece = group_symbols[first : first + _BAND]
                _symbol_indices(piece, lookup, indices)
                encoder.encode(indices[: piece.size], model)
    table_bytes = zlib.compress(_write_varints(tables), 9)
    coded = encoder.get_compressed().tobytes()
    position, pending, count = (int(v) for v in pack_state)
    low_bytes = packed[:position].tobytes()
    if count:
        low_bytes += bytes([(pending << (8 - count)) & 0xFF])
    exact_bytes = b""
    if exact_values:
        values = _to_dtype(np.concatenate(exact_values), dtype)
        exact_bytes = zlib.compress(values.astype(dtype.newbyteorder("<")).tobytes(), 9)
    mask = sum(1 << a for a in axes)
    weight_bytes = b"".join(w.tobytes() for w in stored_weights)
    tile_bytes = tile_writer.finish(dtype) if tile_writer is not None else b""
    head = _HEAD.pack(
        step,
        (_FLAG_INTEGER if integer else 0) | (_FLAG_TILED if tile_writer is not None else 0),
        mask,
        len(weight_bytes),
        len(table_bytes),
        len(coded),
        len(low_bytes),
        len(exact_bytes),
    )
    squares, largest_error = float(stats[0]), float(stats[1])
    if cast == 3:
        final = _to_dtype(y, dtype).astype(np.float64)
        errors = np.where(missing, 0.0, final - original)
        squares, largest_error = float(np.sum(errors * errors)), float(np.max(np.abs(errors)))
    stream = head + weight_bytes + table_bytes + coded + low_bytes + exact_bytes + tile_bytes
    return stream, squares, largest_error


def decode_predictive(
    data: bytes, shape: tuple[int, ...], dtype: np.dtype[Any], keep: float | None = None
) -> np.ndarray:
    """The grid (its dtype; missing cells hold their fill) that :func:`encode_predictive`
    coded, or ``BundleError``.  With ``keep`` below 1 only that fraction of the largest
    residuals is kept (:func:`_drop_smallest`)."""
    return _decode_stream(data, tuple(shape), dtype, keep, None)


def fixed_bytes(data: bytes) -> int:
    """The bytes of a stream that do not grow with the samples: its header, fitted weights
    and tables (what an encoder aiming at a size from a crop leaves out)."""
    _, _, _, n_weights, n_tables, _, _, _ = _HEAD.unpack_from(data)
    return int(_HEAD.size + n_weights + n_tables)


def is_tiled_stream(data: bytes) -> bool:
    """Whether an interpolation stream codes its fine levels by tiles (its flag byte)."""
    return len(data) > 8 and bool(data[8] & _FLAG_TILED)


def decode_predictive_window(
    data: bytes, shape: tuple[int, ...], dtype: np.dtype[Any], box: tuple[tuple[int, int], ...]
) -> np.ndarray:
    """The samples ``[lo, hi)`` per axis (``box``) of what :func:`decode_predictive` returns.

    Only the samples the window's predictions reach are reconstructed: at stride ``s`` the
    window grows by ``3 s`` along each odd axis of each group, coarse to fine, so the work is
    the window's size plus a margin of some ``12 s`` samples per level.  In a tiled stream
    (``_FLAG_TILED``) only the tiles those samples lie in are entropy decoded, each up to the
    finest group it is needed for; an older stream is entropy decoded whole.
    """
    if len(box) != len(shape) or any(
        not 0 <= lo < hi <= n for (lo, hi), n in zip(box, shape, strict=True)
    ):
        msg = f"window {box} does not fit the grid's shape {list(shape)}"
        raise BundleError(msg)
    return _decode_stream(data, tuple(shape), dtype, None, tuple(box))


@njit(nogil=True, cache=True)
def _residuals(
    index: np.ndarray,
    present: np.ndarray,
    low_data: np.ndarray,
    low_state: np.ndarray,
    pool: np.ndarray,
    used: int,
    multiples: np.ndarray,
    exact: np.ndarray,
    values: np.ndarray,
) -> int:
    """Decoded model indices → residuals (``multiples``), exact flags and exact values (from
    ``pool`` on, at ``used``), reading the large classes' low bits from ``low_data`` at
    ``low_state``; returns the exact values used, or -1 when the pool or the bits run out."""
    position = low_state[0]
    total = low_data.size * 8
    for k in range(index.size):
        symbol = present[index[k]]
        if symbol == _EXACT:
            if used >= pool.size:
                return -1
            exact[k] = True
            values[k] = pool[used]
            multiples[k] = 0
            used += 1
            continue
        exact[k] = False
        values[k] = 0.0
        z = symbol
        if symbol >= _DIRECT:
            c = symbol - _DIRECT
            low = (c >> _TOP_BITS) + _FIRST_CLASS_BITS - _TOP_BITS
            top = (c & ((1 << _TOP_BITS) - 1)) + (1 << _TOP_BITS)
            if position + low > total:
                return -1
            r = np.int64(0)
            for _ in range(low):
                r = (r << 1) | ((low_data[position >> 3] >> (7 - (position & 7))) & 1)
                position += 1
            z = (np.int64(top) << low) + r
        multiples[k] = -(z >> 1) - 1 if z & 1 else z >> 1
    low_state[0] = position
    return used


class _Group:
    """One group's geometry, table and weights, and its residuals once decoded."""

    def __init__(
        self, s: int, odd: tuple[int, ...], slices: tuple[slice, ...], shape: tuple[int, ...]
    ) -> None:
        self.s, self.odd, self.slices = s, odd, slices
        self.shape = tuple(
            len(range(*item.indices(n))) for item, n in zip(slices, shape, strict=True)
        )
        self.size = math.prod(self.shape)
        self.present = np.zeros(0, dtype=np.int64)
        self.counts = np.zeros(0, dtype=np.int64)
        self.weights = _default_weights(len(odd))
        self.multiples = np.zeros(0, dtype=np.int64)
        self.exact = np.zeros(0, dtype=bool)
        self.values = np.zeros(0, dtype=np.float64)
        self._model: Any = None

    def allocate(self) -> None:
        self.multiples = np.zeros(self.size, dtype=np.int64)
        self.exact = np.zeros(self.size, dtype=bool)
        self.values = np.zeros(self.size, dtype=np.float64)

    def decode(
        self,
        decoder: Any,
        count: int,
        low_data: np.ndarray,
        low_state: np.ndarray,
        pool: np.ndarray,
        used: int,
        out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], int]:
        """``count`` symbols from ``decoder`` as ``(multiples, exact, values)`` (into ``out``
        if given), and the exact values of ``pool`` now used."""
        if self.present.size > 1:
            if self._model is None:
                self._model = _model(self.counts.astype(np.float64))
            index = np.asarray(decoder.decode(self._model, count), dtype=np.int64)
        else:
            index = np.zeros(count, dtype=np.int64)
        if out is None:
            out = (
                np.empty(count, dtype=np.int64),
                np.empty(count, dtype=np.bool_),
                np.empty(count, dtype=np.float64),
            )
        used = _residuals(index, self.present, low_data, low_state, pool, used, *out)
        if used < 0:
            msg = "grid interpolation stream's exact values or low bits are truncated"
            raise BundleError(msg)
        return out, used


def _decode_stream(
    data: bytes,
    shape: tuple[int, ...],
    dtype: np.dtype[Any],
    keep: float | None,
    box: tuple[tuple[int, int], ...] | None,
) -> np.ndarray:
    if len(data) < _HEAD.size:
        msg = "grid interpolation stream is truncated"
        raise BundleError(msg)
    step, flags, mask, n_weights, n_tables, n_coded, n_low, n_exact = _HEAD.unpack_from(data)
    axes = tuple(k for k in range(len(shape)) if mask >> k & 1)
    sections = _HEAD.size + n_weights + n_tables + n_coded + n_low + n_exact
    tiled = bool(flags & _FLAG_TILED)
    if (
        not axes
        or mask >> len(shape)
        or flags >> 2
        or not (math.isfinite(step) and step > 0)
        or (sections != len(data) if not tiled else sections + 2 > len(data))
        or n_weights % 4
        or n_coded % 4
    ):
        msg = "grid interpolation stream's header does not fit the grid"
        raise BundleError(msg)
    integer = bool(flags & _FLAG_INTEGER)
    position = _HEAD.size
    all_weights = np.frombuffer(data[position : position + n_weights], "<f4").astype(np.float64)
    used_weights = 0
    position += n_weights
    tables = _Reader(_inflate(data[position : position + n_tables], 32 * math.prod(shape) + 64))
    position += n_tables
    words = np.frombuffer(data[position : position + n_coded], dtype="<u4").astype(np.uint32)
    position += n_coded
    low_data = np.frombuffer(data[position : position + n_low], dtype=np.uint8)
    low_state = np.zeros(1, dtype=np.int64)
    position += n_low
    itemsize = dtype.itemsize
    exact_raw = (
        _inflate(data[position : position + n_exact], itemsize * math.prod(shape))
        if n_exact
        else b""
    )
    position += n_exact
    if len(exact_raw) % itemsize:
        msg = "grid interpolation stream's exact values are truncated"
        raise BundleError(msg)
    exact_all = np.frombuffer(exact_raw, dtype=dtype.newbyteorder("<")).astype(np.float64)
    used_exact = 0
    tiling = _read_tiling(data, position, shape, axes) if tiled else None
    decoder = constriction.stream.queue.RangeDecoder(words)
    groups: list[_Group] = []
    for s, odd, slices in _groups(shape, axes):
        group = _Group(s, odd, slices, shape)
        n_present = tables.varint()
        if not 1 <= n_present <= _EXACT + 1:
            msg = f"grid interpolation table lists {n_present} symbols"
            raise BundleError(msg)
        present = np.zeros(n_present, dtype=np.int64)
        counts = np.zeros(n_present, dtype=np.int64)
        previous = 0
        for i in range(n_present):
            previous += tables.varint()
            present[i] = previous
            counts[i] = tables.varint()
        if present[-1] > _EXACT or counts.sum() != group.size or counts.min() < 1:
            msg = "grid interpolation table does not match its group"
            raise BundleError(msg)
        group.present, group.counts = present, counts
        count = len(odd)
        if count and group.size >= _FIT_MIN:
            n = 2 * count - 1
            if used_weights + n > all_weights.size:
                msg = "grid interpolation stream has too few weights"
                raise BundleError(msg)
            group.weights = all_weights[used_weights : used_weights + n]
            used_weights += n
        if tiling is not None and tiling[0].tiled(s, odd):
            group.allocate()  # filled tile by tile below
        else:
            (group.multiples, group.exact, group.values), used_exact = group.decode(
                decoder, group.size, low_data, low_state, exact_all, used_exact
            )
        groups.append(group)
    if used_weights != all_weights.size or not np.all(np.isfinite(all_weights)):
        msg = "grid interpolation stream has bad or left-over weights"
        raise BundleError(msg)
    if used_exact != exact_all.size or (int(low_state[0]) + 7) // 8 != low_data.size:
        msg = "grid interpolation stream has exact values or low bits left over"
        raise BundleError(msg)
    shape3 = _shape3(shape)
    pad = 3 - len(shape)
    needs = _needed_boxes(groups, shape3, pad, box)
    if tiling is not None:
        _decode_tiles(data, tiling, groups, needs, dtype, pad, whole=box is None)
    if keep is not None and keep < 1.0:
        _drop_smallest(
            [(g.s, g.odd, g.slices, g.multiples, g.exact, g.values, g.weights) for g in groups],
            keep,
        )
    y = np.zeros(shape, dtype=np.float64)
    y_flat = y.reshape(-1)
    for group, need in zip(groups, needs, strict=True):
        odd_flags, starts, strides = _layout(group.slices, group.odd, len(shape))
        if need is None:
            _decode_group(
                y_flat,
                shape3,
                odd_flags,
                starts,
                strides,
                group.s,
                step,
                integer,
                group.multiples,
                group.exact,
                group.values,
                group.weights,
            )
        else:
            _decode_group_box(
                y_flat,
                shape3,
                odd_flags,
                starts,
                strides,
                np.array([lo for lo, _ in need], dtype=np.int64),
                np.array([hi for _, hi in need], dtype=np.int64),
                np.array((1,) * pad + group.shape, dtype=np.int64),
                group.s,
                step,
                integer,
                group.multiples,
                group.exact,
                group.values,
                group.weights,
            )
    if box is not None:
        y = y[tuple(slice(lo, hi) for lo, hi in box)]
    return _to_dtype(y, dtype)


def _needed_boxes(
    groups: list[_Group],
    shape3: tuple[int, int, int],
    pad: int,
    box: tuple[tuple[int, int], ...] | None,
) -> list[list[tuple[int, int]] | None]:
    """Per group, the samples (``[lo, hi)`` on the 3-D view's axes) a window needs of it: the
    window itself for the finest groups, grown by ``3 s`` along a group's odd axes for every
    group coded before it (the reach of its predictions); None everywhere without a window."""
    if box is None:
        return [None] * len(groups)
    current = [(0, 1)] * pad + [(int(lo), int(hi)) for lo, hi in box]
    needs: list[list[tuple[int, int]] | None] = [None] * len(groups)
    for index in range(len(groups) - 1, -1, -1):
        group = groups[index]
        needs[index] = list(current)
        for axis in group.odd:
            lo, hi = current[pad + axis]
            reach = 3 * group.s
            current[pad + axis] = (max(lo - reach, 0), min(hi + reach, shape3[pad + axis]))
    return needs


def _read_tiling(
    data: bytes, position: int, shape: tuple[int, ...], axes: tuple[int, ...]
) -> tuple[_Tiling, list[tuple[int, int, int]], list[int]]:
    """The tiling of a tiled stream's last section, each tile's three part lengths, and where
    each tile's parts start."""
    side_log, top_log = data[position], data[position + 1]
    if not (2 <= side_log <= 31 and top_log <= side_log):
        msg = "grid interpolation stream's tile section is corrupt"
        raise BundleError(msg)
    tiling = _Tiling(shape, axes, 1 << side_log, 1 << top_log)
    if tiling.size > 64 * _MOST_TILES:
        msg = "grid interpolation stream declares too many tiles"
        raise BundleError(msg)
    reader = _Reader(data[position + 2 :])
    lengths = [(reader.varint(), reader.varint(), reader.varint()) for _ in range(tiling.size)]
    start = position + 2 + reader.position
    starts = []
    for words, low, exact in lengths:
        if words % 4:
            msg = "grid interpolation stream's tile words are truncated"
            raise BundleError(msg)
        starts.append(start)
        start += words + low + exact
    if start != len(data):
        msg = "grid interpolation stream's tile section does not add up"
        raise BundleError(msg)
    return tiling, lengths, starts


def _decode_tiles(
    data: bytes,
    tiling_parts: tuple[_Tiling, list[tuple[int, int, int]], list[int]],
    groups: list[_Group],
    needs: list[list[tuple[int, int]] | None],
    dtype: np.dtype[Any],
    pad: int,
    *,
    whole: bool,
) -> None:
    """Fill the tiled groups' residuals from the tiles (all of them, or those a window needs,
    each up to the finest group it needs)."""
    tiling, lengths, starts = tiling_parts
    tiled = [g for g in groups if tiling.tiled(g.s, g.odd)]
    needs_tiled = [n for g, n in zip(groups, needs, strict=True) if tiling.tiled(g.s, g.odd)]
    blocks = [dict(tiling.blocks(g.slices)) for g in tiled]
    for tile in range(tiling.size):
        depth = len(tiled)
        if not whole:
            tile_box = tiling.tile_box(tile)
            depth = 0
            for k, need in enumerate(needs_tiled):
                assert need is not None
                if all(
                    lo < b_hi and b_lo < hi
                    for (lo, hi), (b_lo, b_hi) in zip(need[pad:], tile_box, strict=True)
                ):
                    depth = k + 1
        if depth == 0:
            continue
        words, low, exact = lengths[tile]
        at = starts[tile]
        _decode_tile(
            np.frombuffer(data[at : at + words], dtype="<u4").astype(np.uint32),
            np.frombuffer(data[at + words : at + words + low], dtype=np.uint8),
            np.frombuffer(
                data[at + words + low : at + words + low + exact], dtype=dtype.newbyteorder("<")
            ).astype(np.float64),
            tile,
            tiled[:depth],
            blocks,
            complete=depth == len(tiled),
        )


def _decode_tile(
    words: np.ndarray,
    low_data: np.ndarray,
    exact_values: np.ndarray,
    tile: int,
    groups: list[_Group],
    blocks: list[dict[int, tuple[slice, ...]]],
    *,
    complete: bool,
) -> None:
    """One tile's symbols of ``groups`` (a prefix of the tiled groups, in coding order) into
    their residual arrays; ``complete`` when the prefix is all of them (then nothing of the
    tile's parts may be left over)."""
    decoder = constriction.stream.queue.RangeDecoder(words)
    low_state = np.zeros(1, dtype=np.int64)
    used = 0
    for group, group_blocks in zip(groups, blocks, strict=False):
        block = group_blocks.get(tile)
        if block is None:
            continue
        block_shape = tuple(b.stop - b.start for b in block)
        (multiples, exact, values), used = group.decode(
            decoder, math.prod(block_shape), low_data, low_state, exact_values, used
        )
        group.multiples.reshape(group.shape)[block] = multiples.reshape(block_shape)
        group.exact.reshape(group.shape)[block] = exact.reshape(block_shape)
        group.values.reshape(group.shape)[block] = values.reshape(block_shape)
    if complete and (used != exact_values.size or (int(low_state[0]) + 7) // 8 != low_data.size):
        msg = "grid interpolation stream's tile has exact values or low bits left over"
        raise BundleError(msg)


def _drop_smallest(groups: list[Any], keep: float) -> None:
    """Zero all but the ``keep`` fraction of largest residuals (the details of this
    interpolating transform), in place: the decoded grid is then interpolated where they were
    dropped, smoother, and no longer within the bound.  Exact samples are kept."""
    magnitudes = np.concatenate([np.abs(g[3][~g[4]]) for g in groups])
    kept = math.ceil(keep * magnitudes.size)
    if kept >= magnitudes.size:
        return
    threshold = kth_smallest(magnitudes, magnitudes.size - kept - 1) if kept else magnitudes.max()
    for group in groups:
        multiples = group[3]
        multiples[np.abs(multiples) <= threshold] = 0


def _inflate(data: bytes, limit: int) -> bytes:
    return inflate(data, limit, "grid interpolation stream")
