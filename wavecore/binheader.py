"""The binary header of bundle formats 2.0, 3.0, 3.1 and 4.0 on: the codec's header dict in a
few dozen bytes.

:func:`pack` maps the header dict that the codec builds (``_Plan.header()`` plus the quantizer,
coder and error keys) to bytes, and :func:`unpack` maps the bytes back to an equal dict, so the
codec never sees the difference between format 1.x (JSON) and 2.0.  ``docs/bundle-format.md``
specifies the bytes; in short, in this order:

* four flag bytes: the enumerated fields (``kind``, ``colour``, ``dtype``, ``wavelet``,
  ``boundary``, the quantizer and the coder) as small codes, and flags saying which optional
  fields follow and which fields take their implied value (``fitted`` = ``shape`` + ``pads``,
  ``pads`` all zero or zero before, ``rounding`` = 0.27);
* unsigned LEB128 varints for ``levels``, ``shape``, ``fitted`` and ``pads`` (then, for colour
  code 3, the chroma weight of ``"rct-p<w>"``, zigzagged; a weight of 0 stands for a
  per-picture colour rotation, ``"klt:<a>,<b>,<c>"``, whose three angles follow, zigzagged);
* numbers in one *number* form (a varint whose low four bits say how to read it: a short
  decimal, an integer, a float32 or a float64, or null) — every value comes back bit for bit,
  except ``max_error``, which may be stored as the float32 at or above it (a diagnostic that
  decoding never reads; it stays an upper bound);
* each stage's configuration once: the quantizer's ``step`` as a float64, its per-band
  ``weights`` (four significant digits, see :func:`quantize.band_weights`) as one 16-bit code
  each, the coder's ``version``, ``two_d`` and ``block`` in one byte;
* an optional *extension*: a raw-DEFLATE JSON object holding whatever the compact fields cannot
  say (unknown keys, parameters of another shape, wavelet names not in the table).  So every
  header that :func:`wavecore.bundle.check_header` accepts packs, and unpacks to an equal dict.

Format 3.1 (:func:`pack` with ``pinned``, :func:`unpack_pinned`) adds a quantizer code, 3: the
``deadzone`` quantizer whose weights the plan gives; only the *pinned* ones are stored (each
with its band's index), then a CRC-8 of them all (:func:`weights_check`); and a coder code, 3:
the ``context`` coder whose chunks delimit themselves (the bundle then stores no chunk
lengths), which every 3.1 header has.

Format 4.0 (:func:`pack` with ``major=4``, :func:`unpack_from`) has the same fields, with
no length before them, and gives three flag bits new meanings: the weights are derived from
the plan (then not stored; ``fitted`` is always derived, or in the extension), the step is a
float32 (4 bytes), the coder's parameters are the default ones (no byte).  Its numbers have a
binary form ``k · 2**e`` in place of the decimal ``k · 1000``.

Every read goes through one reader whose errors (:class:`~wavecore.errors.BundleError`) name
the field being read, as NumPy's ``.npy`` reader does; no input makes :func:`unpack` raise
anything else, read past the end, or allocate more than a small multiple of its input.
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from typing import Any

import numpy as np

from .colour import KLT_LIMIT, KLT_PREFIX, klt_matrix
from .errors import BundleError
from .restoration import (
    CLASSES,
    FILTERED_DTYPES,
    RECORD_GUARD,
    TAPS,
    check_restore,
    colour_channels,
    largest_activity,
)
from .varints import encode_varint, unzigzag, zigzag

__all__ = ["MAX_VARINT_BYTES", "PinnedWeights", "pack", "unpack", "unpack_pinned", "weights_check"]

# The format's code tables.  A code is an index into its table: never reorder them, only append
# (a new value is a new minor version; an older reader refuses the unknown code by name).
KIND_CODES = ("image", "curve", "surface")
COLOUR_CODES = ("none", "ycbcr", "rct")
#: Colour code 3: the lossless RCT with Cr predicted from Cb, ``"rct-p<w>"``; its weight ``w``
#: follows the pads as a zigzag varint.
COLOUR_PREDICTED, PREDICTED_PREFIX = 3, "rct-p"
#: Colour code 3 with the weight 0 (never an ``rct-p``: the RCT alone is code 2) is the
#: per-picture colour rotation ``"klt:<a>,<b>,<c>"``; its three angles follow as zigzag
#: varints.  A reader from before it reads the name ``"rct-p0"``, which the header check
#: refuses by name.
MATRIX_WEIGHT = 0
DTYPE_CODES = (
    "uint8",
    "uint16",
    "float32",
    "float64",
    "float16",
    "int8",
    "int16",
    "int32",
    "int64",
    "uint32",
)
#: Code 0 means "the name is in the extension"; code 4 is ``reversible`` with its ``lifting``.
WAVELET_CODES = ("", "bspline2", "haar", "cdf97", "reversible")
BOUNDARY_CODES = ("open", "closed", "symmetric")
LIFTING_CODES = ("legall53", "haar", "bspline2", "511c")
#: Code 2 means "the name is in the extension".
QUANTIZER_CODES = ("none", "deadzone")
#: Quantizer code 3 (format 3.1): ``deadzone`` whose weights the plan gives, but for a few
#: *pinned* ones stored with their index, and a one-byte check of them all.  A 3.0 reader
#: refuses it by name ("binary header field 'quantizer' … unknown code 3").
DERIVED_DEADZONE = 3
CODER_CODES = ("context", "zlib")
IN_EXTENSION = 2
#: Coder code 3 (format 3.1): the ``context`` coder (its parameters compact) whose chunks
#: delimit themselves, so the bundle stores no chunk lengths.  Every 3.1 bundle has it, so a
#: 3.0 reader refuses each one by name ("binary header field 'coder' … unknown code 3")
#: before it reads the chunk table it would misread.
DELIMITED_CONTEXT = 3
#: The coder byte's version nibble 9: the context coder's version 8 (``RESTORED_BASE``) with a
#: restoration record after the byte (the header's ``restore``: :mod:`wavecore.restoration`).
#: A reader from before it refuses such a header by the record's guard bytes
#: (:data:`restoration.RECORD_GUARD`), which it reads as a malformed PSNR.
RESTORED_VERSION, RESTORED_BASE = 9, 8

#: The rounding the codec uses today; a flag stands for it.
DEFAULT_ROUNDING = 0.27
#: Weight codes: ``(e - WEIGHT_EXPONENT_MIN) * 9000 + (m - 1000)`` for ``m · 10**e``.
WEIGHT_EXPONENT_MIN = -9
WEIGHT_CODE_LIMIT = 7 * 9000  # seven decades, 1e-6 … 9.999
MAX_VARINT_BYTES = 10
_MAX_SIZE = 2**40  # any size, length or count a header may declare (the bundle checks less)
_MAX_EXTENSION = 65535
#: The largest number-form varint (ten varint bytes hold 70 bits).
_MAX_NUMBER_HEAD = 2**70 - 1

# The number form: a varint ``V``; ``V & 15`` says how to read it.
_NUM_DECIMAL_MIN, _NUM_DECIMAL_MAX = -8, 3  # codes 0 … 11: ``k · 10**(code - 8)``
#: Format 4.0: code 11 is the *binary* form ``k · 2**e`` (``k = zigzag⁻¹(V >> 4)``, odd, then
#: ``e`` as a zigzag varint) instead of the decimal ``k · 1000``: a value with few significant
#: bits (a curve's ``peak``, rounded up to 9 of them) takes three bytes at any magnitude.
_NUM_BINARY = 11
_BINARY_EXPONENT_MAX = 1100
_NUM_NULL, _NUM_FLOAT32, _NUM_FLOAT64, _NUM_INT = 12, 13, 14, 15

_FLOAT32_NORMAL = 2.0**-126  # the smallest normal float32
_F64 = struct.Struct("<d")
_F32 = struct.Struct("<f")
_U16 = struct.Struct("<H")

# Keys the compact form writes; anything else goes to the extension.
_CORE_KEYS = (
    "kind",
    "shape",
    "dtype",
    "fit",
    "pads",
    "fitted",
    "wavelet",
    "boundary",
    "levels",
    "colour",
    "peak",
    "quantizer",
    "qparams",
    "coder",
    "cparams",
    "psnr",
    "max_error",
)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def _same_float(a: float, b: float) -> bool:
    return _F64.pack(a) == _F64.pack(b)


def _decimal(value: float) -> tuple[int, int] | None:
    """``(k, e)`` with ``value == k · 10**e`` exactly as parsed, or None."""
    if not math.isfinite(value):
        return None
    try:
        sign, digits, exponent = Decimal(repr(value)).as_tuple()
    except InvalidOperation:  # pragma: no cover - repr of a finite float always parses
        return None
    assert isinstance(exponent, int)
    k = int("".join(map(str, digits)) or "0") * (-1 if sign else 1)
    if k == 0:
        return 0, 0
    while k % 10 == 0:  # 1.0 is 1e0, not 10e-1
        k, exponent = k // 10, exponent + 1
    return k, exponent


def _binary(value: float) -> tuple[int, int] | None:
    """``(k, e)`` with ``value == k · 2**e`` and ``k`` odd, or None (zero, not finite)."""
    if not math.isfinite(value) or value == 0.0:
        return None
    num, den = value.as_integer_ratio()
    if den > 1:
        return num, 1 - den.bit_length()
    shift = (num & -num).bit_length() - 1
    return num >> shift, shift


def _number(value: Any, field: str, *, upper_float32: bool = False, major: int = 3) -> bytes:
    """The number form of ``value`` (int, float or None), shortest exact encoding."""
    if value is None:
        return encode_varint(_NUM_NULL)
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"header field {field!r} must be a number, not {str(value)[:40]!r}"
        raise BundleError(msg)
    if isinstance(value, int):
        if zigzag(value) * 16 + _NUM_INT > _MAX_NUMBER_HEAD:
            msg = f"header field {field!r} is an integer too large for the binary header"
            raise BundleError(msg)
        return encode_varint(zigzag(value) * 16 + _NUM_INT)
    value = float(value)
    best = bytes([_NUM_FLOAT64]) + _F64.pack(value)
    decimal = _decimal(value)
    if decimal is not None:
        k, e = decimal
        if e > _NUM_DECIMAL_MAX:
            k, e = k * 10 ** (e - _NUM_DECIMAL_MAX), _NUM_DECIMAL_MAX
        if major >= 4 and e == _NUM_DECIMAL_MAX:  # code 11 is the binary form in 4.0
            k, e = k * 10, e - 1
        if e >= _NUM_DECIMAL_MIN and _same_float(float(f"{k}e{e}"), value):
            short = encode_varint(zigzag(k) * 16 + (e - _NUM_DECIMAL_MIN))
            if len(short) < len(best):
                best = short
    binary = _binary(value) if major >= 4 else None
    if binary is not None and abs(binary[1]) <= _BINARY_EXPONENT_MAX:
        # 4.0: the binary form when it beats a float32 (at most 4 bytes), else a float32 when
        # the value is one (5 bytes), so that a value read back packs to the same bytes.
        k, e = binary
        short = encode_varint(zigzag(k) * 16 + _NUM_BINARY) + encode_varint(zigzag(e))
        if len(short) < min(len(best), 5):
            best = short
        elif len(best) > 5 and _is_float32(value):
            best = bytes([_NUM_FLOAT32]) + _F32.pack(value)
    if upper_float32 and len(best) > 5 and _FLOAT32_NORMAL <= abs(value) < 3.0e38:
        # The float32 at or above the value: a diagnostic that stays an upper bound, within
        # 2**-23 of it (in float32's normal range; beyond it, the float64).
        single = np.float32(value)
        if float(single) < value:
            single = np.nextafter(single, np.float32(np.inf))
        best = bytes([_NUM_FLOAT32]) + _F32.pack(float(single))
    return best


def _weight_code(weight: Any) -> int | None:
    """The 16-bit code of a four-significant-digit weight, or None if it has none."""
    if isinstance(weight, bool) or not isinstance(weight, float):
        return None
    decimal = _decimal(weight)
    if decimal is None or decimal[0] <= 0:
        return None
    k, e = decimal
    while k < 1000:  # four digits: 0.5 is 5000e-4
        k, e = k * 10, e - 1
    if k > 9999 or not _same_float(float(f"{k}e{e}"), weight):
        return None
    code = (e - WEIGHT_EXPONENT_MIN) * 9000 + (k - 1000)
    return code if 0 <= code < WEIGHT_CODE_LIMIT else None


def _pack_weights(weights: Any, levels: int, two_d: bool) -> tuple[bytes, list[int]] | None:
    """The weights in the standard layout ``[[cA], [bands of level L], …]``, and every band's
    code (coarse first, ``cV`` included), or None."""
    bands = 3 if two_d else 1
    if not isinstance(weights, list) or len(weights) != levels + 1:
        return None
    codes: list[list[int]] = []
    for index, entry in enumerate(weights):
        if not isinstance(entry, list) or len(entry) != (1 if index == 0 else bands):
            return None
        entry_codes = [_weight_code(w) for w in entry]
        if any(c is None for c in entry_codes):
            return None
        codes.append([c for c in entry_codes if c is not None])
    out = bytearray()
    same_hv = 0
    if two_d:
        for index, entry in enumerate(codes[1:]):
            if entry[0] == entry[1]:
                same_hv |= 1 << index
        out += encode_varint(same_hv)
    for index, entry in enumerate(codes):
        for band, code in enumerate(entry):
            if two_d and band == 1 and same_hv >> (index - 1) & 1:
                continue
            out += _U16.pack(code)
    return bytes(out), [code for entry in codes for code in entry]


def _flat_codes(weights: Any) -> list[int] | None:
    """The weight codes of every band, coarse first (``cV`` included), or None."""
    if not isinstance(weights, list):
        return None
    codes = []
    for entry in weights:
        if not isinstance(entry, list):
            return None
        for weight in entry:
            code = _weight_code(weight)
            if code is None:
                return None
            codes.append(code)
    return codes


def weights_check(weights: Any) -> int | None:
    """Format 3.1's check of a header's weights: the CRC-8 (polynomial ``0x07``, initial value
    0) of every band's 16-bit weight code, little-endian, coarse first and ``cV`` included; None
    when a weight has no code.

    A CRC-8 finds every change of up to 8 consecutive bits, so every change of one weight by
    one in its last digit but those that carry through more than 8 bits of its code.

    >>> weights_check([[0.9535], [1.0]])
    213
    """
    codes = _flat_codes(weights)
    return None if codes is None else _codes_check(codes)


def _codes_check(codes: list[int]) -> int:
    """The CRC-8 of :func:`weights_check`, of the codes themselves."""
    crc = 0
    for byte in struct.pack(f"<{len(codes)}H", *codes):
        crc ^= byte
        for _ in range(8):
            crc = (crc << 1 ^ 0x07) & 0xFF if crc & 0x80 else crc << 1
    return crc


@dataclass(frozen=True)
class PinnedWeights:
    """What a 3.1 header (quantizer code 3) says about its weights: the *pinned* ones, by
    their index among every band coarse first (``cV`` included), and the check of them all
    (:func:`weights_check`); the rest are the plan's (:func:`wavecore.bundle.derived_weights`)."""

    pins: dict[int, float]
    check: int

    def apply(self, derived: list[list[float]]) -> list[list[float]]:
        """The derived weights with the pinned ones put in."""
        out, index = [], 0
        for entry in derived:
            row = []
            for weight in entry:
                row.append(self.pins.get(index, weight))
                index += 1
            out.append(row)
        if self.pins and max(self.pins) >= index:
            msg = f"qparams.weights: pinned weight {max(self.pins)} is past the {index} bands"
            raise BundleError(msg)
        return out


def _pack_pins(codes: list[int], pinned: Mapping[int, float]) -> bytes | None:
    """3.1's weights field from every band's weight code: how many weights are pinned, each
    one's index (a varint) and code (uint16), then the check byte; None when a pin is not the
    header's weight."""
    out = bytearray(encode_varint(len(pinned)))
    for index in sorted(pinned):
        if not 0 <= index < len(codes) or _weight_code(pinned[index]) != codes[index]:
            return None
        out += encode_varint(index) + _U16.pack(codes[index])
    return bytes(out) + bytes([_codes_check(codes)])


def _is_float32(value: float) -> bool:
    """Whether ``value`` is a float32 exactly (finite, in float32's range)."""
    return abs(value) < 3.0e38 and _same_float(float(np.float32(value)), value)


def _compact_qparams(
    header: dict[str, Any],
    major: int = 3,
    derived_weights: bool = False,
    pinned: Mapping[int, float] | None = None,
) -> tuple[bytes, bool, bool, bool] | None:
    """(bytes, rounding is the default, step is a float32, weights are pinned) of the
    quantizer's parameters, or None.  In 4.0 the step takes 4 bytes when it is a float32, and
    ``derived_weights`` (the weights are those the plan gives,
    :func:`wavecore.bundle.derived_weights`) leaves them out.  In 3.1 ``pinned`` (the weights
    the plan does not give for sure) stores those alone, when that is shorter."""
    quantizer, qparams = header.get("quantizer"), header.get("qparams")
    if not isinstance(qparams, dict):
        return None
    if quantizer == "none":
        return (b"", False, False, False) if qparams == {} else None
    if quantizer != "deadzone" or set(qparams) != {"name", "step", "weights", "rounding"}:
        return None
    step, rounding = qparams["step"], qparams["rounding"]
    if qparams["name"] != quantizer or isinstance(step, bool) or not isinstance(step, float):
        return None
    if isinstance(rounding, bool) or not isinstance(rounding, int | float):
        return None
    levels, boundary = header.get("levels"), header.get("boundary")
    if not isinstance(levels, int) or not isinstance(boundary, list):
        return None
    packed_weights = _pack_weights(qparams["weights"], levels, len(boundary) == 2)
    if packed_weights is None:
        return None
    weights, codes = packed_weights
    if major >= 4 and derived_weights:
        weights = b""
    pins = None
    if major == 3 and pinned is not None:
        pins = _pack_pins(codes, pinned)
        if pins is not None and len(pins) < len(weights):
            weights = pins
        else:
            pins = None
    is_default = isinstance(rounding, float) and _same_float(rounding, DEFAULT_ROUNDING)
    middle = b"" if is_default else _number(rounding, "qparams.rounding", major=major)
    single = major >= 4 and _is_float32(step)
    packed_step = _F32.pack(step) if single else _F64.pack(step)
    return packed_step + middle + weights, is_default, single, pins is not None


def _compact_cparams(header: dict[str, Any]) -> bytes | None:
    coder, cparams = header.get("coder"), header.get("cparams")
    if not isinstance(cparams, dict) or cparams.get("coder") != coder:
        return None
    if coder == "zlib":
        return b"" if set(cparams) == {"coder"} else None
    if coder != "context" or not {"version", "two_d"} <= set(cparams) <= {
        "coder",
        "version",
        "two_d",
        "block",
    }:
        return None
    version, two_d = cparams["version"], cparams["two_d"]
    if isinstance(version, bool) or not isinstance(version, int) or not 0 <= version <= 15:
        return None
    if version == RESTORED_VERSION:  # that nibble says "version 8 and a restoration record"
        return None
    if not isinstance(two_d, bool):
        return None
    block_code = 0
    if "block" in cparams:
        block = cparams["block"]
        if isinstance(block, bool) or not isinstance(block, int):
            return None
        if block not in [2 ** (k + 3) for k in range(1, 8)]:
            return None
        block_code = block.bit_length() - 4
    return bytes([version | two_d << 4 | block_code << 5])


def _pack_restore(header: dict[str, Any], cparams: bytes) -> bytes | None:
    """The restoration record of ``header["restore"]`` (docs/bundle-format.md, "The
    restoration record"), or None where it goes to the extension instead: no ``restore``, a
    coder other than version 8, or a ``restore`` that :func:`restoration.check_restore`
    refuses (the header check names it)."""
    restore = header.get("restore")
    if restore is None or len(cparams) != 1 or cparams[0] & 15 != RESTORED_BASE:
        return None
    try:
        check_restore(header)
    except BundleError:
        return None
    out = bytearray(RECORD_GUARD)
    for item in restore:
        if item is None:
            out.append(0)
            continue
        out.append(sum(1 << c for c, taps in enumerate(item["taps"]) if taps is not None))
        edges = item["edges"]
        for low, high in zip([0, *edges[:-1]], edges, strict=True):
            out += encode_varint(high - low)
        bits = count = 0
        for taps in item["taps"]:
            for tap in taps or ():
                bits |= (tap & 127) << count
                count += 7
        out += bits.to_bytes((count + 7) // 8, "little")
    return bytes(out)


def _unpack_restore(reader: _Reader, header: dict[str, Any]) -> list[Any]:
    shape, dtype = header["shape"], header.get("dtype")
    if len(shape) not in (2, 3) or dtype not in FILTERED_DTYPES:
        raise reader.fail("cparams", "a restoration record in a header that is not a picture's")
    if reader.take(len(RECORD_GUARD), "restore") != RECORD_GUARD:
        raise reader.fail("restore", "the record does not start with its guard bytes 01 1c")
    largest = largest_activity(dtype)
    restore: list[Any] = []
    for _ in range(colour_channels(shape)):
        mask = reader.byte("restore")
        if mask >= 1 << CLASSES:
            raise reader.fail("restore", f"class mask {mask} has bits beyond {CLASSES} classes")
        if mask == 0:
            restore.append(None)
            continue
        edges: list[int] = []
        for _ in range(CLASSES - 1):
            edges.append((edges[-1] if edges else 0) + reader.varint("restore", largest))
        on = [bool(mask >> c & 1) for c in range(CLASSES)]
        count = 7 * TAPS * sum(on)
        bits = int.from_bytes(reader.take((count + 7) // 8, "restore"), "little")
        if bits >> count:
            raise reader.fail("restore", "the taps' padding bits are not zero")
        taps: list[Any] = []
        for c in range(CLASSES):
            if not on[c]:
                taps.append(None)
                continue
            row = []
            for _ in range(TAPS):
                value = bits & 127
                row.append(value - 128 if value >= 64 else value)
                bits >>= 7
            taps.append(row)
        restore.append({"edges": edges, "taps": taps})
    return restore


def default_cparams_for(boundary: Any) -> dict[str, Any]:
    """The coder parameters a 4.0 header stores in no bytes: the context coder's version 4
    with 128-sample blocks, two-dimensional when there are two axes."""
    two_d = isinstance(boundary, list) and len(boundary) == 2
    return {"coder": "context", "version": 4, "two_d": two_d, "block": 128}


def _index(table: tuple[str, ...], value: Any, field: str) -> int:
    if isinstance(value, str) and value in table:
        return table.index(value)
    msg = f"header field {field!r} is {str(value)[:40]!r}; the binary header holds {list(table)}"
    raise BundleError(msg)


def _matrix_units(colour: Any) -> list[int] | None:
    """The three angles of a colour ``"klt:<a>,<b>,<c>"`` (None for any other colour)."""
    if not isinstance(colour, str) or not colour.startswith(KLT_PREFIX):
        return None
    try:
        klt_matrix(colour)
    except ValueError as exc:
        msg = f"header field 'colour' is {colour[:80]!r}: {exc}"
        raise BundleError(msg) from exc
    return [int(unit) for unit in colour[len(KLT_PREFIX) :].split(",")]


def _predicted_weight(colour: Any) -> int | None:
    """``w`` of a colour ``"rct-p<w>"`` (None for any other colour, and for ``"rct-p0"``:
    its code is the per-picture matrix's, :data:`MATRIX_WEIGHT`)."""
    if not isinstance(colour, str) or not colour.startswith(PREDICTED_PREFIX):
        return None
    text = colour[len(PREDICTED_PREFIX) :]
    if len(text) > 4 or not text.lstrip("-").isdigit():
        return None
    weight = int(text)
    if weight == MATRIX_WEIGHT or f"{PREDICTED_PREFIX}{weight}" != colour:
        return None
    return weight


def _sizes(value: Any, field: str) -> list[int]:
    if not isinstance(value, list) or not all(
        isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= _MAX_SIZE for v in value
    ):
        msg = f"header field {field!r} must list sizes from 0 to {_MAX_SIZE}, not {value!r}"
        raise BundleError(msg[:200])
    return value


def _derived_fitted(shape: list[int], pads: list[list[int]]) -> list[int]:
    fitted = list(shape) if len(shape) > 1 else [shape[0], 1]
    for axis, (before, after) in enumerate(pads):
        if axis < len(fitted):
            fitted[axis] += before + after
    return fitted


def pack(
    header: dict[str, Any],
    *,
    major: int = 3,
    derived_weights: bool = False,
    pinned: Mapping[int, float] | None = None,
    delimited: bool = False,
) -> bytes:
    """The binary form of a header dict (one that :func:`bundle.check_header` accepts).

    ``major`` is the bundle format's major version: 2 and 3 share one form; 4 (see
    ``docs/bundle-format.md``, *The binary header in 4.0*) always derives ``fitted`` (else it
    goes to the extension), leaves the weights out when ``derived_weights`` says they are the
    plan's, stores a float32 step in 4 bytes and the default coder parameters in none, and
    has the binary number form.  ``pinned`` (major 3 only: format 3.1) says that the weights
    are the plan's but for these (an index among every band, coarse first and ``cV``
    included, to the header's weight): the quantizer is then written as code 3, with the
    pinned weights and a check byte in place of the weights (when that is shorter).
    ``delimited`` (major 3 only: format 3.1) writes the ``context`` coder, with compact
    parameters, as code 3: the bundle stores no chunk lengths.

    Raises
    ------
    BundleError
        For a field the binary header has no room for (an unknown kind, dtype, colour, fit or
        boundary, sizes beyond ``2**40``); :func:`bundle.check_header` refuses those too.

    Examples
    --------
    >>> header = {"kind": "curve", "shape": [8, 2], "dtype": "float64", "fit": "none",
    ...           "pads": [[0, 0]], "fitted": [8, 2], "wavelet": "bspline2",
    ...           "boundary": ["open"], "levels": 0, "colour": "none", "quantizer": "none",
    ...           "qparams": {}, "coder": "zlib", "cparams": {"coder": "zlib"}, "peak": 1.0,
    ...           "psnr": None, "max_error": 0.0}
    >>> data = pack(header)  # 4 flag bytes; levels, 8, 2; peak, psnr, max_error: 1 byte each
    >>> len(data), unpack(data) == header
    (10, True)
    """
    if not isinstance(header, dict):
        msg = f"the header must be a dict, not {type(header).__name__}"
        raise BundleError(msg)
    missing = [key for key in _CORE_KEYS if key not in header]
    if missing:
        msg = f"header field {missing[0]!r} is missing"
        raise BundleError(msg)
    extension: dict[str, Any] = {
        k: v for k, v in header.items() if k not in _CORE_KEYS + ("opaque", "scale", "lifting")
    }
    kind = _index(KIND_CODES, header["kind"], "kind")
    weight = _predicted_weight(header["colour"])
    matrix = _matrix_units(header["colour"])
    if matrix is not None:
        colour, weight = COLOUR_PREDICTED, MATRIX_WEIGHT
    elif weight is None:
        colour = _index(COLOUR_CODES, header["colour"], "colour")
    else:
        colour = COLOUR_PREDICTED
    dtype = _index(DTYPE_CODES, header["dtype"], "dtype")
    fit = _index(("none", "pad"), header["fit"], "fit")
    shape = _sizes(header["shape"], "shape")
    if not 1 <= len(shape) <= 4:
        msg = f"header field 'shape' must list 1 to 4 sizes, not {len(shape)}"
        raise BundleError(msg)
    boundary = header["boundary"]
    if not isinstance(boundary, list) or not 1 <= len(boundary) <= 2:
        msg = "header field 'boundary' must list one or two boundaries"
        raise BundleError(msg)
    boundary_codes = [_index(BOUNDARY_CODES, b, "boundary") for b in boundary] + [0]
    pads = header["pads"]
    if not isinstance(pads, list) or len(pads) != len(boundary):
        msg = f"header field 'pads' must hold one pair per boundary ({len(boundary)})"
        raise BundleError(msg)
    for pair in pads:
        if not isinstance(pair, list) or len(pair) != 2:
            msg = f"header field 'pads' must hold pairs of sizes, not {pair!r}"
            raise BundleError(msg[:200])
        _sizes(pair, "pads")
    levels = header["levels"]
    if isinstance(levels, bool) or not isinstance(levels, int) or not 0 <= levels <= 255:
        msg = f"header field 'levels' must be an integer from 0 to 255, not {levels!r}"
        raise BundleError(msg[:200])
    fitted = _sizes(header["fitted"], "fitted")
    fitted_derived = fitted == _derived_fitted(shape, pads)
    if major >= 4 and not fitted_derived:
        extension["fitted"] = fitted
    if all(p == [0, 0] for p in pads):
        pads_mode = 0
    elif all(p[0] == 0 for p in pads):
        pads_mode = 1
    else:
        pads_mode = 2

    wavelet = header["wavelet"]
    lifting = header.get("lifting")
    lifting_compact = (
        wavelet == "reversible"
        and isinstance(lifting, list)
        and len(lifting) <= 255
        and all(isinstance(n, str) and n in LIFTING_CODES for n in lifting)
    )
    if lifting_compact:
        wavelet_code = WAVELET_CODES.index("reversible")
    elif wavelet in WAVELET_CODES[1:4]:
        wavelet_code = WAVELET_CODES.index(wavelet)
    else:
        wavelet_code = 0
        extension["wavelet"] = wavelet
    if "lifting" in header and not lifting_compact:
        extension["lifting"] = lifting

    opaque = header.get("opaque", False) is True
    if "opaque" in header and not opaque:
        extension["opaque"] = header["opaque"]
    scale = header.get("scale")
    scale_compact = "scale" in header and isinstance(scale, int) and not isinstance(scale, bool)
    if "scale" in header and not scale_compact:
        extension["scale"] = scale

    quantizer = header["quantizer"]
    quantizer_code = QUANTIZER_CODES.index(quantizer) if quantizer in QUANTIZER_CODES else 2
    if quantizer_code == IN_EXTENSION:
        extension["quantizer"] = quantizer
    qparams = (
        _compact_qparams(header, major, derived_weights, pinned)
        if quantizer_code != IN_EXTENSION
        else None
    )
    if qparams is not None and qparams[3]:
        quantizer_code = DERIVED_DEADZONE
    if qparams is None:
        extension["qparams"] = header["qparams"]
        if major >= 4 and quantizer_code != IN_EXTENSION:  # 4.0: both in the extension
            quantizer_code = IN_EXTENSION
            extension["quantizer"] = quantizer
    coder = header["coder"]
    coder_code = CODER_CODES.index(coder) if coder in CODER_CODES else 2
    if coder_code == IN_EXTENSION:
        extension["coder"] = coder
    cparams = _compact_cparams(header) if coder_code != IN_EXTENSION else None
    record = None if cparams is None or major >= 4 else _pack_restore(header, cparams)
    if cparams is not None and record is not None:  # the version nibble says a record follows
        cparams = bytes([cparams[0] & ~15 | RESTORED_VERSION]) + record
        extension.pop("restore", None)
    if cparams is None:
        extension["cparams"] = header["cparams"]
        if major >= 4 and coder_code != IN_EXTENSION:
            coder_code = IN_EXTENSION
            extension["coder"] = coder
    if delimited and major <= 3 and coder_code == 0 and cparams is not None:
        coder_code = DELIMITED_CONTEXT
    default_cparams = (
        major >= 4 and cparams is not None and header["cparams"] == default_cparams_for(boundary)
    )
    if major >= 4:
        # 4.0's flags: byte 1 bit 5 says the weights are derived (``fitted`` always is),
        # byte 3 bit 4 that the step is a float32, bit 5 that the coder's parameters are the
        # default ones (no byte); a stage whose parameters have no compact form is named in
        # the extension with them.
        fitted_derived = derived_weights and qparams is not None and quantizer_code == 1
        q_flag = qparams is not None and qparams[2]
        c_flag = default_cparams
    else:
        q_flag, c_flag = qparams is not None, cparams is not None

    out = bytearray(
        [
            kind | colour << 2 | (len(shape) - 1) << 4 | fit << 6 | opaque << 7,
            dtype | (len(boundary) - 1) << 4 | fitted_derived << 5 | pads_mode << 6,
            wavelet_code | boundary_codes[0] << 3 | boundary_codes[1] << 5 | scale_compact << 7,
            quantizer_code
            | coder_code << 2
            | q_flag << 4
            | c_flag << 5
            | bool(extension) << 6
            | (qparams is not None and qparams[1]) << 7,
        ]
    )
    out += encode_varint(levels)
    for size in shape:
        out += encode_varint(size)
    if not fitted_derived and major < 4:
        if not 1 <= len(fitted) <= 4:
            msg = f"header field 'fitted' must list 1 to 4 sizes, not {len(fitted)}"
            raise BundleError(msg)
        out += encode_varint(len(fitted))
        for size in fitted:
            out += encode_varint(size)
    for before, after in pads:
        if pads_mode == 2:
            out += encode_varint(before)
        if pads_mode:
            out += encode_varint(after)
    if weight is not None:
        out += encode_varint(zigzag(weight))
    for unit in matrix or ():
        out += encode_varint(zigzag(unit))
    if lifting_compact:
        assert isinstance(lifting, list)
        out += encode_varint(len(lifting))
        codes = [LIFTING_CODES.index(name) for name in lifting]
        for start in range(0, len(codes), 4):
            out.append(sum(c << (2 * i) for i, c in enumerate(codes[start : start + 4])))
    out += _number(header["peak"], "peak", major=major)
    if scale_compact:
        assert isinstance(scale, int)
        out += encode_varint(zigzag(scale))
    if qparams is not None:
        out += qparams[0]
    if cparams is not None and not default_cparams:
        out += cparams
    psnr = header["psnr"]
    if psnr is None:
        out += encode_varint(0)
    elif (
        isinstance(psnr, float) and abs(psnr) < 1e12 and _same_float(round(psnr * 1e4) / 1e4, psnr)
    ):
        out += encode_varint(zigzag(round(psnr * 1e4)) + 2)
    else:
        out += encode_varint(1) + _number(psnr, "psnr", major=major)
    out += _number(header["max_error"], "max_error", upper_float32=True, major=major)
    if extension:
        try:
            text = json.dumps(extension, separators=(",", ":"), allow_nan=False).encode()
        except (TypeError, ValueError) as exc:
            msg = f"the header's other fields are not JSON: {exc}"
            raise BundleError(msg) from exc
        packer = zlib.compressobj(9, zlib.DEFLATED, -15)
        packed = packer.compress(text) + packer.flush()
        if len(text) > _MAX_EXTENSION or len(packed) > _MAX_EXTENSION:
            msg = (
                f"the header's other fields take {len(text)} bytes, more than "
                f"MAX_HEADER_SIZE = {_MAX_EXTENSION}"
            )
            raise BundleError(msg)
        out += encode_varint(len(packed)) + packed
    return bytes(out)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


class _Reader:
    """Reads a binary header in order; every error names the field it was reading."""

    def __init__(self, data: bytes | bytearray | memoryview) -> None:
        self.data = bytes(data)
        self.offset = 0

    def fail(self, field: str, problem: str) -> BundleError:
        return BundleError(f"binary header field {field!r} (at byte {self.offset}): {problem}")

    def take(self, size: int, field: str) -> bytes:
        remaining = len(self.data) - self.offset
        if size > remaining:
            problem = f"the header ends: it needs {size} byte(s), {remaining} remain"
            raise self.fail(field, problem)
        out = self.data[self.offset : self.offset + size]
        self.offset += size
        return out

    def byte(self, field: str) -> int:
        return self.take(1, field)[0]

    def varint(self, field: str, maximum: int) -> int:
        value = shift = 0
        for count in range(MAX_VARINT_BYTES):
            byte = self.byte(field)
            value |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                if byte == 0 and count:
                    raise self.fail(field, "a varint with a needless trailing zero byte")
                if value > maximum:
                    raise self.fail(field, f"{value} is more than the largest, {maximum}")
                return value
        raise self.fail(field, f"a varint longer than {MAX_VARINT_BYTES} bytes")

    def code(self, value: int, table: tuple[str, ...], field: str) -> str:
        if value >= len(table) or not table[value]:
            raise self.fail(field, f"unknown code {value}; known: {list(table)}")
        return table[value]

    def number(self, field: str, major: int = 3) -> Any:
        head = self.varint(field, _MAX_NUMBER_HEAD)
        form, rest = head & 15, head >> 4
        if form == _NUM_BINARY and major >= 4:
            k = unzigzag(rest)
            e = unzigzag(self.varint(field, 2 * _BINARY_EXPONENT_MAX))
            if not k & 1 or abs(k) >= 2**53:
                raise self.fail(field, f"binary number {k}·2^{e} needs an odd k below 2^53")
            try:
                value = math.ldexp(k, e)
            except OverflowError:
                raise self.fail(field, f"binary number {k}·2^{e} is not finite") from None
            return value
        if form <= _NUM_DECIMAL_MAX - _NUM_DECIMAL_MIN:
            k = unzigzag(rest)
            return float(f"{k}e{form + _NUM_DECIMAL_MIN}")
        if form == _NUM_INT:
            return unzigzag(rest)
        if rest:
            raise self.fail(field, f"number form {form} takes no value bits, found {rest}")
        if form == _NUM_NULL:
            return None
        fmt = _F32 if form == _NUM_FLOAT32 else _F64
        (value,) = fmt.unpack(self.take(fmt.size, field))
        if not math.isfinite(value):
            raise self.fail(field, f"{value} is not a finite number")
        return float(value)

    def end(self) -> None:
        if self.offset != len(self.data):
            extra = len(self.data) - self.offset
            raise self.fail("end", f"{extra} unexpected byte(s) after the last field")


def _unpack_weights(reader: _Reader, levels: int, two_d: bool) -> list[list[float]]:
    same_hv = reader.varint("qparams.weights", 2**levels - 1) if two_d else 0
    weights: list[list[float]] = []
    for index in range(levels + 1):
        entry: list[float] = []
        for band in range(1 if index == 0 else 3 if two_d else 1):
            if two_d and band == 1 and same_hv >> (index - 1) & 1:
                entry.append(entry[0])
                continue
            (code,) = _U16.unpack(reader.take(2, "qparams.weights"))
            if code >= WEIGHT_CODE_LIMIT:
                raise reader.fail("qparams.weights", f"weight code {code} is not a weight")
            entry.append(_weight_of(code))
        weights.append(entry)
    return weights


def _weight_of(code: int) -> float:
    exponent, mantissa = divmod(code, 9000)
    return float(f"{mantissa + 1000}e{exponent + WEIGHT_EXPONENT_MIN}")


def _unpack_pins(reader: _Reader, levels: int, two_d: bool) -> PinnedWeights:
    """3.1's weights field: the pinned weights (indices strictly increasing, below the number
    of bands) and the check byte."""
    bands = 1 + levels * (3 if two_d else 1)
    count = reader.varint("qparams.weights", bands)
    pins: dict[int, float] = {}
    for _ in range(count):
        index = reader.varint("qparams.weights", bands - 1)
        if pins and index <= max(pins):
            raise reader.fail("qparams.weights", "pinned weights out of order")
        (code,) = _U16.unpack(reader.take(2, "qparams.weights"))
        if code >= WEIGHT_CODE_LIMIT:
            raise reader.fail("qparams.weights", f"weight code {code} is not a weight")
        pins[index] = _weight_of(code)
    return PinnedWeights(pins, reader.byte("qparams.weights"))


def unpack(data: bytes | bytearray | memoryview) -> dict[str, Any]:
    """The header dict of a binary header (the exact bytes, nothing after them).

    Raises
    ------
    BundleError
        For any malformed input, naming the field being read: truncated, an unknown code, a
        varint too long or too large, a non-finite number, bytes left over.  What the fields
        say together is checked by :func:`bundle.check_header` and the codec.
    """
    header, pinned = unpack_pinned(data)
    if pinned is not None:
        msg = (
            "binary header field 'qparams.weights': derived from the plan (quantizer code 3, "
            "format 3.1); read the bundle with wavecore.bundle.read_bundle"
        )
        raise BundleError(msg)
    return header


def unpack_pinned(
    data: bytes | bytearray | memoryview,
) -> tuple[dict[str, Any], PinnedWeights | None]:
    """As :func:`unpack`, for a header of format 3.1 too: the header dict and, when its
    quantizer is code 3 (the weights derived from the plan), its :class:`PinnedWeights`;
    ``qparams`` then holds no ``weights`` (:func:`wavecore.bundle.read_bundle` derives them
    once the header's CRC has matched)."""
    reader = _Reader(data)
    header, _, pinned = _read_fields(reader, 3)
    reader.end()
    return header, pinned


def unpack_from(
    data: bytes | bytearray | memoryview, offset: int, *, major: int = 4
) -> tuple[dict[str, Any], int, bool]:
    """A 4.0 header read from ``data`` at ``offset``, where nothing says its length: the header
    dict, the offset just past it, and whether its weights are derived from the plan (then
    ``qparams`` holds no ``weights``: :func:`wavecore.bundle.derived_weights` gives them).

    Reads at most ``MAX_HEADER_SIZE`` (65 535) bytes; raises :class:`BundleError` naming the
    field for anything malformed, as :func:`unpack` does.
    """
    reader = _Reader(memoryview(data)[offset : offset + _MAX_EXTENSION])
    header, derived, _ = _read_fields(reader, major)
    return header, offset + reader.offset, derived


def _read_fields(reader: _Reader, major: int) -> tuple[dict[str, Any], bool, PinnedWeights | None]:
    """The fields of a binary header, in order (``major`` 2, 3 or 4): the header, whether its
    weights are derived (4.0 on), and 3.1's pinned weights (quantizer code 3)."""
    flags = [reader.byte("flags") for _ in range(4)]
    kind = reader.code(flags[0] & 3, KIND_CODES, "kind")
    colour_code = flags[0] >> 2 & 3
    if colour_code != COLOUR_PREDICTED:
        colour = reader.code(colour_code, COLOUR_CODES, "colour")
    rank = (flags[0] >> 4 & 3) + 1
    fit = ("none", "pad")[flags[0] >> 6 & 1]
    opaque = bool(flags[0] >> 7)
    dtype = reader.code(flags[1] & 15, DTYPE_CODES, "dtype")
    axes = (flags[1] >> 4 & 1) + 1
    fitted_derived = bool(flags[1] >> 5 & 1) or major >= 4
    weights_derived = bool(flags[1] >> 5 & 1) and major >= 4
    pads_mode = flags[1] >> 6
    if pads_mode == 3:
        raise reader.fail("pads", "unknown pads form 3")
    wavelet_code = flags[2] & 7
    if wavelet_code >= len(WAVELET_CODES):
        raise reader.fail("wavelet", f"unknown code {wavelet_code}; known: {WAVELET_CODES}")
    boundary = [reader.code(flags[2] >> 3 & 3, BOUNDARY_CODES, "boundary")]
    if axes == 2:
        boundary.append(reader.code(flags[2] >> 5 & 3, BOUNDARY_CODES, "boundary"))
    elif flags[2] >> 5 & 3:
        raise reader.fail("boundary", "a second boundary code for one axis")
    has_scale = bool(flags[2] >> 7)
    quantizer_code, coder_code = flags[3] & 3, flags[3] >> 2 & 3
    # 3.1's code 3 is a deadzone quantizer whose weights the plan gives (2.0's and 3.0's
    # header form; 4.0 on have their own flag for it).
    derived_deadzone = quantizer_code == DERIVED_DEADZONE and major <= 3
    if derived_deadzone:
        if not flags[3] >> 4 & 1:
            raise reader.fail("flags", "quantizer code 3 without its compact parameters")
        quantizer_code = 1
    elif quantizer_code > IN_EXTENSION:
        raise reader.fail("quantizer", f"unknown code {quantizer_code}")
    if coder_code == DELIMITED_CONTEXT and major <= 3:  # 3.1: the context coder, delimited
        if not flags[3] >> 5 & 1:
            raise reader.fail("flags", "coder code 3 without its compact parameters")
        coder_code = 0
    elif coder_code > IN_EXTENSION:
        raise reader.fail("coder", f"unknown code {coder_code}")
    q_compact, c_compact = bool(flags[3] >> 4 & 1), bool(flags[3] >> 5 & 1)
    single_step = default_cparams = False
    if major >= 4:
        # 4.0: a stage named by its code has compact parameters; bits 4 and 5 say the step is
        # a float32 and the coder's parameters are the default ones.
        single_step, default_cparams = q_compact, c_compact
        if single_step and quantizer_code != 1:
            raise reader.fail("flags", "the float32-step flag without a deadzone quantizer")
        if default_cparams and coder_code != 0:
            raise reader.fail("flags", "the default-parameters flag without the context coder")
        if weights_derived and quantizer_code != 1:
            raise reader.fail("flags", "the derived-weights flag without a deadzone quantizer")
        q_compact, c_compact = quantizer_code != IN_EXTENSION, coder_code != IN_EXTENSION
    has_extension, default_rounding = bool(flags[3] >> 6 & 1), bool(flags[3] >> 7)
    if (q_compact and quantizer_code == IN_EXTENSION) or (c_compact and coder_code == 2):
        raise reader.fail("flags", "compact parameters for a stage named in the extension")
    if default_rounding and not (q_compact and quantizer_code == 1):
        raise reader.fail("flags", "the default-rounding flag without a deadzone quantizer")

    pinned: PinnedWeights | None = None
    levels = reader.varint("levels", 255)
    shape = [reader.varint("shape", _MAX_SIZE) for _ in range(rank)]
    fitted = None
    if not fitted_derived:
        count = reader.varint("fitted", 4)
        fitted = [reader.varint("fitted", _MAX_SIZE) for _ in range(count)]
    pads = []
    for _ in range(axes):
        before = reader.varint("pads", _MAX_SIZE) if pads_mode == 2 else 0
        after = reader.varint("pads", _MAX_SIZE) if pads_mode else 0
        pads.append([before, after])
    if fitted is None:
        fitted = _derived_fitted(shape, pads)
    header: dict[str, Any] = {
        "kind": kind,
        "shape": shape,
        "dtype": dtype,
        "fit": fit,
        "pads": pads,
        "fitted": fitted,
    }
    if wavelet_code:
        header["wavelet"] = WAVELET_CODES[wavelet_code]
    header["boundary"] = boundary
    header["levels"] = levels
    if colour_code == COLOUR_PREDICTED:
        weight = unzigzag(reader.varint("colour", 255))
        if weight == MATRIX_WEIGHT:
            limit = zigzag(-KLT_LIMIT)
            units = [unzigzag(reader.varint("colour", limit)) for _ in range(3)]
            colour = KLT_PREFIX + ",".join(map(str, units))
        else:
            colour = f"{PREDICTED_PREFIX}{weight}"
    header["colour"] = colour
    if wavelet_code == WAVELET_CODES.index("reversible"):
        count = reader.varint("lifting", 255)
        codes = []
        for start in range(0, count, 4):
            byte = reader.byte("lifting")
            for i in range(min(4, count - start)):
                codes.append(byte >> (2 * i) & 3)
            if byte >> (2 * min(4, count - start)):
                raise reader.fail("lifting", "bits set beyond the last filter")
        header["lifting"] = [reader.code(c, LIFTING_CODES, "lifting") for c in codes]
    header["peak"] = reader.number("peak", major)
    if has_scale:
        header["scale"] = unzigzag(reader.varint("scale", 2**20))
    if opaque:
        header["opaque"] = True
    if quantizer_code != IN_EXTENSION:
        header["quantizer"] = QUANTIZER_CODES[quantizer_code]
    if q_compact and quantizer_code == 0:
        header["qparams"] = {}
    elif q_compact:
        step_form = _F32 if single_step else _F64
        (step,) = step_form.unpack(reader.take(step_form.size, "qparams.step"))
        rounding = (
            DEFAULT_ROUNDING if default_rounding else reader.number("qparams.rounding", major)
        )
        qparams: dict[str, Any] = {"name": "deadzone", "step": float(step)}
        if derived_deadzone:  # the bundle reader derives them, once the CRC has matched
            pinned = _unpack_pins(reader, levels, axes == 2)
        elif not weights_derived:  # else the bundle reader derives them from the plan
            qparams["weights"] = _unpack_weights(reader, levels, axes == 2)
        qparams["rounding"] = rounding
        header["qparams"] = qparams
    if coder_code != IN_EXTENSION:
        header["coder"] = CODER_CODES[coder_code]
    if c_compact and coder_code == 1:
        header["cparams"] = {"coder": "zlib"}
    elif default_cparams:
        header["cparams"] = default_cparams_for(boundary)
    elif c_compact:
        byte = reader.byte("cparams")
        cparams: dict[str, Any] = {
            "coder": "context",
            "version": byte & 15,
            "two_d": bool(byte >> 4 & 1),
        }
        if byte >> 5:
            cparams["block"] = 2 ** ((byte >> 5) + 3)
        header["cparams"] = cparams
        if cparams["version"] == RESTORED_VERSION:
            cparams["version"] = RESTORED_BASE
            header["restore"] = _unpack_restore(reader, header)
    psnr_head = reader.varint("psnr", _MAX_NUMBER_HEAD)
    if psnr_head == 0:
        header["psnr"] = None
    elif psnr_head == 1:
        header["psnr"] = reader.number("psnr", major)
    else:
        header["psnr"] = unzigzag(psnr_head - 2) / 1e4
    header["max_error"] = reader.number("max_error", major)
    if has_extension:
        derived_fitted = header.pop("fitted") if major >= 4 else None
        _merge_extension(reader, header)
        if derived_fitted is not None:  # 4.0: ``fitted`` is derived unless the extension says
            header.setdefault("fitted", derived_fitted)
    return header, weights_derived, pinned


def _merge_extension(reader: _Reader, header: dict[str, Any]) -> None:
    size = reader.varint("extension", _MAX_EXTENSION)
    packed = reader.take(size, "extension")
    inflater = zlib.decompressobj(-15)
    try:
        text = inflater.decompress(packed, _MAX_EXTENSION + 1)
    except zlib.error as exc:
        raise reader.fail("extension", f"not valid DEFLATE data: {exc}") from exc
    if len(text) > _MAX_EXTENSION or not inflater.eof or inflater.unused_data:
        raise reader.fail("extension", "the DEFLATE stream is too long, cut or followed by bytes")
    try:
        extension = json.loads(text.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise reader.fail("extension", f"not UTF-8 JSON: {str(exc)[:80]}") from exc
    if not isinstance(extension, dict) or not extension:
        raise reader.fail("extension", "not a non-empty JSON object")
    for key, value in extension.items():
        if key in header:
            raise reader.fail("extension", f"it repeats the field {key[:40]!r}")
        header[key] = value


def _no_constant(name: str) -> None:
    msg = f"binary header field 'extension' contains {name}, which is not a number"
    raise BundleError(msg)
