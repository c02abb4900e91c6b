"""wavecore.binheader: every header the codec writes packs and unpacks to an equal dict.

Each value decoding reads comes back bit for bit (the step and peak, the weights, ``scale``);
``max_error`` may come back as the float32 at or above it.  Numbers are checked over every
float Hypothesis finds, the weights over every code the format has.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_bundle_fuzz import BUNDLES, split

import wavecore
from wavecore import BundleError, binheader
from wavecore.bundle import BOUNDARIES, COLOURS, DTYPES, KINDS, read_bundle
from wavecore.codec import replication
from wavecore.lossless import FILTERS
from wavecore.quantize import band_weights

GOLDEN = Path(__file__).resolve().parent / "golden"


def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


def _headers() -> dict[str, dict[str, Any]]:
    made = {name: split(data)[0] for name, data in BUNDLES.items()}
    for path in sorted(GOLDEN.glob("*.wvb")):  # every version's headers, old ones included
        data = path.read_bytes()
        if replication.is_replicated(data):  # 7.0: the source's bundle holds the header
            data = replication.unwrap(data)[1]
        made[path.stem] = read_bundle(data).header
    made["huge surface"] = read_bundle(wavecore.encode_surface(np.full((6, 6), 1e300))).header
    return made


HEADERS = _headers()


def _same_but_max_error(header: dict[str, Any], back: dict[str, Any]) -> None:
    assert {k: v for k, v in back.items() if k != "max_error"} == {
        k: v for k, v in header.items() if k != "max_error"
    }
    for key in ("peak", "psnr"):
        if isinstance(header[key], float):
            assert _bits(back[key]) == _bits(header[key])
    if "qparams" in header and "step" in header["qparams"]:
        assert _bits(back["qparams"]["step"]) == _bits(header["qparams"]["step"])
    exact, stored = header["max_error"], back["max_error"]
    assert stored >= exact and stored - exact <= abs(exact) * 2.0**-23


@pytest.mark.parametrize("name", sorted(HEADERS))
def test_every_header_round_trips(name: str) -> None:
    header = HEADERS[name]
    _same_but_max_error(header, binheader.unpack(binheader.pack(header)))


def test_the_code_tables_hold_every_value_the_bundle_accepts() -> None:
    assert set(binheader.KIND_CODES) == set(KINDS)
    assert set(binheader.DTYPE_CODES) == set(DTYPES)
    # The lossless "rct-p<w>" colours share code 3, their weight in a varint.
    assert set(binheader.COLOUR_CODES) == {c for c in COLOURS if not c.startswith("rct-p")}
    assert set(binheader.BOUNDARY_CODES) == set(BOUNDARIES)
    assert set(binheader.LIFTING_CODES) == set(FILTERS)


def test_what_the_codec_writes_is_compact() -> None:
    """No extension (no JSON) in any header the codec writes today."""
    for name, data in BUNDLES.items():
        packed = binheader.pack(split(data)[0])
        assert not packed[3] & 0x40, name  # the extension flag
        assert len(packed) < 64, (name, len(packed))


def test_every_weight_code_round_trips() -> None:
    """All 63 000 codes: four significant digits, 1.000e-6 to 9.999 (seven decades)."""
    for code in range(binheader.WEIGHT_CODE_LIMIT):
        exponent, mantissa = divmod(code, 9000)
        weight = float(f"{mantissa + 1000}e{exponent + binheader.WEIGHT_EXPONENT_MIN}")
        header = _curve_with_weights([[weight], [weight]]) if code % 97 == 0 else None
        if header is not None:
            back = binheader.unpack(binheader.pack(header))
            assert _bits(back["qparams"]["weights"][1][0]) == _bits(weight)
    # The brief's shortcut, weight x 10 000 as an integer, would not be exact: band_weights
    # keeps four significant digits, not four decimals (a 5-level cdf97 image has 0.02918).
    weights = band_weights(
        wavecore.wavedec2(np.zeros((512, 512)), wavelet="cdf97", level=5),
        wavelet="cdf97",
        boundary="open",
    )
    assert any(round(w * 1e4) / 1e4 != w for level in weights for w in level)
    header = _curve_with_weights(weights, two_d=True)
    assert binheader.unpack(binheader.pack(header))["qparams"]["weights"] == weights


def _curve_with_weights(weights: list[list[float]], two_d: bool = False) -> dict[str, Any]:
    header, _ = split(BUNDLES["surface" if two_d else "closed curve"])
    header["levels"] = len(weights) - 1
    header["qparams"] = {**header["qparams"], "weights": weights}
    return header


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(2**64), 2**64))
def test_peaks_round_trip_bit_for_bit(value: float | int) -> None:
    header = {**HEADERS["lossy image"], "peak": value}
    back = binheader.unpack(binheader.pack(header))["peak"]
    assert type(back) is type(value)
    assert _bits(float(back)) == _bits(float(value)) and back == value


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_psnr_and_rounding_round_trip_bit_for_bit(value: float) -> None:
    header = dict(HEADERS["lossy image"])
    header["psnr"] = value
    header["qparams"] = {**header["qparams"], "rounding": value}
    back = binheader.unpack(binheader.pack(header))
    assert _bits(back["psnr"]) == _bits(value)
    assert _bits(back["qparams"]["rounding"]) == _bits(value)


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=0.0, allow_nan=False, allow_infinity=False))
def test_max_error_stays_an_upper_bound(value: float) -> None:
    header = {**HEADERS["closed curve"], "max_error": value}
    stored = binheader.unpack(binheader.pack(header))["max_error"]
    assert stored >= value and stored - value <= value * 2.0**-23


def test_psnr_of_four_decimals_takes_three_bytes() -> None:
    header = HEADERS["lossy image"]
    sizes = {}
    for psnr in (None, 40.0128, 65.8746, 104.8574):
        sizes[psnr] = len(binheader.pack({**header, "psnr": psnr}))
    assert sizes[40.0128] == sizes[65.8746] == sizes[104.8574] == sizes[None] + 2


def test_unknown_keys_and_other_parameters_go_to_the_extension() -> None:
    header = dict(HEADERS["lossy image"])
    header["future"] = {"a": [1, 2.5, None]}
    header["cparams"] = {**header["cparams"], "extra": True}
    header["wavelet"] = "mywave"
    back = binheader.unpack(binheader.pack(header))
    assert back == header


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("kind", "movie", "'kind'"),
        ("dtype", "complex64", "'dtype'"),
        ("shape", [2**41], "'shape'"),
        ("levels", 256, "'levels'"),
        ("peak", 2**70, "'peak' is an integer too large"),
        ("peak", "high", "'peak'"),
        ("max_error", [1], "'max_error'"),
        ("boundary", ["open"] * 3, "'boundary'"),
    ],
)
def test_pack_refuses_what_it_cannot_say(field: str, value: Any, message: str) -> None:
    with pytest.raises(BundleError, match=message):
        binheader.pack({**HEADERS["lossy image"], field: value})


_NAMES = st.sampled_from(["bspline2", "haar", "cdf97", "reversible", "mywave", "x_1"])
_FLOATS = st.floats(allow_nan=False, allow_infinity=False)
_SIZES = st.integers(0, 2**37)


@st.composite
def headers(draw: st.DrawFn) -> dict[str, Any]:
    """Any header the binary form must carry, compact or through its extension."""
    axes = draw(st.integers(1, 2))
    levels = draw(st.integers(0, 30))
    shape = draw(st.lists(_SIZES, min_size=1, max_size=4))
    pads = [draw(st.sampled_from([[0, 0], [0, draw(_SIZES)], [draw(_SIZES), draw(_SIZES)]]))]
    if axes == 2:
        pads.append([draw(_SIZES), draw(_SIZES)])
    fitted = list(shape) if len(shape) > 1 else [shape[0], 1]
    for axis, (before, after) in enumerate(pads[: len(fitted)]):
        fitted[axis] += before + after
    if draw(st.booleans()):
        fitted = draw(st.lists(_SIZES, min_size=1, max_size=4))
    bands = 3 if axes == 2 else 1
    code = st.integers(0, binheader.WEIGHT_CODE_LIMIT - 1)
    weight = code.map(lambda c: float(f"{c % 9000 + 1000}e{c // 9000 - 9}"))
    weights = [[draw(weight)]] + [
        draw(st.lists(weight, min_size=bands, max_size=bands)) for _ in range(levels)
    ]
    header: dict[str, Any] = {
        "kind": draw(st.sampled_from(KINDS)),
        "shape": shape,
        "dtype": draw(st.sampled_from(DTYPES)),
        "fit": draw(st.sampled_from(["pad", "none"])),
        "pads": pads,
        "fitted": fitted,
        "wavelet": draw(_NAMES),
        "boundary": draw(st.lists(st.sampled_from(BOUNDARIES), min_size=axes, max_size=axes)),
        "levels": levels,
        "colour": draw(st.sampled_from(COLOURS)),
        "peak": draw(_FLOATS | st.integers(0, 2**60)),
        "quantizer": draw(st.sampled_from(["deadzone", "none", "other"])),
        "coder": draw(st.sampled_from(["context", "zlib", "other"])),
        "psnr": draw(st.none() | _FLOATS | _FLOATS.map(lambda x: round(x % 200, 4))),
        "max_error": draw(st.floats(min_value=0, allow_nan=False, allow_infinity=False)),
    }
    header["qparams"] = draw(
        st.sampled_from(
            [
                {},
                {
                    "name": header["quantizer"],
                    "step": draw(_FLOATS),
                    "weights": weights,
                    "rounding": draw(st.sampled_from([0.27, 0.4, 0.5]) | _FLOATS),
                },
                {"name": "deadzone", "step": 1},
            ]
        )
    )
    version = draw(st.integers(0, 20))
    header["cparams"] = draw(
        st.sampled_from(
            [
                {"coder": header["coder"]},
                {"coder": header["coder"], "version": version, "two_d": draw(st.booleans())},
                {
                    "coder": "context",
                    "version": 4,
                    "two_d": True,
                    "block": 2 ** draw(st.integers(3, 11)),
                },
            ]
        )
    )
    if header["wavelet"] == "reversible" or draw(st.booleans()):
        header["lifting"] = draw(
            st.lists(st.sampled_from(["legall53", "haar", "bspline2"]), max_size=30)
            | st.just(["nope"])
        )
    if draw(st.booleans()):
        header["opaque"] = draw(st.sampled_from([True, False]))
    if draw(st.booleans()):
        header["scale"] = draw(st.integers(-1100, 1100))
    if draw(st.booleans()):
        header["future_key"] = draw(st.lists(st.integers(-5, 5), max_size=3))
    return header


@settings(max_examples=400, deadline=None)
@given(headers())
def test_any_header_round_trips(header: dict[str, Any]) -> None:
    back = binheader.unpack(binheader.pack(header))
    _same_but_max_error(header, back)
    assert type(back["peak"]) is type(header["peak"])
