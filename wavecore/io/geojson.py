"""GeoJSON (RFC 7946): LineString, MultiLineString, Polygon, MultiPolygon, GeometryCollection,
Feature and FeatureCollection.

Every line and ring becomes one curve (rings closed, lines open); the document itself, with
its coordinates replaced by curve numbers, goes into the bundle's metadata, so that features,
properties, ids and foreign members come back as they were.  Positions may have 2 or 3
coordinates (the third, elevation, is coded like the others).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..errors import InvalidParameter
from .common import CurveData, as_text, finite_array

__all__ = ["read_geojson", "write_geojson"]

_LINE_TYPES = {"LineString": 1, "MultiLineString": 2, "Polygon": 2, "MultiPolygon": 3}


class _Reader:
    def __init__(self) -> None:
        self.curves: list[np.ndarray] = []
        self.closed: list[bool] = []

    def line(self, coords: Any, where: str, ring: bool) -> int:
        arr = finite_array(coords, where, min_points=4 if ring else 2)
        if arr.shape[1] > 3:  # (one is taken too: GeoJSON written from 1-D curves reads back)
            msg = f"{where}: positions have {arr.shape[1]} numbers; GeoJSON allows 2 or 3"
            raise InvalidParameter(msg)
        self.curves.append(arr)
        self.closed.append(ring)
        return len(self.curves) - 1

    def nested(self, coords: Any, depth: int, where: str, ring: bool) -> Any:
        if depth == 1:
            return self.line(coords, where, ring)
        if not isinstance(coords, list):
            msg = f"{where}: expected a list, got {type(coords).__name__}"
            raise InvalidParameter(msg)
        return [self.nested(c, depth - 1, f"{where}[{i}]", ring) for i, c in enumerate(coords)]

    def geometry(self, geometry: Any, where: str) -> Any:
        if geometry is None:
            return None
        if not isinstance(geometry, dict):
            msg = f"{where}: a geometry must be an object, not {type(geometry).__name__}"
            raise InvalidParameter(msg)
        kind = geometry.get("type")
        skeleton = dict(geometry)
        if kind == "GeometryCollection":
            parts = geometry.get("geometries")
            if not isinstance(parts, list):
                msg = f"{where}.geometries: expected a list"
                raise InvalidParameter(msg)
            skeleton["geometries"] = [
                self.geometry(g, f"{where}.geometries[{i}]") for i, g in enumerate(parts)
            ]
            return skeleton
        if kind not in _LINE_TYPES:
            accepted = ", ".join([*_LINE_TYPES, "GeometryCollection"])
            msg = f"{where}: geometry type {kind!r} is not a curve; accepted: {accepted}"
            raise InvalidParameter(msg)
        if "coordinates" not in geometry:
            msg = f"{where}: a {kind} needs 'coordinates'"
            raise InvalidParameter(msg)
        ring = kind in ("Polygon", "MultiPolygon")
        skeleton["coordinates"] = self.nested(
            geometry["coordinates"], _LINE_TYPES[kind], f"{where}.coordinates", ring
        )
        return skeleton

    def feature(self, feature: Any, where: str) -> Any:
        if not isinstance(feature, dict) or feature.get("type") != "Feature":
            msg = f"{where}: expected a Feature object"
            raise InvalidParameter(msg)
        skeleton = dict(feature)
        skeleton["geometry"] = self.geometry(feature.get("geometry"), f"{where}.geometry")
        return skeleton


def read_geojson(data: bytes | str) -> CurveData:
    """Read a GeoJSON document's lines and rings.

    Raises
    ------
    InvalidParameter
        Naming the place in the document (``features[3].geometry.coordinates[0]``) and what is
        wrong there, or for a document nested too deeply to read.
    """
    try:
        return _read_geojson(data)
    except RecursionError:  # the JSON parser's or the reader's (nested collections)
        msg = "GeoJSON is nested too deeply"
        raise InvalidParameter(msg) from None


def _read_geojson(data: bytes | str) -> CurveData:
    try:
        doc = json.loads(as_text(data, "GeoJSON"))
    except json.JSONDecodeError as exc:
        msg = f"GeoJSON is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
        raise InvalidParameter(msg) from None
    except ValueError as exc:  # valid JSON Python refuses: an integer of over 4,300 digits
        msg = f"GeoJSON cannot be read: {str(exc).split(';')[0]}"[:300]
        raise InvalidParameter(msg) from None
    if not isinstance(doc, dict) or "type" not in doc:
        msg = "GeoJSON must be an object with a 'type'"
        raise InvalidParameter(msg)
    reader = _Reader()
    if doc["type"] == "FeatureCollection":
        features = doc.get("features")
        if not isinstance(features, list):
            msg = "FeatureCollection: 'features' must be a list"
            raise InvalidParameter(msg)
        skeleton = dict(doc)
        skeleton["features"] = [reader.feature(f, f"features[{i}]") for i, f in enumerate(features)]
    elif doc["type"] == "Feature":
        skeleton = reader.feature(doc, "feature")
    else:
        skeleton = reader.geometry(doc, "geometry")
    return CurveData(reader.curves, reader.closed, {"format": "geojson", "document": skeleton})


def _positions(points: np.ndarray, closed: bool) -> list[list[float]]:
    if closed and (len(points) < 2 or not np.array_equal(points[0], points[-1])):
        points = np.concatenate([points, points[:1]])
    out: list[list[float]] = np.asarray(points, dtype=np.float64).tolist()
    return out


def _fill(node: Any, depth: int, data: CurveData, used: set[int]) -> Any:
    if depth == 1:
        if not isinstance(node, int) or not 0 <= node < len(data.curves):
            msg = f"GeoJSON structure refers to curve {node!r}, not in the bundle"
            raise InvalidParameter(msg[:200])
        if node in used:  # the reader names each curve once: a bundle naming one again
            msg = f"GeoJSON structure refers to curve {node} twice"  # would repeat its points
            raise InvalidParameter(msg)
        used.add(node)
        return _positions(data.curves[node], data.closed[node])
    return [_fill(child, depth - 1, data, used) for child in node]


def _fill_geometry(geometry: Any, data: CurveData, used: set[int]) -> Any:
    if geometry is None:
        return None
    out = dict(geometry)
    if geometry.get("type") == "GeometryCollection":
        out["geometries"] = [_fill_geometry(g, data, used) for g in geometry["geometries"]]
    else:
        depth = _LINE_TYPES[geometry["type"]]
        out["coordinates"] = _fill(geometry["coordinates"], depth, data, used)
    return out


def _generic_document(data: CurveData) -> dict[str, Any]:
    """A FeatureCollection for curves that did not come from GeoJSON."""
    features = []
    for index, (points, closed) in enumerate(zip(data.curves, data.closed, strict=True)):
        geometry: dict[str, Any]
        if closed:
            geometry = {"type": "Polygon", "coordinates": [_positions(points, True)]}
        else:
            geometry = {"type": "LineString", "coordinates": _positions(points, False)}
        properties: dict[str, Any] = {"curve": index}
        features.append({"type": "Feature", "properties": properties, "geometry": geometry})
    return {"type": "FeatureCollection", "features": features}


def write_geojson(data: CurveData) -> bytes:
    """GeoJSON text: the original document's structure when there is one, else a
    FeatureCollection of LineStrings (open curves) and Polygons (closed ones)."""
    document = data.metadata.get("document") if data.metadata.get("format") == "geojson" else None
    used: set[int] = set()
    if document is None:
        out = _generic_document(data)
    elif document.get("type") == "FeatureCollection":
        out = dict(document)
        out["features"] = [
            {**f, "geometry": _fill_geometry(f.get("geometry"), data, used)}
            for f in document["features"]
        ]
    elif document.get("type") == "Feature":
        out = {**document, "geometry": _fill_geometry(document.get("geometry"), data, used)}
    else:
        out = _fill_geometry(document, data, used)
    return json.dumps(out, separators=(",", ":"), allow_nan=False).encode()
