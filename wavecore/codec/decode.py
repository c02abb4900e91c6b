"""Decoding: ``decode`` (the encoding path backwards, as far as the requested level needs) and
``inspect`` (a bundle described without decoding it)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import curvesets, grids
from ..bundle import Bundle, read_bundle
from ..errors import BundleError, InvalidParameter
from ..layout import band_names
from ..threshold import check_share
from .plan import Plan, plan_from_header
from .samples import finish, unscaled
from .stages import pipeline


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
    bundle: Any, *, keep: float | None = None, level: int = 0, drop_levels: int | None = None
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

    Returns
    -------
    numpy.ndarray
        ``level=0``: the original's shape and dtype.  ``level=k``: a smaller array of the same
        dtype, with the same channel/coordinate axis.

    Raises
    ------
    BundleError
        For anything wrong with the bytes.
    InvalidParameter
        For a bad ``keep`` or a ``level`` deeper than the bundle's.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import encode_image
    >>> image = np.random.default_rng(0).integers(0, 256, (33, 47), dtype=np.uint8)
    >>> bundle = encode_image(image, lossless=True, level=3)
    >>> decode(bundle, level=2).shape, decode(bundle, drop_levels=2).shape
    ((9, 12), (9, 12))
    """
    if curvesets.is_curve_set(bundle):  # encode_curves' bundles: a list of (n_i, d) arrays
        if keep is not None or level or drop_levels:
            msg = (
                "a curve set decodes whole, at its guaranteed tolerance: keep, level and "
                "drop_levels do not apply to it"
            )
            raise InvalidParameter(msg)
        return curvesets.decode_curves(bundle).curves  # type: ignore[return-value]
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        msg = f"level must be an integer >= 0, not {level!r}"
        raise InvalidParameter(msg)
    if grids.is_grid_bundle(bundle):  # a grid's container around a surface bundle
        return grids.decode_grid(
            bundle, level=level if drop_levels is None else drop_levels, keep=keep
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
    if level > plan.levels:
        msg = f"level {level} is deeper than the bundle's {plan.levels} levels"
        raise InvalidParameter(msg)
    try:
        return _decode(parsed, plan, keep, int(level))
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


def _decode(parsed: Bundle, plan: Plan, keep: float | None, level: int) -> np.ndarray:
    """The encoding pipeline backwards, through the stages the header names, as far as
    ``level`` needs: entropy decoding, dequantization, ``keep``, inverse transform, finish."""
    count = plan.levels - level + 1
    chunks = [parsed.chunk(i) for i in range(count)]
    for index, chunk in enumerate(chunks):
        if not chunk:  # every coder writes a few bytes even for all-zero bands
            msg = f"chunk {index} is empty; no encoder writes an empty chunk"
            raise BundleError(msg)
    stages = pipeline(parsed.header)
    with np.errstate(all="ignore"):
        qcoeffs = stages.coder.decode(chunks, plan.band_shapes()[:count])
        coeffs = stages.quantizer.decode(qcoeffs, plan)
        if keep is not None and keep < 1.0 and len(coeffs) > 1:
            coeffs = stages.transform.keep(coeffs, keep, plan)
        return finish(plan, stages.transform.inverse(coeffs, plan), level)


def inspect(bundle: Any) -> dict[str, Any]:
    """Describe a bundle without decoding it.

    Returns
    -------
    dict
        ``version``, ``kind``, ``shape``, ``dtype``, ``wavelet``, ``boundary``, ``levels``,
        ``colour``, ``lossless``, ``quantizer``, ``coder``, ``psnr`` (the encoder's measured
        PSNR in dB, ``None`` when exact), ``max_error``, ``total_bytes``, ``header_bytes``,
        ``peak`` (in the original's units), ``scale`` (the power of two the values were
        coded under, ``0`` for all but huge or tiny floats), ``bpp`` (images), ``chunks``
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
        "header": header,
    }
    if plan.kind == "image":
        info["bpp"] = 8.0 * total / (plan.shape[0] * plan.shape[1])
    return info
