"""Images: any shape, dtype and channel layout round-trips; coarse images; the mosaic."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import InvalidLength, InvalidParameter

DTYPES = [np.uint8, np.uint16, np.int16, np.float16, np.float32, np.float64]


def _random_image(rng: np.random.Generator, shape: tuple[int, ...], dtype: type) -> np.ndarray:
    kind = np.dtype(dtype).kind
    if kind in "iu":
        info = np.iinfo(dtype)
        return rng.integers(info.min, int(info.max) + 1, shape, dtype=dtype)
    return (rng.standard_normal(shape) * 50).astype(dtype)


@given(
    height=st.integers(8, 70),
    width=st.integers(8, 70),
    channels=st.sampled_from([None, 1, 3, 4]),
    channel_axis=st.sampled_from([0, -1]),
    dtype=st.sampled_from(DTYPES),
    level=st.sampled_from([None, 1, 2, 3]),
    seed=st.integers(0, 2**16),
)
@settings(max_examples=80, deadline=None)
def test_any_image_round_trips_exactly_with_nothing_removed(
    height: int,
    width: int,
    channels: int | None,
    channel_axis: int,
    dtype: type,
    level: int | None,
    seed: int,
) -> None:
    rng = np.random.default_rng(seed)
    if channels is None:
        shape: tuple[int, ...] = (height, width)
        axis = None
    else:
        shape = (channels, height, width) if channel_axis == 0 else (height, width, channels)
        axis = channel_axis
    image = _random_image(rng, shape, dtype)
    dec = wavecore.decompose_image(image, level, channel_axis=axis)
    back = dec.reconstruct(keep=1.0)
    assert back.shape == image.shape
    assert back.dtype == image.dtype
    if np.dtype(dtype) == np.float64:
        assert np.allclose(back, image, rtol=1e-12, atol=1e-12)
    else:
        assert np.array_equal(back, image)


@pytest.mark.parametrize("dtype", DTYPES)
def test_resampled_fit_gives_the_shape_and_dtype_back(dtype: type) -> None:
    rng = np.random.default_rng(1)
    image = _random_image(rng, (37, 53, 3), dtype)
    dec = wavecore.decompose_image(image, 2, channel_axis=-1, fit="resample")
    back = dec.reconstruct()
    assert back.shape == image.shape and back.dtype == image.dtype
    smooth = np.linspace(0, 200, 37 * 53).reshape(37, 53).astype(dtype)
    near = wavecore.decompose_image(smooth, 2, fit="resample").reconstruct()
    assert np.max(np.abs(near.astype(np.float64) - smooth.astype(np.float64))) < 2.0


def test_integers_are_rounded_and_clipped() -> None:
    image = np.zeros((34, 34), dtype=np.uint8)
    image[:, 17:] = 255  # a hard edge: removing details rings past 0 and 255
    out = wavecore.decompose_image(image, 2).reconstruct(keep=0.0)
    assert out.dtype == np.uint8
    ringing = wavecore.waverec2(
        wavecore.remove_smallest(wavecore.wavedec2(image.astype(float), level=2), 1.0)
    )
    assert ringing.min() < 0 or ringing.max() > 255
    assert np.array_equal(out, np.clip(np.rint(ringing), 0, 255).astype(np.uint8))


def test_photograph_quality_falls_with_removal() -> None:
    from skimage import data

    photo = data.astronaut()[::4, ::4]  # 128 × 128 × 3, uint8
    dec = wavecore.decompose_image(photo, 3, channel_axis=-1)

    def psnr(image: np.ndarray) -> float:
        mse = np.mean((image.astype(float) - photo.astype(float)) ** 2)
        return float(10 * np.log10(255**2 / mse))

    values = [psnr(dec.reconstruct(keep=k)) for k in (0.8, 0.4, 0.1, 0.0)]
    assert values == sorted(values, reverse=True)
    assert values[0] > 35  # keeping most details keeps most of the picture


def test_coarse_images_at_every_level() -> None:
    image = np.random.default_rng(0).random((100, 61))
    dec = wavecore.decompose_image(image, 3)
    for level in range(4):
        coarse = dec.coarse(level)
        for n, c in zip(image.shape, coarse.shape, strict=True):
            assert -(-n // 2**level) <= c <= -(-n // 2**level) + 2
    assert np.allclose(dec.coarse(0), image)
    # The coarse image is a smoothed, smaller copy: same value range, same mean roughly.
    assert abs(dec.coarse(2).mean() - image.mean()) < 0.05
    with pytest.raises(InvalidParameter, match="deeper"):
        dec.coarse(4)


def test_coarse_image_keeps_channels_where_they_were() -> None:
    image = np.random.default_rng(0).random((3, 40, 50))
    dec = wavecore.decompose_image(image, 2, channel_axis=0)
    assert dec.coarse().shape[0] == 3
    assert dec.mosaic().shape[0] == 3


def test_mosaic_tiles_the_subbands() -> None:
    image = np.random.default_rng(0).random((34, 66))
    coeffs = wavecore.wavedec2(image, level=2)
    mosaic = wavecore.subband_mosaic(coeffs)
    assert mosaic.shape == image.shape
    assert mosaic.min() >= 0 and mosaic.max() <= 1
    ca = coeffs[0]
    # The coarse image sits top-left, stretched to [0, 1].
    corner = mosaic[: ca.shape[0], : ca.shape[1]]
    assert np.allclose(corner, (ca - ca.min()) / (ca.max() - ca.min()))
    # The finest cD sits bottom-right, as a magnitude.
    cd = coeffs[-1][2]
    assert np.array_equal(mosaic[-cd.shape[0] :, -cd.shape[1] :] > 0, np.abs(cd) > 0)


def test_too_small_image_names_the_minimum() -> None:
    with pytest.raises(InvalidLength, match="at least 8 samples"):
        wavecore.decompose_image(np.zeros((7, 100)))
    with pytest.raises(InvalidLength, match="at least 2 samples"):
        wavecore.decompose_image(np.zeros((1, 100)), wavelet="haar")
    # Haar and the closed boundary need only 2.
    assert wavecore.decompose_image(np.ones((2, 2)), wavelet="haar").reconstruct().shape == (2, 2)


def test_bad_images() -> None:
    with pytest.raises(InvalidParameter, match="channel_axis=-1"):
        wavecore.decompose_image(np.zeros((20, 20, 3)))
    with pytest.raises(InvalidParameter, match="3 dimensions"):
        wavecore.decompose_image(np.zeros((20, 20)), channel_axis=-1)
    with pytest.raises(InvalidParameter, match="dtype bool"):
        wavecore.decompose_image(np.zeros((20, 20), dtype=bool))
    with pytest.raises(InvalidParameter, match="fit"):
        wavecore.decompose_image(np.zeros((20, 20)), fit="crop")
    with pytest.raises(InvalidParameter, match="keep"):
        wavecore.decompose_image(np.zeros((20, 20))).reconstruct(keep=-1)
