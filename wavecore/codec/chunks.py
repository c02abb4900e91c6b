"""Reading a bundle's coded chunks for decoding: whole (coders that read a chunk whole), or
block by block (the block coder), checked, only the blocks a region needs, with damaged blocks
zeroed under ``damaged="zero"``, and stand-ins from the stored band counts where blocks are not
read.

:mod:`.decode` composes these with the stages; :func:`chunk_block_info` is what
:func:`wavecore.bundle.write_bundle` needs to lay out format 3.0's block checks.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..blockcoder import (
    BLOCK_SIZES,
    PARENT_VERSIONS,
    band_counts,
    block_counts,
    decode_block_windows,
    decode_blocks,
    fill_stand_ins,
    needed_blocks,
    parent_blocks,
    strip_block_checks,
)
from ..bundle import Bundle
from ..errors import BundleError
from ..layout import is_band_group
from ..regions import windowed_inverse
from .plan import Plan, plan_from_header
from .stages import quantizer_of


def block_coder(header: dict[str, Any]) -> tuple[bool, int, int] | None:
    """``(two_d, block, version)`` when the header's coder codes in blocks, else None."""
    cparams = header.get("cparams")
    if header.get("coder") != "context" or not isinstance(cparams, dict):
        return None
    version, two_d, block = cparams.get("version"), cparams.get("two_d"), cparams.get("block")
    if isinstance(version, bool) or not isinstance(version, int) or version < 4:
        return None
    if not isinstance(two_d, bool) or isinstance(block, bool) or block not in BLOCK_SIZES:
        return None
    return two_d, int(block), version


def _parents_of(
    entries: list[list[tuple[int, ...]]], coder: tuple[bool, int, int]
) -> np.ndarray | None:
    """Each block's parent block (versions 6 to 8), or None (blocks that depend on none)."""
    two_d, block, version = coder
    return parent_blocks(entries, two_d, block) if version in PARENT_VERSIONS else None


def _with_ancestors(wanted: np.ndarray, parent_of: np.ndarray | None) -> np.ndarray:
    """``wanted`` and every ancestor of a wanted block (versions 6 to 8 decode a block from its
    parent block's values)."""
    if parent_of is None:
        return wanted
    wanted = wanted.copy()
    while True:
        up = parent_of[wanted & (parent_of >= 0)]
        if wanted[up].all():
            return wanted
        wanted[up] = True


def _with_descendants(lost: np.ndarray, parent_of: np.ndarray | None) -> np.ndarray:
    """``lost`` and every descendant of a lost block (whose contexts read lost values)."""
    if parent_of is None:
        return lost
    has = parent_of >= 0
    while True:
        more = lost | (has & lost[np.maximum(parent_of, 0)])
        if np.array_equal(more, lost):
            return lost
        lost = more


def band_entries(shapes: list[Any]) -> list[list[tuple[int, ...]]]:
    """Band shapes as the block coder lists them: ``[[cA], [bands of level L], ...]``."""
    out = []
    for index, entry in enumerate(shapes):
        grouped = index > 0 and is_band_group(entry)
        out.append([tuple(band) for band in entry] if grouped else [tuple(entry)])
    return out


def chunk_block_info(
    header: dict[str, Any], chunks: Sequence[bytes]
) -> list[tuple[int, list[tuple[int, int]] | None]] | None:
    """Per chunk, its number of blocks and (detail chunks of several blocks) the band counts
    that format 3.0 stores; None when the header's coder does not code in blocks.

    What :func:`wavecore.bundle.write_bundle` needs.  The counts come with the chunks of
    :func:`wavecore.blockcoder.encode_blocks`; chunks without them are decoded to find them.
    """
    coder = block_coder(header)
    if coder is None:
        return None
    plan = plan_from_header(header)
    entries = band_entries(plan.band_shapes()[: len(chunks)])
    two_d, block, version = coder
    counts = block_counts(entries, two_d, block)
    known = [getattr(chunk, "band_counts", None) for chunk in chunks]
    missing = any(
        k is None and n > 1 and i for i, (k, n) in enumerate(zip(known, counts, strict=True))
    )
    if missing:
        levels = decode_blocks(
            [bytes(c) for c in chunks],
            entries,
            two_d,
            block,
            version=version,
            chunks_total=len(plan.band_shapes()),
        )
        known = [[band_counts(band) for band in bands] for bands in levels]
    return [(n, known[i] if n > 1 and i else None) for i, n in enumerate(counts)]


def zero_levels(shapes: list[Any], first: int) -> list[Any]:
    """All-zero quantized levels of ``shapes`` (level ``first`` onwards): the finer levels
    an older coder loses after a damaged chunk under ``damaged="zero"``."""
    out: list[Any] = []
    for index, entry in enumerate(shapes, start=first):
        if index > 0 and is_band_group(entry):
            out.append(tuple(np.zeros(band, dtype=np.int32) for band in entry))
        else:
            out.append(np.zeros(entry, dtype=np.int32))
    return out


def whole_chunks(parsed: Bundle, count: int, damaged: str) -> list[bytes]:
    """The first ``count`` chunks, checked (a coder that reads chunks whole).

    With ``damaged="zero"``, the intact chunks before the first damaged or missing one (the
    older coders carry context from level to level, so nothing after a lost chunk is sound).
    """
    chunks = []
    for index in range(count):
        if damaged == "zero" and not parsed.intact(index):
            if not index:
                msg = "chunk 0 (the coarse approximation) is damaged or missing"
                raise BundleError(msg)
            break
        chunk = parsed.chunk(index)
        if not chunk:  # every coder writes a few bytes even for all-zero bands
            msg = f"chunk {index} is empty; no encoder writes an empty chunk"
            raise BundleError(msg)
        chunks.append(chunk)
    return chunks


def decode_block_levels(
    parsed: Bundle,
    entries: list[list[tuple[int, ...]]],
    coder: tuple[bool, int, int],
    masks: list[list[tuple[np.ndarray, ...]]] | None,
    damaged: str,
) -> list[Any]:
    """Decode block-coded chunks, reading only the blocks ``masks`` needs (all without).

    Checks what it reads: a chunk of several blocks of a 3.0 bundle block by block (the needed
    blocks only), any other chunk whole.  ``damaged="zero"`` zeroes what fails its check
    instead of raising (under versions 6 to 8 with the blocks that descend from it).
    """
    two_d, block, version = coder
    counts = block_counts(entries, two_d, block)
    if masks is not None and two_d != (len(masks[0][0]) == 2):
        masks = None  # a layout the masks do not describe: decode every block
    uses_counts = quantizer_of(parsed.header).uses_band_counts
    if not parsed.block_checks and uses_counts:
        # Before 3.0 the band counts that place dequantized values are not stored: they
        # come from every block of the band (see fill_stand_ins).
        masks = None
    parent_of = _parents_of(entries, coder)
    wanted = (
        _with_ancestors(needed_blocks(entries, two_d, block, masks), parent_of)
        if masks is not None
        else np.ones(sum(counts), dtype=bool)
    )
    chunks, skip, stored = _read_chunks(parsed, entries, counts, wanted, damaged, parent_of)
    # Version 8's level classes count from the bundle's finest chunk, decoded or not.
    whole = parsed.header["levels"] + 1
    levels = decode_blocks(
        chunks, entries, two_d, block, skip=skip, version=version, chunks_total=whole
    )
    if uses_counts and skip.any():
        fill_stand_ins(levels, entries, two_d, block, skip, stored)
    out: list[Any] = []
    for index, arrays in enumerate(levels):
        out.append(tuple(arrays) if index > 0 and len(arrays) > 1 else arrays[0])
    return out


def _read_chunks(
    parsed: Bundle,
    entries: list[list[tuple[int, ...]]],
    counts: list[int],
    wanted: np.ndarray,
    damaged: str,
    parent_of: np.ndarray | None,
) -> tuple[list[bytes], np.ndarray, list[list[tuple[int, int]] | None]]:
    """The chunks in the coder's form, the blocks to skip (unwanted, lost, or under versions 6-8
    descended from a lost block), and each chunk's stored band counts (None where it stores
    none or they are lost).  ``wanted`` holds the ancestors of what it holds (versions 6 to 8)."""
    skip = ~wanted
    chunks: list[bytes] = []
    stored: list[list[tuple[int, int]] | None] = []
    first = 0
    for index, count in enumerate(counts):
        need = wanted[first : first + count]
        bands = len(entries[index]) if index else 0
        chunk, lost, band_counts = _checked_chunk(parsed, index, count, bands, need, damaged)
        skip[first : first + count] |= lost
        chunks.append(chunk)
        stored.append(band_counts)
        first += count
    # A block whose parent is skipped is skipped: either it is not wanted either (a wanted
    # block's parent is wanted), or its parent is lost and its contexts would read zeros.
    return chunks, _with_descendants(skip, parent_of), stored


def decode_block_window(
    parsed: Bundle,
    plan: Plan,
    stages: Any,
    entries: list[list[tuple[int, ...]]],
    coder: tuple[bool, int, int],
    masks: list[list[tuple[np.ndarray, ...]]],
    window: list[tuple[int, int]],
    level: int,
    damaged: str,
) -> np.ndarray:
    """A region of a 3.0 bundle (or a lossless 2.0 one), in samples: only the needed blocks
    are decoded, only the part of each band they need is kept, dequantized and synthesized."""
    two_d, block, version = coder
    counts = block_counts(entries, two_d, block)
    parent_of = _parents_of(entries, coder)
    wanted = _with_ancestors(needed_blocks(entries, two_d, block, masks), parent_of)
    chunks, skip, stored = _read_chunks(parsed, entries, counts, wanted, damaged, parent_of)
    cuts: list[list[tuple[int, int, int, int]]] = []
    origins: list[Any] = []
    for band_masks_ in masks:
        entry_cuts, entry_origins = [], []
        for mask in band_masks_:
            spans = [_span(m) for m in mask]
            (r0, r1), (c0, c1) = spans if len(spans) == 2 else [(0, 1), spans[0]]
            entry_cuts.append((r0, r1, c0, c1))
            entry_origins.append(tuple(lo for lo, _ in spans))
        cuts.append(entry_cuts)
        origins.append(entry_origins)
    uses_counts = stages.quantizer.uses_band_counts
    missing = [i for i in range(1, len(entries)) if stored[i] is None] if uses_counts else []
    parts, totals = decode_block_windows(
        chunks,
        entries,
        two_d,
        block,
        skip,
        cuts,
        missing,
        version=version,
        chunks_total=parsed.header["levels"] + 1,
    )
    qcoeffs: list[Any] = [parts[0][0]]
    for index, bands in enumerate(parts[1:], start=1):
        known = (stored[index] or totals[index]) if uses_counts else [None] * len(bands)
        given = [
            part if counts_ is None else _with_stand_ins(part, *counts_)
            for part, counts_ in zip(bands, known, strict=True)
        ]
        qcoeffs.append(tuple(given) if len(given) > 1 else given[0])
    coeffs = stages.quantizer.decode(qcoeffs, plan)
    for index, bands in enumerate(parts[1:], start=1):
        values = coeffs[index] if isinstance(coeffs[index], tuple) else (coeffs[index],)
        shaped = [v[: p.size].reshape(p.shape) for v, p in zip(values, bands, strict=True)]
        coeffs[index] = tuple(shaped) if len(shaped) > 1 else shaped[0]
    origins = [origins[0][0], *origins[1:]]
    return windowed_inverse(
        stages.transform, coeffs, plan.fitted, plan.levels, level, window, origins
    )


def _span(mask: np.ndarray) -> tuple[int, int]:
    """``[first, last + 1)`` of a mask's True values (``(0, 0)`` for none)."""
    where = np.flatnonzero(mask)
    return (int(where[0]), int(where[-1]) + 1) if where.size else (0, 0)


def _with_stand_ins(part: np.ndarray, ones: int, more: int) -> np.ndarray:
    """``part``'s values, flat, then stand-ins (1s, then 2s) up to the band's counts, so the
    dequantizer places them as it does in the whole band (see ``fill_stand_ins``)."""
    have_ones, have_more = band_counts(part)
    if have_ones > ones or have_more > more:
        msg = "a chunk's band counts are fewer than its decoded blocks hold"
        raise BundleError(msg)
    extra = np.concatenate(
        [np.ones(ones - have_ones, dtype=np.int32), np.full(more - have_more, 2, np.int32)]
    )
    return np.concatenate([part.ravel(), extra])


def _checked_chunk(
    parsed: Bundle, index: int, count: int, bands: int, need: np.ndarray, damaged: str
) -> tuple[bytes, np.ndarray, list[tuple[int, int]] | None]:
    """Chunk ``index`` in the coder's form, which of its blocks to zero as damaged, and the
    band counts it stores (format 3.0, chunks of several blocks)."""
    lost = np.zeros(count, dtype=bool)
    empty = bytes(count)  # a table of zero lengths: every block decodes as zeros
    data = parsed.chunks[index]
    if data is None or not len(data):
        if damaged == "zero" or not need.any():
            return empty, ~lost, None
        parsed.chunk(index)  # raises: truncated
        msg = f"chunk {index} is empty; no encoder writes an empty chunk"
        raise BundleError(msg)
    if not (parsed.block_checks and count > 1):  # the chunk's CRC-16 is the only check
        if not need.any():
            return empty, lost, None
        if parsed.intact(index):
            return bytes(data), lost, None
        if damaged == "zero":
            return empty, ~lost, None
        parsed.chunk(index)  # raises, naming the chunk
    whole = need.all() and parsed.intact(index)  # one CRC over the chunk costs less than many
    try:
        chunk, bad, stored = strip_block_checks(data, count, bands, lost if whole else need)
    except BundleError:  # a damaged prefix: no block can be found
        if damaged == "zero":
            return empty, ~lost, None
        msg = f"chunk {index} is corrupt: its table of {count} code-blocks fails its check"
        raise BundleError(msg) from None
    if bad.any() and damaged != "zero":
        blocks = np.flatnonzero(bad).tolist()
        msg = (
            f"chunk {index} is corrupt: code-block(s) {blocks[:8]} of its {count} fail their "
            "CRC-16 (decode with damaged='zero' to get the rest with those blocks zeroed)"
        )
        raise BundleError(msg)
    return chunk, bad, stored
