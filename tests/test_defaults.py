"""The defaults that serve users (issue 12): images default to ``"auto"``, which codes
photographs with cdf97 (the wavelet that wins the measured rate–distortion), exact
enlargements as their sources, and pictures of mostly flat 2 × 2 blocks with Haar; curves and
surfaces keep the paper's bspline2; bspline2 stays one word away."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

import wavecore
from wavecore import decode, encode_curve, encode_image, encode_surface, inspect


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10 * np.log10(255.0**2 / mse)


def test_images_default_to_cdf97_and_bspline2_is_one_word_away() -> None:
    image = (np.random.default_rng(12).random((40, 36)) * 255).astype(np.uint8)
    assert inspect(encode_image(image, quality=30))["wavelet"] == "cdf97"
    assert inspect(encode_image(image, wavelet="bspline2", quality=30))["wavelet"] == "bspline2"
    # Lossless keeps its own reversible filters whatever the lossy default is.
    lossless = encode_image(image, lossless=True)
    assert inspect(lossless)["wavelet"] != "cdf97"
    assert np.array_equal(decode(lossless), image)


def test_curves_and_surfaces_keep_bspline2() -> None:
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    curve = np.column_stack([np.cos(t), np.sin(2 * t)])
    assert inspect(encode_curve(curve, closed=True))["wavelet"] == "bspline2"
    grid = np.add.outer(np.sin(np.linspace(0, 3, 20)), np.cos(np.linspace(0, 2, 24)))
    assert inspect(encode_surface(grid))["wavelet"] == "bspline2"


@pytest.mark.parametrize("name", ["camera", "astronaut"])
def test_the_default_beats_the_papers_filter_on_a_photograph(name: str) -> None:
    # The issue measured bspline2 1.5–2.2 dB below OpenJPEG, and cdf97 on a par with it: the
    # default must give a photograph clearly more PSNR at the same rate.
    image = getattr(data, name)()[::2, ::2]
    default = encode_image(image, bpp=1.0)
    paper = encode_image(image, wavelet="bspline2", bpp=1.0)
    assert len(default) <= len(paper) * 1.03
    assert psnr(decode(default), image) > psnr(decode(paper), image) + 0.5


def test_the_default_is_in_the_signature() -> None:
    import inspect as pyinspect

    assert pyinspect.signature(wavecore.encode_image).parameters["wavelet"].default == "auto"
    assert pyinspect.signature(wavecore.encode_curve).parameters["wavelet"].default == "bspline2"


def _replicated(picture: np.ndarray) -> np.ndarray:
    """The picture enlarged twice by pixel replication (every 2 × 2 block flat)."""
    return picture.repeat(2, axis=0).repeat(2, axis=1)


def _nearly_replicated(picture: np.ndarray) -> np.ndarray:
    """The enlargement with one pixel off: no longer exact, still nearly all 2 × 2 blocks flat."""
    out = _replicated(picture)
    out[0, 1] ^= 1
    return out


@pytest.mark.parametrize("name", ["camera", "astronaut"])
def test_auto_codes_a_picture_of_flat_blocks_with_haar_in_fewer_bytes(name: str) -> None:
    image = _nearly_replicated(getattr(data, name)()[::4, ::4])
    auto = encode_image(image, quality=40)
    named = encode_image(image, wavelet="cdf97", quality=40)
    assert inspect(auto)["wavelet"] == "haar" and inspect(auto)["replicated"] == 1
    assert psnr(decode(auto), image) >= 40
    assert len(auto) < 0.8 * len(named)


@pytest.mark.parametrize("name", ["camera", "astronaut"])
def test_auto_codes_an_exact_enlargement_as_its_source(name: str) -> None:
    source = getattr(data, name)()[::4, ::4]
    image = _replicated(source)
    auto = encode_image(image, quality=40)
    info = inspect(auto)
    assert info["replicated"] == 2 and info["wavelet"] == "cdf97"  # chosen on the source
    assert psnr(decode(auto), image) >= 40
    # cdf97 on the whole picture (one pixel off) takes more than twice the bytes; Haar on it,
    # auto's choice there, takes 0.97–1.06 times (camera, astronaut at these sizes)
    whole = encode_image(_nearly_replicated(source), wavelet="cdf97", quality=40)
    assert len(auto) < 0.5 * len(whole)


def test_auto_is_cdf97_on_a_photograph_byte_for_byte() -> None:
    image = data.coins()
    assert encode_image(image, bpp=0.5) == encode_image(image, wavelet="cdf97", bpp=0.5)


def test_auto_keeps_shape_and_dtype_of_hostile_shapes() -> None:
    for image in (
        np.full((1, 300), 7, dtype=np.uint8),
        np.full((300, 1), 7, dtype=np.uint16),
        np.zeros((2, 2, 3), dtype=np.uint8),
        _replicated(np.arange(64, dtype=">u2").reshape(8, 8) * 1000),
    ):
        out = decode(encode_image(image, quality=45))
        assert out.shape == image.shape and out.dtype == image.dtype.newbyteorder("=")
