"""Pictures enlarged by pixel replication, coded at their source's size.

A picture made by repeating each pixel of a smaller one ``f × f`` times (pixel art and
screenshots enlarged without smoothing; scikit-image's ``moon`` is a 256² picture at 512²)
holds no more than its source.  :func:`replication_factor` finds the largest such ``f``, a
power of two, and ``encode_image`` then codes the source, ``image[::f, ::f]``, and wraps its
bundle in a *replicated picture* (:func:`wrap`); :func:`wavecore.decode` repeats the decoded
source's pixels again.  The error per pixel is the source's, so a ``quality`` or recorded
PSNR holds as it is; a ``bpp`` target keeps its bytes (the source gets ``f²`` times the
rate, less the few bytes of the wrapper).

Measured (``benchmarks/rate_distortion.py --peers``, docs/benchmarks.md, 2026-12-08): ``moon``
with ``wavelet="cdf97"`` went from +11.0 % to −51.1 % BD-rate against AVIF speed 6, where
Haar on the enlarged picture (what ``wavelet="auto"`` took before) gave −49.2 %.

The bytes (docs/bundle-format.md, "Replicated pictures (7.0)")::

    89 57 07 00    the compact preamble with major version 7, minor 0
    s              one byte: f = 2**s, 1 <= s <= MAX_LOG2_FACTOR
    crc            CRC-16/XMODEM of the five bytes before it, little-endian
    ...            the source's image bundle, any format this reader reads

A reader from before 7.0 refuses it by its major version.  Levels count the replication:
``decode(level=k)`` for ``k < s`` is the decoded source with its pixels repeated
``2**(s - k)`` times, and for ``k >= s`` the source's own ``level=k - s``.
"""

from __future__ import annotations

import binascii
import math
import struct
from collections.abc import Callable
from typing import Any

import numpy as np

from ..bundle import COMPACT_MAGIC, MAX_ELEMENTS, REPLICATED_MAJOR
from ..errors import BundleError, InvalidParameter
from ..regions import check_region

__all__ = [
    "MAX_LOG2_FACTOR",
    "MIN_SOURCE_SIDE",
    "OVERHEAD",
    "REPLICATED_VERSION",
    "decode_replicated",
    "enlarged",
    "inspect_replicated",
    "is_replicated",
    "replication_factor",
    "unwrap",
    "wrap",
]

#: The preamble's major and minor version.
REPLICATED_VERSION = (REPLICATED_MAJOR, 0)
_PREAMBLE = COMPACT_MAGIC + bytes(REPLICATED_VERSION)
_CRC = struct.Struct("<H")
#: The bytes a replicated picture adds to its source's bundle.
OVERHEAD = len(_PREAMBLE) + 1 + _CRC.size
#: The source keeps at least this many pixels a side: below it the wrapper's bytes would be a
#: large share of the bundle, and a transform of the source would have few levels.
MIN_SOURCE_SIDE = 8
#: The largest factor read is ``2**MAX_LOG2_FACTOR``.
MAX_LOG2_FACTOR = 15
#: Rows (and columns) compared at once: bounds the temporaries of a large picture, and a
#: photograph is told apart on its first slice.
_SLICE = 64


def _pairs_equal(source: np.ndarray, axis: int) -> bool:
    """Whether every even row (``axis=0``) or column (``axis=1``) of ``source`` equals the next."""
    moved = np.moveaxis(source, axis, 0)
    for start in range(0, moved.shape[0], 2 * _SLICE):
        block = moved[start : start + 2 * _SLICE]
        if not np.array_equal(block[0::2], block[1::2]):
            return False
    return True


def replication_factor(image: np.ndarray) -> int:
    """The largest ``f = 2**s`` such that ``image`` repeats each pixel of
    ``image[::f, ::f]`` ``f × f`` times, with both sides of that source at least
    :data:`MIN_SOURCE_SIDE`; 1 for any other picture.

    Every channel must repeat alike.  The cost is at most 4/3 of a comparison per sample (each
    doubling compares a quarter as many); a photograph is told apart on its first rows.

    Examples
    --------
    >>> import numpy as np
    >>> source = np.arange(80).reshape(8, 10)
    >>> replication_factor(np.kron(source, np.ones((4, 4), int))), replication_factor(source)
    (4, 1)
    """
    factor = 1
    height, width = image.shape[:2]
    for _ in range(MAX_LOG2_FACTOR):
        double = 2 * factor
        if height % double or width % double:
            break
        if min(height, width) // double < MIN_SOURCE_SIDE:
            break
        source = image[::factor, ::factor]
        # the first pair of rows and of columns first: a photograph fails there
        if not (
            np.array_equal(source[0], source[1]) and np.array_equal(source[:, 0], source[:, 1])
        ):
            break
        if not (_pairs_equal(source, 0) and _pairs_equal(source, 1)):
            break
        factor = double
    return factor


def enlarged(source: np.ndarray, factor: int) -> np.ndarray:
    """``source`` with each pixel repeated ``factor × factor`` times (rows and columns)."""
    if factor == 1:
        return source
    return np.repeat(np.repeat(source, factor, axis=0), factor, axis=1)


def wrap(inner: bytes, log2_factor: int) -> bytes:
    """The replicated picture of the source bundle ``inner``, enlarged ``2**log2_factor``."""
    head = _PREAMBLE + bytes([log2_factor])
    return head + _CRC.pack(binascii.crc_hqx(head, 0)) + inner


def is_replicated(bundle: Any) -> bool:
    """Whether ``bundle`` is bytes that begin as a replicated picture does."""
    return (
        isinstance(bundle, bytes | bytearray | memoryview)
        and bytes(bundle[: len(_PREAMBLE)]) == _PREAMBLE
    )


def unwrap(bundle: bytes | bytearray | memoryview) -> tuple[int, bytes]:
    """``(log2_factor, inner)``: the factor's exponent and the source's bundle.

    Raises
    ------
    BundleError
        If the wrapper is cut short, damaged (its CRC) or names a factor out of range.
    """
    data = bytes(bundle)
    if len(data) < OVERHEAD:
        msg = f"replicated picture: {len(data)} bytes, fewer than its {OVERHEAD}-byte wrapper"
        raise BundleError(msg)
    head = data[: len(_PREAMBLE) + 1]
    (crc,) = _CRC.unpack_from(data, len(head))
    if binascii.crc_hqx(head, 0) != crc:
        msg = "replicated picture: its wrapper is damaged (the CRC-16 of its first 5 bytes)"
        raise BundleError(msg)
    log2_factor = head[-1]
    if not 1 <= log2_factor <= MAX_LOG2_FACTOR:
        msg = (
            f"replicated picture: factor 2**{log2_factor}, where 2**1 to "
            f"2**{MAX_LOG2_FACTOR} are read"
        )
        raise BundleError(msg)
    return log2_factor, data[OVERHEAD:]


def _source_info(
    inner: bytes, log2_factor: int, inspect: Callable[[Any], dict[str, Any]]
) -> dict[str, Any]:
    """The source bundle's ``inspect``, checked: an image whose enlargement stays within
    ``MAX_ELEMENTS`` (checked before anything of that size is allocated)."""
    if is_replicated(inner):
        raise BundleError("replicated picture: its source is itself a replicated picture")
    info = inspect(inner)
    if info["kind"] != "image":
        msg = f"replicated picture: its source is a {info['kind']}, not an image"
        raise BundleError(msg)
    elements = math.prod(info["shape"]) << (2 * log2_factor)
    if elements > MAX_ELEMENTS:
        msg = (
            f"replicated picture: {info['shape'][:2]} enlarged 2**{log2_factor} times would be "
            f"{elements} elements, more than MAX_ELEMENTS = {MAX_ELEMENTS}"
        )
        raise BundleError(msg)
    return info


def decode_replicated(
    bundle: bytes | bytearray | memoryview,
    decode: Callable[..., np.ndarray],
    inspect: Callable[[Any], dict[str, Any]],
    *,
    keep: float | None,
    level: int,
    region: Any,
    damaged: str,
) -> np.ndarray:
    """:func:`wavecore.decode` of a replicated picture (the arguments checked there; ``level``
    is the one of ``level``/``drop_levels`` given)."""
    log2_factor, inner = unwrap(bundle)
    info = _source_info(inner, log2_factor, inspect)
    if level >= log2_factor:
        try:
            return decode(
                inner, keep=keep, level=level - log2_factor, region=region, damaged=damaged
            )
        except InvalidParameter as exc:
            if not str(exc).startswith(f"level {level - log2_factor} is deeper"):
                raise
            height, width = info["shape"][:2]
            msg = (
                f"level {level} is too deep for this picture, its {height} × {width} source "
                f"enlarged {1 << log2_factor} times (the levels below {log2_factor} enlarge the "
                f"source; level {level} is the source's level {level - log2_factor}): {exc}"
            )
            raise InvalidParameter(msg) from None
    factor = 1 << (log2_factor - level)
    height, width = info["shape"][:2]
    if region is None:
        return _enlarged_or_refused(decode(inner, keep=keep, damaged=damaged), factor)
    slices = check_region(region, (height * factor, width * factor), 2)
    # the source's pixels that the region touches, enlarged, then the region's samples of them
    wanted, inner_slices = [], []
    for s in slices:
        last = s.start + (s.stop - s.start - 1) // s.step * s.step
        first_source, end_source = s.start // factor, last // factor + 1
        inner_slices.append(slice(first_source, end_source))
        offset = first_source * factor
        wanted.append(slice(s.start - offset, last + 1 - offset, s.step))
    part = decode(inner, keep=keep, region=tuple(inner_slices), damaged=damaged)
    return np.ascontiguousarray(_enlarged_or_refused(part, factor)[tuple(wanted)])


def _enlarged_or_refused(source: np.ndarray, factor: int) -> np.ndarray:
    """:func:`enlarged`, or a ``BundleError`` where memory runs out (as any decode says)."""
    try:
        return enlarged(source, factor)
    except MemoryError as exc:
        msg = f"not enough memory to enlarge a decoded {source.shape} picture {factor} times"
        raise BundleError(msg) from exc


def inspect_replicated(
    bundle: bytes | bytearray | memoryview, inspect: Callable[[Any], dict[str, Any]]
) -> dict[str, Any]:
    """:func:`wavecore.inspect` of a replicated picture: the source's description, with the
    enlarged picture's ``shape``, ``levels``, ``level_shapes``, ``bpp`` and byte counts, each
    chunk's ``level`` counted from the enlarged picture, and ``replicated`` (the factor)."""
    log2_factor, inner = unwrap(bundle)
    info = dict(_source_info(inner, log2_factor, inspect))
    factor = 1 << log2_factor
    shape = list(info["shape"])
    height, width = shape[0] * factor, shape[1] * factor
    # the levels the replication made: the enlarged picture halved, down to the source
    finer = [[height >> k, width >> k, *shape[2:]] for k in range(log2_factor)]
    info.update(
        shape=[height, width, *shape[2:]],
        levels=info["levels"] + log2_factor,
        level_shapes=finer + info["level_shapes"],
        chunks=[{**chunk, "level": chunk["level"] + log2_factor} for chunk in info["chunks"]],
        total_bytes=len(bundle),
        header_bytes=info["header_bytes"] + OVERHEAD,
        bpp=8.0 * len(bundle) / (height * width),
        replicated=factor,
        version=f"{REPLICATED_VERSION[0]}.{REPLICATED_VERSION[1]}",
        source_version=info["version"],
    )
    return info
