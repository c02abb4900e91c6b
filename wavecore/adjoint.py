"""The adjoint (transpose) of the synthesis: ``P.T`` and ``Q.T``, one step or many levels.

The synthesis step is linear, ``F = P C + Q D`` (:func:`wavecore.synthesis_step`); its adjoint
takes fine data ``y`` to ``(P.T y, Q.T y)``, so that ``<P C + Q D, y> = <C, P.T y> + <D, Q.T y>``
for every ``C``, ``D`` and ``y``.  These filters are not orthogonal, so the adjoint is *not* the
analysis (``A``, ``B``); least-squares fits to a reconstruction need the adjoint, as the
quantizer's closed loop does (:func:`wavecore.quantize.quantize_bands`, ``refine``): it fits the
kept coefficients to the image by conjugate gradients on ``S.T S``.

:func:`synthesis_adjoint` is the adjoint of a whole ``waverec``/``waverec2``: fine data in, a
coefficient list out, in the layout those functions read (:mod:`wavecore.layout`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from . import _kernels
from .arguments import as_array
from .errors import InvalidParameter
from .filters import FilterBank, get_wavelet, step_sparse
from .multilevel import as_int, resolve_boundaries
from .transform import fused_level_fits, many_short_rows, normalize_axis, run_rows

__all__ = ["synthesis_adjoint", "synthesis_step_adjoint"]


#: Steps longer than this are cached apart, a few at a time: each holds about 72 bytes per
#: sample, so 128 of a 200 000-point curve's lengths would keep 1.8 GB in a service worker.
_LONG_STEP = 1 << 16


def _transposed(bank_name: str, boundary: str, m: int) -> tuple[tuple[np.ndarray, ...], ...]:
    """``P.T`` and ``Q.T`` of one step of fine length ``m``, in compressed-row form (cached)."""
    if m > _LONG_STEP:
        return _transposed_long(bank_name, boundary, m)
    return _transposed_short(bank_name, boundary, m)


@lru_cache(maxsize=128)
def _transposed_short(bank_name: str, boundary: str, m: int) -> tuple[tuple[np.ndarray, ...], ...]:
    return _build_transposed(bank_name, boundary, m)


@lru_cache(maxsize=8)  # one curve's levels: what one request reuses
def _transposed_long(bank_name: str, boundary: str, m: int) -> tuple[tuple[np.ndarray, ...], ...]:
    return _build_transposed(bank_name, boundary, m)


def _build_transposed(bank_name: str, boundary: str, m: int) -> tuple[tuple[np.ndarray, ...], ...]:
    _, _, P, Q = step_sparse(bank_name, boundary, m)
    out = []
    for matrix in (P, Q):
        rows = np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))
        order = np.argsort(matrix.indices, kind="stable")
        indptr = np.zeros(matrix.shape[1] + 1, dtype=np.intp)
        np.add.at(indptr, matrix.indices + 1, 1)
        out.append(
            (np.cumsum(indptr), rows[order].astype(np.intp), matrix.weights[order].astype(float))
        )
    return out[0], out[1]


@lru_cache(maxsize=128)
def _transposed_compact(
    bank_name: str, boundary: str, m: int
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """``P.T`` and ``Q.T`` in the compact form the fused analysis kernel reads (cached).

    That form is the compressed rows plus one regular interior: rows ``lo + b`` hold the same
    taps in columns ``col + 2 b`` onwards, as an analysis matrix's do (a synthesis matrix's
    columns are its transpose's rows, two fine samples apart).  The interior is the longest run
    of such rows; the compressed rows keep the others.  Each row's sum runs over its taps in
    increasing column order either way, as :func:`_kernels.analysis3` adds them, so the fused
    adjoint gives the same values as the one-axis-at-a-time one.
    """
    out = []
    for indptr, indices, weights in _transposed(bank_name, boundary, m):
        best_lo, best_len = _longest_regular_run(indptr, indices, weights)
        rows = len(indptr) - 1
        if best_len >= 2:
            first, count = int(indptr[best_lo]), int(indptr[best_lo + 1] - indptr[best_lo])
            shift = int(indices[first]) - 2 * best_lo
            interior = np.array([best_lo, best_len, shift + 2 * best_lo], dtype=np.intp)
            pattern = weights[first : first + count].astype(np.float64).reshape(1, -1)
            kept = np.r_[0:best_lo, best_lo + best_len : rows]
        else:
            interior = np.zeros(3, dtype=np.intp)
            pattern = np.zeros((1, 1), dtype=np.float64)
            kept = np.arange(rows)
        counts = np.diff(indptr)[kept]
        ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.intp)
        # The kept rows' entries, in order: each row's run of positions from its start.
        picks = (np.arange(ptr[-1]) + np.repeat(indptr[kept] - ptr[:-1], counts)).astype(np.intp)
        out.append(
            (
                ptr,
                np.ascontiguousarray(indices[picks], dtype=np.intp),
                np.ascontiguousarray(weights[picks], dtype=np.float64),
                interior,
                pattern,
            )
        )
    return out[0], out[1]


def _longest_regular_run(
    indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray
) -> tuple[int, int]:
    """``(first row, rows)`` of the longest run of rows with the same taps (the first such run
    on a tie), each row's taps in consecutive columns starting two columns after the row
    before's; ``(0, 0)`` without one.  Vectorised: a Python loop over the rows cost 7 us a row,
    0.9 s for a picture 131 072 rows high."""
    rows, entries = len(indptr) - 1, len(indices)
    if rows == 0 or entries == 0:
        return 0, 0
    counts = np.diff(indptr)
    starts = indptr[:-1]
    # Breaks between consecutive entries that are not neighbouring columns, counted so far.
    breaks = np.concatenate([[0], np.cumsum(np.diff(indices) != 1)])
    first = np.minimum(starts, entries - 1)
    last = np.clip(starts + counts - 1, 0, entries - 1)
    contiguous = (counts > 0) & (breaks[last] == breaks[first])
    shift = indices[first] - 2 * np.arange(rows)
    table = np.zeros((rows, int(counts.max())), dtype=np.float64)
    entry_rows = np.repeat(np.arange(rows), counts)
    table[entry_rows, np.arange(len(indices)) - np.repeat(starts, counts)] = weights
    link = np.zeros(rows, dtype=bool)  # row r continues row r - 1's run
    link[1:] = (
        contiguous[1:]
        & contiguous[:-1]
        & (counts[1:] == counts[:-1])
        & (shift[1:] == shift[:-1])
        & np.all(table[1:] == table[:-1], axis=1)
    )
    run_starts = np.flatnonzero(~link)
    lengths = np.diff(np.append(run_starts, rows))
    lengths = np.where(contiguous[run_starts], lengths, 0)
    best = int(np.argmax(lengths))
    return int(run_starts[best]), int(lengths[best])


def _adjoint_2d(
    data: np.ndarray, bank: FilterBank, bounds: tuple[str, str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """One level's adjoint over axes 0 and 1 in one pass (the fused analysis kernel given the
    transposed synthesis matrices): ``(aa, ad, da, dd)`` as :func:`wavecore.transform`'s
    ``analysis_2d`` names them, or ``None`` where that kernel cannot take the layout.

    The same values as two :func:`synthesis_step_adjoint` calls, without their transposes.
    """
    if data.ndim < 2 or not fused_level_fits(data.shape, [0, 1], data.dtype):
        return None
    m0, m1 = data.shape[0], data.shape[1]
    trail = data.shape[2:]
    inner = int(np.prod(trail, dtype=np.int64))
    if many_short_rows(m0, m1, inner):
        return None  # two steps, each along whole columns, are faster
    (p0, q0), (p1, q1) = (
        _transposed_compact(bank.name, bounds[0], m0),
        _transposed_compact(bank.name, bounds[1], m1),
    )
    if max(int(np.diff(m[0]).max(initial=0)) for m in (p0, q0, p1, q1)) > _kernels.MAX_TAPS:
        return None
    # Rows: the compressed ones plus the interior's.
    r0, s0, r1, s1 = (len(m[0]) - 1 + int(m[3][1]) for m in (p0, q0, p1, q1))
    x = np.ascontiguousarray(data, dtype=np.float64).reshape(1, m0, m1 * inner)
    sizes = ((r0, r1), (r0, s1), (s0, r1), (s0, s1))
    bands = [np.empty((1, rows, cols * inner)) for rows, cols in sizes]
    args = (x, p0, q0, p1, q1, *bands, inner)
    kernel: Callable[..., None] = _kernels.analysis_2d  # given P.T and Q.T along both axes
    # Each output row is a sum of its own, so any split into row blocks gives the same bits.
    run_rows(lambda lo, hi: kernel(*args, 0, 1, lo, hi), max(r0, s0), x.size)
    aa, ad, da, dd = (
        band.reshape((rows, cols, *trail)) for band, (rows, cols) in zip(bands, sizes, strict=True)
    )
    return aa, ad, da, dd


def synthesis_step_adjoint(
    data: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    axis: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """The adjoint of one synthesis step along ``axis``: ``(P.T @ data, Q.T @ data)``.

    Parameters
    ----------
    data : array_like
        Fine data; its length along ``axis`` must be one the wavelet's ``boundary`` splits
        (:func:`wavecore.valid_length`).
    wavelet, boundary, axis
        As in :func:`wavecore.synthesis_step`.

    Returns
    -------
    coarse, detail : numpy.ndarray
        Float64, shaped like :func:`wavecore.analysis_step`'s coarse and detail parts, such
        that ``<synthesis_step(c, d), data> = <c, coarse> + <d, detail>`` for all ``c``, ``d``.

    Raises
    ------
    InvalidLength
        If the length along ``axis`` does not fit one step.
    InvalidParameter
        For an unknown wavelet, boundary or axis.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import analysis_step, synthesis_step
    >>> rng = np.random.default_rng(0)
    >>> y = rng.standard_normal(14)
    >>> c, d = analysis_step(rng.standard_normal(14))  # shapes of a step's two parts
    >>> ct, dt = synthesis_step_adjoint(y)
    >>> lhs = float(synthesis_step(c, d) @ y)
    >>> bool(np.isclose(lhs, float(c @ ct + d @ dt)))
    True
    """
    bank = get_wavelet(wavelet)
    (bound,) = resolve_boundaries(boundary, 1, bank)
    arr = as_array(data, np.float64)
    ax = normalize_axis(axis, arr.ndim)
    # The axis goes to the front first, so that the kernel's inner loop runs along whole rows
    # (contiguous and long) whatever the axis: the same sums in the same order, several times
    # faster than along the last axis of an image.
    p_t, q_t = _transposed(bank.name, bound, arr.shape[ax])
    front = np.ascontiguousarray(np.moveaxis(arr, ax, 0))
    rest = front.shape[1:]
    x = front.reshape(1, front.shape[0], -1)
    r, s = len(p_t[0]) - 1, len(q_t[0]) - 1
    coarse = np.empty((1, r, x.shape[2]))
    detail = np.empty((1, s, x.shape[2]))
    args = (x, *p_t, *q_t, coarse, detail)
    # Each output row is one sum of its own, so any split into row blocks gives the same bits.
    kernel: Callable[..., None] = _kernels.analysis3  # the analysis kernel, given P.T and Q.T
    run_rows(lambda lo, hi: kernel(*args, 0, 1, lo, hi), max(r, s), x.size)
    return (
        np.moveaxis(coarse.reshape((r, *rest)), 0, ax),
        np.moveaxis(detail.reshape((s, *rest)), 0, ax),
    )


def synthesis_adjoint(
    data: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str | Sequence[str] = "open",
    level: int = 1,
    axes: Sequence[int] = (0, 1),
) -> list[Any]:
    """The adjoint of ``waverec`` (one axis) or ``waverec2`` (two axes) over ``level`` levels.

    Parameters
    ----------
    data : array_like
        Fine data, shaped like what the synthesis returns (trailing axes are carried).
    wavelet, boundary
        As in :func:`wavecore.waverec2` (one boundary, or one per axis).
    level : int
        Levels of the synthesis.
    axes : sequence of int
        ``(axis,)`` for the adjoint of ``waverec(..., axis=axis)``; two axes for ``waverec2``.

    Returns
    -------
    list
        ``[cA, cD_L, ..., cD_1]`` or ``[cA, (cH, cV, cD), ...]`` (float64), the layout
        ``waverec``/``waverec2`` read, such that ``<S(c), data> = <c, S*(data)>`` summed over
        every band, for the synthesis ``S`` and every coefficient list ``c`` of that layout.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import wavedec2, waverec2
    >>> rng = np.random.default_rng(1)
    >>> y = rng.standard_normal((34, 34))
    >>> c = wavedec2(rng.standard_normal((34, 34)), level=2)
    >>> back = synthesis_adjoint(y, level=2)
    >>> inner = float(np.sum(c[0] * back[0])) + sum(
    ...     float(np.sum(a * b)) for t, u in zip(c[1:], back[1:]) for a, b in zip(t, u)
    ... )
    >>> bool(np.isclose(float(np.sum(waverec2(c) * y)), inner))
    True
    """
    bank = get_wavelet(wavelet)
    arr = as_array(data, np.float64)
    named: Any = (axes,) if isinstance(axes, int | np.integer) else axes
    if isinstance(named, str | bytes) or not isinstance(named, Iterable):
        msg = f"axes must name one or two distinct axes, not {axes!r}"
        raise InvalidParameter(msg[:200])
    ax = [normalize_axis(a, arr.ndim) for a in named]
    if len(ax) not in (1, 2) or len(set(ax)) != len(ax):
        msg = f"axes must name one or two distinct axes, not {tuple(named)}"
        raise InvalidParameter(msg)
    bounds = resolve_boundaries(boundary, len(ax), bank)
    count = as_int(level, "level")
    details: list[Any] = []
    coarse = arr
    for _ in range(count):
        if len(ax) == 1:
            coarse, high = synthesis_step_adjoint(coarse, bank, bounds[0], ax[0])
            details.append(high)
            continue
        (a0, a1), (b0, b1) = ax, bounds
        fused = _adjoint_2d(coarse, bank, (b0, b1)) if (a0, a1) == (0, 1) else None
        if fused is not None:
            coarse, cV, cH, cD = fused  # (aa, ad, da, dd)
            details.append((cH, cV, cD))
            continue
        low, high = synthesis_step_adjoint(coarse, bank, b0, a0)
        cH, cD = synthesis_step_adjoint(high, bank, b1, a1)
        coarse, cV = synthesis_step_adjoint(low, bank, b1, a1)
        details.append((cH, cV, cD))
    return [coarse, *reversed(details)]
