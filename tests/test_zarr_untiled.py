"""Zarr chunks above one grid tile are coded untiled; tiled chunks (written before) decode."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("zarr", reason="the Zarr tests need the zarr extra (pip install '.[zarr]')")

from zarr_fields import smooth_field

from wavecore import decode_grid, encode_grid
from wavecore.grids import LAYOUT_FIELD, encode_layout, inspect_grid
from wavecore.zarr import decode_chunk, encode_chunk

BOUND = 0.02


@pytest.fixture(scope="module")
def chunk_field() -> np.ndarray:
    # 300 x 520: above the interpolation coder's 256² tile on both axes, so encode_grid tiles it.
    return smooth_field((300, 520), seed=31)


def test_chunk_is_coded_untiled(chunk_field: np.ndarray) -> None:
    """The chunk's grid bundle is the untiled stream (version 2), not encode_grid's tiled one:
    a chunk is already the unit of a window."""
    tiled = encode_grid(chunk_field, max_error=BOUND)
    assert inspect_grid(tiled)["version"] == "grid 3"  # the public encoder tiles this grid
    chunk = encode_chunk(chunk_field, {"max_error": BOUND})
    untiled = encode_layout(
        chunk_field,
        LAYOUT_FIELD,
        wavelet=None,
        level=None,
        boundary=("open", "open"),
        max_error=BOUND,
        tiles=False,
    )
    assert chunk.endswith(untiled)
    assert inspect_grid(untiled)["version"] == "grid 2"
    out = decode_chunk(chunk)
    assert out.dtype == chunk_field.dtype
    assert float(np.max(np.abs(out.astype(np.float64) - chunk_field))) <= BOUND


def test_tiled_chunk_still_decodes(chunk_field: np.ndarray) -> None:
    """A chunk holding a tiled grid bundle (what the codec wrote with tiles) decodes to what
    decode_grid returns for that bundle."""
    chunk = encode_chunk(chunk_field, {"max_error": BOUND})
    untiled = encode_layout(
        chunk_field,
        LAYOUT_FIELD,
        wavelet=None,
        level=None,
        boundary=("open", "open"),
        max_error=BOUND,
        tiles=False,
    )
    header = chunk[: len(chunk) - len(untiled)]
    tiled = encode_grid(chunk_field, max_error=BOUND)
    assert inspect_grid(tiled)["version"] == "grid 3"
    out = decode_chunk(header + tiled)
    np.testing.assert_array_equal(out, decode_grid(tiled))
    assert float(np.max(np.abs(out.astype(np.float64) - chunk_field))) <= BOUND
