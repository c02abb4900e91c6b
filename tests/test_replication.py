"""Pictures enlarged by pixel replication are coded at their source's size
(wavecore.codec.replication): the same pictures, levels, regions and errors back."""

from __future__ import annotations

import binascii

import numpy as np
import pytest

from wavecore import decode, encode_image, inspect
from wavecore.bundle import MAX_ELEMENTS
from wavecore.codec import replication
from wavecore.codec.replication import (
    MIN_SOURCE_SIDE,
    OVERHEAD,
    enlarged,
    is_replicated,
    replication_factor,
    unwrap,
    wrap,
)
from wavecore.errors import BitrateTooLow, BundleError, InvalidParameter

RNG = np.random.default_rng(7)


def _smooth(height: int, width: int, channels: int = 0) -> np.ndarray:
    """A picture with some structure, so lossy coding has something to do."""
    y, x = np.mgrid[0:height, 0:width]
    picture = 128 + 60 * np.sin(x / 5.0) * np.cos(y / 7.0) + RNG.normal(0, 4, (height, width))
    if channels:
        picture = np.stack([picture + 20 * c for c in range(channels)], axis=-1)
    return np.clip(picture, 0, 255).astype(np.uint8)


def _kron(source: np.ndarray, factor: int) -> np.ndarray:
    return enlarged(source, factor)


@pytest.mark.parametrize("factor", [2, 4, 8])
def test_factor_is_found(factor: int) -> None:
    source = _smooth(24, 40)
    assert replication_factor(_kron(source, factor)) == factor
    assert replication_factor(source) == 1


def test_factor_needs_every_pixel_and_channel() -> None:
    picture = _kron(_smooth(32, 32, channels=3), 2)
    assert replication_factor(picture) == 2
    picture[-1, -1, 2] ^= 1  # the very last sample of one channel
    assert replication_factor(picture) == 1
    rows_only = np.repeat(_smooth(32, 64), 2, axis=0)  # rows repeated, columns not
    assert replication_factor(rows_only) == 1


def test_factor_keeps_the_source_large_enough() -> None:
    flat = np.zeros((64, 48), np.uint8)
    assert replication_factor(flat) == 4  # a 16 × 12 source: 8 would leave 8 × 6
    assert replication_factor(np.zeros((2 * MIN_SOURCE_SIDE - 2,) * 2, np.uint8)) == 1
    odd = _kron(_smooth(21, 30), 2)[:-2]  # 40 rows: still even, factor 2
    assert replication_factor(odd) == 2
    assert replication_factor(_kron(_smooth(21, 30), 2)[:-1]) == 1  # 41 rows


@pytest.mark.parametrize(
    "options",
    [{"quality": 38}, {"bpp": 1.0}, {"keep": 0.2}, {"lossless": True}],
    ids=["quality", "bpp", "keep", "lossless"],
)
def test_bundle_is_the_source_bundle_wrapped(options: dict) -> None:
    source = _smooth(40, 56)
    picture = _kron(source, 4)
    bundle = encode_image(picture, wavelet="cdf97", **options)
    log2_factor, inner = unwrap(bundle)
    assert log2_factor == 2 and len(bundle) == len(inner) + OVERHEAD
    if "bpp" not in options:  # the same source coded alone gives the same bytes
        assert inner == encode_image(source, wavelet="cdf97", **options)
    decoded = decode(bundle)
    assert decoded.shape == picture.shape and decoded.dtype == picture.dtype
    assert np.array_equal(decoded, _kron(decode(inner), 4))
    if options.get("lossless"):
        assert np.array_equal(decoded, picture)


def test_targets_hold_on_the_enlarged_picture() -> None:
    picture = _kron(_smooth(64, 48, channels=3), 2)
    for quality in (30.0, 42.0):
        out = decode(encode_image(picture, quality=quality))
        mse = np.mean((out.astype(float) - picture) ** 2)
        assert 10 * np.log10(255**2 / mse) >= quality
    for bpp in (0.3, 2.0):
        bundle = encode_image(picture, bpp=bpp)
        assert is_replicated(bundle)
        assert 0.9 * bpp <= 8 * len(bundle) / (picture.shape[0] * picture.shape[1]) <= bpp


def test_fewer_bytes_than_without_replication() -> None:
    source = _smooth(64, 64)
    picture = _kron(source, 2)
    broken = picture.copy()
    broken[0, 1] ^= 1  # no longer an enlargement: coded whole
    replicated, whole = (encode_image(p, wavelet="cdf97", quality=40) for p in (picture, broken))
    assert is_replicated(replicated) and not is_replicated(whole)
    assert len(replicated) < 0.5 * len(whole)


def test_levels_and_inspect_agree() -> None:
    picture = _kron(_smooth(40, 24), 4)
    bundle = encode_image(picture, quality=40, level=4)
    info = inspect(bundle)
    assert info["replicated"] == 4 and info["shape"] == [160, 96]
    assert info["levels"] == 4  # two of replication, two of the source's
    assert info["total_bytes"] == len(bundle)
    assert info["bpp"] == pytest.approx(8 * len(bundle) / (160 * 96))
    assert [c["level"] for c in info["chunks"]] == [4, 3, 2]
    for level, shape in enumerate(info["level_shapes"]):
        assert list(decode(bundle, level=level).shape) == shape
    assert info["level_shapes"][:3] == [[160, 96], [80, 48], [40, 24]]
    assert np.array_equal(decode(bundle, level=1), _kron(decode(bundle, level=2), 2))
    assert np.array_equal(decode(bundle, drop_levels=3), decode(unwrap(bundle)[1], level=1))
    with pytest.raises(InvalidParameter, match="level 5 is too deep for this picture"):
        decode(bundle, level=5)
    assert inspect(encode_image(_smooth(40, 24), quality=40))["replicated"] == 1


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_regions_equal_the_whole_decode(level: int) -> None:
    bundle = encode_image(_kron(_smooth(40, 32, channels=3), 4), quality=40)
    whole = decode(bundle, level=level)
    height, width = whole.shape[:2]
    for region in [
        (slice(1, height - 3, 3), slice(5, width)),
        (slice(None), slice(-7, None, 2)),
        ((height // 2, height // 2 + 1), (0, 1)),
        (slice(height - 1, None),),
    ]:
        expected = whole[tuple(slice(*r) if isinstance(r, tuple) else r for r in region)]
        assert np.array_equal(decode(bundle, level=level, region=region), expected)
    with pytest.raises(InvalidParameter, match="region"):
        decode(bundle, level=level, region=(slice(height, None),))


def test_a_level_too_deep_for_the_source_codes_the_whole_picture() -> None:
    picture = _kron(_smooth(32, 32), 2)  # 64²: 7 levels, where the 32² source takes 5
    bundle = encode_image(picture, quality=40, level=7)
    assert not is_replicated(bundle) and inspect(bundle)["levels"] == 7
    assert is_replicated(encode_image(picture, quality=40, level=6))
    with pytest.raises(InvalidParameter, match="level 8 is too deep for length 64"):
        encode_image(picture, quality=40, level=8)  # the whole picture's own refusal


def test_float_and_big_endian_pictures() -> None:
    source = _smooth(24, 32).astype(">f8") / 255.0
    bundle = encode_image(_kron(source, 2), quality=45)
    out = decode(bundle)
    assert is_replicated(bundle) and out.dtype == np.float64 and out.shape == (48, 64)
    assert np.array_equal(out, _kron(out[::2, ::2], 2))


def test_too_small_a_budget_names_the_enlarged_picture() -> None:
    picture = _kron(_smooth(32, 32), 2)
    with pytest.raises(BitrateTooLow, match=r"its smallest bundle needs (\d+) bytes") as caught:
        encode_image(picture, bpp=0.05)
    smallest = caught.value.smallest_bytes
    assert f"= {8 * smallest / picture.size:.4f} bpp" in str(caught.value)
    with pytest.raises(BitrateTooLow) as inner:  # the source alone, in the bytes left to it
        encode_image(picture[::2, ::2], bpp=(0.05 * picture.size - 8 * OVERHEAD) / 32**2)
    assert smallest == inner.value.smallest_bytes + OVERHEAD
    assert len(encode_image(picture, bpp=16 * smallest / picture.size)) <= 2 * smallest


def _rewrapped(bundle: bytes, log2_factor: int) -> bytes:
    return wrap(unwrap(bundle)[1], log2_factor)


def test_damaged_or_hostile_wrappers_are_bundle_errors() -> None:
    bundle = encode_image(_kron(_smooth(16, 16), 2), quality=40)
    flipped = bytearray(bundle)
    flipped[4] ^= 1  # the factor, under the wrapper's CRC
    with pytest.raises(BundleError, match="wrapper is damaged"):
        decode(bytes(flipped))
    for cut in (4, OVERHEAD - 1):
        with pytest.raises(BundleError, match="fewer than its"):
            decode(bundle[:cut])
    with pytest.raises(BundleError, match=r"factor 2\*\*0"):
        inspect(_rewrapped(bundle, 0))
    # a 16 × 16 source enlarged 2**13 times would decode to 2**34 pixels: refused unread
    with pytest.raises(BundleError, match="MAX_ELEMENTS"):
        decode(_rewrapped(bundle, 13))
    assert MAX_ELEMENTS < 16 * 16 << 2 * 13
    nested = wrap(bundle, 1)
    with pytest.raises(BundleError, match="itself a replicated picture"):
        decode(nested)
    source = encode_image(_smooth(16, 16), lossless=True)
    head = b"\x89W\x07\x00\x01"
    crc = binascii.crc_hqx(head, 0).to_bytes(2, "little")
    assert decode(head + crc + source).shape == (32, 32)
    with pytest.raises(BundleError):
        decode(head + crc + source[:-3])  # the source's bundle cut short


def test_memory_running_out_is_a_bundle_error(monkeypatch: pytest.MonkeyPatch) -> None:
    bundle = encode_image(_kron(_smooth(16, 16), 4), quality=40)

    def no_memory(*args: object, **kwargs: object) -> np.ndarray:
        raise MemoryError

    monkeypatch.setattr(replication, "enlarged", no_memory)
    for level in (0, 1):
        with pytest.raises(BundleError, match="not enough memory to enlarge"):
            decode(bundle, level=level)
    with pytest.raises(BundleError, match="not enough memory to enlarge"):
        decode(bundle, region=(slice(0, 8), slice(0, 8)))


def test_the_bundle_reader_names_the_wrapper() -> None:
    from wavecore.bundle import read_bundle

    # (a reader from before 7.0 says "unsupported bundle format version 7.0")
    bundle = encode_image(_kron(_smooth(16, 16), 2), quality=40)
    with pytest.raises(BundleError, match=r"pixel replication \(format 7\.0\).*unwrap"):
        read_bundle(bundle)
    assert read_bundle(unwrap(bundle)[1]).header["shape"] == [16, 16]
