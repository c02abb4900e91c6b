"""Grids: the pointwise bound on every sample, NaN cells, integers, volumes, targets, bundles."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import BundleError, InvalidParameter
from wavecore.grids import (
    decode_mask,
    decode_outliers,
    decode_positions,
    encode_mask,
    encode_outliers,
    encode_positions,
    fill_missing,
    inspect_grid,
)


def terrain(shape: tuple[int, ...], seed: int = 0, exponent: float = 2.2) -> np.ndarray:
    """A terrain-like random field (power-law spectrum), 0..1000."""
    rng = np.random.default_rng(seed)
    freqs = np.meshgrid(*[np.fft.fftfreq(n) for n in shape], indexing="ij")
    radius2 = sum(f * f for f in freqs)
    radius2.flat[0] = 1.0
    field = np.fft.ifftn(np.fft.fftn(rng.standard_normal(shape)) * radius2 ** (-exponent / 4))
    field = field.real
    return 1000.0 * (field - field.min()) / (field.max() - field.min())


def largest_error(decoded: np.ndarray, original: np.ndarray) -> float:
    """The largest error over the finite cells (NaN cells must match, checked apart)."""
    finite = ~np.isnan(original.astype(np.float64))
    diff = decoded.astype(np.float64)[finite] - original.astype(np.float64)[finite]
    return float(np.max(np.abs(diff))) if diff.size else 0.0


def assert_bound(data: np.ndarray, bound: float, **options: object) -> bytes:
    bundle = wavecore.encode_grid(data, max_error=bound, **options)
    out = wavecore.decode(bundle)
    assert out.shape == data.shape and out.dtype == data.dtype.newbyteorder("=")
    original = data.astype(np.float64)
    assert np.array_equal(np.isnan(out.astype(np.float64)), np.isnan(original))
    assert largest_error(out, data) <= bound
    return bundle


# --------------------------------------------------------------------------------------------
# The bound
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("relative", [1e-4, 1e-3, 1e-2, 0.2])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_bound_holds_on_every_sample(relative: float, dtype: str) -> None:
    data = terrain((97, 130), seed=1).astype(dtype)
    bundle = assert_bound(data, relative * 1000.0)
    info = wavecore.inspect(bundle)
    assert info["kind"] == "grid" and info["max_error"] == pytest.approx(relative * 1000.0)
    assert info["largest_error"] <= relative * 1000.0


def test_outliers_are_corrected_when_the_core_overshoots() -> None:
    # The core is aimed at an RMSE well above zero, so some samples overshoot the bound: the
    # bound holds only because they are corrected.
    # (A wavelet named: the wavelet core and its outliers, not the interpolation coder.)
    data = terrain((128, 128), seed=2)
    bundle = assert_bound(data, 0.5, wavelet="cdf97")
    info = inspect_grid(bundle)
    assert info["outlier_bytes"] > 0
    core = wavecore.decode(_core_of(bundle))
    assert np.max(np.abs(core - data)) > 0.5  # the core alone misses it


def _core_of(bundle: bytes) -> bytes:
    info = inspect_grid(bundle)
    start = len(bundle) - 4 - info["outlier_bytes"] - info["mask_bytes"] - info["core_bytes"]
    return bundle[start : start + info["core_bytes"]]


@pytest.mark.parametrize("shape", [(1, 1), (1, 5000), (5000, 1), (2, 3), (3, 1, 700)])
def test_thin_and_tiny_grids_hold_the_bound(shape: tuple[int, ...]) -> None:
    data = np.random.default_rng(32).standard_normal(shape).cumsum(axis=-1)
    assert_bound(data.astype(">f8"), 0.01)


@pytest.mark.parametrize("wavelet", ["cdf97", "bspline2", "haar"])
def test_every_wavelet_holds_the_bound(wavelet: str) -> None:
    data = terrain((40, 57), seed=3)
    bundle = assert_bound(data, 2.0, wavelet=wavelet)
    assert wavecore.inspect(bundle)["wavelet"] == wavelet


def test_bound_on_a_tiny_tolerance_of_huge_values_is_still_held() -> None:
    # 1e300 with a bound of 1e286: corrections of that unit would lose bits; the encoder
    # stores whatever the corrections cannot reach exactly.
    data = terrain((20, 30), seed=4) * 1e297
    assert_bound(data, 1e286)


def test_huge_values_under_a_high_bpp_budget_raise_no_numpy_warning() -> None:
    """The interpolation coder's weight fit overflows on values near the float64 limit and
    falls back to its default weights, without NumPy's overflow warnings reaching the user."""
    data = terrain((200, 260), seed=6) * 1e300
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bundle = wavecore.encode_grid(data, bpp=4.0)
    assert 8 * len(bundle) <= 4.0 * data.size
    assert wavecore.decode(bundle).shape == data.shape


@pytest.mark.parametrize("shape", [(40, 2, 2), (48, 56)])
@pytest.mark.parametrize("target", [{"psnr": 60}, {"wavelet": "cdf97", "psnr": 50}])
def test_huge_values_under_a_psnr_target_meet_it(
    shape: tuple[int, ...], target: dict[str, Any]
) -> None:
    # The RMSE aim of 1e297 was squared and overflowed (an OverflowError, not a library error).
    data = np.cumsum(np.random.default_rng(14).standard_normal(shape), axis=0) * 1e300
    out = wavecore.decode(wavecore.encode_grid(data, **target))
    relative = np.sqrt(np.mean(((out - data) / np.ptp(data)) ** 2))
    assert -20 * np.log10(relative) >= target["psnr"] - 1e-6


def test_a_range_past_the_largest_float_keeps_a_finite_default_bound() -> None:
    # max - min of ±1.8e308 overflowed: the default bound was inf, and cells decoded as NaN
    biggest = np.finfo(np.float64).max
    data = np.where(np.random.default_rng(3).random((32, 32)) > 0.5, biggest, -biggest)
    bundle = wavecore.encode_grid(data)
    bound = wavecore.inspect(bundle)["max_error"]
    assert bound == pytest.approx(1e-3 * biggest * 2)
    out = wavecore.decode(bundle)
    assert np.isfinite(out).all()
    assert np.max(np.abs(out / 2 - data / 2)) <= bound / 2


@pytest.mark.parametrize("wavelet", [None, "cdf97"])
def test_a_grid_of_subnormals_is_coded_exactly(wavelet: str | None) -> None:
    # scaled up by 2**1073, the core's step overflowed math.ldexp (an OverflowError)
    data = np.full((32, 32), 5e-324)
    out = wavecore.decode(wavecore.encode_grid(data, wavelet=wavelet))
    assert np.array_equal(out, data)


def test_zero_bound_on_floats_is_exact() -> None:
    data = terrain((16, 21), seed=5)
    out = wavecore.decode(wavecore.encode_grid(data, max_error=0))
    assert np.array_equal(out, data)


@pytest.mark.parametrize("dtype", ["float16", "float32", "float64"])
def test_narrow_floats_hold_the_bound_after_their_own_rounding(dtype: str) -> None:
    data = (terrain((33, 48), seed=6) / 10).astype(dtype)
    assert_bound(data, 0.01)


# --------------------------------------------------------------------------------------------
# Integers
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", ["uint8", "int8", "uint16", "int16", "int32", "uint32", "int64"])
def test_integer_grids_are_lossless(dtype: str) -> None:
    info = np.iinfo(dtype)
    rng = np.random.default_rng(7)
    lo, hi = max(info.min, -30000), min(info.max, 30000)
    data = (lo + (terrain((31, 44), seed=7) / 1000.0) * (hi - lo)).astype(dtype)
    data[3, 4] = rng.integers(lo, hi)
    out = wavecore.decode(wavecore.encode_grid(data, lossless=True))
    assert out.dtype == data.dtype and np.array_equal(out, data)


def test_whole_numbers_stored_as_floats_may_come_back_exact() -> None:
    data = np.rint(terrain((60, 70), seed=30)).astype(np.float32)  # metres, as float32
    bundle = wavecore.encode_grid(data, max_error=0.1)
    out = wavecore.decode(bundle)
    assert out.dtype == np.float32 and np.array_equal(out, data)
    assert inspect_grid(bundle)["lossless"]  # cheaper than the bounded code at so tight a bound
    loose = wavecore.encode_grid(data, max_error=20.0)
    assert not inspect_grid(loose)["lossless"] and len(loose) < len(bundle)
    assert largest_error(wavecore.decode(loose), data) <= 20.0


def test_wide_integers_are_lossless_through_the_bound_path() -> None:
    data = (terrain((25, 26), seed=8) * 1e6).astype(np.int64) - 10**8  # range 1e9
    bundle = wavecore.encode_grid(data, lossless=True)
    assert np.array_equal(wavecore.decode(bundle), data)
    assert inspect_grid(bundle)["max_error"] == 0.0


@pytest.mark.parametrize("bound", [0.5, 1, 2.7, 10])
def test_integer_bound_counts_whole_units(bound: float) -> None:
    data = np.rint(terrain((50, 61), seed=9)).astype(np.int16)
    assert_bound(data, bound)


def test_default_target_is_a_thousandth_of_the_range() -> None:
    data = terrain((40, 40), seed=10)
    bundle = wavecore.encode_grid(data)
    assert largest_error(wavecore.decode(bundle), data) <= 1.0  # 1e-3 × range 1000
    assert inspect_grid(bundle)["max_error"] == pytest.approx(1.0)


# --------------------------------------------------------------------------------------------
# NaN cells
# --------------------------------------------------------------------------------------------


def test_nan_cells_come_back_as_nan_exactly() -> None:
    data = terrain((80, 90), seed=11)
    data[10:30, 20:45] = np.nan  # a lake
    data[:, 70] = np.nan  # a stripe
    data[::7, ::11] = np.nan  # scattered
    bundle = assert_bound(data.astype(np.float32), 0.5)
    assert inspect_grid(bundle)["mask_bytes"] > 0


def test_nan_holes_cost_little() -> None:
    data = terrain((128, 128), seed=12)
    holed = data.copy()
    holed[40:80, 30:90] = np.nan
    plain = len(wavecore.encode_grid(data, max_error=1.0))
    with_hole = len(wavecore.encode_grid(holed, max_error=1.0))
    assert with_hole < plain  # fewer finite cells: the smooth fill must not cost more


def test_all_nan_grid() -> None:
    data = np.full((9, 13), np.nan, dtype=np.float32)
    out = wavecore.decode(wavecore.encode_grid(data, max_error=0.1))
    assert out.dtype == np.float32 and np.isnan(out).all()


def test_fill_stays_within_the_known_range_and_keeps_known_cells() -> None:
    data = terrain((50, 70), seed=13)
    missing = np.zeros(data.shape, bool)
    missing[10:40, 5:60] = True
    filled = fill_missing(np.where(missing, np.nan, data), missing)
    assert np.array_equal(filled[~missing], data[~missing])
    known = data[~missing]
    assert known.min() <= filled[missing].min() and filled[missing].max() <= known.max()


def test_mask_round_trip_any_pattern() -> None:
    rng = np.random.default_rng(14)
    for shape in [(1, 1), (1, 50), (50, 1), (7, 9, 3)]:
        for density in (0.0, 0.1, 0.9, 1.0):
            mask = rng.random(shape) < density
            assert np.array_equal(decode_mask(encode_mask(mask), shape), mask)


# --------------------------------------------------------------------------------------------
# Hypothesis: random, constant, huge, holed, big-endian, 1 × N
# --------------------------------------------------------------------------------------------

_shapes = st.tuples(st.integers(1, 24), st.integers(1, 40))


@st.composite
def grids(draw: st.DrawFn) -> np.ndarray:
    shape = draw(_shapes)
    kind = draw(st.sampled_from(["random", "constant", "smooth", "huge", "holes", "integer"]))
    dtype = draw(st.sampled_from(["<f8", ">f8", "<f4", ">f4"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if kind == "random":
        data = rng.standard_normal(shape) * draw(st.sampled_from([1e-6, 1.0, 1e4]))
    elif kind == "constant":
        data = np.full(shape, draw(st.floats(-1e6, 1e6)))
    elif kind == "smooth":
        y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
        data = np.sin(x / 5.0) * np.cos(y / 4.0) * 100.0
    elif kind == "huge":
        data = rng.standard_normal(shape) * 1e300
        dtype = draw(st.sampled_from(["<f8", ">f8"]))
    elif kind == "holes":
        data = rng.standard_normal(shape).cumsum(axis=1)
        data[rng.random(shape) < draw(st.floats(0.0, 1.0))] = np.nan
    else:
        data = rng.integers(-2000, 2000, shape)
        dtype = draw(st.sampled_from(["<i2", ">i2", "<i4", ">u2"]))
        if dtype == ">u2":
            data = np.abs(data)
    return np.asarray(data).astype(dtype)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=grids(), relative=st.sampled_from([0.0, 1e-5, 1e-3, 0.05, 0.5]))
def test_bound_holds_on_every_sample_of_any_grid(data: np.ndarray, relative: float) -> None:
    finite = data[~np.isnan(data.astype(np.float64))].astype(np.float64)
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    bound = relative * (span if span > 0 else 1.0)
    if data.dtype.kind == "f" and math.isinf(bound):
        bound = 1e300
    assert_bound(data, bound)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    shape=_shapes,
    dtype=st.sampled_from(["<u1", "<i2", ">i2", "<u2", ">i4", "<i8"]),
    seed=st.integers(0, 2**32 - 1),
)
def test_lossless_integers_of_any_shape(shape: tuple[int, int], dtype: str, seed: int) -> None:
    info = np.iinfo(np.dtype(dtype))
    data = np.random.default_rng(seed).integers(
        max(info.min, -(2**20)), min(info.max, 2**20), shape, endpoint=True
    )
    data = data.astype(dtype)
    out = wavecore.decode(wavecore.encode_grid(data, lossless=True))
    assert np.array_equal(out, data)


# --------------------------------------------------------------------------------------------
# Volumes
# --------------------------------------------------------------------------------------------


def test_volume_bound_shape_and_dtype() -> None:
    volume = terrain((12, 40, 36), seed=15, exponent=1.8).astype(np.float32)
    volume[3, 5:15, 5:15] = np.nan
    bundle = assert_bound(volume, 0.3)
    assert inspect_grid(bundle)["layout"] == "volume"


def test_volume_lossless_integers() -> None:
    volume = np.rint(terrain((5, 17, 23), seed=16)).astype(np.int16)
    assert np.array_equal(wavecore.decode(wavecore.encode_grid(volume, lossless=True)), volume)


def test_volume_coarse_level_keeps_its_slices() -> None:
    volume = terrain((6, 64, 48), seed=17)
    coarse = wavecore.decode(wavecore.encode_grid(volume, max_error=1.0, level=3), level=2)
    assert coarse.shape == (6, 16, 12)
    # Each coarse slice is the coarse level of that slice coded alone (within the quantizer's
    # error at the coarse level, far below the data's spread of about 130).
    for index in (0, 2, 5):
        alone = wavecore.decode(
            wavecore.encode_grid(volume[index], max_error=1.0, level=3), level=2
        )
        assert np.max(np.abs(coarse[index] - alone)) < 5.0


# --------------------------------------------------------------------------------------------
# Other targets
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("rmse", [0.1, 2.0, 20.0])
def test_rmse_target_is_met(rmse: float) -> None:
    data = terrain((70, 80), seed=18)
    data[5:15, 5:25] = np.nan
    out = wavecore.decode(wavecore.encode_grid(data, rmse=rmse))
    finite = ~np.isnan(data)
    measured = np.sqrt(np.mean((out[finite] - data[finite]) ** 2))
    assert measured <= rmse and measured > 0.3 * rmse  # met, not overshot by a mile


def test_rmse_target_on_integers_counts_the_rounding() -> None:
    data = np.rint(terrain((60, 60), seed=19)).astype(np.int16)
    out = wavecore.decode(wavecore.encode_grid(data, rmse=0.7))
    assert np.sqrt(np.mean((out.astype(float) - data) ** 2)) <= 0.7


def test_psnr_target_is_against_the_range() -> None:
    data = terrain((64, 64), seed=20) + 5000.0
    out = wavecore.decode(wavecore.encode_grid(data, psnr=50))
    mse = np.mean((out - data) ** 2)
    assert 20 * np.log10(1000.0) - 10 * np.log10(mse) >= 50


@pytest.mark.parametrize("bpp", [0.5, 2.0])
def test_bpp_target_is_never_exceeded(bpp: float) -> None:
    data = terrain((100, 120), seed=21).astype(np.float32)
    bundle = wavecore.encode_grid(data, bpp=bpp)
    assert 8 * len(bundle) / data.size <= bpp
    assert 8 * len(bundle) / data.size >= 0.8 * bpp


@pytest.mark.parametrize("shape", [(300, 1, 1), (4, 6, 5)])
def test_a_bpp_below_the_smallest_bundle_is_named_per_value_of_the_grid(
    shape: tuple[int, ...],
) -> None:
    # The wavelet core's rate control counts bits per point of a slice; the error speaks of
    # the grid's values, and its figure is a budget that codes.
    from wavecore.errors import BitrateTooLow

    data = np.cumsum(np.random.default_rng(8).standard_normal(shape), axis=0).astype(np.float32)
    with pytest.raises(BitrateTooLow, match="this grid can be coded in: bpp") as caught:
        wavecore.encode_grid(data, bpp=0.05)
    smallest = caught.value.smallest_bytes
    bpp = 8 * smallest / data.size
    assert f"bpp {bpp:.4f} ({smallest} bytes" in str(caught.value)
    assert len(wavecore.encode_grid(data, bpp=bpp)) <= smallest


# --------------------------------------------------------------------------------------------
# Levels and windows
# --------------------------------------------------------------------------------------------


def test_coarse_level_and_its_nan_cells() -> None:
    data = terrain((64, 80), seed=22)
    data[0:16, 0:16] = np.nan  # whole coarse cells
    data[40, 40] = np.nan  # one cell of a coarse cell that keeps data
    bundle = wavecore.encode_grid(data, max_error=0.5, level=3)
    coarse = wavecore.decode(bundle, level=2)
    assert coarse.shape == (16, 20)
    assert np.isnan(coarse[0:4, 0:4]).all() and not np.isnan(coarse[10, 10])
    assert np.count_nonzero(np.isnan(coarse)) == 16


def test_keep_smooths_without_the_corrections_and_keeps_the_nan_cells() -> None:
    data = terrain((48, 64), seed=33)
    data[4:9, 4:9] = np.nan
    bundle = wavecore.encode_grid(data, max_error=0.2)
    smooth = wavecore.decode(bundle, keep=0.1)
    assert smooth.shape == data.shape and np.array_equal(np.isnan(smooth), np.isnan(data))
    assert largest_error(smooth, data) > 0.2  # most details gone: the bound is the full decode's


def test_window_is_the_same_as_slicing() -> None:
    data = terrain((50, 70), seed=23)
    bundle = wavecore.encode_grid(data, max_error=0.2)
    window = (slice(10, 30), slice(5, 60))
    assert np.array_equal(
        wavecore.decode_grid(bundle, window=window), wavecore.decode(bundle)[window]
    )
    with pytest.raises(InvalidParameter, match="window"):
        wavecore.decode_grid(bundle, window=(3, 4))


# --------------------------------------------------------------------------------------------
# Bad input, bad bundles
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("data", "options", "match"),
    [
        (np.zeros(5), {}, "2-D or 3-D"),
        (np.zeros((2, 2, 2, 2)), {}, "2-D or 3-D"),
        (np.zeros((0, 4)), {}, "empty"),
        (np.array([[1.0, np.inf]]), {}, "infinite"),
        (np.zeros((4, 4), bool), {}, "integers or floats"),
        (np.zeros((4, 4)), {"max_error": -1}, "max_error"),
        (np.zeros((4, 4)), {"rmse": 0}, "rmse"),
        (np.zeros((4, 4)), {"max_error": 1, "rmse": 1}, "at most one"),
        (np.zeros((4, 4)), {"lossless": True}, "integer grids"),
        (np.zeros((4, 4), np.int16), {"lossless": True, "max_error": 1}, "lossless"),
        (np.zeros((4, 4)), {"wavelet": "nope"}, "nope"),
        (np.full((4, 4), 2**60, np.int64), {}, "2\\*\\*53"),
    ],
)
def test_bad_input_is_a_clear_error(data: np.ndarray, options: dict, match: str) -> None:
    with pytest.raises(InvalidParameter, match=match):
        wavecore.encode_grid(data, **options)


def test_damaged_bundles_raise_bundle_error() -> None:
    data = terrain((30, 40), seed=24)
    data[3:8, 3:8] = np.nan
    bundle = wavecore.encode_grid(data, max_error=0.3)
    rng = np.random.default_rng(25)
    for cut in (5, 20, len(bundle) // 2, len(bundle) - 1):
        with pytest.raises(BundleError):
            wavecore.decode(bundle[:cut])
    for _ in range(30):
        damaged = bytearray(bundle)
        damaged[int(rng.integers(4, len(bundle)))] ^= 1 << int(rng.integers(0, 8))
        with pytest.raises(BundleError):
            wavecore.decode(bytes(damaged))


@pytest.mark.parametrize("density", [0.0, 1e-4, 0.01, 0.08, 0.5, 1.0])
@pytest.mark.parametrize("size", [1, 7, 5000])
def test_positions_round_trip(density: float, size: int) -> None:
    flags = np.random.default_rng(int(density * 1e4) + size).random(size) < density
    assert np.array_equal(decode_positions(encode_positions(flags), size), flags)


def test_positions_cost_near_their_entropy() -> None:
    p, size = 0.08, 200_000
    flags = np.random.default_rng(31).random(size) < p
    entropy_bytes = size * -(p * math.log2(p) + (1 - p) * math.log2(1 - p)) / 8
    assert len(encode_positions(flags)) < 1.05 * entropy_bytes


def test_crafted_shapes_raise_bundle_error_before_allocating() -> None:
    import struct
    import zlib

    bundle = wavecore.encode_grid(terrain((20, 24), seed=29), max_error=1.0)
    body = bytearray(bundle[:-4])
    for shape in [(2**31, 2**31), (21, 24), (0, 24)]:
        struct.pack_into("<2I", body, 9, *shape)  # the shape field, after the 9-byte head
        crafted = bytes(body) + struct.pack("<I", zlib.crc32(bytes(body)))
        with pytest.raises(BundleError):
            wavecore.decode(crafted)


def test_outlier_section_round_trip_with_escapes_and_exact_values() -> None:
    rng = np.random.default_rng(26)
    flags = rng.random((20, 30)) < 0.2
    count = int(flags.sum())
    multiples = rng.integers(-3, 4, count)
    multiples[multiples == 0] = 1
    multiples[:3] = [10**6, -(10**9), 40]  # escaped
    exact = np.zeros(count, bool)
    exact[5:8] = True
    multiples[exact] = 0
    values = rng.standard_normal(3).astype("<f4")
    section = encode_outliers(flags, multiples, exact, values)
    got = decode_outliers(section, flags.size, np.dtype(np.float32))
    assert np.array_equal(got[0], flags.reshape(-1))
    assert np.array_equal(got[1], multiples) and np.array_equal(got[2], exact)
    assert np.array_equal(got[3], values)


# --------------------------------------------------------------------------------------------
# Surfaces get the same targets
# --------------------------------------------------------------------------------------------


def test_encode_surface_max_error_holds_on_points_and_heights() -> None:
    heights = terrain((30, 40), seed=27)
    out = wavecore.decode(wavecore.encode_surface(heights, max_error=0.5))
    assert out.shape == heights.shape and np.max(np.abs(out - heights)) <= 0.5
    u, v = np.meshgrid(np.linspace(0, 1, 24), np.linspace(0, 2 * np.pi, 32), indexing="ij")
    points = np.stack([np.cos(v) * (1 + u), np.sin(v) * (1 + u), u * u], axis=-1)
    bundle = wavecore.encode_surface(points, max_error=1e-3, boundary=("open", "closed"))
    out = wavecore.decode(bundle)
    assert out.shape == points.shape and np.max(np.abs(out - points)) <= 1e-3


def test_encode_surface_rmse_psnr_bpp() -> None:
    heights = terrain((48, 64), seed=28)
    out = wavecore.decode(wavecore.encode_surface(heights, rmse=1.5))
    assert np.sqrt(np.mean((out - heights) ** 2)) <= 1.5
    out = wavecore.decode(wavecore.encode_surface(heights, psnr=45))
    assert 20 * np.log10(1000.0) - 10 * np.log10(np.mean((out - heights) ** 2)) >= 45
    bundle = wavecore.encode_surface(heights, bpp=1.0)
    assert 8 * len(bundle) / heights.size <= 1.0


def test_a_bundle_declaring_a_huge_grid_is_refused_without_making_it() -> None:
    """A grid bundle's shape is checked against its core's without an array of that shape
    (a 1 KB bundle declaring 2**27 values cost 128 MB and 0.7 s before its error)."""
    import struct
    import tracemalloc
    import zlib

    volume = terrain((64, 80), seed=5)[None].repeat(4, axis=0)
    bundle = bytearray(wavecore.encode_grid(volume, bpp=2.0))
    assert bundle[8] == 3  # the dimensions, then the shape at byte 9
    struct.pack_into("<3I", bundle, 9, 2**27 // (64 * 80), 64, 80)
    crafted = bytes(bundle[:-4]) + struct.pack("<I", zlib.crc32(bytes(bundle[:-4])))
    tracemalloc.start()
    try:
        with pytest.raises(wavecore.BundleError):
            wavecore.decode(crafted)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20
