"""Tests for the level-by-level entropy coders."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavecore import wavedec2
from wavecore.entropy import (
    CODERS,
    CONTEXT_VERSIONS,
    _encode_context,
    decode_levels,
    encode_levels,
)
from wavecore.errors import BundleError, InvalidParameter
from wavecore.quantize import quantize_bands


def _laplace_bands(seed: int, shape: tuple[int, ...] = (34, 34)) -> list[object]:
    """Quantized coefficients of a textured test picture (peaked, like real details)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[: shape[0], : shape[1]]
    image = 128 + 50 * np.sin(x / 5.0 + y / 9.0) + rng.laplace(0, 6, shape[:2])
    if len(shape) == 3:
        image = np.stack([image * (1 - 0.1 * c) for c in range(shape[2])], axis=-1)
    coeffs = wavedec2(image, "bspline2", "open", 2)
    q, _ = quantize_bands(coeffs, 2.0, wavelet="bspline2", boundary="open")
    return q


def _shapes(q: list[object]) -> list[object]:
    out: list[object] = [q[0].shape]  # type: ignore[attr-defined]
    for entry in q[1:]:
        if isinstance(entry, tuple):
            out.append(tuple(b.shape for b in entry))
        else:
            out.append(entry.shape)  # type: ignore[attr-defined]
    return out


def _assert_equal(a: list[object], b: list[object]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        if isinstance(x, tuple):
            assert isinstance(y, tuple)
            for u, v in zip(x, y, strict=True):
                np.testing.assert_array_equal(u, v)
                assert v.dtype == np.int32
        else:
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("coder", CODERS)
@pytest.mark.parametrize("shape", [(34, 34), (34, 18, 3)])
def test_round_trip_and_prefix(coder: str, shape: tuple[int, ...]) -> None:
    q = _laplace_bands(1, shape)
    chunks, params = encode_levels(q, coder=coder)
    assert len(chunks) == len(q)
    shapes = _shapes(q)
    _assert_equal(decode_levels(chunks, shapes, params), q)
    _assert_equal(decode_levels(chunks[:2], shapes, params), q[:2])


@pytest.mark.parametrize("coder", CODERS)
def test_one_dimensional_layout(coder: str) -> None:
    rng = np.random.default_rng(2)
    q = [rng.integers(-50, 50, (6, 2), dtype=np.int32), rng.integers(-3, 4, (4, 2), dtype=np.int32)]
    chunks, params = encode_levels(q, coder=coder)
    back = decode_levels(chunks, [(6, 2), (4, 2)], params)
    assert isinstance(back[1], np.ndarray)
    _assert_equal(back, q)


@pytest.mark.parametrize("coder", CODERS)
def test_large_and_empty_values(coder: str) -> None:
    """Lossless coefficients reach about 2**20; all-zero bands are common."""
    rng = np.random.default_rng(4)
    big = rng.integers(-(2**21), 2**21, (6, 6), dtype=np.int32)
    q = [big, (np.zeros((4, 6), np.int32), np.zeros((6, 4), np.int32), np.zeros((4, 4), np.int32))]
    chunks, params = encode_levels(q, coder=coder)
    _assert_equal(decode_levels(chunks, _shapes(q), params), q)


def test_context_coder_beats_zlib() -> None:
    q = _laplace_bands(5, (130, 130))
    zlib_size = sum(map(len, encode_levels(q, coder="zlib")[0]))
    context_size = sum(map(len, encode_levels(q, coder="context")[0]))
    assert context_size <= zlib_size


def test_bad_arguments() -> None:
    with pytest.raises(InvalidParameter, match="coder"):
        encode_levels([np.zeros((2, 2), np.int32)], coder="gzip")
    with pytest.raises(InvalidParameter, match="integers"):
        encode_levels([np.zeros((2, 2))])


@pytest.mark.parametrize("coder", CODERS)
def test_corrupt_chunks_raise_bundle_error(coder: str) -> None:
    q = _laplace_bands(6)
    chunks, params = encode_levels(q, coder=coder)
    shapes = _shapes(q)
    rng = np.random.default_rng(7)
    for trial in range(60):
        broken = list(chunks)
        index = trial % len(broken)
        data = bytearray(broken[index])
        if trial % 3 == 0:
            data = data[: rng.integers(0, len(data))]
        elif len(data):
            data[rng.integers(0, len(data))] ^= int(rng.integers(1, 256))
        broken[index] = bytes(data)
        try:
            back = decode_levels(broken, shapes, params)
        except BundleError:
            continue
        # A flip the coder cannot see still has to give arrays of the declared shapes.
        assert back[0].shape == q[0].shape  # type: ignore[attr-defined]


def test_bad_shapes_and_params() -> None:
    q = _laplace_bands(8)
    chunks, params = encode_levels(q, coder="zlib")
    with pytest.raises(BundleError):
        decode_levels(chunks, _shapes(q)[:1], params)
    with pytest.raises(BundleError):
        decode_levels(chunks, [(2**40, 2**40)], params)
    with pytest.raises(BundleError):
        decode_levels(chunks, _shapes(q), {"coder": "nope"})
    with pytest.raises(BundleError):
        decode_levels(chunks[:1], [(-1, 3)], params)
    bomb = zlib.compress(bytes(10**6))
    with pytest.raises(BundleError):
        decode_levels([bomb], [(4, 4)], params)


@settings(max_examples=40, deadline=None)
@given(data=st.binary(max_size=200), coder=st.sampled_from(CODERS))
def test_arbitrary_bytes_never_escape(data: bytes, coder: str) -> None:
    q = _laplace_bands(9)
    _, params = encode_levels(q, coder=coder)
    try:
        back = decode_levels([data], _shapes(q), params)
    except BundleError:
        return
    assert back[0].shape == q[0].shape  # type: ignore[attr-defined]


def test_context_coder_is_deterministic() -> None:
    q = _laplace_bands(10, (66, 66, 3))
    first, params = encode_levels(q)
    second, _ = encode_levels(q)
    assert first == second
    assert params["coder"] == "context"


def test_aligned_signs_cost_less_than_random_signs() -> None:
    """Signs that repeat along rows (a texture) are predicted from the neighbours' signs."""
    rng = np.random.default_rng(12)
    magnitude = rng.integers(1, 4, (64, 66))
    rows = np.where(np.arange(64) % 2 == 0, 1, -1)[:, None]
    aligned = (magnitude * rows).astype(np.int32)
    scrambled = (magnitude * rng.choice([-1, 1], magnitude.shape)).astype(np.int32)
    sizes = []
    for band in (aligned, scrambled):
        q = [np.zeros((66, 66), np.int32), (band, np.zeros((66, 64), np.int32), band[:, :64])]
        sizes.append(sum(map(len, encode_levels(q)[0])))
    assert sizes[0] < 0.9 * sizes[1]


def _sparse_bands(seed: int, shape: tuple[int, int], count: int) -> list[np.ndarray]:
    """Two levels whose detail planes hold ``count`` nonzero values each, the rest zero."""
    rng = np.random.default_rng(seed)

    def band(rows: int, cols: int) -> np.ndarray:
        out = np.zeros((rows, cols), np.int32)
        out.flat[rng.choice(rows * cols, min(count, rows * cols), replace=False)] = rng.choice(
            [-40, -3, -1, 1, 2, 25], min(count, rows * cols)
        )
        return out

    rows, cols = shape
    small = (rows // 2 + 1, cols // 2 + 1)
    return [
        rng.integers(-9, 9, small, dtype=np.int32),
        (band(*small), band(*small), band(*small)),
        (band(rows, cols), band(rows, cols + 1), band(rows + 1, cols)),
    ]


@pytest.mark.parametrize("shape", [(37, 29), (8, 8), (9, 1), (1, 17), (64, 40)])
@pytest.mark.parametrize("count", [0, 1, 5, 10_000])
def test_every_context_version_round_trips_sparse_planes(
    shape: tuple[int, int], count: int
) -> None:
    """Tiles cut planes that are not multiples of the tile size; empty and full planes too."""
    q = _sparse_bands(count + shape[0], shape, count)
    for version in CONTEXT_VERSIONS:
        entries = [[q[0]], list(q[1]), list(q[2])]
        chunks, params = _encode_context(entries, version)
        assert params["version"] == version
        _assert_equal(decode_levels(chunks, _shapes(q), params), q)


def test_tile_flags_make_sparse_details_cheaper() -> None:
    """Version 3 says "all zero" once per 8 × 8 tile instead of once per coefficient."""
    q = _sparse_bands(3, (256, 256), 20)
    entries = [[q[0]], list(q[1]), list(q[2])]
    old = sum(map(len, _encode_context(entries, 2)[0]))
    new = sum(map(len, _encode_context(entries, 3)[0]))
    assert new < old


def test_unknown_context_versions_are_refused() -> None:
    q = _laplace_bands(13)
    chunks, params = encode_levels(q)
    # 5 is the lossless coder's (wavecore.losslesscoder, encode_image(effort="max")); 6 the
    # block coder with the parent band, 7 with orientation too, 8 with priors by level.
    for version in (1, 9, "3", None):
        with pytest.raises(BundleError, match="version"):
            decode_levels(chunks, _shapes(q), {**params, "version": version})


@pytest.mark.slow
@settings(max_examples=10_000, deadline=None)
@given(
    chunks=st.lists(st.binary(max_size=120), min_size=1, max_size=3),
    two_d=st.booleans(),
    version=st.sampled_from(CONTEXT_VERSIONS),
)
def test_context_decoder_fuzz(chunks: list[bytes], two_d: bool, version: int) -> None:
    """Any bytes either decode to arrays of the declared shapes or raise BundleError."""
    shapes: list[object] = [(6, 6, 3), ((4, 6, 3), (6, 4, 3), (4, 4, 3)), ((8, 10, 3),) * 3]
    if not two_d:
        shapes = [(6, 2), (4, 2), (8, 2)]
    params = {"coder": "context", "version": version, "two_d": two_d, "block": 64}
    try:
        back = decode_levels(chunks, shapes, params)
    except BundleError:
        return
    assert len(back) == len(chunks)
    assert back[0].shape == shapes[0]


def test_activity_bins_are_exact_at_every_edge() -> None:
    """The binning's float look-up is corrected by integer comparisons, even on the edges."""
    from wavecore.entropy import _EDGES_AT_MOST, _EDGES_MILLI, _bin

    rng = np.random.default_rng(14)
    pairs = list(zip(rng.integers(0, 10**12, 3000), rng.integers(1, 10**9, 3000), strict=True))
    for d in (1, 3, 7, 999_983, 10**9 + 7):  # exactly on each edge, and one unit either side
        for edge in _EDGES_MILLI:
            pairs += [(edge * d + delta, 1000 * d) for delta in (-1, 0, 1) if edge * d + delta >= 0]
    for num, den in pairs:
        expected = sum(1000 * int(num) > int(e) * int(den) for e in _EDGES_MILLI)
        assert _bin(np.int64(num), np.int64(den), _EDGES_MILLI, _EDGES_AT_MOST) == expected


@pytest.mark.parametrize("coder", CODERS)
def test_int32_range_is_checked_for_wider_integers_only(coder: str) -> None:
    """int32 extremes (and narrower dtypes) are coded; int64 or uint32 values past int32's
    range are refused, whatever the dtype's width lets through the skipped check."""
    extremes = np.array([[-(2**31), 2**31 - 1], [0, 5]], dtype=np.int32)
    chunks, params = encode_levels([extremes], coder=coder)
    assert np.array_equal(decode_levels(chunks, [(2, 2)], params)[0], extremes)
    narrow = np.array([[-128, 127], [0, 3]], dtype=np.int8)
    chunks, params = encode_levels([narrow], coder=coder)
    assert np.array_equal(decode_levels(chunks, [(2, 2)], params)[0], narrow)
    for wide in (
        np.array([[2**31, 0], [0, 0]], dtype=np.int64),
        np.array([[-(2**31) - 1, 0], [0, 0]], dtype=np.int64),
        np.array([[2**31, 0], [0, 0]], dtype=np.uint32),
    ):
        with pytest.raises(InvalidParameter, match="int32"):
            encode_levels([wide], coder=coder)
