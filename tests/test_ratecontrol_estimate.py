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


def numpy_estimate_bits(
    counts: np.ndarray,
    centres: np.ndarray,
    rounding: np.ndarray,
    band: np.ndarray,
    totals: np.ndarray,
    bands: int,
    step: float,
) -> float:
    """The estimate's bits as NumPy's calls on all the bins give them (the reference)."""
    indices = np.floor(centres / step + rounding)
    histogram = np.bincount(
        band * 256 + np.minimum(indices, 255).astype(np.int64),
        weights=counts,
        minlength=256 * bands,
    ).reshape(bands, 256)
    used = histogram > 0
    present = histogram[used]
    entropy = present * np.log2(present / np.repeat(totals, used.sum(axis=1)))
    beyond = indices > 255
    lengths = counts[beyond] * np.log2(indices[beyond])
    signed = counts[indices >= 1]
    ends = [
        np.cumsum(used.sum(axis=1)),
        np.searchsorted(band[beyond], np.arange(1, bands + 1)),
        np.searchsorted(band[indices >= 1], np.arange(1, bands + 1)),
    ]
    bits, first = 0.0, (0, 0, 0)
    for last in zip(*(end.tolist() for end in ends), strict=True):
        bits -= float(np.add.reduce(entropy[first[0] : last[0]]))
        bits += 1.2 * float(np.add.reduce(lengths[first[1] : last[1]]))
        bits += float(np.add.reduce(signed[first[2] : last[2]]))
        first = last
    return bits


def test_compiled_terms_give_numpys_estimate() -> None:
    rng = np.random.default_rng(11)
    bands = 16
    sizes = rng.integers(0, 1500, bands)
    sizes[3] = 0  # a band without bins
    counts = rng.integers(1, 10_000, int(sizes.sum())).astype(np.float64)
    centres = np.concatenate([np.sort(rng.uniform(0, 3000, size)) for size in sizes])
    centres[rng.integers(0, centres.size, 20)] = 0.0  # bin 0: the tiny values
    rounding = np.repeat(rng.choice([0.5, 0.3, 0.2], bands), sizes)
    band = np.repeat(np.arange(bands, dtype=np.int64), sizes)
    totals = np.array([counts[band == b].sum() for b in range(bands)])
    for step in np.geomspace(0.05, 5000, 60):
        terms = ratecontrol._estimate_terms(counts, centres, rounding, band, totals, bands, step)
        present, shares, used_ends, large, indices, large_ends, signs, sign_ends = terms
        found = ratecontrol._estimated_bits(
            present * np.log2(shares),
            used_ends,
            large * np.log2(indices),
            large_ends,
            signs,
            sign_ends,
        )
        expected = numpy_estimate_bits(counts, centres, rounding, band, totals, bands, step)
        assert found == expected
