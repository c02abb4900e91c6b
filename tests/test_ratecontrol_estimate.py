"""The bpp search's size estimate adds each band's terms in one compiled call: the sums must be
NumPy's, to the bit, or the search's steps (and so the bundles) would change."""

from __future__ import annotations

import numpy as np
import pytest

from wavecore.codec import ratecontrol


@pytest.mark.parametrize("length", [0, 1, 7, 8, 9, 127, 128, 129, 130, 255, 256, 1000, 4099])
def test_pairwise_sum_is_numpys_sum(length: int) -> None:
    rng = np.random.default_rng(length)
    # Magnitudes over ten decades, so that a different order of the additions shows.
    values = rng.standard_normal(length + 40) * 10.0 ** rng.uniform(-5, 5, length + 40)
    for start in (0, 3, 40):
        part = values[start : start + length]
        expected = float(np.add.reduce(part))
        assert ratecontrol._pairwise_sum(values, start, part.size) == expected


def test_estimated_bits_is_the_loop_over_numpy_sums() -> None:
    rng = np.random.default_rng(5)
    bands = 48
    arrays, ends = [], []
    for _ in range(3):
        sizes = rng.integers(0, 300, bands)
        sizes[rng.integers(0, bands, 5)] = 0  # empty bands, as the estimate meets them
        arrays.append(rng.standard_normal(int(sizes.sum())) * 10.0 ** rng.uniform(-3, 3))
        ends.append(np.cumsum(sizes))
    expected = 0.0
    starts = [0, 0, 0]
    for band in range(bands):
        stops = [int(end[band]) for end in ends]
        expected -= float(np.add.reduce(arrays[0][starts[0] : stops[0]]))
        expected += 1.2 * float(np.add.reduce(arrays[1][starts[1] : stops[1]]))
        expected += float(np.add.reduce(arrays[2][starts[2] : stops[2]]))
        starts = stops
    found = ratecontrol._estimated_bits(arrays[0], ends[0], arrays[1], ends[1], arrays[2], ends[2])
    assert found == expected
