"""The per-picture colour rotation of lossy colour pictures (colour ``"klt:<a>,<b>,<c>"``): its
name, its header bytes, its choice, and round trips through every decode path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import wavecore
from wavecore import binheader, decode, encode_image, inspect
from wavecore.bundle import check_header, read_bundle
from wavecore.codec.choice import choose_colour, colour_cost, colour_details
from wavecore.colour import KLT_LIMIT, YCBCR_MATRIX, klt_matrix, klt_name
from wavecore.errors import BundleError

GOLDEN = Path(__file__).resolve().parent / "golden"


def tinted(rows: int = 96, cols: int = 80, seed: int = 5) -> np.ndarray:
    """A picture whose colours vary along one axis far from YCbCr's (green against magenta)."""
    y, x = np.mgrid[0:rows, 0:cols] / 40.0
    base = 120 + 60 * np.sin(9 * x) * np.cos(6 * y)
    rgb = np.stack([base, 0.5 * base + 40, 255 - base], -1)
    noise = np.random.default_rng(seed).normal(0, 3, rgb.shape)
    return (rgb + noise).clip(0, 255).astype(np.uint8)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10 * np.log10(255.0**2 / mse)


def test_names_round_trip_and_round_to_units() -> None:
    rotation = klt_matrix("klt:1000,-700,3000")
    assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(rotation), 1.0)
    assert klt_name(rotation) == "klt:1000,-700,3000"
    # A rotation off the grid of angles comes back within half a unit of each.
    turned = klt_matrix("klt:1000,-700,3000") @ klt_matrix("klt:1,0,0")
    assert np.allclose(klt_matrix(klt_name(turned)), turned, atol=2 * np.pi / 4096)


@pytest.mark.parametrize(
    "name",
    [
        "klt:1,2",  # too few
        "klt:1,2,3,4",  # too many
        "klt:+1,0,0",  # not canonical
        "klt:01,0,0",
        "klt:-0,0,0",
        f"klt:{KLT_LIMIT + 1},0,0",  # out of range
        f"klt:0,{KLT_LIMIT // 2 + 1},0",
        f"klt:0,0,-{KLT_LIMIT + 1}",
        "klt:a,b,c",
        "ycbcr",
    ],
)
def test_bad_names_are_value_errors(name: str) -> None:
    with pytest.raises(ValueError, match="colour matrix"):
        klt_matrix(name)


def test_a_bad_matrix_in_a_header_is_a_bundle_error_naming_the_colour() -> None:
    bundle = encode_image(tinted(), quality=36)
    header = read_bundle(bundle).header
    assert header["colour"].startswith("klt:")
    header["colour"] = f"klt:0,{KLT_LIMIT},0"
    with pytest.raises(BundleError, match="colour"):
        check_header(header)
    with pytest.raises(BundleError, match="colour"):
        binheader.pack(header)


def test_the_header_holds_the_matrix_in_seven_bytes() -> None:
    image = tinted()
    header = read_bundle(encode_image(image, quality=36)).header
    standard = dict(header, colour="ycbcr")
    packed, plain = binheader.pack(header), binheader.pack(standard)
    assert len(packed) - len(plain) <= 7
    assert binheader.unpack(packed) == header


def test_hostile_matrix_bytes_are_refused_by_name() -> None:
    header = read_bundle(encode_image(tinted(), quality=36)).header
    packed = bytearray(binheader.pack(header))
    # The first angle, pushed past the limit: a varint bigger than the largest.
    name = header["colour"]
    first = int(name[4:].split(",")[0])
    encoded = wavecore.varints.encode_varint(wavecore.varints.zigzag(first))
    at = packed.index(encoded)
    packed[at : at + len(encoded)] = b"\xff\xff\x01"
    with pytest.raises(BundleError, match="colour"):
        binheader.unpack(bytes(packed))


def test_a_tinted_picture_takes_the_matrix_and_fewer_bytes() -> None:
    image = tinted(192, 160)
    chosen = choose_colour(image)
    assert chosen.startswith("klt:")
    matrix = klt_matrix(chosen)
    details = colour_details(image)
    assert colour_cost(details, matrix) < colour_cost(details, YCBCR_MATRIX)
    ours = encode_image(image, bpp=1.0)
    from wavecore.codec import encode as encode_module

    real = encode_module.choose_colour
    try:
        encode_module.choose_colour = lambda _: "ycbcr"
        standard = encode_image(image, bpp=1.0)
    finally:
        encode_module.choose_colour = real
    assert inspect(standard)["colour"] == "ycbcr"
    assert psnr(decode(ours), image) > psnr(decode(standard), image) + 0.2


def test_grey_stored_as_rgb_keeps_ycbcr() -> None:
    grey = np.random.default_rng(2).integers(0, 256, (40, 40, 1)).repeat(3, axis=2)
    assert choose_colour(grey.astype(np.uint8)) == "ycbcr"
    assert choose_colour(np.zeros((1, 50, 3))) == "ycbcr"
    # Values near the float64 limit: the covariance overflows, and YCbCr stays.
    huge = np.random.default_rng(3).random((30, 30, 3)) * 1e300
    assert choose_colour(huge) == "ycbcr"


@pytest.mark.parametrize("dtype", ["uint8", ">u2", "float32", "float16"])
def test_round_trip_keeps_shape_and_dtype(dtype: str) -> None:
    image = tinted().astype(np.float64)
    if np.dtype(dtype).kind == "f":
        image = image / 255.0
    elif np.dtype(dtype).itemsize == 2:
        image = image * 257
    image = image.astype(dtype)
    bundle = encode_image(image, quality=36)
    assert inspect(bundle)["colour"].startswith("klt:")
    out = decode(bundle)
    assert out.shape == image.shape and out.dtype == image.dtype.newbyteorder("=")
    assert inspect(bundle)["psnr"] >= 36


def test_alpha_passes_through_and_every_decode_path_agrees() -> None:
    image = np.dstack([tinted(256, 256), np.full((256, 256), 180, np.uint8)])
    bundle = encode_image(image, bpp=2.0)
    assert inspect(bundle)["colour"].startswith("klt:")
    whole = decode(bundle)
    assert whole.shape == image.shape and np.all(whole[..., 3] == 180)
    assert psnr(whole[..., :3], image[..., :3]) > 30
    coarse = decode(bundle, level=2)
    assert coarse.shape == (64, 64, 4)
    region = decode(bundle, region=(slice(64, 128), slice(32, 160)))
    assert np.array_equal(region, whole[64:128, 32:160])


def test_the_golden_matrix_bundle_is_a_klt_one() -> None:
    bundle = (GOLDEN / "image_rgb_u8_klt.wvb").read_bytes()
    assert inspect(bundle)["colour"].startswith("klt:")
    expected = np.load(GOLDEN / "image_rgb_u8_klt.npy")
    assert np.abs(decode(bundle).astype(int) - expected.astype(int)).max() <= 1
