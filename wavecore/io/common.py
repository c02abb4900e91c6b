"""What the readers give and the writers take."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InvalidParameter

__all__ = ["CurveData", "as_text", "finite_array"]


@dataclass
class CurveData:
    """Curves with their flags and the file's structure.

    Attributes
    ----------
    curves : list of numpy.ndarray
        ``(n_i, d_i)`` points.
    closed : list of bool
        One flag per curve (a closed curve may repeat its first point at the end).
    metadata : dict
        ``{"format": ..., ...}``: how to write the file back (see each reader).
    tolerance : float or None
        For sampled formats (SVG), the sampling's tolerance.
    """

    curves: list[np.ndarray]
    closed: list[bool]
    metadata: dict[str, Any] = field(default_factory=dict)
    tolerance: float | None = None


def as_text(data: bytes | str, what: str) -> str:
    if isinstance(data, str):
        return data
    if not isinstance(data, bytes | bytearray | memoryview):
        msg = f"{what} must be bytes or text, not {type(data).__name__}"
        raise InvalidParameter(msg)
    try:
        return bytes(data).decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        msg = f"{what} is not UTF-8 text (byte {exc.start})"
        raise InvalidParameter(msg) from exc


def finite_array(values: Any, where: str, *, min_points: int = 1) -> np.ndarray:
    """``values`` as an ``(n, d)`` float array of finite numbers; errors name ``where``."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (ValueError, TypeError):
        msg = f"{where}: the positions must be lists of numbers of one length"
        raise InvalidParameter(msg) from None
    if arr.ndim != 2 or arr.shape[1] < 1:
        msg = f"{where}: expected a list of positions (lists of numbers), got shape {arr.shape}"
        raise InvalidParameter(msg)
    if len(arr) < min_points:
        msg = f"{where}: needs at least {min_points} positions, got {len(arr)}"
        raise InvalidParameter(msg)
    if not np.all(np.isfinite(arr)):
        msg = f"{where}: every coordinate must be a finite number"
        raise InvalidParameter(msg)
    return arr
