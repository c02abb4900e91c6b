"""The interpolation coder of ``max_error`` grids: bound, dtypes, volumes, old bundles."""

from __future__ import annotations

import base64
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import BundleError
from wavecore.grids import inspect_grid

# Version-1 bundles (wavelet core plus outliers) written by the encoder before the interpolation
# coder, from the grids of _v1_field and _v1_volume below: they must keep decoding.
V1_FIELD = (
    "V1ZHRAEACQsCFAAAABgAAAAAAAAAAADgPwAAAAAAAPA/AAAAAAAAAACi73bp3uHHPwAAAABwvd8/2gAAAA4AAAA1"
    "AAAAiVdWQg0KGgoCADISMwMxAhQYDgAAALChJl1AAAAAAAAA8D/GCgAKtSO1K7VEtem+575tvpSor0MNLMh9Pyc6"
    "MbaxyITuhqhzJv+qrvnHPAm6O75SYS5B1gwGJSKjzaf0Ty1sdO/DF0+Z3+QGo3+fOfnUhPI534eXw/zlf1Kr7IMo"
    "WeLonMNGDUnLgJ+e1+XA//cy3jiVewcNETsyR7cCbmy8I5UCz0Y7VDC9O3luN9BIvGaoca6CbmBSgbuUW9e6+45D"
    "DnTRyPZzSb4Mv0ByH3KTYmHDRrI9tWV42qtjFgXC9UwABlcBYwsAAAAEAAAACAAAAAgFAw4D4NQ2KKQXAAAAAAAA"
    "AAACBgAAAAAAAAAAJ+DXeHjaAwAAAAABYQq9UQ=="
)
V1_VOLUME = (
    "V1ZHRAEBCggDBAAAAAwAAAAKAAAAAAAAAAAA0D8AAAAAAADgPwAAAAAAAAAA/7r/hdhTtD+Azd1A817IP3YAAAAA"
    "AAAAAAAAAIlXVkINChoKAgAtIjMDMQEMCgQObfVjip7ZU0AAAAAAAADgP8YKABG/oL6kvjW+lPieSQ2b90I+IBYG"
    "bxcfU1UfiMAtDmDxaW9QkyKO/bW//x9TsRsjbHi3FiSj4OjTyhVJj0zHILk1DsvHVfpy0M5QqOou/s7wyuf1"
)


def _v1_field() -> np.ndarray:
    y, x = np.mgrid[0:20, 0:24]
    field = (np.sin(x / 3.0) * np.cos(y / 4.0) * 50.0 + x).astype(np.float32)
    field[5:8, 6:9] = np.nan
    return field


def _v1_volume() -> np.ndarray:
    rows = np.mgrid[0:12, 0:10][0]
    return np.sin(np.arange(4)[:, None, None] / 2.0) * np.cos(rows / 3.0) * 40.0


def largest_error(decoded: np.ndarray, original: np.ndarray) -> float:
    finite = ~np.isnan(original.astype(np.float64))
    diff = decoded.astype(np.float64)[finite] - original.astype(np.float64)[finite]
    return float(np.max(np.abs(diff))) if diff.size else 0.0


def assert_bound(data: np.ndarray, bound: float) -> bytes:
    bundle = wavecore.encode_grid(data, max_error=bound)
    out = wavecore.decode(bundle)
    assert out.shape == data.shape and out.dtype == data.dtype.newbyteorder("=")
    assert np.array_equal(np.isnan(out.astype(np.float64)), np.isnan(data.astype(np.float64)))
    allowed = np.floor(bound) if data.dtype.kind in "iu" else bound
    assert largest_error(out, data) <= allowed
    return bundle


def smooth(shape: tuple[int, ...], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    freqs = np.meshgrid(*[np.fft.fftfreq(n) for n in shape], indexing="ij")
    radius2 = sum(f * f for f in freqs)
    radius2.flat[0] = 1.0
    field = np.fft.ifftn(np.fft.fftn(rng.standard_normal(shape)) * radius2 ** (-0.5)).real
    return 1000.0 * (field - field.min()) / (field.max() - field.min())


def test_old_bundles_still_decode_within_their_bound() -> None:
    field = wavecore.decode(base64.b64decode(V1_FIELD))
    assert field.dtype == np.float32 and field.shape == (20, 24)
    assert np.array_equal(np.isnan(field), np.isnan(_v1_field()))
    assert largest_error(field, _v1_field()) <= 0.5
    assert inspect_grid(base64.b64decode(V1_FIELD))["outlier_bytes"] > 0
    volume = wavecore.decode(base64.b64decode(V1_VOLUME))
    assert volume.shape == (4, 12, 10) and largest_error(volume, _v1_volume()) <= 0.25


def test_max_error_bundles_are_interpolation_coded_without_outliers() -> None:
    bundle = assert_bound(smooth((90, 70), 1), 0.5)
    info = inspect_grid(bundle)
    assert info["wavelet"] == "interpolation" and info["outlier_bytes"] == 0
    assert bundle[4] == 2  # the container version of an interpolation core
    # The errors are each sample's own quantization error: uniform, RMSE near t / sqrt(3).
    assert 0.5 / np.sqrt(3) * 0.9 < info["rmse"] < 0.5 / np.sqrt(3) * 1.1


@pytest.mark.parametrize("dtype", ["uint8", "int8", "uint16", "int16", "int32", "uint32", "int64"])
@pytest.mark.parametrize("bound", [1, 3, 100])
def test_integer_bounds_in_whole_units(dtype: str, bound: int) -> None:
    info = np.iinfo(np.dtype(dtype))
    rng = np.random.default_rng(bound)
    span = min(int(info.max) - int(info.min), 60000)
    data = (rng.integers(0, span, (33, 41)) + max(int(info.min), -30000)).astype(dtype)
    if np.dtype(dtype).itemsize < 8:  # (64-bit integers are refused beyond 2**53)
        data[0, 0], data[-1, -1] = info.min, info.max  # the clipping at the dtype's ends
    assert_bound(data, bound)


def test_integers_near_two_to_the_53_keep_the_bound() -> None:
    data = (2**53 - np.random.default_rng(3).integers(0, 2**40, (20, 30))).astype(np.int64)
    assert_bound(data, 5)


@pytest.mark.parametrize("dtype", ["float16", "float32", "float64"])
def test_a_bound_at_the_dtype_resolution_is_held_by_exact_samples(dtype: str) -> None:
    data = (1000.0 + smooth((30, 30), 4)).astype(dtype)
    resolution = float(np.finfo(np.dtype(dtype)).eps) * 1000.0
    assert_bound(data, resolution / 4)


def test_nan_cells_cost_nearly_nothing() -> None:
    data = smooth((64, 64), 5)
    holed = data.copy()
    holed[10:40, 10:40] = np.nan
    whole = len(assert_bound(data, 0.5))
    with_holes = len(assert_bound(holed, 0.5))
    assert with_holes < whole * 0.9  # the holes hold 22 % of the cells; their zeros cost little


def test_volume_predicted_in_three_axes_beats_its_slices() -> None:
    volume = smooth((16, 48, 40), 6)
    three_d = len(assert_bound(volume, 1.0))
    slices = sum(len(wavecore.encode_grid(plane, max_error=1.0)) for plane in volume)
    assert three_d < slices


def test_coarse_level_is_the_grid_lattice_within_the_bound() -> None:
    data = smooth((50, 70), 7)
    bundle = wavecore.encode_grid(data, max_error=0.3)
    coarse = wavecore.decode(bundle, level=2)
    assert coarse.shape == (13, 18)
    assert largest_error(coarse, data[::4, ::4]) <= 0.3
    volume = smooth((5, 20, 24), 8)
    coarse = wavecore.decode(wavecore.encode_grid(volume, max_error=0.3), level=1)
    assert coarse.shape == (5, 10, 12) and largest_error(coarse, volume[:, ::2, ::2]) <= 0.3


def test_keep_drops_the_smallest_residuals() -> None:
    data = smooth((48, 64), 9)
    bundle = wavecore.encode_grid(data, max_error=0.2)
    full = wavecore.decode(bundle)
    rough = wavecore.decode(bundle, keep=0.05)
    assert largest_error(full, data) <= 0.2 < largest_error(rough, data)
    assert np.array_equal(wavecore.decode(bundle, keep=1.0), full)


def test_damaged_interpolation_bundles_raise_bundle_error() -> None:
    data = smooth((40, 30), 10)
    bundle = wavecore.encode_grid(data, max_error=0.3)
    rng = np.random.default_rng(11)
    for _ in range(40):
        damaged = bytearray(bundle)
        damaged[int(rng.integers(4, len(bundle)))] ^= 1 << int(rng.integers(0, 8))
        with pytest.raises(BundleError):
            wavecore.decode(bytes(damaged))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    shape=st.sampled_from([(1, 1), (1, 9), (7, 1), (2, 2), (5, 9, 3), (1, 1, 6), (17, 33)]),
    dtype=st.sampled_from(["<f8", ">f4", "<f2", "<i2", ">u2", "<i8", "<u1"]),
    relative=st.sampled_from([1e-6, 1e-3, 0.05, 0.5, 3.0]),
    holes=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_bound_holds_on_any_grid_of_any_dtype(
    shape: tuple[int, ...], dtype: str, relative: float, holes: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    data = rng.standard_normal(shape).cumsum(axis=-1) * 300.0
    if np.dtype(dtype).kind in "iu":
        info = np.iinfo(np.dtype(dtype))
        data = np.clip(np.rint(data), info.min, info.max)
    else:
        data[rng.random(shape) < holes] = np.nan
    data = data.astype(dtype)
    finite = data.astype(np.float64)[~np.isnan(data.astype(np.float64))]
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    assert_bound(data, relative * max(span, 1.0))


def test_crafted_cores_with_a_valid_crc_never_crash() -> None:
    # Damage inside the interpolation stream, with the CRC recomputed so that the container
    # lets it through: the decoder must answer with a BundleError or a grid of the right shape.
    data = smooth((24, 31), 12)
    data[2:5, 3:9] = np.nan
    bundle = bytearray(wavecore.encode_grid(data, max_error=0.05))
    info = inspect_grid(bytes(bundle))
    core_start = len(bundle) - 4 - info["mask_bytes"] - info["core_bytes"]
    rng = np.random.default_rng(13)
    for _ in range(150):
        damaged = bytearray(bundle)
        for _ in range(int(rng.integers(1, 4))):
            at = core_start + int(rng.integers(0, info["core_bytes"]))
            damaged[at] = int(rng.integers(0, 256))
        damaged[-4:] = zlib.crc32(bytes(damaged[:-4])).to_bytes(4, "little")
        try:
            out = wavecore.decode(bytes(damaged))
        except BundleError:
            continue
        assert out.shape == data.shape
