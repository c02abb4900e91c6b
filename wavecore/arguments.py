"""Argument normalisation shared by every public entry point.

Two things every function that takes arrays or a boundary needs, in one place so that the entry
points agree:

- :func:`as_native` turns any array-like into an array the compiled kernels accept: native byte
  order (a big-endian ``>f8`` array from an uploaded ``.npy`` file makes numba refuse to compile),
  whatever its strides or writeability.
- :func:`closed_flags` reads the two spellings of a curve's or grid's boundary, ``closed=True`` /
  ``False`` and ``boundary="closed"`` / ``"open"``, and refuses them when they disagree.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import InvalidParameter

__all__ = ["as_array", "as_native", "closed_flags"]

_SPELLINGS = ("open", "closed")


def as_native(data: Any) -> Any:
    """``data`` as an array in native byte order; anything that is not an array passes through.

    Only arrays whose byte order is not the machine's are copied (once, by NumPy); everything
    else, lists and nested coefficient lists included, is returned unchanged, so the callers'
    own checks still see what they were given.

    Examples
    --------
    >>> import numpy as np
    >>> big = np.arange(3, dtype=">f8")
    >>> native = as_native(big)
    >>> native.dtype.isnative, native.tolist() == big.tolist()
    (True, True)
    >>> as_native([1, 2])
    [1, 2]
    """
    if isinstance(data, np.ndarray) and not data.dtype.isnative:
        return data.astype(data.dtype.newbyteorder("="))
    return data


def as_array(data: Any, dtype: Any = None, what: str = "the input") -> np.ndarray:
    """``data`` as an array (of ``dtype`` if given) in native byte order, or
    :class:`InvalidParameter` for what NumPy cannot turn into one (ragged lists; strings or
    objects where ``dtype`` is numeric), naming ``what``.  The dtype itself is the caller's
    to check.

    Examples
    --------
    >>> as_array([[1, 2], [3, 4]], np.float64).dtype
    dtype('float64')
    >>> as_array([[1, 2], [3]])
    Traceback (most recent call last):
    ...
    wavecore.errors.InvalidParameter: cannot turn the input into a numeric array: ...
    """
    try:
        arr = np.asarray(data, dtype=dtype)
    except (TypeError, ValueError, OverflowError) as exc:
        msg = f"cannot turn {what} into a numeric array: {exc}"
        raise InvalidParameter(msg[:300]) from None
    return as_native(arr)


def closed_flags(closed: Any, boundary: Any, count: int, *, name: str = "closed") -> list[bool]:
    """Per axis, whether the boundary is closed, from ``closed=`` and/or ``boundary=``.

    Parameters
    ----------
    closed : bool, sequence of bool or None
        The historical spelling: ``True`` for periodic (closed), ``False`` for open; with
        ``count > 1`` one bool per axis.  ``None`` when not given.
    boundary : str, sequence of str or None
        The same as ``"closed"`` / ``"open"`` (one for all axes, or one per axis).  ``None``
        when not given.
    count : int
        How many axes the caller has (1 for curves, 2 for grids).
    name : str
        How the caller spells ``closed`` (for the error messages).

    Returns
    -------
    list of bool
        ``count`` flags; open where neither is given.

    Raises
    ------
    InvalidParameter
        For a value of the wrong type or length, or when both are given and disagree.

    Examples
    --------
    >>> closed_flags(None, "closed", 1), closed_flags(True, None, 1), closed_flags(None, None, 2)
    ([True], [True], [False, False])
    >>> closed_flags((True, False), ["closed", "open"], 2)
    [True, False]
    """
    from_closed = None if closed is None else _flags_from_closed(closed, count, name)
    from_boundary = None if boundary is None else _flags_from_boundary(boundary, count)
    if from_closed is not None and from_boundary is not None and from_closed != from_boundary:
        msg = (
            f"{name}={closed!r} and boundary={boundary!r} disagree; give one of them "
            "(boundary='closed' means closed=True, boundary='open' means closed=False)"
        )
        raise InvalidParameter(msg)
    return from_closed or from_boundary or [False] * count


def _flags_from_closed(closed: Any, count: int, name: str) -> list[bool]:
    if count == 1 and isinstance(closed, bool | np.bool_):
        return [bool(closed)]
    if (
        count > 1
        and isinstance(closed, tuple | list)
        and len(closed) == count
        and all(isinstance(c, bool | np.bool_) for c in closed)
    ):
        return [bool(c) for c in closed]
    what = "True or False" if count == 1 else "a pair of booleans (one per axis)"
    msg = f"{name} must be {what}, not {closed!r}"
    raise InvalidParameter(msg)


def _flags_from_boundary(boundary: Any, count: int) -> list[bool]:
    names = [boundary] * count if isinstance(boundary, str) else boundary
    if (
        isinstance(names, tuple | list)
        and len(names) == count
        and all(isinstance(b, str) and b in _SPELLINGS for b in names)
    ):
        return [b == "closed" for b in names]
    each = "'open' or 'closed'"
    what = each if count == 1 else f"{each}, or {count} of them (one per axis)"
    msg = f"boundary must be {what}, not {boundary!r}"
    raise InvalidParameter(msg)
