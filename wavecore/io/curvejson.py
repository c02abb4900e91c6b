"""wavecore's curve JSON: ``{"points": [[x, y], ...], "closed": false}`` (one curve, the body of
``POST /v1/curves/encode``) or ``{"curves": [{"points": ..., "closed": ...}, ...]}``."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..errors import InvalidParameter
from .common import CurveData, as_text, finite_array

__all__ = ["read_curve_json", "write_curve_json"]


def _closed(value: Any, where: str) -> bool:
    if value is None:
        return False
    if not isinstance(value, bool):
        msg = f"{where}: 'closed' must be true or false, not {value!r}"
        raise InvalidParameter(msg)
    return value


def read_curve_json(data: bytes | str) -> CurveData:
    """Read one curve (``points``) or many (``curves``) from wavecore's curve JSON."""
    try:
        doc = json.loads(as_text(data, "curve JSON"))
    except json.JSONDecodeError as exc:
        msg = f"curve JSON is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
        raise InvalidParameter(msg) from None
    except ValueError as exc:  # valid JSON Python refuses: an integer of over 4,300 digits
        msg = f"curve JSON cannot be read: {str(exc).split(';')[0]}"[:300]
        raise InvalidParameter(msg) from None
    except RecursionError:
        msg = "curve JSON is nested too deeply"
        raise InvalidParameter(msg) from None
    if isinstance(doc, dict) and "curves" in doc and isinstance(doc["curves"], list):
        curves, closed = [], []
        for i, entry in enumerate(doc["curves"]):
            where = f"curves[{i}]"
            if isinstance(entry, dict):
                curves.append(finite_array(entry.get("points"), f"{where}.points", min_points=1))
                closed.append(_closed(entry.get("closed"), where))
            else:
                curves.append(finite_array(entry, where, min_points=1))
                closed.append(_closed(doc.get("closed"), "curve JSON"))
        return CurveData(curves, closed, {"format": "json"})
    if isinstance(doc, dict) and "points" in doc:
        points = finite_array(doc["points"], "points", min_points=1)
        return CurveData([points], [_closed(doc.get("closed"), "curve JSON")], {"format": "json"})
    msg = 'curve JSON must be {"points": [[x, y], ...]} or {"curves": [{"points": ...}, ...]}'
    raise InvalidParameter(msg)


def write_curve_json(data: CurveData) -> bytes:
    """``{"kind": "curves", "curves": [{"points": ..., "closed": ...}], "tolerance": t}``."""
    out = {
        "kind": "curves",
        "curves": [
            {"points": np.asarray(c, dtype=np.float64).tolist(), "closed": bool(f)}
            for c, f in zip(data.curves, data.closed, strict=True)
        ],
        "tolerance": data.tolerance,
    }
    return json.dumps(out, separators=(",", ":"), allow_nan=False).encode()
