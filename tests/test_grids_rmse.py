"""RMSE and PSNR targets on grids: the interpolation coder first, the wavelet core where smaller,
and the wavelet core's step found from its coefficients (wavecore.gridcore)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_grids import terrain  # one terrain generator for the grid tests

import wavecore
from wavecore.gridcore import SteppedCore


def rmse(decoded: np.ndarray, original: np.ndarray) -> float:
    finite = ~np.isnan(original)
    diff = decoded.astype(np.float64)[finite] - original.astype(np.float64)[finite]
    return float(np.sqrt(np.mean(diff * diff)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("target", [0.05, 0.5, 5.0])
def test_rmse_met_closely_on_fields(dtype: type, target: float) -> None:
    data = terrain((96, 130), seed=3).astype(dtype)
    bundle = wavecore.encode_grid(data, rmse=target)
    measured = rmse(wavecore.decode(bundle), data)
    assert measured <= target
    assert measured >= 0.9 * target  # aimed at the target, not far below it (bytes wasted)
    assert abs(wavecore.inspect(bundle)["rmse"] - measured) <= 1e-6 * target


def test_high_rates_take_the_interpolation_coder_and_its_bound() -> None:
    data = terrain((128, 128), seed=4).astype(np.float32)
    bundle = wavecore.encode_grid(data, rmse=0.05)  # some 8 bits a sample
    info = wavecore.inspect(bundle)
    assert info["wavelet"] == "interpolation"
    # Its errors are uniform within t = sqrt(3) × rmse: a bound that holds, and is recorded.
    out = wavecore.decode(bundle)
    assert np.max(np.abs(out.astype(np.float64) - data)) <= info["max_error"]
    assert info["max_error"] <= np.sqrt(3.0) * 0.05


def test_low_rates_keep_the_smaller_of_the_two_coders() -> None:
    data = terrain((128, 128), seed=5, exponent=3.0)
    target = 8.0  # well under 4 bits a sample: the wavelet core is tried too
    default = wavecore.encode_grid(data, rmse=target)
    wavelet = wavecore.encode_grid(data, rmse=target, wavelet="cdf97")
    assert len(default) <= len(wavelet)
    assert 8 * len(default) / data.size < 4.0
    assert rmse(wavecore.decode(default), data) <= target


def test_rmse_on_a_volume_with_holes() -> None:
    data = terrain((12, 40, 48), seed=6, exponent=1.8)
    data[3:5, 10:20, 5:30] = np.nan
    bundle = wavecore.encode_grid(data, rmse=0.3)
    out = wavecore.decode(bundle)
    assert np.array_equal(np.isnan(out), np.isnan(data))
    assert rmse(out, data) <= 0.3


def test_psnr_on_a_volume() -> None:
    data = terrain((8, 32, 32), seed=7) + 250.0
    out = wavecore.decode(wavecore.encode_grid(data, psnr=60))
    mse = np.mean((out - data) ** 2)
    assert 20 * np.log10(1000.0) - 10 * np.log10(mse) >= 60


@pytest.mark.parametrize("wavelet", ["cdf97", "bspline2"])
def test_named_wavelets_meet_rmse_through_the_wavelet_core(wavelet: str) -> None:
    data = terrain((90, 110), seed=8).astype(np.float32)
    bundle = wavecore.encode_grid(data, rmse=0.4, wavelet=wavelet)
    assert wavecore.inspect(bundle)["wavelet"] == wavelet
    measured = rmse(wavecore.decode(bundle), data)
    assert 0.85 * 0.4 <= measured <= 0.4


def test_open_loop_prediction_matches_the_decoded_rmse() -> None:
    # The step search relies on the coefficient-domain prediction: check it against what the
    # synthesis of the coded core really gives (cdf97 is nearly orthogonal).
    data = terrain((128, 160), seed=9)
    core = SteppedCore(data, "cdf97", None, ("open", "open"))
    for step in (0.05, 0.5, 5.0):
        bundle, decoded = core.encode(step)
        measured = rmse(decoded, data)
        assert core.predicted_rmse(step) == pytest.approx(measured, rel=0.03)
        assert np.array_equal(wavecore.decode(bundle), decoded)  # what the decoder returns
    step = core.step_for(0.7, 3.0)
    assert core.predicted_rmse(step) == pytest.approx(0.7, rel=3e-3)


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    rows=st.integers(2, 40),
    cols=st.integers(2, 40),
    target=st.floats(1e-3, 50.0),
)
def test_rmse_target_always_met(seed: int, rows: int, cols: int, target: float) -> None:
    data = terrain((rows, cols), seed=seed).astype(np.float32)
    out = wavecore.decode(wavecore.encode_grid(data, rmse=target))
    assert out.dtype == data.dtype and out.shape == data.shape
    assert rmse(out, data) <= target


@pytest.mark.parametrize("shape", [(150, 170), (10, 48, 40)])
@pytest.mark.parametrize("bpp", [5.0, 9.0])
def test_high_bpp_by_interpolation_never_exceeded(shape: tuple[int, ...], bpp: float) -> None:
    data = terrain(shape, seed=10).astype(np.float32)
    bundle = wavecore.encode_grid(data, bpp=bpp)
    assert 8 * len(bundle) / data.size <= bpp
    assert 8 * len(bundle) / data.size >= 0.95 * bpp
    info = wavecore.inspect(bundle)
    assert info["wavelet"] == "interpolation"
    assert abs(rmse(wavecore.decode(bundle), data) - info["rmse"]) <= 1e-6 * info["rmse"]


def test_high_bpp_beats_the_wavelet_core_at_the_same_budget() -> None:
    # Why rates of 4 bpp and more go to the interpolation coder: a lower RMSE in as many bytes.
    data = terrain((128, 128), seed=11).astype(np.float32)
    default = wavecore.encode_grid(data, bpp=6.0)
    wavelet = wavecore.encode_grid(data, bpp=6.0, wavelet="cdf97")
    assert rmse(wavecore.decode(default), data) < rmse(wavecore.decode(wavelet), data)


_NOISE = np.random.default_rng(0).standard_normal((64, 64))


@pytest.mark.parametrize(
    ("data", "target"),
    [
        (np.where(_NOISE > 0, 65504, -65504).astype(np.float16), {"psnr": 1000}),
        (_NOISE.astype(np.float16), {"rmse": 1e300}),
        (_NOISE.astype(np.float16), {"psnr": 30}),
        (_NOISE.astype(np.float16), {"rmse": 0.01, "wavelet": "bspline2"}),
        (_NOISE * 1e-300, {"psnr": 1e-9}),
        (_NOISE * 1e-300, {"rmse": 1e-300}),
        (_NOISE * 1e-300, {"psnr": 1000}),
        (_NOISE * 1e-300, {"psnr": 60, "wavelet": "cdf97"}),
        (_NOISE * 5e-324, {"psnr": 1000}),
        (_NOISE * 5e-324, {}),
        (_NOISE * 5e-324, {"rmse": 1e300}),
        (_NOISE * 1e-300, {"rmse": 1e300}),
        (_NOISE * 1e200, {"rmse": 0.01, "wavelet": "bspline2"}),
        (np.zeros((64, 64)), {"rmse": 5e-324}),
        (np.full((64, 64), 3.0), {"rmse": 5e-324}),
        (np.full((64, 64), 65504, np.float16), {"rmse": 5e-324}),
        (np.full((64, 64), 3, np.float16), {"psnr": 1000}),
    ],
    ids=lambda value: (
        str(value) if isinstance(value, dict) else f"{value.dtype}×{np.max(np.abs(value)):.0e}"
    ),
)
def test_extreme_targets_on_extreme_values_are_met(data: np.ndarray, target: dict) -> None:
    """Float16 grids, values near 1e-300 or subnormal, targets of 1000 dB or 1e300: each is
    coded to its target (psnr=1000 or a subnormal rmse exactly), never a crash."""
    bundle = wavecore.encode_grid(data, **target)
    back = wavecore.decode(bundle)
    assert back.dtype == data.dtype and back.shape == data.shape
    error = rmse(back, data)
    if "rmse" in target:
        assert error <= target["rmse"]
    elif "psnr" in target:
        span = float(np.ptp(data.astype(np.float64))) or 1.0
        assert error <= span * 10 ** (-target["psnr"] / 20)
    else:  # the default: 1e-3 of the range as a bound
        assert np.max(np.abs(back - data)) <= 1e-3 * np.ptp(data)
