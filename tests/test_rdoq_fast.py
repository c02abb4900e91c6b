"""Tests for the fast variant of RDOQ: a dead zone that depends on the neighbourhood
(``wavecore.rdoq.adapt_deadzone``), against a plain NumPy statement of its rule."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from wavecore import rdoq, wavedec2
from wavecore.entropy import decode_levels, encode_levels
from wavecore.errors import InvalidParameter
from wavecore.layout import as_levels
from wavecore.quantize import quantize_bands


def _picture(seed: int, channels: int = 0) -> np.ndarray:
    """Edges, a texture and noise: busy places and quiet ones."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:160, :192]
    out = 100 + 50 * ((x // 40 + y // 32) % 2) + 20 * np.sin(x / 3.0) * (y > 80)
    out = out + rng.normal(0, 3, out.shape)
    if channels:
        out = np.stack([out * (0.6 + 0.2 * c) + rng.normal(0, 2, out.shape) for c in range(3)], -1)
    return out


def _quantized(picture: np.ndarray, step: float) -> tuple[list, list, dict]:
    coeffs = wavedec2(picture - 128, "cdf97", "open", 3)
    q, params = quantize_bands(coeffs, step, wavelet="cdf97", boundary="open", refine=0)
    return coeffs, q, params


def _reference(coeffs: list, q: list, params: dict, roundings: tuple) -> list:
    """The rule, written out with NumPy over the dead zone's own indices."""
    out = copy.deepcopy(q)
    six = tuple(roundings) * (2 if len(roundings) == 3 else 1)
    for index in range(1, len(q)):
        bands = [np.abs(np.asarray(b, dtype=np.int64)) for b in q[index]]
        bands = [b if b.ndim == 3 else b[..., None] for b in bands]
        for k, band in enumerate(bands):
            padded = np.pad(band, ((1, 1), (1, 1), (0, 0)))
            rows, cols = band.shape[:2]
            busy_sum = sum(
                padded[1 + di : 1 + di + rows, 1 + dj : 1 + dj + cols]
                for di in (-1, 0, 1)
                for dj in (-1, 0, 1)
                if di or dj
            )
            busy_sum = busy_sum + sum(bands[o] for o in range(3) if o != k)
            busy_sum[..., 1:] += band[..., :1]
            x = np.asarray(coeffs[index][k], dtype=np.float64)
            x = (x if x.ndim == 3 else x[..., None]) / (
                params["step"] * params["weights"][index][k]
            )
            classes = np.where(busy_sum == 0, 0, np.where(busy_sum <= 2, 1, 2))
            classes[..., 1:] += 3  # the chroma channels' own roundings
            r = np.asarray(six)[classes]
            window = (np.abs(x) >= 1 - max(six)) & (np.abs(x) < 1 - min(six))
            new = np.where(np.abs(x) >= 1 - r, np.sign(x), 0).astype(np.int32)
            target = out[index][k]
            view = target if target.ndim == 3 else target[..., None]
            view[window] = new[window]
    return out


@pytest.mark.parametrize(
    ("seed", "channels", "step", "roundings"),
    [
        (0, 0, 4.0, rdoq.FAST_ROUNDINGS),
        (1, 3, 6.0, rdoq.FAST_ROUNDINGS),
        (2, 0, 9.0, (0.1, 0.3, 0.45)),
    ],
)
def test_it_follows_its_rule(seed: int, channels: int, step: float, roundings: tuple) -> None:
    coeffs, q, params = _quantized(_picture(seed, channels), step)
    expected = _reference(coeffs, q, params, roundings)
    coarse = np.array(q[0], copy=True)
    assert rdoq.adapt_deadzone(coeffs, q, params, roundings=roundings) is q  # in place
    assert np.array_equal(q[0], coarse)
    changed = 0
    for mine, theirs, before in zip(
        as_levels(q)[1:],
        as_levels(expected)[1:],
        as_levels(_quantized(_picture(seed, channels), step)[1])[1:],
        strict=True,
    ):
        for a, b, c in zip(mine, theirs, before, strict=True):
            assert np.array_equal(a, b)
            changed += int(np.count_nonzero(a != c))
    assert changed > 0  # the rule did something on this picture


@pytest.mark.parametrize("roundings", [(0.1, 0.2), (0.1, 0.2, 1.0), (0.1, 0.2, -0.1, 0, 0, 0)])
def test_bad_roundings_are_refused_by_name(roundings: tuple) -> None:
    coeffs, q, params = _quantized(_picture(8), 5.0)
    with pytest.raises(InvalidParameter, match="roundings"):
        rdoq.adapt_deadzone(coeffs, q, params, roundings=roundings)


def test_neutral_roundings_change_nothing() -> None:
    coeffs, q, params = _quantized(_picture(3, 3), 5.0)
    before = copy.deepcopy(q)
    rounding = params["rounding"]
    rdoq.adapt_deadzone(coeffs, q, params, roundings=(rounding, rounding, rounding))
    for a, b in zip(as_levels(q), as_levels(before), strict=True):
        for band_a, band_b in zip(a, b, strict=True):
            assert np.array_equal(band_a, band_b)


def test_the_decoder_reads_back_what_it_chose_and_the_encoder_hook_dispatches() -> None:
    coeffs, q, params = _quantized(_picture(7, 3), 7.0)
    fast = rdoq.choose_indices(coeffs, copy.deepcopy(q), params)
    assert rdoq.METHOD == "fast"
    direct = rdoq.adapt_deadzone(coeffs, copy.deepcopy(q), params)
    chunks, cparams = encode_levels(fast)
    shapes = [fast[0].shape, *[tuple(b.shape for b in level) for level in fast[1:]]]
    back = decode_levels(chunks, shapes, cparams)
    for a, b, c in zip(as_levels(fast), as_levels(back), as_levels(direct), strict=True):
        for band_a, band_b, band_c in zip(a, b, c, strict=True):
            assert np.array_equal(band_a, band_b)
            assert np.array_equal(band_a, band_c)
