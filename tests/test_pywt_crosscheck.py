"""Cross-checks against PyWavelets, an independent implementation of the same filters.

Closed ``bspline2`` is PyWavelets' ``bior3.1`` with ``mode="periodization"``, up to scale and a
shift.  Worked out from one step (``NOTES.md``: our ``c_j`` reads ``f[2j-2 .. 2j+1]``, PyWavelets'
``cA[k]`` reads ``x[2k-1 .. 2k+2]``, one fine sample later):

* one level: ``cA = √2 · c(y)`` and ``cD = d(y) / √2`` with ``y = roll(x, -1)``;
* each further level shifts again by one sample *of its own input*, so after ``L`` levels the
  shift is ``1 + 2 + … + 2**(L-1) = 2**L - 1`` fine samples.  Decomposing
  ``roll(x, -(2**L - 1))`` with our transform lines up level ``L`` exactly; the finer detail bands
  of level ``l`` are then ``2**(L-l) - 1`` of their own samples too far and are rolled back;
* the scales are ``√2**L`` for ``cA_L`` and ``√2**(l-2)`` for ``cD_l`` (our analysis is the
  averaging normalisation, PyWavelets' the orthonormal-like one).

Haar is the averaging Haar, ``c = (a + b) / 2`` and ``d = (a - b) / 2``, against PyWavelets'
``(a ± b) / √2``: ``cA_L = √2**L · c_L`` and ``cD_l = √2**l · d_l``, with no shift.
"""

from __future__ import annotations

import numpy as np
import pytest
import pywt

import wavecore

SQRT2 = np.sqrt(2.0)

# PyWavelets warns when short signals are decomposed deeply; for periodic data that is exact.
pytestmark = pytest.mark.filterwarnings("ignore:Level value of .* is too high")

# (length, levels): several lengths for each level count, up to the most the length allows.
CLOSED_CASES = [
    (n, level) for n in (8, 16, 24, 40, 96, 128) for level in range(1, 5) if n % 2**level == 0
]


@pytest.mark.parametrize(("n", "level"), CLOSED_CASES)
def test_closed_is_bior31_periodization_up_to_scale_and_shift(n: int, level: int) -> None:
    x = np.random.default_rng(n * 10 + level).standard_normal(n)
    theirs = pywt.wavedec(x, "bior3.1", mode="periodization", level=level)
    ours = wavecore.wavedec(np.roll(x, -(2**level - 1)), "bspline2", "closed", level)
    assert [len(band) for band in ours] == [len(band) for band in theirs]
    np.testing.assert_allclose(theirs[0], SQRT2**level * ours[0], rtol=1e-12, atol=1e-12)
    for band_level in range(1, level + 1):
        index = level - band_level + 1  # [cA_L, cD_L, …, cD_1]
        shift = 2 ** (level - band_level) - 1
        np.testing.assert_allclose(
            theirs[index],
            SQRT2 ** (band_level - 2) * np.roll(ours[index], shift),
            rtol=1e-12,
            atol=1e-12,
        )


@pytest.mark.parametrize("n", [8, 16, 30, 64])
def test_closed_one_level_shift_is_exactly_one_sample(n: int) -> None:
    # The shift is a property, not a fit: with one sample less or more it no longer matches.
    x = np.random.default_rng(n).standard_normal(n)
    cA, cD = pywt.dwt(x, "bior3.1", mode="periodization")
    for shift in range(-3, 4):
        c, d = wavecore.analysis_step(np.roll(x, -shift), boundary="closed")
        matches = np.allclose(cA, SQRT2 * c) and np.allclose(cD, d / SQRT2)
        assert matches == (shift == 1), shift


@pytest.mark.parametrize(("n", "level"), CLOSED_CASES[::3])
def test_closed_reconstruction_from_pywt_coefficients(n: int, level: int) -> None:
    # Their coefficients, converted back to ours, reconstruct the (shifted) signal in our code.
    x = np.random.default_rng(n + level).standard_normal(n)
    theirs = pywt.wavedec(x, "bior3.1", mode="periodization", level=level)
    converted = [theirs[0] / SQRT2**level]
    for band_level in range(level, 0, -1):
        band = theirs[level - band_level + 1] / SQRT2 ** (band_level - 2)
        converted.append(np.roll(band, -(2 ** (level - band_level) - 1)))
    rebuilt = wavecore.waverec(converted, "bspline2", "closed")
    np.testing.assert_allclose(rebuilt, np.roll(x, -(2**level - 1)), atol=1e-12)


@pytest.mark.parametrize(("n", "level"), [(2, 1), (8, 3), (12, 2), (48, 4), (64, 6)])
@pytest.mark.parametrize("boundary", ["open", "closed"])
def test_haar_is_pywt_haar_in_averaging_normalisation(n: int, level: int, boundary: str) -> None:
    x = np.random.default_rng(n).standard_normal(n)
    theirs = pywt.wavedec(x, "haar", mode="periodization", level=level)
    ours = wavecore.wavedec(x, "haar", boundary, level)
    np.testing.assert_allclose(theirs[0], SQRT2**level * ours[0], rtol=1e-12, atol=1e-12)
    for band_level in range(1, level + 1):
        index = level - band_level + 1
        np.testing.assert_allclose(
            theirs[index], SQRT2**band_level * ours[index], rtol=1e-12, atol=1e-12
        )


def test_haar_2d_matches_pywt_band_for_band() -> None:
    image = np.random.default_rng(5).standard_normal((32, 24))
    theirs = pywt.wavedec2(image, "haar", mode="periodization", level=3)
    ours = wavecore.wavedec2(image, "haar", level=3)
    np.testing.assert_allclose(theirs[0], 2.0**3 * ours[0], atol=1e-12)
    for index in range(1, 4):
        band_level = 3 - index + 1
        for t, o in zip(theirs[index], ours[index], strict=True):  # (cH, cV, cD) both sides
            np.testing.assert_allclose(t, 2.0**band_level * o, atol=1e-12)
