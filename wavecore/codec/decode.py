"""Decoding: ``decode`` (the encoding path backwards, as far as the requested level needs, for
the whole array or a region of it, strictly or with damaged blocks zeroed), ``decode_region``
and ``inspect`` (a bundle described without decoding it)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .. import curvesets, grids
from .. import lossless as _lossless
from ..blockcoder import PRIOR_VERSION
from ..bundle import Bundle, read_bundle
from ..errors import BundleError, InvalidParameter
from ..layout import band_names
from ..losslesscoder import LOSSLESS_VERSION, decode_lossless_levels, stripes_needed
from ..multilevel import default_level
from ..regions import band_masks, windowed_inverse
from ..restoration import APRON, apply_restoration
from ..threshold import check_share
from . import replication
from .chunks import (
    band_entries,
    block_coder,
    decode_block_levels,
    decode_block_window,
    whole_chunks,
    zero_levels,
)

# chunk_block_info's first home, where wavecore.bundle and older callers find it.
from .chunks import chunk_block_info as chunk_block_info
from .extents import level_shape, output_offsets, region_slices
from .plan import MAX_IMAGE_LEVELS, Plan, plan_from_header
from .samples import finish, reconstruct_finished, unscaled
from .stages import ReversibleTransform, pipeline

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
        made; ``drop_levels`` says so in its name.  A picture enlarged ``f = 2**s`` times by
        pixel replication (``inspect(bundle)["replicated"]``) gives its decoded source
        enlarged ``2**(s - k)`` times for ``k < s``, then the source's own levels.
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
        dtype, with the same channel/coordinate axis.  A picture whose bundle carries a
        restoration filter (:mod:`wavecore.restoration`) is filtered at ``level=0`` with
        ``keep`` unset or 1, a region as the whole; other levels and ``keep`` below 1 are not.

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
        curves = curvesets.decode_curves(bundle).curves
        # checked first: a damaged bundle whose first bytes now read as a curve set's (89 57
        # 86 from a 6.0 bundle's 89 57 06) is a BundleError, not a misuse of the arguments
        if keep is not None or level or drop_levels or region is not None or damaged != "strict":
            msg = (
                "a curve set decodes whole, at its guaranteed tolerance: keep, level, "
                "drop_levels, region and damaged do not apply to it"
            )
            raise InvalidParameter(msg)
        return curves  # type: ignore[return-value]
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
    if replication.is_replicated(bundle):  # a picture enlarged by pixel replication
        return replication.decode_replicated(
            bundle, decode, inspect, keep=keep, level=int(level), region=region, damaged=damaged
        )
    parsed, plan = _open(bundle)
    if (
        plan.transform.lossless
        and _lossless_coded(parsed.header)
        and len(plan.shape) >= 2  # only pictures: a curve's level is checked below
        and plan.levels <= 1
        and plan.levels < level <= _lossless.deepest(plan.shape)
    ):
        # A bundle of the lossless coder (effort="max"), whose default depth is 0 or 1 levels:
        # the deeper thumbnail is lifted from the decoded picture (wavecore.lossless.coarser).
        # Bundles of the block coder keep their levels' limit, as before that coder.
        slices = None if region is None else region_slices(plan, int(level), region)
        coded = decode(bundle, keep=keep, level=plan.levels, damaged=damaged)
        thumbnail = _lossless.coarser(coded, int(level) - plan.levels)
        return thumbnail if slices is None else np.ascontiguousarray(thumbnail[slices])
    if level > plan.levels:
        msg = f"level {level} is deeper than the bundle's {plan.levels} levels"
        lifted = plan.transform.lossless and _lossless_coded(parsed.header)
        if lifted and len(plan.shape) >= 2 and plan.levels <= 1:
            # coarser levels are lifted from the picture, as deep as its size allows
            deepest = max(plan.levels, _lossless.deepest(plan.shape))
            msg = f"level {level} is deeper than {deepest}, the most this picture's size allows"
        raise InvalidParameter(msg)
    slices = None if region is None else region_slices(plan, int(level), region)
    restore = parsed.header.get("restore")
    try:
        if restore is not None and level == 0 and (keep is None or keep >= 1.0):
            return _restored(parsed, plan, restore, slices, damaged)
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


def _lossless_coded(header: dict[str, Any]) -> bool:
    """Whether a bundle's chunks are the lossless coder's (:mod:`wavecore.losslesscoder`)."""
    cparams = header.get("cparams")
    return (
        header.get("coder") == "context"
        and isinstance(cparams, dict)
        and cparams.get("version") == LOSSLESS_VERSION
    )


def _restored(
    parsed: Bundle,
    plan: Plan,
    restore: list[Any],
    slices: tuple[slice, ...] | None,
    damaged: str,
) -> np.ndarray:
    """The full-resolution decode with the header's restoration filter applied
    (:mod:`wavecore.restoration`).  A region is decoded with ``APRON`` samples more on each
    side (within the picture), filtered, and cropped: the same samples as the whole picture's."""
    if slices is None:
        return apply_restoration(_decode(parsed, plan, None, 0, None, damaged), restore)
    wider, inner = [], []
    for s, size in zip(slices, plan.shape, strict=False):
        last = s.start + (s.stop - s.start - 1) // s.step * s.step
        start, stop = max(0, s.start - APRON), min(size, last + 1 + APRON)
        wider.append(slice(start, stop))
        inner.append(slice(s.start - start, last + 1 - start, s.step))
    decoded = _decode(parsed, plan, None, 0, tuple(wider), damaged)
    return np.ascontiguousarray(apply_restoration(decoded, restore)[tuple(inner)])


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
    then the ``slices`` of a region (checked by :func:`region_slices`)."""
    count = plan.levels - level + 1
    masks = None
    if slices is not None and (keep is None or keep >= 1.0):  # keep ranks every detail
        window = [
            (s.start + offset, s.stop + offset)
            for s, offset in zip(slices, output_offsets(plan, level), strict=True)
        ]
        masks = band_masks(plan.transform, plan.fitted, plan.levels, level, window)
    stages = pipeline(parsed.header)
    shapes = plan.band_shapes()[:count]
    coder = block_coder(parsed.header)
    compact = (
        masks is not None
        and coder is not None
        and (parsed.block_checks or stages.transform.lossless)
        and coder[0] == (len(plan.axes) == 2)
    )
    if compact:  # nothing of the whole band's size is made
        assert slices is not None and masks is not None and coder is not None
        with np.errstate(all="ignore"):
            samples = decode_block_window(
                parsed, plan, stages, band_entries(shapes), coder, masks, window, level, damaged
            )
            steps = tuple(slice(None, None, s.step) for s in slices)
            unpadded = dataclasses.replace(plan, pads=((0, 0),) * len(plan.axes))
            return np.ascontiguousarray(finish(unpadded, samples[steps], 0))
    with np.errstate(all="ignore"):
        # A coarse level of version 8 too: its blocks' starting models depend on how many
        # chunks the encoder coded (decode_block_levels knows; the coder stage does not).
        partial = coder is not None and coder[2] == PRIOR_VERSION and count < plan.levels + 1
        if coder is not None and (
            masks is not None or damaged != "strict" or parsed.block_checks or partial
        ):
            qcoeffs = decode_block_levels(parsed, band_entries(shapes), coder, masks, damaged)
        elif masks is not None and _lossless_coded(parsed.header):
            # The lossless coder's stripes are coded apart: a region decodes the ones it needs.
            chunks = whole_chunks(parsed, count, damaged)
            stripes = stripes_needed(shapes, masks[: len(chunks)])
            qcoeffs = decode_lossless_levels(chunks, shapes, parsed.header["cparams"], stripes)
        else:
            qcoeffs = stages.coder.decode(whole_chunks(parsed, count, damaged), shapes)
        if len(qcoeffs) < count:  # damaged="zero" with an older coder: the finer levels lost
            qcoeffs = qcoeffs + zero_levels(shapes[len(qcoeffs) :], len(qcoeffs))
        coeffs = stages.quantizer.decode(qcoeffs, plan)
        transform = stages.transform
        if keep is not None and keep < 1.0 and level == 0 and _lossless_coded(parsed.header):
            # The lossless coder codes 0 or 1 levels, which leave keep little or nothing to
            # drop: rank the details of the block coder's depth of 5/3 levels instead.
            depth = min(
                default_level(plan.shape[:2], MAX_IMAGE_LEVELS), _lossless.deepest(plan.shape)
            )
            if plan.levels < depth:
                samples = transform.inverse(coeffs, plan)
                transform = ReversibleTransform(["legall53"] * depth)
                coeffs = transform.forward(samples, depth)
        if keep is not None and keep < 1.0 and len(coeffs) > 1:
            coeffs = transform.keep(coeffs, keep, plan)
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
        out = reconstruct_finished(plan, coeffs, level, transform)
    if slices is not None:
        out = np.ascontiguousarray(out[slices])
    return out


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
        ``shapes``, its ``bytes`` and whether it is ``present``), ``restored`` (whether a
        full-resolution decode applies a restoration filter: :mod:`wavecore.restoration`),
        and ``header`` (the raw header).  Images also give ``replicated``: ``f`` for a
        picture enlarged ``f × f`` by pixel replication and coded as its source (format 7.0,
        whose ``source_version`` is the inner bundle's, and whose ``header`` is the
        source's), 1 for any other.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import encode_image
    >>> picture = np.arange(256, dtype=np.uint8).reshape(16, 16)
    >>> info = inspect(encode_image(picture, lossless=True, level=2))
    >>> info["levels"], [c["level"] for c in info["chunks"]], info["lossless"]
    (2, [2, 1, 0], True)
    """
    if curvesets.is_curve_set(bundle):
        return curvesets.inspect_curves(bundle)
    if grids.is_grid_bundle(bundle):
        return grids.inspect_grid(bundle)
    if replication.is_replicated(bundle):
        return replication.inspect_replicated(bundle, inspect)
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
        "level_shapes": [level_shape(plan, k) for k in range(plan.levels + 1)],
        "restored": header.get("restore") is not None,
        "header": header,
    }
    if plan.kind == "image":
        info["bpp"] = 8.0 * total / (plan.shape[0] * plan.shape[1])
        info["replicated"] = 1
    return info
