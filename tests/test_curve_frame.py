"""The vertex coder's frame predictors (orders 3 and 4): exact round trips and their use."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import curvecoder, curvesets

#: the versions of a plane set of the vertex form (5: version 4 with learnt priors)
_PLANE = (curvesets.PLANE_VERSION, curvesets.PRIOR_VERSION)


def _to_ring(source: np.ndarray, ring: np.ndarray) -> float:
    """The largest distance from the points ``source`` to the closed polyline ``ring``."""
    a, b = ring, np.roll(ring, -1, axis=0)
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    p = source[:, None, :]
    t = np.clip(np.einsum("pij,ij->pi", p - a, ab) / length2, 0.0, 1.0)
    gap = p - (a + t[..., None] * ab)
    return float(np.sqrt(np.einsum("pij,pij->pi", gap, gap).min(axis=1)).max())


@pytest.mark.parametrize("order", [*curvecoder.FRAME_ORDERS])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_frame_orders_round_trip(order: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    # smooth turns, long and short steps, zero steps, reversals and a few huge jumps
    angle = np.cumsum(rng.normal(0, 0.3, 400))
    length = rng.integers(0, 40, 400)
    steps = np.rint(np.stack([np.cos(angle), np.sin(angle)], 1) * length[:, None])
    steps[::37] *= -1
    steps[::53] = rng.integers(-(1 << 40), 1 << 40, size=(len(steps[::53]), 2))
    lattice = np.cumsum(steps, axis=0).astype(np.int64)
    counts = np.array([1, 2, 3, 150, 244])
    closed = np.array([1, 0, 1, 0, 1])
    repeated = np.array([0, 0, 1, 0, 0])
    stream = curvecoder.encode_set(lattice, counts, closed, repeated, 2, order)
    back = curvecoder.decode_set(stream, len(counts), 2, 2, False, len(lattice), order)
    assert back is not None
    for got, want in zip(back, (lattice, counts, closed, repeated), strict=True):
        assert np.array_equal(got, want)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(-(1 << 46) + 1, (1 << 46) - 1), st.integers(-300, 300)),
        min_size=1,
        max_size=60,
    ),
    st.sampled_from(curvecoder.FRAME_ORDERS),
)
def test_frame_orders_round_trip_property(rows: list[tuple[int, int]], order: int) -> None:
    lattice = np.array(rows, dtype=np.int64)
    counts = np.array([len(rows)])
    stream = curvecoder.encode_set(lattice, counts, np.array([0]), np.array([0]), 0, order)
    back = curvecoder.decode_set(stream, 1, 2, 0, False, len(rows), order)
    assert back is not None and np.array_equal(back[0], lattice)


def test_smooth_outlines_pick_a_frame_predictor_and_keep_the_bound() -> None:
    t = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    rings = [
        np.stack([r * np.cos(t) * (1 + 0.2 * np.cos(3 * t)), r * np.sin(t)], 1) for r in (1, 2)
    ]
    bundle = wavecore.encode_curves(rings, closed=True, tolerance=1e-4, method="vertex")
    assert bundle[4] in _PLANE  # plane sets: version 4 or 5 (the 2-byte head)
    head = int.from_bytes(bundle[5:7], "little")
    assert (head >> 3) & 7 in curvecoder.FRAME_ORDERS  # the predictor the encoder kept
    for ring, back in zip(rings, wavecore.decode(bundle), strict=True):
        assert _to_ring(ring, back) <= 1e-4 and _to_ring(back, ring) <= 1e-4
    assert curvesets.inspect_curves(bundle)["method"] == "vertex"
