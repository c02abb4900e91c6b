"""Compiled loops of the lossless coder (:mod:`wavecore.losslesscoder`).

One call codes (or decodes) one resolution level: every band of every channel, in order, through
one binary arithmetic coder whose probabilities come from three adaptive models mixed in the
logistic domain (the mixing of PAQ and lpaq, in integers only, so that every machine computes
the same bits).  The bit-level specification is in ``docs/bundle-format.md`` (lossless coder).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Fields of a row of ``planes`` (one band of one channel, in coding order).
P_OFF, P_ROWS, P_COLS, P_ORIENT = 0, 1, 2, 3
P_PAR, P_PROWS, P_PCOLS = 4, 5, 6  # the parent band in ``parent`` (offset -1: none)
P_SIB1, P_S1ROWS, P_S1COLS = 7, 8, 9  # earlier bands of the channel at this level
P_SIB2, P_S2ROWS, P_S2COLS = 10, 11, 12
P_LUMA = 13  # the same band of the first channel (same shape; -1: none)
PLANE_FIELDS = 14

APPROX = 3  # the orientation of the coarse band (0, 1, 2: cH, cV, cD)
ORIENTS = 4

# Decisions of one value: 0 the zero flag; 1 … 12 "bit length > k"; 13 … 22 the first bit
# below the leading one (by bit length 2 … 11+); 23 … 32 the second (bit length 3 … 12+).
UNARY_LAST = 12
MANT0 = 13
MANT1 = 23
DECISIONS = 33
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
MAX_LENGTH = 34  # the longest bit length a value may have (int32 values, coarse residuals)

S_CLASSES = 24
X_CLASSES = 16
C_CLASSES = 8

M1_SIZE = ORIENTS * DECISIONS * S_CLASSES
M2_SIZE = ORIENTS * DECISIONS * X_CLASSES * C_CLASSES
M3_SIZE = M2_SIZE
M1_BASE = 0
M2_BASE = M1_BASE + M1_SIZE
M3_BASE = M2_BASE + M2_SIZE
SIGN_BASE = M3_BASE + M3_SIZE
SIGN_SIZE = ORIENTS * 27 * 2  # two sign models: (W, N, parent) signs, (sibling, luma, NW)
RAW_BASE = SIGN_BASE + SIGN_SIZE
RAW_SIZE = (MAX_LENGTH + 1) * (MAX_LENGTH + 1)  # lower mantissa bits: (length, position)
MODELS = RAW_BASE + RAW_SIZE

INPUTS = 4  # three models and a bias
MIX_SETS = (
    ORIENTS * DECISIONS + ORIENTS
) * C_CLASSES  # value decisions, then the sign per orientation
WEIGHT_INIT = 22000  # about a third of 1 << 16 for each model, nothing for the bias
LEARNING = 14

PROB_INIT = 1 << 15  # the models' probabilities of a 1, in 1 / 65536
RATE_LIMIT = 7
STATE_CAP = 30


def _stretch_table() -> np.ndarray:
    """``stretch(p) = ln(p / (1 - p))`` at 12-bit probabilities, in 1 / 256, as integers: the
    inverse of ``_squash`` (computed from it, so the two agree exactly)."""
    table = np.zeros(4096, dtype=np.int64)
    pi = 0
    for x in range(-2047, 2048):
        v = _squash_py(x)
        for j in range(pi, v + 1):
            table[j] = x
        pi = v + 1
    for j in range(pi, 4096):
        table[j] = 2047
    return table


_SQUASH_POINTS = (
    1, 2, 3, 6, 10, 16, 27, 45, 73, 120, 194, 310, 488, 747, 1101, 1546,
    2047, 2549, 2994, 3348, 3607, 3785, 3901, 3975, 4024, 4050, 4068, 4079,
    4085, 4089, 4092, 4093, 4094,
)  # fmt: skip


def _squash_py(d: int) -> int:
    """lpaq1's ``squash``: ``4096 / (1 + e^(-d / 256))`` by interpolation in a table."""
    if d > 2047:
        return 4095
    if d < -2047:
        return 1
    w = d & 127
    k = (d >> 7) + 16
    return (_SQUASH_POINTS[k] * (128 - w) + _SQUASH_POINTS[k + 1] * w + 64) >> 7


STRETCH = _stretch_table()
QLOG_SIZE = 4096
BITLEN = np.array([v.bit_length() for v in range(QLOG_SIZE)], dtype=np.int64)
QLOG = np.array(
    [
        v if v < 4 else 2 * v.bit_length() - 2 + ((v >> (v.bit_length() - 2)) & 1)
        for v in range(QLOG_SIZE)
    ],
    dtype=np.int64,
)
SQUASH = np.array([_squash_py(d) for d in range(-2048, 2048)], dtype=np.int64)


#: Array indices as unsigned integers: numba then skips its wrap-around of negative indices
#: (a test and an add per access, which the hot loops make hundreds of times per value).
U = np.uint64


@njit(nogil=True, cache=True, inline="always")
def _squash(d):
    if d > 2047:
        d = 2047
    if d < -2047:
        d = -2047
    return SQUASH[U(d + 2048)]


@njit(nogil=True, cache=True, inline="always")
def _qlog(x, top):
    """A class per half octave of ``x >= 0`` (0, 1, 2, 3, 4-5, 6-7, 8-11, …), at most ``top``."""
    if x < QLOG_SIZE:
        return min(QLOG[U(x)], top)
    if x < 4:
        k = x
    else:
        n = np.int64(0)
        v = x
        while v:
            v >>= 1
            n += 1
        k = 2 * n - 2 + ((x >> (n - 2)) & 1)
    return min(k, top)


@njit(nogil=True, cache=True, inline="always")
def _parent_class(x, top):
    """Model 2's class of a detail value from its parent band: ``x`` sums the parent's signed
    values (not their magnitudes), as version 5 has always done; a negative sum takes the
    class that numba's wrap-around of the negative index gave, ``QLOG[x + 4096]`` (how every
    version-5 bundle was coded), and a sum below -4096, which read outside the table, the top
    class (see ``docs/bundle-format.md``)."""
    if x >= 0:
        return _qlog(x, top)
    if x >= -QLOG_SIZE:
        return min(QLOG[U(x + QLOG_SIZE)], top)
    return np.int64(top)


@njit(nogil=True, cache=True, inline="always")
def _bit_length(value):
    if value < QLOG_SIZE:
        return BITLEN[U(value)]
    n = np.int64(0)
    while value:
        value >>= 1
        n += 1
    return n


@njit(nogil=True, cache=True, inline="always")
def _update(models, ctx, bit):
    """A model's probability of a 1 (16 bits, above 4 bits of count) moves towards the bit by
    ``2**-min(count + 1, RATE_LIMIT)``: fast at first, then steadier."""
    ctx = U(ctx)
    model = models[ctx]
    n = model & 15
    p = model >> 4
    shift = min(n + 1, RATE_LIMIT)
    if bit:
        p += (65536 - p) >> shift
    else:
        p -= p >> shift
    models[ctx] = (max(32, min(65504, p)) << 4) | min(n + 1, RATE_LIMIT)


@njit(nogil=True, cache=True, inline="always")
def _code(x1, x2, x, pos, out, data, p, bit, decoding):
    """One bit at probability ``p`` (of a 1, in 1 / 4096) through the carry-less binary
    arithmetic coder of lpaq1: its range ``[x1, x2]``, the decoder's code ``x`` and the byte
    position live in the caller's locals (kept in an array they cost several times as much)."""
    xmid = x1 + (((x2 - x1) * p) >> 12)
    if decoding:
        bit = 1 if x <= xmid else 0
    if bit:
        x2 = xmid
    else:
        x1 = xmid + 1
    while ((x1 ^ x2) & 0xFF000000) == 0:
        if decoding:
            byte = np.int64(data[U(pos)]) if pos < data.size else np.int64(0)
            x = ((x << 8) & 0xFFFFFFFF) | byte
        elif pos < out.size:
            out[U(pos)] = (x2 >> 24) & 0xFF
        pos += 1
        x1 = (x1 << 8) & 0xFFFFFFFF
        x2 = ((x2 << 8) & 0xFFFFFFFF) | 255
    return x1, x2, x, pos, bit


@njit(nogil=True, cache=True, inline="always")
def _mixed(x1, x2, x, pos, out, data, probs, weights, wset, c1, c2, c3, bit, decoding):
    """A bit under the logistic mix of three models; every model and the mixer learn it."""
    s1 = STRETCH[U(probs[U(c1)] >> 8)]
    s2 = STRETCH[U(probs[U(c2)] >> 8)]
    s3 = STRETCH[U(probs[U(c3)] >> 8)]
    w = U(wset * INPUTS)
    w1, w2, w3 = w + U(1), w + U(2), w + U(3)
    dot = weights[w] * s1 + weights[w1] * s2 + weights[w2] * s3 + weights[w3] * 256
    p = _squash(dot >> 16)
    x1, x2, x, pos, bit = _code(x1, x2, x, pos, out, data, p, bit, decoding)
    err = ((bit << 12) - p) * LEARNING
    weights[w] += (s1 * err) >> 16
    weights[w1] += (s2 * err) >> 16
    weights[w2] += (s3 * err) >> 16
    weights[w3] += (256 * err) >> 16
    _update(probs, c1, bit)
    _update(probs, c2, bit)
    _update(probs, c3, bit)
    return x1, x2, x, pos, bit


@njit(nogil=True, cache=True, inline="always")
def _single(x1, x2, x, pos, out, data, probs, ctx, bit, decoding):
    p = max(1, min(4095, probs[U(ctx)] >> 8))
    x1, x2, x, pos, bit = _code(x1, x2, x, pos, out, data, p, bit, decoding)
    _update(probs, ctx, bit)
    return x1, x2, x, pos, bit


@njit(nogil=True, cache=True, inline="always")
def _at(values, off, rows, cols, i, j):
    """``values[off + i * cols + j]``, 0 outside the band or without one (``off < 0``)."""
    if off < 0 or i < 0 or j < 0 or i >= rows or j >= cols:
        return np.int64(0)
    return np.int64(values[U(off + i * cols + j)])


@njit(nogil=True, cache=True, inline="always")
def _sgn(x):
    return np.int64((x > 0) - (x < 0))


# JPEG XL's weighted predictor (ISO/IEC 18181-1, modular mode; libjxl's defaults), in integers:
# four sub-predictions at 3 extra bits of precision, averaged with weights that fall as each
# one's recent errors at the N, W, NW, WW and NE positions grow.
WP_P1, WP_P2, WP_P3A, WP_P3B, WP_P3C = 16, 10, 7, 7, 7
WP_W = (13, 12, 12, 12, 12)
WP_N = 5
DIVLOOKUP = np.array([(1 << 24) // (i + 1) for i in range(64)], dtype=np.int64)


@njit(nogil=True, cache=True, inline="always")
def _error_weight(x, maxweight):
    shift = _bit_length(x + 1) - 1 - 5
    if shift < 0:
        shift = 0
    return 4 + ((maxweight * DIVLOOKUP[U(x >> shift)]) >> shift)


@njit(nogil=True, cache=True, inline="always")
def _wp_predict(values, off, rows, cols, i, j, te, pe, subs, wts):
    # i is relative to the stripe's first row; values[off] is that row's first sample
    """The weighted prediction of position ``(i, j)`` (rounded), its value at 3 extra bits,
    and the largest magnitude of the true errors around; ``subs`` receives the four
    sub-predictions.  ``te`` holds true errors, ``pe`` the sub-predictors' errors (4 planes)."""
    at = i * cols + j
    if j > 0:
        w = np.int64(values[U(off + at - 1)])
    elif i > 0:
        w = np.int64(values[U(off + at - cols)])
    else:
        w = np.int64(0)
    n = np.int64(values[U(off + at - cols)]) if i > 0 else w
    nw = np.int64(values[U(off + at - cols - 1)]) if i > 0 and j > 0 else n
    ne = np.int64(values[U(off + at - cols + 1)]) if i > 0 and j + 1 < cols else n
    # te and pe keep two rows: this one and the one above
    cur = (i & 1) * cols + j
    prv = ((i + 1) & 1) * cols + j
    te_w = te[U(cur - 1)] if j > 0 else np.int64(0)
    te_n = te[U(prv)] if i > 0 else np.int64(0)
    te_nw = te[U(prv - 1)] if i > 0 and j > 0 else te_n
    te_ne = te[U(prv + 1)] if i > 0 and j + 1 < cols else te_n
    total = np.int64(0)
    # the sub-predictors' errors, WP_N per position: at N, NW, NE (N again at the ends), W, WW
    up = prv * WP_N
    if i > 0 and 1 < j < cols - 1:  # the common case, without a test per neighbour
        for k in range(WP_N):
            e = pe[U(up + k)] + pe[U(up - WP_N + k)] + pe[U(up + WP_N + k)]
            e += pe[U((cur - 1) * WP_N + k)] + pe[U((cur - 2) * WP_N + k)]
            wts[k] = _error_weight(e, WP_W[k])
            total += wts[k]
    else:
        for k in range(WP_N):
            e = np.int64(0)
            if i > 0:
                e += pe[U(up + k)]
                e += pe[U(up - WP_N + k)] if j > 0 else pe[U(up + k)]
                e += pe[U(up + WP_N + k)] if j + 1 < cols else pe[U(up + k)]
            if j > 0:
                e += pe[U((cur - 1) * WP_N + k)]
            if j > 1:
                e += pe[U((cur - 2) * WP_N + k)]
            wts[k] = _error_weight(e, WP_W[k])
            total += wts[k]
    n8, w8, nw8, ne8 = n << 3, w << 3, nw << 3, ne << 3
    sum_wn = te_n + te_w
    subs[0] = w8 + ne8 - n8
    subs[1] = n8 - (((sum_wn + te_ne) * WP_P1) >> 5)
    subs[2] = w8 - (((sum_wn + te_nw) * WP_P2) >> 5)
    subs[3] = n8 - ((te_nw * WP_P3A + te_n * WP_P3B + te_ne * WP_P3C) >> 5)
    if nw8 >= max(w8, n8):
        subs[4] = min(w8, n8)
    elif nw8 <= min(w8, n8):
        subs[4] = max(w8, n8)
    else:
        subs[4] = w8 + n8 - nw8
    log_weight = _bit_length(total) - 1
    wsum = np.int64(0)
    for k in range(WP_N):
        wts[k] >>= log_weight - 4
        wsum += wts[k]
    acc = (wsum >> 1) - 1
    for k in range(WP_N):
        acc += subs[k] * wts[k]
    pred = (acc * DIVLOOKUP[U(wsum - 1)]) >> 24
    if ((te_n ^ te_w) | (te_n ^ te_nw)) <= 0:
        hi = max(w8, max(ne8, n8))
        lo = min(w8, min(ne8, n8))
        pred = max(lo, min(hi, pred))
    big = te_w
    if abs(te_n) > abs(big):
        big = te_n
    if abs(te_nw) > abs(big):
        big = te_nw
    if abs(te_ne) > abs(big):
        big = te_ne
    return (pred + 3) >> 3, pred, big, w, n, nw, ne


@njit(nogil=True, cache=True, inline="always")
def _wp_update(value, at, pred8, subs, te, pe):
    """Record the true error and the sub-predictors' errors at ``at`` (of the two rows kept)."""
    v8 = value << 3
    te[U(at)] = pred8 - v8
    for k in range(WP_N):
        pe[U(at * WP_N + k)] = (abs(subs[k] - v8) + 3) >> 3


@njit(nogil=True, cache=True, inline="always")
def _neighbourhood(mags, off, rows, cols, i, j):
    """``4 (|W| + |N|) + 2 (|NW| + |NE|) + |WW| + |NN|`` and ``|W|``, ``|N|`` (0 outside)."""
    at = off + i * cols + j
    if i >= 2 and 2 <= j < cols - 1:  # the common case, without a test per neighbour
        up = at - cols
        a = np.int64(mags[U(at - 1)])
        b = np.int64(mags[U(up)])
        s = 4 * (a + b) + 2 * (np.int64(mags[U(up - 1)]) + np.int64(mags[U(up + 1)]))
        s += np.int64(mags[U(at - 2)]) + np.int64(mags[U(up - cols)])
        return s, a, b
    a = _at(mags, off, rows, cols, i, j - 1)
    b = _at(mags, off, rows, cols, i - 1, j)
    s = 4 * (a + b) + 2 * (
        _at(mags, off, rows, cols, i - 1, j - 1) + _at(mags, off, rows, cols, i - 1, j + 1)
    )
    s += _at(mags, off, rows, cols, i, j - 2) + _at(mags, off, rows, cols, i - 2, j)
    return s, a, b


@njit(nogil=True, cache=True)
def encode_level(values, mags, parent, planes, stripe, stripes, out):
    """:func:`code_level` coding into ``out`` (compiled without the decoder's branches)."""
    return code_level(values, mags, parent, planes, stripe, stripes, out, out[:0], False)


@njit(nogil=True, cache=True)
def decode_level(values, mags, parent, planes, stripe, stripes, data):
    """:func:`code_level` decoding ``data`` (compiled without the encoder's branches)."""
    nothing = np.empty(0, dtype=np.uint8)
    return code_level(values, mags, parent, planes, stripe, stripes, nothing, data, True)


@njit(nogil=True, cache=True, inline="always")
def code_level(values, mags, parent, planes, stripe, stripes, out, data, decoding):
    """Code (``decoding`` False: ``values`` → ``out``; returns the bytes written, which may
    exceed ``out.size``: then call again with more room) or decode (``data`` → ``values``)
    stripe ``stripe`` of ``stripes`` of one level: rows ``rows * stripe // stripes`` to
    ``rows * (stripe + 1) // stripes`` of every band, which look at no other stripe of the
    level (so the stripes are coded in parallel).  ``mags`` is scratch of ``values``' size: the
    magnitudes the contexts look at (the coarse band's prediction residuals, the details')."""
    probs = np.full(MODELS, PROB_INIT << 4, dtype=np.int32)  # int32: half the cache
    weights = np.zeros(MIX_SETS * INPUTS, dtype=np.int64)
    for k in range(MIX_SETS):
        weights[k * INPUTS] = WEIGHT_INIT
        weights[k * INPUTS + 1] = WEIGHT_INIT
        weights[k * INPUTS + 2] = WEIGHT_INIT
    x1 = np.int64(0)
    x2 = np.int64(0xFFFFFFFF)
    xc = np.int64(0)
    pos = np.int64(0)
    if decoding:
        for _ in range(4):
            byte = np.int64(data[pos]) if pos < data.size else np.int64(0)
            xc = (xc << 8) | byte
            pos += 1
    subs = np.zeros(WP_N, dtype=np.int64)
    wts = np.zeros(WP_N, dtype=np.int64)  # scratch: allocated once, not per sample
    for p in range(planes.shape[0]):
        full_rows = planes[p, P_ROWS]
        cols = planes[p, P_COLS]
        r0 = full_rows * stripe // stripes
        rows = full_rows * (stripe + 1) // stripes - r0
        off = planes[p, P_OFF] + r0 * cols
        orient = planes[p, P_ORIENT]
        par, prows, pcols = planes[p, P_PAR], planes[p, P_PROWS], planes[p, P_PCOLS]
        sib1, s1c = planes[p, P_SIB1], planes[p, P_S1COLS]
        s1lo = planes[p, P_S1ROWS] * stripe // stripes
        s1r = planes[p, P_S1ROWS] * (stripe + 1) // stripes - s1lo
        if sib1 >= 0:
            sib1 += s1lo * s1c
        sib2, s2c = planes[p, P_SIB2], planes[p, P_S2COLS]
        s2lo = planes[p, P_S2ROWS] * stripe // stripes
        s2r = planes[p, P_S2ROWS] * (stripe + 1) // stripes - s2lo
        if sib2 >= 0:
            sib2 += s2lo * s2c
        luma = planes[p, P_LUMA]
        if luma >= 0:
            luma += r0 * cols
        approx = orient == APPROX
        if approx:
            # Two rows, this one and the one above (one for a plane of one row: 96 bytes a
            # sample of its width, 384 MiB for a 1 × 4 194 304 picture, half of it unused).
            # (int64: the coder takes any int32 value, whose errors in eighths need more.)
            kept_rows = 2 if rows > 1 else 1
            te = np.zeros(kept_rows * cols, dtype=np.int64)
            pe = np.zeros(kept_rows * cols * WP_N, dtype=np.int64)  # position-major
        else:
            te = np.zeros(0, dtype=np.int64)
            pe = np.zeros(0, dtype=np.int64)
        pred8 = np.int64(0)
        for i in range(rows):
            for j in range(cols):
                r = i * cols + j
                at = off + r
                s, a, b = _neighbourhood(mags, off, rows, cols, i, j)
                if approx:
                    pred, pred8, big, wv, nv, nwv, nev = _wp_predict(
                        values, off, rows, cols, i, j, te, pe, subs, wts
                    )
                    interior = i > 0 and 0 < j < cols - 1
                    x = 4 * abs(big)
                    # the third model: the gradients' activity, or the first channel's residual
                    if not interior:  # outside the plane counts as 0 here
                        wv = _at(values, off, rows, cols, i, j - 1)
                        nv = _at(values, off, rows, cols, i - 1, j)
                        nwv = _at(values, off, rows, cols, i - 1, j - 1)
                        nev = _at(values, off, rows, cols, i - 1, j + 1) if j + 1 < cols else nv
                    e = 2 * (abs(wv - nwv) + abs(nv - nwv) + abs(nev - nv))
                    qn = min(_qlog(a + b, 2 * C_CLASSES) >> 1, C_CLASSES - 1)
                    if luma >= 0:
                        qn = min(
                            _qlog(4 * _at(mags, luma, rows, cols, i, j), 2 * C_CLASSES) >> 1,
                            C_CLASSES - 1,
                        )
                else:
                    pred = np.int64(0)
                    big = wv = nv = nwv = np.int64(0)
                    pi = (i + r0) >> 1
                    pj = j >> 1
                    x = 2 * _at(parent, par, prows, pcols, pi, pj)
                    x += _at(parent, par, prows, pcols, pi, pj + 1)
                    x += _at(parent, par, prows, pcols, pi + 1, pj)
                    e = 2 * (
                        abs(_at(values, sib1, s1r, s1c, i + r0 - s1lo, j))
                        + abs(_at(values, sib2, s2r, s2c, i + r0 - s2lo, j))
                    )
                    e += 4 * abs(_at(values, luma, rows, cols, i, j))
                    qn = min(_qlog(a + b, 2 * C_CLASSES) >> 1, C_CLASSES - 1)
                qs = _qlog(s, S_CLASSES - 1)
                qx = _parent_class(x, X_CLASSES - 1) if not approx else _qlog(x, X_CLASSES - 1)
                qe = _qlog(e, X_CLASSES - 1)
                qc = min(qs >> 2, C_CLASSES - 1)
                value = np.int64(0)
                if not decoding:
                    value = np.int64(values[U(at)]) - pred
                magnitude = abs(value)
                # the zero flag, then the bit length in unary
                klass = _bit_length(magnitude)
                k = 0
                for k in range(0, MAX_LENGTH + 1):
                    ob = orient * DECISIONS + min(k, UNARY_LAST)
                    c1 = M1_BASE + ob * S_CLASSES + qs
                    c2 = M2_BASE + (ob * X_CLASSES + qx) * C_CLASSES + qc
                    c3 = M3_BASE + (ob * X_CLASSES + qe) * C_CLASSES + qn
                    more = 1 if klass > k else 0
                    x1, x2, xc, pos, more = _mixed(
                        x1,
                        x2,
                        xc,
                        pos,
                        out,
                        data,
                        probs,
                        weights,
                        ob * C_CLASSES + qc,
                        c1,
                        c2,
                        c3,
                        more,
                        decoding,
                    )
                    if not more:
                        break
                if decoding:
                    klass = k
                if klass == 0:
                    mags[U(at)] = 0
                    if decoding:
                        values[U(at)] = pred
                    if approx:
                        _wp_update(pred, (i & 1) * cols + j, pred8, subs, te, pe)
                    continue
                # the bits below the leading one: the top two mixed, the rest one model each
                mag = np.int64(1)
                for position in range(klass - 1):
                    bit = 0
                    if not decoding:
                        bit = (magnitude >> (klass - 2 - position)) & 1
                    if position < 2:
                        if position == 0:
                            dec = MANT0 + min(klass - 2, 9)
                        else:
                            dec = MANT1 + min(klass - 3, 9)
                        ob = orient * DECISIONS + dec
                        c1 = M1_BASE + ob * S_CLASSES + qs
                        c2 = M2_BASE + (ob * X_CLASSES + qx) * C_CLASSES + qc
                        c3 = M3_BASE + (ob * X_CLASSES + qe) * C_CLASSES + qn
                        x1, x2, xc, pos, bit = _mixed(
                            x1,
                            x2,
                            xc,
                            pos,
                            out,
                            data,
                            probs,
                            weights,
                            ob * C_CLASSES + qc,
                            c1,
                            c2,
                            c3,
                            bit,
                            decoding,
                        )
                    else:
                        ctx = RAW_BASE + klass * (MAX_LENGTH + 1) + position
                        x1, x2, xc, pos, bit = _single(
                            x1, x2, xc, pos, out, data, probs, ctx, bit, decoding
                        )
                    mag = (mag << 1) | bit
                if decoding:
                    magnitude = mag
                # the sign
                if approx:
                    sw = _sgn(wv - nwv)
                    sn = _sgn(nv - nwv)
                    sp = _sgn(pred8 - 8 * pred)  # which way the prediction was rounded
                    s1 = _sgn(te[U((i & 1) * cols + j - 1)]) if j > 0 else np.int64(0)
                    s2 = _sgn(te[U(((i + 1) & 1) * cols + j)]) if i > 0 else np.int64(0)
                    s3 = _sgn(big)
                else:
                    sw = _sgn(_at(values, off, rows, cols, i, j - 1))
                    sn = _sgn(_at(values, off, rows, cols, i - 1, j))
                    sp = _sgn(_at(parent, par, prows, pcols, (i + r0) >> 1, j >> 1))
                    s1 = _sgn(_at(values, sib1, s1r, s1c, i + r0 - s1lo, j))
                    s2 = _sgn(_at(values, luma, rows, cols, i, j))
                    s3 = _sgn(_at(values, off, rows, cols, i - 1, j - 1))
                c1 = SIGN_BASE + (orient * 27 + (sw + 1) * 9 + (sn + 1) * 3 + sp + 1) * 2
                c2 = SIGN_BASE + (orient * 27 + (s1 + 1) * 9 + (s2 + 1) * 3 + s3 + 1) * 2 + 1
                negative = 1 if value < 0 else 0
                x1, x2, xc, pos, negative = _mixed(
                    x1,
                    x2,
                    xc,
                    pos,
                    out,
                    data,
                    probs,
                    weights,
                    (ORIENTS * DECISIONS + orient) * C_CLASSES + qc,
                    c1,
                    c2,
                    c1,
                    negative,
                    decoding,
                )
                mags[U(at)] = magnitude
                if decoding:
                    value = pred - magnitude if negative else pred + magnitude
                    if value < INT32_MIN or value > INT32_MAX:
                        return np.int64(-1)  # no coder writes this: the stream is damaged
                    values[U(at)] = value
                if approx:
                    _wp_update(np.int64(values[U(at)]), (i & 1) * cols + j, pred8, subs, te, pe)
    if not decoding:
        # flush: the top bytes of x1, so that any continuation decodes inside [x1, x2]
        for _ in range(4):
            if pos < out.size:
                out[U(pos)] = (x1 >> 24) & 0xFF
            pos += 1
            x1 = (x1 << 8) & 0xFFFFFFFF
    return pos


@njit(nogil=True, cache=True)
def med_histogram(plane, lo, size):
    """How often each residual ``r`` of :func:`wavecore.lossless.med_residuals` occurs in a
    2-D integer plane, at ``counts[r - lo]`` (``size`` bins; the caller bounds the residuals):
    the same counts without the residual plane's six temporary arrays."""
    counts = np.zeros(size, dtype=np.int64)
    rows, cols = plane.shape
    for i in range(rows):
        for j in range(cols):
            x = np.int64(plane[i, j])
            if i == 0 and j == 0:
                pred = np.int64(0)
            elif i == 0:
                pred = np.int64(plane[0, j - 1])  # the first row: from the west
            elif j == 0:
                pred = np.int64(plane[i - 1, 0])  # the first column: from the north
            else:
                w = np.int64(plane[i, j - 1])
                n = np.int64(plane[i - 1, j])
                nw = np.int64(plane[i - 1, j - 1])
                if nw >= max(w, n):
                    pred = min(w, n)
                elif nw <= min(w, n):
                    pred = max(w, n)
                else:
                    pred = w + n - nw
            counts[x - pred - lo] += 1
    return counts
