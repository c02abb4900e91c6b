"""Tests for the colour transforms, and for the codec's compiled passes that use them."""

from __future__ import annotations

import numpy as np
import pytest

from wavecore.codec import _cast, _to_integers, _ycbcr_from
from wavecore.colour import (
    YCBCR_INVERSE_MATRIX,
    rct_forward,
    rct_inverse,
    ycbcr_forward,
    ycbcr_inverse,
)
from wavecore.errors import InvalidParameter


def _numpy_cast(data: np.ndarray, dtype: str) -> np.ndarray:
    """What the codec did before its compiled pass: NaN to 0, round half to even, clip."""
    info = np.iinfo(dtype)
    values = np.nan_to_num(np.asarray(data, dtype=np.float64), nan=0.0)
    return np.clip(np.rint(values), info.min, info.max).astype(dtype)


def test_ycbcr_round_trip_keeps_alpha_and_white() -> None:
    rgba = np.random.default_rng(0).random((5, 7, 4)) * 255
    ycc = ycbcr_forward(rgba)
    np.testing.assert_array_equal(ycc[..., 3], rgba[..., 3])
    np.testing.assert_allclose(ycbcr_inverse(ycc), rgba, atol=1e-9)
    white = ycbcr_forward(np.full((1, 3), 255.0))
    np.testing.assert_allclose(white, [[255.0, 0.0, 0.0]], atol=1e-9)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32, np.float32, np.float64])
@pytest.mark.parametrize("channels", [3, 4])
def test_compiled_forward_pass_matches_numpy(dtype: type, channels: int) -> None:
    rng = np.random.default_rng(1)
    rgb = (rng.random((33, 20, channels)) * 250).astype(dtype)
    np.testing.assert_allclose(
        _ycbcr_from(rgb), ycbcr_forward(rgb.astype(np.float64)), rtol=0, atol=1e-9
    )


@pytest.mark.parametrize("dtype", ["uint8", "uint16", "int16"])
def test_compiled_inverse_pass_rounds_and_clips_like_numpy(dtype: str) -> None:
    rng = np.random.default_rng(2)
    ycc = rng.normal(0, 200, (40, 31, 4))
    ycc[0, 0, 0] = np.nan
    ycc[1, 1, :3] = [1e30, -1e30, np.inf]
    ycc[2, 2, 3] = 2.5  # rounds half to even, as np.rint does
    expected = _numpy_cast(ycbcr_inverse(ycc), dtype)
    got = _to_integers(ycc, dtype, YCBCR_INVERSE_MATRIX)
    assert got.dtype == np.dtype(dtype) and got.shape == ycc.shape
    assert got[2, 2, 3] == 2
    # The matrix sums may differ from BLAS's in the last bit: a value can move across a
    # rounding boundary, nothing more.
    difference = np.abs(got.astype(np.int64) - expected.astype(np.int64))
    assert difference.max() <= 1 and np.count_nonzero(difference) <= 2


@pytest.mark.parametrize("shape", [(17, 9), (17, 9, 2)])
def test_compiled_cast_is_exactly_numpys(shape: tuple[int, ...]) -> None:
    data = np.random.default_rng(3).normal(0, 300, shape)
    data.flat[:4] = [np.nan, np.inf, -np.inf, 0.5]
    for dtype in ("uint8", "uint16", "int8", "int32"):
        np.testing.assert_array_equal(_cast(data, dtype), _numpy_cast(data, dtype))


def test_rct_is_exactly_reversible_and_refuses_floats() -> None:
    rgb = np.random.default_rng(4).integers(0, 65536, (6, 6, 3))
    np.testing.assert_array_equal(rct_inverse(rct_forward(rgb)), rgb)
    with pytest.raises(InvalidParameter, match="integers"):
        rct_forward(rgb.astype(np.float64))
    with pytest.raises(InvalidParameter, match="3 channels"):
        ycbcr_forward(np.zeros((4, 4, 2)))
