"""Tests for rate-distortion-optimised quantization (``wavecore.rdoq``)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from wavecore import rdoq, wavedec2
from wavecore.entropy import decode_levels, encode_levels
from wavecore.layout import as_levels
from wavecore.quantize import quantize_bands, reconstruction_offset


def _picture(seed: int, channels: int = 0) -> np.ndarray:
    """Edges, a texture and noise: busy places and quiet ones, where RDOQ decides apart."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:192, :160]
    out = 100 + 50 * ((x // 40 + y // 32) % 2) + 20 * np.sin(x / 3.0) * (y > 96)
    out = out + rng.normal(0, 3, out.shape)
    if channels:
        out = np.stack([out * (0.6 + 0.2 * c) for c in range(channels)], axis=-1)
    return out


def _quantized(picture: np.ndarray, step: float) -> tuple[list, list, dict]:
    coeffs = wavedec2(picture - 128, "cdf97", "open", 3)
    q, params = quantize_bands(coeffs, step, wavelet="cdf97", boundary="open", refine=0)
    return coeffs, q, params


def _size(q: list) -> int:
    # Context coder version 6: the full RDOQ's rate model follows the symmetric contexts
    # (versions 4 and 6), not version 7's directional zero-flag models.
    return sum(map(len, encode_levels(q, version=6)[0]))


def _distortion(coeffs: list, q: list, params: dict) -> float:
    """Squared error in units of each band's step, against where the dequantizer puts q."""
    total = 0.0
    rounding = params["rounding"]
    for index, (values, indices, weights) in enumerate(
        zip(as_levels(coeffs), as_levels(q), params["weights"], strict=True)
    ):
        for value, index_band, weight in zip(values, indices, weights, strict=True):
            x = np.asarray(value) / (params["step"] * weight)
            offset = 0.0 if index == 0 else reconstruction_offset(index_band, rounding)
            back = np.where(
                index_band == 0, 0.0, np.sign(index_band) * (np.abs(index_band) + offset)
            )
            total += float(np.sum((x - back) ** 2))
    return total


@pytest.mark.parametrize(("seed", "channels", "step"), [(0, 0, 4.0), (1, 0, 12.0), (2, 3, 6.0)])
def test_rdoq_lowers_the_lagrangian_cost(seed: int, channels: int, step: float) -> None:
    coeffs, q, params = _quantized(_picture(seed, channels), step)
    plain = copy.deepcopy(q)
    optimised = rdoq.optimise_indices(coeffs, q, params)
    assert optimised is q  # in place
    # Not always fewer bytes: where values sit just under a bin's edge among busy neighbours,
    # rounding up costs few bits and saves much error.  The sum is what it lowers.
    size_plain, size_rdoq = _size(plain), _size(optimised)
    cost_plain = _distortion(coeffs, plain, params) + rdoq.LAMBDA * 8 * size_plain
    cost_rdoq = _distortion(coeffs, optimised, params) + rdoq.LAMBDA * 8 * size_rdoq
    assert cost_rdoq < cost_plain


def test_every_index_is_a_candidate_and_the_coarse_band_stays() -> None:
    coeffs, q, params = _quantized(_picture(3, 3), 5.0)
    coarse = np.array(q[0], copy=True)
    rdoq.optimise_indices(coeffs, q, params)
    assert np.array_equal(q[0], coarse)
    for values, indices, weights in zip(
        as_levels(coeffs)[1:], as_levels(q)[1:], params["weights"][1:], strict=True
    ):
        for value, index_band, weight in zip(values, indices, weights, strict=True):
            x = np.asarray(value) / (params["step"] * weight)
            top = np.floor(np.abs(x) + rdoq.TOP_ROUNDING)
            magnitude = np.abs(index_band)
            assert np.all((magnitude == 0) | (magnitude == top) | (magnitude == top - 1))
            assert np.all((index_band == 0) | (np.sign(index_band) == np.sign(x)))


def test_the_decoder_reads_back_exactly_what_rdoq_chose() -> None:
    coeffs, q, params = _quantized(_picture(4), 8.0)
    rdoq.optimise_indices(coeffs, q, params)
    chunks, cparams = encode_levels(q)
    shapes = [q[0].shape, *[tuple(b.shape for b in level) for level in q[1:]]]
    back = decode_levels(chunks, shapes, cparams)
    for a, b in zip(as_levels(q), as_levels(back), strict=True):
        for band_a, band_b in zip(a, b, strict=True):
            assert np.array_equal(band_a, band_b)


def test_a_larger_lambda_spends_fewer_bits() -> None:
    sizes = []
    for lam in (0.05, 0.1, 0.2):
        coeffs, q, params = _quantized(_picture(5), 6.0)
        sizes.append(_size(rdoq.optimise_indices(coeffs, q, params, lam=lam)))
    assert sizes[0] > sizes[1] > sizes[2]
