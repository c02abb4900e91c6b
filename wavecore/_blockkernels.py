"""Compiled loops of the code-block coder (context coder versions 4, 6, 7 and 8): see
``blockcoder.py``.

One binary range coder (LZMA's, with 15-bit adaptive probabilities) codes every block from
start to end inside one compiled call that releases the GIL; a call codes a whole span of
blocks, so the Python side runs one call per thread, never one per block or per symbol.  All
arithmetic is on integers, so every machine writes and reads the same bits.

Encoder and decoder run the same function (``_code_block``), so their contexts cannot drift
apart: when decoding, ``flat`` is filled as the block is read and the bit functions return the
decoded bit instead of coding the given one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._blockpriors import PRIORS

# Probabilities of a 0 bit, in units of 2**-PROB_BITS, adapted after every bit with a rate
# that starts fast (a count-based estimate) and settles at 2**-RATE_LIMIT.
PROB_BITS = 15
PROB_ONE = 1 << PROB_BITS
RATE_LIMIT = 6
COUNT_CAP = 1 << RATE_LIMIT
TOP = 1 << 24
MASK32 = (1 << 32) - 1

# Context layout of the model arrays (one set per block, reset at its start).
LOCAL_CLASSES = 14
EXTERNAL_CLASSES = 4
UNARY_INDICES = 8
MAX_CLASS = 34  # bit length of a magnitude; int32 values and approximation residuals fit
ZERO_BASE = 0
ZERO_SIZE = 2 * LOCAL_CLASSES * EXTERNAL_CLASSES
UNARY_BASE = ZERO_BASE + ZERO_SIZE
UNARY_SIZE = 2 * (LOCAL_CLASSES + 1) * UNARY_INDICES
MANTISSA_BASE = UNARY_BASE + UNARY_SIZE
MANTISSA_SIZE = 2 * 2 * (MAX_CLASS + 1)
SIGN_BASE = MANTISSA_BASE + MANTISSA_SIZE
SIGN_SIZE = 4 * 9
TILE_BASE = SIGN_BASE + SIGN_SIZE
TILE_SIZE = 6
#: Version 7: the zero flags of ``cH`` and ``cV`` under the *directional* neighbour sum.
ZERO_DIR_BASE = TILE_BASE + TILE_SIZE
ZERO_DIR_SIZE = LOCAL_CLASSES * EXTERNAL_CLASSES
CONTEXTS = ZERO_DIR_BASE + ZERO_DIR_SIZE
#: Version 6: the parent band's magnitude (the same orientation and channel one level coarser,
#: at ``(i // 2, j // 2)``), times this, joins the other bands' sum ``e`` of a detail value's
#: zero flag and bit-length contexts.  Callers give each plane's parent plane (``parents``,
#: -1 for none: every plane of version 4).
PARENT_WEIGHT = 2
#: Version 7: the directional neighbour sum of ``cH`` (along its rows: ``W``, ``WW``) and ``cV``
#: (along its columns: ``N``, ``NN``), ``ALONG·|a| + ACROSS·|c| + DIAGONAL·(|NW| + |NE|) +
#: ALONG2·|a2|`` with ``a`` the neighbour along the band, ``c`` the one across and ``a2`` the
#: second one along.  Callers say which planes use it (``along``: 1 along rows, 2 along
#: columns, 0 none: every plane of versions 4 and 6).
ALONG, ACROSS, DIAGONAL, ALONG2 = 8, 2, 1, 2
#: Version 7: once a plane's two running costs differ by more than this (1/256 bits: 32 bits),
#: they stop growing, so the choice is settled for the rest of the plane of the block, and
#: only the model chosen is read and adapted (half the flags of the tuning pictures, for
#: 0.01-0.04 % of the gain).
SETTLE = 8192
#: Detail planes first say, per ``TILE × TILE`` tile of the block, whether it holds a nonzero
#: value; the positions of empty tiles are neither coded nor visited.
TILE = 8

#: ``LOCAL_CLASS[s]``: the class of a weighted neighbour sum ``s`` (half-octave steps).
_LOCAL_EDGES = np.array([0, 2, 4, 6, 9, 13, 19, 27, 39, 55, 79, 111, 160], dtype=np.int64)
LOCAL_CLASS = np.searchsorted(_LOCAL_EDGES, np.arange(256), side="left").astype(np.int64)
#: ``COST[p >> 5]``: the cost of a bit whose model gave it probability ``p`` (of 2**15), in
#: 1/256 bits, ``round(-256 log2((32 k + 16) / 32768))``: version 7's running costs.  No entry
#: lies within 2e-4 of a rounding boundary (log2's error is some 1e-12 here), so every machine
#: builds the same table.
COST = np.rint(-256.0 * np.log2((32.0 * np.arange(1024) + 16.0) / 32768.0)).astype(np.int64)
#: ``RATE[n]``: the adaptation shift after ``n`` observations of a context (1, 2, 2, 3, ...).
RATE = np.minimum(
    np.array([int(n + 1).bit_length() for n in range(COUNT_CAP + 1)], dtype=np.int64), RATE_LIMIT
)

# Plane descriptor columns (``planes``): where the plane lives in ``flat`` and its context.
P_OFFSET, P_ROWS, P_COLS, P_KIND, P_SIB1, P_SIB2, P_LUMA, P_ORIENT = range(8)
PLANE_FIELDS = 8
# Block descriptor columns (``blocks``): planes [lo, hi) of its level, its region, and its
# level class (version 8's initial models: 0 for the finest level, 1 for the next, 2 for the
# coarser ones and the approximation).
B_PLANE_LO, B_PLANE_HI, B_ROW0, B_COL0, B_ROW1, B_COL1, B_LEVEL = range(7)
BLOCK_FIELDS = 7
LEVEL_CLASSES = 3


# The range coder.  Its state lives in local variables of the block loops (helpers take it and
# return it, and are inlined): kept in an array it cost five times as much per bit.  The
# encoder's per-bit helper takes and returns scalars only: an array handed to a helper inlined
# into a loop is a new reference to it, and numba counted it up and down (two atomic calls)
# at every bit; its model is read and written at the call site, and ``out`` is handed to
# ``_shift_low`` only when ``rng`` falls below ``TOP`` (once per byte written).  That took a
# fifth off the encoder's time, with the same bits.  Each encoder site reads:
#
#     low, rng, models[ctx] = _code_bit(low, rng, models[ctx], bit)
#     while rng < TOP:
#         rng <<= 8
#         low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
#
# and each decoder site, the same way (``_split_bit``, ``data`` handed to ``_shift_code`` once
# per byte read).  The decoder compiled to the same refcounts before and after (numba had
# pruned them there): its gain came from ``_neighbour_sum`` instead, the six neighbours read at
# the call site.
#
# Numba's pruning removes the pair around an inlined helper's array only when the array's
# last use in the helper is not inside a branch (then the decrement sits at one place that
# follows the increment on every path).  ``_shift_low`` therefore ends with an unconditional
# store (the byte it read back when it has none to write); it was counted at every byte
# written.  The edge coefficients' neighbours (first two rows and columns, last column) are
# read at the call site too, each under its own condition.  Indices known to be non-negative
# go through ``_u``: numba wraps a negative signed index around (a compare, an add and a
# select at every read), and none of these can be negative.  Together with the two changes
# above, encode_span and decode_span took 0.8-0.88x the CPU time, with the same bytes.


@njit(nogil=True, cache=True, inline="always")
def _u(i):
    """A non-negative index as unsigned, so that numba indexes without its wrap-around of
    negative indices (an unsigned index is taken as it is)."""
    return np.uint64(i)


@njit(nogil=True, cache=True, inline="always")
def _shift_low(low, cache, pending, pos, out):
    """LZMA's carry-propagating output of the top byte of ``low``; ``pos`` counts on past the
    end of ``out`` (the caller then grows ``out`` and codes the block again).

    The cached byte goes to ``out[pos]``, and the ``pending - 1`` bytes of 0xFF that waited for
    a carry after it.  The store at the end is unconditional (``out[at]`` as it was when no
    byte is due, or ``pos`` is past the end) so that numba can drop its reference count.
    """
    last = out.size - 1
    at = min(pos, last)
    byte = out[_u(at)]
    if low < 0xFF000000 or low > MASK32:
        carry = low >> 32
        if pos <= last:
            byte = (cache + carry) & 0xFF
        if pending > 1:
            for k in range(pos + 1, min(pos + pending, last + 1)):
                out[_u(k)] = (0xFF + carry) & 0xFF
        pos += pending
        pending = 0
        cache = (low >> 24) & 0xFF
    pending += 1
    low = (low & 0x00FFFFFF) << 8
    out[_u(at)] = byte
    return low, cache, pending, pos


@njit(nogil=True, cache=True, inline="always")
def _adapted(p, n, bit):
    """A context's model (probability of a 0 and count) after ``bit``: the probability moves
    towards the bit seen, by ``2**-RATE[n]``."""
    shift = RATE[n]
    if bit == 0:
        p += (PROB_ONE - p) >> shift
    else:
        p -= p >> shift
    if n < COUNT_CAP:
        n += 1
    return (p << 8) | n


@njit(nogil=True, cache=True, inline="always")
def _code_bit(low, rng, model, bit):
    """One adaptive bit into the coder's ``low`` and ``rng`` (before normalization), and the
    context's model after it."""
    p = model >> 8
    bound = (rng >> PROB_BITS) * p
    if bit == 0:
        rng = bound
    else:
        low += bound
        rng -= bound
    return low, rng, _adapted(p, model & 0xFF, bit)


@njit(nogil=True, cache=True, inline="always")
def _split_bit(code, rng, model):
    """The decoder's :func:`_code_bit`: the coder's ``code`` and ``rng`` (before
    normalization), the context's model after the bit, and the bit."""
    p = model >> 8
    bound = (rng >> PROB_BITS) * p
    if code < bound:
        rng = bound
        bit = 0
    else:
        code -= bound
        rng -= bound
        bit = 1
    return code, rng, _adapted(p, model & 0xFF, bit), bit


@njit(nogil=True, cache=True, inline="always")
def _shift_code(code, pos, end, data):
    """The next byte of ``data[:end]`` (0 past its end) into ``code``."""
    byte = np.int64(data[_u(pos)]) if pos < end else np.int64(0)
    return ((code << 8) | byte) & MASK32, pos + 1


@njit(nogil=True, cache=True, inline="always")
def _decode_raw(code, rng, pos, end, data, count):
    value = np.int64(0)
    for _ in range(count):
        rng >>= 1
        bit = 0
        if code >= rng:
            code -= rng
            bit = 1
        value = (value << 1) | bit
        while rng < TOP:
            rng <<= 8
            code, pos = _shift_code(code, pos, end, data)
    return code, rng, pos, value


#: ``BIT_LENGTH[v]``: the bit length of ``v`` below 256, looked up (most magnitudes are).
BIT_LENGTH = np.array([int(v).bit_length() for v in range(256)], dtype=np.int64)


@njit(nogil=True, cache=True, inline="always")
def _bit_length(value):
    n = np.int64(0)
    while value >= 256:
        value >>= 8
        n += 8
    return n + BIT_LENGTH[value]


@njit(nogil=True, cache=True, inline="always")
def _sign_of(x):
    return np.int64((x > 0) - (x < 0))


# The contexts, shared by the encoder and the decoder (so that they cannot drift apart).


@njit(nogil=True, cache=True, inline="always")
def _neighbour_sum(w, n, nw, ne, ww, nn):
    """``4 (|W| + |N|) + 2 (|NW| + |NE|) + |WW| + |NN|`` from the six causal neighbours inside
    the block, read at the call site (0 for those outside it): an array handed to an inlined
    helper with branches is counted up and down at every value."""
    return (
        4 * (abs(np.int64(w)) + abs(np.int64(n)))
        + 2 * (abs(np.int64(nw)) + abs(np.int64(ne)))
        + abs(np.int64(ww))
        + abs(np.int64(nn))
    )


@njit(nogil=True, cache=True, inline="always")
def _sums(w, n, nw, ne, ww, nn, along, directional):
    """A detail value's symmetric neighbour sum (:func:`_neighbour_sum`) and, when
    ``directional``, version 7's directional one (``along`` 1: along rows, ``cH``; 2: along
    columns, ``cV``; else the symmetric sum again), from the six causal neighbours read at the
    call site."""
    w, n, nw, ne = abs(np.int64(w)), abs(np.int64(n)), abs(np.int64(nw)), abs(np.int64(ne))
    ww, nn = abs(np.int64(ww)), abs(np.int64(nn))
    s = 4 * (w + n) + 2 * (nw + ne) + ww + nn
    if not directional:
        return s, s
    if along == 1:
        return s, ALONG * w + ACROSS * n + DIAGONAL * (nw + ne) + ALONG2 * ww
    if along == 2:
        return s, ALONG * n + ACROSS * w + DIAGONAL * (nw + ne) + ALONG2 * nn
    return s, s


@njit(nogil=True, cache=True, inline="always")
def _zero_context(s, sd, e, zero_base, cs, cd, directional):
    """A value's zero-flag context under its symmetric sum ``s``; when ``directional``
    (version 7), the directional sum ``sd``'s (else the same context again); whether the flag
    is coded under the latter (its running cost ``cd`` in this plane of the block is below the
    symmetric one's, ``cs``); and the sum its bit length's context then reads."""
    external = _external_class(e)
    ctx = zero_base + LOCAL_CLASS[min(s, 255)] * EXTERNAL_CLASSES + external
    if not directional:
        return ctx, ctx, False, s
    ctx_d = ZERO_DIR_BASE + LOCAL_CLASS[min(sd, 255)] * EXTERNAL_CLASSES + external
    chosen = cd < cs
    return ctx, ctx_d, chosen, sd if chosen else s


@njit(nogil=True, cache=True, inline="always")
def _track(cs, cd, model_s, model_d, chosen, bit):
    """Version 7, after a zero flag coded under one of its two models (both as they were
    before it), while the choice is not settled: both running costs grown by what each model
    would have cost, and the model not coded under adapted too."""
    ps = model_s >> 8
    pd = model_d >> 8
    if bit:
        ps, pd = PROB_ONE - ps, PROB_ONE - pd
    cs += COST[ps >> 5]
    cd += COST[pd >> 5]
    other = model_s if chosen else model_d
    return cs, cd, _adapted(other >> 8, other & 0xFF, bit)


@njit(nogil=True, cache=True, inline="always")
def _row_of(plane_info, i):
    """Where row ``i`` of another plane of the block starts in ``flat`` (-1: no such row), and
    that plane's width."""
    offset, rows, cols = plane_info
    if offset < 0 or i >= rows:
        return np.int64(-1), cols
    return offset + i * cols, cols


#: ``EXTERNAL_CLASS[min(e, 12)]``: the class of a weighted sum ``e`` of the other bands
#: (0; 1-3; 4-11; 12 and more), looked up rather than branched on.
EXTERNAL_CLASS = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2, 2, 2, 2, 3], dtype=np.int64)


@njit(nogil=True, cache=True, inline="always")
def _external_class(e):
    return EXTERNAL_CLASS[min(e, 12)]


@njit(nogil=True, cache=True, inline="always")
def _predict(flat, at, cols, i, j, r0, c0):
    """The approximation's prediction (LOCO-I's median edge detector) from decoded values."""
    a = np.int64(flat[_u(at - 1)]) if j > c0 else np.int64(0)
    b = np.int64(flat[_u(at - cols)]) if i > r0 else np.int64(0)
    if i > r0 and j > c0:
        c = np.int64(flat[_u(at - cols - 1)])
        if c >= max(a, b):
            return min(a, b)
        if c <= min(a, b):
            return max(a, b)
        return a + b - c
    return a + b  # one of them is zero (or both, at the block's corner)


@njit(nogil=True, cache=True, inline="always")
def _plane_info(planes, p):
    if p < 0:
        return (np.int64(-1), np.int64(0), np.int64(0))
    return (planes[p, P_OFFSET], planes[p, P_ROWS], planes[p, P_COLS])


@njit(nogil=True, cache=True, inline="always")
def _tile_grid(block, planes):
    """Tiles per row of the block's tile grid, and tiles per plane (anchored at its corner).

    The grid covers only the part of the block that its planes reach, not the nominal block:
    a 1-D block is 16 384 coefficients wide, so a short curve of many dimensions (one plane
    each) needed 2 048 flags per plane however short it was, gigabytes for a crafted header
    (decoding allocates the flags before it finds the payload corrupt).  A plane's flags keep
    their (row, column) positions, so the contexts and the coded bits are the same.
    """
    r0, c0 = block[B_ROW0], block[B_COL0]
    r1, c1 = r0 + 1, c0 + 1
    for p in range(block[B_PLANE_LO], block[B_PLANE_HI]):
        r1 = max(r1, min(block[B_ROW1], planes[p, P_ROWS]))
        c1 = max(c1, min(block[B_COL1], planes[p, P_COLS]))
    grid_rows = (r1 - r0 + TILE - 1) // TILE
    grid_cols = (c1 - c0 + TILE - 1) // TILE
    return grid_cols, grid_rows * grid_cols


@njit(nogil=True, cache=True, inline="always")
def _tile_context(flags, base, tr, tc, grid_cols, per_plane, block, planes, p):
    """A tile flag's context: how many of its left and upper tiles hold a value (0-2), and
    whether the same tile of an earlier orientation or of the first channel does."""
    at = base + tr * grid_cols + tc
    near = 0
    if tc > 0:
        near += flags[_u(at - 1)]
    if tr > 0:
        near += flags[_u(at - grid_cols)]
    other = 0
    for slot in (P_SIB1, P_SIB2, P_LUMA):
        q = planes[p, slot]
        if q >= 0 and flags[(q - block[B_PLANE_LO]) * per_plane + tr * grid_cols + tc]:
            other = 1
    return TILE_BASE + near * 2 + other


@njit(nogil=True, cache=True, inline="always")
def _encode_rows(
    flat,
    out,
    models,
    scratch,
    flags,
    low,
    rng,
    cache,
    pending,
    pos,
    approx,
    offset,
    cols,
    r0,
    r1,
    c0,
    c1,
    base,
    grid_cols,
    sib1,
    sib2,
    luma,
    parent,
    sign_base,
    zero_base,
    unary_base,
    mantissa,
    along,
    directional,
):
    """The values of one plane of a block, row by row (the tiles flagged empty skipped).

    Inlined at three call sites (the approximation; details; version 7's ``cH`` and ``cV``,
    ``directional`` True), so that each copy is compiled without the other kinds' branches:
    with one copy for all details, versions 4 and 6 took 8-12 % more time (the third copy
    doubles the compile time of the spans, 51 to 107 s, once per machine)."""
    width = c1 - c0
    tile_cols = (c1 - c0 + TILE - 1) // TILE
    cs = cd = np.int64(0)  # version 7's running costs of the plane's zero flags, grown
    tracking = directional  # until they differ by more than SETTLE
    for i in range(r0, r1):
        row = offset + i * cols
        srow = (i - r0) * width - c0
        tile_row = base + ((i - r0) // TILE) * grid_cols
        s1, s1c = _row_of(sib1, i)
        s2, s2c = _row_of(sib2, i)
        y0, y0c = _row_of(luma, i)
        pr, prc = _row_of(parent, i >> 1)
        # The columns below which each other band has a value on this row (0: none), so that
        # a value costs one comparison per band, read here rather than in a helper.
        l1 = s1c if s1 >= 0 else 0
        l2 = s2c if s2 >= 0 else 0
        ly = y0c if y0 >= 0 else 0
        lp = 2 * prc if pr >= 0 else 0
        for tc in range(tile_cols):
            if not approx and flags[_u(tile_row + tc)] == 0:
                continue
            for j in range(c0 + tc * TILE, min(c0 + (tc + 1) * TILE, c1)):
                at = row + j
                if approx:
                    if i > r0 + 1 and c0 + 1 < j < c1 - 1:
                        up = srow + j - width
                        s = _neighbour_sum(
                            scratch[_u(srow + j - 1)],
                            scratch[_u(up)],
                            scratch[_u(up - 1)],
                            scratch[_u(up + 1)],
                            scratch[_u(srow + j - 2)],
                            scratch[_u(up - width)],
                        )
                    else:
                        here = srow + j
                        up = here - width
                        s = _neighbour_sum(
                            scratch[_u(here - 1)] if j > c0 else 0,
                            scratch[_u(up)] if i > r0 else 0,
                            scratch[_u(up - 1)] if i > r0 and j > c0 else 0,
                            scratch[_u(up + 1)] if i > r0 and j + 1 < c1 else 0,
                            scratch[_u(here - 2)] if j > c0 + 1 else 0,
                            scratch[_u(up - width)] if i > r0 + 1 else 0,
                        )
                    sd = s
                    e = np.int64(0)
                    value = np.int64(flat[_u(at)]) - _predict(flat, at, cols, i, j, r0, c0)
                else:
                    if i > r0 + 1 and c0 + 1 < j < c1 - 1:
                        up = at - cols
                        s, sd = _sums(
                            flat[_u(at - 1)],
                            flat[_u(up)],
                            flat[_u(up - 1)],
                            flat[_u(up + 1)],
                            flat[_u(at - 2)],
                            flat[_u(up - cols)],
                            along,
                            directional,
                        )
                    else:
                        here = at
                        up = here - cols
                        s, sd = _sums(
                            flat[_u(here - 1)] if j > c0 else 0,
                            flat[_u(up)] if i > r0 else 0,
                            flat[_u(up - 1)] if i > r0 and j > c0 else 0,
                            flat[_u(up + 1)] if i > r0 and j + 1 < c1 else 0,
                            flat[_u(here - 2)] if j > c0 + 1 else 0,
                            flat[_u(up - cols)] if i > r0 + 1 else 0,
                            along,
                            directional,
                        )
                    e = np.int64(0)
                    if j < l1:
                        e += 2 * abs(np.int64(flat[_u(s1 + j)]))
                    if j < l2:
                        e += 2 * abs(np.int64(flat[_u(s2 + j)]))
                    if j < ly:
                        e += 4 * abs(np.int64(flat[_u(y0 + j)]))
                    if j < lp:  # version 6: the parent band
                        e += PARENT_WEIGHT * abs(np.int64(flat[_u(pr + (j >> 1))]))
                    value = np.int64(flat[_u(at)])
                magnitude = abs(value)
                nonzero = 1 if magnitude else 0
                ctx, ctx_d, chosen, su = _zero_context(s, sd, e, zero_base, cs, cd, directional)
                coded = ctx_d if chosen else ctx
                model_s, model_d = models[_u(ctx)], models[_u(ctx_d)]
                low, rng, models[_u(coded)] = _code_bit(low, rng, models[_u(coded)], nonzero)
                while rng < TOP:
                    rng <<= 8
                    low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
                if tracking:
                    cs, cd, models[_u(ctx + ctx_d - coded)] = _track(
                        cs, cd, model_s, model_d, chosen, nonzero
                    )
                    tracking = abs(cs - cd) <= SETTLE
                if approx:
                    scratch[_u(srow + j)] = magnitude
                if magnitude == 0:
                    continue
                # The bit length in unary, then the bits below the leading one: the top two
                # under adaptive models, the rest raw.
                unary = unary_base + (LOCAL_CLASS[min(su + e, 255)] >> 1) * UNARY_INDICES
                klass = _bit_length(magnitude)
                for k in range(1, klass + 1):
                    more = 1 if klass > k else 0
                    at_ctx = unary + min(k - 1, UNARY_INDICES - 1)
                    low, rng, models[_u(at_ctx)] = _code_bit(low, rng, models[_u(at_ctx)], more)
                    while rng < TOP:
                        rng <<= 8
                        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
                below = klass - 1
                top = min(below, 2)
                for position in range(top):
                    bit = (magnitude >> (below - 1 - position)) & 1
                    at_ctx = mantissa + position * (MAX_CLASS + 1) + klass
                    low, rng, models[_u(at_ctx)] = _code_bit(low, rng, models[_u(at_ctx)], bit)
                    while rng < TOP:
                        rng <<= 8
                        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
                if below > top:
                    rest = below - top
                    for k in range(rest - 1, -1, -1):  # equiprobable, the highest first
                        rng >>= 1
                        if (magnitude >> k) & 1:
                            low += rng
                        while rng < TOP:
                            rng <<= 8
                            low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
                sw = sn = np.int64(0)  # residual signs: one context
                if not approx:
                    if j > c0:
                        sw = _sign_of(flat[_u(at - 1)])
                    if i > r0:
                        sn = _sign_of(flat[_u(at - cols)])
                at_ctx = sign_base + (sw + 1) * 3 + sn + 1
                low, rng, models[_u(at_ctx)] = _code_bit(
                    low, rng, models[_u(at_ctx)], 1 if value < 0 else 0
                )
                while rng < TOP:
                    rng <<= 8
                    low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
    return low, rng, cache, pending, pos


@njit(nogil=True, cache=True, inline="always")
def _decode_rows(
    data,
    end,
    flat,
    models,
    scratch,
    flags,
    code,
    rng,
    pos,
    approx,
    offset,
    cols,
    r0,
    r1,
    c0,
    c1,
    base,
    grid_cols,
    sib1,
    sib2,
    luma,
    parent,
    sign_base,
    zero_base,
    unary_base,
    mantissa,
    along,
    directional,
):
    """The decoder's :func:`_encode_rows`; the last value is 1 for a corrupt block."""
    width = c1 - c0
    tile_cols = (c1 - c0 + TILE - 1) // TILE
    cs = cd = np.int64(0)  # version 7's running costs of the plane's zero flags, grown
    tracking = directional  # until they differ by more than SETTLE
    for i in range(r0, r1):
        row = offset + i * cols
        srow = (i - r0) * width - c0
        tile_row = base + ((i - r0) // TILE) * grid_cols
        s1, s1c = _row_of(sib1, i)
        s2, s2c = _row_of(sib2, i)
        y0, y0c = _row_of(luma, i)
        pr, prc = _row_of(parent, i >> 1)
        # The columns below which each other band has a value on this row (0: none), so that
        # a value costs one comparison per band, read here rather than in a helper.
        l1 = s1c if s1 >= 0 else 0
        l2 = s2c if s2 >= 0 else 0
        ly = y0c if y0 >= 0 else 0
        lp = 2 * prc if pr >= 0 else 0
        for tc in range(tile_cols):
            if not approx and flags[_u(tile_row + tc)] == 0:
                continue
            for j in range(c0 + tc * TILE, min(c0 + (tc + 1) * TILE, c1)):
                at = row + j
                prediction = np.int64(0)
                if approx:
                    if i > r0 + 1 and c0 + 1 < j < c1 - 1:
                        up = srow + j - width
                        s = _neighbour_sum(
                            scratch[_u(srow + j - 1)],
                            scratch[_u(up)],
                            scratch[_u(up - 1)],
                            scratch[_u(up + 1)],
                            scratch[_u(srow + j - 2)],
                            scratch[_u(up - width)],
                        )
                    else:
                        here = srow + j
                        up = here - width
                        s = _neighbour_sum(
                            scratch[_u(here - 1)] if j > c0 else 0,
                            scratch[_u(up)] if i > r0 else 0,
                            scratch[_u(up - 1)] if i > r0 and j > c0 else 0,
                            scratch[_u(up + 1)] if i > r0 and j + 1 < c1 else 0,
                            scratch[_u(here - 2)] if j > c0 + 1 else 0,
                            scratch[_u(up - width)] if i > r0 + 1 else 0,
                        )
                    sd = s
                    e = np.int64(0)
                    prediction = _predict(flat, at, cols, i, j, r0, c0)
                else:
                    if i > r0 + 1 and c0 + 1 < j < c1 - 1:
                        up = at - cols
                        s, sd = _sums(
                            flat[_u(at - 1)],
                            flat[_u(up)],
                            flat[_u(up - 1)],
                            flat[_u(up + 1)],
                            flat[_u(at - 2)],
                            flat[_u(up - cols)],
                            along,
                            directional,
                        )
                    else:
                        here = at
                        up = here - cols
                        s, sd = _sums(
                            flat[_u(here - 1)] if j > c0 else 0,
                            flat[_u(up)] if i > r0 else 0,
                            flat[_u(up - 1)] if i > r0 and j > c0 else 0,
                            flat[_u(up + 1)] if i > r0 and j + 1 < c1 else 0,
                            flat[_u(here - 2)] if j > c0 + 1 else 0,
                            flat[_u(up - cols)] if i > r0 + 1 else 0,
                            along,
                            directional,
                        )
                    e = np.int64(0)
                    if j < l1:
                        e += 2 * abs(np.int64(flat[_u(s1 + j)]))
                    if j < l2:
                        e += 2 * abs(np.int64(flat[_u(s2 + j)]))
                    if j < ly:
                        e += 4 * abs(np.int64(flat[_u(y0 + j)]))
                    if j < lp:  # version 6: the parent band
                        e += PARENT_WEIGHT * abs(np.int64(flat[_u(pr + (j >> 1))]))
                ctx, ctx_d, chosen, su = _zero_context(s, sd, e, zero_base, cs, cd, directional)
                coded = ctx_d if chosen else ctx
                model_s, model_d = models[_u(ctx)], models[_u(ctx_d)]
                code, rng, models[_u(coded)], nonzero = _split_bit(code, rng, models[_u(coded)])
                while rng < TOP:
                    rng <<= 8
                    code, pos = _shift_code(code, pos, end, data)
                if tracking:
                    cs, cd, models[_u(ctx + ctx_d - coded)] = _track(
                        cs, cd, model_s, model_d, chosen, nonzero
                    )
                    tracking = abs(cs - cd) <= SETTLE
                if nonzero == 0:
                    if approx:
                        scratch[_u(srow + j)] = 0
                    flat[_u(at)] = prediction
                    continue
                unary = unary_base + (LOCAL_CLASS[min(su + e, 255)] >> 1) * UNARY_INDICES
                klass = np.int64(1)
                while True:
                    at_ctx = unary + min(klass - 1, UNARY_INDICES - 1)
                    code, rng, models[_u(at_ctx)], more = _split_bit(code, rng, models[_u(at_ctx)])
                    while rng < TOP:
                        rng <<= 8
                        code, pos = _shift_code(code, pos, end, data)
                    if more == 0:
                        break
                    klass += 1
                    if klass > MAX_CLASS:
                        return code, rng, pos, 1
                below = klass - 1
                top = 2 if below > 2 else below
                magnitude = np.int64(1)
                for position in range(top):
                    at_ctx = mantissa + position * (MAX_CLASS + 1) + klass
                    code, rng, models[_u(at_ctx)], bit = _split_bit(code, rng, models[_u(at_ctx)])
                    while rng < TOP:
                        rng <<= 8
                        code, pos = _shift_code(code, pos, end, data)
                    magnitude = (magnitude << 1) | bit
                if below > top:
                    code, rng, pos, low_bits = _decode_raw(code, rng, pos, end, data, below - top)
                    magnitude = (magnitude << (below - top)) | low_bits
                sw = sn = np.int64(0)
                if not approx:
                    if j > c0:
                        sw = _sign_of(flat[_u(at - 1)])
                    if i > r0:
                        sn = _sign_of(flat[_u(at - cols)])
                at_ctx = sign_base + (sw + 1) * 3 + sn + 1
                code, rng, models[_u(at_ctx)], negative = _split_bit(code, rng, models[_u(at_ctx)])
                while rng < TOP:
                    rng <<= 8
                    code, pos = _shift_code(code, pos, end, data)
                if approx:
                    scratch[_u(srow + j)] = magnitude
                result = prediction + (-magnitude if negative else magnitude)
                if result > 2147483647 or result < -2147483648:
                    return code, rng, pos, 1
                flat[_u(at)] = result
    return code, rng, pos, 0


@njit(nogil=True, cache=True)
def _encode_block(flat, planes, parents, oriented, block, out, pos, models, scratch, flags):
    """Code one block (a region of every plane of one level) into ``out`` from ``pos``.

    Returns the position after its last byte (past ``out``'s end when it did not fit).
    """
    low, rng, cache, pending = np.int64(0), np.int64(MASK32), np.int64(0), np.int64(1)
    r0, c0 = block[B_ROW0], block[B_COL0]
    grid_cols, tiles_per_plane = _tile_grid(block, planes)
    flags[:] = 0
    for p in range(block[B_PLANE_LO], block[B_PLANE_HI]):
        offset, rows, cols = planes[p, P_OFFSET], planes[p, P_ROWS], planes[p, P_COLS]
        r1, c1 = min(block[B_ROW1], rows), min(block[B_COL1], cols)
        if r1 <= r0 or c1 <= c0:
            continue
        approx = planes[p, P_KIND] == 0
        kind = 0 if approx else 1
        sib1 = _plane_info(planes, planes[p, P_SIB1])
        sib2 = _plane_info(planes, planes[p, P_SIB2])
        luma = _plane_info(planes, planes[p, P_LUMA])
        parent = _plane_info(planes, parents[p])
        sign_base = SIGN_BASE + (3 if approx else planes[p, P_ORIENT]) * 9
        zero_base = ZERO_BASE + kind * LOCAL_CLASSES * EXTERNAL_CLASSES
        unary_base = UNARY_BASE + kind * (LOCAL_CLASSES + 1) * UNARY_INDICES
        mantissa = MANTISSA_BASE + kind * 2 * (MAX_CLASS + 1)
        # Version 7: cH's zero flags also under the sum along rows, cV's along columns.
        along = 1 + planes[p, P_ORIENT] if oriented and planes[p, P_ORIENT] < 2 else 0
        base = (p - block[B_PLANE_LO]) * tiles_per_plane
        tile_rows = (r1 - r0 + TILE - 1) // TILE
        tile_cols = (c1 - c0 + TILE - 1) // TILE
        if not approx:
            for tr in range(tile_rows):
                for tc in range(tile_cols):
                    ctx = _tile_context(
                        flags, base, tr, tc, grid_cols, tiles_per_plane, block, planes, p
                    )
                    flag = 0
                    for i in range(r0 + tr * TILE, min(r0 + (tr + 1) * TILE, r1)):
                        row = offset + i * cols
                        seen = np.int32(0)  # or-ed over the row's part: no branch per value
                        for j in range(c0 + tc * TILE, min(c0 + (tc + 1) * TILE, c1)):
                            seen |= flat[_u(row + j)]
                        if seen != 0:
                            flag = 1
                            break
                    low, rng, models[_u(ctx)] = _code_bit(low, rng, models[_u(ctx)], flag)
                    while rng < TOP:
                        rng <<= 8
                        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
                    flags[_u(base + tr * grid_cols + tc)] = flag
        if approx:
            low, rng, cache, pending, pos = _encode_rows(
                flat,
                out,
                models,
                scratch,
                flags,
                low,
                rng,
                cache,
                pending,
                pos,
                True,
                offset,
                cols,
                r0,
                r1,
                c0,
                c1,
                base,
                grid_cols,
                sib1,
                sib2,
                luma,
                parent,
                sign_base,
                zero_base,
                unary_base,
                mantissa,
                0,
                False,
            )
        elif along:  # version 7: cH, cV
            low, rng, cache, pending, pos = _encode_rows(
                flat,
                out,
                models,
                scratch,
                flags,
                low,
                rng,
                cache,
                pending,
                pos,
                False,
                offset,
                cols,
                r0,
                r1,
                c0,
                c1,
                base,
                grid_cols,
                sib1,
                sib2,
                luma,
                parent,
                sign_base,
                zero_base,
                unary_base,
                mantissa,
                along,
                True,
            )
        else:
            low, rng, cache, pending, pos = _encode_rows(
                flat,
                out,
                models,
                scratch,
                flags,
                low,
                rng,
                cache,
                pending,
                pos,
                False,
                offset,
                cols,
                r0,
                r1,
                c0,
                c1,
                base,
                grid_cols,
                sib1,
                sib2,
                luma,
                parent,
                sign_base,
                zero_base,
                unary_base,
                mantissa,
                0,
                False,
            )

    # End at the value in [low, low + range) with the most trailing zero bytes, and flush: the
    # decoder reads zeros beyond a block's end, so the caller trims them.
    for keep in range(1, 5):
        mask = (np.int64(1) << (32 - 8 * keep)) - 1
        end_value = (low + mask) & ~mask
        if end_value - low < rng:
            low = end_value
            break
    for _ in range(5):
        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
    return pos


@njit(nogil=True, cache=True)
def _decode_block(data, start, end, flat, planes, parents, oriented, block, models, scratch, flags):
    """Decode one block from ``data[start:end]`` into ``flat``; 0, or 1 if it is corrupt."""
    rng, pos = np.int64(MASK32), start
    code = np.int64(0)
    for _ in range(4):  # the encoder's first byte, always 0, is not stored
        byte = np.int64(data[_u(pos)]) if pos < end else np.int64(0)
        pos += 1
        code = (code << 8) | byte
    r0, c0 = block[B_ROW0], block[B_COL0]
    grid_cols, tiles_per_plane = _tile_grid(block, planes)
    flags[:] = 0
    for p in range(block[B_PLANE_LO], block[B_PLANE_HI]):
        offset, rows, cols = planes[p, P_OFFSET], planes[p, P_ROWS], planes[p, P_COLS]
        r1, c1 = min(block[B_ROW1], rows), min(block[B_COL1], cols)
        if r1 <= r0 or c1 <= c0:
            continue
        approx = planes[p, P_KIND] == 0
        kind = 0 if approx else 1
        sib1 = _plane_info(planes, planes[p, P_SIB1])
        sib2 = _plane_info(planes, planes[p, P_SIB2])
        luma = _plane_info(planes, planes[p, P_LUMA])
        parent = _plane_info(planes, parents[p])
        sign_base = SIGN_BASE + (3 if approx else planes[p, P_ORIENT]) * 9
        zero_base = ZERO_BASE + kind * LOCAL_CLASSES * EXTERNAL_CLASSES
        unary_base = UNARY_BASE + kind * (LOCAL_CLASSES + 1) * UNARY_INDICES
        mantissa = MANTISSA_BASE + kind * 2 * (MAX_CLASS + 1)
        # Version 7: cH's zero flags also under the sum along rows, cV's along columns.
        along = 1 + planes[p, P_ORIENT] if oriented and planes[p, P_ORIENT] < 2 else 0
        base = (p - block[B_PLANE_LO]) * tiles_per_plane
        tile_rows = (r1 - r0 + TILE - 1) // TILE
        tile_cols = (c1 - c0 + TILE - 1) // TILE
        if not approx:
            for tr in range(tile_rows):
                for tc in range(tile_cols):
                    ctx = _tile_context(
                        flags, base, tr, tc, grid_cols, tiles_per_plane, block, planes, p
                    )
                    code, rng, models[_u(ctx)], flag = _split_bit(code, rng, models[_u(ctx)])
                    while rng < TOP:
                        rng <<= 8
                        code, pos = _shift_code(code, pos, end, data)
                    flags[_u(base + tr * grid_cols + tc)] = flag
        if approx:
            code, rng, pos, bad = _decode_rows(
                data,
                end,
                flat,
                models,
                scratch,
                flags,
                code,
                rng,
                pos,
                True,
                offset,
                cols,
                r0,
                r1,
                c0,
                c1,
                base,
                grid_cols,
                sib1,
                sib2,
                luma,
                parent,
                sign_base,
                zero_base,
                unary_base,
                mantissa,
                0,
                False,
            )
        elif along:  # version 7: cH, cV
            code, rng, pos, bad = _decode_rows(
                data,
                end,
                flat,
                models,
                scratch,
                flags,
                code,
                rng,
                pos,
                False,
                offset,
                cols,
                r0,
                r1,
                c0,
                c1,
                base,
                grid_cols,
                sib1,
                sib2,
                luma,
                parent,
                sign_base,
                zero_base,
                unary_base,
                mantissa,
                along,
                True,
            )
        else:
            code, rng, pos, bad = _decode_rows(
                data,
                end,
                flat,
                models,
                scratch,
                flags,
                code,
                rng,
                pos,
                False,
                offset,
                cols,
                r0,
                r1,
                c0,
                c1,
                base,
                grid_cols,
                sib1,
                sib2,
                luma,
                parent,
                sign_base,
                zero_base,
                unary_base,
                mantissa,
                0,
                False,
            )
        if bad:
            return 1
    return 0


@njit(nogil=True, cache=True)
def _block_is_empty(flat, planes, block):
    r0, c0 = block[B_ROW0], block[B_COL0]
    for p in range(block[B_PLANE_LO], block[B_PLANE_HI]):
        offset, rows, cols = planes[p, P_OFFSET], planes[p, P_ROWS], planes[p, P_COLS]
        for i in range(r0, min(block[B_ROW1], rows)):
            for j in range(c0, min(block[B_COL1], cols)):
                if flat[offset + i * cols + j] != 0:
                    return False
    return True


@njit(nogil=True, cache=True)
def _scratch_size(blocks, lo, hi):
    largest = 1
    for b in range(lo, hi):
        area = (blocks[b, B_ROW1] - blocks[b, B_ROW0]) * (blocks[b, B_COL1] - blocks[b, B_COL0])
        largest = max(largest, area)
    return largest


def _initial_models() -> np.ndarray:
    """Every block's models start here: a zero is likely where the neighbours are quiet.

    The probability of a zero starts at ``(15 - class) / 16`` for the zero flags of the
    quiet local classes (and one half elsewhere), with a count of 2, so the first few bits
    still move it quickly.
    """
    p = np.full(CONTEXTS, PROB_ONE // 2, dtype=np.int64)
    n = np.zeros(CONTEXTS, dtype=np.int64)
    for kind in range(2):
        for local in range(LOCAL_CLASSES):
            for external in range(EXTERNAL_CLASSES):
                ctx = ZERO_BASE + (kind * LOCAL_CLASSES + local) * EXTERNAL_CLASSES + external
                level = max(8, 15 - local - external)
                p[ctx] = level * PROB_ONE // 16
                n[ctx] = 2
    # Version 7's directional zero flags start as the detail ones.
    detail = ZERO_BASE + LOCAL_CLASSES * EXTERNAL_CLASSES
    p[ZERO_DIR_BASE : ZERO_DIR_BASE + ZERO_DIR_SIZE] = p[detail : detail + ZERO_DIR_SIZE]
    n[ZERO_DIR_BASE : ZERO_DIR_BASE + ZERO_DIR_SIZE] = 2
    return ((p << 8) | n).astype(np.int32)


INITIAL_MODELS = _initial_models()
#: Each block's starting models by the kernels' ``oriented`` argument and level class: row 0
#: for versions 4, 6 and 7 (:data:`INITIAL_MODELS`), row ``1 + B_LEVEL`` for version 8 (its
#: trained priors, :data:`wavecore._blockpriors.PRIORS`).
STARTING_MODELS = np.concatenate([INITIAL_MODELS[None], PRIORS]).astype(np.int32)


@njit(nogil=True, cache=True)
def _flags_size(planes, blocks, lo, hi):
    largest = 1
    for b in range(lo, hi):
        largest = max(
            largest,
            _tile_grid(blocks[b], planes)[1] * (blocks[b, B_PLANE_HI] - blocks[b, B_PLANE_LO]),
        )
    return largest


@njit(nogil=True, cache=True)
def _fresh_models(models, oriented, block):
    """A block's models at its start: version 8's priors of its level class, else
    :data:`INITIAL_MODELS`."""
    row = 1 + block[B_LEVEL] if oriented == 2 else 0
    models[:] = STARTING_MODELS[row]


@njit(nogil=True, cache=True)
def encode_span(flat, planes, parents, oriented, blocks, lo, hi):
    """Code blocks ``lo .. hi - 1``; return their bytes, concatenated, and each one's length.

    An all-zero block has length 0; any other block at least 1 byte.  ``parents``: each
    plane's parent plane (-1: none; versions 6, 7 and 8); ``oriented``: 1 for version 7 (the
    directional zero-flag models of ``cH`` and ``cV``), 2 for version 8 (version 7 whose
    blocks start from the priors of their level class, ``blocks[:, B_LEVEL]``), else 0.
    """
    # Room for 8 bits per position to begin with: a block that does not fit is coded again
    # from its start into a larger buffer, and at 2 bits per position (as before) every dense
    # block (coarse levels, high rates, lossless) was coded twice.  The pages of ``np.empty``
    # are only mapped as they are written, so unused room costs address space, not memory.
    # Positions are the coefficients the block holds (its planes clipped to their extent): the
    # nominal area is 16 384 per plane of a 1-D block, however short the curve.
    room = 0
    for b in range(lo, hi):
        r0, c0 = blocks[b, B_ROW0], blocks[b, B_COL0]
        for p in range(blocks[b, B_PLANE_LO], blocks[b, B_PLANE_HI]):
            rows = min(blocks[b, B_ROW1], planes[p, P_ROWS]) - r0
            cols = min(blocks[b, B_COL1], planes[p, P_COLS]) - c0
            if rows > 0 and cols > 0:
                room += rows * cols
    out = np.empty(max(1024, room), dtype=np.uint8)
    lengths = np.zeros(hi - lo, dtype=np.int64)
    models = np.empty(CONTEXTS, dtype=np.int32)
    scratch = np.empty(_scratch_size(blocks, lo, hi), dtype=np.int64)
    flags = np.zeros(_flags_size(planes, blocks, lo, hi), dtype=np.int64)
    pos = 0
    for b in range(lo, hi):
        if _block_is_empty(flat, planes, blocks[b]):
            continue
        while True:
            _fresh_models(models, oriented, blocks[b])
            end = _encode_block(
                flat, planes, parents, oriented, blocks[b], out, pos, models, scratch, flags
            )
            if end <= out.size:
                break
            bigger = np.empty(2 * out.size + 2 * (end - pos), dtype=np.uint8)
            bigger[:pos] = out[:pos]
            out = bigger
        # The first byte LZMA's encoder writes is always 0: dropped (the decoder knows it).
        out[pos : end - 1] = out[pos + 1 : end].copy()
        end -= 1
        while end > pos and out[end - 1] == 0:
            end -= 1  # the decoder reads zeros beyond a block's end
        if end == pos:
            out[pos] = 0
            end = pos + 1
        lengths[b - lo] = end - pos
        pos = end
    return out[:pos].copy(), lengths


@njit(nogil=True, cache=True)
def decode_span(data, starts, lengths, planes, parents, oriented, blocks, flat, lo, hi):
    """Decode blocks ``lo .. hi - 1`` into ``flat`` (zeros where a block's length is 0).

    ``data[starts[b] : starts[b] + lengths[b]]`` holds block ``b``; ``parents`` and
    ``oriented`` as :func:`encode_span`'s.  Returns the number of blocks found corrupt.
    """
    models = np.empty(CONTEXTS, dtype=np.int32)
    scratch = np.empty(_scratch_size(blocks, lo, hi), dtype=np.int64)
    flags = np.zeros(_flags_size(planes, blocks, lo, hi), dtype=np.int64)
    bad = 0
    for b in range(lo, hi):
        if lengths[b] == 0:
            continue
        _fresh_models(models, oriented, blocks[b])
        bad += _decode_block(
            data,
            starts[b],
            starts[b] + lengths[b],
            flat,
            planes,
            parents,
            oriented,
            blocks[b],
            models,
            scratch,
            flags,
        )
    return bad


@njit(nogil=True, cache=True)
def write_varints(values):
    """Unsigned LEB128 of each value (7 bits a byte, low first), concatenated."""
    out = np.empty(values.size * 10, dtype=np.uint8)
    pos = 0
    for k in range(values.size):
        v = values[k]
        while v >= 0x80:
            out[pos] = (v & 0x7F) | 0x80
            v >>= 7
            pos += 1
        out[pos] = v
        pos += 1
    return out[:pos].copy()


@njit(nogil=True, cache=True)
def read_varints(data, count, limit):
    """``count`` LEB128 values from the start of ``data``; each below ``limit``.

    Returns ``(values, bytes read)``, or bytes read ``-1`` when the table is cut short, a value
    has more than 5 bytes, or is ``limit`` or more.
    """
    values = np.zeros(count, dtype=np.int64)
    pos = 0
    for k in range(count):
        v = np.int64(0)
        shift = 0
        while True:
            if pos >= data.size or shift > 28:
                return values, -1
            byte = np.int64(data[pos])
            pos += 1
            v |= (byte & 0x7F) << shift
            shift += 7
            if byte < 0x80:
                break
        if v >= limit:
            return values, -1
        values[k] = v
    return values, pos
