"""Windows of interpolation-coded grids: tiles at the fine levels (grid container version 3),
only the window's reach reconstructed, and version-2 bundles still decoding (tests/golden_grids)."""

from __future__ import annotations

import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_grids import terrain  # one terrain generator for the grid tests

import wavecore
from wavecore import gridpredict
from wavecore.errors import BundleError

GOLDEN = Path(__file__).resolve().parent / "golden_grids"


@pytest.fixture(scope="module")
def field_bundle() -> tuple[np.ndarray, bytes]:
    data = terrain((600, 520), seed=1).astype(np.float32)
    data[100:140, 300:420] = np.nan
    return data, wavecore.encode_grid(data, max_error=0.5)


@pytest.mark.parametrize("name", ["field_v2", "volume_nan_v2"])
def test_version_2_bundles_still_decode(name: str) -> None:
    bundle = (GOLDEN / f"{name}.wvg").read_bytes()
    expected = np.load(GOLDEN / f"{name}.npy")
    assert wavecore.inspect(bundle)["version"] == "grid 2"
    out = wavecore.decode(bundle)
    assert out.dtype == expected.dtype
    assert np.array_equal(out, expected, equal_nan=True)
    # A window of an untiled stream: entropy decoded whole, reconstructed in the window's reach.
    window = tuple(slice(n // 3, n // 3 + 17) for n in expected.shape)
    assert np.array_equal(wavecore.decode(bundle, region=window), expected[window], equal_nan=True)


def test_grids_larger_than_a_tile_write_version_3(field_bundle: tuple[np.ndarray, bytes]) -> None:
    data, bundle = field_bundle
    assert wavecore.inspect(bundle)["version"] == "grid 3"
    out = wavecore.decode(bundle)
    finite = ~np.isnan(data)
    assert np.array_equal(np.isnan(out), ~finite)
    assert np.max(np.abs(out[finite].astype(np.float64) - data[finite])) <= 0.5
    small = wavecore.encode_grid(terrain((100, 90), seed=2), max_error=0.5)
    assert wavecore.inspect(small)["version"] == "grid 2"  # one tile: nothing to split


def test_tiles_cost_few_bytes() -> None:
    data = terrain((700, 600), seed=3)
    shape, axes = data.shape, (0, 1)
    missing = np.zeros(shape, dtype=bool)
    whole = gridpredict.encode_predictive(data, missing, data.dtype, 0.3, axes, tiles=False)
    tiled = gridpredict.encode_predictive(data, missing, data.dtype, 0.3, axes, tiles=True)
    assert gridpredict.is_tiled_stream(tiled[0]) and not gridpredict.is_tiled_stream(whole[0])
    assert whole[1:] == tiled[1:]  # the same samples, the same errors
    assert len(tiled[0]) <= 1.003 * len(whole[0])
    assert np.array_equal(
        gridpredict.decode_predictive(whole[0], shape, data.dtype),
        gridpredict.decode_predictive(tiled[0], shape, data.dtype),
    )


def test_a_small_window_decodes_few_tiles(
    field_bundle: tuple[np.ndarray, bytes], monkeypatch: pytest.MonkeyPatch
) -> None:
    _, bundle = field_bundle
    calls: list[int] = []
    original = getattr(gridpredict, "_decode_tile")  # noqa: B009 (the hook under test)

    def counting(*args: Any, **kwargs: Any) -> None:
        calls.append(args[3])
        original(*args, **kwargs)

    monkeypatch.setattr(gridpredict, "_decode_tile", counting)
    window = (slice(10, 40), slice(20, 60))
    out = wavecore.decode(bundle, region=window)
    in_window = set(calls)
    calls.clear()
    full = wavecore.decode(bundle)
    assert np.array_equal(out, full[window], equal_nan=True)
    assert 0 < len(in_window) < len(set(calls))  # 600 × 520 in 256² tiles: 9 of them


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_windows_equal_slices(data: Any) -> None:
    volume = data.draw(st.booleans())
    shape = (20, 70, 300) if volume else (280, 530)
    grid = terrain(shape, seed=4, exponent=1.8 if volume else 2.2)
    grid[tuple(slice(n // 4, n // 3) for n in shape)] = np.nan
    bundle = _cached(volume, grid)
    window = []
    for n in shape:
        lo = data.draw(st.integers(0, n - 1))
        hi = data.draw(st.integers(lo + 1, n))
        step = data.draw(st.sampled_from([None, 1, 2, 5]))
        window.append(slice(lo, hi, step))
    expected = _full(volume, grid)[tuple(window)]
    out = wavecore.decode(bundle, region=tuple(window))
    assert out.shape == expected.shape and out.dtype == expected.dtype
    assert np.array_equal(out, expected, equal_nan=True)


_CACHE: dict[bool, tuple[bytes, np.ndarray]] = {}


def _cached(volume: bool, grid: np.ndarray) -> bytes:
    if volume not in _CACHE:
        bundle = wavecore.encode_grid(grid, max_error=0.8)
        _CACHE[volume] = (bundle, wavecore.decode(bundle))
    return _CACHE[volume][0]


def _full(volume: bool, grid: np.ndarray) -> np.ndarray:
    return _CACHE[volume][1]


def test_version_3_bundle_with_an_untiled_stream_is_refused(
    field_bundle: tuple[np.ndarray, bytes],
) -> None:
    _, bundle = field_bundle
    body = bytearray(bundle[:-4])
    body[4] = 2  # claims version 2, whose streams are never tiled
    forged = bytes(body) + zlib.crc32(bytes(body)).to_bytes(4, "little")
    with pytest.raises(BundleError, match="version 2 does not match"):
        wavecore.decode(forged)


def test_window_decode_rejects_a_box_outside_the_grid() -> None:
    data = terrain((40, 50), seed=5)
    missing = np.zeros(data.shape, dtype=bool)
    stream = gridpredict.encode_predictive(data, missing, data.dtype, 0.5, (0, 1))[0]
    with pytest.raises(BundleError, match="does not fit"):
        gridpredict.decode_predictive_window(stream, data.shape, data.dtype, ((0, 41), (0, 5)))


def test_interpolation_levels_past_the_lattice_and_zero_steps_are_refused_at_once() -> None:
    """A 304-byte bundle with level=2**63 computed 2**level and padded a mask to it (3 GB)."""
    bundle = wavecore.encode_grid(np.full((1024, 1024), np.nan), max_error=0.01)
    assert wavecore.decode(bundle, level=10).shape == (1, 1)
    for level in (11, 16, 2**63):
        with pytest.raises(wavecore.InvalidParameter, match="deeper than 10"):
            wavecore.decode(bundle, level=level)
    for region in [(slice(0, 1, 0),), (slice(0.5, 3),)]:
        with pytest.raises(wavecore.InvalidParameter, match="window slice"):
            wavecore.decode(bundle, region=region)


def test_a_nan_mask_inflates_no_further_than_an_honest_one_can_be() -> None:
    """Each run of L >= 1 cells takes at most L bytes: a checkerboard of NaN (every run 1 cell,
    the most bytes a mask can take) decodes; one byte more per cell is refused unread."""
    import zlib

    from wavecore.grids import decode_mask, encode_mask

    shape = (3, 40, 50)
    checkerboard = np.indices(shape).sum(axis=0) % 2 == 1
    assert np.array_equal(decode_mask(encode_mask(checkerboard), shape), checkerboard)
    bomb = zlib.compress(b"\x01" * (2 * checkerboard.size), 9)
    with pytest.raises(BundleError, match="size limit"):
        decode_mask(bomb, shape)
