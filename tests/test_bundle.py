"""The container format (wavecore.bundle): layout, limits, and clean failures.

Like NumPy's tests of the .npy format, a list of malformed inputs that must each fail with a
BundleError naming what was wrong.
"""

from __future__ import annotations

import binascii
import json
import struct
import zlib
from typing import Any

import pytest

from wavecore import BundleError, binheader
from wavecore.bundle import (
    FORMAT_VERSION,
    MAGIC,
    MAX_ELEMENTS,
    MAX_HEADER_SIZE,
    check_header,
    deflate_header,
    inflate_header,
    read_bundle,
    write_bundle,
)


def make_header(**changes: Any) -> dict[str, Any]:
    header: dict[str, Any] = {
        "kind": "image",
        "shape": [30, 20],
        "dtype": "uint8",
        "fit": "pad",
        "pads": [[0, 4], [0, 2]],
        "fitted": [34, 22],
        "wavelet": "bspline2",
        "boundary": ["open", "open"],
        "levels": 2,
        "colour": "none",
        "quantizer": "deadzone",
        "qparams": {"step": 1.5},
        "coder": "zlib",
        "cparams": {},
        "peak": 255.0,
        "psnr": 41.5,
        "max_error": 3.0,
    }
    header.update(changes)
    return header


CHUNKS = [b"coarse", b"middle level", b"the finest level, longest"]


def raw_bundle(header_bytes: bytes, chunks: list[bytes], major: int = 1, minor: int = 0) -> bytes:
    """Assemble a bundle by hand, with correct CRCs, to reach the checks after the CRC."""
    header_bytes = deflate_header(header_bytes)
    head = struct.pack("<8sBBH", MAGIC, major, minor, len(header_bytes)) + header_bytes
    head += bytes([len(chunks)])
    for chunk in chunks:
        head += struct.pack("<II", len(chunk), zlib.crc32(chunk))
    return head + struct.pack("<I", zlib.crc32(head)) + b"".join(chunks)


@pytest.mark.parametrize("version", [FORMAT_VERSION, (1, 1)])
def test_round_trip_keeps_header_and_chunks(version: tuple[int, int]) -> None:
    header = make_header()
    parsed = read_bundle(write_bundle(header, CHUNKS, version=version))
    assert parsed.header == header
    # 3.1 is what the writer writes, labelled 3.0 for a header without weights the plan gives
    # (as this one); 1.1 on request (no "scale" key: every 1.x reader reads it).
    assert parsed.version == ((3, 0) if version == FORMAT_VERSION else version)
    assert [parsed.chunk(i) for i in range(3)] == CHUNKS
    assert parsed.available == 3


def test_a_scaled_header_is_labelled_1_2_and_checked() -> None:
    header = {**make_header(), "scale": -1070}
    parsed = read_bundle(write_bundle(header, CHUNKS, version=(1, 1)))
    assert parsed.version == (1, 2)
    assert parsed.header["scale"] == -1070
    parsed = read_bundle(write_bundle(header, CHUNKS))
    assert FORMAT_VERSION == (3, 1) and parsed.version == (3, 0)  # no weights to derive
    assert parsed.header == header
    for bad in (True, 1.5, "3", None, 5000, -5000):
        with pytest.raises(BundleError, match="'scale'"):
            write_bundle({**make_header(), "scale": bad}, CHUNKS)


def _varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    return bytes(out + bytes([value]))


def test_layout_2_0_matches_the_spec() -> None:
    """docs/bundle-format.md, byte by byte: preamble, header, lengths, CRC-16s, CRC-32, chunks."""
    header = make_header()
    data = write_bundle(header, CHUNKS, version=(2, 0))
    packed = binheader.pack(header)
    assert data[:10] == MAGIC + bytes([2, 0])
    assert data[10] == len(packed) < 128  # a one-byte varint
    assert data[11 : 11 + len(packed)] == packed
    at = 11 + len(packed)
    assert data[at : at + 3] == bytes(len(c) for c in CHUNKS)  # all below 128
    at += 3
    crc16 = [struct.unpack_from("<H", data, at + 2 * i)[0] for i in range(2)]
    assert crc16 == [binascii.crc_hqx(c, 0) for c in CHUNKS[1:]]  # CRC-16/XMODEM
    at += 4
    (crc,) = struct.unpack_from("<I", data, at)
    assert crc == zlib.crc32(data[:at] + CHUNKS[0])  # the header's CRC covers chunk 0
    assert data[at + 4 :] == b"".join(CHUNKS)
    # The flag bytes and the first fields of make_header(): an image, uint8, padded.
    assert packed[0] == 0 | 0 << 2 | 1 << 4 | 1 << 6  # image, no colour, rank 2, fit pad
    assert packed[1] == 0 | 1 << 4 | 1 << 5 | 1 << 6  # uint8, 2 axes, fitted derived, after
    assert packed[4:].startswith(_varint(2) + _varint(30) + _varint(20) + bytes([4, 2]))


def test_a_bundle_cut_inside_chunk_0_or_with_a_bad_chunk_fails_cleanly() -> None:
    data = write_bundle(make_header(), CHUNKS, version=(2, 0))
    start = len(data) - sum(map(len, CHUNKS))
    with pytest.raises(BundleError, match="truncated inside chunk 0"):
        read_bundle(data[: start + 3])
    damaged = bytearray(data)
    damaged[start + 1] ^= 0x40  # chunk 0: the header's CRC-32 catches it
    with pytest.raises(BundleError, match="header CRC-32 does not match"):
        read_bundle(bytes(damaged))
    damaged = bytearray(data)
    damaged[-1] ^= 0xFF  # the last chunk: its CRC-16, when it is used
    parsed = read_bundle(bytes(damaged))
    assert parsed.chunk(1) == CHUNKS[1]
    with pytest.raises(BundleError, match="chunk 2 is corrupt"):
        parsed.chunk(2)


@pytest.mark.parametrize(
    ("tail", "message"),
    [
        (b"", "truncated while reading the header length"),
        (b"\x80" * 11, "the header length is a varint longer than 10 bytes"),
        (b"\x80\x00", "the header length is a varint with a needless trailing zero"),
        (_varint(70000), "the header length is 70000, more than the largest, 65535"),
        (b"\x05\x00\x00", "truncated while reading the header"),
        (b"\x00", "'flags'"),
    ],
)
def test_malformed_2_0_preambles_fail_cleanly(tail: bytes, message: str) -> None:
    with pytest.raises(BundleError, match=message):
        read_bundle(MAGIC + bytes([2, 0]) + tail)


def test_a_huge_chunk_length_is_refused() -> None:
    packed = binheader.pack(make_header())
    head = MAGIC + bytes([2, 0]) + _varint(len(packed)) + packed
    with pytest.raises(BundleError, match="the length of chunk 0 is 2199023255552, more than"):
        read_bundle(head + _varint(2**41))


def test_layout_matches_the_spec() -> None:
    data = write_bundle(make_header(), CHUNKS, version=(1, 1))
    magic, major, minor, size = struct.unpack_from("<8sBBH", data)
    assert (magic, (major, minor)) == (MAGIC, (1, 1))
    assert json.loads(inflate_header(data[12 : 12 + size])) == make_header()
    assert data[12 + size] == len(CHUNKS)
    table = 13 + size
    lengths = [struct.unpack_from("<II", data, table + 8 * i)[0] for i in range(3)]
    assert lengths == [len(c) for c in CHUNKS]
    payload = table + 8 * 3 + 4
    (crc,) = struct.unpack_from("<I", data, payload - 4)
    assert crc == zlib.crc32(data[: payload - 4])
    assert data[payload:] == b"".join(CHUNKS)


def test_a_truncated_payload_keeps_its_complete_prefix() -> None:
    data = write_bundle(make_header(), CHUNKS)
    cut = data[: len(data) - len(CHUNKS[2]) + 3]
    parsed = read_bundle(cut)
    assert parsed.available == 2
    assert parsed.chunk(1) == CHUNKS[1]
    with pytest.raises(BundleError, match="truncated: chunk 2 of 3 is missing"):
        parsed.chunk(2)


def test_a_corrupt_chunk_fails_only_when_it_is_used() -> None:
    data = bytearray(write_bundle(make_header(), CHUNKS))
    data[-1] ^= 0xFF
    parsed = read_bundle(bytes(data))
    assert parsed.chunk(0) == CHUNKS[0]
    with pytest.raises(BundleError, match="chunk 2 is corrupt"):
        parsed.chunk(2)


def test_unknown_major_version_is_refused_clearly() -> None:
    """A 3.0 bundle whose major version byte says 4: refused by the version, not by a CRC
    (the CRC-32 covers the preamble, so it no longer matches either)."""
    data = bytearray(write_bundle(make_header(), CHUNKS))
    assert data[8:10] == bytes([3, 0])
    data[8] = 4
    with pytest.raises(BundleError, match=r"unsupported bundle format version 4\.0") as error:
        read_bundle(bytes(data))
    assert "CRC" not in str(error.value)


def test_a_2_x_bundle_of_a_later_minor_version_is_read_in_the_2_0_layout() -> None:
    """Minor versions only add optional keys or values, so any 2.x is laid out as 2.0 is."""
    data = bytearray(write_bundle(make_header(), CHUNKS, version=(2, 0)))
    data[9] = 1
    at = len(data) - sum(map(len, CHUNKS)) - 4  # the CRC-32, over the head and chunk 0
    data[at : at + 4] = struct.pack("<I", zlib.crc32(data[:at] + CHUNKS[0]))
    parsed = read_bundle(bytes(data))
    assert parsed.version == (2, 1) and not parsed.block_checks
    assert [parsed.chunk(i) for i in range(3)] == CHUNKS


def test_a_newer_minor_version_with_extra_keys_is_read() -> None:
    header = make_header(future_key={"anything": [1, 2]})
    text = json.dumps(header).encode()
    parsed = read_bundle(raw_bundle(text, CHUNKS, minor=7))
    assert parsed.version == (1, 7)
    assert parsed.chunk(2) == CHUNKS[2]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", "truncated while reading the preamble"),
        (b"\x89WVB", "truncated while reading the preamble"),
        (b"\x89PNG\r\n\x1a\n\x01\x00\x02\x00{}", "not a wavecore bundle"),
        (MAGIC + b"\x01\x00\x00\x00", "header length 0 is too short"),
        (MAGIC + b"\x01\x00\x10\x00{}", "truncated while reading the header"),
        (MAGIC + b"\x01\x00\x02\x00\xff\xff", "not valid DEFLATE data"),
        (MAGIC + b"\x01\x00\x04\x00" + deflate_header(b"[]"), "must be a JSON object"),
        (MAGIC + b"\x01\x00\x04\x00" + deflate_header(b"\xff\xfe"), "not valid UTF-8 JSON"),
        (MAGIC + b"\x01\x00\x04\x00" + deflate_header(b"{}"), "'kind' is missing"),
        ("a string", "must be bytes"),
        (12345, "must be bytes"),
    ],
)
def test_malformed_preambles_fail_cleanly(data: Any, message: str) -> None:
    with pytest.raises(BundleError, match=message):
        read_bundle(data)


BAD_HEADERS = [
    ({"kind": "movie"}, "'kind' is 'movie'"),
    ({"kind": 3}, "'kind' must be a string"),
    ({"dtype": "complex64"}, "'dtype' is 'complex64'"),
    ({"shape": []}, "'shape' must list 1 to 4 sizes"),
    ({"shape": [0, 5]}, "'shape' must hold integers >= 1"),
    ({"shape": [True, 5]}, "'shape' must hold integers"),
    ({"shape": [2.5, 5]}, "'shape' must hold integers"),
    ({"shape": [MAX_ELEMENTS + 1, 1]}, "above MAX_ELEMENTS"),
    ({"fitted": [2**14, 2**14]}, "more than MAX_ELEMENTS"),
    ({"levels": -1}, "'levels' must be between 0 and"),
    ({"levels": 10**6}, "'levels' must be between 0 and"),
    ({"levels": "2"}, "'levels' must be an integer"),
    ({"levels": True}, "'levels' must be an integer, not a boolean"),
    ({"boundary": ["open", "sideways"]}, "'boundary' must list"),
    ({"pads": [[0, 4]]}, "one pair per boundary"),
    ({"pads": [[0, -4], [0, 2]]}, "pairs of integers >= 0"),
    ({"wavelet": "x" * 100}, "'wavelet' must be a short alphanumeric name"),
    ({"coder": "../etc"}, "'coder' must be a short alphanumeric name"),
    ({"qparams": []}, "'qparams' must be an object"),
    ({"peak": -1}, "'peak' must be a finite number >= 0"),
    ({"psnr": "high"}, "'psnr' must be"),
]


@pytest.mark.parametrize(("changes", "message"), BAD_HEADERS)
def test_bad_header_fields_are_named(changes: dict[str, Any], message: str) -> None:
    header = make_header(**changes)
    with pytest.raises(BundleError, match=message):
        check_header(header)
    # The reader refuses it too, even with valid CRCs (a crafted bundle).
    with pytest.raises(BundleError, match=message):
        read_bundle(raw_bundle(json.dumps(header).encode(), CHUNKS))


def test_missing_fields_are_named() -> None:
    for key in make_header():
        header = make_header()
        del header[key]
        with pytest.raises(BundleError, match=f"'{key}' is missing"):
            check_header(header)


@pytest.mark.parametrize(
    "text",
    [
        b'{"kind": NaN}',
        b"[" * 5000 + b"]" * 5000,
        b'{"levels": 1' + b"0" * 5000 + b"}",
        b'{"a": 1e999}',
    ],
)
def test_hostile_json_fails_cleanly(text: bytes) -> None:
    with pytest.raises(BundleError):
        read_bundle(raw_bundle(text, CHUNKS))


def test_a_deflate_bomb_header_is_refused() -> None:
    bomb = deflate_header(b"{" + b" " * 200_000 + b"}")
    assert len(bomb) < 1000
    data = MAGIC + bytes([1, 0]) + struct.pack("<H", len(bomb)) + bomb
    with pytest.raises(BundleError, match="inflates to more than MAX_HEADER_SIZE"):
        read_bundle(data)
    cut = deflate_header(json.dumps(make_header()).encode())[:-5]
    with pytest.raises(BundleError, match=r"incomplete|not valid DEFLATE"):
        read_bundle(MAGIC + bytes([1, 0]) + struct.pack("<H", len(cut)) + cut)


def test_chunk_count_must_match_levels() -> None:
    text = json.dumps(make_header()).encode()
    with pytest.raises(BundleError, match="chunk count 2 does not match"):
        read_bundle(raw_bundle(text, CHUNKS[:2]))
    with pytest.raises(BundleError, match="needs 3 chunks"):
        write_bundle(make_header(), CHUNKS[:2])


@pytest.mark.parametrize("version", [FORMAT_VERSION, (1, 1)])
def test_trailing_bytes_are_refused(version: tuple[int, int]) -> None:
    with pytest.raises(BundleError, match="3 unexpected byte"):
        read_bundle(write_bundle(make_header(), CHUNKS, version=version) + b"abc")


def test_header_crc_catches_a_changed_table() -> None:
    data = bytearray(write_bundle(make_header(), CHUNKS, version=(1, 1)))
    size = struct.unpack_from("<H", data, 10)[0]
    data[13 + size] ^= 1  # the first chunk's length
    with pytest.raises(BundleError, match="header CRC-32 does not match"):
        read_bundle(bytes(data))


def test_header_size_is_bounded() -> None:
    header = make_header(qparams={"steps": list(range(20000))})
    with pytest.raises(BundleError, match="MAX_HEADER_SIZE"):
        write_bundle(header, CHUNKS)
    assert MAX_HEADER_SIZE == 65535  # the uint16 length field of 1.x cannot say more
    with pytest.raises(BundleError, match="MAX_HEADER_SIZE"):
        write_bundle(header, CHUNKS, version=(1, 1))


def test_chunk_views_do_not_copy_the_input() -> None:
    data = write_bundle(make_header(), CHUNKS)
    parsed = read_bundle(data)
    view = parsed.chunks[2]
    assert isinstance(view, memoryview)
    assert view.obj is memoryview(data).obj


def test_writing_the_same_coded_chunks_again_reuses_their_block_checks() -> None:
    # The rate control writes the same chunks twice (a size bound, then the bundle): the
    # block checks are computed once, and a header of another block structure does not reuse
    # them.
    import numpy as np

    import wavecore
    from wavecore.blockcoder import CodedChunk, strip_block_checks
    from wavecore.codec.decode import chunk_block_info

    image = np.random.default_rng(3).integers(0, 256, (300, 280), dtype=np.uint8)
    bundle = wavecore.encode_image(image, level=1, quality=45)
    parsed = read_bundle(bundle)
    header = parsed.header
    stored = [bytes(c or b"") for c in parsed.chunks]
    counts = [4, 4]  # one level: about 150 × 140 coarse and detail samples, 2 × 2 blocks
    chunks = []
    for index, (data, count) in enumerate(zip(stored, counts, strict=True)):
        coded, _, band_counts = strip_block_checks(data, count, 3 if index else 0)
        chunk = CodedChunk(coded)
        chunk.band_counts = band_counts
        chunks.append(chunk)
    info = chunk_block_info(header, chunks)
    assert info is not None and [n for n, _ in info] == counts
    assert write_bundle(header, chunks) == bundle
    assert all(getattr(c, "stored_form", None) is not None for c in chunks)
    assert write_bundle(header, chunks) == bundle  # from the kept forms
    assert write_bundle(header, [bytes(c) for c in chunks]) == bundle  # plain bytes
    other = {**header, "cparams": {**header["cparams"], "block": 64}}
    with pytest.raises(BundleError):  # 64 × 64 blocks: not the structure these chunks have
        write_bundle(other, chunks)
