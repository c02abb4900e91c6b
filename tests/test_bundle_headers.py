"""Malformed headers, field by field: each gives a ``BundleError`` that names the field.

Like NumPy's tests of the ``.npy`` header, a table of bad values per field, each written into a
real bundle behind valid CRCs (as an attacker would), so that only the header checks stand
between it and the decoder.  ``decode`` (at every level) and ``inspect`` must both refuse it
cleanly; a few values that are well-formed (an ignored key, an informational number) must decode
to exactly what the untouched bundle gives.
"""

from __future__ import annotations

import contextlib
import json
import math
import struct
from typing import Any

import numpy as np
import pytest
from test_bundle_fuzz import (  # the same real bundles as the fuzz
    BUNDLES,
    assemble,
    assemble2,
    packed_header,
    split,
)

import wavecore
from wavecore import BundleError, binheader, decode, inspect
from wavecore.bundle import deflate_header, read_bundle

MISSING = object()  # the row deletes the field

#: (field, bad value) for every kind of bundle.  The message must name the field.
ANY_BUNDLE: list[tuple[str, Any]] = [
    *[("kind", v) for v in (MISSING, None, 5, "x", ["image"], "")],
    *[("shape", v) for v in (MISSING, None, [], [0, 5], [-1, 5], [2**40, 1], [1, 2, 3, 4, 5])],
    *[("shape", v) for v in ("22", [22.5, 19], [True, 19], [None, 19])],
    *[("dtype", v) for v in (MISSING, None, "complex128", 3, "object", "<f8")],
    *[("fit", v) for v in (MISSING, None, "zz", 1)],
    *[("pads", v) for v in (MISSING, None, "x", [[0]], [[-1, 0], [0, 0]], [[0.5, 0], [0, 0]])],
    *[("pads", v) for v in ([[0, 2**40], [0, 0]], [[0, 0], [0, 0], [0, 0]], [None, None])],
    *[("fitted", v) for v in (MISSING, None, [1, 1], [2**40, 2], [0, 4], "x")],
    *[("wavelet", v) for v in (MISSING, None, "nope", "x" * 100, 7, "a b")],
    *[("boundary", v) for v in (MISSING, None, ["wrap"], [], ["open"] * 3, "open", [None])],
    *[("levels", v) for v in (MISSING, None, -1, 31, 2.5, True, 1000, "2", 2**70)],
    *[("colour", v) for v in (MISSING, None, "cmyk", 0)],
    *[("quantizer", v) for v in (MISSING, None, "", "zz", "a" * 40)],
    *[("qparams", v) for v in (MISSING, None, [], "x")],
    *[("coder", v) for v in (MISSING, None, "zz", "")],
    *[("cparams", v) for v in (MISSING, None, [], {}, {"coder": "zz"})],
    *[("peak", v) for v in (MISSING, None, -1, "1", [1.0])],
    *[("psnr", v) for v in (MISSING, "x", [1])],
    *[("max_error", v) for v in (MISSING, -1, None, "0")],
    *[("scale", v) for v in (True, 1.5, 5000, -5000, "3", None)],
    *[("opaque", v) for v in (1, "yes", None, [True])],
]

#: Rows that apply to some bundles only: (bundle, field, value, what the message names).
SPECIFIC: list[tuple[str, str, Any, str]] = [
    # issue 10: ``"lifting": null`` on a lossless bundle was a TypeError.
    ("lossless rgb", "lifting", None, "lifting"),
    ("lossless rgb", "lifting", [], "lifting"),
    ("lossless rgb", "lifting", ["zz", "zz"], "lifting"),
    ("lossless rgb", "lifting", "legall53", "lifting"),
    ("lossless rgb", "lifting", [None, None], "lifting"),
    ("lossless rgb", "lifting", [["legall53"], "haar"], "lifting"),
    ("lossless rgb", "lifting", ["bspline2", "bspline2"], "lifting"),  # odd sizes
    ("lossless rgb", "boundary", ["open", "open"], "boundary"),
    ("lossless rgb", "colour", "ycbcr", "lossless"),
    ("lossless rgb", "dtype", "float64", "lossless"),
    ("lossless rgb", "pads", [[0, 1], [0, 0]], "fitted"),
    ("lossless rgb", "quantizer", "deadzone", "quantizer"),
    ("lossless rgb", "shape", [11, 9, 7], "fitted"),
    ("lossless rgb", "scale", 3, "scale"),  # integers are never scaled
    ("lossy image", "wavelet", "reversible", "lossless"),
    ("lossy image", "colour", "ycbcr", "colour"),
    ("lossy image", "kind", "curve", "curve"),
    ("lossy image", "qparams", {}, "quantizer"),
    ("lossy image", "qparams", {"name": "deadzone"}, "qparams"),
    ("lossy image", "qparams", {"name": "deadzone", "step": -1.0}, "qparams"),
    ("lossy image", "cparams", {"coder": "context", "version": 99}, "coder"),
    ("lossy image", "cparams", {"coder": "context", "version": 3, "two_d": "x"}, "coder"),
    ("lossy image", "levels", 5, "levels"),
    ("lossy image", "levels", 0, "chunk count"),
    ("lossy image", "fitted", [23, 19], "fitted"),
    ("lossy image", "shape", [22, 19, 3], "colour|fitted|boundar"),
    ("closed curve", "boundary", ["closed", "closed"], "boundar"),
    ("closed curve", "shape", [37, 2, 2], "shape"),
    ("closed curve", "pads", [[0, 0], [0, 0]], "pads"),
    ("surface", "shape", [12], "shape"),
    ("surface", "fitted", [12, 10, 3], "fitted"),
    ("lossy image", "opaque", True, "opaque"),  # a grey image has no alpha
    ("surface", "opaque", True, "opaque"),
]

#: Well-formed values a reader accepts: the bundle decodes exactly as before.
HARMLESS: list[tuple[str, str, Any]] = [
    # ``lifting`` means something only with the reversible wavelet; elsewhere it is ignored, as
    # unknown keys are (issue 10's null ``lifting`` on a lossy bundle was a TypeError).
    *[
        (name, "lifting", v)
        for name in ("lossy image", "closed curve", "surface")
        for v in (None, [], ["zz"], "x", {"a": 1})
    ],
    ("lossy image", "psnr", None),
    ("lossy image", "max_error", 0),
    ("lossy image", "unknown_key", [1, 2, 3]),
    ("lossy image", "scale", 0),
]


def _bundle_with(name: str, field: str, value: Any) -> bytes:
    header, chunks = split(BUNDLES[name])
    if value is MISSING:
        del header[field]
    else:
        header[field] = value
    return assemble(json.dumps(header).encode(), chunks)


#: What the quantizer and coder parameters hold is read only by decoding, so ``inspect`` (which
#: describes a bundle without decoding it) may accept a bundle whose parameters are wrong inside.
DECODER_FIELDS = ("qparams", "cparams")


def _refused(data: bytes, names: str, levels: int, *, inspect_too: bool = True) -> None:
    for level in range(levels + 1):
        with pytest.raises(BundleError, match=names):
            decode(data, level=level)
    if inspect_too:
        with pytest.raises(BundleError, match=names):
            inspect(data)
    else:
        with contextlib.suppress(BundleError):
            inspect(data)


@pytest.mark.parametrize("name", sorted(BUNDLES))
@pytest.mark.parametrize(("field", "value"), ANY_BUNDLE, ids=repr)
def test_a_bad_field_is_named(name: str, field: str, value: Any) -> None:
    _refused(_bundle_with(name, field, value), field, inspect(BUNDLES[name])["levels"])


@pytest.mark.parametrize(("name", "field", "value", "names"), SPECIFIC, ids=repr)
def test_a_field_inconsistent_with_the_rest_is_refused(
    name: str, field: str, value: Any, names: str
) -> None:
    data = _bundle_with(name, field, value)
    levels = inspect(BUNDLES[name])["levels"]
    _refused(data, names, levels, inspect_too=field not in DECODER_FIELDS or value == {})


@pytest.mark.parametrize(("name", "field", "value"), HARMLESS, ids=repr)
def test_a_well_formed_value_decodes_as_before(name: str, field: str, value: Any) -> None:
    data = _bundle_with(name, field, value)
    assert np.array_equal(decode(data), decode(BUNDLES[name]))
    assert inspect(data)["shape"] == inspect(BUNDLES[name])["shape"]


@pytest.mark.parametrize("name", sorted(BUNDLES))
def test_a_bundle_of_empty_chunks_is_refused(name: str) -> None:
    """Issue 10: a bundle whose chunks were all empty decoded to zeros."""
    header, chunks = split(BUNDLES[name])
    with pytest.raises(BundleError, match="chunk 0 is empty"):
        decode(assemble(json.dumps(header).encode(), [b""] * len(chunks)))
    # One empty chunk among good ones is refused too, at the levels that need it.
    emptied = [*chunks[:-1], b""]
    data = assemble(json.dumps(header).encode(), emptied)
    with pytest.raises(BundleError, match=f"chunk {len(chunks) - 1} is empty"):
        decode(data)
    assert np.array_equal(decode(data, level=1), decode(BUNDLES[name], level=1))


def test_the_table_covers_every_field_an_encoder_writes() -> None:
    written = set()
    for data in BUNDLES.values():
        written |= set(read_bundle(data).header)
    covered = {field for field, _ in ANY_BUNDLE} | {row[1] for row in SPECIFIC}
    assert written <= covered, written - covered
    huge = wavecore.encode_surface(np.full((6, 6), 1e300))
    assert set(read_bundle(huge).header) <= covered


# --------------------------------------------------------------------------------------------
# Format 2.0: the same table through the binary header, then its bytes one field at a time
# --------------------------------------------------------------------------------------------


def _packed_with(name: str, field: str, value: Any) -> bytes | None:
    """The bundle with one field changed, as a crafted 2.0 bundle; None if the binary header
    has no way to say the value (its codes cannot name a bad kind, say)."""
    header, chunks = split(BUNDLES[name])
    if value is MISSING:
        del header[field]
    else:
        header[field] = value
    try:
        return assemble2(binheader.pack(header), chunks)
    except BundleError:
        return None


@pytest.mark.parametrize("name", sorted(BUNDLES))
@pytest.mark.parametrize(("field", "value"), ANY_BUNDLE, ids=repr)
def test_a_bad_field_in_a_binary_header_is_named(name: str, field: str, value: Any) -> None:
    data = _packed_with(name, field, value)
    if data is not None:
        _refused(data, field, inspect(BUNDLES[name])["levels"])


@pytest.mark.parametrize(("name", "field", "value", "names"), SPECIFIC, ids=repr)
def test_an_inconsistent_field_in_a_binary_header_is_refused(
    name: str, field: str, value: Any, names: str
) -> None:
    data = _packed_with(name, field, value)
    if data is None:  # the binary header has one pads pair per boundary, by construction
        assert (name, field) in UNSAYABLE_IN_BINARY
        return
    # In 2.0 the chunk count is levels + 1 by construction: a wrong ``levels`` reads the chunk
    # table wrongly, and the table's varints or the CRC-32 say so.
    names = "chunk|CRC" if field == "levels" else names
    levels = inspect(BUNDLES[name])["levels"]
    _refused(data, names, levels, inspect_too=field not in DECODER_FIELDS or value == {})


UNSAYABLE_IN_BINARY = {("closed curve", "boundary"), ("closed curve", "pads")}


@pytest.mark.parametrize(("name", "field", "value"), HARMLESS, ids=repr)
def test_a_well_formed_value_in_a_binary_header_decodes_as_before(
    name: str, field: str, value: Any
) -> None:
    data = _packed_with(name, field, value)
    assert data is not None
    assert np.array_equal(decode(data), decode(BUNDLES[name]))


def _first_difference(a: bytes, b: bytes) -> int:
    return next(i for i, (x, y) in enumerate(zip(a, b, strict=False)) if x != y)


def _with_bytes(packed: bytes, at: int, old_size: int, new: bytes) -> bytes:
    return packed[:at] + new + packed[at + old_size :]


def _flags(name: str, byte: int, mask: int, bits: int) -> bytes:
    packed = bytearray(packed_header(BUNDLES[name]))
    packed[byte] = packed[byte] & ~mask | bits
    return bytes(packed)


#: (bundle, flag byte, mask, new bits, the field the error names): codes no table holds.
UNKNOWN_CODES = [
    ("lossy image", 0, 0x03, 0x03, "'kind'.*unknown code 3"),
    *[("surface", 1, 0x0F, code, f"'dtype'.*unknown code {code}") for code in range(10, 16)],
    ("closed curve", 1, 0xC0, 0xC0, "'pads'.*unknown pads form 3"),
    *[("lossy image", 2, 0x07, code, "'wavelet'.*unknown code") for code in (5, 6, 7)],
    ("lossy image", 2, 0x18, 0x18, "'boundary'.*unknown code 3"),
    ("lossy image", 2, 0x60, 0x60, "'boundary'.*unknown code 3"),
    ("closed curve", 2, 0x60, 0x20, "'boundary'.*a second boundary code"),
    # Code 3 (3.1: the weights derived) holds its parameters in the compact form only.
    ("lossy image", 3, 0x13, 0x03, "'flags'.*quantizer code 3 without"),
    # Coder code 3 (3.1: the context coder, chunks without lengths): compact parameters only.
    ("lossy image", 3, 0x2C, 0x0C, "'flags'.*coder code 3 without"),
    ("lossless rgb", 3, 0x80, 0x80, "'flags'.*default-rounding"),
    ("lossy image", 3, 0x03, 0x02, "'flags'.*compact parameters"),
]


@pytest.mark.parametrize(("name", "byte", "mask", "bits", "message"), UNKNOWN_CODES, ids=repr)
def test_an_unknown_code_is_named(name: str, byte: int, mask: int, bits: int, message: str) -> None:
    packed = _flags(name, byte, mask, bits)
    with pytest.raises(BundleError, match=message):
        binheader.unpack(packed)
    with pytest.raises(BundleError, match=message):
        decode(assemble2(packed, split(BUNDLES[name])[1]))


def _offset_of(name: str, field: str, value: Any) -> tuple[bytes, int]:
    """The packed header and the offset where ``field`` starts (found by changing it)."""
    header, _ = split(BUNDLES[name])
    packed = binheader.pack(header)
    return packed, _first_difference(packed, binheader.pack({**header, field: value}))


def test_huge_and_malformed_varints_are_named() -> None:
    packed = packed_header(BUNDLES["lossy image"])
    levels_at = 4  # after the four flag bytes
    for varint, message in [
        (b"\x80" * 10 + b"\x01", "'levels'.*longer than 10 bytes"),
        (b"\x82\x00", "'levels'.*needless trailing zero"),
        (b"\x80\x80\x04", "'levels'.*65536 is more than the largest, 255"),
    ]:
        with pytest.raises(BundleError, match=message):
            binheader.unpack(_with_bytes(packed, levels_at, 1, varint))
    shape_at = levels_at + 1
    huge = bytes([0xFF] * 9 + [0x01])  # 2**64 - 1
    with pytest.raises(BundleError, match=r"'shape'.*more than the largest"):
        binheader.unpack(_with_bytes(packed, shape_at, 1, huge))


def test_a_bad_number_is_named() -> None:
    _, at = _offset_of("lossy image", "peak", 1e300)
    header, _ = split(BUNDLES["lossy image"])
    wide = binheader.pack({**header, "peak": 1e300})  # now a float64: form 14, 8 bytes
    nan = _with_bytes(wide, at + 1, 8, struct.pack("<d", math.nan))
    with pytest.raises(BundleError, match=r"'peak'.*not a finite number"):
        binheader.unpack(nan)
    with pytest.raises(BundleError, match=r"'peak'.*takes no value bits"):
        binheader.unpack(_with_bytes(wide, at, 9, bytes([0x1C])))  # null form, value bits 1


def test_a_bad_weight_code_is_named() -> None:
    header, chunks = split(BUNDLES["lossy image"])
    packed = binheader.pack(header)
    step_at = packed.index(struct.pack("<d", header["qparams"]["step"]))
    first_weight = step_at + 8 + 1  # the default rounding, then the cH = cV mask (one byte)
    bad = _with_bytes(packed, first_weight, 2, struct.pack("<H", 63000))
    with pytest.raises(BundleError, match=r"'qparams.weights'.*weight code 63000"):
        decode(assemble2(bad, chunks))


def test_a_bad_lifting_code_is_named() -> None:
    header, chunks = split(BUNDLES["lossless rgb"])
    packed = binheader.pack(header)
    at = _first_difference(packed, binheader.pack({**header, "lifting": ["haar", "haar"]}))
    # Code 3 is 511c now (every 2-bit code is taken): only bits past the last filter are bad.
    three = binheader.unpack(_with_bytes(packed, at, 1, bytes([packed[at] | 0x03])))
    assert three["lifting"][0] == "511c"
    with pytest.raises(BundleError, match=r"'lifting'.*bits set beyond"):
        decode(assemble2(_with_bytes(packed, at, 1, bytes([packed[at] | 0x30])), chunks))


@pytest.mark.parametrize(
    ("extension", "message"),
    [
        (b"\x05" + b"\xff" * 5, "'extension'.*not valid DEFLATE"),
        (b"\x02" + deflate_header(b"[1]")[:1], "'extension'"),
        (len(deflate_header(b"[1]")).to_bytes(1, "little") + deflate_header(b"[1]"), "object"),
        (len(deflate_header(b"{}")).to_bytes(1, "little") + deflate_header(b"{}"), "non-empty"),
        (
            len(deflate_header(b'{"kind":"image"}')).to_bytes(1, "little")
            + deflate_header(b'{"kind":"image"}'),
            "repeats the field 'kind'",
        ),
        (
            len(deflate_header(b'{"a":NaN}')).to_bytes(1, "little") + deflate_header(b'{"a":NaN}'),
            "NaN",
        ),
        (b"\x80\x80\x04", "'extension'.*more than the largest"),
    ],
)
def test_a_bad_extension_is_named(extension: bytes, message: str) -> None:
    packed = bytearray(packed_header(BUNDLES["closed curve"]))
    packed[3] |= 1 << 6  # an extension follows the last field
    with pytest.raises(BundleError, match=message):
        binheader.unpack(bytes(packed) + extension)
