"""The rate estimate's log histogram (compiled, from the floats' bits) against ``math.frexp``,
value by value, including zeros, subnormals and the edges of the mantissa range."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavecore import _kernels


def _reference(values: np.ndarray, scale: float, per_octave: int, octaves: int, top: int):
    counts = np.zeros(per_octave * octaves, dtype=np.int64)
    for v in values:
        a = abs(float(v)) * scale
        if a == 0:
            counts[0] += 1
            continue
        mantissa, exponent = math.frexp(a)
        octave = exponent - top + octaves - 1
        if octave < 0:
            counts[0] += 1
        else:
            counts[octave * per_octave + int((2 * mantissa - 1) * per_octave)] += 1
    return counts


EDGES = [0.0, -0.0, 5e-324, 2.0**-1022, 2.0**-1023, 1.0, 2.0, 0.5, 1.9999999999999998, 1e300]


@pytest.mark.parametrize("per_octave", [64, 10, 7, 1])
@pytest.mark.parametrize("scale", [1.0, 0.37, 3.0e5, 2.0**-600])
def test_counts_match_frexp(per_octave: int, scale: float) -> None:
    rng = np.random.default_rng(per_octave)
    values = np.concatenate(
        [rng.normal(0, 1, 3000), rng.normal(0, 1e-310, 50), -rng.pareto(1.0, 500), EDGES]
    )
    top = int(_kernels.top_octave(_kernels.largest_scaled(values, scale)))
    for extra in (0, 3):  # the true top, and one above it
        got = _kernels.log_histogram_counts(values, scale, per_octave, 24, top + extra)
        np.testing.assert_array_equal(got, _reference(values, scale, per_octave, 24, top + extra))
        assert got.sum() == values.size


def test_slices_add_up_to_the_whole() -> None:
    values = np.random.default_rng(3).standard_normal(5000) * 40
    top = int(_kernels.top_octave(_kernels.largest_scaled(values, 1.0)))
    whole = _kernels.log_histogram_counts(values, 1.0, 64, 24, top)
    parts = sum(
        _kernels.log_histogram_counts(values[lo : lo + 777], 1.0, 64, 24, top)
        for lo in range(0, values.size, 777)
    )
    np.testing.assert_array_equal(whole, parts)
