"""SVG: every shape's outline (paths, rects, circles, ellipses, lines, polylines, polygons),
transforms applied, curved segments sampled to the tolerance.

Parsed by svgelements (pure Python, no dependencies of its own, the whole document: groups,
transforms, ``viewBox``, units, ``<use>``, every basic shape converted to a path); svgpathtools
parses path data just as well but needs SciPy and handles less of the document.  It is the
``svg`` extra (``pip install "wavecore[svg]"``), loaded only here.  It is given a sanitized
copy of the document (:func:`sanitized_svg`), whose parse :func:`scan_svg` estimates first:
its regular expressions take quadratic time on some values, and it expands every ``<use>``.

Each subpath becomes one curve, closed when it ends with ``Z``.  The written SVG has one
``<path>`` per element, with its ``id`` and paint (``fill``, ``stroke``, ``stroke-width``,
``fill-rule``, ``opacity``), in the user space the parser resolved (so ``viewBox`` is the
drawing's width and height in pixels).
"""

from __future__ import annotations

import io
import math
import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..curvesets import MAX_POINTS
from ..errors import InvalidParameter
from .common import CurveData, as_text

__all__ = ["SvgWork", "read_svg", "sanitized_svg", "scan_svg", "write_svg"]

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


# --- the cost of reading a document, known before svgelements parses it ------------------------

_COMMANDS = "MmLlHhVvCcSsQqTtAaZz"
_DRAWING = "LlHhVvCcSsQqTtAa"
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
#: Path commands by kind: letters, the fewest and the most numbers a segment is written with
#: (an arc's two flags may be packed against the next number), and what svgelements takes to
#: parse, measure and sample one segment, in microseconds (svgelements 1.9.6 on a 2-core
#: machine, 2026-12-07, 20,000 segments: lines 17-29 µs, quadratics 62-98, cubics 124-163,
#: arcs 570-770; ``benchmarks/svg_scan.py`` compares the estimates with the reads).
_KINDS = (
    ("Ll", 2, 2, 40),
    ("HhVv", 1, 1, 40),
    ("Qq", 4, 4, 100),
    ("Tt", 2, 2, 100),
    ("Cc", 6, 6, 200),
    ("Ss", 4, 4, 200),
    ("Aa", 5, 7, 800),
)
_LINE_MICROSECONDS = 40
#: A move or a close, each a segment object of its own (30-52 µs a bare ``M0 0``).
_MOVE_MICROSECONDS = 50
_CLOSE_MICROSECONDS = 40
#: Each close looks back over its subpath for the last move (svgelements' ``z_point`` and
#: ``_validate_close``), 0.09 µs a segment passed: a subpath of many closes is quadratic
#: (``M0 0`` and 8,000 ``Z``, 8 kB: 2.9 s; 100,000 ``Z``: past the request timeout).  Its
#: closes times its segments, halved (on average a close passes half), over this.
_CLOSE_LOOKBACK_DIVISOR = 16
_MOVE_LETTERS = re.compile("[Mm]")
_COMMAND_LETTERS = re.compile(f"[{_COMMANDS}]")
#: One regular expression per kind that blanks every other kind's commands.
_OTHER_COMMANDS = tuple(
    re.compile("[" + "".join(c for c in _COMMANDS if c not in letters) + f"][^{_COMMANDS}]*")
    for letters, *_ in _KINDS
)
_NOT_MOVES = re.compile(f"[{_COMMANDS.replace('Mm', '')}][^{_COMMANDS}]*")
#: A move that starts a curve: a drawing command, or a pair of numbers more (lines), follows.
_CURVE_START = re.compile(
    f"[Mm](?:[^{_COMMANDS}]*(?=[{_DRAWING}])"
    f"|\\s*{_NUMBER.pattern}[\\s,]*{_NUMBER.pattern}[\\s,]*(?=[-+.\\d]))"
)
#: Microseconds an element takes whatever its content (98.5 µs for a path of one segment).
_ELEMENT_MICROSECONDS = 120
#: And a polyline's or polygon's point (13.6-19.7 µs).
_POINT_MICROSECONDS = 25
#: A quarter of a circle or ellipse, or a rounded corner (a circle took 1.27-2.13 ms).
_QUARTER_MICROSECONDS = 600
#: Basic shapes, which svgelements turns into paths: (segments, microseconds of those).
_SHAPES = {
    "rect": (4, 4 * _LINE_MICROSECONDS),  # four arcs more with rounded corners (``rx``, ``ry``)
    "circle": (4, 4 * _QUARTER_MICROSECONDS),
    "ellipse": (4, 4 * _QUARTER_MICROSECONDS),
    "line": (1, _LINE_MICROSECONDS),
}
_SVG_NAMESPACE = "{http://www.w3.org/2000/svg}"
#: Containers whose shapes are parsed but not drawn (unless a ``<use>`` draws them).
_HIDDEN = frozenset({"defs", "clipPath", "pattern"})


# --- what svgelements is given: the document's geometry and paint, each value bounded ------------
#
# svgelements runs backtracking regular expressions on attribute values and ``<style>`` text
# (colours, fonts, transforms, CSS), some quadratic in a value's length, and copies every
# inherited property into every element.  It is given a copy of the document rebuilt from what
# reading uses: the elements that can draw (text, images and other namespaces dropped), the
# attributes of geometry, paint, transforms and links, each value checked in linear time and
# bounded, and the CSS rebuilt from its rules' properties of paint and display.

_XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
#: Elements that draw nothing, dropped with their content (svgelements makes no shape of them).
_DROPPED = frozenset(
    {"text", "tspan", "textPath", "image", "title", "desc", "metadata", "foreignObject", "script"}
)
#: Properties kept, as attributes, in ``style`` attributes and in CSS rules, and their longest
#: value (a longer one is refused).
_PROPERTIES = {
    **{name: 64 for name in ("fill", "stroke", "stroke-width", "fill-rule", "opacity")},
    "display": 32,
    "visibility": 32,
    "transform": 1024,
}
#: Geometry attributes, their longest value (``d`` and ``points`` are costed, not bounded).
_GEOMETRY = {
    **{name: 64 for name in ("x", "y", "width", "height", "rx", "ry", "cx", "cy", "r")},
    **{name: 64 for name in ("x1", "y1", "x2", "y2")},
    "viewBox": 128,
    "preserveAspectRatio": 64,
    "id": 256,
    "class": 256,
    "href": 256,
}
#: No number in a kept value may be longer: the parser's number patterns backtrack on long runs.
_LONGEST_NUMBER = re.compile(r"[0-9.]{33}")
#: One transform function up to its ``)``: neighbouring parts share no character, so a match
#: never backtracks (``\s*,?\s*`` did, quadratically, on a long run of spaces).
_TRANSFORM_PIECE = re.compile(r"[\s,]*[A-Za-z]+\s*\([-+0-9.eE,\s]*")
#: The most CSS selectors a document's ``<style>`` rules may name.
_MOST_SELECTORS = 10_000


def _checked_value(name: str, value: str, longest: int, where: str) -> str:
    if len(value) > longest:
        msg = f"SVG {where}: {name} is {len(value)} characters long, more than {longest}"
        raise InvalidParameter(msg)
    if _LONGEST_NUMBER.search(value):
        msg = f"SVG {where}: {name} has a number of more than 32 characters"
        raise InvalidParameter(msg)
    if name == "transform":
        pieces = value.split(")")
        if pieces[-1].strip(" \t\r\n,") or not all(
            _TRANSFORM_PIECE.fullmatch(piece) for piece in pieces[:-1]
        ):
            msg = f"SVG {where}: transform {value[:40]!r} is not a list of transforms"
            raise InvalidParameter(msg)
    return value


def _style_properties(text: str, where: str) -> dict[str, str]:
    """The kept properties of a ``style`` attribute or a CSS rule's body, the last one of a
    name winning (as the parser takes them)."""
    kept: dict[str, str] = {}
    for declaration in text.split(";"):
        name, colon, value = declaration.partition(":")
        name, value = name.strip(), value.strip()
        if colon and name in _PROPERTIES:
            kept[name] = _checked_value(name, value, _PROPERTIES[name], where)
    return kept


def _css(text: str) -> str:
    """``<style>`` text rebuilt from its rules (comments dropped; one rule per selector, its
    kept properties merged in order), in linear time."""
    rules: dict[str, dict[str, str]] = {}
    pieces = []
    position = 0
    while True:  # comments out, in one pass
        start = text.find("/*", position)
        if start < 0:
            pieces.append(text[position:])
            break
        pieces.append(text[position:start])
        end = text.find("*/", start + 2)
        position = len(text) if end < 0 else end + 2
    for rule in "".join(pieces).split("}"):
        selectors, brace, body = rule.partition("{")
        if not brace or "{" in body:
            continue
        properties = _style_properties(body, "<style>")
        properties.pop("transform", None)  # kept in attributes and style attributes only
        for selector in selectors.split(","):
            selector = selector.strip()
            if selector and properties:
                if len(selector) > 256:
                    msg = f"SVG <style>: a selector of {len(selector)} characters"
                    raise InvalidParameter(msg)
                rules.setdefault(selector, {}).update(properties)
                if len(rules) > _MOST_SELECTORS:
                    msg = f"SVG <style> has more than {_MOST_SELECTORS} selectors"
                    raise InvalidParameter(msg)
    return "\n".join(
        f"{selector}{{{';'.join(f'{k}:{v}' for k, v in properties.items())}}}"
        for selector, properties in rules.items()
    )


def _sanitized(root: ElementTree.Element) -> ElementTree.Element:
    """A copy of the document with only what reading uses, every value checked (above)."""

    def copy(element: ElementTree.Element) -> ElementTree.Element | None:
        tag = _drawing_tag(element)
        if tag is None:
            return None
        where = f"<{tag}>" + (f" {element.get('id')!r}"[:60] if element.get("id") else "")
        attributes: dict[str, str] = {}
        for name, value in element.attrib.items():
            if name == _XLINK_HREF:
                name = "href" if "href" not in element.attrib else ""  # href wins, as it does
            if name in ("d", "points"):  # only where they draw: a group's would be inherited
                if (name == "d") == (tag == "path") and (name == "points") == (
                    tag in ("polyline", "polygon")
                ):
                    attributes[name] = value
            elif name in _GEOMETRY:
                attributes[name] = _checked_value(name, value, _GEOMETRY[name], where)
            elif name in _PROPERTIES:
                attributes[name] = _checked_value(name, value, _PROPERTIES[name], where)
            elif name == "style":
                style = _style_properties(value, where)
                if style:
                    attributes["style"] = ";".join(f"{k}:{v}" for k, v in style.items())
        out = ElementTree.Element(tag, attributes)
        if tag == "style":
            out.text = _css(element.text or "")
        for child in element:
            kept = copy(child)
            if kept is not None:
                out.append(kept)
        return out

    try:
        clean = copy(root)
    except RecursionError:
        msg = "SVG is nested too deeply"
        raise InvalidParameter(msg) from None
    if clean is None:
        msg = "SVG's root is not an SVG element"
        raise InvalidParameter(msg)
    clean.set("xmlns", _SVG_NAMESPACE[1:-1])
    return clean


def _parsed(text: str) -> ElementTree.Element:
    try:
        return ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        msg = f"SVG could not be parsed: {exc}"[:300]
        raise InvalidParameter(msg) from None


def sanitized_svg(data: bytes | str) -> str:
    """The SVG document as :func:`read_svg` hands it to svgelements: only the elements that
    can draw (text, images and other namespaces dropped) and the attributes of geometry,
    paint (``fill``, ``stroke``, ``stroke-width``, ``fill-rule``, ``opacity``), display,
    transforms and links, in attributes, ``style`` attributes and ``<style>`` rules.

    Raises
    ------
    InvalidParameter
        For text that is not XML, or a kept value longer than its bound (64 characters for
        paint and lengths, 1024 for a transform) or not of its form.
    """
    return ElementTree.tostring(_sanitized(_parsed(as_text(data, "SVG"))), encoding="unicode")


@dataclass(frozen=True)
class SvgWork:
    """What reading an SVG document takes, from a scan that does not parse its path data.

    Attributes
    ----------
    microseconds : int
        An estimate, on the high side, of the time :func:`read_svg` takes to parse the
        document (every ``<use>`` expanded, as the parser expands it) before it samples it.
    points : int
        At least this many points come out (a drawn segment gives one or more).
    curves : int
        At least this many curves (each drawn subpath or shape with a segment).
    """

    microseconds: int
    points: int
    curves: int


def _path_work(data: str) -> tuple[int, int, int]:
    """(microseconds, fewest points, fewest curves) of one ``d`` attribute."""
    microseconds = points = 0
    for (letters, fewest, most, cost), others in zip(_KINDS, _OTHER_COMMANDS, strict=True):
        if not any(c in data for c in letters):
            continue
        runs = others.sub(" ", data)  # this kind's commands and their numbers only
        commands = sum(runs.count(c) for c in letters)
        numbers = _NUMBER.subn("", runs)[1]
        microseconds += cost * max(commands, numbers // fewest)
        points += max(commands, numbers // most)
    moves = _NOT_MOVES.sub(" ", data)
    lines_after_moves = max(
        0, _NUMBER.subn("", moves)[1] // 2 - moves.count("M") - moves.count("m")
    )
    microseconds += _LINE_MICROSECONDS * lines_after_moves
    points += lines_after_moves
    closes = data.count("Z") + data.count("z")
    microseconds += _MOVE_MICROSECONDS * (data.count("M") + data.count("m"))
    microseconds += _CLOSE_MICROSECONDS * closes
    if closes > 1:
        for subpath in _MOVE_LETTERS.split(data):
            closes_here = subpath.count("Z") + subpath.count("z")
            if closes_here > 1:  # at most this many segments to look back over, each
                segments = (
                    len(_COMMAND_LETTERS.findall(subpath)) + _NUMBER.subn("", subpath)[1] // 2
                )
                microseconds += closes_here * segments // _CLOSE_LOOKBACK_DIVISOR
    curves = max(len(_CURVE_START.findall(data)), 1 if points else 0)
    return microseconds, points, curves


class _OverLimit(Exception):
    pass


def scan_svg(data: bytes | str, *, limit: int | None = None) -> SvgWork:
    """Estimate what reading an SVG document takes, before anything parses its path data.

    svgelements, which :func:`read_svg` uses, parses the whole document, with every
    ``<use>`` expanded, before the first point is known; a few kilobytes of nested ``<use>``
    elements expand to millions of shapes, and a few megabytes of arcs take minutes.  This
    scan reads the XML with the standard library's parser and counts, per element, the path
    commands and their numbers by regular expressions, each ``<use>`` counted with what it
    draws (once per reference, in linear time).

    Parameters
    ----------
    data : bytes or str
        The SVG document.
    limit : int, optional, keyword-only
        Stop once the estimate passes this many microseconds (a caller that refuses such
        documents need not scan the rest): the work returned then has that estimate so far,
        and no points or curves.

    Returns
    -------
    SvgWork
        The estimated parse time and the fewest points and curves reading it gives.

    Raises
    ------
    InvalidParameter
        For text that is not XML, or ``<use>`` references that form a cycle.

    Examples
    --------
    >>> svg = '<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 L1 1 2 0 Z"/></svg>'
    >>> work = scan_svg(svg)
    >>> work.points, work.curves
    (2, 1)
    """
    root = _parsed(as_text(data, "SVG"))
    if limit is not None:
        # each element svgelements will see costs at least this: a document of more is
        # refused without the rest of the scan (400 000 paths: 0.1 s, not 2.5)
        elements = sum(1 for element in root.iter() if _drawing_tag(element) is not None)
        if _ELEMENT_MICROSECONDS * elements > limit:
            return SvgWork(_ELEMENT_MICROSECONDS * elements, 0, 0)
    return _scan(_sanitized(root), limit)


def _drawing_tag(element: ElementTree.Element) -> str | None:
    """The local name of an element that svgelements is given, or None (see _sanitized)."""
    tag = element.tag
    if not isinstance(tag, str):
        return None  # a comment or an instruction
    if tag.startswith(_SVG_NAMESPACE):
        tag = tag[len(_SVG_NAMESPACE) :]
    elif tag.startswith("{"):
        return None  # another namespace (an editor's)
    return None if tag in _DROPPED else tag


#: What parsing a transform takes a character, for every element that inherits it (svgelements
#: parses each element's transform with all its ancestors': 4.5 µs for ``rotate(1) ``).
_TRANSFORM_MICROSECONDS_PER_CHARACTER = 1


def _scan(root: ElementTree.Element, limit: int | None) -> SvgWork:
    """:func:`scan_svg` of a sanitized document."""
    ids = {e.get("id"): e for e in root.iter() if e.get("id") is not None}
    # per (element, drawn): microseconds, points, curves, elements drawn or parsed below it
    done: dict[tuple[int, bool], tuple[int, int, int, int]] = {}
    visiting: set[int] = set()
    spent = 0  # the estimate so far, for the limit

    def work_of(element: ElementTree.Element, drawn: bool) -> tuple[int, int, int, int]:
        nonlocal spent
        key = (id(element), drawn)
        if key in done:
            return done[key]
        if id(element) in visiting:
            msg = "SVG <use> references form a cycle"
            raise InvalidParameter(msg)
        visiting.add(id(element))
        tag = element.tag
        drawn = drawn and tag not in _HIDDEN
        microseconds, points, curves, elements = _ELEMENT_MICROSECONDS, 0, 0, 1
        if tag == "path":
            microseconds_d, points, curves = _path_work(element.get("d") or "")
            microseconds += microseconds_d
        elif tag in ("polyline", "polygon"):
            count = _NUMBER.subn("", element.get("points") or "")[1] // 2
            microseconds += _POINT_MICROSECONDS * count
            points, curves = max(0, count - 1), 1 if count > 1 else 0
        elif tag in _SHAPES:
            points, cost = _SHAPES[tag]
            rounded = tag == "rect" and (element.get("rx") or element.get("ry"))
            microseconds += cost + (4 * _QUARTER_MICROSECONDS if rounded else 0)
            curves = 1
        elif tag == "use":
            # as svgelements resolves it: ``href`` before ``xlink:href`` (sanitized into one),
            # its first character dropped whatever it is
            href = element.get("href")
            target = ids.get(href[1:]) if href else None
            if target is not None:
                used = work_of(target, True)
                microseconds += used[0]
                points, curves, elements = used[1], used[2], 1 + used[3]
        if not drawn:
            points = curves = 0
        spent += microseconds
        if limit is not None and spent > limit:
            raise _OverLimit
        for child in element:
            child_work = work_of(child, drawn)
            microseconds += child_work[0]
            points += child_work[1]
            curves += child_work[2]
            elements += child_work[3]
        # every element below parses this one's transform again, with its own
        transform = len(element.get("transform") or "") + len(element.get("style") or "")
        microseconds += _TRANSFORM_MICROSECONDS_PER_CHARACTER * transform * elements
        visiting.discard(id(element))
        done[key] = (microseconds, points, curves, elements)
        return done[key]

    try:
        microseconds, points, curves, _ = work_of(root, True)
    except RecursionError:
        msg = "SVG is nested too deeply"
        raise InvalidParameter(msg) from None
    except _OverLimit:
        return SvgWork(spent, 0, 0)
    return SvgWork(microseconds, points, curves)


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
        Refuse (``InvalidParameter``) once the samples pass this many points, or before
        parsing when :func:`scan_svg` finds that they will.  Default: the most a curve set
        holds (``curvesets.MAX_POINTS``, 2**27): a 2.7 kB document of nested ``<use>`` draws
        2**40 shapes, which the parser would expand for ever.

    Raises
    ------
    InvalidParameter
        For text that is not an SVG document, or one without any shape.
    """
    se = _parser()
    clean = _sanitized(_parsed(as_text(data, "SVG")))
    if max_points is None:
        max_points = MAX_POINTS
    # before the parser expands every <use>: a few kilobytes may draw millions of shapes
    fewest = _scan(clean, None).points
    if fewest > max_points:
        msg = f"SVG draws {fewest} points or more, more than {max_points}"
        raise InvalidParameter(msg)
    try:
        svg = se.SVG.parse(io.StringIO(ElementTree.tostring(clean, encoding="unicode")))
        shapes = [e for e in svg.elements() if isinstance(e, se.Shape)]
        paths = [abs(se.Path(shape)) for shape in shapes]
    except Exception as exc:  # svgelements raises the XML parser's and its own errors
        msg = f"SVG could not be parsed: {type(exc).__name__}: {exc}"[:300]
        raise InvalidParameter(msg) from None
    if tolerance is None:
        boxes = [box for box in (p.bbox() for p in paths) if box is not None]
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
                try:
                    pieces.append(_samples(segment, sampling, se))
                except (ValueError, ArithmeticError) as exc:  # svgelements on extreme values
                    name = shape.id or type(shape).__name__
                    msg = f"SVG element {name} has a segment that cannot be sampled: {exc}"
                    raise InvalidParameter(msg[:300]) from None
                total += len(pieces[-1])
                if total > max_points:
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


#: The attributes written on a path: the paint the reader keeps, and ``id``.
_WRITTEN_ATTRIBUTES = frozenset((*_PAINT, "id"))
#: Characters XML 1.0 does not allow (C0 controls but tab and newlines, surrogates, U+FFFE/F).
_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def _length(value: Any) -> float | None:
    """A width or height from a set's metadata: a positive finite number, else None."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) and number > 0 else None


def write_svg(data: CurveData) -> bytes:
    """An SVG document: one ``<path>`` per original element (or per curve)."""
    meta = data.metadata if data.metadata.get("format") == "svg" else {}
    elements = meta.get("elements") or [
        {"curves": [i], "attributes": {"fill": "none", "stroke": "black"}}
        for i in range(len(data.curves))
    ]
    width, height = _length(meta.get("width")), _length(meta.get("height"))
    if width and height:
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
    used: set[int] = set()
    for element in elements:
        for i in element["curves"]:
            if i in used:  # the reader names each curve once: a bundle naming one again
                msg = f"SVG elements refer to curve {i!r} twice"  # would repeat its points
                raise InvalidParameter(msg[:200])
            used.add(i)
        d = " ".join(_path_data(data.curves[i], data.closed[i]) for i in element["curves"])
        # only the attributes the reader keeps, whose names are known: a bundle's metadata
        # could name one '"/><script>…' (its values are quoted; names cannot be)
        attributes = "".join(
            f" {name}={quoteattr(_XML_INVALID.sub('', str(value)))}"
            for name, value in element["attributes"].items()
            if name in _WRITTEN_ATTRIBUTES
        )
        lines.append(f'<path d="{d}"{attributes}/>')
    lines.append("</svg>")
    return ("\n".join(lines) + "\n").encode()
