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


@njit(nogil=True, cache=True)
def synthesis3(c, d, p_ptr, p_idx, p_w, q_ptr, q_idx, q_w, f, outer_lo, outer_hi, row_lo, row_hi):
    inner = f.shape[2]
    for o in range(outer_lo, outer_hi):
        for r in range(row_lo, row_hi):
            out = f[o, r]
            out[:] = 0
            for p in range(p_ptr[r], p_ptr[r + 1]):
                w = p_w[p]
                src = c[o, p_idx[p]]
                for i in range(inner):
                    out[i] += w * src[i]
            for p in range(q_ptr[r], q_ptr[r + 1]):
                w = q_w[p]
                src = d[o, q_idx[p]]
                for i in range(inner):
                    out[i] += w * src[i]


# --- Rows along the last axis (contiguous), with the regular interior vectorised ---------------
#
# A matrix is passed as its compressed rows ``(ptr, idx, w)`` plus its regular interior ``reg =
# (lo, blocks, col)`` and ``pat``: analysis rows ``lo + b`` hold ``pat[0]`` from column
# ``col + 2 b``; synthesis rows ``lo + 2 b + i`` hold ``pat[i]`` from column ``col + b``.  The
# fixed strides let LLVM vectorise the interior; the few boundary rows go through the CSR form.


@njit(nogil=True, cache=True)
def _csr_rows(src, ptr, idx, w, out, lo, hi, add):
    zero = out.dtype.type(0)
    for r in range(lo, hi):
        acc = zero
        for k in range(ptr[r], ptr[r + 1]):
            acc += w[k] * src[idx[k]]
        if add:
            out[r] += acc
        else:
            out[r] = acc


@njit(nogil=True, cache=True)
def _row_analysis(src, ptr, idx, w, reg, pat, out):
    lo = reg[0]
    blocks = reg[1]
    col = reg[2]
    _csr_rows(src, ptr, idx, w, out, 0, lo, False)
    _csr_rows(src, ptr, idx, w, out, lo + blocks, out.shape[0], False)
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
    else:
        for b in range(blocks):
            o[b] = 0
        for t in range(taps):
            wt = pat[0, t]
            st = s[t:]
            for b in range(blocks):
                o[b] += wt * st[2 * b]


@njit(nogil=True, cache=True)
def _row_synthesis_part(src, ptr, idx, w, reg, pat, out, add):
    lo = reg[0]
    blocks = reg[1]
    col = reg[2]
    _csr_rows(src, ptr, idx, w, out, 0, lo, add)
    _csr_rows(src, ptr, idx, w, out, lo + 2 * blocks, out.shape[0], add)
    taps = pat.shape[1]
    s = src[col : col + blocks - 1 + taps]  # sliced for non-negative indices, as above
    o = out[lo : lo + 2 * blocks]
    if taps == 2:
        w00, w01, w10, w11 = pat[0, 0], pat[0, 1], pat[1, 0], pat[1, 1]
        if add:
            for b in range(blocks):
                s0 = s[b]
                s1 = s[b + 1]
                o[2 * b] += w00 * s0 + w01 * s1
                o[2 * b + 1] += w10 * s0 + w11 * s1
        else:
            for b in range(blocks):
                s0 = s[b]
                s1 = s[b + 1]
                o[2 * b] = w00 * s0 + w01 * s1
                o[2 * b + 1] = w10 * s0 + w11 * s1
    else:
        if not add:
            for j in range(2 * blocks):
                o[j] = 0
        for i in range(pat.shape[0]):
            oi = o[i:]
            for t in range(taps):
                wt = pat[i, t]
                st = s[t:]
                for b in range(blocks):
                    oi[2 * b] += wt * st[b]


@njit(nogil=True, cache=True)
def _row_synthesis(c, d, p_ptr, p_idx, p_w, p_reg, p_pat, q_ptr, q_idx, q_w, q_reg, q_pat, out):
    _row_synthesis_part(c, p_ptr, p_idx, p_w, p_reg, p_pat, out, False)
    _row_synthesis_part(d, q_ptr, q_idx, q_w, q_reg, q_pat, out, True)


@njit(nogil=True, cache=True)
def analysis_last(
    x, a_ptr, a_idx, a_w, a_reg, a_pat, b_ptr, b_idx, b_w, b_reg, b_pat, c, d, outer_lo, outer_hi
):
    for o in range(outer_lo, outer_hi):
        _row_analysis(x[o], a_ptr, a_idx, a_w, a_reg, a_pat, c[o])
        _row_analysis(x[o], b_ptr, b_idx, b_w, b_reg, b_pat, d[o])


@njit(nogil=True, cache=True)
def synthesis_last(
    c, d, p_ptr, p_idx, p_w, p_reg, p_pat, q_ptr, q_idx, q_w, q_reg, q_pat, f, outer_lo, outer_hi
):
    for o in range(outer_lo, outer_hi):
        _row_synthesis(
            c[o], d[o], p_ptr, p_idx, p_w, p_reg, p_pat, q_ptr, q_idx, q_w, q_reg, q_pat, f[o]
        )


# --- One 2-D level in one pass ---------------------------------------------------------------
#
# The data is a view ``(outer, n0, n1 * inner)``: rows are flat, with any trailing channels
# interleaved, so the axis-0 combinations run over whole rows.  Analysis makes one row of the
# axis-0 step at a time (a short combination of input rows, still in cache) and splits it at
# once along axis 1 into the final bands, so the half-transformed image is never stored.
# Synthesis does the reverse, keeping the axis-1 syntheses of recent coefficient rows in small
# ring buffers.  Trailing channels are split out one at a time for the axis-1 row kernels.


@njit(nogil=True, cache=True)
def _combine(rows, ptr, idx, w, r, out):
    """``out = sum_k w[k] * rows[idx[k]]`` over the taps of row ``r``."""
    k0 = ptr[r]
    k1 = ptr[r + 1]
    n = out.shape[0]
    if k1 - k0 == 4:
        s0, s1, s2, s3 = rows[idx[k0]], rows[idx[k0 + 1]], rows[idx[k0 + 2]], rows[idx[k0 + 3]]
        w0, w1, w2, w3 = w[k0], w[k0 + 1], w[k0 + 2], w[k0 + 3]
        for i in range(n):
            out[i] = w0 * s0[i] + w1 * s1[i] + w2 * s2[i] + w3 * s3[i]
        return
    for i in range(n):
        out[i] = 0
    for k in range(k0, k1):
        wk = w[k]
        src = rows[idx[k]]
        for i in range(n):
            out[i] += wk * src[i]


@njit(nogil=True, cache=True)
def _split_row(
    tmp,
    inner,
    a_ptr,
    a_idx,
    a_w,
    a_reg,
    a_pat,
    b_ptr,
    b_idx,
    b_w,
    b_reg,
    b_pat,
    chan,
    c_buf,
    d_buf,
    out_c,
    out_d,
):
    """The axis-1 analysis of one flat row ``(n1, inner)``, into flat rows of the two bands."""
    if inner == 1:
        _row_analysis(tmp, a_ptr, a_idx, a_w, a_reg, a_pat, out_c)
        _row_analysis(tmp, b_ptr, b_idx, b_w, b_reg, b_pat, out_d)
        return
    # Trailing channels: one contiguous channel at a time, so the row kernels still vectorise.
    n1 = tmp.shape[0] // inner
    r1 = out_c.shape[0] // inner
    s1 = out_d.shape[0] // inner
    for ch in range(inner):
        for i in range(n1):
            chan[i] = tmp[i * inner + ch]
        _row_analysis(chan[:n1], a_ptr, a_idx, a_w, a_reg, a_pat, c_buf[:r1])
        _row_analysis(chan[:n1], b_ptr, b_idx, b_w, b_reg, b_pat, d_buf[:s1])
        for j in range(r1):
            out_c[j * inner + ch] = c_buf[j]
        for j in range(s1):
            out_d[j * inner + ch] = d_buf[j]


@njit(nogil=True, cache=True)
def _merge_row(
    c,
    d,
    inner,
    p_ptr,
    p_idx,
    p_w,
    p_reg,
    p_pat,
    q_ptr,
    q_idx,
    q_w,
    q_reg,
    q_pat,
    chan_c,
    chan_d,
    f_buf,
    out,
):
    """The axis-1 synthesis of one flat coarse row and one flat detail row, into ``out``."""
    if inner == 1:
        _row_synthesis(c, d, p_ptr, p_idx, p_w, p_reg, p_pat, q_ptr, q_idx, q_w, q_reg, q_pat, out)
        return
    r1 = c.shape[0] // inner
    s1 = d.shape[0] // inner
    n1 = out.shape[0] // inner
    for ch in range(inner):
        for j in range(r1):
            chan_c[j] = c[j * inner + ch]
        for j in range(s1):
            chan_d[j] = d[j * inner + ch]
        _row_synthesis(
            chan_c[:r1],
            chan_d[:s1],
            p_ptr,
            p_idx,
            p_w,
            p_reg,
            p_pat,
            q_ptr,
            q_idx,
            q_w,
            q_reg,
            q_pat,
            f_buf[:n1],
        )
        for i in range(n1):
            out[i * inner + ch] = f_buf[i]


@njit(nogil=True, cache=True)
def analysis_2d(
    x,
    a0_ptr,
    a0_idx,
    a0_w,
    b0_ptr,
    b0_idx,
    b0_w,
    a1_ptr,
    a1_idx,
    a1_w,
    a1_reg,
    a1_pat,
    b1_ptr,
    b1_idx,
    b1_w,
    b1_reg,
    b1_pat,
    aa,
    ad,
    da,
    dd,
    inner,
    outer_lo,
    outer_hi,
    row_lo,
    row_hi,
):
    width = x.shape[2]  # n1 * inner: rows are flat, channels (if any) interleaved
    tmp = np.empty(width, dtype=x.dtype)
    chan = np.empty(width // inner, dtype=x.dtype)
    c_buf = np.empty(width // inner + 2, dtype=x.dtype)
    d_buf = np.empty(width // inner + 2, dtype=x.dtype)
    r0 = aa.shape[1]
    s0 = da.shape[1]
    for o in range(outer_lo, outer_hi):
        rows = x[o]
        for r in range(row_lo, row_hi):
            if r < r0:
                _combine(rows, a0_ptr, a0_idx, a0_w, r, tmp)
                _split_row(
                    tmp,
                    inner,
                    a1_ptr,
                    a1_idx,
                    a1_w,
                    a1_reg,
                    a1_pat,
                    b1_ptr,
                    b1_idx,
                    b1_w,
                    b1_reg,
                    b1_pat,
                    chan,
                    c_buf,
                    d_buf,
                    aa[o, r],
                    ad[o, r],
                )
            if r < s0:
                _combine(rows, b0_ptr, b0_idx, b0_w, r, tmp)
                _split_row(
                    tmp,
                    inner,
                    a1_ptr,
                    a1_idx,
                    a1_w,
                    a1_reg,
                    a1_pat,
                    b1_ptr,
                    b1_idx,
                    b1_w,
                    b1_reg,
                    b1_pat,
                    chan,
                    c_buf,
                    d_buf,
                    da[o, r],
                    dd[o, r],
                )


_RING = 16  # rows of axis-1 syntheses kept per band; a miss only costs a recomputation


@njit(nogil=True, cache=True)
def synthesis_2d(
    aa,
    ad,
    da,
    dd,
    p0_ptr,
    p0_idx,
    p0_w,
    q0_ptr,
    q0_idx,
    q0_w,
    p1_ptr,
    p1_idx,
    p1_w,
    p1_reg,
    p1_pat,
    q1_ptr,
    q1_idx,
    q1_w,
    q1_reg,
    q1_pat,
    f,
    inner,
    outer_lo,
    outer_hi,
    row_lo,
    row_hi,
):
    n1 = f.shape[2]  # flat rows: n1 * inner
    low = np.empty((_RING, n1), dtype=f.dtype)
    high = np.empty((_RING, n1), dtype=f.dtype)
    chan_c = np.empty(n1 // inner + 2, dtype=f.dtype)
    chan_d = np.empty(n1 // inner + 2, dtype=f.dtype)
    f_buf = np.empty(n1 // inner, dtype=f.dtype)
    low_tag = np.empty(_RING, dtype=np.intp)
    high_tag = np.empty(_RING, dtype=np.intp)
    slots = np.empty(64, dtype=np.intp)  # up to 32 taps per row and band (checked by callers)
    weights = np.empty(64, dtype=f.dtype)
    for o in range(outer_lo, outer_hi):
        low_tag[:] = -1
        high_tag[:] = -1
        for r in range(row_lo, row_hi):
            n_low = 0
            for k in range(p0_ptr[r], p0_ptr[r + 1]):
                i = p0_idx[k]
                slot = i % _RING
                if low_tag[slot] != i:
                    _merge_row(
                        aa[o, i],
                        ad[o, i],
                        inner,
                        p1_ptr,
                        p1_idx,
                        p1_w,
                        p1_reg,
                        p1_pat,
                        q1_ptr,
                        q1_idx,
                        q1_w,
                        q1_reg,
                        q1_pat,
                        chan_c,
                        chan_d,
                        f_buf,
                        low[slot],
                    )
                    low_tag[slot] = i
                slots[n_low] = slot
                weights[n_low] = p0_w[k]
                n_low += 1
            n_high = 0
            for k in range(q0_ptr[r], q0_ptr[r + 1]):
                i = q0_idx[k]
                slot = i % _RING
                if high_tag[slot] != i:
                    _merge_row(
                        da[o, i],
                        dd[o, i],
                        inner,
                        p1_ptr,
                        p1_idx,
                        p1_w,
                        p1_reg,
                        p1_pat,
                        q1_ptr,
                        q1_idx,
                        q1_w,
                        q1_reg,
                        q1_pat,
                        chan_c,
                        chan_d,
                        f_buf,
                        high[slot],
                    )
                    high_tag[slot] = i
                slots[32 + n_high] = slot
                weights[32 + n_high] = q0_w[k]
                n_high += 1
            out = f[o, r]
            if n_low == 2 and n_high == 2:
                l0, l1 = low[slots[0]], low[slots[1]]
                h0, h1 = high[slots[32]], high[slots[33]]
                u0, u1, v0, v1 = weights[0], weights[1], weights[32], weights[33]
                for j in range(n1):
                    out[j] = u0 * l0[j] + u1 * l1[j] + v0 * h0[j] + v1 * h1[j]
                continue
            for j in range(n1):
                out[j] = 0
            for k in range(n_low):
                wk = weights[k]
                src = low[slots[k]]
                for j in range(n1):
                    out[j] += wk * src[j]
            for k in range(n_high):
                wk = weights[32 + k]
                src = high[slots[32 + k]]
                for j in range(n1):
                    out[j] += wk * src[j]
