"""The vertex form of curve sets (format version 2) and the choice between the two forms.

The bound is measured here by brute force (every point against every segment), independently
of the encoder's own check.
"""

from __future__ import annotations

import binascii
import itertools
import math
import struct
import time
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import curvecoder, curvesets

#: the versions of a plane set of the vertex form (5: version 4 with learnt priors; 6: 5 with
#: translated copies of earlier curves)
_PLANE = (curvesets.PLANE_VERSION, curvesets.PRIOR_VERSION, curvesets.COPY_VERSION)


def _start(bundle: bytes) -> int:
    """The length of a set's preamble: 3 for version 6 (``89 57 86``), else 5 (magic, version)."""
    return 3 if bundle[:2] == b"\x89W" and bundle[2] >= 0x80 else 5


def _version(bundle: bytes) -> int:
    """A set's version, read from its preamble (docs/curves.md)."""
    return bundle[2] & 0x7F if _start(bundle) == 3 else bundle[4]


def _head(bundle: bytes) -> int:
    """A plane set's head (version 4's bit layout; version 6 packs it with the tolerance and
    the count in the 3 bytes after its preamble)."""
    if _start(bundle) == 3:
        return curvesets._unpack_head(bundle[3:6])[0]
    return int.from_bytes(bundle[5:7], "little")


def _to_polyline(source: np.ndarray, target: np.ndarray, closed: bool) -> float:
    nodes = np.concatenate([target, target[:1]]) if closed and len(target) > 2 else target
    if len(nodes) == 1:
        return float(np.max(np.linalg.norm(source - nodes[0], axis=1)))
    a, b = nodes[:-1], nodes[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    worst = 0.0
    for start in range(0, len(source), 512):
        p = source[start : start + 512, None, :]
        t = np.clip(np.einsum("pij,ij->pi", p - a, ab) / length2, 0.0, 1.0)
        gap = p - (a + t[..., None] * ab)
        worst = max(worst, float(np.sqrt(np.einsum("pij,pij->pi", gap, gap).min(axis=1)).max()))
    return worst


def _both_ways(original: np.ndarray, decoded: np.ndarray, closed: bool) -> float:
    original = np.asarray(original, dtype=np.float64)
    decoded = np.asarray(decoded, dtype=np.float64)
    if closed and len(original) > 2 and np.array_equal(original[0], original[-1]):
        original = original[:-1]
    if closed and len(decoded) > 2 and np.array_equal(decoded[0], decoded[-1]):
        decoded = decoded[:-1]
    return max(_to_polyline(original, decoded, closed), _to_polyline(decoded, original, closed))


def _walk(n: int, seed: int, d: int = 2) -> np.ndarray:
    return np.cumsum(np.random.default_rng(seed).normal(size=(n, d)), axis=0)


def _ring(n: int, radius: float = 1.0) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = radius * (1 + 0.3 * np.cos(5 * t))
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


@pytest.mark.parametrize("tolerance", [0.5, 0.05, 0.002, 1e-6])
@pytest.mark.parametrize("d", [1, 2, 3])
def test_vertex_form_keeps_the_bound(tolerance: float, d: int) -> None:
    curves = [_walk(500, 1, d), _walk(30, 2, d), _walk(2, 3, d), _walk(1, 4, d), _walk(3, 5, d)]
    closed = [False, True, True, False, True]
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, method="vertex")
    # plane sets are written as version 4, others as version 2
    assert _version(bundle) in (_PLANE if d == 2 else (curvesets.VERTEX_VERSION,))
    out = wavecore.decode_curves(bundle)
    assert out.closed == closed and out.tolerance == tolerance
    for original, back, flag in zip(curves, out.curves, closed, strict=True):
        assert back.shape[1] == d and back.dtype == original.dtype
        assert _both_ways(original, back, flag) <= tolerance


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    count=st.integers(1, 6),
    d=st.integers(1, 3),
    tolerance=st.floats(1e-4, 10.0),
    scale=st.floats(1e-3, 1e4),
    dtype=st.sampled_from(["float64", "float32", "int32"]),
    closed=st.booleans(),
)
def test_vertex_bound_property(
    seed: int, count: int, d: int, tolerance: float, scale: float, dtype: str, closed: bool
) -> None:
    rng = np.random.default_rng(seed)
    curves = []
    for _ in range(count):
        n = int(rng.integers(1, 120))
        steps = rng.normal(size=(n, d)) * rng.choice([0.0, 0.1, 1.0, 10.0], size=(n, 1))
        curves.append((np.cumsum(steps, axis=0) * scale).astype(dtype))
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, method="vertex")
    out = wavecore.decode(bundle)
    for original, back in zip(curves, out, strict=True):
        assert back.dtype == original.dtype
        assert _both_ways(original, back, closed) <= tolerance


def test_repeated_closing_point_comes_back() -> None:
    ring = _ring(60)
    again = np.concatenate([ring, ring[:1]])
    out = wavecore.decode(wavecore.encode_curves([again, ring], tolerance=0.01, method="vertex"))
    assert np.array_equal(out[0][0], out[0][-1]) and not np.array_equal(out[1][0], out[1][-1])


def test_auto_keeps_the_smaller_form() -> None:
    for curves, tolerance in (([_ring(300)], 1e-5), ([_walk(400, 6)], 0.5)):
        sizes = {
            method: len(wavecore.encode_curves(curves, tolerance=tolerance, method=method))
            for method in ("wavelet", "vertex")
        }
        auto = wavecore.encode_curves(curves, tolerance=tolerance)
        assert len(auto) == min(sizes.values())
        assert wavecore.encode_curves(curves, tolerance=tolerance, method="auto") == auto


def test_vertex_falls_back_to_the_wavelet_form_where_it_cannot() -> None:
    mixed = [_walk(50, 1, 2), _walk(50, 2, 3)]
    bundle = wavecore.encode_curves(mixed, closed=False, tolerance=0.01, method="vertex")
    assert _version(bundle) == curvesets.VERSION
    huge = [np.array([[1e150, 0.0], [1e150, 1.0], [-1e150, 2.0]])]
    bundle = wavecore.encode_curves(huge, closed=False, tolerance=1e-3, method="vertex")
    assert _version(bundle) == curvesets.VERSION
    assert _both_ways(huge[0], wavecore.decode(bundle)[0], False) <= 1e-3


@pytest.mark.parametrize("scale", [2.0**700, 1e300])
def test_huge_coordinates_are_coded_as_at_unit_scale(scale: float) -> None:
    # squared distances overflow past 1e154: such sets were stored raw, with warnings
    curves = [_walk(400, 5), _ring(100)]
    flags = [False, True]
    exact = math.ldexp(1.0, -math.frexp(scale)[1])  # a power of two: measures exactly
    for method in ("vertex", "wavelet"):
        unit = wavecore.encode_curves(curves, closed=flags, tolerance=0.05, method=method)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            big = wavecore.encode_curves(
                [c * scale for c in curves], closed=flags, tolerance=0.05 * scale, method=method
            )
            decoded = wavecore.decode(big)
        assert _version(big) == _version(unit)
        # the wavelet form codes the same integers; the vertex form, without parabolas
        assert len(big) == len(unit) if method == "wavelet" else len(big) < 1.5 * len(unit)
        assert len(big) < 0.2 * 16 * 500  # the raw values' bytes
        for curve, out, closed in zip(curves, decoded, flags, strict=True):
            gap = _both_ways(curve * scale * exact, out * exact, closed)
            assert gap <= 0.05 * scale * exact


def test_a_curve_stored_exactly_beside_huge_ones_keeps_every_bit() -> None:
    # a one-point curve is stored exactly; scaled down with its set by 2**-997 and back, 1e-10
    # would pass through the subnormals and lose bits
    huge = _walk(50, 1) * 1e300
    tiny = np.array([[1e-10, 3.3e-11]])
    for tolerance in (1e-12, None):
        bundle = wavecore.encode_curves(
            [huge, tiny], closed=False, tolerance=tolerance, method="wavelet"
        )
        assert np.array_equal(wavecore.decode(bundle)[1], tiny)


def test_bad_method_is_named() -> None:
    with pytest.raises(wavecore.InvalidParameter, match="method"):
        wavecore.encode_curves([_ring(10)], method="fractal")


def test_hundred_curves_header_is_small() -> None:
    rng = np.random.default_rng(3)
    curves = [_ring(int(rng.integers(20, 200)), float(rng.uniform(0.5, 3))) for _ in range(100)]
    bundle = wavecore.encode_curves(curves, tolerance=1e-3, method="vertex")
    info = wavecore.inspect(bundle)
    assert info["count"] == 100 and info["total_bytes"] == len(bundle)
    # everything outside the coded stream (magic, fields, CRC): the records are in the stream
    assert info["header_bytes"] <= 64
    alone = sum(
        wavecore.inspect(wavecore.encode_curves([c], tolerance=1e-3, method="vertex"))[
            "payload_bytes"
        ]
        for c in curves
    )
    assert len(bundle) <= alone + 64


def test_inspect_describes_the_vertex_form() -> None:
    curves = [_ring(50), _walk(20, 1)]
    bundle = wavecore.encode_curves(
        curves, closed=[True, False], tolerance=0.01, method="vertex", metadata={"k": [1, 2]}
    )
    info = wavecore.inspect(bundle)
    decoded = wavecore.decode_curves(bundle)
    assert info["method"] == "vertex" and info["count"] == 2
    assert info["points"] == [len(c) for c in decoded.curves]
    assert info["closed"] == [True, False] and info["metadata"] is True
    assert decoded.metadata == {"k": [1, 2]}


def test_tolerance_is_kept_or_tightened() -> None:
    curve = _walk(30, 2)
    for tolerance in (0.1, 3.0, 1e-7, 125e-9):  # short decimals: exactly
        bundle = wavecore.encode_curves([curve], tolerance=tolerance, method="vertex")
        assert wavecore.decode_curves(bundle).tolerance == tolerance
    for tolerance in (0.1 + 0.2, np.pi, 1e-300, 7.123456789e39):  # others: never looser
        bundle = wavecore.encode_curves([curve], tolerance=tolerance, method="vertex")
        got = wavecore.decode_curves(bundle)
        assert tolerance * (1 - 2**-23) <= got.tolerance <= tolerance
        assert _both_ways(curve, got.curves[0], True) <= got.tolerance


def test_crafted_vertex_bundles_give_curves_or_bundle_error() -> None:
    bundle = wavecore.encode_curves(
        [_ring(80), _walk(40, 3), _walk(1, 4)],
        closed=[True, False, False],
        tolerance=0.01,
        method="vertex",
    )
    assert _version(bundle) in _PLANE
    assert _head(bundle) & 0x40  # the ring's arcs are bulged segments
    rng = np.random.default_rng(9)
    for trial in range(450):
        body = bytearray(bundle[: -curvesets.check_size(bundle)])
        start, version = _start(bundle), _version(bundle)
        if trial % 5 == 0:  # the same bytes read as another vertex version (the 4-byte magic)
            version = (curvesets.VERTEX_VERSION, curvesets.BULGED_VERSION)[trial % 2]
            body[:start] = curvesets.MAGIC + bytes([version])
            start = 5
        if trial % 3 == 0:  # cut or extend the stream
            body = body[: int(rng.integers(start, len(body)))] + bytes(int(rng.integers(0, 9)))
        for _ in range(int(rng.integers(1, 4))):
            at = int(rng.integers(start, len(body)))
            body[at] = int(rng.integers(0, 256))
        crafted = curvesets._with_check(body, version)  # the check its version ends in
        try:
            out = wavecore.decode(crafted)
        except wavecore.BundleError:
            continue
        assert isinstance(out, list)
        assert all(isinstance(c, np.ndarray) and c.ndim == 2 for c in out)
        assert sum(c.size for c in out) <= curvesets.VERTEX_PER_BYTE * (len(crafted) + 16)


def test_coder_round_trips_extreme_values() -> None:
    rng = np.random.default_rng(4)
    limit = (1 << 46) - 1
    lattice = rng.integers(-limit, limit, size=(300, 2))
    lattice[100:200] = 0
    counts = np.array([1, 99, 150, 50])
    closed = np.array([0, 1, 0, 1])
    repeated = np.array([0, 1, 0, 0])
    stream = curvecoder.encode_set(lattice, counts, closed, repeated, 2)
    back = curvecoder.decode_set(stream, 4, 2, 2, False, 300)
    assert back is not None
    for got, want in zip(back, (lattice, counts, closed, repeated), strict=True):
        assert np.array_equal(got, want)
    assert curvecoder.decode_set(stream, 4, 2, 2, False, 299) is None  # more than allowed


@pytest.mark.slow
def test_cost_is_linear_for_long_curves_and_many_curves() -> None:
    def seconds(curves: list[np.ndarray]) -> float:
        start = time.perf_counter()
        bundle = wavecore.encode_curves(curves, closed=False, tolerance=0.05, method="vertex")
        wavecore.decode(bundle)
        return time.perf_counter() - start

    seconds([_walk(500, 7)])  # compiled code warmed up
    small = min(seconds([_walk(5_000, 7)]) for _ in range(3))
    # ten times the points: linear cost is ~10x (a generous margin for a shared machine)
    assert seconds([_walk(50_000, 7)]) < 40 * max(small, 0.005)
    few = min(seconds([_walk(4, seed) for seed in range(1_000)]) for _ in range(2))
    assert seconds([_walk(4, seed) for seed in range(10_000)]) < 40 * max(few, 0.005)


# Bundles written by this release (one per form), kept as bytes: every later reader must decode
# them.  The check is against the curves they were made from (the bound), not against bytes.
FROZEN = {
    "wavelet": (
        "89575643010900007b14ae47e17a843f45020204800128c10112a001041d0607071cffc588d5e886dc"
        "e8e341906c5259761174dca5eb2224d356c2d5b555053ab1558aa0065e5b79f799e306fe37614bd8ba"
        "1978daab56ca4bcc4d55b2524a2bcaaf4acd53aa0500343605f0225b9b13"
    ),
    "vertex": (
        "8957564302290002050106021978daab56ca4bcc4d55b2524a2bcaaf4acd53aa0500343605f0be7f7e"
        "d72560226396195a1105e2dc5116233680dde8687853f2832ebf0bf417bf4e4e5f8ccd2f0e2b3f7efd"
        "2adca65435f5fd"
    ),
    # version 3 (bulged segments), written by the release that introduced it
    "bulged": (
        "8957564303090002050106021978daab56ca4bcc4d55b2524a2bcaaf4acd53aa0500343605f0b8fd09"
        "2ed58c5de4deb85a7f9ba76ddd0398f5e0e7b6c14f77e74e8587d393788e"
    ),
    # version 4 (plane curves, 2-byte head), written by the release that introduced it
    "plane": (
        "8957564304450c0501021978daab56ca4bcc4d55b2524a2bcaaf4acd53aa0500343605f0b8fd092ed5"
        "8c5de4deb85a7f9ba76ddd0398f5e0e7b6c14f77e74e85877ea31a6a"
    ),
}


@pytest.mark.parametrize("form", sorted(FROZEN))
def test_frozen_bundles_of_both_forms_still_decode(form: str) -> None:
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t) * 0.5], 1)
    walk = np.stack([np.linspace(0, 3, 25), np.sin(np.linspace(0, 3, 25))], 1)
    got = wavecore.decode_curves(bytes.fromhex(FROZEN[form]))
    assert got.closed == [True, False] and got.tolerance == 0.01
    assert got.metadata == {"name": "frozen"}
    info = wavecore.inspect(bytes.fromhex(FROZEN[form]))
    assert info["method"] == ("wavelet" if form == "wavelet" else "vertex")
    assert info["version"] == {"wavelet": "1", "vertex": "2", "bulged": "3", "plane": "4"}[form]
    for original, back, flag in zip((ring, walk), got.curves, got.closed, strict=True):
        assert _both_ways(original, back, flag) <= 0.01


def _spans_fit(points, nodes, offsets, closed, keep, tolerance) -> bool:
    """Brute force: every point between two kept points within ``tolerance`` of their segment
    (``nodes``: the decoded position of every point)."""
    for c in range(len(offsets) - 1):
        first, stop = int(offsets[c]), int(offsets[c + 1])
        kept = np.flatnonzero(keep[first:stop]).tolist()
        if closed[c] and stop - first > 2:
            kept.append(stop - first)  # the start again
        for a, b in itertools.pairwise(kept):
            ring = np.arange(a, b + 1) % (stop - first) + first
            segment = nodes[ring[[0, -1]]]
            if _to_polyline(points[ring], segment, False) > tolerance * (1 + 1e-12):
                return False
    return True


@pytest.mark.parametrize("closed_flag", [0, 1])
def test_optimal_simplification_never_keeps_more_than_greedy(closed_flag: int) -> None:
    rng = np.random.default_rng(13)
    curves = []
    for _ in range(12):
        n = int(rng.integers(3, 300))
        angle = np.cumsum(rng.normal(0, 0.3, n))
        curves.append(np.cumsum(np.stack([np.cos(angle), np.sin(angle)], 1), 0))
    points = np.ascontiguousarray(np.concatenate(curves))
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in curves])]).astype(np.int64)
    closed = np.full(len(curves), closed_flag, dtype=np.int64)
    starts = np.zeros(len(curves), dtype=np.int64)
    for tolerance in (0.05, 0.3, 1.5):
        nodes = np.rint(points / (1.4 * tolerance)) * (1.4 * tolerance)
        greedy = curvecoder.reach_set(points, nodes, offsets, closed, starts, tolerance, 64)
        best = curvecoder.optimal_set(points, nodes, offsets, closed, starts, tolerance, 64, greedy)
        by_curve = np.add.reduceat(best, offsets[:-1])
        assert np.all(by_curve <= np.add.reduceat(greedy, offsets[:-1]))
        assert _spans_fit(points, nodes, offsets, closed, best, tolerance)
        ends = offsets[:-1] if closed_flag else np.concatenate([offsets[:-1], offsets[1:] - 1])
        assert np.all(best[ends])


def test_optimal_simplification_is_the_fewest_by_brute_force() -> None:
    # small open curves: every subset of the inner points, with the ends, tried
    rng = np.random.default_rng(0)
    offsets = np.array([0, 0], dtype=np.int64)
    closed = np.zeros(1, dtype=np.int64)
    starts = np.zeros(1, dtype=np.int64)
    beaten = 0
    for _ in range(150):
        n = int(rng.integers(3, 9))
        points = np.ascontiguousarray(np.cumsum(rng.normal(0, 1, (n, 2)), 0).round(1))
        offsets[1] = n
        greedy = curvecoder.reach_set(points, points, offsets, closed, starts, 0.5, 64)
        best = curvecoder.optimal_set(points, points, offsets, closed, starts, 0.5, 64, greedy)
        fewest = n
        for bits in range(1 << (n - 2)):
            keep = np.array([True] + [bool(bits >> i & 1) for i in range(n - 2)] + [True])
            if keep.sum() < fewest and _spans_fit(points, points, offsets, closed, keep, 0.5):
                fewest = int(keep.sum())
        assert best.sum() == fewest
        assert _spans_fit(points, points, offsets, closed, best, 0.5)
        beaten += int(greedy.sum() > fewest)
    assert beaten > 0  # curves where greedy reach is not the fewest (seed 0: several)


def test_optimal_simplification_keeps_greedy_beyond_its_work_budget() -> None:
    # a long circle: every span up to the window fits, so the path search would test about
    # window points per point, beyond its linear budget; it must give greedy's mask back
    n = 20000
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    points = np.ascontiguousarray(np.stack([np.cos(t), np.sin(t)], 1) * 1000)
    offsets = np.array([0, n], dtype=np.int64)
    closed = np.ones(1, dtype=np.int64)
    starts = np.zeros(1, dtype=np.int64)
    greedy = curvecoder.reach_set(points, points, offsets, closed, starts, 1.0, 512)
    best = curvecoder.optimal_set(points, points, offsets, closed, starts, 1.0, 512, greedy)
    assert np.array_equal(best, greedy)


@pytest.mark.parametrize("tolerance", [0.01, 0.002])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_bulged_segments_keep_the_bound_in_fewer_bytes(tolerance: float, dtype: str) -> None:
    # smooth closed and open plane curves: the parabolas between vertices follow the arcs
    curves = [(_ring(400, 1 + k) + 3 * k).astype(dtype) for k in range(4)]
    curves.append(np.stack([np.linspace(0, 6, 300), np.sin(np.linspace(0, 6, 300))], 1))
    curves[-1] = curves[-1].astype(dtype)
    closed = [True, True, True, True, False]
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, method="vertex")
    assert _version(bundle) in _PLANE and _head(bundle) & 0x40  # bulged segments
    out = wavecore.decode_curves(bundle)
    assert out.closed == closed
    for original, back, flag in zip(curves, out.curves, closed, strict=True):
        assert back.dtype == original.dtype
        assert _both_ways(original, back, flag) <= out.tolerance
    # the same vertices without bulges: the stream the encoder weighed it against
    stream_v3 = len(bundle)
    assert wavecore.inspect(bundle)["version"] in ("4", "5")
    plain = _plain_vertex_size(curves, closed, tolerance)
    assert stream_v3 < plain


def _plain_vertex_size(curves, closed, tolerance) -> int:
    """The vertex form's size with bulges switched off (version 2)."""
    original = curvesets._bulged_stream
    curvesets._bulged_stream = lambda *args: None
    try:
        bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, method="vertex")
    finally:
        curvesets._bulged_stream = original
    assert _version(bundle) in _PLANE and not _head(bundle) & 0x40
    return len(bundle)


def test_bulged_polylines_lie_on_their_parabolas() -> None:
    # decoded inner points: on the parabola through both vertices, its middle `bulge * unit`
    # to the left of the chord (independent formula: the vertex form of a parabola)
    vertices = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]])
    counts = np.array([3], dtype=np.int64)
    closed = np.array([1], dtype=np.int64)
    bulges = np.array([2, 3, 0], dtype=np.int64)  # segments ending at rows 0 (closing), 1, 2
    out, sizes, rows = curvecoder.bulged_polylines(vertices, counts, closed, bulges, 0.25)
    parts = curvecoder.BULGE_PARTS
    assert sizes.tolist() == [3 + 2 * (parts - 1)]
    assert rows.tolist() == [0, parts, parts + 1]
    first = out[1:parts]  # (0,0) -> (4,0), middle 0.75 to the left (+y)
    assert np.allclose(first[:, 1], 0.75 * (1 - ((first[:, 0] - 2) / 2) ** 2))
    closing = out[parts + 2 :]  # (4,3) -> (0,0), middle 0.5 to the left of that chord
    chord = np.array([-4.0, -3.0]) / 5
    left = np.array([-chord[1], chord[0]])
    along = (closing - [4.0, 3.0]) @ chord / 5
    assert np.allclose((closing - [4.0, 3.0]) @ left, 0.5 * 4 * along * (1 - along))


@pytest.mark.parametrize("from_last", [False, True])
@pytest.mark.parametrize("bulged", [False, True])
def test_version_4_coder_round_trips(from_last: bool, bulged: bool) -> None:
    rng = np.random.default_rng(21)
    lattice = np.cumsum(rng.integers(-40, 41, size=(240, 2)), axis=0)
    lattice[60:70] = rng.integers(-(1 << 40), 1 << 40, size=(10, 2))  # huge steps too
    counts = np.array([1, 59, 100, 2, 78])
    closed = np.array([1, 1, 0, 1, 1])
    repeated = np.array([0, 1, 0, 0, 1])
    bulges = rng.integers(-9, 10, size=240) if bulged else None
    for order in (0, 3, 4):
        stream = curvecoder.encode_set(
            lattice, counts, closed, repeated, 2, order, bulges, from_last
        )
        back = curvecoder.decode_bulged_set(stream, 5, 2, 2, False, 240, order, bulged, from_last)
        assert back is not None
        for got, want in zip(back[:4], (lattice, counts, closed, repeated), strict=True):
            assert np.array_equal(got, want)
        if bulges is not None:
            want = bulges.copy()
            want[[0, 60]] = 0  # a lone vertex's and an open curve's first row: no segment
            assert np.array_equal(back[4], want)


def test_starts_from_the_previous_last_vertex_keep_each_polygon() -> None:
    # three rings side by side: each start is one of its corners, the polygon the same, and
    # the chosen starts cost no more bits than the rings' first vertices
    rings = []
    for k in range(3):
        square = np.array([[0, 0], [10, 0], [10, 10], [5, 14], [0, 10]]) + [20 * k, 3 * k]
        rings.append(np.roll(square, k + 1, axis=0))
    vertices = np.concatenate(rings).astype(np.int64)
    counts = np.array([5, 5, 5])
    closed = np.array([1, 1, 1])
    rows = curvesets._from_last_starts(vertices, counts, closed)
    placed = vertices[rows]
    for k in range(3):
        got = placed[5 * k : 5 * k + 5]
        shifts = [np.roll(rings[k], -s, axis=0) for s in range(5)]
        assert any(np.array_equal(got, shift) for shift in shifts)

    def bits(v: np.ndarray) -> float:
        firsts = v[[0, 5, 10]]
        lasts = np.array([[0, 0], v[4], v[9]])
        return float(curvesets._coded_bits(firsts - lasts).sum())

    assert bits(placed) <= bits(vertices)


def test_version_4_header_is_shorter_than_version_3s() -> None:
    # plane float64 sets: no dimension, dtype or step byte (they are in the 2-byte head)
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t)], 1)
    bundle = wavecore.encode_curves([ring], closed=True, tolerance=0.01, method="vertex")
    info = wavecore.inspect(bundle)
    assert info["version"] in ("4", "5")
    # magic 4, version 1, head 2, tolerance 2 (0.01 as a short decimal), count 1, CRC 4
    assert info["header_bytes"] == 14


@pytest.mark.parametrize("priors", [False, True])
def test_version_5_priors_round_trip_and_differ(priors: bool) -> None:
    rng = np.random.default_rng(55)
    lattice = np.cumsum(rng.integers(-30, 31, size=(120, 2)), axis=0)
    counts = np.array([40, 50, 30])
    closed = np.array([1, 1, 1])
    repeated = np.zeros(3, dtype=np.int64)
    bulges = rng.integers(-5, 6, size=120)
    stream = curvecoder.encode_set(lattice, counts, closed, repeated, 1, 4, bulges, True, priors)
    back = curvecoder.decode_bulged_set(stream, 3, 2, 1, True, 120, 4, True, True, priors)
    assert back is not None
    assert np.array_equal(back[0], lattice) and np.array_equal(back[1], counts)
    # the priors are part of the format: read without them, the same stream is another set
    other = curvecoder.decode_bulged_set(stream, 3, 2, 1, True, 120, 4, True, True, not priors)
    assert other is None or not np.array_equal(other[0], lattice)


def test_glyph_like_set_written_as_version_5_keeps_the_bound() -> None:
    # rounded closed outlines (arcs and corners), as glyphs are; the encoder keeps version 5
    # where its priors pay, and the bound holds whichever version it writes
    t = np.linspace(0, 2 * np.pi, 97)[:-1]
    curves = [
        np.stack([3 * np.cos(t) + k * 7, 4 * np.sin(t) + np.sin(3 * t)], axis=1) for k in range(6)
    ]
    bundle = wavecore.encode_curves(curves, tolerance=0.05, method="vertex")
    assert _version(bundle) in _PLANE
    for original, decoded in zip(curves, wavecore.decode(bundle), strict=True):
        assert _both_ways(original, decoded, True) <= 0.05


@pytest.mark.parametrize("bulged", [False, True])
def test_version_6_copies_round_trip(bulged: bool) -> None:
    rng = np.random.default_rng(66)
    shape = np.cumsum(rng.integers(-30, 31, size=(40, 2)), axis=0)
    other = np.cumsum(rng.integers(-30, 31, size=(25, 2)), axis=0)
    lattice = np.concatenate([shape, other, shape + [500, -7], shape - [3, 900]])
    counts = np.array([40, 25, 40, 40])
    closed = np.ones(4, dtype=np.int64)
    repeated = np.zeros(4, dtype=np.int64)
    one = rng.integers(-5, 6, size=40)
    bulges = np.concatenate([one, rng.integers(-5, 6, size=25), one, one]) if bulged else None
    sources = np.array([-1, -1, 0, 2])
    fractions = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [3, 5, 0, 0], [0, 0, 2, 3]])
    stream = curvecoder.encode_set(
        lattice, counts, closed, repeated, 1, 4, bulges, False, True, None, sources, fractions
    )
    copies = np.zeros((4, 5), dtype=np.int64)
    back = curvecoder.decode_bulged_set(stream, 4, 2, 1, True, 200, 4, bulged, False, True, copies)
    assert back is not None
    assert np.array_equal(back[0], lattice) and np.array_equal(back[1], counts)
    if bulges is not None:
        assert np.array_equal(back[4], bulges)
    assert np.array_equal(copies[:, 0], sources) and np.array_equal(copies[:, 1:], fractions)
    # a copy costs its flag, distance, start and fraction: far less than its 40 vertices
    plain = curvecoder.encode_set(lattice, counts, closed, repeated, 1, 4, bulges, False, True)
    assert len(stream) < len(plain) - 40


@pytest.mark.parametrize("tolerance", [0.3, 0.05, 0.004])
@pytest.mark.parametrize("offset", [7.0, 7.123456, -3.3])
def test_translated_curves_are_copies_and_keep_the_bound(tolerance: float, offset: float) -> None:
    # the same outline at offsets off the lattice (as one letter repeats in a text), and one
    # other outline: the repeats are copied, and every curve keeps the bound (brute force)
    t = np.linspace(0, 2 * np.pi, 97)[:-1]
    shape = np.stack([3 * np.cos(t), 4 * np.sin(t) + np.sin(3 * t)], axis=1)
    curves = [shape + [k * offset, 0.37 * k] for k in range(5)] + [_ring(80, 2.0) + 20]
    bundle = wavecore.encode_curves(curves, tolerance=tolerance, method="vertex")
    assert _version(bundle) == curvesets.COPY_VERSION
    for original, decoded in zip(curves, wavecore.decode(bundle), strict=True):
        assert _both_ways(original, decoded, True) <= tolerance
    alone = wavecore.encode_curves([curves[0], curves[-1]], tolerance=tolerance, method="vertex")
    # four copies of at most 8 B each (a translation off the lattice, and its fractions),
    # where coding each 96-point outline in full costs far more
    assert len(bundle) <= len(alone) + 4 * 8


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    tolerance=st.floats(1e-3, 1.0),
    offsets=st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=1, max_size=4),
    dtype=st.sampled_from(["float64", "float32", "int32"]),
    closed=st.booleans(),
)
def test_copies_keep_the_bound_property(
    seed: int,
    tolerance: float,
    offsets: list[tuple[float, float]],
    dtype: str,
    closed: bool,
) -> None:
    # a walk and its translates (in the output dtype, as decoded): whichever curves become
    # copies, every curve keeps the bound both ways (brute force)
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(size=(int(rng.integers(3, 90)), 2)), axis=0) * 4
    curves = [walk.astype(dtype)] + [(walk + offset).astype(dtype) for offset in offsets]
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, method="vertex")
    for original, back in zip(curves, wavecore.decode(bundle), strict=True):
        assert back.dtype == original.dtype
        assert _both_ways(original, back, closed) <= tolerance


@pytest.mark.parametrize("tolerance", [0.05, 0.3, 10.0, 0.07, 12.5, 1 / 3])
def test_version_6_short_check_and_tolerance(tolerance: float) -> None:
    # a short version-6 set ends in a CRC-16 (a long one in a CRC-32) and its tolerance comes
    # back exactly as the encoder stated it; damage anywhere is found
    t = np.linspace(0, 2 * np.pi, 97)[:-1]
    shape = np.stack([3 * np.cos(t), 4 * np.sin(t) + np.sin(3 * t)], axis=1) * tolerance * 20
    curves = [shape + [k * 7.123456 * tolerance * 20, 0] for k in range(3)]
    bundle = wavecore.encode_curves(curves, tolerance=tolerance, method="vertex")
    assert _version(bundle) == curvesets.COPY_VERSION
    assert len(bundle) <= curvesets.SHORT_CHECK
    body = bundle[:-2]
    assert struct.unpack("<H", bundle[-2:])[0] == binascii.crc_hqx(body, 0)
    got = wavecore.decode_curves(bundle)
    assert got.tolerance <= tolerance and got.tolerance == curvesets._pack_tolerance(tolerance)[0]
    for original, back in zip(curves, got.curves, strict=True):
        assert _both_ways(original, back, True) <= got.tolerance
    for at in range(0, len(bundle), 3):
        damaged = bytearray(bundle)
        damaged[at] ^= 0x10
        with pytest.raises(wavecore.BundleError):
            wavecore.decode(bytes(damaged))


def test_version_6_crafted_bundles_give_curves_or_bundle_error() -> None:
    # bytes changed and the CRC-16 made to match: curves within the declared limit, or a
    # BundleError, never another exception
    t = np.linspace(0, 2 * np.pi, 41)[:-1]
    shape = np.stack([np.cos(t), np.sin(t) * 0.5], 1)
    bundle = wavecore.encode_curves(
        [shape, shape + [3.3, 0.1], _walk(30, 2)], tolerance=0.01, method="vertex"
    )
    assert _version(bundle) == curvesets.COPY_VERSION and len(bundle) <= curvesets.SHORT_CHECK
    rng = np.random.default_rng(6)
    for _ in range(300):
        body = bytearray(bundle[:-2])
        for _ in range(int(rng.integers(1, 4))):
            at = int(rng.integers(6, len(body)))
            body[at] = int(rng.integers(0, 256))
        crafted = bytes(body) + struct.pack("<H", binascii.crc_hqx(bytes(body), 0))
        try:
            out = wavecore.decode(crafted)
        except wavecore.BundleError:
            continue
        assert all(isinstance(c, np.ndarray) and c.ndim == 2 for c in out)
        assert sum(c.size for c in out) <= curvesets.VERTEX_PER_BYTE * (len(crafted) + 16)
