"""Compiled loops over the block coder's tables and its block checks (see ``blockcoder.py``).

The block coder's own coding loops are in ``_blockkernels``; these are the per-block loops
around them that used to run in Python: the CRC-16 of every block (bundle format 3.0's block
checks), the coefficients per block (for sharing the work out), and the compact tables of a
sample of blocks.  Each is one compiled call that releases the GIL, so no Python loop runs per
block or per plane.
"""

from __future__ import annotations

import binascii

import numpy as np
from numba import njit

from ._blockkernels import (
    B_COL0,
    B_COL1,
    B_LEVEL,
    B_PLANE_HI,
    B_PLANE_LO,
    B_ROW0,
    B_ROW1,
    BLOCK_FIELDS,
    P_COLS,
    P_LUMA,
    P_OFFSET,
    P_ROWS,
    P_SIB1,
    P_SIB2,
)


def _crc16_tables(slices: int) -> np.ndarray:
    """Slicing-by-``slices`` tables of CRC-16/XMODEM (polynomial 0x1021, MSB first, the CRC
    that ``binascii.crc_hqx(data, 0)`` computes, which bundles store): row ``k`` holds the
    CRC of each byte followed by ``k`` zero bytes (row 0 is the byte-at-a-time table)."""
    tables = np.zeros((slices, 256), dtype=np.int64)
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
        tables[0, byte] = crc
    for k in range(1, slices):
        previous = tables[k - 1]
        tables[k] = ((previous << 8) & 0xFFFF) ^ tables[0, previous >> 8]
    return tables


#: Bytes per step of :func:`crc16_update`: eight table look-ups per step, independent of
#: each other, instead of a chain of eight (about six times the byte-at-a-time speed).
CRC16_SLICES = 8
CRC16_TABLES = _crc16_tables(CRC16_SLICES)
CRC16_TABLE = CRC16_TABLES[0].copy()
#: Below this many bytes :func:`crc16` leaves the work to ``binascii`` (no dispatch).
_SHORT_CRC = 256


@njit(nogil=True, cache=True)
def crc16_update(data: np.ndarray, lo: int, hi: int, crc: int) -> int:
    """``binascii.crc_hqx(data[lo:hi], crc)``, eight bytes a step.

    The CRC is linear (no final xor), so the running value, xored into the next two bytes,
    is carried like message bytes: eight bytes then add up from the slicing tables."""
    tables = CRC16_TABLES
    i = lo
    while i + 8 <= hi:
        b0 = data[i] ^ (crc >> 8)
        b1 = data[i + 1] ^ (crc & 0xFF)
        crc = (
            tables[7, b0]
            ^ tables[6, b1]
            ^ tables[5, data[i + 2]]
            ^ tables[4, data[i + 3]]
            ^ tables[3, data[i + 4]]
            ^ tables[2, data[i + 5]]
            ^ tables[1, data[i + 6]]
            ^ tables[0, data[i + 7]]
        )
        i += 8
    while i < hi:
        crc = ((crc << 8) & 0xFFFF) ^ tables[0, ((crc >> 8) ^ data[i]) & 0xFF]
        i += 1
    return crc


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16/XMODEM of ``data`` continued from ``crc``: ``binascii.crc_hqx(data, crc)``, by
    :func:`crc16_update` for all but short data, without holding the GIL.

    Examples
    --------
    >>> import binascii
    >>> crc16(bytes(range(256)) * 3, 7) == binascii.crc_hqx(bytes(range(256)) * 3, 7)
    True
    """
    if len(data) < _SHORT_CRC:
        return binascii.crc_hqx(data, crc)
    array = np.frombuffer(data, dtype=np.uint8)
    return int(crc16_update(array, 0, array.size, crc))


@njit(nogil=True, cache=True)
def crc16_spans(data: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """CRC-16/XMODEM (``binascii.crc_hqx(data[s:e], 0)``) of each span ``[starts[k], ends[k])``
    of the bytes ``data``."""
    out = np.empty(starts.size, dtype=np.int64)
    for k in range(starts.size):
        out[k] = crc16_update(data, starts[k], ends[k], 0)
    return out


@njit(nogil=True, cache=True)
def block_sizes(planes: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """Coefficients per block: over the planes of its level, the part of its region inside
    each plane."""
    total = np.zeros(blocks.shape[0], dtype=np.int64)
    for b in range(blocks.shape[0]):
        count = 0
        for p in range(blocks[b, B_PLANE_LO], blocks[b, B_PLANE_HI]):
            height = min(blocks[b, B_ROW1], planes[p, P_ROWS]) - blocks[b, B_ROW0]
            width = min(blocks[b, B_COL1], planes[p, P_COLS]) - blocks[b, B_COL0]
            if height > 0 and width > 0:
                count += height * width
        total[b] = count
    return total


@njit(nogil=True, cache=True)
def compact_tables(
    planes: np.ndarray, blocks: np.ndarray, indices: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Plane and block tables holding only blocks ``indices``, each with planes of its own
    (the region of every plane of its level that the block covers, cut where the plane ends,
    and the block at their corner); where each compact plane comes from (rows of ``(plane,
    row0, row1, col0, col1)``); their total size."""
    count = 0
    for k in range(indices.size):
        b = indices[k]
        count += blocks[b, B_PLANE_HI] - blocks[b, B_PLANE_LO]
    sub_planes = np.empty((count, planes.shape[1]), dtype=np.int64)
    sub_blocks = np.empty((indices.size, BLOCK_FIELDS), dtype=np.int64)
    pieces = np.empty((count, 5), dtype=np.int64)
    offset = 0
    n = 0
    for k in range(indices.size):
        b = indices[k]
        lo, hi = blocks[b, B_PLANE_LO], blocks[b, B_PLANE_HI]
        r0, c0, r1, c1 = blocks[b, B_ROW0], blocks[b, B_COL0], blocks[b, B_ROW1], blocks[b, B_COL1]
        first = n
        for p in range(lo, hi):
            sub_planes[n, :] = planes[p, :]
            height = max(0, min(r1, planes[p, P_ROWS]) - r0)
            width = max(0, min(c1, planes[p, P_COLS]) - c0)
            sub_planes[n, P_OFFSET] = offset
            sub_planes[n, P_ROWS] = height
            sub_planes[n, P_COLS] = width
            for slot in (P_SIB1, P_SIB2, P_LUMA):
                if sub_planes[n, slot] >= 0:
                    sub_planes[n, slot] += first - lo
            pieces[n, 0] = p
            pieces[n, 1] = r0
            pieces[n, 2] = r0 + height
            pieces[n, 3] = c0
            pieces[n, 4] = c0 + width
            offset += height * width
            n += 1
        sub_blocks[k, B_PLANE_LO] = first
        sub_blocks[k, B_PLANE_HI] = n
        sub_blocks[k, B_ROW0] = 0
        sub_blocks[k, B_COL0] = 0
        sub_blocks[k, B_ROW1] = r1 - r0
        sub_blocks[k, B_COL1] = c1 - c0
        sub_blocks[k, B_LEVEL] = blocks[b, B_LEVEL]
    return sub_planes, sub_blocks, pieces, offset
