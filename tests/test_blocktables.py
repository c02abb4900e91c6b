"""The compiled table loops of the block coder (``wavecore._blocktables``) against plain
Python written from their definitions: the CRC against ``binascii.crc_hqx`` (the CRC the
bundle format names), the block sizes and compact tables against loops over the tables."""

from __future__ import annotations

import binascii

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore import _blockkernels as kernels
from wavecore import _blocktables as tables
from wavecore.blockcoder import block_table


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=600), st.lists(st.integers(0, 600), max_size=8))
def test_crc16_spans_is_crc_hqx(data: bytes, cuts: list[int]) -> None:
    bounds = sorted(min(c, len(data)) for c in cuts)
    starts = np.array([0, *bounds], dtype=np.int64)
    ends = np.array([*bounds, len(data)], dtype=np.int64)
    found = tables.crc16_spans(np.frombuffer(data, dtype=np.uint8), starts, ends)
    expected = [binascii.crc_hqx(data[s:e], 0) for s, e in zip(starts, ends, strict=True)]
    assert found.tolist() == expected


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=2000), st.integers(0, 0xFFFF), st.integers(0, 20))
def test_crc16_is_crc_hqx(data: bytes, start: int, skip: int) -> None:
    """Eight bytes a step, the running value carried in, any length (and views of bytes)
    give ``binascii.crc_hqx``'s value, on both sides of the short-data threshold."""
    assert tables.crc16(data, start) == binascii.crc_hqx(data, start)
    view = memoryview(data)[skip:]
    assert tables.crc16(view, start) == binascii.crc_hqx(view, start)
    array = np.frombuffer(data, dtype=np.uint8)
    lo = min(skip, len(data))
    assert tables.crc16_update(array, lo, len(data), start) == binascii.crc_hqx(data[lo:], start)


def test_crc16_continues_over_parts() -> None:
    """A CRC continued over the parts of a long chunk is the whole chunk's CRC (the bundle's
    group checks are computed that way)."""
    data = np.random.default_rng(7).integers(0, 256, 100_003, dtype=np.uint8).tobytes()
    crc = 0
    for lo in range(0, len(data), 30_001):
        crc = tables.crc16(data[lo : lo + 30_001], crc)
    assert crc == binascii.crc_hqx(data, 0) == tables.crc16(data)


def _random_tables(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Two levels of three planes each (sizes cut short at the edges), blocks of 4 x 4."""
    planes, blocks = [], []
    for level in range(2):
        first = len(planes)
        rows, cols = (int(v) for v in rng.integers(1, 11, size=2))
        for k in range(3):
            sibling = first if k else -1
            planes.append([0, rows - (k == 2), cols, 1, sibling, -1, -1, k])
        for r0 in range(0, rows, 4):
            for c0 in range(0, cols, 4):
                blocks.append([first, len(planes), r0, c0, r0 + 4, c0 + 4, 1 - level])
        del level
    return np.array(planes, dtype=np.int64), np.array(blocks, dtype=np.int64)


def test_block_sizes_and_compact_tables_match_their_definition() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        planes, blocks = _random_tables(rng)
        sizes = tables.block_sizes(planes, blocks)
        indices = np.sort(rng.choice(len(blocks), size=max(1, len(blocks) // 2), replace=False))
        sub_planes, sub_blocks, pieces, total = tables.compact_tables(planes, blocks, indices)
        offset = 0
        n = 0
        for k, b in enumerate(indices):
            lo, hi, r0, c0, r1, c1, level = blocks[b]
            expected_size = 0
            for p in range(lo, hi):
                height = max(0, min(r1, planes[p, kernels.P_ROWS]) - r0)
                width = max(0, min(c1, planes[p, kernels.P_COLS]) - c0)
                expected_size += height * width
                assert pieces[n].tolist() == [p, r0, r0 + height, c0, c0 + width]
                assert sub_planes[n, kernels.P_OFFSET] == offset
                assert sub_planes[n, kernels.P_ROWS] == height
                assert sub_planes[n, kernels.P_COLS] == width
                sibling = planes[p, kernels.P_SIB1]
                assert sub_planes[n, kernels.P_SIB1] == (
                    sibling - lo + n - (p - lo) if sibling >= 0 else -1
                )
                offset += height * width
                n += 1
            assert sizes[b] == expected_size
            assert sub_blocks[k].tolist() == [n - (hi - lo), n, 0, 0, r1 - r0, c1 - c0, level]
        assert total == offset == sizes[indices].sum()


def test_block_table_round_trip_through_checks() -> None:
    """add_block_checks then strip_block_checks gives back the chunk; a flipped byte in one
    block is reported for that block only."""
    from wavecore.blockcoder import add_block_checks, strip_block_checks

    rng = np.random.default_rng(3)
    lengths = [5, 0, 17, 300, 1]
    table = kernels.write_varints(np.array(lengths, dtype=np.int64)).tobytes()
    chunk = table + rng.integers(0, 256, size=sum(lengths), dtype=np.uint8).tobytes()
    assert block_table(chunk, len(lengths))[1].tolist() == lengths
    stored = add_block_checks(chunk, len(lengths), [(3, 1), (0, 0)])
    back, bad, counts = strip_block_checks(stored, len(lengths), 2)
    assert back == chunk and not bad.any() and counts == [(3, 1), (0, 0)]
    damaged = bytearray(stored)
    damaged[-2] ^= 0x40  # inside the last-but-one block (300 bytes)
    _, bad, _ = strip_block_checks(bytes(damaged), len(lengths), 2)
    assert bad.tolist() == [False, False, False, True, False]
