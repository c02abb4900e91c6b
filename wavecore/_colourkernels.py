"""Compiled loops of the colour stage: the encoder's colour matrix into floats, and the
decoder's last pass (colour matrix, rounding and clipping into the caller's integer dtype).
Moved from :mod:`wavecore._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

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
def finite_floats(src, largest, out, row_lo, row_hi):
    """``out = clip(nan_to_num(src), -largest, largest)`` rows ``[row_lo, row_hi)`` of
    ``(rows, cols)`` arrays, cast to ``out``'s dtype as NumPy's ``astype`` does: NaN → 0,
    infinities and values beyond ``largest`` saturated.  One pass, where NumPy's
    ``nan_to_num`` made four full-size temporaries (a fifth of a grid's synthesis)."""
    cols = src.shape[1]
    for i in range(row_lo, row_hi):
        row = src[i]
        dest = out[i]
        for j in range(cols):
            v = row[j]
            if v != v:
                v = 0.0
            elif v > largest:
                v = largest
            elif v < -largest:
                v = -largest
            dest[j] = v
