"""The vertex coder of curve-set format version 2: lattice vertices, predicted and range-coded.

A curve set at a guaranteed tolerance is, at heart, a list of polylines whose vertices may move
by a bounded amount.  This module keeps a subset of each curve's points (a Douglas–Peucker
simplification whose distances are measured to the *quantized* segments, so the rounding is
part of the test, not a margin taken off it), rounds them to a lattice of step ``q``, and codes
the lattice differences with an adaptive binary range coder and small contexts.  Everything
runs in compiled loops over the whole set (one call per set, not per curve or per symbol).

The range coder is LZMA's (``low`` with a carry cache, 32-bit ``range``, renormalised by bytes)
with 15-bit probabilities adapted at a rate that starts fast and settles at ``2**-5``: the sets
are small (a glyph is a few hundred bytes), so the models must learn in a few dozen symbols.
It is written here rather than borrowed from ``_blockkernels`` because its contexts are the
curve's own and its stream format must not move when the image coder's does.  All arithmetic
is on integers: every machine writes and reads the same bits.

One function (:func:`_code_set`) both encodes and decodes, so the two cannot drift apart.

Integers are coded as a sign and a magnitude; the magnitude as its bit length ``k`` (unary,
adaptive, in a context) and then its ``k - 1`` lower bits (adaptive per ``(k, position)``).
Contexts: the bit length of the previous segment's largest coordinate step, and for the second
and later coordinates the bit length of this vertex's first step.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PROB_BITS = 15
PROB_HALF = 1 << (PROB_BITS - 1)
PROB_ONE = 1 << PROB_BITS
RATE_LIMIT = 5
TOP = 1 << 24
MASK32 = (1 << 32) - 1
MAX_BITS = 48  # the largest magnitude coded: 2**48 - 1 lattice steps

# model layout: [probability, count] pairs, grouped
_CLASSES = 17  # context classes of a magnitude's bit length (0 … 16)
_UNARY = MAX_BITS + 1
# classes: 0 count, 1 first vertex of a curve, 2 … 2+_CLASSES first coordinate, then second
_KIND_COUNT, _KIND_START = 0, 1
_FIRST_COORD = 2
_OTHER_COORD = _FIRST_COORD + _CLASSES
_MAG_KINDS = _OTHER_COORD + _CLASSES * 4
MAG_BASE = 0
MANT_BASE = MAG_BASE + _MAG_KINDS * _UNARY
MANT_SIZE = (MAX_BITS + 1) * MAX_BITS
SIGN_BASE = MANT_BASE + MANT_SIZE
SIGN_SIZE = 3 * 4
FLAG_BASE = SIGN_BASE + SIGN_SIZE
FLAG_SIZE = 4
MODELS = FLAG_BASE + FLAG_SIZE

# state fields
_LOW, _RANGE, _CACHE, _CSIZE, _POS, _CODE = 0, 1, 2, 3, 4, 5


@njit(cache=True, nogil=True, inline="always")
def _shift_low(st, out):
    low = st[_LOW]
    if low < 0xFF000000 or low > MASK32:
        carry = low >> 32
        temp = st[_CACHE]
        while True:
            pos = st[_POS]
            if pos < len(out):
                out[pos] = (temp + carry) & 0xFF
            st[_POS] = pos + 1
            temp = 0xFF
            st[_CSIZE] -= 1
            if st[_CSIZE] == 0:
                break
        st[_CACHE] = (low >> 24) & 0xFF
    st[_CSIZE] += 1
    st[_LOW] = (low & 0x00FFFFFF) << 8


@njit(cache=True, nogil=True, inline="always")
def _next_byte(st, data):
    pos = st[_POS]
    st[_POS] = pos + 1
    return data[pos] if pos < len(data) else 0


@njit(cache=True, nogil=True)
def _bit(st, buf, models, ctx, bit, decoding):
    """Code ``bit`` (encoding) or return the decoded bit, with the adaptive model ``ctx``."""
    p = models[2 * ctx]
    bound = (st[_RANGE] >> PROB_BITS) * p
    if decoding:
        if st[_CODE] < bound:
            st[_RANGE] = bound
            bit = 0
        else:
            st[_CODE] -= bound
            st[_RANGE] -= bound
            bit = 1
        while st[_RANGE] < TOP:
            st[_RANGE] = (st[_RANGE] << 8) & MASK32
            st[_CODE] = ((st[_CODE] << 8) | _next_byte(st, buf)) & MASK32
    else:
        if bit == 0:
            st[_RANGE] = bound
        else:
            st[_LOW] += bound
            st[_RANGE] -= bound
        while st[_RANGE] < TOP:
            st[_RANGE] = (st[_RANGE] << 8) & MASK32
            _shift_low(st, buf)
    count = models[2 * ctx + 1]
    rate = min(count + 1, RATE_LIMIT)
    if bit == 0:
        p += (PROB_ONE - p) >> rate
    else:
        p -= p >> rate
    models[2 * ctx] = p
    if count < RATE_LIMIT:
        models[2 * ctx + 1] = count + 1
    return bit


@njit(cache=True, nogil=True, inline="always")
def _bit_length(value):
    k = 0
    while value > 0:
        value >>= 1
        k += 1
    return k


@njit(cache=True, nogil=True)
def _magnitude(st, buf, models, kind, value, decoding):
    """Code a magnitude ``value >= 0`` in the unary context set ``kind``; return it."""
    k = 0 if decoding else _bit_length(value)
    base = MAG_BASE + kind * _UNARY
    if decoding:
        while k < MAX_BITS and _bit(st, buf, models, base + k, 0, True):
            k += 1
    else:
        for i in range(k):
            _bit(st, buf, models, base + i, 1, False)
        if k < MAX_BITS:
            _bit(st, buf, models, base + k, 0, False)
    if k <= 1:
        return k
    out = 1
    mbase = MANT_BASE + k * MAX_BITS
    for i in range(k - 2, -1, -1):
        position = k - 2 - i
        ctx = mbase + min(position, MAX_BITS - 1)
        if position >= 2:  # below the two leading bits: nearly uniform, one shared model
            ctx = mbase + 2
        bit = _bit(st, buf, models, ctx, (value >> i) & 1, decoding)
        out = (out << 1) | bit
    return out


@njit(cache=True, nogil=True)
def _signed(st, buf, models, kind, sign_ctx, value, decoding):
    magnitude = _magnitude(st, buf, models, kind, abs(value), decoding)
    if magnitude == 0:
        return 0
    negative = _bit(st, buf, models, SIGN_BASE + sign_ctx, 1 if value < 0 else 0, decoding)
    return -magnitude if negative else magnitude


@njit(cache=True, nogil=True, inline="always")
def _class(k):
    return min(k, _CLASSES - 1)


@njit(cache=True, nogil=True)
def _code_set(buf, st, lattice, counts, closed, repeated, closed_mode, d, order, decoding):
    """Code (or decode into ``lattice``, ``counts``, ``closed``, ``repeated``) a whole set.

    ``lattice`` holds the vertices of all curves, one after another, ``(total, d)`` int64.
    ``order`` is the predictor: each step is predicted as ``(order * previous step) >> 1``
    (0: the previous vertex; 2: a straight continuation; 1: half way), and the residual coded.
    Returns the number of vertices (decoding: those written; -1 if the stream declares more
    than ``lattice`` holds).
    """
    models = np.empty(2 * MODELS, dtype=np.int64)
    for i in range(MODELS):
        models[2 * i] = PROB_HALF
        models[2 * i + 1] = 0
    start = np.zeros(d, dtype=np.int64)
    previous_step = np.zeros(d, dtype=np.int64)
    previous_residual = np.zeros(d, dtype=np.int64)
    at = 0
    limit = len(lattice)
    for c in range(len(counts)):
        if closed_mode == 2:
            closed[c] = _bit(st, buf, models, FLAG_BASE, closed[c], decoding)
        if closed[c]:
            repeated[c] = _bit(st, buf, models, FLAG_BASE + 1, repeated[c], decoding)
        m = _magnitude(st, buf, models, _KIND_COUNT, counts[c] - 1, decoding) + 1
        if decoding:
            if m > limit - at:
                return -1
            counts[c] = m
        # the first vertex: a step from the previous curve's first vertex
        for j in range(d):
            value = 0 if decoding else lattice[at, j] - start[j]
            value = _signed(st, buf, models, _KIND_START, 0, value, decoding)
            if decoding:
                lattice[at, j] = start[j] + value
            start[j] = lattice[at, j]
        length_class = _class(_bit_length(0))
        for j in range(d):
            previous_step[j] = 0
            previous_residual[j] = 0
        for v in range(at + 1, at + m):
            first_class = 0
            largest = 0
            for j in range(d):
                if j == 0:
                    kind = _FIRST_COORD + length_class
                else:
                    kind = _OTHER_COORD + length_class * 4 + min(first_class, 3)
                r = previous_residual[j]
                sign_ctx = 1 + (r > 0) - (r < 0) + 3 * min(j, 3)
                predicted = lattice[v - 1, j] + ((order * previous_step[j]) >> 1)
                value = 0 if decoding else lattice[v, j] - predicted
                value = _signed(st, buf, models, kind, sign_ctx, value, decoding)
                if decoding:
                    lattice[v, j] = predicted + value
                previous_step[j] = lattice[v, j] - lattice[v - 1, j]
                previous_residual[j] = value
                k = _bit_length(abs(value))
                if j == 0:
                    # how far the first coordinate's size is below the segment's (0 … 3)
                    first_class = max(0, min(3, length_class - k + 1))
                largest = max(largest, abs(value))
            length_class = _class(_bit_length(largest))
        at += m
    return at


@njit(cache=True, nogil=True)
def _finish_stream(st, out):
    """Flush with the fewest bytes: pick the value in [low, low + range) with most low zeros."""
    low = st[_LOW]
    high = low + st[_RANGE] - 1
    for shift in range(32, -1, -1):
        candidate = (high >> shift) << shift
        if candidate >= low:
            st[_LOW] = candidate
            break
    for _ in range(5):
        _shift_low(st, out)


def encode_set(
    lattice: np.ndarray,
    counts: np.ndarray,
    closed: np.ndarray,
    repeated: np.ndarray,
    closed_mode: int,
    order: int = 0,
) -> bytes:
    """The range-coded stream of a set of lattice curves (see :func:`decode_set`)."""
    d = lattice.shape[1]
    capacity = 64 + 16 * lattice.size + 8 * len(counts)
    out = np.zeros(capacity, dtype=np.uint8)
    st = np.array([0, MASK32, 0, 1, 0, 0], dtype=np.int64)
    _code_set(
        out,
        st,
        np.ascontiguousarray(lattice, dtype=np.int64),
        np.ascontiguousarray(counts, dtype=np.int64),
        np.ascontiguousarray(closed, dtype=np.int64),
        np.ascontiguousarray(repeated, dtype=np.int64),
        closed_mode,
        d,
        order,
        False,
    )
    _finish_stream(st, out)
    size = int(st[_POS])
    if size > capacity or out[0] != 0:
        msg = "the curve coder overflowed its buffer"  # cannot happen: 16 B per value is ample
        raise RuntimeError(msg)
    data = bytes(out[1:size])  # the first byte of an LZMA-style stream is always 0
    return data.rstrip(b"\0")  # the decoder reads zeros past the end


def decode_set(
    data: bytes,
    count: int,
    d: int,
    closed_mode: int,
    all_closed: bool,
    max_vertices: int,
    order: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Decode ``count`` curves of dimension ``d``: (lattice, counts, closed, repeated).

    None if the stream declares more than ``max_vertices`` vertices in all.
    """
    buf = np.frombuffer(bytes(data), dtype=np.uint8).copy()  # one compiled signature
    st = np.array([0, MASK32, 0, 1, 0, 0], dtype=np.int64)
    code = 0
    for _ in range(4):
        code = (code << 8) | (int(buf[st[_POS]]) if st[_POS] < len(buf) else 0)
        st[_POS] += 1
    st[_CODE] = code
    lattice = np.zeros((max_vertices, d), dtype=np.int64)
    counts = np.zeros(count, dtype=np.int64)
    closed = np.full(count, 1 if all_closed else 0, dtype=np.int64)
    repeated = np.zeros(count, dtype=np.int64)
    total = _code_set(buf, st, lattice, counts, closed, repeated, closed_mode, d, order, True)
    if total < 0:
        return None
    return lattice[:total], counts, closed, repeated


# --- the encoder's geometry: simplification against quantized segments, and the check --------


@njit(cache=True, nogil=True)
def _segment_distance(points, k, nodes, a, b, d):
    """Distance from ``points[k]`` to the segment ``nodes[a]``–``nodes[b]``."""
    length2 = 0.0
    dot = 0.0
    for j in range(d):
        ab = nodes[b, j] - nodes[a, j]
        length2 += ab * ab
        dot += (points[k, j] - nodes[a, j]) * ab
    t = 0.0
    if length2 > 0.0:
        t = min(1.0, max(0.0, dot / length2))
    gap2 = 0.0
    for j in range(d):
        g = points[k, j] - (nodes[a, j] + t * (nodes[b, j] - nodes[a, j]))
        gap2 += g * g
    return np.sqrt(gap2)


@njit(cache=True, nogil=True)
def simplify_set(points, decoded, offsets, closed, tolerance, chunk):
    """Douglas–Peucker on each curve, distances measured to the *decoded* (lattice) segments.

    ``points`` are the originals and ``decoded`` each point's lattice position, both
    ``(total, d)``; curve ``c`` is rows ``offsets[c]:offsets[c + 1]``.  Vertices every
    ``chunk`` points are kept, so the cost is at most ``chunk`` per point (linear), whatever
    the shape.  Returns a mask of the kept points.
    """
    total, d = points.shape
    keep = np.zeros(total, dtype=np.bool_)
    stack = np.empty((2 * chunk + 8, 2), dtype=np.int64)
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        keep[first] = True
        if not (closed[c] and n > 2):
            keep[stop - 1] = True
        ring = n + 1 if closed[c] and n > 2 else n  # index n is point 0 again
        a = 0
        while a < ring - 1:
            b = min(a + chunk, ring - 1)
            keep[first + (b % n)] = True
            top = 0
            stack[0, 0], stack[0, 1] = a, b
            top = 1
            while top > 0:
                top -= 1
                lo, hi = stack[top, 0], stack[top, 1]
                if hi - lo < 2:
                    continue
                worst, where = -1.0, lo + 1
                for k in range(lo + 1, hi):
                    gap = _segment_distance(
                        points, first + k, decoded, first + lo, first + (hi % n), d
                    )
                    if gap > worst:
                        worst, where = gap, k
                if worst > tolerance:
                    keep[first + where] = True
                    stack[top, 0], stack[top, 1] = lo, where
                    stack[top + 1, 0], stack[top + 1, 1] = where, hi
                    top += 2
            a = b
    return keep


@njit(cache=True, nogil=True)
def check_set(points, offsets, closed, keep, decoded):
    """The largest deviation, both ways, of each curve (an upper bound of the true one).

    ``decoded`` holds the decoded vertices (the kept points, in order, as the decoder gives
    them).  Each original point is measured to the decoded segment between the kept points
    around it (one segment of the decoded polyline: the true distance is no larger), each
    decoded vertex to the original point it stands for (ditto).
    """
    d = points.shape[1]
    worst = np.zeros(len(offsets) - 1)
    at = 0
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        start = at
        last_vertex = at
        last_index = 0
        largest = 0.0
        for i in range(n):
            if keep[first + i]:
                gap2 = 0.0
                for j in range(d):
                    g = decoded[at, j] - points[first + i, j]
                    gap2 += g * g
                largest = max(largest, np.sqrt(gap2))
                if i > 0:
                    for k in range(last_index + 1, i):
                        largest = max(
                            largest,
                            _segment_distance(points, first + k, decoded, last_vertex, at, d),
                        )
                last_vertex, last_index = at, i
                at += 1
        if closed[c] and n > 2:
            for k in range(last_index + 1, n):
                largest = max(
                    largest, _segment_distance(points, first + k, decoded, last_vertex, start, d)
                )
        worst[c] = largest
    return worst
