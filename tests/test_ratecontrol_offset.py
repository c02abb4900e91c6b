"""A tolerance far below the data's distance from the origin (a track in projected metres)."""

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidParameter


@pytest.mark.parametrize("offset", [0.0, 500.0, 5.0e5])
def test_curve_far_from_origin_meets_its_tolerance(offset: float) -> None:
    # The finest step overflows the quantizer's integers here; a coarser one still fits.
    t = np.linspace(0, 2 * np.pi, 200)
    curve = np.stack([np.cos(t), np.sin(t)], axis=1) * 0.5 + offset
    decoded = wavecore.decode(wavecore.encode_curve(curve, tolerance=1e-3))
    assert decoded.shape == curve.shape
    assert np.linalg.norm(decoded - curve, axis=1).max() <= 1e-3


def test_unreachable_tolerance_far_from_origin_is_a_clear_error() -> None:
    curve = np.stack([np.linspace(0, 1, 50), np.zeros(50)], axis=1) + 5.0e5
    with pytest.raises(InvalidParameter, match="tolerance 1e-09 cannot be met"):
        wavecore.encode_curve(curve, tolerance=1e-9)
