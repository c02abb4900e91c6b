"""Norms of the synthesis basis functions, per coefficient.

These filters are not orthogonal, so a coefficient's size says little about its effect on the
reconstruction until it is multiplied by the L2 norm of its synthesis basis function: the fine
signal that ``waverec`` makes from that one coefficient set to 1.  Thresholds ("remove the
smallest details") and quantizers weight by these norms.

In 1-D the basis function of ``cD_l[j]`` is ``P_1 … P_{l-1} Q_l e_j``; in n-D it is the tensor
product of one 1-D basis function per axis, so its norm is the product of the 1-D norms.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from .filters import FilterBank, get_wavelet
from .multilevel import _axes, _boundaries, _resolve_level, wavedec, waverec

__all__ = ["basis_norms", "basis_norms_nd"]

_BATCH = 256  # impulses reconstructed at once; bounds the temporary memory to n × 256 floats


@lru_cache(maxsize=64)
def _basis_norms_cached(n: int, wavelet: str, boundary: str, level: int) -> tuple[np.ndarray, ...]:
    template = wavedec(np.zeros(n), wavelet, boundary, level)
    norms: list[np.ndarray] = []
    for band_index, band in enumerate(template):
        size = band.shape[0]
        out = np.empty(size)
        for start in range(0, size, _BATCH):
            stop = min(size, start + _BATCH)
            coeffs: list[np.ndarray | None] = [None] * len(template)
            coeffs[0] = np.zeros((template[0].shape[0], stop - start))
            impulses = np.zeros((size, stop - start))
            impulses[np.arange(start, stop), np.arange(stop - start)] = 1.0
            if band_index == 0:
                coeffs[0] = impulses
            else:
                coeffs[band_index] = impulses
            out[start:stop] = np.linalg.norm(waverec(coeffs, wavelet, boundary), axis=0)
        out.setflags(write=False)
        norms.append(out)
    return tuple(norms)


def basis_norms(
    n: int,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    level: int | None = None,
) -> list[np.ndarray]:
    """L2 norm of every coefficient's synthesis basis function, for a 1-D decomposition.

    Parameters
    ----------
    n : int
        The fine length.
    wavelet, boundary, level
        As for :func:`wavecore.wavedec`.

    Returns
    -------
    list of numpy.ndarray
        Laid out like ``wavedec``'s result, ``[norms of cA_L, norms of cD_L, ..., cD_1]``; each
        a read-only 1-D array (cached).

    Examples
    --------
    >>> norms = basis_norms(34, level=2)
    >>> [len(v) for v in norms]
    [10, 8, 16]
    >>> bool(norms[0][5] > norms[1][4] > norms[2][8])  # coarser functions are wider
    True
    """
    bank = get_wavelet(wavelet)
    (b,) = _boundaries(boundary, 1, bank)
    lvl = _resolve_level(level, bank, [b], [int(n)], [0])
    return list(_basis_norms_cached(int(n), bank.name, b, lvl))


def basis_norms_nd(
    shape: Sequence[int],
    wavelet: str | FilterBank = "bspline2",
    boundary: str | Sequence[str] = "open",
    level: int | None = None,
) -> list[object]:
    """Per-coefficient basis norms for :func:`wavecore.wavedecn` over all axes of ``shape``.

    Returns
    -------
    list
        ``[norms of cA_L, {key: norms}, ...]`` like ``wavedecn``'s result, each entry a full
        array of the band's shape (the outer product of the per-axis 1-D norms).

    Examples
    --------
    >>> norms = basis_norms_nd((18, 16), boundary=("open", "closed"), level=1)
    >>> norms[0].shape, norms[1]["dd"].shape
    ((10, 8), (8, 8))
    """
    bank = get_wavelet(wavelet)
    shape = tuple(int(s) for s in shape)
    axes = _axes(None, len(shape))
    bounds = _boundaries(boundary, len(shape), bank)
    lvl = _resolve_level(level, bank, bounds, shape, axes)

    def outer(vectors: list[np.ndarray]) -> np.ndarray:
        result = vectors[0]
        for v in vectors[1:]:
            result = np.multiply.outer(result, v)
        return result

    def coarse(axis: int, lvl_: int) -> np.ndarray:
        return _basis_norms_cached(shape[axis], bank.name, bounds[axis], lvl_)[0]

    def detail(axis: int, lvl_: int) -> np.ndarray:
        return _basis_norms_cached(shape[axis], bank.name, bounds[axis], lvl_)[1]

    out: list[object] = [outer([coarse(i, lvl) for i in range(len(shape))])]
    for lvl_ in range(lvl, 0, -1):
        out.append(
            {
                key: outer(
                    [detail(i, lvl_) if ch == "d" else coarse(i, lvl_) for i, ch in enumerate(key)]
                )
                for key in _detail_keys(len(shape))
            }
        )
    return out


def _detail_keys(count: int) -> list[str]:
    return ["".join(k) for k in itertools.product("ad", repeat=count)][1:]
