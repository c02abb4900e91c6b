"""Tests for the CDF 9/7 filter bank derived from JPEG 2000's lifting steps."""

from __future__ import annotations

import numpy as np
import pytest
import pywt
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore import matrices, wavedec, wavedec2, wavelet_names, waverec, waverec2
from wavecore.cdf97 import lifting_analysis, lifting_matrices, lifting_synthesis


@pytest.mark.parametrize("boundary", ["open", "closed"])
def test_matrices_equal_lifting_and_are_biorthogonal(boundary: str) -> None:
    periodic = boundary == "closed"
    for m in range(8 if boundary == "open" else 2, 90, 2):
        A, B, P, Q = matrices(m, "cdf97", boundary)
        for got, ref in zip((A, B, P, Q), lifting_matrices(m, periodic), strict=True):
            np.testing.assert_allclose(got, ref, atol=1e-12)
        analysis, synthesis = np.vstack([A, B]), np.hstack([P, Q])
        np.testing.assert_allclose(analysis @ synthesis, np.eye(m), atol=1e-12)
        np.testing.assert_allclose(synthesis @ analysis, np.eye(m), atol=1e-12)


def test_registered() -> None:
    assert "cdf97" in wavelet_names()


def test_averaging_normalisation() -> None:
    """Coarse coefficients keep the data's units (DC gain 1), as for bspline2 and haar."""
    c, d = wavedec(np.full(64, 7.0), "cdf97", "open", 1)
    np.testing.assert_allclose(c, 7.0)
    np.testing.assert_allclose(d, 0.0, atol=1e-12)


def test_periodic_equals_pywavelets_bior44() -> None:
    """Periodic cdf97 is PyWavelets' bior4.4 in periodization mode, divided by sqrt(2)."""
    x = np.random.default_rng(0).standard_normal(64)
    coarse, detail = wavedec(x, "cdf97", "closed", 1)
    a, d = pywt.dwt(x, "bior4.4", mode="periodization")
    np.testing.assert_allclose(coarse * np.sqrt(2), a, atol=1e-12)
    # The detail sign is a convention; JPEG 2000's lifting gives the opposite of PyWavelets'.
    np.testing.assert_allclose(detail * np.sqrt(2), -d, atol=1e-12)


def test_open_interior_matches_pywavelets() -> None:
    """Away from the ends, the open transform is the same filter as bior4.4."""
    x = np.random.default_rng(1).standard_normal(80)
    coarse, detail = wavedec(x, "cdf97", "open", 1)
    a, d = pywt.dwt(x, "bior4.4", mode="periodization")
    interior = slice(4, 36)
    np.testing.assert_allclose(coarse[interior] * np.sqrt(2), a[interior], atol=1e-12)
    np.testing.assert_allclose(detail[interior] * np.sqrt(2), -d[interior], atol=1e-12)


def test_open_is_whole_sample_symmetric() -> None:
    """Open equals the periodic transform of the mirrored signal (x, reversed interior)."""
    x = np.random.default_rng(2).standard_normal(32)
    mirrored = np.concatenate([x, x[-2:0:-1]])  # one period (2m - 2) of the mirrored signal
    coarse, detail = lifting_analysis(x)
    full_c, full_d = lifting_analysis(mirrored, periodic=True)
    np.testing.assert_allclose(coarse, full_c[:16], atol=1e-12)
    np.testing.assert_allclose(detail, full_d[:16], atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k=st.integers(1, 6),
    level=st.integers(1, 3),
    boundary=st.sampled_from(["open", "closed"]),
)
def test_perfect_reconstruction(seed: int, k: int, level: int, boundary: str) -> None:
    n = (2**level) * (k + 3)
    if boundary == "open" and n >> (level - 1) < 8:
        n = 8 << (level - 1)
    x = np.random.default_rng(seed).standard_normal((n, 3))
    np.testing.assert_allclose(waverec(wavedec(x, "cdf97", boundary, level), "cdf97", boundary), x)
    np.testing.assert_allclose(lifting_synthesis(*lifting_analysis(x)), x, atol=1e-12)


def test_image_round_trip() -> None:
    image = np.random.default_rng(3).random((64, 96, 3))
    coeffs = wavedec2(image, "cdf97", "open", 3)
    assert coeffs[0].shape == (8, 12, 3)
    np.testing.assert_allclose(waverec2(coeffs, "cdf97", "open"), image, atol=1e-10)
