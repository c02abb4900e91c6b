"""Gridded data: height fields ``(H, W)`` and volumes ``(D, H, W)``, with guaranteed error bounds.

:func:`encode_grid` wraps the codec's wavelet coding of a grid (the *core*) in a small container
that adds what gridded data needs beyond a picture:

* **A pointwise bound.**  With ``max_error=t`` every decoded sample is within ``t`` of the
  original.  Without a wavelet named, the grid is coded by multilevel interpolation quantized
  in the loop (:mod:`wavecore.gridpredict`): each sample's error is its own quantization error,
  within ``t`` by construction (2-35 % fewer bytes than SZ3 on the benchmark's grids).  With a
  wavelet named, the core (below) is quantized a little coarser than ``t`` needs on average;
  the samples where it overshoots (the *outliers*, as SPERR calls them) are corrected: their
  positions are coded as Rice codes of the gaps between them, and each correction as a small
  integer multiple of ``2t`` (range coded; any residual ``r`` is within ``t`` of
  ``round(r / 2t) · 2t``).  Either way the encoder checks the bound on exactly what the decoder
  returns (after the cast to the grid's dtype) and stores any sample that a correction cannot
  reach (rounding of huge values, ``t`` below the dtype's resolution) exactly.
* **Missing cells.**  NaN cells' mask is stored as run lengths; they decode as NaN, exactly.
  The interpolation coder codes no residual there (the decoder interpolates across the hole);
  for the wavelet core they are filled smoothly before the transform (push–pull: averaged down
  a pyramid, interpolated back up), so that the hole costs few bits.
* **RMSE, PSNR and bpp.**  Without a wavelet named, a float grid under ``rmse`` (or
  ``psnr``) is coded by the interpolation coder too, at ``t = sqrt(3) × rmse`` (its errors are
  nearly uniform in ``[-t, t]``), checked on what the decoder returns; where that comes to
  under 4 bits a sample the wavelet core codes it as well and the smaller is kept (the
  transform's coding gain wins at low rates).  A ``bpp`` budget of 4 or more is searched on
  ``t`` the same way; lower budgets and named wavelets use the wavelet core (its step for
  ``rmse`` found from the coefficients and checked on each try's synthesis before the one
  coding, :mod:`wavecore.gridcore`; for ``bpp`` the codec's rate control, whose own
  reconstruction is measured).  An integer grid's coder is chosen from the target before
  anything is coded (``_EXACT_BELOW_RMSE`` and ``_RUNG_TOP`` give the measurements): ``rmse`` of
  0.4 or less, the interpolation coder exact; from ``sqrt(2/3)`` (its RMSE at a bound of one
  unit) to 1.06 times that, the interpolation coder at that bound; otherwise the wavelet core.
  Under ``bpp`` it is coded exactly where a centred crop predicts that fits the budget.
* **Volumes.**  The interpolation coder predicts a volume ``(D, H, W)`` along all three axes
  (3-7 % fewer bytes than its slices coded apart, on the benchmark's volume).  The wavelet
  core (a named wavelet, low ``bpp``) codes it as ``D`` slices under one 2-D
  transform each (the codec's surface of ``(H, W)`` points with ``D`` values), in one core
  bundle: the layout that the codec's two-axis plan, quantizer and context coder take as they
  are, and one whose coarse levels are coarse slices.
* **Integers.**  ``lossless=True`` codes integer grids bit-exactly (the codec's reversible
  integer lifting, after an offset into ``uint16``; wider ranges through ``max_error=0``).

The container (little-endian)::

    offset  size  field
    0       4     magic b"WVGD"
    4       1     version (1; 2 when flag 16 is set; 3 when the interpolation stream codes
                  its fine levels by tiles)
    5       1     layout: 0 height field, 1 volume (slices first), 2 surface points (U, V, d)
    6       1     dtype code (``_DTYPES``)
    7       1     flags: 1 NaN mask, 2 outliers, 4 lossless core, 8 bound held,
                  16 interpolation core (:mod:`wavecore.gridpredict`'s stream, not a bundle)
    8       1     number of dimensions k
    9       4k    shape (uint32 each)
    ...     8     max_error: the bound held (float64; NaN when no bound was asked for)
    ...     8     correction unit (float64)
    ...     8     offset added to a lossless core's samples (int64)
    ...     8     RMSE measured by the encoder over the finite cells (float64)
    ...     8     largest error measured by the encoder (float64)
    ...     12    lengths of the core, the mask and the outliers sections (uint32 each)
    ...           the three sections
    end-4   4     CRC-32 of everything before it

A wavelet core is an ordinary wavecore bundle (:func:`wavecore.decode` reads it), so a coarse
level (``decode(bundle, level=k)``) comes from its first chunks, as for any bundle; an
interpolation core gives the lattice of every ``2**k``-th sample.  A window of a wavelet core
reads only its code-blocks; a window of an interpolation core (version 3) entropy decodes only
the tiles its predictions reach and reconstructs only those samples.
"""

from __future__ import annotations

import math
import struct
import sys
import zlib
from collections.abc import Sequence
from typing import Any

import constriction
import numpy as np

from .arguments import as_native
from .bundle import MAX_ELEMENTS
from .errors import BitrateTooLow, BundleError, InvalidParameter
from .gridpredict import (
    decode_predictive,
    decode_predictive_window,
    encode_predictive,
    fixed_bytes,
    is_tiled_stream,
)
from .inflate import inflate

__all__ = ["decode_grid", "encode_grid", "inspect_grid", "is_grid_bundle"]

MAGIC = b"WVGD"
VERSION = 1
#: The version of bundles whose core is the interpolation stream (flag 16), which a reader of
#: version 1 would take for a wavecore bundle; version-1 bundles are still written otherwise.
PREDICTIVE_VERSION = 2
#: The version of bundles whose interpolation stream codes its fine levels by tiles (the
#: stream's own flag; a window decodes from its tiles), which a reader of version 2 would
#: refuse as a corrupt stream.  Grids of one tile still write version 2.
TILED_VERSION = 3
LAYOUT_FIELD, LAYOUT_VOLUME, LAYOUT_POINTS = 0, 1, 2
_FLAG_MASK, _FLAG_OUTLIERS, _FLAG_LOSSLESS, _FLAG_BOUND = 1, 2, 4, 8
_FLAG_PREDICTIVE = 16
_DTYPES = (
    "uint8",
    "int8",
    "uint16",
    "int16",
    "uint32",
    "int32",
    "uint64",
    "int64",
    "float16",
    "float32",
    "float64",
)
_HEAD = struct.Struct("<4sBBBBB")
_TAIL = struct.Struct("<ddqddIII")  # see the module docstring; the order is the file's
_CRC = struct.Struct("<I")
#: The default wavelet: at the same largest error the paper's bspline2 needs 9-13 % more bytes
#: than cdf97 on the benchmark's elevation model, field and volume (docs/benchmarks.md, Grids).
DEFAULT_WAVELET = "cdf97"
#: Without a target, a grid is coded to this fraction of its data range as the largest error.
DEFAULT_RELATIVE_MAX_ERROR = 1e-3
#: With ``max_error=t`` the core is quantized once with the base step ``t × _STEP_PER_BOUND``:
#: coarse enough that several per cent of the samples overshoot and are corrected (the total
#: size was flat within 1 % from 1.6 to 2.5 on the benchmark's float fields).
_STEP_PER_BOUND = 2.0
#: The same for integer grids, of the bound plus the half unit that rounding absorbs (on the
#: int16 elevation model 2.2 codes 3-7 % smaller than 1.4, flat from 2.0 to 2.4).
_STEP_PER_INTEGER_BOUND = 2.2
#: The dead zone of the bounded core: wider zero bins than the rate-distortion default (0.27)
#: leave more outliers but cost less in the core: 0.5-1 % smaller in total on those fields.
_BOUNDED_ROUNDING = 0.42
_MAX_SHAPE = 2**31
#: Integers beyond 2**53 do not survive the float64 core (nor the error check) exactly.
_EXACT_INTEGER = 2**53
_SMALL_CORRECTION = 8  # corrections -8..8 get their own symbol; larger ones are escaped
#: PSNR targets are met with this much to spare (dB), so that rounding in the arithmetic of the
#: target's conversion never leaves the RMSE a hair above what was asked.
_PSNR_MARGIN_DB = 1e-6
_RETRIES = 4


# --------------------------------------------------------------------------------------------
# Argument checks
# --------------------------------------------------------------------------------------------


def checked_grid(data: Any, ndims: Sequence[int], what: str) -> np.ndarray:
    try:
        arr = np.asarray(as_native(data))
    except (TypeError, ValueError) as exc:
        msg = f"cannot turn the {what} into a numeric array: {exc}"
        raise InvalidParameter(msg) from None
    arr = as_native(arr)
    if arr.dtype == np.bool_ or arr.dtype.kind not in "uif":
        msg = f"a {what} must hold integers or floats, not {arr.dtype}"
        raise InvalidParameter(msg)
    if arr.ndim not in ndims:
        spelled = " or ".join(f"{n}-D" for n in ndims)
        msg = f"a {what} must be {spelled}, not shape {arr.shape}"
        raise InvalidParameter(msg)
    if arr.size == 0:
        msg = f"the {what} is empty (shape {arr.shape})"
        raise InvalidParameter(msg)
    if any(n >= _MAX_SHAPE for n in arr.shape) or arr.size > MAX_ELEMENTS:
        msg = f"the {what}'s shape {arr.shape} holds more than {MAX_ELEMENTS} values"
        raise InvalidParameter(msg)
    if arr.dtype.kind == "f" and arr.dtype.itemsize > 8:
        arr = arr.astype(np.float64)  # longdouble: no wider float is portable
    if arr.dtype.name not in _DTYPES:
        msg = f"the {what} has dtype {arr.dtype}; expected one of {', '.join(_DTYPES)}"
        raise InvalidParameter(msg)
    if any_infinite(arr):
        msg = f"the {what} holds infinite values; only finite numbers and NaN can be encoded"
        raise InvalidParameter(msg)
    if arr.dtype.itemsize == 8 and arr.dtype.kind in "iu":
        lo, hi = int(arr.min()), int(arr.max())
        if max(abs(lo), abs(hi)) > _EXACT_INTEGER:
            msg = (
                f"the {what}'s 64-bit integers reach {hi if abs(hi) > abs(lo) else lo}, beyond "
                f"±2**53 that a float64 holds exactly; cast to float64 or a narrower range"
            )
            raise InvalidParameter(msg)
    return np.ascontiguousarray(arr)


def any_infinite(arr: np.ndarray) -> bool:
    """Whether a float array holds an infinite value, with no array of its size on the way
    (``np.isinf(arr).any()`` makes a bool a value: a quarter of a float32 Zarr chunk at the
    encoder's memory peak).  ``fmin``/``fmax`` skip NaN, which would hide an extreme."""
    if arr.dtype.kind != "f" or arr.size == 0:
        return False
    low, high = np.min(arr), np.max(arr)  # the fast reductions first
    if np.isnan(low):
        low, high = np.fmin.reduce(arr, axis=None), np.fmax.reduce(arr, axis=None)
    return bool(np.isinf(low) or np.isinf(high))


def _target(value: Any, name: str, what: str, *, zero: bool = False) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        msg = f"{name} must be a positive number ({what}), not {value!r}"
        raise InvalidParameter(msg)
    number = float(value)
    if not math.isfinite(number) or number < 0 or (number == 0 and not zero):
        accepted = "a finite number >= 0" if zero else "a positive finite number"
        msg = f"{name} must be {accepted} ({what}), not {value!r}"
        raise InvalidParameter(msg)
    return number


# --------------------------------------------------------------------------------------------
# NaN cells: a smooth fill for the transform, and the mask as run lengths
# --------------------------------------------------------------------------------------------


def fill_missing(values: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """``values`` (float64, 2-D or a stack of 2-D on the last two axes) with ``missing`` filled.

    Push–pull: the known cells are averaged down a pyramid of 2 × 2 blocks until every block
    has a value, then every missing cell takes the (smoothed) value of its block one level up,
    from the coarsest level back to the finest.  Linear in the size; the fill is an average of
    nearby known values, so it stays within their range and varies smoothly across a hole.

    Examples
    --------
    >>> z = np.array([[1.0, np.nan, 3.0], [4.0, 5.0, np.nan]])
    >>> filled = fill_missing(z, np.isnan(z))
    >>> bool(np.array_equal(filled[~np.isnan(z)], z[~np.isnan(z)]))  # known cells kept
    True
    >>> bool(np.all((filled >= 1.0) & (filled <= 5.0)))  # within the known range
    True
    """
    if not missing.any():
        return values
    if missing.all():
        return np.zeros_like(values)
    weights = (~missing).astype(np.float64)
    known = np.where(missing, 0.0, values)
    return _push_pull(known, weights)


def _push_pull(known: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Fill where ``weights`` is 0 from the weighted averages of coarser levels."""
    h, w = known.shape[-2:]
    if (h == 1 and w == 1) or weights.min() > 0:
        return np.where(weights > 0, known / np.maximum(weights, 1e-300), 0.0)
    # Down: 2 × 2 block sums (edge-padded to even sides).
    ph, pw = h + (h % 2), w + (w % 2)
    pad = [(0, 0)] * (known.ndim - 2) + [(0, ph - h), (0, pw - w)]
    k2 = np.pad(known, pad)
    w2 = np.pad(weights, pad)
    shape = (*known.shape[:-2], ph // 2, 2, pw // 2, 2)
    coarse_known = k2.reshape(shape).sum(axis=(-3, -1))
    coarse_weights = w2.reshape(shape).sum(axis=(-3, -1))
    coarse = _push_pull(coarse_known, coarse_weights)
    # Up: the coarse values, smoothed over their 3 × 3 neighbourhood, then repeated.
    smooth = _box3(coarse)
    up = np.repeat(np.repeat(smooth, 2, axis=-2), 2, axis=-1)[..., :h, :w]
    own = known / np.maximum(weights, 1e-300)
    return np.where(weights > 0, own, up)


def _box3(a: np.ndarray) -> np.ndarray:
    """The mean over each cell's 3 × 3 neighbourhood (edge-replicated), on the last two axes."""
    pad = [(0, 0)] * (a.ndim - 2) + [(1, 1), (1, 1)]
    p = np.pad(a, pad, mode="edge")
    rows = p[..., :-2, :] + p[..., 1:-1, :] + p[..., 2:, :]
    return (rows[..., :-2] + rows[..., 1:-1] + rows[..., 2:]) / 9.0


def _write_varints(values: np.ndarray) -> bytes:
    """Unsigned integers as LEB128 varints, vectorised (7 bits a byte, high bit = more)."""
    values = np.asarray(values, dtype=np.uint64)
    if values.size == 0:
        return b""
    nbytes = np.ones(values.size, dtype=np.int64)
    rest = values >> np.uint64(7)
    while rest.any():
        nbytes += rest > 0
        rest >>= np.uint64(7)
    ends = np.cumsum(nbytes)
    out = np.zeros(int(ends[-1]), dtype=np.uint8)
    starts = ends - nbytes
    current = values.copy()
    for i in range(int(nbytes.max())):
        active = nbytes > i
        byte = (current[active] & np.uint64(0x7F)).astype(np.uint8)
        more = nbytes[active] > i + 1
        out[starts[active] + i] = byte | (more.astype(np.uint8) << 7)
        current[active] >>= np.uint64(7)
    return out.tobytes()


def _read_varints(data: bytes, count: int) -> np.ndarray:
    """``count`` varints from ``data`` (all of it), or ``BundleError``."""
    raw = np.frombuffer(data, dtype=np.uint8)
    ends = np.flatnonzero(raw < 0x80)
    if ends.size != count or (raw.size and raw[-1] >= 0x80):
        msg = f"grid section holds {ends.size} numbers where {count} were expected"
        raise BundleError(msg)
    starts = np.concatenate(([0], ends[:-1] + 1))
    lengths = ends - starts + 1
    if lengths.size and lengths.max() > 9:
        msg = "grid section holds a number longer than 63 bits"
        raise BundleError(msg)
    values = np.zeros(count, dtype=np.uint64)
    for i in range(int(lengths.max()) if lengths.size else 0):
        active = lengths > i
        byte = raw[starts[active] + i].astype(np.uint64) & np.uint64(0x7F)
        values[active] |= byte << np.uint64(7 * i)
    return values


def encode_mask(mask: np.ndarray) -> bytes:
    """A boolean mask (any shape, C order) as deflated run lengths, first run unmasked.

    Holes in gridded data are blobs and stripes: a row crosses one in two runs.

    Examples
    --------
    >>> m = np.zeros((4, 5), bool); m[1:3, 2:4] = True
    >>> bool(np.array_equal(decode_mask(encode_mask(m), m.shape), m))
    True
    """
    flat = mask.reshape(-1)
    changes = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate(([0], changes, [flat.size]))
    runs = np.diff(bounds)
    if flat[0]:
        runs = np.concatenate(([0], runs))
    return zlib.compress(_write_varints(runs), 9)


def decode_mask(data: bytes, shape: tuple[int, ...]) -> np.ndarray:
    """The mask that :func:`encode_mask` wrote, or ``BundleError``."""
    size = math.prod(shape)
    # A run of L >= 1 cells takes at most L bytes as a varint (and the first run may be 0):
    # an honest mask's varints are at most size + 1 bytes.
    text = _inflate(data, size + 16, "NaN mask")
    raw = np.frombuffer(text, dtype=np.uint8)
    runs = _read_varints(text, int(np.count_nonzero(raw < 0x80)))
    if runs.size == 0 or int(runs.sum()) != size or (runs.size > 1 and runs[1:].min() == 0):
        msg = f"grid NaN mask does not describe {size} cells"
        raise BundleError(msg)
    states = np.arange(runs.size) % 2 == 1
    return np.repeat(states, runs.astype(np.int64)).reshape(shape)


def _inflate(data: bytes, limit: int, what: str) -> bytes:
    return inflate(data, limit, f"grid {what}")


# --------------------------------------------------------------------------------------------
# Outliers: positions (Rice-coded gaps) and corrections
# --------------------------------------------------------------------------------------------


def encode_positions(flags: np.ndarray) -> bytes:
    """The positions of the set flags (C order), as Golomb–Rice codes of the gaps between them.

    The outliers of a quantized wavelet code are scattered nearly independently (their flag's
    entropy hardly drops given the neighbours' flags or the local roughness, measured on the
    benchmark's fields), so their gaps are close to geometric, for which a Rice code is within
    about 3 % of the entropy, and it is coded and decoded in a few vectorised passes: the
    quotients in unary in one bit stream, the ``k``-bit remainders in another.

    Examples
    --------
    >>> flags = np.zeros(40, bool); flags[[0, 3, 4, 39]] = True
    >>> bool(np.array_equal(decode_positions(encode_positions(flags), 40), flags))
    True
    """
    positions = np.flatnonzero(flags.reshape(-1)).astype(np.int64)
    if positions.size == 0:
        return _write_varints(np.zeros(1, dtype=np.uint64))
    gaps = np.diff(positions, prepend=-1) - 1
    mean = float(gaps.mean())
    guess = max(0, round(math.log2(max(mean, 1.0) * math.log(2))))
    choices = [k for k in (guess - 1, guess, guess + 1) if 0 <= k <= 40]
    k = min(choices, key=lambda c: int(np.sum(gaps >> c)) + positions.size * (c + 1))
    quotients = gaps >> k
    ones = np.cumsum(quotients + 1) - 1
    unary = np.zeros(int(ones[-1]) + 1, dtype=np.uint8)
    unary[ones] = 1
    unary_bytes = np.packbits(unary).tobytes()
    shifts = np.arange(k - 1, -1, -1, dtype=np.int64)
    remainder_bits = ((gaps[:, None] >> shifts) & 1).astype(np.uint8).reshape(-1)
    head = _write_varints(np.array([positions.size, k, len(unary_bytes)], dtype=np.uint64))
    return head + unary_bytes + np.packbits(remainder_bits).tobytes()


def decode_positions(data: bytes, size: int) -> np.ndarray:
    """The flags that :func:`encode_positions` wrote, for ``size`` samples, or ``BundleError``."""
    raw = np.frombuffer(data, dtype=np.uint8)
    ends = np.flatnonzero(raw < 0x80)
    if ends.size == 0:
        msg = "grid outlier positions are truncated"
        raise BundleError(msg)
    if _read_varints(data[: int(ends[0]) + 1], 1)[0] == 0:
        if len(data) != int(ends[0]) + 1:
            msg = "grid outlier positions have bytes after an empty list"
            raise BundleError(msg)
        return np.zeros(size, dtype=bool)
    if ends.size < 3:
        msg = "grid outlier positions are truncated"
        raise BundleError(msg)
    head = int(ends[2]) + 1
    count, k, unary_length = (int(v) for v in _read_varints(data[:head], 3))
    remainder_length = (count * k + 7) // 8
    if count > size or k > 40 or head + unary_length + remainder_length != len(data):
        msg = "grid outlier positions do not fit the grid"
        raise BundleError(msg)
    unary = np.unpackbits(raw[head : head + unary_length])
    ones = np.flatnonzero(unary)
    if ones.size < count:
        msg = "grid outlier positions are truncated"
        raise BundleError(msg)
    ones = ones[:count]
    quotients = np.diff(ones, prepend=-1) - 1
    if k:
        bits = np.unpackbits(raw[head + unary_length :])[: count * k].reshape(count, k)
        remainders = bits.astype(np.int64) @ (np.int64(1) << np.arange(k - 1, -1, -1))
    else:
        remainders = np.zeros(count, dtype=np.int64)
    if quotients.size and quotients.max() > (size >> k):
        msg = "grid outlier positions lie beyond the grid"
        raise BundleError(msg)
    positions = np.cumsum((quotients.astype(np.int64) << k) + remainders + 1) - 1
    if positions[-1] >= size:
        msg = "grid outlier positions lie beyond the grid"
        raise BundleError(msg)
    flags = np.zeros(size, dtype=bool)
    flags[positions] = True
    return flags


# Correction symbols: 0 = stored exactly, 1..16 = -8..-1, 1..8, 17 = escaped integer.
_EXACT_SYMBOL = 0
_ESCAPE_SYMBOL = 2 * _SMALL_CORRECTION + 1
_SYMBOLS = _ESCAPE_SYMBOL + 1


def _symbols(multiples: np.ndarray, exact: np.ndarray) -> np.ndarray:
    small = (np.abs(multiples) <= _SMALL_CORRECTION) & (multiples != 0)
    symbols = np.full(multiples.size, _ESCAPE_SYMBOL, dtype=np.int32)
    negative = small & (multiples < 0)
    positive = small & (multiples > 0)
    symbols[negative] = (multiples[negative] + _SMALL_CORRECTION + 1).astype(np.int32)
    symbols[positive] = (multiples[positive] + _SMALL_CORRECTION).astype(np.int32)
    symbols[exact] = _EXACT_SYMBOL
    return symbols


def _multiples(symbols: np.ndarray) -> np.ndarray:
    out = np.zeros(symbols.size, dtype=np.int64)
    negative = (symbols >= 1) & (symbols <= _SMALL_CORRECTION)
    positive = (symbols > _SMALL_CORRECTION) & (symbols < _ESCAPE_SYMBOL)
    out[negative] = symbols[negative].astype(np.int64) - _SMALL_CORRECTION - 1
    out[positive] = symbols[positive].astype(np.int64) - _SMALL_CORRECTION
    return out


def encode_outliers(
    flags: np.ndarray,
    multiples: np.ndarray,
    exact: np.ndarray,
    exact_values: np.ndarray,
) -> bytes:
    """Positions and corrections of the outliers, as one section.

    ``flags`` (bool, one per sample) marks the outliers; per outlier, in order, ``multiples``
    (int64, the correction in
    units) and ``exact`` (bool: stored as ``exact_values`` instead, in the grid's dtype).
    """
    positions = encode_positions(flags)
    symbols = _symbols(multiples, exact)
    counts = np.bincount(symbols, minlength=_SYMBOLS).astype(np.int64)
    encoder = constriction.stream.queue.RangeEncoder()
    if symbols.size:
        model = constriction.stream.model.Categorical(
            (counts + 0.01) / (counts + 0.01).sum(), perfect=False
        )
        encoder.encode(symbols, model)
    corrections = encoder.get_compressed().tobytes()
    escaped = multiples[symbols == _ESCAPE_SYMBOL]
    zigzag = np.where(escaped < 0, -2 * escaped - 1, 2 * escaped).astype(np.uint64)
    extras = zlib.compress(_write_varints(zigzag) + exact_values.tobytes(), 9)
    parts = [positions, _write_varints(counts), corrections, extras]
    return struct.pack("<III", len(parts[0]), len(parts[2]), len(parts[3])) + b"".join(
        [parts[0], parts[1], parts[2], parts[3]]
    )


def decode_outliers(
    data: bytes, size: int, dtype: np.dtype[Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(flags, multiples, exact, exact_values)`` as :func:`encode_outliers` took them."""
    if len(data) < 12:
        msg = "grid outlier section is truncated"
        raise BundleError(msg)
    n_positions, n_corrections, n_extras = struct.unpack_from("<III", data)
    body = data[12:]
    positions = body[:n_positions]
    rest = body[n_positions:]
    raw = np.frombuffer(rest, dtype=np.uint8)
    ends = np.flatnonzero(raw < 0x80)
    if ends.size < _SYMBOLS:
        msg = "grid outlier section is truncated"
        raise BundleError(msg)
    head = int(ends[_SYMBOLS - 1]) + 1
    counts = _read_varints(rest[:head], _SYMBOLS).astype(np.int64)
    corrections = rest[head : head + n_corrections]
    extras = rest[head + n_corrections :]
    if len(extras) != n_extras or len(corrections) != n_corrections or n_corrections % 4:
        msg = "grid outlier section's lengths do not add up"
        raise BundleError(msg)
    flags = decode_positions(positions, size)
    total = int(np.count_nonzero(flags))
    if int(counts.sum()) != total:
        msg = f"grid outlier section has {int(counts.sum())} corrections for {total} outliers"
        raise BundleError(msg)
    symbols = np.zeros(0, dtype=np.int32)
    if total:
        model = constriction.stream.model.Categorical(
            (counts + 0.01) / (counts + 0.01).sum(), perfect=False
        )
        decoder = constriction.stream.queue.RangeDecoder(
            np.frombuffer(corrections, dtype=np.uint32).copy()
        )
        symbols = np.asarray(decoder.decode(model, total), dtype=np.int32)
        if not np.array_equal(np.bincount(symbols, minlength=_SYMBOLS), counts):
            msg = "grid outlier corrections do not match their counts"
            raise BundleError(msg)
    multiples = _multiples(symbols)
    escapes = int(counts[_ESCAPE_SYMBOL])
    exact_count = int(counts[_EXACT_SYMBOL])
    limit = 10 * escapes + exact_count * dtype.itemsize
    text = _inflate(extras, limit, "outlier values")
    raw_extra = np.frombuffer(text, dtype=np.uint8)
    tail = exact_count * dtype.itemsize
    if len(text) < tail:
        msg = "grid outlier values are truncated"
        raise BundleError(msg)
    varint_part = text[: len(text) - tail]
    del raw_extra
    zigzag = (
        _read_varints(varint_part, escapes).astype(np.int64) if escapes else np.zeros(0, np.int64)
    )
    multiples[symbols == _ESCAPE_SYMBOL] = np.where(
        zigzag % 2 == 1, -(zigzag + 1) // 2, zigzag // 2
    )
    exact = symbols == _EXACT_SYMBOL
    exact_values = np.frombuffer(text[len(text) - tail :], dtype=dtype.newbyteorder("<"))
    return flags, multiples, exact, exact_values.astype(dtype)


# --------------------------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------------------------


def _to_dtype(values: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    """Float64 samples → the grid's dtype, as the decoder does it: rounded and clipped for
    integers, saturated for narrow floats (never turned infinite)."""
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), float(info.min), float(info.max)).astype(dtype)
    if dtype.itemsize < 8:
        largest = float(np.finfo(dtype).max)
        return np.clip(values, -largest, largest).astype(dtype)
    return values.astype(dtype)


def _to_core(values: np.ndarray, layout: int) -> np.ndarray:
    """The grid in the core's layout: a volume's slices become the trailing axis."""
    if layout == LAYOUT_VOLUME:
        return np.ascontiguousarray(np.moveaxis(values, 0, -1))
    return values


def _from_core(values: np.ndarray, layout: int) -> np.ndarray:
    if layout == LAYOUT_VOLUME:
        return np.ascontiguousarray(np.moveaxis(values, -1, 0))
    return values


def _core_shape(shape: tuple[int, ...], layout: int) -> tuple[int, ...]:
    """:func:`_to_core`'s shape, with no array made (a bundle's declared shape may be large)."""
    return (*shape[1:], shape[0]) if layout == LAYOUT_VOLUME else tuple(shape)


def _grid_shape(core_shape: tuple[int, ...], layout: int) -> tuple[int, ...]:
    """:func:`_from_core`'s shape, with no array made."""
    if layout == LAYOUT_VOLUME:
        return (core_shape[-1], *core_shape[:-1])
    return tuple(core_shape)


def _spatial_shape(shape: tuple[int, ...], layout: int) -> tuple[int, int]:
    """(rows, columns) of the 2-D transform."""
    return (shape[1], shape[2]) if layout == LAYOUT_VOLUME else (shape[0], shape[1])


class _Core:
    """Codes the float64 core with the codec, in the core layout, and decodes it back."""

    def __init__(self, wavelet: str, level: int | None, boundary: tuple[str, str]) -> None:
        self.wavelet, self.level, self.boundary = wavelet, level, boundary

    def at_step(
        self, core: np.ndarray, step: float, rounding: float = _BOUNDED_ROUNDING
    ) -> tuple[bytes, np.ndarray]:
        """The core bundle quantized at ``step``, and what decoding it returns."""
        from .codec.encode import encode_surface_at_step

        return encode_surface_at_step(
            core,
            step,
            level=self.level,
            wavelet=self.wavelet,
            boundary=self.boundary,
            rounding=rounding,
        )

    def encode_to_bpp(self, core: np.ndarray, bpp: float) -> tuple[bytes, np.ndarray]:
        """The core bundle of at most ``bpp`` bits per point (the codec's rate control) and what
        decoding it returns (the rate control's own reconstruction where it kept one)."""
        from .codec.encode import encode_surface_and_output

        return encode_surface_and_output(
            core, bpp=bpp, wavelet=self.wavelet, level=self.level, boundary=self.boundary
        )

    def encode(self, core: np.ndarray, *, quality: float | None, bpp: float | None) -> bytes:
        from .codec import encode_surface  # the codec imports this module for decode

        targets: dict[str, Any] = {"quality": quality}
        if bpp is not None:
            targets = {"bpp": bpp}
        return encode_surface(
            core,
            **targets,
            wavelet=self.wavelet,
            level=self.level,
            boundary=self.boundary,
        )


def _decode_core(
    core: bytes, level: int, keep: float | None = None, region: Any = None
) -> np.ndarray:
    from .codec import decode

    return decode(core, level=level, keep=keep, region=region)


def _inspect_core(core: bytes) -> dict[str, Any]:
    from .codec import inspect

    return inspect(core)


def _peak(values: np.ndarray) -> float:
    """The codec's peak of a float surface: its range, or its magnitude (at least 1) if flat."""
    lo, hi = float(values.min()), float(values.max())
    return hi - lo if hi > lo else max(abs(hi), 1.0)


def _quality_for(peak: float, rmse: float) -> float:
    """The PSNR (dB) against ``peak`` that an RMSE of at most ``rmse`` needs."""
    if rmse <= 0:
        return 400.0
    ratio = peak / rmse
    if ratio <= 0 or not math.isfinite(ratio):
        return 400.0 if ratio > 0 else 0.1
    return max(20.0 * math.log10(ratio) + _PSNR_MARGIN_DB, 0.1)


def encode_grid(
    data: Any,
    *,
    wavelet: str | None = None,
    level: int | None = None,
    max_error: float | None = None,
    rmse: float | None = None,
    psnr: float | None = None,
    bpp: float | None = None,
    lossless: bool = False,
) -> bytes:
    """Encode a height field ``(H, W)`` or a volume ``(D, H, W)`` of floats or integers.

    Parameters
    ----------
    data : array_like
        Any size, any of ``uint8`` … ``int64`` (64-bit integers up to ±2**53) and ``float16`` …
        ``float64``, any byte order.  NaN cells (missing data) decode as NaN, exactly;
        infinities are refused.  The interpolation coder (``max_error``; ``rmse``, ``psnr``
        and ``bpp`` at high rates) predicts a volume along all three axes; the wavelet core
        codes it slice by slice along its first axis, under one 2-D transform per slice (see
        the module docstring).
    wavelet : str, optional
        The wavelet core's: ``"cdf97"`` by default (the measured winner on height fields,
        docs/benchmarks.md), ``"bspline2"`` (the paper's), ``"haar"`` or an alias
        (:func:`wavecore.wavelet_names`).  With ``max_error``, naming one codes the wavelet core
        and its outliers instead of the interpolation coder (which is smaller and faster).
    level : int, optional
        The wavelet core's decomposition levels; ``None`` picks up to 5.  (The interpolation
        coder of ``max_error`` always goes down to a single sample; any coarse level decodes.)
    max_error : float, optional
        A bound on the absolute error that holds on **every** sample (finite cells; NaN cells
        are exact).  For integer grids it counts in whole units (``0.5`` means exact).
    rmse : float, optional
        The root-mean-square error over the finite cells, met or beaten.
    psnr : float, optional
        In dB against the data range (largest minus smallest finite value), met or beaten.
    bpp : float, optional
        Bits per sample of the whole bundle (``8 × len(bundle) / size``), never exceeded.
    lossless : bool
        Bit-exact coding of an integer grid.

    Give at most one target.  Without one the grid is coded to ``max_error`` = 0.001 × its
    data range (which is lossless for integer grids of range below 1000).

    Returns
    -------
    bytes
        A grid bundle; :func:`wavecore.decode` returns the grid in its shape and dtype.

    Examples
    --------
    >>> import numpy as np
    >>> y, x = np.mgrid[0:60, 0:80]
    >>> heights = np.sin(x / 9.0) * np.cos(y / 7.0) * 100.0
    >>> heights[20:30, 10:25] = np.nan
    >>> bundle = encode_grid(heights, max_error=0.05)
    >>> out = decode_grid(bundle)
    >>> bool(np.nanmax(np.abs(out - heights)) <= 0.05), bool(np.isnan(out[20:30, 10:25]).all())
    (True, True)
    """
    arr = checked_grid(data, (2, 3), "grid")
    layout = LAYOUT_VOLUME if arr.ndim == 3 else LAYOUT_FIELD
    return encode_layout(
        arr,
        layout,
        wavelet=wavelet,
        level=level,
        boundary=("open", "open"),
        max_error=max_error,
        rmse=rmse,
        psnr=psnr,
        bpp=bpp,
        lossless=lossless,
    )


def encode_layout(
    arr: np.ndarray,
    layout: int,
    *,
    wavelet: str | None,
    level: int | None,
    boundary: tuple[str, str],
    max_error: float | None = None,
    rmse: float | None = None,
    psnr: float | None = None,
    bpp: float | None = None,
    lossless: bool = False,
    tiles: bool = True,
) -> bytes:
    """:func:`encode_grid` of an already checked array in the given layout (``LAYOUT_*``);
    ``encode_surface`` comes here for its ``max_error`` target.  ``tiles=False`` codes the
    interpolation coder's ``max_error`` stream untiled even above one tile (version 2): for a
    caller whose unit of a window is the grid itself (a Zarr chunk)."""
    given = [
        name
        for name, value in (("max_error", max_error), ("rmse", rmse), ("psnr", psnr), ("bpp", bpp))
        if value is not None
    ]
    if len(given) > 1:
        msg = f"give at most one of max_error, rmse, psnr and bpp, not {' and '.join(given)}"
        raise InvalidParameter(msg)
    if not isinstance(lossless, bool | np.bool_):
        msg = f"lossless must be True or False, not {lossless!r}"
        raise InvalidParameter(msg)
    dtype = arr.dtype
    if lossless:
        if given:
            msg = f"lossless=True cannot be combined with {given[0]}"
            raise InvalidParameter(msg)
        if dtype.kind == "f":
            msg = (
                f"lossless=True is for integer grids, not {dtype}; give max_error for a "
                "guaranteed bound on floats"
            )
            raise InvalidParameter(msg)
    bound = _target(max_error, "max_error", "an absolute error", zero=True)
    rmse_target = _target(rmse, "rmse", "a root-mean-square error")
    psnr_target = _target(psnr, "psnr", "a PSNR in dB")
    bpp_target = _target(bpp, "bpp", "bits per sample")
    name = DEFAULT_WAVELET if wavelet is None else wavelet
    if not isinstance(name, str):
        msg = f"wavelet must be a name such as 'cdf97' or 'bspline2', not {wavelet!r}"
        raise InvalidParameter(msg)
    core = _Core(name, level, boundary)

    values = arr.astype(np.float64)
    # NaN propagates through min (the grid holds no infinities): the mask is made only when
    # needed; without NaN a read-only view of False stands for it (no bytes per sample).
    low = values.min()
    has_mask = dtype.kind == "f" and bool(np.isnan(low))
    missing = np.isnan(values) if has_mask else np.broadcast_to(np.False_, arr.shape)
    if has_mask:
        finite = values[~missing]
        top, bottom = (float(finite.max()), float(finite.min())) if finite.size else (0.0, 0.0)
    else:  # no copy of the values for their range
        top, bottom = float(values.max()), float(low)
    # halved, so that a range of more than the largest float (±1.8e308) stays finite
    half_range = top / 2 - bottom / 2
    if not (bound is not None or rmse_target or psnr_target or bpp_target or lossless):
        bound = 2 * DEFAULT_RELATIVE_MAX_ERROR * half_range
    if psnr_target is not None:
        scale = 10.0 ** (-psnr_target / 20.0)
        rmse_target = 2 * (half_range * scale) if half_range > 0 else scale
    if rmse_target is not None and dtype.kind == "f" and bound is None:
        finite_values = values[~missing] if has_mask else values
        largest = float(np.max(np.abs(finite_values))) if finite_values.size else 0.0
        unresolved = math.ldexp(largest, -_UNRESOLVED_BITS)
        if not rmse_target >= max(unresolved, sys.float_info.min):
            # Far below what float64 resolves (psnr=1000), subnormal or 0: coded to a bound that
            # float64 does not resolve either (or exactly, on subnormal data), where the
            # searches would divide by the target, or step to 0.
            bound = unresolved if unresolved >= sys.float_info.min else 0.0
            rmse_target = None
        elif largest > 0:
            # Zeros everywhere would meet any larger target; the searches' steps would
            # overflow with it (an rmse of 1e300 on values near 1e-300).
            rmse_target = min(rmse_target, largest)
    if dtype.kind in "iu" and bound is not None and bound < 1.0:
        lossless = True  # no error below one unit is possible but none
    # An integer grid under rmse (or psnr), no wavelet named: the coder is chosen from the
    # target before anything is coded (see _EXACT_BELOW_RMSE and _RUNG_TOP).
    integer_rmse = (
        wavelet is None
        and dtype.kind in "iu"
        and rmse_target is not None
        and layout != LAYOUT_POINTS
    )
    if integer_rmse and rmse_target is not None and rmse_target <= _EXACT_BELOW_RMSE:
        bound = 0.0  # the interpolation coder, exact (see _EXACT_BELOW_RMSE)
    if lossless:
        span = int(arr.max()) - int(arr.min())
        if span <= 65535 and layout != LAYOUT_POINTS:
            return _encode_lossless(arr, layout, level)
        bound = 0.0
    mask_bytes = encode_mask(missing) if has_mask else b""
    # The interpolation coder for a bound, unless a wavelet was asked for by name (the
    # wavelet core and its outliers, as before it) or the bound is 0 on floats.
    predictive = wavelet is None and (bound is not None and (bound > 0 or dtype.kind in "iu"))
    if predictive and bound is not None:
        return _encode_predictive(arr, layout, values, missing, mask_bytes, bound, tiles=tiles)
    if not has_mask:  # the other coders index, invert and reshape the mask: a real one
        missing = np.zeros(arr.shape, dtype=bool)

    def core_layout() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(filled values, values, missing) in the wavelet core's layout."""
        filled = fill_missing(values, missing) if has_mask else values
        return _to_core(filled, layout), _to_core(values, layout), _to_core(missing, layout)

    if integer_rmse and rmse_target is not None and _RUNG_RMSE <= rmse_target <= _RUNG_TOP:
        target = rmse_target
        return _encode_rmse_rung(
            arr,
            layout,
            values,
            missing,
            mask_bytes,
            target,
            lambda: _encode_rmse_wavelet(arr, layout, core, *core_layout(), mask_bytes, target),
        )
    by_interpolation = wavelet is None and dtype.kind == "f" and layout != LAYOUT_POINTS
    if rmse_target is not None and by_interpolation:
        # A float field or volume under rmse (or psnr), no wavelet named: interpolation first.
        target = rmse_target
        return _encode_rmse_predictive(
            arr,
            layout,
            values,
            missing,
            mask_bytes,
            target,
            lambda: _encode_rmse_wavelet(arr, layout, core, *core_layout(), mask_bytes, target),
        )
    if bpp_target is not None and by_interpolation and bpp_target >= _WAVELET_BELOW_BPP:
        found = _encode_bpp_predictive(arr, layout, values, missing, mask_bytes, bpp_target)
        if found is not None:
            return found
    if (
        bpp_target is not None
        and wavelet is None
        and dtype.kind in "iu"
        and layout != LAYOUT_POINTS
    ):
        found = _encode_bpp_exact(arr, layout, values, missing, mask_bytes, bpp_target)
        if found is not None:
            return found
    bounded = b""
    core_values, original, core_missing = core_layout()
    finite_count = max(int(np.count_nonzero(~missing)), 1)

    if bound is not None:
        bounded = _encode_bounded(
            arr, layout, core, core_values, original, core_missing, mask_bytes, bound
        )
        if dtype.kind == "f" and not has_mask and layout != LAYOUT_POINTS and _integers(values):
            # Whole numbers stored as floats (an elevation model in metres, say): coded
            # bit-exactly they can be smaller than any lossy code of a tight bound (a third
            # smaller than the bounded code at 1e-4 of the range on the benchmark's model).
            try:
                return min(bounded, _encode_lossless(arr, layout, level), key=len)
            except InvalidParameter:  # a level too deep for the reversible filters
                return bounded
        return bounded
    # RMSE (or PSNR) and bpp: the core alone, verified over the finite cells.
    if bpp_target is not None:
        overhead = _TAIL.size + _HEAD.size + 4 * arr.ndim + _CRC.size + len(mask_bytes)
        budget_bits = bpp_target * arr.size - 8 * overhead
        rows, cols = core_values.shape[:2]
        try:
            core_bytes, decoded = core.encode_to_bpp(
                core_values, max(budget_bits, 1.0) / (rows * cols)
            )
        except BitrateTooLow as exc:  # restated per value of the grid, not per core point
            smallest = exc.smallest_bytes + overhead
            msg = (
                f"bpp {bpp_target} is below what this grid can be coded in: bpp "
                f"{8 * smallest / arr.size:.4f} ({smallest} bytes, header included) codes it"
            )
            raise BitrateTooLow(msg, smallest) from None
        if not has_mask and dtype.kind in "iu" and dtype.itemsize <= 4:
            # Measured as the RMSE search measures: one compiled pass that rounds and clips as
            # the cast does, with no array of the dtype made (the cast and NumPy's four passes
            # were 7 % of an int16 grid's bpp encode).
            from .gridcore import squared_and_largest_rounded

            squares, largest = squared_and_largest_rounded(decoded, original, dtype)
            measured = (math.sqrt(squares / finite_count), largest)
        else:
            measured = _measure(_to_dtype(decoded, dtype), original, core_missing, finite_count)
        return _assemble_core(arr, layout, core_bytes, mask_bytes, *measured)
    assert rmse_target is not None
    return _encode_rmse_wavelet(
        arr, layout, core, core_values, original, core_missing, mask_bytes, rmse_target
    )


def _encode_rmse_wavelet(
    arr: np.ndarray,
    layout: int,
    core: _Core,
    core_values: np.ndarray,
    original: np.ndarray,
    core_missing: np.ndarray,
    mask_bytes: bytes,
    rmse_target: float,
) -> bytes:
    """An RMSE target met by the wavelet core alone (see :func:`_encode_rmse_at_steps`)."""
    dtype = arr.dtype
    finite_count = max(int(np.count_nonzero(~core_missing)), 1)
    peak = _peak(core_values)
    fast = _encode_rmse_at_steps(
        arr, layout, core, core_values, original, core_missing, mask_bytes, rmse_target
    )
    if fast is not None:
        return fast
    aim = rmse_target * math.sqrt(finite_count / core_values.size)
    for _ in range(_RETRIES):
        core_bytes = core.encode(core_values, quality=_quality_for(peak, aim), bpp=None)
        final = _to_dtype(_decode_core(core_bytes, 0), dtype)
        measured_rmse, largest = _measure(final, original, core_missing, finite_count)
        if measured_rmse <= rmse_target:
            return _assemble_core(arr, layout, core_bytes, mask_bytes, measured_rmse, largest)
        aim *= 0.95 * rmse_target / measured_rmse
    msg = f"rmse {rmse_target!r} could not be reached for this grid; ask for a larger rmse"
    raise InvalidParameter(msg)


#: Under an RMSE target a float grid is coded by interpolation (uniform errors in ``[-t, t]``,
#: RMSE ``t / sqrt(3)``) with ``t`` this many times the target, then checked.
_BOUND_PER_RMSE = math.sqrt(3.0)
#: Below this many bits per sample the interpolation coder's bundle is compared with the
#: wavelet core's and the smaller kept: at low rates the transform's coding gain wins (the
#: elevation model at 2.2 bpp: the wavelet core 6 % smaller), at high rates in-loop
#: prediction does (the benchmark's field at 7 bpp: interpolation 1-3 % smaller, 3x faster).
_WAVELET_BELOW_BPP = 4.0


def _encode_rmse_predictive(
    arr: np.ndarray,
    layout: int,
    values: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    rmse_target: float,
    wavelet_core: Any,
) -> bytes:
    """An RMSE target on a float grid, by the interpolation coder: its in-loop quantization
    leaves each sample an error nearly uniform in ``[-t, t]``, so ``t = sqrt(3) × target``
    lands within a per mille of the target (the encoder measures the exact RMSE of what the
    decoder returns and steps ``t`` down if it missed).  Where that takes fewer than
    ``_WAVELET_BELOW_BPP`` bits per sample, ``wavelet_core()`` codes the grid too and the
    smaller bundle is kept.  A volume is predicted along all three axes."""
    bound = rmse_target * _BOUND_PER_RMSE * _RMSE_AIM
    best: bytes | None = None
    for _ in range(_RMSE_TRIES):
        bundle, measured = _predictive_bundle(arr, layout, values, missing, mask_bytes, bound)
        if measured <= rmse_target:
            best = bundle
            break
        if not measured > 0 or not math.isfinite(measured):
            break
        bound *= 0.99 * rmse_target / measured
    if best is not None and 8.0 * len(best) >= _WAVELET_BELOW_BPP * arr.size:
        return best
    other = wavelet_core()
    return other if best is None or len(other) < len(best) else best


#: An integer grid under an RMSE target at most this is coded exactly, by the interpolation
#: coder at a bound of 0: the wavelet core's rounded output needs so fine a step there that the
#: exact code is smaller (on seven integer grids, the elevation model, tiled or not, as uint8,
#: and four quantized synthesized fields and volumes, the wavelet core took 1.01-1.08x its bytes
#: at an RMSE of 0.4, 1.13-1.35x at 0.3; 0.90-1.05x at 0.45).  It is 0.93-1.06x the bytes of
#: the reversible lossless code, and three times as fast.
_EXACT_BELOW_RMSE = 0.4
#: A float grid's RMSE (or PSNR) target below its largest magnitude × 2**-100 (some 600 dB;
#: float64 resolves 2**-52) is met by a bound of that size instead.
_UNRESOLVED_BITS = 100
#: The interpolation coder's RMSE on an integer grid at a bound of one unit (errors -1, 0 and 1,
#: about equally likely): its first rung above exact.
_RUNG_RMSE = math.sqrt(2.0 / 3.0)
#: Up to this RMSE the rung takes fewer bytes than the wavelet core at the target (2-7 % fewer
#: at 1.06x the rung's RMSE on six integer grids of 3 to 12 bits a sample; at 1.5 bits a sample,
#: a uint8 elevation model, 9 % more), and codes several times faster.
_RUNG_TOP = 1.06 * _RUNG_RMSE
#: Below this many bits per sample the rung's bundle is compared with the wavelet core's.
_RUNG_MIN_BPP = 3.0


def _encode_rmse_rung(
    arr: np.ndarray,
    layout: int,
    values: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    rmse_target: float,
    wavelet_core: Any,
) -> bytes:
    """An RMSE target on an integer grid just above the interpolation coder's first rung
    (``_RUNG_RMSE``, a bound of one unit): that coder alone, unless its measured RMSE misses
    the target (a hair above the rung's typical one) or it takes fewer than ``_RUNG_MIN_BPP``
    bits a sample (then ``wavelet_core()`` codes too, and the smaller bundle that meets the
    target is kept)."""
    bundle, measured = _predictive_bundle(arr, layout, values, missing, mask_bytes, 1.0)
    if measured <= rmse_target and 8.0 * len(bundle) >= _RUNG_MIN_BPP * arr.size:
        return bundle
    other: bytes = wavelet_core()
    return bundle if measured <= rmse_target and len(bundle) < len(other) else other


#: The bpp search's full codings: each after the first moves ``t`` by the bits it missed by
#: (at these rates a sample's bits fall by one as ``t`` doubles).
_BPP_TRIES = 4
#: A coding within this fraction under the budget is taken.
_BPP_SLACK = 0.015
#: The side of the centred crop whose codings give the search its first ``t`` (a field's
#: 128 × 128, a volume's 16 × 64 × 64): cheap, and within a few per cent on stationary fields.
_BPP_CROP = (128, 128)
#: The crop aims this far under the budget, so that the first coding of the whole grid lands
#: inside ``_BPP_SLACK`` under it (the crops' bits per sample were within 0.3 % of the whole
#: field's at the same ``t``) and is the only one.
_BPP_CROP_AIM = 0.993
_BPP_VOLUME_CROP = (16, 64, 64)


def _encode_bpp_predictive(
    arr: np.ndarray,
    layout: int,
    values: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    bpp: float,
) -> bytes | None:
    """A ``bpp`` budget of ``_WAVELET_BELOW_BPP`` or more on a float grid, by the interpolation
    coder (which codes smaller than the wavelet core at such rates, and several times faster):
    ``t`` is found on a centred crop, then corrected on the whole grid by the bits it missed
    by, never over the budget; ``None`` if the tries end over it (the wavelet core then)."""
    budget = math.floor(bpp * arr.size / 8.0)
    crop_shape = _BPP_VOLUME_CROP if arr.ndim == 3 else _BPP_CROP
    crop = tuple(
        slice((n - min(n, c)) // 2, (n - min(n, c)) // 2 + min(n, c))
        for n, c in zip(arr.shape, crop_shape, strict=True)
    )
    finite = values[~missing]
    spread = float(finite.max() - finite.min()) if finite.size else 0.0
    bound = max(spread, 1e-300) * 2.0**-12
    sample = arr[crop]
    crop_mask = encode_mask(missing[crop]) if bool(missing[crop].any()) else b""
    for _ in range(6):  # the crop's own search: a few codings of at most 16 384 samples
        crop_bundle = _predictive_bundle(
            sample, layout, values[crop], missing[crop], crop_mask, bound
        )[0]
        # Its fixed bytes (headers, tables, weights: about as many as the whole grid's) are
        # left out: the crop aims at the whole grid's bits per sample of residuals.
        fixed = (
            fixed_bytes(_Parsed(crop_bundle).core)
            + len(crop_bundle)
            - len(_Parsed(crop_bundle).core)
        )
        target = (budget - fixed) * _BPP_CROP_AIM * sample.size / arr.size
        miss = 8.0 * (len(crop_bundle) - fixed - target) / sample.size
        if abs(miss) < 0.01:
            break
        bound *= 2.0 ** min(max(miss, -8.0), 8.0)
    best: bytes | None = None
    for _ in range(_BPP_TRIES):
        if not (bound > 0 and math.isfinite(bound)):
            break
        bundle, measured = _predictive_bundle(arr, layout, values, missing, mask_bytes, bound)
        if len(bundle) <= budget:
            if best is None or len(bundle) > len(best):
                best = bundle
            if len(bundle) >= (1.0 - _BPP_SLACK) * budget or measured == 0:
                break  # close enough, or exact: no larger bundle is worth having
        # A little more than the bits missed by, so that the next try lands under the budget.
        miss = 8.0 * (len(bundle) - budget) / arr.size
        bound *= 2.0 ** (miss + (0.005 if miss > 0 else 0.002))
    return best


#: An integer grid under a ``bpp`` budget is coded exactly (the interpolation coder at a bound
#: of 0) where a centred crop coded so predicts at most this share of the budget: the crop's
#: bits per sample were within 1 % of the whole grid's on the benchmark's integer grids.
_EXACT_BPP_SHARE = 0.97


def _encode_bpp_exact(
    arr: np.ndarray,
    layout: int,
    values: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    bpp: float,
) -> bytes | None:
    """An integer grid's exact code if it fits a ``bpp`` budget (no error at all, where the
    wavelet core would spend the same budget on a lossy code), else None.  Whether it fits is
    predicted from a centred crop (``_BPP_CROP``) before the whole grid is coded, so a budget
    it cannot fit costs the crop's coding only."""
    budget = math.floor(bpp * arr.size / 8.0)
    crop_shape = _BPP_VOLUME_CROP if arr.ndim == 3 else _BPP_CROP
    crop = tuple(
        slice((n - min(n, c)) // 2, (n - min(n, c)) // 2 + min(n, c))
        for n, c in zip(arr.shape, crop_shape, strict=True)
    )
    sample = arr[crop]
    crop_bundle = _predictive_bundle(sample, layout, values[crop], missing[crop], b"", 0.0)[0]
    if sample.size == arr.size:  # the crop is the grid
        return crop_bundle if len(crop_bundle) <= budget else None
    parsed = _Parsed(crop_bundle)
    fixed = fixed_bytes(parsed.core) + len(crop_bundle) - len(parsed.core)
    predicted = fixed + (len(crop_bundle) - fixed) * arr.size / sample.size
    if predicted > _EXACT_BPP_SHARE * budget:
        return None
    bundle = _predictive_bundle(arr, layout, values, missing, mask_bytes, 0.0)[0]
    return bundle if len(bundle) <= budget else None


#: The open-loop search's first step, this many times the target: about what the dead-zone
#: quantizer's error comes to at the rates such targets ask for (the measured ratio was 2.9-3.6
#: on the benchmark's grids); the search then moves it to the predicted step.
_STEP_PER_RMSE = 3.2
_RMSE_TRIES = 4
#: The open-loop prediction is aimed this far below the target, so that the one coding lands
#: on its safe side: the prediction was within 0.1 % of the decoded RMSE on the benchmark's
#: fields, and the cast to float32 adds a little.
_RMSE_AIM = 0.995
#: A try that missed is followed by one aimed this far below the target (with the open loop's
#: prediction corrected by what the miss measured).
_RMSE_RETRY_AIM = 0.997
#: A try whose RMSE comes this far under the target or further is tried again at a coarser
#: step (no coding in between): on integer grids at sub-unit targets the rounding of the
#: decoded samples takes most errors to 0, which the open-loop step cannot foresee.
_RMSE_FAR_UNDER = 0.95


def _encode_rmse_at_steps(
    arr: np.ndarray,
    layout: int,
    core: _Core,
    core_values: np.ndarray,
    original: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    rmse_target: float,
) -> bytes | None:
    """An RMSE target met by quantizing at the step that the coefficients predict
    (:class:`wavecore.gridcore.SteppedCore`: decomposed once, no synthesis but the ones that
    verify): each try is synthesized and measured in the grid's dtype before any entropy
    coding, stepped down if it misses the target (to where the prediction, scaled by what the
    miss measured against it, meets the target), or up, if it lands ``_RMSE_FAR_UNDER`` or
    further below it; only the kept try is coded; ``None`` if no try meets it.  (The rate
    control's PSNR search, with its closed-loop refinement, cost 8x more on the benchmark's
    1024² field for an RMSE within a per cent or two at the same bytes.)"""
    # (The codec imports this module: these are imported when used.)
    from .gridcore import SteppedCore, squared_and_largest, squared_and_largest_rounded

    dtype = arr.dtype
    has_mask = bool(missing.any())
    finite_count = max(int(np.count_nonzero(~missing)), 1) if has_mask else missing.size
    stepped = SteppedCore(core_values, core.wavelet, core.level, core.boundary)
    # Integer samples are rounded on decoding, which adds about 1/12 of a unit squared.
    rounding = 1.0 / 12.0 if dtype.kind in "iu" else 0.0

    def open_loop_aim(aim: float) -> float:
        """The open loop's RMSE whose rounded output is predicted at ``aim``."""
        if rounding == 0.0 or aim > 1e150:  # floats (nothing rounds): aim², which may
            return aim  # overflow or underflow, would give aim back
        if aim < 1e-150:  # (0.5 aim)² is the larger, and it would underflow
            return 0.5 * aim
        return math.sqrt(max(aim * aim - rounding, (0.5 * aim) ** 2))

    step = stepped.step_for(open_loop_aim(rmse_target * _RMSE_AIM), rmse_target * _STEP_PER_RMSE)

    def measured(decoded: np.ndarray) -> tuple[float, float]:
        if has_mask:
            return _measure(_to_dtype(decoded, dtype), original, missing, finite_count)
        if dtype.kind in "iu" and dtype.itemsize <= 4:  # rounded in the measuring pass
            squares, largest = squared_and_largest_rounded(decoded, original, dtype)
        else:
            squares, largest = squared_and_largest(_to_dtype(decoded, dtype), original)
        return math.sqrt(squares / finite_count), largest

    # The kept try: the largest RMSE that met the target, with its step, bands and output.
    best: tuple[float, float, float, Any, np.ndarray] | None = None
    missed: float | None = None  # the finest step that missed
    for _ in range(_RMSE_TRIES):
        # Each try is measured on its reconstruction before any entropy coding: a step that
        # misses (or overshoots) costs a quantization and a synthesis, not a coding.
        quantized, decoded = stepped.reconstructed(step)
        measured_rmse, largest = measured(decoded)
        if not measured_rmse > 0 or not math.isfinite(measured_rmse):
            if measured_rmse == 0 and best is None:  # exact already: nothing coarser is known
                best = (measured_rmse, largest, step, quantized, decoded)
            break
        if measured_rmse <= rmse_target:
            if best is None or measured_rmse > best[0]:
                best = (measured_rmse, largest, step, quantized, decoded)
            if measured_rmse >= _RMSE_FAR_UNDER * rmse_target:
                break
            # Far under the target (an integer grid whose errors are mostly rounded away, at
            # RMSEs below a unit): a coarser step, short of the finest one that missed.  The
            # rounded RMSE grows faster than the step there (nearly as its square on the
            # benchmark's elevation model): half the ratio in logarithms.
            step *= math.sqrt(rmse_target / measured_rmse)
            if missed is not None:
                step = min(step, math.sqrt(best[2] * missed))
        else:
            missed = step if missed is None else min(missed, step)
            # The open loop's prediction scaled by what this try measured against it (it was
            # 1-6 % low on the real elevation model, and the RMSE grows more slowly than the
            # step at low rates, where scaling the step by the ratio missed again: three or
            # four tries at 40 dB), aimed a little below the target so that the next try
            # lands on its safe side.
            predicted = math.sqrt(stepped.predicted_rmse(step) ** 2 + rounding)
            bias = measured_rmse / predicted if predicted > 0 else 1.0
            aim = _RMSE_RETRY_AIM * rmse_target / max(bias, 1.0)
            # (From the step that scaling by the ratio gives: a prediction or two from there.)
            start = step * _RMSE_RETRY_AIM * rmse_target / measured_rmse
            step = min(stepped.step_for(open_loop_aim(aim), start), step)
            if best is not None:
                step = max(step, math.sqrt(best[2] * missed))
        del quantized, decoded
    if best is None:
        return None
    measured_rmse, largest, _, quantized, decoded = best
    core_bytes, output = stepped.code(quantized, decoded)
    if output is not decoded:  # the header rounded a parameter: what decodes counts
        measured_rmse, largest = measured(output)
        if measured_rmse > rmse_target:
            return None
    return _assemble_core(arr, layout, core_bytes, mask_bytes, measured_rmse, largest)


def _measure(
    final: np.ndarray, original: np.ndarray, missing: np.ndarray, finite_count: int
) -> tuple[float, float]:
    """(RMSE, largest error) of the decoded samples over the finite cells."""
    with np.errstate(over="ignore", invalid="ignore"):
        diff = np.subtract(final, original, dtype=np.float64)  # no float64 copy of final
        diff[missing] = 0.0
        largest = float(np.max(np.abs(diff))) if diff.size else 0.0
        scale = largest if largest > 0 and math.isfinite(largest) else 1.0
        rmse = scale * math.sqrt(float(np.sum((diff / scale) ** 2)) / finite_count)
    return rmse, largest


def _encode_bounded(
    arr: np.ndarray,
    layout: int,
    core: _Core,
    core_values: np.ndarray,
    original: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    bound: float,
) -> bytes:
    """The core quantized at a step proportional to ``bound``, and its outliers: since the
    interpolation coder, only for a bound of 0 on floats (a fine core, the misses exact)."""
    dtype = arr.dtype
    integer = dtype.kind in "iu"
    allowed = math.floor(bound) if integer else bound
    unit = 2.0 * allowed + 1.0 if integer else 2.0 * bound
    peak = _peak(core_values)
    # Integer samples are rounded on decoding, which absorbs errors below half a unit.
    step = (allowed + 0.5) * _STEP_PER_INTEGER_BOUND if integer else bound * _STEP_PER_BOUND
    # A bound of 0 on floats: a fine core, and every sample it misses stored exactly (on
    # subnormal data, where the peak's share underflows, a core of zeros).
    step = max(step, peak * 2.0**-20, sys.float_info.min)
    core_bytes, decoded = core.at_step(core_values, step)
    finite_count = max(int(np.count_nonzero(~missing)), 1)
    outliers, final = _outliers(decoded, original, missing, dtype, allowed, unit)
    del decoded  # a full-size float64 array: not held while _measure makes its own
    measured_rmse, largest = _measure(final, original, missing, finite_count)
    if largest > allowed:  # cannot happen: every violation was stored exactly
        msg = f"internal error: the bound {bound!r} was missed ({largest!r})"
        raise AssertionError(msg)
    return _assemble(
        arr,
        layout,
        _FLAG_BOUND,
        float(allowed),
        unit,
        0,
        core_bytes,
        mask_bytes,
        outliers,
        measured_rmse,
        largest,
    )


#: The axes the interpolation coder predicts along, per layout: a volume along all three (its
#: slices are samples of one field; see :func:`_encode_predictive`), surface points along their
#: grid's two (the coordinates are separate fields).
_PREDICTED_AXES = {LAYOUT_FIELD: (0, 1), LAYOUT_VOLUME: (0, 1, 2), LAYOUT_POINTS: (0, 1)}


def _encode_predictive(
    arr: np.ndarray,
    layout: int,
    values: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    bound: float,
    axes: tuple[int, ...] | None = None,
    *,
    tiles: bool = True,
) -> bytes:
    """:func:`_predictive_bundle`'s bundle (``values`` is not used after: coded in place)."""
    return _predictive_bundle(
        arr, layout, values, missing, mask_bytes, bound, axes, disposable=True, tiles=tiles
    )[0]


def _predictive_bundle(
    arr: np.ndarray,
    layout: int,
    values: np.ndarray,
    missing: np.ndarray,
    mask_bytes: bytes,
    bound: float,
    axes: tuple[int, ...] | None = None,
    *,
    disposable: bool = False,
    tiles: bool = True,
) -> tuple[bytes, float]:
    """The grid under the interpolation coder (:mod:`wavecore.gridpredict`), whose errors are
    bounded by construction: no outliers to correct.  Returns the bundle and the RMSE it
    measured over the finite cells.

    On the benchmark's grids it takes 7-12 % fewer bytes than the wavelet core plus outliers
    at the same bound (docs/benchmarks.md, Grids), and it is several times faster.  A volume is
    predicted along all three axes: on the benchmark's volume that is 3-7 % smaller than
    predicting its slices apart (``axes=(1, 2)``), for the same reason a 3-D transform beats 2-D
    slices: neighbouring slices are as alike as neighbouring rows.  ``disposable``: the
    caller has no further use for ``values`` (its own copy), which the coder then overwrites
    instead of copying it; the RMSE and bpp searches code the same values again and keep them.
    """
    dtype = arr.dtype
    has_mask = _holds_true(missing)
    known = np.where(missing, 0.0, values) if has_mask else values
    integer = dtype.kind in "iu"
    if not integer and bound < 0.5 and not has_mask and _integers(values):
        # Whole numbers stored as floats (an elevation model in metres, say) under a bound
        # below half a unit: coded exactly, in whole-number arithmetic, they take fewer bytes
        # than any finer step (a third fewer at 1e-4 of the range on the benchmark's model).
        integer, bound = True, 0.0
    stream, squares, largest = encode_predictive(
        known,
        missing,
        dtype,
        bound,
        _PREDICTED_AXES[layout] if axes is None else axes,
        integer=integer,
        # Our copy, not needed after: coded in place.
        overwrite=(has_mask or disposable) and not np.may_share_memory(known, arr),
        tiles=tiles,
    )
    # No ~missing copy for the count.
    finite_count = max(missing.size - int(np.count_nonzero(missing)), 1) if has_mask else arr.size
    measured_rmse = math.sqrt(squares / finite_count)
    allowed = math.floor(bound) if integer else bound
    if largest > allowed:  # cannot happen: every sample that missed was stored exactly
        msg = f"internal error: the bound {bound!r} was missed ({largest!r})"
        raise AssertionError(msg)
    bundle = _assemble(
        arr,
        layout,
        _FLAG_BOUND | _FLAG_PREDICTIVE,
        float(allowed),
        0.0,
        0,
        stream,
        mask_bytes,
        b"",
        measured_rmse,
        largest,
    )
    return bundle, measured_rmse


def _outliers(
    decoded: np.ndarray,
    original: np.ndarray,
    missing: np.ndarray,
    dtype: np.dtype[Any],
    allowed: float,
    unit: float,
) -> tuple[bytes, np.ndarray]:
    """The outlier section for ``decoded`` (core layout), and the grid the decoder will return."""
    final = _to_dtype(decoded, dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        error = np.subtract(final, original, dtype=np.float64)  # in place: peak memory
        np.abs(error, out=error)
        flags = (error > allowed) | ~np.isfinite(error)
    flags &= ~missing
    if not flags.any():
        return b"", final
    flat_final = final.reshape(-1)
    positions = np.flatnonzero(flags)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        residual = original.reshape(-1)[positions] - decoded.reshape(-1)[positions]
        multiples = np.rint(residual / unit)
        usable = np.isfinite(multiples) & (np.abs(multiples) < 2.0**52) & (multiples != 0)
        multiples = np.where(usable, multiples, 0.0).astype(np.int64)
        corrected = _corrected(decoded.reshape(-1)[positions], multiples, unit, dtype)
        still = np.abs(corrected.astype(np.float64) - original.reshape(-1)[positions])
    exact = ~usable | ~(still <= allowed)
    exact_values = arr_values = original.reshape(-1)[positions[exact]]
    exact_values = _to_dtype(arr_values, dtype)  # the original values, exactly representable
    flat_final[positions] = corrected
    flat_final[positions[exact]] = exact_values
    multiples[exact] = 0
    section = encode_outliers(flags, multiples, exact, exact_values.astype(dtype.newbyteorder("<")))
    return section, flat_final.reshape(final.shape)


def _corrected(
    decoded: np.ndarray, multiples: np.ndarray, unit: float, dtype: np.dtype[Any]
) -> np.ndarray:
    """Decoded samples moved by whole correction units, in the grid's dtype (the decoder's
    arithmetic, shared)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _to_dtype(decoded + multiples.astype(np.float64) * unit, dtype)


def _holds_true(mask: np.ndarray) -> bool:
    """``mask.any()``, at once for a view of one value (``encode_layout``'s stand-in for the
    mask of a grid without NaN, whose ``any`` NumPy would otherwise walk value by value)."""
    if mask.size and not any(mask.strides):
        return bool(mask.flat[0])
    return bool(mask.any())


def _integers(values: np.ndarray) -> bool:
    """Whether float64 ``values`` are all whole numbers spanning at most 65535 (a uint16 after
    an offset, as the reversible path takes them)."""
    lo, hi = float(values.min()), float(values.max())
    if not (hi - lo <= 65535 and abs(lo) < 2**52 and abs(hi) < 2**52):
        return False
    # In blocks: a field of fractions is told from its first block, with no full-size copy.
    flat = values.reshape(-1)
    block = 1 << 16
    return all(
        np.array_equal(part, np.rint(part))
        for part in (flat[start : start + block] for start in range(0, flat.size, block))
    )


def _encode_lossless(arr: np.ndarray, layout: int, level: int | None) -> bytes:
    """An integer grid of range at most 65535, offset into uint16 and coded reversibly."""
    from .codec import encode_image

    offset = int(arr.min())
    shifted = (arr.astype(np.int64) - offset).astype(np.uint16)
    if layout == LAYOUT_VOLUME:
        # The slices stacked into one tall picture: the reversible lifting takes 2-D only.
        shifted = shifted.reshape(-1, arr.shape[-1])
    core_bytes = encode_image(shifted, lossless=True, level=level)
    return _assemble(
        arr, layout, _FLAG_LOSSLESS | _FLAG_BOUND, 0.0, 1.0, offset, core_bytes, b"", b"", 0.0, 0.0
    )


def _assemble_core(
    arr: np.ndarray, layout: int, core: bytes, mask: bytes, rmse: float, largest: float
) -> bytes:
    """A grid bundle of the wavelet core alone: no bound, no outliers (rmse, psnr, bpp)."""
    return _assemble(arr, layout, 0, math.nan, 0.0, 0, core, mask, b"", rmse, largest)


def _assemble(
    arr: np.ndarray,
    layout: int,
    flags: int,
    bound: float,
    unit: float,
    offset: int,
    core: bytes,
    mask: bytes,
    outliers: bytes,
    rmse: float,
    largest: float,
) -> bytes:
    flags |= (_FLAG_MASK if mask else 0) | (_FLAG_OUTLIERS if outliers else 0)
    version = PREDICTIVE_VERSION if flags & _FLAG_PREDICTIVE else VERSION
    if flags & _FLAG_PREDICTIVE and is_tiled_stream(core):
        version = TILED_VERSION
    head = _HEAD.pack(MAGIC, version, layout, _DTYPES.index(arr.dtype.name), flags, arr.ndim)
    shape = struct.pack(f"<{arr.ndim}I", *arr.shape)
    tail = _TAIL.pack(bound, unit, offset, rmse, largest, len(core), len(mask), len(outliers))
    body = head + shape + tail + core + mask + outliers
    return body + _CRC.pack(zlib.crc32(body))


# --------------------------------------------------------------------------------------------
# Decoding
# --------------------------------------------------------------------------------------------


def is_grid_bundle(bundle: Any) -> bool:
    """Whether ``bundle`` is bytes that begin as a grid bundle does."""
    return isinstance(bundle, bytes | bytearray | memoryview) and bytes(bundle[:4]) == MAGIC


class _Parsed:
    def __init__(self, bundle: Any) -> None:
        if not isinstance(bundle, bytes | bytearray | memoryview):
            msg = f"a bundle must be bytes, not {type(bundle).__name__}"
            raise BundleError(msg)
        data = bytes(bundle)
        if len(data) < _HEAD.size + _TAIL.size + _CRC.size or data[:4] != MAGIC:
            msg = "not a grid bundle (too short or no b'WVGD' magic)"
            raise BundleError(msg)
        (crc,) = _CRC.unpack_from(data, len(data) - _CRC.size)
        if zlib.crc32(data[: -_CRC.size]) != crc:
            msg = "grid bundle is corrupt or truncated (its CRC-32 does not match)"
            raise BundleError(msg)
        _, version, layout, dtype_code, flags, ndim = _HEAD.unpack_from(data)
        if version not in (VERSION, PREDICTIVE_VERSION, TILED_VERSION):
            msg = (
                f"grid bundle version {version} is not supported (this reader knows {VERSION} "
                f"to {TILED_VERSION})"
            )
            raise BundleError(msg)
        if (version != VERSION) != bool(flags & _FLAG_PREDICTIVE):
            msg = f"grid bundle version {version} does not match its flags {flags}"
            raise BundleError(msg)
        if layout not in (LAYOUT_FIELD, LAYOUT_VOLUME, LAYOUT_POINTS) or dtype_code >= len(_DTYPES):
            msg = f"grid bundle has an unknown layout {layout} or dtype code {dtype_code}"
            raise BundleError(msg)
        if ndim != (2 if layout == LAYOUT_FIELD else 3):
            msg = f"grid bundle layout {layout} cannot have {ndim} dimensions"
            raise BundleError(msg)
        position = _HEAD.size
        if len(data) < position + 4 * ndim + _TAIL.size + _CRC.size:
            msg = "grid bundle is truncated"
            raise BundleError(msg)
        self.shape = struct.unpack_from(f"<{ndim}I", data, position)
        if not 0 < math.prod(self.shape) <= MAX_ELEMENTS:
            msg = (
                f"grid bundle declares shape {list(self.shape)}, outside 1 to {MAX_ELEMENTS} values"
            )
            raise BundleError(msg)
        position += 4 * ndim
        fields = _TAIL.unpack_from(data, position)
        position += _TAIL.size
        self.bound, self.unit, self.offset, self.rmse, self.largest = fields[:5]
        lengths = fields[5:]
        if position + sum(lengths) + _CRC.size != len(data):
            msg = "grid bundle's section lengths do not add up to its size"
            raise BundleError(msg)
        self.core = data[position : position + lengths[0]]
        self.mask = data[position + lengths[0] : position + lengths[0] + lengths[1]]
        self.outliers = data[position + lengths[0] + lengths[1] : position + sum(lengths)]
        self.layout, self.flags, self.version = layout, flags, version
        if self.predictive and (version == TILED_VERSION) != is_tiled_stream(self.core):
            msg = f"grid bundle version {version} does not match its interpolation stream"
            raise BundleError(msg)
        self.dtype = np.dtype(_DTYPES[dtype_code])
        if self.dtype.kind != "f" and self.mask:
            msg = "grid bundle has a NaN mask for an integer grid"
            raise BundleError(msg)
        if not (math.isfinite(self.unit) and self.unit >= 0):
            msg = f"grid bundle has a bad correction unit {self.unit!r}"
            raise BundleError(msg)

    @property
    def lossless(self) -> bool:
        return bool(self.flags & _FLAG_LOSSLESS)

    @property
    def predictive(self) -> bool:
        return bool(self.flags & _FLAG_PREDICTIVE)


def decode_grid(
    bundle: Any, *, level: int = 0, window: Any = None, keep: float | None = None
) -> np.ndarray:
    """Decode a grid bundle (what :func:`wavecore.decode` does for one).

    Parameters
    ----------
    bundle : bytes
        What :func:`encode_grid` returned.
    level : int
        ``0`` for the grid itself (the bound holds); ``k`` for the coarse grid after ``k``
        levels (about ``ceil(n / 2**k)`` per side of the 2-D transform; a volume keeps its
        slices), decoded from the core's first chunks; a coarse cell is NaN where all the cells
        it covers are.
    window : tuple of slice, optional
        A window of the result, ``(slice(r0, r1), slice(c0, c1))`` (a volume takes
        ``(depth, rows, cols)``); the same as slicing the result, but only the core's
        code-blocks that reach the window are decoded, and only the window is synthesized;
        from the interpolation coder only the samples the window's predictions reach are
        reconstructed, from the tiles they lie in (version 3 bundles; older ones are entropy
        decoded whole).  A lossless volume, a coarse level of an interpolation-coded grid,
        and a window with a negative step or nothing in it are decoded whole, then sliced.
    keep : float, optional
        Keep only this fraction of the core's details (as :func:`wavecore.decode` does for any
        bundle): a smoother grid, without the outlier corrections, so the bound no longer holds.

    Returns
    -------
    numpy.ndarray
        The grid's shape (or the coarse shape) and dtype.
    """
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        msg = f"level must be an integer >= 0, not {level!r}"
        raise InvalidParameter(msg)
    parsed = _Parsed(bundle)
    if parsed.predictive and level:
        # its coarse levels are lattices of stride 2**level: one sample a side at the deepest
        sides = parsed.shape[-2:] if parsed.layout == LAYOUT_VOLUME else parsed.shape[:2]
        deepest = max(1, (max(int(n) for n in sides) - 1).bit_length())
        if level > deepest:
            msg = (
                f"level {level} is deeper than {deepest}, where this grid's lattice is one "
                "sample a side"
            )
            raise InvalidParameter(msg[:300])
    if window is not None:
        _window_items(window, len(parsed.shape))  # checked before anything is decoded
    split = _split_window(window, parsed) if window is not None else None
    box = _predictive_box(window, parsed, level, keep) if window is not None else None
    try:
        if box is not None:
            return _decode_predictive_window(parsed, window, box)
        if split is not None:
            return _decode_window(parsed, int(level), keep, *split)
        out = _decode(parsed, int(level), keep)
    except (BundleError, InvalidParameter):
        raise
    except Exception as exc:  # a crafted bundle whose sections do not fit together
        msg = f"corrupt grid bundle: {type(exc).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc
    if window is not None:
        out = _window(out, window)
    return out


def _predictive_box(
    window: Any, parsed: _Parsed, level: int, keep: float | None
) -> tuple[tuple[int, int], ...] | None:
    """The samples ``[lo, hi)`` per axis that a window of an interpolation-coded grid spans,
    for :func:`_decode_predictive_window`; None to decode whole and slice (a coarse level,
    ``keep``, a negative step or a window of nothing)."""
    if not parsed.predictive or level or (keep is not None and keep < 1.0):
        return None
    items = _full(_window_items(window, len(parsed.shape)), len(parsed.shape))
    box = []
    for item, n in zip(items, parsed.shape, strict=True):
        if not all(v is None or isinstance(v, int | np.integer) for v in (item.start, item.stop)):
            return None
        if item.step is not None and (
            not isinstance(item.step, int | np.integer) or item.step <= 0
        ):
            return None
        chosen = range(*item.indices(n))
        if len(chosen) == 0:
            return None
        box.append((chosen[0], chosen[-1] + 1))
    return tuple(box)


def _decode_predictive_window(
    parsed: _Parsed, window: Any, box: tuple[tuple[int, int], ...]
) -> np.ndarray:
    """A window of an interpolation-coded grid: only the samples its predictions reach, and
    in a tiled stream (version 3) only the tiles they lie in, are decoded."""
    shape = tuple(parsed.shape)
    out = decode_predictive_window(parsed.core, shape, parsed.dtype, box)
    items = _full(_window_items(window, len(shape)), len(shape))
    steps = tuple(slice(None, None, item.step) for item in items)
    out = np.ascontiguousarray(out[steps])
    if parsed.mask:
        out[decode_mask(parsed.mask, shape)[tuple(items)]] = np.nan
    return out


def _window_items(window: Any, ndim: int) -> list[slice]:
    if not isinstance(window, tuple | list) or len(window) > ndim:
        msg = f"window must be a tuple of at most {ndim} slices, not {window!r}"
        raise InvalidParameter(msg)
    for item in window:
        if not isinstance(item, slice):
            msg = f"window must hold slices (e.g. slice(0, 100)), not {item!r}"
            raise InvalidParameter(msg)
        parts = (item.start, item.stop, item.step)
        if not all(v is None or isinstance(v, int | np.integer) for v in parts):
            msg = f"window slices take integers or None, not {item!r}"
            raise InvalidParameter(msg[:200])
        if item.step == 0:
            msg = f"window slice {item!r} has a step of 0"
            raise InvalidParameter(msg[:200])
    return list(window)


def _split_window(window: Any, parsed: _Parsed) -> tuple[tuple[slice, ...], slice] | None:
    """``(spatial window, depth slice)`` for a region decode of the core, or None to decode
    whole (the interpolation coder has no code-blocks; a lossless volume stacks its slices in
    one picture; a negative step or a window
    that selects nothing keeps NumPy's slicing of the whole result)."""
    items = _window_items(window, len(parsed.shape))
    if parsed.predictive:  # the interpolation coder predicts every sample from coarser ones
        return None
    if parsed.lossless and parsed.layout == LAYOUT_VOLUME:
        return None
    for item in items:
        if not all(v is None or isinstance(v, int | np.integer) for v in (item.start, item.stop)):
            return None
        if item.step is not None and (
            not isinstance(item.step, int | np.integer) or item.step <= 0
        ):
            return None
    depth = slice(None)
    if parsed.layout == LAYOUT_VOLUME and items:
        depth, items = items[0], items[1:]
        count = parsed.shape[0]
        if len(range(*depth.indices(count))) == 0:
            return None
    return tuple(items), depth


def _decode_window(
    parsed: _Parsed, level: int, keep: float | None, spatial: tuple[slice, ...], depth: slice
) -> np.ndarray:
    """The grid's window, decoding only the core's blocks that reach it (see decode_grid)."""
    dtype, shape, layout = parsed.dtype, tuple(parsed.shape), parsed.layout
    if not spatial:  # only a depth range: the whole spatial extent
        spatial = (slice(None),)
    expected = shape if parsed.lossless else _core_shape(shape, layout)
    core_shape = tuple(_inspect_core(parsed.core)["shape"])
    if core_shape != tuple(expected):
        msg = f"grid core holds {list(core_shape)}, not the grid's {list(expected)}"
        raise BundleError(msg)
    try:
        decoded = _decode_core(parsed.core, level, keep, spatial)
    except InvalidParameter as exc:
        if "selects no samples" in str(exc):  # NumPy's slicing of the whole: an empty window
            out = _decode(parsed, level, keep)
            return _window(out, (depth, *spatial) if layout == LAYOUT_VOLUME else spatial)
        raise
    if parsed.lossless:
        return _to_dtype(decoded.astype(np.int64).astype(np.float64) + parsed.offset, dtype)
    rows, cols = _spatial_shape(shape, layout)
    bounds = [item.indices(n) for item, n in zip(spatial, (rows, cols), strict=False)]
    bounds += [(0, cols, 1)] * (2 - len(bounds))
    smoothed = keep is not None and keep < 1.0
    final = _to_dtype(decoded, dtype)
    if level == 0 and not smoothed and parsed.outliers:
        flags, multiples, exact, exact_values = decode_outliers(
            parsed.outliers, math.prod(core_shape), dtype
        )
        if exact_values.size != int(np.count_nonzero(exact)):
            msg = "grid outlier section has the wrong number of exact values"
            raise BundleError(msg)
        positions = np.flatnonzero(flags)
        depth_count = core_shape[2] if len(core_shape) == 3 else 1
        r, rest = np.divmod(positions, cols * depth_count)
        c, d = np.divmod(rest, depth_count)
        inside = np.ones(positions.size, dtype=bool)
        local = []
        for index, (start, stop, step) in zip((r, c), bounds, strict=True):
            inside &= (index >= start) & (index < stop) & ((index - start) % step == 0)
            local.append((index - start) // step)
        flat = final.reshape(-1)
        width = final.shape[1]
        target = (local[0] * width + local[1]) * depth_count + d
        chosen = np.flatnonzero(inside)
        flat[target[chosen]] = _corrected(
            decoded.reshape(-1)[target[chosen]], multiples[chosen], parsed.unit, dtype
        )
        exact_rank = np.cumsum(exact) - 1
        exact_chosen = chosen[exact[chosen]]
        flat[target[exact_chosen]] = exact_values[exact_rank[exact_chosen]]
    out = _from_core(final, layout)
    window = (depth, *spatial) if layout == LAYOUT_VOLUME else spatial
    if layout == LAYOUT_VOLUME:
        out = out[depth]
    if parsed.mask:
        mask = decode_mask(parsed.mask, shape)
        if level:
            coarse_shape = _grid_shape(_decode_core_shape(parsed.core, level), layout)
            mask = _coarse_mask(mask, level, layout, coarse_shape)
        out[mask[tuple(_full(window, len(shape)))]] = np.nan
    return np.ascontiguousarray(out)


def _full(window: Sequence[slice], ndim: int) -> list[slice]:
    return list(window) + [slice(None)] * (ndim - len(window))


def _decode_core_shape(core: bytes, level: int) -> tuple[int, ...]:
    """The shape the core decodes to at ``level``, without decoding it."""
    return tuple(_inspect_core(core)["level_shapes"][level])


def _window(out: np.ndarray, window: Any) -> np.ndarray:
    return np.ascontiguousarray(out[tuple(_window_items(window, out.ndim))])


def _decode(parsed: _Parsed, level: int, keep: float | None) -> np.ndarray:
    dtype, shape, layout = parsed.dtype, tuple(parsed.shape), parsed.layout
    if parsed.predictive:
        return _decode_predictive(parsed, level, keep)
    if parsed.lossless:
        if level and layout == LAYOUT_VOLUME:
            msg = "a lossless volume decodes at level 0 only (its slices share one picture)"
            raise InvalidParameter(msg)
        stacked = (shape[0] * shape[1], shape[2]) if layout == LAYOUT_VOLUME else shape
        if tuple(_inspect_core(parsed.core)["shape"]) != stacked:
            msg = f"grid core does not hold the grid's {list(shape)} samples"
            raise BundleError(msg)
        core = _decode_core(parsed.core, level, keep).astype(np.int64) + parsed.offset
        if layout == LAYOUT_VOLUME:
            core = core.reshape(shape)
        return _to_dtype(core.astype(np.float64), dtype)
    smoothed = keep is not None and keep < 1.0
    expected = _core_shape(shape, layout)
    core_shape = tuple(_inspect_core(parsed.core)["shape"])
    if core_shape != expected:  # checked before anything of the grid's size is allocated
        msg = f"grid core holds {list(core_shape)}, not the grid's {list(expected)}"
        raise BundleError(msg)
    decoded = _decode_core(parsed.core, level, keep)
    if level == 0 and not smoothed:
        final = _to_dtype(decoded, dtype)
        if parsed.outliers:
            flags, multiples, exact, exact_values = decode_outliers(
                parsed.outliers, decoded.size, dtype
            )
            flat = final.reshape(-1)
            positions = np.flatnonzero(flags)
            flat[positions] = _corrected(
                decoded.reshape(-1)[positions], multiples, parsed.unit, dtype
            )
            if exact_values.size != int(np.count_nonzero(exact)):
                msg = "grid outlier section has the wrong number of exact values"
                raise BundleError(msg)
            flat[positions[exact]] = exact_values
        out = _from_core(final, layout)
        if parsed.mask:
            out[decode_mask(parsed.mask, shape)] = np.nan
        return out
    out = _from_core(_to_dtype(decoded, dtype), layout)
    if parsed.mask and level == 0:
        out[decode_mask(parsed.mask, shape)] = np.nan
    elif parsed.mask:
        out[_coarse_mask(decode_mask(parsed.mask, shape), level, layout, out.shape)] = np.nan
    return out


def _decode_predictive(parsed: _Parsed, level: int, keep: float | None) -> np.ndarray:
    """An interpolation-coded grid.  A coarse level is its lattice of stride ``2**level`` on
    the 2-D axes (a volume keeps its slices, as the wavelet core's levels do): samples of the
    grid itself, within the bound; a coarse cell is NaN where every cell of its block is.
    ``keep`` keeps that fraction of the largest interpolation residuals."""
    shape = tuple(parsed.shape)
    out = decode_predictive(parsed.core, shape, parsed.dtype, keep)
    if level:
        stride = 1 << level  # at most the lattice's depth (decode_grid checks)
        spatial: tuple[slice, ...] = (slice(None, None, stride), slice(None, None, stride))
        if parsed.layout == LAYOUT_VOLUME:
            spatial = (slice(None), *spatial)
        out = np.ascontiguousarray(out[spatial])
    if parsed.mask:
        mask = decode_mask(parsed.mask, shape)
        if level:
            mask = _coarse_mask(mask, level, parsed.layout, out.shape)
        out[mask] = np.nan
    return out


def _coarse_mask(mask: np.ndarray, level: int, layout: int, shape: tuple[int, ...]) -> np.ndarray:
    """A coarse cell is missing where every cell of its ``2**level`` block is."""
    block = 2**level
    spatial = mask  # a volume is (D, H, W): its last two axes are the spatial ones
    axes = (-2, -1) if layout == LAYOUT_VOLUME else (0, 1)
    h, w = (spatial.shape[a] for a in axes)
    ph, pw = -(-h // block) * block, -(-w // block) * block
    if layout == LAYOUT_VOLUME:
        padded = np.pad(spatial, ((0, 0), (0, ph - h), (0, pw - w)), constant_values=True)
        coarse = padded.reshape(shape[0], ph // block, block, pw // block, block).all(axis=(2, 4))
        return _fit_shape(coarse, shape)
    pad = [(0, ph - h), (0, pw - w)] + [(0, 0)] * (spatial.ndim - 2)
    padded = np.pad(spatial, pad, constant_values=True)
    coarse = padded.reshape(ph // block, block, pw // block, block, *spatial.shape[2:])
    return _fit_shape(coarse.all(axis=(1, 3)), shape)


def _fit_shape(mask: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``mask`` cropped (or padded with False) to ``shape``."""
    mask = np.asarray(mask)
    out = np.zeros(shape, dtype=bool)
    region = tuple(slice(0, min(a, b)) for a, b in zip(mask.shape, shape, strict=True))
    out[region] = mask[region]
    return out


def inspect_grid(bundle: Any) -> dict[str, Any]:
    """Describe a grid bundle without decoding it (what :func:`wavecore.inspect` gives for one).

    Returns
    -------
    dict
        The keys :func:`wavecore.inspect` gives for any bundle, taken from the core bundle
        (``wavelet``, ``levels``, ``chunks``, ...) except ``kind`` ("grid"), ``shape``,
        ``dtype``, ``max_error`` (the bound that holds; ``None`` when none was asked for),
        ``total_bytes`` and ``header_bytes`` (everything but the core's chunks); and
        ``layout`` ("field", "volume" or "points"), ``rmse`` and ``largest_error`` (measured
        by the encoder over the finite cells), and the bytes of each section
        (``core_bytes``, ``mask_bytes``, ``outlier_bytes``).
    """
    from .codec import inspect

    parsed = _Parsed(bundle)
    core: dict[str, Any]
    if parsed.predictive:
        # The keys a wavelet core gives, for tools that print them (the CLI's inspect).
        core = {
            "version": f"grid {parsed.version}",
            "wavelet": "interpolation",
            "boundary": ["open", "open"],
            "colour": "none",
            "quantizer": "uniform, in the loop",
            "levels": 0,
            "psnr": math.nan,  # no peak is stored; rmse and largest_error are
            "chunks": [
                {
                    "level": 0,
                    "bands": ["residuals"],
                    "shapes": [list(parsed.shape)],
                    "bytes": len(parsed.core),
                    "present": True,
                }
            ],
        }
    else:
        core = inspect(parsed.core)
    names = {LAYOUT_FIELD: "field", LAYOUT_VOLUME: "volume", LAYOUT_POINTS: "points"}
    total = len(bytes(bundle))
    payload = sum(c["bytes"] or 0 for c in core["chunks"])
    return {
        **core,
        "kind": "grid",
        "layout": names[parsed.layout],
        "shape": list(parsed.shape),
        "dtype": parsed.dtype.name,
        "lossless": parsed.lossless or (parsed.predictive and parsed.bound == 0),
        "max_error": parsed.bound if parsed.flags & _FLAG_BOUND else None,
        "rmse": parsed.rmse,
        "largest_error": parsed.largest,
        "total_bytes": total,
        "header_bytes": total - payload,
        "core_bytes": len(parsed.core),
        "mask_bytes": len(parsed.mask),
        "outlier_bytes": len(parsed.outliers),
    }
