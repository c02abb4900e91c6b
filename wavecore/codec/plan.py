"""The plan: the caller's arguments checked, and what a bundle's header records about how the
data was transformed (kind, shape, dtype, wavelet, boundaries, levels, colour, padding, peak),
as a :class:`Plan`, to a header dict and back (with the kind-specific consistency checks)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arguments import as_native
from ..blockcoder import PARENT_VERSION, PRIOR_VERSION
from ..bundle import DTYPES, MAX_ELEMENTS
from ..errors import BundleError, InvalidParameter
from ..multilevel import (
    DEFAULT_MOST_CURVE_LEVELS,
    DEFAULT_MOST_LEVELS,
    default_level,
    valid_length,
)
from ..resample import pad_converted_to_fit, pad_to_fit
from .stages import Transform, get_transform, transform_config, transform_of

DEFAULT_CODER = "context"
# The default depths are the library's one rule (multilevel.default_level), not the codec's own.
MAX_IMAGE_LEVELS = DEFAULT_MOST_LEVELS
MAX_CURVE_LEVELS = DEFAULT_MOST_CURVE_LEVELS
_PAD_ALLOWANCE = 64  # padded length <= 2 × length + this (the default levels stay far below)


# --------------------------------------------------------------------------------------------
# Validation of the caller's arguments
# --------------------------------------------------------------------------------------------


def codes_two_d(levels: int, columns: int) -> bool:
    """Whether the block coder codes a 2-D decomposition of ``levels`` levels of a picture
    ``columns`` wide as 2-D (rows and columns): always, also with no levels, whose lone ``cA``
    the coder cannot tell from a 1-D layout's, except a single column (its 1-D layout is that
    column, in long blocks).  As 1-D, a 1 × N picture of no levels was N planes of one value
    each, some 8 µs a pixel to code."""
    return levels > 0 or columns > 1


def positive(value: Any, name: str, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        msg = f"{name} must be a positive number ({what}), not {value!r}"
        raise InvalidParameter(msg)
    if not (math.isfinite(float(value)) and float(value) > 0):
        msg = f"{name} must be a positive finite number ({what}), not {value!r}"
        raise InvalidParameter(msg)
    return float(value)


def one_of(**targets: Any) -> None:
    given = [name for name, value in targets.items() if value is not None]
    if len(given) > 1:
        msg = f"give at most one of {', '.join(targets)}, not {' and '.join(given)}"
        raise InvalidParameter(msg)


def level_arg(level: Any) -> int | None:
    if level is None:
        return None
    if isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 0:
        msg = f"level must be None or an integer >= 0, not {level!r}"
        raise InvalidParameter(msg)
    if level > 30:
        msg = f"level {level} is more than 30; no input is that large"
        raise InvalidParameter(msg)
    return int(level)


def as_array(data: Any, name: str) -> np.ndarray:
    arr = np.asarray(as_native(data))
    if arr.dtype == np.bool_ or arr.dtype.kind not in "uif":
        msg = f"{name} must hold real numbers (integers or floats), not {arr.dtype}"
        raise InvalidParameter(msg)
    if arr.size == 0:
        msg = f"{name} is empty (shape {arr.shape})"
        raise InvalidParameter(msg)
    if arr.size > MAX_ELEMENTS:
        msg = f"{name} has {arr.size} elements, more than the bundle limit {MAX_ELEMENTS}"
        raise InvalidParameter(msg)
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        msg = f"{name} holds NaN or infinite values; only finite numbers can be encoded"
        raise InvalidParameter(msg)
    return arr


def dtype_name(arr: np.ndarray, name: str, *, integer_only: bool = False) -> str:
    allowed = ("uint8", "uint16") if integer_only else DTYPES
    if arr.dtype.name in allowed:
        return arr.dtype.name
    if not integer_only and arr.dtype.kind == "f":
        return "float64"  # longdouble: no wider float is portable, so it comes back as float64
    msg = f"{name} has dtype {arr.dtype}; expected one of {', '.join(allowed)}"
    raise InvalidParameter(msg)


# --------------------------------------------------------------------------------------------
# The plan: everything the header records about how the data was transformed
# --------------------------------------------------------------------------------------------


@dataclass
class Plan:
    kind: str
    shape: tuple[int, ...]
    dtype: str
    wavelet: str
    boundary: tuple[str, ...]
    levels: int
    colour: str
    pads: tuple[tuple[int, int], ...]
    fitted: tuple[int, ...]
    peak: float
    lifting: tuple[str, ...] = ()  # lossless only: the reversible filter per level, finest first
    scale: int = 0  # the coded values are the original's times 2**-scale (see scaled)
    opaque: bool = False  # an image whose alpha channel is fully opaque (see _finish)

    @property
    def axes(self) -> tuple[int, ...]:
        return (0,) if len(self.boundary) == 1 else (0, 1)

    @property
    def coded_two_d(self) -> bool:
        """Whether the block coder codes the bands as 2-D: :func:`codes_two_d` of a 2-D plan."""
        return len(self.boundary) == 2 and codes_two_d(self.levels, self.fitted[1])

    @property
    def context_version(self) -> int | None:
        """The block coder's version for this plan's bands (None: the coder's default).

        Pictures take version 8: version 7, whose directional models pay on edges and
        textures (brick -3.8 %, the grey tuning pictures -1.06 % against version 6), with
        blocks that start from models trained per level class (the grey tuning pictures
        -0.66 % against version 7, astronaut -0.72 %).  Surfaces and grids stay on version 6: on
        the height fields of ``benchmarks/grids.py`` version 7 saved 0.1-0.4 % for 10-20 % of
        the encode time (the integer grid at ``bpp=4``: 31.5 MB/s against 35.2).
        """
        if len(self.boundary) != 2:  # one-dimensional layouts: the coder's own choice
            return None
        if self.kind == "image":
            return PRIOR_VERSION
        if self.kind == "surface":
            return PARENT_VERSION
        return None

    def header(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "shape": list(self.shape),
            "dtype": self.dtype,
            "fit": "pad" if any(after or before for before, after in self.pads) else "none",
            "pads": [list(p) for p in self.pads],
            "fitted": list(self.fitted),
            "wavelet": self.wavelet,
            "boundary": list(self.boundary),
            "levels": self.levels,
            "colour": self.colour,
            "peak": self.peak,
            **self.transform.header_fields(),
            **({"scale": self.scale} if self.scale else {}),
            **({"opaque": True} if self.opaque else {}),
        }

    @property
    def transform(self) -> Transform:
        """The transform stage (a filter bank, or the lossless integer lifting)."""
        return transform_of(self.wavelet, self.boundary, self.lifting)

    def band_shapes(self) -> list[Any]:
        """Subband shapes in ``wavedec``/``wavedec2`` layout, computed without any allocation."""
        return self.transform.band_shapes(self.fitted, self.levels, self.axes)


def fit(
    data: np.ndarray,
    plan_level: int | None,
    wavelet: str,
    boundary: Sequence[str],
    most: int,
    convert: Callable[[np.ndarray, int, int], None] | None = None,
) -> tuple[np.ndarray, tuple[tuple[int, int], ...], int]:
    """``data`` padded to fit the levels (given, or the default for its shape): the fitted
    array, its pads and the levels.  With ``convert`` (see
    :func:`wavecore.resample.pad_converted_to_fit`) the fitted array is float64, always new,
    and ``convert`` writes ``data``'s converted samples into it."""
    axes = (0,) if len(boundary) == 1 else (0, 1)
    level = plan_level
    if level is None:
        level = default_level([data.shape[a] for a in axes], most)
    for axis in axes:
        n = data.shape[axis]
        fitted = valid_length(n, level, boundary[axes.index(axis)], wavelet)
        if fitted > _padded_limit(n):
            msg = (
                f"level {level} is too deep for length {n} (axis {axis}): it would pad it to "
                f"{fitted}, more than {_padded_limit(n)}; give a smaller level"
            )
            raise InvalidParameter(msg)
    if convert is not None:
        padded, pads = pad_converted_to_fit(
            data,
            level,
            axes=axes,
            boundary=list(boundary),
            wavelet=wavelet,
            dtype=np.dtype(np.float64),
            convert=convert,
        )
    else:
        padded, pads = pad_to_fit(data, level, axes=axes, boundary=list(boundary), wavelet=wavelet)
    return padded, tuple((int(b), int(a)) for b, a in pads), level


def _padded_limit(n: int) -> int:
    """The longest padded length a bundle may declare for an original length ``n``.

    Bounding the padding keeps what a decoder allocates proportional to the original's size,
    so a tiny bundle cannot ask for a huge grid by declaring many levels.
    """
    return 2 * n + _PAD_ALLOWANCE


# --------------------------------------------------------------------------------------------
# The header read back into a plan, with the kind-specific checks
# --------------------------------------------------------------------------------------------


def plan_from_header(header: dict[str, Any]) -> Plan:
    """Check the kind-specific consistency of a (generically valid) header."""
    kind, shape, fitted = header["kind"], tuple(header["shape"]), tuple(header["fitted"])
    boundary, pads, levels = tuple(header["boundary"]), header["pads"], header["levels"]
    ranks = {"image": (2, 3), "curve": (1, 2), "surface": (2, 3)}[kind]
    axes_count = 1 if kind == "curve" else 2
    if len(shape) not in ranks or len(boundary) != axes_count:
        msg = f"header: a {kind} cannot have shape {list(shape)} and {len(boundary)} boundaries"
        raise BundleError(msg)
    expected = list(shape) if len(shape) > 1 else [shape[0], 1]
    for axis, (before, after) in enumerate(pads):
        expected[axis] += before + after
    if list(fitted) != expected:
        msg = f"header field 'fitted' is {list(fitted)}; shape and pads make it {expected}"
        raise BundleError(msg)
    for axis in range(axes_count):
        if fitted[axis] > _padded_limit(expected[axis] - sum(pads[axis])):
            msg = f"header field 'pads' pads axis {axis} far beyond its length: {pads[axis]}"
            raise BundleError(msg)
    if kind == "image" and len(shape) == 3 and shape[2] > 4:
        msg = f"header: an image has at most 4 channels, not {shape[2]}"
        raise BundleError(msg)
    colour = header["colour"]
    if colour != "none" and (kind != "image" or len(shape) != 3 or shape[2] < 3):
        msg = f"header: colour transform {colour!r} needs an image with 3 or 4 channels"
        raise BundleError(msg)
    wavelet = header["wavelet"]
    config = transform_config(wavelet, boundary, header.get("lifting"))
    transform = get_transform(config)
    lifting = transform.check_header(header)
    # The header names each stage twice (its name, and again inside its parameters): the two
    # must agree, or a reader that trusts either would be misled.
    coder = header["cparams"].get("coder")
    if header["coder"] != coder:
        msg = f"header field 'coder' is {header['coder']!r}, but 'cparams' names {coder!r}"
        raise BundleError(msg[:200])
    quantizer = "none" if transform.lossless else header["qparams"].get("name")
    if header["quantizer"] != quantizer:
        msg = f"header field 'quantizer' is {header['quantizer']!r}; expected {quantizer!r}"
        raise BundleError(msg[:200])
    return Plan(
        kind,
        shape,
        header["dtype"],
        wavelet,
        boundary,
        levels,
        colour,
        tuple((int(b), int(a)) for b, a in pads),
        fitted,
        float(header["peak"]),
        tuple(lifting),
        _scale_from_header(header),
        _opaque_from_header(header, kind, shape),
    )


def _opaque_from_header(header: dict[str, Any], kind: str, shape: tuple[int, ...]) -> bool:
    """The optional ``opaque`` key (format 1.2): the alpha channel decodes fully opaque."""
    opaque = header.get("opaque", False)
    if opaque is not False and (
        opaque is not True or kind != "image" or len(shape) != 3 or shape[2] not in (2, 4)
    ):
        msg = f"header field 'opaque' must be true, and only for images with alpha, not {opaque!r}"
        raise BundleError(msg[:200])
    return bool(opaque)


def _scale_from_header(header: dict[str, Any]) -> int:
    """The optional ``scale`` key (format 1.2): decoded values are multiplied by 2**scale."""
    scale = int(header.get("scale", 0))  # its type and range are checked by check_header
    if scale and np.dtype(header["dtype"]).kind != "f":
        msg = f"header field 'scale' is {scale}, but only float data is ever scaled"
        raise BundleError(msg)
    return scale
