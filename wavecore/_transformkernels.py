"""Compiled loops of the transform stage: one analysis or synthesis step, and one fused 2-D
level (moved from :mod:`wavecore._kernels`, whose docstring they shared).

The general kernels (``analysis3``, ``synthesis3``) apply banded matrices in compressed-row form
along the middle axis of a 3-D view ``(outer, n, inner)`` of the data, so they serve every axis,
every trailing shape and every filter family; their innermost loop runs along ``inner``, which is
contiguous, so it vectorises.  When the transformed axis is the last one (``inner == 1``) the
``*_last`` kernels run along rows instead, with the matrices' regular interior written out with
fixed strides so that it vectorises too.  ``analysis_2d`` and ``synthesis_2d`` do one whole 2-D
level in one pass over the data.  All kernels release the GIL, so :mod:`wavecore.transform` runs
them on blocks in threads.  ``fastmath`` is deliberately off: results must not depend on it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._colourkernels import colour_to_integers

# Each kernel fills output rows [row_lo, row_hi) for outer indices [outer_lo, outer_hi): the
# callers split the work into blocks along whichever of the two is longer.


@njit(nogil=True, cache=True)
def analysis3(x, a_ptr, a_idx, a_w, b_ptr, b_idx, b_w, c, d, outer_lo, outer_hi, row_lo, row_hi):
    inner = x.shape[2]
    nc = c.shape[1]
    nd = d.shape[1]
    for o in range(outer_lo, outer_hi):
        for r in range(row_lo, row_hi):
            if r < nc:
                out = c[o, r]
                out[:] = 0
                for p in range(a_ptr[r], a_ptr[r + 1]):
                    w = a_w[p]
                    src = x[o, a_idx[p]]
                    for i in range(inner):
                        out[i] += w * src[i]
            if r < nd:
                out = d[o, r]
                out[:] = 0
                for p in range(b_ptr[r], b_ptr[r + 1]):
                    w = b_w[p]
                    src = x[o, b_idx[p]]
                    for i in range(inner):
                        out[i] += w * src[i]


# --- The same along the middle axis, from the compact form of the matrices -------------------
#
# A matrix in compact form is the tuple ``(ptr, idx, w, reg, pat)`` described below for the row
# kernels: rows ``[lo, lo + blocks * p)`` are the regular pattern, and the compressed rows hold
# only the others (row ``r`` past the interior at ``ptr[r - blocks * p]``).  Its size does not
# depend on the length, so no kernel needs an array as long as the data to describe a matrix.

MAX_TAPS = 64  # the longest row any matrix may have (the callers check)


@njit(nogil=True, cache=True)
def _taps(mat, r, p, step, cols, ws):
    """Row ``r``'s columns and weights, in increasing column order, zeros left out."""
    ptr, idx, w, reg, pat = mat
    lo = reg[0]
    hi = lo + reg[1] * p
    n = 0
    if lo <= r < hi:
        b = (r - lo) // p
        i = r - lo - b * p
        c0 = reg[2] + b * step
        for t in range(pat.shape[1]):
            wt = pat[i, t]
            if wt != 0:
                cols[n] = c0 + t
                ws[n] = wt
                n += 1
        return n
    k = r if r < lo else r - (hi - lo)
    for j in range(ptr[k], ptr[k + 1]):
        cols[n] = idx[j]
        ws[n] = w[j]
        n += 1
    return n


# The two kernels below unpack the matrices once and spell out the two kinds of rows: a
# helper taking the matrix tuple per row made them ten times slower (curves, ``inner == 2``).


@njit(nogil=True, cache=True)
def analysis_mid(x, a_mat, b_mat, c, d, outer_lo, outer_hi, row_lo, row_hi):
    """``c = A x`` and ``d = B x`` along the middle axis of ``(outer, n, inner)`` views."""
    inner = x.shape[2]
    for half in range(2):
        out_band = c if half == 0 else d
        ptr, idx, w, reg, pat = a_mat if half == 0 else b_mat
        lo = reg[0]
        hi = lo + reg[1]
        col = reg[2]
        rows = out_band.shape[1]
        for o in range(outer_lo, outer_hi):
            for r in range(row_lo, min(row_hi, rows)):
                out = out_band[o, r]
                out[:] = 0
                if lo <= r < hi:
                    c0 = col + 2 * (r - lo)
                    for t in range(pat.shape[1]):
                        wt = pat[0, t]
                        if wt != 0:
                            src = x[o, c0 + t]
                            for j in range(inner):
                                out[j] += wt * src[j]
                else:
                    k = r if r < lo else r - (hi - lo)
                    for q in range(ptr[k], ptr[k + 1]):
                        wt = w[q]
                        src = x[o, idx[q]]
                        for j in range(inner):
                            out[j] += wt * src[j]


@njit(nogil=True, cache=True)
def synthesis_mid(c, d, p_mat, q_mat, f, outer_lo, outer_hi, row_lo, row_hi):
    """``f = P c + Q d`` along the middle axis of ``(outer, n, inner)`` views."""
    inner = f.shape[2]
    for half in range(2):
        src_band = c if half == 0 else d
        ptr, idx, w, reg, pat = p_mat if half == 0 else q_mat
        lo = reg[0]
        hi = lo + 2 * reg[1]
        col = reg[2]
        for o in range(outer_lo, outer_hi):
            for r in range(row_lo, row_hi):
                out = f[o, r]
                if half == 0:
                    out[:] = 0
                if lo <= r < hi:
                    b = (r - lo) >> 1
                    i = r - lo - 2 * b
                    for t in range(pat.shape[1]):
                        wt = pat[i, t]
                        if wt != 0:
                            src = src_band[o, col + b + t]
                            for j in range(inner):
                                out[j] += wt * src[j]
                else:
                    k = r if r < lo else r - (hi - lo)
                    for q in range(ptr[k], ptr[k + 1]):
                        wt = w[q]
                        src = src_band[o, idx[q]]
                        for j in range(inner):
                            out[j] += wt * src[j]


# --- Rows along the last axis (contiguous), with the regular interior vectorised ---------------
#
# A matrix is passed as a tuple ``(ptr, idx, w, reg, pat)``: its compressed rows plus its regular
# interior ``reg = (lo, blocks, col)`` and ``pat``.  Analysis rows ``lo + b`` hold ``pat[0]`` from
# column ``col + 2 b``; synthesis rows ``lo + 2 b + i`` hold ``pat[i]`` from column ``col + b``.
# The fixed strides let LLVM vectorise the interior; the few boundary rows use the CSR form.
# Each helper has one call site per kernel where possible: LLVM inlines every call site, and
# the compile time (paid once per machine, then cached) grows with the copies.


@njit(nogil=True, cache=True)
def _csr_rows(src, ptr, idx, w, out, lo, hi, add, shift):
    """Rows ``[lo, hi)`` from the compressed rows; row ``r`` is stored at ``r - shift``."""
    zero = out.dtype.type(0)
    for r in range(lo, hi):
        acc = zero
        for k in range(ptr[r - shift], ptr[r - shift + 1]):
            acc += w[k] * src[idx[k]]
        if add:
            out[r] += acc
        else:
            out[r] = acc


@njit(nogil=True, cache=True)
def _row_analysis(src, mat, out):
    ptr, idx, w, reg, pat = mat
    lo = reg[0]
    blocks = reg[1]
    col = reg[2]
    _csr_rows(src, ptr, idx, w, out, 0, lo, False, 0)
    _csr_rows(src, ptr, idx, w, out, lo + blocks, out.shape[0], False, blocks)
    taps = pat.shape[1]
    # Slicing first makes every index below provably non-negative, so no wrap-around test is
    # compiled into the loops and they vectorise (several times faster, float32 most).
    s = src[col : col + 2 * (blocks - 1) + taps]
    o = out[lo : lo + blocks]
    if taps == 4:
        w0, w1, w2, w3 = pat[0, 0], pat[0, 1], pat[0, 2], pat[0, 3]
        for b in range(blocks):
            o[b] = w0 * s[2 * b] + w1 * s[2 * b + 1] + w2 * s[2 * b + 2] + w3 * s[2 * b + 3]
    elif taps == 2:
        w0, w1 = pat[0, 0], pat[0, 1]
        for b in range(blocks):
            o[b] = w0 * s[2 * b] + w1 * s[2 * b + 1]
    elif taps == 9:  # cdf97's low pass: spelled out, in the general loop's order of additions
        w0, w1, w2, w3, w4 = pat[0, 0], pat[0, 1], pat[0, 2], pat[0, 3], pat[0, 4]
        w5, w6, w7, w8 = pat[0, 5], pat[0, 6], pat[0, 7], pat[0, 8]
        for b in range(blocks):
            k = 2 * b
            o[b] = (
                w0 * s[k]
                + w1 * s[k + 1]
                + w2 * s[k + 2]
                + w3 * s[k + 3]
                + w4 * s[k + 4]
                + w5 * s[k + 5]
                + w6 * s[k + 6]
                + w7 * s[k + 7]
                + w8 * s[k + 8]
            )
    elif taps == 7:  # cdf97's high pass
        w0, w1, w2, w3 = pat[0, 0], pat[0, 1], pat[0, 2], pat[0, 3]
        w4, w5, w6 = pat[0, 4], pat[0, 5], pat[0, 6]
        for b in range(blocks):
            k = 2 * b
            o[b] = (
                w0 * s[k]
                + w1 * s[k + 1]
                + w2 * s[k + 2]
                + w3 * s[k + 3]
                + w4 * s[k + 4]
                + w5 * s[k + 5]
                + w6 * s[k + 6]
            )
    else:
        for b in range(blocks):
            o[b] = 0
        for t in range(taps):
            wt = pat[0, t]
            st = s[t:]
            for b in range(blocks):
                o[b] += wt * st[2 * b]


@njit(nogil=True, cache=True)
def _row_synthesis(c, d, p_mat, q_mat, out):
    """``out = P c + Q d`` along one contiguous row."""
    for part in range(2):
        src = c if part == 0 else d
        ptr, idx, w, reg, pat = p_mat if part == 0 else q_mat
        add = part == 1
        lo = reg[0]
        blocks = reg[1]
        col = reg[2]
        _csr_rows(src, ptr, idx, w, out, 0, lo, add, 0)
        _csr_rows(src, ptr, idx, w, out, lo + 2 * blocks, out.shape[0], add, 2 * blocks)
        taps = pat.shape[1]
        s = src[col : col + blocks - 1 + taps]  # sliced for non-negative indices, as above
        o = out[lo : lo + 2 * blocks]
        if not add:
            for j in range(2 * blocks):
                o[j] = 0
        if taps == 2:
            w00, w01, w10, w11 = pat[0, 0], pat[0, 1], pat[1, 0], pat[1, 1]
            for b in range(blocks):
                s0 = s[b]
                s1 = s[b + 1]
                o[2 * b] += w00 * s0 + w01 * s1
                o[2 * b + 1] += w10 * s0 + w11 * s1
        elif taps == 4 and pat.shape[0] == 2:
            # cdf97's P: one pass instead of eight, each sum in the general loop's order (so
            # the same bits: from zero, or from the value so far, one term at a time).
            w00, w01, w02, w03 = pat[0, 0], pat[0, 1], pat[0, 2], pat[0, 3]
            w10, w11, w12, w13 = pat[1, 0], pat[1, 1], pat[1, 2], pat[1, 3]
            for b in range(blocks):
                s0, s1, s2, s3 = s[b], s[b + 1], s[b + 2], s[b + 3]
                o[2 * b] = o[2 * b] + w00 * s0 + w01 * s1 + w02 * s2 + w03 * s3
                o[2 * b + 1] = o[2 * b + 1] + w10 * s0 + w11 * s1 + w12 * s2 + w13 * s3
        elif taps == 5 and pat.shape[0] == 2:  # cdf97's Q
            w00, w01, w02, w03, w04 = pat[0, 0], pat[0, 1], pat[0, 2], pat[0, 3], pat[0, 4]
            w10, w11, w12, w13, w14 = pat[1, 0], pat[1, 1], pat[1, 2], pat[1, 3], pat[1, 4]
            for b in range(blocks):
                s0, s1, s2, s3, s4 = s[b], s[b + 1], s[b + 2], s[b + 3], s[b + 4]
                o[2 * b] = o[2 * b] + w00 * s0 + w01 * s1 + w02 * s2 + w03 * s3 + w04 * s4
                o[2 * b + 1] = o[2 * b + 1] + w10 * s0 + w11 * s1 + w12 * s2 + w13 * s3 + w14 * s4
        else:
            for i in range(pat.shape[0]):
                oi = o[i:]
                for t in range(taps):
                    wt = pat[i, t]
                    st = s[t:]
                    for b in range(blocks):
                        oi[2 * b] += wt * st[b]


@njit(nogil=True, cache=True)
def analysis_last(x, a_mat, b_mat, c, d, outer_lo, outer_hi):
    for o in range(outer_lo, outer_hi):
        for half in range(2):
            _row_analysis(x[o], a_mat if half == 0 else b_mat, c[o] if half == 0 else d[o])


@njit(nogil=True, cache=True)
def synthesis_last(c, d, p_mat, q_mat, f, outer_lo, outer_hi):
    for o in range(outer_lo, outer_hi):
        _row_synthesis(c[o], d[o], p_mat, q_mat, f[o])


# --- Many short rows at once --------------------------------------------------------------------
#
# A tall, thin picture has a great many rows of a few samples, and the row kernels above pay
# their set-up once per row: a 65 536 × 8 level took 20 times as long a sample as an 8 × 65 536
# one.  The caller transposes the rows into the columns of a 2-D array ``(n, rows)``; for the
# analysis ``analysis_mid`` then adds in the row kernel's order already, but ``synthesis_mid``
# groups the detail half's sums differently, hence this kernel.


@njit(nogil=True, cache=True)
def synthesis_columns(c, d, p_mat, q_mat, f, acc):
    """:func:`_row_synthesis` of every column of ``c`` and ``d`` into the columns of ``f``;
    ``acc`` is scratch of a row's size.  As there, the detail half's boundary rows are summed
    apart and then added, and its two-tap rows add their pair."""
    m, n = f.shape
    for part in range(2):
        src = c if part == 0 else d
        ptr, idx, w, reg, pat = p_mat if part == 0 else q_mat
        add = part == 1
        rlo = reg[0]
        rhi = rlo + 2 * reg[1]
        taps = pat.shape[1]
        for r in range(m):
            out = f[r]
            if not (rlo <= r < rhi):
                k = r if r < rlo else r - (rhi - rlo)
                acc[:n] = 0
                for q in range(ptr[k], ptr[k + 1]):
                    wt = w[q]
                    s = src[idx[q]]
                    for j in range(n):
                        acc[j] += wt * s[j]
                if add:
                    for j in range(n):
                        out[j] += acc[j]
                else:
                    for j in range(n):
                        out[j] = acc[j]
                continue
            b = (r - rlo) >> 1
            i = r - rlo - 2 * b
            base = reg[2] + b
            if not add:
                out[:] = 0
            if taps == 2:
                w0, w1 = pat[i, 0], pat[i, 1]
                s0, s1 = src[base], src[base + 1]
                for j in range(n):
                    out[j] += w0 * s0[j] + w1 * s1[j]
            else:  # the row kernel's other branches add one term at a time, from the left
                for t in range(taps):
                    wt = pat[i, t]
                    s = src[base + t]
                    for j in range(n):
                        out[j] += wt * s[j]


# --- One 2-D level in one pass ---------------------------------------------------------------
#
# The data is a view ``(outer, n0, n1 * inner)``: rows are flat, with any trailing channels
# interleaved, so the axis-0 combinations run over whole rows.  Analysis makes one row of the
# axis-0 step at a time (a short combination of input rows, still in cache) and splits it at
# once along axis 1 into the final bands, so the half-transformed image is never stored.
# Synthesis does the reverse, keeping the axis-1 syntheses of recent coefficient rows in small
# ring buffers.  Trailing channels are split out one at a time for the axis-1 row kernels.


@njit(nogil=True, cache=True)
def _combine(rows, mat, r, out, cols, ws):
    """``out = sum_k w[k] * rows[col[k]]`` over the taps of row ``r`` of an analysis matrix."""
    count = _taps(mat, r, 1, 2, cols, ws)
    n = out.shape[0]
    if count == 4:
        s0, s1, s2, s3 = rows[cols[0]], rows[cols[1]], rows[cols[2]], rows[cols[3]]
        w0, w1, w2, w3 = ws[0], ws[1], ws[2], ws[3]
        for i in range(n):
            out[i] = w0 * s0[i] + w1 * s1[i] + w2 * s2[i] + w3 * s3[i]
        return
    if count == 9:  # cdf97's low pass, in the order of the general loop below (same bits)
        s0, s1, s2, s3, s4 = (
            rows[cols[0]],
            rows[cols[1]],
            rows[cols[2]],
            rows[cols[3]],
            rows[cols[4]],
        )
        s5, s6, s7, s8 = rows[cols[5]], rows[cols[6]], rows[cols[7]], rows[cols[8]]
        w0, w1, w2, w3, w4 = ws[0], ws[1], ws[2], ws[3], ws[4]
        w5, w6, w7, w8 = ws[5], ws[6], ws[7], ws[8]
        for i in range(n):
            out[i] = (
                w0 * s0[i]
                + w1 * s1[i]
                + w2 * s2[i]
                + w3 * s3[i]
                + w4 * s4[i]
                + w5 * s5[i]
                + w6 * s6[i]
                + w7 * s7[i]
                + w8 * s8[i]
            )
        return
    if count == 7:  # cdf97's high pass
        s0, s1, s2, s3 = rows[cols[0]], rows[cols[1]], rows[cols[2]], rows[cols[3]]
        s4, s5, s6 = rows[cols[4]], rows[cols[5]], rows[cols[6]]
        w0, w1, w2, w3, w4, w5, w6 = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6]
        for i in range(n):
            out[i] = (
                w0 * s0[i]
                + w1 * s1[i]
                + w2 * s2[i]
                + w3 * s3[i]
                + w4 * s4[i]
                + w5 * s5[i]
                + w6 * s6[i]
            )
        return
    for i in range(n):
        out[i] = 0
    for k in range(count):
        wk = ws[k]
        src = rows[cols[k]]
        for i in range(n):
            out[i] += wk * src[i]


@njit(nogil=True, cache=True)
def analysis_2d(x, a0, b0, a1, b1, aa, ad, da, dd, inner, outer_lo, outer_hi, row_lo, row_hi):
    width = x.shape[2]
    n1 = width // inner
    r1 = aa.shape[2] // inner
    s1 = ad.shape[2] // inner
    tmp = np.empty(width, dtype=x.dtype)
    chan = np.empty(n1, dtype=x.dtype)
    bufs = (np.empty(r1, dtype=x.dtype), np.empty(s1, dtype=x.dtype))
    r0 = aa.shape[1]
    s0 = da.shape[1]
    cols = np.empty(MAX_TAPS, dtype=np.intp)
    ws = np.empty(MAX_TAPS, dtype=x.dtype)
    for o in range(outer_lo, outer_hi):
        rows = x[o]
        for r in range(row_lo, row_hi):
            for half in range(2):
                if r >= (r0 if half == 0 else s0):
                    continue
                _combine(rows, a0 if half == 0 else b0, r, tmp, cols, ws)
                outs = (aa[o, r], ad[o, r]) if half == 0 else (da[o, r], dd[o, r])
                for ch in range(inner):
                    if inner > 1:
                        # One contiguous channel at a time, so the row kernel still vectorises.
                        for i in range(n1):
                            chan[i] = tmp[i * inner + ch]
                    src = tmp if inner == 1 else chan
                    for which in range(2):
                        out = outs[which]
                        dest = out if inner == 1 else bufs[which]
                        _row_analysis(src, a1 if which == 0 else b1, dest)
                        if inner > 1:
                            for j in range(dest.shape[0]):
                                out[j * inner + ch] = dest[j]


@njit(nogil=True, cache=True)
def _ring_row(
    aa, ad, da, dd, p0, q0, p1, q1, inner, ring_rows, o, r, scratch, slots, weights, counts, out
):
    """Fine row ``r`` of outer index ``o`` into ``out``, from the axis-1 syntheses kept in the
    ring buffers of ``scratch`` (made by :func:`_ring_scratch`; updated as rows come in)."""
    rings, tags, chan_c, chan_d, f_buf, tap_cols, tap_ws = scratch
    width = rings.shape[2]
    n1 = width // inner
    for half in range(2):
        taps = _taps(p0 if half == 0 else q0, r, 2, 1, tap_cols, tap_ws)
        coarse = aa[o] if half == 0 else da[o]
        detail = ad[o] if half == 0 else dd[o]
        n = 0
        for k in range(taps):
            i = tap_cols[k]
            slot = i % ring_rows
            if tags[half, slot] != i:
                ring = rings[half, slot]
                for ch in range(inner):
                    if inner > 1:
                        for j in range(chan_c.shape[0]):
                            chan_c[j] = coarse[i, j * inner + ch]
                        for j in range(chan_d.shape[0]):
                            chan_d[j] = detail[i, j * inner + ch]
                    _row_synthesis(
                        coarse[i] if inner == 1 else chan_c,
                        detail[i] if inner == 1 else chan_d,
                        p1,
                        q1,
                        ring if inner == 1 else f_buf,
                    )
                    if inner > 1:
                        for j in range(n1):
                            ring[j * inner + ch] = f_buf[j]
                tags[half, slot] = i
            slots[half, n] = slot
            weights[half, n] = tap_ws[k]
            n += 1
        counts[half] = n
    if counts[0] == 2 and counts[1] == 2:
        l0, l1 = rings[0, slots[0, 0]], rings[0, slots[0, 1]]
        h0, h1 = rings[1, slots[1, 0]], rings[1, slots[1, 1]]
        u0, u1, v0, v1 = weights[0, 0], weights[0, 1], weights[1, 0], weights[1, 1]
        for j in range(width):
            out[j] = u0 * l0[j] + u1 * l1[j] + v0 * h0[j] + v1 * h1[j]
        return
    if counts[0] == 3 and counts[1] == 4:
        # cdf97's even rows: one pass (not one per tap), each sum in the order of the
        # general loop below, so the same bits.
        l0, l1, l2 = rings[0, slots[0, 0]], rings[0, slots[0, 1]], rings[0, slots[0, 2]]
        h0, h1 = rings[1, slots[1, 0]], rings[1, slots[1, 1]]
        h2, h3 = rings[1, slots[1, 2]], rings[1, slots[1, 3]]
        u0, u1, u2 = weights[0, 0], weights[0, 1], weights[0, 2]
        v0, v1, v2, v3 = weights[1, 0], weights[1, 1], weights[1, 2], weights[1, 3]
        for j in range(width):
            out[j] = (
                u0 * l0[j]
                + u1 * l1[j]
                + u2 * l2[j]
                + v0 * h0[j]
                + v1 * h1[j]
                + v2 * h2[j]
                + v3 * h3[j]
            )
        return
    if counts[0] == 4 and counts[1] == 5:  # cdf97's odd rows
        l0, l1 = rings[0, slots[0, 0]], rings[0, slots[0, 1]]
        l2, l3 = rings[0, slots[0, 2]], rings[0, slots[0, 3]]
        h0, h1 = rings[1, slots[1, 0]], rings[1, slots[1, 1]]
        h2, h3, h4 = rings[1, slots[1, 2]], rings[1, slots[1, 3]], rings[1, slots[1, 4]]
        u0, u1, u2, u3 = weights[0, 0], weights[0, 1], weights[0, 2], weights[0, 3]
        v0, v1, v2 = weights[1, 0], weights[1, 1], weights[1, 2]
        v3, v4 = weights[1, 3], weights[1, 4]
        for j in range(width):
            out[j] = (
                u0 * l0[j]
                + u1 * l1[j]
                + u2 * l2[j]
                + u3 * l3[j]
                + v0 * h0[j]
                + v1 * h1[j]
                + v2 * h2[j]
                + v3 * h3[j]
                + v4 * h4[j]
            )
        return
    for j in range(width):
        out[j] = 0
    for half in range(2):
        for k in range(counts[half]):
            wk = weights[half, k]
            src = rings[half, slots[half, k]]
            for j in range(width):
                out[j] += wk * src[j]


@njit(nogil=True, cache=True)
def _ring_scratch(aa, ad, width, inner, ring_rows, dtype_of):
    """The ring buffers (two bands of ``ring_rows`` rows), their tags and the row scratch."""
    rings = np.empty((2, ring_rows, width), dtype=dtype_of.dtype)
    tags = np.full((2, ring_rows), -1, dtype=np.intp)
    chan_c = np.empty(aa.shape[2] // inner, dtype=dtype_of.dtype)
    chan_d = np.empty(ad.shape[2] // inner, dtype=dtype_of.dtype)
    f_buf = np.empty(width // inner, dtype=dtype_of.dtype)
    tap_cols = np.empty(MAX_TAPS, dtype=np.intp)
    tap_ws = np.empty(MAX_TAPS, dtype=dtype_of.dtype)
    return rings, tags, chan_c, chan_d, f_buf, tap_cols, tap_ws


@njit(nogil=True, cache=True)
def synthesis_2d(
    aa, ad, da, dd, p0, q0, p1, q1, f, inner, ring_rows, outer_lo, outer_hi, row_lo, row_hi
):
    # ``ring_rows``: axis-1 syntheses kept per band, chosen by the caller so that the taps of
    # one row never share a slot; a slot that holds another row only costs a recomputation.
    scratch = _ring_scratch(aa, ad, f.shape[2], inner, ring_rows, f)
    slots = np.empty((2, 32), dtype=np.intp)  # up to 32 taps per row and half (checked by callers)
    weights = np.empty((2, 32), dtype=f.dtype)
    counts = np.zeros(2, dtype=np.intp)
    for o in range(outer_lo, outer_hi):
        scratch[1][:] = -1
        for r in range(row_lo, row_hi):
            _ring_row(
                aa,
                ad,
                da,
                dd,
                p0,
                q0,
                p1,
                q1,
                inner,
                ring_rows,
                o,
                r,
                scratch,
                slots,
                weights,
                counts,
                f[o, r],
            )


@njit(nogil=True, cache=True)
def synthesis_2d_integers(
    aa,
    ad,
    da,
    dd,
    p0,
    q0,
    p1,
    q1,
    width,
    inner,
    ring_rows,
    matrix,
    use_matrix,
    lo,
    hi,
    out,
    row0,
    col0,
    row_lo,
    row_hi,
):
    """:func:`synthesis_2d` (one outer index) fused with :func:`colour_to_integers`: fine rows
    ``row0 + [row_lo, row_hi)``, columns from ``col0``, go through the colour matrix and the
    rounding straight into ``out`` (``(rows, cols, channels)``), one row buffer at a time, so
    the full-size float picture is never stored (nor its fresh pages touched).  The same
    values as the two passes one after the other.  ``width`` is the fine row's length
    (samples × ``inner`` channels)."""
    scratch = _ring_scratch(aa, ad, width, inner, ring_rows, aa)
    slots = np.empty((2, 32), dtype=np.intp)
    weights = np.empty((2, 32), dtype=aa.dtype)
    counts = np.zeros(2, dtype=np.intp)
    row = np.empty(width, dtype=aa.dtype)
    cols = out.shape[1]
    # The window's columns as a contiguous (1, cols, channels) array, for the vectorised loop.
    window = row[col0 * inner : (col0 + cols) * inner].reshape(1, cols, inner)
    for r in range(row_lo, row_hi):
        _ring_row(
            aa,
            ad,
            da,
            dd,
            p0,
            q0,
            p1,
            q1,
            inner,
            ring_rows,
            0,
            row0 + r,
            scratch,
            slots,
            weights,
            counts,
            row,
        )
        colour_to_integers(window, matrix, use_matrix, lo, hi, out[r : r + 1], 0, 1)
