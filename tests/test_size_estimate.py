"""The bpp search's first-order size estimate, computed for every band at once, adds up the
same sums as the band-by-band formula it replaced (the search's steps, and so the bundles,
must not move by a bit)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore.codec.ratecontrol import _band_estimates


def _band_by_band(histograms: list, step: float) -> float:
    bits = 0.0
    for counts, centres, rounding in histograms:
        indices = np.floor(centres / step + rounding)
        histogram = np.bincount(
            np.minimum(indices, 255).astype(np.int64), weights=counts, minlength=256
        )
        present = histogram[histogram > 0]
        bits -= float(np.sum(present * np.log2(present / counts.sum())))
        beyond = indices > 255
        bits += 1.2 * float(np.sum(counts[beyond] * np.log2(indices[beyond])))
        bits += float(counts[indices >= 1].sum())
    return bits


def _at_once(histograms: list, step: float) -> float:
    bits = 0.0
    for lost, large, signs in _band_estimates(histograms, step):
        bits -= lost
        bits += 1.2 * large
        bits += signs
    return bits


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    bands=st.integers(1, 20),
    step=st.floats(1e-3, 1e3),
)
def test_estimates_at_once_equal_band_by_band(seed: int, bands: int, step: float) -> None:
    rng = np.random.default_rng(seed)
    histograms = []
    for _ in range(bands):
        size = int(rng.integers(1, 3000))
        counts = rng.integers(1, 10**6, size).astype(np.float64)
        centres = np.sort(rng.exponential(rng.uniform(0.1, 500.0), size))
        centres[0] = 0.0
        histograms.append((counts, centres, float(rng.choice([0.5, 0.38, 0.3]))))
    assert _at_once(histograms, step) == _band_by_band(histograms, step)  # bit for bit
