"""Compiled loops for one analysis or synthesis step.

Each step applies banded matrices in compressed-row form along the middle axis of a 3-D view
``(outer, n, inner)`` of the data, so one kernel serves every axis, every trailing shape and every
filter family.  The kernels release the GIL, so :mod:`wavecore.transform` runs them on blocks in
threads.  When the transformed axis is the last one (``inner == 1``) the 2-D variants avoid a
loop of length one in the innermost position.
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
def analysis2(x, a_ptr, a_idx, a_w, b_ptr, b_idx, b_w, c, d, outer_lo, outer_hi, row_lo, row_hi):
    nc = c.shape[1]
    nd = d.shape[1]
    zero = x.dtype.type(0)
    for o in range(outer_lo, outer_hi):
        src = x[o]
        for r in range(row_lo, row_hi):
            if r < nc:
                acc = zero
                for p in range(a_ptr[r], a_ptr[r + 1]):
                    acc += a_w[p] * src[a_idx[p]]
                c[o, r] = acc
            if r < nd:
                acc = zero
                for p in range(b_ptr[r], b_ptr[r + 1]):
                    acc += b_w[p] * src[b_idx[p]]
                d[o, r] = acc


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


@njit(nogil=True, cache=True)
def synthesis2(c, d, p_ptr, p_idx, p_w, q_ptr, q_idx, q_w, f, outer_lo, outer_hi, row_lo, row_hi):
    zero = f.dtype.type(0)
    for o in range(outer_lo, outer_hi):
        cs = c[o]
        ds = d[o]
        for r in range(row_lo, row_hi):
            acc = zero
            for p in range(p_ptr[r], p_ptr[r + 1]):
                acc += p_w[p] * cs[p_idx[p]]
            for p in range(q_ptr[r], q_ptr[r + 1]):
                acc += q_w[p] * ds[q_idx[p]]
            f[o, r] = acc


def warm_up() -> None:
    """Compile (or load from the on-disk cache) every kernel for float32 and float64."""
    for dtype in (np.float32, np.float64):
        ptr = np.zeros(2, dtype=np.intp)
        idx = np.zeros(0, dtype=np.intp)
        w = np.zeros(0, dtype=dtype)
        x3 = np.zeros((1, 1, 2), dtype=dtype)
        analysis3(x3, ptr, idx, w, ptr, idx, w, x3.copy(), x3.copy(), 0, 1, 0, 1)
        synthesis3(x3, x3, ptr, idx, w, ptr, idx, w, x3.copy(), 0, 1, 0, 1)
        x2 = np.zeros((1, 1), dtype=dtype)
        analysis2(x2, ptr, idx, w, ptr, idx, w, x2.copy(), x2.copy(), 0, 1, 0, 1)
        synthesis2(x2, x2, ptr, idx, w, ptr, idx, w, x2.copy(), 0, 1, 0, 1)
