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
