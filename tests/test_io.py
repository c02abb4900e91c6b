"""Curve files: GeoJSON, SVG and curve JSON through bundles, structure and bound kept."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

import wavecore
from wavecore import io as wio

pytest.importorskip("svgelements", reason="SVG reading is the svg extra (part of the test extra)")


def _to_polyline(source: np.ndarray, target: np.ndarray, closed: bool) -> float:
    nodes = np.concatenate([target, target[:1]]) if closed else target
    a, b = nodes[:-1], nodes[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    p = source[:, None, :]
    t = np.clip(np.einsum("pij,ij->pi", p - a, ab) / length2, 0.0, 1.0)
    gap = p - (a + t[..., None] * ab)
    return float(np.sqrt(np.einsum("pij,pij->pi", gap, gap).min(axis=1)).max())


def _both_ways(original: list, decoded: list, closed: bool) -> float:
    a, b = np.asarray(original, float), np.asarray(decoded, float)
    if closed:  # GeoJSON rings repeat their first position
        a, b = a[:-1], b[:-1]
    return max(_to_polyline(a, b, closed), _to_polyline(b, a, closed))


def _ring(n: int, radius: float, centre: tuple[float, float], seed: int) -> list:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = radius * (1 + 0.1 * np.random.default_rng(seed).random(n))
    pts = np.stack([centre[0] + r * np.cos(t), centre[1] + r * np.sin(t)], axis=1)
    return np.concatenate([pts, pts[:1]]).tolist()


FEATURES = {
    "type": "FeatureCollection",
    "name": "test layer",
    "features": [
        {
            "type": "Feature",
            "id": "lake",
            "properties": {"name": "Lac Léman", "depth": 310, "tags": ["a", None]},
            "geometry": {
                "type": "Polygon",
                "coordinates": [_ring(200, 10, (6.5, 46.4), 1), _ring(30, 1, (6.5, 46.4), 2)],
            },
        },
        {
            "type": "Feature",
            "properties": None,
            "geometry": {
                "type": "MultiLineString",
                "coordinates": [
                    np.cumsum(np.random.default_rng(3).normal(size=(300, 3)), 0).tolist(),
                    [[0.0, 0.0], [1.0, 1.0]],
                ],
            },
        },
        {
            "type": "Feature",
            "properties": {"islands": 2},
            "geometry": {
                "type": "MultiPolygon",
                "coordinates": [[_ring(50, 2, (0, 0), 4)], [_ring(60, 3, (9, 9), 5)]],
            },
        },
        {"type": "Feature", "properties": {"empty": True}, "geometry": None},
    ],
}


def test_geojson_round_trip_keeps_structure_and_bound() -> None:
    bundle = wavecore.encode_curve_file(json.dumps(FEATURES).encode(), "geojson", tolerance=0.05)
    back = json.loads(wavecore.decode_curve_file(bundle))
    assert back["name"] == "test layer"
    for original, decoded in zip(FEATURES["features"], back["features"], strict=True):
        assert decoded["properties"] == original["properties"]
        assert decoded.get("id") == original.get("id")
        if original["geometry"] is None:
            assert decoded["geometry"] is None
            continue
        assert decoded["geometry"]["type"] == original["geometry"]["type"]
    lake, lines, islands = (f["geometry"]["coordinates"] for f in back["features"][:3])
    originals = [f["geometry"]["coordinates"] for f in FEATURES["features"][:3]]
    for ring, original in zip(lake, originals[0], strict=True):
        assert ring[0] == ring[-1]
        assert _both_ways(original, ring, True) <= 0.05
    for line, original in zip(lines, originals[1], strict=True):
        assert len(line[0]) == len(original[0])  # 3-D positions stay 3-D
        assert _both_ways(original, line, False) <= 0.05
    for polygon, original in zip(islands, originals[2], strict=True):
        assert _both_ways(original[0], polygon[0], True) <= 0.05


@pytest.mark.parametrize(
    "geometry",
    [
        {"type": "LineString", "coordinates": [[0, 0], [1, 2], [3, 1]]},
        {"type": "Polygon", "coordinates": [[[0, 0], [4, 0], [4, 3], [0, 0]]]},
    ],
)
def test_bare_geometries_come_back_as_themselves(geometry: dict) -> None:
    bundle = wavecore.encode_curve_file(json.dumps(geometry), "geojson", tolerance=0.01)
    back = json.loads(wavecore.decode_curve_file(bundle, "geojson"))
    assert back["type"] == geometry["type"]
    closed = geometry["type"] == "Polygon"
    coords = back["coordinates"][0] if closed else back["coordinates"]
    original = geometry["coordinates"][0] if closed else geometry["coordinates"]
    assert _both_ways(original, coords, closed) <= 0.01


@pytest.mark.parametrize(
    ("document", "words"),
    [
        ("{not json", "not valid JSON"),
        ({"type": "Point", "coordinates": [0, 0]}, "'Point' is not a curve"),
        ({"type": "LineString", "coordinates": [[0, 0]]}, "at least 2"),
        ({"type": "LineString", "coordinates": [[0, "a"], [1, 1]]}, "lists of numbers"),
        ({"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [0, 0]]]}, r"coordinates\[0\]"),
        (
            {"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": 3}]},
            r"features\[0\].geometry",
        ),
        ({"type": "LineString", "coordinates": [[0, 0, 0, 0], [1, 1, 1, 1]]}, "2 or 3"),
    ],
)
def test_bad_geojson_is_named(document: object, words: str) -> None:
    text = document if isinstance(document, str) else json.dumps(document)
    with pytest.raises(wavecore.InvalidParameter, match=words):
        wavecore.encode_curve_file(text, "geojson")


SVG = b"""<svg xmlns="http://www.w3.org/2000/svg" width="200" height="100" viewBox="0 0 200 100">
<g transform="translate(10, 5)">
<path id="wave" d="M 0 50 C 30 0 60 100 90 50 S 150 0 180 50" fill="none" stroke="red"/>
</g>
<circle id="dot" cx="100" cy="50" r="30" fill="blue"/>
<rect x="5" y="5" width="20" height="10"/>
</svg>"""


def test_svg_is_sampled_to_the_tolerance_and_written_back() -> None:
    tolerance = 0.05
    data = wio.read_curves(SVG, "svg", tolerance=tolerance)
    assert data.closed == [False, True, True]
    # the circle's samples lie on it, and its chords are within a quarter of the tolerance
    circle = data.curves[1]
    radius = np.linalg.norm(circle - [100, 50], axis=1)
    assert np.allclose(radius, 30, atol=1e-9)
    chord_middles = (circle + np.roll(circle, -1, axis=0)) / 2
    assert np.min(np.linalg.norm(chord_middles - [100, 50], axis=1)) >= 30 - tolerance / 4
    # the transform is applied
    assert data.curves[0][0] == pytest.approx([10, 55])
    bundle = wavecore.encode_curve_file(SVG, "svg", tolerance=tolerance)
    text = wavecore.decode_curve_file(bundle).decode()
    assert text.startswith("<svg") and 'id="wave"' in text and 'fill="blue"' in text
    back = wio.read_curves(text.encode(), "svg", tolerance=tolerance)
    assert len(back.curves) == 3 and back.closed == [False, True, True]
    for original, decoded, closed in zip(data.curves, back.curves, data.closed, strict=True):
        # the written SVG keeps 6 significant digits: 1e-3 on these coordinates at most
        assert (
            max(_to_polyline(original, decoded, closed), _to_polyline(decoded, original, closed))
            <= 0.75 * tolerance + 1e-3
        )


@pytest.mark.parametrize(
    ("document", "words"),
    [
        (b"<svg", "could not be parsed"),
        (b'<svg xmlns="http://www.w3.org/2000/svg"></svg>', "no shape"),
        (b"\xff\xfe\x00", "UTF-8"),
    ],
)
def test_bad_svg_is_named(document: bytes, words: str) -> None:
    with pytest.raises(wavecore.InvalidParameter, match=words):
        wavecore.encode_curve_file(document, "svg")


def test_curve_json_one_and_many() -> None:
    one = {"points": [[0, 0], [1, 0], [1, 1], [0, 1]], "closed": True}
    bundle = wavecore.encode_curve_file(json.dumps(one), "json", tolerance=1e-3)
    back = json.loads(wavecore.decode_curve_file(bundle))
    assert back["kind"] == "curves" and back["curves"][0]["closed"] is True
    assert _both_ways(one["points"], back["curves"][0]["points"], False) <= 1e-3
    many = {
        "curves": [{"points": [[0, 0], [2, 2], [3, 0]]}, {"points": one["points"], "closed": True}]
    }
    data = wio.read_curves(json.dumps(many), "json")
    assert data.closed == [False, True]


def test_formats_convert_into_each_other() -> None:
    bundle = wavecore.encode_curve_file(json.dumps(FEATURES), "geojson", tolerance=0.05)
    svg = wavecore.decode_curve_file(bundle, "svg")
    assert svg.count(b"<path") == 6  # not from an SVG: one path per curve
    as_json = json.loads(wavecore.decode_curve_file(bundle, "json"))
    assert len(as_json["curves"]) == 6
    with pytest.raises(wavecore.InvalidParameter, match="format"):
        wavecore.decode_curve_file(bundle, "kml")


def test_a_decoded_set_is_written_as_its_bundle_decodes() -> None:
    """``curve_set_file`` writes a set already decoded (the service decodes once)."""
    bundle = wavecore.encode_curve_file(json.dumps(FEATURES), "geojson", tolerance=0.05)
    curveset = wavecore.decode_curves(bundle)
    assert wio.curve_set_file(curveset) == wavecore.decode_curve_file(bundle)  # its own: geojson
    for fmt in wio.FORMATS:
        assert wio.curve_set_file(curveset, fmt) == wavecore.decode_curve_file(bundle, fmt)
    with pytest.raises(wavecore.InvalidParameter, match="format"):
        wio.curve_set_file(curveset, "kml")


def test_suffixes() -> None:
    assert wavecore.curve_file_format("a/b.GeoJSON") == "geojson"
    assert wavecore.curve_file_format("x.svg") == "svg"
    with pytest.raises(wavecore.InvalidParameter, match="suffix"):
        wavecore.curve_file_format("x.kml")


def test_cli_encodes_and_decodes_curve_files_by_suffix(tmp_path) -> None:  # type: ignore[no-untyped-def]
    cli = pytest.importorskip("service.cli", reason="the CLI lives in the service package")
    source = tmp_path / "layer.geojson"
    source.write_text(json.dumps(FEATURES))
    bundle = tmp_path / "layer.wcb"
    assert cli.main(["encode", str(source), str(bundle), "--tolerance", "0.05", "-q"]) == 0
    assert wavecore.inspect(bundle.read_bytes())["count"] == 6
    back = tmp_path / "back.geojson"
    assert cli.main(["decode", str(bundle), str(back), "-q"]) == 0
    assert json.loads(back.read_text())["features"][0]["properties"]["name"] == "Lac Léman"
    drawing = tmp_path / "back.svg"
    assert cli.main(["decode", str(bundle), str(drawing), "-q"]) == 0
    assert drawing.read_text().count("<path") == 6
    svg = tmp_path / "shapes.svg"
    svg.write_bytes(SVG)
    assert cli.main(["encode", str(svg), str(tmp_path / "shapes.wcb"), "-q"]) == 0
    assert cli.main(["decode", str(tmp_path / "shapes.wcb"), str(tmp_path / "s.svg"), "-q"]) == 0
    assert 'id="dot"' in (tmp_path / "s.svg").read_text()
    # a plain curve JSON stays a single curve (the old contract)
    one = tmp_path / "one.json"
    one.write_text(json.dumps({"points": [[0, 0], [1, 1], [2, 0], [3, 1]]}))
    assert cli.main(["encode", str(one), str(tmp_path / "one.wcb"), "-q"]) == 0
    assert wavecore.inspect((tmp_path / "one.wcb").read_bytes())["kind"] == "curve"


# --- hostile documents: what reading costs is known before the parser runs -----------------

_SVG = '<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink">'


def _use_bomb(depth: int) -> str:
    """``depth`` levels of groups of ten ``<use>`` of the level below: 10**depth paths."""
    parts = [_SVG, '<defs><path id="g0" d="M0 0 l1 1"/>']
    for level in range(1, depth + 1):
        uses = "".join(f'<use xlink:href="#g{level - 1}" x="{j}"/>' for j in range(10))
        parts.append(f'<g id="g{level}">{uses}</g>')
    parts.append(f'</defs><use xlink:href="#g{depth}"/></svg>')
    return "".join(parts)


@pytest.mark.parametrize(
    "document",
    [
        _SVG + '<path d="M0 0 l1 1 2 2 h3 v4 z m5 5 c1 1 2 2 3 3 s4 4 5 5"/></svg>',
        _SVG + '<path d="M0 0 q1 1 2 2 t3 3 4 4 a5 5 0 1 1 6 6 5 5 0 113 3"/></svg>',
        _SVG + '<path d="M0 0 1 1 2 0 3 1"/><polyline points="0 0 1 1 2 0"/></svg>',
        _SVG + '<rect width="3" height="2"/><rect width="3" height="2" rx="1"/></svg>',
        _SVG + '<circle r="2"/><ellipse rx="3" ry="1"/><line x2="4" y2="1"/></svg>',
        _use_bomb(2),
        _use_bomb(2).replace('href="#', 'href="X'),  # svgelements drops any first character
        _SVG + '<o:path xmlns:o="urn:o" d="M0 0 l1 1 2 2"/><path d="M0 0 l1 1"/></svg>',
    ],
)
def test_the_scan_bounds_what_reading_gives(document: str) -> None:
    work = wio.svg.scan_svg(document)
    read = wio.read_curves(document, "svg")
    assert work.points <= sum(len(c) for c in read.curves)
    assert work.curves <= len(read.curves)
    assert work.microseconds >= 100 * (1 + work.curves)  # an element, a path or shape each


def test_nested_use_past_what_a_set_holds_is_refused_without_max_points() -> None:
    # each group draws the one before twice: 2.7 kB that the parser would expand for ever
    groups = "".join(
        f'<g id="p{i + 1}"><use xlink:href="#p{i}"/><use xlink:href="#p{i}"/></g>'
        for i in range(40)
    )
    document = _SVG + '<path id="p0" d="M0 0 L1 1 L2 0"/>' + groups + "</svg>"
    assert len(document) < 3000
    start = time.perf_counter()
    with pytest.raises(wavecore.InvalidParameter, match="more than 134217728"):
        wio.read_curves(document, "svg")
    assert time.perf_counter() - start < 5


def test_the_scan_prices_moves_and_the_closes_quadratic_look_back() -> None:
    def path(d: str) -> int:
        return int(wio.svg.scan_svg(f'{_SVG}<path d="{d}"/></svg>').microseconds)

    # bare moves draw nothing, but svgelements builds a segment for each (30-52 µs)
    assert path("M0 0" * 2000) - path("M0 0") >= 2000 * 30
    # each close looks back over its subpath for its move: twice the closes, four times the work
    few, many = path("M0 0" + "Z" * 4000), path("M0 0" + "Z" * 8000)
    assert many > 3.5 * few > 3.5 * 4000 * 4000 / 2 * 0.09  # 0.09 µs a segment passed
    # closes that each follow their own move look back over one segment
    squares = path("M0 0 l1 0 l0 1Z" * 2000)
    assert squares < 2 * path("M0 0 l1 0 l0 1Z" * 1000) + 1


def test_a_use_bomb_is_refused_before_it_is_parsed() -> None:
    document = _use_bomb(7)  # 2 KB that draw 10**7 paths
    assert len(document) < 3000
    work = wio.svg.scan_svg(document)
    assert work.points == 10**7 and work.curves == 10**7
    assert work.microseconds > 10**9  # over a thousand seconds of parsing
    with pytest.raises(wavecore.InvalidParameter, match="10000000 points or more"):
        wio.read_curves(document, "svg", max_points=1_000_000)
    without_hashes = document.replace('href="#', 'href="X')
    assert wio.svg.scan_svg(without_hashes) == work


@pytest.mark.parametrize(
    ("document", "words"),
    [
        (
            _SVG + '<g id="a"><use xlink:href="#b"/></g><g id="b"><use xlink:href="#a"/></g></svg>',
            "cycle",
        ),
        (_SVG + "<g>" * 3000 + "</g>" * 3000 + "</svg>", "nested too deeply"),
        ("<svg><path d='M0 0 L1 1'></svg>", "could not be parsed"),
    ],
)
def test_bad_documents_are_named_by_the_scan(document: str, words: str) -> None:
    with pytest.raises(wavecore.InvalidParameter, match=words):
        wio.svg.scan_svg(document)


def test_arcs_are_counted_at_their_cost() -> None:
    arcs = _SVG + '<path d="M0 0 ' + "a5 5 0 1 1 3 3 " * 1000 + '"/></svg>'
    lines = _SVG + '<path d="M0 0 ' + "l1 1 " * 1000 + '"/></svg>'
    arc_work, line_work = wio.svg.scan_svg(arcs), wio.svg.scan_svg(lines)
    assert arc_work.points == line_work.points == 1000
    assert arc_work.microseconds > 15 * line_work.microseconds


@pytest.mark.parametrize(
    ("document", "words"),
    [
        (_SVG + '<path d="M0 0 a1e300 1e300 0 1 1 1e300 1e-300"/></svg>', "cannot be sampled"),
    ],
)
def test_segments_that_cannot_be_sampled_are_named(document: str, words: str) -> None:
    with pytest.raises(wavecore.InvalidParameter, match=words):
        wavecore.encode_curve_file(document.encode(), "svg")


def test_a_subnormal_drawing_is_kept_exactly() -> None:
    document = _SVG + '<circle r="1e-320" cx="0" cy="0"/></svg>'
    bundle = wavecore.encode_curve_file(document.encode(), "svg")
    data = wavecore.decode_curves(bundle)
    read = wio.read_curves(document, "svg")
    assert [c.tolist() for c in data.curves] == [c.tolist() for c in read.curves]


@pytest.mark.parametrize(
    "document",
    [
        '{"type": "LineString", "coordinates": ' + "[" * 1000 + "0" + "]" * 1000 + "}",
        '{"type": "Feature", "properties": {}, "geometry": '
        + '{"type": "GeometryCollection", "geometries": [' * 950
        + '{"type": "LineString", "coordinates": [[0, 0], [1, 1]]}'
        + "]}" * 950
        + "}",
    ],
)
def test_geojson_nested_too_deeply_is_named(document: str) -> None:
    with pytest.raises(wavecore.InvalidParameter, match="nested too deeply"):
        wio.read_curves(document, "geojson")


_SQUARE = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]


def _svg_bundle(elements: list[dict[str, object]], **sizes: object) -> bytes:
    meta = {"format": "svg", "width": 100, "height": 100, **sizes, "elements": elements}
    return wavecore.encode_curves([_SQUARE], closed=True, metadata=meta)


def test_svg_written_from_hostile_metadata_is_plain_well_formed_svg() -> None:
    from xml.etree import ElementTree

    attributes = {
        'x="1"/><script>alert(1)</script><path fill': "none",  # a name: dropped
        "onload": "alert(1)",  # not an attribute the reader keeps: dropped
        "id": 'a\x01"><script>b',  # a control character (dropped) and markup (quoted)
        "fill": "red",
    }
    for sizes in ({}, {"width": "1e309", "height": "nan"}):
        text = wavecore.decode_curve_file(
            _svg_bundle([{"curves": [0], "attributes": attributes}], **sizes), "svg"
        )
        root = ElementTree.fromstring(text)  # well-formed
        elements = list(root.iter())
        assert [e.tag.split("}")[-1] for e in elements] == ["svg", "path"]
        path = elements[1]
        assert sorted(path.attrib) == ["d", "fill", "id"] and path.get("id") == 'a"><script>b'
        assert all(math.isfinite(float(v)) for v in root.get("viewBox", "").split())


@pytest.mark.parametrize("fmt", ["svg", "geojson"])
def test_metadata_naming_a_curve_twice_is_refused(fmt: str) -> None:
    # 600 bytes naming one 1000-point curve 10 000 times wrote 106 MB of SVG
    if fmt == "svg":
        meta = {"format": "svg", "elements": [{"curves": [0], "attributes": {}}] * 3}
    else:
        line = {"type": "LineString", "coordinates": 0}
        meta = {
            "format": "geojson",
            "document": {"type": "GeometryCollection", "geometries": [line] * 3},
        }
    bundle = wavecore.encode_curves([_SQUARE], closed=False, metadata=meta)
    with pytest.raises(wavecore.BundleError, match="curve 0 twice"):
        wavecore.decode_curve_file(bundle, fmt)


def test_geojson_written_from_1d_curves_reads_back() -> None:
    # RFC 7946 asks for two numbers a position, but a 1-D set writes one: it must read back
    bundle = wavecore.encode_curves([np.arange(10.0)], closed=False, tolerance=1e-9)
    again = wio.read_curves(wavecore.decode_curve_file(bundle, "geojson"), "geojson")
    assert np.array_equal(again.curves[0], wavecore.decode(bundle)[0].reshape(-1, 1))


@pytest.mark.parametrize(
    ("document", "fmt"),
    [
        ('{"type": "LineString", "coordinates": [[1' + "0" * 5000 + ", 0], [0, 1]]}", "geojson"),
        ('{"points": [[1' + "0" * 5000 + ", 0], [0, 1]]}", "json"),
    ],
)
def test_an_integer_python_will_not_convert_is_named(document: str, fmt: str) -> None:
    # valid JSON, but past Python's 4,300 digits: a ValueError that is not a JSONDecodeError
    with pytest.raises(wavecore.InvalidParameter, match="cannot be read: Exceeds the limit"):
        wio.read_curves(document, fmt)


def test_metadata_too_deep_to_decode_is_refused() -> None:
    document = (
        '{"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]},'
        ' "properties": ' + '{"a": ' * 300 + "1" + "}" * 300 + "}"
    )
    with pytest.raises(wavecore.InvalidParameter, match="nested 302 levels deep"):
        wavecore.encode_curve_file(document.encode(), "geojson")
    shallow = document.replace('{"a": ' * 300, '{"a": ' * 150).replace("}" * 300, "}" * 150)
    back = json.loads(
        wavecore.decode_curve_file(wavecore.encode_curve_file(shallow.encode(), "geojson"))
    )
    assert back["type"] == "Feature"


# --- what svgelements is given: values its regular expressions would take quadratic time on ---

_PATH = '<path d="M0 0 L1 1"/>'


@pytest.mark.parametrize(
    ("document", "words"),
    [
        (_SVG + '<g fill="rgb(' + "1" * 3000 + '">' + _PATH * 100 + "</g></svg>", "fill is 3004"),
        (_SVG + '<path transform="' + "rotate(" * 3000 + '" d="M0 0 L1 1"/></svg>', "transform"),
        (
            _SVG + '<g transform="' + "rotate(1) " * 200 + '">' + _PATH + "</g></svg>",
            "more than 1024",
        ),
        (_SVG + '<path style="fill:' + "9" * 40 + '" d="M0 0 L1 1"/></svg>', "more than 32"),
        (_SVG + "<style>.a{stroke:" + "x" * 100 + "}</style>" + _PATH + "</svg>", "stroke is 100"),
    ],
)
def test_overlong_or_malformed_values_are_refused(document: str, words: str) -> None:
    with pytest.raises(wavecore.InvalidParameter, match=words):
        wio.svg.sanitized_svg(document)
    with pytest.raises(wavecore.InvalidParameter, match=words):
        wio.read_curves(document, "svg")


@pytest.mark.parametrize(
    "document",
    [
        # each took svgelements 4-45 s before it was given the sanitized copy
        _SVG + '<g font="' + "1" * 3000 + ' x;x">' + "<text>a</text>" * 200 + _PATH + "</g></svg>",
        _SVG + "<style>" + "a" * 80_000 + "</style>" + _PATH + "</svg>",
        _SVG + '<path clip-path="' + "url(" * 20_000 + '" d="M0 0 L1 1"/></svg>',
        _SVG
        + "<style>*{"
        + ";".join(f"a{i}:1" for i in range(20_000))
        + "}</style>"
        + "<g/>" * 1000
        + _PATH
        + "</svg>",
        _SVG
        + "<g "
        + " ".join(f'a{i}=""' for i in range(20_000))
        + ">"
        + "<g/>" * 2000
        + _PATH
        + "</g></svg>",
        _SVG + "<style>" + "*{fill:red}" * 20_000 + "</style>" + _PATH * 100 + "</svg>",
    ],
)
def test_what_reading_ignores_costs_nothing(document: str) -> None:
    import time

    start = time.perf_counter()
    data = wio.read_curves(document, "svg")
    assert time.perf_counter() - start < 2.0
    assert len(data.curves) >= 1


def test_the_sanitized_copy_keeps_geometry_paint_and_links() -> None:
    document = (
        _SVG + "<defs><style>/* a comment */ .a, path.b { fill: #ff0000; font: 12px x; "
        "stroke-linecap: round } #c{stroke:blue}</style>"
        '<path id="p" class="a" d="M0 0 l10 0 0 10 z"/></defs>'
        '<g transform="translate(5 5) rotate(30)" opacity="0.5" inkscape:label="x" '
        'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape">'
        '<use xlink:href="#p" x="3"/><rect id="c" x="1" y="2" width="3" height="4" rx="1" '
        'style="stroke-width:2;stroke-dasharray:1 2"/><text>label</text>'
        '<polygon points="0 0 5 0 5 5" fill="rgb(1, 2, 3)"/></g></svg>'
    )
    clean = wio.svg.sanitized_svg(document)
    for kept in (
        "translate(5 5) rotate(30)",
        'href="#p"',
        "stroke-width:2",
        ".a{fill:#ff0000}",
        "path.b{fill:#ff0000}",
        "#c{stroke:blue}",
        'points="0 0 5 0 5 5"',
        'rx="1"',
    ):
        assert kept in clean
    for dropped in ("comment", "font", "linecap", "dasharray", "label", "inkscape"):
        assert dropped not in clean
    before = wio.read_curves(document, "svg")
    assert len(before.curves) == 3
    paints = [e["attributes"] for e in before.metadata["elements"]]
    assert {"fill": "#ff0000", "opacity": "0.5"}.items() <= paints[0].items()
    assert paints[1]["stroke"] == "blue" and paints[1]["stroke-width"] == "2"
