"""Image files ↔ numpy arrays with Pillow (which ``wavecore`` itself never imports).

Decoding is defended against decompression bombs twice: Pillow's own ``MAX_IMAGE_PIXELS`` is set
from the settings, and the size in the file's header is checked against the limit before a
single pixel is decoded.  Anything Pillow cannot read completely is an "unsupported image".

No bits are dropped silently.  Pillow reads 16-bit grey (modes ``I;16``/``I;16B``) as it is, but
opens 48- and 64-bit RGB(A) TIFFs and PNGs as 8-bit RGB(A).  Those TIFFs are read again with
tifffile (a well-kept TIFF reader, by the author of the format's reference tests), which keeps
16 bits; those PNGs, which no dependency of ours decodes at 16 bits, are refused with a 415
that names the formats that do keep them (16-bit TIFF, ``.npy``).

>>> import numpy as np
>>> png = encode_array(np.zeros((4, 5, 3), np.uint8), "png")
>>> read_image(png, max_pixels=100).shape
(4, 5, 3)
"""

from __future__ import annotations

import io
import warnings

import numpy as np
import tifffile
from PIL import Image

from .errors import Problem
from .gridfiles import tiff_chunk_limit

#: Output formats for images and the media type of each.
IMAGE_FORMATS = {"png": "image/png", "webp": "image/webp", "tiff": "image/tiff"}
NPY_MEDIA_TYPE = "application/x-npy"


def set_pixel_limit(max_pixels: int) -> None:
    """Pillow's bomb check (process-wide) from the settings: warn above it, refuse at twice."""
    Image.MAX_IMAGE_PIXELS = max_pixels


def read_image(data: bytes, *, max_pixels: int) -> np.ndarray:
    """Decode an image file into ``(H, W)`` or ``(H, W, C)`` ``uint8``/``uint16``/``float32``.

    Palette and 1-bit images become 8-bit (RGB(A) or grey), CMYK and other colour spaces RGB;
    16-bit greys stay ``uint16``; only the first frame of an animation is used.

    Raises
    ------
    Problem
        ``image-too-large`` (413) past ``max_pixels``; ``unsupported-media-type`` (415) for
        anything that is not a complete image Pillow reads.
    """
    try:
        with warnings.catch_warnings():
            # Between 1× and 2× the limit Pillow only warns; the check below refuses it.
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(data))
            width, height = image.size
            if width * height > max_pixels:
                msg = (
                    f"the image is {width} × {height} = {width * height} pixels; the limit is "
                    f"{max_pixels} pixels (WAVECORE_MAX_PIXELS)"
                )
                raise Problem("image-too-large", msg)
            if image.format == "TIFF":
                _check_tiff_chunk(image)
            deeper = _bits_beyond_the_mode(image, data)  # from the header, before decoding
            if deeper:
                return _read_deep(image, data, deeper)
            image.load()
            return _to_array(image)
    except Problem:
        raise
    except Image.DecompressionBombError as exc:
        # Pillow's own check in Image.open (past twice the limit), also from the header.
        msg = f"the image is over the limit of {max_pixels} pixels (WAVECORE_MAX_PIXELS): {exc}"
        raise Problem("image-too-large", msg) from None
    except MemoryError:
        raise Problem("image-too-large", "the image does not fit in memory") from None
    except Image.UnidentifiedImageError:
        msg = "not an image: Pillow recognises no image format in the file"
        raise Problem("unsupported-media-type", msg) from None
    except Exception as exc:
        # Pillow raises many kinds (UnidentifiedImageError, OSError for truncated data,
        # SyntaxError and ValueError from plugins): any of them means "not a readable image".
        msg = f"not a complete image that Pillow can read ({type(exc).__name__}: {exc})"
        raise Problem("unsupported-media-type", msg[:500]) from None


def _check_tiff_chunk(image: Image.Image) -> None:
    """Refuse a TIFF whose tiles (or strips) decode to far more than its picture, from its
    tags, before a sample is decoded."""
    tags = getattr(image, "tag_v2", {})  # Pillow's TIFF plugin has it; typing does not
    width, height = image.size
    bits = tags.get(258, (8,))  # BitsPerSample, one value per sample
    sample_bytes = -(-(max(bits) if isinstance(bits, tuple) else int(bits)) // 8)
    samples = int(tags.get(277, 1))  # SamplesPerPixel
    if 322 in tags and 323 in tags:  # TileWidth, TileLength
        across, down = int(tags[322]), int(tags[323])
    else:  # strips: RowsPerStrip rows (a larger value means the whole picture)
        across, down = width, min(int(tags.get(278, height)), height)
    chunk = across * down * samples * sample_bytes
    limit = tiff_chunk_limit(width * height * samples * sample_bytes)
    if chunk > limit:
        msg = (
            f"this {width} × {height} TIFF is stored in tiles or strips of {across} × {down} "
            f"pixels, {chunk} bytes each once decoded; at most {limit} are accepted"
        )
        raise Problem("image-too-large", msg)


def _bits_beyond_the_mode(image: Image.Image, data: bytes) -> int:
    """The file's bits per sample when Pillow's mode holds fewer (it drops them), else 0."""
    if image.mode not in ("RGB", "RGBA", "LA", "L", "CMYK", "P"):
        return 0  # the I;16, I and F modes keep every bit
    if image.format == "TIFF":
        tags = getattr(image, "tag_v2", {})  # Pillow's TIFF plugin has it; typing does not
        bits = tags.get(258, (8,))  # BitsPerSample, one value per sample
        deepest = max(bits) if isinstance(bits, tuple) else int(bits)
        return deepest if deepest > 8 else 0
    if image.format == "PNG" and data[12:16] == b"IHDR" and data[24] == 16:
        return 16
    return 0


def _read_deep(image: Image.Image, data: bytes, bits: int) -> np.ndarray:
    """A file of more than 8 bits per sample that Pillow would have read as 8: all its bits,
    or a 415 that says what to send instead."""
    instead = "send a 16-bit TIFF (uncompressed or deflate) or the array as .npy"
    if image.format != "TIFF":
        msg = (
            f"this {bits}-bit {image.format} ({image.mode}) would be read as 8 bits per sample, "
            f"losing its low bits; {instead}"
        )
        raise Problem("unsupported-media-type", msg)
    try:
        array = tifffile.imread(io.BytesIO(data), key=0)
    except Exception as exc:
        # A compression that needs imagecodecs (LZW, JPEG, …), or a layout tifffile refuses.
        msg = (
            f"this {bits}-bit TIFF cannot be read without losing bits "
            f"({type(exc).__name__}: {exc}); {instead}"
        )
        raise Problem("unsupported-media-type", msg[:500]) from None
    array = np.asarray(array)
    if array.dtype != np.uint16 or array.shape[:2] != (image.height, image.width):
        msg = (
            f"this {bits}-bit TIFF reads as {array.dtype} {array.shape}, not as "
            f"{image.height} × {image.width} pixels of 16-bit samples; {instead}"
        )
        raise Problem("unsupported-media-type", msg)
    if array.ndim == 3 and array.shape[2] > 4:  # extra samples beyond RGBA
        array = array[:, :, :4]
    return array.astype(np.uint16)  # native byte order, whatever the file's


def _to_array(image: Image.Image) -> np.ndarray:
    mode = image.mode
    if mode in ("L", "LA", "RGB", "RGBA"):
        return np.asarray(image)
    if mode.startswith("I;16"):
        return np.asarray(image).astype(np.uint16)
    if mode in ("I", "F"):
        arr = np.asarray(image)
        if mode == "I" and arr.size and arr.min() >= 0 and arr.max() <= 65535:
            return arr.astype(np.uint16)
        return arr.astype(np.float32)
    if mode in ("1",):
        return np.asarray(image.convert("L"))
    if mode in ("P", "PA"):
        has_alpha = "transparency" in image.info or mode == "PA"
        converted = image.convert("RGBA" if has_alpha else "RGB")
        return np.asarray(converted)
    if mode == "La":
        return np.asarray(image.convert("LA"))
    if mode in ("RGBa", "RGBX"):
        return np.asarray(image.convert("RGBA" if mode == "RGBa" else "RGB"))
    return np.asarray(image.convert("RGB"))


def encode_array(array: np.ndarray, fmt: str) -> bytes:
    """Write a decoded image as ``png``, ``webp`` or ``tiff``.

    ``uint8`` images of any channel count, and ``uint16`` grey, are written exactly; other
    combinations have no exact file in that format and raise a 406 problem that names
    ``format=npy``, which always works.
    """
    image = _to_image(array, fmt)
    out = io.BytesIO()
    if fmt == "png":
        # Level 1: the response is a preview, and zlib's default level costs 3× the time.
        image.save(out, format="PNG", compress_level=1)
    elif fmt == "webp":
        image.save(out, format="WEBP", lossless=True, quality=50, method=2)
    else:
        image.save(out, format="TIFF", compression="tiff_adobe_deflate")
    return out.getvalue()


def _to_image(array: np.ndarray, fmt: str) -> Image.Image:
    grey = array.ndim == 2 or (array.ndim == 3 and array.shape[2] == 1)
    if array.dtype == np.uint8:
        if array.ndim == 3 and array.shape[2] == 1:
            array = array[:, :, 0]
        # Pillow's WebP writer converts grey and grey + alpha to RGB(A) itself.
        return Image.fromarray(np.ascontiguousarray(array))
    if array.dtype == np.uint16 and grey and fmt in ("png", "tiff"):
        return Image.fromarray(np.ascontiguousarray(array.reshape(array.shape[:2])))
    if array.dtype == np.float32 and grey and fmt == "tiff":
        return Image.fromarray(np.ascontiguousarray(array.reshape(array.shape[:2])))
    shape = "x".join(str(s) for s in array.shape)
    msg = (
        f"a {shape} {array.dtype} image has no exact {fmt} file; ask for format=npy "
        "(or png/tiff for 16-bit grey, tiff for float grey)"
    )
    raise Problem("not-acceptable", msg)
