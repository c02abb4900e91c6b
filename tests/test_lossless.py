"""Lossless coding: the reversible integer transforms, and encode_image(..., lossless=True)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import wavecore
from wavecore import lossless
from wavecore.colour import rct_forward, rct_inverse, ycbcr_forward, ycbcr_inverse

int_arrays = hnp.arrays(
    np.int64,
    hnp.array_shapes(min_dims=1, max_dims=3, min_side=1, max_side=19),
    elements=st.integers(-(2**20), 2**20),
)


# No deadline: the liftings are compiled kernels, and the first call of a process loads numba.
@settings(deadline=None)
@given(int_arrays, st.sampled_from(lossless.FILTERS))
def test_one_lift_is_exactly_reversible(x: np.ndarray, name: str) -> None:
    if name == "bspline2" and x.shape[0] % 2:
        with pytest.raises(wavecore.InvalidParameter, match="even length"):
            lossless.lift(x, 0, name)
        return
    coarse, detail = lossless.lift(x, 0, name)
    assert coarse.shape[0] == (x.shape[0] + 1) // 2
    assert detail.shape[0] == x.shape[0] // 2
    assert np.array_equal(lossless.unlift(coarse, detail, 0, name), x)


@settings(max_examples=60)
@given(
    hnp.arrays(
        np.int64,
        st.tuples(st.integers(1, 40), st.integers(1, 40), st.integers(1, 4)),
        elements=st.integers(-(2**17), 2**17),
    ),
    st.lists(st.sampled_from(lossless.FILTERS), min_size=0, max_size=4),
)
def test_multilevel_round_trip_and_prefixes(image: np.ndarray, filters: list[str]) -> None:
    level = len(filters)
    sizes = list(image.shape[:2])
    for index, name in enumerate(filters):  # the closed bspline2 needs even sizes
        if name == "bspline2" and any(n % 2 for n in sizes):
            filters[index] = "legall53"
        sizes = [(n + 1) // 2 for n in sizes]
    coeffs = lossless.forward(image, level, (0, 1), filters)
    shapes = [coeffs[0].shape, *(tuple(b.shape for b in bands) for bands in coeffs[1:])]
    assert shapes == lossless.band_shapes(image.shape, level)
    assert all(c.dtype == np.int32 for c in [coeffs[0], *(b for bs in coeffs[1:] for b in bs)])
    assert np.array_equal(lossless.inverse(coeffs, (0, 1), filters), image)
    for k in range(level + 1):
        coarse = lossless.inverse(coeffs[: level - k + 1], (0, 1), filters)
        side = [-(-n // 2**k) for n in image.shape[:2]]
        assert list(coarse.shape[:2]) == side


def test_one_axis_layout_is_wavedec() -> None:
    x = np.random.default_rng(0).integers(-500, 500, (37, 2))
    coeffs = lossless.forward(x, 3, (0,))
    assert [c.shape for c in coeffs] == lossless.band_shapes(x.shape, 3, (0,))
    assert np.array_equal(lossless.inverse(coeffs, (0,)), x)


def test_low_pass_has_unit_gain() -> None:
    """The coarse band is a thumbnail in the image's own units (decode(level=k) relies on it)."""
    flat = np.full((20, 20), 200)
    assert np.all(lossless.forward(flat, 2)[0] == 200)


def test_integer_haar_zeroes_the_details_of_a_pixel_repeated_image() -> None:
    small = np.random.default_rng(1).integers(0, 256, (12, 9))
    big = np.kron(small, np.ones((2, 2), dtype=int))
    coeffs = lossless.forward(big, 1, (0, 1), ["haar"])
    assert all(not np.any(band) for band in coeffs[1])
    assert lossless.choose_filters(big, 2)[0] == "haar"
    assert lossless.choose_filters(big, 2, candidates=("legall53", "haar")) == ["haar", "legall53"]


@settings(deadline=None)  # the first closed-boundary transform of a size compiles
@given(
    hnp.arrays(
        np.int64,
        st.tuples(st.integers(1, 12).map(lambda k: 2 * k), st.integers(1, 3)),
        elements=st.integers(-(2**16), 2**16),
    )
)
def test_integer_bspline2_is_the_papers_closed_transform_within_one(x: np.ndarray) -> None:
    coarse, detail = lossless.lift(x, 0, "bspline2")
    exact = wavecore.wavedec(x.astype(float), "bspline2", "closed", level=1)
    assert np.max(np.abs(coarse - exact[0])) <= 1.0
    assert np.max(np.abs(detail - exact[1])) <= 1.0
    assert np.array_equal(lossless.unlift(coarse, detail, 0, "bspline2"), x)


@pytest.mark.parametrize("m", [8, 10, 12, 18, 34])
def test_open_bspline2_has_determinant_two_so_no_integer_bijection(m: int) -> None:
    """Why lossless does not use the paper's open rows (see wavecore.lossless)."""
    A, B, _, _ = wavecore.matrices(m)
    assert abs(np.linalg.det(np.vstack([A, B]))) == pytest.approx(2.0)
    A, B, _, _ = wavecore.matrices(m, "bspline2", "closed")
    assert abs(np.linalg.det(np.vstack([A, B]))) == pytest.approx(1.0)


def test_filters_are_checked() -> None:
    with pytest.raises(wavecore.InvalidParameter, match="filters must name one of"):
        lossless.forward(np.zeros((4, 4), int), 1, (0, 1), ["cdf97"])
    with pytest.raises(wavecore.InvalidParameter, match="integer data"):
        lossless.forward(np.zeros((4, 4)), 1)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_rct_is_exact_at_the_extremes(dtype: type) -> None:
    top = np.iinfo(dtype).max
    values = np.array([0, 1, top - 1, top], dtype=dtype)
    grid = np.stack(np.meshgrid(values, values, values, values, indexing="ij"), -1)
    rgba = grid.reshape(-1, 4)
    assert np.array_equal(rct_inverse(rct_forward(rgba)), rgba)


def test_ycbcr_puts_grey_into_luma_only() -> None:
    grey = np.linspace(0, 255, 30)[:, None].repeat(3, axis=1)
    ycc = ycbcr_forward(grey)
    assert np.allclose(ycc[:, 0], grey[:, 0]) and np.allclose(ycc[:, 1:], 0)
    assert np.allclose(ycbcr_inverse(ycc), grey)
    with pytest.raises(wavecore.InvalidParameter, match="at least 3 channels"):
        ycbcr_forward(np.zeros((4, 2)))


# --- through the codec -----------------------------------------------------------------------

SHAPES = [(1, 1), (1, 7), (5, 1), (13, 10), (64, 48), (13, 10, 1), (9, 11, 2), (17, 6, 3)]


@pytest.mark.parametrize("shape", [*SHAPES, (33, 20, 4)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_lossless_is_bit_exact(shape: tuple[int, ...], dtype: type) -> None:
    rng = np.random.default_rng(sum(shape))
    image = rng.integers(0, np.iinfo(dtype).max, shape, endpoint=True).astype(dtype)
    bundle = wavecore.encode_image(image, lossless=True)
    out = wavecore.decode(bundle)
    assert out.dtype == image.dtype and out.shape == image.shape
    assert np.array_equal(out, image)
    info = wavecore.inspect(bundle)
    assert info["lossless"] and info["psnr"] is None and info["max_error"] == 0


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_lossless_extremes_and_smooth_data(dtype: type) -> None:
    top = np.iinfo(dtype).max
    checker = (np.indices((40, 30)).sum(axis=0) % 2 * top).astype(dtype)
    ramp = np.linspace(0, top, 40 * 30 * 3).reshape(40, 30, 3).astype(dtype)
    for image in (checker, ramp, np.zeros((40, 30), dtype), np.full((40, 30, 4), top, dtype)):
        assert np.array_equal(wavecore.decode(wavecore.encode_image(image, lossless=True)), image)


def test_lossless_coarse_levels_are_thumbnails() -> None:
    image = np.random.default_rng(2).integers(0, 256, (45, 70, 3), dtype=np.uint8)
    bundle = wavecore.encode_image(image, lossless=True, level=3)
    for k in range(4):
        coarse = wavecore.decode(bundle, level=k)
        assert coarse.shape == (-(-45 // 2**k), -(-70 // 2**k), 3)
        assert coarse.dtype == np.uint8
    flat = np.full((45, 70), 77, np.uint8)
    assert np.all(wavecore.decode(wavecore.encode_image(flat, lossless=True), level=2) == 77)
    # effort="max" coded without levels (the picture predicted): the thumbnail is lifted after
    # decoding
    whole = wavecore.encode_image(image, lossless=True, level=0, effort="max")
    for k in range(4):
        assert np.array_equal(wavecore.decode(whole, level=k), lossless.coarser(image, k))
    assert wavecore.decode(whole, level=2, region=(slice(1, 4), slice(2, 9))).shape == (3, 7, 3)
    # the block coder's bundles keep their levels' limit
    plain = wavecore.encode_image(image, lossless=True, level=0, effort="fast")
    with pytest.raises(wavecore.InvalidParameter, match="deeper than the bundle's 0 levels"):
        wavecore.decode(plain, level=1)


def test_lossless_keep_at_decode_time_is_lossy_but_close() -> None:
    x = np.linspace(0, 200, 64)
    image = (np.add.outer(x, x) / 2 + np.random.default_rng(3).normal(0, 4, (64, 64))).clip(0, 255)
    image = image.astype(np.uint8)
    bundle = wavecore.encode_image(image, lossless=True)
    smooth = wavecore.decode(bundle, keep=0.2)
    assert smooth.shape == image.shape and not np.array_equal(smooth, image)
    error = np.abs(smooth.astype(float) - image).mean()
    assert 0 < error < 10


def test_lossless_levels_leave_no_empty_subband() -> None:
    with pytest.raises(wavecore.InvalidParameter, match="at most 0 levels"):
        wavecore.encode_image(np.zeros((1, 7), np.uint8), lossless=True, level=3)
    image = np.arange(21, dtype=np.uint8).reshape(3, 7)
    assert np.array_equal(
        wavecore.decode(wavecore.encode_image(image, lossless=True, level=1)), image
    )


def _fast_two_d(bundle: bytes) -> bool:
    from wavecore.bundle import read_bundle

    return bool(read_bundle(bundle).header["cparams"]["two_d"])


@pytest.mark.parametrize("shape", [(1, 3000), (1, 3000, 3), (2, 1500), (40, 70), (3000, 1)])
def test_fast_lossless_of_no_levels_codes_rows_and_columns(
    shape: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    # A picture the block coder codes with no levels (one row or column: no level fits; or
    # level=0) is coded as 2-D.  Taken as 1-D, a 1 × N picture was N planes of one value each:
    # some 8 µs a pixel to code, against some 0.1 µs, and bigger.  A single column keeps the
    # 1-D layout (one plane: the column in long blocks), and the old bundles keep decoding.
    rng = np.random.default_rng(7)
    image = (rng.integers(0, 9, shape).cumsum(axis=1) % 256).astype(np.uint8)
    level = 0 if min(shape[:2]) > 1 else None
    bundle = wavecore.encode_image(image, lossless=True, level=level, effort="fast")
    assert wavecore.inspect(bundle)["levels"] == 0
    assert _fast_two_d(bundle) is (shape[1] > 1)
    assert np.array_equal(wavecore.decode(bundle), image)
    window = (slice(0, min(2, shape[0])), slice(shape[1] // 3, shape[1] // 3 + 40))
    assert np.array_equal(wavecore.decode_region(bundle, window), image[window])
    assert wavecore.decode(bundle, keep=0.5).shape == image.shape

    import wavecore.codec.reversible as reversible

    old_form = reversible.encode_levels

    def as_before(coeffs: list, **kwargs: object) -> object:
        kwargs.pop("two_d")  # the layout alone decides: 1-D for a decomposition of no levels
        return old_form(coeffs, **kwargs)

    monkeypatch.setattr(reversible, "encode_levels", as_before)
    before = wavecore.encode_image(image, lossless=True, level=level, effort="fast")
    assert _fast_two_d(before) is False
    assert np.array_equal(wavecore.decode(before), image)
    assert np.array_equal(wavecore.decode_region(before, window), image[window])
    if shape[0] == 1:
        assert len(bundle) < len(before)


@pytest.mark.parametrize("shape", [(1, 3000), (40, 70, 3), (3000, 1)])
@pytest.mark.parametrize("target", [{}, {"bpp": 2.0}])
def test_lossy_pictures_of_no_levels_code_rows_and_columns(
    shape: tuple[int, ...], target: dict[str, float], monkeypatch: pytest.MonkeyPatch
) -> None:
    # The lossy encoder's bundles of level=0 follow the same rule as the block coder's lossless
    # ones above (the plan's ``coded_two_d``), and code these pictures better than as 1-D.
    from wavecore.codec.plan import Plan

    rng = np.random.default_rng(8)
    image = (rng.integers(0, 9, shape).cumsum(axis=1) % 256).astype(np.uint8)
    bundle = wavecore.encode_image(image, level=0, **target)
    assert _fast_two_d(bundle) is (shape[1] > 1)
    whole = wavecore.decode(bundle)
    assert whole.shape == image.shape and whole.dtype == np.uint8
    window = (slice(0, min(3, shape[0])), slice(0, min(50, shape[1])))
    assert np.array_equal(wavecore.decode_region(bundle, window), whole[window])

    monkeypatch.setattr(Plan, "coded_two_d", property(lambda plan: plan.levels > 0))
    before = wavecore.encode_image(image, level=0, **target)
    assert _fast_two_d(before) is False
    assert np.array_equal(wavecore.decode_region(before, window), wavecore.decode(before)[window])
    if shape[1] > 1 and target:
        assert wavecore.inspect(bundle)["psnr"] > wavecore.inspect(before)["psnr"]
    elif shape[1] > 1:
        assert len(bundle) < len(before)
    else:
        assert bundle == before


def test_encode_levels_two_d_must_fit_the_layout() -> None:
    from wavecore.entropy import decode_levels, encode_levels

    picture = np.arange(60, dtype=np.int32).reshape(1, 60) % 7
    chunks, params = encode_levels([picture], two_d=True)
    assert params["two_d"] is True
    assert np.array_equal(decode_levels(chunks, [(1, 60)], params)[0], picture)
    curve = [np.zeros(8, np.int32), np.ones(8, np.int32)]
    with pytest.raises(wavecore.InvalidParameter, match="does not fit a layout"):
        encode_levels(curve, two_d=True)
    with pytest.raises(wavecore.InvalidParameter, match="does not fit a layout"):
        encode_levels([picture], two_d="yes")  # type: ignore[arg-type]


def test_lossless_refuses_floats_and_rate_targets() -> None:
    with pytest.raises(wavecore.InvalidParameter, match="uint8, uint16"):
        wavecore.encode_image(np.zeros((8, 8)), lossless=True)
    with pytest.raises(wavecore.InvalidParameter, match="cannot be combined"):
        wavecore.encode_image(np.zeros((8, 8), np.uint8), lossless=True, quality=30)


def _png_size(image: np.ndarray) -> int:
    pil = pytest.importorskip("PIL.Image", reason="Pillow compares lossless sizes")
    buffer = io.BytesIO()
    pil.fromarray(image).save(buffer, format="PNG", optimize=True)
    return len(buffer.getvalue())


@pytest.mark.parametrize("name", ["camera", "moon", "coins", "brick", "astronaut"])
def test_lossless_is_smaller_than_png(name: str) -> None:
    data = pytest.importorskip("skimage.data", reason="scikit-image ships the test images")
    image = getattr(data, name)()
    bundle = wavecore.encode_image(image, lossless=True)
    assert np.array_equal(wavecore.decode(bundle), image)
    assert len(bundle) < _png_size(image)


def _smooth_textured(shape: tuple[int, ...], seed: int) -> np.ndarray:
    """A smooth surface with a little noise: the kind of picture 5/11-C codes best."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    surface = 120 + 60 * np.sin(rows / 9.0) * np.cos(cols / 13.0) + rng.normal(0, 2, shape[:2])
    if len(shape) == 3:
        surface = surface[..., None] + np.arange(shape[2]) * 10
    return np.clip(surface, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape", [(70, 91), (64, 57, 3)])
def test_5_11_c_lifting_decodes_exactly_whole_and_by_region(shape: tuple[int, ...]) -> None:
    image = _smooth_textured(shape, 3)
    bundle = wavecore.encode_image(image, lossless=True, level=3)
    lifting = wavecore.inspect(bundle)["header"]["lifting"]
    assert "511c" in lifting  # the curvature correction pays on a smooth picture
    assert np.array_equal(wavecore.decode(bundle), image)
    for rows, cols in [(slice(0, 9), slice(50, 57)), (slice(31, 46), slice(3, 4))]:
        region = wavecore.decode_region(bundle, (rows, cols))
        assert np.array_equal(region, image[rows, cols])


def _chroma_correlated(seed: int) -> np.ndarray:
    """RGB whose blue and red differences from green move together (as in photographs)."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:48, 0:40]
    green = 100 + 40 * np.sin(rows / 5.0) + rng.normal(0, 3, rows.shape)
    chroma = 30 * np.cos(cols / 4.0) * np.sin(rows / 7.0) + rng.normal(0, 2, rows.shape)
    rgb = np.stack([green + chroma, green, green + chroma / 2], axis=-1)
    return np.clip(rgb, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("weight", [w for w in lossless.CHROMA_WEIGHTS if w])
def test_chroma_prediction_is_reversible_at_every_weight(weight: int) -> None:
    ycc = np.random.default_rng(weight + 8).integers(-70000, 70000, (9, 7, 4))
    predicted = lossless.predict_chroma(ycc, weight)
    assert np.array_equal(predicted[..., :2], ycc[..., :2])  # only Cr changes
    assert np.array_equal(lossless.unpredict_chroma(predicted, weight), ycc)


def test_chroma_prediction_is_chosen_recorded_and_decoded_exactly() -> None:
    image = _chroma_correlated(4)
    bundle = wavecore.encode_image(image, lossless=True)
    info = wavecore.inspect(bundle)
    # Cr = (R - G) is twice Cb = (B - G) here, so the weight is 16 eighths, clipped to 8.
    assert info["colour"] == "rct-p8"
    assert np.array_equal(wavecore.decode(bundle), image)
    region = wavecore.decode_region(bundle, (slice(9, 30), slice(17, 40)))
    assert np.array_equal(region, image[9:30, 17:40])
    plain = np.dstack([image[..., 1]] * 3)  # grey as RGB: no chroma to predict
    assert wavecore.inspect(wavecore.encode_image(plain, lossless=True))["colour"] == "rct"


def test_a_predicted_colour_packs_compactly_and_round_trips() -> None:
    from wavecore import binheader

    header = wavecore.inspect(wavecore.encode_image(_chroma_correlated(5), lossless=True))["header"]
    plain = binheader.pack({**header, "colour": "rct"})
    for weight in (-8, -1, 1, 8):
        packed = binheader.pack({**header, "colour": f"rct-p{weight}"})
        assert len(packed) == len(plain) + 1  # one varint byte, no extension
        assert binheader.unpack(packed)["colour"] == f"rct-p{weight}"


def test_a_colour_weight_out_of_range_is_refused_by_name() -> None:
    from wavecore import binheader

    bundle = wavecore.encode_image(_chroma_correlated(6), lossless=True)
    header = wavecore.inspect(bundle)["header"]
    # "rct-p0" is spelt "rct", and its code is the per-picture colour matrix's ("klt:<m>"):
    # the binary header cannot even hold it.
    with pytest.raises(wavecore.BundleError, match="colour"):
        binheader.pack({**header, "colour": "rct-p0"})
    for weight in (9, -9, 100):  # the weights stop at ±8
        packed = binheader.pack({**header, "colour": f"rct-p{weight}"})
        assert binheader.unpack(packed)["colour"] == f"rct-p{weight}"
        with pytest.raises(wavecore.BundleError, match="colour"):
            wavecore.bundle.check_header(binheader.unpack(packed))


@pytest.mark.parametrize("effort", ["default", "max", "fast"])
def test_every_effort_is_exact_whole_by_region_and_by_level(effort: str) -> None:
    rng = np.random.default_rng(11)
    for image in (
        rng.integers(0, 256, (50, 37, 3), dtype=np.uint8),
        rng.integers(0, 65536, (33, 46), dtype=np.uint16),
    ):
        bundle = wavecore.encode_image(image, lossless=True, effort=effort)
        assert np.array_equal(wavecore.decode(bundle), image)
        region = (slice(7, 29), slice(3, 31))
        assert np.array_equal(wavecore.decode(bundle, region=region), image[region])
        half = tuple(-(-n // 2) for n in image.shape[:2])
        assert wavecore.decode(bundle, level=1).shape == half + image.shape[2:]


def test_default_and_max_are_the_lossless_coder_and_fast_the_block_coder() -> None:
    image = np.random.default_rng(12).integers(0, 256, (40, 44), dtype=np.uint8)
    plain = wavecore.encode_image(image, lossless=True)
    assert wavecore.encode_image(image, lossless=True, effort="max") == plain
    assert wavecore.encode_image(image, lossless=True, effort="default") == plain
    info = wavecore.inspect(plain)
    assert info["header"]["cparams"]["version"] == 5 and info["levels"] in (0, 1)
    fast = wavecore.inspect(wavecore.encode_image(image, lossless=True, effort="fast"))
    assert fast["header"]["cparams"].get("version") == 4 and "block" in fast["header"]["cparams"]


@pytest.mark.parametrize("effort", ["hard", "MAX", "Fast", "", None, 2])
def test_an_unknown_effort_is_refused_by_name(effort: object) -> None:
    with pytest.raises(
        wavecore.InvalidParameter, match=r"effort must be one of 'default', 'max', 'fast'"
    ):
        wavecore.encode_image(np.zeros((8, 8), np.uint8), lossless=True, effort=effort)  # type: ignore[arg-type]


def test_max_effort_needs_lossless() -> None:
    image = np.zeros((8, 8), np.uint8)
    with pytest.raises(wavecore.InvalidParameter, match=r"effort='max' applies only with lossless"):
        wavecore.encode_image(image, effort="max")
    with pytest.raises(wavecore.InvalidParameter, match=r"effort='max' applies only with lossless"):
        wavecore.encode_image(image, quality=30, effort="max")
    with pytest.raises(
        wavecore.InvalidParameter, match=r"effort='fast' applies only with lossless"
    ):
        wavecore.encode_image(image, bpp=1.0, effort="fast")
    assert wavecore.decode(wavecore.encode_image(image, effort="default")).shape == (8, 8)


def test_a_level_too_deep_for_a_lossless_coder_bundle_names_the_deepest() -> None:
    image = np.random.default_rng(13).integers(0, 256, (64, 48), dtype=np.uint8)
    bundle = wavecore.encode_image(image, lossless=True)
    assert wavecore.decode(bundle, level=5).shape == (2, 2)
    with pytest.raises(wavecore.InvalidParameter, match=r"deeper than 5, the most this picture"):
        wavecore.decode(bundle, level=6)
