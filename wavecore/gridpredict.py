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
    8       1     flags: 1 integer arithmetic
    9       1     predicted axes (bit k set: axis k)
    10      20    lengths of the five sections (uint32 each)
    30            the five sections: the fitted weights (float32, ``2c - 1`` per group of at
                  least ``_FIT_MIN`` samples and ``c`` odd axes), per group the present symbols
                  and their counts (varints, deflated), the range coder's words, the low bits
                  of the large residuals (packed, most significant first), the exact values
                  (the dtype, deflated)
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

__all__ = ["decode_predictive", "encode_predictive"]

_HEAD = struct.Struct("<dBBIIIII")
_FLAG_INTEGER = 1
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
    if count == 0:
        return 0.0
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
    return np.rint(total) if integer else total


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
    bound itself and may still turn samples into exact ones).  ``cast``: 0 float64,
    1 float32, 2 integers clipped to ``[lo, hi]``, 3 a check left to the caller.  ``stats``
    gathers the squared errors and the largest error of what the decoder returns (cast 0-2).
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
    exact_count = 0
    k = first
    for line in range(lines[0], lines[1]):
        i0 = starts[0] + (line // per_line) * strides[0]
        i1 = starts[1] + (line % per_line) * strides[1]
        row = (i0 * n1 + i1) * n2
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
    no copy of the grid.

    Memory: the coder works in place in one float64 grid (the decoder's reconstruction
    replaces each value as it is coded), and its scratch is one byte a sample of the largest
    group (the symbols, whose histogram precedes their coding) and a band of ``_BAND`` samples.
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
    for s, odd, slices in groups:
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
            needed = int(pack_state[0]) + (last_line - first_line) * per_line * 7 + 16
            if packed.size < needed:
                grown = np.zeros(max(needed, 2 * packed.size), dtype=np.uint8)
                grown[: int(pack_state[0])] = packed[: int(pack_state[0])]
                packed = grown
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
                packed,
                pack_state,
                remainders,
                stats,
                weights,
                counts,
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
        if exact_count:
            # An exact sample's place in y still holds its value.
            exact_values.append(y[slices].reshape(-1)[group_symbols == _EXACT])
        present = np.flatnonzero(counts)
        tables.append(present.size)
        previous = 0
        for symbol in present.tolist():
            tables += [symbol - previous, int(counts[symbol])]
            previous = symbol
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
    head = _HEAD.pack(
        step,
        _FLAG_INTEGER if integer else 0,
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
    stream = head + weight_bytes + table_bytes + coded + low_bytes + exact_bytes
    return stream, squares, largest_error


def decode_predictive(
    data: bytes, shape: tuple[int, ...], dtype: np.dtype[Any], keep: float | None = None
) -> np.ndarray:
    """The grid (its dtype; missing cells hold their fill) that :func:`encode_predictive`
    coded, or ``BundleError``.  With ``keep`` below 1 only that fraction of the largest
    residuals is kept (:func:`_drop_smallest`)."""
    if len(data) < _HEAD.size:
        msg = "grid interpolation stream is truncated"
        raise BundleError(msg)
    step, flags, mask, n_weights, n_tables, n_coded, n_low, n_exact = _HEAD.unpack_from(data)
    axes = tuple(k for k in range(len(shape)) if mask >> k & 1)
    if (
        not axes
        or mask >> len(shape)
        or not (math.isfinite(step) and step > 0)
        or _HEAD.size + n_weights + n_tables + n_coded + n_low + n_exact != len(data)
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
    exact_raw = _inflate(data[position:], itemsize * math.prod(shape)) if n_exact else b""
    if len(exact_raw) % itemsize:
        msg = "grid interpolation stream's exact values are truncated"
        raise BundleError(msg)
    exact_all = np.frombuffer(exact_raw, dtype=dtype.newbyteorder("<")).astype(np.float64)
    used_exact = 0
    decoder = constriction.stream.queue.RangeDecoder(words)
    groups = []
    for s, odd, slices in _groups(shape, axes):
        size = math.prod(
            len(range(*item.indices(n))) for item, n in zip(slices, shape, strict=True)
        )
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
        if present[-1] > _EXACT or counts.sum() != size or counts.min() < 1:
            msg = "grid interpolation table does not match its group"
            raise BundleError(msg)
        if n_present > 1:
            index = np.asarray(decoder.decode(_model(counts.astype(np.float64)), size))
            symbols = present[index]
        else:
            symbols = np.full(size, present[0], dtype=np.int64)
        exact = symbols == _EXACT
        large = (symbols >= _DIRECT) & ~exact
        zigzag = np.where(large, 0, symbols)
        if large.any():
            classes = symbols[large] - _DIRECT
            low = (classes >> _TOP_BITS) + _FIRST_CLASS_BITS - _TOP_BITS
            top = (classes & ((1 << _TOP_BITS) - 1)) + (1 << _TOP_BITS)
            remainders = np.zeros(low.size, dtype=np.int64)
            if not _unpack_bits(low_data, low, remainders, low_state):
                msg = "grid interpolation stream's low bits are truncated"
                raise BundleError(msg)
            zigzag[large] = (top << low) + remainders
        multiples = np.where(zigzag & 1, -(zigzag >> 1) - 1, zigzag >> 1)
        values = np.zeros(size, dtype=np.float64)
        n = int(np.count_nonzero(exact))
        if n:
            if used_exact + n > exact_all.size:
                msg = "grid interpolation stream has too few exact values"
                raise BundleError(msg)
            values[exact] = exact_all[used_exact : used_exact + n]
            used_exact += n
        count = len(odd)
        weights = _default_weights(count)
        if count and size >= _FIT_MIN:
            n = 2 * count - 1
            if used_weights + n > all_weights.size:
                msg = "grid interpolation stream has too few weights"
                raise BundleError(msg)
            weights = all_weights[used_weights : used_weights + n]
            used_weights += n
        groups.append((s, odd, slices, multiples, exact, values, weights))
    if used_weights != all_weights.size or not np.all(np.isfinite(all_weights)):
        msg = "grid interpolation stream has bad or left-over weights"
        raise BundleError(msg)
    if used_exact != exact_all.size or (int(low_state[0]) + 7) // 8 != low_data.size:
        msg = "grid interpolation stream has exact values or low bits left over"
        raise BundleError(msg)
    if keep is not None and keep < 1.0:
        _drop_smallest(groups, keep)
    y = np.zeros(shape, dtype=np.float64)
    y_flat = y.reshape(-1)
    shape3 = _shape3(shape)
    for s, odd, slices, multiples, exact, values, weights in groups:
        odd_flags, starts, strides = _layout(slices, odd, len(shape))
        _decode_group(
            y_flat,
            shape3,
            odd_flags,
            starts,
            strides,
            s,
            step,
            integer,
            multiples,
            exact,
            values,
            weights,
        )
    return _to_dtype(y, dtype)


def _drop_smallest(groups: list[Any], keep: float) -> None:
    """Zero all but the ``keep`` fraction of largest residuals (the details of this
    interpolating transform), in place: the decoded grid is then interpolated where they were
    dropped, smoother, and no longer within the bound.  Exact samples are kept."""
    magnitudes = np.concatenate([np.abs(g[3][~g[4]]) for g in groups])
    kept = math.ceil(keep * magnitudes.size)
    if kept >= magnitudes.size:
        return
    threshold = (
        np.partition(magnitudes, magnitudes.size - kept - 1)[magnitudes.size - kept - 1]
        if kept
        else magnitudes.max()
    )
    for group in groups:
        multiples = group[3]
        multiples[np.abs(multiples) <= threshold] = 0


def _inflate(data: bytes, limit: int) -> bytes:
    inflater = zlib.decompressobj()
    try:
        text = inflater.decompress(data, limit + 1)
    except zlib.error as exc:
        msg = f"grid interpolation stream is not valid deflate data: {exc}"
        raise BundleError(msg) from None
    if len(text) > limit or not inflater.eof:
        msg = "grid interpolation stream inflates past its size limit or is truncated"
        raise BundleError(msg)
    return text
