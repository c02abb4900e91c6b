"""Inflating deflated sections of a bundle, never past a bound: a few bytes of a crafted
bundle could otherwise inflate to gigabytes before any size is checked."""

from __future__ import annotations

import zlib

from .errors import BundleError

__all__ = ["inflate"]


def inflate(data: bytes, limit: int, what: str) -> bytes:
    """``data`` inflated, at most ``limit`` bytes of it.

    Raises
    ------
    BundleError
        If ``data`` is not deflate data, is truncated, or inflates past ``limit`` bytes (naming
        the section as ``what``).

    Examples
    --------
    >>> inflate(zlib.compress(b"abc"), 3, "a section")
    b'abc'
    """
    inflater = zlib.decompressobj()
    try:
        text = inflater.decompress(data, limit + 1)
    except zlib.error as exc:
        msg = f"{what} is not valid deflate data: {exc}"
        raise BundleError(msg) from None
    if len(text) > limit or not inflater.eof:
        msg = f"{what} inflates past its size limit ({limit} bytes) or is truncated"
        raise BundleError(msg)
    return text
