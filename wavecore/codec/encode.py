"""The front ends: ``encode_image``, ``encode_curve`` and ``encode_surface`` check their input,
make the plan and hand it to the rate control; lossless images take their own pipeline."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from .. import _heap
from ..arguments import closed_flags
from ..bundle import read_bundle, with_header
from ..errors import BitrateTooLow, BundleError, InvalidParameter
from ..filters import get_wavelet
from ..threshold import check_share
from .choice import AUTO, choose_colour, choose_image_wavelet
from .decode import decode

# The one-step surface coding's first home, where wavecore.grids and wavecore.gridcore find it.
from .fixedstep import bundle_from_quantized as bundle_from_quantized
from .fixedstep import coded_units
from .fixedstep import encode_surface_at_step as encode_surface_at_step
from .fixedstep import reconstructed_from_quantized as reconstructed_from_quantized
from .plan import (
    MAX_CURVE_LEVELS,
    MAX_IMAGE_LEVELS,
    Plan,
    as_array,
    dtype_name,
    fit,
    level_arg,
    one_of,
    positive,
)
from .ratecontrol import encode_lossy
from .replication import OVERHEAD as REPLICATION_OVERHEAD
from .replication import replication_factor
from .replication import wrap as wrap_replicated
from .reversible import encode_lossless_image
from .samples import (
    fitted_samples,
    is_opaque,
    measure_errors,
    peak_of,
    scaled,
    scaled_tolerance,
    unscaled,
)
from .stages import quantizer_of

# Freed working arrays stay mapped between codings instead of being faulted in afresh by each
# (a tenth of a 512² encode's CPU time; see wavecore._heap).
_heap.keep_freed_memory()

#: Without ``keep``/``tolerance``, curves are coded to this fraction of their bounding-box
#: diagonal as the largest point deviation.
DEFAULT_RELATIVE_TOLERANCE = 1e-3

#: The values of ``encode_image(effort=...)``: ``"default"`` and ``"max"`` (its earlier name,
#: kept) code lossless pictures with the lossless coder of :mod:`wavecore.losslesscoder`;
#: ``"fast"`` with the block coder (faster, a few per cent bigger, regions by blocks).
EFFORTS = ("default", "max", "fast")


#: What an encoder returns: a bundle, or a bundle and its output (the grids' surface coding).
_Encoded = TypeVar("_Encoded")


def _refuses_as_parameter(encoder: Callable[..., _Encoded]) -> Callable[..., _Encoded]:
    """An encoder's ``BundleError`` (say, a header past the format's limits) is its input's
    fault: raise it as ``InvalidParameter``, so that callers (the service) never mistake an
    encode for a bad bundle."""

    @functools.wraps(encoder)
    def checked(*args: Any, **kwargs: Any) -> _Encoded:
        try:
            return encoder(*args, **kwargs)
        except BundleError as exc:
            msg = f"this input cannot be stored in a bundle: {exc}"
            raise InvalidParameter(msg) from exc

    return checked


@_refuses_as_parameter
def encode_image(
    image: Any,
    *,
    wavelet: str = AUTO,
    level: int | None = None,
    keep: float | None = None,
    quality: float | None = None,
    bpp: float | None = None,
    lossless: bool = False,
    effort: str = "default",
) -> bytes:
    """Encode an image into a bundle.

    Parameters
    ----------
    image : array_like
        ``(H, W)`` grey or ``(H, W, C)`` with ``C`` from 1 to 4 (grey, grey + alpha, RGB, RGBA);
        ``uint8``, ``uint16`` or float, any byte order and layout.  Any finite float works,
        subnormals to ``±1.7e308`` (coded in an exactly scaled domain, the header's
        ``scale``).  An alpha channel that decodes exactly, as an opaque one always does, is
        left out of ``quality`` and of the recorded PSNR, which are then the colour channels'.
    wavelet : str
        The wavelet for lossy coding.  ``"auto"`` (the default) chooses per picture:
        ``"cdf97"``, the one that wins the measured rate–distortion on photographs
        (docs/benchmarks.md), unless most 2 × 2 blocks of pixels are flat (binary and
        two-tone graphics, pictures nearly enlarged by pixel replication), where ``"haar"``
        takes 45–70 % fewer bytes (:mod:`wavecore.codec.choice`).  Or name one: ``"cdf97"``,
        ``"bspline2"`` (the paper's, smooth, with interpolated ends), ``"haar"`` or an alias
        (see :func:`wavecore.wavelet_names`).  The bundle records the wavelet used, so any
        bundle decodes alike.
    level : int, optional
        Decomposition levels; ``None`` picks up to 5, keeping the coarsest band at least about
        4 pixels a side.  Any image size works: the image is edge-padded to a size that fits,
        and the padding is recorded and cropped again.  Lossless: ``None`` codes none or one
        level, by entropy, close calls by coding a sample both ways (with ``effort="fast"``: 2
        and 3 levels, fewer if the image is small, keeping the smaller bundle).
    keep : float, optional
        Fraction of detail coefficients kept (the smallest ``1 - keep`` by their effect on the
        reconstruction are removed), quantized finely (about 60 dB).
    quality : float, optional
        Target PSNR in dB, met or exceeded (measured on the decoded image, in the original
        dtype, against the dtype's peak: 255, 65535, or 1 for floats in ``[0, 1]``, else the
        data range).
    bpp : float, optional
        Target bits per pixel: ``8 × len(bundle) / (H × W)``, header included; never exceeded
        and within 3 % below.  A ``uint8`` or ``uint16`` picture then also gets a restoration
        filter where it pays and fits in the bytes left under the budget
        (:mod:`wavecore.restoration`: 0.3–2.6 % fewer bytes at the same PSNR on photographs).
    lossless : bool
        Code bit-exactly (``uint8``/``uint16`` only), after the reversible colour transform, by
        prediction or integer lifting (see ``effort``); ``wavelet`` is then not used.
    effort : {"default", "max", "fast"}
        How a lossless encode codes (only ``lossless=True`` takes anything but ``"default"``).
        ``"default"`` (``"max"`` is the same): the lossless coder of
        :mod:`wavecore.losslesscoder` (JPEG XL's weighted predictor, three mixed models per
        bit), smaller than JPEG XL e7 on grey and WebP lossless on colour; a region decodes the
        stripes of rows it touches, a coarser level lifts the decoded picture, and damage loses
        a whole level.  ``"fast"``: the block context coder, 3–7 % bigger in 0.6–0.85× the
        encode + decode wall time (0.55–0.75× the CPU), with regions, coarser levels and
        damage by code-blocks.  Either decodes with :func:`decode`.

    With none of ``keep``/``quality``/``bpp`` the image is coded to ``quality=40`` dB.

    A picture enlarged by pixel replication (each pixel of a source at least 8 pixels a side
    repeated ``f × f`` times, ``f`` a power of two: pixel art, scikit-image's ``moon``) is
    coded as its source, with these arguments, and decodes to the enlarged picture again
    (:mod:`wavecore.codec.replication`, bundle format 7.0): the PSNR is the source's, a
    ``bpp`` target keeps its bytes (``f²`` times the rate for the source), ``keep`` counts
    the source's details, and ``level`` counts the replication's levels first (one too deep
    for the source codes the whole picture).  ``inspect(bundle)["replicated"]`` gives ``f``.

    Returns
    -------
    bytes
        The bundle (see :mod:`wavecore.bundle`).

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import decode, inspect
    >>> image = (np.add.outer(np.arange(40), np.arange(30)) * 3).astype(np.uint8)
    >>> bundle = encode_image(image, quality=35)
    >>> out = decode(bundle)
    >>> out.shape, out.dtype, inspect(bundle)["psnr"] >= 35
    ((40, 30), dtype('uint8'), True)
    >>> bool(np.array_equal(decode(encode_image(image, lossless=True)), image))
    True
    """
    one_of(keep=keep, quality=quality, bpp=bpp)
    arr = as_array(image, "image")
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and not 1 <= arr.shape[2] <= 4):
        msg = f"image must be (H, W) or (H, W, C) with 1 to 4 channels, not shape {arr.shape}"
        raise InvalidParameter(msg)
    level = level_arg(level)
    if not isinstance(effort, str) or effort not in EFFORTS:
        msg = f"effort must be one of {', '.join(map(repr, EFFORTS))}, not {effort!r}"
        raise InvalidParameter(msg)
    if effort != "default" and not lossless:
        msg = f"effort={effort!r} applies only with lossless=True; lossy encodes take 'default'"
        raise InvalidParameter(msg)
    if lossless and (keep is not None or quality is not None or bpp is not None):
        msg = "lossless=True cannot be combined with keep, quality or bpp"
        raise InvalidParameter(msg)
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    quality = None if quality is None else positive(quality, "quality", "a PSNR in dB")
    bpp = None if bpp is None else positive(bpp, "bpp", "bits per pixel")
    factor = replication_factor(arr)
    if factor == 1:
        return _encode_picture(arr, wavelet, level, keep, quality, bpp, lossless, effort)
    # a picture enlarged by pixel replication: its source coded in the same bytes
    log2_factor = factor.bit_length() - 1
    source = np.ascontiguousarray(arr[::factor, ::factor])
    source_bpp = None
    if bpp is not None:
        budget_bits = bpp * arr.shape[0] * arr.shape[1] - 8 * REPLICATION_OVERHEAD
        if budget_bits <= 0:  # not even the wrapper fits: the plain picture's refusal says so
            return _encode_picture(arr, wavelet, level, keep, quality, bpp, lossless, effort)
        source_bpp = budget_bits / (source.shape[0] * source.shape[1])
    source_level = None if level is None else max(0, level - log2_factor)
    try:
        inner = _encode_picture(
            source, wavelet, source_level, keep, quality, source_bpp, lossless, effort
        )
    except BitrateTooLow as exc:
        smallest = exc.smallest_bytes + REPLICATION_OVERHEAD
        msg = (
            f"bpp {bpp} is below what this image can be coded in: its smallest bundle needs "
            f"{smallest} bytes = {8 * smallest / (arr.shape[0] * arr.shape[1]):.4f} bpp "
            f"(header included)"
        )
        raise BitrateTooLow(msg, smallest) from None
    except InvalidParameter:
        if source_level is None or source_level == 0:
            raise
        # a level too deep for the source, which the whole picture may take: code it whole
        return _encode_picture(arr, wavelet, level, keep, quality, bpp, lossless, effort)
    return wrap_replicated(inner, log2_factor)


def _encode_picture(
    arr: np.ndarray,
    wavelet: str,
    level: int | None,
    keep: float | None,
    quality: float | None,
    bpp: float | None,
    lossless: bool,
    effort: str,
) -> bytes:
    """:func:`encode_image` of a picture that is not enlarged by pixel replication, its
    arguments checked."""
    if lossless:
        return encode_lossless_image(arr, level, effort)
    dtype = dtype_name(arr, "image")
    arr, scale = scaled(arr)
    colour = choose_colour(arr) if arr.ndim == 3 and arr.shape[2] >= 3 else "none"
    try:
        bank = get_wavelet(choose_image_wavelet(arr) if wavelet == AUTO else wavelet)
    except InvalidParameter as exc:  # images take "auto" too: say so
        msg = f"{exc}, or {AUTO!r} (the default: chosen per picture)"
        raise InvalidParameter(msg) from None
    # Images use the paper's endpoint-interpolating rows; a wavelet without them (cdf97's
    # symmetric extension) uses its own non-periodic boundary.
    boundary = ("open", "open") if "open" in bank.rules else (next(iter(bank.rules)),) * 2
    fitted, pads, levels = fitted_samples(arr, colour, level, bank.name, boundary, MAX_IMAGE_LEVELS)
    plan = Plan(
        "image",
        arr.shape,
        dtype,
        bank.name,
        boundary,
        levels,
        colour,
        pads,
        fitted.shape,
        peak_of(arr, dtype, "image"),
        scale=scale,
        opaque=is_opaque(arr),
    )
    return encode_lossy(plan, arr, fitted, keep=keep, quality=quality, bpp=bpp, tolerance=None)


@_refuses_as_parameter
def encode_curve(
    points: Any,
    *,
    closed: bool | None = None,
    level: int | None = None,
    keep: float | None = None,
    tolerance: float | None = None,
    wavelet: str = "bspline2",
    boundary: str | None = None,
) -> bytes:
    """Encode a curve, ``(n, d)`` points (or ``(n,)`` samples), into a bundle.

    Parameters
    ----------
    points : array_like
        The points in order, any ``n >= 1`` and ``d >= 1``, any finite values (huge or tiny
        floats are coded in an exactly scaled domain).  The curve is extended at its end to
        a length that fits (``wavecore.pad_to_fit``: repeated last point when open, a straight
        blend back to the first point when closed); the decoder gives back exactly ``n`` points.
    closed : bool, optional
        A closed curve (periodic boundary) or an open one (endpoint interpolating, the
        default).
    level : int, optional
        Levels; ``None`` picks up to 8, keeping at least about 4 coarse points.
    keep : float, optional
        Fraction of detail vectors kept (the rest, smallest effect first, removed).
    tolerance : float, optional
        The largest allowed distance between an original point and its decoded point; verified
        on the decoded bundle.  Default: ``1e-3`` × the bounding-box diagonal.
    wavelet : str
        ``"bspline2"`` (the paper's, smooth; the default), ``"haar"`` (piecewise constant: a
        staircase once details are dropped) or ``"cdf97"``.
    boundary : {"open", "closed"}, optional
        The same choice as ``closed``, spelled as elsewhere in the library: ``"closed"`` is
        ``closed=True``.  Give either; both is accepted only when they agree.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import decode, inspect
    >>> t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    >>> circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    >>> bundle = encode_curve(circle, closed=True, tolerance=1e-3)
    >>> out = decode(bundle)
    >>> out.shape, bool(np.max(np.linalg.norm(out - circle, axis=1)) <= 1e-3)
    ((50, 2), True)
    """
    one_of(keep=keep, tolerance=tolerance)
    arr = as_array(points, "points")
    if arr.ndim not in (1, 2):
        msg = f"points must be (n, d) or (n,), not shape {arr.shape}"
        raise InvalidParameter(msg)
    (is_closed,) = closed_flags(closed, boundary, 1)
    level = level_arg(level)
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    dtype = dtype_name(arr, "points")
    arr, scale = scaled(arr)
    data = arr.astype(np.float64).reshape(arr.shape[0], -1)
    boundaries = ("closed",) if is_closed else ("open",)
    bank = get_wavelet(wavelet)
    fitted, pads, levels = fit(data, level, bank.name, boundaries, MAX_CURVE_LEVELS)
    diagonal = float(np.linalg.norm(data.max(axis=0) - data.min(axis=0)))
    plan = Plan(
        "curve",
        arr.shape,
        dtype,
        bank.name,
        boundaries,
        levels,
        "none",
        pads,
        fitted.shape,
        _rounded_up(peak_of(data, dtype, "curve"), CURVE_PEAK_BITS),
        scale=scale,
    )
    if keep is None:
        if tolerance is None:
            tolerance = DEFAULT_RELATIVE_TOLERANCE * (diagonal if diagonal > 0 else 1.0)
        else:  # in the coded (scaled) units
            tolerance = scaled_tolerance(positive(tolerance, "tolerance", "a distance"), scale)
    bundle = encode_lossy(plan, arr, fitted, keep=keep, quality=None, bpp=None, tolerance=tolerance)
    return _with_float32_step(bundle, plan, arr, tolerance)


#: A curve's ``peak`` (its data range, the reference of its PSNR) is rounded up to this many
#: significant bits, which bundle format 4.0 stores in 3 bytes (a float64 takes 9): the PSNR
#: moves by at most 0.017 dB.
CURVE_PEAK_BITS = 9


def _rounded_up(value: float, bits: int) -> float:
    """The smallest number of ``bits`` significant bits at or above ``value`` (> 0)."""
    mantissa, exponent = math.frexp(value)
    rounded = math.ldexp(math.ceil(math.ldexp(mantissa, bits)), exponent - bits)
    return rounded if math.isfinite(rounded) else value


def _with_float32_step(
    bundle: bytes, plan: Plan, coded: np.ndarray, tolerance: float | None
) -> bytes:
    """``bundle`` with its quantizer step rounded to a float32 (4 bytes in format 4.0, not 8)
    when the decoded curve still meets ``tolerance``; its errors measured again.

    The rate control picks the step as a float64; the nearest float32 is within 2**-24 of it,
    so the decoded points move by some 1e-7 of their magnitude.  The result is decoded and
    measured as the rate control measures (and kept only within the tolerance), so the header's
    ``psnr`` and ``max_error`` are those of what it decodes to.
    """
    header = read_bundle(bundle).header
    qparams = header["qparams"]
    field = quantizer_of(header).step_field
    if field is None:
        return bundle
    step = float(qparams[field])
    single = float(np.float32(step))
    if single == step or not (math.isfinite(single) and single > 0):
        return bundle
    trial = {**header, "qparams": {**qparams, field: single}}
    decoded = decode(with_header(bundle, trial))
    if plan.scale:
        decoded = np.ldexp(decoded, -plan.scale)
    psnr, largest = measure_errors(plan, coded, decoded)
    if tolerance is not None and largest > tolerance:
        return bundle
    trial.update(psnr=psnr, max_error=unscaled(largest, plan.scale))
    return with_header(bundle, trial)


@_refuses_as_parameter
def encode_surface(
    grid: Any,
    *,
    closed: tuple[bool, bool] | None = None,
    level: int | None = None,
    keep: float | None = None,
    quality: float | None = None,
    wavelet: str = "bspline2",
    boundary: str | tuple[str, str] | None = None,
    max_error: float | None = None,
    rmse: float | None = None,
    psnr: float | None = None,
    bpp: float | None = None,
) -> bytes:
    """Encode a surface, a ``(U, V, d)`` grid of points or a ``(U, V)`` height field.

    Parameters
    ----------
    grid : array_like
        The grid; each of the two grid axes is padded to a length that fits and cropped again.
        Any finite values (huge or tiny floats are coded in an exactly scaled domain).
    closed : pair of bool, optional
        Per grid axis, periodic (``True``, e.g. the circles of a surface of revolution) or open
        (the default).
    level : int, optional
        Levels; ``None`` picks up to 5.
    keep : float, optional
        Fraction of detail vectors kept.
    quality : float, optional
        Target PSNR in dB against the data range (largest minus smallest value), met or
        exceeded.  Default: 40 dB.
    wavelet : str
        ``"bspline2"`` (the paper's, the default), ``"haar"``, ``"cdf97"`` or an alias (see
        :func:`wavecore.wavelet_names`); the bundle records it.
    boundary : str or pair of str, optional
        The same choice as ``closed``, spelled ``"open"`` / ``"closed"`` (one for both axes, or
        one per axis).  Give either; both is accepted only when they agree.
    max_error : float, optional
        A bound on the absolute error of every value (each coordinate of each point); the
        result is a grid bundle (:func:`wavecore.encode_grid`, whose outlier corrections
        guarantee it), decoded by :func:`wavecore.decode` alike.
    rmse : float, optional
        Target root-mean-square error over all values, met or beaten.
    psnr : float, optional
        The same as ``quality``, under the name :func:`wavecore.encode_grid` uses.
    bpp : float, optional
        Bits per grid point (``8 × len(bundle) / (U × V)``, header included), never exceeded.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore import decode, inspect
    >>> u, v = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 24), indexing="ij")
    >>> bundle = encode_surface(np.sin(3 * u) * np.cos(2 * v), quality=50)
    >>> decode(bundle).shape, inspect(bundle)["psnr"] >= 50
    ((20, 24), True)
    """
    one_of(keep=keep, quality=quality, max_error=max_error, rmse=rmse, psnr=psnr, bpp=bpp)
    if max_error is not None:  # the grid container's outlier pass keeps the bound
        return _bounded_surface(grid, closed, boundary, level, wavelet, max_error)
    quality = psnr if psnr is not None else quality
    return _encode_surface(grid, closed, boundary, level, keep, quality, wavelet, rmse, bpp)


@_refuses_as_parameter
def encode_surface_and_output(
    grid: Any, *, bpp: float, wavelet: str, level: int | None, boundary: tuple[str, str]
) -> tuple[bytes, np.ndarray]:
    """:func:`encode_surface` of a float64 height field to ``bpp``, and what
    :func:`wavecore.decode` returns for its bundle: the rate control's own reconstruction of
    the bundle it settled on where it made one, else the bundle decoded.  For
    :mod:`wavecore.grids`, which measures that output (a decoding was a quarter of an int16
    grid's ``bpp`` encode), and whose rate control samples every third code-block of each
    level of several (``half_sample``); the package does not export it."""
    outputs: list[np.ndarray | None] = []
    bundle = _encode_surface(
        grid, None, boundary, level, None, None, wavelet, None, bpp, outputs, half_sample=True
    )
    output = outputs[0] if outputs else None
    if output is None or read_bundle(bundle).header.get("scale"):
        return bundle, decode(bundle)  # (a scaled plan's reconstruction is in coded units)
    return bundle, output


# One home for what both surface encoders share: the plan, then the rate control.
def _encode_surface(
    grid: Any,
    closed: tuple[bool, bool] | None,
    boundary: str | tuple[str, str] | None,
    level: int | None,
    keep: float | None,
    quality: float | None,
    wavelet: str,
    rmse: float | None,
    bpp: float | None,
    outputs: list[np.ndarray | None] | None = None,
    *,
    half_sample: bool = False,
) -> bytes:
    arr = as_array(grid, "grid")
    if arr.ndim not in (2, 3):
        msg = f"grid must be (U, V) or (U, V, d), not shape {arr.shape}"
        raise InvalidParameter(msg)
    flags = closed_flags(closed, boundary, 2)
    level = level_arg(level)
    keep = None if keep is None else check_share(keep, "keep", "details to keep")
    quality = None if quality is None else positive(quality, "quality", "a PSNR in dB")
    bpp = None if bpp is None else positive(bpp, "bpp", "bits per grid point")
    dtype = dtype_name(arr, "grid")
    arr, scale = scaled(arr)
    data = arr.astype(np.float64)
    bank = get_wavelet(wavelet)
    boundaries = tuple("closed" if c else "open" for c in flags)
    fitted, pads, levels = fit(data, level, bank.name, boundaries, MAX_IMAGE_LEVELS)
    plan = Plan(
        "surface",
        arr.shape,
        dtype,
        bank.name,
        boundaries,
        levels,
        "none",
        pads,
        fitted.shape,
        peak_of(data, dtype, "surface"),
        scale=scale,
    )
    if rmse is not None:
        # PSNR against the plan's peak is measured on exactly what decode returns; the tiny
        # margin keeps the conversion's rounding from leaving the RMSE a hair above the target.
        target = positive(rmse, "rmse", "a root-mean-square error")
        quality = 20.0 * math.log10(plan.peak / coded_units(target, scale)) + 1e-6
        if quality <= 0:  # any coding meets so loose a target: code coarsely
            quality = 1e-3
    return encode_lossy(
        plan,
        arr,
        fitted,
        keep=keep,
        quality=quality,
        bpp=bpp,
        tolerance=None,
        outputs=outputs,
        half_sample=half_sample,
    )


def _bounded_surface(
    grid: Any, closed: Any, boundary: Any, level: Any, wavelet: str, max_error: Any
) -> bytes:
    from .. import grids  # the grid container composes this codec: imported when used

    arr = grids.checked_grid(grid, (2, 3), "grid")
    flags = closed_flags(closed, boundary, 2)
    return grids.encode_layout(
        arr,
        grids.LAYOUT_FIELD if arr.ndim == 2 else grids.LAYOUT_POINTS,
        wavelet=wavelet,
        level=level,
        boundary=("closed" if flags[0] else "open", "closed" if flags[1] else "open"),
        max_error=max_error,
    )
