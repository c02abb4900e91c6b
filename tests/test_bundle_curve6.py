"""Bundle format 6.0, the curve layout with block checks (docs/bundle-format.md).

6.0 is 5.0 except for chunks of more than one code-block (a curve's band of more than 16 384
positions): those carry 3.0's block checks and band counts and are in no group.  What it must
give: a damaged block of a long curve loses only itself, a region of a long curve reads only
the blocks it needs, and every curve's overhead (block checks included) stays at most 48
bytes; curves whose chunks are all of one block pay nothing more than in 5.0.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import BundleError, decode
from wavecore.blockcoder import block_table, strip_block_checks
from wavecore.bundle import (
    CURVE_OVERHEAD_LIMIT,
    CURVE_VERSION,
    CURVE_VERSION_5,
    checked_groups,
    read_bundle,
    write_bundle,
)

chunks_module = importlib.import_module("wavecore.codec.chunks")


def _curve(n: int, dims: int, noise: float = 0.0) -> np.ndarray:
    t = np.linspace(0, 1, n)
    points = np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:dims], axis=1)
    return points + np.random.default_rng(5).normal(0, noise, points.shape)


def _coder_chunks(bundle: bytes) -> list[bytes]:
    parsed = read_bundle(bundle)
    checked = parsed.checked or (None,) * len(parsed.chunks)
    return [
        bytes(c or b"") if own is None else strip_block_checks(bytes(c or b""), *own)[0]
        for c, own in zip(parsed.chunks, checked, strict=True)
    ]


def _overhead(bundle: bytes) -> int:
    return len(bundle) - sum(map(len, _coder_chunks(bundle)))


# 40 000 points at 3 levels: the finest band's 20 000 positions make two blocks of 16 384.
LONG = _curve(40_000, 2, 0.002)
LONG_BUNDLE = wavecore.encode_curve(LONG, level=3)


def _finest_block_span(bundle: bytes, block: int) -> tuple[int, int]:
    """Where block ``block`` of the finest chunk lies in the bundle's bytes."""
    parsed = read_bundle(bundle)
    data = bytes(parsed.chunks[-1])
    count = parsed.checked[-1][0]
    _, lengths = block_table(data, count)
    start = len(bundle) - len(data) + len(data) - int(lengths.sum()) + int(lengths[:block].sum())
    return start, start + int(lengths[block])


def test_a_long_curve_carries_block_checks_in_its_chunks_of_several_blocks() -> None:
    parsed = read_bundle(LONG_BUNDLE)
    assert parsed.version == CURVE_VERSION == (6, 0)
    assert parsed.checked == (None, None, None, (2, 1))
    assert parsed.block_checks
    assert _overhead(LONG_BUNDLE) <= CURVE_OVERHEAD_LIMIT == 48
    # The same coder chunks in 5.0: the same curve, a few bytes less.
    chunks = _coder_chunks(LONG_BUNDLE)
    older = write_bundle(parsed.header, chunks, version=CURVE_VERSION_5)
    assert read_bundle(older).version == (5, 0)
    assert np.array_equal(decode(older), decode(LONG_BUNDLE))
    assert 0 < len(LONG_BUNDLE) - len(older) <= 12
    # write_bundle writes the same 6.0 bytes again from the coder's chunks.
    assert write_bundle(parsed.header, chunks, version=CURVE_VERSION) == LONG_BUNDLE


def test_a_short_curve_pays_nothing_for_6_0() -> None:
    bundle = wavecore.encode_curve(_curve(1000, 3, 0.01))
    parsed = read_bundle(bundle)
    assert parsed.version == (6, 0) and all(c is None for c in parsed.checked)
    as_5 = write_bundle(parsed.header, _coder_chunks(bundle), version=CURVE_VERSION_5)
    # Only the major version and so the head check differ.
    assert len(as_5) == len(bundle)
    assert sum(a != b for a, b in zip(as_5, bundle, strict=True)) <= 3


def test_checked_groups() -> None:
    assert checked_groups([1]) == [(0, 0)]
    assert checked_groups([1, 1, 1, 1]) == [(0, 2), (3, 3)]
    assert checked_groups([1, 1, 2, 3]) == [(0, 1)]
    assert checked_groups([2, 2]) == []


def test_a_damaged_block_of_a_long_curve_loses_only_itself() -> None:
    clean = decode(LONG_BUNDLE)
    start, stop = _finest_block_span(LONG_BUNDLE, 1)
    damaged = bytearray(LONG_BUNDLE)
    for at in range(start + 2, min(stop, start + 40), 7):
        damaged[at] ^= 0xA5
    with pytest.raises(BundleError, match=r"chunk 3 is corrupt: code-block\(s\) \[1\]"):
        decode(bytes(damaged))
    out = decode(bytes(damaged), damaged="zero")
    assert out.shape == clean.shape
    differs = np.flatnonzero(np.any(out != clean, axis=1))
    assert differs.size  # the block's details are gone ...
    # ... and nothing else: block 1 holds the finest details 16 384 on, which reach the
    # points from about 2 × 16 384 on (a few points' margin for the synthesis).
    assert differs.min() >= 2 * 16_384 - 8
    # The coarser levels do not need the finest chunk at all.
    assert np.array_equal(decode(bytes(damaged), level=1), decode(LONG_BUNDLE, level=1))


def test_a_damaged_block_keeps_the_dequantizer_of_a_full_decode() -> None:
    # The stand-ins restore the band's stored counts, so the undamaged block's values are
    # placed exactly as in the clean decode: the points it alone reaches are unchanged.
    clean = decode(LONG_BUNDLE)
    start, _ = _finest_block_span(LONG_BUNDLE, 0)
    damaged = bytearray(LONG_BUNDLE)
    damaged[start + 3] ^= 0xFF
    out = decode(bytes(damaged), damaged="zero")
    assert np.array_equal(out[2 * 16_384 + 8 :], clean[2 * 16_384 + 8 :])
    assert not np.array_equal(out[: 2 * 16_384], clean[: 2 * 16_384])


def test_a_region_of_a_long_curve_reads_only_its_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    clean = decode(LONG_BUNDLE)
    seen: list[int] = []
    original = chunks_module.decode_block_windows

    def spy(chunks, entries, two_d, block, skip, *args, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(int((~skip).sum()))
        return original(chunks, entries, two_d, block, skip, *args, **kwargs)

    monkeypatch.setattr(chunks_module, "decode_block_windows", spy)
    region = (slice(100, 300),)
    assert np.array_equal(decode(LONG_BUNDLE, region=region), clean[region])
    total = sum(c[0] if c else 1 for c in read_bundle(LONG_BUNDLE).checked)
    assert seen == [total - 1]  # every block but the finest chunk's second one
    # So a damaged block the region does not need is never read: even a strict decode works.
    start, stop = _finest_block_span(LONG_BUNDLE, 1)
    damaged = bytearray(LONG_BUNDLE)
    damaged[(start + stop) // 2] ^= 0x41
    for region in [(slice(100, 300),), (slice(0, 20_000),), (slice(-10, None),)]:
        if region[0].start == -10:  # the end of the curve needs block 1
            with pytest.raises(BundleError, match=r"code-block\(s\) \[1\]"):
                decode(bytes(damaged), region=region)
        else:
            assert np.array_equal(decode(bytes(damaged), region=region), clean[region])


def test_regions_at_every_level_equal_the_full_decode() -> None:
    for level in range(4):
        full = decode(LONG_BUNDLE, level=level)
        for region in [(slice(0, 7),), (slice(len(full) // 2, len(full) // 2 + 50),)]:
            assert np.array_equal(decode(LONG_BUNDLE, region=region, level=level), full[region])


def test_a_bundle_cut_inside_a_checked_chunk_decodes_its_coarse_levels() -> None:
    cut = LONG_BUNDLE[: len(LONG_BUNDLE) - 10]
    assert read_bundle(cut).available == 3
    assert np.array_equal(decode(cut, level=1), decode(LONG_BUNDLE, level=1))
    with pytest.raises(BundleError, match="truncated"):
        decode(cut)


@pytest.mark.parametrize("level", [1, 2, 8, 13, 14, 15])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_long_curves_stay_at_most_48_bytes(level: int, noise: float) -> None:
    # 50 000 points: at level 1 chunk 0 has two blocks too; at levels 14 and 15 the curve is
    # padded to 65 538 points (chunks of 2 and 3 blocks).  Where the checks would pass 48
    # bytes (a noisy 3-D curve's band counts take 3 bytes each) the curve is written in 5.0.
    bundle = wavecore.encode_curve(_curve(50_000, 3, noise), level=level)
    assert _overhead(bundle) <= CURVE_OVERHEAD_LIMIT
    parsed = read_bundle(bundle)
    checked = write_bundle(parsed.header, _coder_chunks(bundle), version=CURVE_VERSION)
    fits = _overhead(checked) <= CURVE_OVERHEAD_LIMIT
    assert parsed.version == ((6, 0) if fits else (5, 0))
    if noise == 0.0 and level <= 13:
        assert fits


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_any_damage_to_a_6_0_curve_gives_an_array_or_a_bundle_error(data: st.DataObject) -> None:
    damaged = bytearray(LONG_BUNDLE)
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(damaged) - 1))
        damaged[at] ^= data.draw(st.integers(1, 255))
    if data.draw(st.booleans()):
        damaged = damaged[: data.draw(st.integers(0, len(damaged)))]
    mode = data.draw(st.sampled_from(["strict", "zero"]))
    try:
        out = decode(bytes(damaged), damaged=mode)
    except BundleError:
        return
    assert out.shape == LONG.shape
