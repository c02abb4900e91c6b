"""Grid windows decode only what they need: ``decode_grid(bundle, window=...)`` (and
``decode(bundle, region=...)``) equal the whole grid sliced, for height fields and volumes,
NaN cells, outlier corrections (``max_error``), integers, lossless and coarse levels."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import InvalidParameter, decode, decode_grid


def _field(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    axes = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    smooth = sum(np.sin(a / (5.0 + 3 * i)) for i, a in enumerate(axes))
    return 40 * smooth + rng.normal(0, 1.5, shape)


def _grids() -> dict[str, bytes]:
    field = _field((290, 310))
    holes = field.copy()
    holes[100:140, 30:60] = np.nan
    holes[5, 300] = np.nan
    volume = _field((4, 150, 170), 1).astype(np.float32)
    ints = np.round(_field((300, 280), 2) * 20).astype(np.int16)
    return {
        "field max_error": wavecore.encode_grid(field, max_error=0.05),
        "field NaN rmse": wavecore.encode_grid(holes, rmse=0.5, wavelet="bspline2"),
        "volume": wavecore.encode_grid(volume, max_error=0.1),
        "int16 lossless": wavecore.encode_grid(ints, lossless=True),
        "int16 max_error": wavecore.encode_grid(ints, max_error=3),
    }


GRIDS = _grids()
NAMES = sorted(GRIDS)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=True))


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    "window",
    [
        (slice(0, 1), slice(0, 1)),
        (slice(95, 145), slice(20, 70)),
        (slice(-3, None),),
        (slice(10, 200, 7), slice(None, None, 3)),
        (slice(0, 500), slice(250, 1000)),
    ],
)
def test_a_window_equals_the_grid_sliced(name: str, window: tuple[slice, ...]) -> None:
    bundle = GRIDS[name]
    whole = decode(bundle)
    if whole.ndim == 3:  # a volume: the window's first slice is the depth
        window = (slice(1, 3), *window)
    assert _same(decode_grid(bundle, window=window), whole[window])
    assert _same(decode(bundle, region=window), whole[window])


@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
@pytest.mark.parametrize("name", ["field NaN rmse", "volume", "int16 max_error"])
def test_any_window_at_any_level(name: str, data: st.DataObject) -> None:
    bundle = GRIDS[name]
    level = data.draw(st.integers(0, 3), label="level")
    whole = decode_grid(bundle, level=level)
    window = []
    for n in whole.shape:
        start = data.draw(st.integers(0, n - 1))
        window.append(slice(start, data.draw(st.integers(start + 1, n))))
    assert _same(decode_grid(bundle, level=level, window=tuple(window)), whole[tuple(window)])


@pytest.mark.parametrize(
    "window", [(slice(5, 2), slice(0, 4)), (slice(None, None, -1),), (slice(3, 3),)]
)
def test_unusual_windows_keep_numpy_slicing(window: Any) -> None:
    bundle = GRIDS["field max_error"]
    assert _same(decode_grid(bundle, window=window), decode(bundle)[window])


def test_bad_windows_are_refused() -> None:
    with pytest.raises(InvalidParameter, match="window must hold slices"):
        decode_grid(GRIDS["volume"], window=(1, slice(0, 3)))
    with pytest.raises(InvalidParameter, match="at most 2 slices"):
        decode_grid(GRIDS["field max_error"], window=(slice(0, 1),) * 3)
    with pytest.raises(InvalidParameter, match="damaged='zero' does not apply"):
        decode(GRIDS["volume"], damaged="zero")
