"""Tests for the weighted dead-zone quantizer."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore import basis_norms, wavedec, wavedec2, waverec, waverec2
from wavecore.errors import InvalidCoefficients, InvalidParameter
from wavecore.layout import as_levels
from wavecore.quantize import (
    DEFAULT_ROUNDING,
    dequantize_bands,
    quantize_bands,
    reconstruction_offset,
)


def _image(seed: int = 0, shape: tuple[int, ...] = (66, 34)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[: shape[0], : shape[1]]
    smooth = 100 + 60 * np.sin(x / 7.0) * np.cos(y / 5.0)
    noise = rng.normal(0, 4, shape[:2])
    out = smooth + noise
    if len(shape) == 3:
        out = np.stack([out * (0.5 + 0.2 * c) for c in range(shape[2])], axis=-1)
    return out


@pytest.mark.parametrize("wavelet", ["bspline2", "haar", "cdf97"])
def test_error_shrinks_with_step(wavelet: str) -> None:
    image = _image(shape=(66, 34) if wavelet == "bspline2" else (64, 32))
    coeffs = wavedec2(image, wavelet, "open", 2)
    errors = []
    for step in (8.0, 2.0, 0.5):
        q, params = quantize_bands(coeffs, step, wavelet=wavelet, boundary="open")
        back = waverec2(dequantize_bands(q, params, wavelet=wavelet, boundary="open"), wavelet)
        errors.append(float(np.sqrt(np.mean((back - image) ** 2))))
    assert errors[0] > errors[1] > errors[2]
    # At a fine step the error is about step / sqrt(12) (dead zone aside), not much more.
    assert errors[2] < 0.5


def test_layout_dtype_and_json_params() -> None:
    image = _image(shape=(34, 34, 3))
    coeffs = wavedec2(image, "bspline2", "open", 2)
    q, params = quantize_bands(coeffs, 1.0, wavelet="bspline2", boundary="open")
    assert q[0].dtype == np.int32 and q[0].shape == coeffs[0].shape
    for bands, qbands in zip(coeffs[1:], q[1:], strict=True):
        assert isinstance(qbands, tuple)
        assert [b.shape for b in qbands] == [b.shape for b in bands]
    assert json.loads(json.dumps(params)) == params


def test_steps_follow_basis_norms() -> None:
    """A band whose basis functions are larger gets a proportionally finer step."""
    x = np.random.default_rng(3).normal(size=66)
    coeffs = wavedec(x, "bspline2", "open", 3)
    _, params = quantize_bands(coeffs, 1.0, wavelet="bspline2", boundary="open", axes=(0,))
    norms = basis_norms(66, "bspline2", "open", 3)
    rms = [float(np.sqrt(np.mean(n**2))) for n in norms]
    steps = [params["step"] * w[0] for w in params["weights"]]
    # cA of level 3 and cD of level 3 come from the same decomposition depth.
    assert steps[0] * rms[0] == pytest.approx(1.0, rel=1e-3)
    assert steps[1] * rms[1] == pytest.approx(1.0, rel=1e-3)


def test_dead_zone_zeros_small_details() -> None:
    coeffs = [np.zeros((6, 6)), (np.full((4, 6), 0.55), np.full((6, 4), -0.55), np.zeros((4, 4)))]
    q, params = quantize_bands(coeffs, 1.0, wavelet="bspline2", boundary="open")
    step = params["step"] * params["weights"][1][0]
    # 0.55 / step is below 1 - rounding for these norms, so the dead zone takes it.
    assert 0.55 / step < 1 - DEFAULT_ROUNDING
    assert not np.any(q[1][0]) and not np.any(q[1][1])


def test_prefix_dequantizes_alone() -> None:
    image = _image()
    coeffs = wavedec2(image, "bspline2", "open", 3)
    q, params = quantize_bands(coeffs, 1.0, wavelet="bspline2", boundary="open")
    full = dequantize_bands(q, params, wavelet="bspline2", boundary="open")
    prefix = dequantize_bands(q[:2], params, wavelet="bspline2", boundary="open")
    assert len(prefix) == 2
    np.testing.assert_array_equal(prefix[0], full[0])
    np.testing.assert_array_equal(prefix[1][2], full[1][2])


@pytest.mark.parametrize(
    "params",
    [
        {"name": "other", "step": 1.0, "weights": [[1.0]], "rounding": 0.4},
        {"name": "deadzone", "step": 1.0, "weights": [], "rounding": 0.4},
        {"name": "deadzone", "step": 1.0, "weights": [["x"]], "rounding": 0.4},
        {"name": "deadzone", "step": float("nan"), "weights": [[1.0]], "rounding": 0.4},
        {"name": "deadzone", "step": -1.0, "weights": [[1.0]], "rounding": 0.4},
        {"name": "deadzone", "step": 1.0, "weights": [[1.0]], "rounding": 0.9},
        {"name": "deadzone", "step": 1.0, "weights": [[1.0, 2.0]], "rounding": 0.4},
        {"name": "deadzone", "step": 1.0, "weights": [1.0], "rounding": 0.4},
        "not a dict",
    ],
)
def test_bad_params_are_rejected(params: object) -> None:
    q = [np.zeros((3, 3), dtype=np.int32)]
    with pytest.raises(InvalidParameter):
        dequantize_bands(q, params, wavelet="haar", boundary="open")  # type: ignore[arg-type]


def test_bad_arguments() -> None:
    coeffs = wavedec2(_image(shape=(64, 32)), "haar", "open", 1)
    for step in (0, -1.0, float("inf"), "1", True):
        with pytest.raises(InvalidParameter, match="step"):
            quantize_bands(coeffs, step, wavelet="haar", boundary="open")  # type: ignore[arg-type]
    with pytest.raises(InvalidParameter, match="rounding"):
        quantize_bands(coeffs, 1.0, wavelet="haar", boundary="open", rounding=0.8)
    with pytest.raises(InvalidCoefficients):
        quantize_bands([], 1.0, wavelet="haar", boundary="open")


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    step=st.floats(0.05, 20.0),
    n=st.sampled_from([16, 32, 64]),
)
def test_curve_round_trip_error_is_bounded(seed: int, step: float, n: int) -> None:
    """Open loop, every coefficient comes back within one band step (dead zone plus offset)."""
    points = np.random.default_rng(seed).normal(0, 10, (n, 2))
    coeffs = wavedec(points, "bspline2", "closed", 2)
    q, params = quantize_bands(
        coeffs, step, wavelet="bspline2", boundary="closed", axes=(0,), refine=0
    )
    back = dequantize_bands(q, params, wavelet="bspline2", boundary="closed", axes=(0,))
    for index, (c, b) in enumerate(zip(coeffs, back, strict=True)):
        band_step = params["step"] * params["weights"][index][0]
        assert np.all(np.abs(c - b) <= band_step * (1 + 1e-9))
    assert waverec(back, "bspline2", "closed").shape == points.shape


def test_reconstruction_offset_follows_the_histogram() -> None:
    """A steeper histogram puts the reconstruction lower in the bin; a flat one near its middle."""
    rng = np.random.default_rng(11)
    steep = np.round(rng.laplace(0, 0.6, 5000)).astype(np.int32)
    flat = np.round(rng.laplace(0, 8.0, 5000)).astype(np.int32)
    low, high = reconstruction_offset(steep, 0.4), reconstruction_offset(flat, 0.4)
    assert -0.4 <= low < high <= 0.5 - 0.4 + 1e-9
    assert reconstruction_offset(np.zeros(5, np.int32), 0.4) == pytest.approx(0.1)


def test_offset_lowers_error_on_laplacian_details() -> None:
    """The fitted offset reconstructs Laplacian data better than the bin middle would."""
    rng = np.random.default_rng(12)
    x = rng.laplace(0, 1.0, (64, 64))
    big = [np.zeros((34, 34)), (x[:32, :34], x[:34, :32], x[:32, :32])]
    q, params = quantize_bands(big, 1.5, wavelet="bspline2", boundary="open")
    back = dequantize_bands(q, params, wavelet="bspline2", boundary="open")
    step = params["step"] * params["weights"][1][2]
    middle = np.copysign((np.abs(q[1][2]) + 0.5 - params["rounding"]) * step, q[1][2])
    middle[q[1][2] == 0] = 0
    fitted_error = np.mean((back[1][2] - big[1][2]) ** 2)
    assert fitted_error < np.mean((middle - big[1][2]) ** 2)


@pytest.mark.parametrize(
    ("wavelet", "boundary", "shape"),
    [
        ("bspline2", "open", (66, 98)),
        ("bspline2", "closed", (64, 32, 3)),
        ("haar", "open", (64, 64)),
    ],
)
def test_closed_loop_lowers_the_reconstruction_error(
    wavelet: str, boundary: str, shape: tuple[int, ...]
) -> None:
    """Refinement keeps the dead zone's zeros and fits the rest to the image: less error."""
    image = _image(5, shape)
    coeffs = wavedec2(image, wavelet, boundary, 3)
    errors, nonzeros = [], []
    for refine in (0, 6):
        q, params = quantize_bands(coeffs, 6.0, wavelet=wavelet, boundary=boundary, refine=refine)
        back = waverec2(
            dequantize_bands(q, params, wavelet=wavelet, boundary=boundary), wavelet, boundary
        )
        errors.append(float(np.mean((back - image) ** 2)))
        nonzeros.append(sum(int(np.count_nonzero(b)) for e in q[1:] for b in e))
    assert errors[1] < errors[0]
    assert nonzeros[1] <= nonzeros[0]


def test_closed_loop_curve_layout() -> None:
    points = np.cumsum(np.random.default_rng(6).normal(0, 1, (66, 2)), axis=0)
    coeffs = wavedec(points, "bspline2", "open", 3)
    errors = []
    for refine in (0, 8):
        q, params = quantize_bands(
            coeffs, 2.0, wavelet="bspline2", boundary="open", axes=(0,), refine=refine
        )
        back = waverec(dequantize_bands(q, params, wavelet="bspline2", boundary="open", axes=(0,)))
        errors.append(float(np.mean((back - points) ** 2)))
    assert errors[1] < errors[0]


def test_refine_argument_is_checked() -> None:
    coeffs = wavedec2(_image(shape=(64, 32)), "haar", "open", 1)
    with pytest.raises(InvalidParameter, match="refine"):
        quantize_bands(coeffs, 1.0, wavelet="haar", boundary="open", refine=-1)


def test_dequantize_into_given_arrays() -> None:
    rng = np.random.default_rng(11)
    coeffs = wavedec2(rng.normal(0, 40, (64, 48, 3)), wavelet="cdf97", level=2)
    q, params = quantize_bands(coeffs, 3.0, wavelet="cdf97", boundary="open", refine=0)
    fresh = dequantize_bands(q, params, wavelet="cdf97", boundary="open")
    targets = [np.zeros_like(coeffs[0]), tuple(np.zeros_like(b) for b in coeffs[1])]
    # A band of the wrong dtype is not written into: it gets a new array.
    targets.append((np.zeros(coeffs[2][0].shape, dtype=np.float32), *coeffs[2][1:]))
    out = dequantize_bands(q, params, wavelet="cdf97", boundary="open", out=targets)
    assert out[0] is targets[0] and out[1][2] is targets[1][2]
    assert out[2][0] is not targets[2][0] and out[2][1] is targets[2][1]
    for got, expected in zip(as_levels(out), as_levels(fresh), strict=True):
        for a, b in zip(got, expected, strict=True):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("wavelet", ["bspline2", "haar", "cdf97"])
@pytest.mark.parametrize("boundary", ["open", "closed"])
def test_short_curves_close_the_loop_on_a_dense_matrix_with_the_same_integers(
    wavelet: str, boundary: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A short 1-D layout's closed loop multiplies by its synthesis as one dense matrix; the
    integers are those of the level-by-level synthesis and adjoint."""
    from wavecore import quantize as quantize_module
    from wavecore.filters import get_wavelet

    rng = np.random.default_rng(11)
    length = 66 if (wavelet, boundary) == ("bspline2", "open") else 64  # fits 3 levels
    points = np.cumsum(rng.normal(size=(length, 2)), axis=0)
    coeffs = wavedec(points, wavelet, boundary, 3)
    lengths = tuple(len(band) for band in coeffs)
    name = get_wavelet(wavelet).name
    assert quantize_module._dense_synthesis(lengths, name, boundary) is not None

    def integers() -> list[np.ndarray]:
        quantize_module._dense_synthesis.cache_clear()
        q, _ = quantize_module.quantize_bands(
            coeffs, 0.3, wavelet=wavelet, boundary=boundary, axes=(0,)
        )
        return [np.asarray(band) for band in q]

    dense = integers()
    monkeypatch.setattr(quantize_module, "_DENSE_LOOP_LENGTH", 0)
    banded = integers()
    quantize_module._dense_synthesis.cache_clear()
    assert all(np.array_equal(a, b) for a, b in zip(dense, banded, strict=True))
    assert any(np.count_nonzero(band) for band in dense[1:])
