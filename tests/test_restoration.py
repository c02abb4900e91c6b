"""The restoration filter (wavecore.restoration): the compiled passes against a plain NumPy
reading of docs/bundle-format.md's "The restoration record", the header record, where the
decoder applies it, and what the encoder writes."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

import wavecore
from wavecore import binheader, restoration
from wavecore.bundle import check_header, read_bundle
from wavecore.codec.decode import _decode, _open
from wavecore.errors import BundleError


def _activity_reference(x: np.ndarray) -> np.ndarray:
    x = x.astype(np.int64)
    p = np.pad(x, 1, mode="symmetric")
    lap = np.abs(4 * x - p[:-2, 1:-1] - p[2:, 1:-1] - p[1:-1, :-2] - p[1:-1, 2:])
    q = np.pad(lap, 2, mode="symmetric")
    h, w = x.shape
    return sum(q[2 + a : 2 + a + h, 2 + b : 2 + b + w] for a in range(-2, 3) for b in range(-2, 3))


def _filter_reference(x: np.ndarray, item: dict, high: int) -> np.ndarray:
    x = x.astype(np.int64)
    h, w = x.shape
    classes = np.searchsorted(np.array(item["edges"]), _activity_reference(x), side="right")
    p = np.pad(x, 2, mode="symmetric")

    def shifted(a: int, b: int) -> np.ndarray:
        return p[2 + a : 2 + a + h, 2 + b : 2 + b + w]

    out = x.copy()
    for c, taps in enumerate(item["taps"]):
        if taps is None:
            continue
        pairs = zip(taps, restoration.OFFSETS, strict=True)
        delta = 64 + sum(t * (shifted(a, b) + shifted(-a, -b) - 2 * x) for t, (a, b) in pairs)
        out[classes == c] = np.clip(x + (delta >> 7), 0, high)[classes == c]
    return out


ITEM = {
    "edges": [10, 100, 300],
    "taps": [[5, -3, 2, 1, 0, 7], None, [-64, 63, 1, 2, 3, 4], [1, 1, 1, 1, 1, 1]],
}


@pytest.mark.parametrize("shape", [(1, 7), (7, 1), (1, 1), (2, 3), (5, 5), (37, 41)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_filter_matches_the_specification(shape: tuple[int, int], dtype: type) -> None:
    high = int(np.iinfo(dtype).max)
    x = np.random.default_rng(sum(shape)).integers(0, high + 1, shape).astype(dtype)
    like = np.empty(0, restoration._work_dtype(x.dtype))
    _, activity = restoration._block(x[..., np.newaxis], 0, 0, shape[0], like)
    assert np.array_equal(activity, _activity_reference(x))
    out = restoration.apply_restoration(x, [ITEM])
    assert out.dtype == dtype and out.shape == shape
    assert np.array_equal(out, _filter_reference(x, ITEM, high))


def test_colour_channels_are_filtered_and_alpha_is_not() -> None:
    rng = np.random.default_rng(3)
    rgba = rng.integers(0, 256, (20, 30, 4)).astype(np.uint8)
    out = restoration.apply_restoration(rgba, [ITEM, None, ITEM])
    assert np.array_equal(out[..., 3], rgba[..., 3])
    assert np.array_equal(out[..., 1], rgba[..., 1])
    assert np.array_equal(out[..., 0], _filter_reference(rgba[..., 0], ITEM, 255))
    assert not np.array_equal(out[..., 2], rgba[..., 2])


@pytest.fixture(scope="module")
def camera_bundle() -> bytes:
    return wavecore.encode_image(data.camera(), wavelet="cdf97", bpp=0.5)


def test_encoder_writes_a_filter_that_pays(camera_bundle: bytes) -> None:
    camera = data.camera()
    parsed, plan = _open(camera_bundle)
    restore = parsed.header["restore"]
    assert restore is not None and len(restore) == 1
    plain = _decode(parsed, plan, None, 0)
    out = wavecore.decode(camera_bundle)
    assert np.array_equal(out, restoration.apply_restoration(plain, restore))

    def psnr(a: np.ndarray) -> float:
        return 10 * np.log10(255**2 / np.mean((a.astype(float) - camera) ** 2))

    assert psnr(out) > psnr(plain)
    info = wavecore.inspect(camera_bundle)
    assert info["restored"]
    assert info["psnr"] == np.floor(psnr(out) * 1e4) / 1e4
    assert info["max_error"] == np.max(np.abs(out.astype(int) - camera))
    assert len(camera_bundle) <= 0.5 * camera.size / 8


@pytest.mark.parametrize(
    "region",
    [
        (slice(0, 1), slice(0, 512)),
        (slice(100, 140), slice(50, 90)),
        (slice(509, 512), slice(0, 3)),
        (slice(3, 200, 7), slice(2, 511, 3)),
        (slice(255, 256), slice(256, 257)),
    ],
)
def test_regions_equal_the_crop_of_the_whole(camera_bundle: bytes, region: tuple) -> None:
    whole = wavecore.decode(camera_bundle)
    assert np.array_equal(wavecore.decode(camera_bundle, region=region), whole[region])


def test_coarse_levels_and_keep_decode_without_the_filter(camera_bundle: bytes) -> None:
    parsed, plan = _open(camera_bundle)
    assert np.array_equal(wavecore.decode(camera_bundle, level=1), _decode(parsed, plan, None, 1))
    assert np.array_equal(wavecore.decode(camera_bundle, keep=0.5), _decode(parsed, plan, 0.5, 0))


def test_record_round_trips_and_is_bounded(camera_bundle: bytes) -> None:
    header = read_bundle(camera_bundle).header
    packed = binheader.pack(header)
    without = binheader.pack({k: v for k, v in header.items() if k != "restore"})
    assert 0 < len(packed) - len(without) <= restoration.record_bound("uint8", 1)
    assert binheader.unpack(packed) == header
    # a header whose coder is not version 8 keeps the filter in the extension
    other = dict(header, cparams=dict(header["cparams"], version=7))
    assert binheader.unpack(binheader.pack(other)) == other


def test_colour_and_sixteen_bit_pictures_round_trip() -> None:
    astronaut = data.astronaut()
    bundle = wavecore.encode_image(astronaut, wavelet="cdf97", bpp=0.5)
    restore = read_bundle(bundle).header["restore"]
    assert len(restore) == 3 and any(item is not None for item in restore)
    deep = data.camera().astype(np.uint16) * 257
    bundle16 = wavecore.encode_image(deep, wavelet="cdf97", bpp=0.5)
    out = wavecore.decode(bundle16)
    assert out.dtype == np.uint16 and out.shape == deep.shape
    assert read_bundle(bundle16).header.get("restore") is not None


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"edges": [5, 4, 6]}, "edges"),
        ({"taps": [[64, 0, 0, 0, 0, 0], None, None, None]}, "taps"),
        ({"taps": [None, None, None, None]}, "taps"),
        ({"edges": [1, 2]}, "edges"),
    ],
)
def test_bad_records_are_refused_by_name(camera_bundle: bytes, change: dict, problem: str) -> None:
    header = dict(read_bundle(camera_bundle).header)
    header["restore"] = [dict(header["restore"][0], **change)]
    with pytest.raises(BundleError, match=f"'restore' {problem}"):
        check_header(header)


def test_restore_only_on_lossy_integer_pictures(camera_bundle: bytes) -> None:
    header = dict(read_bundle(camera_bundle).header)
    for change in ({"dtype": "float32"}, {"kind": "surface"}, {"quantizer": "none"}):
        with pytest.raises(BundleError, match="'restore' applies only"):
            check_header(dict(header, **change))
    with pytest.raises(BundleError, match="list of 1 channel"):
        check_header(dict(header, restore=[None, None]))


def test_a_record_without_its_guard_is_refused(camera_bundle: bytes) -> None:
    header = read_bundle(camera_bundle).header
    packed = binheader.pack(header)
    plain = binheader.pack({k: v for k, v in header.items() if k != "restore"})
    coder_byte = next(i for i, (a, b) in enumerate(zip(packed, plain, strict=False)) if a != b)
    at = coder_byte + 1  # the version nibble 9, then the record
    assert packed[at : at + 2] == restoration.RECORD_GUARD
    damaged = packed[:at] + b"\x01\x1d" + packed[at + 2 :]
    with pytest.raises(BundleError, match=r"'restore'.*guard"):
        binheader.unpack(damaged)


def test_cut_records_are_bundle_errors(camera_bundle: bytes) -> None:
    header = read_bundle(camera_bundle).header
    packed = binheader.pack(header)
    for end in range(len(packed)):
        with pytest.raises(BundleError):
            binheader.unpack(packed[:end])


def test_no_filter_without_a_fitting_target() -> None:
    image = data.camera()[:128, :128]
    floats = image.astype(np.float32) / 255
    for bundle in (
        wavecore.encode_image(image, keep=0.5),
        wavecore.encode_image(image, lossless=True),
        wavecore.encode_image(floats, wavelet="cdf97", bpp=1.0),
        wavecore.encode_image(image, wavelet="cdf97", bpp=0.05),  # too small a budget
    ):
        assert "restore" not in read_bundle(bundle).header
        assert not wavecore.inspect(bundle)["restored"]


def test_thread_count_does_not_change_the_bytes(monkeypatch: pytest.MonkeyPatch) -> None:
    image = data.coins()
    first = wavecore.encode_image(image, wavelet="cdf97", bpp=0.75)
    monkeypatch.setenv("WAVECORE_THREADS", "1")
    assert wavecore.encode_image(image, wavelet="cdf97", bpp=0.75) == first
    assert read_bundle(first).header.get("restore") is not None


def test_a_read_only_or_strided_original_needs_no_kernel_of_its_own() -> None:
    # A picture from Pillow may be read-only; each array type would be a signature to compile
    # at the first request after the warm-up.
    rng = np.random.default_rng(7)
    original = rng.integers(0, 256, (40, 50, 3)).astype(np.uint8)
    decoded = np.clip(original.astype(int) + rng.integers(-3, 4, original.shape), 0, 255)
    decoded = decoded.astype(np.uint8)
    expected = restoration.fit_restoration(decoded, original.copy())
    kernels = (restoration._fit_sums, restoration._change_sums)
    before = [len(k.signatures) for k in kernels]
    frozen = original.copy()
    frozen.setflags(write=False)
    strided = np.ascontiguousarray(original[:, :, ::-1])[:, :, ::-1]
    assert restoration.fit_restoration(decoded, frozen) == expected
    assert restoration.fit_restoration(decoded, strided) == expected
    assert [len(k.signatures) for k in kernels] == before
