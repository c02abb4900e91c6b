"""Many levels: ``wavedec``/``waverec`` (1-D), ``wavedec2``/``waverec2``, ``wavedecn``/``waverecn``.

Coefficient lists are ordered coarse first, as PyWavelets orders them::

    wavedec   -> [cA_L, cD_L, ..., cD_1]
    wavedec2  -> [cA_L, (cH_L, cV_L, cD_L), ..., (cH_1, cV_1, cD_1)]
    wavedecn  -> [cA_L, {"ad": ..., "da": ..., "dd": ...}, ..., {...}]

In 2-D, ``cH`` is detail along the first axis and coarse along the second, ``cV`` the other way
round, and ``cD`` detail along both — the same convention as PyWavelets.  In the n-D dictionaries,
each key has one letter per transformed axis: ``"a"`` for coarse and ``"d"`` for detail.

Size rules: one level of the open ``bspline2`` boundary takes ``m`` samples to ``(m + 2) / 2``
coarse and ``(m - 2) / 2`` details, so ``L`` levels need ``m = 2**L * k + 2`` with ``k >= 3``.
The closed boundary and Haar take ``m`` to ``m / 2`` and ``m / 2`` and need ``m = 2**L * k``
(``k >= 1``).  Reconstruction always returns exactly the decomposed shape.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .errors import InvalidCoefficients, InvalidLength, InvalidParameter
from .filters import BoundaryRule, FilterBank, get_wavelet
from .transform import (
    analysis_2d,
    analysis_step,
    as_float_array,
    fused_level_fits,
    normalize_axis,
    synthesis_2d,
    synthesis_step,
)

__all__ = [
    "default_level",
    "max_level",
    "valid_length",
    "wavedec",
    "wavedec2",
    "wavedecn",
    "waverec",
    "waverec2",
    "waverecn",
]


def _rule(wavelet: str | FilterBank, boundary: str) -> tuple[FilterBank, BoundaryRule]:
    bank = get_wavelet(wavelet)
    return bank, bank.rule(boundary)


def as_int(value: Any, name: str, minimum: int = 0) -> int:
    """``value`` as an ``int`` of at least ``minimum``, or an error that names ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        msg = f"{name} must be an integer, not {value!r}"
        raise InvalidParameter(msg)
    if value < minimum:
        msg = f"{name} must be at least {minimum}, not {value}"
        raise InvalidParameter(msg)
    return int(value)


def _level_count(rule: BoundaryRule, n: int) -> int:
    level = 0
    while n % 2 == 0 and n >= rule.min_length:
        n = rule.coarse_length(n)
        level += 1
    return level


#: No length beyond this is ever accepted: 2**40 float64 samples are 8 TiB.
MAX_LENGTH = 1 << 40
#: The most values a function whose result is sized by an argument makes (32 GiB of float64):
#: beyond it the request is an error, not an attempt to allocate.
MAX_RESULT_VALUES = 1 << 32


def check_result_values(count: int, what: str) -> None:
    """Raise :class:`InvalidParameter` if ``what`` would hold more than
    :data:`MAX_RESULT_VALUES` values."""
    if count > MAX_RESULT_VALUES:
        msg = f"{what} would hold {count} values, more than the {MAX_RESULT_VALUES} allowed"
        raise InvalidParameter(msg[:300])


#: Padding or re-sampling to fit a level may make an axis at most this long (as in the codec).
_GROWTH, _GROWTH_ALLOWANCE = 2, 64
_FIT_ANY_SIZE = (
    "wavecore.decompose_image, decompose_surface and decompose_curve fit any size; "
    "wavecore.pad_to_fit pads exactly (undone by crop_padding), and resample_curve to "
    "wavecore.fitting_length re-samples; wavecore.valid_length gives the next length that fits"
)


def smallest_fitting_length(rule: BoundaryRule, level: int) -> int:
    """The shortest length that ``level`` levels accept (``level`` at most 64)."""
    if level == 0:
        return 1
    return (1 << level) * rule.smallest_k(level) + rule.extra


def growth_limit(n: int) -> int:
    """The longest an axis of ``n`` samples may become when it is padded or re-sampled to fit."""
    return _GROWTH * n + _GROWTH_ALLOWANCE


def deepest_level(rule: BoundaryRule, limit: int) -> int:
    """The most levels whose shortest fitting length is at most ``limit``."""
    level = 0
    while level < 64 and smallest_fitting_length(rule, level + 1) <= limit:
        level += 1
    return level


def check_level_bound(level: int, rule: BoundaryRule, limit: int, what: str) -> None:
    """Refuse, before any work, a ``level`` whose shortest fitting length exceeds ``limit``.

    ``what`` says what the limit is for the message.  Cheap whatever ``level`` is: the bound
    is compared before ``2**level`` is ever formed.
    """
    if level <= 64 and smallest_fitting_length(rule, level) <= limit:
        return
    deepest = deepest_level(rule, limit)
    msg = f"level {level} is too deep for {what}; the largest accepted level is {deepest}"
    raise InvalidParameter(msg)


#: The default depth of images and surfaces (``most`` of :func:`default_level`), and of curves.
#: Measured with the codec on scikit-image's 512 × 512 camera and astronaut: a sixth level made
#: the bundles at 40 dB 0.05-0.20 % larger, and at 0.25-1 bpp changed PSNR by +0.02 to -0.15 dB
#: (bspline2 and cdf97), so deeper does not pay; JPEG 2000's usual depth is 5 too.
DEFAULT_MOST_LEVELS = 5
DEFAULT_MOST_CURVE_LEVELS = 8
#: The default level keeps about this many coarse samples per axis, or more.
DEFAULT_COARSEST = 4


def default_level(
    sizes: Sequence[int], most: int = DEFAULT_MOST_LEVELS, coarsest: int = DEFAULT_COARSEST
) -> int:
    """The number of levels used when none is given: one rule for the front ends and the codec.

    The most levels, up to ``most``, that keep at least ``coarsest`` samples per axis in the
    coarsest band (``min(sizes) >= coarsest * 2**level``), and at least one.

    Parameters
    ----------
    sizes : sequence of int
        The lengths of the transformed axes.
    most : int
        The deepest default (5 for images and surfaces, 8 for curves).
    coarsest : int
        The fewest coarse samples per axis.

    Examples
    --------
    >>> default_level([512, 512]), default_level([40, 30]), default_level([1000], most=8)
    (5, 2, 7)
    """
    if not len(sizes):
        msg = "sizes must name at least one axis"
        raise InvalidParameter(msg)
    smallest = min(int(n) for n in sizes)
    coarsest = int(coarsest)
    if coarsest < 1:  # (with 0 the loop below would run to ``most``, whatever it is)
        msg = f"coarsest must be at least 1, not {coarsest}"
        raise InvalidParameter(msg)
    level = 1
    while level < most and smallest >= coarsest << (level + 1):
        level += 1
    return level


def max_level(n: int, boundary: str = "open", wavelet: str | FilterBank = "bspline2") -> int:
    """How many levels a length ``n`` allows, exactly (no padding, no re-sampling).

    Parameters
    ----------
    n : int
        The fine length.
    boundary : {"open", "closed"}
        The boundary; open ``bspline2`` needs ``n = 2**L * k + 2`` with ``k >= 3``.
    wavelet : str, optional
        The wavelet (Haar follows the closed rule at both boundaries).

    Returns
    -------
    int
        The largest ``L`` such that ``n`` fits ``L`` levels (0 when not even one fits).

    Examples
    --------
    >>> max_level(514), max_level(512, "closed"), max_level(513)
    (7, 9, 0)
    """
    _, rule = _rule(wavelet, boundary)
    return _level_count(rule, as_int(n, "length"))


def valid_length(
    n: int, level: int, boundary: str = "open", wavelet: str | FilterBank = "bspline2"
) -> int:
    """The smallest length ``>= n`` that fits ``level`` levels.

    That is ``2**level * k + 2`` with ``k >= 3`` for the open boundary and ``2**level * k``
    (``k >= 1``) for the closed one and for Haar.  A ``level`` whose fitting length would be
    more than ``2 * n + 64`` is refused (:class:`~wavecore.InvalidParameter`): it asks for more
    levels than ``n`` samples can hold.

    Examples
    --------
    >>> valid_length(500, 5), valid_length(500, 5, "closed"), valid_length(3, 2)
    (514, 512, 14)
    """
    _, rule = _rule(wavelet, boundary)
    n = as_int(n, "length")
    level = as_int(level, "level")
    check_level_bound(
        level,
        rule,
        growth_limit(n),
        f"length {n} (fitted, it may grow to at most {growth_limit(n)})",
    )
    if level == 0:
        return n
    step = 1 << level
    k = max(rule.smallest_k(level), -(-(n - rule.extra) // step))
    return step * k + rule.extra


def _nearest_lengths(rule: BoundaryRule, n: int, level: int) -> tuple[int | None, int]:
    step = 1 << level
    k_min = rule.smallest_k(level)
    above = step * max(k_min, -(-(n - rule.extra) // step)) + rule.extra
    k_below = (n - rule.extra) // step
    below = (
        step * k_below + rule.extra
        if k_below >= k_min and step * k_below + rule.extra < n
        else None
    )
    return below, above


def _check_length(bank: FilterBank, boundary: str, n: int, level: int, axis: int) -> None:
    rule = bank.rule(boundary)
    if rule.fits(n, level):
        return
    as_is = _level_count(rule, n)
    deepest = deepest_level(rule, growth_limit(n))
    if level > deepest:
        # No padding that keeps the data's size in proportion fits: do not even name lengths.
        msg = (
            f"level {level} is too deep for length {n} (axis {axis}): it allows {as_is} "
            f"level(s) as it is, and at most {deepest} once padded or re-sampled to fit "
            f"({_FIT_ANY_SIZE})"
        )
        raise InvalidLength(msg)
    below, above = _nearest_lengths(rule, n, level)
    nearest = f"{below} and {above}" if below is not None else f"{above}"
    form = "2**L*k + 2 with k >= 3" if rule.extra else "2**L*k"
    msg = (
        f"length {n} (axis {axis}) does not fit {level} level(s) of the {boundary} boundary "
        f"of {bank.name!r}, which needs {form}; the nearest lengths that fit are {nearest} "
        f"({_FIT_ANY_SIZE})"
    )
    raise InvalidLength(msg)


def resolve_level(
    level: Any,
    bank: FilterBank,
    boundaries: Sequence[str],
    sizes: Sequence[int],
    axes: Sequence[int],
) -> int:
    """The level to use: the deepest that every axis fits when ``None``, else ``level``
    checked against every axis (the error names the nearest lengths that fit)."""
    if level is None:
        level = min(_level_count(bank.rule(b), n) for b, n in zip(boundaries, sizes, strict=True))
        if level == 0:
            for b, n, ax in zip(boundaries, sizes, axes, strict=True):
                _check_length(bank, b, n, 1, ax)
        return level
    level = as_int(level, "level")
    for b, n, ax in zip(boundaries, sizes, axes, strict=True):
        _check_length(bank, b, n, level, ax)
    return level


def resolve_boundaries(boundary: str | Sequence[str], count: int, bank: FilterBank) -> list[str]:
    """One boundary per axis (``count``), each one ``bank`` has a rule for."""
    if isinstance(boundary, str):
        result = [boundary] * count
    elif not isinstance(boundary, Sequence) or isinstance(boundary, bytes):
        # PyWavelets' order is wavedec(data, wavelet, mode, level): a level passed third lands
        # here, in ``boundary``.
        hint = (
            f"; to ask for {boundary} levels write level={boundary} (the third argument here is "
            "the boundary, not PyWavelets' mode or level)"
            if isinstance(boundary, int | np.integer) and not isinstance(boundary, bool)
            else ""
        )
        msg = (
            f"boundary= must be 'open' or 'closed', or one of them per axis, not {boundary!r}{hint}"
        )
        raise InvalidParameter(msg)
    else:
        result = list(boundary)
        if len(result) != count:
            msg = f"got {len(result)} boundaries for {count} axes; give one, or one per axis"
            raise InvalidParameter(msg)
    for b in result:
        bank.rule(b)
    return result


def resolve_axes(axes: Sequence[int] | None, ndim: int) -> list[int]:
    """``axes`` (all when ``None``, one int accepted) as distinct non-negative axes of ``ndim``."""
    if axes is None:
        return list(range(ndim))
    if isinstance(axes, int | np.integer):
        axes = [int(axes)]
    if isinstance(axes, str | bytes) or not isinstance(axes, Iterable):
        msg = f"axes must be None, an axis or a sequence of axes, not {axes!r}"
        raise InvalidParameter(msg[:200])
    result = [normalize_axis(a, ndim) for a in axes]
    if len(set(result)) != len(result):
        msg = f"axes {tuple(axes)} repeat an axis"
        raise InvalidParameter(msg)
    if not result:
        msg = "axes must name at least one axis"
        raise InvalidParameter(msg)
    return result


def _axis_pair(axes: Any, name: str) -> tuple[Any, ...]:
    """``axes`` as a tuple of two, or :class:`InvalidParameter` naming ``name``."""
    if isinstance(axes, str | bytes) or not isinstance(axes, Iterable):
        msg = f"{name} needs exactly two axes, such as (0, 1), not {axes!r}"
        raise InvalidParameter(msg[:200])
    pair = tuple(axes)
    if len(pair) != 2:
        msg = f"{name} needs exactly two axes, not {pair}"
        raise InvalidParameter(msg[:200])
    return pair


def wavedec(
    data: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    level: int | None = None,
    axis: int = 0,
) -> list[np.ndarray]:
    """Multi-level decomposition along one axis.

    Parameters
    ----------
    data : array_like
        Samples along ``axis``; other axes are carried along (curve points ``(m, d)``).
    wavelet : str
        ``"bspline2"`` (alias ``"chaikin"``), ``"haar"`` or ``"cdf97"`` (alias ``"jpeg2000"``);
        see :func:`wavecore.wavelet_names`.
    boundary : {"open", "closed"}
        Endpoint-interpolating or periodic.
    level : int, optional
        Number of levels; ``None`` means as many as the length allows.
    axis : int
        The axis to decompose.

    Returns
    -------
    list of numpy.ndarray
        ``[cA_L, cD_L, ..., cD_1]``, coarse first.

    Raises
    ------
    InvalidLength
        If the length does not fit ``level`` levels; the message gives the nearest that do.

    Examples
    --------
    >>> import numpy as np
    >>> coeffs = wavedec(np.linspace(0, 1, 18), level=2)
    >>> [c.shape[0] for c in coeffs]
    [6, 4, 8]
    """
    bank = get_wavelet(wavelet)
    arr = as_float_array(data)
    if arr.ndim == 0:
        msg = "cannot decompose a scalar; pass an array with at least one dimension"
        raise InvalidParameter(msg)
    axis = normalize_axis(axis, arr.ndim)
    (b,) = resolve_boundaries(boundary, 1, bank)
    level = resolve_level(level, bank, [b], [arr.shape[axis]], [axis])
    details: list[np.ndarray] = []
    coarse = arr
    for _ in range(level):
        coarse, detail = analysis_step(coarse, bank, b, axis)
        details.append(detail)
    if level == 0:
        coarse = arr.copy()
    return [coarse, *reversed(details)]


def waverec(
    coeffs: Sequence[Any],
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    axis: int = 0,
) -> np.ndarray:
    """Multi-level reconstruction along one axis, the inverse of :func:`wavedec`.

    Parameters
    ----------
    coeffs : sequence of array_like
        ``[cA_L, cD_L, ..., cD_1]``.  A detail may be ``None``, meaning zeros.
    wavelet, boundary, axis
        As given to :func:`wavedec`.

    Returns
    -------
    numpy.ndarray
        The fine data, of exactly the decomposed length.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(1).standard_normal(34)
    >>> bool(np.allclose(waverec(wavedec(x)), x))
    True
    """
    bank = get_wavelet(wavelet)
    (b,) = resolve_boundaries(boundary, 1, bank)
    if isinstance(coeffs, np.ndarray) or not len(coeffs):
        msg = "coeffs must be a non-empty list [cA_L, cD_L, ..., cD_1]"
        raise InvalidCoefficients(msg)
    coarse = as_float_array(coeffs[0])
    if coarse.ndim == 0:
        msg = "cA must have at least one dimension"
        raise InvalidCoefficients(msg)
    axis = normalize_axis(axis, coarse.ndim)
    for detail in coeffs[1:]:
        coarse = synthesis_step(coarse, detail, bank, b, axis)
    return coarse if len(coeffs) > 1 else coarse.copy()


def _keys(count: int) -> list[str]:
    return ["".join(k) for k in itertools.product("ad", repeat=count)][1:]


def wavedecn(
    data: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str | Sequence[str] = "open",
    level: int | None = None,
    axes: Sequence[int] | None = None,
) -> list[Any]:
    """Multi-level tensor-product decomposition over several axes.

    Parameters
    ----------
    data : array_like
        Any shape; the axes not in ``axes`` are carried along (a grid of 3-D points
        ``(U, V, 3)`` with ``axes=(0, 1)``).
    wavelet : str
        As in :func:`wavedec`.
    boundary : str or sequence of str
        One boundary for every axis, or one per axis in ``axes`` (a surface closed in u and
        open in v: ``("closed", "open")``).
    level : int, optional
        Levels, the same on every axis; ``None`` means as many as every axis allows.
    axes : sequence of int, optional
        The axes to transform; all of them by default.

    Returns
    -------
    list
        ``[cA_L, {key: detail, ...}_L, ..., {...}_1]``: each key has one letter per axis in
        ``axes``, ``"a"`` for coarse and ``"d"`` for detail.

    Examples
    --------
    >>> import numpy as np
    >>> coeffs = wavedecn(np.zeros((10, 16, 3)), boundary=("open", "closed"), level=1, axes=(0, 1))
    >>> coeffs[0].shape, sorted(coeffs[1])
    ((6, 8, 3), ['ad', 'da', 'dd'])
    """
    bank = get_wavelet(wavelet)
    arr = as_float_array(data)
    if arr.ndim == 0:
        msg = "cannot decompose a scalar; pass an array with at least one dimension"
        raise InvalidParameter(msg)
    ax = resolve_axes(axes, arr.ndim)
    bounds = resolve_boundaries(boundary, len(ax), bank)
    level = resolve_level(level, bank, bounds, [arr.shape[a] for a in ax], ax)
    coarse = arr
    details: list[dict[str, np.ndarray]] = []
    for _ in range(level):
        if len(ax) == 2 and fused_level_fits(coarse.shape, ax, coarse.dtype):
            fused = analysis_2d(coarse, bank, (bounds[0], bounds[1]), ax[0])
            if fused is not None:
                coarse, ad, da, dd = fused
                details.append({"ad": ad, "da": da, "dd": dd})
                continue
        bands: dict[str, np.ndarray] = {"": coarse}
        for a, b in zip(ax, bounds, strict=True):
            split: dict[str, np.ndarray] = {}
            for key, band in bands.items():
                split[key + "a"], split[key + "d"] = analysis_step(band, bank, b, a)
            bands = split
        coarse = bands.pop("a" * len(ax))
        details.append(bands)
    if level == 0:
        coarse = arr.copy()
    return [coarse, *reversed(details)]


def waverecn(
    coeffs: Sequence[Any],
    wavelet: str | FilterBank = "bspline2",
    boundary: str | Sequence[str] = "open",
    axes: Sequence[int] | None = None,
) -> np.ndarray:
    """Multi-level tensor-product reconstruction, the inverse of :func:`wavedecn`.

    Parameters
    ----------
    coeffs : sequence
        ``[cA_L, {key: detail}, ...]`` as :func:`wavedecn` returns it.  A missing key or a
        ``None`` value means zeros.
    wavelet, boundary, axes
        As given to :func:`wavedecn`; ``axes=None`` means all axes of ``cA``.

    Returns
    -------
    numpy.ndarray
        The reconstruction, of exactly the decomposed shape.
    """
    bank = get_wavelet(wavelet)
    if isinstance(coeffs, np.ndarray) or not len(coeffs):
        msg = "coeffs must be a non-empty list [cA_L, {...}_L, ..., {...}_1]"
        raise InvalidCoefficients(msg)
    coarse = as_float_array(coeffs[0])
    if coarse.ndim == 0:
        msg = "cA must have at least one dimension"
        raise InvalidCoefficients(msg)
    ax = resolve_axes(axes, coarse.ndim)
    bounds = resolve_boundaries(boundary, len(ax), bank)
    keys = set(_keys(len(ax)))
    for level_details in coeffs[1:]:
        if not isinstance(level_details, dict):
            msg = f"each level's details must be a dict with keys {sorted(keys)}"
            raise InvalidCoefficients(msg)
        unknown = set(level_details) - keys
        if unknown:
            msg = f"unknown detail keys {sorted(unknown)}; expected {sorted(keys)}"
            raise InvalidCoefficients(msg)
        if len(ax) == 2 and fused_level_fits(coarse.shape, ax, coarse.dtype):
            fine = synthesis_2d(
                (coarse, level_details.get("ad"), level_details.get("da"), level_details.get("dd")),
                bank,
                (bounds[0], bounds[1]),
                ax[0],
            )
            if fine is not None:
                coarse = fine
                continue
        bands: dict[str, Any] = {"a" * len(ax): coarse, **level_details}
        # Undo the axes in reverse order: merge the last letter of every key first.
        for depth in range(len(ax), 0, -1):
            a, b = ax[depth - 1], bounds[depth - 1]
            merged: dict[str, np.ndarray] = {}
            for prefix in {k[: depth - 1] for k in _keys(depth) + ["a" * depth]}:
                low = bands.get(prefix + "a")
                high = bands.get(prefix + "d")
                if low is None and high is None:
                    continue  # both halves are zero, so the merged band is zero too
                if low is None:
                    low = _zeros_like_low(a, bank, b, high, coarse)
                merged[prefix] = synthesis_step(low, high, bank, b, a)
            bands = merged
        coarse = bands[""]
    return coarse if len(coeffs) > 1 else coarse.copy()


def _zeros_like_low(
    axis: int, bank: FilterBank, boundary: str, high: Any, coarse: np.ndarray
) -> np.ndarray:
    """Zeros in place of a missing coarse-side band, shaped from its detail-side sibling."""
    rule = bank.rule(boundary)
    high = as_float_array(high)
    shape = list(high.shape)
    shape[axis] = high.shape[axis] + rule.extra
    return np.zeros(shape, dtype=np.result_type(high.dtype, coarse.dtype))


def wavedec2(
    data: Any,
    wavelet: str | FilterBank = "bspline2",
    boundary: str | Sequence[str] = "open",
    level: int | None = None,
    axes: Sequence[int] = (0, 1),
) -> list[Any]:
    """Multi-level 2-D decomposition (images; grids of points with ``axes=(0, 1)``).

    Parameters
    ----------
    data : array_like
        At least two dimensions; other axes (colour channels, point coordinates) are carried
        along.
    wavelet : str
        As in :func:`wavedec`.
    boundary : str or pair of str
        One boundary, or one per axis.
    level : int, optional
        Levels; ``None`` means as many as both axes allow.
    axes : pair of int
        The two axes to transform.

    Returns
    -------
    list
        ``[cA_L, (cH_L, cV_L, cD_L), ..., (cH_1, cV_1, cD_1)]``.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.random.default_rng(0).random((34, 18))
    >>> coeffs = wavedec2(image, level=2)
    >>> coeffs[0].shape, [band.shape for band in coeffs[1]]
    ((10, 6), [(8, 6), (10, 4), (8, 4)])
    >>> bool(np.allclose(waverec2(coeffs), image))
    True
    """
    axes = _axis_pair(axes, "wavedec2")
    coeffs = wavedecn(data, wavelet, boundary, level, axes)
    return [coeffs[0], *((d["da"], d["ad"], d["dd"]) for d in coeffs[1:])]


def waverec2(
    coeffs: Sequence[Any],
    wavelet: str | FilterBank = "bspline2",
    boundary: str | Sequence[str] = "open",
    axes: Sequence[int] = (0, 1),
) -> np.ndarray:
    """Multi-level 2-D reconstruction, the inverse of :func:`wavedec2`.

    A detail band may be ``None``, meaning zeros.
    """
    axes = _axis_pair(axes, "waverec2")
    if isinstance(coeffs, np.ndarray) or not len(coeffs):
        msg = "coeffs must be a non-empty list [cA_L, (cH_L, cV_L, cD_L), ...]"
        raise InvalidCoefficients(msg)
    levels = []
    for bands in coeffs[1:]:
        if not isinstance(bands, tuple | list) or len(bands) != 3:
            msg = "each level's details must be a tuple (cH, cV, cD)"
            raise InvalidCoefficients(msg)
        levels.append(
            {k: v for k, v in zip(("da", "ad", "dd"), bands, strict=True) if v is not None}
        )
    return waverecn([coeffs[0], *levels], wavelet, boundary, axes)


# The private spellings these helpers had before they were shared, for code written against
# them on other branches; new code imports the public names (tests/test_private_imports.py).
_as_int, _axes, _boundaries, _resolve_level = (
    as_int,
    resolve_axes,
    resolve_boundaries,
    resolve_level,
)
