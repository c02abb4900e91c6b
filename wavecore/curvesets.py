"""Curve sets: many curves in one compact bundle, each within a guaranteed distance.

A glyph is a handful of closed contours, a map layer thousands of lines, a GPS log one long
track: :func:`encode_curves` codes them together, with a few bytes of record per curve and one
entropy-coded stream for all their coefficients, so that statistics are shared and no curve pays
for a header of its own.

The bound
---------
``tolerance`` is a promise about *every* point, checked on the decoded result before the
encoder returns (on the values in the output dtype):

* each original point lies within ``tolerance`` of the decoded polyline, and
* each decoded point lies within ``tolerance`` of the original polyline

(closed curves including their closing segment).  Distances to a polyline are measured against
the segments within a window of the point's position along the curve: a minimum over fewer
segments can only be larger, so the measured value bounds the true distance from above, at a
cost linear in the number of points.  A curve whose quantized coefficients miss the bound gets
a finer step; one that misses it even at the finest step is padded rather than re-sampled (then
decoded point ``i`` belongs to original point ``i``, and at a fine enough step the decoded points
are as near their originals as needed), and as the last resort it is stored as it is (``mode`` 2
below), so the bound holds for any finite input.

How a curve is coded
--------------------
The encoder tries re-sampling the curve uniformly by arc length to fewer points (down by
factors of ``√2`` while the re-sampled polyline stays within half the tolerance), transforms it
with :func:`wavecore.wavedec`, quantizes with :func:`wavecore.quantize.quantize_bands` at the
largest step ``tolerance · 2**(e/4)`` that keeps the bound, and entropy-codes the integers of all
curves together with :func:`wavecore.entropy.encode_levels` (group 0: the coarse points'
differences; group ``g``: detail level ``g`` counted from the finest, of every curve).

That is the *wavelet form*.  The *vertex form* (format version 2, ``method="vertex"``; by
default the encoder writes both and keeps the smaller) codes a simplified polyline on a
lattice instead: see :mod:`wavecore.curvecoder` and ``docs/curves.md`` for its bytes.

Format (version 1)
------------------
All integers are unsigned LEB128 varints unless a size is given; ``zz`` is the zigzag map.

==================  ==========================================================================
field               contents
==================  ==========================================================================
magic               4 bytes ``b"\\x89WVC"``
version             1 byte, ``1``
flags               varint: bit 0 metadata present, bit 1 dimension per curve, bits 2–3
                    ``closed`` (0 all open, 1 all closed, 2 per curve), bit 4 ``level`` given
wavelet, dtype      1 byte each, indexes into ``WAVELETS`` and ``DTYPES``
tolerance           8 bytes, float64 little-endian (the steps are relative to it)
rounding            1 byte ``r``: the dead zone's rounding is ``r / 256``
d                   varint, unless per curve
level               varint, when given (a cap on every curve's levels)
count               varint, the number of curves
coder               varints: the context coder's version and block size
records             per curve: ``d`` (when per curve), ``n`` (varint: the number of points
                    decoded; for a re-sampled curve the fitted length), ``code`` (varint:
                    ``((zz(e) << 2 | mode) << 1 | repeated) << 1 | closed``, the ``closed``
                    bit only when per curve).  ``mode`` 0: re-sampled to ``n`` points; 1: padded
                    to fit and cropped back to ``n``; 2: stored as it is.  ``repeated``: the
                    input of a closed curve repeated its first point at the end (given back so)
chunks              varint count, varint lengths, then the entropy-coded chunks
raw                 the stored curves' values, in the bundle's dtype, little-endian
metadata            when flagged: varint length, then deflated UTF-8 JSON
crc                 4 bytes: CRC-32 of everything before it
==================  ==========================================================================
"""

from __future__ import annotations

import binascii
import json
import math
import struct
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from functools import lru_cache
from typing import Any, TypeVar

import numpy as np

from . import curvecoder
from .blockcoder import BLOCK_SIZE
from .entropy import decode_levels, encode_levels
from .errors import BundleError, InvalidParameter
from .filters import get_wavelet
from .inflate import inflate
from .multilevel import max_level, valid_length, wavedec, waverec
from .quantize import DEFAULT_ROUNDING, band_weights, dequantize_bands, quantize_bands
from .resample import pad_to_fit, resample_curve
from .varints import encode_varint, unzigzag, zigzag

__all__ = ["CurveSet", "decode_curves", "encode_curves", "inspect_curves", "is_curve_set"]

MAGIC = b"\x89WVC"
VERSION = 1
#: The vertex-coded form (format version 2): see :mod:`wavecore.curvecoder` and docs/curves.md.
VERTEX_VERSION = 2
#: The vertex form with bulged segments (parabolas between vertices): the same layout as
#: version 2, each segment's bulge in the stream after the curve's vertices.
BULGED_VERSION = 3
#: Versions 2 and 3 for plane curves with a shorter header, and a curve's first vertex
#: optionally coded from the previous curve's last (docs/curves.md, version 4).
PLANE_VERSION = 4
#: Version 4's layout, the coder's models started at learnt priors rather than one half
#: (docs/curves.md, version 5).
PRIOR_VERSION = 5
#: Version 5 with copies: a curve may be coded as an earlier curve's vertices and bulges,
#: translated by a lattice vector and a fraction of a step (docs/curves.md, version 6).
COPY_VERSION = 6
#: A version-6 bundle of at most this many bytes ends in a CRC-16/XMODEM (2 bytes) instead of
#: a CRC-32, as bundle format 4.0's groups of chunks up to 1 KiB do: it still finds every
#: damage of up to 3 bits and every burst of up to 16 in so short a message.
SHORT_CHECK = 1024
#: Version 6 starts with a 3-byte preamble instead of the magic and a version byte: the
#: family's two magic bytes (as bundle formats 4.0–6.0 start) and one byte, ``0x80 | version``.
#: A bundle's third byte is its major version (3..6) or ``V`` (``\x89WVB``), never 0x80 or
#: more, so the two kinds never meet.
SHORT_MAGIC = b"\x89W"
SHORT_FLAG = 0x80


def _preamble(data: bytes) -> tuple[int, int]:
    """A curve set's version and the length of its preamble (5 bytes, or 3 for version 6).

    ``data`` starts with :data:`MAGIC` or :data:`SHORT_MAGIC` and a byte of 0x80 or more."""
    if data.startswith(MAGIC):
        return data[len(MAGIC)], len(MAGIC) + 1
    return data[len(SHORT_MAGIC)] & 0x7F, len(SHORT_MAGIC) + 1


def _preamble_bytes(version: int) -> bytearray:
    """The preamble a set of ``version`` starts with."""
    if version == COPY_VERSION:
        return bytearray(SHORT_MAGIC + bytes([SHORT_FLAG | version]))
    return bytearray(MAGIC + bytes([version]))


#: Version 6 packs its head, a one-byte tolerance and a count below this many into 3 bytes:
#: the head's fields as a mixed-radix number below :data:`_HEADS` (its 13 bits hold only
#: 2 880 values), then the tolerance byte (7 bits), then the count plus one.
_HEADS = 2 * 3 * 5 * 2 * 2 * 2 * 12
_PACKED_COUNTS = (1 << 24) // (_HEADS * 128) - 1


def _pack_head(head: int, tolerance: bytes, count: int) -> bytes:
    """Version 6's head, tolerance and count (docs/curves.md): 3 bytes when the tolerance is
    one byte and the count is below :data:`_PACKED_COUNTS`, else 3 bytes (tolerance and count
    0: "they follow") and the tolerance and the count varint."""
    fields = (head & 1, head >> 1 & 3, head >> 3 & 7, head >> 6 & 1, head >> 7 & 1, head >> 8 & 1)
    value = head >> 9 & 15
    for part, radix in zip(reversed(fields), (2, 2, 2, 5, 3, 2), strict=True):
        value = value * radix + part
    if len(tolerance) == 1 and count < _PACKED_COUNTS:
        value += _HEADS * (tolerance[0] + 128 * (count + 1))
        return value.to_bytes(3, "little")
    return value.to_bytes(3, "little") + tolerance + encode_varint(count)


def _unpack_head(packed: bytes) -> tuple[int, int, int]:
    """The head (version 5's bit layout), the tolerance byte and the count plus one (0: the
    tolerance and the count follow) of :func:`_pack_head`'s first 3 bytes."""
    value = int.from_bytes(packed, "little")
    value, tolerance_and_count = value % _HEADS, value // _HEADS
    head = 0
    for shift, radix in zip((0, 1, 3, 6, 7, 8), (2, 3, 5, 2, 2, 2), strict=True):
        head |= value % radix << shift
        value //= radix
    return head | value << 9, tolerance_and_count % 128, tolerance_and_count // 128


def check_size(data: bytes) -> int:
    """The size of the check that ends a whole curve-set bundle.

    Parameters
    ----------
    data : bytes
        A whole curve-set bundle, its preamble included.

    Returns
    -------
    int
        2 for a version-6 set of at most ``SHORT_CHECK`` bytes (a CRC-16), else 4 (a CRC-32).
    """
    short = len(data) <= SHORT_CHECK and _preamble(data)[0] == COPY_VERSION
    return 2 if short else 4


def _with_check(out: bytearray, version: int) -> bytes:
    """``out`` and its check: a CRC-16 for a short version-6 set, else a CRC-32."""
    if version == COPY_VERSION and len(out) + 2 <= SHORT_CHECK:
        return bytes(out + struct.pack("<H", binascii.crc_hqx(bytes(out), 0)))
    return bytes(out + struct.pack("<I", zlib.crc32(out)))


METHODS = ("auto", "wavelet", "vertex")
#: Lattice steps of the vertex form, as multiples of the tolerance (a byte indexes this table).
#: A vertex moves by at most ``step * sqrt(d) / 2`` when rounded, which must stay within the
#: tolerance: the encoder tries the coarsest steps that allow it.
VERTEX_STEPS = (1.4, 1.0, 0.7, 0.5, 0.35, 0.25, 1.9, 1.7, 1.55, 1.8, 1.6, 1.47)
#: Steps whose rounding may move a point by more than the tolerance (``step · √d / 2`` up to
#: this many tolerances) are used with snapped vertices: the lattice point nearest the curve
#: (across it) rather than nearest the point.
_SNAP_LIMIT = 1.4
#: Greedy reach looks at most this many points ahead (a vertex is kept at least this often),
#: so that its cost stays linear whatever the shape.
_VERTEX_WINDOW = 512
#: A bulge's unit, in lattice steps (on the glyphs 1.0 wrote 1.5 % fewer bytes than 0.5, and
#: 2 % fewer than 0.35)
_BULGE_UNIT = 1.0
#: Lattice coordinates beyond this many steps are not vertex-coded (the wavelet form takes them).
_VERTEX_LIMIT = 1 << 46
#: The decoder refuses a vertex-coded set that declares more curves or values than this many
#: per byte of its stream (the encoder uses the wavelet form for such sets).
VERTEX_PER_BYTE = 4096
_VERTEX_ORDERS = (0, 1, 2, 3, 4)
#: A closed curve may start at a vertex where it turns by more than this (its cosine): 45°.
_CORNER_COSINE = 0.7
#: How far (lattice steps per coordinate, for d = 1, 2, 3) a vertex may move towards its
#: prediction; curves of more dimensions keep their rounded vertices.
_REFINE_RADIUS = (64, 7, 3)
WAVELETS = ("bspline2", "haar", "cdf97")
DTYPES = (
    "float64",
    "float32",
    "float16",
    "int8",
    "int16",
    "int32",
    "int64",
    "uint8",
    "uint16",
    "uint32",
)
DEFAULT_WAVELET = "bspline2"
#: Default tolerance relative to the bounding-box diagonal of all curves (as ``encode_curve``).
DEFAULT_RELATIVE_TOLERANCE = 1e-3
#: Step exponents are quarter octaves around the tolerance: ``step = tolerance * 2**(e / 4)``.
_STEP_FRACTION = 4
_FINEST_EXPONENT = -80  # step = tolerance / 2**20: below this a curve is stored as it is
_COARSEST_EXPONENT = 24
_MAX_LEVEL = 24
#: Smallest number of points a curve is re-sampled to.
_MIN_POINTS = 8
#: The share of the tolerance that re-sampling to fewer points may use (the rest is the
#: quantizer's): measured best on the glyphs of benchmarks/curves.py.
_RESAMPLE_SHARE = 0.7
#: The most points a bundle may declare in all (the decoder's bound on hostile counts).
MAX_POINTS = 1 << 27
#: The most curves in one set: each decoded curve is a few hundred bytes of Python objects,
#: and a vertex-form stream may code thousands of them in a byte.
MAX_CURVES = 1 << 20
#: The most bytes a set's metadata inflates to (its JSON), written or read.
MAX_METADATA_BYTES = 32 << 20
_MODE_RESAMPLED, _MODE_PADDED, _MODE_RAW, _MODE_VERTEX = 0, 1, 2, 3
_INDEX_LIMIT = 1 << 29  # quantized integers beyond this would not fit the coder's int32
#: Below this tolerance (3.9e-121) every curve is stored as it is: the bound is measured
#: through squared distances, which underflow to 0 below about 1e-154.
SMALLEST_TOLERANCE = 2.0**-400


@dataclass(frozen=True)
class CurveSet:
    """What :func:`decode_curves` gives back.

    Attributes
    ----------
    curves : list of numpy.ndarray
        One ``(n_i, d_i)`` array per curve, in the bundle's dtype.
    closed : list of bool
        Whether each curve is closed.
    tolerance : float
        The bound the encoder guaranteed.
    wavelet : str
        The wavelet the curves were coded with.
    metadata : dict or None
        What the encoder was given as ``metadata`` (the file formats keep structure and
        properties here).
    """

    curves: list[np.ndarray]
    closed: list[bool]
    tolerance: float
    wavelet: str
    metadata: dict[str, Any] | None = None
    modes: list[int] = field(default_factory=list)


# --- varints -------------------------------------------------------------------------------


class _Reader:
    def __init__(self, data: bytes) -> None:
        self.data = data
        self.at = 0

    def take(self, size: int, what: str) -> bytes:
        if size < 0 or self.at + size > len(self.data):
            msg = f"curve set truncated: {what} needs {size} bytes at offset {self.at}"
            raise BundleError(msg)
        out = self.data[self.at : self.at + size]
        self.at += size
        return out

    def varint(self, what: str, limit: int = 1 << 40) -> int:
        value = 0
        for shift in range(0, 64, 7):
            byte = self.take(1, what)[0]
            value |= (byte & 0x7F) << shift
            if not byte & 0x80:
                if value > limit:
                    msg = f"curve set field {what} is {value}, more than the limit {limit}"
                    raise BundleError(msg)
                return value
        msg = f"curve set field {what} is not a valid varint"
        raise BundleError(msg)


# --- arguments ---------------------------------------------------------------------------


def _as_curves(curves: Any) -> list[np.ndarray]:
    if isinstance(curves, np.ndarray) or not isinstance(curves, Sequence | tuple):
        if isinstance(curves, np.ndarray) and curves.dtype == object:
            curves = list(curves)
        else:
            msg = (
                "curves must be a list of (n, d) arrays, not "
                f"{type(curves).__name__}; for one curve use [points] or encode_curve"
            )
            raise InvalidParameter(msg)
    out = []
    for index, curve in enumerate(curves):
        try:
            arr = np.asarray(curve)
        except (ValueError, TypeError) as exc:
            msg = f"curve {index} is not an array of numbers: {exc}"
            raise InvalidParameter(msg) from exc
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] < 1 or arr.shape[0] < 1:
            msg = f"curve {index} must have shape (n, d) with n >= 1 and d >= 1, not {arr.shape}"
            raise InvalidParameter(msg)
        if arr.dtype.kind not in "fiub" or arr.dtype.name not in (*DTYPES, "bool"):
            msg = f"curve {index} has dtype {arr.dtype}; accepted dtypes are {', '.join(DTYPES)}"
            raise InvalidParameter(msg)
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            msg = f"curve {index} has a NaN or infinite value; every point must be finite"
            raise InvalidParameter(msg)
        out.append(arr)
    return out


def _closed_list(closed: Any, count: int) -> list[bool]:
    if isinstance(closed, bool | np.bool_):
        return [bool(closed)] * count
    if isinstance(closed, Sequence) and not isinstance(closed, str):
        flags = list(closed)
        if len(flags) != count or not all(isinstance(f, bool | np.bool_) for f in flags):
            msg = (
                f"closed must be one bool or a list of {count} bools (one per curve), "
                f"not {closed!r}"[:300]
            )
            raise InvalidParameter(msg)
        return [bool(f) for f in flags]
    msg = f"closed must be a bool or a list of bools, not {closed!r}"[:300]
    raise InvalidParameter(msg)


def _wavelet_name(wavelet: Any) -> str:
    if wavelet is None:
        return DEFAULT_WAVELET
    try:
        name = get_wavelet(wavelet).name
    except InvalidParameter:
        name = None
    if name not in WAVELETS:
        msg = f"wavelet {wavelet!r} is not accepted for curve sets; accepted: {WAVELETS}"
        raise InvalidParameter(msg)
    return str(name)


# --- geometry: the measured bound ------------------------------------------------------------


def _arc_fractions(points: np.ndarray, closed: bool) -> np.ndarray:
    """Each vertex's position along the polyline in [0, 1] (closed: the seam counts)."""
    nodes = np.concatenate([points, points[:1]]) if closed else points
    steps = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(steps)])
    total = s[-1]
    if not total > 0:
        return np.linspace(0.0, 1.0, len(nodes))
    return s / total


def _segment_distances(
    queries: np.ndarray, nodes: np.ndarray, first: np.ndarray, count: int
) -> np.ndarray:
    """Distance from each query to the nearest of segments ``first + k`` (``0 <= k < count``).

    All ``len(queries) × count`` pairs at once, in slices of queries that keep the temporary
    arrays near a million pairs (``count`` is at most a few times the density ratio of the two
    polylines, so the pairs are linear in the points).
    """
    best = np.empty(len(queries))
    last = len(nodes) - 2
    offsets = np.arange(count)
    rows = max(1, (1 << 20) // max(count, 1))
    for start in range(0, len(queries), rows):
        stop = min(start + rows, len(queries))
        index = np.clip(first[start:stop, None] + offsets, 0, last)
        a = nodes[index]
        ab = nodes[index + 1] - a
        rel = queries[start:stop, None, :] - a
        length2 = np.einsum("ijk,ijk->ij", ab, ab)
        t = np.einsum("ijk,ijk->ij", rel, ab)
        t = np.divide(t, length2, out=np.zeros_like(t), where=length2 > 0)
        np.clip(t, 0.0, 1.0, out=t)
        gap = rel - t[..., None] * ab
        best[start:stop] = np.sqrt(np.einsum("ijk,ijk->ij", gap, gap).min(axis=1))
    return best


def _one_way(source: np.ndarray, target: np.ndarray, closed: bool) -> float:
    """An upper bound of the largest distance from ``source``'s vertices to ``target``'s polyline.

    Both polylines run the same way; each vertex is compared with the target's segments in a
    window around the same arc-length fraction, as wide as the two densities require.
    """
    nodes = np.concatenate([target, target[:1]]) if closed else target
    if len(nodes) < 2:
        return float(np.max(np.linalg.norm(source - nodes[0], axis=1)))
    where = _arc_fractions(source, closed)[: len(source)]
    target_fractions = _arc_fractions(target, closed)
    centre = np.searchsorted(target_fractions, where, side="right") - 1
    segments = len(nodes) - 1
    ratio = max(1, math.ceil(segments / max(len(source), 1)))
    half = 3 + 2 * ratio
    return float(np.max(_segment_distances(source, nodes, centre - half, 2 * half + 1)))


def _deviation(original: np.ndarray, decoded: np.ndarray, closed: bool) -> float:
    """Largest deviation both ways (an upper bound of the true one)."""
    return max(_one_way(original, decoded, closed), _one_way(decoded, original, closed))


# --- one curve ---------------------------------------------------------------------------


@dataclass
class _Coded:
    mode: int
    count: int
    exponent: int = 0
    qcoeffs: list[np.ndarray] | None = None
    raw: np.ndarray | None = None


def _level_for(m: int, boundary: str, wavelet: str, cap: int) -> int:
    return min(max_level(m, boundary, wavelet), cap)


def _padded_level(n: int, boundary: str, wavelet: str, cap: int) -> int:
    """The deepest level (up to ``cap``) whose padding adds at most an eighth of ``n``."""
    level = 0
    while level < cap:
        try:
            fitted = valid_length(n, level + 1, boundary, wavelet)
        except InvalidParameter:
            break
        if fitted - n > max(2, n // 8):
            break
        level += 1
    return level


def _band_lengths(m: int, level: int, boundary: str, wavelet: str) -> list[int]:
    rule = get_wavelet(wavelet).rule(boundary)
    details = []
    for _ in range(level):
        details.append(rule.detail_length(m))
        m = rule.coarse_length(m)
    return [m, *reversed(details)]


@lru_cache(maxsize=256)
def _weights(lengths: tuple[int, ...], wavelet: str, boundary: str) -> list[list[float]]:
    """The quantizer's band weights for these band lengths (they depend on nothing else)."""
    template = [np.zeros((length, 1)) for length in lengths]
    return band_weights(template, wavelet=wavelet, boundary=boundary, axes=(0,))


def _qparams(
    lengths: list[int], step: float, rounding: float, wavelet: str, boundary: str
) -> dict[str, Any]:
    weights = _weights(tuple(lengths), wavelet, boundary)
    return {"name": "deadzone", "step": step, "weights": weights, "rounding": rounding}


def _synthesize(
    qcoeffs: list[np.ndarray], step: float, rounding: float, wavelet: str, boundary: str
) -> np.ndarray:
    lengths = [len(q) for q in qcoeffs]
    params = _qparams(lengths, step, rounding, wavelet, boundary)
    coeffs = dequantize_bands(qcoeffs, params, wavelet=wavelet, boundary=boundary, axes=(0,))
    if len(coeffs) == 1:
        return np.asarray(coeffs[0])
    return waverec(coeffs, wavelet, boundary)


def _finish(points: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    if dtype.kind == "f":
        return points.astype(dtype)
    info = np.iinfo(dtype)
    return np.clip(np.rint(points), info.min, info.max).astype(dtype)


class _CurveCoder:
    def __init__(self, wavelet: str, tolerance: float, rounding: float, cap: int, dtype: Any):
        self.wavelet = wavelet
        self.tolerance = tolerance
        self.rounding = rounding
        self.cap = cap
        self.dtype = np.dtype(dtype)

    def step(self, exponent: int) -> float:
        return self.tolerance * 2.0 ** (exponent / _STEP_FRACTION)

    def _fitted(self, points: np.ndarray, closed: bool, mode: int, count: int):
        boundary = "closed" if closed else "open"
        if mode == _MODE_RESAMPLED:
            if count == len(points):
                fitted = points
            else:
                fitted = resample_curve(points, count, closed=closed)
            return fitted, _level_for(count, boundary, self.wavelet, self.cap)
        level = _padded_level(count, boundary, self.wavelet, self.cap)
        fitted, _ = pad_to_fit(points, level, axes=0, boundary=boundary, wavelet=self.wavelet)
        return fitted, level

    def _try(self, coeffs, exponent, closed, mode, count):
        boundary = "closed" if closed else "open"
        step = self.step(exponent)
        try:
            q, _ = quantize_bands(
                coeffs,
                step,
                wavelet=self.wavelet,
                boundary=boundary,
                axes=(0,),
                rounding=self.rounding,
            )
        except InvalidParameter:  # a subnormal step (a tolerance near 1e-308): the raw form
            return None, None
        q = [np.asarray(band, dtype=np.int32) for band in q]
        if max(int(np.max(np.abs(band))) for band in q) >= _INDEX_LIMIT:
            return None, None
        decoded = _synthesize(q, step, self.rounding, self.wavelet, boundary)
        if mode == _MODE_PADDED:
            decoded = decoded[:count]
        return q, _finish(decoded, self.dtype)

    def code(self, points: np.ndarray, closed: bool) -> tuple[_Coded, np.ndarray]:
        n = len(points)
        original = points.astype(np.float64)
        boundary = "closed" if closed else "open"
        span = float(np.max(np.abs(original))) if n else 0.0
        if not (
            span / self.tolerance < _INDEX_LIMIT / 4  # integers too large for the coder
            and self.tolerance >= SMALLEST_TOLERANCE
        ):
            raw = _finish(original, self.dtype)
            return _Coded(_MODE_RAW, n, raw=raw), raw
        for mode, count in self._plans(original, closed):
            fitted, level = self._fitted(original, closed, mode, count)
            coeffs = wavedec(fitted, self.wavelet, boundary, level) if level else [fitted]
            found = self._search(coeffs, original, closed, mode, count)
            if found is not None:
                return found
        raw = _finish(original, self.dtype)
        return _Coded(_MODE_RAW, n, raw=raw), raw

    def _plans(self, points: np.ndarray, closed: bool) -> list[tuple[int, int]]:
        """Re-sampled counts worth trying, fewest points first, then the padded curve."""
        n = len(points)
        plans: list[tuple[int, int]] = []
        if n < 4:
            return [(_MODE_PADDED, n)] if n >= 2 else []
        boundary = "closed" if closed else "open"
        target = float(n)
        counts: list[int] = []
        while target >= _MIN_POINTS:
            level = _padded_level(max(int(target), 2), boundary, self.wavelet, self.cap)
            count = valid_length(max(int(target), 2), level, boundary, self.wavelet)
            if count <= 2 * n and count not in counts:
                counts.append(count)
            target /= math.sqrt(2.0)
        # the fewest points whose re-sampled polyline stays within its share of the tolerance:
        # a bisection over the candidates (the cut grows as the count falls, nearly always
        # monotonically; the chosen count is itself measured, so a non-monotone case only
        # costs bytes)
        chosen = None
        candidates = sorted(counts)

        def fits(count: int) -> bool:
            if count == n:
                return True
            fitted = resample_curve(points, count, closed=closed)
            return _deviation(points, fitted, closed) <= limit

        limit = _RESAMPLE_SHARE * self.tolerance
        low, high = 0, len(candidates) - 1
        if candidates and fits(candidates[high]):
            while low < high:
                middle = (low + high) // 2
                if fits(candidates[middle]):
                    high = middle
                else:
                    low = middle + 1
            chosen = candidates[high]
        if chosen is not None:
            plans.append((_MODE_RESAMPLED, chosen))
        plans.append((_MODE_PADDED, n))
        return plans

    def _search(self, coeffs, original, closed, mode, count):
        """The largest step (quarter octaves) whose decoded curve keeps the bound."""

        def attempt(exponent: int):
            q, decoded = self._try(coeffs, exponent, closed, mode, count)
            if q is None:
                return None
            # windowed polyline distances for padded curves too: they let decoded points slide
            # along the curve, which the pointwise distance does not (2-4 % fewer bytes on the
            # benchmark's glyphs at fine tolerances)
            if _deviation(original, decoded.astype(np.float64), closed) <= self.tolerance:
                return _Coded(mode, count, exponent, q), decoded
            return None

        best = None
        good, bad = None, None
        exponent = 0
        # walk down by octaves to a passing step, or up while it passes
        result = attempt(exponent)
        if result is None:
            bad = exponent
            while exponent > _FINEST_EXPONENT:
                exponent = max(exponent - 2 * _STEP_FRACTION, _FINEST_EXPONENT)
                result = attempt(exponent)
                if result is not None:
                    good, best = exponent, result
                    break
                bad = exponent
            if good is None:
                return None
        else:
            good, best = exponent, result
            while exponent < _COARSEST_EXPONENT:
                exponent += _STEP_FRACTION
                result = attempt(exponent)
                if result is None:
                    bad = exponent
                    break
                good, best = exponent, result
            if bad is None:
                return best
        while bad - good > 1:
            middle = (bad + good) // 2
            result = attempt(middle)
            if result is None:
                bad = middle
            else:
                good, best = middle, result
        return best


# --- the set ----------------------------------------------------------------------------------


def _group_arrays(coded: list[_Coded]) -> list[np.ndarray]:
    """Group 0: coarse points' differences; group g: detail level g from the finest."""
    depth = max((len(c.qcoeffs) - 1 for c in coded if c.qcoeffs is not None), default=-1)
    if depth < 0:
        return []
    groups: list[list[np.ndarray]] = [[] for _ in range(depth + 1)]
    for c in coded:
        if c.qcoeffs is None:
            continue
        coarse = c.qcoeffs[0].astype(np.int64)
        groups[0].append(np.diff(coarse, axis=0, prepend=0).ravel())
        for g, band in enumerate(reversed(c.qcoeffs[1:]), start=1):
            groups[g].append(band.ravel())
    return [np.concatenate(parts).astype(np.int64) for parts in groups]


#: The deepest metadata a curve set takes (lists and dicts within each other): deeper would
#: need the decoder's JSON parser to recurse near Python's limit.
MAX_METADATA_DEPTH = 200


def _nesting(value: Any) -> int:
    """How deep lists and dicts sit within each other in ``value`` (0 for a scalar)."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            stack.extend((v, depth + 1) for v in item.values())
        elif isinstance(item, list | tuple):
            stack.extend((v, depth + 1) for v in item)
        else:
            continue
        deepest = max(deepest, depth + 1)
    return deepest


def encode_curves(
    curves: Any,
    *,
    closed: bool | Sequence[bool] = True,
    tolerance: float | None = None,
    wavelet: str | None = None,
    level: int | None = None,
    metadata: dict[str, Any] | None = None,
    method: str | None = None,
) -> bytes:
    """Encode many curves into one bundle, every point within ``tolerance`` both ways.

    Parameters
    ----------
    curves : sequence of array_like
        Each curve ``(n_i, d_i)`` (or ``(n_i,)`` for ``d = 1``), any ``n_i >= 1`` and
        ``d_i >= 1``; the dimension may differ between curves.  Finite values, in one of the
        dtypes ``float64``, ``float32``, ``float16``, ``int8`` … ``uint32``; the decoded
        curves come back in the common dtype (``numpy.result_type`` of the inputs; ``bool``
        is taken as ``uint8``, and comes back so, as 0 and 1).
    closed : bool or sequence of bool, keyword-only
        Closed (periodic) or open curves: one flag for all, or one per curve.  A closed curve
        may repeat its first point at the end; it comes back the same way.
    tolerance : float, optional, keyword-only
        The guaranteed bound: every original point within ``tolerance`` of the decoded
        polyline, and every decoded point within ``tolerance`` of the original polyline.
        Default: ``1e-3`` × the bounding-box diagonal of all the curves.
    wavelet : str, optional, keyword-only
        ``"bspline2"`` (the default: the paper's, smooth; the fewest bytes on the benchmark's
        glyphs and track, see ``docs/benchmarks.md``), ``"haar"`` or ``"cdf97"``.
    level : int, optional, keyword-only
        The most levels any curve gets (default: as many as its length allows).
    metadata : dict, optional, keyword-only
        JSON-serialisable data kept in the bundle and given back by :func:`decode_curves`
        (the file readers of :mod:`wavecore.io` keep structure and properties here).
    method : {"auto", "wavelet", "vertex"}, optional, keyword-only
        ``"wavelet"``: the curves' wavelet coefficients, quantized and context-coded (format
        version 1).  ``"vertex"``: a simplified polyline on a lattice, range-coded (format
        version 2; used only where it can keep the bound: curves of one dimension and
        coordinates within ``2**46`` lattice steps, else the wavelet form is written).
        ``"auto"`` (the default) writes both and keeps the smaller.  Both keep the bound.

    Returns
    -------
    bytes
        A curve-set bundle: :func:`wavecore.decode` gives the list of curves back,
        :func:`decode_curves` the curves with their flags and metadata.

    Raises
    ------
    InvalidParameter
        For a bad curve (naming its index), flag, tolerance, wavelet or level.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    >>> ring = np.stack([np.cos(t), np.sin(t)], axis=1)
    >>> bundle = encode_curves([ring, 0.5 * ring], tolerance=1e-3)
    >>> [c.shape[1] for c in decode_curves(bundle).curves]
    [2, 2]
    """
    if isinstance(curves, Sequence) and len(curves) > MAX_CURVES:  # before any is converted
        msg = f"a curve set holds at most {MAX_CURVES} curves, not {len(curves)}"
        raise InvalidParameter(msg)
    arrays = _as_curves(curves)
    if len(arrays) > MAX_CURVES:
        msg = f"a curve set holds at most {MAX_CURVES} curves, not {len(arrays)}"
        raise InvalidParameter(msg)
    flags = _closed_list(closed, len(arrays))
    name = _wavelet_name(wavelet)
    if level is None:
        cap, level_given = _MAX_LEVEL, False
    else:
        if isinstance(level, bool) or not isinstance(level, int | np.integer):
            msg = f"level must be None or an integer from 0 to {_MAX_LEVEL}, not {level!r}"
            raise InvalidParameter(msg)
        if not 0 <= int(level) <= _MAX_LEVEL:
            msg = f"level must be from 0 to {_MAX_LEVEL}, not {level}"
            raise InvalidParameter(msg)
        cap, level_given = int(level), True
    dtype = np.result_type(*arrays) if arrays else np.dtype(np.float64)
    if dtype == np.bool_:
        dtype = np.dtype(np.uint8)
    if dtype.name not in DTYPES:
        dtype = np.dtype(np.float64)
    if tolerance is None:
        if arrays and all(a.shape[1] == arrays[0].shape[1] for a in arrays):
            stacked = np.concatenate([a.astype(np.float64) for a in arrays])
            extent = np.ptp(stacked, axis=0)
            with np.errstate(over="ignore", under="ignore"):  # measured again below
                diagonal = float(np.linalg.norm(extent))
            top = float(np.max(extent))
            if top > 0 and not 1e-150 < diagonal < 1e150:  # the squares under- or overflowed
                diagonal = top * float(np.linalg.norm(extent / top))
        else:
            diagonal = max((float(np.ptp(a.astype(np.float64))) for a in arrays), default=1.0)
        # (at least the smallest float: on subnormal curves the product underflows to 0)
        tolerance = max(
            DEFAULT_RELATIVE_TOLERANCE * (diagonal if diagonal > 0 else 1.0), math.ulp(0.0)
        )
    if (
        isinstance(tolerance, bool)
        or not isinstance(tolerance, int | float | np.integer | np.floating)
        or not (math.isfinite(float(tolerance)) and float(tolerance) > 0)
    ):
        msg = f"tolerance must be a positive finite distance, not {tolerance!r}"
        raise InvalidParameter(msg)
    tolerance = float(tolerance)
    if metadata is not None:
        try:
            text = json.dumps(metadata, separators=(",", ":"), allow_nan=False).encode()
        except (TypeError, ValueError, RecursionError) as exc:
            msg = f"metadata must be JSON-serialisable: {exc}"
            raise InvalidParameter(msg) from exc
        if len(text) > MAX_METADATA_BYTES:
            msg = f"metadata is {len(text)} bytes of JSON, more than {MAX_METADATA_BYTES}"
            raise InvalidParameter(msg)
        meta_bytes = zlib.compress(text, 9)
        depth = _nesting(metadata)
        if depth > MAX_METADATA_DEPTH:  # it would not decode: json.loads recurses
            msg = f"metadata is nested {depth} levels deep, more than {MAX_METADATA_DEPTH}"
            raise InvalidParameter(msg)
    if method is None:
        method = "auto"
    if method not in METHODS:
        msg = f"method must be one of {METHODS}, not {method!r}"[:300]
        raise InvalidParameter(msg)
    meta = meta_bytes if metadata is not None else None
    scale = _working_scale(arrays, dtype)
    vertex = None
    if method != "wavelet":
        vertex = _encode_vertex(arrays, flags, tolerance, dtype, meta, scale)
        if method == "vertex" and vertex is not None:
            return vertex
    wavelet_form = _encode_wavelet(
        arrays, flags, name, tolerance, cap, level_given, dtype, meta, scale
    )
    if vertex is not None and len(vertex) < len(wavelet_form):
        return vertex
    return wavelet_form


def _working_scale(arrays: list[np.ndarray], dtype: np.dtype[Any]) -> float:
    """A power of two that brings the largest coordinate under 1, or 1 (below
    ``_SCALED_ABOVE``, and for every dtype but ``float64``, whose values square without
    overflow).

    The searches measure squared distances, which overflow past about ``1e154``: coded at
    that scale a set fell back to its raw values.  Scaling by a power of two is exact, so
    coding the scaled values with the scaled tolerance gives the same integers, and the
    header keeps the true tolerance, from which the decoder's steps come out scaled back.
    """
    if dtype != np.float64:
        return 1.0
    largest = max((float(np.max(np.abs(a), initial=0.0)) for a in arrays), default=0.0)
    if not largest > _SCALED_ABOVE:
        return 1.0
    return math.ldexp(1.0, -math.frexp(largest)[1])


#: Plane sets with coordinates up to this (about 3e150) may have parabolic spans: a chord's
#: squared length stays finite where the decoder computes it, from the unscaled values.
_BULGED_BELOW = 2.0**500
#: Coordinates past this (about 3e144) are coded at a power-of-two scale
#: (:func:`_working_scale`); below it every sum of squares the searches form is finite.
_SCALED_ABOVE = 2.0**480


def _encode_wavelet(
    arrays: list[np.ndarray],
    flags: list[bool],
    name: str,
    tolerance: float,
    cap: int,
    level_given: bool,
    dtype: np.dtype[Any],
    meta_bytes: bytes | None,
    scale: float = 1.0,
) -> bytes:
    """The wavelet form (format version 1), coded on the values times ``scale``."""
    rounding_byte = round(DEFAULT_ROUNDING * 256)
    coder = _CurveCoder(name, tolerance * scale, rounding_byte / 256, cap, dtype)
    coded: list[_Coded] = []
    repeated: list[bool] = []
    unscaled: list[np.ndarray] = []  # a curve stored exactly is written from these
    for arr, is_closed in zip(arrays, flags, strict=True):
        points = arr.astype(np.float64)
        repeat = bool(is_closed and len(points) > 2 and np.array_equal(points[0], points[-1]))
        if repeat:
            points = points[:-1]
        repeated.append(repeat)
        unscaled.append(points)
        coded.append(coder.code(points * scale, is_closed)[0])
    dims = [a.shape[1] for a in arrays]
    mixed = len(set(dims)) > 1
    closed_mode = 2 if len(set(flags)) > 1 else (1 if flags and flags[0] else 0)
    flag_bits = (meta_bytes is not None) | mixed << 1 | closed_mode << 2 | level_given << 4
    out = bytearray(MAGIC)
    out.append(VERSION)
    out += encode_varint(flag_bits)
    out.append(WAVELETS.index(name))
    out.append(DTYPES.index(dtype.name))
    out += struct.pack("<d", tolerance)
    out.append(rounding_byte)
    if not mixed:
        out += encode_varint(dims[0] if dims else 1)
    if level_given:
        out += encode_varint(cap)
    out += encode_varint(len(arrays))
    out += encode_varint(4) + encode_varint(BLOCK_SIZE)
    for c, d, is_closed, repeat in zip(coded, dims, flags, repeated, strict=True):
        if mixed:
            out += encode_varint(d)
        out += encode_varint(c.count)
        code = (zigzag(c.exponent) << 2 | c.mode) << 1 | repeat
        if closed_mode == 2:
            code = code << 1 | is_closed
        out += encode_varint(code)
    groups = _group_arrays(coded)
    if groups:
        entries = [g.astype(np.int32)[:, None] for g in groups]
        chunks, params = encode_levels(entries, coder="context")
        if params.get("version") != 4 or params.get("block") != BLOCK_SIZE:
            msg = f"the entropy coder changed its parameters ({params}); update curvesets"
            raise RuntimeError(msg)
    else:
        chunks = []
    out += encode_varint(len(chunks))
    for chunk in chunks:
        out += encode_varint(len(chunk))
    for chunk in chunks:
        out += chunk
    for c, points in zip(coded, unscaled, strict=True):
        if c.raw is not None:  # (scaled down, a tiny value would have lost bits)
            out += _finish(points, dtype).astype(dtype.newbyteorder("<")).tobytes()
    if meta_bytes is not None:
        out += encode_varint(len(meta_bytes)) + meta_bytes
    out += struct.pack("<I", zlib.crc32(out))
    return bytes(out)


# --- the vertex form (format version 2) ------------------------------------------------------


def _pack_tolerance(tolerance: float) -> tuple[float, bytes]:
    """The tolerance the vertex form guarantees, and its bytes.

    A short decimal (``varint(2 + zz(e)), varint(k)`` for ``k · 10**e``) is kept exactly.  Any
    other value is lowered to the float32 at or below it (head 1, then 4 bytes): a bound at
    most ``2**-23`` tighter, 4 bytes shorter than a float64 (head 0, then 8 bytes, for values
    outside float32's normal range).
    """
    sign, digits, exponent = Decimal(repr(tolerance)).as_tuple()
    if not sign and isinstance(exponent, int) and len(digits) <= 9:
        mantissa = int("".join(map(str, digits)))
        if float(f"{mantissa}e{exponent}") == tolerance:
            return tolerance, encode_varint(2 + zigzag(exponent)) + encode_varint(mantissa)
    if 2.0**-126 <= tolerance < 3.0e38:
        single = np.float32(tolerance)
        if float(single) > tolerance:
            single = np.nextafter(single, np.float32(0))
        return float(single), encode_varint(1) + struct.pack("<f", float(single))
    return tolerance, encode_varint(0) + struct.pack("<d", tolerance)


def _compact_tolerance(packed: bytes) -> bytes:
    """Version 6's form of :func:`_pack_tolerance`'s bytes: a short decimal ``k · 10**e`` as
    one varint ``2 + 8 zz(e) + (k − 1)`` when ``k`` ≤ 7 (one byte for ``e`` in −8 … 7), else
    ``2 + 8 zz(e) + 7`` and the varint ``k``; a float as before."""
    if packed[0] < 2:
        return packed
    reader = _Reader(packed)
    exponent = unzigzag(reader.varint("tolerance", 1 << 12) - 2)
    mantissa = reader.varint("tolerance", 10**9)
    while mantissa and mantissa % 10 == 0:  # 10.0 is 100e-1 as written: the same value
        mantissa //= 10
        exponent += 1
    folded = zigzag(exponent)
    if 1 <= mantissa <= 7:
        return encode_varint(2 + 8 * folded + mantissa - 1)
    return encode_varint(2 + 8 * folded + 7) + encode_varint(mantissa)


def _read_tolerance(reader: _Reader, compact: bool = False) -> float:
    head = reader.varint("tolerance", 1 << 12)
    if head == 0:
        (tolerance,) = struct.unpack("<d", reader.take(8, "tolerance"))
    elif head == 1:
        (tolerance,) = struct.unpack("<f", reader.take(4, "tolerance"))
    elif compact:  # version 6: the exponent and a small mantissa in the head
        low = (head - 2) & 7
        mantissa = low + 1 if low < 7 else reader.varint("tolerance", 10**9)
        tolerance = float(f"{mantissa}e{unzigzag((head - 2) >> 3)}")
    else:
        mantissa = reader.varint("tolerance", 10**9)
        tolerance = float(f"{mantissa}e{unzigzag(head - 2)}")
    if not (math.isfinite(tolerance) and tolerance > 0):
        msg = f"curve set tolerance {tolerance!r} is not a positive number"
        raise BundleError(msg)
    return tolerance


def _lattice_values(lattice: np.ndarray, step: float, dtype: np.dtype[Any]) -> np.ndarray:
    """The decoded coordinates of lattice points (in ``dtype``)."""
    with np.errstate(all="ignore"):
        return _finish(lattice.astype(np.float64) * step, dtype)


def _start_rotation(
    points: np.ndarray,
    decoded: np.ndarray,
    offsets: np.ndarray,
    closed: np.ndarray,
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Row order that starts each closed curve where greedy reach keeps the fewest vertices,
    and greedy reach's mask in that order (reach from a ring index is reach on the curve
    rotated there, so the mask found here is the one a new search would give).

    A closed curve's start is always a vertex, so a start in the middle of a smooth stretch
    costs one.  Tried: point 0 and the first few vertices that greedy reach from point 0
    keeps (natural corners); each curve takes the start with the fewest vertices.
    """
    count = len(offsets) - 1
    starts = np.zeros(count, dtype=np.int64)
    zeros = np.zeros(count, dtype=np.int64)
    keep = curvecoder.reach_set(points, decoded, offsets, closed, zeros, tolerance, _VERTEX_WINDOW)
    if not np.any(closed):
        return np.arange(len(points)), keep
    best = np.add.reduceat(keep, offsets[:-1]) if count else zeros
    chosen = keep
    kept = np.flatnonzero(keep)
    for nth in (1, 2, 3):
        trial = zeros.copy()
        for c in range(count):
            first, stop = int(offsets[c]), int(offsets[c + 1])
            inside = kept[np.searchsorted(kept, first) : np.searchsorted(kept, stop)]
            if closed[c] and len(inside) > nth:
                trial[c] = inside[nth] - first
        found = curvecoder.reach_set(
            points, decoded, offsets, closed, trial, tolerance, _VERTEX_WINDOW
        )
        counts = np.add.reduceat(found, offsets[:-1])
        better = counts < best
        starts[better] = trial[better]
        best = np.minimum(best, counts)
        chosen = np.where(np.repeat(better, np.diff(offsets)), found, chosen)
    rows = np.arange(len(points))
    for rotated in np.flatnonzero(starts).tolist():
        first, stop = int(offsets[rotated]), int(offsets[rotated + 1])
        rows[first:stop] = np.roll(rows[first:stop], -int(starts[rotated]))
    return rows, np.ascontiguousarray(chosen[rows])


def _cheapest_starts(
    lattice: np.ndarray, keep: np.ndarray, offsets: np.ndarray, closed: np.ndarray
) -> np.ndarray:
    """Row order that starts each closed curve at the kept vertex nearest (in coded bits) the
    previous curve's first vertex, from which the coder codes a curve's first vertex.

    The polygon and its vertices stay the same: only which of them comes first changes.
    Corners are found for all curves at once; the choice, which depends on the previous
    curve's, runs in :func:`curvecoder.nearest_corner_starts`.
    """
    count = len(offsets) - 1
    sizes = np.diff(offsets)
    kept_rows = np.flatnonzero(keep)
    curve_of = np.searchsorted(offsets, kept_rows, side="right") - 1
    kept_count = np.bincount(curve_of, minlength=count)
    eligible = (np.asarray(closed) != 0) & (sizes > 2) & (kept_count > 2)
    rows_in = kept_rows[eligible[curve_of]]
    curves_in = curve_of[eligible[curve_of]]
    corner = np.zeros(len(lattice), dtype=np.bool_)
    if len(rows_in):
        # each kept vertex's neighbours around its own curve's kept vertices
        group = np.searchsorted(curves_in, curves_in, side="left")
        size = kept_count[curves_in]
        at = np.arange(len(rows_in)) - group
        vertices = lattice[rows_in].astype(np.float64)
        before = vertices - vertices[group + (at - 1) % size]
        after = vertices[group + (at + 1) % size] - vertices
        norms = np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1)
        turn = np.einsum("ij,ij->i", before, after) / np.maximum(norms, 1e-300)
        # corners only: after a corner the next steps are unpredictable anyway, while a
        # start inside a smooth run would cost the predictor its first two steps there
        corner[rows_in[turn < _CORNER_COSINE]] = True
    starts = curvecoder.nearest_corner_starts(
        np.ascontiguousarray(lattice, dtype=np.int64), np.asarray(offsets, np.int64), corner
    )
    curve_of_row = np.repeat(np.arange(count), sizes)
    within = np.arange(len(lattice)) - offsets[curve_of_row]
    rows: np.ndarray = offsets[curve_of_row] + (within + starts[curve_of_row]) % np.maximum(
        sizes[curve_of_row], 1
    )
    return rows


#: A closed curve's start (version 4, first vertex from the previous curve's last) is chosen
#: among at most this many of its corners, so that the choice costs ``O(curves · 16²)``.
_START_CHOICES = 16


def _coded_bits(gaps: np.ndarray) -> np.ndarray:
    """About how many bits the coder spends on lattice differences (per row): a bit length
    in unary and its bits, and a sign."""
    gaps = np.abs(gaps)
    return np.sum(2 * np.ceil(np.log2(gaps + 1)) + (gaps != 0), axis=-1)


def _from_last_starts(vertices: np.ndarray, counts: np.ndarray, closed: np.ndarray) -> np.ndarray:
    """Row order of the kept vertices that starts each closed curve at the corner (a turn of
    more than 45°) from which the set's first vertices cost the fewest bits when each is
    coded from the previous curve's last vertex (version 4's ``from_last``).

    A closed curve's last vertex is the one before its start, so each curve's choice moves
    the next curve's reference: the starts are chosen together, by dynamic programming over
    the curves (at most :data:`_START_CHOICES` corners each, the ones nearest the previous
    curve's first vertex).  The polygons stay the same.
    """
    rows = np.arange(len(vertices))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    choices: list[np.ndarray] = []
    previous_first = np.zeros(vertices.shape[1], dtype=np.int64)
    for c in range(len(counts)):
        first, m = int(offsets[c]), int(counts[c])
        options = np.zeros(1, dtype=np.int64)
        if closed[c] and m > 2:
            ring = vertices[first : first + m].astype(np.float64)
            before = ring - np.roll(ring, 1, axis=0)
            after = np.roll(ring, -1, axis=0) - ring
            norms = np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1)
            turn = np.einsum("ij,ij->i", before, after) / np.maximum(norms, 1e-300)
            corners = np.flatnonzero(turn < _CORNER_COSINE)
            if len(corners) > _START_CHOICES:
                bits = _coded_bits(vertices[first + corners] - previous_first)
                corners = corners[np.argsort(bits, kind="stable")[:_START_CHOICES]]
            if len(corners):
                options = corners.astype(np.int64)
        choices.append(options)
        previous_first = vertices[first + options[0]]
    if not len(counts):
        return rows
    # cost[i]: the fewest bits up to curve c when it starts at choices[c][i]
    cost = _coded_bits(vertices[offsets[0] + choices[0]])
    back: list[np.ndarray] = []
    for c in range(1, len(counts)):
        first, m_prev = int(offsets[c - 1]), int(counts[c - 1])
        lasts = vertices[first + (choices[c - 1] - 1) % m_prev]  # the vertex before each start
        starts = vertices[int(offsets[c]) + choices[c]]
        total = cost[:, None] + _coded_bits(starts[None, :, :] - lasts[:, None, :])
        back.append(np.argmin(total, axis=0))
        cost = total[back[-1], np.arange(len(choices[c]))]
    pick = int(np.argmin(cost))
    for c in range(len(counts) - 1, -1, -1):
        first, m = int(offsets[c]), int(counts[c])
        start = int(choices[c][pick])
        rows[first : first + m] = np.roll(rows[first : first + m], -start)
        if c:
            pick = int(back[c - 1][pick])
    return rows


def _bulged_polylines(
    lattice: np.ndarray,
    counts: np.ndarray,
    closed: np.ndarray,
    bulges: np.ndarray,
    step: float,
    dtype: np.dtype[Any],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Version 3's decoded polylines (in ``dtype``): the vertices, and each bulged segment's
    parabola points between them; each curve's point count; each vertex's row."""
    vertices = np.ascontiguousarray(_lattice_values(lattice, step, dtype), dtype=np.float64)
    with np.errstate(all="ignore"):
        out, sizes, rows = curvecoder.bulged_polylines(
            vertices, counts, closed, bulges, step * _BULGE_UNIT
        )
        return _finish(out, dtype), sizes, rows


def _bulged_stream(
    points: np.ndarray,
    lattice: np.ndarray,
    decoded: np.ndarray,
    fallback_keep: np.ndarray,
    fallback_lattice: np.ndarray,
    offsets: np.ndarray,
    closed: np.ndarray,
    repeated: np.ndarray,
    closed_mode: int,
    step: float,
    tolerance: float,
    dtype: np.dtype[Any],
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Version 3's vertices (bulged segments), each curve's count and each segment's bulge,
    or None where its measured bound fails.  The fewest parabolic spans
    (:func:`curvecoder.bulged_reach_set`,
    :func:`curvecoder.optimal_bulged_set`) on the points' own lattice points; a curve whose
    measured bound fails is simplified again with stricter spans, then straight ones, and at
    last takes ``fallback_keep`` and ``fallback_lattice`` (version 2's choice) unbulged."""
    strict = np.zeros(len(offsets) - 1, dtype=np.int64)
    for _ in range(4):  # a curve whose check fails is simplified again, stricter
        bulges = np.zeros(len(points), dtype=np.int64)
        keep = curvecoder.bulged_reach_set(
            points,
            decoded,
            offsets,
            closed,
            tolerance,
            _VERTEX_WINDOW,
            step * _BULGE_UNIT,
            bulges,
            strict,
        )
        keep = curvecoder.optimal_bulged_set(
            points,
            decoded,
            offsets,
            closed,
            tolerance,
            _VERTEX_WINDOW,
            step * _BULGE_UNIT,
            strict,
            keep,
            bulges,
        )
        last_resort = np.repeat(strict == 3, np.diff(offsets))
        keep = np.where(last_resort, fallback_keep, keep)
        bulges[last_resort] = 0
        moved = np.where(last_resort[:, None], fallback_lattice, lattice)
        rows = _cheapest_starts(moved, keep, offsets, closed)
        trial_points = np.ascontiguousarray(points[rows])
        keep = np.ascontiguousarray(keep[rows])
        vertices = np.ascontiguousarray(moved[rows][keep])
        bulges = np.ascontiguousarray(bulges[rows][keep])
        counts = np.add.reduceat(keep, offsets[:-1]).astype(np.int64)
        out, sizes, vertex_rows = _bulged_polylines(vertices, counts, closed, bulges, step, dtype)
        worst = curvecoder.check_bulged(
            trial_points, offsets, closed, keep, out.astype(np.float64), sizes, vertex_rows
        )
        if np.all(worst <= tolerance):
            break
        if np.any(strict[worst > tolerance] == 3):
            return None
        strict[worst > tolerance] += 1
    return vertices, counts, bulges


def _encode_vertex(
    arrays: list[np.ndarray],
    flags: list[bool],
    tolerance: float,
    dtype: np.dtype[Any],
    meta_bytes: bytes | None,
    scale: float = 1.0,
) -> bytes | None:
    """The vertex form (format version 2), or None where it cannot keep the bound; coded on
    the values times ``scale``.

    Each curve is simplified (greedy farthest reach, distances to the decoded lattice segments), its
    kept points rounded to the lattice, and the set range-coded (:mod:`wavecore.curvecoder`).
    The bound is then measured on the decoded values; a lattice step that misses it anywhere
    is not used, and the next finer one is tried.
    """
    if not arrays or len({a.shape[1] for a in arrays}) != 1 or tolerance < SMALLEST_TOLERANCE:
        return None
    d = arrays[0].shape[1]
    tolerance, tolerance_bytes = _pack_tolerance(tolerance)
    tolerance *= scale
    repeated = []
    parts = []
    for arr, is_closed in zip(arrays, flags, strict=True):
        points = arr.astype(np.float64) * scale
        repeat = bool(is_closed and len(points) > 2 and np.array_equal(points[0], points[-1]))
        repeated.append(repeat)
        parts.append(points[:-1] if repeat else points)
    points = np.ascontiguousarray(np.concatenate(parts))
    offsets = np.zeros(len(parts) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(p) for p in parts])
    closed = np.array(flags, dtype=np.int64)
    closed_mode = 2 if len(set(flags)) > 1 else (1 if flags[0] else 0)
    largest = float(np.max(np.abs(points)))
    best: bytes | None = None
    weighed = False
    for factor in sorted(VERTEX_STEPS, reverse=True):
        index = VERTEX_STEPS.index(factor)
        reach = factor * math.sqrt(d) / 2
        if reach > _SNAP_LIMIT:
            continue
        step = tolerance * factor
        if not largest / step < _VERTEX_LIMIT:
            return best
        snapped = 1
        if reach > 1:
            lattice, snapped = curvecoder.snap_set(points, offsets, closed, step, tolerance)
            if not snapped:
                continue
        else:
            lattice = np.rint(points / step).astype(np.int64)
        decoded = _lattice_values(lattice, step, dtype).astype(np.float64)
        order_rows, keep = _start_rotation(points, decoded, offsets, closed, tolerance)
        points_r = np.ascontiguousarray(points[order_rows])
        lattice = np.ascontiguousarray(lattice[order_rows])
        decoded = np.ascontiguousarray(decoded[order_rows])
        plain_points, plain_lattice, plain_decoded = points_r, lattice, decoded
        # vertices lifted off the curve where that lets a span reach farther; where the
        # measured bound then fails, the points' own lattice points
        zeros = np.zeros(len(offsets) - 1, dtype=np.int64)
        keep = curvecoder.optimal_set(
            points_r, decoded, offsets, closed, zeros, tolerance, _VERTEX_WINDOW, keep
        )
        moved = lattice
        if d == 2:  # lifting costs 3**d positions per end: plane curves only
            # vertices lifted off the curve where that lets a span reach farther; a curve
            # whose measured bound then fails keeps its own points' lattice points
            lifted = lattice.copy()
            lifted_keep = curvecoder.lifted_reach_set(
                points_r, lifted, offsets, closed, step, tolerance, _VERTEX_WINDOW
            )
            kept = _lattice_values(lifted[lifted_keep], step, dtype).astype(np.float64)
            fits = curvecoder.check_set(points_r, offsets, closed, lifted_keep, kept) <= tolerance
            # lifted only where that keeps fewer vertices than the optimum on the curve's own
            # points (on a tie the points' own lattice points: 0.2 % fewer bytes on the glyphs)
            fewer = np.add.reduceat(lifted_keep, offsets[:-1]) < np.add.reduceat(keep, offsets[:-1])
            fits &= fewer
            rows_lifted = np.repeat(fits, np.diff(offsets))
            keep = np.where(rows_lifted, lifted_keep, keep)
            moved = np.where(rows_lifted[:, None], lifted, lattice)
        chosen_keep, chosen_lattice = keep, moved  # a bulged curve's last resort
        rows = _cheapest_starts(moved, keep, offsets, closed)
        trial_points = np.ascontiguousarray(points_r[rows])
        trial_lattice = np.ascontiguousarray(moved[rows])
        keep = np.ascontiguousarray(keep[rows])
        kept = _lattice_values(trial_lattice[keep], step, dtype).astype(np.float64)
        straight_fits = bool(
            np.all(curvecoder.check_set(trial_points, offsets, closed, keep, kept) <= tolerance)
        )
        if not straight_fits and d != 2:
            continue  # (plane sets may still keep the bound with bulged segments, below)
        points_r, lattice = trial_points, trial_lattice
        counts = np.add.reduceat(keep, offsets[:-1]).astype(np.int64)
        again = np.array(repeated, dtype=np.int64)
        # the predictor that writes the fewest bytes: the previous vertex (order 0), a straight
        # continuation (2; dense smooth curves) or half way (1); each with the vertices moved
        # along the curve towards its predictions
        stream = b""
        order = -1
        plane: list[tuple[np.ndarray, np.ndarray | None, int]] = []  # version 4's candidates
        for candidate in _VERTEX_ORDERS if straight_fits else ():
            if candidate in curvecoder.FRAME_ORDERS and d != 2:
                continue  # the frame predictors are for plane curves
            vertices = np.ascontiguousarray(lattice[keep])
            if d <= len(_REFINE_RADIUS):
                curvecoder.refine_set(
                    points_r,
                    offsets,
                    closed,
                    keep,
                    vertices,
                    step,
                    tolerance,
                    candidate,
                    _REFINE_RADIUS[d - 1],
                )
                moved = _lattice_values(vertices, step, dtype).astype(np.float64)
                if not np.all(
                    curvecoder.check_set(points_r, offsets, closed, keep, moved) <= tolerance
                ):
                    vertices = np.ascontiguousarray(lattice[keep])
            if d == 2:
                if straight_fits:
                    plane.append((vertices, None, candidate))
                continue
            coded = curvecoder.encode_set(vertices, counts, closed, again, closed_mode, candidate)
            if order < 0 or len(coded) < len(stream):
                stream, order = coded, candidate
        if d == 2:  # parabolas between the vertices too; every choice coded as version 4
            # (not past _BULGED_BELOW: decoding a parabola squares its chord's length, which
            # must not overflow in the unscaled values)
            bulged = (
                None
                if largest / scale >= _BULGED_BELOW
                else _bulged_stream(
                    plain_points,
                    plain_lattice,
                    plain_decoded,
                    chosen_keep,
                    chosen_lattice,
                    offsets,
                    closed,
                    again,
                    closed_mode,
                    step,
                    tolerance,
                    dtype,
                )
            )
            bulged_counts = counts
            if bulged is not None:
                bulged_vertices, bulged_counts, segment_bulges = bulged
                plane += [(bulged_vertices, segment_bulges, o) for o in _VERTEX_ORDERS]
            if not plane:
                continue  # neither form keeps the bound at this step: the next finer one
            best_plane: tuple[bytes, int, int] | None = None
            # every coding tried: its size, head, inputs
            choices: list[tuple[int, int, tuple[np.ndarray, np.ndarray, Any, int, bool]]] = []
            counts_written = counts
            start_rows: dict[int, np.ndarray] = {}
            for kept_vertices, kept_bulges, candidate in plane:
                sizes = counts if kept_bulges is None else bulged_counts
                for from_last in (False, True) if len(arrays) > 1 else (False,):
                    placed = kept_vertices
                    placed_bulges = kept_bulges
                    if from_last:
                        if id(kept_vertices) not in start_rows:  # bulged: one for all orders
                            start_rows[id(kept_vertices)] = _from_last_starts(
                                kept_vertices, sizes, closed
                            )
                        starts = start_rows[id(kept_vertices)]
                        placed = np.ascontiguousarray(kept_vertices[starts])
                        placed_bulges = None if kept_bulges is None else kept_bulges[starts]
                    coded_by_version = [
                        (
                            curvecoder.encode_set(
                                placed,
                                sizes,
                                closed,
                                again,
                                closed_mode,
                                candidate,
                                placed_bulges,
                                from_last,
                                priors=version == PRIOR_VERSION,
                            ),
                            version,
                        )
                        for version in (PLANE_VERSION, PRIOR_VERSION)
                    ]
                    coded, version = min(coded_by_version, key=lambda pair: len(pair[0]))
                    head = (
                        (meta_bytes is not None)
                        | closed_mode << 1
                        | candidate << 3
                        | (kept_bulges is not None) << 6
                        | from_last << 7
                        | (dtype.name != "float64") << 8
                        | index << 9
                    )
                    inputs = (placed, sizes, placed_bulges, candidate, from_last)
                    choices.append((len(coded), head, inputs))
                    if best_plane is None or len(coded) < len(best_plane[0]):
                        best_plane = (coded, head, version)
                        counts_written = sizes
            assert best_plane is not None
            choices.sort(key=lambda choice: choice[0])
            if len(best_plane[0]) > _COPY_EVERY_CHOICE:
                choices = choices[:1]  # a large set: copies in its chosen coding only
            for _, head, inputs in choices:
                copied = _copied_stream(
                    parts, closed, again, closed_mode, inputs, step, tolerance, dtype
                )
                if copied is not None and len(copied[0]) < len(best_plane[0]):
                    best_plane = (copied[0], head, COPY_VERSION)
                    counts_written = copied[1]  # a copy has its source's count
            stream, head, plane_version = best_plane
            limit = VERTEX_PER_BYTE * (len(stream) + 16)
            if len(arrays) > limit or int(counts_written.sum()) * d > limit:
                return best
            out = _preamble_bytes(plane_version)
            if plane_version == COPY_VERSION:
                tail = _pack_head(head, _compact_tolerance(tolerance_bytes), len(arrays))
                out += tail[:3]
            else:
                out += struct.pack("<H", head)
            if dtype.name != "float64":
                out.append(DTYPES.index(dtype.name))
            if plane_version == COPY_VERSION:
                out += tail[3:]
            else:
                out += tolerance_bytes + encode_varint(len(arrays))
            if meta_bytes is not None:
                out += encode_varint(len(meta_bytes)) + meta_bytes
            out += stream
            written = _with_check(out, plane_version)
            if best is None or len(written) < len(best):
                best = written
            if (snapped == 2 or not straight_fits) and not weighed:
                weighed = True  # kept only through a fallback: the next finer step may be
                continue  # smaller (one more step is weighed, so the cost stays bounded)
            break
        limit = VERTEX_PER_BYTE * (len(stream) + 16)
        if len(arrays) > limit or int(counts.sum()) * d > limit:
            return best
        out = bytearray(MAGIC)
        out.append(VERTEX_VERSION)
        out += encode_varint((meta_bytes is not None) | closed_mode << 2 | order << 4)
        out.append(DTYPES.index(dtype.name))
        out += encode_varint(d)
        out += tolerance_bytes
        out.append(index)
        out += encode_varint(len(arrays))
        if meta_bytes is not None:
            out += encode_varint(len(meta_bytes)) + meta_bytes
        out += stream
        out += struct.pack("<I", zlib.crc32(out))
        if best is None or len(out) < len(best):
            best = bytes(out)
        if snapped == 2 and not weighed:
            weighed = True  # kept only through a fallback: the next finer step may be smaller
            continue
        break  # the coarsest step that keeps the bound (finer ones measured: never smaller)
    return best


#: A set whose chosen stream is at most this many bytes has copies tried in every coding
#: (predictor, bulges, starts), not only the chosen one: a few more bytes found where each is
#: a larger share, for little time (such sets are quick to code).
_COPY_EVERY_CHOICE = 256
#: The most point-to-segment distances that copies' checks may measure, per original point
#: of the set (and a fixed allowance): the copies' cost stays linear in the input.
_COPY_WORK = 256
_COPY_CANDIDATES = 8  # earlier curves of the same length compared with a curve


def _one_way_exact(source: np.ndarray, target: np.ndarray, closed: bool) -> float:
    """The largest distance from a point of ``source`` to the polyline ``target`` (closed:
    with its closing segment), every point against every segment."""
    a = target if not closed or len(target) < 2 else np.concatenate([target, target[:1]])
    if len(a) == 1:
        return float(np.max(np.linalg.norm(source - a[0], axis=1)))
    start, edge = a[:-1], np.diff(a, axis=0)
    length2 = np.maximum(np.einsum("ij,ij->i", edge, edge), 1e-300)
    worst = 0.0
    for lo in range(0, len(source), 256):
        p = source[lo : lo + 256, None, :] - start[None]
        t = np.clip(np.einsum("ijk,jk->ij", p, edge) / length2, 0.0, 1.0)
        gap = p - t[..., None] * edge[None]
        worst = max(worst, float(np.sqrt(np.min(np.einsum("ijk,ijk->ij", gap, gap), axis=1)).max()))
    return worst


def _copy_values(
    vertices: np.ndarray, bulges: np.ndarray | None, closed: bool, step: float, dtype: Any
) -> np.ndarray:
    """One curve's decoded polyline from its (fractional) lattice vertices, as decoding
    computes it."""
    counts = np.array([len(vertices)], dtype=np.int64)
    flags = np.array([int(closed)], dtype=np.int64)
    if bulges is None:
        return _lattice_values(vertices, step, dtype).astype(np.float64)
    return _bulged_polylines(vertices, counts, flags, bulges, step, dtype)[0].astype(np.float64)


def _fraction_pairs(k: np.ndarray, fraction: np.ndarray) -> list[int]:
    """Each coordinate's fraction ``f_j / 2**k_j`` as its shortest ``(k_j, f_j)``: a
    coordinate not moved off the lattice (a copy along a baseline) costs no fraction bits."""
    pairs = []
    for shift, f in zip(k.tolist(), fraction.tolist(), strict=True):
        while shift and not f & 1:
            f >>= 1
            shift -= 1
        pairs += [shift, f]
    return pairs


def _copy_tries(
    target: np.ndarray, again_as: tuple[np.ndarray, np.ndarray, np.ndarray] | None
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Where a copy's first vertex may go, in the order tried: as the previous copy
    (``again_as``), then ``target`` rounded to fractions of a step, the fewest bits per
    coordinate in all first (a copy along a baseline needs none across it).  Made one at a
    time: most copies fit at the first."""
    if again_as is not None:
        yield again_as
    most = curvecoder.COPY_SHIFTS
    for bits in range(2 * most + 1):
        for kx in range(max(0, bits - most), min(most, bits) + 1):
            k = np.array([kx, bits - kx], dtype=np.int64)
            total = np.rint(target * (1 << k)).astype(np.int64)
            yield total >> k, k, total & ((1 << k) - 1)


def _copied_stream(
    parts: list[np.ndarray],
    closed: np.ndarray,
    again: np.ndarray,
    closed_mode: int,
    inputs: tuple[np.ndarray, np.ndarray, np.ndarray | None, int, bool],
    step: float,
    tolerance: float,
    dtype: Any,
) -> tuple[bytes, np.ndarray] | None:
    """Version 6's stream, and each curve's vertex count, for the chosen coding ``inputs``
    (vertices, counts, bulges, predictor, ``from_last``), where some curve is a translate of
    an earlier one (glyphs of one letter, repeated symbols) and the earlier curve's decoded
    shape, moved by a lattice vector and a fraction of a step (the coarsest that does, or the
    previous copy's translation), keeps the bound on it: measured exactly, every point against
    every segment, both ways.  None where no curve is copied."""
    vertices, counts, bulges, order, from_last = inputs
    count = len(parts)
    rows = np.zeros(count + 1, dtype=np.int64)
    rows[1:] = np.cumsum(counts)
    budget = _COPY_WORK * sum(len(p) for p in parts) + (1 << 22)
    sources = np.full(count, -1, dtype=np.int64)
    fractions = np.zeros((count, 4), dtype=np.int64)
    # per curve, its rows (a copy takes its source's count)
    shapes = [vertices[rows[c] : rows[c + 1]] for c in range(count)]
    curve_bulges = [None if bulges is None else bulges[rows[c] : rows[c + 1]] for c in range(count)]
    phases = np.zeros((count, 2))  # each curve's fraction of a step (0 unless a copy)
    by_length: dict[int, list[int]] = {}
    last: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None = None  # the previous copy's
    for j, points in enumerate(parts):
        earlier = by_length.setdefault(len(points), [])
        # the newest first (the nearest back), and first of all the one the previous copy's
        # distance back names (a repeated word: one bit where its translation is the same)
        newest = earlier[::-1][:_COPY_CANDIDATES]
        if last is not None and j - 1 - last[0] in earlier:
            newest.insert(0, j - 1 - last[0])
        for i in newest:
            if closed[i] != closed[j]:
                continue
            shift = points - parts[i]
            if np.ptp(shift, axis=0).max() > tolerance * 1e-3:
                continue
            shape = shapes[i] - shapes[i][:1]
            kept_bulges = curve_bulges[i]
            # where the first vertex goes (a copied source's decoded points are off its lattice
            # vertices by its own fraction)
            target = shapes[i][0] + phases[i] + shift[0] / step
            again_as = None
            if last is not None and last[0] == j - 1 - i:  # as the previous copy: 1 bit
                again_as = (shapes[i][0] + last[1], last[2], last[3])
            for first, k, fraction in _copy_tries(target, again_as):
                moved = (shape + first).astype(np.float64) + fraction / (1 << k)
                decoded = _copy_values(moved, kept_bulges, bool(closed[j]), step, dtype)
                work = 2 * len(points) * len(decoded)
                if work > budget:
                    break
                budget -= work
                if (
                    _one_way_exact(points, decoded, bool(closed[j])) <= tolerance
                    and _one_way_exact(decoded, points, bool(closed[j])) <= tolerance
                ):
                    shapes[j] = shape + first
                    curve_bulges[j] = kept_bulges
                    sources[j] = i
                    fractions[j] = _fraction_pairs(k, fraction)
                    phases[j] = fraction / (1 << k)
                    last = (j - 1 - i, first - shapes[i][0], k, fraction)
                    break
            if sources[j] >= 0:
                break
        earlier.append(j)
    if not np.any(sources >= 0):
        return None
    written = np.array([len(v) for v in shapes], dtype=np.int64)
    stream = curvecoder.encode_set(
        np.ascontiguousarray(np.concatenate(shapes)),
        written,
        closed,
        again,
        closed_mode,
        order,
        None if bulges is None else np.concatenate([b for b in curve_bulges if b is not None]),
        from_last,
        priors=True,
        sources=sources,
        fractions=fractions,
    )
    return stream, written


def _decode_vertex(data: bytes, parse_metadata: bool = True) -> tuple[CurveSet, dict[str, Any]]:
    """Decode a vertex-form bundle (CRC already checked): the set and what inspect shows
    (with ``parse_metadata`` false, the metadata is inflated but not parsed: its JSON may
    take far more memory as Python objects than as text)."""
    reader = _Reader(data[: -check_size(data)])
    version, start = _preamble(data)
    reader.take(start, "preamble")
    from_last = False
    packed_tolerance = packed_count = 0
    if version in (PLANE_VERSION, PRIOR_VERSION, COPY_VERSION):
        if version == COPY_VERSION:
            head, packed_tolerance, packed_count = _unpack_head(reader.take(3, "head"))
        else:
            (head,) = struct.unpack("<H", reader.take(2, "head"))
        closed_mode = (head >> 1) & 3
        order = (head >> 3) & 7
        bulged = bool(head >> 6 & 1)
        from_last = bool(head >> 7 & 1)
        step_index = (head >> 9) & 15
        metadata_given = bool(head & 1)
        if head >> 13 or closed_mode == 3 or order not in _VERTEX_ORDERS:
            msg = f"curve set head {head:#06x} is not version {version}'s"
            raise BundleError(msg)
        dtype_index = reader.take(1, "dtype")[0] if head >> 8 & 1 else 0
        d = 2
    else:
        flags = reader.varint("flags", 127)
        closed_mode = (flags >> 2) & 3
        order = flags >> 4
        bulged = version == BULGED_VERSION
        metadata_given = bool(flags & 1)
        if flags & 2 or closed_mode == 3 or order not in _VERTEX_ORDERS:
            msg = f"curve set flags {flags} are not a vertex form's"
            raise BundleError(msg)
        dtype_index = reader.take(1, "dtype")[0]
        d = reader.varint("d", 1 << 16)
        if d < 1:
            msg = "curve set dimension 0 is invalid"
            raise BundleError(msg)
    if dtype_index >= len(DTYPES):
        msg = f"curve set names dtype {dtype_index}, unknown"
        raise BundleError(msg)
    dtype = np.dtype(DTYPES[dtype_index])
    if packed_count:  # version 6: a one-byte tolerance and the count in the head
        if packed_tolerance < 2:
            msg = f"curve set tolerance byte {packed_tolerance} names a longer form"
            raise BundleError(msg)
        tolerance = _read_tolerance(_Reader(bytes([packed_tolerance])), True)
    else:
        if packed_tolerance:
            msg = f"curve set head names tolerance byte {packed_tolerance} without a count"
            raise BundleError(msg)
        tolerance = _read_tolerance(reader, version == COPY_VERSION)
    if version not in (PLANE_VERSION, PRIOR_VERSION, COPY_VERSION):
        step_index = reader.take(1, "step")[0]
    if step_index >= len(VERTEX_STEPS):
        msg = f"curve set lattice step {step_index} is unknown"
        raise BundleError(msg)
    step = tolerance * VERTEX_STEPS[step_index]
    count = packed_count - 1 if packed_count else reader.varint("count", MAX_CURVES)
    metadata = None
    metadata_bytes = 0
    if metadata_given:
        size = reader.varint("metadata length", len(data))
        text = _metadata_text(reader.take(size, "metadata"))
        metadata_bytes = len(text)
        if parse_metadata:
            try:
                metadata = json.loads(text)
            except ValueError as exc:
                msg = f"curve set metadata is not deflated JSON: {exc}"
                raise BundleError(msg) from exc
    stream = reader.data[reader.at :]
    limit = min(MAX_POINTS, VERTEX_PER_BYTE * (len(stream) + 16))
    if count > limit:
        msg = f"curve set declares {count} curves in a {len(stream)}-byte stream"
        raise BundleError(msg)
    capacity = min(limit // d, 1024 + 64 * len(stream))
    if bulged and d != 2:
        msg = f"curve set version {version} is for plane curves, not of dimension {d}"
        raise BundleError(msg)
    copies = np.zeros((count, 2 * d + 1), dtype=np.int64) if version == COPY_VERSION else None
    while True:  # grow the vertex buffer only as far as the stream really goes
        result = curvecoder.decode_bulged_set(
            stream,
            count,
            d,
            closed_mode,
            closed_mode == 1,
            capacity,
            order,
            bulged,
            from_last,
            version in (PRIOR_VERSION, COPY_VERSION),
            copies,
        )
        if result is not None or capacity >= limit // d:
            break
        capacity = min(limit // d, 4 * capacity)
    if result is None:
        msg = f"curve set declares more than {limit} values in a {len(stream)}-byte stream"
        raise BundleError(msg)
    lattice, counts, closed, repeated, bulges = result
    if np.any(np.abs(lattice) >= _VERTEX_LIMIT):
        msg = "curve set coordinate out of range"
        raise BundleError(msg)
    if np.any(np.abs(bulges) >= _VERTEX_LIMIT):
        msg = "curve set bulge out of range"
        raise BundleError(msg)
    places: np.ndarray = lattice
    if copies is not None and np.any(copies[:, 0] >= 0):  # copies moved by their fractions
        places = lattice.astype(np.float64)
        first = np.concatenate([[0], np.cumsum(counts)])
        for c in np.flatnonzero(copies[:, 0] >= 0).tolist():
            shifts = copies[c, 1::2]
            if np.any(shifts < 0) or np.any(shifts > curvecoder.COPY_SHIFTS):
                msg = "curve set copy fraction out of range"  # (the coder refuses these)
                raise BundleError(msg)
            places[first[c] : first[c + 1]] += copies[c, 2::2] / (1 << shifts).astype(np.float64)
    if bulged:
        extra = (curvecoder.BULGE_PARTS - 1) * int(np.count_nonzero(bulges))
        if (len(lattice) + extra) * d > limit:
            msg = f"curve set declares more than {limit} values in a {len(stream)}-byte stream"
            raise BundleError(msg)
        values, sizes, _ = _bulged_polylines(places, counts, closed, bulges, step, dtype)
    else:
        values, sizes = _lattice_values(places, step, dtype), counts
    curves = []
    at = 0
    for m, again in zip(sizes.tolist(), repeated.tolist(), strict=True):
        points = values[at : at + m]
        at += m
        curves.append(np.concatenate([points, points[:1]]) if again else points.copy())
    flags_out = [bool(c) for c in closed.tolist()]
    info = {
        "version": version,
        "dtype": dtype,
        "d": d,
        "stream": len(stream),
        "has_metadata": bool(metadata_given),
        "metadata_bytes": metadata_bytes,
        "step": step,
        "repeated": [bool(r) for r in repeated.tolist()],
        "closed_mode": closed_mode,
        "bulged": bulged,
        "from_last": from_last,
        "order": order,
        # version 6: per curve, the copied curve (-1: coded in full) and its fractions' bits
        "copies": [] if copies is None else copies[:, [0, 1, 3]].tolist(),
        "coded": (lattice, counts, closed, repeated, bulges),
    }
    curve_set = CurveSet(
        curves, flags_out, tolerance, "none", metadata, [_MODE_VERTEX] * len(curves)
    )
    return curve_set, info


def coded_vertices(bundle: Any) -> dict[str, Any]:
    """What the vertex coder wrote in a vertex-form bundle (versions 2–4), for measurements:
    ``coded`` (lattice vertices, counts, closed and repeated flags, bulges), ``closed_mode``,
    ``order``, ``bulged``, ``from_last``, ``step``."""
    data = _checked(bundle)
    if not _is_vertex_form(data):
        msg = "not a vertex-form curve set (version 1 is the wavelet form)"
        raise BundleError(msg)
    return _decode_vertex(data)[1]


def is_curve_set(data: Any) -> bool:
    """Whether ``data`` starts like a curve-set bundle (made by :func:`encode_curves`)."""
    if not isinstance(data, bytes | bytearray | memoryview):
        return False
    start = bytes(data[:4])
    return start == MAGIC or (
        start[:2] == SHORT_MAGIC and len(start) > 2 and start[2] >= SHORT_FLAG
    )


@dataclass
class _Record:
    d: int
    count: int
    exponent: int
    mode: int
    repeated: bool
    closed: bool


def _metadata_text(deflated: bytes) -> bytes:
    """A set's metadata JSON: at most ``MAX_METADATA_BYTES`` of it is inflated."""
    return inflate(deflated, MAX_METADATA_BYTES, "curve set metadata")


def _inflated_metadata(deflated: bytes) -> Any:
    """A set's metadata, parsed."""
    return json.loads(_metadata_text(deflated))


def _checked(data: Any) -> bytes:
    """The bundle's bytes, once its magic, length and CRC-32 are checked."""
    if not isinstance(data, bytes | bytearray | memoryview):
        msg = f"a bundle must be bytes, not {type(data).__name__}"
        raise BundleError(msg)
    data = bytes(data)
    if not is_curve_set(data):
        msg = "not a curve-set bundle (the first bytes are not b'\\x89WVC' nor b'\\x89W\\x86')"
        raise BundleError(msg)
    if len(data) < 8:  # version 6's preamble, head and CRC-16
        msg = f"curve set truncated: {len(data)} bytes"
        raise BundleError(msg)
    version, start = _preamble(data)
    if not VERSION <= version <= COPY_VERSION:
        msg = (
            f"curve set version {version} is not supported (this reader reads {VERSION}, "
            f"{VERTEX_VERSION}, {BULGED_VERSION}, {PLANE_VERSION}, {PRIOR_VERSION} and "
            f"{COPY_VERSION}); use a wavecore release that knows this version"
        )
        raise BundleError(msg)
    if (start == len(SHORT_MAGIC) + 1) != (version == COPY_VERSION):
        # Version 6 has only the short preamble, and versions 1-5 only the magic: a set that
        # mixes them is damaged (or crafted), not a version to guess at.
        form = "the 3-byte preamble" if version == COPY_VERSION else "the 4-byte magic"
        msg = f"curve set version {version} is damaged: it is written with {form}"
        raise BundleError(msg)
    if check_size(data) == 2:
        (crc,) = struct.unpack("<H", data[-2:])
        if binascii.crc_hqx(data[:-2], 0) != crc:
            msg = "curve set damaged: its CRC-16 does not match"
            raise BundleError(msg)
        return data
    (crc,) = struct.unpack("<I", data[-4:])
    if zlib.crc32(data[:-4]) != crc:
        msg = "curve set damaged: its CRC-32 does not match"
        raise BundleError(msg)
    return data


def _is_vertex_form(data: bytes) -> bool:
    return _preamble(data)[0] in (
        VERTEX_VERSION,
        BULGED_VERSION,
        PLANE_VERSION,
        PRIOR_VERSION,
        COPY_VERSION,
    )


def _parse(data: Any) -> tuple[dict[str, Any], list[_Record], list[bytes], _Reader]:
    data = _checked(data)
    reader = _Reader(data[:-4])
    reader.take(4, "magic")
    version = reader.take(1, "version")[0]
    if version != VERSION:
        msg = (
            f"curve set version {version} is not supported "
            f"(this reader reads {VERSION}, {VERTEX_VERSION}, {BULGED_VERSION}, {PLANE_VERSION}, "
            f"{PRIOR_VERSION} and {COPY_VERSION})"
        )
        raise BundleError(msg)
    flags = reader.varint("flags", 31)
    wavelet_index = reader.take(1, "wavelet")[0]
    dtype_index = reader.take(1, "dtype")[0]
    if wavelet_index >= len(WAVELETS) or dtype_index >= len(DTYPES):
        msg = f"curve set names wavelet {wavelet_index} or dtype {dtype_index}, unknown"
        raise BundleError(msg)
    (tolerance,) = struct.unpack("<d", reader.take(8, "tolerance"))
    if not (math.isfinite(tolerance) and tolerance > 0):
        msg = f"curve set tolerance {tolerance!r} is not a positive number"
        raise BundleError(msg)
    rounding_byte = reader.take(1, "rounding")[0]
    if not 0 < rounding_byte <= 128:
        msg = f"curve set rounding {rounding_byte}/256 is out of range"
        raise BundleError(msg)
    mixed = bool(flags & 2)
    closed_mode = (flags >> 2) & 3
    if closed_mode == 3:
        msg = "curve set closed mode 3 is unknown"
        raise BundleError(msg)
    d = 0 if mixed else reader.varint("d", 1 << 16)
    cap = reader.varint("level", _MAX_LEVEL) if flags & 16 else _MAX_LEVEL
    count = reader.varint("count", MAX_CURVES)
    coder_version = reader.varint("coder version", 255)
    block = reader.varint("block size", 1 << 16)
    records: list[_Record] = []
    total = 0
    for _ in range(count):
        dim = reader.varint("d", 1 << 16) if mixed else d
        n = reader.varint("points", MAX_POINTS)
        code = reader.varint("code", 1 << 40)
        is_closed = closed_mode == 1
        if closed_mode == 2:
            is_closed = bool(code & 1)
            code >>= 1
        repeated = bool(code & 1)
        mode = (code >> 1) & 3
        exponent = unzigzag(code >> 3)
        if mode > 2 or dim < 1 or n < 1 or (mode != _MODE_RAW and n < 2):
            msg = f"curve set record {len(records)} is invalid (mode {mode}, d {dim}, n {n})"
            raise BundleError(msg)
        total += n * dim
        if total > MAX_POINTS:
            msg = f"curve set declares more than {MAX_POINTS} values"
            raise BundleError(msg)
        records.append(_Record(dim, n, exponent, mode, repeated, is_closed))
    chunk_count = reader.varint("chunk count", 64)
    lengths = [reader.varint("chunk length", len(data)) for _ in range(chunk_count)]
    chunks = [reader.take(length, "chunk") for length in lengths]
    info = {
        "wavelet": WAVELETS[wavelet_index],
        "dtype": np.dtype(DTYPES[dtype_index]),
        "tolerance": tolerance,
        "rounding": rounding_byte / 256,
        "cap": cap,
        "coder": {"coder": "context", "version": coder_version, "two_d": False, "block": block},
        "has_metadata": bool(flags & 1),
    }
    return info, records, chunks, reader


def _layout(info: dict[str, Any], record: _Record) -> tuple[int, int, list[int]]:
    """The fitted length, the level and the band lengths of a coded curve."""
    boundary = "closed" if record.closed else "open"
    wavelet = info["wavelet"]
    if record.mode == _MODE_RESAMPLED:
        level = _level_for(record.count, boundary, wavelet, info["cap"])
        fitted = record.count
    else:
        level = _padded_level(record.count, boundary, wavelet, info["cap"])
        fitted = valid_length(record.count, level, boundary, wavelet) if level else record.count
    return fitted, level, _band_lengths(fitted, level, boundary, wavelet)


def decode_curves(bundle: Any) -> CurveSet:
    """Decode a curve-set bundle into its curves, closed flags, tolerance and metadata.

    Raises
    ------
    BundleError
        For anything wrong with the bytes (never another exception).
    """
    return _bundle_errors(_decode, bundle)


_T = TypeVar("_T")


def _bundle_errors(read: Callable[[Any], _T], bundle: Any) -> _T:
    """``read(bundle)``, any error but a ``BundleError`` raised as one: a crafted bundle with
    a valid CRC is still the bundle's fault."""
    try:
        return read(bundle)
    except BundleError:
        raise
    except Exception as exc:
        msg = f"corrupt curve set: {type(exc).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc


def _decode(bundle: Any) -> CurveSet:
    data = _checked(bundle)
    if _is_vertex_form(data):
        return _decode_vertex(data)[0]
    info, records, chunks, reader = _parse(data)
    wavelet = info["wavelet"]
    dtype = info["dtype"]
    layouts = [None if r.mode == _MODE_RAW else _layout(info, r) for r in records]
    depth = max((len(lay[2]) - 1 for lay in layouts if lay is not None), default=-1)
    group_sizes = [0] * (depth + 1)
    for record, lay in zip(records, layouts, strict=True):
        if lay is None:
            continue
        lengths = lay[2]
        group_sizes[0] += lengths[0] * record.d
        for g, length in enumerate(reversed(lengths[1:]), start=1):
            group_sizes[g] += length * record.d
    if len(chunks) != len(group_sizes):
        msg = f"curve set has {len(chunks)} chunks for {len(group_sizes)} coefficient groups"
        raise BundleError(msg)
    groups = []
    if chunks:
        decoded = decode_levels(chunks, [(size, 1) for size in group_sizes], info["coder"])
        groups = [np.asarray(g).reshape(-1).astype(np.int64) for g in decoded]
    at = [0] * len(groups)
    curves = []
    for record, lay in zip(records, layouts, strict=True):
        if lay is None:
            size = record.count * record.d * dtype.itemsize
            raw = np.frombuffer(reader.take(size, "raw curve"), dtype=dtype.newbyteorder("<"))
            points = raw.reshape(record.count, record.d).astype(dtype)
        else:
            _, _, lengths = lay
            bands = []
            take = lengths[0] * record.d
            coarse = groups[0][at[0] : at[0] + take].reshape(lengths[0], record.d)
            at[0] += take
            bands.append(np.cumsum(coarse, axis=0))
            details = []
            for g, length in enumerate(reversed(lengths[1:]), start=1):
                take = length * record.d
                details.append(groups[g][at[g] : at[g] + take].reshape(length, record.d))
                at[g] += take
            bands.extend(reversed(details))
            if any(np.max(np.abs(b), initial=0) >= _INDEX_LIMIT for b in bands):
                msg = "curve set coefficient out of range"
                raise BundleError(msg)
            q = [b.astype(np.int32) for b in bands]
            boundary = "closed" if record.closed else "open"
            step = info["tolerance"] * 2.0 ** (record.exponent / _STEP_FRACTION)
            with np.errstate(all="ignore"):
                values = _synthesize(q, step, info["rounding"], wavelet, boundary)
            if record.mode == _MODE_PADDED:
                values = values[: record.count]
            points = _finish(values, dtype)
        if record.repeated:
            points = np.concatenate([points, points[:1]])
        curves.append(points)
    metadata = None
    if info["has_metadata"]:
        size = reader.varint("metadata length", len(reader.data))
        try:
            metadata = _inflated_metadata(reader.take(size, "metadata"))
        except (zlib.error, ValueError) as exc:
            msg = f"curve set metadata is not deflated JSON: {exc}"
            raise BundleError(msg) from exc
    if reader.at != len(reader.data):
        msg = f"curve set has {len(reader.data) - reader.at} bytes after its last field"
        raise BundleError(msg)
    return CurveSet(
        curves,
        [r.closed for r in records],
        info["tolerance"],
        wavelet,
        metadata,
        [r.mode for r in records],
    )


def inspect_curves(bundle: Any) -> dict[str, Any]:
    """Describe a curve-set bundle without decoding its coefficients.

    ``kind`` is ``"curves"``; ``count`` curves with their ``points``, ``dims`` and ``closed``
    flags; ``tolerance`` (also as ``max_error``: the guaranteed bound); ``total_bytes`` and
    ``payload_bytes`` (the entropy-coded coefficients; the rest is header and records);
    ``metadata`` (whether the set has any) and ``metadata_bytes`` (its JSON's length, inflated
    but not parsed: as Python objects it may take some 30 times that).
    A vertex-coded set (format version 2) keeps its records in the coded stream: it is
    decoded to describe it (``payload_bytes`` is then the stream, records included).

    Raises
    ------
    BundleError
        For anything wrong with the bytes (never another exception).
    """
    return _bundle_errors(_inspect_curves, bundle)


def _inspect_curves(bundle: Any) -> dict[str, Any]:
    data = _checked(bundle)
    if _is_vertex_form(data):
        return _inspect_vertex(data)
    info, records, chunks, reader = _parse(data)
    total = len(bytes(bundle))
    payload = sum(len(c) for c in chunks)
    metadata_bytes = 0
    if info["has_metadata"]:
        for record in records:  # the raw values come before the metadata
            if record.mode == _MODE_RAW:
                reader.take(record.count * record.d * info["dtype"].itemsize, "raw curve")
        size = reader.varint("metadata length", len(reader.data))
        metadata_bytes = len(_metadata_text(reader.take(size, "metadata")))
    return {
        "kind": "curves",
        "version": f"{VERSION}",
        "shape": [len(records)],
        "levels": max((_layout(info, r)[1] for r in records if r.mode != _MODE_RAW), default=0),
        "boundary": ["closed" if r.closed else "open" for r in records],
        "colour": "none",
        "psnr": None,
        "header_bytes": total - payload,
        "chunks": [],
        "count": len(records),
        "dtype": info["dtype"].name,
        "wavelet": info["wavelet"],
        "tolerance": info["tolerance"],
        "max_error": info["tolerance"],
        "closed": [r.closed for r in records],
        "points": [r.count + r.repeated for r in records],
        "dims": [r.d for r in records],
        "total_points": sum(r.count + r.repeated for r in records),
        "total_bytes": total,
        "payload_bytes": payload,
        "method": "wavelet",
        "metadata": info["has_metadata"],
        "metadata_bytes": metadata_bytes,
    }


def _inspect_vertex(data: bytes) -> dict[str, Any]:
    curve_set, info = _decode_vertex(data, parse_metadata=False)
    points = [len(c) for c in curve_set.curves]
    total = len(data)
    return {
        "kind": "curves",
        "version": f"{info['version']}",
        "shape": [len(points)],
        "levels": 0,
        "boundary": ["closed" if c else "open" for c in curve_set.closed],
        "colour": "none",
        "psnr": None,
        "header_bytes": total - info["stream"],
        "chunks": [],
        "count": len(points),
        "dtype": info["dtype"].name,
        "wavelet": "none",
        "method": "vertex",
        "lattice_step": info["step"],
        "tolerance": curve_set.tolerance,
        "max_error": curve_set.tolerance,
        "closed": curve_set.closed,
        "points": points,
        "dims": [info["d"]] * len(points),
        "total_points": sum(points),
        "total_bytes": total,
        "payload_bytes": info["stream"],
        "metadata": info["has_metadata"],
        "metadata_bytes": info["metadata_bytes"],
    }
