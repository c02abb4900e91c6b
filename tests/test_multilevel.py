"""Multi-level decomposition: orders, sizes, round trips and the size-rule errors."""

from __future__ import annotations

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidLength, InvalidParameter


def test_wavedec_order_and_sizes() -> None:
    # 98 = 2**5 * 3 + 2: each level takes m to (m + 2) / 2 coarse and (m - 2) / 2 details,
    # leaving k + 2 = 5 coarse samples.
    coeffs = wavecore.wavedec(np.zeros(98), level=5)
    assert [len(c) for c in coeffs] == [5, 3, 6, 12, 24, 48]
    closed = wavecore.wavedec(np.zeros(96), boundary="closed", level=5)
    assert [len(c) for c in closed] == [3, 3, 6, 12, 24, 48]


@pytest.mark.parametrize(
    ("wavelet", "boundary", "n"),
    [
        ("bspline2", "open", 98),
        ("bspline2", "closed", 96),
        ("haar", "open", 96),
        ("haar", "closed", 40),
    ],
)
def test_round_trips_every_api(wavelet: str, boundary: str, n: int) -> None:
    rng = np.random.default_rng(n)
    x = rng.standard_normal((n, 3))
    np.testing.assert_allclose(
        wavecore.waverec(wavecore.wavedec(x, wavelet, boundary), wavelet, boundary), x, atol=1e-12
    )
    img = rng.standard_normal((n, wavecore.valid_length(20, 1, boundary, wavelet)))
    coeffs = wavecore.wavedec2(img, wavelet, boundary, level=1)
    np.testing.assert_allclose(wavecore.waverec2(coeffs, wavelet, boundary), img, atol=1e-12)
    cube = rng.standard_normal((n, 8 if boundary == "closed" or wavelet == "haar" else 10, 3))
    coeffs = wavecore.wavedecn(cube, wavelet, boundary, level=1, axes=(0, 1))
    np.testing.assert_allclose(
        wavecore.waverecn(coeffs, wavelet, boundary, axes=(0, 1)), cube, atol=1e-12
    )


def test_boundary_per_axis_surface_of_revolution() -> None:
    u, v = np.meshgrid(
        np.linspace(0, 2 * np.pi, 32, endpoint=False), np.linspace(0, 1, 18), indexing="ij"
    )
    grid = np.stack([np.cos(u) * (1 + v), np.sin(u) * (1 + v), v], axis=-1)
    coeffs = wavecore.wavedec2(grid, boundary=("closed", "open"), level=2)
    assert coeffs[0].shape == (8, 6, 3)
    np.testing.assert_allclose(
        wavecore.waverec2(coeffs, boundary=("closed", "open")), grid, atol=1e-12
    )


def test_none_details_mean_zeros() -> None:
    x = np.random.default_rng(2).standard_normal(34)
    coeffs = wavecore.wavedec(x, level=2)
    zeroed = [coeffs[0], np.zeros_like(coeffs[1]), np.zeros_like(coeffs[2])]
    np.testing.assert_allclose(wavecore.waverec([coeffs[0], None, None]), wavecore.waverec(zeroed))
    img = np.random.default_rng(3).standard_normal((18, 18))
    c2 = wavecore.wavedec2(img, level=1)
    np.testing.assert_allclose(
        wavecore.waverec2([c2[0], (None, None, None)]),
        wavecore.waverec2([c2[0], tuple(np.zeros_like(b) for b in c2[1])]),
    )


def test_size_functions() -> None:
    assert wavecore.max_level(514) == 7
    assert wavecore.max_level(513) == 0
    assert wavecore.max_level(512, "closed") == 9
    assert wavecore.valid_length(500, 5) == 514
    assert wavecore.valid_length(500, 5, "closed") == 512
    for n in range(1, 200):
        for level in range(4):
            m = wavecore.valid_length(n, level)
            assert m >= n and wavecore.max_level(m) >= level
            assert all(wavecore.max_level(k) < level for k in range(n, m))


def test_length_errors_name_the_nearest_fits() -> None:
    with pytest.raises(
        InvalidLength, match=r"length 513 \(axis 0\) does not fit 5 level.*482 and 514"
    ):
        wavecore.wavedec(np.zeros(513), level=5)
    with pytest.raises(
        InvalidLength, match=r"length 7 \(axis 0\) does not fit 1 level.*fit are 8 "
    ):
        wavecore.wavedec(np.zeros(7))
    with pytest.raises(InvalidParameter, match="level must be at least 0"):
        wavecore.wavedec(np.zeros(34), level=-1)
    with pytest.raises(InvalidParameter, match="2 boundaries for 3 axes"):
        wavecore.wavedecn(np.zeros((10, 10, 10)), boundary=("open", "open"))
