"""The coefficient layout: the one module that knows how a decomposition is listed.

A multilevel decomposition is a list ordered coarse first, as PyWavelets lists it:

* ``wavedec`` (one transformed axis): ``[cA, cD_L, ..., cD_1]``;
* ``wavedec2`` (two axes): ``[cA, (cH_L, cV_L, cD_L), ..., (cH_1, cV_1, cD_1)]``, where ``cH`` is
  the detail along the first axis (key ``"da"``), ``cV`` along the second (``"ad"``) and ``cD``
  along both (``"dd"``);
* ``wavedecn`` (any number of axes): ``[cA, {key: band}, ...]`` with one letter per axis.

The stages see it in three forms, all made here:

* :func:`as_levels` / :func:`from_levels`: ``[[cA], [bands of level L], ..., [bands of level
  1]]``, a list of bands per entry (the quantizer and the entropy coder work band by band);
* :func:`as_keyed` / :func:`from_keyed`: each level as a dict keyed by ``"da"``-style names
  (thresholding ranks bands of any dimension alike);
* :func:`band_shapes`: the shapes of every band, in the layout, computed from the fine shape
  without allocating anything (what a decoder expects before it reads a byte); a prefix of it,
  ``[cA, level L, ..., level k+1]``, is what a coarse decode reads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .arguments import as_native
from .errors import InvalidCoefficients

__all__ = [
    "KEYS_2D",
    "NAMES_2D",
    "as_keyed",
    "as_levels",
    "band_names",
    "band_shapes",
    "from_keyed",
    "from_levels",
    "is_band_group",
]

#: The ``wavedecn`` keys of ``wavedec2``'s ``(cH, cV, cD)``, in tuple order.
KEYS_2D = ("da", "ad", "dd")
#: The names of ``wavedec2``'s detail bands, in tuple order.
NAMES_2D = ("cH", "cV", "cD")


def is_band_group(entry: Any) -> bool:
    """Whether a layout entry is a group of bands (a ``wavedec2`` tuple), not a single band.

    Shapes are tuples too, so a group of shapes is a non-empty tuple or list of tuples or lists.
    """
    if isinstance(entry, np.ndarray) or not isinstance(entry, tuple | list):
        return False
    return bool(entry) and all(isinstance(e, tuple | list | np.ndarray) for e in entry)


def as_levels(coeffs: Sequence[Any], what: str = "coeffs") -> list[list[np.ndarray]]:
    """A ``wavedec``/``wavedec2`` list as ``[[cA], [bands of level L], ..., [bands of level 1]]``.

    The bands are ``numpy.asarray`` views (no copy, no change of dtype).

    Raises
    ------
    InvalidCoefficients
        If ``coeffs`` is an array or empty.

    Examples
    --------
    >>> import numpy as np
    >>> a, d = np.zeros((2, 2)), np.ones((2, 2))
    >>> [len(bands) for bands in as_levels([a, (d, d, d), (d, d, d)])]
    [1, 3, 3]
    """
    if isinstance(coeffs, np.ndarray) or not len(coeffs):
        msg = f"{what} must be a non-empty list [cA, details of level L, ..., details of level 1]"
        raise InvalidCoefficients(msg)
    levels: list[list[np.ndarray]] = [[np.asarray(coeffs[0])]]
    for entry in coeffs[1:]:
        if isinstance(entry, tuple | list):
            levels.append([np.asarray(band) for band in entry])
        else:
            levels.append([np.asarray(entry)])
    return levels


def from_levels(template: Sequence[Any], levels: Sequence[Sequence[Any]]) -> list[Any]:
    """The inverse of :func:`as_levels`: bands back into ``template``'s layout.

    ``levels`` may be shorter than ``template`` (a prefix of the layout).
    """
    out: list[Any] = [levels[0][0]]
    for entry, bands in zip(template[1:], levels[1:], strict=False):
        out.append(tuple(bands) if isinstance(entry, tuple | list) else bands[0])
    return out


def band_shapes(
    shape: Sequence[int],
    level: int,
    axes: Sequence[int],
    split: Callable[[int, int], tuple[int, int]],
) -> list[Any]:
    """Every band's shape, in ``wavedec`` (one axis) or ``wavedec2`` (two axes) layout.

    Parameters
    ----------
    shape : sequence of int
        The fine data's shape (trailing axes, colour channels or coordinates, are carried).
    level : int
        Levels of the decomposition.
    axes : sequence of int
        The one or two transformed axes.
    split : callable
        ``split(i, n)`` -> ``(coarse length, detail length)`` of one step along ``axes[i]``
        from ``n`` samples: the transform's size rule.

    Examples
    --------
    >>> halves = lambda i, n: ((n + 1) // 2, n // 2)
    >>> band_shapes((5, 8), 2, (0, 1), halves)
    [(2, 2), ((1, 2), (2, 2), (1, 2)), ((2, 4), (3, 4), (2, 4))]
    >>> band_shapes((9, 2), 2, (0,), halves)
    [(3, 2), (2, 2), (4, 2)]
    """
    current = list(shape)
    details: list[Any] = []
    for _ in range(level):
        coarse, fine = list(current), list(current)
        for i, a in enumerate(axes):
            coarse[a], fine[a] = split(i, current[a])
        if len(axes) == 1:
            details.append(tuple(fine))
        else:
            (a0, a1) = axes
            cH, cV = list(coarse), list(coarse)
            cH[a0], cV[a1] = fine[a0], fine[a1]
            details.append((tuple(cH), tuple(cV), tuple(fine)))
        current = coarse
    return [tuple(current), *reversed(details)]


def band_names(index: int, axes_count: int) -> list[str]:
    """The names of the bands of layout entry ``index``: ``cA``, ``cD`` or ``cH, cV, cD``."""
    if index == 0:
        return ["cA"]
    return ["cD"] if axes_count == 1 else list(NAMES_2D)


def _keyed_band(value: Any, name: str) -> np.ndarray:
    if value is None:
        msg = f"detail band {name!r} is None; remove_smallest needs every band as an array"
        raise InvalidCoefficients(msg)
    return np.asarray(as_native(np.asarray(value)))


def as_keyed(coeffs: Any) -> tuple[str, np.ndarray, list[dict[str, np.ndarray]]]:
    """Any of the three layouts as ``(kind, cA, [{key: band}, ...])``, coarse level first.

    ``kind`` is ``"wavedec"`` (key ``"d"``), ``"wavedec2"`` (keys :data:`KEYS_2D`) or
    ``"wavedecn"``; bands come in native byte order.

    Raises
    ------
    InvalidCoefficients
        If the list is not one of the three layouts, or its bands' dimensions disagree.

    Examples
    --------
    >>> import numpy as np
    >>> kind, cA, levels = as_keyed([np.zeros((2, 2)), (np.ones((2, 2)),) * 3])
    >>> kind, list(levels[0])
    ('wavedec2', ['da', 'ad', 'dd'])
    """
    if isinstance(coeffs, np.ndarray | dict) or not isinstance(coeffs, Sequence) or not coeffs:
        msg = "coeffs must be a non-empty list as wavedec, wavedec2 or wavedecn returns it"
        raise InvalidCoefficients(msg)
    try:
        coarse = np.asarray(as_native(np.asarray(coeffs[0])))
    except ValueError:  # a tuple of bands of several shapes where cA belongs
        msg = f"cA must be an array, not a {type(coeffs[0]).__name__} of bands"
        raise InvalidCoefficients(msg) from None
    if coarse.ndim == 0:
        msg = "cA must have at least one dimension"
        raise InvalidCoefficients(msg)
    details = list(coeffs[1:])
    if not details:
        return "wavedec", coarse, []
    first = details[0]
    levels: list[dict[str, np.ndarray]] = []
    if isinstance(first, dict):
        kind = "wavedecn"
        for d in details:
            if not isinstance(d, dict) or not d:
                msg = "every level of a wavedecn list must be a non-empty dict of detail bands"
                raise InvalidCoefficients(msg)
            levels.append({k: _keyed_band(v, k) for k, v in d.items()})
    elif isinstance(first, tuple | list):
        kind = "wavedec2"
        for d in details:
            if not isinstance(d, tuple | list) or len(d) != 3:
                msg = "every level of a wavedec2 list must be a tuple (cH, cV, cD)"
                raise InvalidCoefficients(msg)
            levels.append({k: _keyed_band(v, k) for k, v in zip(KEYS_2D, d, strict=True)})
    else:
        kind = "wavedec"
        levels = [{"d": _keyed_band(d, "cD")} for d in details]
    lengths = {len(k) for bands in levels for k in bands}
    if len(lengths) != 1:
        msg = f"detail keys of different lengths {sorted(lengths)}; expected one per axis"
        raise InvalidCoefficients(msg)
    for bands in levels:
        for key, band in bands.items():
            if band.ndim != coarse.ndim:
                msg = (
                    f"detail band {key!r} has {band.ndim} dimensions but cA has {coarse.ndim}; "
                    "they must match"
                )
                raise InvalidCoefficients(msg)
    return kind, coarse, levels


def from_keyed(kind: str, coarse: np.ndarray, levels: list[dict[str, np.ndarray]]) -> list[Any]:
    """The inverse of :func:`as_keyed`: the bands back in ``kind``'s layout."""
    if kind == "wavedec":
        return [coarse, *(bands["d"] for bands in levels)]
    if kind == "wavedec2":
        return [coarse, *(tuple(bands[k] for k in KEYS_2D) for bands in levels)]
    return [coarse, *levels]
