"""Decoding any bytes returns an array or raises BundleError: never another error, never a hang.

Real bundles are cut at every length and have every byte flipped; then Hypothesis mutates them,
both as they are (the CRCs catch it) and with the CRCs recomputed after the mutation, the way an
attacker would, so that the header checks and the entropy decoder see the damage themselves.
The default run is fast; ``-m slow`` runs more than 10 000 cases.
"""

from __future__ import annotations

import binascii
import contextlib
import json
import struct
import tracemalloc
import zlib
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import BundleError, binheader, decode, inspect
from wavecore.bundle import (
    COMPACT_MAGIC,
    COMPACT_VERSION,
    CURVE_VERSION,
    MAGIC,
    chunk_groups,
    curve_groups,
    deflate_header,
    read_bundle,
    self_delimiting_blocks,
    write_bundle,
)

FAST = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
SLOW = settings(max_examples=2600, deadline=None, suppress_health_check=list(HealthCheck))


def _make_bundles() -> dict[str, bytes]:
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:22, 0:19]
    grey = (120 + 60 * np.sin(x / 3) * np.cos(y / 4) + rng.normal(0, 4, x.shape)).clip(0, 255)
    rgb = np.add.outer(np.arange(11) * 9, np.arange(9) * 5)[..., None] + [0, 40, 90]
    rgb = (rgb + rng.integers(0, 4, rgb.shape)).astype(np.uint8)
    t = np.linspace(0, 2 * np.pi, 37, endpoint=False)
    curve = np.stack([np.cos(t), np.sin(2 * t)], axis=1)
    grid = np.stack([np.add.outer(np.arange(12.0), np.zeros(10)), rng.random((12, 10))], -1)
    compact = wavecore.encode_curve(curve, closed=True, level=2, tolerance=0.01)
    t = np.linspace(0, 1, 90)
    open_curve = wavecore.encode_curve(
        np.stack([t, np.sin(5 * t) * t, t**2], axis=1), level=3, tolerance=1e-4
    )
    lossy = wavecore.encode_image(grey.astype(np.uint8), level=2, quality=30)
    return {
        # Format 3.1, as the codec writes images and surfaces (the weights derived).
        "lossy image": lossy,
        # The same image in 3.0 (its weights stored).
        "lossy image 3.0": write_bundle(*split(lossy), version=(3, 0)),
        "lossless rgb": wavecore.encode_image(rgb, lossless=True, level=2),
        # The same curve in format 3.0 (its chunks are one block each: stored as coded).
        "closed curve": write_bundle(*split(compact), version=(3, 0)),
        "surface": wavecore.encode_surface(grid, closed=(True, False), level=1, quality=30),
        # Format 4.0, as encode_curve wrote curves before 5.0.
        "compact curve": write_bundle(*split(compact), version=COMPACT_VERSION),
        "compact open curve": write_bundle(*split(open_curve), version=COMPACT_VERSION),
        # Format 5.0, as encode_curve writes curves.
        "curve 5.0": compact,
        "open curve 5.0": open_curve,
    }


def split(data: bytes) -> tuple[dict[str, Any], list[bytes]]:
    parsed = read_bundle(data)
    return json.loads(json.dumps(parsed.header)), [bytes(c or b"") for c in parsed.chunks]


BUNDLES = _make_bundles()
NAMES = sorted(BUNDLES)
#: Each bundle's format version.
VERSIONS = {name: read_bundle(data).version for name, data in BUNDLES.items()}


def decodes_or_fails_cleanly(data: bytes, **kwargs: Any) -> np.ndarray | None:
    """Decode; only an array or a BundleError is acceptable.

    Not a BundleError made of a MemoryError: ``decode`` turns one into a BundleError, which
    hid a crafted header's 22.9 GB allocation whenever it failed (under a ``ulimit``, or above
    what the kernel lets a process map) and let the OOM killer take the run when it did not.
    """
    try:
        out = decode(data, **kwargs)
    except BundleError as exc:
        assert not isinstance(exc.__cause__, MemoryError), exc
        return None
    assert isinstance(out, np.ndarray)
    return out


def assemble(header: bytes, chunks: list[bytes], major: int = 1, minor: int = 0) -> bytes:
    """A bundle with correct CRCs around whatever header bytes and chunks it is given."""
    header = deflate_header(header)
    head = struct.pack("<8sBBH", MAGIC, major, minor, len(header)) + header
    head += bytes([len(chunks) % 256])
    for chunk in chunks:
        head += struct.pack("<II", len(chunk), zlib.crc32(chunk))
    return head + struct.pack("<I", zlib.crc32(head)) + b"".join(chunks)


def _varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    return bytes(out + bytes([value]))


def assemble2(packed: bytes, chunks: list[bytes], version: tuple[int, int] = (3, 0)) -> bytes:
    """A format 3.x or 2.0 bundle with correct CRCs around whatever binary header bytes it is
    given (3.x: a CRC-16 per chunk, the CRC-32 over the head; 2.0: chunk 0 under the CRC-32)."""
    head = MAGIC + bytes(version) + _varint(len(packed)) + packed
    if version < (3, 1) or not _delimits_in_3_1(packed):  # 3.1: such chunks have no lengths
        head += b"".join(_varint(len(c)) for c in chunks)
    checked = chunks if version >= (3, 0) else chunks[1:]
    head += b"".join(struct.pack("<H", binascii.crc_hqx(c, 0)) for c in checked)
    if version >= (3, 0):
        return head + struct.pack("<I", zlib.crc32(head)) + b"".join(chunks)
    crc = zlib.crc32(chunks[0] if chunks else b"", zlib.crc32(head))
    return head + struct.pack("<I", crc) + b"".join(chunks)


def _delimits_in_3_1(packed: bytes) -> bool:
    """Whether a 3.1 reader finds the chunks of this header without their lengths: its coder
    code is 3."""
    return len(packed) > 3 and packed[3] >> 2 & 3 == binheader.DELIMITED_CONTEXT


def assemble4(packed: bytes, chunks: list[bytes], minor: int = 0) -> bytes:
    """A format 4.0 bundle with correct CRCs around whatever binary header bytes it is given:
    the 4-byte preamble, the header, the chunk lengths, a CRC-16 per group of chunks, the
    CRC-16 of all that."""
    head = COMPACT_MAGIC + bytes([COMPACT_VERSION[0], minor]) + packed
    head += b"".join(_varint(len(c)) for c in chunks)
    for first, last in chunk_groups([len(c) for c in chunks]):
        head += struct.pack("<H", binascii.crc_hqx(b"".join(chunks[first : last + 1]), 0))
    return head + struct.pack("<H", binascii.crc_hqx(head, 0)) + b"".join(chunks)


def assemble5(
    packed: bytes, chunks: list[bytes], *, lengths: bool = False, minor: int = 0
) -> bytes:
    """A format 5.0 bundle with correct CRCs around whatever binary header bytes it is given:
    the 4-byte preamble, the header, the chunk lengths only when ``lengths`` (a coder whose
    chunks do not delimit themselves), a CRC-16 per group of chunks, the CRC-16 of all that."""
    head = COMPACT_MAGIC + bytes([CURVE_VERSION[0], minor]) + packed
    if lengths:
        head += b"".join(_varint(len(c)) for c in chunks)
    for first, last in curve_groups(len(chunks)):
        head += struct.pack("<H", binascii.crc_hqx(b"".join(chunks[first : last + 1]), 0))
    return head + struct.pack("<H", binascii.crc_hqx(head, 0)) + b"".join(chunks)


def assemble_as(name: str, packed: bytes, chunks: list[bytes]) -> bytes:
    """``packed`` and ``chunks`` in the format version of bundle ``name``."""
    if VERSIONS[name] == COMPACT_VERSION:
        return assemble4(packed, chunks)
    if VERSIONS[name] == CURVE_VERSION:
        return assemble5(packed, chunks, lengths=not _self_delimiting(packed))
    return assemble2(packed, chunks, VERSIONS[name])


def _self_delimiting(packed: bytes) -> bool:
    """Whether a 5.0 reader finds the chunks of this header without their lengths."""
    try:
        return self_delimiting_blocks(binheader.unpack_from(packed, 0)[0]) is not None
    except Exception:  # a crafted header: the reader refuses it before the lengths matter
        return True


#: The versions whose header has no length before it.
SHORT = (COMPACT_VERSION, CURVE_VERSION)


def packed_header(data: bytes) -> bytes:
    """The binary header of a 2.x, 3.x, 4.x or 5.x bundle, as stored."""
    if data[:2] == COMPACT_MAGIC and data[2] in (COMPACT_VERSION[0], CURVE_VERSION[0]):
        return data[4 : binheader.unpack_from(data, 4)[1]]
    assert data[8] in (2, 3) and data[10] < 128
    return data[11 : 11 + data[10]]


def unpack_as(name: str, packed: bytes) -> dict[str, Any]:
    """The header dict of binary header bytes in the version of bundle ``name``; the whole of
    the bytes must be read."""
    if VERSIONS[name] not in SHORT:
        return binheader.unpack_pinned(packed)[0]
    header, end, _ = binheader.unpack_from(packed, 0)
    if end != len(packed):
        msg = "binary header field 'end': unexpected bytes"
        raise BundleError(msg)
    return header


@pytest.mark.parametrize("name", NAMES)
def test_assemble2_rebuilds_the_writers_bytes(name: str) -> None:
    _, chunks = split(BUNDLES[name])
    assert assemble_as(name, packed_header(BUNDLES[name]), chunks) == BUNDLES[name]


@pytest.mark.parametrize("name", NAMES)
def test_a_binary_header_cut_at_every_length_names_a_field(name: str) -> None:
    packed = packed_header(BUNDLES[name])
    _, chunks = split(BUNDLES[name])
    for length in range(len(packed)):
        with pytest.raises(BundleError, match="binary header field '"):
            unpack_as(name, packed[:length])
        assert decodes_or_fails_cleanly(assemble_as(name, packed[:length], chunks)) is None
    if VERSIONS[name] not in SHORT:  # 4.0's header has no length: it ends where it ends
        with pytest.raises(BundleError, match=r"'end'.*1 unexpected byte"):
            binheader.unpack(packed + b"\x00")


@pytest.mark.parametrize("name", NAMES)
def test_every_flipped_header_byte_with_fixed_crcs(name: str) -> None:
    """Each byte of the binary header changed, behind valid CRCs: an array or a BundleError."""
    packed = packed_header(BUNDLES[name])
    _, chunks = split(BUNDLES[name])
    for position in range(len(packed)):
        for flip in (0x01, 0x10, 0x80, 0xFF):
            damaged = bytearray(packed)
            damaged[position] ^= flip
            bundle = assemble_as(name, bytes(damaged), chunks)
            for level in (0, 1):
                with contextlib.suppress(wavecore.InvalidParameter):  # a level too deep
                    decodes_or_fails_cleanly(bundle, level=level)
            with contextlib.suppress(BundleError):
                inspect(bundle)


@pytest.mark.parametrize("name", NAMES)
def test_every_cut_fails_cleanly_or_decodes_its_complete_levels(name: str) -> None:
    data = BUNDLES[name]
    info = inspect(data)
    levels = info["levels"]
    ends = np.cumsum([info["header_bytes"]] + [c["bytes"] for c in info["chunks"]])
    # 4.0 checks chunks in groups: a chunk counts once its whole group is there.
    groups = read_bundle(data).groups or [(i, i) for i in range(levels + 1)]
    full = [decode(data, level=k) for k in range(levels + 1)]
    for length in range(len(data)):
        cut = data[:length]
        assert decodes_or_fails_cleanly(cut) is None  # the finest level always needs more
        present = int(np.searchsorted(ends, length, side="right")) - 1  # chunks fully present
        complete = 0
        while complete < present and groups[complete][1] < present:
            complete += 1
        for k in range(levels + 1):
            out = decodes_or_fails_cleanly(cut, level=k)
            if length >= info["header_bytes"] and levels - k + 1 <= complete:
                assert out is not None and np.array_equal(out, full[k])
            else:
                assert out is None


@pytest.mark.parametrize("name", NAMES)
def test_every_flipped_byte_is_caught(name: str) -> None:
    data = BUNDLES[name]
    for position in range(len(data)):
        damaged = bytearray(data)
        damaged[position] ^= 0xFF
        # Every byte is covered by a magic check, the header CRC or a chunk CRC.
        assert decodes_or_fails_cleanly(bytes(damaged)) is None, position


@pytest.mark.parametrize("name", NAMES)
def test_every_flipped_payload_byte_with_fixed_crcs(name: str) -> None:
    """The decoding stages themselves must reject (or survive) any damaged chunk."""
    header, chunks = split(BUNDLES[name])
    text = json.dumps(header).encode()
    for index, chunk in enumerate(chunks):
        for position in range(len(chunk)):
            damaged = bytearray(chunk)
            damaged[position] ^= (0x01, 0x80, 0xFF)[position % 3]
            mutated = chunks[:index] + [bytes(damaged)] + chunks[index + 1 :]
            decodes_or_fails_cleanly(assemble(text, mutated))


def json_values() -> st.SearchStrategy[Any]:
    leaves = (
        st.none()
        | st.booleans()
        | st.integers(-(2**40), 2**40)
        | st.floats(allow_nan=False, allow_infinity=False)
        | st.text(max_size=12)
    )
    return st.recursive(
        leaves,
        lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner),
        max_leaves=12,
    )


def mutate_header(header: dict[str, Any], data: st.DataObject) -> dict[str, Any]:
    header = dict(header)
    key = data.draw(st.sampled_from(sorted(header)))
    choice = data.draw(st.integers(0, 3))
    value = header[key]
    if choice == 0:
        header[key] = data.draw(json_values())
    elif choice == 1 and isinstance(value, list) and value:
        i = data.draw(st.integers(0, len(value) - 1))
        value = list(value)
        value[i] = data.draw(st.integers(-3, 70000) | json_values())
        header[key] = value
    elif choice == 2 and isinstance(value, dict) and value:
        sub = dict(value)
        subkey = data.draw(st.sampled_from(sorted(sub)))
        sub[subkey] = data.draw(json_values())
        header[key] = sub
    elif isinstance(value, int) and not isinstance(value, bool):
        header[key] = value + data.draw(st.integers(-3, 3))
    else:
        del header[key]
    return header


def mutate_bytes(raw: bytes, data: st.DataObject) -> bytes:
    buffer = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 4))):
        action = data.draw(st.integers(0, 2))
        position = data.draw(st.integers(0, max(len(buffer), 1)))
        if action == 0 and buffer:
            buffer[min(position, len(buffer) - 1)] = data.draw(st.integers(0, 255))
        elif action == 1:
            buffer[position:position] = data.draw(st.binary(min_size=1, max_size=8))
        else:
            del buffer[position : position + data.draw(st.integers(1, 8))]
    return bytes(buffer)


def fuzz_case(data: st.DataObject) -> None:
    name = data.draw(st.sampled_from(NAMES))
    header, chunks = split(BUNDLES[name])
    mode = data.draw(st.integers(0, 5))
    if mode == 0:  # raw damage, CRCs left as they are
        bundle = mutate_bytes(BUNDLES[name], data)
    elif mode == 1:  # damaged chunks with valid CRCs
        index = data.draw(st.integers(0, len(chunks) - 1))
        chunks[index] = mutate_bytes(chunks[index], data)
        bundle = assemble(json.dumps(header).encode(), chunks)
    elif mode == 2:  # a crafted header with valid CRCs
        bundle = assemble(json.dumps(mutate_header(header, data)).encode(), chunks)
    elif mode == 3:  # arbitrary bytes behind a valid preamble
        major = data.draw(st.sampled_from([1, 2, 3, 4, 5]))
        if major in (COMPACT_VERSION[0], CURVE_VERSION[0]):
            bundle = COMPACT_MAGIC + bytes([major, 0])
        else:
            bundle = MAGIC + bytes([major, 0])
        bundle += data.draw(st.binary(max_size=300))
    elif mode == 4:  # a crafted binary header (from a crafted dict) with valid CRCs
        compact = VERSIONS[name] in SHORT
        try:
            packed = binheader.pack(
                mutate_header(header, data),
                major=4 if compact else 3,
                derived_weights=compact and data.draw(st.booleans()),
                # 3.1: the weights left to the plan (quantizer code 3), whatever it gives.
                pinned=None if compact or not data.draw(st.booleans()) else {},
            )
        except BundleError:  # a value the binary header cannot hold
            return
        bundle = assemble_as(name, packed, chunks)
    else:  # damaged binary header bytes with valid CRCs
        bundle = assemble_as(name, mutate_bytes(packed_header(BUNDLES[name]), data), chunks)
    level = data.draw(st.integers(0, 2))
    try:
        decodes_or_fails_cleanly(bundle, level=level)
    except wavecore.InvalidParameter as exc:
        # A level deeper than a (crafted) bundle has; or damage that turned the magic into a
        # curve set's (``\x89WVC``), which takes no level.
        assert "deeper than the bundle" in str(exc) or "a curve set decodes whole" in str(exc)
    with contextlib.suppress(BundleError):
        inspect(bundle)


@FAST
@given(st.data())
def test_fuzz_fast(data: st.DataObject) -> None:
    fuzz_case(data)


@pytest.mark.slow
@SLOW
@given(st.data())
@pytest.mark.parametrize("round_", range(4))
def test_fuzz_slow_10000_cases(round_: int, data: st.DataObject) -> None:
    fuzz_case(data)


@FAST
@given(st.binary(max_size=200))
def test_random_bytes_fail_cleanly(data: bytes) -> None:
    assert decodes_or_fails_cleanly(data) is None


def test_declared_size_is_bounded_before_allocation() -> None:
    header, chunks = split(BUNDLES["lossy image"])
    header["shape"] = [40000, 40000]
    header["fitted"] = [40000 + 2, 40000 + 2]
    bundle = assemble(json.dumps(header).encode(), chunks)
    tracemalloc.start()
    try:
        with pytest.raises(BundleError, match="MAX_ELEMENTS"):
            decode(bundle)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000


def _peak_of_failing_decode(bundle: bytes) -> int:
    """The peak traced memory of decoding ``bundle``, which must fail cleanly."""
    tracemalloc.start()
    try:
        assert decodes_or_fails_cleanly(bundle) is None
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_large_declared_shape_with_a_small_payload_fails_without_large_allocations() -> None:
    header, chunks = split(BUNDLES["lossy image"])
    header["shape"] = [4000, 3000]
    header["pads"] = [[0, 98], [0, 2]]
    header["fitted"] = [4098, 3002]
    bundle = assemble(json.dumps(header).encode(), chunks)
    # Never more than a few float64 arrays of the declared size (4098 × 3002 elements).
    assert _peak_of_failing_decode(bundle) < 6 * 8 * 4098 * 3002


def test_a_short_curve_of_many_dimensions_fails_without_large_allocations() -> None:
    """A crafted header turning the 90 × 3 curve into 474 points of 2 000 dimensions.

    The block decoder once gave every dimension (a plane of its own) the tile flags of a whole
    1-D block, 16 KiB each however short the curve, and cleared them for every block: one
    flipped byte gave 474 × 16 107 and 563 MB, and 700 000 dimensions would take the 22.9 GB
    that got a test run killed (under a ``ulimit`` the MemoryError became a BundleError).
    """
    name = "compact open curve"
    header = binheader.unpack_from(packed_header(BUNDLES[name]), 0)[0]
    shape = [474, 2000]
    packed = binheader.pack({**header, "shape": shape, "fitted": shape}, major=4)
    bundle = assemble_as(name, packed, split(BUNDLES[name])[1])
    # The int32 coefficients of the declared size and little else (the flags took 32-64 MB).
    assert _peak_of_failing_decode(bundle) < 8 * 474 * 2000


def test_padding_far_beyond_the_original_is_refused() -> None:
    """A tiny bundle cannot make the decoder allocate a grid far larger than its original."""
    header, chunks = split(BUNDLES["lossy image"])
    header["shape"] = [1, 1]
    header["pads"] = [[0, 6145], [0, 6145]]
    header["fitted"] = [6146, 6146]
    header["levels"] = 11
    chunks = chunks + [b""] * 9
    with pytest.raises(BundleError, match="pads axis 0 far beyond its length"):
        decode(assemble(json.dumps(header).encode(), chunks))


def test_unknown_major_version_through_decode() -> None:
    data = bytearray(BUNDLES["surface"])
    data[8] = 9
    with pytest.raises(BundleError, match="unsupported bundle format version 9"):
        decode(bytes(data))
