"""Curve sets: the guaranteed bound (measured here by brute force), the format, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import curvesets


def _to_polyline(source: np.ndarray, target: np.ndarray, closed: bool) -> float:
    """Exact largest distance from ``source``'s points to ``target``'s polyline (all segments)."""
    nodes = np.concatenate([target, target[:1]]) if closed else target
    if len(nodes) == 1:
        return float(np.max(np.linalg.norm(source - nodes[0], axis=1)))
    a, b = nodes[:-1], nodes[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    p = source[:, None, :]
    t = np.clip(np.einsum("pij,ij->pi", p - a, ab) / length2, 0.0, 1.0)
    gap = p - (a + t[..., None] * ab)
    return float(np.sqrt(np.einsum("pij,pij->pi", gap, gap).min(axis=1)).max())


def _both_ways(original: np.ndarray, decoded: np.ndarray, closed: bool) -> float:
    original = np.asarray(original, dtype=np.float64)
    decoded = np.asarray(decoded, dtype=np.float64)
    if original.ndim == 1:
        original, decoded = original[:, None], decoded.reshape(-1, 1)
    return max(_to_polyline(original, decoded, closed), _to_polyline(decoded, original, closed))


def _star(n: int, points: int = 5) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 1 + 0.4 * np.sign(np.cos(points * t)) * np.abs(np.cos(points * t)) ** 0.3
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


def _walk(n: int, seed: int, d: int = 2) -> np.ndarray:
    return np.cumsum(np.random.default_rng(seed).normal(size=(n, d)), axis=0)


@pytest.mark.parametrize("tolerance", [0.3, 0.03, 0.003, 1e-5])
@pytest.mark.parametrize("wavelet", ["bspline2", "haar", "cdf97"])
def test_bound_holds_both_ways_on_seeded_curves(tolerance: float, wavelet: str) -> None:
    curves = [_star(400), 0.3 * _star(37, 3) + 2, _walk(300, 1), _walk(9, 2), _walk(2, 3)]
    closed = [True, True, False, False, False]
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, wavelet=wavelet)
    decoded = wavecore.decode(bundle)
    assert len(decoded) == len(curves)
    for original, back, flag in zip(curves, decoded, closed, strict=True):
        assert back.dtype == original.dtype and back.shape[1] == original.shape[1]
        assert _both_ways(original, back, flag) <= tolerance


def test_any_dimension_and_mixed_dimensions() -> None:
    t = np.linspace(0, 4 * np.pi, 500)
    helix = np.stack([np.cos(t), np.sin(t), t / 5], axis=1)
    series = np.sin(np.linspace(0, 20, 700))[:, None]
    four = _walk(120, 5, d=4)
    bundle = wavecore.encode_curves([helix, series, four], closed=False, tolerance=0.01)
    out = wavecore.decode(bundle)
    assert [c.shape[1] for c in out] == [3, 1, 4]
    for original, back in zip([helix, series, four], out, strict=True):
        assert _both_ways(original, back, False) <= 0.01


def test_dtype_comes_back_and_float32_bound_holds() -> None:
    curve = _star(300).astype(np.float32)
    out = wavecore.decode(wavecore.encode_curves([curve], tolerance=1e-3))
    assert out[0].dtype == np.float32
    assert _both_ways(curve, out[0], True) <= 1e-3


def test_integer_curves_stay_integer() -> None:
    curve = np.rint(_walk(200, 9) * 10).astype(np.int32)
    out = wavecore.decode(wavecore.encode_curves([curve], closed=False, tolerance=2.0))
    assert out[0].dtype == np.int32
    assert _both_ways(curve, out[0], False) <= 2.0


def test_closing_point_and_flags_come_back() -> None:
    ring = _star(100)
    written_out = np.concatenate([ring, ring[:1]])
    curveset = wavecore.decode_curves(
        wavecore.encode_curves([written_out, ring, _walk(50, 4)], closed=[True, True, False])
    )
    assert curveset.closed == [True, True, False]
    assert np.array_equal(curveset.curves[0][0], curveset.curves[0][-1])
    assert not np.array_equal(curveset.curves[1][0], curveset.curves[1][-1])


def test_metadata_round_trips() -> None:
    meta = {"type": "FeatureCollection", "properties": [{"name": "ü", "n": 3}]}
    curveset = wavecore.decode_curves(wavecore.encode_curves([_star(40)], metadata=meta))
    assert curveset.metadata == meta


def test_default_tolerance_is_a_thousandth_of_the_diagonal() -> None:
    curve = _walk(400, 11) * 7
    bundle = wavecore.encode_curves([curve], closed=False)
    diagonal = float(np.linalg.norm(np.ptp(curve, axis=0)))
    assert wavecore.decode_curves(bundle).tolerance == pytest.approx(1e-3 * diagonal)
    assert _both_ways(curve, wavecore.decode(bundle)[0], False) <= 1e-3 * diagonal


def test_huge_values_and_tiny_tolerance_are_still_bounded() -> None:
    huge = _walk(50, 12) * 1e300
    tiny = _walk(60, 13)
    bundle = wavecore.encode_curves([huge, tiny], closed=False, tolerance=1e-12)
    out = wavecore.decode(bundle)
    # a bound far below the values' resolution: stored exactly rather than missed
    assert np.array_equal(out[0], huge)
    assert _both_ways(tiny, out[1], False) <= 1e-12


@pytest.mark.parametrize("method", ["vertex", "wavelet"])
def test_inspect_gives_the_metadata_length_without_parsing_it(method: str) -> None:
    meta = {"name": "ü", "values": list(range(1000))}
    raw = [np.array([[1.5, 2.5]])]  # one point: stored exactly, ahead of the metadata
    bundle = wavecore.encode_curves([_walk(60, 5), *raw], metadata=meta, method=method)
    info = wavecore.inspect(bundle)
    text = json.dumps(meta, separators=(",", ":"), allow_nan=False).encode()
    assert info["metadata"] is True and info["metadata_bytes"] == len(text)
    plain = wavecore.inspect(wavecore.encode_curves([_walk(60, 5)], method=method))
    assert plain["metadata"] is False and plain["metadata_bytes"] == 0


def test_hundred_curves_cost_little_more_than_their_payloads() -> None:
    rng = np.random.default_rng(21)
    curves = [_star(int(rng.integers(40, 200))) * rng.uniform(0.5, 2) for _ in range(100)]
    bundle = wavecore.encode_curves(curves, tolerance=1e-3)
    alone = 0
    for curve in curves:
        single = wavecore.inspect(wavecore.encode_curves([curve], tolerance=1e-3))
        alone += single["payload_bytes"]
    # the whole set, header and records included, against the coded coefficients of the curves
    # coded one by one: joint coding must pay for the records and the header
    assert len(bundle) - alone <= 64


def test_empty_set() -> None:
    assert wavecore.decode(wavecore.encode_curves([])) == []


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"curves": np.zeros((5, 2))}, "list of (n, d) arrays"),
        ({"curves": [np.zeros((5, 2)), [[np.nan, 0.0]]]}, "curve 1"),
        ({"curves": [np.zeros((0, 2))]}, "curve 0"),
        ({"curves": [np.zeros((5, 2))], "closed": [True, False]}, "one per curve"),
        ({"curves": [np.zeros((5, 2))], "tolerance": -1.0}, "tolerance"),
        ({"curves": [np.zeros((5, 2))], "wavelet": "db4"}, "wavelet"),
        ({"curves": [np.zeros((5, 2))], "level": 99}, "level"),
        ({"curves": [np.zeros((5, 2))], "metadata": {"x": object()}}, "metadata"),
    ],
)
def test_bad_arguments_are_named(kwargs: dict, words: str) -> None:
    curves = kwargs.pop("curves")
    with pytest.raises(
        wavecore.InvalidParameter, match=words.replace("(", r"\(").replace(")", r"\)")
    ):
        wavecore.encode_curves(curves, **kwargs)


def test_damaged_bundles_raise_bundle_error() -> None:
    bundle = wavecore.encode_curves([_star(80), _walk(40, 3)], closed=[True, False])
    rng = np.random.default_rng(5)
    for _ in range(200):
        damaged = bytearray(bundle)
        cut = int(rng.integers(0, len(bundle)))
        if rng.random() < 0.5:
            damaged = damaged[:cut]
        else:
            damaged[cut] ^= 1 << int(rng.integers(0, 8))
        with pytest.raises(wavecore.BundleError):
            wavecore.decode(bytes(damaged))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    count=st.integers(1, 4),
    n=st.integers(1, 120),
    d=st.integers(1, 3),
    closed=st.booleans(),
    log_tolerance=st.floats(-4, 1),
    scale=st.sampled_from([1e-6, 1.0, 1e6]),
)
def test_bound_property(
    seed: int, count: int, n: int, d: int, closed: bool, log_tolerance: float, scale: float
) -> None:
    rng = np.random.default_rng(seed)
    curves = []
    for _ in range(count):
        size = int(rng.integers(1, n + 1))
        kind = rng.integers(0, 3)
        if kind == 0:
            points = rng.normal(size=(size, d))
        elif kind == 1:
            points = np.cumsum(rng.normal(size=(size, d)), axis=0)
        else:  # repeated points and straight runs
            points = np.repeat(rng.integers(-3, 3, size=(max(size // 3, 1), d)), 3, axis=0)
        curves.append(points * scale)
    tolerance = 10.0**log_tolerance * scale
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance)
    out = wavecore.decode(bundle)
    for original, back in zip(curves, out, strict=True):
        assert _both_ways(original, back, closed) <= tolerance


def test_curve_set_is_told_from_other_bundles() -> None:
    single = wavecore.encode_curve(_star(50), closed=True)
    assert not curvesets.is_curve_set(single)
    assert curvesets.is_curve_set(wavecore.encode_curves([_star(50)]))
    assert wavecore.inspect(wavecore.encode_curves([_star(50)]))["kind"] == "curves"


def test_crafted_bundles_with_a_valid_crc_give_curves_or_bundle_error() -> None:
    import struct
    import zlib

    bundle = wavecore.encode_curves(
        [_star(80), _walk(40, 3), _walk(1, 4)], closed=[True, False, False], tolerance=0.01
    )
    rng = np.random.default_rng(8)
    for _ in range(300):
        body = bytearray(bundle[:-4])
        for _ in range(int(rng.integers(1, 4))):
            at = int(rng.integers(5, len(body)))
            body[at] = int(rng.integers(0, 256))
        crafted = bytes(body) + struct.pack("<I", zlib.crc32(bytes(body)))
        try:
            out = wavecore.decode(crafted)
        except wavecore.BundleError:
            continue
        assert isinstance(out, list)
        assert all(isinstance(c, np.ndarray) and c.ndim == 2 for c in out)


@pytest.mark.parametrize("option", [{"keep": 0.5}, {"level": 1}, {"drop_levels": 1}])
def test_decode_refuses_options_a_curve_set_cannot_honour(option: dict[str, float]) -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] * 4)
    bundle = wavecore.encode_curves([square, square[::-1] * 2], tolerance=1e-3)
    with pytest.raises(wavecore.InvalidParameter, match="curve set decodes whole"):
        wavecore.decode(bundle, **option)  # type: ignore[arg-type]


@pytest.mark.parametrize("scale", [1e-200, 1e-310, 5e-324])
@pytest.mark.parametrize("method", ["auto", "vertex", "wavelet"])
def test_tolerances_too_small_to_measure_store_the_curves_as_they_are(
    scale: float, method: str
) -> None:
    """Below 2**-400 the bound cannot be measured (squared distances underflow): the curves are
    stored exactly rather than simplified to what looks like no distance at all."""
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t)], axis=1) * scale
    line = np.stack([t, np.sin(t)], axis=1) * scale
    bundle = wavecore.encode_curves([ring, line], closed=[True, False], method=method)
    back = wavecore.decode_curves(bundle).curves
    assert [c.tolist() for c in back] == [ring.tolist(), line.tolist()]


def _vertex_bomb(count: int, stream: int) -> bytes:
    """A version-2 vertex-form set declaring ``count`` curves over ``stream`` zero bytes."""
    import struct
    import zlib

    from wavecore.varints import encode_varint as varint

    body = (
        b"\x89WVC\x02" + varint(0) + b"\x00" + varint(1) + varint(2) + varint(1) + b"\x00"
        + varint(count) + bytes(stream)
    )  # fmt: skip
    return body + struct.pack("<I", zlib.crc32(body))


def test_a_set_declaring_more_curves_than_a_set_holds_is_refused_at_once() -> None:
    """2 KB of zeros declared 8 M one-point curves (10 s and 2.3 GB to decode or inspect)."""
    import time

    bomb = _vertex_bomb(4096 * 2016, 2000)
    for read in (wavecore.decode_curves, wavecore.inspect, wavecore.decode):
        start = time.perf_counter()
        with pytest.raises(wavecore.BundleError, match="more than the limit 1048576"):
            read(bomb)
        assert time.perf_counter() - start < 0.5
    with pytest.raises(wavecore.InvalidParameter, match="at most 1048576 curves"):
        wavecore.encode_curves([np.zeros((1, 2))] * (curvesets.MAX_CURVES + 1))


def test_inspect_of_a_crafted_set_raises_only_bundle_errors() -> None:
    import struct
    import zlib

    from wavecore.varints import encode_varint as varint

    # 20 bytes declaring 65 536 curves of dimension 65 536: numpy's MemoryError (64 GiB)
    body = b"\x89WVC\x02" + varint(0) + b"\x00" + varint(65536) + varint(2) + varint(1)
    body += b"\x00" + varint(65536)
    bundle = body + struct.pack("<I", zlib.crc32(body))
    with pytest.raises(wavecore.BundleError, match="corrupt curve set"):
        wavecore.inspect(bundle)


def test_metadata_inflating_past_its_bound_is_refused() -> None:
    import struct
    import zlib

    t = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t)], axis=1)
    bundle = wavecore.encode_curves([ring], metadata={"note": "x"})
    small = zlib.compress(b'{"note":"x"}', 9)
    assert bundle.count(small) == 1
    huge = zlib.compress(b'{"a":"' + b"x" * (curvesets.MAX_METADATA_BYTES + 10) + b'"}', 9)
    at = bundle.index(small)
    # the metadata's length varint sits just before it: 1 byte for the small one
    assert bundle[at - 1] == len(small)
    body = bundle[: at - 1] + varint_bytes(len(huge)) + huge + bundle[at + len(small) : -4]
    crafted = body + struct.pack("<I", zlib.crc32(body))
    with pytest.raises(wavecore.BundleError, match="inflates past"):
        wavecore.decode_curves(crafted)
    with pytest.raises(wavecore.InvalidParameter, match="bytes of JSON"):
        wavecore.encode_curves([ring], metadata={"a": "x" * (curvesets.MAX_METADATA_BYTES + 10)})


def varint_bytes(value: int) -> bytes:
    from wavecore.varints import encode_varint

    return bytes(encode_varint(value))
