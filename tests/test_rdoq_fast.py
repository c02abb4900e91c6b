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


@pytest.mark.parametrize("channels", [0, 3])
def test_regions_decide_as_the_whole_pass_there_and_leave_the_rest(channels: int) -> None:
    # The bpp search re-decides only its sample of code-blocks: inside them it must find what
    # the whole pass finds (a region's decisions read the dead zone's indices around it).
    coeffs, q, params = _quantized(_picture(5, channels), 5.0)
    whole = rdoq.adapt_deadzone(coeffs, copy.deepcopy(q), params)
    before = copy.deepcopy(q)
    regions = np.array([[3, 0, 0, 40, 48], [3, 50, 60, 80, 96], [2, 10, 5, 30, 40]])
    rdoq.adapt_deadzone(coeffs, q, params, regions=regions)
    inside_changed = 0
    for entry, (mine, everywhere, dead_zone) in enumerate(
        zip(as_levels(q), as_levels(whole), as_levels(before), strict=True)
    ):
        for a, w, d in zip(mine, everywhere, dead_zone, strict=True):
            inside = np.zeros(a.shape[:2], dtype=bool)
            for _, r0, c0, r1, c1 in regions[regions[:, 0] == entry]:
                inside[r0:r1, c0:c1] = True
            assert np.array_equal(a[inside], w[inside])
            assert np.array_equal(a[~inside], d[~inside])
            inside_changed += int(np.count_nonzero(a[inside] != d[inside]))
    assert inside_changed > 0  # the regions held decisions to make


def test_the_same_indices_and_bundles_on_one_and_two_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Threads split the pass by rows (or by regions): decisions read the dead zone's indices,
    # never a neighbour's new one, so the result does not depend on who got there first.
    import wavecore

    rng = np.random.default_rng(4)
    y, x = np.mgrid[:1024, :1024]
    waves = [np.sin(x / (17.0 + 5 * c)) * np.cos(y / (23.0 - 3 * c)) for c in range(3)]
    picture = np.stack([60 * w + 40.0 * ((x // 96 + y // 80) % 2) for w in waves], -1)
    picture = np.clip(picture + 128 + rng.normal(0, 6, picture.shape), 0, 255).astype(np.uint8)
    coeffs, q, params = _quantized(picture.astype(np.float64), 6.0)
    regions = np.array([[3, 0, 0, 128, 128], [3, 256, 128, 384, 512], [2, 0, 0, 256, 256]])
    results = {}
    for count in ("1", "2"):
        monkeypatch.setenv("WAVECORE_THREADS", count)
        whole = rdoq.adapt_deadzone(coeffs, copy.deepcopy(q), params)
        some = rdoq.adapt_deadzone(coeffs, copy.deepcopy(q), params, regions=regions)
        bundles = [
            wavecore.encode_image(picture, bpp=1.0),
            wavecore.encode_image(picture[:512, :512, 0], bpp=0.5),
            wavecore.encode_image(picture[:512, :512], quality=38.0),
        ]
        results[count] = (whole, some, bundles)
    for one, two in zip(results["1"][:2], results["2"][:2], strict=True):
        for a, b in zip(as_levels(one), as_levels(two), strict=True):
            for band_a, band_b in zip(a, b, strict=True):
                assert np.array_equal(band_a, band_b)
    assert results["1"][2] == results["2"][2]


def test_a_quality_target_takes_fewer_bytes_with_it() -> None:
    # The point of it: the default quality search meets its target in fewer bytes.
    data = pytest.importorskip("skimage.data", reason="the photographs come from scikit-image")
    import wavecore

    image = data.camera()
    sizes = {}
    for enabled in (False, True):
        was = rdoq.ENABLED
        rdoq.ENABLED = enabled
        try:
            bundle = wavecore.encode_image(image, quality=40.0)
        finally:
            rdoq.ENABLED = was
        error = np.mean((wavecore.decode(bundle).astype(float) - image) ** 2)
        assert 40.0 <= 10 * np.log10(255.0**2 / error) <= 40.05
        sizes[enabled] = len(bundle)
    assert sizes[True] < 0.995 * sizes[False]
