"""Compiled loops for one analysis or synthesis step, and for one fused 2-D level.

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

import math

import numpy as np
from numba import njit

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


# --------------------------------------------------------------------------------------------
# The decoder's last pass: colour matrix, rounding and clipping into the caller's integer dtype
# --------------------------------------------------------------------------------------------


@njit(nogil=True, cache=True, inline="always")
def _rounded_into(v, lo, hi):
    """``clip(rint(v), lo, hi)``, NaN → 0: the same values as the general loop below."""
    v = np.rint(v) if v == v else 0.0
    return min(max(v, lo), hi)


@njit(nogil=True, cache=True)
def colour_to_integers(src, matrix, use_matrix, lo, hi, out, row_lo, row_hi):
    """``out = clip(rint(matrix @ src), lo, hi)`` per pixel (NaN → 0), rows ``[row_lo, row_hi)``.

    ``src`` and ``out`` are ``(rows, cols, channels)``; the matrix applies to the first three
    channels when ``use_matrix`` (the others pass through).  One pass, no float temporaries:
    the NumPy version made five full-size float64 copies of a decoded picture.
    """
    cols, channels = src.shape[1], src.shape[2]
    if use_matrix and channels == 3:
        # The common case (a colour picture), without a branch per sample, so it vectorises.
        m00, m01, m02 = matrix[0, 0], matrix[0, 1], matrix[0, 2]
        m10, m11, m12 = matrix[1, 0], matrix[1, 1], matrix[1, 2]
        m20, m21, m22 = matrix[2, 0], matrix[2, 1], matrix[2, 2]
        for i in range(row_lo, row_hi):
            row = src[i]
            dest = out[i]
            for j in range(cols):
                y, cb, cr = row[j, 0], row[j, 1], row[j, 2]
                dest[j, 0] = _rounded_into(m00 * y + m01 * cb + m02 * cr, lo, hi)
                dest[j, 1] = _rounded_into(m10 * y + m11 * cb + m12 * cr, lo, hi)
                dest[j, 2] = _rounded_into(m20 * y + m21 * cb + m22 * cr, lo, hi)
        return
    for i in range(row_lo, row_hi):
        for j in range(cols):
            pixel = src[i, j]
            for c in range(channels):
                if use_matrix and c < 3:
                    v = matrix[c, 0] * pixel[0] + matrix[c, 1] * pixel[1] + matrix[c, 2] * pixel[2]
                else:
                    v = pixel[c]
                if v != v:
                    v = 0.0
                v = np.rint(v)
                if v < lo:
                    v = lo
                elif v > hi:
                    v = hi
                out[i, j, c] = v


@njit(nogil=True, cache=True)
def squared_and_largest_error(decoded, original):
    """(sum of squared differences, largest absolute difference) of two same-shape 1-D arrays."""
    total = 0.0
    largest = 0.0
    for k in range(decoded.size):
        d = np.float64(decoded[k]) - np.float64(original[k])  # float32 pairs too
        total += d * d
        d = abs(d)
        if d > largest or d != d:
            largest = d
    return total, largest


@njit(nogil=True, cache=True)
def squared_and_largest_integer_error(decoded, original):
    """:func:`squared_and_largest_error` of integer samples whose squared differences add up
    below ``2**53``, in integers: the same values (every float partial sum of integers that
    small is exact), in a loop that vectorises (a float sum must keep its order)."""
    total = np.int64(0)
    largest = np.int64(0)
    for k in range(decoded.size):
        d = np.int64(decoded[k]) - np.int64(original[k])
        total += d * d
        if d < 0:
            d = -d
        if d > largest:
            largest = d
    return total, largest


@njit(nogil=True, cache=True)
def colour_to_floats(src, matrix, out, row_lo, row_hi):
    """``out = matrix @ src`` per pixel on the first three channels (the others copied), as
    float64, rows ``[row_lo, row_hi)``: the encoder's colour transform in one pass."""
    cols, channels = src.shape[1], src.shape[2]
    for i in range(row_lo, row_hi):
        for j in range(cols):
            pixel = src[i, j]
            a, b, c = float(pixel[0]), float(pixel[1]), float(pixel[2])
            for k in range(3):
                out[i, j, k] = matrix[k, 0] * a + matrix[k, 1] * b + matrix[k, 2] * c
            for k in range(3, channels):
                out[i, j, k] = pixel[k]


@njit(nogil=True, cache=True)
def deadzone_quantize(values, inverse_step, rounding, largest, out):
    """``out = sign(v) · min(floor(|v| · inverse_step + rounding), largest)``, elementwise."""
    for k in range(values.size):
        v = values[k]
        q = min(np.floor(abs(v) * inverse_step + rounding), largest)
        out[k] = -q if v < 0 else q


@njit(nogil=True, cache=True)
def dequantize(q, offset, step, out):
    """``out = sign(q) · (|q| + offset) · step`` for ``q != 0``, and 0 where ``q == 0``."""
    for k in range(q.size):
        v = np.int64(q[k])
        # Selects rather than branches, so that it vectorises; the same values as
        # ``(v + offset) * step`` for positive ``v``, negated for negative ones.
        scaled = (float(abs(v)) + offset) * step
        out[k] = 0.0 if v == 0 else (scaled if v > 0 else -scaled)


@njit(nogil=True, cache=True)
def count_ones_and_more(q):
    """How many values have magnitude 1, and how many 2 or more."""
    ones = 0
    more = 0
    for k in range(q.size):
        a = abs(np.int64(q[k]))
        if a == 1:
            ones += 1
        elif a >= 2:
            more += 1
    return ones, more


@njit(nogil=True, cache=True)
def largest_scaled(values, scale):
    """The largest ``|v| · scale`` (0 for no values): the first pass of :func:`log_histogram`."""
    largest = 0.0
    for k in range(values.size):
        largest = max(largest, abs(values[k]) * scale)
    return largest


@njit(nogil=True, cache=True)
def _log_bin(a, per_octave, octaves, top):
    """The bin of one scaled magnitude ``a`` by ``frexp`` (zeros, subnormals, inf and NaN)."""
    if a == 0:
        return 0
    mantissa, exponent = math.frexp(a)  # a = mantissa · 2**exponent, mantissa in [0.5, 1)
    octave = exponent - top + octaves - 1
    if octave < 0:
        return 0
    return octave * per_octave + int((2.0 * mantissa - 1.0) * per_octave)


_CHUNK = 1024


@njit(nogil=True, cache=True)
def log_histogram_counts(values, scale, per_octave, octaves, top):
    """The counts of :func:`log_histogram` for a given top octave ``top``: its second pass.

    Counts of slices add up to the counts of the whole (so slices can run in threads).  For
    normal numbers the exponent and mantissa are read from the float's bits, which is what
    ``frexp`` returns (exponent ``e - 1022``, ``2 · mantissa - 1`` the fraction bits over
    ``2**52``, exactly), at a fraction of its cost; the rest go through ``frexp``."""
    bins = per_octave * octaves
    counts = np.zeros(bins, dtype=np.int64)
    scaled = np.empty(_CHUNK, dtype=np.float64)
    bits = scaled.view(np.uint64)
    fraction_unit = 2.0**-52
    for start in range(0, values.size, _CHUNK):
        stop = min(start + _CHUNK, values.size)
        for k in range(start, stop):
            scaled[k - start] = abs(values[k]) * scale
        for k in range(stop - start):
            word = bits[k]
            biased = np.int64((word >> np.uint64(52)) & np.uint64(0x7FF))
            if biased == 0 or biased == 0x7FF:  # zero, subnormal, inf or NaN
                counts[_log_bin(scaled[k], per_octave, octaves, top)] += 1
                continue
            octave = biased - 1022 - top + octaves - 1
            if octave < 0:
                counts[0] += 1
                continue
            fraction = np.float64(word & np.uint64(0xFFFFFFFFFFFFF)) * fraction_unit
            counts[octave * per_octave + int(fraction * per_octave)] += 1
    return counts


@njit(nogil=True, cache=True)
def top_octave(largest):
    """The exponent ``frexp`` gives the largest scaled magnitude (0 when it is 0)."""
    return math.frexp(largest)[1] if largest > 0 else 0


@njit(nogil=True, cache=True)
def log_histogram(values, scale, per_octave, octaves):
    """Counts of ``|v| · scale`` in ``per_octave`` bins to an octave (equal steps of the
    mantissa), over the ``octaves`` octaves below the largest; bin 0 also holds everything
    smaller (zeros included).  Returns the counts and the top octave's exponent ``top``: bin
    ``b = per_octave · o + k`` starts at ``2 ** (top - octaves + o) · (1 + k / per_octave)``.
    Exponents come from ``frexp``: no logarithm per value.
    """
    top = top_octave(largest_scaled(values, scale))
    return log_histogram_counts(values, scale, per_octave, octaves, top), top


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
