"""The defaults that serve users (issue 12): photographs default to cdf97, the wavelet that wins
the measured rate–distortion; curves and surfaces keep the paper's bspline2; bspline2 stays one
word away."""

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

    assert pyinspect.signature(wavecore.encode_image).parameters["wavelet"].default == "cdf97"
    assert pyinspect.signature(wavecore.encode_curve).parameters["wavelet"].default == "bspline2"
