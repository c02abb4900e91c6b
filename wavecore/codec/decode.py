"""Decoding: ``decode`` (the encoding path backwards, as far as the requested level needs, for
the whole array or a region of it, strictly or with damaged blocks zeroed), ``decode_region``
and ``inspect`` (a bundle described without decoding it)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from .. import curvesets, grids
from .. import lossless as _lossless
from ..blockcoder import (
    BLOCK_SIZES,
    band_counts,
    block_counts,
    decode_block_windows,
    decode_blocks,
    fill_stand_ins,
    needed_blocks,
    strip_block_checks,
)
from ..bundle import Bundle, read_bundle
from ..errors import BundleError, InvalidParameter
from ..layout import band_names, is_band_group
from ..losslesscoder import LOSSLESS_VERSION
from ..regions import band_masks, check_region, windowed_inverse
from ..resample import coarse_extent
from ..threshold import check_share
from .plan import Plan, plan_from_header
from .samples import finish, reconstruct_finished, unscaled
from .stages import pipeline, quantizer_of

#: The values of ``decode``'s ``damaged`` argument.
DAMAGED_MODES = ("strict", "zero")


def _open(bundle: Any) -> tuple[Bundle, Plan]:
    if not isinstance(bundle, bytes | bytearray | memoryview):
        msg = f"a bundle must be bytes, not {type(bundle).__name__}"
        raise BundleError(msg)
    parsed = read_bundle(bundle)
    try:
        return parsed, plan_from_header(parsed.header)
    except BundleError:
        raise
    except Exception as exc:
        # A field combination the checks above did not foresee: still the bundle's fault, and
        # the promise is "an array or BundleError" for any bytes.
        msg = f"header: inconsistent fields ({type(exc).__name__}: {exc})"
        raise BundleError(msg[:300]) from exc


def decode(
    bundle: Any,
    *,
    keep: float | None = None,
    level: int = 0,
    drop_levels: int | None = None,
    region: Any = None,
    damaged: str = "strict",
) -> np.ndarray:
    """Decode a bundle back into an array of the original's shape and dtype.

    Parameters
    ----------
    bundle : bytes
        What ``encode_image``/``encode_curve``/``encode_surface`` returned, or any bytes: the
        result is an array or a :class:`~wavecore.errors.BundleError`, never another error.
    keep : float, optional
        Keep only this fraction of the stored detail coefficients (the smallest by effect
        removed): a smoother, cheaper-looking reconstruction from the same bundle.
    level : int
        ``0`` for full resolution; ``k`` for the coarse approximation after ``k`` levels,
        cropped to the original's extent (about ``ceil(n / 2**k)`` samples per side), decoded
        from the first ``L - k + 1`` chunks only, so a truncated bundle still gives it.
        Note that this counts levels *dropped*, where ``encode_*(level=L)`` counts levels
        made; ``drop_levels`` says so in its name.
    drop_levels : int, optional
        The same as ``level``, under a name that says what it does: leave out the
        ``drop_levels`` finest levels of detail.  Give one of the two (both only when equal).
    region : tuple of slice, optional
        Decode only this part of the result: ``(rows, cols)`` for an image, surface or grid
        (a volume takes ``(depth, rows, cols)``), ``(points,)`` for a curve, in the
        coordinates of the array that ``level`` gives.  Each item is a ``slice`` (NumPy's
        rules: ``None`` ends, negative indices, a positive step) or a ``(start, stop)`` pair.
        The result equals ``decode(bundle, level=level)[region]`` exactly, but only the
        code-blocks holding coefficients that reach the region are read and decoded (bundles
        of the block coder, context version 4 on; older ones decode whole, then crop).
    damaged : {"strict", "zero"}
        ``"strict"`` (the default): any damaged chunk the decode needs is a
        :class:`~wavecore.errors.BundleError` naming it.  ``"zero"``: decode what is intact and
        set the coefficients of what is damaged or missing to zero.  From format 3.0 on, a
        damaged code-block loses only itself (each block has its own CRC-16); in 2.0 bundles
        a damaged chunk loses its level's details; with the older coders (zlib, context
        versions 2 and 3) the damaged level and every finer one.  The header, the chunk
        table (and in 2.0 chunk 0) must still be intact.

    Returns
    -------
    numpy.ndarray
        ``level=0``: the original's shape and dtype.  ``level=k``: a smaller array of the same
        dtype, with the same channel/coordinate axis.

    Raises
    ------
    BundleError
        For anything wrong with the bytes (with ``damaged="strict"``, a damaged chunk or
        block that the decode needs: the message names it).
    InvalidParameter
        For a bad ``keep``, ``region`` or ``damaged``, or a ``level`` deeper than the bundle's.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import encode_image
    >>> image = np.random.default_rng(0).integers(0, 256, (33, 47), dtype=np.uint8)
    >>> bundle = encode_image(image, lossless=True, level=3)
    >>> decode(bundle, level=2).shape, decode(bundle, drop_levels=2).shape
    ((9, 12), (9, 12))
    >>> part = decode(bundle, region=(slice(5, 20), slice(30, None)))
    >>> part.shape, bool((part == image[5:20, 30:]).all())
    ((15, 17), True)
    """
    if damaged not in DAMAGED_MODES:
        msg = f"damaged must be one of {list(DAMAGED_MODES)}, not {damaged!r}"
        raise InvalidParameter(msg[:200])
    if curvesets.is_curve_set(bundle):  # encode_curves' bundles: a list of (n_i, d) arrays
        if keep is not None or level or drop_levels or region is not None or damaged != "strict":
            msg = (
                "a curve set decodes whole, at its guaranteed tolerance: keep, level, "
                "drop_levels, region and damaged do not apply to it"
            )
            raise InvalidParameter(msg)
        return curvesets.decode_curves(bundle).curves  # type: ignore[return-value]
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        msg = f"level must be an integer >= 0, not {level!r}"
        raise InvalidParameter(msg)
    if grids.is_grid_bundle(bundle):  # a grid's container around a surface bundle
        if damaged != "strict":
            msg = (
                "damaged='zero' does not apply to grid bundles: their container is checked "
                "by one CRC-32, so a damaged grid is refused whole"
            )
            raise InvalidParameter(msg)
        return grids.decode_grid(
            bundle, level=level if drop_levels is None else drop_levels, keep=keep, window=region
        )
    if drop_levels is not None:
        if (
            isinstance(drop_levels, bool)
            or not isinstance(drop_levels, int | np.integer)
            or drop_levels < 0
        ):
            msg = f"drop_levels must be None or an integer >= 0, not {drop_levels!r}"
            raise InvalidParameter(msg)
        if level not in (0, drop_levels):
            msg = f"drop_levels={drop_levels} and level={level} disagree; give one of them"
            raise InvalidParameter(msg)
        level = drop_levels
    parsed, plan = _open(bundle)
    if (
        plan.levels <= 1
        and plan.levels < level <= _lossless.deepest(plan.shape)
        and plan.transform.lossless
        and (parsed.header.get("cparams") or {}).get("version") == LOSSLESS_VERSION
    ):
        # A bundle of the lossless coder (effort="max"), whose default depth is 0 or 1 levels:
        # the deeper thumbnail is lifted from the decoded picture (wavecore.lossless.coarser).
        # Bundles of the block coder keep their levels' limit, as before that coder.
        slices = None if region is None else _region_slices(plan, int(level), region)
        coded = decode(bundle, keep=keep, level=plan.levels, damaged=damaged)
        thumbnail = _lossless.coarser(coded, int(level) - plan.levels)
        return thumbnail if slices is None else np.ascontiguousarray(thumbnail[slices])
    if level > plan.levels:
        msg = f"level {level} is deeper than the bundle's {plan.levels} levels"
        raise InvalidParameter(msg)
    slices = None if region is None else _region_slices(plan, int(level), region)
    try:
        return _decode(parsed, plan, keep, int(level), slices, damaged)
    except BundleError:
        raise
    except MemoryError as exc:
        msg = f"not enough memory to decode a bundle of {plan.fitted} samples"
        raise BundleError(msg) from exc
    except Exception as exc:
        # The header passed its checks but its parameters are still inconsistent (a crafted
        # bundle with a valid CRC): whatever a stage tripped over, the bundle is what is wrong.
        msg = f"corrupt bundle: {type(exc).__name__}: {exc}"
        raise BundleError(msg) from exc


def decode_region(
    bundle: Any, region: Any, *, level: int = 0, damaged: str = "strict"
) -> np.ndarray:
    """Decode only a region of a bundle: ``decode(bundle, region=region, level=level)``.

    Parameters
    ----------
    bundle : bytes
        An image, surface, curve or grid bundle.
    region : tuple of slice
        ``(rows, cols)`` (a grid volume: ``(depth, rows, cols)``; a curve: ``(points,)``) in
        the coordinates of the array ``decode(bundle, level=level)`` returns.
    level, damaged
        As for :func:`decode`.

    Returns
    -------
    numpy.ndarray
        Exactly ``decode(bundle, level=level)[region]``, at a cost that grows with the region
        (the blocks it needs) rather than with the whole array, for block-coded bundles.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import encode_image
    >>> image = np.random.default_rng(1).integers(0, 256, (300, 200), dtype=np.uint8)
    >>> bundle = encode_image(image, quality=40)
    >>> window = (slice(100, 140), slice(50, 90))
    >>> bool((decode_region(bundle, window) == decode(bundle)[window]).all())
    True
    """
    return decode(bundle, region=region, level=level, damaged=damaged)


def _block_coder(header: dict[str, Any]) -> tuple[bool, int] | None:
    """``(two_d, block)`` when the header's coder codes in independent blocks, else None."""
    cparams = header.get("cparams")
    if header.get("coder") != "context" or not isinstance(cparams, dict):
        return None
    version, two_d, block = cparams.get("version"), cparams.get("two_d"), cparams.get("block")
    if isinstance(version, bool) or not isinstance(version, int) or version < 4:
        return None
    if not isinstance(two_d, bool) or isinstance(block, bool) or block not in BLOCK_SIZES:
        return None
    return two_d, int(block)


def _entries(shapes: list[Any]) -> list[list[tuple[int, ...]]]:
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
    coder = _block_coder(header)
    if coder is None:
        return None
    plan = plan_from_header(header)
    entries = _entries(plan.band_shapes()[: len(chunks)])
    counts = block_counts(entries, *coder)
    known = [getattr(chunk, "band_counts", None) for chunk in chunks]
    missing = any(
        k is None and n > 1 and i for i, (k, n) in enumerate(zip(known, counts, strict=True))
    )
    if missing:
        levels = decode_blocks([bytes(c) for c in chunks], entries, *coder)
        known = [[band_counts(band) for band in bands] for bands in levels]
    return [(n, known[i] if n > 1 and i else None) for i, n in enumerate(counts)]


def _output_shape(plan: Plan, level: int) -> list[int]:
    """The samples per transformed axis that a decode at ``level`` returns."""
    if plan.transform.lossless:
        out = []
        for n in plan.fitted[: len(plan.axes)]:
            for _ in range(level):
                n = (n + 1) // 2
            out.append(n)
        return out
    if level == 0:
        return [plan.fitted[a] - sum(plan.pads[a]) for a in range(len(plan.axes))]
    return [
        coarse_extent(
            plan.fitted[a] - sum(plan.pads[a]),
            plan.pads[a],
            level,
            boundary=plan.boundary[a],
            wavelet=plan.wavelet,
        )
        for a in range(len(plan.axes))
    ]


def _level_shape(plan: Plan, level: int) -> list[int]:
    """The shape ``decode(level=level)`` returns."""
    shape = list(plan.shape)
    for axis, n in enumerate(_output_shape(plan, level)):
        shape[axis] = n
    return shape


def _output_offsets(plan: Plan, level: int) -> list[int]:
    """Where a decode's first sample sits in the level's approximation, per axis (the
    padding before it: the fine data only, coarse levels are never padded before)."""
    if plan.transform.lossless or level:
        return [0] * len(plan.axes)
    return [before for before, _ in plan.pads]


def _region_slices(plan: Plan, level: int, region: Any) -> tuple[slice, ...]:
    """``region`` checked against what a decode at ``level`` returns (InvalidParameter)."""
    try:
        shape = _output_shape(plan, level)
    except Exception as exc:  # a crafted header whose padding does not fit its levels
        msg = f"header: the padding does not fit the levels ({type(exc).__name__}: {exc})"
        raise BundleError(msg[:300]) from exc
    return check_region(region, shape, len(plan.axes))


def _decode(
    parsed: Bundle,
    plan: Plan,
    keep: float | None,
    level: int,
    slices: tuple[slice, ...] | None = None,
    damaged: str = "strict",
) -> np.ndarray:
    """The encoding pipeline backwards, through the stages the header names, as far as
    ``level`` needs: entropy decoding, dequantization, ``keep``, inverse transform, finish;
    then the ``slices`` of a region (checked by :func:`_region_slices`)."""
    count = plan.levels - level + 1
    masks = None
    if slices is not None and (keep is None or keep >= 1.0):  # keep ranks every detail
        window = [
            (s.start + offset, s.stop + offset)
            for s, offset in zip(slices, _output_offsets(plan, level), strict=True)
        ]
        masks = band_masks(plan.transform, plan.fitted, plan.levels, level, window)
    stages = pipeline(parsed.header)
    shapes = plan.band_shapes()[:count]
    coder = _block_coder(parsed.header)
    compact = (
        masks is not None
        and coder is not None
        and (parsed.block_checks or stages.transform.lossless)
        and coder[0] == (len(plan.axes) == 2)
    )
    if compact:  # nothing of the whole band's size is made
        assert slices is not None and masks is not None and coder is not None
        with np.errstate(all="ignore"):
            samples = _decode_window_blocks(
                parsed, plan, stages, _entries(shapes), coder, masks, window, level, damaged
            )
            steps = tuple(slice(None, None, s.step) for s in slices)
            unpadded = dataclasses.replace(plan, pads=((0, 0),) * len(plan.axes))
            return np.ascontiguousarray(finish(unpadded, samples[steps], 0))
    with np.errstate(all="ignore"):
        if coder is not None and (masks is not None or damaged != "strict" or parsed.block_checks):
            qcoeffs = _decode_blocks(parsed, _entries(shapes), coder, masks, damaged)
        else:
            qcoeffs = stages.coder.decode(_whole_chunks(parsed, count, damaged), shapes)
        if len(qcoeffs) < count:  # damaged="zero" with an older coder: the finer levels lost
            qcoeffs = qcoeffs + _zero_levels(shapes[len(qcoeffs) :], len(qcoeffs))
        coeffs = stages.quantizer.decode(qcoeffs, plan)
        if keep is not None and keep < 1.0 and len(coeffs) > 1:
            coeffs = stages.transform.keep(coeffs, keep, plan)
        if masks is not None:
            # Synthesize the window only, then finish it as a picture of its own: nothing
            # left to crop, the colour and dtype steps work sample by sample.
            assert slices is not None
            samples = windowed_inverse(
                stages.transform, coeffs, plan.fitted, plan.levels, level, window
            )
            steps = tuple(slice(None, None, s.step) for s in slices)
            unpadded = dataclasses.replace(plan, pads=((0, 0),) * len(plan.axes))
            return np.ascontiguousarray(finish(unpadded, samples[steps], 0))
        out = reconstruct_finished(plan, coeffs, level, stages.transform)
    if slices is not None:
        out = np.ascontiguousarray(out[slices])
    return out


def _zero_levels(shapes: list[Any], first: int) -> list[Any]:
    out: list[Any] = []
    for index, entry in enumerate(shapes, start=first):
        if index > 0 and is_band_group(entry):
            out.append(tuple(np.zeros(band, dtype=np.int32) for band in entry))
        else:
            out.append(np.zeros(entry, dtype=np.int32))
    return out


def _whole_chunks(parsed: Bundle, count: int, damaged: str) -> list[bytes]:
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


def _decode_blocks(
    parsed: Bundle,
    entries: list[list[tuple[int, ...]]],
    coder: tuple[bool, int],
    masks: list[list[tuple[np.ndarray, ...]]] | None,
    damaged: str,
) -> list[Any]:
    """Decode block-coded chunks, reading only the blocks ``masks`` needs (all without).

    Checks what it reads: a chunk of several blocks of a 3.0 bundle block by block (the needed
    blocks only), any other chunk whole.  ``damaged="zero"`` zeroes what fails its check
    instead of raising.
    """
    two_d, block = coder
    counts = block_counts(entries, two_d, block)
    if masks is not None and two_d != (len(masks[0][0]) == 2):
        masks = None  # a layout the masks do not describe: decode every block
    uses_counts = quantizer_of(parsed.header).uses_band_counts
    if not parsed.block_checks and uses_counts:
        # Before 3.0 the band counts that place dequantized values are not stored: they
        # come from every block of the band (see fill_stand_ins).
        masks = None
    wanted = (
        needed_blocks(entries, two_d, block, masks)
        if masks is not None
        else np.ones(sum(counts), dtype=bool)
    )
    chunks, skip, stored = _read_chunks(parsed, entries, counts, wanted, damaged)
    levels = decode_blocks(chunks, entries, two_d, block, skip=skip)
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
) -> tuple[list[bytes], np.ndarray, list[list[tuple[int, int]] | None]]:
    """The chunks in the coder's form, the blocks to skip (unwanted or lost), and each
    chunk's stored band counts (None where it stores none or they are lost)."""
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
    return chunks, skip, stored


def _decode_window_blocks(
    parsed: Bundle,
    plan: Plan,
    stages: Any,
    entries: list[list[tuple[int, ...]]],
    coder: tuple[bool, int],
    masks: list[list[tuple[np.ndarray, ...]]],
    window: list[tuple[int, int]],
    level: int,
    damaged: str,
) -> np.ndarray:
    """A region of a 3.0 bundle (or a lossless 2.0 one), in samples: only the needed blocks
    are decoded, only the part of each band they need is kept, dequantized and synthesized."""
    two_d, block = coder
    counts = block_counts(entries, two_d, block)
    wanted = needed_blocks(entries, two_d, block, masks)
    chunks, skip, stored = _read_chunks(parsed, entries, counts, wanted, damaged)
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
    parts, totals = decode_block_windows(chunks, entries, two_d, block, skip, cuts, missing)
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


def inspect(bundle: Any) -> dict[str, Any]:
    """Describe a bundle without decoding it.

    Returns
    -------
    dict
        ``version``, ``kind``, ``shape``, ``dtype``, ``wavelet``, ``boundary``, ``levels``,
        ``colour``, ``lossless``, ``quantizer``, ``coder``, ``psnr`` (the encoder's measured
        PSNR in dB, ``None`` when exact), ``max_error``, ``total_bytes``, ``header_bytes``,
        ``peak`` (in the original's units), ``scale`` (the power of two the values were
        coded under, ``0`` for all but huge or tiny floats), ``bpp`` (images),
        ``level_shapes`` (the shape ``decode(level=k)`` returns, for each ``k``), ``chunks``
        (one entry per chunk, coarse to fine: its resolution ``level``, its subband
        ``shapes``, its ``bytes`` and whether it is ``present``), and ``header`` (the raw
        header).

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import encode_image
    >>> info = inspect(encode_image(np.zeros((16, 16), np.uint8), lossless=True, level=2))
    >>> info["levels"], [c["level"] for c in info["chunks"]], info["lossless"]
    (2, [2, 1, 0], True)
    """
    if curvesets.is_curve_set(bundle):
        return curvesets.inspect_curves(bundle)
    if grids.is_grid_bundle(bundle):
        return grids.inspect_grid(bundle)
    parsed, plan = _open(bundle)
    header = parsed.header
    try:
        shapes = plan.band_shapes()
    except Exception as exc:  # a crafted header that passed every check; see decode
        msg = f"corrupt bundle: {type(exc).__name__}: {exc}"
        raise BundleError(msg) from exc
    chunks = []
    for index, (entry, chunk) in enumerate(zip(shapes, parsed.chunks, strict=True)):
        band_shapes = (
            [list(entry)] if index == 0 or len(plan.axes) == 1 else [list(s) for s in entry]
        )
        chunks.append(
            {
                "level": plan.levels - index,
                "bands": band_names(index, len(plan.axes)),
                "shapes": band_shapes,
                "bytes": len(chunk) if chunk is not None else None,
                "present": chunk is not None,
            }
        )
    payload = sum(len(c) for c in parsed.chunks if c is not None)
    total = len(bundle)
    info: dict[str, Any] = {
        "version": f"{parsed.version[0]}.{parsed.version[1]}",
        "kind": plan.kind,
        "shape": list(plan.shape),
        "dtype": plan.dtype,
        "wavelet": plan.wavelet,
        "boundary": list(plan.boundary),
        "levels": plan.levels,
        "colour": plan.colour,
        "lossless": plan.transform.lossless,
        "quantizer": header["quantizer"],
        "coder": header["coder"],
        "psnr": header["psnr"],
        "max_error": header["max_error"],
        "peak": unscaled(plan.peak, plan.scale),
        "scale": plan.scale,
        "total_bytes": total,
        "header_bytes": total - payload,
        "chunks": chunks,
        "level_shapes": [_level_shape(plan, k) for k in range(plan.levels + 1)],
        "header": header,
    }
    if plan.kind == "image":
        info["bpp"] = 8.0 * total / (plan.shape[0] * plan.shape[1])
    return info
