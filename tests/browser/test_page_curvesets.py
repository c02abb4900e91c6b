"""The page's curve tab opens GeoJSON and SVG files and draws them (real Chromium, real server)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import wavecore

pytestmark = [pytest.mark.browser, pytest.mark.long]
pytest.importorskip("svgelements", reason="SVG reading is the svg extra (part of the test extra)")


def _ring(n: int, radius: float, dx: float) -> list[list[float]]:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.stack([dx + radius * np.cos(t), radius * np.sin(t)], axis=1)
    return np.concatenate([pts, pts[:1]]).tolist()


def test_geojson_file_is_drawn_with_every_curve(page: Any, tmp_path: Path, artifacts: Path):
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"name": "ring"},
                "geometry": {"type": "Polygon", "coordinates": [_ring(90, 2, 0), _ring(30, 1, 0)]},
            },
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": [[3, 0], [4, 1], [5, 0], [6, 2]]},
            },
        ],
    }
    path = tmp_path / "layer.geojson"
    path.write_text(json.dumps(doc))
    page.click("label:has(input[name=mode][value=curve])")
    page.set_input_files("#curve-file", str(path))
    page.wait_for_selector("#curve-plot[data-curves='3']")
    assert page.locator("#curve-plot path.set-curve").count() == 3
    assert "3 curves from layer.geojson" in page.inner_text("#curveset-info")
    with page.expect_download() as info:
        page.click("#download")
    curveset = wavecore.decode_curves(Path(info.value.path()).read_bytes())
    assert curveset.closed == [True, True, False]
    assert curveset.metadata["document"]["features"][0]["properties"] == {"name": "ring"}
    page.screenshot(path=artifacts / "curveset-geojson.png", full_page=True)


def test_svg_file_is_drawn(page: Any, tmp_path: Path, artifacts: Path):
    path = tmp_path / "drawing.svg"
    path.write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="100" height="60">'
        '<path d="M 5 30 C 25 0 45 60 65 30" fill="none" stroke="black"/>'
        '<circle cx="70" cy="30" r="20"/></svg>'
    )
    page.click("label:has(input[name=mode][value=curve])")
    page.set_input_files("#curve-file", str(path))
    page.wait_for_selector("#curve-plot[data-curves='2']")
    assert page.locator("#curve-plot path.set-curve").count() == 2
    assert int(page.get_attribute("#curve-plot", "data-bytes")) > 0
    page.screenshot(path=artifacts / "curveset-svg.png", full_page=True)


def test_a_broken_geojson_file_gets_a_message_next_to_the_file_input(page: Any, tmp_path: Path):
    path = tmp_path / "broken.geojson"
    path.write_text(json.dumps({"type": "Point", "coordinates": [1, 2]}))
    page.click("label:has(input[name=mode][value=curve])")
    page.set_input_files("#curve-file", str(path))
    page.wait_for_selector("#curve-file-error:not([hidden])")
    assert "not a curve" in page.inner_text("#curve-file-error")
