"""The tiles or strips of a TIFF series, from its tags alone: what a reader decodes whole.

A reader decodes a whole tile or strip before it crops it, so a small compressed file can ask
for far more memory than its picture (one zstd tile of 16384² float64 zeros is 66 kB and 2 GiB).
The service's grid reader and the pyramids' TIFF source each bound what they accept from this.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, NamedTuple

import numpy as np

__all__ = ["TiffLayout", "tiff_layouts"]


class TiffLayout(NamedTuple):
    """One page layout of a TIFF series."""

    shape: tuple[int, ...]  #: the page's samples
    chunks: tuple[int, ...]  #: one tile or strip
    chunk_bytes: int  #: a tile or strip, decoded
    page_bytes: int  #: the page, decoded


def tiff_layouts(series: Any) -> Iterator[TiffLayout]:
    """Each distinct page layout of a tifffile series (the frames of a stack share their
    keyframe's, which is given once), read from the tags, before a sample is decoded."""
    seen = set()
    for page in series.pages:
        key = getattr(page, "keyframe", page)
        if key is None or id(key) in seen:
            continue
        seen.add(id(key))
        itemsize = np.dtype(key.dtype).itemsize
        shape, chunks = tuple(key.shape), tuple(key.chunks)
        yield TiffLayout(shape, chunks, math.prod(chunks) * itemsize, math.prod(shape) * itemsize)
