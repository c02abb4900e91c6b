"""The fast steps against the dense matrices, along every axis and for every trailing shape."""

from __future__ import annotations

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidCoefficients, InvalidParameter

CASES = [
    ("bspline2", "open", 8),
    ("bspline2", "open", 22),
    ("bspline2", "closed", 2),
    ("bspline2", "closed", 4),
    ("bspline2", "closed", 18),
    ("haar", "open", 6),
    ("haar", "closed", 10),
]


@pytest.mark.parametrize(("wavelet", "boundary", "m"), CASES)
@pytest.mark.parametrize(
    ("shape", "axis"), [((), 0), ((3,), 0), ((3,), 1), ((2, 5), 0), ((2, 5), 1), ((2, 5), -1)]
)
def test_step_equals_matrix_product(
    wavelet: str, boundary: str, m: int, shape: tuple[int, ...], axis: int
) -> None:
    rng = np.random.default_rng(m)
    full = (m, *shape)
    data = np.moveaxis(rng.standard_normal(full), 0, axis)
    A, B, _, _ = wavecore.matrices(m, wavelet, boundary)
    c, d = wavecore.analysis_step(data, wavelet, boundary, axis)
    np.testing.assert_allclose(
        c, np.moveaxis(np.tensordot(A, np.moveaxis(data, axis, 0), 1), 0, axis), atol=1e-13
    )
    np.testing.assert_allclose(
        d, np.moveaxis(np.tensordot(B, np.moveaxis(data, axis, 0), 1), 0, axis), atol=1e-13
    )
    f = wavecore.synthesis_step(c, d, wavelet, boundary, axis)
    np.testing.assert_allclose(f, data, atol=1e-13)


@pytest.mark.parametrize(
    "dtype", [np.float32, np.float64, np.int16, np.uint8, np.bool_, np.float16, np.complex64]
)
def test_dtype_policy(dtype: type) -> None:
    data = (np.arange(40).reshape(10, 4) % 7).astype(dtype)
    c, d = wavecore.analysis_step(data)
    expected = {np.float32: np.float32, np.float16: np.float32, np.complex64: np.complex64}.get(
        dtype, np.float64
    )
    assert c.dtype == d.dtype == expected
    assert wavecore.synthesis_step(c, d).dtype == expected


def test_large_arrays_take_the_threaded_path() -> None:
    data = np.random.default_rng(0).standard_normal((1026, 600))
    A = wavecore.matrices(1026)[0]
    for axis in (0, 1):
        arr = data if axis == 0 else data.T.copy()
        c, d = wavecore.analysis_step(arr, axis=axis)
        ref = A @ data
        np.testing.assert_allclose(c if axis == 0 else c.T, ref, atol=1e-12)
        np.testing.assert_allclose(wavecore.synthesis_step(c, d, axis=axis), arr, atol=1e-12)


def test_step_errors_are_clear() -> None:
    with pytest.raises(InvalidParameter, match="scalar"):
        wavecore.analysis_step(3.0)
    with pytest.raises(InvalidParameter, match="axis 2 is out of range"):
        wavecore.analysis_step(np.zeros((8, 8)), axis=2)
    with pytest.raises(InvalidParameter, match="dtype"):
        wavecore.analysis_step(np.array(["a"] * 8))
    with pytest.raises(InvalidCoefficients, match="do not come from one"):
        wavecore.synthesis_step(np.zeros(5), np.zeros(5))
    with pytest.raises(InvalidCoefficients, match="do not agree"):
        wavecore.synthesis_step(np.zeros((5, 2)), np.zeros((3, 3)))


def _dense_along(matrix: np.ndarray, data: np.ndarray, axis: int) -> np.ndarray:
    return np.moveaxis(np.tensordot(matrix, np.moveaxis(data, axis, 0), 1), 0, axis)


SWEEP = [
    ("bspline2", "open", range(8, 48, 2)),
    ("bspline2", "closed", range(2, 40, 2)),
    ("haar", "open", range(2, 24, 2)),
    ("haar", "closed", range(2, 24, 2)),
]


@pytest.mark.parametrize(("wavelet", "boundary", "lengths"), SWEEP)
@pytest.mark.parametrize(
    ("shape", "axis"),
    [((), 0), ((4,), 1), ((3,), 0), ((2, 3), 1), ((2, 3), 2), ((5, 1), 0), ((1, 2), -1)],
)
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_step_equals_matrix_product_for_many_lengths(
    wavelet: str,
    boundary: str,
    lengths: range,
    shape: tuple[int, ...],
    axis: int,
    dtype: type,
) -> None:
    # Every length exercises the boundary rows and the regular interior in their own proportion
    # (short closed lengths wrap onto themselves); float32 runs through its own compiled kernels.
    tol = 1e-13 if dtype is np.float64 else 2e-6
    for m in lengths:
        rng = np.random.default_rng(m)
        ax = axis % (len(shape) + 1)
        data = rng.standard_normal((*shape[:ax], m, *shape[ax:])).astype(dtype)
        A, B, P, Q = wavecore.matrices(m, wavelet, boundary)
        c, d = wavecore.analysis_step(data, wavelet, boundary, axis)
        assert c.dtype == d.dtype == dtype
        np.testing.assert_allclose(c, _dense_along(A, data, ax), atol=tol, rtol=0)
        np.testing.assert_allclose(d, _dense_along(B, data, ax), atol=tol, rtol=0)
        # Synthesis of unrelated coefficients is P C + Q D too.
        c2 = rng.standard_normal(c.shape).astype(dtype)
        d2 = rng.standard_normal(d.shape).astype(dtype)
        f = wavecore.synthesis_step(c2, d2, wavelet, boundary, axis)
        expected = _dense_along(P, c2, ax) + _dense_along(Q, d2, ax)
        np.testing.assert_allclose(f, expected, atol=4 * tol, rtol=0)


def test_non_contiguous_input_and_mixed_dtypes() -> None:
    data = np.random.default_rng(1).standard_normal((20, 18))[::2, ::-1]  # a strided view
    c, d = wavecore.analysis_step(data, axis=1)
    A = wavecore.matrices(18)[0]
    np.testing.assert_allclose(c, data @ A.T, atol=1e-13)
    f = wavecore.synthesis_step(c.astype(np.float32), d, axis=1)
    assert f.dtype == np.float64  # the wider of the two coefficient dtypes
    np.testing.assert_allclose(f, data, atol=1e-6)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize(("shape", "axes"), [((2, 770, 514), (1, 2)), ((514, 514, 3), (0, 1))])
def test_threaded_fused_level_matches_per_axis_steps(
    dtype: type, shape: tuple[int, ...], axes: tuple[int, int]
) -> None:
    # Large enough to be split over threads and row blocks, in both fused directions, with and
    # without trailing channels (an RGB image).
    image = np.random.default_rng(2).standard_normal(shape).astype(dtype)
    coeffs = wavecore.wavedec2(image, level=1, axes=axes)
    low, high = wavecore.analysis_step(image, axis=axes[0])
    tol = 1e-12 if dtype is np.float64 else 1e-5
    aa, ad = wavecore.analysis_step(low, axis=axes[1])
    da, dd = wavecore.analysis_step(high, axis=axes[1])
    for band, expected in zip((coeffs[0], *coeffs[1]), (aa, da, ad, dd), strict=True):
        assert band.shape == expected.shape
        np.testing.assert_allclose(band, expected, atol=tol)
    rebuilt = wavecore.waverec2(coeffs, axes=axes)
    assert rebuilt.dtype == dtype
    np.testing.assert_allclose(rebuilt, image, atol=10 * tol)


@pytest.mark.parametrize("boundary", ["open", "closed", ("closed", "open")])
@pytest.mark.parametrize("trailing", [(), (3,)])
def test_images_take_the_fused_pass(
    boundary: str | tuple[str, str], trailing: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    # The one-pass 2-D level is what makes images fast; the per-axis steps must not be used.
    # 18 closed (9 coarse rows) wraps onto ring slots that a ring of 8 would share.
    def per_axis_step(*args: object, **kwargs: object) -> None:
        raise AssertionError("the per-axis path was taken")

    image = np.random.default_rng(3).standard_normal((18, 34, *trailing))
    b0, b1 = (boundary, boundary) if isinstance(boundary, str) else boundary
    low = wavecore.analysis_step(image, boundary=b0, axis=0)[0]
    expected = wavecore.analysis_step(low, boundary=b1, axis=1)[0]
    monkeypatch.setattr(wavecore.multilevel, "analysis_step", per_axis_step)
    monkeypatch.setattr(wavecore.multilevel, "synthesis_step", per_axis_step)
    coeffs = wavecore.wavedec2(image, boundary=boundary, level=1)
    np.testing.assert_allclose(coeffs[0], expected, atol=1e-13)
    np.testing.assert_allclose(wavecore.waverec2(coeffs, boundary=boundary), image, atol=1e-12)
