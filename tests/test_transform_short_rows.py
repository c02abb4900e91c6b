"""Many short rows (a tall, thin picture) go through the column kernels: the same bits as the
row kernels and the fused 2-D levels that they replace there."""

from __future__ import annotations

import numpy as np
import pytest

import wavecore
from wavecore import transform
from wavecore.adjoint import synthesis_adjoint
from wavecore.filters import get_wavelet

# (wavelet, boundary, fine length): every bank, both boundaries, interiors of every size the
# short-row path takes (up to transform._SHORT_ROW).
STEPS = [
    ("bspline2", "open", 8),
    ("bspline2", "open", 14),
    ("bspline2", "open", 32),
    ("bspline2", "closed", 4),
    ("bspline2", "closed", 18),
    ("cdf97", "open", 8),
    ("cdf97", "open", 24),
    ("cdf97", "closed", 2),
    ("cdf97", "closed", 16),
    ("haar", "open", 6),
    ("haar", "closed", 32),
]


def _bits(arr: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(arr)
    return arr.view(np.int32 if arr.dtype == np.float32 else np.int64)


def _steps(
    data: np.ndarray, wavelet: str, boundary: str, axis: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c, d = wavecore.analysis_step(data, wavelet, boundary, axis)
    return c, d, wavecore.synthesis_step(c, 2.0 * d, wavelet, boundary, axis)


@pytest.mark.parametrize(("wavelet", "boundary", "m"), STEPS)
@pytest.mark.parametrize(("shape", "axis"), [((300, "m"), 1), ((130, "m", 3), 1), ((260, "m"), -1)])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_short_row_steps_give_the_row_kernels_bits(
    wavelet: str,
    boundary: str,
    m: int,
    shape: tuple[int | str, ...],
    axis: int,
    dtype: type,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rng = np.random.default_rng(m)
    full = tuple(m if n == "m" else n for n in shape)
    # Huge finite values too: the sums must round the same way, not only nearly.
    largest = 300 if dtype == np.float64 else 30
    data = (rng.standard_normal(full) * 10.0 ** rng.integers(-3, largest, full)).astype(dtype)
    inner = full[-1] if len(full) == 3 else 1
    assert transform.many_short_rows(full[0], m, inner)
    fast = _steps(data, wavelet, boundary, axis)
    monkeypatch.setattr(transform, "_MANY_ROWS", 1 << 62)
    slow = _steps(data, wavelet, boundary, axis)
    for got, want in zip(fast, slow, strict=True):
        assert got.shape == want.shape and got.dtype == want.dtype == dtype
        np.testing.assert_array_equal(_bits(got), _bits(want))


@pytest.mark.parametrize("wavelet", ["bspline2", "cdf97", "haar"])
@pytest.mark.parametrize("shape", [(4096, 8), (2050, 16), (1000, 3), (700, 24, 3)])
def test_tall_thin_levels_give_the_fused_levels_bits(
    wavelet: str, shape: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(len(shape))
    fitted = [wavecore.valid_length(n, 2, "open", wavelet) for n in shape[:2]]
    picture = rng.uniform(0.0, 255.0, (*fitted, *shape[2:]))

    def run() -> list[np.ndarray]:
        coeffs = wavecore.wavedec2(picture, wavelet, level=2)
        back = wavecore.waverec2(coeffs, wavelet)
        adjoint = synthesis_adjoint(picture, wavelet, level=2)
        return [
            arr
            for layout in (coeffs, adjoint)
            for arr in (layout[0], *(band for level in layout[1:] for band in level))
        ] + [back]

    got = run()
    monkeypatch.setattr(transform, "_MANY_ROWS", 1 << 62)
    want = run()
    for a, b in zip(got, want, strict=True):
        assert a.shape == b.shape
        np.testing.assert_array_equal(_bits(a), _bits(b))


def test_a_tall_thin_level_runs_one_step_per_axis() -> None:
    """The fused kernels decline it (the reason the column kernels exist), and a wide one
    of the same size stays fused."""
    bank = get_wavelet("cdf97")
    tall = np.zeros((4096, 8))
    assert transform.analysis_2d(tall, bank, ("open", "open"), 0) is None
    assert transform.analysis_2d(tall.T.copy(), bank, ("open", "open"), 0) is not None


@pytest.mark.parametrize("wavelet", ["bspline2", "cdf97"])
def test_closed_tall_thin_levels_agree_with_the_fused_levels(
    wavelet: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A closed boundary that wraps a level 2 samples wide is where the fused kernel and the
    steps already differed by a few ulps; elsewhere the bits are the same."""
    rng = np.random.default_rng(11)
    picture = rng.uniform(0.0, 255.0, (1024, 4))
    coeffs = wavecore.wavedec2(picture, wavelet, boundary="closed", level=2)
    back = wavecore.waverec2(coeffs, wavelet, boundary="closed")
    monkeypatch.setattr(transform, "_MANY_ROWS", 1 << 62)
    want_coeffs = wavecore.wavedec2(picture, wavelet, boundary="closed", level=2)
    want_back = wavecore.waverec2(want_coeffs, wavelet, boundary="closed")
    np.testing.assert_array_equal(_bits(coeffs[0]), _bits(want_coeffs[0]))
    np.testing.assert_allclose(back, want_back, rtol=0, atol=1e-12 * 255)
    np.testing.assert_allclose(back, picture, rtol=0, atol=1e-9)
