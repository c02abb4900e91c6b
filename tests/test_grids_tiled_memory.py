"""The tiled interpolation coder keeps the in-place encoder's memory: no array of a group's
size beyond its one-byte symbols (merge of the grids and zarr branches)."""

from __future__ import annotations

import tracemalloc

import numpy as np
from zarr_fields import smooth_field

from wavecore.gridpredict import decode_predictive, encode_predictive, is_tiled_stream


def _peak(side: int) -> tuple[int, int]:
    values = smooth_field((side, side), seed=side).astype(np.float64)
    missing = np.zeros(values.shape, dtype=bool)
    bound = 1e-3 * float(np.ptp(values))
    args = (missing, np.dtype("float32"), bound, (0, 1))
    stream = encode_predictive(values.copy(), *args, overwrite=True)[0]  # kernels compiled
    assert is_tiled_stream(stream)
    grid = values.copy()
    tracemalloc.start()
    try:
        encode_predictive(grid, *args, overwrite=True)
        return tracemalloc.get_traced_memory()[1], values.nbytes
    finally:
        tracemalloc.stop()


def test_tiled_in_place_allocations_stay_below_a_group_int64() -> None:
    """The finest groups hold a quarter of a field's samples each: one int64 a sample of such a
    group would add 0.25 byte per byte of the float64 grid to the slope between two sizes; the
    one-byte symbols add 0.125, the tiles' low bits (here a few bits a sample) a little more."""
    (p0, s0), (p1, s1) = _peak(512), _peak(1024)
    slope = (p1 - p0) / (s1 - s0)
    assert slope < 0.25, slope


def test_tiled_in_place_is_the_stream_of_a_copy() -> None:
    rng = np.random.default_rng(5)
    values = smooth_field((300, 610), seed=5).astype(np.float64)
    missing = rng.random(values.shape) < 0.05
    values[missing] = 0.0
    values[17, 400] = 1e300  # stored exactly, in its tile
    kept = values.copy()
    args = (missing, np.dtype("float64"), 0.01, (0, 1))
    copied = encode_predictive(values, *args)
    assert np.array_equal(values, kept)
    in_place = encode_predictive(values, *args, overwrite=True)
    assert in_place == copied and is_tiled_stream(in_place[0])
    decoded = decode_predictive(in_place[0], values.shape, np.dtype("float64"))
    assert np.all(np.abs(decoded - kept)[~missing] <= 0.01)
