"""Compiled loops of the lossless pipeline: the reversible integer liftings, value ranges
and histograms, and the predicted reversible colour transform.  Moved from
:mod:`wavecore._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# --------------------------------------------------------------------------------------------
# The reversible integer liftings of ``wavecore.lossless`` along the middle axis of
# ``(outer, n, inner)`` int64 views: the same integer formulas as its docstring, written out
# per sample (NumPy made a dozen whole-array temporaries per step).  ``kind``: 0 LeGall 5/3,
# 1 integer Haar, 2 the closed bspline2, 3 the 5/11-C of JPEG 2000 Part 2 (5/3 and one more
# predict step).  Each fills outer indices ``[o_lo, o_hi)`` and inner
# columns ``[j_lo, j_hi)``; int64 arithmetic wraps as NumPy's does.
# --------------------------------------------------------------------------------------------


@njit(nogil=True, cache=True)
def lift_steps(x, s, d, kind, o_lo, o_hi, j_lo, j_hi):
    """One analysis step: ``x`` (n rows) into ``s`` (coarse) and ``d`` (detail) rows."""
    # Indexed in place, not through row views: along an image's second axis ``inner`` is its
    # 1 to 4 channels, and a view per row cost more than the arithmetic.
    n = x.shape[1]
    ns = s.shape[1]
    nd = d.shape[1]
    saved = np.empty(max(j_hi - j_lo, 0), dtype=np.int64)
    for o in range(o_lo, o_hi):
        if kind != 2 and n < 2:
            for i in range(ns):
                for j in range(j_lo, j_hi):
                    s[o, i, j] = x[o, i, j]
            continue
        if kind == 2:
            # s and e first (e kept in d), then c and d from the last row down, so that each
            # row's e[i - 1] is still unchanged when it is read; e[-1] is e[K - 1], saved.
            for i in range(ns):
                for j in range(j_lo, j_hi):
                    t = x[o, 2 * i, j] - x[o, 2 * i + 1, j]
                    v = x[o, 2 * i + 1, j] + (t >> 1)
                    s[o, i, j] = v
                    d[o, i, j] = t - v
            if ns == 0:
                continue
            for j in range(j_lo, j_hi):
                saved[j - j_lo] = d[o, ns - 1, j]
            for i in range(ns - 1, -1, -1):
                for j in range(j_lo, j_hi):
                    before = d[o, i - 1, j] if i > 0 else saved[j - j_lo]
                    c = s[o, i, j] + ((d[o, i, j] - before) >> 1)
                    s[o, i, j] = c
                    d[o, i, j] = c + before
            continue
        if kind == 1:
            for i in range(nd):
                for j in range(j_lo, j_hi):
                    v = x[o, 2 * i + 1, j] - x[o, 2 * i, j]
                    d[o, i, j] = v
                    s[o, i, j] = x[o, 2 * i, j] + (v >> 1)
            if ns > nd:
                for j in range(j_lo, j_hi):
                    s[o, ns - 1, j] = x[o, n - 1, j]
            continue
        if j_hi - j_lo >= _FUSED_LEAST:
            _lift_fused(x, s, d, kind, o, n, ns, nd, j_lo, j_hi)
            continue
        for i in range(nd):  # 5/3 predict: s[i + 1] past the end is s[ns - 1] (= x[2 i])
            right = 2 * i + 2 if 2 * i + 2 < n else 2 * i
            for j in range(j_lo, j_hi):
                d[o, i, j] = x[o, 2 * i + 1, j] - ((x[o, 2 * i, j] + x[o, right, j]) >> 1)
        for i in range(ns):  # 5/3 update: d[-1] is d[0], d[nd] is d[nd - 1]
            left = i - 1 if i > 0 else 0
            right = i if i < nd else nd - 1
            for j in range(j_lo, j_hi):
                s[o, i, j] = x[o, 2 * i, j] + ((d[o, left, j] + d[o, right, j] + 2) >> 2)
        if kind == 3:  # 5/11-C: the details corrected by the coarse samples' curvature
            for i in range(nd):
                a, b, c, e = _coarse_taps(i, ns, n)
                for j in range(j_lo, j_hi):
                    d[o, i, j] += (s[o, a, j] - s[o, b, j] - s[o, c, j] + s[o, e, j] + 8) >> 4


#: The fewest inner columns lifted row by row in one pass (``_lift_fused``): along an image's
#: first axis (a row of columns each) it took 5/3 0.7x and 5/11-C 0.8x the time of a pass per
#: step; along its second (one column) the pass per step is the quicker.
_FUSED_LEAST = 8


@njit(nogil=True, cache=True)
def _lift_fused(x, s, d, kind, o, n, ns, nd, j_lo, j_hi):
    """5/3 (``kind`` 0) or 5/11-C (3) of outer index ``o`` in one pass over the rows, each
    coarse row made as soon as the details it reads are: row ``i``'s predict, then its update
    (from ``d[i - 1]``, made the row before), then (5/11-C) the correction of the detail row
    two back, whose coarse taps ``s[i - 3 .. i]`` are all made by then (the last two are
    corrected after the loop).  The same formulas as :func:`lift_steps`' passes, in an order
    that reads each row while it is in cache; an update never reads a corrected detail."""
    for i in range(ns):
        if i < nd:
            right = 2 * i + 2 if 2 * i + 2 < n else 2 * i
            for j in range(j_lo, j_hi):
                d[o, i, j] = x[o, 2 * i + 1, j] - ((x[o, 2 * i, j] + x[o, right, j]) >> 1)
        left = i - 1 if i > 0 else 0
        right = i if i < nd else nd - 1
        for j in range(j_lo, j_hi):
            s[o, i, j] = x[o, 2 * i, j] + ((d[o, left, j] + d[o, right, j] + 2) >> 2)
        if kind == 3 and i >= 2 and i - 2 < nd:
            a, b, c, e = _coarse_taps(i - 2, ns, n)
            for j in range(j_lo, j_hi):
                d[o, i - 2, j] += (s[o, a, j] - s[o, b, j] - s[o, c, j] + s[o, e, j] + 8) >> 4
    if kind == 3:
        for i in range(max(ns - 2, 0), nd):
            a, b, c, e = _coarse_taps(i, ns, n)
            for j in range(j_lo, j_hi):
                d[o, i, j] += (s[o, a, j] - s[o, b, j] - s[o, c, j] + s[o, e, j] + 8) >> 4


@njit(nogil=True, cache=True, inline="always")
def _coarse_reflect(i, ns, n):
    """Coarse index ``i`` mirrored as whole-sample symmetric extension of the ``n`` samples
    mirrors it: about coarse sample 0 on the left; on the right about the last coarse sample
    (odd ``n``) or half a sample past it (even ``n``); clamped for very short signals."""
    if i < 0:
        i = -i
    if i >= ns:
        i = 2 * (ns - 1) - i if n % 2 else 2 * ns - 1 - i
    return min(max(i, 0), ns - 1)


@njit(nogil=True, cache=True, inline="always")
def _coarse_taps(i, ns, n):
    """The coarse samples ``i - 1, i, i + 1, i + 2`` of the 5/11-C detail correction."""
    if i > 0 and i + 2 < ns:  # inside: no mirroring (a row lifted alone took it per sample)
        return i - 1, i, i + 1, i + 2
    return (
        _coarse_reflect(i - 1, ns, n),
        _coarse_reflect(i, ns, n),
        _coarse_reflect(i + 1, ns, n),
        _coarse_reflect(i + 2, ns, n),
    )


@njit(nogil=True, cache=True)
def unlift_steps(s, d, out, kind, o_lo, o_hi, j_lo, j_hi):
    """The exact inverse of :func:`lift_steps`: ``s`` and ``d`` rows back into ``out``."""
    ns = s.shape[1]
    nd = d.shape[1]
    for o in range(o_lo, o_hi):
        if kind != 2 and nd == 0:
            for i in range(ns):
                for j in range(j_lo, j_hi):
                    out[o, i, j] = s[o, i, j]
            continue
        if kind == 2:
            for i in range(ns):
                f = i + 1 if i + 1 < ns else 0
                for j in range(j_lo, j_hi):
                    before = d[o, i, j] - s[o, i, j]
                    e = d[o, f, j] - s[o, f, j]
                    v = s[o, i, j] - ((e - before) >> 1)
                    t = e + v
                    w = v - (t >> 1)
                    out[o, 2 * i, j] = t + w
                    out[o, 2 * i + 1, j] = w
            continue
        if kind == 1:
            for i in range(nd):
                for j in range(j_lo, j_hi):
                    v = s[o, i, j] - (d[o, i, j] >> 1)
                    out[o, 2 * i, j] = v
                    out[o, 2 * i + 1, j] = d[o, i, j] + v
            if ns > nd:
                for j in range(j_lo, j_hi):
                    out[o, 2 * nd, j] = s[o, ns - 1, j]
            continue
        if kind == 3:  # undo the 5/11-C correction into the odd rows, then 5/3 from them
            n = ns + nd
            for i in range(nd):
                a, b, c, e = _coarse_taps(i, ns, n)
                for j in range(j_lo, j_hi):
                    out[o, 2 * i + 1, j] = d[o, i, j] - (
                        (s[o, a, j] - s[o, b, j] - s[o, c, j] + s[o, e, j] + 8) >> 4
                    )
            for i in range(ns):
                left = 2 * (i - 1 if i > 0 else 0) + 1
                right = 2 * (i if i < nd else nd - 1) + 1
                for j in range(j_lo, j_hi):
                    out[o, 2 * i, j] = s[o, i, j] - ((out[o, left, j] + out[o, right, j] + 2) >> 2)
            for i in range(nd):
                right = 2 * i + 2 if i + 1 < ns else 2 * i
                for j in range(j_lo, j_hi):
                    out[o, 2 * i + 1, j] += (out[o, 2 * i, j] + out[o, right, j]) >> 1
            continue
        for i in range(ns):  # undo the 5/3 update into the even rows
            left = i - 1 if i > 0 else 0
            right = i if i < nd else nd - 1
            for j in range(j_lo, j_hi):
                out[o, 2 * i, j] = s[o, i, j] - ((d[o, left, j] + d[o, right, j] + 2) >> 2)
        for i in range(nd):  # then the predict, from the restored even rows
            right = 2 * i + 2 if i + 1 < ns else 2 * i
            for j in range(j_lo, j_hi):
                out[o, 2 * i + 1, j] = d[o, i, j] + ((out[o, 2 * i, j] + out[o, right, j]) >> 1)


@njit(nogil=True, cache=True)
def value_range(values):
    """``(smallest, largest)`` of a non-empty 1-D integer array."""
    lo = values[0]
    hi = values[0]
    for k in range(1, values.size):
        v = values[k]
        lo = min(lo, v)
        hi = max(hi, v)
    return lo, hi


@njit(nogil=True, cache=True)
def value_histogram(values, lo, bins):
    """How often each of ``lo, lo + 1, ..., lo + bins - 1`` occurs in ``values``."""
    counts = np.zeros(bins, dtype=np.int64)
    for k in range(values.size):
        counts[values[k] - lo] += 1
    return counts


# --------------------------------------------------------------------------------------------
# The lossless colour transform with chroma prediction (``wavecore.lossless``): JPEG 2000's RCT
# and ``Cr -= floor((w Cb + 4) / 8)`` in one pass per pixel, either way, over pixel rows
# ``[lo, hi)`` of ``(pixels, channels)`` views (channels past the third are copied).
# --------------------------------------------------------------------------------------------


@njit(nogil=True, cache=True)
def predicted_rct_forward(rgb, weight, out, lo, hi):
    """``(R, G, B, ...)`` to ``(Y, Cb, Cr - prediction, ...)`` as int64."""
    for i in range(lo, hi):
        r = np.int64(rgb[i, 0])
        g = np.int64(rgb[i, 1])
        b = np.int64(rgb[i, 2])
        cb = b - g
        out[i, 0] = (r + 2 * g + b) >> 2
        out[i, 1] = cb
        out[i, 2] = r - g - ((weight * cb + 4) >> 3)
        for k in range(3, rgb.shape[1]):
            out[i, k] = rgb[i, k]


@njit(nogil=True, cache=True)
def predicted_rct_inverse(ycc, weight, out, lo, hi):
    """The exact inverse of :func:`predicted_rct_forward`."""
    for i in range(lo, hi):
        cb = np.int64(ycc[i, 1])
        cr = np.int64(ycc[i, 2]) + ((weight * cb + 4) >> 3)
        g = np.int64(ycc[i, 0]) - ((cb + cr) >> 2)
        out[i, 0] = cr + g
        out[i, 1] = g
        out[i, 2] = cb + g
        for k in range(3, ycc.shape[1]):
            out[i, k] = ycc[i, k]
