"""Blocks coded alone (``block_lengths``, ``CodedBlocks.recode``: each chosen block copied
into compact planes of its own) give exactly the bytes of the full coding, also where the
bands of a level differ in size (a block's siblings then end inside it) and for 1-D layouts."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore.blockcoder import CodedBlocks, block_lengths, encode_blocks


def _level(rng: np.random.Generator, shapes: list[tuple[int, ...]], scale: float) -> list:
    return [rng.laplace(0, scale, shape).astype(np.int32) for shape in shapes]


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    channels=st.integers(1, 3),
    rows=st.integers(1, 200),
    cols=st.integers(1, 200),
    block=st.sampled_from([16, 32, 64]),
)
def test_blocks_coded_alone_match_the_full_coding(
    seed: int, channels: int, rows: int, cols: int, block: int
) -> None:
    rng = np.random.default_rng(seed)
    coarse = (max(1, rows // 2), max(1, cols // 2), channels)
    # Unequal bands in one level, as odd sizes give: one row and one column fewer.
    shapes = [(rows, cols, channels), (max(1, rows - 1), cols, channels)]
    shapes.append((rows, max(1, cols - 1), channels))
    entries = [
        [rng.integers(-300, 300, coarse).astype(np.int32)],
        _level(rng, shapes, 1.5),
    ]
    chunks = encode_blocks(entries, True, block)
    layout = [[band.shape for band in bands] for bands in entries]
    full = CodedBlocks(chunks, layout, True, block)
    everything = np.arange(len(full.regions))
    lengths, _ = block_lengths(entries, True, block, everything)
    assert np.array_equal(lengths, full.lengths())
    chosen = rng.permutation(everything)[: max(1, len(everything) // 3)]
    assert np.array_equal(block_lengths(entries, True, block, chosen)[0], full.lengths()[chosen])
    # Recoding unchanged blocks leaves every byte as it was.
    full.recode(entries, np.sort(chosen))
    assert full.chunks() == chunks


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), length=st.integers(1, 5000), dims=st.integers(1, 3))
def test_one_dimensional_blocks_coded_alone_match(seed: int, length: int, dims: int) -> None:
    rng = np.random.default_rng(seed)
    entries = [
        [rng.integers(-50, 50, (max(1, length // 2), dims)).astype(np.int32)],
        [rng.laplace(0, 1.0, (length, dims)).astype(np.int32)],
    ]
    chunks = encode_blocks(entries, False, 16)
    layout = [[band.shape for band in bands] for bands in entries]
    full = CodedBlocks(chunks, layout, False, 16)
    everything = np.arange(len(full.regions))
    assert np.array_equal(block_lengths(entries, False, 16, everything)[0], full.lengths())


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    channels=st.integers(1, 3),
    rows=st.integers(1, 300),
    cols=st.integers(1, 300),
    block=st.sampled_from([16, 32]),
)
def test_version_6_blocks_coded_alone_match_and_recode_their_children(
    seed: int, channels: int, rows: int, cols: int, block: int
) -> None:
    """Version 6: a block coded alone reads its parent's values (copied with it) and matches
    the full coding; a block recoded with new values recodes its children, whose contexts
    read them, so the chunks stay those of a full coding of the new values."""
    rng = np.random.default_rng(seed)
    levels = []
    for level in range(3):  # coarse to fine, each about twice the last, sizes off by one
        r, c = max(1, rows >> (2 - level)), max(1, cols >> (2 - level))
        shapes = [(r, c, channels), (max(1, r - 1), c, channels), (r, max(1, c - 1), channels)]
        levels.append(_level(rng, shapes, 2.0 / (level + 1)))
    coarse = (max(1, (rows >> 2) - 1), max(1, (cols >> 2) - 1), channels)
    entries = [[rng.integers(-300, 300, coarse).astype(np.int32)], *levels]
    layout = [[band.shape for band in bands] for bands in entries]
    chunks = encode_blocks(entries, True, block, 6)
    assert chunks != encode_blocks(entries, True, block, 4) or rows * cols < 64
    full = CodedBlocks(chunks, layout, True, block, 6)
    everything = np.arange(len(full.regions))
    assert np.array_equal(block_lengths(entries, True, block, everything, 6)[0], full.lengths())
    chosen = rng.permutation(everything)[: max(1, len(everything) // 3)]
    assert np.array_equal(block_lengths(entries, True, block, chosen, 6)[0], full.lengths()[chosen])
    # New values in the middle level's first block: recoding it alone recodes its children.
    changed = [[band.copy() for band in bands] for bands in entries]
    for band in changed[2]:
        band[:block, :block] = rng.laplace(0, 3.0, band[:block, :block].shape).astype(np.int32)
    first = int(np.flatnonzero(full.regions[:, 0] == 2)[0])
    full.recode(changed, np.array([first]))
    assert full.chunks() == encode_blocks(changed, True, block, 6)
