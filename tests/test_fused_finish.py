"""The decoder's fused last level (synthesis, crop, colour and rounding in one pass) against the
two-step path it replaces: the same integers, bit for bit, on every kind of picture."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import wavecore
from wavecore.bundle import read_bundle
from wavecore.codec.plan import Plan, plan_from_header
from wavecore.codec.samples import cast, finish, reconstruct_finished

RNG = np.random.default_rng(7)
SMOOTH = np.add.outer(np.arange(90.0), np.arange(77.0))
IMAGES = {
    "grey": (SMOOTH * 1.3 + RNG.normal(0, 9, SMOOTH.shape)).clip(0, 255).astype(np.uint8),
    "rgb": RNG.integers(0, 256, (61, 130, 3), dtype=np.uint8),
    "rgba-opaque": np.dstack([RNG.integers(0, 256, (40, 33, 3)), np.full((40, 33), 255)]).astype(
        np.uint8
    ),
    "rgba16": RNG.integers(0, 65536, (37, 52, 4), dtype=np.uint16),
    "one-channel": RNG.integers(0, 256, (64, 64, 1), dtype=np.uint8),
    "two-rows": RNG.integers(0, 256, (2, 300), dtype=np.uint8),
}


def _plan(bundle: bytes) -> Plan:
    return plan_from_header(read_bundle(bundle).header)


def _both(plan: Plan, coeffs: list) -> tuple[np.ndarray, np.ndarray]:
    fused = reconstruct_finished(plan, coeffs)
    separate = finish(plan, plan.transform.inverse(coeffs, plan), 0)
    return fused, separate


@pytest.mark.parametrize("wavelet", ["cdf97", "bspline2", "haar"])
@pytest.mark.parametrize("name", list(IMAGES))
def test_fused_last_level_gives_the_same_integers(name: str, wavelet: str) -> None:
    image = IMAGES[name]
    bundle = wavecore.encode_image(image, wavelet=wavelet, keep=0.5)
    plan = _plan(bundle)
    # Coefficients of a noisy stand-in, well outside the dtype's range in places: the
    # rounding, the clipping and the colour matrix all have work to do.
    scale = 4.0 * float(np.iinfo(image.dtype).max)
    coeffs = plan.transform.forward(RNG.normal(0, scale, plan.fitted), plan.levels)
    fused, separate = _both(plan, coeffs)
    assert fused.dtype == separate.dtype == image.dtype
    assert fused.shape == separate.shape == image.shape
    assert fused.min() == np.iinfo(image.dtype).min  # clipped at both ends
    np.testing.assert_array_equal(fused, separate)
    assert wavecore.decode(bundle).shape == image.shape  # the decoder's own call of it


def test_fused_path_maps_nan_to_zero_like_the_colour_pass() -> None:
    bundle = wavecore.encode_image(IMAGES["rgb"], keep=0.5)
    plan = dataclasses.replace(_plan(bundle), opaque=False)
    coeffs = plan.transform.forward(RNG.normal(128, 40, plan.fitted), plan.levels)
    coeffs[-1] = tuple(np.where(band > 60, np.nan, band) for band in coeffs[-1])
    fused, separate = _both(plan, coeffs)
    assert (fused == 0).any()
    np.testing.assert_array_equal(fused, separate)


def test_opaque_alpha_stays_opaque_on_the_fused_path() -> None:
    bundle = wavecore.encode_image(IMAGES["rgba-opaque"], bpp=1.5)
    assert np.all(wavecore.decode(bundle)[..., 3] == 255)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16])
def test_grey_rounding_is_rint_and_clip(dtype: type) -> None:
    """The one-channel pass (a loop of its own, without the colour matrix) rounds half to
    even, clips into the dtype and maps NaN to 0: NumPy's ``rint`` and ``clip``, element by
    element, for the values a synthesis can give (ties, both infinities, far out of range)."""
    from wavecore import _kernels

    info = np.iinfo(dtype)
    values = np.concatenate(
        [
            [np.nan, np.inf, -np.inf, -0.0, 0.5, 1.5, 2.5, -0.5, 254.5, 255.5, 1e300, -1e300],
            RNG.normal(info.max / 2, info.max, 500),
        ]
    )
    src = values.reshape(1, -1, 1)
    out = np.empty(src.shape, dtype=dtype)
    lo, hi = float(info.min), float(info.max)
    _kernels.colour_to_integers(src, np.eye(3), False, lo, hi, out, 0, 1)
    expected = np.clip(np.rint(np.nan_to_num(values, nan=0.0, posinf=hi, neginf=lo)), lo, hi)
    np.testing.assert_array_equal(out.reshape(-1), expected.astype(dtype))


def _cast_by_numpy(data: np.ndarray, dtype: str) -> np.ndarray:
    """The float cast as NumPy did it: NaN to 0, infinities saturated, clipped to the dtype."""
    values = np.nan_to_num(np.asarray(data, dtype=np.float64))
    largest = float(np.finfo(dtype).max)
    return np.clip(values, -largest, largest).astype(dtype)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("shape", [(37, 53), (20, 30, 3), (5, 7, 1)])
@pytest.mark.parametrize("view", [False, True])
def test_float_cast_is_numpys_bit_for_bit(dtype: str, shape: tuple[int, ...], view: bool) -> None:
    """``samples.cast`` to a float dtype (one compiled pass for 2-D and 3-D float64 samples)
    gives NumPy's values to the bit: NaN, infinities, signed zeros and values beyond float32,
    on whole arrays and on cropped views."""
    data = RNG.standard_normal(shape) * 1e300
    data.flat[::7] = np.nan
    data.flat[1::11] = np.inf
    data.flat[2::13] = -np.inf
    data.flat[3::17] = -0.0
    data.flat[4::19] = 3.5e38
    data.flat[5::23] = -3.41e38
    source = data[1:-1, 2:] if view else data
    out = cast(source, dtype)
    expected = _cast_by_numpy(source, dtype)
    assert out.dtype == expected.dtype and out.shape == expected.shape
    np.testing.assert_array_equal(out, expected)
    np.testing.assert_array_equal(np.signbit(out), np.signbit(expected))
