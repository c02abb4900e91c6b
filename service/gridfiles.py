"""Grid files in: ``.npy`` and (Geo)TIFF height maps, read with their own dtype.

Used by ``POST /v1/grids/encode`` and by the CLI.  TIFF goes through tifffile (already the
service's reader of 16-bit RGB TIFFs, service/imaging.py): it reads 16-bit, signed and float
samples and multi-page stacks as they are, where Pillow turns them into 8-bit or 32-bit
integers, and it exposes GeoTIFF's ``GDAL_NODATA`` tag, whose cells become NaN (floats).
Both readers learn the shape and dtype from the header, so the size is refused before any
sample is decoded.
"""

from __future__ import annotations

import io
import math
from typing import Any

import numpy as np

from wavecore.tiffchunks import tiff_layouts

__all__ = [
    "GridFileError",
    "check_npy_length",
    "is_grid_file",
    "read_grid_file",
    "read_npy_header",
]

NPY_MAGIC = b"\x93NUMPY"
TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # classic and BigTIFF
#: GeoTIFF's no-data value (GDAL's private tag 42113, an ASCII number).
GDAL_NODATA_TAG = 42113


class GridFileError(ValueError):
    """A grid file that cannot be read; ``kind`` is the problem type to answer with."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def is_grid_file(data: bytes) -> bool:
    """Whether ``data`` begins as a ``.npy`` or a TIFF file does."""
    return data.startswith(NPY_MAGIC) or data[:4] in TIFF_MAGICS


def read_grid_file(data: bytes, name: str, *, max_elements: int) -> np.ndarray:
    """A ``.npy`` or TIFF file's array, in its own dtype (NaN for GeoTIFF no-data cells).

    Raises
    ------
    GridFileError
        ``unsupported-media-type`` for something that is neither, or is unreadable;
        ``invalid-parameter`` for a dtype that is not numeric or a size above
        ``max_elements``.

    Examples
    --------
    >>> buffer = io.BytesIO(); np.save(buffer, np.arange(6, dtype=">i2").reshape(2, 3))
    >>> read_grid_file(buffer.getvalue(), "file", max_elements=10).dtype.str
    '>i2'
    """
    if data.startswith(NPY_MAGIC):
        return _read_npy(data, name, max_elements)
    if data[:4] in TIFF_MAGICS:
        return _read_tiff(data, name, max_elements)
    msg = f"{name} is neither a .npy file nor a TIFF (GeoTIFF) height map"
    raise GridFileError("unsupported-media-type", msg)


def _check(shape: tuple[int, ...], dtype: np.dtype, name: str, max_elements: int) -> None:
    if dtype.kind not in "iuf" or dtype.fields is not None:
        msg = f"{name} has dtype {dtype}; a grid holds integers or floats"
        raise GridFileError("invalid-parameter", msg)
    size = math.prod(shape)
    if size > max_elements:
        msg = f"{name} has {size} values; the limit is {max_elements}"
        raise GridFileError("invalid-parameter", msg)


#: The most axes a ``.npy`` upload may declare.
NPY_MOST_AXES = 8


def read_npy_header(data: bytes, name: str) -> tuple[tuple[int, ...], bool, np.dtype, int]:
    """A ``.npy`` file's shape, Fortran order, dtype and data offset, read from its header only.

    Raises
    ------
    GridFileError
        ``unsupported-media-type`` for a header numpy cannot read.
    """
    f = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        else:
            msg = f".npy version {version} is not supported (1.0 and 2.0 are)"
            raise ValueError(msg)
    except Exception as exc:  # numpy's header parser raises ValueError, TokenError, ...
        msg = f"{name} is not a readable .npy file: {exc}"
        raise GridFileError("unsupported-media-type", msg[:500]) from None
    # No array we take has more axes or longer ones; numpy's own limits (64 axes, an index
    # of 2**63) would be errors of their own after this check.
    if len(shape) > NPY_MOST_AXES or any(n >= 2**31 for n in shape):
        msg = f"{name} declares shape {shape}: more than {NPY_MOST_AXES} axes or one of 2**31"
        raise GridFileError("unsupported-media-type", msg[:500])
    return shape, fortran, dtype, f.tell()


def check_npy_length(
    data: bytes, offset: int, shape: tuple[int, ...], dtype: np.dtype, name: str
) -> None:
    """Refuse a ``.npy`` file whose data is not exactly what its header declares."""
    expected = math.prod(shape) * dtype.itemsize
    if len(data) - offset != expected:
        msg = (
            f"{name} is truncated or padded: its header declares {expected} bytes of data "
            f"and {len(data) - offset} follow"
        )
        raise GridFileError("unsupported-media-type", msg)


def _read_npy(data: bytes, name: str, max_elements: int) -> np.ndarray:
    shape, fortran, dtype, offset = read_npy_header(data, name)
    _check(shape, dtype, name, max_elements)
    check_npy_length(data, offset, shape, dtype, name)
    flat = np.frombuffer(data, dtype=dtype, offset=offset)
    return flat.reshape(shape, order="F" if fortran else "C")


#: The most bytes one decoded TIFF tile or strip may take beyond the picture's own: a reader
#: decodes a whole tile before it crops it, and a 16 × 16 picture stored as one zstd tile of
#: 16384 × 16384 is 25 kB that decodes to 805 MB.  (Here, not in imaging.py, which needs
#: Pillow: the CLI reads grids with tifffile alone.)
TIFF_CHUNK_BYTES = 16 << 20


def tiff_chunk_limit(picture_bytes: int) -> int:
    """The most bytes a decoded tile or strip of a TIFF picture of ``picture_bytes`` may take."""
    return max(picture_bytes, TIFF_CHUNK_BYTES)


def _check_chunks(series: Any, name: str) -> None:
    """Refuse tiles or strips that decode to far more than their pages (a reader decodes a
    whole tile before it crops it: one zstd tile of 16384 × 16384 float64 zeros is 66 kB
    and 2 GiB), from the tags, before a sample is decoded."""
    for layout in tiff_layouts(series):
        limit = tiff_chunk_limit(layout.page_bytes)
        if layout.chunk_bytes > limit:
            msg = (
                f"{name} stores its {' × '.join(map(str, layout.shape))} samples in tiles or "
                f"strips of {' × '.join(map(str, layout.chunks))}, {layout.chunk_bytes} bytes "
                f"each once decoded; at most {limit} are accepted"
            )
            raise GridFileError("too-costly", msg)


def _read_tiff(data: bytes, name: str, max_elements: int) -> np.ndarray:
    import tifffile

    try:
        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            series = tif.series[0]
            shape, dtype = tuple(series.shape), np.dtype(series.dtype)
            _check(shape, dtype, name, max_elements)
            _check_chunks(series, name)
            arr = series.asarray(maxworkers=1)  # one decoded tile at a time
            page = tif.pages.first
            nodata = page.tags.get(GDAL_NODATA_TAG)
            nodata_text = None if nodata is None else str(nodata.value).strip("\x00 ")
    except GridFileError:
        raise
    except Exception as exc:  # tifffile reports bad files in many exception types
        msg = f"{name} is not a readable TIFF: {type(exc).__name__}: {exc}"
        raise GridFileError("unsupported-media-type", msg[:500]) from None
    while arr.ndim > 2 and arr.shape[0] == 1:  # a single page of a stack
        arr = arr[0]
    while arr.ndim > 2 and arr.shape[-1] == 1:  # one sample per pixel
        arr = arr[..., 0]
    if nodata_text and arr.dtype.kind == "f":
        try:
            value = float(nodata_text)
        except ValueError:
            value = None
        if value is not None:
            arr = np.where(arr == value, np.nan, arr).astype(arr.dtype)
    return arr
