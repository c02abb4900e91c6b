"""Curve files people have: GeoJSON, SVG paths and wavecore's curve JSON, to and from bundles.

:func:`encode_file` reads a file's bytes into curves and codes them with
:func:`wavecore.encode_curves`, keeping the file's structure (GeoJSON features, properties,
geometry types; SVG elements and their paint) in the bundle's metadata; :func:`decode_file`
writes the decoded curves back as the same format or another.

>>> import json
>>> doc = {"type": "LineString", "coordinates": [[0, 0], [1, 0.5], [2, 0], [3, 1]]}
>>> bundle = encode_file(json.dumps(doc).encode(), "geojson", tolerance=0.01)
>>> json.loads(decode_file(bundle))["type"]
'LineString'
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..curvesets import CurveSet, decode_curves, encode_curves
from ..errors import BundleError, InvalidParameter
from .common import CurveData
from .curvejson import read_curve_json, write_curve_json
from .geojson import read_geojson, write_geojson
from .svg import read_svg, write_svg

__all__ = [
    "FORMATS",
    "MEDIA_TYPES",
    "CurveData",
    "curve_set_file",
    "decode_file",
    "encode_file",
    "format_from_suffix",
    "read_curves",
    "write_curves",
]

FORMATS = ("geojson", "svg", "json")
MEDIA_TYPES = {
    "geojson": "application/geo+json",
    "svg": "image/svg+xml",
    "json": "application/json",
}
_SUFFIXES = {".geojson": "geojson", ".svg": "svg", ".json": "json"}


def format_from_suffix(name: str) -> str:
    """``"geojson"``, ``"svg"`` or ``"json"`` from a file name's suffix."""
    lowered = str(name).lower()
    for suffix, fmt in _SUFFIXES.items():
        if lowered.endswith(suffix):
            return fmt
    msg = f"{name!r} has no curve file suffix; accepted: {', '.join(_SUFFIXES)}"
    raise InvalidParameter(msg)


def _check_format(fmt: Any) -> str:
    if fmt not in FORMATS:
        msg = f"format {fmt!r} is not a curve format; accepted: {', '.join(FORMATS)}"
        raise InvalidParameter(msg)
    return str(fmt)


def read_curves(
    data: bytes | str,
    fmt: str,
    *,
    tolerance: float | None = None,
    max_points: int | None = None,
) -> CurveData:
    """Read a file's curves (``fmt`` one of :data:`FORMATS`).

    ``tolerance`` matters for SVG only: curved segments are sampled so that the polyline is
    within a quarter of it (default: 1e-3 of the drawing's size).  ``max_points`` bounds the
    SVG's samples (an :class:`~wavecore.InvalidParameter` once passed, before they are made).
    """
    fmt = _check_format(fmt)
    if fmt == "geojson":
        return read_geojson(data)
    if fmt == "svg":
        return read_svg(data, tolerance=tolerance, max_points=max_points)
    return read_curve_json(data)


def write_curves(data: CurveData, fmt: str) -> bytes:
    """Write curves as ``fmt``; structure from another format is kept where the target can."""
    fmt = _check_format(fmt)
    if fmt == "geojson":
        return write_geojson(data)
    if fmt == "svg":
        return write_svg(data)
    return write_curve_json(data)


def encode_file(
    data: bytes | str,
    fmt: str,
    *,
    tolerance: float | None = None,
    wavelet: str | None = None,
    level: int | None = None,
    check: Callable[[CurveData], None] | None = None,
    max_points: int | None = None,
    method: str | None = None,
) -> bytes:
    """Read a curve file and code it into one curve-set bundle.

    ``method`` is :func:`wavecore.encode_curves`' (``"auto"``, ``"wavelet"`` or ``"vertex"``).
    ``check``, when given, sees the curves before they are coded (the service checks their
    cost there); ``max_points`` bounds an SVG's samples (see :func:`read_curves`).

    For SVG the curved segments are sampled to a quarter of ``tolerance`` and the samples coded
    to the rest (three quarters), so decoded points stay within ``tolerance`` of the drawing's
    sampled outline and of its true curves at the vertices.
    """
    curves = read_curves(data, fmt, tolerance=tolerance, max_points=max_points)
    if check is not None:
        check(curves)
    code_tolerance = tolerance
    if fmt == "svg":
        code_tolerance = 0.75 * curves.tolerance if curves.tolerance else tolerance
    return encode_curves(
        curves.curves,
        closed=curves.closed,
        tolerance=code_tolerance,
        wavelet=wavelet,
        level=level,
        metadata=curves.metadata,
        method=method,
    )


def decode_file(bundle: bytes, fmt: str | None = None) -> bytes:
    """Decode a curve-set bundle into a file: ``fmt``, or the format it was read from."""
    return curve_set_file(decode_curves(bundle), fmt)


def curve_set_file(curveset: CurveSet, fmt: str | None = None) -> bytes:
    """A decoded curve set (:func:`~wavecore.decode_curves`) written as a file.

    Parameters
    ----------
    curveset : CurveSet
        What ``decode_curves`` gave.
    fmt : {"geojson", "svg", "json"}, optional
        The file format; by default the one the set was read from (its ``metadata``).

    Returns
    -------
    bytes
        The file.

    Raises
    ------
    wavecore.errors.InvalidParameter
        ``fmt`` is not a format.
    wavecore.errors.BundleError
        The set's metadata does not describe a file of that format.
    """
    metadata = curveset.metadata or {}
    if fmt is None:
        fmt = metadata.get("format", "json")
    data = CurveData(curveset.curves, curveset.closed, metadata, curveset.tolerance)
    fmt = _check_format(fmt)
    try:
        return write_curves(data, fmt)
    except InvalidParameter as exc:
        raise BundleError(f"the bundle's metadata does not fit its curves: {exc}") from exc
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        msg = f"the bundle's metadata does not describe a {fmt} file: {type(exc).__name__}"
        raise BundleError(msg) from exc
