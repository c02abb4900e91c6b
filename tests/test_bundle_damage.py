"""A damaged code-block loses only itself (bundle format 3.0, ``decode(..., damaged="zero")``).

Bytes are flipped inside one block of one chunk; the strict decode refuses the bundle naming the
chunk and block, and ``damaged="zero"`` gives the clean decode everywhere except where that
block's coefficients reach (worked out from the same supports as region decodes).
"""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_bundle_fuzz import assemble2

import wavecore
from wavecore import BundleError, InvalidParameter, decode
from wavecore.blockcoder import block_counts, block_table
from wavecore.bundle import read_bundle, write_bundle
from wavecore.codec.plan import plan_from_header


def _picture(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    base = 128 + 60 * np.sin(x / 7.0) * np.cos(y / 5.0) + rng.normal(0, 12, shape[:2])
    if len(shape) == 3:
        base = base[..., None] + np.arange(shape[2]) * 20
    return base.clip(0, 255).astype(np.uint8)


def _entries(header: dict) -> list[list[tuple[int, ...]]]:
    shapes = plan_from_header(header).band_shapes()
    return [[tuple(shapes[0])]] + [[tuple(b) for b in entry] for entry in shapes[1:]]


def _block_span(bundle: bytes, chunk: int, block: int) -> tuple[int, int]:
    """Where block ``block`` of chunk ``chunk`` lies in the bundle's bytes (format 3.0)."""
    parsed = read_bundle(bundle)
    cparams = parsed.header["cparams"]
    entries = _entries(parsed.header)
    count = block_counts(entries, cparams["two_d"], cparams["block"])[chunk]
    assert count > 1
    data = bytes(parsed.chunks[chunk])
    _, lengths = block_table(data, count)
    payload = len(data) - int(lengths.sum())  # the table, checks and band counts come first
    start = payload + int(lengths[:block].sum())
    chunk_start = len(bundle) - sum(len(c) for c in parsed.chunks[chunk:])
    return chunk_start + start, chunk_start + start + int(lengths[block])


def _block_region(bundle: bytes, chunk: int, block: int) -> tuple[slice, slice]:
    """The image area that block ``block`` of ``chunk`` can reach (a generous bound)."""
    parsed = read_bundle(bundle)
    header = parsed.header
    side = header["cparams"]["block"]
    entries = _entries(header)
    cols = -(-max(s[1] for s in entries[chunk]) // side)
    row, col = divmod(block, cols)
    scale = 2 ** (header["levels"] - chunk + 1)
    margin = 8 * scale  # the synthesis reaches a few coarse samples beyond the block
    return (
        slice(max(0, row * side * scale - margin), (row + 1) * side * scale + margin),
        slice(max(0, col * side * scale - margin), (col + 1) * side * scale + margin),
    )


BUNDLES = {
    "grey lossy": wavecore.encode_image(_picture((700, 650)), quality=40),
    "rgb lossy bspline2": wavecore.encode_image(
        _picture((600, 700, 3), 1), quality=38, wavelet="bspline2"
    ),
    # the block coder's (effort="fast"): the default lossless coder's test is below
    "grey lossless": wavecore.encode_image(_picture((600, 560), 2), lossless=True, effort="fast"),
}


@pytest.mark.parametrize("name", sorted(BUNDLES))
@pytest.mark.parametrize("block", [0, 3])
def test_a_damaged_block_loses_only_itself(name: str, block: int) -> None:
    bundle = BUNDLES[name]
    parsed = read_bundle(bundle)
    assert parsed.version == (3, 1)  # lossless too: the block coder's chunks delimit themselves
    finest = len(parsed.chunks) - 1
    start, stop = _block_span(bundle, finest, block)
    damaged = bytearray(bundle)
    for at in range(start + 2, min(stop, start + 40), 7):
        damaged[at] ^= 0xA5
    with pytest.raises(BundleError, match=rf"chunk {finest} is corrupt"):
        decode(bytes(damaged))
    clean = decode(bundle)
    out = decode(bytes(damaged), damaged="zero")
    assert out.shape == clean.shape and out.dtype == clean.dtype
    differs = np.any(out != clean, axis=-1) if out.ndim == 3 else out != clean
    assert differs.any()  # the block's details are gone
    reach = np.zeros(differs.shape, dtype=bool)
    reach[_block_region(bundle, finest, block)] = True
    assert not (differs & ~reach).any()  # and nothing else is


@pytest.mark.parametrize("name", ["grey lossy", "rgb lossy bspline2"])
def test_a_damaged_block_of_version_8_takes_its_descendants(name: str) -> None:
    """Version 8 (as 6 and 7) decodes a block from its parent block's values: under
    ``damaged="zero"`` a damaged block of a coarser chunk is zeroed with its descendants (the
    same picture area, at the finer levels), and nothing outside that area changes."""
    bundle = BUNDLES[name]
    parsed = read_bundle(bundle)
    assert parsed.header["cparams"]["version"] == 8
    chunk = len(parsed.chunks) - 2
    start, stop = _block_span(bundle, chunk, 0)
    damaged = bytearray(bundle)
    for at in range(start + 2, min(stop, start + 40), 7):
        damaged[at] ^= 0xA5
    with pytest.raises(BundleError, match=rf"chunk {chunk} is corrupt"):
        decode(bytes(damaged))
    from wavecore.codec import chunks as chunks_module

    decoded: list[list[np.ndarray]] = []
    original = chunks_module.decode_blocks

    def recording(*args: object, **kwargs: object) -> list[list[np.ndarray]]:
        levels = original(*args, **kwargs)  # type: ignore[arg-type]
        decoded.append(levels)
        return levels

    chunks_module.decode_blocks = recording  # type: ignore[assignment]
    try:
        clean = decode(bundle)
        out = decode(bytes(damaged), damaged="zero")
    finally:
        chunks_module.decode_blocks = original
    differs = np.any(out != clean, axis=-1) if out.ndim == 3 else out != clean
    reach = np.zeros(differs.shape, dtype=bool)
    reach[_block_region(bundle, chunk, 0)] = True
    assert differs.any() and not (differs & ~reach).any()
    # The finest chunk's first block (a child of the damaged one) was not decoded: it holds
    # stand-ins (1s and 2s restoring the band counts) or zeros, not the clean values.
    side = parsed.header["cparams"]["block"]
    finest_clean, finest_out = decoded[0][-1][0], decoded[1][-1][0]
    child_clean, child_out = finest_clean[:side, :side], finest_out[:side, :side]
    assert not np.array_equal(child_out, child_clean)
    assert np.isin(child_out, [0, 1, 2]).all()
    # Blocks that descend from no damaged block decode as before.
    assert np.array_equal(finest_out[2 * side :, 2 * side :], finest_clean[2 * side :, 2 * side :])


def test_strict_decode_names_the_block() -> None:
    bundle = BUNDLES["grey lossy"]
    finest = len(read_bundle(bundle).chunks) - 1
    start, _ = _block_span(bundle, finest, 2)
    damaged = bytearray(bundle)
    damaged[start + 3] ^= 0xFF
    region = (slice(0, 40), slice(0, 40))  # far from block 2 (top row, third column)
    with pytest.raises(BundleError, match=r"code-block\(s\) \[2\]"):
        decode(bytes(damaged), region=(slice(0, 600), slice(0, 650)))
    # A region that does not need the block never reads it.
    assert np.array_equal(decode(bytes(damaged), region=region), decode(bundle)[region])


def test_a_damaged_block_table_loses_its_chunk_only() -> None:
    bundle = BUNDLES["grey lossy"]
    parsed = read_bundle(bundle)
    finest = len(parsed.chunks) - 1
    chunk_start = len(bundle) - len(parsed.chunks[finest])
    damaged = bytearray(bundle)
    damaged[chunk_start] ^= 0x01  # the first block length
    with pytest.raises(BundleError, match=rf"chunk {finest} is corrupt"):
        decode(bytes(damaged))
    out = decode(bytes(damaged), damaged="zero")
    coarse = decode(bundle, level=1)
    assert out.shape == decode(bundle).shape
    # Without its finest details the picture is still close to the clean one.
    assert float(np.abs(out.astype(float) - decode(bundle)).mean()) < 12
    assert coarse.shape[0] < out.shape[0]


def test_a_truncated_bundle_decodes_with_the_missing_details_zero() -> None:
    bundle = BUNDLES["rgb lossy bspline2"]
    parsed = read_bundle(bundle)
    cut = bundle[: len(bundle) - len(parsed.chunks[-1]) // 2]
    with pytest.raises(BundleError, match="truncated"):
        decode(cut)
    out = decode(cut, damaged="zero")
    assert out.shape == decode(bundle).shape
    assert float(np.abs(out.astype(float) - decode(bundle)).mean()) < 15


def test_a_2_0_bundle_loses_the_damaged_chunk() -> None:
    """Without block checks the whole chunk (one level's details) is zeroed."""
    bundle = BUNDLES["grey lossless"]
    parsed = read_bundle(bundle)
    entries = _entries(parsed.header)
    cparams = parsed.header["cparams"]
    counts = block_counts(entries, cparams["two_d"], cparams["block"])
    from wavecore.blockcoder import strip_block_checks

    chunks = [
        strip_block_checks(bytes(c), n, len(e) if i else 0)[0]
        for i, (c, n, e) in enumerate(zip(parsed.chunks, counts, entries, strict=True))
    ]
    old = write_bundle(parsed.header, chunks, version=(2, 0))
    assert np.array_equal(decode(old), decode(bundle))
    damaged = bytearray(old)
    damaged[-5] ^= 0x10
    with pytest.raises(BundleError, match="corrupt"):
        decode(bytes(damaged))
    out = decode(bytes(damaged), damaged="zero")
    assert out.shape == decode(bundle).shape


def test_damaged_must_be_strict_or_zero() -> None:
    with pytest.raises(InvalidParameter, match="damaged must be one of"):
        decode(BUNDLES["grey lossy"], damaged="ignore")


def test_the_checks_cost_a_few_bytes_per_block() -> None:
    """3.0 against 2.0 for the same chunks: 2 B per block, the band counts, 2 B per chunk."""
    bundle = BUNDLES["grey lossy"]
    parsed = read_bundle(bundle)
    entries = _entries(parsed.header)
    cparams = parsed.header["cparams"]
    counts = block_counts(entries, cparams["two_d"], cparams["block"])
    from wavecore.blockcoder import strip_block_checks

    chunks = [
        strip_block_checks(bytes(c), n, len(e) if i else 0)[0]
        for i, (c, n, e) in enumerate(zip(parsed.chunks, counts, entries, strict=True))
    ]
    # 3.0 itself (3.1, written by default, also drops the chunk lengths).
    three = write_bundle(parsed.header, chunks, version=(3, 0))
    extra = len(three) - len(write_bundle(parsed.header, chunks, version=(2, 0)))
    several = [n for n in counts if n > 1]
    assert 2 * sum(several) + 2 * len(several) + 2 <= extra
    assert extra <= 2 * sum(several) + 2 * len(several) + 2 + 3 * 2 * 3 * len(several)


@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_any_damage_gives_an_array_or_a_bundle_error(data: st.DataObject) -> None:
    """Flipped bytes anywhere, with the container's CRCs recomputed half the time (so that the
    block checks, the prefix check and the decoders see the damage): every decode option gives
    an array or a BundleError, never another exception."""
    bundle = BUNDLES[data.draw(st.sampled_from(sorted(BUNDLES)))]
    damaged = bytearray(bundle)
    for _ in range(data.draw(st.integers(1, 6))):
        at = data.draw(st.integers(0, len(damaged) - 1))
        damaged[at] ^= data.draw(st.integers(1, 255))
    candidates = [bytes(damaged)]
    with contextlib.suppress(BundleError):
        parsed = read_bundle(bundle)
        chunks = _split_chunks(bytes(damaged), [len(c) for c in parsed.chunks])
        packed = bundle[11 : 11 + bundle[10]]
        candidates.append(assemble2(packed, chunks))
    for candidate in candidates:
        for options in ({"damaged": "zero"}, {"region": (slice(100, 180), slice(200, 330))}):
            try:
                out = decode(candidate, **options)
            except BundleError:
                continue
            assert isinstance(out, np.ndarray)


def _split_chunks(data: bytes, lengths: list[int]) -> list[bytes]:
    end = len(data)
    chunks = []
    for length in reversed(lengths):
        chunks.append(data[end - length : end])
        end -= length
    return list(reversed(chunks))


def test_a_damaged_lossless_coder_bundle_loses_its_level_with_a_clear_error() -> None:
    """The default lossless coder (version 5) checks a chunk whole: damage to a picture coded
    without levels (one chunk) is refused by name, also with damaged="zero"; with one level,
    damage to the details loses them (a lossy picture back)."""
    image = _picture((420, 300), 3)
    flat = wavecore.encode_image(image, lossless=True, level=0)
    damaged = bytearray(flat)
    damaged[len(flat) // 2] ^= 0x5A
    with pytest.raises(BundleError, match="chunk 0"):
        decode(bytes(damaged))
    with pytest.raises(BundleError, match="chunk 0"):
        decode(bytes(damaged), damaged="zero")
    one = wavecore.encode_image(image, lossless=True, level=1)
    parsed = read_bundle(one)
    assert len(parsed.chunks) == 2 and parsed.header["cparams"]["version"] == 5
    damaged = bytearray(one)
    damaged[len(one) - len(parsed.chunks[-1]) // 2] ^= 0x5A
    with pytest.raises(BundleError, match="chunk 1"):
        decode(bytes(damaged))
    out = decode(bytes(damaged), damaged="zero")
    assert out.shape == image.shape and not np.array_equal(out, image)
    assert float(np.abs(out.astype(float) - image).mean()) < 15
