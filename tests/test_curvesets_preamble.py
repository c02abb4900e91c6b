"""Version 6's 3-byte preamble (``89 57 86``) and the sniffing of every kind of bundle.

Curve sets of version 6 share their first two bytes with bundle formats 4.0–6.0 (``89 57
<major> <minor>``); the third byte (0x80 | the curve-set version, against a major of 3..6 or
``V``) tells them apart, so no reader may take one kind for the other.
"""

from __future__ import annotations

import binascii
import contextlib
import struct

import numpy as np
import pytest

import wavecore
from wavecore import curvesets
from wavecore.bundle import read_bundle


def _outlines() -> list[np.ndarray]:
    t = np.linspace(0, 2 * np.pi, 61)[:-1]
    ring = np.stack([np.cos(t), 0.6 * np.sin(t)], 1) * 20
    return [ring, ring + [45.3, 2.1], ring[::2] * 0.5 + [10, 60]]


def _version_6() -> bytes:
    bundle = wavecore.encode_curves(_outlines(), closed=True, tolerance=0.1, method="vertex")
    assert bundle[:3] == b"\x89W\x86"  # the family's two bytes and 0x80 | 6
    return bundle


def _with_crc16(body: bytes) -> bytes:
    return body + struct.pack("<H", binascii.crc_hqx(body, 0))


def test_version_6_preamble_round_trips_and_is_sniffed() -> None:
    bundle = _version_6()
    assert wavecore.curvesets.is_curve_set(bundle)
    back = wavecore.decode_curves(bundle)
    assert len(back.curves) == 3
    for got, want in zip(wavecore.decode(bundle), _outlines(), strict=True):
        assert got.shape[1] == 2 and len(got) >= 3
        # the decoded vertices lie within the tolerance of the outline: same extent
        assert np.abs(got.min(0) - want.min(0)).max() < 0.5
        assert np.abs(got.max(0) - want.max(0)).max() < 0.5
    info = wavecore.inspect(bundle)
    assert info["version"] == str(curvesets.COPY_VERSION) and info["count"] == 3


def test_image_and_curve_bundles_are_not_taken_for_curve_sets() -> None:
    image = (np.arange(24 * 20) % 251).astype(np.uint8).reshape(24, 20)
    curve = np.cumsum(np.random.default_rng(3).normal(size=(200, 2)), 0)
    kinds = [
        wavecore.encode_image(image, lossless=True, level=2),
        wavecore.encode_image(image, quality=80),
        wavecore.encode_curve(curve, tolerance=0.1),
        wavecore.encode_curve(curve[:20], tolerance=0.01),
    ]
    for bundle in kinds:
        assert bundle[:2] == b"\x89W" and bundle[2] < 0x80
        assert not curvesets.is_curve_set(bundle)
        read_bundle(bundle)  # still read as a bundle
        with pytest.raises(wavecore.BundleError, match="not a curve-set bundle"):
            wavecore.decode_curves(bundle)


def test_the_bundle_reader_names_a_curve_set() -> None:
    with pytest.raises(wavecore.BundleError, match=r"a curve set \(version 6\)"):
        read_bundle(_version_6())


@pytest.mark.parametrize("third", [0x80, 0x87, 0xFF])
def test_an_unknown_short_version_is_refused_plainly(third: int) -> None:
    bundle = _version_6()
    crafted = _with_crc16(b"\x89W" + bytes([third]) + bundle[3:-2])
    assert curvesets.is_curve_set(crafted)
    with pytest.raises(
        wavecore.BundleError, match=f"curve set version {third & 0x7F} is not supported"
    ):
        wavecore.decode(crafted)
    with pytest.raises(wavecore.BundleError, match="not supported"):
        wavecore.inspect(crafted)


def test_preambles_of_the_wrong_form_are_refused() -> None:
    bundle = _version_6()
    long_6 = curvesets.MAGIC + bytes([curvesets.COPY_VERSION]) + bundle[3:-2]
    with pytest.raises(
        wavecore.BundleError, match="version 6 is damaged: it is written with the 3-byte"
    ):
        wavecore.decode_curves(_with_crc16(long_6))
    short_5 = b"\x89W" + bytes([0x80 | curvesets.PRIOR_VERSION]) + bundle[3:-2]
    with pytest.raises(
        wavecore.BundleError, match="version 5 is damaged: it is written with the 4-byte"
    ):
        wavecore.decode_curves(short_5 + struct.pack("<I", 0))


def test_damaged_preambles_fail_with_wavecore_errors() -> None:
    # every value of each preamble byte, and of the first byte after it, in a version-6 set and
    # in a 4.0 image bundle: curves, an image, or a wavecore error (never another exception)
    image = (np.arange(16 * 16) % 7).astype(np.uint8).reshape(16, 16)
    for bundle in (_version_6(), wavecore.encode_image(image, lossless=True, level=2)):
        for at in range(4):
            for value in range(256):
                damaged = bytearray(bundle)
                damaged[at] = value
                with contextlib.suppress(wavecore.WavecoreError):
                    wavecore.decode(bytes(damaged))
                with contextlib.suppress(wavecore.WavecoreError):
                    wavecore.inspect(bytes(damaged))


def test_older_versions_keep_their_magic() -> None:
    curves = [np.cumsum(np.random.default_rng(5).normal(size=(40, 3)), 0)]
    vertex = wavecore.encode_curves(curves, tolerance=0.05, method="vertex")
    wavelet = wavecore.encode_curves(curves, tolerance=0.05, method="wavelet")
    assert vertex[:5] == curvesets.MAGIC + bytes([curvesets.VERTEX_VERSION])
    assert wavelet[:5] == curvesets.MAGIC + bytes([curvesets.VERSION])
    for bundle in (vertex, wavelet):
        assert curvesets.is_curve_set(bundle)
        assert len(wavecore.decode(bundle)) == 1
        with pytest.raises(wavecore.BundleError, match="not a wavecore bundle"):
            read_bundle(bundle)


def test_version_6_packs_head_tolerance_and_count_in_three_bytes() -> None:
    # the fixed part of a short version-6 set: preamble 3, packed head 3, CRC-16 2
    bundle = _version_6()
    head, tolerance_byte, count_plus_one = curvesets._unpack_head(bundle[3:6])
    assert (
        count_plus_one == 4
        and tolerance_byte == curvesets._compact_tolerance(curvesets._pack_tolerance(0.1)[1])[0]
    )
    assert head & 1 == 0 and head >> 1 & 3 == 1  # no metadata; all closed


@pytest.mark.parametrize("tolerance", [0.1, 0.123456789])
@pytest.mark.parametrize("count", [curvesets._PACKED_COUNTS - 1, curvesets._PACKED_COUNTS + 3])
def test_version_6_escapes_long_tolerances_and_many_curves(tolerance: float, count: int) -> None:
    t = np.linspace(0, 2 * np.pi, 13)[:-1]
    shape = np.stack([np.cos(t), np.sin(t)], 1) * 3
    curves = [shape + [7.1 * k, 0.3 * (k % 3)] for k in range(count)]
    bundle = wavecore.encode_curves(curves, closed=True, tolerance=tolerance, method="vertex")
    assert bundle[:3] == b"\x89W\x86"
    _, tolerance_byte, count_plus_one = curvesets._unpack_head(bundle[3:6])
    packed = count < curvesets._PACKED_COUNTS and tolerance == 0.1
    assert (count_plus_one == count + 1) if packed else (count_plus_one, tolerance_byte) == (0, 0)
    back = wavecore.decode_curves(bundle)
    assert len(back.curves) == count and back.tolerance <= tolerance
    for got, want in zip(back.curves, curves, strict=True):
        assert np.abs(got.min(0) - want.min(0)).max() <= tolerance * 1.5
