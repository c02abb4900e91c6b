"""Test data for the service tests (generated, seeded)."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from PIL import Image


def test_image(shape: tuple[int, ...] = (48, 64), seed: int = 0) -> np.ndarray:
    """A smooth gradient with seeded noise, uint8."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[: shape[0], : shape[1]]
    base = 90 + 60 * np.sin(x / 9.0) + 50 * np.cos(y / 7.0)
    if len(shape) == 3:
        base = base[:, :, None] + np.array([0, 25, -25])[: shape[2]]
    return np.clip(base + rng.normal(0, 4, base.shape), 0, 255).astype(np.uint8)


test_image.__test__ = False  # type: ignore[attr-defined]  # a helper, not a test


def image_file(array: np.ndarray, fmt: str = "PNG", **options: Any) -> bytes:
    out = io.BytesIO()
    Image.fromarray(array).save(out, format=fmt, **options)
    return out.getvalue()


def circle(n: int = 64, closed: bool = True) -> list[list[float]]:
    t = np.linspace(0, 2 * np.pi, n, endpoint=not closed)
    r = 1 + 0.1 * np.sin(5 * t)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1).tolist()


def bomb_png(width: int = 10_000, height: int = 10_000) -> bytes:
    """A real decompression bomb: a valid all-zero grey PNG of ``width × height`` pixels.

    Its rows are compressed as they are generated, so the 100 MB of pixels never exist here;
    the file is about 100 KB.
    """
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    compressor = zlib.compressobj(9)
    row = b"\x00" * (width + 1)  # filter byte 0, then the zero pixels
    rows_per_step = 256
    parts = []
    for start in range(0, height, rows_per_step):
        parts.append(compressor.compress(row * min(rows_per_step, height - start)))
    parts.append(compressor.flush())
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", b"".join(parts))
        + chunk(b"IEND", b"")
    )


def tiled_tiff_declaring(array: np.ndarray, side: int) -> bytes:
    """A TIFF of ``array`` in one 16 × 16 tile whose tags declare ``side`` × ``side`` tiles.

    A bomb of that shape is a few kilobytes once compressed (one zstd tile of 16384² zeros:
    66 kB for 2 GiB), but writing it needs the codec and the memory; the readers' check uses
    the tags alone, so these are what is patched.
    """
    import struct

    import tifffile

    out = io.BytesIO()
    photometric = "minisblack" if array.ndim == 2 else "rgb"
    tifffile.imwrite(out, array, tile=(16, 16), photometric=photometric)
    data = bytearray(out.getvalue())
    for tag in (322, 323):  # TileWidth, TileLength: one LONG (tifffile's choice)
        entry = data.find(struct.pack("<HHI", tag, 4, 1))
        assert entry > 0, tag
        data[entry + 8 : entry + 12] = struct.pack("<I", side)
    return bytes(data)
