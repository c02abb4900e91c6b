"""Synthesis basis norms: against brute force, closed forms, symmetries and the n-D products."""

from __future__ import annotations

import itertools
import tracemalloc

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidLength, InvalidParameter


def brute_force_norms(n: int, wavelet: str, boundary: str, level: int) -> list[np.ndarray]:
    """Reconstruct every unit coefficient on its own and measure the result."""
    template = wavecore.wavedec(np.zeros(n), wavelet, boundary, level)
    norms = []
    for index, band in enumerate(template):
        values = []
        for j in range(len(band)):
            coeffs = [np.zeros_like(b) for b in template]
            coeffs[index][j] = 1.0
            values.append(np.linalg.norm(wavecore.waverec(coeffs, wavelet, boundary)))
        norms.append(np.array(values))
    return norms


@pytest.mark.parametrize(
    ("n", "wavelet", "boundary", "level"),
    [
        (8, "bspline2", "open", 1),
        (34, "bspline2", "open", 3),
        (50, "bspline2", "open", 2),
        (16, "bspline2", "closed", 3),
        (24, "bspline2", "closed", 2),
        (24, "haar", "open", 3),
        (12, "haar", "closed", 2),
    ],
)
def test_norms_equal_brute_force(n: int, wavelet: str, boundary: str, level: int) -> None:
    got = wavecore.basis_norms(n, wavelet, boundary, level)
    want = brute_force_norms(n, wavelet, boundary, level)
    assert [len(g) for g in got] == [len(w) for w in want]
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g, w, rtol=1e-13)


def test_haar_norms_have_a_closed_form() -> None:
    # Averaging Haar synthesises cD_l[j] as 2**l samples of ±1 and cA_L[j] as 2**L ones.
    norms = wavecore.basis_norms(96, "haar", level=5)
    np.testing.assert_allclose(norms[0], np.sqrt(2.0**5))
    for index, band in enumerate(norms[1:]):
        level = 5 - index
        np.testing.assert_allclose(band, np.sqrt(2.0**level))


def test_closed_norms_are_shift_invariant_and_open_coarse_norms_symmetric() -> None:
    for band in wavecore.basis_norms(64, boundary="closed", level=4):
        np.testing.assert_allclose(band, band[0], rtol=1e-13)
    # P's end rows mirror its start rows, so the coarse functions are mirror images too.
    coarse = wavecore.basis_norms(98, level=5)[0]
    np.testing.assert_allclose(coarse, coarse[::-1], rtol=1e-13)
    # Open interior functions are the closed ones: far from the ends the norms agree.
    open_norms = wavecore.basis_norms(258, level=2)
    closed_norms = wavecore.basis_norms(256, boundary="closed", level=2)
    np.testing.assert_allclose(open_norms[1][20:40], closed_norms[1][0], rtol=1e-12)


def test_norms_grow_with_the_level_default_level_and_cache() -> None:
    norms = wavecore.basis_norms(514)  # level=None: all 7 levels
    assert len(norms) == 8
    middles = [band[len(band) // 2] for band in norms[1:]]  # cD_7 … cD_1
    assert all(a > b for a, b in itertools.pairwise(middles))
    again = wavecore.basis_norms(514)
    assert all(a is b for a, b in zip(norms, again, strict=True))
    with pytest.raises(ValueError, match="read-only"):
        norms[0][0] = 1.0


def test_nd_norms_are_the_products_and_match_brute_force() -> None:
    shape, boundary = (18, 16), ("open", "closed")
    norms = wavecore.basis_norms_nd(shape, boundary=boundary, level=2)
    u = wavecore.basis_norms(18, boundary="open", level=2)
    v = wavecore.basis_norms(16, boundary="closed", level=2)
    np.testing.assert_allclose(norms[0], np.outer(u[0], v[0]))
    # Finest level: detail along u at level 1 times coarse along v at level 1.
    v1 = wavecore.basis_norms(16, boundary="closed", level=1)
    np.testing.assert_allclose(norms[2]["da"], np.outer(u[2], v1[0]))
    np.testing.assert_allclose(norms[1]["dd"], np.outer(u[1], v[1]))
    # Brute force for a few coefficients of every band.
    template = wavecore.wavedecn(np.zeros(shape), boundary=boundary, level=2)
    rng = np.random.default_rng(0)
    for level_index in range(len(template)):
        keys = [None] if level_index == 0 else sorted(template[level_index])
        for key in keys:
            band = template[0] if key is None else template[level_index][key]
            expected = norms[0] if key is None else norms[level_index][key]
            assert expected.shape == band.shape
            for _ in range(3):
                pos = tuple(int(rng.integers(s)) for s in band.shape)
                coeffs = [np.zeros_like(template[0])] + [
                    {k: np.zeros_like(b) for k, b in d.items()} for d in template[1:]
                ]
                target = coeffs[0] if key is None else coeffs[level_index][key]
                target[pos] = 1.0
                rebuilt = wavecore.waverecn(coeffs, boundary=boundary)
                np.testing.assert_allclose(np.linalg.norm(rebuilt), expected[pos], rtol=1e-12)


def test_norm_errors() -> None:
    with pytest.raises(InvalidLength, match="length 20"):
        wavecore.basis_norms(20, level=2)
    with pytest.raises(InvalidParameter, match="unknown wavelet"):
        wavecore.basis_norms(34, "db2")
    with pytest.raises(InvalidParameter, match="2 boundaries for 3 axes"):
        wavecore.basis_norms_nd((10, 10, 10), boundary=("open", "open"))


def dense_reference_norms(n: int, wavelet: str, boundary: str, level: int) -> list[np.ndarray]:
    """The basis functions themselves, as columns of products of the dense step matrices."""
    basis = np.eye(n)
    details = []
    for _ in range(level):
        _, _, P, Q = wavecore.matrices(basis.shape[1], wavelet, boundary)
        details.append(np.linalg.norm(basis @ Q, axis=0))
        basis = basis @ P
    return [np.linalg.norm(basis, axis=0), *reversed(details)]


def _lengths(wavelet: str, boundary: str) -> list[int]:
    """Short lengths (full matrices) and long ones (the stand-in path), every level they hold."""
    extra = 2 if (wavelet, boundary) == ("bspline2", "open") else 0
    short = [valid for valid in range(2, 60, 2) if wavecore.max_level(valid, boundary, wavelet)]
    long = [130 + extra, 258 + extra, 64 * 7 + extra]
    return short[:10] + [n for n in long if wavecore.max_level(n, boundary, wavelet)]


@pytest.mark.parametrize("wavelet", ["bspline2", "haar", "cdf97"])
@pytest.mark.parametrize("boundary", ["open", "closed"])
def test_norms_equal_the_dense_basis_for_every_wavelet_length_and_level(
    wavelet: str, boundary: str
) -> None:
    for n in _lengths(wavelet, boundary):
        for level in range(wavecore.max_level(n, boundary, wavelet) + 1):
            got = wavecore.basis_norms(n, wavelet, boundary, level)
            want = dense_reference_norms(n, wavelet, boundary, level)
            assert [len(g) for g in got] == [len(w) for w in want], (n, level)
            for g, w in zip(got, want, strict=True):
                np.testing.assert_allclose(g, w, rtol=1e-12, err_msg=f"n={n} level={level}")


@pytest.mark.parametrize("name", wavecore.wavelet_names())
def test_every_name_and_alias_has_exact_norms(name: str) -> None:
    for n, boundary in ((64, "closed"), (wavecore.valid_length(200, 3, "open", name), "open")):
        got = wavecore.basis_norms(n, name, boundary, 3)
        for g, w in zip(got, dense_reference_norms(n, name, boundary, 3), strict=True):
            np.testing.assert_allclose(g, w, rtol=1e-12)


def test_long_norms_repeat_the_interior_and_cost_little() -> None:
    # 2**20 samples: the old impulse method took minutes here.  The interior value of every
    # band equals that of a length whose dense reference is cheap (translates of one function).
    n = 2**20 + 2
    norms = wavecore.basis_norms(n, level=6)
    small = dense_reference_norms(2**6 * 5 + 2, "bspline2", "open", 6)
    for big_band, small_band in zip(norms, small, strict=True):
        np.testing.assert_allclose(big_band[:2], small_band[:2], rtol=1e-12)
        np.testing.assert_allclose(big_band[-2:], small_band[-2:], rtol=1e-12)
        np.testing.assert_allclose(big_band[len(big_band) // 2], small_band[2], rtol=1e-12)
    # Only small things are cached: the long vectors are gone once the caller drops them.
    del norms
    tracemalloc.start()
    for level in (3, 4, 5):
        wavecore.basis_norms(n, level=level)
    retained, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert retained < 1 << 20


def test_default_level_refuses_what_would_loop_without_end() -> None:
    """``coarsest=0`` made every level fit, so the loop ran to ``most`` (10**9: 49 s)."""
    with pytest.raises(wavecore.InvalidParameter, match="coarsest must be at least 1"):
        wavecore.default_level([100], 10**9, 0)
    with pytest.raises(wavecore.InvalidParameter, match="at least one axis"):
        wavecore.default_level([])
    assert 90 < wavecore.default_level([10**30], 10**9) < 100  # as deep as 2**100 allows


def test_coarse_extent_takes_no_memory_of_the_length() -> None:
    """It counted coarse positions in an array of them: 10**9 passed 3 GB."""
    import time

    start = time.perf_counter()
    assert wavecore.coarse_extent(10**9, (0, 2), 1) == 500_000_001
    assert wavecore.coarse_extent(10**9 + 1, (0, 1), 1, boundary="closed") == 500_000_001
    assert time.perf_counter() - start < 0.1
