"""Issue 15 item 4: an alpha channel that is opaque or decodes exactly is left out of the PSNR.

An opaque RGBA picture at ``quality=35`` reported 35.02 dB while its RGB PSNR was 33.77 dB: the
exactly coded alpha's zero errors were averaged in.  Now the figure (``inspect``, and through it
the service's ``X-Wavecore-PSNR``) and the quality target are the colour channels', and an
opaque alpha decodes exactly opaque.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from test_bundle_fuzz import assemble, split  # crafted headers behind valid CRCs

import wavecore
from wavecore import BundleError, decode, inspect
from wavecore.bundle import read_bundle


def picture(shape: tuple[int, int], channels: int, dtype: type = np.uint8) -> np.ndarray:
    """A textured colour picture (edges, gradients and noise), fixed by its seed."""
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    base = 0.5 + 0.3 * np.sin(x / 5.0) * np.cos(y / 7.0) + 0.15 * ((x // 9 + y // 11) % 2)
    planes = [base + 0.1 * np.sin((x + 13 * c) / (3.0 + c)) for c in range(channels)]
    data = np.clip(np.stack(planes, axis=-1) + rng.normal(0, 0.03, (*shape, channels)), 0, 1)
    top = np.iinfo(dtype).max
    return np.rint(data * top).astype(dtype)


def measured_psnr(out: np.ndarray, original: np.ndarray, channels: slice) -> float:
    top = float(np.iinfo(original.dtype).max)
    diff = out[..., channels].astype(np.float64) - original[..., channels]
    mse = float(np.mean(diff * diff))
    return math.inf if mse == 0 else 10 * math.log10(top * top / mse)


def with_alpha(colour: np.ndarray, alpha: np.ndarray | int) -> np.ndarray:
    alpha_plane = np.broadcast_to(np.asarray(alpha, colour.dtype), colour.shape[:2])
    return np.dstack([colour, alpha_plane])


@pytest.mark.parametrize("quality", [26, 30, 35, 42])
def test_an_opaque_rgba_picture_meets_its_target_on_the_colours(quality: float) -> None:
    rgb = picture((64, 72), 3)
    rgba = with_alpha(rgb, 255)
    bundle = wavecore.encode_image(rgba, quality=quality)
    out = decode(bundle)
    assert np.all(out[..., 3] == 255)  # still exactly opaque, at every quality
    rgb_psnr = measured_psnr(out, rgba, slice(0, 3))
    assert rgb_psnr >= quality
    # The recorded figure is the colours' (rounded down to 4 decimals), not an average with
    # the alpha channel's zero errors.
    assert inspect(bundle)["psnr"] == pytest.approx(rgb_psnr, abs=2e-4)
    assert read_bundle(bundle).header["opaque"] is True


def test_the_issues_case_rgba_and_rgb_agree() -> None:
    """The issue's figures: 35.02 dB reported, 33.77 dB on RGB.  Now both are the RGB PSNR."""
    rgb = picture((96, 80), 3)
    rgba_bundle = wavecore.encode_image(with_alpha(rgb, 255), quality=35)
    rgb_bundle = wavecore.encode_image(rgb, quality=35)
    for bundle in (rgba_bundle, rgb_bundle):
        psnr = inspect(bundle)["psnr"]
        assert psnr == pytest.approx(measured_psnr(decode(bundle), rgb, slice(0, 3)), abs=2e-4)
        assert 35 <= psnr <= 35.1


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_grey_with_opaque_alpha_and_sixteen_bits(dtype: type) -> None:
    grey = picture((40, 52), 1, dtype)
    top = np.iinfo(dtype).max
    for image in (with_alpha(grey[..., 0], top), with_alpha(picture((40, 52), 3, dtype), top)):
        bundle = wavecore.encode_image(image, quality=33)
        out = decode(bundle)
        assert np.all(out[..., -1] == top) and out.dtype == dtype
        colour = measured_psnr(out, image, slice(0, -1))
        assert colour >= 33 and inspect(bundle)["psnr"] == pytest.approx(colour, abs=2e-4)
        coarse = decode(bundle, drop_levels=1)
        assert np.all(coarse[..., -1] == top)  # coarse levels too


def test_a_translucent_alpha_is_counted_unless_it_decodes_exactly() -> None:
    rgb = picture((64, 64), 3)
    ramp = np.linspace(0, 255, 64).astype(np.uint8)[None, :].repeat(64, axis=0)
    rgba = with_alpha(rgb, ramp)
    for quality in (28, 40):
        bundle = wavecore.encode_image(rgba, quality=quality)
        out = decode(bundle)
        exact_alpha = np.array_equal(out[..., 3], rgba[..., 3])
        counted = slice(0, 3) if exact_alpha else slice(0, 4)
        expected = measured_psnr(out, rgba, counted)
        assert inspect(bundle)["psnr"] == pytest.approx(expected, abs=2e-4)
        assert expected >= quality
        assert "opaque" not in read_bundle(bundle).header


def test_a_lossless_rgba_stays_exact() -> None:
    rgba = with_alpha(picture((30, 34), 3), 255)
    bundle = wavecore.encode_image(rgba, lossless=True)
    assert np.array_equal(decode(bundle), rgba) and inspect(bundle)["psnr"] is None


@pytest.mark.parametrize("value", [1, "yes", None, [True]])
def test_a_bad_opaque_key_is_refused(value: object) -> None:
    header, chunks = split(wavecore.encode_image(with_alpha(picture((16, 16), 3), 255)))
    header["opaque"] = value
    with pytest.raises(BundleError, match="'opaque'"):
        decode(assemble(json.dumps(header).encode(), chunks))


def test_opaque_is_refused_on_an_image_without_alpha() -> None:
    header, chunks = split(wavecore.encode_image(picture((16, 16), 3)))
    header["opaque"] = True
    with pytest.raises(BundleError, match=r"'opaque'.*alpha"):
        decode(assemble(json.dumps(header).encode(), chunks))
