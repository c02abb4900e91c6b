"""A surface coded at one given quantizer step: no search, no closed-loop refinement, the
fastest lossy coding, and the bundle measured on what the decoder returns.  What
:mod:`wavecore.grids` and :mod:`wavecore.gridcore` build their containers on (through the names
:mod:`.encode` keeps for them); not part of the public API.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..bundle import read_bundle, write_bundle
from ..entropy import encode_levels
from ..errors import BundleError, InvalidParameter
from ..filters import get_wavelet
from ..quantize import DEFAULT_ROUNDING, dequantize_bands, quantize_bands
from .decode import decode
from .plan import (
    DEFAULT_CODER,
    MAX_IMAGE_LEVELS,
    Plan,
    as_array,
    dtype_name,
    fit,
    level_arg,
    positive,
)
from .samples import decompose, finish, measure_errors, peak_of, reconstruct, scaled, unscaled


def coded_units(rmse: float, scale: int) -> float:
    """A distance (an RMSE, a step) in the original's units → the coded units of a plan
    scaled by ``2**scale`` (capped at the largest float, as :func:`samples.unscaled` caps the
    other way: a step that coarse on subnormal data, scaled up by ``2**1073``, quantizes
    everything to zero either way)."""
    return unscaled(rmse, -scale) if scale else rmse


def encode_surface_at_step(
    grid: Any,
    step: float,
    *,
    level: int | None = None,
    wavelet: str = "cdf97",
    boundary: tuple[str, str] = ("open", "open"),
    rounding: float = DEFAULT_ROUNDING,
) -> tuple[bytes, np.ndarray]:
    """A surface bundle quantized once at ``step`` (the base step of the dead-zone quantizer,
    in the data's units): no search and no closed-loop refinement, the fastest lossy coding.

    Returns the bundle and what :func:`wavecore.decode` returns for it (the encoder's own
    reconstruction, from the same integers and parameters; decoded again only if the stored
    parameters did not survive the header exactly).  For :mod:`wavecore.grids`, whose outlier
    pass needs a core of a known step, not a PSNR; not part of the public API.
    """
    arr = as_array(grid, "grid")
    level = level_arg(level)
    dtype = dtype_name(arr, "grid")
    arr, scale = scaled(arr)
    # No copy of float64 data (the transform only reads it); a Zarr chunk's peak memory.
    data = np.asarray(arr, dtype=np.float64)
    bank = get_wavelet(wavelet)
    fitted, pads, levels = fit(data, level, bank.name, boundary, MAX_IMAGE_LEVELS)
    plan = Plan(
        "surface",
        arr.shape,
        dtype,
        bank.name,
        tuple(boundary),
        levels,
        "none",
        pads,
        fitted.shape,
        peak_of(data, dtype, "surface"),
        scale=scale,
    )
    coded_step = positive(coded_units(step, scale), "step", "a quantizer step")
    bounds = list(plan.boundary)
    coeffs = decompose(plan, fitted)
    quantized, qparams = quantize_bands(
        coeffs,
        coded_step,
        wavelet=plan.wavelet,
        boundary=bounds,
        axes=plan.axes,
        rounding=rounding,
        refine=0,
    )
    del coeffs  # each full-size temporary is let go once used: peak memory per Zarr chunk
    return bundle_from_quantized(plan, quantized, qparams, arr, "input")


def reconstructed_from_quantized(
    plan: Plan, quantized: list[Any], qparams: dict[str, Any]
) -> np.ndarray:
    """What the decoder returns for a surface plan's quantized bands (the plan's units, before
    any unscaling), with no entropy coding: a caller that may reject the step (the grids' RMSE
    search) measures this first and codes only the step it keeps."""
    dequantized = dequantize_bands(
        quantized, qparams, wavelet=plan.wavelet, boundary=list(plan.boundary), axes=plan.axes
    )
    samples = reconstruct(plan, dequantized)
    del dequantized
    output = finish(plan, samples, 0)
    del samples
    return output


def bundle_from_quantized(
    plan: Plan,
    quantized: list[Any],
    qparams: dict[str, Any],
    coded: np.ndarray,
    what: str,
    output: np.ndarray | None = None,
) -> tuple[bytes, np.ndarray]:
    """Code a surface plan's quantized bands into its bundle, measured on what the decoder
    returns: the bundle and that output.  ``coded`` is the (scaled) samples the plan was made
    from; ``what`` names them in the error a bundle that cannot be stored raises.  ``output``,
    if given, is :func:`reconstructed_from_quantized` of the same bands (not made again)."""
    chunks, cparams = encode_levels(
        quantized, coder=DEFAULT_CODER, version=plan.context_version, two_d=plan.coded_two_d
    )
    if output is None:
        output = reconstructed_from_quantized(plan, quantized, qparams)
    del quantized
    scale = plan.scale
    decoded = np.ldexp(output, -scale) if scale else output
    psnr, largest = measure_errors(plan, coded, decoded)
    header = plan.header()
    header.update(
        quantizer=str(qparams.get("name", "deadzone")),
        qparams=qparams,
        coder=str(cparams.get("coder", DEFAULT_CODER)),
        cparams=cparams,
        psnr=psnr,
        max_error=unscaled(largest, scale),
    )
    try:
        bundle = write_bundle(header, chunks)
    except BundleError as exc:
        msg = f"this {what} cannot be stored in a bundle: {exc}"
        raise InvalidParameter(msg) from exc
    if read_bundle(bundle).header.get("qparams") != qparams:
        output = decode(bundle)  # the header rounded a parameter: take the decoder's result
    return bundle, output
