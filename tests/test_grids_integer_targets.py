"""RMSE, PSNR and bpp targets on integer grids: the coder chosen from the target before coding,
the wavelet core's tries measured before any entropy coding, and a bpp core's output taken from
the rate control instead of a decoding."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_grids import terrain  # one terrain generator for the grid tests

import wavecore
from wavecore import grids
from wavecore.blockcoder import block_lengths
from wavecore.codec import fixedstep, ratecontrol
from wavecore.codec.encode import encode_surface_and_output
from wavecore.gridcore import SteppedCore
from wavecore.layout import as_levels


def rmse(decoded: np.ndarray, original: np.ndarray) -> float:
    diff = decoded.astype(np.float64) - original.astype(np.float64)
    return float(np.sqrt(np.mean(diff * diff)))


def integer_terrain(dtype: type, shape: tuple[int, ...] = (96, 130), seed: int = 3) -> np.ndarray:
    info = np.iinfo(dtype)
    scale = min(1.0, (float(info.max) - max(float(info.min), 0.0)) / 1000.0)
    return np.rint(terrain(shape, seed=seed) * scale).astype(dtype)


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.int32])
@pytest.mark.parametrize("psnr", [40.0, 50.0, 60.0, 70.0])
def test_psnr_on_integer_grids_is_met_in_their_dtype(dtype: type, psnr: float) -> None:
    data = integer_terrain(dtype)
    out = wavecore.decode(wavecore.encode_grid(data, psnr=psnr))
    assert out.dtype == data.dtype and out.shape == data.shape
    span = float(data.max()) - float(data.min())
    assert rmse(out, data) <= span * 10.0 ** (-psnr / 20.0)


def test_sub_unit_rmse_is_coded_exactly_by_interpolation() -> None:
    data = integer_terrain(np.int16)
    for target in (0.05, 0.3, 0.4):
        bundle = wavecore.encode_grid(data, rmse=target)
        assert wavecore.inspect(bundle)["wavelet"] == "interpolation"
        np.testing.assert_array_equal(wavecore.decode(bundle), data)
    # Smaller than the wavelet core's code of the same target (whose output is rounded).
    assert len(wavecore.encode_grid(data, rmse=0.3)) < len(
        wavecore.encode_grid(data, rmse=0.3, wavelet="cdf97")
    )


def test_rmse_just_above_one_unit_bound_takes_the_interpolation_rung() -> None:
    data = integer_terrain(np.int16, (128, 128), seed=4)  # many bits a sample
    target = 0.84
    bundle = wavecore.encode_grid(data, rmse=target)
    assert wavecore.inspect(bundle)["wavelet"] == "interpolation"
    out = wavecore.decode(bundle)
    assert rmse(out, data) <= target
    assert np.max(np.abs(out.astype(np.int64) - data)) <= 1
    assert len(bundle) < len(wavecore.encode_grid(data, rmse=target, wavelet="cdf97"))


def test_the_rung_at_few_bits_a_sample_keeps_the_smaller_coder() -> None:
    # A smooth uint8 grid: the rung costs under 3 bits a sample, the wavelet core codes too.
    data = np.rint(terrain((128, 128), seed=6, exponent=3.0) / 8.0).astype(np.uint8)
    target = 0.85
    bundle = wavecore.encode_grid(data, rmse=target)
    wavelet = wavecore.encode_grid(data, rmse=target, wavelet="cdf97")
    rung = grids._predictive_bundle(
        data, grids.LAYOUT_FIELD, data.astype(np.float64), np.zeros(data.shape, bool), b"", 1.0
    )[0]
    assert 8 * len(rung) < 3.0 * data.size
    assert len(bundle) == min(len(wavelet), len(rung))
    assert rmse(wavecore.decode(bundle), data) <= target


def test_mid_rates_take_the_wavelet_core_coded_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """An int16 grid's first open-loop step usually misses (the rounding of the decoded samples,
    the model's bias on real terrain): the miss costs a synthesis, never an entropy coding."""
    data = integer_terrain(np.int16, (160, 200), seed=7)
    codings = []
    encode_levels = fixedstep.encode_levels

    def counted(*args: object, **kwargs: object) -> object:
        codings.append(1)
        return encode_levels(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(fixedstep, "encode_levels", counted)
    for target in (1.5, 3.0, 6.0):
        codings.clear()
        bundle = wavecore.encode_grid(data, rmse=target)
        assert wavecore.inspect(bundle)["wavelet"] == "cdf97"
        assert len(codings) == 1
        measured = rmse(wavecore.decode(bundle), data)
        assert 0.95 * target <= measured <= target


@pytest.mark.parametrize("bias", [0.9, 0.94, 0.97, 1.0])
def test_a_missed_try_is_corrected_through_the_open_loop_model(
    monkeypatch: pytest.MonkeyPatch, bias: float
) -> None:
    """The open loop's prediction was 1-6 % low on the real elevation model, and scaling the
    step by the ratio missed again at low rates (three or four syntheses at 40 dB): the retry
    corrects the model by what the miss measured, and lands at most two tries in, just under
    the target (a coarser step than a safe margin would take: fewer bytes)."""
    data = integer_terrain(np.int16, (160, 200), seed=9)
    predicted_rmse = SteppedCore.predicted_rmse
    monkeypatch.setattr(
        SteppedCore, "predicted_rmse", lambda self, step: bias * predicted_rmse(self, step)
    )
    tries: list[float] = []
    reconstructed = SteppedCore.reconstructed

    def counted(self: SteppedCore, step: float) -> object:
        tries.append(step)
        return reconstructed(self, step)

    monkeypatch.setattr(SteppedCore, "reconstructed", counted)
    span = float(data.max()) - float(data.min())
    for psnr in (40.0, 45.0, 50.0):
        tries.clear()
        target = span * 10.0 ** (-psnr / 20.0)
        measured = rmse(wavecore.decode(wavecore.encode_grid(data, psnr=psnr)), data)
        assert 0.99 * target <= measured <= target
        assert 1 <= len(tries) <= 2, tries


def test_sub_unit_rmse_on_the_wavelet_core_is_aimed_at_the_target() -> None:
    """Rounding takes most sub-unit errors to 0: the search steps up from a try far under the
    target instead of coding it (named wavelet, so the wavelet core runs)."""
    data = integer_terrain(np.int16, (128, 160), seed=8)
    for target in (0.45, 0.55):
        bundle = wavecore.encode_grid(data, rmse=target, wavelet="cdf97")
        measured = rmse(wavecore.decode(bundle), data)
        assert 0.9 * target <= measured <= target


def test_reconstructed_is_what_the_coded_core_decodes_to() -> None:
    data = terrain((70, 90), seed=9)
    core = SteppedCore(data, "cdf97", None, ("open", "open"))
    quantized, output = core.reconstructed(2.5)
    bundle, decoded = core.code(quantized, output)
    np.testing.assert_array_equal(wavecore.decode(bundle), output)
    assert decoded is output
    assert bundle == core.encode(2.5)[0]


@pytest.mark.parametrize("bpp", [0.5, 1.5, 3.0])
@pytest.mark.parametrize("wavelet", ["cdf97", "bspline2"])
def test_the_rate_controls_output_is_the_decoded_core(bpp: float, wavelet: str) -> None:
    data = terrain((150, 210), seed=10)
    bundle, output = encode_surface_and_output(
        data, bpp=bpp, wavelet=wavelet, level=None, boundary=("open", "open")
    )
    np.testing.assert_array_equal(output, wavecore.decode(bundle))
    assert 8 * len(bundle) <= bpp * data.size


@pytest.mark.parametrize("dtype", [np.int16, np.uint8, np.int32])
def test_a_bpp_grid_is_not_decoded_to_be_measured(
    monkeypatch: pytest.MonkeyPatch, dtype: type
) -> None:
    """The rate control's own reconstruction is measured, rounded and clipped as the cast
    does, in one compiled pass: no decoding, and no array of the grid's dtype made."""
    data = integer_terrain(dtype, (300, 330), seed=11)

    def refused(*args: object, **kwargs: object) -> None:
        raise AssertionError("the core was decoded, or cast to be measured")

    monkeypatch.setattr(grids, "_decode_core", refused)
    monkeypatch.setattr(grids, "_to_dtype", refused)
    bundle = wavecore.encode_grid(data, bpp=2.0)
    monkeypatch.undo()  # decoded below, to check what the encoder measured
    assert 8 * len(bundle) <= 2.0 * data.size
    info = wavecore.inspect(bundle)
    out = wavecore.decode(bundle)
    assert out.dtype == data.dtype
    assert info["rmse"] == pytest.approx(rmse(out, data), rel=1e-9, abs=1e-12)


def test_grid_bpp_samples_fewer_blocks_than_the_picture_holds() -> None:
    """A grid of 20-39 blocks in its sampled levels sampled all of them (a second full coding);
    the grids' rate control takes a third of them."""
    data = terrain((900, 1100), seed=12)
    ratecontrol.coding_counts.reset()
    wavecore.encode_grid(data.astype(np.int16), bpp=2.0)
    sampled = ratecontrol.coding_counts.sampled_blocks
    ratecontrol.coding_counts.reset()
    wavecore.encode_surface(data, bpp=2.0, wavelet="cdf97")  # images' and surfaces' sample
    assert 0 < sampled < ratecontrol.coding_counts.sampled_blocks


def test_grid_bpp_sample_takes_a_third_of_each_level() -> None:
    """The grids' sample codes single-block levels whole and every third block of the others
    (levels of up to four blocks were coded whole, and every other block of the rest: most of
    a coding's bytes); the bundle still lands in the budget's window after one full coding."""
    data = terrain((1000, 1200), seed=13).astype(np.int16)
    ratecontrol.coding_counts.reset()
    bundle = wavecore.encode_grid(data, bpp=2.0)
    counts = ratecontrol.coding_counts
    coeffs = SteppedCore(data.astype(np.float64), "cdf97", None, ("open", "open")).coeffs
    _, regions = block_lengths(as_levels(coeffs), True, 128, np.zeros(0, dtype=np.int64))
    per_level = np.bincount(regions[:, 0])
    most = sum(1 if n == 1 else -(-n // 3) for n in per_level)
    assert 0 < counts.sampled_blocks <= most < len(regions)
    assert counts.full_codings == 1
    budget = math.floor(2.0 * data.size / 8)
    assert 0.975 * budget <= len(bundle) <= budget


@pytest.mark.parametrize("bpp", [1.0, 2.0, 3.0])
def test_grid_bpp_prediction_aims_at_the_budget_itself(bpp: float) -> None:
    """The grids' sampled prediction is solved for the budget itself (the pictures' looser
    window left codings anywhere from 98.5 % of it, and trimmed those aimed 1 % over it): one
    full coding, no block coded again, and at least 99 % of the budget used."""
    data = terrain((1000, 1200), seed=13).astype(np.int16)
    ratecontrol.coding_counts.reset()
    bundle = wavecore.encode_grid(data, bpp=bpp)
    assert wavecore.inspect(bundle)["wavelet"] == "cdf97"
    assert ratecontrol.coding_counts.full_codings == 1
    assert ratecontrol.coding_counts.blocks_recoded == 0
    budget = math.floor(bpp * data.size / 8)
    assert 0.99 * budget <= len(bundle) <= budget


def test_bpp_that_affords_the_exact_code_gets_it() -> None:
    data = integer_terrain(np.int16, (300, 330), seed=13)
    exact = grids._predictive_bundle(
        data, grids.LAYOUT_FIELD, data.astype(np.float64), np.zeros(data.shape, bool), b"", 0.0
    )[0]
    exact_bpp = 8 * len(exact) / data.size
    roomy = wavecore.encode_grid(data, bpp=1.05 * exact_bpp)
    np.testing.assert_array_equal(wavecore.decode(roomy), data)
    tight = wavecore.encode_grid(data, bpp=0.9 * exact_bpp)  # lossy, within its budget
    assert 8 * len(tight) <= 0.9 * exact_bpp * data.size
    assert 0 < rmse(wavecore.decode(tight), data) < 1.0


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    rows=st.integers(9, 70),
    cols=st.integers(9, 70),
    dtype=st.sampled_from([np.uint8, np.int16, np.uint16, np.int32]),
    target=st.floats(0.05, 20.0),
)
def test_integer_rmse_always_met(
    seed: int, rows: int, cols: int, dtype: type, target: float
) -> None:
    data = integer_terrain(dtype, (rows, cols), seed=seed)
    bundle = wavecore.encode_grid(data, rmse=target)
    out = wavecore.decode(bundle)
    assert out.dtype == data.dtype
    assert rmse(out, data) <= target
    assert math.isclose(wavecore.inspect(bundle)["rmse"], rmse(out, data), abs_tol=1e-9)


@pytest.mark.parametrize("dtype", [np.uint8, np.int8, np.int16, np.uint16, np.int32, np.uint32])
def test_rounded_measure_is_the_cast_measured(dtype: type) -> None:
    """The RMSE search's fused pass (round, clip, compare) gives what the cast then the plain
    pass give, clipping at the dtype's ends included."""
    from wavecore.gridcore import squared_and_largest, squared_and_largest_rounded

    info = np.iinfo(dtype)
    rng = np.random.default_rng(14)
    original = rng.integers(int(info.min), int(info.max), size=(37, 41), endpoint=True)
    original = original.astype(np.float64)
    decoded = original + rng.normal(0.0, 3.0, original.shape)
    decoded.flat[:5] = [info.min - 7.3, info.max + 9.9, 0.5, -0.5, 2.5]  # clips, ties to even
    expected = squared_and_largest(grids._to_dtype(decoded, np.dtype(dtype)), original)
    assert squared_and_largest_rounded(decoded, original, np.dtype(dtype)) == expected
