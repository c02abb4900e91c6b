"""One analysis or synthesis step along any axis of an n-D array.

The step is the paper's matrix product — ``C = A F``, ``D = B F`` and ``F = P C + Q D`` — applied
along one axis, with the boundary given by the paper's start and end rows (never by padding).
The matrices come from :mod:`wavecore.filters` in compressed-row form, and compiled kernels in
:mod:`wavecore._kernels` apply them in one pass over the data, split over threads for large
arrays.

Dtype policy: float32 stays float32, float64 stays float64 and complex64/complex128 keep their
precision (real and imaginary parts are transformed separately); float16 is computed in float32;
booleans and integers become float64.  Anything else is an
:class:`~wavecore.errors.InvalidParameter`.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from typing import Any

import numpy as np

from . import _kernels, filters
from .arguments import as_array
from .errors import InvalidCoefficients, InvalidParameter
from .filters import (
    FilterBank,
    Regular,
    Sparse,
    check_fine_length,
    get_wavelet,
    step_compact,
    step_sparse,
)

__all__ = ["analysis_step", "as_float_array", "normalize_axis", "synthesis_step", "work_dtype"]

# Up to this many trailing values per sample (a curve's coordinates) a step along a middle axis
# runs as contiguous rows, one per trailing value, through the vectorised row kernels.
_FEW_TRAILING = 4

# Rows up to this long, when there are at least _MANY_ROWS of them, run through the column
# kernels on the transposed data (the row kernels' set-up per row costs more than such a row).
_SHORT_ROW = 32
_MANY_ROWS = 256
# Rows transposed at a time (times up to _FEW_TRAILING values): 32 values a row of 8 bytes
# make 1 MB.
_COLUMN_BLOCK = 1024

# Below this many elements a step runs on the calling thread: the hand-off costs more.  At
# 1 << 18 a 512² grey picture's encode (its quality search synthesises 512² levels a few
# hundred times) took 0.30 s on two threads against 0.22 s on one; at 1 << 19, 0.23 s.
_THREADED_MIN_ELEMENTS = 1 << 19

# The fused 2-D levels (analysis_2d, synthesis_2d, synthesis_2d_integers) do dozens of
# operations an element in one pass, so smaller levels pay for a region: a 512² grey
# picture's finest level (2^18 elements, about 1 ms a pass) and a 2048² RGB picture's
# 256² level ran on the calling thread alone, the largest serial part of their codings.
# Each row block computes its rows as the whole pass does, so the values do not change.
_THREADED_MIN_FUSED = 1 << 17

# Row blocks per thread of the compiled per-pixel passes that cut their rows into blocks
# (``_run_blocks``, the fused last level, the padding copy).  The blocks are handed to whichever
# thread is free, so the two threads end a pass together only if the last blocks are short:
# on the 2-core host the same block took one thread up to 20 % longer than the other, and with
# 2 blocks a thread a 2048² RGB picture's fused last level left one thread idle for 3-10 ms
# (a sixth of the pass).  A block costs the pool some 10 µs and the fused kernels a refill of
# their ring buffers: 16 blocks of the last level took 2 % more CPU than 4 (within the noise).
BLOCKS_PER_THREAD = 8

# Read once: the hot paths ask for the thread count hundreds of times per encode.
_CPUS = os.cpu_count() or 1


def _thread_count() -> int:
    try:
        return max(1, int(os.environ.get("WAVECORE_THREADS", "0")) or _CPUS)
    except ValueError:
        return _CPUS


@lru_cache(maxsize=1)
def _pool() -> ThreadPoolExecutor:
    # The calling thread works too (see _Tasks), so the pool holds the other threads.
    return ThreadPoolExecutor(
        max_workers=max(1, _thread_count() - 1), thread_name_prefix="wavecore"
    )


class _Tasks:
    """Calls shared out between the calling thread and helpers from the pool.

    Each participant claims the next call not yet started until none is left.  The calling
    thread is one of them, so it never idles while there is work, and it waits only for calls
    already running: a helper that starts late (its pool thread busy, or slow to wake on a
    loaded machine) finds nothing left and returns at once.  A region then costs one hand-off
    per helper, not one per call: a 2048² RGB encode made 372 hand-offs in 65 regions, which
    took 12 ms of the calling thread's time (a fifth of its serial part).  Nested regions
    (a call that splits its own work) cannot deadlock either, whatever the pool is doing.
    The first exception is raised by :meth:`run`, and calls not yet started are dropped.
    """

    def __init__(self, calls: list[Callable[[], None]]) -> None:
        self.calls = calls
        self.claimed = 0
        self.left = len(calls)
        self.lock = threading.Lock()
        self.finished = threading.Event()
        self.error: BaseException | None = None

    def drain(self) -> None:
        calls = self.calls
        while True:
            with self.lock:
                index = self.claimed
                if index >= len(calls):
                    return
                self.claimed = index + 1
            try:
                calls[index]()
            except BaseException as exc:  # raised by run(), on the calling thread
                with self.lock:
                    if self.error is None:
                        self.error = exc
                    self.left -= len(calls) - self.claimed  # drop the calls not yet started
                    self.claimed = len(calls)
            with self.lock:
                self.left -= 1
                if self.left == 0:
                    self.finished.set()

    def run(self, helpers: int) -> None:
        for _ in range(min(helpers, len(self.calls) - 1)):
            _pool().submit(self.drain)
        self.drain()
        self.finished.wait()
        if self.error is not None:
            raise self.error


def work_dtype(dtype: np.dtype[Any]) -> np.dtype[Any]:
    """The dtype in which data of ``dtype`` is transformed (see the module's dtype policy)."""
    dtype = np.dtype(dtype)
    if dtype in (np.float32, np.float64, np.complex64, np.complex128):
        return dtype
    if dtype == np.float16:
        return np.dtype(np.float32)
    if dtype.kind in "biu":
        return np.dtype(np.float64)
    msg = (
        f"cannot transform data of dtype {dtype}; use booleans, integers, floats or complex numbers"
    )
    raise InvalidParameter(msg)


def as_float_array(data: Any) -> np.ndarray:
    """``data`` as an array of its working dtype (no copy when it already is one)."""
    arr = as_array(data)  # big-endian input (an uploaded .npy) included
    return arr.astype(work_dtype(arr.dtype), copy=False)


def normalize_axis(axis: Any, ndim: int) -> int:
    """``axis`` as a non-negative index into ``ndim`` dimensions, with a clear error."""
    if isinstance(axis, bool) or not isinstance(axis, int | np.integer):
        msg = f"axis must be an integer, not {axis!r}"
        raise InvalidParameter(msg)
    if not -ndim <= axis < ndim:
        msg = f"axis {axis} is out of range for data with {ndim} dimension(s)"
        raise InvalidParameter(msg)
    return int(axis) % ndim


def _run_blocks(
    kernel: Callable[..., None],
    args: tuple[Any, ...],
    outer: int,
    rows: int,
    work: int,
    rows_even: bool = False,
    outer_only: bool = False,
    min_rows: int = 1,
    least: int = _THREADED_MIN_ELEMENTS,
) -> None:
    """Call ``kernel(*args, outer_lo, outer_hi, row_lo, row_hi)`` over blocks, in threads if big.

    ``outer_only`` kernels take only ``(outer_lo, outer_hi)``; ``rows_even`` keeps row blocks
    on even boundaries (a synthesis block then starts on a whole pair of fine rows);
    ``min_rows`` is the fewest rows worth a block of their own when splitting rows; ``least``
    the fewest elements of ``work`` worth threads.
    """
    threads = _thread_count()
    if threads == 1 or work < least or (outer_only and outer == 1):
        kernel(*args, 0, outer) if outer_only else kernel(*args, 0, outer, 0, rows)
        return
    blocks = threads * BLOCKS_PER_THREAD
    if outer >= blocks or outer_only:
        edges = np.linspace(0, outer, min(blocks, outer) + 1).astype(int)
        spans = [(lo, hi, 0, rows) for lo, hi in itertools.pairwise(edges) if hi > lo]
    else:
        edges = np.linspace(0, rows, max(1, min(blocks, rows // min_rows)) + 1).astype(int)
        if rows_even:
            edges = edges - edges % 2
            edges[-1] = rows
        spans = [(0, outer, lo, hi) for lo, hi in itertools.pairwise(edges) if hi > lo]
    calls = [
        functools.partial(kernel, *args, *(span[:2] if outer_only else span)) for span in spans
    ]
    run_calls(calls)


def run_calls(calls: Sequence[Callable[[], None]]) -> None:
    """Run independent ``calls`` as one parallel region: the calling thread and the pool's
    threads (``WAVECORE_THREADS`` in all) take them in order, each the next one not yet
    started, and this returns once all have run (the first exception is raised).

    Every parallel region of the library runs through here, so timing its calls tells the
    calling thread's serial work from its share of the parallel work
    (``benchmarks/codec_speed.py --stages``).  Results must not depend on which thread runs
    which call, or in what order: each call writes its own slice or slot.
    """
    calls = list(calls)
    threads = _thread_count()
    if threads == 1 or len(calls) < 2:
        for call in calls:
            call()
        return
    _Tasks(calls).run(threads - 1)


def run_slices(
    sizes: Sequence[int], call: Callable[[int, int, int], None], least: int = 1 << 15
) -> None:
    """``call(item, lo, hi)`` over slices of items of ``sizes`` elements (a picture's bands),
    all in one parallel region: each item in up to two slices per thread of at least
    ``least`` elements, the largest items first so that the threads finish together.  Below
    the threading threshold in all (a region would cost more than it saves), each item is
    one call on the calling thread.  For elementwise passes and counts that add up exactly,
    whose results do not depend on the slicing."""
    threads = _thread_count()
    total = int(sum(int(size) for size in sizes))
    if threads == 1 or total < _THREADED_MIN_ELEMENTS:
        for item, size in enumerate(sizes):
            if size > 0:
                call(item, 0, int(size))
        return
    calls = []
    for item in sorted(range(len(sizes)), key=lambda k: -int(sizes[k])):
        size = int(sizes[item])
        pieces = max(1, min(threads * 2, size // least))
        # Whole-number edges (np.linspace costs ~10 us a call, and a region may cut 40 bands).
        edges = [size * k // pieces for k in range(pieces + 1)]
        calls += [
            functools.partial(call, item, lo, hi) for lo, hi in itertools.pairwise(edges) if hi > lo
        ]
    run_calls(calls)


def run_rows(
    call: Callable[[int, int], None],
    rows: int,
    work: int | None = None,
    pieces: int | None = None,
    least: int = _THREADED_MIN_ELEMENTS,
    per_thread: int = 2,
) -> None:
    """Call ``call(row_lo, row_hi)`` over blocks of ``rows`` rows, in threads if the work is big.

    For the codec's compiled per-pixel passes (which release the GIL).  ``work``, the number of
    elements processed, keeps small jobs (below ``least``) on the calling thread; without it a
    job counts as big.  ``pieces`` (default: ``per_thread`` per thread) is how many blocks the
    rows are cut into: uneven work balances better over more, smaller blocks, which the pool
    hands to whichever thread is free.
    """
    threads = _thread_count()
    if threads == 1 or rows < 2 or (work is not None and work < least):
        call(0, rows)
        return
    count = threads * max(1, per_thread) if pieces is None else max(1, pieces)
    edges = np.linspace(0, rows, min(rows, count) + 1).astype(int)
    run_calls([functools.partial(call, lo, hi) for lo, hi in itertools.pairwise(edges) if hi > lo])


def _view3(arr: np.ndarray, axis: int) -> np.ndarray:
    """A ``(outer, n, inner)`` view of a C-contiguous array around ``axis``."""
    shape = arr.shape
    outer = math.prod(shape[:axis])
    inner = math.prod(shape[axis + 1 :])
    return arr.reshape(outer, shape[axis], inner)


def _csr(matrix: Sparse, dtype: np.dtype[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return matrix.indptr, matrix.indices, matrix.weights.astype(dtype, copy=False)


@lru_cache(maxsize=1024)
def _kernel_args(
    bank_name: str, boundary: str, m: int, dtype: np.dtype[Any]
) -> dict[str, tuple[np.ndarray, ...]]:
    """Kernel arguments for the four matrices of fine length ``m``, in ``dtype`` (cached).

    ``"A+"`` … ``"Q+"`` are the compact form the kernels read: the compressed rows of the
    boundary rows only, plus the regular interior (see :mod:`wavecore._kernels`).  Nothing in
    it grows with ``m``, so the cache stays small however long the data.
    """
    compact = dict(zip("ABPQ", step_compact(bank_name, boundary, m), strict=True))
    out: dict[str, tuple[np.ndarray, ...]] = {}
    for name in "ABPQ":
        sparse, reg = compact[name]
        p, step = (1, 2) if name in "AB" else (2, 1)
        if reg.blocks and (reg.p != p or reg.step != step):
            # Strides the kernels are not written for: every row from the compressed form.
            sparse = step_sparse(bank_name, boundary, m)["ABPQ".index(name)]
            reg = dataclasses.replace(reg, blocks=0)
        if reg.blocks:
            interior = np.array([reg.lo, reg.blocks, reg.col], dtype=np.intp)
            pattern = reg.pattern.astype(dtype)
        else:
            interior = np.zeros(3, dtype=np.intp)
            pattern = np.zeros((p, 1), dtype=dtype)
        longest = max(int(np.diff(sparse.indptr).max(initial=0)), pattern.shape[1])
        if longest > _kernels.MAX_TAPS:
            msg = f"a row of {longest} taps is longer than the {_kernels.MAX_TAPS} supported"
            raise InvalidParameter(msg)
        out[name + "+"] = (*_csr(sparse, dtype), interior, pattern)
    return out


def _forget_cached_matrices() -> None:
    _kernel_args.cache_clear()
    _synthesis_ring.cache_clear()


filters.CACHE_CLEARERS.append(_forget_cached_matrices)


def analysis_step(
    data: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    axis: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """One decomposition step along ``axis``: the paper's ``C = A F`` and ``D = B F``.

    Parameters
    ----------
    data : array_like
        Any shape; the step runs along ``axis`` for every position of the other axes (curve
        points ``(m, d)``, images, grids of points).
    wavelet : str or FilterBank
        ``"bspline2"`` (alias ``"chaikin"``), ``"haar"`` or ``"cdf97"`` (alias ``"jpeg2000"``);
        see :func:`wavecore.wavelet_names`.
    boundary : {"open", "closed"}
        Endpoint-interpolating (the paper's start and end rows) or periodic (section 4.4).
    axis : int
        The axis to transform.

    Returns
    -------
    coarse, detail : numpy.ndarray
        C-contiguous arrays shaped like ``data`` except along ``axis``, in the working dtype.

    Raises
    ------
    InvalidLength
        If the length along ``axis`` does not fit one step.

    Examples
    --------
    >>> import numpy as np
    >>> c, d = analysis_step(np.arange(8.0))
    >>> c
    array([0.  , 1.75, 3.5 , 5.25, 7.  ])
    >>> d  # zero in the interior: the regular rows annihilate linear data
    array([ 0.25,  0.  , -0.25])
    """
    bank = get_wavelet(wavelet)
    rule = bank.rule(boundary)
    arr = as_float_array(data)
    if arr.ndim == 0:
        msg = "cannot transform a scalar; pass an array with at least one dimension"
        raise InvalidParameter(msg)
    axis = normalize_axis(axis, arr.ndim)
    m = arr.shape[axis]
    check_fine_length(rule, m, bank.name, boundary)
    if arr.dtype.kind == "c":
        cr, dr = analysis_step(arr.real, bank, boundary, axis)
        ci, di = analysis_step(arr.imag, bank, boundary, axis)
        return cr + 1j * ci, dr + 1j * di
    mats = _kernel_args(bank.name, boundary, m, arr.dtype)
    arr = np.ascontiguousarray(arr)
    x = _view3(arr, axis)
    r, s = rule.coarse_length(m), rule.detail_length(m)
    c = np.empty((x.shape[0], r, x.shape[2]), dtype=arr.dtype)
    d = np.empty((x.shape[0], s, x.shape[2]), dtype=arr.dtype)
    if many_short_rows(x.shape[0], m, x.shape[2]):
        _analysis_short_rows(x, mats["A+"], mats["B+"], c, d)
    elif x.shape[2] == 1:
        args: tuple[Any, ...] = (x[:, :, 0], mats["A+"], mats["B+"], c[:, :, 0], d[:, :, 0])
        _run_blocks(_kernels.analysis_last, args, x.shape[0], m, x.size, outer_only=True)
    elif x.shape[2] <= _FEW_TRAILING:
        # A curve's few coordinates: one contiguous row per coordinate for the vectorised
        # row kernel (the transposes cost far less than a short inner loop per sample).
        rows = np.ascontiguousarray(x.transpose(0, 2, 1)).reshape(-1, m)
        c_rows = np.empty((rows.shape[0], r), dtype=arr.dtype)
        d_rows = np.empty((rows.shape[0], s), dtype=arr.dtype)
        args = (rows, mats["A+"], mats["B+"], c_rows, d_rows)
        _run_blocks(_kernels.analysis_last, args, rows.shape[0], m, x.size, outer_only=True)
        c[...] = c_rows.reshape(x.shape[0], x.shape[2], r).transpose(0, 2, 1)
        d[...] = d_rows.reshape(x.shape[0], x.shape[2], s).transpose(0, 2, 1)
    else:
        args = (x, mats["A+"], mats["B+"], c, d)
        _run_blocks(_kernels.analysis_mid, args, x.shape[0], max(r, s), x.size)
    shape_c = arr.shape[:axis] + (r,) + arr.shape[axis + 1 :]
    shape_d = arr.shape[:axis] + (s,) + arr.shape[axis + 1 :]
    return c.reshape(shape_c), d.reshape(shape_d)


def synthesis_step(
    coarse: Any,
    detail: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    axis: int = 0,
) -> np.ndarray:
    """One reconstruction step along ``axis``: the paper's ``F = P C + Q D``.

    Parameters
    ----------
    coarse, detail : array_like
        Coefficients from :func:`analysis_step` (or edited ones).  Their shapes must agree
        except along ``axis``, where their lengths must belong to one fine length.  ``detail``
        may be ``None`` for "no details".
    wavelet, boundary, axis
        As in :func:`analysis_step`.

    Returns
    -------
    numpy.ndarray
        The fine data, in the working dtype of the coefficients.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.random.default_rng(0).standard_normal(10)
    >>> bool(np.allclose(synthesis_step(*analysis_step(f)), f))
    True
    """
    bank = get_wavelet(wavelet)
    rule = bank.rule(boundary)
    c_arr = as_float_array(coarse)
    if c_arr.ndim == 0:
        msg = "coarse coefficients must have at least one dimension"
        raise InvalidCoefficients(msg)
    axis = normalize_axis(axis, c_arr.ndim)
    if detail is None:
        s = c_arr.shape[axis] - rule.extra
        d_shape = c_arr.shape[:axis] + (max(s, 0),) + c_arr.shape[axis + 1 :]
        d_arr = np.zeros(d_shape, dtype=c_arr.dtype)
    else:
        d_arr = as_float_array(detail)
    if d_arr.ndim != c_arr.ndim or any(
        a != b for i, (a, b) in enumerate(zip(c_arr.shape, d_arr.shape, strict=True)) if i != axis
    ):
        msg = (
            f"coarse coefficients of shape {c_arr.shape} and details of shape {d_arr.shape} "
            f"do not agree away from axis {axis}"
        )
        raise InvalidCoefficients(msg)
    r, s = c_arr.shape[axis], d_arr.shape[axis]
    m = rule.fine_length(r, s)
    if rule.coarse_length(m) != r or rule.detail_length(m) != s or m % 2 or m < rule.min_length:
        msg = (
            f"{r} coarse and {s} detail coefficients along axis {axis} do not come from one "
            f"{boundary} step of {bank.name!r} (a fine length m gives "
            f"{'(m + 2) / 2 and (m - 2) / 2' if rule.extra else 'm / 2 and m / 2'})"
        )
        raise InvalidCoefficients(msg)
    dtype = np.result_type(c_arr.dtype, d_arr.dtype)
    if dtype.kind == "c":
        fr = synthesis_step(c_arr.real, d_arr.real, bank, boundary, axis)
        fi = synthesis_step(c_arr.imag, d_arr.imag, bank, boundary, axis)
        return fr + 1j * fi
    mats = _kernel_args(bank.name, boundary, m, dtype)
    cx = _view3(np.ascontiguousarray(c_arr, dtype=dtype), axis)
    dx = _view3(np.ascontiguousarray(d_arr, dtype=dtype), axis)
    f = np.empty((cx.shape[0], m, cx.shape[2]), dtype=dtype)
    if many_short_rows(f.shape[0], m, f.shape[2]):
        _synthesis_short_rows(cx, dx, mats["P+"], mats["Q+"], f)
    elif f.shape[2] == 1:
        args: tuple[Any, ...] = (cx[:, :, 0], dx[:, :, 0], mats["P+"], mats["Q+"], f[:, :, 0])
        _run_blocks(_kernels.synthesis_last, args, f.shape[0], m, f.size, outer_only=True)
    elif f.shape[2] <= _FEW_TRAILING:
        c_rows = np.ascontiguousarray(cx.transpose(0, 2, 1)).reshape(-1, r)
        d_rows = np.ascontiguousarray(dx.transpose(0, 2, 1)).reshape(-1, s)
        f_rows = np.empty((c_rows.shape[0], m), dtype=dtype)
        args = (c_rows, d_rows, mats["P+"], mats["Q+"], f_rows)
        _run_blocks(_kernels.synthesis_last, args, f_rows.shape[0], m, f.size, outer_only=True)
        f[...] = f_rows.reshape(f.shape[0], f.shape[2], m).transpose(0, 2, 1)
    else:
        args = (cx, dx, mats["P+"], mats["Q+"], f)
        _run_blocks(_kernels.synthesis_mid, args, f.shape[0], m, f.size)
    return f.reshape(c_arr.shape[:axis] + (m,) + c_arr.shape[axis + 1 :])


def many_short_rows(rows: int, length: int, inner: int) -> bool:
    """Whether a step along an axis of ``length`` samples, over ``rows`` positions of the axes
    before it and ``inner`` values after, would run as many short rows through the row kernels
    (which then cost more in set-up than in work).  The fused 2-D levels decline such levels:
    one step per axis, through the column kernels, is several times faster."""
    return inner <= _FEW_TRAILING and length <= _SHORT_ROW and rows * inner >= _MANY_ROWS


def _rows_as_columns(x: np.ndarray) -> np.ndarray:
    """``(outer, n, inner)`` as ``(n, outer * inner)``: each row the row kernels would take (one
    per outer index and trailing value) as a column."""
    return np.ascontiguousarray(x.transpose(1, 0, 2)).reshape(x.shape[1], -1)


def _columns_to_rows(cols: np.ndarray, out: np.ndarray) -> None:
    """Undo :func:`_rows_as_columns` into ``out`` (``(outer, n, inner)``)."""
    out[...] = cols.reshape(out.shape[1], out.shape[0], out.shape[2]).transpose(1, 0, 2)


def _by_column_blocks(outer: int, work: int, block: Callable[[int, int], None]) -> None:
    """``block(lo, hi)`` over the outer indices in pieces of ``_COLUMN_BLOCK``, in threads if
    the work is big: each piece's transposed copies stay small, and in cache."""

    def run(lo: int, hi: int) -> None:
        for start in range(lo, hi, _COLUMN_BLOCK):
            block(start, min(start + _COLUMN_BLOCK, hi))

    run_rows(run, outer, work)


def _analysis_short_rows(
    x: np.ndarray, a_mat: Any, b_mat: Any, c: np.ndarray, d: np.ndarray
) -> None:
    """An analysis step along the middle axis of ``x`` for many short rows: the same values as
    the row kernels, from the middle-axis kernel over the transposed rows."""

    def block(lo: int, hi: int) -> None:
        src = _rows_as_columns(x[lo:hi])
        count = src.shape[1]
        c_cols = np.empty((1, c.shape[1], count), dtype=c.dtype)
        d_cols = np.empty((1, d.shape[1], count), dtype=d.dtype)
        # The middle-axis kernel adds each row's taps from zero in column order, as the row
        # kernel does (the banks' regular analysis rows have no zero taps, which it skips).
        rows = max(c.shape[1], d.shape[1])
        _kernels.analysis_mid(src[None], a_mat, b_mat, c_cols, d_cols, 0, 1, 0, rows)
        _columns_to_rows(c_cols[0], c[lo:hi])
        _columns_to_rows(d_cols[0], d[lo:hi])

    _by_column_blocks(x.shape[0], x.size, block)


def _synthesis_short_rows(
    c: np.ndarray, d: np.ndarray, p_mat: Any, q_mat: Any, f: np.ndarray
) -> None:
    """The synthesis counterpart of :func:`_analysis_short_rows`."""

    def block(lo: int, hi: int) -> None:
        c_cols, d_cols = _rows_as_columns(c[lo:hi]), _rows_as_columns(d[lo:hi])
        count = c_cols.shape[1]
        f_cols = np.empty((f.shape[1], count), dtype=f.dtype)
        scratch = np.empty(count, dtype=f.dtype)
        _kernels.synthesis_columns(c_cols, d_cols, p_mat, q_mat, f_cols, scratch)
        _columns_to_rows(f_cols, f[lo:hi])

    _by_column_blocks(f.shape[0], f.size, block)


def fused_level_fits(shape: tuple[int, ...], axes: list[int], dtype: np.dtype[Any]) -> bool:
    """Whether one 2-D level over ``axes`` can run as one fused pass (the image case).

    It can when the two axes are neighbours, in increasing order (images, with or without
    trailing channels), and the data is real floating point; any other layout takes one step
    per axis.
    """
    return (
        len(axes) == 2
        and axes[0] >= 0
        and axes[1] == axes[0] + 1 < len(shape)
        and np.dtype(dtype) in (np.float32, np.float64)
    )


def _ring_fits(matrix: tuple[Any, Regular], ring: int) -> bool:
    """Whether every row's taps land in distinct slots of a ring buffer of ``ring`` rows.

    ``matrix`` is the compact form (boundary rows, regular interior).  Periodic rows that wrap
    around (``c[n-1]`` and ``c[0]``) are fine unless two of their indices are equal modulo the
    ring size; at most 32 taps per row are allowed.  Every placement of the regular pattern is
    the first one shifted, which moves all its slots alike, so the first one speaks for all.
    """
    sparse, reg = matrix
    counts = np.diff(sparse.indptr)
    rows = np.repeat(np.arange(len(counts)), counts)
    keys = rows * ring + sparse.indices % ring
    if int(counts.max(initial=0)) > 32 or len(np.unique(keys)) != len(keys):
        return False
    for phase in range(reg.p if reg.blocks else 0):
        columns = reg.col + np.flatnonzero(reg.pattern[phase])
        if len(columns) > 32 or len(np.unique(columns % ring)) != len(columns):
            return False
    return True


@lru_cache(maxsize=1024)
def _synthesis_ring(bank_name: str, boundary: str, m: int) -> int:
    """Rows of axis-1 syntheses the fused kernel keeps per band (0: it cannot run fused)."""
    _, _, P, Q = step_compact(bank_name, boundary, m)
    for ring in range(8, 33):
        if _ring_fits(P, ring) and _ring_fits(Q, ring):
            return ring
    return 0


def _split_shape(shape: tuple[int, ...], axis: int) -> tuple[int, int, int, int]:
    """``(outer, n0, n1, inner)`` for the axes ``axis`` and ``axis + 1`` of ``shape``."""
    outer = math.prod(shape[:axis])
    inner = math.prod(shape[axis + 2 :])
    return outer, shape[axis], shape[axis + 1], inner


def analysis_2d(
    arr: np.ndarray, bank: FilterBank, boundaries: tuple[str, str], axis: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """One 2-D level over axes ``axis`` and ``axis + 1`` in one pass, or ``None`` if it cannot.

    Returns the bands ``(aa, ad, da, dd)``: the first letter is ``axis``, the second
    ``axis + 1``; ``"a"`` coarse, ``"d"`` detail.  The lengths must already be checked.
    """
    if not fused_level_fits(arr.shape, [axis, axis + 1], arr.dtype):
        return None
    outer, m0, m1, inner = _split_shape(arr.shape, axis)
    if many_short_rows(outer * m0, m1, inner):
        return None  # one step per axis is faster (and gives the same values)
    rule0, rule1 = bank.rule(boundaries[0]), bank.rule(boundaries[1])
    mats0 = _kernel_args(bank.name, boundaries[0], m0, arr.dtype)
    mats1 = _kernel_args(bank.name, boundaries[1], m1, arr.dtype)
    x = np.ascontiguousarray(arr).reshape(outer, m0, m1 * inner)
    r0, s0 = rule0.coarse_length(m0), rule0.detail_length(m0)
    r1, s1 = rule1.coarse_length(m1), rule1.detail_length(m1)
    sizes = ((r0, r1), (r0, s1), (s0, r1), (s0, s1))
    bands = [np.empty((outer, rows, cols * inner), dtype=arr.dtype) for rows, cols in sizes]
    args = (x, mats0["A+"], mats0["B+"], mats1["A+"], mats1["B+"], *bands, inner)
    _run_blocks(_kernels.analysis_2d, args, outer, max(r0, s0), x.size, least=_THREADED_MIN_FUSED)
    lead, trail = arr.shape[:axis], arr.shape[axis + 2 :]
    aa, ad, da, dd = (
        band.reshape(lead + size + trail) for band, size in zip(bands, sizes, strict=True)
    )
    return aa, ad, da, dd


def _fused_synthesis(
    bands: tuple[Any, Any, Any, Any], bank: FilterBank, boundaries: tuple[str, str], axis: int
) -> tuple[Any, ...] | None:
    """What :func:`synthesis_2d` and :func:`synthesis_2d_integers` hand the kernels: the
    bands as contiguous ``(outer, rows, cols * inner)`` views, the four synthesis matrices,
    ``(outer, m0, m1, inner)``, the ring size, the leading and trailing shape and the dtype;
    or ``None`` when the level cannot run fused."""
    if any(band is None for band in bands):
        return None
    aa, ad, da, dd = (as_float_array(band) for band in bands)
    dtype = np.result_type(aa, ad, da, dd)
    if not fused_level_fits(aa.shape, [axis, axis + 1], dtype):
        return None
    rule0, rule1 = bank.rule(boundaries[0]), bank.rule(boundaries[1])
    outer, r0, r1, inner = _split_shape(aa.shape, axis)
    s0, s1 = dd.shape[axis : axis + 2] if dd.ndim == aa.ndim else (-1, -1)
    m0, m1 = rule0.fine_length(r0, s0), rule1.fine_length(r1, s1)
    if many_short_rows(outer * m0, m1, inner):
        # One step per axis is faster.  The same values, except where a closed boundary
        # wraps a level 2 samples wide (a few ulps: this kernel and the steps differ there).
        return None
    lead, trail = aa.shape[:axis], aa.shape[axis + 2 :]
    fits = all(
        band.shape == lead + size + trail
        for band, size in ((ad, (r0, s1)), (da, (s0, r1)), (dd, (s0, s1)))
    ) and all(
        m % 2 == 0
        and m >= rule.min_length
        and rule.coarse_length(m) == r
        and rule.detail_length(m) == s
        for rule, m, r, s in ((rule0, m0, r0, s0), (rule1, m1, r1, s1))
    )
    ring = _synthesis_ring(bank.name, boundaries[0], m0) if fits else 0
    if not ring:
        return None
    mats0 = _kernel_args(bank.name, boundaries[0], m0, dtype)
    mats1 = _kernel_args(bank.name, boundaries[1], m1, dtype)
    views = [
        np.ascontiguousarray(band, dtype=dtype).reshape(outer, band.shape[axis], -1)
        for band in (aa, ad, da, dd)
    ]
    matrices = (mats0["P+"], mats0["Q+"], mats1["P+"], mats1["Q+"])
    return views, matrices, (outer, m0, m1, inner), ring, lead, trail, dtype


def synthesis_2d(
    bands: tuple[Any, Any, Any, Any], bank: FilterBank, boundaries: tuple[str, str], axis: int
) -> np.ndarray | None:
    """The inverse of :func:`analysis_2d` in one pass, or ``None`` if it cannot run fused.

    ``None`` also when the bands' shapes do not fit together: the per-axis path then raises
    the precise error.
    """
    fused = _fused_synthesis(bands, bank, boundaries, axis)
    if fused is None:
        return None
    views, matrices, (outer, m0, m1, inner), ring, lead, trail, dtype = fused
    f = np.empty((outer, m0, m1 * inner), dtype=dtype)
    args = (*views, *matrices, f, inner, ring)
    # Each block fills its ring buffers afresh (a few coarse rows' syntheses along axis 1), so
    # a block of a handful of rows would mostly redo its neighbours' work: the 8 rows of a
    # padded 1 × N image took 4 times the work in 8 blocks.
    _run_blocks(
        _kernels.synthesis_2d,
        args,
        outer,
        m0,
        f.size,
        rows_even=True,
        min_rows=32,
        least=_THREADED_MIN_FUSED,
    )
    return f.reshape((*lead, m0, m1, *trail))


def synthesis_2d_integers(
    bands: tuple[Any, Any, Any, Any],
    bank: FilterBank,
    boundaries: tuple[str, str],
    window: tuple[tuple[int, int], tuple[int, int]],
    dtype: np.dtype[Any],
    matrix: np.ndarray | None,
) -> np.ndarray | None:
    """The last level of an image's synthesis (axes 0 and 1) straight into integers.

    The same values as :func:`synthesis_2d` followed by cropping to ``window`` (``(start,
    stop)`` of the fine rows and columns) and the decoder's colour pass (``matrix`` on the
    first three channels when given, then rounding and clipping into ``dtype``, NaN → 0), in
    one pass: the fine picture in floats (eight bytes a sample, all of it fresh memory) is
    never made.  ``None`` when the level cannot run fused, or the bands are not float64.
    """
    fused = _fused_synthesis(bands, bank, boundaries, 0)
    if fused is None:
        return None
    views, matrices, (outer, m0, m1, inner), ring, _, trail, work = fused
    (row0, row1), (col0, col1) = window
    if (
        work != np.float64
        or outer != 1
        or len(trail) > 1
        or not (0 <= row0 < row1 <= m0 and 0 <= col0 < col1 <= m1)
        or (matrix is not None and inner < 3)
    ):
        return None
    info = np.iinfo(dtype)
    out = np.empty((row1 - row0, col1 - col0, inner), dtype=dtype)
    colours = np.ascontiguousarray(matrix if matrix is not None else np.eye(3), dtype=np.float64)
    args = (
        *views,
        *matrices,
        m1 * inner,
        inner,
        ring,
        colours,
        matrix is not None,
        float(info.min),
        float(info.max),
        out,
        row0,
        col0,
    )
    kernel: Callable[..., None] = _kernels.synthesis_2d_integers
    # Blocks of at least 32 rows, as in synthesis_2d (each block refills its ring buffers).
    run_rows(
        lambda lo, hi: kernel(*args, lo, hi),
        row1 - row0,
        (row1 - row0) * m1 * inner,
        pieces=max(1, min(_thread_count() * BLOCKS_PER_THREAD, (row1 - row0) // 32)),
        least=_THREADED_MIN_FUSED,
    )
    return out.reshape(out.shape[:2] + trail)
