"""Fitting data to the lengths the transform accepts: padding grids, re-sampling curves.

The transform takes only lengths of the form ``2**L * k + 2`` (open) or ``2**L * k`` (closed)
along each axis.  Two ways to get there:

* :func:`pad_to_fit` / :func:`crop_padding` — extend each axis at its *end* up to the next length
  that fits, and cut the extension off again after reconstruction.  Exact: with every detail kept
  the original comes back bit for bit (up to float rounding).  The default for images.
* :func:`resample_curve` — the paper's section 4.5: re-sample a curve uniformly by arc length to a
  length that fits.  Changes the samples (not exact), but keeps the shape, and is what the curve
  front end does.

Why the padding goes at the end
    The first sample keeps index 0 at every level, so the original's extent is always a prefix:
    cropping is a slice ``[:n]`` on the fine data and ``[:coarse_extent(...)]`` on a coarse
    approximation.  Splitting the padding between both ends would shift the origin by a
    fraction of a coarse sample at every level.

How the extension looks
    Open axes repeat the last sample (edge padding): a flat continuation has no details of its
    own, so it disturbs the open boundary's end rows the least.  Closed (periodic) axes are
    extended by a straight blend from the last sample back to the first, so the periodic signal
    that the closed filters see has no jump at the seam (wrap padding, ``x[0], x[1], …`` appended,
    would move the jump to where the appended run meets ``x[0]`` again).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .arguments import as_array, closed_flags
from .errors import InvalidLength, InvalidParameter
from .filters import FilterBank, get_wavelet
from .multilevel import (
    MAX_LENGTH,
    as_int,
    check_level_bound,
    check_result_values,
    growth_limit,
    max_level,
    resolve_axes,
    resolve_boundaries,
    valid_length,
)
from .transform import BLOCKS_PER_THREAD, as_float_array, run_rows

__all__ = [
    "GridFit",
    "coarse_extent",
    "crop_padding",
    "fit_grid",
    "minimum_length",
    "pad_to_fit",
    "resample_curve",
    "resample_grid",
]

Pads = tuple[tuple[int, int], ...]


def pad_to_fit(
    data: Any,
    level: int,
    *,
    axes: Sequence[int] | int,
    boundary: str | Sequence[str] = "open",
    wavelet: str | FilterBank = "bspline2",
) -> tuple[np.ndarray, Pads]:
    """Extend each axis in ``axes`` at its end to the smallest length that fits ``level`` levels.

    Parameters
    ----------
    data : array_like
        Any array; axes not in ``axes`` are left alone (colour channels, point coordinates).
    level : int
        The number of levels the padded array must allow (0 pads nothing).
    axes : int or sequence of int
        The axes to pad (keyword-only: the axes that will be transformed).
    boundary : str or sequence of str
        One boundary for all axes or one per axis in ``axes``.  Open axes repeat their last
        sample; closed axes blend linearly from the last sample back to the first, so the
        periodic signal stays without a jump.
    wavelet : str
        The wavelet whose size rule applies (see :func:`wavecore.valid_length`).

    Returns
    -------
    padded : numpy.ndarray
        The padded array, of ``data``'s dtype (integers rounded in a closed blend).
    pads : tuple of (int, int)
        ``(before, after)`` per axis in ``axes`` — ``before`` is always 0 — for
        :func:`crop_padding`.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.arange(12.0).reshape(3, 4)
    >>> padded, pads = pad_to_fit(image, 1, axes=(0, 1))
    >>> padded.shape, pads
    ((8, 8), ((0, 5), (0, 4)))
    >>> bool(np.array_equal(crop_padding(padded, pads, axes=(0, 1)), image))
    True
    """
    arr = as_array(data)
    pads, extensions = _fit_extensions(arr.shape, level, axes, boundary, wavelet)
    if any(after for _, after, _ in extensions):
        arr = _padded(arr, extensions, arr.dtype, None)
    return arr, pads


def pad_converted_to_fit(
    data: np.ndarray,
    level: int,
    *,
    axes: Sequence[int] | int,
    boundary: str | Sequence[str],
    wavelet: str | FilterBank,
    dtype: np.dtype[Any],
    convert: Callable[[np.ndarray, int, int], None],
) -> tuple[np.ndarray, Pads]:
    """``pad_to_fit(converted, ...)`` where ``convert(out, lo, hi)`` writes rows ``[lo, hi)`` of
    ``data`` converted (to ``dtype``, of ``data``'s shape) into the same rows and leading
    columns of ``out``, the padded array: the codec's colour transform, written straight into
    the padded array, so that the converted picture is never made on its own (a 2048² RGB one
    is 100 MB of fresh float64 pages, whose faults cost more than the arithmetic).  Always a
    new array, padded or not.  Not public: for :mod:`wavecore.codec`."""
    pads, extensions = _fit_extensions(data.shape, level, axes, boundary, wavelet)
    return _padded(data, extensions, np.dtype(dtype), convert), pads


def _fit_extensions(
    shape: tuple[int, ...],
    level: int,
    axes: Sequence[int] | int,
    boundary: str | Sequence[str],
    wavelet: str | FilterBank,
) -> tuple[Pads, list[tuple[int, int, bool]]]:
    """``pad_to_fit``'s pads, and its ``(axis, count, closed)`` extensions, for ``shape``."""
    ax = resolve_axes(axes if not isinstance(axes, int | np.integer) else [int(axes)], len(shape))
    bank = get_wavelet(wavelet)
    bounds = resolve_boundaries(boundary, len(ax), bank)
    level = as_int(level, "level")
    pads: list[tuple[int, int]] = []
    for a, b in zip(ax, bounds, strict=True):
        n = shape[a]
        if n == 0:
            msg = f"axis {a} is empty; there is nothing to pad"
            raise InvalidParameter(msg)
        check_level_bound(
            level,
            bank.rule(b),
            growth_limit(n),
            f"axis {a} of {n} samples (padded to fit, it may grow to {growth_limit(n)})",
        )
        after = valid_length(n, level, b, bank) - n
        pads.append((0, after))
    extensions = [
        (a, after, b == "closed") for a, (_, after), b in zip(ax, pads, bounds, strict=True)
    ]
    return tuple(pads), extensions


def _padded(
    arr: np.ndarray,
    extensions: list[tuple[int, int, bool]],
    dtype: np.dtype[Any],
    convert: Callable[[np.ndarray, int, int], None] | None,
) -> np.ndarray:
    """``arr`` extended by ``count`` samples after the end of each ``(axis, count, closed)``, in
    that order, written into one new array of ``dtype``: the original is copied (or converted,
    by ``convert``) once, in row slices over the thread pool (NumPy's copies and the compiled
    conversions release the GIL), not once per padded axis."""
    shape = list(arr.shape)
    for axis, count, _ in extensions:
        shape[axis] += count
    out = np.empty(shape, dtype=dtype)
    inner = out[tuple(slice(0, n) for n in arr.shape)]

    def copy(lo: int, hi: int) -> None:
        inner[lo:hi] = arr[lo:hi]

    def converted(lo: int, hi: int) -> None:
        assert convert is not None
        convert(out, lo, hi)

    # (The copy's pages are fresh memory: their faults make the blocks' times uneven.)
    run_rows(
        copy if convert is None else converted,
        arr.shape[0],
        arr.size,
        per_thread=BLOCKS_PER_THREAD,
    )
    filled = list(arr.shape)
    for axis, count, closed in extensions:
        if count:
            current = out[tuple(slice(0, n) for n in filled)]
            target = [slice(0, n) for n in filled]
            target[axis] = slice(filled[axis], filled[axis] + count)
            out[tuple(target)] = _extension(current, axis, count, closed=closed)
            filled[axis] += count
    return out


def _extension(arr: np.ndarray, axis: int, count: int, *, closed: bool) -> np.ndarray:
    """The ``count`` samples that extend ``arr`` along ``axis``: its last one repeated (open),
    or steps from the last back to the first (closed)."""
    # Slices, not np.take: take copies a strided view (the padded array's filled part) whole
    # before it picks anything, 23 ms for each axis of a 2048 x 2048 RGB picture.
    before = (slice(None),) * axis
    last = arr[(*before, slice(-1, None))]
    if not closed:
        return last  # broadcast along the axis
    first = arr[(*before, slice(0, 1))]
    shape = [1] * arr.ndim
    shape[axis] = count
    # count + 1 steps from the last sample to the first, neither of them repeated.
    t = (np.arange(1, count + 1) / (count + 1)).reshape(shape)
    blend = last + (first.astype(np.float64) - last) * t
    if arr.dtype.kind in "biu":
        info = np.iinfo(arr.dtype) if arr.dtype.kind != "b" else None
        blend = np.rint(blend)
        if info is not None:
            blend = np.clip(blend, info.min, info.max)
    return blend.astype(arr.dtype)


def coarse_extent(
    n: int,
    pad: tuple[int, int],
    level: int,
    *,
    boundary: str = "open",
    wavelet: str | FilterBank = "bspline2",
) -> int:
    """How many samples of a level-``level`` coarse approximation cover the original's extent.

    Each coarse sample sits at the centre of its basis function (its Greville abscissa).  The
    coarse approximation keeps the samples that sit inside the original's extent, plus the next
    one when the extent ends between two of them: about ``n / 2**level`` samples, and one or two
    more for the open boundary, whose end samples interpolate the ends.

    Parameters
    ----------
    n : int
        The original length of the axis.
    pad : (int, int)
        The ``(before, after)`` padding that :func:`pad_to_fit` returned for this axis.
    level : int
        The level of the coarse approximation (0 is the fine data: ``n`` itself).
    boundary, wavelet
        As given to :func:`pad_to_fit`.

    Examples
    --------
    >>> coarse_extent(512, (0, 2), 2), coarse_extent(60, (0, 6), 3), coarse_extent(37, (0, 5), 3)
    (130, 9, 6)
    >>> coarse_extent(100, (0, 4), 2, wavelet="haar")
    25
    """
    before, after = (int(p) for p in pad)
    if before:
        msg = f"padding before the data ({before}) is not supported; pad_to_fit pads at the end"
        raise InvalidParameter(msg)
    n = as_int(n, "n", minimum=1)
    level = as_int(level, "level")
    bank = get_wavelet(wavelet)
    rule = bank.rule(boundary)
    if not rule.fits(n + after, level):
        msg = (
            f"level {level} does not fit the padded length {n + after}: the largest accepted "
            f"level is {max_level(n + after, boundary, bank)}"
        )
        raise InvalidParameter(msg)
    coarse = n + after
    for _ in range(level):
        coarse = rule.coarse_length(coarse)
    step = 1 << level
    if level == 0:
        return n
    if bank.name == "haar":
        return min(coarse, -(-n // step))
    if rule.periodic:
        # Chaikin: fine sample i sits at coarse position (i - 1/2) / 2**level + 1/2.
        end = (n - 1.5) / step + 0.5

        def position(k: int) -> float:
            return float(k)

    else:
        # Endpoint interpolating: Greville abscissae 0, 1/2, 3/2, …, K - 1/2, K (coarse units).
        end = max(0.0, (n - 1.5) / step)

        def position(k: int) -> float:
            return min(max(k - 0.5, 0.0), coarse - 2.0)

    # The positions rise with k: the count at or below the end by bisection, not an array of
    # ``coarse`` of them (n may be 10**9).
    low, high = 0, coarse
    while low < high:
        middle = (low + high) // 2
        if position(middle) <= end + 1e-12:
            low = middle + 1
        else:
            high = middle
    inside = low
    if position(inside - 1) < end - 1e-12:
        inside += 1
    return min(coarse, inside)


def crop_padding(
    data: Any,
    pads: Pads,
    *,
    axes: Sequence[int] | int,
    level: int = 0,
    boundary: str | Sequence[str] = "open",
    wavelet: str | FilterBank = "bspline2",
) -> np.ndarray:
    """Undo :func:`pad_to_fit`: cut the padding off the fine data or off a coarse approximation.

    Parameters
    ----------
    data : array_like
        The padded array (``level=0``) or its coarse approximation after ``level`` levels.
    pads : tuple of (int, int)
        As :func:`pad_to_fit` returned them.
    axes : int or sequence of int
        The same axes as given to :func:`pad_to_fit`.
    level : int
        0 for fine data; ``k`` for a coarse approximation after ``k`` levels, which is cropped to
        the original's extent with :func:`coarse_extent`.
    boundary, wavelet
        As given to :func:`pad_to_fit` (only needed for ``level > 0``).

    Returns
    -------
    numpy.ndarray
        A view of ``data`` without the padding.

    Examples
    --------
    >>> import numpy as np
    >>> import wavecore
    >>> image = np.random.default_rng(0).random((37, 60))
    >>> padded, pads = pad_to_fit(image, 3, axes=(0, 1))
    >>> coarse = wavecore.wavedec2(padded, level=3)[0]
    >>> padded.shape, coarse.shape, crop_padding(coarse, pads, axes=(0, 1), level=3).shape
    ((42, 66), (7, 10), (6, 9))
    """
    arr = as_array(data)
    ax = resolve_axes(axes if not isinstance(axes, int | np.integer) else [int(axes)], arr.ndim)
    if len(pads) != len(ax):
        msg = f"got {len(pads)} pads for {len(ax)} axes; give one (before, after) per axis"
        raise InvalidParameter(msg)
    bounds = resolve_boundaries(boundary, len(ax), get_wavelet(wavelet))
    index: list[slice] = [slice(None)] * arr.ndim
    for a, b, pad in zip(ax, bounds, pads, strict=True):
        before, after = (int(p) for p in pad)
        if level == 0:
            n = arr.shape[a] - before - after
            if n <= 0:
                msg = f"axis {a} has {arr.shape[a]} samples, fewer than its padding {pad}"
                raise InvalidParameter(msg)
            index[a] = slice(before, before + n)
            continue
        # The padded fine length is unknown here; recover it from the coarse length.
        rule = get_wavelet(wavelet).rule(b)
        padded = arr.shape[a]
        check_level_bound(as_int(level, "level"), rule, MAX_LENGTH, "a coarse approximation")
        for _ in range(level):
            padded = 2 * padded - rule.extra
        keep = coarse_extent(
            padded - before - after, (before, after), level, boundary=b, wavelet=wavelet
        )
        index[a] = slice(0, keep)
    return arr[tuple(index)]


def resample_curve(
    points: Any, n: int, *, closed: bool | None = None, boundary: str | None = None
) -> np.ndarray:
    """Re-sample a curve to ``n`` points spaced uniformly by arc length (the paper's section 4.5).

    Parameters
    ----------
    points : array_like, shape (m, d) or (m,)
        The curve's points in order.  With ``d >= 2`` the parameter is arc length (straight
        segments between the points).  With ``d == 1`` (and for 1-D input) the curve is a time
        series, and the parameter is the sample index: arc length along the values alone would
        fold the series onto its range and skip its turning points.
    n : int
        The number of points wanted (at least 2).
    closed : bool, keyword-only
        Whether the curve is closed: then the segment from the last point back to the first
        counts, a last point equal to the first (a written-out seam) is dropped, and the
        result has no duplicated seam point either.  Default: open.
    boundary : {"open", "closed"}, optional, keyword-only
        The same choice as ``closed``, spelled as elsewhere in the library; give either (both
        only when they agree).

    Returns
    -------
    numpy.ndarray, shape (n, d) or (n,)
        The re-sampled points, float (float32 input stays float32).  An open curve keeps both
        end points exactly; a closed curve starts at the first point.

    Raises
    ------
    InvalidParameter
        For fewer than 2 input points, ``n < 2``, or points that are not finite.

    Examples
    --------
    >>> import numpy as np
    >>> square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    >>> resample_curve(square, 8, closed=True)[:3].tolist()
    [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]
    >>> resample_curve([[0.0, 0.0], [3.0, 4.0]], 3).tolist()
    [[0.0, 0.0], [1.5, 2.0], [3.0, 4.0]]
    """
    (closed,) = closed_flags(closed, boundary, 1)
    arr = as_float_array(points)
    flat = arr.ndim == 1
    if flat:
        arr = arr[:, None]
    if arr.ndim != 2:
        msg = f"points must have shape (m, d) or (m,), not {arr.shape}"
        raise InvalidParameter(msg)
    n = as_int(n, "n", minimum=2)
    check_result_values(n * arr.shape[1], f"a curve of {n} points")
    if not np.all(np.isfinite(arr)):
        msg = "points must be finite (no NaN or infinity)"
        raise InvalidParameter(msg)
    if closed and len(arr) > 2 and np.array_equal(arr[0], arr[-1]):
        arr = arr[:-1]
    if len(arr) < 2:
        msg = f"a curve needs at least 2 points, got {len(arr)}"
        raise InvalidParameter(msg)
    nodes = np.concatenate([arr, arr[:1]]) if closed else arr
    if arr.shape[1] == 1:
        s = np.arange(len(nodes), dtype=np.float64)
    else:
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(nodes, axis=0), axis=1))])
    total = s[-1]
    if total == 0.0:
        out = np.repeat(arr[:1], n, axis=0)
        return out[:, 0] if flat else out
    # Repeated points give zero-length segments; np.interp needs increasing nodes.
    keep = np.concatenate([[True], np.diff(s) > 0])
    s, nodes = s[keep], nodes[keep]
    try:
        targets = total * np.arange(n) / n if closed else np.linspace(0.0, total, n)
        out = np.stack([np.interp(targets, s, nodes[:, j]) for j in range(nodes.shape[1])], axis=1)
    except MemoryError:  # under the values' limit, over this machine's memory
        msg = f"a curve of {n} points of {arr.shape[1]} coordinates does not fit in memory"
        raise InvalidParameter(msg) from None
    out = out.astype(arr.dtype, copy=False)
    out[0] = arr[0]
    if not closed:
        out[-1] = arr[-1]
    return out[:, 0] if flat else out


def resample_grid(
    data: Any,
    shape: Sequence[int],
    *,
    axes: Sequence[int] | int,
    boundary: str | Sequence[str] = "open",
) -> np.ndarray:
    """Re-sample a grid (an image, a surface's points) along ``axes`` to new lengths, linearly.

    The samples stay uniformly spaced over the same extent: along an open axis the first and
    last samples stay where they were; along a closed (periodic) axis sample ``i`` of ``n``
    sits at ``i / n`` of the period.  This is the grid counterpart of :func:`resample_curve`
    (the paper's section 4.5 for images and tensor-product surfaces).

    Parameters
    ----------
    data : array_like
        The grid.
    shape : sequence of int
        The new length of each axis in ``axes``.
    axes : int or sequence of int, keyword-only
        The axes to re-sample.
    boundary : str or sequence of str, keyword-only
        ``"open"`` or ``"closed"``, one for all axes or one per axis.

    Returns
    -------
    numpy.ndarray
        Float (float64, or float32 for float32 input).

    Examples
    --------
    >>> import numpy as np
    >>> resample_grid(np.array([0.0, 1.0, 2.0]), (5,), axes=0).tolist()
    [0.0, 0.5, 1.0, 1.5, 2.0]
    >>> resample_grid(np.array([0.0, 1.0, 2.0, 1.0]), (2,), axes=0, boundary="closed").tolist()
    [0.0, 2.0]
    """
    arr = as_float_array(data)
    ax = resolve_axes(axes if not isinstance(axes, int | np.integer) else [int(axes)], arr.ndim)
    lengths = [as_int(s, "length", minimum=1) for s in shape]
    if len(lengths) != len(ax):
        msg = f"got {len(lengths)} lengths for {len(ax)} axes; give one per axis"
        raise InvalidParameter(msg)
    bounds = resolve_boundaries(boundary, len(ax), get_wavelet("bspline2"))
    result = dict(enumerate(arr.shape)) | dict(zip(ax, lengths, strict=True))
    check_result_values(math.prod(result.values()), f"a grid of shape {tuple(result.values())}")
    for a, b, n_out in zip(ax, bounds, lengths, strict=True):
        n_in = arr.shape[a]
        if n_in == n_out:
            continue
        if not n_in:
            msg = f"axis {a} has no samples to re-sample"
            raise InvalidParameter(msg)
        if b == "closed":
            position = np.arange(n_out) * (n_in / n_out)
        elif n_out == 1:
            position = np.zeros(1)
        else:
            position = np.linspace(0.0, n_in - 1.0, n_out)
        low = np.floor(position).astype(np.intp)
        weight = position - low
        high = low + 1
        if b == "closed":
            low, high = low % n_in, high % n_in
        else:
            low = np.minimum(low, n_in - 1)
            high = np.minimum(high, n_in - 1)
        shape_w = [1] * arr.ndim
        shape_w[a] = n_out
        w = weight.reshape(shape_w).astype(arr.dtype)
        arr = np.take(arr, low, axis=a) * (1 - w) + np.take(arr, high, axis=a) * w
    return arr


@dataclass(frozen=True)
class GridFit:
    """How a grid was fitted to the transform's lengths, and how to undo it.

    Made by :func:`fit_grid`; used by the image and surface front ends.

    Attributes
    ----------
    method : {"pad", "resample"}
        Edge padding at the end of each axis (exact) or linear re-sampling.
    axes : tuple of int
        The fitted axes.
    boundaries : tuple of str
        One boundary per axis.
    wavelet : str
        The wavelet whose size rule was fitted.
    original : tuple of int
        The original length of each axis.
    fitted : tuple of int
        The fitted length of each axis.
    """

    method: str
    axes: tuple[int, ...]
    boundaries: tuple[str, ...]
    wavelet: str
    original: tuple[int, ...]
    fitted: tuple[int, ...]

    @property
    def pads(self) -> Pads:
        """The ``(before, after)`` padding per axis (only meaningful for ``method="pad"``)."""
        return tuple((0, f - o) for o, f in zip(self.original, self.fitted, strict=True))

    def undo(self, data: np.ndarray) -> np.ndarray:
        """Fine data of the fitted size back at the original size."""
        if self.method == "pad":
            return crop_padding(data, self.pads, axes=self.axes)
        return resample_grid(data, self.original, axes=self.axes, boundary=self.boundaries)

    def coarse_view(self, coarse: np.ndarray, level: int) -> np.ndarray:
        """A level-``level`` coarse approximation restricted to the original's extent.

        Padding is cropped away (see :func:`coarse_extent`); a re-sampled grid's coarse
        approximation already spans exactly the original's extent and is returned as it is.
        """
        if self.method == "pad" and level > 0:
            return crop_padding(
                coarse,
                self.pads,
                axes=self.axes,
                level=level,
                boundary=self.boundaries,
                wavelet=self.wavelet,
            )
        if self.method == "pad":
            return crop_padding(coarse, self.pads, axes=self.axes)
        return coarse


def minimum_length(boundary: str = "open", wavelet: str | FilterBank = "bspline2") -> int:
    """The shortest length that allows one level (8 for open ``bspline2``, else 2).

    Examples
    --------
    >>> minimum_length(), minimum_length("closed"), minimum_length(wavelet="haar")
    (8, 2, 2)
    """
    return valid_length(1, 1, boundary, wavelet)


def fit_grid(
    data: Any,
    level: int,
    *,
    axes: Sequence[int],
    boundary: str | Sequence[str] = "open",
    wavelet: str | FilterBank = "bspline2",
    method: str = "pad",
) -> tuple[np.ndarray, GridFit]:
    """Fit the lengths of ``axes`` to ``level`` levels by padding or by re-sampling.

    ``method="pad"`` pads at the end with :func:`pad_to_fit` (exact, undone by cropping);
    ``method="resample"`` re-samples linearly with :func:`resample_grid` to the nearest length
    that fits (the paper's section 4.5; not exact).  Every axis must have at least
    :func:`minimum_length` samples: a grid too small for one level is an error.

    Returns
    -------
    fitted : numpy.ndarray
        The fitted grid (float for ``"resample"``, ``data``'s dtype for ``"pad"``).
    fit : GridFit
        What was done, with :meth:`GridFit.undo` and :meth:`GridFit.coarse_view`.

    Examples
    --------
    >>> import numpy as np
    >>> fitted, fit = fit_grid(np.zeros((100, 60)), 2, axes=(0, 1), method="resample")
    >>> fitted.shape, fit.undo(fitted).shape
    ((102, 62), (100, 60))
    """
    from .curves import fitting_length  # curves imports this module

    if method not in ("pad", "resample"):
        msg = f"method must be 'pad' (exact) or 'resample' (section 4.5), not {method!r}"
        raise InvalidParameter(msg)
    arr = as_array(data)
    bank = get_wavelet(wavelet)
    ax = tuple(resolve_axes(axes, arr.ndim))
    bounds = tuple(resolve_boundaries(boundary, len(ax), bank))
    level = as_int(level, "level")
    original = tuple(arr.shape[a] for a in ax)
    for a, b, n in zip(ax, bounds, original, strict=True):
        check_level_bound(
            level,
            bank.rule(b),
            growth_limit(n),
            f"axis {a} of {n} samples (fitted, it may grow to {growth_limit(n)})",
        )
        least = minimum_length(b, bank)
        if n < least:
            sizes = "×".join(str(s) for s in original)
            msg = (
                f"a grid of {sizes} samples is too small: axis {a} has {n}, and one level of "
                f"the {b} boundary of {bank.name!r} needs at least {least} samples per axis"
            )
            raise InvalidLength(msg)
    if method == "pad":
        fitted_arr, pads = pad_to_fit(arr, level, axes=ax, boundary=bounds, wavelet=bank)
        fitted = tuple(o + p[1] for o, p in zip(original, pads, strict=True))
    else:
        fitted = tuple(
            fitting_length(n, level, b, bank) for n, b in zip(original, bounds, strict=True)
        )
        fitted_arr = resample_grid(arr, fitted, axes=ax, boundary=bounds)
    return fitted_arr, GridFit(method, ax, bounds, bank.name, original, fitted)
