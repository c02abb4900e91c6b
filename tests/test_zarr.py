"""wavecore as a Zarr codec: the chunk format, numcodecs, zarr-python 3, xarray."""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

pytest.importorskip("zarr", reason="the Zarr tests need the zarr extra (pip install '.[zarr]')")
numcodecs = pytest.importorskip("numcodecs", reason="the zarr extra installs numcodecs")

import zarr  # noqa: E402
from zarr_fields import smooth_field  # noqa: E402

from wavecore.errors import BundleError, InvalidParameter  # noqa: E402
from wavecore.zarr import (  # noqa: E402
    MODE_GRID,
    MODE_WAVELET,
    CodecConfig,
    WavecoreCodec,
    WavecoreZarrCodec,
    decode_chunk,
    encode_chunk,
)

GOLDEN = Path(__file__).parent / "golden_zarr"


def largest_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64))))


# --------------------------------------------------------------------------------------------
# The chunk codec
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "shape", [(40, 33), (1, 50), (50, 1), (1, 1), (3, 17, 12), (2, 1, 9), (64, 64)]
)
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_max_error_holds_on_every_value(shape: tuple[int, ...], dtype: str) -> None:
    data = smooth_field(shape, seed=sum(shape), dtype=dtype)
    bound = 1e-3 * float(np.ptp(data)) or 1e-3
    out = decode_chunk(encode_chunk(data, {"max_error": bound}))
    assert out.shape == data.shape and out.dtype == data.dtype
    assert largest_error(out, data) <= bound


@pytest.mark.parametrize("dtype", ["int16", "uint16", "int32", "uint8"])
def test_max_error_on_integers(dtype: str) -> None:
    data = np.clip(smooth_field((37, 29), seed=4), 0, 127).astype(dtype)
    out = decode_chunk(encode_chunk(data, {"max_error": 2}))
    assert out.dtype == data.dtype
    assert largest_error(out, data) <= 2


@pytest.mark.parametrize("dtype", ["uint8", "uint16", "int16", "int32", "int64", "uint32"])
def test_lossless_integers_are_exact(dtype: str) -> None:
    rng = np.random.default_rng(7)
    info = np.iinfo(dtype)
    data = rng.integers(max(info.min, -3000), min(info.max, 3000), (3, 21, 14)).astype(dtype)
    out = decode_chunk(encode_chunk(data, {"lossless": True}))
    assert out.dtype == data.dtype and np.array_equal(out, data)


def test_lossless_wide_and_extreme_integers() -> None:
    rng = np.random.default_rng(8)
    wide = rng.integers(-(2**40), 2**40, (20, 30), dtype=np.int64)  # past 16 bits
    extreme = rng.integers(0, 2**64 - 1, (9, 8), dtype=np.uint64, endpoint=True)
    for data in (wide, extreme):
        out = decode_chunk(encode_chunk(data, {"lossless": True}))
        assert out.dtype == data.dtype and np.array_equal(out, data)


def test_lossless_is_smaller_than_raw_on_smooth_integers() -> None:
    data = (smooth_field((64, 64), seed=3) * 10).astype(np.int16)
    assert len(encode_chunk(data, {"lossless": True})) < data.nbytes / 2


def test_nan_and_infinities_come_back_exactly() -> None:
    data = smooth_field((30, 20), seed=5, dtype="float64")
    data[3, 4] = np.nan
    data[10, :] = np.inf
    data[0, 0] = -np.inf
    out = decode_chunk(encode_chunk(data, {"max_error": 0.05}))
    assert np.array_equal(np.isnan(out), np.isnan(data))
    finite = np.isfinite(data)
    assert np.array_equal(out[~finite & ~np.isnan(data)], data[~finite & ~np.isnan(data)])
    assert largest_error(out[finite], data[finite]) <= 0.05


@pytest.mark.parametrize("value", [0.0, np.nan, 7.5])
def test_constant_chunks_are_a_few_bytes(value: float) -> None:
    data = np.full((64, 48), value, dtype=np.float32)
    coded = encode_chunk(data, {"max_error": 0.1})
    assert len(coded) < 40
    assert np.array_equal(decode_chunk(coded), data, equal_nan=True)


def test_psnr_target_is_met() -> None:
    data = smooth_field((48, 40), seed=9, dtype="float64")
    out = decode_chunk(encode_chunk(data, {"psnr": 50}))
    mse = float(np.mean((out - data) ** 2))
    assert 10 * np.log10(float(np.ptp(data)) ** 2 / mse) >= 50


def test_bpp_target_is_not_exceeded_per_slice() -> None:
    data = smooth_field((64, 64), seed=10, dtype="float64")
    coded = encode_chunk(data, {"bpp": 2.0})
    # The slice's bundle keeps to 2 bpp; the chunk adds its framing (about 75 bytes).
    assert len(coded) <= 2.0 * data.size / 8 + 96


def test_wavelet_and_level_are_used() -> None:
    data = smooth_field((64, 64), seed=11)
    a = encode_chunk(data, {"max_error": 0.1, "wavelet": "haar", "level": 2})
    b = encode_chunk(data, {"max_error": 0.1, "wavelet": "bspline2", "level": 3})
    assert a != b
    for coded in (a, b):
        assert largest_error(decode_chunk(coded), data) <= 0.1


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    data=hnp.arrays(
        dtype=st.sampled_from([np.float32, np.float64]),
        shape=hnp.array_shapes(min_dims=2, max_dims=3, min_side=1, max_side=12),
        elements=st.floats(-1e6, 1e6, width=32),
    ),
    bound=st.sampled_from([1e-3, 0.1, 3.0]),
)
def test_max_error_bound_property(data: np.ndarray, bound: float) -> None:
    out = decode_chunk(encode_chunk(data, {"max_error": bound}))
    assert out.shape == data.shape and out.dtype == data.dtype
    assert largest_error(out, data) <= bound


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    data=hnp.arrays(
        dtype=st.sampled_from([np.uint8, np.int16, np.int32, np.uint16]),
        shape=hnp.array_shapes(min_dims=2, max_dims=3, min_side=1, max_side=10),
    )
)
def test_lossless_property(data: np.ndarray) -> None:
    out = decode_chunk(encode_chunk(data, {"lossless": True}))
    assert out.dtype == data.dtype and np.array_equal(out, data)


@pytest.mark.parametrize(
    ("config", "words"),
    [
        ({"max_error": 1, "psnr": 40}, "one target"),
        ({"max_error": -1}, "max_error"),
        ({"psnr": float("nan")}, "psnr"),
        ({"bpp": "much"}, "bpp"),
        ({"lossles": True}, "lossles"),
        ({"wavelet": "db4"}, "db4"),
        ({"level": 0}, "level"),
        ({"lossless": "yes"}, "lossless"),
    ],
)
def test_bad_configuration_is_named(config: dict[str, object], words: str) -> None:
    with pytest.raises(InvalidParameter, match=words):
        CodecConfig.from_mapping(config)


def test_bad_chunks_are_named() -> None:
    with pytest.raises(InvalidParameter, match="2-D or 3-D"):
        encode_chunk(np.zeros(10), {"max_error": 1})
    with pytest.raises(InvalidParameter, match="integer data"):
        encode_chunk(np.ones((4, 4)) * np.arange(4), {"lossless": True})
    with pytest.raises(InvalidParameter, match="dtype"):
        encode_chunk(np.zeros((4, 4), dtype=complex), {"max_error": 1})


def test_bad_bytes_are_a_bundle_error() -> None:
    good = encode_chunk(smooth_field((20, 20), seed=1), {"max_error": 0.01})
    for bad in (b"", b"nonsense", good[:-7], good[:30], b"WZC1" + b"\xff" * 40):
        with pytest.raises(BundleError):
            decode_chunk(bad)
    # settings that are not a mapping, and an ``out`` of another size, are named too
    with pytest.raises(InvalidParameter, match="must be a mapping"):
        encode_chunk(np.zeros((4, 4)), None)  # type: ignore[arg-type]
    with pytest.raises(InvalidParameter, match="out holds 56 bytes"):
        WavecoreCodec(max_error=0.1).decode(good, out=np.empty(7))
    # not a buffer at all: numpy's TypeError ("array of references") came out bare
    for thing in (None, [None], {"a": 1}, object()):
        with pytest.raises(BundleError, match="bytes or a buffer"):
            decode_chunk(thing)


# --------------------------------------------------------------------------------------------
# Golden chunks: the format stays readable
# --------------------------------------------------------------------------------------------


def golden_cases() -> list[dict[str, object]]:
    return json.loads((GOLDEN / "cases.json").read_text())["cases"]  # type: ignore[no-any-return]


def golden_source(case: dict[str, object]) -> np.ndarray:
    shape = tuple(case["shape"])  # type: ignore[arg-type]
    data = smooth_field(shape, seed=int(case["seed"]), dtype=str(case["dtype"]))  # type: ignore[call-overload]
    return data


@pytest.mark.parametrize("case", golden_cases(), ids=lambda c: str(c["file"]))
def test_golden_chunks_decode(case: dict[str, object]) -> None:
    """Chunks written by an earlier build decode to within their bound of the same source.

    The decoded bytes' digest is recorded too: a decoder change that alters any value (even
    within the bound) would leave arrays already stored in Zarr reading differently.
    """
    import hashlib

    coded = (GOLDEN / str(case["file"])).read_bytes()
    source = golden_source(case)
    out = decode_chunk(coded)
    assert out.shape == source.shape and out.dtype == source.dtype
    config = case["config"]
    assert isinstance(config, dict)
    if config.get("lossless"):
        assert np.array_equal(out, source)
    else:
        assert largest_error(out, source) <= float(config["max_error"])
    assert hashlib.sha256(out.tobytes()).hexdigest() == case["sha256"]


# --------------------------------------------------------------------------------------------
# numcodecs, zarr-python 3, xarray
# --------------------------------------------------------------------------------------------


def test_entry_points_are_declared() -> None:
    groups = {
        "numcodecs.codecs": "wavecore.zarr:WavecoreCodec",
        "zarr.codecs": "wavecore.zarr:WavecoreZarrCodec",
    }
    for group, value in groups.items():
        found = {ep.name: ep.value for ep in importlib.metadata.entry_points(group=group)}
        assert found.get("wavecore") == value


def test_numcodecs_finds_the_codec_by_id() -> None:
    codec = numcodecs.get_codec({"id": "wavecore", "max_error": 0.5, "wavelet": "haar"})
    assert isinstance(codec, WavecoreCodec)
    assert codec.get_config() == {"id": "wavecore", "wavelet": "haar", "max_error": 0.5}
    again = numcodecs.get_codec(codec.get_config())
    assert again.get_config() == codec.get_config()
    data = smooth_field((30, 41), seed=2)
    assert largest_error(codec.decode(codec.encode(data)), data) <= 0.5
    out = np.empty_like(data)
    codec.decode(codec.encode(data), out=out)
    assert largest_error(out, data) <= 0.5


def test_zarr3_serializer_with_partial_edge_chunks(tmp_path: Path) -> None:
    data = smooth_field((100, 70), seed=12)
    arr = zarr.create_array(
        tmp_path / "a.zarr",
        shape=data.shape,
        chunks=(32, 32),
        dtype="float32",
        serializer={"name": "wavecore", "configuration": {"max_error": 0.05}},
        compressors=None,
    )
    arr[:] = data
    again = zarr.open_array(tmp_path / "a.zarr", mode="r")
    codecs = json.loads((tmp_path / "a.zarr" / "zarr.json").read_text())["codecs"]
    assert codecs[0]["name"] == "wavecore"
    assert codecs[0]["configuration"]["max_error"] == 0.05
    assert largest_error(again[:], data) <= 0.05
    assert largest_error(again[90:, 60:], data[90:, 60:]) <= 0.05  # the corner chunk


def test_zarr3_codec_object_and_3d_integers(tmp_path: Path) -> None:
    data = np.clip(smooth_field((3, 40, 36), seed=13), -120, 120).astype(np.int16)
    arr = zarr.create_array(
        tmp_path / "b.zarr",
        shape=data.shape,
        chunks=(2, 16, 16),
        dtype="int16",
        serializer=WavecoreZarrCodec(lossless=True),
    )
    arr[:] = data
    assert np.array_equal(zarr.open_array(tmp_path / "b.zarr", mode="r")[:], data)


def test_zarr_format_2_compressor(tmp_path: Path) -> None:
    data = smooth_field((50, 45), seed=14, dtype="float64")
    arr = zarr.create_array(
        tmp_path / "v2.zarr",
        shape=data.shape,
        chunks=(20, 20),
        dtype="float64",
        zarr_format=2,
        compressors=numcodecs.get_codec({"id": "wavecore", "max_error": 0.01}),
        filters=None,
    )
    arr[:] = data
    meta = json.loads((tmp_path / "v2.zarr" / ".zarray").read_text())
    assert meta["compressor"]["id"] == "wavecore"
    assert largest_error(zarr.open_array(tmp_path / "v2.zarr", mode="r")[:], data) <= 0.01


@pytest.mark.parametrize("zarr_format", [2, 3])
def test_xarray_to_zarr_encoding(tmp_path: Path, zarr_format: int) -> None:
    xr = pytest.importorskip("xarray", reason="the zarr extra installs xarray")
    field = smooth_field((60, 50), seed=15)
    ds = xr.Dataset({"t": (("y", "x"), field)}, coords={"y": np.arange(60), "x": np.arange(50)})
    if zarr_format == 3:
        serializer = {"name": "wavecore", "configuration": {"max_error": 0.02}}
        encoding = {"t": {"serializer": serializer, "compressors": None, "chunks": (25, 25)}}
    else:
        codec = numcodecs.get_codec({"id": "wavecore", "max_error": 0.02})
        encoding = {"t": {"compressors": [codec], "chunks": (25, 25)}}
    store = tmp_path / f"ds{zarr_format}.zarr"
    ds.to_zarr(store, encoding=encoding, zarr_format=zarr_format, consolidated=False)
    back = xr.open_zarr(store, consolidated=False)
    assert largest_error(back["t"].values, field) <= 0.02


@pytest.mark.parametrize("missing", ["zarr", "numcodecs"])
def test_without_the_extra_the_error_names_it(missing: str) -> None:
    code = (
        "import sys\n"
        f"sys.modules[{missing!r}] = None\n"
        "import wavecore\n"
        "assert wavecore.decode\n"
        "try:\n"
        "    import wavecore.zarr\n"
        "except ModuleNotFoundError as exc:\n"
        "    print(exc)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert "pip install 'wavecore[zarr]'" in done.stdout
    assert missing in done.stdout


def test_max_error_chunks_are_grid_bundles_and_infinities_keep_the_search() -> None:
    field = np.sin(np.linspace(0, 6, 64))[:, None] * np.cos(np.linspace(0, 4, 48))
    big_endian = field.astype(">f4")
    coded = encode_chunk(big_endian, {"max_error": 1e-3})
    assert coded[4] == 3  # mode 3: wavecore.encode_grid
    out = decode_chunk(coded)
    assert out.dtype.kind == "f" and out.dtype.itemsize == 4
    assert np.max(np.abs(out.astype(np.float64) - big_endian)) <= 1e-3
    field[5, 7] = np.inf
    coded = encode_chunk(field, {"max_error": 1e-3})
    assert coded[4] == 0
    out = decode_chunk(coded)
    finite = np.isfinite(field)
    assert out[5, 7] == np.inf and np.max(np.abs(out[finite] - field[finite])) <= 1e-3


@pytest.mark.parametrize("shape", [(4096, 1, 1), (300, 3, 5), (17, 64, 64)])
@pytest.mark.parametrize("dtype", [np.float32, np.int16])
def test_a_chunk_of_small_slices_is_coded_whole_under_psnr_and_bpp(
    shape: tuple[int, int, int], dtype: type
) -> None:
    # A bundle a slice cost 7-25 ms and some 50 bytes whatever its size: a chunk of small
    # slices is one grid bundle (mode 3), its PSNR against the chunk's range, its bpp over it.
    rng = np.random.default_rng(11)
    chunk = (np.cumsum(rng.standard_normal(shape), axis=0) * 40).astype(dtype)
    span = float(chunk.max()) - float(chunk.min())
    for config in ({"psnr": 55}, {"bpp": 6.0}, {}):
        data = encode_chunk(chunk, config)
        assert data[4] == MODE_GRID, config
        out = decode_chunk(data)
        assert out.shape == chunk.shape and out.dtype == chunk.dtype
        mse = float(np.mean((out.astype(np.float64) - chunk) ** 2))
        if "bpp" in config:
            assert 8 * len(data) <= config["bpp"] * chunk.size + 8 * 64  # the chunk's header
        else:
            assert 10 * np.log10(span**2 / max(mse, 1e-300)) >= config.get("psnr", 60) - 1e-9
    # One slice, or larger ones, keep a bundle a slice.
    one = np.arange(12, dtype=dtype).reshape(1, 3, 4)
    assert encode_chunk(one, {"psnr": 55})[4] == MODE_WAVELET
    large = np.arange(2 * 65 * 65, dtype=dtype).reshape(2, 65, 65)
    assert encode_chunk(large, {"psnr": 55})[4] == MODE_WAVELET


def test_nan_cells_of_small_slices_stay_nan() -> None:
    chunk = np.cumsum(np.random.default_rng(12).standard_normal((500, 2, 2)), axis=0)
    chunk[7, 1, 0] = np.nan
    out = decode_chunk(encode_chunk(chunk, {"psnr": 50}))
    assert np.isnan(out[7, 1, 0]) and np.isnan(out).sum() == 1


def test_a_bpp_below_a_slices_smallest_bundle_names_a_bpp_that_codes() -> None:
    from wavecore.errors import BitrateTooLow

    chunk = np.random.default_rng(13).standard_normal((8, 8))
    with pytest.raises(BitrateTooLow, match="8 × 8 slice of this chunk") as caught:
        encode_chunk(chunk, {"bpp": 4.0})
    enough = 8 * caught.value.smallest_bytes / chunk.size
    assert f"bpp {enough:.4f}" in str(caught.value)
    assert decode_chunk(encode_chunk(chunk, {"bpp": enough})).shape == chunk.shape


def _header(mode: int, dtype: str, shape: tuple[int, ...]) -> bytes:
    import struct

    return (
        b"WZC1"
        + bytes([mode, len(dtype)])
        + dtype.encode()
        + struct.pack(f"<B{len(shape)}I", len(shape), *shape)
    )


def test_a_chunk_declaring_more_than_a_decoder_takes_is_refused_before_it_is_made() -> None:
    # 26 bytes asking for 2**29 float64 values (4 GiB) as a constant
    bomb = _header(2, "<f8", (2**28, 2)) + bytes(8)
    with pytest.raises(BundleError, match="more than 134217728"):
        decode_chunk(bomb)


def test_raw_values_are_inflated_no_further_than_the_shape_needs() -> None:
    import zlib

    # 1 value declared, 16 MiB of zeros compressed into 16 kB
    bomb = _header(1, "<u1", (1, 1)) + zlib.compress(bytes(2**24))
    with pytest.raises(BundleError, match=r"values inflates past its size limit \(1 bytes\)"):
        decode_chunk(bomb)
    short = _header(1, "<u2", (3, 4)) + zlib.compress(bytes(10))
    with pytest.raises(BundleError, match="inflate to other than 24 bytes"):
        decode_chunk(short)


def test_a_slice_bundle_of_another_shape_is_refused() -> None:
    data = smooth_field((2, 80, 70), seed=4).astype(np.float32)
    coded = encode_chunk(data, {"psnr": 50})
    assert coded[4] == MODE_WAVELET  # a bundle a slice
    # the same chunk relabelled as 2 slices of 70 × 80 (the same number of values)
    head = len(_header(0, "<f4", data.shape))
    relabelled = _header(MODE_WAVELET, "<f4", (2, 70, 80)) + coded[head:]
    with pytest.raises(BundleError, match="a slice's bundle has shape"):
        decode_chunk(relabelled)
    assert np.array_equal(decode_chunk(coded).shape, data.shape)


def test_chunks_beyond_what_a_decoder_takes_are_refused_on_encoding() -> None:
    too_big = np.broadcast_to(np.float32(1), (2**14, 2**13 + 1))  # 134 225 920 values
    with pytest.raises(InvalidParameter, match="use smaller chunks"):
        encode_chunk(too_big, {"lossless": True})
