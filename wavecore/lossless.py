"""The reversible integer transform of ``encode_image(..., lossless=True)``: LeGall 5/3 lifting.

Lossless coding needs a transform that maps integers to integers and back bit-exactly on any
machine, so the decoder must not depend on float rounding.  This module implements the
reversible LeGall 5/3 integer lifting of JPEG 2000 (ISO/IEC 15444-1, annex F), with whole-sample
symmetric extension at both ends:

.. code-block:: text

    d[i] = x[2i+1] - floor((x[2i] + x[2i+2]) / 2)          (predict)
    s[i] = x[2i]   + floor((d[i-1] + d[i] + 2) / 4)         (update)

Why not an integer form of the paper's ``bspline2`` filters: the interior of ``bspline2`` has a
polyphase determinant of ±1, so an integer lifting factorisation exists for periodic data, but the
paper's endpoint-interpolating start and end rows (eqs. 4–19) are not a restriction of that
factorisation; they would need their own boundary lifting steps, derived and proved reversible
separately.  The 5/3 lifting is the standard reversible wavelet, accepts every length (``n``
samples split into ``ceil(n/2)`` coarse and ``floor(n/2)`` details), so a lossless image needs no
padding, and its low-pass has unit DC gain, so the coarse band is a viewable thumbnail for
``decode(..., level=k)``.

Only integer arithmetic in ``int64`` is used (floor division by shifts), so the result is the same
everywhere.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import InvalidParameter

__all__ = ["band_shapes", "forward", "inverse", "lift", "unlift"]


def _neighbours(s: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The symmetric-extension neighbours: s[i+1] for every d, d[i-1] and d[i] for every s."""
    ns, nd = len(s), len(d)
    s_right = np.concatenate([s[1:], s[-1:]])[:nd]
    d_left = np.concatenate([d[:1], d])[:ns]
    d_right = np.concatenate([d, d[-1:]])[:ns]
    return s_right, d_left, d_right


def lift(x: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """One 5/3 analysis step along ``axis``: ``(coarse, detail)`` as ``int64``.

    Examples
    --------
    >>> import numpy as np
    >>> s, d = lift(np.array([10, 12, 14, 16, 18]))
    >>> s.tolist(), d.tolist()
    ([10, 14, 18], [0, 0])
    """
    data = np.moveaxis(np.asarray(x, dtype=np.int64), axis, 0)
    if data.shape[0] < 2:
        return np.moveaxis(data.copy(), 0, axis), np.moveaxis(data[:0].copy(), 0, axis)
    s = data[0::2].copy()
    d = data[1::2].copy()
    s_right, _, _ = _neighbours(s, d)
    d -= (s[: len(d)] + s_right) >> 1
    _, d_left, d_right = _neighbours(s, d)
    s += (d_left + d_right + 2) >> 2
    return np.moveaxis(s, 0, axis), np.moveaxis(d, 0, axis)


def unlift(coarse: np.ndarray, detail: np.ndarray, axis: int = 0) -> np.ndarray:
    """The exact inverse of :func:`lift`."""
    s = np.moveaxis(np.asarray(coarse, dtype=np.int64), axis, 0).copy()
    d = np.moveaxis(np.asarray(detail, dtype=np.int64), axis, 0).copy()
    if d.shape[0] == 0:
        return np.moveaxis(s, 0, axis)
    _, d_left, d_right = _neighbours(s, d)
    s -= (d_left + d_right + 2) >> 2
    s_right, _, _ = _neighbours(s, d)
    d += (s[: len(d)] + s_right) >> 1
    out = np.empty((len(s) + len(d), *s.shape[1:]), dtype=np.int64)
    out[0::2] = s
    out[1::2] = d
    return np.moveaxis(out, 0, axis)


def band_shapes(shape: Sequence[int], level: int, axes: Sequence[int] = (0, 1)) -> list[Any]:
    """Subband shapes of :func:`forward`, in ``wavedec2`` layout (or ``wavedec`` for one axis).

    Examples
    --------
    >>> band_shapes((5, 8), 2)
    [(2, 2), ((1, 2), (2, 2), (1, 2)), ((2, 4), (3, 4), (2, 4))]
    """
    current = list(shape)
    details: list[Any] = []
    for _ in range(level):
        coarse = list(current)
        fine = list(current)
        for a in axes:
            coarse[a] = (current[a] + 1) // 2
            fine[a] = current[a] // 2
        if len(axes) == 1:
            details.append(tuple(fine))
        else:
            a0, a1 = axes
            cH = list(coarse)
            cH[a0] = fine[a0]
            cV = list(coarse)
            cV[a1] = fine[a1]
            details.append((tuple(cH), tuple(cV), tuple(fine)))
        current = coarse
    return [tuple(current), *reversed(details)]


def forward(data: np.ndarray, level: int, axes: Sequence[int] = (0, 1)) -> list[Any]:
    """Multi-level 5/3 decomposition of integer data, in ``wavedec2`` layout (``int32``).

    With two axes the result is ``[cA, (cH, cV, cD), ...]`` (``cH`` detail along the first
    axis), with one axis ``[cA, cD, ...]``.  Other axes (colour) are carried along.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.random.default_rng(0).integers(0, 65536, (13, 10, 3))
    >>> coeffs = forward(image, 3)
    >>> bool(np.array_equal(inverse(coeffs), image))
    True
    """
    arr = np.asarray(data)
    if arr.dtype.kind not in "iu":
        msg = f"the reversible transform needs integer data, not {arr.dtype}"
        raise InvalidParameter(msg)
    axes = tuple(axes)
    coarse = arr.astype(np.int64)
    details: list[Any] = []
    for _ in range(level):
        if len(axes) == 1:
            coarse, d = lift(coarse, axes[0])
            details.append(d.astype(np.int32))
            continue
        low, high = lift(coarse, axes[0])
        ll, lh = lift(low, axes[1])
        hl, hh = lift(high, axes[1])
        details.append((hl.astype(np.int32), lh.astype(np.int32), hh.astype(np.int32)))
        coarse = ll
    return [coarse.astype(np.int32), *reversed(details)]


def inverse(coeffs: Sequence[Any], axes: Sequence[int] = (0, 1)) -> np.ndarray:
    """Reconstruct from :func:`forward`'s list, or from a prefix of it (a coarser image)."""
    axes = tuple(axes)
    coarse = np.asarray(coeffs[0], dtype=np.int64)
    for bands in coeffs[1:]:
        if len(axes) == 1:
            coarse = unlift(coarse, bands, axes[0])
            continue
        cH, cV, cD = bands
        low = unlift(coarse, cV, axes[1])
        high = unlift(cH, cD, axes[1])
        coarse = unlift(low, high, axes[0])
    return coarse
