"""The squared error and largest error of integer samples, summed in integers over the threads,
equal NumPy's float64 sums exactly (the PSNR in the header must not move by a bit)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore._kernels import squared_and_largest_error, squared_and_largest_integer_error


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    size=st.integers(0, 5000),
    dtype=st.sampled_from(["uint8", "uint16", "int16", "int8", "bool"]),
)
def test_integer_errors_equal_float_sums(seed: int, size: int, dtype: str) -> None:
    rng = np.random.default_rng(seed)
    if dtype == "bool":
        a, b = rng.random(size) < 0.5, rng.random(size) < 0.5
    else:
        info = np.iinfo(dtype)
        a = rng.integers(info.min, int(info.max) + 1, size).astype(dtype)
        b = rng.integers(info.min, int(info.max) + 1, size).astype(dtype)
    diff = a.astype(np.float64) - b.astype(np.float64)
    total, largest = squared_and_largest_integer_error(a, b)
    assert float(total) == float(np.sum(diff * diff))  # exact: integers below 2**53
    assert float(largest) == (float(np.max(np.abs(diff))) if size else 0.0)
    assert (float(total), float(largest)) == squared_and_largest_error(a, b)


def test_the_psnr_of_an_image_comes_from_the_integer_sums() -> None:
    import wavecore

    rng = np.random.default_rng(7)
    image = rng.integers(0, 256, (300, 700, 3)).astype(np.uint8)  # over the threads' threshold
    bundle = wavecore.encode_image(image, keep=0.2)
    decoded = wavecore.decode(bundle)
    mse = float(np.mean((decoded.astype(np.float64) - image) ** 2))
    expected = 20 * np.log10(255.0) - 10 * np.log10(mse)
    assert wavecore.inspect(bundle)["psnr"] == pytest.approx(expected, abs=2e-4)
