"""The chunk encoder's memory: issue 14's target of at most 4 × the chunk plus a constant, and
the in-place interpolation coder that meets it (same stream as coding a copy)."""

from __future__ import annotations

import tracemalloc

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from zarr_fields import smooth_field

from wavecore.gridpredict import decode_predictive, encode_predictive
from wavecore.zarr import decode_chunk, encode_chunk


def _allocation_peak(function: object, *args: object) -> int:
    tracemalloc.start()
    try:
        function(*args)  # type: ignore[operator]
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_float32_chunk_allocations_grow_below_four_chunks() -> None:
    peaks, sizes = [], []
    for side in (256, 512):
        chunk = smooth_field((side, side), seed=side)
        config = {"max_error": 1e-3 * float(np.ptp(chunk))}
        encode_chunk(chunk, config)  # compiled kernels loaded outside the measure
        peaks.append(_allocation_peak(encode_chunk, chunk, config))
        sizes.append(chunk.nbytes)
        back = decode_chunk(encode_chunk(chunk, config))
        assert np.max(np.abs(back.astype(np.float64) - chunk)) <= config["max_error"]
    # The target: at most 4 x the chunk plus a constant.  tracemalloc counts every
    # NumPy array (not the caller's chunk); the slope between two sizes is the bytes per chunk
    # byte, apart from the constant (the coder's fixed-size band scratch, under 1 MiB).
    slope = (peaks[1] - peaks[0]) / (sizes[1] - sizes[0])
    constant = peaks[0] - slope * sizes[0]
    assert slope <= 4.0, slope
    assert constant <= 2**20, constant


@settings(max_examples=25, deadline=None)
@given(
    rows=st.integers(1, 70),
    cols=st.integers(1, 70),
    depth=st.sampled_from([0, 1, 3]),
    dtype=st.sampled_from(["float64", "float32", "float16", "int16"]),
    bound=st.sampled_from([1e-3, 0.05, 0.7, 3.0]),
    seed=st.integers(0, 2**16),
)
def test_in_place_coding_gives_the_stream_of_a_copy(
    rows: int, cols: int, depth: int, dtype: str, bound: float, seed: int
) -> None:
    shape = (rows, cols) if depth == 0 else (depth, rows, cols)
    rng = np.random.default_rng(seed)
    values = smooth_field(shape, seed, dtype).astype(np.float64)
    missing = rng.random(shape) < 0.05 if dtype.startswith("float") else np.zeros(shape, bool)
    values[missing] = 0.0
    axes = tuple(range(len(shape)))
    kept = values.copy()
    copied = encode_predictive(values, missing, np.dtype(dtype), bound, axes)
    assert np.array_equal(values, kept)  # not overwritten unless asked
    in_place = encode_predictive(values, missing, np.dtype(dtype), bound, axes, overwrite=True)
    assert in_place == copied
    decoded = decode_predictive(in_place[0], shape, np.dtype(dtype)).astype(np.float64)
    allowed = np.floor(bound) if dtype == "int16" else bound
    assert np.all(np.abs(decoded - kept)[~missing] <= allowed)
    if dtype != "float16":  # float16 is checked on a copy, never in place
        # What is left in the grid is the decoder's reconstruction, before its cast.
        assert np.array_equal(values[~missing].astype(dtype), decoded[~missing].astype(dtype))
