"""``wavecore.codec.choice``: the per-picture wavelet of ``encode_image(wavelet="auto")``."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

from wavecore.codec.choice import FLAT_SHARE_FOR_HAAR, choose_image_wavelet, flat_block_share


def test_the_share_counts_flat_blocks_over_every_channel() -> None:
    image = np.zeros((4, 6, 3), dtype=np.uint8)
    assert flat_block_share(image) == 1.0
    image[0, 0, 2] = 1  # one channel of one pixel breaks one of the six blocks
    assert flat_block_share(image) == pytest.approx(5 / 6)
    image[3, 5, 0] = 1
    assert flat_block_share(image) == pytest.approx(4 / 6)


def test_odd_edges_and_tiny_pictures_are_left_out_or_zero() -> None:
    assert flat_block_share(np.zeros((1, 9))) == 0.0
    assert flat_block_share(np.zeros((9, 1))) == 0.0
    ramp = np.kron(np.arange(12).reshape(3, 4), np.ones((2, 2)))
    odd = np.pad(ramp, ((0, 1), (0, 1)), constant_values=99)  # last row and column unpaired
    assert flat_block_share(odd) == 1.0


@pytest.mark.parametrize(
    ("name", "expected"),
    [("camera", "cdf97"), ("coins", "cdf97"), ("astronaut", "cdf97"), ("moon", "haar")],
)
def test_tuning_pictures(name: str, expected: str) -> None:
    # moon is a 256² picture enlarged to 512² by pixel replication.
    assert choose_image_wavelet(getattr(data, name)()) == expected


def test_haar_is_chosen_on_the_full_count_only() -> None:
    # Flat blocks on exactly the rows the sample reads, busy ones elsewhere: the sample sees a
    # flat picture, the full count a busy one.
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (2048, 64)).astype(np.uint8)
    for pair in range(0, 1024, 32):
        image[2 * pair + 1] = image[2 * pair]
        image[2 * pair : 2 * pair + 2, 1::2] = image[2 * pair : 2 * pair + 2, 0::2]
    assert flat_block_share(image, 32) == 1.0
    assert flat_block_share(image) < FLAT_SHARE_FOR_HAAR
    assert choose_image_wavelet(image) == "cdf97"


def test_an_unknown_wavelet_names_auto_among_the_accepted() -> None:
    import wavecore

    with pytest.raises(wavecore.InvalidParameter, match="'auto' \\(the default"):
        wavecore.encode_image(np.zeros((8, 8), np.uint8), wavelet="nope")
