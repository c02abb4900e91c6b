"""Bundle format 5.0, the curve layout ``encode_curve`` writes (docs/bundle-format.md).

What it must give: issue 11's target, a curve's overhead (everything but the coder's chunks:
preamble, header, checks) at most 48 bytes for every curve, at any length, dimension,
boundary, explicit level, tolerance and noise.  What it must keep: resolution decodes,
truncated bundles decoding their complete groups, damage found and confined to its group,
region decodes equal to the full decode, and every older bundle decoding as before.
"""

from __future__ import annotations

import binascii
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import BundleError, binheader, decode, inspect
from wavecore.blockcoder import strip_block_checks
from wavecore.bundle import (
    COMPACT_MAGIC,
    CURVE_VERSION,
    FORMAT_VERSION,
    curve_groups,
    read_bundle,
    self_delimiting_blocks,
    with_header,
    write_bundle,
    written_version,
)

GOLDEN = Path(__file__).resolve().parent / "golden"
MANIFEST = json.loads((GOLDEN / "MANIFEST.json").read_text())
#: issue 11's bound on a curve's header.
LIMIT = 48


def _curve(n: int, dims: int, noise: float = 0.0, seed: int = 5) -> np.ndarray:
    t = np.linspace(0, 1, n)
    points = np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:dims], axis=1)
    return points + np.random.default_rng(seed).normal(0, noise, points.shape)


def _split(bundle: bytes) -> tuple[dict, list[bytes]]:
    return read_bundle(bundle).header, _coder_chunks(bundle)


def _overhead(bundle: bytes) -> int:
    """Everything in a 5.0 or 6.0 bundle that is not the coder's own chunks (6.0's block
    checks and band counts, inside chunks of several blocks, count as overhead)."""
    info = inspect(bundle)
    assert info["version"] in ("5.0", "6.0")
    chunks = sum(c["bytes"] for c in info["chunks"])
    assert info["header_bytes"] == len(bundle) - chunks
    return len(bundle) - sum(map(len, _coder_chunks(bundle)))


def _coder_chunks(bundle: bytes) -> list[bytes]:
    """The chunks as the coder wrote them (6.0 stores chunks of several blocks with checks)."""
    parsed = read_bundle(bundle)
    checked = parsed.checked or (None,) * len(parsed.chunks)
    return [
        bytes(c or b"") if own is None else strip_block_checks(bytes(c or b""), *own)[0]
        for c, own in zip(parsed.chunks, checked, strict=True)
    ]


def test_encode_curve_writes_5_0_with_no_chunk_lengths() -> None:
    bundle = wavecore.encode_curve(_curve(200, 2))
    # 6.0 since 2026-11-23, evening; a curve whose chunks are all of one block (this one) is
    # laid out as in 5.0, with major 6.
    assert bundle[:4] == COMPACT_MAGIC + bytes(CURVE_VERSION) == b"\x89W\x06\x00"
    assert written_version({"kind": "curve"}) == CURVE_VERSION
    assert written_version({"kind": "image"}) == FORMAT_VERSION
    header, chunks = _split(bundle)
    # The head is the preamble, the header, one CRC-16 per group and the head check; the
    # chunks follow as the coder wrote them (each starts with its table of block lengths).
    groups = curve_groups(len(chunks))
    head = len(bundle) - sum(map(len, chunks))
    assert groups == [(0, len(chunks) - 2), (len(chunks) - 1, len(chunks) - 1)]
    assert bundle[head:] == b"".join(chunks)
    crcs = [binascii.crc_hqx(b"".join(chunks[a : b + 1]), 0) for a, b in groups]
    assert bundle[head - 2 - 2 * len(groups) : head - 2] == struct.pack("<HH", *crcs)
    assert struct.unpack("<H", bundle[head - 2 : head])[0] == binascii.crc_hqx(
        bundle[: head - 2], 0
    )
    assert self_delimiting_blocks(header) == [1] * len(chunks)
    # The same header and chunks in 3.0 decode to the same curve.
    older = write_bundle(header, chunks, version=FORMAT_VERSION)
    assert np.array_equal(decode(older), decode(bundle))
    assert len(bundle) < len(older)


@pytest.mark.parametrize(("noise", "level"), [(0.0, 14), (0.0, 15), (0.01, None), (0.01, 15)])
def test_the_cases_4_0_left_above_48_bytes(noise: float, level: int | None) -> None:
    # 4.0 wrote 49 and 51 bytes at levels 14 and 15 of a smooth 50 000-point curve, and 68
    # for a noisy one (its kilobyte chunks each kept a length and a CRC-16).
    points = _curve(50_000, 2, noise)
    bundle = wavecore.encode_curve(points, level=level)
    assert _overhead(bundle) <= LIMIT
    tolerance = 1e-3 * float(np.linalg.norm(np.ptp(points, axis=0)))
    assert np.max(np.linalg.norm(decode(bundle) - points, axis=1)) <= tolerance


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(
    n=st.integers(2, 3000),
    dims=st.integers(0, 3),
    closed=st.booleans(),
    noise=st.sampled_from([0.0, 1e-4, 0.01, 0.3]),
    level=st.none() | st.integers(0, 13),
    target=st.sampled_from(["default", "tolerance", "keep"]),
    relative=st.floats(1e-7, 0.3),
    wavelet=st.sampled_from(["bspline2", "bspline2", "haar", "cdf97"]),
    offset=st.sampled_from([0.0, 60.0, -1e6]),
)
def test_every_curve_header_is_at_most_48_bytes(
    n: int,
    dims: int,
    closed: bool,
    noise: float,
    level: int | None,
    target: str,
    relative: float,
    wavelet: str,
    offset: float,
) -> None:
    # The sweep's space, bounded in size: any length, 1-D series (dims 0) to 3-D points,
    # open and closed, every legal explicit level, any tolerance from 1e-7 to 0.3 of the
    # curve's diagonal, a kept share, noise up to larger than the curve, far from the origin.
    points = _curve(n, max(dims, 1), noise, seed=n) + offset
    if dims == 0:
        points = points[:, 0]
    diagonal = float(np.linalg.norm(np.ptp(points.reshape(n, -1), axis=0))) or 1.0
    options: dict = {"closed": closed, "level": level, "wavelet": wavelet}
    if target == "tolerance":
        options["tolerance"] = relative * diagonal
    elif target == "keep":
        options["keep"] = min(relative * 3, 1.0)
    try:
        bundle = wavecore.encode_curve(points, **options)
    except wavecore.InvalidParameter as exc:  # a level too deep for this length
        assert "too deep" in str(exc) or "cannot be met" in str(exc)
        assume(False)
    assert _overhead(bundle) <= LIMIT
    out = decode(bundle)
    assert out.shape == points.shape
    if "tolerance" in options:
        errors = np.abs(out - points) if dims == 0 else np.linalg.norm(out - points, axis=1)
        assert errors.max() <= options["tolerance"]


def test_the_bound_holds_field_by_field() -> None:
    # The header's largest fields together: a 4-byte length, the ``scale`` field, a ``peak``
    # with an exponent far from 0, a float64 step, a 4-byte psnr, a float32 max_error: the
    # bound the docs derive, 4 + 35 + 2 · 2 + 2 = 45 bytes, stays under 48.
    header, _ = _split(wavecore.encode_curve(_curve(300, 3)))
    n = 2**27 // 4
    header = {
        **header,
        "shape": [n, 3],
        "fitted": [n + header["pads"][0][1], 3],
        "scale": -1100,
        "peak": 511 * 2.0**-1020,
        "psnr": 1000.0,
        "max_error": 3.3e-38,
        "qparams": {**header["qparams"], "step": 0.1},  # not a float32: 8 bytes
    }
    packed = binheader.pack(header, major=4, derived_weights=True)
    assert len(packed) <= 35
    assert len(COMPACT_MAGIC) + 2 + len(packed) + 2 * len(curve_groups(30)) + 2 <= 45 < LIMIT


def test_damage_in_the_finest_chunk_loses_only_its_level() -> None:
    points = _curve(3000, 2, 0.01)
    bundle = wavecore.encode_curve(points, level=5)
    _, chunks = _split(bundle)
    head = len(bundle) - sum(map(len, chunks))
    last = len(chunks) - 1
    finest = head + sum(map(len, chunks[:last]))
    damaged = bytearray(bundle)
    damaged[finest + len(chunks[last]) // 2] ^= 0x10
    with pytest.raises(BundleError, match=f"chunk {last} is corrupt"):
        decode(bytes(damaged))
    assert np.array_equal(decode(bytes(damaged), level=1), decode(bundle, level=1))
    # damaged="zero": the finest details are zero, as when the bundle is cut before them.
    cut = decode(bundle[:finest], damaged="zero")
    assert np.array_equal(decode(bytes(damaged), damaged="zero"), cut)
    # Damage in the coarse group: the coarse levels are lost, and said so.
    damaged = bytearray(bundle)
    damaged[head + len(chunks[0]) - 1] ^= 0x10
    with pytest.raises(BundleError, match="corrupt"):
        decode(bytes(damaged), level=1)


def test_a_truncated_bundle_decodes_its_coarse_levels() -> None:
    bundle = wavecore.encode_curve(_curve(3000, 3, 0.01), level=6)
    _, chunks = _split(bundle)
    finest = len(bundle) - len(chunks[-1])
    for cut in (finest, finest + 1, len(bundle) - 1):
        parsed = read_bundle(bundle[:cut])
        assert parsed.available == len(chunks) - 1
        for k in range(1, 7):
            assert np.array_equal(decode(bundle[:cut], level=k), decode(bundle, level=k))
        with pytest.raises(BundleError, match="truncated"):
            decode(bundle[:cut])
    assert read_bundle(bundle[: finest - 1]).available == 0  # the coarse group is cut
    with pytest.raises(BundleError, match="unexpected byte"):
        read_bundle(bundle + b"\x00")


def test_chunks_of_several_blocks_delimit_themselves_too() -> None:
    # 40 000 points: the finest band's 20 000 positions make two code-blocks of 16 384.
    points = _curve(40_000, 2, 0.002)
    bundle = wavecore.encode_curve(points, level=3)
    header, chunks = _split(bundle)
    blocks = self_delimiting_blocks(header)
    assert blocks is not None and blocks[-1] == 2
    assert _overhead(bundle) <= LIMIT
    older = write_bundle(header, chunks, version=FORMAT_VERSION)  # with its block checks
    full = decode(bundle)
    assert np.array_equal(full, decode(older))
    region = (slice(17_000, 17_200),)
    assert np.array_equal(decode(bundle, region=region), full[region])
    assert np.array_equal(decode(bundle, region=region, level=1), decode(bundle, level=1)[region])


def test_a_coder_whose_chunks_do_not_delimit_themselves_stores_their_lengths() -> None:
    old = (GOLDEN / "curve_open_tolerance.wvb").read_bytes()  # context coder version 2
    header, chunks = _split(old)
    assert self_delimiting_blocks(header) is None
    bundle = write_bundle(header, chunks, version=CURVE_VERSION)
    assert read_bundle(bundle).version == CURVE_VERSION
    assert np.array_equal(decode(bundle), decode(old))
    lengths = b"".join(
        bytes([n]) if n < 128 else bytes([n & 127 | 128, n >> 7]) for n in map(len, chunks)
    )
    assert lengths in bundle[: len(bundle) - sum(map(len, chunks))]


def test_a_chunk_that_does_not_match_its_block_table_is_refused() -> None:
    header, chunks = _split(wavecore.encode_curve(_curve(100, 2)))
    with pytest.raises(BundleError, match="chunk 1 is not as the block coder writes it"):
        write_bundle(header, [chunks[0], chunks[1] + b"\x00", *chunks[2:]], version=CURVE_VERSION)


def test_every_kind_round_trips_in_5_0() -> None:
    image = (np.add.outer(np.arange(60), np.arange(50)) % 251).astype(np.uint8)
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 30), np.linspace(0, 2, 26)), -1)
    for bundle in (
        wavecore.encode_image(image, quality=35),
        wavecore.encode_image(image, lossless=True),
        wavecore.encode_surface(grid),
    ):
        header, chunks = _split(bundle)
        new = write_bundle(header, chunks, version=CURVE_VERSION)
        assert read_bundle(new).header == read_bundle(bundle).header
        assert np.array_equal(decode(new), decode(bundle))


def test_with_header_keeps_the_version_and_the_chunks() -> None:
    bundle = wavecore.encode_curve(_curve(120, 2))
    header, chunks = _split(bundle)
    changed = with_header(bundle, {**header, "psnr": 12.5})
    assert read_bundle(changed).version == CURVE_VERSION
    assert read_bundle(changed).header == {**header, "psnr": 12.5}
    assert changed.endswith(b"".join(chunks))


def test_an_unknown_major_after_7_is_refused_by_name() -> None:
    bundle = wavecore.encode_curve(_curve(30, 2))
    with pytest.raises(BundleError, match=r"unsupported bundle format version 8\.0"):
        read_bundle(COMPACT_MAGIC + bytes([8, 0]) + bundle[4:])  # (7.0 is the replication's)
    later = COMPACT_MAGIC + bytes([6, 3]) + bundle[4:]  # a minor version is read as 6.0
    with pytest.raises(BundleError, match="header CRC-16"):  # the head check covers it
        read_bundle(later)


@pytest.mark.parametrize(
    "name", sorted(n for n, e in MANIFEST.items() if e["version"].startswith("5."))
)
def test_5_0_golden_bundles_are_at_most_48_bytes_of_overhead(name: str) -> None:
    bundle = (GOLDEN / f"{name}.wvb").read_bytes()
    assert _overhead(bundle) <= LIMIT


def test_the_block_count_rule_is_the_block_coders() -> None:
    from wavecore.blockcoder import block_counts
    from wavecore.codec.plan import plan_from_header

    image = np.zeros((300, 270, 3), np.uint8)
    image[0, 0] = 1  # not a picture enlarged by pixel replication, which is coded smaller
    for bundle in (
        wavecore.encode_curve(_curve(40_000, 3, 0.01), level=4),
        wavecore.encode_curve(_curve(9, 1)[:, 0]),
        wavecore.encode_image(image, level=3, quality=30),
        wavecore.encode_surface(np.zeros((40, 300))),
    ):
        header = read_bundle(bundle).header
        plan = plan_from_header(header)
        one = len(plan.axes) == 1
        entries = [
            [tuple(entry)] if index == 0 or one else [tuple(b) for b in entry]
            for index, entry in enumerate(plan.band_shapes())
        ]
        cparams = header["cparams"]
        expected = block_counts(entries, cparams["two_d"], cparams["block"])
        assert self_delimiting_blocks(header) == expected


def test_a_crafted_huge_shape_is_refused_quickly() -> None:
    # The block count comes before the head check: it must not cost what the shape declares.
    import time

    bundle = wavecore.encode_curve(_curve(90, 3))
    header, _ = _split(bundle)
    for shape in ([90, 2**20], [2**26, 2], [2**13, 2**13]):
        crafted = {**header, "shape": shape, "fitted": [shape[0] + header["pads"][0][1], shape[1]]}
        start = time.perf_counter()
        try:
            blocks = self_delimiting_blocks(crafted)
        except BundleError:
            blocks = None
        assert time.perf_counter() - start < 1.0, shape
        assert blocks is None or len(blocks) == header["levels"] + 1
