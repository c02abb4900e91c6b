"""The PSNR's squared-error pass: the byte pictures' integer loop against the general one."""

from __future__ import annotations

import numpy as np
import pytest

from wavecore import _kernels


@pytest.mark.parametrize("size", [0, 1, 7, 1000, 262_144])
@pytest.mark.parametrize("spread", [0, 3, 255])
def test_byte_pictures_give_the_general_loops_numbers(size: int, spread: int) -> None:
    """Both sums are exact at these sizes (integers below 2**53), so they must agree to the
    bit; the header's PSNR is written from them."""
    rng = np.random.default_rng(size + spread)
    original = rng.integers(0, 256, size, dtype=np.uint8)
    noise = rng.integers(-spread, spread + 1, size)
    decoded = np.clip(original.astype(np.int64) + noise, 0, 255).astype(np.uint8)
    expected = _kernels.squared_and_largest_error(decoded, original)
    got = _kernels.squared_and_largest_error_u8(decoded, original)
    assert got == expected
    diff = decoded.astype(np.int64) - original.astype(np.int64)
    assert got == (float(np.sum(diff * diff)), float(np.abs(diff).max(initial=0)))
