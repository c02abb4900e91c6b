"""Format 3.1: images and surfaces whose quantizer weights are derived from the plan.

The header names the quantizer by code 3 and stores, in place of the weights, only the
*pinned* ones (those the plan may not give bit for bit: a weight that differs from it, or one
whose unrounded value lies within ``PIN_MARGIN`` of a change of its four digits) and a CRC-8
of them all; a reader derives the rest once the head's CRC-32 has matched and refuses the
bundle when the check differs.  The chunks are those of 3.0, byte for byte; the block
coder's chunks delimit themselves, so the head stores no chunk lengths (the last chunk runs to
the end of the bundle), and an image's head is at most 96 bytes.
"""

from __future__ import annotations

import binascii
import json
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from skimage import data

import wavecore
from wavecore import BundleError, binheader, bundle, decode, inspect, quantize, restoration
from wavecore.bundle import (
    FORMAT_VERSION,
    MAGIC,
    PIN_MARGIN,
    pinned_weights,
    read_bundle,
    write_bundle,
)
from wavecore.errors import InvalidParameter
from wavecore.quantize import band_weight_margins

GOLDEN = Path(__file__).resolve().parent / "golden"


def _picture() -> np.ndarray:
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:70, 0:90] / 60.0
    rgb = np.stack([np.sin(5 * x + y), np.cos(4 * y), x * y], -1) * 90 + 120
    return (rgb + rng.normal(0, 6, rgb.shape)).clip(0, 255).astype(np.uint8)


BUNDLE = wavecore.encode_image(_picture(), quality=38, level=3)


def _split(data_: bytes) -> tuple[dict[str, Any], list[bytes]]:
    parsed = read_bundle(data_)
    return json.loads(json.dumps(parsed.header)), [bytes(c or b"") for c in parsed.chunks]


def _packed(data_: bytes) -> bytes:
    assert data_[8] == 3 and data_[10] < 128
    return data_[11 : 11 + data_[10]]


def _assemble(packed: bytes, chunks: list[bytes]) -> bytes:
    """A 3.1 bundle with correct CRCs around whatever header bytes it is given (the block
    coder's chunks delimit themselves: no lengths)."""
    head = MAGIC + bytes(FORMAT_VERSION) + bytes([len(packed)]) + packed
    head += b"".join(struct.pack("<H", binascii.crc_hqx(c, 0)) for c in chunks)
    return head + struct.pack("<I", zlib.crc32(head)) + b"".join(chunks)


def _weights_field(packed: bytes, header: dict[str, Any]) -> int:
    """Where 3.1's weights field (pin count, pins, check) starts: after the float64 step (the
    rounding is the default one, so nothing follows the step)."""
    return packed.index(struct.pack("<d", header["qparams"]["step"])) + 8


def test_the_codec_writes_3_1_with_quantizer_code_3_and_no_weights() -> None:
    header, chunks = _split(BUNDLE)
    packed = _packed(BUNDLE)
    assert read_bundle(BUNDLE).version == FORMAT_VERSION == (3, 1)
    assert packed[3] & 3 == binheader.DERIVED_DEADZONE
    older = write_bundle(header, chunks, version=(3, 0))
    # The same chunks, the same header read back; the head lost the weights (2 bytes a band,
    # less cV where it equals cH) for a pin count and a check byte.
    assert _split(older) == (header, chunks)
    assert len(BUNDLE) - sum(map(len, chunks)) <= len(older) - sum(map(len, chunks)) - 10
    weights = header["qparams"]["weights"]
    assert weights == bundle.derived_weights(header)
    assert np.array_equal(decode(BUNDLE), decode(older))
    # binheader.unpack alone cannot give the weights (they need the plan): it says so.
    with pytest.raises(BundleError, match="derived from the plan"):
        binheader.unpack(packed)


@pytest.mark.parametrize("target", [{"bpp": 1.0}, {"quality": 40.0}])
def test_an_image_head_is_at_most_96_bytes_at_every_level(target: dict[str, float]) -> None:
    picture = data.astronaut()  # 512² RGB: up to 8 levels (the picture padded to 1024²)
    heads = []
    for level in range(0, 12):
        try:
            coded = wavecore.encode_image(picture, level=level, **target)
        except InvalidParameter:
            break
        info = inspect(coded)
        heads.append(info["header_bytes"] - _record_bytes(info["header"]))
    assert len(heads) == 9 and max(heads) <= 96, heads


def _record_bytes(header: dict) -> int:
    """The bytes of a header's restoration record (docs/bundle-format.md): not in the 96."""
    if "restore" not in header:
        return 0
    plain = {k: v for k, v in header.items() if k != "restore"}
    record = len(binheader.pack(header)) - len(binheader.pack(plain))
    assert 0 < record <= restoration.record_bound(header["dtype"], 3)
    return record


def test_pinned_weights_are_those_near_a_change_of_digit(monkeypatch: pytest.MonkeyPatch) -> None:
    header, chunks = _split(BUNDLE)
    assert pinned_weights(header) == {}  # the codec's weights: none this close
    wavelet, boundary, shapes = bundle._plan_shapes(header)
    coeffs, axes = bundle._stand_ins(boundary, shapes)
    margins = [
        m
        for level in band_weight_margins(coeffs, wavelet=wavelet, boundary=boundary, axes=axes)
        for m in level
    ]
    flat = [w for level in header["qparams"]["weights"] for w in level]
    assert min(margins) > 0 and max(margins) <= 5e-4 and min(margins) > PIN_MARGIN
    # With a wider margin, exactly the weights within it are pinned, and still decode alike.
    margin = float(np.median(margins))
    monkeypatch.setattr(bundle, "PIN_MARGIN", margin)
    expected = {i: w for i, (w, m) in enumerate(zip(flat, margins, strict=True)) if m < margin}
    assert 0 < len(expected) < len(flat) and pinned_weights(header) == expected
    pinned = write_bundle(header, chunks)
    stored = binheader.unpack_pinned(_packed(pinned))[1]
    assert stored is not None and stored.pins == expected
    assert _split(pinned) == (header, chunks) and np.array_equal(decode(pinned), decode(BUNDLE))
    # When pins would take more bytes than the weights, the weights are stored (code 1).
    monkeypatch.setattr(bundle, "PIN_MARGIN", 1.0)
    every = write_bundle(header, chunks)
    assert _packed(every)[3] & 3 == 1 and _split(every) == (header, chunks)


def test_a_weight_that_is_not_the_plans_is_pinned() -> None:
    header, chunks = _split(BUNDLE)
    header["qparams"]["weights"][2][1] = 0.5  # cV of level 2: the plan's is another
    assert pinned_weights(header) == {1 + 3 + 1: 0.5}
    nudged = write_bundle(header, chunks)
    assert read_bundle(nudged).header == header
    assert np.array_equal(decode(nudged), decode(write_bundle(header, chunks, version=(3, 0))))


def test_the_pinned_golden_keeps_its_nudged_weight() -> None:
    data_ = (GOLDEN / "v3_1_image_grey_u8_pinned.wvb").read_bytes()
    header = read_bundle(data_).header
    stored = binheader.unpack_pinned(_packed(data_))[1]
    assert stored is not None and list(stored.pins) == [0]
    plan = bundle.derived_weights(header)[0][0]
    assert header["qparams"]["weights"][0][0] == stored.pins[0] != plan
    assert round((stored.pins[0] - plan) / 10 ** (np.floor(np.log10(plan)) - 3)) == 1


def test_a_reader_that_derives_other_weights_refuses_the_bundle(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    original = bundle._plan_weights

    def drifted(*args: Any) -> tuple[tuple[float, ...], ...]:
        weights = [list(level) for level in original(*args)]
        weights[-1][2] = float(f"{weights[-1][2] * 1.0003:.4g}")  # cD of level 1, one digit
        return tuple(tuple(level) for level in weights)

    monkeypatch.setattr(bundle, "_plan_weights", drifted)
    with pytest.raises(BundleError, match="are not the writer's"):
        decode(BUNDLE)
    with pytest.raises(BundleError, match="are not the writer's"):
        inspect(BUNDLE)


def test_a_wrong_check_byte_is_refused() -> None:
    header, chunks = _split(BUNDLE)
    packed = bytearray(_packed(BUNDLE))
    at = _weights_field(bytes(packed), header)
    assert packed[at] == 0  # no pins; the check follows
    packed[at + 1] ^= 0x10
    with pytest.raises(BundleError, match=r"their check is .*the header says"):
        decode(_assemble(bytes(packed), chunks))


@pytest.mark.parametrize(
    ("pins", "message"),
    [
        (b"\x02\x03\x10\x27\x01\x10\x27", "pinned weights out of order"),
        (b"\x01\x0a\x10\x27", "more than the largest, 9"),  # 10 bands at 3 levels: 0 … 9
        (b"\x0b", "more than the largest, 10"),  # more pins than bands
        (b"\x01\x00" + struct.pack("<H", 63000), "weight code 63000"),
    ],
)
def test_malformed_pins_are_named(pins: bytes, message: str) -> None:
    header, chunks = _split(BUNDLE)
    packed = _packed(BUNDLE)
    at = _weights_field(packed, header)
    bad = packed[:at] + pins + packed[at + 2 :]
    with pytest.raises(BundleError, match=rf"'qparams.weights'.*{message}"):
        binheader.unpack_pinned(bad)
    with pytest.raises(BundleError, match=r"qparams\.weights"):
        decode(_assemble(bad, chunks))
    with pytest.raises(BundleError, match=r"'qparams.weights'.*the header ends"):
        binheader.unpack_pinned(packed[:at] + b"\x01\x00")


def test_quantizer_code_3_is_unknown_to_the_compact_headers() -> None:
    t = np.linspace(0, 1, 50)
    curve = wavecore.encode_curve(np.stack([t, np.sin(6 * t)], 1))
    start = 4  # 6.0's preamble, then the flags
    flags = bytearray(curve[start : start + 4])
    flags[3] |= 3
    packed = flags + curve[start + 4 :]
    with pytest.raises(BundleError, match=r"'quantizer'.*unknown code 3"):
        binheader.unpack_from(bytes(packed), 0, major=6)


def test_band_weight_margins_bound_what_rounding_can_move() -> None:
    coeffs = wavecore.wavedec2(np.zeros((64, 72)), level=3, wavelet="cdf97")
    margins = band_weight_margins(coeffs, wavelet="cdf97", boundary="open")
    assert [len(level) for level in margins] == [1, 3, 3, 3]
    # At most half a unit of the fourth digit: 0.5 / 1000 relative.
    assert all(0 <= m <= 5e-4 * (1 + 1e-12) for level in margins for m in level)
    rng = np.random.default_rng(3)
    for value in [*10.0 ** rng.uniform(-5, 0.9, 200), 0.029185, 0.0291849999, 1.0, 9.9994]:
        margin = quantize._rounding_margin(float(value))
        digits = f"{value:.4g}"
        # Moved by less than its margin, a value keeps its four digits; moved by a little
        # more, one way or the other, it takes other ones.
        assert (
            f"{value * (1 + 0.99 * margin):.4g}" == digits == f"{value * (1 - 0.99 * margin):.4g}"
        )
        moved = {f"{value * (1 + 1.01 * margin):.4g}", f"{value * (1 - 1.01 * margin):.4g}"}
        assert margin < 1e-15 or moved != {digits}


def test_the_check_finds_every_change_of_one_weight_in_its_last_digit() -> None:
    weights = read_bundle(
        wavecore.encode_image(data.astronaut()[:300, :300], quality=40, level=7)
    ).header["qparams"]["weights"]
    check = binheader.weights_check(weights)
    for level, entry in enumerate(weights):
        for band, weight in enumerate(entry):
            unit = 10 ** (np.floor(np.log10(weight)) - 3)
            for step in (*range(-9, 0), *range(1, 10)):
                changed = [list(e) for e in weights]
                changed[level][band] = float(f"{weight + step * unit:.4g}")
                assert binheader.weights_check(changed) != check, (level, band, step)


def _head(header: dict[str, Any], pinned: dict[int, float] | None) -> int:
    """A 3.1 head from its header alone: preamble, header length, header, CRC-16s, CRC-32."""
    packed = binheader.pack(header, pinned=pinned, delimited=True)
    assert len(packed) < 128
    return len(MAGIC) + 2 + 1 + len(packed) + 2 * (header["levels"] + 1) + 4


@pytest.mark.parametrize(
    "options", [{}, {"bpp": 4.0, "level": 6}, {"quality": 55.0}, {"wavelet": "haar", "level": 7}]
)
def test_the_head_is_the_header_and_two_bytes_a_level(options: dict[str, Any]) -> None:
    """Nothing in a 3.1 image's head depends on the chunks' sizes."""
    picture = np.kron(_picture(), np.ones((2, 2, 1), np.uint8))
    picture[0, 1] ^= 1  # no longer an exact enlargement (that is coded as its source, in 7.0)
    data_ = wavecore.encode_image(picture, **options)
    parsed = read_bundle(data_)
    assert parsed.version == FORMAT_VERSION
    head = _head(parsed.header, pinned_weights(parsed.header))
    assert inspect(data_)["header_bytes"] == head
    assert len(data_) - head == sum(len(c or b"") for c in parsed.chunks)


def _deepest(wavelet: str, levels: int, shape: list[int], fitted: list[int]) -> dict[str, Any]:
    """A header of the largest picture a bundle may declare, with float64 data whose numbers
    all take their longest forms, and the plan's weights."""
    header = dict(read_bundle(BUNDLE).header)
    header.update(
        shape=shape,
        fitted=fitted,
        pads=[[0, fitted[0] - shape[0]], [0, fitted[1] - shape[1]]],
        colour="none",
        dtype="float64",
        wavelet=wavelet,
        levels=levels,
        peak=float(np.pi * 1e10),
        psnr=9404.9999,
        max_error=1e-300,
    )
    weights = bundle.derived_weights(header)
    header["qparams"] = dict(header["qparams"], step=float(np.pi / 7), weights=weights)
    return header


@pytest.mark.parametrize(
    ("wavelet", "fitted"), [("cdf97", [8192, 16384]), ("bspline2", [6146, 16386])]
)
def test_the_largest_head_is_at_most_96_bytes(wavelet: str, fitted: list[int]) -> None:
    """docs/bundle-format.md's bound for the filters of 11 levels at most (their deepest plan:
    both fitted lengths at least 4 · 2**11, resp. 3 · 2**11 + 2, and at most 2**27 samples),
    with the plan's own pins and one more."""
    header = _deepest(wavelet, 11, fitted, fitted)
    pins = pinned_weights(header)
    assert pins is not None
    flat = [w for entry in header["qparams"]["weights"] for w in entry]
    index = next(i for i in range(len(flat)) if i not in pins)
    one_more = {**pins, index: flat[index]}
    assert _head(header, pins) < _head(header, one_more) <= 96


def test_haars_deepest_heads_are_at_most_96_bytes_and_its_ties_need_no_pin() -> None:
    """The deepest plans (12 and 13 levels, which only Haar reaches), float64 numbers at their
    longest.  Haar's weights 2**-6 and 2**-7 lie exactly on a change of their fourth digit;
    the 2-D norms come from exact means of squares, so the ties are exact (margin 0), the same
    everywhere, and are not pinned (a product of two rounded square roots put them a few ulps
    off, and six bands were pinned: 107 bytes)."""
    header = _deepest("haar", 13, [4064, 16384], [8192, 16384])
    wavelet, boundary, shapes = bundle._plan_shapes(header)
    coeffs, axes = bundle._stand_ins(boundary, shapes)
    margins = band_weight_margins(coeffs, wavelet=wavelet, boundary=boundary, axes=axes)
    assert sum(m == 0.0 for level in margins for m in level) == 6
    pins = pinned_weights(header)
    assert pins == {}
    coarse = header["qparams"]["weights"][0][0]
    assert _head(header, pins) <= 89 < _head(header, {0: coarse}) <= 96  # and with a pin
    # One level more does not fit the element limit.
    with pytest.raises(BundleError):
        bundle.check_header(dict(header, levels=14, fitted=[16384, 16384]))


def test_a_bundle_cut_inside_its_last_chunk_is_truncated() -> None:
    picture = np.kron(_picture(), np.ones((4, 4, 1), np.uint8))
    picture[0, 1] ^= 1  # no longer an exact enlargement (that is coded as its source, in 7.0)
    big = wavecore.encode_image(picture, bpp=2.0)
    parsed = read_bundle(big)
    last = len(parsed.chunks) - 1
    cut = big[: len(big) - len(parsed.chunks[last]) // 2]
    assert read_bundle(cut).chunks[last] is None  # its intact table asks for more
    with pytest.raises(BundleError, match="truncated"):
        decode(cut)
    assert decode(cut, damaged="zero").shape == decode(big).shape
    assert decode(cut, level=1).shape == decode(big, level=1).shape


def test_bytes_after_the_last_chunk_are_its_damage() -> None:
    longer = BUNDLE + b"\x00"
    with pytest.raises(BundleError, match=r"corrupt.*or the bundle is truncated"):
        decode(longer)
    assert decode(longer, damaged="zero").shape == decode(BUNDLE).shape


def test_the_largest_lossless_head_is_at_most_66_bytes() -> None:
    """docs/bundle-format.md: a lossless 16-bit picture at 13 levels (coder code 3, no lengths)."""
    # the block coder's (effort="fast"): the default lossless coder's bundles are 3.0's
    blocks = wavecore.encode_image(_picture(), lossless=True, level=2, effort="fast")
    header = read_bundle(blocks).header
    assert read_bundle(wavecore.encode_image(_picture(), lossless=True, effort="fast")).version == (
        3,
        1,
    )
    header.update(
        shape=[8192, 16384],
        fitted=[8192, 16384],
        colour="none",
        dtype="uint16",
        levels=13,
        lifting=["511c"] * 13,
        peak=65535.0,
    )
    bundle.check_header(header)  # a header a bundle may carry (2**27 samples)
    assert _head(header, None) <= 66
