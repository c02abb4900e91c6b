"""Bundle format 4.0, the compact layout ``encode_curve`` wrote before 5.0 (docs/bundle-format.md;
tests/test_bundle_curve5.py tests 5.0).

What it must keep from 3.0: every field of the header, resolution decodes, damage found per
group of chunks (and per chunk where chunks are large), ``damaged="zero"``, truncated bundles
decoding their complete groups.  What it must give: a curve's overhead (``header_bytes``,
everything but the chunks) at most 48 bytes at every length from 8 to 50 000 points at the
default levels (5.0 holds it at every level).
"""

from __future__ import annotations

import binascii
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_bundle_fuzz import BUNDLES, assemble4, packed_header, split

import wavecore
from wavecore import BundleError, binheader, decode, inspect
from wavecore.blockcoder import strip_block_checks
from wavecore.bundle import (
    COMPACT_MAGIC,
    COMPACT_VERSION,
    CURVE_VERSION,
    FORMAT_VERSION,
    GROUP_BYTES,
    MAGIC,
    chunk_groups,
    derived_weights,
    read_bundle,
    with_header,
    write_bundle,
    written_version,
)
from wavecore.codec import replication

GOLDEN = Path(__file__).resolve().parent / "golden"
MANIFEST = json.loads((GOLDEN / "MANIFEST.json").read_text())


def _as_4_0(bundle: bytes) -> bytes:
    """The header and chunks of a (5.0 or 6.0) bundle written in 4.0."""
    parsed = read_bundle(bundle)
    checked = parsed.checked or (None,) * len(parsed.chunks)
    chunks = [  # as the coder wrote them: 6.0 adds block checks to chunks of several blocks
        bytes(c or b"") if own is None else strip_block_checks(bytes(c or b""), *own)[0]
        for c, own in zip(parsed.chunks, checked, strict=True)
    ]
    return write_bundle(parsed.header, chunks, version=(4, 0))


def _curve(n: int, dims: int) -> np.ndarray:
    t = np.linspace(0, 1, n)
    return np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:dims], axis=1)


@pytest.mark.parametrize("n", [8, 50, 200, 1000, 50_000])
@pytest.mark.parametrize("closed", [False, True])
def test_a_curve_header_is_at_most_48_bytes_at_every_length(n: int, closed: bool) -> None:
    # issue 11's target, for the curves benchmarks/header_sizes.py measures (2-D and 3-D).
    for dims in (2, 3):
        bundle = _as_4_0(wavecore.encode_curve(_curve(n, dims), closed=closed))
        info = inspect(bundle)
        assert info["version"] == "4.0"
        assert info["header_bytes"] <= 48, (n, dims, closed, info["header_bytes"])
        assert info["header_bytes"] + sum(c["bytes"] for c in info["chunks"]) == len(bundle)


def test_a_curve_header_stays_small_at_explicit_levels() -> None:
    # Each level beyond the default adds about one byte (its chunk's length); 13 levels of a
    # 50 000-point curve still fit in 48 bytes.
    points = _curve(50_000, 2)
    sizes = [
        inspect(_as_4_0(wavecore.encode_curve(points, level=k)))["header_bytes"] for k in (2, 8, 13)
    ]
    assert sizes[-1] <= 48 and sizes == sorted(sizes)


def test_images_and_surfaces_are_written_in_3_1() -> None:
    image = np.add.outer(np.arange(40), np.arange(36)).astype(np.uint8)
    assert inspect(wavecore.encode_image(image))["version"] == "3.1"
    assert inspect(wavecore.encode_surface(image.astype(float)))["version"] == "3.1"
    assert written_version({"kind": "image"}) == FORMAT_VERSION == (3, 1)
    assert written_version({"kind": "curve"}) == CURVE_VERSION == (6, 0)
    assert COMPACT_VERSION == (4, 0)


def test_the_preamble_is_four_bytes_and_never_the_old_magic() -> None:
    bundle = BUNDLES["compact curve"]
    assert bundle[:4] == COMPACT_MAGIC + bytes(COMPACT_VERSION) == b"\x89W\x04\x00"
    assert MAGIC[:2] == COMPACT_MAGIC and MAGIC[2] == ord("V")  # never read as a major
    with pytest.raises(BundleError, match=r"unsupported bundle format version 8\.0"):
        read_bundle(COMPACT_MAGIC + bytes([8, 0]) + bundle[4:])  # (7.0 is the replication's)
    with pytest.raises(BundleError, match=r"unsupported bundle format version 4\.0"):
        read_bundle(MAGIC + bytes([4, 0]) + bundle[4:])  # 4.x never has the long magic
    with pytest.raises(BundleError, match="truncated while reading the preamble"):
        read_bundle(bundle[:3])
    # A later minor version is read as 4.0 (it may only add codes, refused by name).
    later = assemble4(packed_header(bundle), split(bundle)[1], minor=1)
    assert read_bundle(later).version == (4, 1)
    assert np.array_equal(decode(later), decode(bundle))


@pytest.mark.parametrize(
    "name", sorted(n for n, e in MANIFEST.items() if e["kind"] == "curve" and e["version"] < "4")
)
def test_derived_weights_are_the_weights_older_bundles_stored(name: str) -> None:
    # 3.0 and earlier bundles store their weights: the plan must give exactly those, or a 4.0
    # bundle (which stores none) would decode with other steps than it was coded with.
    header = read_bundle((GOLDEN / f"{name}.wvb").read_bytes()).header
    if header["quantizer"] != "deadzone":
        pytest.skip("a lossless curve has no weights")
    assert derived_weights(header) == header["qparams"]["weights"]


def test_derived_weights_match_two_axis_golden_bundles_too() -> None:
    checked = 0
    for name, entry in MANIFEST.items():
        if entry["kind"] == "curve" or entry["quantizer"] != "deadzone":
            continue
        if entry["arguments"].get("nudge_weight"):  # a 3.1 bundle with a weight not the plan's
            continue
        data = (GOLDEN / f"{name}.wvb").read_bytes()
        if replication.is_replicated(data):  # 7.0: the source's bundle holds the header
            data = replication.unwrap(data)[1]
        header = read_bundle(data).header
        assert derived_weights(header) == header["qparams"]["weights"], name
        checked += 1
    assert checked >= 8


def test_a_4_0_curve_header_carries_no_weights_and_a_float32_step() -> None:
    bundle = BUNDLES["compact open curve"]
    header = read_bundle(bundle).header
    step = header["qparams"]["step"]
    assert float(np.float32(step)) == step
    levels = header["levels"]
    # The same header with the weights and a float64 step: 2 bytes a weight and 4 more.
    longer = binheader.pack(header, major=4)
    assert len(longer) - len(packed_header(bundle)) == 2 * (levels + 1)
    assert header["qparams"]["weights"] == derived_weights(header)


def test_the_recorded_errors_are_those_of_what_decodes() -> None:
    points = _curve(300, 2)
    for options in ({"tolerance": 2e-3}, {"keep": 0.4}):
        bundle = wavecore.encode_curve(points, **options)
        out = decode(bundle)
        largest = float(np.max(np.linalg.norm(out - points, axis=1)))
        info = inspect(bundle)
        # max_error is an upper bound within float32's precision (2**-23) of the measured one.
        assert largest <= info["max_error"] <= largest * (1 + 2**-22)
        if "tolerance" in options:
            assert largest <= options["tolerance"]
        span = float(np.ptp(points))
        assert span <= info["peak"] <= span * (1 + 2**-8)  # rounded up to 9 significant bits
        mse = float(np.mean((out - points) ** 2))
        assert info["psnr"] == pytest.approx(10 * math.log10(info["peak"] ** 2 / mse), abs=2e-4)


def test_chunk_groups_pack_small_chunks_and_leave_large_ones_alone() -> None:
    assert chunk_groups([10]) == [(0, 0)]
    assert chunk_groups([1000, 24, 1, 2000, 1, 1]) == [(0, 1), (2, 2), (3, 3), (4, 5)]
    assert chunk_groups([GROUP_BYTES + 1, 0, 0]) == [(0, 0), (1, 2)]
    lengths = list(np.random.default_rng(3).integers(0, 3000, 40))
    groups = chunk_groups(lengths)
    assert [g[0] for g in groups[1:]] == [g[1] + 1 for g in groups[:-1]]  # a partition
    for first, last in groups:
        assert first == last or sum(lengths[first : last + 1]) <= GROUP_BYTES


def _noisy_bundle() -> bytes:
    return (GOLDEN / "v4_0_curve_noisy_groups.wvb").read_bytes()


def test_damage_in_one_group_loses_only_its_chunks() -> None:
    bundle = _noisy_bundle()
    parsed = read_bundle(bundle)
    groups = sorted(set(parsed.groups or ()))
    assert len(groups) >= 3
    info = inspect(bundle)
    starts = np.cumsum([info["header_bytes"]] + [c["bytes"] for c in info["chunks"]])
    levels = info["levels"]
    clean = decode(bundle)
    for first, last in groups:
        damaged = bytearray(bundle)
        damaged[int(starts[first]) + 3] ^= 0x40
        with pytest.raises(BundleError, match=f"chunk {first} is corrupt"):
            decode(bytes(damaged))
        # The levels coarser than the group still decode exactly.
        for k in range(levels - first + 1, levels + 1):
            assert np.array_equal(decode(bytes(damaged), level=k), decode(bundle, level=k))
        zeroed = decode(bytes(damaged), damaged="zero")
        # Zeroing the details of the group's levels: what decode gives without those chunks.
        if first > 0:
            cut = decode(bundle[: int(starts[first])], damaged="zero")
            if last == levels:
                assert np.array_equal(zeroed, cut)
            assert not np.array_equal(zeroed, clean)


def test_a_cut_inside_a_group_loses_the_group() -> None:
    bundle = _noisy_bundle()
    parsed = read_bundle(bundle)
    info = inspect(bundle)
    ends = np.cumsum([info["header_bytes"]] + [c["bytes"] for c in info["chunks"]])
    first, last = parsed.groups[-1]
    cut = read_bundle(bundle[: int(ends[last + 1]) - 1])
    assert cut.available == first
    with pytest.raises(BundleError, match="truncated"):
        cut.chunk(first)


def test_every_kind_round_trips_in_4_0() -> None:
    for name in ("lossy image", "lossless rgb", "surface", "closed curve"):
        header, chunks = split(BUNDLES[name])  # one block a chunk: stored as coded
        parsed = read_bundle(BUNDLES[name])
        compact = write_bundle(header, chunks, version=COMPACT_VERSION)
        assert read_bundle(compact).header == parsed.header
        assert np.array_equal(decode(compact), decode(BUNDLES[name]))
        assert len(compact) < len(BUNDLES[name])


def test_fields_without_a_compact_form_go_to_the_extension() -> None:
    header, _ = split(BUNDLES["compact curve"])
    header["cparams"] = {**header["cparams"], "block": 64}  # not the default: its byte
    header["qparams"] = {**header["qparams"], "note": 1}  # no compact form: the extension
    header["fitted"] = [header["fitted"][0], 5]  # not derived: the extension
    header["later"] = [1, 2]
    packed = binheader.pack(header, major=4)
    unpacked, end, derived = binheader.unpack_from(packed + b"tail", 0)
    assert unpacked == header and end == len(packed) and not derived


@pytest.mark.parametrize(
    ("byte", "bit", "message"),
    [
        (3, 4, "float32-step flag without a deadzone"),
        (3, 5, "default-parameters flag without the context coder"),
        (1, 5, "derived-weights flag without a deadzone"),
    ],
)
def test_4_0_flags_that_contradict_the_stages_are_named(byte: int, bit: int, message: str) -> None:
    header, chunks = split(BUNDLES["lossless rgb"])  # quantizer none, coder context
    if "coder" in message:
        header["coder"], header["cparams"] = "zlib", {"coder": "zlib"}
    packed = bytearray(binheader.pack(header, major=4))
    packed[byte] |= 1 << bit
    with pytest.raises(BundleError, match=message):
        binheader.unpack_from(bytes(packed), 0)
    with pytest.raises(BundleError, match=message):
        decode(assemble4(bytes(packed), chunks))


def test_the_head_check_covers_every_byte_before_it() -> None:
    bundle = BUNDLES["compact curve"]
    info = inspect(bundle)
    head = info["header_bytes"] - 2
    assert struct.unpack("<H", bundle[head : head + 2])[0] == binascii.crc_hqx(bundle[:head], 0)
    for position in range(2, head):
        damaged = bytearray(bundle)
        damaged[position] ^= 0x04
        with pytest.raises(BundleError):
            read_bundle(bytes(damaged))


def test_with_header_keeps_the_chunks() -> None:
    bundle = BUNDLES["compact curve"]
    header = read_bundle(bundle).header
    changed = with_header(bundle, {**header, "psnr": 12.5})
    assert read_bundle(changed).header == {**header, "psnr": 12.5}
    assert changed.endswith(bytes(b"".join(split(bundle)[1])))
    with pytest.raises(BundleError, match=r"complete 4\.x, 5\.x or 6\.x bundle"):
        with_header(BUNDLES["closed curve"], header)


@settings(max_examples=300, deadline=None)
@given(
    st.floats(allow_nan=False, allow_infinity=False)
    | st.integers(-(2**60), 2**60).map(lambda k: math.ldexp(k, -30))
)
def test_every_number_comes_back_bit_for_bit_in_4_0(value: float) -> None:
    header, _ = split(BUNDLES["compact curve"])
    header["psnr"] = None  # psnr has its own form; peak and max_error are numbers
    header["peak"] = abs(value)
    out = binheader.unpack_from(binheader.pack(header, major=4), 0)[0]
    assert struct.pack("<d", out["peak"]) == struct.pack("<d", abs(value))


def test_binary_numbers_are_short_and_checked() -> None:
    header, _ = split(BUNDLES["compact curve"])
    header["peak"] = 1.8046875  # 231 · 2**-7: 3 bytes, where a float64 takes 9
    three = len(binheader.pack(header, major=4))
    header["peak"] = 1.8046875000000002
    assert len(binheader.pack(header, major=4)) == three + 6
    zero = binheader.pack({**header, "peak": 0.0}, major=4)  # peak 0 is one byte, 0x08
    one = binheader.pack({**header, "peak": 1.0}, major=4)
    at = next(i for i, (a, b) in enumerate(zip(zero, one, strict=True)) if a != b)
    assert zero[at] == 0x08
    for bad, message in (
        (bytes([0x4B, 0x00]), "odd k"),  # k = 2, e = 0: not the one form of 2.0
        (bytes([0x2B, 0xBE, 0x10]), "not finite"),  # k = 1, e = 1055
    ):
        with pytest.raises(BundleError, match=f"'peak'.*{message}"):
            binheader.unpack_from(zero[:at] + bad + zero[at + 1 :], 0)


def test_a_float32_step_that_would_break_the_tolerance_is_not_taken() -> None:
    # Far from the origin (60 times its extent), rounding the step to a float32 moves the
    # points by some 60 · 2**-24 of their magnitude: more than a tight tolerance allows.
    t = np.linspace(0, 1, 300)
    points = np.stack([t + 60, np.sin(6 * t) * t + 60], axis=1)
    tolerance = 1e-5
    bundle = wavecore.encode_curve(points, tolerance=tolerance)
    header = read_bundle(bundle).header
    step = header["qparams"]["step"]
    assert float(np.max(np.linalg.norm(decode(bundle) - points, axis=1))) <= tolerance
    single = float(np.float32(step))
    if single != step:  # the encoder kept the float64 step: the float32 one must fail
        rounded = with_header(bundle, {**header, "qparams": {**header["qparams"], "step": single}})
        assert float(np.max(np.linalg.norm(decode(rounded) - points, axis=1))) > tolerance
    else:  # the float32 step met the tolerance (and was verified by the encoder)
        assert inspect(bundle)["max_error"] <= tolerance * (1 + 2**-22)
