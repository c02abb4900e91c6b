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


def _reference(coeffs: list, q: list, params: dict, roundings: tuple, parent: int) -> list:
    """The rule, written out with NumPy over the dead zone's own indices."""
    out = copy.deepcopy(q)
    table = np.asarray(tuple(roundings) * (2 if len(roundings) == 9 else 1)).reshape(2, 3, 3)

    def three_d(band: np.ndarray) -> np.ndarray:
        band = np.abs(np.asarray(band, dtype=np.int64))
        return band if band.ndim == 3 else band[..., None]

    for index in range(1, len(q)):
        bands = [three_d(b) for b in q[index]]
        for k, band in enumerate(bands):
            padded = np.pad(band, ((1, 1), (1, 1), (0, 0)))
            rows, cols = band.shape[:2]
            local = sum(
                padded[1 + di : 1 + di + rows, 1 + dj : 1 + dj + cols]
                for di in (-1, 0, 1)
                for dj in (-1, 0, 1)
                if di or dj
            )
            external = 2 * sum(bands[o] for o in range(3) if o != k)
            external[..., 1:] += 4 * band[..., :1]
            if index >= 2:  # the same band one level coarser, at (i // 2, j // 2)
                above = three_d(q[index - 1][k])
                grown = above.repeat(2, axis=0).repeat(2, axis=1)[:rows, :cols]
                external[: grown.shape[0], : grown.shape[1]] += parent * grown
            x = np.asarray(coeffs[index][k], dtype=np.float64)
            x = (x if x.ndim == 3 else x[..., None]) / (
                params["step"] * params["weights"][index][k]
            )
            local_class = np.where(local == 0, 0, np.where(local <= 2, 1, 2))
            external_class = np.where(external == 0, 0, np.where(external <= 3, 1, 2))
            chroma = np.zeros(band.shape, dtype=np.int64)
            chroma[..., 1:] = 1  # the chroma channels' own table
            r = table[chroma, local_class, external_class]
            window = (np.abs(x) >= 1 - table.max()) & (np.abs(x) < 1 - table.min())
            new = np.where(np.abs(x) >= 1 - r, np.sign(x), 0).astype(np.int32)
            target = out[index][k]
            view = target if target.ndim == 3 else target[..., None]
            view[window] = new[window]
    return out


_OTHER = (0.1, 0.2, 0.3, 0.25, 0.3, 0.4, 0.3, 0.4, 0.45)


@pytest.mark.parametrize(
    ("seed", "channels", "step", "roundings", "parent"),
    [
        (0, 0, 4.0, rdoq.FAST_ROUNDINGS, rdoq.PARENT_WEIGHT),
        (1, 3, 6.0, rdoq.FAST_ROUNDINGS, rdoq.PARENT_WEIGHT),
        (2, 0, 9.0, _OTHER, rdoq.PARENT_WEIGHT),
        (6, 3, 5.0, rdoq.FAST_ROUNDINGS, 0),
    ],
)
def test_it_follows_its_rule(
    seed: int, channels: int, step: float, roundings: tuple, parent: int
) -> None:
    coeffs, q, params = _quantized(_picture(seed, channels), step)
    expected = _reference(coeffs, q, params, roundings, parent)
    coarse = np.array(q[0], copy=True)
    got = rdoq.adapt_deadzone(coeffs, q, params, roundings=roundings, parent_weight=parent)
    assert got is q  # in place
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


def test_the_parent_band_moves_decisions() -> None:
    # Context coder version 6 reads the parent band: where it is nonzero, a 1 is cheaper.
    coeffs, q, params = _quantized(_picture(9, 3), 5.0)
    with_parent = rdoq.adapt_deadzone(coeffs, copy.deepcopy(q), params)
    without = rdoq.adapt_deadzone(coeffs, copy.deepcopy(q), params, parent_weight=0)
    differ = [
        int(np.count_nonzero(a != b))
        for level_a, level_b in zip(as_levels(with_parent), as_levels(without), strict=True)
        for a, b in zip(level_a, level_b, strict=True)
    ]
    assert differ[0] == 0  # the coarse band
    assert sum(differ[1:4]) == 0  # the coarsest details have no parent
    assert sum(differ[4:]) > 0


@pytest.mark.parametrize(
    "roundings", [(0.1, 0.2, 0.3), (0.1,) * 8 + (1.0,), (0.1,) * 17 + (-0.5,), (0.1,) * 12]
)
def test_bad_roundings_are_refused_by_name(roundings: tuple) -> None:
    coeffs, q, params = _quantized(_picture(8), 5.0)
    with pytest.raises(InvalidParameter, match="roundings"):
        rdoq.adapt_deadzone(coeffs, q, params, roundings=roundings)
    with pytest.raises(InvalidParameter, match="parent_weight"):
        rdoq.adapt_deadzone(coeffs, q, params, parent_weight=-1)


def test_neutral_roundings_change_nothing() -> None:
    coeffs, q, params = _quantized(_picture(3, 3), 5.0)
    before = copy.deepcopy(q)
    rounding = params["rounding"]
    rdoq.adapt_deadzone(coeffs, q, params, roundings=(rounding,) * 9)
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
