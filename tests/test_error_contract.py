"""Issue 10's library cases: every input gives a result or an error from ``wavecore.errors``.

- huge and tiny finite floats round-trip within the requested target (the scaled domain);
- float images near the top of their dtype's range no longer break the PSNR;
- big-endian, strided, Fortran-ordered and read-only arrays give the native results;
- encoders raise ``InvalidParameter`` for bad input, never ``BundleError``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import wavecore
from wavecore import BundleError, InvalidParameter, decode, inspect
from wavecore.bundle import read_bundle


def _psnr(decoded: np.ndarray, original: np.ndarray) -> float:
    """PSNR against the data range, computed independently of the codec (in scaled units)."""
    top = float(np.max(np.abs(original)))
    a, b = decoded / top, original / top  # both exact to rescale: the codec's own trick aside
    span = float(b.max() - b.min()) or 1.0
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(span * span / mse)


# --- huge and tiny floats ---------------------------------------------------------------------

MAGNITUDES = [1e155, 1e300, -1e308, 1.7976931348623157e308, 1e-300, 1e-310, 5e-324 * 7]


def _field(magnitude: float, shape: tuple[int, ...]) -> np.ndarray:
    rng = np.random.default_rng(3)
    if abs(magnitude) < 1e-307:  # subnormals: small integer multiples of the smallest float
        return rng.integers(-9, 10, shape) * abs(magnitude) / 7 * 7
    u = np.linspace(0, 3, shape[0])[:, None] + np.linspace(0, 2, shape[1])[None, :]
    smooth = np.sin(u) if len(shape) == 2 else np.sin(u)[..., None] * [1.0, 0.5]
    return (smooth * 0.9 + rng.uniform(-0.05, 0.05, shape)) * magnitude


@pytest.mark.parametrize("magnitude", MAGNITUDES)
def test_surfaces_of_any_finite_magnitude_meet_their_quality(magnitude: float) -> None:
    grid = _field(magnitude, (20, 17))
    bundle = wavecore.encode_surface(grid, quality=40)
    out = decode(bundle)
    assert out.dtype == np.float64 and np.all(np.isfinite(out))
    assert _psnr(out, grid) >= 40 - 1e-9
    info = inspect(bundle)
    assert info["scale"] != 0 and info["version"] == "3.1"  # 1.2 in the JSON header of 1.x
    assert info["max_error"] >= np.max(np.abs(out - grid)) * (1 - 1e-12)


@pytest.mark.parametrize("magnitude", MAGNITUDES)
def test_images_of_any_finite_magnitude_meet_their_quality(magnitude: float) -> None:
    image = _field(magnitude, (24, 19))
    for quality in (30, 55):
        out = decode(wavecore.encode_image(image, quality=quality))
        assert np.all(np.isfinite(out)) and _psnr(out, image) >= quality - 1e-9


@pytest.mark.parametrize("magnitude", MAGNITUDES)
def test_curves_of_any_finite_magnitude_meet_their_tolerance(magnitude: float) -> None:
    points = _field(magnitude, (40, 2))
    relative_diagonal = float(np.hypot(*(np.ptp(points / abs(magnitude), axis=0))))
    # (subnormals: at least a few of the smallest floats, which decoding rounds to)
    tolerance = max(relative_diagonal / 500 * abs(magnitude), 2e-322)
    out = decode(wavecore.encode_curve(points, tolerance=tolerance))
    scale = abs(magnitude)
    deviation = np.max(np.hypot(*((out - points) / scale).T)) * scale
    assert np.all(np.isfinite(out)) and deviation <= tolerance
    # The default tolerance (relative to the diagonal) works at any magnitude too.
    assert np.all(np.isfinite(decode(wavecore.encode_curve(points))))


def test_ordinary_data_is_not_scaled() -> None:
    grid = _field(1e6, (12, 12))
    header = read_bundle(wavecore.encode_surface(grid)).header
    assert "scale" not in header and inspect(wavecore.encode_surface(grid))["version"] == "3.1"


def test_a_scaled_bundle_with_keep_and_coarse_levels_decodes() -> None:
    grid = _field(1e300, (36, 36))
    bundle = wavecore.encode_surface(grid, keep=0.3, level=2)
    assert np.all(np.isfinite(decode(bundle, keep=0.5)))
    coarse = decode(bundle, drop_levels=2)
    assert np.array_equal(coarse, decode(bundle, level=2)) and np.all(np.isfinite(coarse))


def test_a_longdouble_beyond_float64_is_refused_naming_the_value() -> None:
    if np.finfo(np.longdouble).max <= np.finfo(np.float64).max:
        pytest.skip("this platform's longdouble is float64")
    grid = np.full((8, 8), np.longdouble("1e400"))
    with pytest.raises(InvalidParameter, match=r"1e\+400.*float64"):
        wavecore.encode_surface(grid)


@pytest.mark.parametrize("dtype", [np.float32, np.float16])
@pytest.mark.parametrize("keep", [None, 0.5])
def test_floats_near_their_dtypes_largest_value_give_a_finite_psnr(dtype: Any, keep: Any) -> None:
    """Issue 10: a float32 image near ±1e30 made ``math domain error`` in the PSNR."""
    top = 1e30 if dtype == np.float32 else 6e4
    rng = np.random.default_rng(5)
    for image in (
        (rng.random((16, 16)) * 2 * top - top).astype(dtype),
        np.full((16, 16), top, dtype),
        np.where(rng.random((16, 16)) > 0.5, top, -top).astype(dtype),
        np.where(rng.random((16, 16)) > 0.5, 1, -1).astype(dtype) * np.finfo(dtype).max,
    ):
        bundle = wavecore.encode_image(image, keep=keep)
        out = decode(bundle)
        assert out.dtype == dtype and np.all(np.isfinite(out))
        psnr = inspect(bundle)["psnr"]
        assert psnr is None or math.isfinite(psnr)


# --- byte order, strides, read-only -----------------------------------------------------------

BASE = np.random.default_rng(0).random((34, 18)) * 100


def _variants() -> list[tuple[str, np.ndarray]]:
    strided = np.zeros((34, 36))
    strided[:, ::2] = BASE
    readonly = BASE.copy()
    readonly.flags.writeable = False
    big_readonly = BASE.astype(">f8")
    big_readonly.flags.writeable = False
    return [
        *[(dtype, BASE.astype(dtype)) for dtype in (">f8", ">f4", ">i2", ">u2", ">i4", ">u4")],
        ("strided", strided[:, ::2]),
        ("fortran", np.asfortranarray(BASE)),
        ("read-only", readonly),
        ("read-only >f8", big_readonly),
    ]


def _arrays(result: Any) -> list[np.ndarray]:
    if isinstance(result, bytes):
        return [np.asarray(decode(result))]
    if isinstance(result, np.ndarray):
        return [result]
    if isinstance(result, dict):
        return [a for key in sorted(result) for a in _arrays(result[key])]
    if isinstance(result, list | tuple):
        return [a for item in result for a in _arrays(item)]
    if hasattr(result, "reconstruct"):
        return [np.asarray(result.reconstruct())]
    return [np.asarray(result)]


ENTRY_POINTS: dict[str, Callable[[np.ndarray], Any]] = {
    "encode_image": lambda x: wavecore.encode_image(x, quality=30),
    "encode_image lossless": lambda x: wavecore.encode_image(
        x if x.dtype.name in ("uint8", "uint16") else np.abs(x).astype(np.uint16), lossless=True
    ),
    "encode_curve": lambda x: wavecore.encode_curve(x[:, :3], tolerance=0.5),
    "encode_surface": lambda x: wavecore.encode_surface(x, quality=30),
    "decompose_image": wavecore.decompose_image,
    "decompose_curve": lambda x: wavecore.decompose_curve(x, 2),
    "decompose_surface": wavecore.decompose_surface,
    "wavedec": lambda x: wavecore.wavedec(x, "bspline2", "open", 2, axis=0),
    "wavedec2": lambda x: wavecore.wavedec2(x, "bspline2", "open", 1),
    "wavedecn": lambda x: wavecore.wavedecn(x, "bspline2", "open", 1),
    "waverec2": lambda x: wavecore.waverec2(
        [x[:17, :9], (x[:17, :9], x[1:18, :9], x[2:19, :9])], "haar", "closed"
    ),
    "waverec": lambda x: wavecore.waverec([x[:17], x[1:18]], "haar", "closed", axis=0),
    "remove_smallest": lambda x: wavecore.remove_smallest(
        [x[:17, :9], (x[:17, :9], x[1:18, :9], x[2:19, :9])], 0.5, wavelet="haar", boundary="closed"
    ),
    "analysis_step": lambda x: wavecore.analysis_step(x, "bspline2", "open"),
    "pad_to_fit": lambda x: wavecore.pad_to_fit(x, 2, axes=(0, 1)),
    "resample_curve": lambda x: wavecore.resample_curve(x, 20),
    "resample_grid": lambda x: wavecore.resample_grid(x, (20, 20), axes=(0, 1)),
    "transfer_details": lambda x: wavecore.transfer_details(x, x[::-1] * 0.5, level=2),
}


ENCODER_VARIANTS = {">f8", ">i2", ">u2", "strided", "read-only >f8"}
#: Functions documented to return the caller's own dtype (byte order included).
KEEPS_THE_DTYPE = {"pad_to_fit"}


@pytest.mark.parametrize("entry", sorted(ENTRY_POINTS))
def test_every_entry_point_takes_any_byte_order_and_layout(entry: str) -> None:
    """Issue 10: a big-endian ``>f8`` array (an uploaded .npy) made numba raise TypingError."""
    function = ENTRY_POINTS[entry]
    for name, variant in _variants():
        if entry.startswith("encode") and name not in ENCODER_VARIANTS:
            continue  # each dtype compiles the codec's loops again: the three suffice
        native = np.ascontiguousarray(variant).astype(variant.dtype.newbyteorder("="))
        got, expected = _arrays(function(variant)), _arrays(function(native))
        assert len(got) == len(expected), name
        for a, b in zip(got, expected, strict=True):
            # Bit-identical, except for summation order on other memory layouts.
            assert np.allclose(a, b, rtol=1e-12, atol=1e-12), (entry, name)
            assert a.dtype.isnative or entry in KEEPS_THE_DTYPE, (entry, name)


# --- encoders never raise BundleError ---------------------------------------------------------


def test_an_encoder_turns_a_bundle_limit_into_invalid_parameter(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Whatever the bundle writer refuses is the input's fault when an encoder wrote it."""
    from wavecore.codec import fixedstep, ratecontrol, reversible

    def refuse(header: dict[str, Any], chunks: Any) -> bytes:
        raise BundleError("header is 70000 bytes, more than MAX_HEADER_SIZE")

    # Lossy bundles are written by the rate control, lossless ones by their own pipeline,
    # and surfaces at a fixed step by theirs.
    for writer in (ratecontrol, reversible, fixedstep):
        monkeypatch.setattr(writer, "write_bundle", refuse)
    for encode in (
        lambda: wavecore.encode_image(BASE, quality=30),
        lambda: wavecore.encode_image(BASE.astype(np.uint8), lossless=True),
        lambda: wavecore.encode_curve(BASE),
        lambda: wavecore.encode_surface(BASE, keep=0.5),
    ):
        with pytest.raises(InvalidParameter, match=r"cannot be stored in a bundle.*MAX_HEADER"):
            encode()


ODD_INPUTS: list[Any] = [
    np.zeros((1, 1)),
    np.zeros((1, 700)),
    np.full((9, 9), 5e-324),
    np.full((9, 9), -1.7976931348623157e308),
    np.array([[1e-300, 1e300], [0.0, -1e300]]),
    np.eye(7) * 1e-320,
    np.full((3, 3), 2**62, dtype=np.int64),
    np.array([[np.iinfo(np.int64).min, np.iinfo(np.int64).max]] * 8),
    np.array([[0, np.iinfo(np.uint32).max]] * 8, dtype=np.uint32),
]


@pytest.mark.parametrize("index", range(len(ODD_INPUTS)))
def test_odd_inputs_encode_or_raise_invalid_parameter(index: int) -> None:
    data = ODD_INPUTS[index]
    encoders = [
        lambda: wavecore.encode_image(data),
        lambda: wavecore.encode_image(data, keep=0.3),
        lambda: wavecore.encode_image(data, bpp=2.0),
        lambda: wavecore.encode_surface(data),
        lambda: wavecore.encode_curve(data),
        lambda: wavecore.encode_curve(data, keep=0.5),
    ]
    for encode in encoders:
        try:
            bundle = encode()
        except BundleError as exc:  # pragma: no cover - what this test guards against
            pytest.fail(f"an encoder raised BundleError: {exc}")
        except InvalidParameter:
            continue
        out = decode(bundle)
        assert out.shape == data.shape and out.dtype == data.dtype
        if data.dtype.kind == "f":
            assert np.all(np.isfinite(out))


# --- the transform API: hostile arguments are InvalidParameter, named, and cost nothing -------

RAGGED = [[1.0, 2.0], [3.0]]
API_CASES: list[tuple[str, Callable[[], Any], str]] = [
    ("basis_norms_nd of no axes", lambda: wavecore.basis_norms_nd(()), "at least one axis"),
    ("basis_norms_nd of a number", lambda: wavecore.basis_norms_nd(5), "sequence of lengths"),
    ("basis_norms_nd of 2**40 × 8", lambda: wavecore.basis_norms_nd((2**40, 8)), "values"),
    ("basis_norms of 10**12", lambda: wavecore.basis_norms(10**12), "values"),
    ("basis_norms of a word", lambda: wavecore.basis_norms("many"), "n must be a length"),
    (
        "resample_curve to 2**63 points",
        lambda: wavecore.resample_curve(np.zeros((5, 2)), 2**63),
        "values",
    ),
    (
        "resample_grid to 10**12 samples",
        lambda: wavecore.resample_grid(np.zeros(5), (10**12,), axes=0),
        "values",
    ),
    (
        "resample_grid of an empty axis",
        lambda: wavecore.resample_grid(np.zeros((0, 5)), (5,), axes=0),
        "no samples",
    ),
    ("synthesis_adjoint of words", lambda: wavecore.synthesis_adjoint(["a", "b"]), "numeric"),
    ("synthesis_adjoint of ragged", lambda: wavecore.synthesis_adjoint(RAGGED), "numeric"),
    (
        "synthesis_step_adjoint of objects",
        lambda: wavecore.synthesis_step_adjoint(np.array([object()] * 8)),
        "numeric",
    ),
    ("pad_to_fit of ragged", lambda: wavecore.pad_to_fit(RAGGED, 1, axes=(0, 1)), "numeric"),
    ("fit_grid of ragged", lambda: wavecore.fit_grid(RAGGED, 1, axes=(0, 1)), "numeric"),
    ("decompose_image of ragged", lambda: wavecore.decompose_image(RAGGED), "the image"),
    (
        "subband_mosaic of words",
        lambda: wavecore.subband_mosaic(["a", ("b", "c", "d")]),
        "coarse band",
    ),
    ("wavedec2 with axes=None", lambda: wavecore.wavedec2(np.zeros((16, 16)), axes=None), "two"),
    ("wavedec2 with axes=0", lambda: wavecore.wavedec2(np.zeros((16, 16)), axes=0), "two axes"),
    (
        "waverec2 with axes=0",
        lambda: wavecore.waverec2(wavecore.wavedec2(np.zeros((16, 16))), axes=0),
        "two axes",
    ),
    (
        "synthesis_adjoint with axes=None",
        lambda: wavecore.synthesis_adjoint(np.zeros(16), axes=None),
        "axes",
    ),
]


@pytest.mark.parametrize(("name", "call", "message"), API_CASES, ids=[c[0] for c in API_CASES])
def test_hostile_transform_arguments_are_named_invalid_parameters(
    name: str, call: Callable[[], Any], message: str
) -> None:
    """Each of these raised a raw ValueError, TypeError, IndexError, OverflowError or
    MemoryError (terabytes asked for), or tried to allocate them."""
    with pytest.raises(InvalidParameter, match=message):
        call()
