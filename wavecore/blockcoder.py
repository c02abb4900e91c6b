"""Independent code-blocks: the context coder's version 4.

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

The bit-level specification is in ``docs/bundle-format.md`` (context coder version 4).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from . import _blockkernels as kernels
from .errors import BundleError
from .transform import run_rows

__all__ = [
    "BLOCK_SIZE",
    "BLOCK_SIZES",
    "CodedBlocks",
    "block_lengths",
    "decode_blocks",
    "encode_blocks",
]

#: The block side: 128 × 128 positions per band.  Each block learns its statistics afresh,
#: so small blocks cost bits: against version 3 on scikit-image's pictures, 32 × 32 blocks
#: wrote 3.4 % more, 64 × 64 0.5 % less (up to 1.5 % more at low rates), 128 × 128 1.4 % less
#: (see ``docs/bundle-format.md``).
BLOCK_SIZE = 128
#: The sides a reader accepts.
BLOCK_SIZES = (16, 32, 64, 128, 256)
#: Runs of blocks per encode or decode, each its own task for the thread pool: blocks cost
#: very unequal time (dense coarse blocks, nearly empty fine ones), so many small tasks handed
#: to whichever thread is free keep both cores busy to the end (a few large tasks can leave
#: one core waiting for the other).
_SPANS = 64


def _plane_dims(band_shape: tuple[int, ...], two_d: bool) -> tuple[int, int, int]:
    """``(rows, cols, channels)`` of a band; 1-D bands are one row of samples per channel."""
    if not band_shape:
        return 1, 1, 1
    if two_d and len(band_shape) >= 2:
        return int(band_shape[0]), int(band_shape[1]), int(np.prod(band_shape[2:], dtype=np.int64))
    return 1, int(band_shape[0]), int(np.prod(band_shape[1:], dtype=np.int64))


def _structure(
    layout: list[list[tuple[int, ...]]], two_d: bool, block: int
) -> tuple[np.ndarray, np.ndarray, list[int], int]:
    """The plane and block tables of a layout, the number of blocks per chunk, the total size.

    Planes are listed level by level, channel by channel, band by band (the order of ``flat``
    and of coding inside a block); blocks level by level, in rows of blocks.
    """
    planes: list[list[int]] = []
    blocks: list[np.ndarray] = []
    per_chunk: list[int] = []
    offset = 0
    block_rows, block_cols = (block, block) if two_d else (1, block * block)
    for index, band_shapes in enumerate(layout):
        dims = [_plane_dims(shape, two_d) for shape in band_shapes]
        first = len(planes)
        channels = max(d[2] for d in dims) if dims else 0
        for channel in range(channels):
            for k, (rows, cols, count) in enumerate(dims):
                if channel >= count:
                    continue
                me = len(planes)
                detail = index > 0
                siblings = [me - k + s for s in range(k)] if detail else []
                luma = first + k if detail and channel > 0 and dims[k][2] > 0 else -1
                planes.append(
                    [
                        offset,
                        rows,
                        cols,
                        1 if detail else 0,
                        siblings[0] if siblings else -1,
                        siblings[1] if len(siblings) > 1 else -1,
                        luma,
                        min(k, 2),
                    ]
                )
                offset += rows * cols
        height = max((d[0] for d in dims), default=0)
        width = max((d[1] for d in dims), default=0)
        grid_rows = -(-height // block_rows)
        grid_cols = -(-width // block_cols)
        rows0, cols0 = np.meshgrid(
            np.arange(grid_rows) * block_rows, np.arange(grid_cols) * block_cols, indexing="ij"
        )
        table = np.empty((grid_rows * grid_cols, kernels.BLOCK_FIELDS), dtype=np.int64)
        table[:, kernels.B_PLANE_LO] = first
        table[:, kernels.B_PLANE_HI] = len(planes)
        table[:, kernels.B_ROW0] = rows0.ravel()
        table[:, kernels.B_COL0] = cols0.ravel()
        table[:, kernels.B_ROW1] = rows0.ravel() + block_rows
        table[:, kernels.B_COL1] = cols0.ravel() + block_cols
        blocks.append(table)
        per_chunk.append(len(table))
    plane_table = np.array(planes, dtype=np.int64).reshape(-1, kernels.PLANE_FIELDS)
    return plane_table, np.concatenate(blocks), per_chunk, offset


def _block_sizes(planes: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """Coefficients per block (for sharing the work out evenly)."""
    total = np.zeros(len(blocks), dtype=np.int64)
    for p in range(len(planes)):
        rows, cols = planes[p, kernels.P_ROWS], planes[p, kernels.P_COLS]
        inside = (blocks[:, kernels.B_PLANE_LO] <= p) & (p < blocks[:, kernels.B_PLANE_HI])
        height = np.clip(
            np.minimum(blocks[:, kernels.B_ROW1], rows) - blocks[:, kernels.B_ROW0], 0, None
        )
        width = np.clip(
            np.minimum(blocks[:, kernels.B_COL1], cols) - blocks[:, kernels.B_COL0], 0, None
        )
        total += np.where(inside, height * width, 0)
    return total


def _cuts(weights: np.ndarray) -> np.ndarray:
    """``_SPANS + 1`` block indices that cut the blocks into runs of about equal weight."""
    cumulative = np.concatenate([[0], np.cumsum(weights + 1)])
    targets = np.linspace(0, cumulative[-1], _SPANS + 1)
    cuts = np.searchsorted(cumulative, targets, side="left")
    cuts[0], cuts[-1] = 0, len(weights)
    return np.maximum.accumulate(cuts)


def encode_blocks(
    entries: list[list[np.ndarray]], two_d: bool, block: int = BLOCK_SIZE
) -> list[bytes]:
    """Code integer bands (``[[cA], [level L bands], ...]``) into one chunk per entry."""
    layout = [[band.shape for band in bands] for bands in entries]
    planes, blocks, per_chunk, total = _structure(layout, two_d, block)
    flat = np.empty(total, dtype=np.int32)
    views = _plane_views(entries, two_d)
    targets = [
        flat[start : start + view.size].reshape(view.shape)
        for start, view in zip(planes[:, kernels.P_OFFSET], views, strict=True)
    ]
    _copy_planes(views, targets, int(total))
    sizes = _block_sizes(planes, blocks)
    cuts = _cuts(sizes)
    results: list[Any] = [None] * _SPANS

    def run(lo: int, hi: int) -> None:
        for span in range(lo, hi):
            results[span] = kernels.encode_span(flat, planes, blocks, cuts[span], cuts[span + 1])

    run_rows(run, _SPANS, int(total), pieces=_SPANS)
    payload = np.concatenate([r[0] for r in results])
    lengths = np.concatenate([r[1] for r in results])
    ends = np.cumsum(lengths)
    chunks = []
    first = 0
    for count in per_chunk:
        last = first + count
        start = int(ends[first - 1]) if first else 0
        stop = int(ends[last - 1]) if count else start
        table = kernels.write_varints(lengths[first:last])
        chunks.append(table.tobytes() + payload[start:stop].tobytes())
        first = last
    return chunks


class CodedBlocks:
    """The chunks of :func:`encode_blocks`, held block by block, so that rate control can code
    some blocks again (say, with details removed) without coding the others.

    ``CodedBlocks(chunks, layout, two_d, block)`` splits chunks made by :func:`encode_blocks`
    (their tables of block lengths say where each block's bytes are); :meth:`recode` codes the
    given blocks again from new integer bands, by the same compiled coder, so a block's bytes
    are exactly what :func:`encode_blocks` writes for its values; :meth:`chunks` puts the
    chunks back together.  ``regions[b]`` is block ``b``'s ``(entry, row0, col0, row1, col1)``:
    the positions it holds in every band (and channel) of layout entry ``entry``.
    """

    def __init__(
        self, chunks: list[bytes], layout: list[list[tuple[int, ...]]], two_d: bool, block: int
    ) -> None:
        self.layout, self.two_d, self.block = layout, two_d, block
        self._planes, self._blocks, self._per_chunk, self._total = _structure(layout, two_d, block)
        self.payloads: list[bytes] = []
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
        """Code blocks ``indices`` again from ``entries`` (integer bands of the same layout)."""
        indices = np.asarray(indices, dtype=np.int64)
        if indices.size == 0:
            return
        payload, lengths = _code_some(entries, self.two_d, self._planes, self._blocks, indices)
        ends = np.cumsum(lengths)
        for k, index in enumerate(indices):
            start = int(ends[k - 1]) if k else 0
            self.payloads[int(index)] = payload[start : int(ends[k])].tobytes()

    def chunks(self) -> list[bytes]:
        """The chunks, as :func:`encode_blocks` writes them for the blocks' current values."""
        out = []
        first = 0
        for count in self._per_chunk:
            parts = self.payloads[first : first + count]
            lengths = np.array([len(p) for p in parts], dtype=np.int64)
            out.append(kernels.write_varints(lengths).tobytes() + b"".join(parts))
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
) -> tuple[np.ndarray, np.ndarray]:
    """Blocks ``indices`` of the tables coded from ``entries``: their bytes and lengths."""
    total = int((planes[:, kernels.P_ROWS] * planes[:, kernels.P_COLS]).sum())
    flat = np.empty(total, dtype=np.int32)
    views = _plane_views(entries, two_d)
    targets = [
        flat[start : start + view.size].reshape(view.shape)
        for start, view in zip(planes[:, kernels.P_OFFSET], views, strict=True)
    ]
    _copy_planes(views, targets, total)
    chosen = np.ascontiguousarray(blocks[indices])
    sizes = _block_sizes(planes, chosen)
    cuts = _cuts(sizes)
    results: list[Any] = [None] * _SPANS

    def run(lo: int, hi: int) -> None:
        for span in range(lo, hi):
            results[span] = kernels.encode_span(flat, planes, chosen, cuts[span], cuts[span + 1])

    run_rows(run, _SPANS, int(sizes.sum()), pieces=_SPANS)
    return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])


def block_lengths(
    entries: list[list[np.ndarray]], two_d: bool, block: int, indices: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The coded bytes of blocks ``indices`` alone (what :func:`encode_blocks` would write for
    them), and every block's region ``(entry, row0, col0, row1, col1)``: for rate control to
    sample the coder on a few blocks."""
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
    return _code_some(entries, two_d, planes, blocks, indices)[1], regions


def _plane_views(entries: list[list[np.ndarray]], two_d: bool) -> list[np.ndarray]:
    """The planes of every entry in ``_structure``'s order."""
    out = []
    for bands in entries:
        views = []
        for band in bands:
            rows, cols, channels = _plane_dims(band.shape, two_d)
            views.append(np.asarray(band, dtype=np.int32).reshape(rows, cols, channels))
        channels = max((v.shape[2] for v in views), default=0)
        for channel in range(channels):
            for view in views:
                if channel < view.shape[2]:
                    out.append(view[:, :, channel])
    return out


def decode_blocks(
    chunks: list[bytes], layout: list[list[tuple[int, ...]]], two_d: bool, block: int
) -> list[list[np.ndarray]]:
    """Decode the chunks of :func:`encode_blocks` into ``int32`` bands of the ``layout``'s shapes.

    Raises
    ------
    BundleError
        For a block table that does not add up to its chunk, or a block that decodes to
        something impossible.
    """
    if block not in BLOCK_SIZES:
        msg = f"context coder block size {block!r} is not one of {BLOCK_SIZES}"
        raise BundleError(msg)
    planes, blocks, per_chunk, total = _structure(layout, two_d, block)
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
    flat = np.zeros(total, dtype=np.int32)
    sizes = _block_sizes(planes, blocks)
    cuts = _cuts(np.where(block_lengths > 0, sizes, 0))
    bad = [0] * _SPANS

    def run(lo: int, hi: int) -> None:
        for span in range(lo, hi):
            bad[span] = kernels.decode_span(
                data, block_starts, block_lengths, planes, blocks, flat, cuts[span], cuts[span + 1]
            )

    run_rows(run, _SPANS, int(np.count_nonzero(block_lengths)) * block * block, pieces=_SPANS)
    if sum(bad):
        msg = f"{sum(bad)} code-block(s) of the context-coded chunks are corrupt"
        raise BundleError(msg)
    levels = []
    sources, targets = [], []
    p = 0
    for band_shapes in layout:
        dims = [_plane_dims(shape, two_d) for shape in band_shapes]
        arrays = [np.empty((r, c, n), dtype=np.int32) for r, c, n in dims]
        channels = max((d[2] for d in dims), default=0)
        for channel, k in itertools.product(range(channels), range(len(dims))):
            rows, cols, count = dims[k]
            if channel >= count:
                continue
            start = planes[p, kernels.P_OFFSET]
            sources.append(flat[start : start + rows * cols].reshape(rows, cols))
            targets.append(arrays[k][:, :, channel])
            p += 1
        levels.append([a.reshape(shape) for a, shape in zip(arrays, band_shapes, strict=True)])
    _copy_planes(sources, targets, int(total))
    return levels


#: Rows of planes per copy task: about this many values, so that the tasks balance.
_COPY_TASK = 1 << 16


def _copy_planes(sources: list[np.ndarray], targets: list[np.ndarray], total: int) -> None:
    """``targets[k][...] = sources[k]`` for 2-D planes, in row slices over the thread pool.

    The planes of a colour picture are strided channel views; NumPy's strided copies release
    the GIL, so slices of rows copy on every core (the largest planes would not balance as
    whole planes).
    """
    tasks: list[tuple[int, int, int]] = []
    for k, source in enumerate(sources):
        rows, cols = source.shape
        step = max(1, _COPY_TASK // max(cols, 1))
        tasks.extend((k, lo, min(lo + step, rows)) for lo in range(0, rows, step))

    def run(lo: int, hi: int) -> None:
        for k, row_lo, row_hi in tasks[lo:hi]:
            targets[k][row_lo:row_hi] = sources[k][row_lo:row_hi]

    run_rows(run, len(tasks), total)
