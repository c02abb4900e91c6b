"""GeoJSON and SVG through the service: in process and against the live uvicorn server."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest

pytestmark = pytest.mark.anyio
pytest.importorskip("svgelements", reason="SVG reading is the svg extra (part of the test extra)")

GEOJSON = "application/geo+json"
SVG_TYPE = "image/svg+xml"


def _ring(n: int, radius: float) -> list[list[float]]:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.stack([radius * np.cos(t), radius * np.sin(t) * 0.6], axis=1)
    return np.concatenate([pts, pts[:1]]).tolist()


FEATURES = {
    "type": "FeatureCollection",
    "features": [
        {
            "type": "Feature",
            "properties": {"name": "field", "crop": "wheat"},
            "geometry": {"type": "Polygon", "coordinates": [_ring(120, 5.0), _ring(40, 1.0)]},
        },
        {
            "type": "Feature",
            "properties": {"name": "road"},
            "geometry": {
                "type": "LineString",
                "coordinates": np.cumsum(
                    np.random.default_rng(2).normal(size=(200, 2)), 0
                ).tolist(),
            },
        },
    ],
}

SVG = b"""<svg xmlns="http://www.w3.org/2000/svg" width="120" height="80">
<path id="s" d="M 10 40 Q 40 0 70 40 T 110 40" fill="none" stroke="green"/>
<ellipse cx="60" cy="40" rx="30" ry="15" fill="orange"/>
</svg>"""


def _max_gap(a: list, b: list) -> float:
    """Largest distance from a point of ``a`` to the polyline ``b`` (exact, every segment)."""
    p, nodes = np.asarray(a, float)[:, None, :], np.asarray(b, float)
    s, e = nodes[:-1], nodes[1:]
    ab = e - s
    t = np.clip(np.einsum("pij,ij->pi", p - s, ab) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
    gap = p - (s + t[..., None] * ab)
    return float(np.sqrt((gap * gap).sum(-1)).min(1).max())


async def test_geojson_round_trip(client: httpx.AsyncClient) -> None:
    r = await client.post(
        "/v1/curves/encode",
        params={"tolerance": 0.02},
        content=json.dumps(FEATURES),
        headers={"content-type": GEOJSON},
    )
    assert r.status_code == 200, r.text
    assert r.headers["x-wavecore-curves"] == "3"
    assert float(r.headers["x-wavecore-max-error"]) == 0.02
    bundle = r.content
    r = await client.post("/v1/bundles/reconstruct", content=bundle)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith(GEOJSON)
    back = r.json()
    assert [f["properties"] for f in back["features"]] == [
        f["properties"] for f in FEATURES["features"]
    ]
    outer = back["features"][0]["geometry"]["coordinates"][0]
    original = FEATURES["features"][0]["geometry"]["coordinates"][0]
    assert max(_max_gap(original, outer), _max_gap(outer, original)) <= 0.02
    road = back["features"][1]["geometry"]["coordinates"]
    road0 = FEATURES["features"][1]["geometry"]["coordinates"]
    assert max(_max_gap(road0, road), _max_gap(road, road0)) <= 0.02
    # another format by format= and by Accept
    r = await client.post("/v1/bundles/reconstruct", params={"format": "svg"}, content=bundle)
    assert r.status_code == 200 and r.headers["content-type"].startswith(SVG_TYPE)
    assert r.text.count("<path") == 3
    r = await client.post(
        "/v1/bundles/reconstruct", content=bundle, headers={"accept": "application/json"}
    )
    assert r.status_code == 200 and r.json()["kind"] == "curves"
    r = await client.post("/v1/bundles/reconstruct", params={"format": "png"}, content=bundle)
    assert r.status_code == 406 and "geojson" in r.json()["detail"]
    info = (await client.post("/v1/bundles/inspect", content=bundle)).json()
    assert info["kind"] == "curves" and info["count"] == 3


async def test_svg_round_trip(client: httpx.AsyncClient) -> None:
    r = await client.post(
        "/v1/curves/encode",
        params={"tolerance": 0.1, "wavelet": "cdf97"},
        content=SVG,
        headers={"content-type": SVG_TYPE},
    )
    assert r.status_code == 200, r.text
    r2 = await client.post("/v1/bundles/reconstruct", content=r.content)
    assert r2.status_code == 200 and r2.headers["content-type"].startswith(SVG_TYPE)
    assert 'id="s"' in r2.text and 'fill="orange"' in r2.text
    r3 = await client.post(
        "/v1/bundles/reconstruct", content=r.content, headers={"accept": GEOJSON}
    )
    assert r3.status_code == 200
    kinds = [f["geometry"]["type"] for f in r3.json()["features"]]
    assert kinds == ["LineString", "Polygon"]


@pytest.mark.parametrize(
    ("body", "media_type", "words"),
    [
        (b"{oops", GEOJSON, "not valid JSON"),
        (b'{"type": "Point", "coordinates": [1, 2]}', GEOJSON, "'Point' is not a curve"),
        (
            b'{"type": "LineString", "coordinates": [[0, 0], [1, "x"]]}',
            GEOJSON,
            "coordinates",
        ),
        (b"<svg><path d=", SVG_TYPE, "could not be parsed"),
        (b'<svg xmlns="http://www.w3.org/2000/svg"/>', SVG_TYPE, "no shape"),
    ],
)
async def test_bad_files_are_named(
    client: httpx.AsyncClient, body: bytes, media_type: str, words: str
) -> None:
    r = await client.post("/v1/curves/encode", content=body, headers={"content-type": media_type})
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    assert words in r.json()["detail"]


async def test_too_many_points_cost_413(make_client) -> None:  # type: ignore[no-untyped-def]
    line = {"type": "LineString", "coordinates": [[i, i % 7] for i in range(3000)]}
    async with make_client(max_points=1000) as client:
        r = await client.post(
            "/v1/curves/encode", content=json.dumps(line), headers={"content-type": GEOJSON}
        )
    assert r.status_code == 413 and "3000 points" in r.json()["detail"]


async def test_json_contract_unchanged(client: httpx.AsyncClient) -> None:
    r = await client.post("/v1/curves/encode", json={"points": _ring(50, 1.0)[:-1], "closed": True})
    assert r.status_code == 200
    r = await client.post("/v1/bundles/reconstruct", content=r.content)
    assert r.json()["kind"] == "curve"


async def test_openapi_lists_the_curve_file_bodies(client: httpx.AsyncClient) -> None:
    """/docs and schema-driven clients learn that /v1/curves/encode takes GeoJSON and SVG."""
    spec = (await client.get("/openapi.json")).json()
    content = spec["paths"]["/v1/curves/encode"]["post"]["requestBody"]["content"]
    assert {"application/json", GEOJSON, SVG_TYPE} <= set(content)
    assert content[GEOJSON]["schema"]["type"] == "object"
    assert "FeatureCollection" in content[GEOJSON]["schema"]["properties"]["type"]["enum"]
    assert content[SVG_TYPE]["schema"]["type"] == "string"
    # the JSON body of one curve keeps its schema
    assert "points" in json.dumps(content["application/json"]["schema"])
    # and what the document advertises is what the route takes
    for media_type, body in ((GEOJSON, json.dumps(FEATURES).encode()), (SVG_TYPE, SVG)):
        r = await client.post(
            "/v1/curves/encode",
            content=body,
            params={"tolerance": 0.05},
            headers={"content-type": media_type},
        )
        assert r.status_code == 200, (media_type, r.text)


@pytest.mark.parametrize("method", ["wavelet", "vertex"])
async def test_method_query_picks_the_form(client: httpx.AsyncClient, method: str) -> None:
    r = await client.post(
        "/v1/curves/encode",
        content=json.dumps(FEATURES).encode(),
        params={"tolerance": 0.05, "method": method},
        headers={"content-type": GEOJSON},
    )
    assert r.status_code == 200, r.text
    info = (await client.post("/v1/bundles/inspect", content=r.content)).json()
    assert info["method"] == method
    back = await client.post("/v1/bundles/reconstruct", content=r.content)
    assert back.status_code == 200
    assert back.json()["features"][0]["properties"] == {"name": "field", "crop": "wheat"}


async def test_a_file_of_many_curves_costs_its_search(make_client) -> None:  # type: ignore[no-untyped-def]
    # A curve set is searched curve by curve (some 6 ms a short curve): a file of many short
    # curves is refused by what that costs, before any is coded.  max_pixels 20 000: 100 000
    # samples a request, 6 curves of 2 points (16 584 samples each), not 7.
    def lines(count: int) -> bytes:
        coordinates = [[[float(i), 0.0], [float(i), 1.0]] for i in range(count)]
        return json.dumps({"type": "MultiLineString", "coordinates": coordinates}).encode()

    async with make_client(max_pixels=20_000) as client:
        r = await client.post(
            "/v1/curves/encode", content=lines(7), headers={"content-type": GEOJSON}
        )
        assert r.status_code == 413, r.text
        assert "7 curves of 14 points" in r.json()["detail"]
        r = await client.post(
            "/v1/curves/encode", content=lines(6), headers={"content-type": GEOJSON}
        )
        assert r.status_code == 200, r.text
        assert r.headers["X-Wavecore-Curves"] == "6"


async def test_svg_from_a_hostile_bundle_runs_nothing(client: httpx.AsyncClient) -> None:
    # the metadata named an attribute '"/><script>…': a page posting the bundle to the API as
    # a form got an SVG that ran the script at the service's origin
    import wavecore

    name = 'x="1"/><script>alert(document.domain)</script><path fill'
    meta = {"format": "svg", "width": 100, "height": 100}
    meta["elements"] = [{"curves": [0], "attributes": {name: "none", "fill": "red"}}]
    square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]
    bundle = wavecore.encode_curves([square], metadata=meta)
    r = await client.post("/v1/bundles/reconstruct", params={"format": "svg"}, content=bundle)
    assert r.status_code == 200 and r.headers["content-type"].startswith(SVG_TYPE)
    assert "<script" not in r.text and 'fill="red"' in r.text
    # and whatever an answer holds, a browser shown it runs nothing and sniffs no other type
    assert r.headers["content-security-policy"] == "default-src 'none'; sandbox"
    assert r.headers["x-content-type-options"] == "nosniff"
    page = await client.get("/")
    assert "script-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["x-content-type-options"] == "nosniff"
