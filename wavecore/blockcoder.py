"""Code-blocks: the context coder's versions 4, 6, 7 and 8.

Every level's bands are cut into blocks of ``block × block`` positions (``1 × block²`` for the
1-D layouts of curves).  A block holds that region of *every* band and channel of the level
(``cH``, ``cV``, ``cD`` of each channel, or the one ``cA``), so its contexts can use the other
orientations and the first channel (luma) at the same place, and yet it is coded on its own:

* the coder restarts at each block (fresh adaptive models, a fresh range coder), and its
  contexts look at nothing outside the block, so a block decodes from its own bytes alone: a
  damaged block loses only itself, and a region needs only the blocks that cover it;
* each chunk (one resolution level, as before) starts with the byte length of each of its blocks,
  so a reader finds any block without decoding the others;
* blocks are coded by compiled loops (``_blockkernels``) that release the GIL, one call per run
  of blocks, spread over the library's thread pool (``transform.run_rows``).

Why our own coder rather than constriction's: constriction's vectorised calls take one model
per call (or per symbol, built in Python), so adaptive coding needs a Python loop over runs of
symbols, which is where version 3 spends its time and why it holds the GIL.  An LZMA-style
binary range coder with adaptive probabilities is a few dozen lines, compiles with numba, and
adapts after every bit (which also codes smaller than adapting after every run).

Version 6 (:data:`PARENT_VERSION`) adds one context term: a detail value's zero flag and
bit-length contexts also look at the parent band (the same orientation and channel, one level
coarser, at ``(i // 2, j // 2)``), which lies in one block of the previous chunk, the block's
*parent block*.  A block then decodes from its own bytes and its parent block's values: the
decoder decodes a chunk's parent chunk first, a region decodes the parent blocks of the blocks
it needs, and a damaged block takes its descendants with it (:func:`parent_blocks`).

Version 7 (:data:`ORIENT_VERSION`) is version 6 whose ``cH`` and ``cV`` zero flags also have
models under a *directional* neighbour sum (along the band's rows for ``cH``, its columns for
``cV``, as EBCOT's contexts are): both models learn from every flag, and each flag is coded
under the one that would have cost less so far in that plane of the block, which the decoder
finds the same way (no side information).  Its blocks depend on their parent blocks as
version 6's do.

Version 8 (:data:`PRIOR_VERSION`) is version 7 whose blocks start from models trained per
level class (the finest level, the next one, the coarser ones and the approximation:
:mod:`wavecore._blockpriors`) instead of version 7's one hand-made start.

The bit-level specification is in ``docs/bundle-format.md`` (context coder versions 4, 6, 7
and 8).
"""

from __future__ import annotations

import binascii
import functools
import itertools
import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from . import _blockkernels as kernels
from . import _blocktables as tables
from . import _kernels as sample_kernels
from .errors import BundleError
from .transform import run_rows, run_slices
from .varints import encode_varint

__all__ = [
    "BLOCK_SIZE",
    "BLOCK_SIZES",
    "ORIENT_VERSION",
    "PARENT_VERSION",
    "PARENT_VERSIONS",
    "PRIOR_VERSION",
    "CodedBlocks",
    "CodedChunk",
    "KnownBlocks",
    "add_block_checks",
    "band_counts",
    "block_counts",
    "block_lengths",
    "block_table",
    "code_blocks",
    "decode_block_windows",
    "decode_blocks",
    "encode_blocks",
    "fill_stand_ins",
    "needed_blocks",
    "parent_blocks",
    "strip_block_checks",
]

#: The block side: 128 × 128 positions per band.  Each block learns its statistics afresh,
#: so small blocks cost bits: against version 3 on scikit-image's pictures, 32 × 32 blocks
#: wrote 3.4 % more, 64 × 64 0.5 % less (up to 1.5 % more at low rates), 128 × 128 1.4 % less
#: (see ``docs/bundle-format.md``).
BLOCK_SIZE = 128
#: The sides a reader accepts.
BLOCK_SIZES = (16, 32, 64, 128, 256)
#: The context coder's version whose detail contexts look at the parent band (version 4's do
#: not; version 5 is the lossless coder, :mod:`wavecore.losslesscoder`).
PARENT_VERSION = 6
#: Version 6 plus the directional zero-flag models of ``cH`` and ``cV``.
ORIENT_VERSION = 7
#: Version 7 whose blocks start from trained models of their level class.
PRIOR_VERSION = 8
#: The versions whose blocks read their parent blocks' values.
PARENT_VERSIONS = (PARENT_VERSION, ORIENT_VERSION, PRIOR_VERSION)
#: Runs of blocks per encode or decode, each its own task for the thread pool: blocks cost
#: very unequal time (dense coarse blocks, nearly empty fine ones), so many small tasks handed
#: to whichever thread is free keep both cores busy to the end (a few large tasks can leave
#: one core waiting for the other).
_SPANS = 64
#: The fewest coefficients per run of blocks worth a task of its own.  Coding costs some 40 to
#: 80 ns a coefficient, dozens of times a transform step, so much smaller jobs than the
#: transform's pay for the pool: a 512 × 512 grey picture (16 blocks a level) is split over
#: the threads too, into 16 runs (a task costs the pool some 10 µs: 64 empty tasks took
#: 0.6 ms of CPU, 16 took 0.2 ms).  How the blocks are grouped into runs changes no byte:
#: each block is coded on its own.
_SPAN_MIN_VALUES = 16384


def _span_count(values: int) -> int:
    """How many runs of blocks to cut ``values`` coefficients into (1 keeps it serial)."""
    return int(min(_SPANS, max(1, values // _SPAN_MIN_VALUES)))


def _plane_dims(band_shape: tuple[int, ...], two_d: bool) -> tuple[int, int, int]:
    """``(rows, cols, channels)`` of a band; 1-D bands are one row of samples per channel."""
    if not band_shape:
        return 1, 1, 1
    if two_d and len(band_shape) >= 2:
        return int(band_shape[0]), int(band_shape[1]), int(math.prod(band_shape[2:]))
    return 1, int(band_shape[0]), int(math.prod(band_shape[1:]))


_LayoutKey = tuple[tuple[tuple[int, ...], ...], ...]


def _layout_key(layout: Sequence[Sequence[Sequence[int]]]) -> _LayoutKey:
    """A layout as nested tuples of ints (hashable: the key of the cached tables)."""
    return tuple(tuple(tuple(int(n) for n in shape) for shape in shapes) for shapes in layout)


def _structure(
    layout: Sequence[Sequence[Sequence[int]]], two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray, list[int], int]:
    """The plane and block tables of a layout, the number of blocks per chunk, the total size.

    Planes are listed level by level, channel by channel, band by band (the order of ``flat``
    and of coding inside a block); blocks level by level, in rows of blocks.  The tables are
    cached per layout (building them cost some 1 ms of Python per encode or decode of a
    512 × 512 picture, a tenth of its decode) and shared: callers only read them.
    """
    planes, blocks, per_chunk, total, _ = _tables(layout, two_d, block)
    return planes, blocks, list(per_chunk), total


def _structure_sizes(
    layout: Sequence[Sequence[Sequence[int]]], two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray, list[int], int, np.ndarray]:
    """:func:`_structure` and the coefficients of every block (:func:`_block_sizes`), cached."""
    planes, blocks, per_chunk, total, sizes = _tables(layout, two_d, block)
    return planes, blocks, list(per_chunk), total, sizes


#: The largest tables kept in the cache (bytes of the plane and block tables of one layout):
#: a picture's are kilobytes, but a crafted header declaring a short curve of millions of
#: dimensions (a plane each) made hundreds of megabytes, which the cache kept after the decode
#: failed (370 MB for 34 × 1.5 M; 32 such layouts could pin tens of gigabytes).
_CACHED_TABLE_BYTES = 4 << 20


def _table_bytes(layout: _LayoutKey, two_d: bool, block: int) -> int:
    """What :func:`_cached_structure` would keep for ``layout``, from the shapes alone."""
    block_rows, block_cols = (block, block) if two_d else (1, block * block)
    planes = blocks = 0
    for band_shapes in layout:
        dims = [_plane_dims(shape, two_d) for shape in band_shapes]
        planes += sum(d[2] for d in dims)
        height = max((d[0] for d in dims), default=0)
        width = max((d[1] for d in dims), default=0)
        blocks += -(-height // block_rows) * -(-width // block_cols)
    return 8 * (kernels.PLANE_FIELDS * planes + (kernels.BLOCK_FIELDS + 1) * blocks)


def _tables(
    layout: Sequence[Sequence[Sequence[int]]], two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray, tuple[int, ...], int, np.ndarray]:
    """:func:`_cached_structure`, through the cache only while its tables are small."""
    return _while_small(_cached_structure, _layout_key(layout), two_d, block)


def _while_small(cached: Any, layout: _LayoutKey, two_d: bool, block: int) -> Any:
    """``cached(layout, two_d, block)`` (an ``lru_cache``'d function of the tables), through
    its cache only while the layout's tables are small: large ones would pin their memory."""
    if _table_bytes(layout, two_d, block) > _CACHED_TABLE_BYTES:
        return cached.__wrapped__(layout, two_d, block)
    return cached(layout, two_d, block)


@functools.lru_cache(maxsize=32)
def _cached_structure(
    layout: _LayoutKey, two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray, tuple[int, ...], int, np.ndarray]:
    planes, blocks, per_chunk, total = _build_structure(layout, two_d, block)
    return planes, blocks, tuple(per_chunk), total, _block_sizes(planes, blocks)


def _build_structure(
    layout: _LayoutKey, two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray, list[int], int]:
    plane_tables: list[np.ndarray] = []
    blocks: list[np.ndarray] = []
    per_chunk: list[int] = []
    offset = 0
    first = 0
    block_rows, block_cols = (block, block) if two_d else (1, block * block)
    for index, band_shapes in enumerate(layout):
        dims = np.array(
            [_plane_dims(shape, two_d) for shape in band_shapes], dtype=np.int64
        ).reshape(-1, 3)
        table, offset = _chunk_planes(dims, index > 0, first, offset)
        plane_tables.append(table)
        height = int(dims[:, 0].max(initial=0))
        width = int(dims[:, 1].max(initial=0))
        grid_rows = -(-height // block_rows)
        grid_cols = -(-width // block_cols)
        rows0, cols0 = np.meshgrid(
            np.arange(grid_rows) * block_rows, np.arange(grid_cols) * block_cols, indexing="ij"
        )
        blocks_table = np.empty((grid_rows * grid_cols, kernels.BLOCK_FIELDS), dtype=np.int64)
        blocks_table[:, kernels.B_PLANE_LO] = first
        blocks_table[:, kernels.B_PLANE_HI] = first + len(table)
        blocks_table[:, kernels.B_ROW0] = rows0.ravel()
        blocks_table[:, kernels.B_COL0] = cols0.ravel()
        blocks_table[:, kernels.B_ROW1] = rows0.ravel() + block_rows
        blocks_table[:, kernels.B_COL1] = cols0.ravel() + block_cols
        # Version 8's level class: 0 for the finest level (the last chunk), 1 the next, 2 the rest.
        blocks_table[:, kernels.B_LEVEL] = min(len(layout) - 1 - index, kernels.LEVEL_CLASSES - 1)
        blocks.append(blocks_table)
        per_chunk.append(len(blocks_table))
        first += len(table)
    plane_table = np.concatenate(
        [np.zeros((0, kernels.PLANE_FIELDS), dtype=np.int64), *plane_tables]
    )
    return plane_table, np.concatenate(blocks), per_chunk, offset


def _chunk_planes(
    dims: np.ndarray, detail: bool, first: int, offset: int
) -> tuple[np.ndarray, int]:
    """The plane rows of one chunk whose bands are ``dims`` (rows, cols, channels each), its
    first plane numbered ``first`` and its values starting at ``offset``: channel by
    channel, band by band, a band missing from the channels past its count.  Built with
    array operations: a volume of thin slices has a plane per slice and band (millions)."""
    bands = len(dims)
    channels = int(dims[:, 2].max(initial=0))
    channel = np.repeat(np.arange(channels, dtype=np.int64), bands)
    k = np.tile(np.arange(bands, dtype=np.int64), channels)
    kept = channel < dims[k, 2]
    channel, k = channel[kept], k[kept]
    me = first + np.arange(len(k), dtype=np.int64)
    sizes = dims[k, 0] * dims[k, 1]
    table = np.empty((len(k), kernels.PLANE_FIELDS), dtype=np.int64)
    table[:, kernels.P_OFFSET] = offset + np.cumsum(sizes) - sizes
    table[:, kernels.P_ROWS] = dims[k, 0]
    table[:, kernels.P_COLS] = dims[k, 1]
    table[:, kernels.P_KIND] = 1 if detail else 0
    # A detail plane's first two siblings: the planes of bands 0 and 1 of its channel.
    table[:, kernels.P_SIB1] = np.where(detail & (k >= 1), me - k, -1)
    table[:, kernels.P_SIB2] = np.where(detail & (k >= 2), me - k + 1, -1)
    table[:, kernels.P_LUMA] = np.where(detail & (channel > 0), first + k, -1)
    table[:, kernels.P_ORIENT] = np.minimum(k, 2)
    return table, offset + int(sizes.sum())


def _parents(
    layout: Sequence[Sequence[Sequence[int]]], two_d: bool, block: int, version: int
) -> np.ndarray:
    """Each plane's parent plane for the coder's ``version`` (-1: none; every plane but of
    versions 6, 7 and 8): see :func:`_parent_tables`."""
    if version not in PARENT_VERSIONS:
        return _no_parents(_structure(layout, two_d, block)[0].shape[0])
    return _parent_tables(_layout_key(layout), two_d, block)[0]


def _oriented(version: int) -> int:
    """The kernels' ``oriented`` argument: 1 for version 7, 2 for version 8, else 0."""
    return {ORIENT_VERSION: 1, PRIOR_VERSION: 2}.get(version, 0)


@functools.lru_cache(maxsize=8)
def _no_parents(count: int) -> np.ndarray:
    # Shared, read by the kernels only (a read-only array would compile them again).
    return np.full(count, -1, dtype=np.int64)


def parent_blocks(layout: Sequence[Sequence[Sequence[int]]], two_d: bool, block: int) -> np.ndarray:
    """Each block's parent block under versions 6 to 8 (-1: none), in :func:`needed_blocks`' order.

    The parent block is the block of the previous chunk that holds every parent value of the
    block's detail values; it comes earlier in the order, so a pass from the last block to the
    first can hand a block's needs on to its ancestors, and one from the first to the last a
    parent's loss on to its descendants.
    """
    return _parent_tables(_layout_key(layout), two_d, block)[1]


def _parent_tables(layout: _LayoutKey, two_d: bool, block: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_parents` and :func:`parent_blocks` of versions 6 to 8, cached with the tables."""
    return _while_small(_cached_parent_tables, layout, two_d, block)


@functools.lru_cache(maxsize=32)
def _cached_parent_tables(
    layout: _LayoutKey, two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray]:
    # A detail plane's parent is the plane at the same place (channel, then band) of the
    # previous chunk, when that chunk is a detail chunk of the same bands and channels: the
    # same orientation and channel one level coarser.  Chunk 1 (the coarsest details) has
    # none: chunk 0 is the approximation.
    planes, blocks, per_chunk, _ = _structure(layout, two_d, block)
    block_rows, block_cols = (block, block) if two_d else (1, block * block)
    parents = np.full(len(planes), -1, dtype=np.int64)
    parent_of = np.full(len(blocks), -1, dtype=np.int64)
    first_plane, first_block = 0, 0
    previous: tuple[list[int], int, int, int, int] | None = None
    for index, band_shapes in enumerate(layout):
        dims = [_plane_dims(shape, two_d) for shape in band_shapes]
        counts = [d[2] for d in dims]
        count = sum(counts)
        height = max((d[0] for d in dims), default=0)
        width = max((d[1] for d in dims), default=0)
        grid_rows, grid_cols = -(-height // block_rows), -(-width // block_cols)
        if index >= 2 and previous is not None and previous[0] == counts:
            _, plane0, block0, rows0, cols0 = previous
            parents[first_plane : first_plane + count] = np.arange(plane0, plane0 + count)
            table = blocks[first_block : first_block + per_chunk[index]]
            prow = (table[:, kernels.B_ROW0] // 2) // block_rows
            pcol = (table[:, kernels.B_COL0] // 2) // block_cols
            inside = (prow < rows0) & (pcol < cols0)
            parent_of[first_block : first_block + per_chunk[index]] = np.where(
                inside, block0 + prow * cols0 + pcol, -1
            )
        previous = (counts, first_plane, first_block, grid_rows, grid_cols) if index else None
        first_plane += count
        first_block += per_chunk[index]
    return parents, parent_of


def _block_sizes(planes: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """Coefficients per block (for sharing the work out evenly): one compiled pass."""
    return tables.block_sizes(planes, blocks)


def _cuts(weights: np.ndarray, spans: int) -> np.ndarray:
    """``spans + 1`` block indices that cut the blocks into runs of about equal weight."""
    cumulative = np.concatenate([[0], np.cumsum(weights + 1)])
    targets = np.linspace(0, cumulative[-1], spans + 1)
    cuts = np.searchsorted(cumulative, targets, side="left")
    cuts[0], cuts[-1] = 0, len(weights)
    return np.maximum.accumulate(cuts)


def encode_blocks(
    entries: list[list[np.ndarray]],
    two_d: bool,
    block: int = BLOCK_SIZE,
    version: int = 4,
    known: KnownBlocks | None = None,
) -> list[bytes]:
    """Code integer bands (``[[cA], [level L bands], ...]``) into one chunk per entry, with
    the context coder's ``version`` (4, :data:`PARENT_VERSION` or :data:`ORIENT_VERSION`).

    ``known``: blocks of these very bands coded already with the same ``version``
    (:func:`code_blocks`: the bpp search's sample at the step it settled on), whose bytes are
    taken as they are (blocks of another version are ignored).
    """
    layout = [[band.shape for band in bands] for bands in entries]
    parents = _parents(layout, two_d, block, version)
    if known is not None and known.indices.size and known.version == version:
        return _encode_blocks_knowing(entries, two_d, block, layout, parents, known, version)
    planes, blocks, per_chunk, total, sizes = _structure_sizes(layout, two_d, block)
    flat = np.empty(total, dtype=np.int32)
    _copy_planes(*_copies_into(flat, planes, entries, two_d), int(total))
    spans = _span_count(int(total))
    cuts = _cuts(sizes, spans)
    results: list[Any] = [None] * spans
    oriented = _oriented(version)

    def run(lo: int, hi: int) -> None:
        for span in range(lo, hi):
            results[span] = kernels.encode_span(
                flat, planes, parents, oriented, blocks, cuts[span], cuts[span + 1]
            )

    run_rows(run, spans, pieces=spans)
    payload = np.concatenate([r[0] for r in results])
    lengths = np.concatenate([r[1] for r in results])
    return _assembled_chunks(entries, per_chunk, payload, lengths)


def _assembled_chunks(
    entries: list[list[np.ndarray]], per_chunk: list[int], payload: np.ndarray, lengths: np.ndarray
) -> list[bytes]:
    """The chunks of :func:`encode_blocks` from every block's bytes (``payload``, in block
    order) and lengths."""
    ends = np.cumsum(lengths)
    # What bundle format 3.0 stores for a region decode: the counts of the detail chunks of
    # several blocks, all in one parallel region.
    counted = [index > 0 and count > 1 for index, count in enumerate(per_chunk)]
    wanted = [band for bands, c in zip(entries, counted, strict=True) if c for band in bands]
    counts = iter(_band_counts_of(wanted))
    chunks: list[bytes] = []
    first = 0
    for bands, count, has_counts in zip(entries, per_chunk, counted, strict=True):
        last = first + count
        start = int(ends[first - 1]) if first else 0
        stop = int(ends[last - 1]) if count else start
        table = kernels.write_varints(lengths[first:last])
        chunk = CodedChunk(table.tobytes() + payload[start:stop].tobytes())
        if has_counts:
            chunk.band_counts = [next(counts) for _ in bands]
        chunks.append(chunk)
        first = last
    return chunks


class KnownBlocks(NamedTuple):
    """Blocks coded already: their indices (ascending, in :func:`needed_blocks`' order), their
    bytes one after another, each one's length, and the coder's version they were coded
    with."""

    indices: np.ndarray
    payload: np.ndarray
    lengths: np.ndarray
    version: int


def code_blocks(
    entries: list[list[np.ndarray]], two_d: bool, block: int, indices: np.ndarray, version: int = 4
) -> KnownBlocks:
    """Blocks ``indices`` of ``entries`` coded alone with the coder's ``version``: exactly the
    bytes :func:`encode_blocks` writes for them."""
    layout = [[band.shape for band in bands] for bands in entries]
    planes, blocks, _, _ = _structure(layout, two_d, block)
    indices = np.asarray(indices, dtype=np.int64)
    parents = _parents(layout, two_d, block, version)
    payload, lengths = _code_some(entries, two_d, planes, blocks, indices, parents, version)
    return KnownBlocks(indices, payload, lengths, version)


def _encode_blocks_knowing(
    entries: list[list[np.ndarray]],
    two_d: bool,
    block: int,
    layout: list[list[tuple[int, ...]]],
    parents: np.ndarray,
    known: KnownBlocks,
    version: int,
) -> list[bytes]:
    """:func:`encode_blocks` where ``known`` blocks are coded already: only the others are."""
    planes, blocks, per_chunk, _ = _structure(layout, two_d, block)
    rest = np.setdiff1d(np.arange(len(blocks), dtype=np.int64), known.indices)
    parts: list[np.ndarray] = [np.zeros(0, dtype=np.uint8)] * len(blocks)
    lengths = np.zeros(len(blocks), dtype=np.int64)
    coded = [known]
    if rest.size:
        payload, sizes = _code_some(entries, two_d, planes, blocks, rest, parents, version)
        coded.append(KnownBlocks(rest, payload, sizes, known.version))
    for some in coded:
        ends = np.cumsum(some.lengths)
        for k, index in enumerate(some.indices.tolist()):
            parts[index] = some.payload[int(ends[k] - some.lengths[k]) : int(ends[k])]
            lengths[index] = some.lengths[k]
    return _assembled_chunks(entries, per_chunk, np.concatenate(parts), lengths)


class CodedChunk(bytes):
    """A chunk of :func:`encode_blocks`: bytes, plus ``band_counts`` for detail chunks of
    several blocks (see :func:`band_counts`), which bundle format 3.0 stores beside the
    blocks; plain bytes work too (the counts are then found by decoding the chunk)."""

    band_counts: list[tuple[int, int]] | None = None


def band_counts(band: np.ndarray) -> tuple[int, int]:
    """``(ones, more)``: how many values of a band have magnitude 1, and how many 2 or more.

    The dead-zone dequantizer places every nonzero value in its bin from these two counts
    (:func:`wavecore.quantize.reconstruction_offset`), so a decode that reads only some
    blocks of a band needs them for the whole band.
    """
    # The dequantizer's own count (compiled passes), so the two can never disagree; in slices
    # over the threads (integer counts add up exactly), since the encoder counts every band.
    flat = np.ravel(band)
    parts: list[tuple[int, int]] = []
    run_rows(
        lambda lo, hi: parts.append(sample_kernels.count_ones_and_more(flat[lo:hi])),
        flat.size,
        flat.size,
    )
    return sum(int(p[0]) for p in parts), sum(int(p[1]) for p in parts)


def _band_counts_of(bands: list[np.ndarray]) -> list[tuple[int, int]]:
    """:func:`band_counts` of each of ``bands``, in one parallel region for all of them (one
    region a band spent more on handing out its slices than on counting a small band)."""
    flats = [np.ravel(band) for band in bands]
    parts: list[tuple[int, tuple[int, int]]] = []

    def count(item: int, lo: int, hi: int) -> None:
        parts.append((item, sample_kernels.count_ones_and_more(flats[item][lo:hi])))

    run_slices([flat.size for flat in flats], count)
    totals = [[0, 0] for _ in flats]
    for item, (ones, more) in parts:
        totals[item][0] += int(ones)
        totals[item][1] += int(more)
    return [(ones, more) for ones, more in totals]


class CodedBlocks:
    """The chunks of :func:`encode_blocks`, held block by block, so that rate control can code
    some blocks again (say, with details removed) without coding the others.

    ``CodedBlocks(chunks, layout, two_d, block, version)`` splits chunks made by
    :func:`encode_blocks` (their tables of block lengths say where each block's bytes are);
    :meth:`recode` codes the given blocks again from new integer bands, by the same compiled
    coder, so a block's bytes are exactly what :func:`encode_blocks` writes for its values
    (under versions 6 to 8 with their child blocks, whose contexts read them); :meth:`chunks`
    puts the chunks back together.  ``regions[b]`` is block ``b``'s ``(entry, row0, col0,
    row1, col1)``: the positions it holds in every band (and channel) of layout entry
    ``entry``.
    """

    def __init__(
        self,
        chunks: list[bytes],
        layout: list[list[tuple[int, ...]]],
        two_d: bool,
        block: int,
        version: int = 4,
    ) -> None:
        self.layout, self.two_d, self.block, self.version = layout, two_d, block, version
        self._planes, self._blocks, self._per_chunk, self._total = _structure(layout, two_d, block)
        self._parents = _parents(layout, two_d, block, version)
        self.payloads: list[bytes] = []
        # Bundle format 3.0 stores each detail band's counts beside its blocks (see CodedChunk).
        self.band_counts = [getattr(chunk, "band_counts", None) for chunk in chunks]
        for chunk, count in zip(chunks, self._per_chunk, strict=True):
            data = np.frombuffer(chunk, dtype=np.uint8)
            lengths, read = kernels.read_varints(data, count, data.size + 1)
            if read < 0 or read + int(lengths.sum()) != data.size:
                msg = f"a chunk of {data.size} bytes does not hold its {count} blocks"
                raise BundleError(msg)
            ends = read + np.cumsum(lengths)
            starts = ends - lengths
            self.payloads.extend(chunk[int(a) : int(b)] for a, b in zip(starts, ends, strict=True))
        entry_of = np.repeat(np.arange(len(self._per_chunk)), self._per_chunk)
        self.regions = np.column_stack(
            [
                entry_of,
                self._blocks[:, kernels.B_ROW0],
                self._blocks[:, kernels.B_COL0],
                self._blocks[:, kernels.B_ROW1],
                self._blocks[:, kernels.B_COL1],
            ]
        )

    def recode(self, entries: list[list[np.ndarray]], indices: np.ndarray) -> None:
        """Code blocks ``indices`` again from ``entries`` (integer bands of the same layout);
        under versions 6 to 8 their child blocks too, whose contexts read their values."""
        indices = np.asarray(indices, dtype=np.int64)
        if indices.size == 0:
            return
        if self.version in PARENT_VERSIONS:
            parent_of = parent_blocks(self.layout, self.two_d, self.block)
            children = np.flatnonzero(np.isin(parent_of, indices))
            indices = np.union1d(indices, children)
        payload, lengths = _code_some(
            entries, self.two_d, self._planes, self._blocks, indices, self._parents, self.version
        )
        ends = np.cumsum(lengths)
        for k, index in enumerate(indices):
            start = int(ends[k - 1]) if k else 0
            self.payloads[int(index)] = payload[start : int(ends[k])].tobytes()
        recount = [entry for entry in range(len(entries)) if self.band_counts[entry] is not None]
        counts = iter(_band_counts_of([band for entry in recount for band in entries[entry]]))
        for entry in recount:
            self.band_counts[entry] = [next(counts) for _ in entries[entry]]

    def chunks(self) -> list[bytes]:
        """The chunks, as :func:`encode_blocks` writes them for the blocks' current values."""
        out: list[bytes] = []
        first = 0
        for count, counts in zip(self._per_chunk, self.band_counts, strict=True):
            parts = self.payloads[first : first + count]
            lengths = np.array([len(p) for p in parts], dtype=np.int64)
            chunk = CodedChunk(kernels.write_varints(lengths).tobytes() + b"".join(parts))
            chunk.band_counts = counts
            out.append(chunk)
            first += count
        return out

    def lengths(self) -> np.ndarray:
        """Each block's coded bytes."""
        return np.array([len(p) for p in self.payloads], dtype=np.int64)


def _code_some(
    entries: list[list[np.ndarray]],
    two_d: bool,
    planes: np.ndarray,
    blocks: np.ndarray,
    indices: np.ndarray,
    parents: np.ndarray,
    version: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Blocks ``indices`` of the tables coded from ``entries`` with the coder's ``version``
    (whose parent planes are ``parents``): their bytes and lengths.

    Only the chosen blocks' regions are copied, each into planes of its own (a block's coding
    reads nothing outside it, and depends on its planes' sizes only where they cut it short,
    which the compact planes keep): the bpp search's sample codes a quarter of a picture's
    blocks, and copying every plane for it cost as much as the coding of the sample.
    """
    sub_planes, sub_blocks, pieces, total = _compact_tables(planes, blocks, indices)
    sub_parents, sub_planes, pieces, total = _with_parent_pieces(
        sub_planes, pieces, total, planes, parents
    )
    flat = np.empty(total, dtype=np.int32)
    views = _plane_views(entries, two_d)
    sources, targets = [], []
    for (p, r0, r1, c0, c1), offset in zip(
        pieces.tolist(), sub_planes[:, kernels.P_OFFSET].tolist(), strict=True
    ):
        if r1 > r0 and c1 > c0:
            sources.append(views[p][r0:r1, c0:c1])
            targets.append(flat[offset : offset + (r1 - r0) * (c1 - c0)].reshape(r1 - r0, c1 - c0))
    _copy_planes(sources, targets, total)
    sizes = _block_sizes(sub_planes, sub_blocks)
    spans = _span_count(int(sizes.sum()))
    cuts = _cuts(sizes, spans)
    results: list[Any] = [None] * spans
    oriented = _oriented(version)

    def run(lo: int, hi: int) -> None:
        for span in range(lo, hi):
            results[span] = kernels.encode_span(
                flat, sub_planes, sub_parents, oriented, sub_blocks, cuts[span], cuts[span + 1]
            )

    run_rows(run, spans, pieces=spans)
    return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])


def _with_parent_pieces(
    sub_planes: np.ndarray, pieces: np.ndarray, total: int, planes: np.ndarray, parents: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Compact tables (:func:`_compact_tables`) with, for each compact plane whose plane has a
    parent (versions 6 to 8), a compact plane of the parent's values it reads, appended.

    A block starts at even rows and columns, so its position ``(i, j)`` reads the parent's
    ``(i // 2, j // 2)`` from a compact parent plane anchored at half the block's corner, cut
    where the parent plane ends, as in the whole plane.  Returns the compact parents (-1:
    none), the tables and the total size.
    """
    count = len(sub_planes)
    sub_parents = np.full(count, -1, dtype=np.int64)
    source = pieces[:, 0]
    has = np.flatnonzero(
        (parents[source] >= 0) & (pieces[:, 2] > pieces[:, 1]) & (pieces[:, 4] > pieces[:, 3])
    )
    if not has.size:
        return sub_parents, sub_planes, pieces, total
    q = parents[source[has]]
    r0, c0 = pieces[has, 1] // 2, pieces[has, 3] // 2
    r1 = np.minimum((pieces[has, 2] + 1) // 2, planes[q, kernels.P_ROWS])
    c1 = np.minimum((pieces[has, 4] + 1) // 2, planes[q, kernels.P_COLS])
    r1, c1 = np.maximum(r1, r0), np.maximum(c1, c0)
    sizes = (r1 - r0) * (c1 - c0)
    extra = planes[q].copy()
    extra[:, kernels.P_OFFSET] = total + np.concatenate([[0], np.cumsum(sizes)[:-1]])
    extra[:, kernels.P_ROWS] = r1 - r0
    extra[:, kernels.P_COLS] = c1 - c0
    extra[:, [kernels.P_SIB1, kernels.P_SIB2, kernels.P_LUMA]] = -1  # never coded
    sub_parents[has] = count + np.arange(has.size)
    sub_parents = np.concatenate([sub_parents, np.full(has.size, -1, dtype=np.int64)])
    extra_pieces = np.column_stack([q, r0, r1, c0, c1])
    return (
        sub_parents,
        np.concatenate([sub_planes, extra]),
        np.concatenate([pieces, extra_pieces]),
        total + int(sizes.sum()),
    )


def _compact_tables(
    planes: np.ndarray, blocks: np.ndarray, indices: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Plane and block tables that hold only blocks ``indices``, each with planes of its own:
    the region of every plane of its level that the block covers, cut where the plane ends,
    and the block at their corner.  Also where each compact plane comes from (rows of
    ``(plane, row0, row1, col0, col1)`` of the original tables) and their total size.  One
    compiled pass (``_blocktables.compact_tables``), not a Python loop per block and plane."""
    sub_planes, sub_blocks, pieces, total = tables.compact_tables(
        planes, blocks, np.asarray(indices, dtype=np.int64)
    )
    return sub_planes, sub_blocks, pieces, int(total)


def block_lengths(
    entries: list[list[np.ndarray]],
    two_d: bool,
    block: int,
    indices: np.ndarray,
    version: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """The coded bytes of blocks ``indices`` alone (what :func:`encode_blocks` would write for
    them with the coder's ``version``), and every block's region ``(entry, row0, col0, row1,
    col1)``: for rate control to sample the coder on a few blocks."""
    layout = [[band.shape for band in bands] for bands in entries]
    planes, blocks, per_chunk, _ = _structure(layout, two_d, block)
    entry_of = np.repeat(np.arange(len(per_chunk)), per_chunk)
    regions = np.column_stack(
        [
            entry_of,
            blocks[:, kernels.B_ROW0],
            blocks[:, kernels.B_COL0],
            blocks[:, kernels.B_ROW1],
            blocks[:, kernels.B_COL1],
        ]
    )
    indices = np.asarray(indices, dtype=np.int64)
    if indices.size == 0:
        return np.zeros(0, dtype=np.int64), regions
    parents = _parents(layout, two_d, block, version)
    return _code_some(entries, two_d, planes, blocks, indices, parents, version)[1], regions


#: A chunk whose bands have at least this many channels each (a volume's slices) is copied
#: a band at a time, every channel at once: a volume of thin slices has a plane per slice and
#: band, and a copy per plane cost some 10 µs of Python each.  Pictures (1 or 3 channels) keep
#: the copies per plane, which the threads share out (see :func:`_copy_planes`).
_MANY_CHANNELS = 16


def _many_channels(dims: Sequence[tuple[int, int, int]]) -> bool:
    """Whether a chunk of bands ``dims`` is copied a band at a time."""
    return bool(dims) and all(d[2] == dims[0][2] for d in dims) and dims[0][2] >= _MANY_CHANNELS


def _channels_first(
    flat: np.ndarray, start: int, dims: Sequence[tuple[int, int, int]]
) -> list[np.ndarray]:
    """Each band's planes in ``flat`` as one ``(channels, rows, cols)`` view: a chunk whose
    bands have equal channel counts holds them channel by channel, band by band from
    ``start``."""
    channels = dims[0][2]
    stride = sum(rows * cols for rows, cols, _ in dims)
    chunk = flat[start : start + channels * stride].reshape(channels, stride)
    out, offset = [], 0
    for rows, cols, _ in dims:
        out.append(chunk[:, offset : offset + rows * cols].reshape(channels, rows, cols))
        offset += rows * cols
    return out


def _copies_into(
    flat: np.ndarray, planes: np.ndarray, entries: list[list[np.ndarray]], two_d: bool
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Sources and targets in ``flat`` (laid out by ``planes``) for :func:`_copy_planes`:
    per plane, or per band where a chunk has many channels."""
    sources: list[np.ndarray] = []
    targets: list[np.ndarray] = []
    p = 0
    for bands in entries:
        views = _band_views(bands, two_d)
        dims = [view.shape for view in views]
        if _many_channels(dims):
            start = int(planes[p, kernels.P_OFFSET])
            sources.extend(view.transpose(2, 0, 1) for view in views)
            targets.extend(_channels_first(flat, start, dims))
            p += dims[0][2] * len(dims)
            continue
        for plane in _planes_of(views):
            start = int(planes[p, kernels.P_OFFSET])
            sources.append(plane)
            targets.append(flat[start : start + plane.size].reshape(plane.shape))
            p += 1
    return sources, targets


def _band_views(bands: list[np.ndarray], two_d: bool) -> list[np.ndarray]:
    """Each band as ``int32`` ``(rows, cols, channels)`` (see :func:`_plane_dims`)."""
    return [
        np.asarray(band, dtype=np.int32).reshape(_plane_dims(band.shape, two_d)) for band in bands
    ]


def _planes_of(views: list[np.ndarray]) -> list[np.ndarray]:
    """The planes of one entry's :func:`_band_views`, channel by channel, band by band."""
    channels = max((view.shape[2] for view in views), default=0)
    return [view[:, :, c] for c in range(channels) for view in views if c < view.shape[2]]


def _plane_views(entries: list[list[np.ndarray]], two_d: bool) -> list[np.ndarray]:
    """The planes of every entry in ``_structure``'s order."""
    return [plane for bands in entries for plane in _planes_of(_band_views(bands, two_d))]


def decode_blocks(
    chunks: list[bytes],
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    block: int,
    *,
    skip: np.ndarray | None = None,
    version: int = 4,
    chunks_total: int | None = None,
) -> list[list[np.ndarray]]:
    """Decode the chunks of :func:`encode_blocks` into ``int32`` bands of the ``layout``'s shapes.

    Parameters
    ----------
    chunks, layout, two_d, block
        The chunks (a prefix of the bundle's), the band shapes of each, and the coder's
        ``two_d`` and ``block`` parameters.
    skip : numpy.ndarray of bool, optional
        One flag per block of these chunks (in :func:`needed_blocks`' order): a flagged block is
        not decoded, its coefficients are zero (a region decode's unneeded blocks, or the
        damaged blocks of ``decode(..., damaged="zero")``).  Under versions 6 to 8 the caller
        skips no parent block of a block it decodes (see :func:`parent_blocks`).
    version : int
        The context coder's version (4, :data:`PARENT_VERSION`, :data:`ORIENT_VERSION` or
        :data:`PRIOR_VERSION`).
    chunks_total : int, optional
        The number of chunks of the whole layout the encoder coded, when ``layout`` is only
        its first chunks (a coarse level's decode): version 8's blocks start from the models
        of their level counted from the *finest* chunk coded.  Default: ``len(layout)``.

    Raises
    ------
    BundleError
        For a block table that does not add up to its chunk, or a block that decodes to
        something impossible.
    """
    flat, planes, total = _decode_flat(chunks, layout, two_d, block, skip, version, chunks_total)
    return _bands_out(flat, planes, layout, two_d, total)


def _level_classes(blocks: np.ndarray, per_chunk: Sequence[int], chunks_total: int) -> np.ndarray:
    """A copy of the block table whose level classes count from the finest of
    ``chunks_total`` chunks (the whole layout's), not of the ``len(per_chunk)`` given."""
    index = np.repeat(np.arange(len(per_chunk)), per_chunk)
    out = blocks.copy()
    out[:, kernels.B_LEVEL] = np.minimum(chunks_total - 1 - index, kernels.LEVEL_CLASSES - 1)
    return out


def _decode_flat(
    chunks: list[bytes],
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    block: int,
    skip: np.ndarray | None,
    version: int,
    chunks_total: int | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Every plane decoded into one flat ``int32`` array: ``(flat, plane table, size)``."""
    if block not in BLOCK_SIZES:
        msg = f"context coder block size {block!r} is not one of {BLOCK_SIZES}"
        raise BundleError(msg)
    planes, blocks, per_chunk, total, all_sizes = _structure_sizes(layout, two_d, block)
    if chunks_total is not None and chunks_total != len(per_chunk):
        blocks = _level_classes(blocks, per_chunk, chunks_total)
    per_chunk = per_chunk[: len(chunks)]
    parts, starts, lengths = [], [], []
    offset = 0
    for chunk, count in zip(chunks, per_chunk, strict=True):
        data = np.frombuffer(chunk, dtype=np.uint8)
        values, read = kernels.read_varints(data, count, data.size + 1)
        if read < 0 or read + int(values.sum()) != data.size:
            msg = (
                f"context-coded chunk of {data.size} bytes: its table of {count} block lengths "
                "does not add up to it"
            )
            raise BundleError(msg)
        parts.append(data)
        starts.append(
            offset + read + np.concatenate([[0], np.cumsum(values)[:-1]]).astype(np.int64)
        )
        lengths.append(values)
        offset += data.size
    data = np.concatenate(parts) if parts else np.zeros(0, dtype=np.uint8)
    block_starts = np.concatenate(starts).astype(np.int64)
    block_lengths = np.concatenate(lengths).astype(np.int64)
    if skip is not None:
        block_lengths = np.where(skip[: len(block_lengths)], 0, block_lengths)
    flat = np.zeros(total, dtype=np.int32)
    sizes = np.where(block_lengths > 0, all_sizes, 0)
    parents = _parents(layout, two_d, block, version)
    # Versions 6 and 7 read the previous chunk's values: one chunk after the other, each over
    # the threads (chunks 0 and 1 depend on none); version 4, every block at once.
    waves = [0, len(sizes)]
    oriented = _oriented(version)
    if version in PARENT_VERSIONS:
        ends = np.cumsum(per_chunk[: len(chunks)]).tolist()
        waves = [0, *ends[1:]] if len(ends) > 1 else [0, *ends]
    bad: list[int] = []
    for first, last in itertools.pairwise(waves):
        spans = _span_count(int(sizes[first:last].sum()))
        cuts = first + _cuts(sizes[first:last], spans)
        found = [0] * spans

        def run(lo: int, hi: int, cuts: np.ndarray = cuts, found: list[int] = found) -> None:
            for span in range(lo, hi):
                found[span] = kernels.decode_span(
                    data,
                    block_starts,
                    block_lengths,
                    planes,
                    parents,
                    oriented,
                    blocks,
                    flat,
                    cuts[span],
                    cuts[span + 1],
                )

        run_rows(run, spans, pieces=spans)
        bad.extend(found)
    if sum(bad):
        msg = f"{sum(bad)} code-block(s) of the context-coded chunks are corrupt"
        raise BundleError(msg)
    return flat, planes, int(total)


def _bands_out(
    flat: np.ndarray,
    planes: np.ndarray,
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    total: int,
    windows: Sequence[Sequence[tuple[int, int, int, int]]] | None = None,
) -> list[list[np.ndarray]]:
    """The bands (or the ``(row0, row1, col0, col1)`` windows of their planes) from ``flat``."""
    levels = []
    sources, targets = [], []
    p = 0
    for index, band_shapes in enumerate(layout):
        dims = [_plane_dims(shape, two_d) for shape in band_shapes]
        if windows is None and all(count == 1 for _, _, count in dims):
            # One plane per band, held whole and contiguous in ``flat``: the band is a view of
            # it (``flat`` is this decode's own), no copy.
            views = []
            for shape, (rows, cols, _) in zip(band_shapes, dims, strict=True):
                start = int(planes[p, kernels.P_OFFSET])
                views.append(flat[start : start + rows * cols].reshape(shape))
                p += 1
            levels.append(views)
            continue
        cuts = (
            windows[index]
            if windows is not None
            else [(0, rows, 0, cols) for rows, cols, _ in dims]
        )
        arrays = [
            np.empty((r1 - r0, c1 - c0, n), dtype=np.int32)
            for (r0, r1, c0, c1), (_, _, n) in zip(cuts, dims, strict=True)
        ]
        channels = max((d[2] for d in dims), default=0)
        if _many_channels(dims):
            start = int(planes[p, kernels.P_OFFSET])
            for view, (r0, r1, c0, c1), array in zip(
                _channels_first(flat, start, dims), cuts, arrays, strict=True
            ):
                sources.append(view[:, r0:r1, c0:c1])
                targets.append(array.transpose(2, 0, 1))
            p += channels * len(dims)
            channels = 0  # copied
        for channel, k in itertools.product(range(channels), range(len(dims))):
            rows, cols, count = dims[k]
            if channel >= count:
                continue
            start = planes[p, kernels.P_OFFSET]
            r0, r1, c0, c1 = cuts[k]
            plane = flat[start : start + rows * cols].reshape(rows, cols)
            sources.append(plane[r0:r1, c0:c1])
            targets.append(arrays[k][:, :, channel])
            p += 1
        levels.append(
            [
                a.reshape(_window_shape(shape, a.shape[:2], two_d))
                for a, shape in zip(arrays, band_shapes, strict=True)
            ]
        )
    _copy_planes(sources, targets, sum(a.size for a in targets))
    return levels


def _window_shape(shape: tuple[int, ...], window: tuple[int, ...], two_d: bool) -> tuple:
    """A band's shape with its plane's rows and columns those of a window of it."""
    if two_d and len(shape) >= 2:
        return (window[0], window[1], *shape[2:])
    return (window[1], *shape[1:])


def decode_block_windows(
    chunks: list[bytes],
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    block: int,
    skip: np.ndarray,
    windows: Sequence[Sequence[tuple[int, int, int, int]]],
    totals_for: Sequence[int] = (),
    version: int = 4,
    chunks_total: int | None = None,
) -> tuple[list[list[np.ndarray]], dict[int, list[tuple[int, int]]]]:
    """:func:`decode_blocks` for a region: only ``windows`` of each band, and no more.

    Parameters
    ----------
    chunks, layout, two_d, block, skip
        As for :func:`decode_blocks` (the skipped blocks are neither read nor touched).
    windows : sequence
        Per chunk, per band, ``(row0, row1, col0, col1)`` of its planes to return (1-D bands:
        rows ``(0, 1)``, the samples as columns).
    totals_for : sequence of int
        Chunks whose bands' :func:`band_counts` over the whole band are wanted too (the
        chunks that do not store them: they are decoded whole, or not at all).
    version, chunks_total : int
        As for :func:`decode_blocks`.

    Returns
    -------
    list, dict
        The windows, shaped like their bands but for the window's sizes, and the counts.
    """
    flat, planes, total = _decode_flat(chunks, layout, two_d, block, skip, version, chunks_total)
    totals: dict[int, list[tuple[int, int]]] = {}
    p = 0
    for index, band_shapes in enumerate(layout):
        dims = [_plane_dims(shape, two_d) for shape in band_shapes]
        if index not in totals_for:
            p += sum(d[2] for d in dims)
            continue
        channels = max((d[2] for d in dims), default=0)
        sums = [[0, 0] for _ in dims]
        for channel, k in itertools.product(range(channels), range(len(dims))):
            rows, cols, count = dims[k]
            if channel >= count:
                continue
            start = planes[p, kernels.P_OFFSET]
            ones, more = band_counts(flat[start : start + rows * cols])
            sums[k][0] += ones
            sums[k][1] += more
            p += 1
        totals[index] = [(ones, more) for ones, more in sums]
    return _bands_out(flat, planes, layout, two_d, total, windows), totals


#: Rows of planes per copy task: about this many values, so that the tasks balance.
_COPY_TASK = 1 << 16
#: At most this many pieces (runs of tasks) a copy is cut into for the threads.
_COPY_PIECES = 16


def _copy_planes(sources: list[np.ndarray], targets: list[np.ndarray], total: int) -> None:
    """``targets[k][...] = sources[k]`` for 2-D planes (or 3-D bands, channels first), in
    slices of the first axis over the thread pool.

    The planes of a colour picture are strided channel views; NumPy's strided copies release
    the GIL, so slices of rows copy on every core (the largest planes would not balance as
    whole planes).
    """
    tasks: list[tuple[int, int, int]] = []
    for k, source in enumerate(sources):
        rows = source.shape[0]
        step = max(1, _COPY_TASK // max(source.size // max(rows, 1), 1))
        tasks.extend((k, lo, min(lo + step, rows)) for lo in range(0, rows, step))

    def run(lo: int, hi: int) -> None:
        for k, row_lo, row_hi in tasks[lo:hi]:
            targets[k][row_lo:row_hi] = sources[k][row_lo:row_hi]

    # Many pieces: a copy's time varies with the page faults of its target rows (fresh
    # memory), and in two pieces a thread one slow piece could leave the other thread idle.
    run_rows(run, len(tasks), total, pieces=min(len(tasks), _COPY_PIECES))


# --------------------------------------------------------------------------------------------
# Finding blocks: which a region needs, and the per-block checks of bundle format 3.0
# --------------------------------------------------------------------------------------------


def block_counts(layout: list[list[tuple[int, ...]]], two_d: bool, block: int) -> list[int]:
    """How many blocks each chunk of this layout holds."""
    return _structure(layout, two_d, block)[2]


def needed_blocks(
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    block: int,
    masks: Sequence[Sequence[tuple[np.ndarray, ...]]],
) -> np.ndarray:
    """Which blocks hold at least one wanted coefficient (one flag per block, chunk by chunk).

    ``masks`` gives, per band of the layout, its wanted rows and columns as boolean masks:
    ``(rows, cols)`` for 2-D bands, ``(samples,)`` for the bands of one transformed axis (the
    layout of :func:`wavecore.regions.band_masks`).  A block is needed when one of its bands
    has a wanted row and a wanted column inside it.
    """
    _, blocks, per_chunk, _ = _structure(layout, two_d, block)
    out = np.zeros(len(blocks), dtype=bool)
    first = 0
    for band_shapes, band_masks, count in zip(layout, masks, per_chunk, strict=False):
        table = blocks[first : first + count]
        for shape, mask in zip(band_shapes, band_masks, strict=True):
            rows_mask, cols_mask = mask if len(mask) == 2 else (np.ones(1, dtype=bool), *mask)
            rows, cols, _ = _plane_dims(shape, two_d)
            if len(rows_mask) != rows or len(cols_mask) != cols:
                msg = f"band masks of {len(rows_mask)} × {len(cols_mask)} for a {shape} band"
                raise ValueError(msg)
            out[first : first + count] |= _hits(
                rows_mask, table[:, kernels.B_ROW0], table[:, kernels.B_ROW1]
            ) & _hits(cols_mask, table[:, kernels.B_COL0], table[:, kernels.B_COL1])
        first += count
    return out


def _hits(mask: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether ``mask`` has a True in ``[lo, hi)`` (clipped to its length), per pair."""
    total = np.concatenate([[0], np.cumsum(mask, dtype=np.int64)])
    n = len(mask)
    return total[np.minimum(hi, n)] > total[np.minimum(lo, n)]


def block_table(chunk: bytes | memoryview, count: int) -> tuple[int, np.ndarray]:
    """``(table bytes, block lengths)`` of a block-coded chunk of ``count`` blocks.

    The table is the varint length of each block at the start of the chunk; the lengths must
    fit in the chunk (with the 3.0 block checks, they add up to less than it).

    Raises
    ------
    BundleError
        For a table cut short or one whose lengths do not fit.
    """
    data = np.frombuffer(chunk, dtype=np.uint8)
    values, read = kernels.read_varints(data, count, data.size + 1)
    if read < 0 or read + int(values.sum()) > data.size:
        msg = (
            f"block-coded chunk of {data.size} bytes: its table of {count} block lengths "
            "does not fit in it"
        )
        raise BundleError(msg)
    return int(read), values.astype(np.int64)


#: Bytes of one block check (a CRC-16/XMODEM, little-endian).
CHECK_BYTES = 2


def add_block_checks(
    chunk: bytes, count: int, counts: Sequence[tuple[int, int]] | None = None
) -> bytes:
    """Bundle format 3.0's form of a block-coded chunk of ``count`` blocks.

    A chunk of one block is left as it is (the chunk's own CRC-16 checks that block).  A chunk
    of several gets, between its table of block lengths and the blocks: a CRC-16 of each
    block; for a detail chunk (``counts`` given), the :func:`band_counts` of each band as two
    varints; then a CRC-16 of everything before it in the chunk (the *prefix check*).
    """
    if count <= 1:
        return bytes(chunk)
    read, lengths = block_table(chunk, count)
    ends = read + np.cumsum(lengths)
    checks = tables.crc16_spans(np.frombuffer(chunk, dtype=np.uint8), ends - lengths, ends)
    prefix = bytearray(chunk[:read])
    prefix += checks.astype("<u2").tobytes()
    for ones, more in counts or ():
        prefix += encode_varint(ones) + encode_varint(more)
    prefix += binascii.crc_hqx(prefix, 0).to_bytes(CHECK_BYTES, "little")
    return bytes(prefix) + bytes(chunk[read:])


def strip_block_checks(
    chunk: bytes | memoryview, count: int, bands: int, verify: np.ndarray | None = None
) -> tuple[bytes, np.ndarray, list[tuple[int, int]] | None]:
    """The coder's form of a 3.0 block-coded chunk, which blocks fail, and its band counts.

    Parameters
    ----------
    chunk : bytes
        The chunk as stored in a 3.0 bundle.
    count : int
        Its number of blocks (a chunk of one block has no block checks).
    bands : int
        The number of bands whose counts it stores (0 for chunk 0).
    verify : numpy.ndarray of bool, optional
        Check only these blocks (the ones a region needs); by default every block.

    Returns
    -------
    bytes, numpy.ndarray, list or None
        The chunk without its checks (what :func:`decode_blocks` reads); one flag per block,
        True where the block's bytes do not match its CRC-16 (never for a block that was not
        verified); the ``(ones, more)`` counts of each band (None for a chunk of one block).

    Raises
    ------
    BundleError
        If the prefix (table, checks, counts) fails its CRC-16 or does not add up.
    """
    chunk = bytes(chunk)
    bad = np.zeros(count, dtype=bool)
    if count <= 1:
        return chunk, bad, None
    read, lengths = block_table(chunk, count)
    data = np.frombuffer(chunk, dtype=np.uint8)
    position = read + CHECK_BYTES * count
    values, used = kernels.read_varints(data[position:], 2 * bands, 2**62)
    if used < 0:
        msg = f"block-coded chunk of {len(chunk)} bytes: its band counts are cut short"
        raise BundleError(msg)
    position += int(used)
    payload = position + CHECK_BYTES
    if payload + int(lengths.sum()) != len(chunk):
        msg = (
            f"block-coded chunk of {len(chunk)} bytes: its {count} block lengths, checks and "
            "band counts do not add up to it"
        )
        raise BundleError(msg)
    if binascii.crc_hqx(chunk[:position], 0) != int.from_bytes(chunk[position:payload], "little"):
        msg = "block-coded chunk: its table of block lengths and checks fails its CRC-16"
        raise BundleError(msg)
    checks = np.frombuffer(chunk, dtype="<u2", count=count, offset=read)
    ends = payload + np.cumsum(lengths)
    starts = ends - lengths
    indices = np.arange(count) if verify is None else np.flatnonzero(verify[:count])
    found = tables.crc16_spans(data, starts[indices], ends[indices])
    bad[indices] = found != checks[indices]
    counts = [(int(values[2 * k]), int(values[2 * k + 1])) for k in range(bands)]
    return chunk[:read] + chunk[payload:], bad, counts or None


def fill_stand_ins(
    levels: list[list[np.ndarray]],
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    block: int,
    skip: np.ndarray,
    counts: Sequence[Sequence[tuple[int, int]] | None],
) -> None:
    """Put stand-in values (1s, then 2s) into skipped blocks so each band has its counts.

    A decode that skips blocks (a region's unneeded ones, or damaged ones) leaves them zero,
    which changes each band's :func:`band_counts` and with them where the dead-zone
    dequantizer places every nonzero value of the band.  The blocks a region skips hold no
    coefficient that reaches it, so what they hold is free: stand-ins that restore the stored
    counts make the dequantizer treat the band exactly as a full decode does.  ``counts``
    gives each chunk's stored band counts (None: not stored, nothing to restore).

    Raises
    ------
    BundleError
        If the stored counts are fewer than the decoded blocks already hold, or more than the
        skipped blocks can take (a crafted chunk: its prefix check passed).
    """
    _, blocks, per_chunk, _ = _structure(layout, two_d, block)
    first = 0
    for index, (bands, shapes, count) in enumerate(zip(levels, layout, per_chunk, strict=False)):
        stored = counts[index] if index < len(counts) else None
        skipped = blocks[first : first + count][skip[first : first + count]]
        first += count
        if stored is None or not len(skipped):
            continue
        for band, shape, (ones, more) in zip(bands, shapes, stored, strict=True):
            view = band.reshape(_plane_dims(shape, two_d))
            have_ones, have_more = band_counts(band)
            ones, more = ones - have_ones, more - have_more
            if ones < 0 or more < 0:
                msg = f"chunk {index}: its band counts are fewer than its decoded blocks hold"
                raise BundleError(msg)
            for r0, c0, r1, c1 in skipped[
                :, [kernels.B_ROW0, kernels.B_COL0, kernels.B_ROW1, kernels.B_COL1]
            ].tolist():
                if not ones and not more:
                    break
                part = view[r0:r1, c0:c1]
                values = np.zeros(part.size, dtype=band.dtype)
                take_ones = min(ones, part.size)
                take_more = min(more, part.size - take_ones)
                values[:take_ones] = 1
                values[take_ones : take_ones + take_more] = 2
                part[...] = values.reshape(part.shape)
                ones, more = ones - take_ones, more - take_more
            if ones or more:
                msg = f"chunk {index}: its band counts are more than its skipped blocks hold"
                raise BundleError(msg)
