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

import itertools
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from typing import Any

import numpy as np

from . import _kernels
from .errors import InvalidCoefficients, InvalidParameter
from .filters import FilterBank, Sparse, check_fine_length, get_wavelet, step_sparse

__all__ = ["analysis_step", "as_float_array", "normalize_axis", "synthesis_step", "work_dtype"]

# Below this many output elements a step runs on the calling thread: the hand-off costs more.
_THREADED_MIN_ELEMENTS = 1 << 18


def _thread_count() -> int:
    try:
        return max(1, int(os.environ.get("WAVECORE_THREADS", "0")) or (os.cpu_count() or 1))
    except ValueError:
        return os.cpu_count() or 1


@lru_cache(maxsize=1)
def _pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=_thread_count(), thread_name_prefix="wavecore")


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
    try:
        arr = np.asarray(data)
    except (TypeError, ValueError) as exc:
        msg = f"cannot turn the input into a numeric array: {exc}"
        raise InvalidParameter(msg) from None
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
    kernel: Callable[..., None], args: tuple[Any, ...], outer: int, rows: int, work: int
) -> None:
    """Call ``kernel(*args, outer_lo, outer_hi, row_lo, row_hi)`` over blocks, in threads if big."""
    threads = _thread_count()
    if threads == 1 or work < _THREADED_MIN_ELEMENTS:
        kernel(*args, 0, outer, 0, rows)
        return
    blocks = threads * 4
    if outer >= blocks:
        edges = np.linspace(0, outer, blocks + 1).astype(int)
        spans = [(lo, hi, 0, rows) for lo, hi in itertools.pairwise(edges) if hi > lo]
    else:
        edges = np.linspace(0, rows, blocks + 1).astype(int)
        spans = [(0, outer, lo, hi) for lo, hi in itertools.pairwise(edges) if hi > lo]
    futures = [_pool().submit(kernel, *args, *span) for span in spans]
    for future in futures:
        future.result()


def _view3(arr: np.ndarray, axis: int) -> np.ndarray:
    """A ``(outer, n, inner)`` view of a C-contiguous array around ``axis``."""
    shape = arr.shape
    outer = int(np.prod(shape[:axis], dtype=np.int64))
    inner = int(np.prod(shape[axis + 1 :], dtype=np.int64))
    return arr.reshape(outer, shape[axis], inner)


def _csr(matrix: Sparse, dtype: np.dtype[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return matrix.indptr, matrix.indices, matrix.weights.astype(dtype, copy=False)


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
        ``"bspline2"`` (alias ``"chaikin"``) or ``"haar"``.
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
    A, B, _, _ = step_sparse(bank.name, boundary, m)
    arr = np.ascontiguousarray(arr)
    x = _view3(arr, axis)
    r, s = A.shape[0], B.shape[0]
    c = np.empty((x.shape[0], r, x.shape[2]), dtype=arr.dtype)
    d = np.empty((x.shape[0], s, x.shape[2]), dtype=arr.dtype)
    if x.shape[2] == 1:
        kernel, args = (
            _kernels.analysis2,
            (x[:, :, 0], *_csr(A, arr.dtype), *_csr(B, arr.dtype), c[:, :, 0], d[:, :, 0]),
        )
    else:
        kernel, args = _kernels.analysis3, (x, *_csr(A, arr.dtype), *_csr(B, arr.dtype), c, d)
    _run_blocks(kernel, args, x.shape[0], max(r, s), x.size)
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
    _, _, P, Q = step_sparse(bank.name, boundary, m)
    cx = _view3(np.ascontiguousarray(c_arr, dtype=dtype), axis)
    dx = _view3(np.ascontiguousarray(d_arr, dtype=dtype), axis)
    f = np.empty((cx.shape[0], m, cx.shape[2]), dtype=dtype)
    if f.shape[2] == 1:
        kernel, args = (
            _kernels.synthesis2,
            (cx[:, :, 0], dx[:, :, 0], *_csr(P, dtype), *_csr(Q, dtype), f[:, :, 0]),
        )
    else:
        kernel, args = _kernels.synthesis3, (cx, dx, *_csr(P, dtype), *_csr(Q, dtype), f)
    _run_blocks(kernel, args, f.shape[0], m, f.size)
    return f.reshape(c_arr.shape[:axis] + (m,) + c_arr.shape[axis + 1 :])
