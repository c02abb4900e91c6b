"""SVG: every shape's outline (paths, rects, circles, ellipses, lines, polylines, polygons),
transforms applied, curved segments sampled to the tolerance.

Parsed by svgelements (pure Python, no dependencies of its own, the whole document: groups,
transforms, ``viewBox``, units, ``<use>``, every basic shape converted to a path); svgpathtools
parses path data just as well but needs SciPy and handles less of the document.  It is the
``svg`` extra (``pip install "wavecore[svg]"``), loaded only here.

Each subpath becomes one curve, closed when it ends with ``Z``.  The written SVG has one
``<path>`` per element, with its ``id`` and paint (``fill``, ``stroke``, ``stroke-width``,
``fill-rule``, ``opacity``), in the user space the parser resolved (so ``viewBox`` is the
drawing's width and height in pixels).
"""

from __future__ import annotations

import io
import math
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import InvalidParameter
from .common import CurveData, as_text

__all__ = ["read_svg", "write_svg"]

_PAINT = ("fill", "stroke", "stroke-width", "fill-rule", "opacity")
#: Share of the tolerance the sampling of curved segments may use.
SAMPLING_SHARE = 0.25
_MAX_SAMPLES_PER_SEGMENT = 4096


def _parser() -> Any:
    try:
        import svgelements
    except ImportError as exc:  # pragma: no cover - the extra is part of the service and tests
        msg = 'reading SVG needs svgelements: pip install "wavecore[svg]"'
        raise InvalidParameter(msg) from exc
    return svgelements


def _samples(segment: Any, tolerance: float, se: Any) -> np.ndarray:
    """Points after the start of ``segment``, its chords within ``tolerance`` of it."""
    if isinstance(segment, se.Arc):
        cubics = list(segment.as_cubic_curves())
        return (
            np.concatenate([_samples(c, tolerance, se) for c in cubics])
            if cubics
            else (np.array([[segment.end.x, segment.end.y]]))
        )
    if isinstance(segment, se.CubicBezier | se.QuadraticBezier):
        if isinstance(segment, se.CubicBezier):
            p = np.array(
                [
                    [q.x, q.y]
                    for q in (segment.start, segment.control1, segment.control2, segment.end)
                ]
            )
            bend = 6 * max(
                np.linalg.norm(p[0] - 2 * p[1] + p[2]), np.linalg.norm(p[1] - 2 * p[2] + p[3])
            )
        else:
            p = np.array([[q.x, q.y] for q in (segment.start, segment.control, segment.end)])
            bend = 2 * np.linalg.norm(p[0] - 2 * p[1] + p[2])
        # a chord over a parameter step h is within bend * h**2 / 8 of the curve
        count = max(1, math.ceil(math.sqrt(bend / (8 * tolerance)))) if bend > 0 else 1
        count = min(count, _MAX_SAMPLES_PER_SEGMENT)
        t = np.linspace(0.0, 1.0, count + 1)[1:]
        if len(p) == 4:
            u = 1 - t
            basis = np.stack([u**3, 3 * u * u * t, 3 * u * t * t, t**3], axis=1)
        else:
            u = 1 - t
            basis = np.stack([u * u, 2 * u * t, t * t], axis=1)
        return basis @ p
    return np.array([[segment.end.x, segment.end.y]], dtype=np.float64)


def read_svg(
    data: bytes | str, *, tolerance: float | None = None, max_points: int | None = None
) -> CurveData:
    """Read an SVG document's outlines as curves.

    Parameters
    ----------
    data : bytes or str
        The SVG document.
    tolerance : float, optional
        Curved segments are sampled so that the polyline is within ``SAMPLING_SHARE`` (a
        quarter) of it.  Default: ``1e-3`` × the drawing's diagonal.
    max_points : int, optional
        Refuse (``InvalidParameter``) once the samples pass this many points.

    Raises
    ------
    InvalidParameter
        For text that is not an SVG document, or one without any shape.
    """
    se = _parser()
    text = as_text(data, "SVG")
    try:
        svg = se.SVG.parse(io.StringIO(text))
        shapes = [e for e in svg.elements() if isinstance(e, se.Shape)]
        paths = [abs(se.Path(shape)) for shape in shapes]
    except Exception as exc:  # svgelements raises the XML parser's and its own errors
        msg = f"SVG could not be parsed: {type(exc).__name__}: {exc}"[:300]
        raise InvalidParameter(msg) from None
    if tolerance is None:
        boxes = [p.bbox() for p in paths if p.bbox() is not None]
        if boxes:
            box = np.array(boxes, dtype=np.float64)
            size = math.hypot(box[:, 2].max() - box[:, 0].min(), box[:, 3].max() - box[:, 1].min())
        else:
            size = 0.0
        tolerance = 1e-3 * (size if size > 0 else 1.0)
    elif not (isinstance(tolerance, int | float) and math.isfinite(tolerance) and tolerance > 0):
        msg = f"tolerance must be a positive finite distance, not {tolerance!r}"
        raise InvalidParameter(msg)
    sampling = SAMPLING_SHARE * float(tolerance)
    curves: list[np.ndarray] = []
    closed: list[bool] = []
    elements = []
    total = 0
    for shape, path in zip(shapes, paths, strict=True):
        indices = []
        for subpath in path.as_subpaths():
            segments = [s for s in subpath if not isinstance(s, se.Move)]
            start = next((s for s in subpath if isinstance(s, se.Move)), None)
            if start is None or start.end is None or not segments:
                continue
            pieces = [np.array([[start.end.x, start.end.y]], dtype=np.float64)]
            is_closed = False
            for segment in segments:
                if isinstance(segment, se.Close):
                    is_closed = True
                    continue
                pieces.append(_samples(segment, sampling, se))
                total += len(pieces[-1])
                if max_points is not None and total > max_points:
                    msg = (
                        f"SVG sampled to tolerance {tolerance:g} gives more than {max_points} "
                        "points; give a larger tolerance or a smaller drawing"
                    )
                    raise InvalidParameter(msg)
            points = np.concatenate(pieces)
            if is_closed and len(points) > 1 and np.allclose(points[0], points[-1]):
                points = points[:-1]
            if not np.all(np.isfinite(points)):
                msg = f"SVG element {shape.id or type(shape).__name__} has non-finite coordinates"
                raise InvalidParameter(msg)
            curves.append(points)
            closed.append(is_closed)
            indices.append(len(curves) - 1)
        if indices:
            paint = {k: str(shape.values[k]) for k in _PAINT if shape.values.get(k) is not None}
            if shape.id:
                paint["id"] = str(shape.id)
            elements.append({"curves": indices, "attributes": paint})
    if not curves:
        msg = "SVG has no shape with an outline (path, rect, circle, polygon, ...)"
        raise InvalidParameter(msg)
    width = float(svg.width) if svg.width else None
    height = float(svg.height) if svg.height else None
    metadata = {"format": "svg", "width": width, "height": height, "elements": elements}
    return CurveData(curves, closed, metadata, float(tolerance))


def _path_data(points: np.ndarray, closed: bool) -> str:
    xy = np.asarray(points, dtype=np.float64)[:, :2]
    if xy.shape[1] == 1:
        xy = np.concatenate([np.arange(len(xy))[:, None], xy], axis=1)
    if closed and len(xy) > 2 and np.array_equal(xy[0], xy[-1]):
        xy = xy[:-1]
    coords = [f"{x:.6g} {y:.6g}" for x, y in xy]
    return "M" + " L".join(coords) + (" Z" if closed else "")


def write_svg(data: CurveData) -> bytes:
    """An SVG document: one ``<path>`` per original element (or per curve)."""
    meta = data.metadata if data.metadata.get("format") == "svg" else {}
    elements = meta.get("elements") or [
        {"curves": [i], "attributes": {"fill": "none", "stroke": "black"}}
        for i in range(len(data.curves))
    ]
    if meta.get("width") and meta.get("height"):
        width, height = float(meta["width"]), float(meta["height"])
        box = f"0 0 {width:.6g} {height:.6g}"
    else:  # curves from elsewhere: a view of their bounding box
        xy = [np.asarray(c, dtype=np.float64)[:, :2] for c in data.curves]
        both = np.concatenate(xy) if xy else np.zeros((1, 2))
        if both.shape[1] == 1:
            both = np.concatenate([np.zeros_like(both), both], axis=1)
        low, high = both.min(axis=0), both.max(axis=0)
        width, height = (float(v) if v > 0 else 1.0 for v in high - low)
        box = f"{low[0]:.6g} {low[1]:.6g} {width:.6g} {height:.6g}"
    lines = [
        '<svg xmlns="http://www.w3.org/2000/svg" '
        f'width="{width:.6g}" height="{height:.6g}" viewBox="{box}">'
    ]
    for element in elements:
        d = " ".join(_path_data(data.curves[i], data.closed[i]) for i in element["curves"])
        attributes = "".join(
            f" {name}={quoteattr(str(value))}" for name, value in element["attributes"].items()
        )
        lines.append(f'<path d="{d}"{attributes}/>')
    lines.append("</svg>")
    return ("\n".join(lines) + "\n").encode()
