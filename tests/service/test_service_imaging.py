"""Image files keep every bit, or are refused (issue 10), and RGBA figures agree (issue 15).

Real files, made by Pillow and tifffile: 16-bit grey PNG and TIFF (both byte orders), 48- and
64-bit RGB(A) TIFF (which Pillow alone opens as 8-bit RGB), and a 16-bit RGB PNG (which no
reader of ours keeps at 16 bits: refused with a 415 that says what to send instead).
"""

from __future__ import annotations

import io
import math
import struct
import zlib
from collections.abc import Callable

import httpx
import numpy as np
import pytest
import tifffile
from PIL import Image
from service_helpers import image_file, test_image, tiled_tiff_declaring

import wavecore
from service.errors import Problem
from service.imaging import read_image

pytestmark = pytest.mark.anyio

RNG = np.random.default_rng(21)
RGB16 = RNG.integers(0, 65536, (24, 20, 3), dtype=np.uint16)
RGBA16 = RNG.integers(0, 65536, (24, 20, 4), dtype=np.uint16)
GREY16 = RNG.integers(0, 65536, (24, 20), dtype=np.uint16)


def tiff(array: np.ndarray, **options: object) -> bytes:
    out = io.BytesIO()
    photometric = "minisblack" if array.ndim == 2 else "rgb"
    tifffile.imwrite(out, array, photometric=photometric, **options)  # type: ignore[arg-type]
    return out.getvalue()


def png16_rgb(array: np.ndarray) -> bytes:
    """A 48-bit RGB PNG, written by hand (Pillow cannot write one): IHDR, one IDAT, IEND."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (
            struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
        )

    height, width, _ = array.shape
    rows = b"".join(b"\x00" + array[y].astype(">u2").tobytes() for y in range(height))
    header = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows))
        + chunk(b"IEND", b"")
    )


KEPT: dict[str, tuple[Callable[[], bytes], np.ndarray]] = {
    "48-bit RGB TIFF": (lambda: tiff(RGB16), RGB16),
    "48-bit RGB TIFF, big-endian": (lambda: tiff(RGB16, byteorder=">"), RGB16),
    "48-bit RGB TIFF, deflate": (lambda: tiff(RGB16, compression="zlib"), RGB16),
    "64-bit RGBA TIFF": (lambda: tiff(RGBA16, extrasamples=["unassalpha"]), RGBA16),
    "16-bit grey TIFF": (lambda: tiff(GREY16), GREY16),
    "16-bit grey TIFF, big-endian": (lambda: tiff(GREY16, byteorder=">"), GREY16),
    "16-bit grey PNG (Pillow)": (lambda: image_file(GREY16, "PNG"), GREY16),
    "16-bit grey TIFF (Pillow)": (lambda: image_file(GREY16, "TIFF"), GREY16),
}


@pytest.mark.parametrize("name", sorted(KEPT))
def test_sixteen_bit_files_keep_sixteen_bits(name: str) -> None:
    make, expected = KEPT[name]
    array = read_image(make(), max_pixels=10_000)
    assert array.dtype == np.uint16 and array.dtype.isnative
    assert np.array_equal(array, expected)


def test_a_sixteen_bit_colour_png_is_refused_not_cut_to_eight_bits() -> None:
    data = png16_rgb(RGB16)
    assert Image.open(io.BytesIO(data)).mode == "RGB"  # what Pillow alone would give: 8 bits
    with pytest.raises(Problem, match=r"16-bit PNG.*8 bits.*16-bit TIFF.*npy") as caught:
        read_image(data, max_pixels=10_000)
    assert caught.value.status == 415


def test_a_tiff_tifffile_cannot_decode_is_refused_clearly() -> None:
    try:
        import imagecodecs  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("imagecodecs is installed: tifffile reads LZW, so nothing is refused")
    from tifffile import TiffWriter

    out = io.BytesIO()
    with TiffWriter(out) as writer:
        # Written uncompressed, then labelled LZW: tifffile needs imagecodecs to read it.
        writer.write(RGB16, photometric="rgb")
    data = bytearray(out.getvalue())
    entry = data.find(struct.pack("<HHI", 259, 3, 1))  # Compression, SHORT, 1 value
    assert entry > 0
    data[entry + 8 : entry + 10] = struct.pack("<H", 5)
    with pytest.raises(Problem, match=r"16-bit TIFF cannot be read without losing bits") as caught:
        read_image(bytes(data), max_pixels=10_000)
    assert caught.value.status == 415


@pytest.mark.parametrize("array", [RGB16, test_image((24, 20)), test_image((24, 20, 3))])
def test_a_tiff_whose_tiles_decode_to_far_more_is_refused_before_decoding(
    array: np.ndarray,
) -> None:
    # a 24 × 20 picture whose tiles are 8192 × 8192: 64-384 MiB each once decoded
    with pytest.raises(Problem, match=r"tiles or strips of 8192 × 8192") as caught:
        read_image(tiled_tiff_declaring(array, 8192), max_pixels=10_000)
    assert caught.value.status == 413
    # ordinary tiles, larger than the picture, and one strip of the whole picture still read
    for options in ({"tile": (256, 256), "compression": "zlib"}, {"rowsperstrip": 24}):
        assert np.array_equal(read_image(tiff(array, **options), max_pixels=10_000), array)


def test_eight_bit_files_are_unchanged() -> None:
    image = test_image((20, 24, 3))
    assert np.array_equal(read_image(image_file(image, "TIFF"), max_pixels=10_000), image)
    assert np.array_equal(read_image(image_file(image, "PNG"), max_pixels=10_000), image)


async def test_a_48_bit_tiff_is_coded_losslessly_at_16_bits(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    """Issue 10: it came back 8-bit with PSNR "inf"."""
    async with make_client() as client:
        r = await client.post(
            "/v1/images/encode",
            files={"file": ("in.tiff", tiff(RGB16), "image/tiff")},
            data={"lossless": "true"},
        )
        assert r.status_code == 200, r.text
        assert r.headers["x-wavecore-dtype"] == "uint16"
        assert r.headers["x-wavecore-psnr"] == "inf"
        assert np.array_equal(wavecore.decode(r.content), RGB16)
        refused = await client.post(
            "/v1/images/encode",
            files={"file": ("in.png", png16_rgb(RGB16), "image/png")},
            data={"lossless": "true"},
        )
        assert refused.status_code == 415
        assert refused.headers["content-type"].startswith("application/problem+json")
        assert "16-bit" in refused.json()["detail"]


async def test_an_opaque_rgba_upload_reports_its_colour_psnr(
    make_client: Callable[..., httpx.AsyncClient],
) -> None:
    """Issue 15: 35.02 dB was reported for an RGBA picture whose RGB PSNR was 33.77 dB."""
    rgb = test_image((64, 72, 3), seed=4)
    rgba = np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)])
    async with make_client() as client:
        r = await client.post(
            "/v1/images/encode",
            files={"file": ("in.png", image_file(rgba, "PNG"), "image/png")},
            data={"quality": "35"},
        )
    assert r.status_code == 200, r.text
    decoded = wavecore.decode(r.content)
    assert np.all(decoded[..., 3] == 255)
    mse = float(np.mean((decoded[..., :3].astype(float) - rgb) ** 2))
    rgb_psnr = 10 * math.log10(255**2 / mse)
    header = float(r.headers["x-wavecore-psnr"])
    assert rgb_psnr >= 35 and header == pytest.approx(rgb_psnr, abs=5e-3)
    assert wavecore.inspect(r.content)["psnr"] == pytest.approx(header, abs=5e-3)


@pytest.mark.parametrize(
    ("dtype", "magnitude"), [(">f8", 1.0), (">f8", 1e300), (">i2", 1000.0), (">u2", 1000.0)]
)
async def test_a_big_endian_or_huge_npy_surface_is_encoded(
    make_client: Callable[..., httpx.AsyncClient], dtype: str, magnitude: float
) -> None:
    """Issue 10: a big-endian ``.npy`` upload was a numba TypingError (500), values from 1e155
    an OverflowError (500)."""
    u, v = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 18), indexing="ij")
    grid = (np.abs(np.sin(3 * u) * np.cos(2 * v)) * magnitude).astype(dtype)
    out = io.BytesIO()
    np.save(out, grid)
    async with make_client() as client:
        r = await client.post(
            "/v1/surfaces/encode",
            files={"file": ("s.npy", out.getvalue(), "application/x-npy")},
            data={"quality": "40"},
        )
    assert r.status_code == 200, r.text
    decoded = wavecore.decode(r.content)
    assert decoded.shape == grid.shape and decoded.dtype.isnative
    scale = float(np.max(np.abs(grid.astype(np.float64))))
    error = (decoded.astype(np.float64) - grid.astype(np.float64)) / scale
    assert np.all(np.isfinite(decoded.astype(np.float64)))
    assert float(np.max(np.abs(error))) < 0.1
