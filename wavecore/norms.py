"""Norms of the synthesis basis functions, per coefficient.

These filters are not orthogonal, so a coefficient's size says little about its effect on the
reconstruction until it is multiplied by the L2 norm of its synthesis basis function: the fine
signal that ``waverec`` makes from that one coefficient set to 1.  Thresholds ("remove the
smallest details") and quantizers weight by these norms.

In 1-D the basis function of ``cD_l[j]`` is ``P_1 … P_{l-1} Q_l e_j``; in n-D it is the tensor
product of one 1-D basis function per axis, so its norm is the product of the 1-D norms.

How they are computed, in time and memory independent of the length
    The norms come from the Gram matrices of the coarse basis functions, level by level:
    ``G_0 = I``, ``G_l = P_lᵀ G_{l-1} P_l``; the squared norms of the level-``l`` details are
    ``diag(Q_lᵀ G_{l-1} Q_l)`` and those of ``cA_L`` are ``diag(G_L)``.  ``P`` and ``Q`` are
    banded, so each ``G_l`` is banded too, and away from the boundary rows it is Toeplitz (the
    interior basis functions are translates of one another).  A long Gram matrix therefore
    carries no more information than a short one with the same start rows, the same end rows
    and a shorter Toeplitz middle.  Every length above ``_PROXY_LENGTH`` is replaced by such a
    short stand-in before each step (rows of the Toeplitz middle are dropped, or repeated), the
    step runs on small dense matrices, and the long norm vectors are rebuilt at the end by
    repeating their constant middle value.  That is exact, not an approximation: the stand-in's
    middle is checked to be Toeplitz (or the stand-in is made longer) before it is used.  Lengths
    up to ``_PROXY_LENGTH`` are computed on the full matrices.
"""

from __future__ import annotations

import itertools
import math
import threading
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from .errors import InvalidParameter
from .filters import CACHE_CLEARERS, BoundaryRule, FilterBank, get_wavelet
from .multilevel import check_result_values, resolve_axes, resolve_boundaries, resolve_level

__all__ = ["basis_norms", "basis_norms_nd"]

# Lengths up to this are computed exactly on full matrices; longer ones through a stand-in of
# about this length.  The filters here have Gram bands of at most 5 and boundary regions of at
# most 3 coefficients, so 128 leaves a wide Toeplitz middle; a wider filter makes the check
# below fail and the stand-in grows.
_PROXY_LENGTH = 128
# Entries of a stand-in's Gram matrix farther than this from the diagonal must be zero.
_BAND_FRACTION = 8  # the band may take at most 1/8 of the stand-in's length

# Expanded norm vectors are kept for repeated calls only while they are small: all of them
# together take at most this many bytes (the compact form is always cached; it is tiny).
_EXPANDED_CACHE_BYTES = 4 << 20


class _NotToeplitz(Exception):
    """The stand-in is too short for this filter: its middle is not (yet) Toeplitz."""


def _band_rows(gram: np.ndarray, band: int, periodic: bool) -> np.ndarray:
    """``rows[i, band + k] = gram[i, i + k]`` for ``|k| <= band`` (wrapping when periodic).

    Raises :class:`_NotToeplitz` when the matrix has entries farther out than ``band``.
    """
    p = gram.shape[0]
    i = np.arange(p)[:, None]
    k = np.arange(-band, band + 1)[None, :]
    cols = i + k
    if periodic:
        rows = gram[i, cols % p]
    else:
        inside = (cols >= 0) & (cols < p)
        rows = np.where(inside, gram[i, np.clip(cols, 0, p - 1)], 0.0)
    scale = float(np.abs(gram).max(initial=0.0))
    distance = np.abs(np.arange(p)[:, None] - np.arange(p)[None, :])
    if periodic:
        distance = np.minimum(distance, p - distance)
    if np.any(np.abs(gram[distance > band]) > 1e-14 * scale):
        raise _NotToeplitz
    return rows


def _from_band_rows(rows: np.ndarray, periodic: bool) -> np.ndarray:
    p, width = rows.shape
    band = width // 2
    gram = np.zeros((p, p))
    i = np.repeat(np.arange(p), width)
    cols = (np.arange(p)[:, None] + np.arange(-band, band + 1)[None, :]).ravel()
    values = rows.ravel()
    if periodic:
        cols = cols % p
        keep = np.ones(cols.shape, dtype=bool)
    else:
        keep = (cols >= 0) & (cols < p)
    gram[i[keep], cols[keep]] = values[keep]
    return gram


def _resize(gram: np.ndarray, length: int, periodic: bool) -> np.ndarray:
    """The Gram matrix with its Toeplitz middle made ``length - len(gram)`` rows longer."""
    p = gram.shape[0]
    if length == p:
        return gram
    band = p // _BAND_FRACTION
    rows = _band_rows(gram, band, periodic)
    middle = p // 2
    # Every row whose band reaches the cut must be the same row (the Toeplitz middle), with
    # room for the start and end rows on either side.
    around = rows[middle - 2 * band : middle + max(0, p - length) + 2 * band + 1]
    scale = float(np.abs(rows).max(initial=0.0))
    if np.any(np.abs(around - rows[middle]) > 1e-13 * max(scale, 1e-300)):
        raise _NotToeplitz
    if length > p:
        extra = np.repeat(rows[middle : middle + 1], length - p, axis=0)
        rows = np.concatenate([rows[:middle], extra, rows[middle:]])
    else:
        rows = np.concatenate([rows[:middle], rows[middle + p - length :]])
    return _from_band_rows(rows, periodic)


def _stand_in(n: int, target: int) -> int:
    """The stand-in for a true length ``n``: ``n`` itself, or near ``target`` with its parity."""
    if n <= target:
        return n
    return target - (target - n) % 2


def _expand(values: np.ndarray, length: int) -> np.ndarray:
    """A stand-in's per-coefficient values at the true ``length`` (the middle value repeated)."""
    count = len(values)
    if length == count:
        return values
    middle = count // 2
    return np.concatenate(
        [values[:middle], np.full(length - count, values[middle]), values[middle:]]
    )


def _squared_norms(
    rule: BoundaryRule, n: int, level: int, target: int
) -> tuple[tuple[tuple[np.ndarray, int], tuple[np.ndarray, int]], ...]:
    """Squared norms in compact form, (stand-in values, true length), for every level.

    Entry ``l`` (``0 <= l <= level``) is ``(coarse norms at level l, detail norms at level l)``;
    level 0 has no details (an empty placeholder).
    """
    gram: np.ndarray | None = None  # None: the identity (G_0), at any length
    true_m = n
    m = _stand_in(n, target)
    table = [((np.ones(m), true_m), (np.zeros(0), 0))]
    for _ in range(level):
        if gram is None:
            gram = np.eye(m)
        r, s = rule.coarse_length(m), rule.detail_length(m)
        P = rule.P.dense(m, r, rule.periodic)
        Q = rule.Q.dense(m, s, rule.periodic)
        detail = (np.einsum("ij,ik,kj->j", Q, gram, Q), rule.detail_length(true_m))
        # einsum's own loops rather than BLAS: on matrices this small a threaded BLAS spends
        # far longer waking its threads (tens of ms on a busy machine) than multiplying.
        gram = np.einsum("ik,kl->il", np.einsum("ji,jk->ik", P, gram), P)
        true_m = rule.coarse_length(true_m)
        m = _stand_in(true_m, target)
        gram = _resize(gram, m, rule.periodic)
        table.append(((np.diag(gram).copy(), true_m), detail))
    return tuple(table)


@lru_cache(maxsize=256)
def _squared_table(
    n: int, wavelet: str, boundary: str, level: int
) -> tuple[tuple[tuple[np.ndarray, int], tuple[np.ndarray, int]], ...]:
    """Squared norms in compact form for levels 0 … ``level`` (see :func:`_squared_norms`)."""
    rule = get_wavelet(wavelet).rule(boundary)
    target = _PROXY_LENGTH
    while True:
        try:
            return _squared_norms(rule, n, level, target)
        except _NotToeplitz:
            # A wider filter than the stand-in allows for: a longer one (at worst the full
            # length, which needs no stand-in at all).
            target *= 2


@lru_cache(maxsize=512)  # the rate searches ask for the same ones at every trial step
def mean_squared_norms(n: int, wavelet: str, boundary: str, level: int) -> tuple[float, float]:
    """The mean squared basis norm of level ``level``'s coarse and detail coefficients of a
    1-D decomposition of fine length ``n``, from the squared norms themselves.

    Before any square root: Haar's are powers of two, exactly, so the quantizer's weights of a
    2-D band (the square root of the product of its two axes' means) come out exact, the same
    on every machine, where a product of two rounded square roots missed them by an ulp.

    Parameters
    ----------
    n : int
        The fine length.
    wavelet, boundary : str
        As for :func:`basis_norms`.
    level : int
        The level, at least 1.

    Returns
    -------
    tuple of float
        The means over the coarse and the detail coefficients of that level.
    """
    table = _squared_table(n, wavelet, boundary, level)
    return tuple(  # type: ignore[return-value]
        float(np.mean(np.maximum(_expand(values, length), 0.0))) for values, length in table[level]
    )


@lru_cache(maxsize=256)
def _compact_table(
    n: int, wavelet: str, boundary: str, level: int
) -> tuple[tuple[tuple[np.ndarray, int], tuple[np.ndarray, int]], ...]:
    """Norms in compact form for levels 0 … ``level`` (see :func:`_squared_norms`).

    Each band is at most a few hundred values and its true length: small whatever ``n`` is,
    so the cache may hold many of them.
    """
    out = []
    for (coarse, coarse_length), (detail, detail_length) in _squared_table(
        n, wavelet, boundary, level
    ):
        pair = []
        for values, length in ((coarse, coarse_length), (detail, detail_length)):
            norms = np.sqrt(np.maximum(values, 0.0))
            norms.setflags(write=False)
            pair.append((norms, length))
        out.append((pair[0], pair[1]))
    return tuple(out)


def _compact_norms(
    n: int, wavelet: str, boundary: str, level: int, top: int | None = None
) -> list[tuple[np.ndarray, int]]:
    """``[cA_level, cD_level, …, cD_1]`` in compact form, read from the table up to ``top``."""
    table = _compact_table(n, wavelet, boundary, level if top is None else top)
    return [table[level][0], *(table[lvl][1] for lvl in range(level, 0, -1))]


_expanded: OrderedDict[tuple[int, str, str, int], tuple[np.ndarray, ...]] = OrderedDict()
_expanded_bytes = 0
_expanded_lock = threading.Lock()


def _norms(
    n: int, wavelet: str, boundary: str, level: int, top: int | None = None
) -> tuple[np.ndarray, ...]:
    """Read-only norm vectors, ``[cA_L, cD_L, …, cD_1]``; small results are kept for reuse.

    ``top`` (at least ``level``) shares one table among the levels of one decomposition.
    """
    global _expanded_bytes
    key = (n, wavelet, boundary, level)
    with _expanded_lock:
        hit = _expanded.get(key)
        if hit is not None:
            _expanded.move_to_end(key)
            return hit
    vectors = []
    for values, length in _compact_norms(n, wavelet, boundary, level, top):
        vector = _expand(values, length)
        if vector is values:
            vector = values.copy()
        vector.setflags(write=False)
        vectors.append(vector)
    result = tuple(vectors)
    size = sum(v.nbytes for v in result)
    if size <= _EXPANDED_CACHE_BYTES // 8:
        with _expanded_lock:
            if key not in _expanded:
                _expanded[key] = result
                _expanded_bytes += size
            while _expanded_bytes > _EXPANDED_CACHE_BYTES:
                _, dropped = _expanded.popitem(last=False)
                _expanded_bytes -= sum(v.nbytes for v in dropped)
            result = _expanded[key]
    return result


def _forget() -> None:
    global _expanded_bytes
    _compact_table.cache_clear()
    _squared_table.cache_clear()
    mean_squared_norms.cache_clear()
    with _expanded_lock:
        _expanded.clear()
        _expanded_bytes = 0


CACHE_CLEARERS.append(_forget)  # a wavelet registered again under its name has other norms


def basis_norms(
    n: int,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    level: int | None = None,
) -> list[np.ndarray]:
    """L2 norm of every coefficient's synthesis basis function, for a 1-D decomposition.

    Computed from the filters by a recursion over the levels, in time and memory that do not
    grow with ``n`` beyond the result itself.

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
        a read-only 1-D array (small results are cached and shared).

    Examples
    --------
    >>> norms = basis_norms(34, level=2)
    >>> [len(v) for v in norms]
    [10, 8, 16]
    >>> bool(norms[0][5] > norms[1][4] > norms[2][8])  # coarser functions are wider
    True
    """
    bank = get_wavelet(wavelet)
    (b,) = resolve_boundaries(boundary, 1, bank)
    length = _length(n, "n")
    check_result_values(length, f"the basis norms of {length} samples")
    lvl = resolve_level(level, bank, [b], [length], [0])
    return list(_norms(length, bank.name, b, lvl))


def _length(value: Any, name: str) -> int:
    """A length argument as an ``int``, or :class:`InvalidParameter` naming ``name``."""
    try:
        return int(value)
    except (TypeError, ValueError, OverflowError):
        msg = f"{name} must be a length (an integer), not {value!r}"
        raise InvalidParameter(msg[:200]) from None


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
    if isinstance(shape, str | bytes) or not isinstance(shape, Iterable):
        msg = f"shape must be a sequence of lengths, not {shape!r}"
        raise InvalidParameter(msg[:200])
    shape = tuple(_length(s, "each length of shape") for s in shape)
    if not shape:
        msg = "shape must have at least one axis"
        raise InvalidParameter(msg)
    check_result_values(math.prod(shape), f"the basis norms of shape {shape}")
    axes = resolve_axes(None, len(shape))
    bounds = resolve_boundaries(boundary, len(shape), bank)
    lvl = resolve_level(level, bank, bounds, shape, axes)

    def outer(vectors: list[np.ndarray]) -> np.ndarray:
        result = vectors[0]
        for v in vectors[1:]:
            result = np.multiply.outer(result, v)
        return result

    def coarse(axis: int, lvl_: int) -> np.ndarray:
        return _norms(shape[axis], bank.name, bounds[axis], lvl_, lvl)[0]

    def detail(axis: int, lvl_: int) -> np.ndarray:
        return _norms(shape[axis], bank.name, bounds[axis], lvl_, lvl)[1]

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
