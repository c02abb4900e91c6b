"""Which coefficients a region of a decoded array depends on.

A region decode (``wavecore.decode(bundle, region=...)``) decodes only the code-blocks that
hold coefficients the region needs, with every other coefficient left zero, and then runs the
usual inverse transform.  That is exact, not an approximation: each output sample is a sum
over the synthesis taps that reach it (the lossy filter banks), or an integer lifting of a few
neighbours (the lossless path), so coefficients outside its support never enter it, whatever
their value.

The support is worked out one transformed axis and one level at a time, finest first:

* the lossy filter banks (``bspline2``, ``haar``, ``cdf97``; open, closed or symmetric) from
  their synthesis matrices ``P`` and ``Q`` themselves (:func:`wavecore.filters.step_compact`):
  the coarse and detail coefficients a fine sample needs are the columns of its rows, boundary
  rows and periodic wrap-around included, so no filter length is written down here;
* the reversible lifting (LeGall 5/3, integer Haar, closed integer B-spline) from its lifting
  steps: a fine sample ``i`` needs coefficients within ``LIFTING_REACH`` of ``i // 2``, taken
  modulo the band's length (this covers the periodic B-spline lifting and the mirror at a
  symmetric edge, whose mirrored neighbours are the edge's own).

A 2-D transform is separable in its supports (each step runs along one axis at a time), so
the samples a rectangle needs are the product of a row set and a column set in every band.
Sets are boolean masks as long as the axis, so the cost grows with the sides, not the area.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import InvalidParameter
from .filters import Regular, Sparse, get_wavelet, step_compact
from .lossless import unlift
from .transform import synthesis_step

__all__ = ["LIFTING_REACH", "band_masks", "check_region", "windowed_inverse"]

#: How far (in coefficients of the coarser level) a reversible lifting step reaches: LeGall
#: 5/3 reaches one detail either side of a coarse sample and then one coarse sample further;
#: the closed integer B-spline one neighbour each way.  Three is a safe margin (checked by
#: tests/test_regions.py against full decodes).
LIFTING_REACH = 3


def check_region(region: Any, shape: Sequence[int], axes: int) -> tuple[slice, ...]:
    """``region`` as one ``slice`` per transformed axis, checked against the output's ``shape``.

    Parameters
    ----------
    region : tuple of slice
        ``(rows, cols)`` for an image, surface or grid; ``(points,)`` (or one ``slice``) for a
        curve.  Each item is a ``slice`` (``None`` ends and negative indices as in NumPy, a
        positive step) or a ``(start, stop)`` pair of integers.  Fewer items than axes leave
        the last axes whole.
    shape : sequence of int
        The shape that the decode without ``region`` would return.
    axes : int
        The number of transformed axes (1 for curves, 2 otherwise).

    Returns
    -------
    tuple of slice
        Slices with explicit, non-negative ``start`` and ``stop`` and a positive ``step``,
        selecting at least one sample on every axis.

    Raises
    ------
    InvalidParameter
        For anything that is not such a region, or one that selects nothing.
    """
    if isinstance(region, slice):
        region = (region,)
    if not isinstance(region, tuple | list) or not 1 <= len(region) <= axes:
        msg = (
            f"region must be a tuple of 1 to {axes} slices (e.g. (slice(0, 256), slice(0, 256))),"
            f" not {str(region)[:80]}"
        )
        raise InvalidParameter(msg)
    out = []
    for axis, item in enumerate(region):
        n = int(shape[axis])
        if isinstance(item, tuple | list) and len(item) == 2:
            item = slice(*item)
        if not isinstance(item, slice):
            msg = f"region axis {axis} must be a slice or a (start, stop) pair, not {item!r}"
            raise InvalidParameter(msg[:200])
        for name in ("start", "stop", "step"):
            value = getattr(item, name)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int | np.integer)
            ):
                msg = f"region axis {axis}: {name} must be an integer or None, not {value!r}"
                raise InvalidParameter(msg[:200])
        if item.step is not None and item.step <= 0:
            msg = f"region axis {axis}: the step must be positive, not {item.step}"
            raise InvalidParameter(msg)
        start, stop, step = item.indices(n)
        if stop <= start:
            msg = (
                f"region axis {axis} selects no samples: {item} of an axis of {n} samples "
                f"(the decoded shape is {list(shape)})"
            )
            raise InvalidParameter(msg)
        out.append(slice(start, stop, step))
    out += [slice(0, int(shape[axis]), 1) for axis in range(len(out), axes)]
    return tuple(out)


def _rows_columns(indptr: np.ndarray, indices: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The column indices of the given rows of a compressed-row matrix."""
    begin, end = indptr[rows], indptr[rows + 1]
    counts = end - begin
    total = int(counts.sum())
    if not total:
        return np.zeros(0, dtype=np.intp)
    starts = np.repeat(begin - np.cumsum(counts) + counts, counts)
    return indices[starts + np.arange(total)]


def _step_support(
    transform: Any, axis: int, m: int, want: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The coarse and detail masks that fine samples ``want`` (a mask of ``m``) need."""
    fine = np.flatnonzero(want)
    if getattr(transform, "lossless", False):
        coarse_len, detail_len = (m + 1) // 2, m // 2
        near = (fine // 2)[:, None] + np.arange(-LIFTING_REACH, LIFTING_REACH + 1)[None, :]
        coarse = np.zeros(coarse_len, dtype=bool)
        coarse[near.ravel() % coarse_len] = True
        detail = np.zeros(detail_len, dtype=bool)
        if detail_len:
            detail[near.ravel() % detail_len] = True
        return coarse, detail
    bank = get_wavelet(transform.wavelet)
    boundary = transform.boundary[axis]
    rule = bank.rule(boundary)
    _, _, P, Q = step_compact(bank.name, boundary, m)
    coarse = np.zeros(rule.coarse_length(m), dtype=bool)
    detail = np.zeros(rule.detail_length(m), dtype=bool)
    coarse[compact_rows_columns(*P, fine)] = True
    detail[compact_rows_columns(*Q, fine)] = True
    return coarse, detail


def compact_rows_columns(sparse: Sparse, regular: Regular, rows: np.ndarray) -> np.ndarray:
    """The column indices of ``rows`` of a matrix in compact form (boundary rows in
    ``sparse``, the interior as ``regular``'s pattern), in no particular order.

    Read from the pattern rather than from every row written out, so a region of a long axis
    costs memory in proportion to the rows it asks about (a crafted header can declare an axis
    of millions of samples).
    """
    rows = np.asarray(rows, dtype=np.intp)
    if not regular.blocks:
        return _rows_columns(sparse.indptr, sparse.indices, rows)
    inside = (rows >= regular.lo) & (rows < regular.hi)
    outside = rows[~inside]
    # Rows after the interior sit that many places earlier in the compressed rows.
    outside = np.where(outside >= regular.hi, outside - regular.blocks * regular.p, outside)
    parts = [_rows_columns(sparse.indptr, sparse.indices, outside)]
    block, phase = np.divmod(rows[inside] - regular.lo, regular.p)
    for which in range(regular.p):
        taps = np.flatnonzero(regular.pattern[which])
        starts = regular.col + regular.step * block[phase == which]
        parts.append((starts[:, None] + taps[None, :]).ravel())
    return np.concatenate(parts).astype(np.intp, copy=False)


def band_masks(
    transform: Any,
    fitted: Sequence[int],
    levels: int,
    level: int,
    window: Sequence[tuple[int, int]],
) -> list[list[tuple[np.ndarray, ...]]]:
    """For each band a decode down to ``level`` reads, the rows (and columns) it needs.

    Parameters
    ----------
    transform : wavecore.codec.stages.Transform
        The bundle's transform stage (a filter bank with its boundaries, or the lifting).
    fitted : sequence of int
        The transformed lengths (the fitted shape's first one or two sizes).
    levels : int
        The bundle's levels ``L``.
    level : int
        The level decoded (0: full resolution).
    window : sequence of (int, int)
        Per transformed axis, the ``[start, stop)`` wanted in the level-``level``
        approximation's own coordinates.

    Returns
    -------
    list
        In layout order (``[[cA_L], [bands of level L], …, [bands of level level + 1]]``), one
        tuple of masks per band: ``(rows,)`` for one axis, ``(rows, cols)`` for two.
    """
    return _supports(transform, fitted, levels, level, window)[0]


def _supports(
    transform: Any,
    fitted: Sequence[int],
    levels: int,
    level: int,
    window: Sequence[tuple[int, int]],
) -> tuple[list[list[tuple[np.ndarray, ...]]], list[list[np.ndarray]]]:
    """:func:`band_masks`, and the approximation samples wanted at each level (``level``
    first, then coarser), one mask per axis."""
    axes = len(window)
    want = []
    lengths = []
    for axis, (start, stop) in enumerate(window):
        n = int(fitted[axis])
        for _ in range(level):
            n = _coarse_length(transform, axis, n)
        mask = np.zeros(n, dtype=bool)
        mask[start:stop] = True
        want.append(mask)
        lengths.append(n)
    wants = [want]
    details: list[list[tuple[np.ndarray, ...]]] = []
    for _ in range(level, levels):
        steps = [_step_support(transform, axis, lengths[axis], want[axis]) for axis in range(axes)]
        if axes == 1:
            details.append([(steps[0][1],)])
        else:
            (c0, d0), (c1, d1) = steps
            details.append([(d0, c1), (c0, d1), (d0, d1)])
        want = [coarse for coarse, _ in steps]
        wants.append(want)
        lengths = [len(mask) for mask in want]
    return [[tuple(want)], *reversed(details)], wants


def windowed_inverse(
    transform: Any,
    coeffs: list[Any],
    fitted: Sequence[int],
    levels: int,
    level: int,
    window: Sequence[tuple[int, int]],
    origins: Sequence[Any] | None = None,
) -> np.ndarray:
    """The inverse transform of ``coeffs`` (down to ``level``) at ``window`` only.

    Equal, to the last bit, to ``transform.inverse(coeffs)`` cropped to ``window`` (the
    synthesis steps are the library's own, one axis at a time as the fused pass computes
    them; each step runs only on the rows or columns the window needs, with every other
    sample zero, which no needed output reads).  The cost of a level is the window's span
    along one axis times the level's length along the other, not the level's area.

    ``coeffs`` may hold only a part of each band (what :func:`band_masks` needs, or more):
    ``origins`` then gives the index of each part's first sample in its band, in the layout
    of ``coeffs`` (a tuple per band: one index per transformed axis).  The reversible lifting
    is not linear (it rounds), but it is local just the same, so zeros stand for the samples
    no needed output reads there too.
    """
    _, wants = _supports(transform, fitted, levels, level, window)
    wants.reverse()  # coarsest first, like coeffs
    picks = [[np.flatnonzero(mask) for mask in want] for want in wants]
    axes = len(window)
    if origins is None:
        zero = (0,) * axes
        origins = [zero] + [[zero] * (3 if axes == 2 else 1)] * (len(coeffs) - 1)
    first: Any = origins[0]
    lossless = bool(getattr(transform, "lossless", False))
    dtype = np.int64 if lossless else np.float64

    def step(low: np.ndarray, high: np.ndarray, axis: int, index: int) -> np.ndarray:
        """One synthesis step of the level of ``coeffs[index]`` along ``axis``."""
        if lossless:
            names = transform.lifting
            return unlift(low, high, axis, names[len(names) - index])
        bank = get_wavelet(transform.wavelet)
        return synthesis_step(low, high, bank, transform.boundary[axis], axis)

    if axes == 1:
        sub = np.asarray(coeffs[0])[picks[0][0] - first[0]]
        for index, detail in enumerate(coeffs[1:], start=1):
            origin: Any = origins[index][0]
            m = len(wants[index][0])
            r, s = _split(transform, 0, m)
            detail_rows = np.flatnonzero(_step_support(transform, 0, m, wants[index][0])[1])
            detail = np.asarray(detail)
            trail = detail.shape[1:]
            low = np.zeros((r, *trail), dtype=dtype)
            low[picks[index - 1][0]] = sub
            high = np.zeros((s, *trail), dtype=dtype)
            high[detail_rows] = detail[detail_rows - origin[0]]
            sub = step(low, high, 0, index)[picks[index][0]]
        return sub
    sub = np.asarray(coeffs[0])[np.ix_(picks[0][0] - first[0], picks[0][1] - first[1])]
    for index, bands in enumerate(coeffs[1:], start=1):
        cH, cV, cD = (np.asarray(band) for band in bands)
        oH: Any
        oV: Any
        oD: Any
        oH, oV, oD = origins[index]
        rows, cols = picks[index - 1]
        fine_rows, fine_cols = picks[index]
        m0, m1 = len(wants[index][0]), len(wants[index][1])
        r0, s0 = _split(transform, 0, m0)
        r1, s1 = _split(transform, 1, m1)
        detail_rows = np.flatnonzero(_step_support(transform, 0, m0, wants[index][0])[1])
        detail_cols = np.flatnonzero(_step_support(transform, 1, m1, wants[index][1])[1])
        trail = cH.shape[2:]
        # Along axis 1 first (as the fused pass, waverec2 and the lifting do), on the rows
        # needed only.
        aa = np.zeros((len(rows), r1, *trail), dtype=dtype)
        aa[:, cols] = sub
        ad = np.zeros((len(rows), s1, *trail), dtype=dtype)
        ad[:, detail_cols] = cV[np.ix_(rows - oV[0], detail_cols - oV[1])]
        da = np.zeros((len(detail_rows), r1, *trail), dtype=dtype)
        da[:, cols] = cH[np.ix_(detail_rows - oH[0], cols - oH[1])]
        dd = np.zeros((len(detail_rows), s1, *trail), dtype=dtype)
        dd[:, detail_cols] = cD[np.ix_(detail_rows - oD[0], detail_cols - oD[1])]
        # Then along axis 0, on the columns needed only (and a few more when they are so few
        # that the step would take its narrow path, whose sums are ordered differently).
        columns = _wide_enough(fine_cols, m1, int(np.prod(trail, dtype=np.int64)))
        low_rows = step(aa, ad, 1, index)[:, columns]
        high_rows = step(da, dd, 1, index)[:, columns]
        low = np.zeros((r0, len(columns), *trail), dtype=dtype)
        low[rows] = low_rows
        high = np.zeros((s0, len(columns), *trail), dtype=dtype)
        high[detail_rows] = high_rows
        sub = step(low, high, 0, index)[fine_rows, : len(fine_cols)]
    return sub


def _split(transform: Any, axis: int, m: int) -> tuple[int, int]:
    """``(coarse, detail)`` lengths of one step from ``m`` fine samples along ``axis``."""
    if getattr(transform, "lossless", False):
        return (m + 1) // 2, m // 2
    rule = get_wavelet(transform.wavelet).rule(transform.boundary[axis])
    return rule.coarse_length(m), rule.detail_length(m)


#: Values per row that a step along axis 0 is given at least (or the whole level): the
#: transform takes a narrow path, whose sums run in another order, for a few trailing values
#: per row (up to 4 today), so a window of one or two columns must not be stepped alone.
WIDE_ENOUGH = 64


def _wide_enough(columns: np.ndarray, n: int, inner: int) -> np.ndarray:
    """``columns``, then more of the ``n`` until they hold :data:`WIDE_ENOUGH` values per
    row (or all ``n``): the step along axis 0 then runs as it does on the whole level."""
    if len(columns) * inner >= WIDE_ENOUGH or len(columns) == n:
        return columns
    need = min(n, -(-WIDE_ENOUGH // inner))
    others = np.setdiff1d(np.arange(n), columns)[: need - len(columns)]
    return np.concatenate([columns, others])


def _coarse_length(transform: Any, axis: int, n: int) -> int:
    if getattr(transform, "lossless", False):
        return (n + 1) // 2
    return get_wavelet(transform.wavelet).rule(transform.boundary[axis]).coarse_length(n)
