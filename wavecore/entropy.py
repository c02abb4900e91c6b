"""Entropy coding of quantized subbands, one chunk per resolution level, coarse to fine.

``encode_levels`` turns the integers of a decomposition (``wavedec2`` layout
``[cA, (cH, cV, cD), ...]`` or ``wavedec`` layout ``[cA, cD, ...]``) into one byte chunk per
list entry, so that the first ``k`` chunks decode to the first ``k`` entries: a prefix of a
bundle is a complete lower-resolution image.

Coders:

``"zlib"``
    The generic baseline: the level's integers as little-endian ``int32``, deflated.
``"context"``
    The default: a context-modelling range coder (for now it falls back to ``"zlib"``).

The decoder treats its input as hostile: every chunk is checked against the sizes the caller
declares (``shapes``), decompression is bounded by those sizes, and anything wrong raises
:class:`wavecore.errors.BundleError`.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import BundleError, InvalidParameter

__all__ = ["CODERS", "decode_levels", "encode_levels"]

CODERS = ("context", "zlib")
#: The most elements :func:`decode_levels` accepts in one call (matches the bundle limit).
MAX_ELEMENTS = 1 << 31


def _entries(qcoeffs: Sequence[Any]) -> list[list[np.ndarray]]:
    if isinstance(qcoeffs, np.ndarray) or not len(qcoeffs):
        msg = "qcoeffs must be a non-empty list [cA, details of level L, ..., details of level 1]"
        raise InvalidParameter(msg)
    out = []
    for entry in qcoeffs:
        bands = list(entry) if isinstance(entry, tuple | list) else [entry]
        arrays = []
        for band in bands:
            arr = np.asarray(band)
            if arr.dtype.kind not in "iu":
                msg = f"quantized coefficients must be integers, not {arr.dtype}"
                raise InvalidParameter(msg)
            if arr.size and (arr.min() < -(2**31) or arr.max() >= 2**31):
                msg = "quantized coefficients must fit in int32"
                raise InvalidParameter(msg)
            arrays.append(arr.astype(np.int32, copy=False))
        out.append(arrays)
    return out


def _check_coder(coder: Any) -> str:
    if coder not in CODERS:
        accepted = ", ".join(repr(c) for c in CODERS)
        msg = f"unknown coder {coder!r}; accepted coders are {accepted}"
        raise InvalidParameter(msg)
    return str(coder)


def encode_levels(
    qcoeffs: Sequence[Any], *, coder: str = "context"
) -> tuple[list[bytes], dict[str, Any]]:
    """Entropy-code quantized coefficients, one chunk per resolution level.

    Parameters
    ----------
    qcoeffs : list
        Integer arrays in ``wavedec2`` or ``wavedec`` layout, coarse first (as made by
        :func:`wavecore.quantize.quantize_bands`, or integer lifting for lossless coding).
    coder : {"context", "zlib"}
        ``"context"`` (default) is the context-modelling range coder; ``"zlib"`` the generic
        baseline.  (For now ``"context"`` falls back to ``"zlib"``.)

    Returns
    -------
    chunks : list of bytes
        ``chunks[0]`` codes ``cA``, ``chunks[i]`` all bands of entry ``i``.
    params : dict
        JSON-serialisable; :func:`decode_levels` needs it.

    Examples
    --------
    >>> import numpy as np
    >>> q = [np.arange(6, dtype=np.int32).reshape(2, 3), np.array([0, -1, 0, 2], dtype=np.int32)]
    >>> chunks, params = encode_levels(q, coder="zlib")
    >>> len(chunks)
    2
    >>> back = decode_levels(chunks, [(2, 3), (4,)], params)
    >>> bool(np.array_equal(back[1], q[1]))
    True
    """
    coder = _check_coder(coder)
    entries = _entries(qcoeffs)
    chunks = []
    for bands in entries:
        raw = b"".join(band.astype("<i4", copy=False).tobytes() for band in bands)
        chunks.append(zlib.compress(raw, 9))
    return chunks, {"coder": "zlib"}


def _shape_entries(shapes: Sequence[Any]) -> list[list[tuple[int, ...]]]:
    """Normalise ``shapes`` (``[shape, (shape, shape, shape) | shape, ...]``) and bound them."""
    if isinstance(shapes, np.ndarray) or not isinstance(shapes, Sequence):
        msg = "shapes must be a list of band shapes"
        raise BundleError(msg)
    out = []
    total = 0
    for entry in shapes:
        if not isinstance(entry, tuple | list):
            msg = f"band shape entry {entry!r} is not a tuple"
            raise BundleError(msg)
        if entry and all(isinstance(e, tuple | list) for e in entry):
            bands = [tuple(e) for e in entry]
        else:
            bands = [tuple(entry)]
        for band in bands:
            if not all(isinstance(n, int | np.integer) and 0 <= n <= MAX_ELEMENTS for n in band):
                msg = f"band shape {band!r} is not a tuple of sizes"
                raise BundleError(msg)
            total += int(np.prod(band, dtype=object))
            if total > MAX_ELEMENTS:
                msg = f"band shapes declare more than {MAX_ELEMENTS} coefficients"
                raise BundleError(msg)
        out.append([tuple(int(n) for n in band) for band in bands])
    return out


def _inflate(chunk: bytes, expected: int) -> bytes:
    """Decompress at most ``expected`` bytes; anything else is a corrupt chunk."""
    try:
        inflater = zlib.decompressobj()
        raw = inflater.decompress(chunk, expected)
        if inflater.unconsumed_tail or not inflater.eof:
            msg = "zlib chunk does not hold exactly the declared number of coefficients"
            raise BundleError(msg)
    except zlib.error as exc:
        msg = f"corrupt zlib chunk: {exc}"
        raise BundleError(msg) from exc
    if len(raw) != expected or inflater.unused_data:
        msg = (
            f"zlib chunk holds {len(raw)} bytes (+{len(inflater.unused_data)} trailing), "
            f"expected {expected}"
        )
        raise BundleError(msg)
    return raw


def decode_levels(
    chunks: Sequence[bytes], shapes: Sequence[Any], params: dict[str, Any]
) -> list[Any]:
    """Decode the first ``len(chunks)`` levels into integer arrays of the given shapes.

    Parameters
    ----------
    chunks : sequence of bytes
        A prefix of what :func:`encode_levels` returned.
    shapes : sequence
        Band shapes for (at least) those entries, in the same layout: ``shape`` for ``cA`` and
        1-D details, a tuple of three shapes for 2-D details.
    params : dict
        As returned by :func:`encode_levels` (treated as untrusted).

    Returns
    -------
    list
        ``int32`` arrays, ``[cA, (cH, cV, cD) | cD, ...]``, one entry per chunk.

    Raises
    ------
    BundleError
        For anything inconsistent or corrupt; never another exception.
    """
    if not isinstance(params, dict) or params.get("coder") not in CODERS:
        msg = f"entropy coder parameters must name a coder in {CODERS}, not {params!r}"
        raise BundleError(msg)
    if isinstance(chunks, bytes | bytearray) or not isinstance(chunks, Sequence):
        msg = "chunks must be a list of byte strings"
        raise BundleError(msg)
    layout = _shape_entries(shapes)
    if len(chunks) > len(layout) or not chunks:
        msg = f"{len(chunks)} chunks given for {len(layout)} band entries"
        raise BundleError(msg)
    layout = layout[: len(chunks)]
    levels = _decode_zlib(chunks, layout)
    out: list[Any] = []
    for index, (arrays, bands) in enumerate(zip(levels, layout, strict=True)):
        is_single = len(bands) == 1 and not (
            index > 0 and isinstance(shapes[index], tuple | list) and _is_nested(shapes[index])
        )
        out.append(arrays[0] if is_single else tuple(arrays))
    return out


def _is_nested(entry: Any) -> bool:
    return bool(entry) and all(isinstance(e, tuple | list) for e in entry)


def _decode_zlib(
    chunks: Sequence[bytes], layout: list[list[tuple[int, ...]]]
) -> list[list[np.ndarray]]:
    levels = []
    for chunk, bands in zip(chunks, layout, strict=True):
        if not isinstance(chunk, bytes | bytearray | memoryview):
            msg = "each chunk must be bytes"
            raise BundleError(msg)
        sizes = [int(np.prod(b, dtype=np.int64)) for b in bands]
        raw = _inflate(bytes(chunk), 4 * sum(sizes))
        flat = np.frombuffer(raw, dtype="<i4").astype(np.int32)
        arrays, start = [], 0
        for band, size in zip(bands, sizes, strict=True):
            arrays.append(flat[start : start + size].reshape(band))
            start += size
        levels.append(arrays)
    return levels
