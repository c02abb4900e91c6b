"""The chunk encoder's memory: issue 14's target of at most 4 × the chunk plus a constant, and
the in-place interpolation coder that meets it (same stream as coding a copy)."""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from zarr_fields import smooth_field

from wavecore.gridpredict import decode_predictive, encode_predictive
from wavecore.grids import any_infinite
from wavecore.zarr import decode_chunk, encode_chunk

da = pytest.importorskip("dask.array", reason="the zarr extra installs dask")
dask = pytest.importorskip("dask", reason="the zarr extra installs dask")
zarr = pytest.importorskip("zarr", reason="the zarr extra installs zarr")


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


def _slope(peaks: list[int], sizes: list[int]) -> float:
    return (peaks[1] - peaks[0]) / (sizes[1] - sizes[0])


def test_float32_chunk_without_nan_allocates_its_float64_copy_and_little_else() -> None:
    """Without NaN no mask of the chunk's size is made (nor an ``isinf`` or ``~missing``
    array): what grows with the chunk is the float64 grid the coder works in (2 bytes per
    float32 byte) and its one-byte symbols of the largest group (1/16).  A bool array of the
    chunk's size would add 0.25: main's code before this test measured 2.31 (its NaN mask)."""
    peaks, sizes = [], []
    for side in (256, 512):
        chunk = smooth_field((side, side), seed=side)
        config = {"max_error": 1e-2 * float(np.ptp(chunk))}
        encode_chunk(chunk, config)
        peaks.append(_allocation_peak(encode_chunk, chunk, config))
        sizes.append(chunk.nbytes)
    assert _slope(peaks, sizes) <= 2.2, _slope(peaks, sizes)


def write_path_slope(directory: Path) -> float:
    """Allocations per chunk byte of the worker's path (see the test below), fitted over two
    chunk sizes."""
    peaks, sizes = [], []
    for side in (256, 512):
        source = zarr.create_array(
            directory / f"raw_{side}.zarr",
            shape=(2 * side, 2 * side),
            chunks=(side, side),
            dtype="float32",
            compressors=None,
        )
        source[:] = smooth_field((2 * side, 2 * side), seed=side)
        bound = 1e-2 * float(np.ptp(source[:]))

        def write(side: int = side, source: object = source, bound: float = bound) -> None:
            target = zarr.create_array(
                directory / f"coded_{side}.zarr",
                shape=(2 * side, 2 * side),
                chunks=(side, side),
                dtype="float32",
                serializer={"name": "wavecore", "configuration": {"max_error": bound}},
                compressors=None,
                overwrite=True,
            )
            da.from_zarr(source).store(target, lock=False)

        with dask.config.set(scheduler="synchronous"):
            write()  # compiled kernels and Zarr's first-use imports outside the measure
            peaks.append(_allocation_peak(write))
        sizes.append(side * side * 4)
        back = np.asarray(zarr.open_array(directory / f"coded_{side}.zarr")[:], np.float64)
        assert np.max(np.abs(back - source[:])) <= bound
    return _slope(peaks, sizes)


def test_zarr_write_path_allocations_stay_well_below_four_chunks(tmp_path: Path) -> None:
    """The worker's path of benchmarks/zarr_scale.py (Dask's synchronous scheduler): a raw Zarr
    chunk read, coded by the ``wavecore`` serializer and written.  What grows with the chunk:
    the chunk read (1), the coder's float64 grid (2) and its symbols (1/16), measured 3.05
    bytes per chunk byte; main's code before this test 3.29 (its NaN mask and a bool array for
    its count).  The resident rise in a worker adds glibc's free memory on top (docs/scale.md,
    Memory per chunk), so this is the part the code controls.  It runs in a fresh interpreter:
    tracemalloc counts every thread's allocations, and in a long test session other tests'
    leftover threads and caches showed up in the peak (3.68)."""
    script = (
        "import sys; from pathlib import Path; sys.path.insert(0, sys.argv[1]); "
        "from test_zarr_memory import write_path_slope; "
        "print(write_path_slope(Path(sys.argv[2])))"
    )
    tests = str(Path(__file__).resolve().parent)
    run = subprocess.run(
        [sys.executable, "-c", script, tests, str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    slope = float(run.stdout.split()[-1])
    assert slope <= 3.2, slope


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(
        st.sampled_from([np.float16, np.float32, np.float64, np.dtype(">f8")]),
        hnp.array_shapes(min_dims=1, max_dims=3, max_side=9),
        elements=st.floats(allow_nan=True, allow_infinity=True, width=16),
    )
)
def test_any_infinite_is_isinf_any(values: np.ndarray) -> None:
    assert any_infinite(values) == bool(np.isinf(values).any())
    assert any_infinite(values[..., ::2]) == bool(np.isinf(values[..., ::2]).any())


def test_any_infinite_of_integers_and_empty_arrays() -> None:
    assert not any_infinite(np.arange(5))
    assert not any_infinite(np.zeros((0, 3)))
    assert any_infinite(np.array([[np.nan, -np.inf], [np.nan, np.nan]]))


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
