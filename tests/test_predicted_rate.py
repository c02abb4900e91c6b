"""The pieces the rate control predicts with: ``CodedBlocks`` (code some blocks again, the
others' bytes kept) and ``quantize.OpenLoopDistortion`` (the open loop's error without a
synthesis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore import wavedec2, waverec2
from wavecore.blockcoder import CodedBlocks, encode_blocks
from wavecore.errors import BundleError
from wavecore.quantize import OpenLoopDistortion, dequantize_bands, quantize_bands


def _entries(rng: np.random.Generator, size: int, channels: int) -> list[list[np.ndarray]]:
    shape = (size, size + 5, channels)
    coarse = rng.integers(-200, 200, (9, 10, channels)).astype(np.int32)
    return [
        [coarse],
        [rng.laplace(0, 2.0, (9, 10, channels)).astype(np.int32) for _ in range(3)],
        [rng.laplace(0, 0.6, shape).astype(np.int32) for _ in range(3)],
    ]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), channels=st.integers(1, 3), size=st.integers(1, 300))
def test_recoded_blocks_give_the_bytes_of_a_full_coding(
    seed: int, channels: int, size: int
) -> None:
    rng = np.random.default_rng(seed)
    entries = _entries(rng, size, channels)
    layout = [[band.shape for band in bands] for bands in entries]
    coded = CodedBlocks(encode_blocks(entries, True, 128), layout, True, 128)
    assert coded.chunks() == encode_blocks(entries, True, 128)
    # Zero one block's region (as the bpp trim does) and code only that block again.
    chosen = int(rng.integers(len(coded.regions)))
    entry, row0, col0, row1, col1 = coded.regions[chosen]
    changed = [[band.copy() for band in bands] for bands in entries]
    for band in changed[entry]:
        band[row0:row1, col0:col1] = 0
    coded.recode(changed, np.array([chosen]))
    assert coded.chunks() == encode_blocks(changed, True, 128)
    assert coded.lengths()[chosen] == 0  # an all-zero block codes to nothing


def test_chunks_that_do_not_hold_their_blocks_are_refused() -> None:
    entries = _entries(np.random.default_rng(1), 200, 1)
    layout = [[band.shape for band in bands] for bands in entries]
    chunks = encode_blocks(entries, True, 128)
    with pytest.raises(BundleError, match="does not hold"):
        CodedBlocks([chunks[0], chunks[1], chunks[2][:-1]], layout, True, 128)


@pytest.mark.parametrize("wavelet", ["cdf97", "haar"])
@pytest.mark.parametrize("step", [0.5, 4.0, 20.0])
def test_predicted_distortion_matches_the_synthesis(wavelet: str, step: float) -> None:
    # Measured independently: dequantize, synthesise with waverec2, sum the squares.
    rng = np.random.default_rng(3)
    y, x = np.mgrid[:128, :128]
    image = 100 * np.sin(x / 7.0) * np.cos(y / 11.0) + rng.normal(0, 8, x.shape)
    coeffs = wavedec2(image, wavelet=wavelet, level=3)
    q, params = quantize_bands(coeffs, step, wavelet=wavelet, boundary="open", refine=0)
    back = waverec2(dequantize_bands(q, params, wavelet=wavelet, boundary="open"), wavelet)
    measured = float(np.sum((back - image) ** 2))
    predicted = OpenLoopDistortion(coeffs, wavelet=wavelet, boundary="open")(step)
    # Exact for the orthogonal Haar (up to its norms' 4 significant digits); cdf97 is nearly
    # orthogonal, and quantization errors nearly uncorrelated.
    assert predicted == pytest.approx(measured, rel=0.002 if wavelet == "haar" else 0.06)


def test_channel_gains_weight_each_channel() -> None:
    rng = np.random.default_rng(4)
    coeffs = wavedec2(rng.normal(0, 30, (64, 64, 2)), wavelet="cdf97", level=2)
    plain = OpenLoopDistortion(coeffs, wavelet="cdf97", boundary="open")
    first = OpenLoopDistortion(coeffs, wavelet="cdf97", boundary="open", channel_gains=[1, 0])
    second = OpenLoopDistortion(coeffs, wavelet="cdf97", boundary="open", channel_gains=[0, 1])
    assert first(3.0) + second(3.0) == pytest.approx(plain(3.0), rel=1e-12)
    assert math.isclose(first(3.0), second(3.0), rel_tol=0.2)  # the same noise in each


def test_block_lengths_are_those_of_the_full_coding() -> None:
    from wavecore.blockcoder import block_lengths

    entries = _entries(np.random.default_rng(5), 300, 2)
    layout = [[band.shape for band in bands] for bands in entries]
    full = CodedBlocks(encode_blocks(entries, True, 128), layout, True, 128)
    chosen = np.array([0, 3, len(full.regions) - 1])
    lengths, regions = block_lengths(entries, True, 128, chosen)
    assert np.array_equal(lengths, full.lengths()[chosen])
    assert np.array_equal(regions, full.regions)
