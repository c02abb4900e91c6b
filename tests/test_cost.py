"""Cost in proportion to size: bounded levels, hostile shapes, memory that grows linearly.

Nothing here measures wall-clock time against a threshold (the machine is shared): refusals are
checked by the memory they allocate, and linearity by how peak memory grows with the size.
"""

from __future__ import annotations

import contextlib
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidLength, InvalidParameter, WavecoreError


def _peak_bytes(call: Callable[[], Any]) -> tuple[int, Any]:
    """Peak traced allocation of ``call()`` (NumPy reports its buffers to tracemalloc)."""
    tracemalloc.start()
    try:
        result = call()
    except WavecoreError as exc:
        result = exc
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return peak, result


CURVE = np.cumsum(np.random.default_rng(0).standard_normal((100, 2)), axis=0)

ABSURD_LEVELS = [
    ("transfer_details", lambda lvl: wavecore.transfer_details(CURVE, CURVE[:10], level=lvl)),
    ("decompose_curve", lambda lvl: wavecore.decompose_curve(CURVE, lvl)),
    ("fitting_length", lambda lvl: wavecore.fitting_length(100, lvl)),
    ("valid_length", lambda lvl: wavecore.valid_length(100, lvl)),
    ("wavedec", lambda lvl: wavecore.wavedec(np.zeros(100), level=lvl)),
    ("wavedec2", lambda lvl: wavecore.wavedec2(np.zeros((34, 34)), level=lvl)),
    ("wavedecn", lambda lvl: wavecore.wavedecn(np.zeros((34, 18, 10)), level=lvl)),
    ("basis_norms", lambda lvl: wavecore.basis_norms(34, level=lvl)),
    ("pad_to_fit", lambda lvl: wavecore.pad_to_fit(np.zeros((20, 3)), lvl, axes=0)),
    ("fit_grid", lambda lvl: wavecore.fit_grid(np.zeros((20, 20)), lvl, axes=(0, 1))),
    (
        "fit_grid resample",
        lambda lvl: wavecore.fit_grid(np.zeros((20, 20)), lvl, axes=(0, 1), method="resample"),
    ),
    ("decompose_image", lambda lvl: wavecore.decompose_image(np.zeros((20, 30)), lvl)),
    ("decompose_surface", lambda lvl: wavecore.decompose_surface(np.zeros((20, 30, 3)), lvl)),
    ("coarse_extent", lambda lvl: wavecore.coarse_extent(20, (0, 6), lvl)),
]
# Cropping a level-30 approximation of a 2**34-sample signal is a cheap view; 100 is absurd.
BEYOND_ANY_LENGTH = [
    (
        "crop_padding",
        lambda lvl: wavecore.crop_padding(np.zeros(20), ((0, 6),), axes=0, level=lvl),
    ),
]


@pytest.mark.parametrize(
    ("name", "call", "level"),
    [(name, call, level) for name, call in ABSURD_LEVELS for level in (30, 100, 10**15)]
    + [(name, call, level) for name, call in BEYOND_ANY_LENGTH for level in (100, 10**15)],
    ids=lambda value: str(value) if not callable(value) else "",
)
def test_absurd_levels_are_refused_before_any_work(
    name: str, call: Callable[[int], Any], level: int
) -> None:
    peak, result = _peak_bytes(lambda: call(level))
    assert isinstance(result, InvalidParameter | InvalidLength), (name, result)
    message = str(result)
    assert f"level {level}" in message
    # The largest accepted level is named, and it is small.
    assert any(f"{word} {k}" in message for k in range(0, 40) for word in ("is", "most"))
    assert peak < 256 << 10, f"{name} allocated {peak} bytes before refusing level {level}"


def test_the_largest_accepted_level_is_accepted() -> None:
    # The message's "largest accepted level" is the real bound: one more is refused, it is not.
    with pytest.raises(InvalidParameter, match="largest accepted level is 6"):
        wavecore.transfer_details(CURVE, CURVE[:10], level=7)
    assert wavecore.transfer_details(CURVE, CURVE[:10], level=6).shape == CURVE.shape
    with pytest.raises(InvalidParameter, match="largest accepted level is 5"):
        wavecore.pad_to_fit(np.zeros(20), 6, axes=0)
    padded, _ = wavecore.pad_to_fit(np.zeros(20), 5, axes=0)
    assert len(padded) <= 2 * 20 + 64


def test_dense_matrices_are_refused_beyond_their_bound() -> None:
    peak, result = _peak_bytes(lambda: wavecore.matrices(10**6))
    assert isinstance(result, InvalidParameter) and "at most 2048, not 1000000" in str(result)
    assert peak < 256 << 10
    assert wavecore.matrices(2048, boundary="closed")[0].shape == (1024, 2048)


def test_a_pywavelets_style_positional_level_names_boundary() -> None:
    x = np.zeros(34)
    with pytest.raises(InvalidParameter, match=r"boundary=.*not 3.*level=3"):
        wavecore.wavedec(x, "bspline2", 3)
    with pytest.raises(InvalidParameter, match=r"boundary=.*level=2"):
        wavecore.wavedec2(np.zeros((34, 34)), "haar", 2)
    with pytest.raises(InvalidParameter, match="boundary="):
        wavecore.waverec(wavecore.wavedec(x), "bspline2", None)  # type: ignore[arg-type]
    with pytest.raises(InvalidParameter, match="boundary="):
        wavecore.wavedecn(np.zeros((34, 34)), "bspline2", ("open", 3))  # type: ignore[arg-type]


def test_length_errors_name_the_helpers_that_fit_any_size() -> None:
    with pytest.raises(InvalidLength) as info:
        wavecore.wavedec(np.zeros(35), level=2)
    message = str(info.value)
    for helper in ("decompose_image", "decompose_curve", "pad_to_fit", "fitting_length"):
        assert helper in message
    assert "valid_length" in message and "34 and 38" in message


HOSTILE = [
    ("image 1×N", lambda n: wavecore.encode_image(np.arange(n, dtype=np.uint8)[None, :])),
    ("image N×1", lambda n: wavecore.encode_image(np.arange(n, dtype=np.uint8)[:, None])),
    ("image 1×N bpp", lambda n: wavecore.encode_image(np.ones((1, n), np.uint8), bpp=1.0)),
    ("image 1×N keep", lambda n: wavecore.encode_image(np.ones((1, n), np.uint8), keep=0.3)),
    ("image N×2 rgb", lambda n: wavecore.encode_image(np.ones((n, 2, 3), np.uint8))),
    (
        "decode keep",
        lambda n: wavecore.decode(
            wavecore.encode_image(np.arange(n, dtype=np.uint8)[None, :]), keep=0.5
        ),
    ),
    ("curve", lambda n: wavecore.encode_curve(np.cumsum(np.ones((n, 2)), axis=0))),
    ("curve tolerance", lambda n: wavecore.encode_curve(np.ones((n, 3)), tolerance=1e-3)),
    ("curve 1-D", lambda n: wavecore.encode_curve(np.sin(np.arange(n)), closed=True)),
    ("decompose_curve", lambda n: wavecore.decompose_curve(np.ones((n, 2))).reconstruct(0.5)),
    ("resample_curve", lambda n: wavecore.resample_curve(np.ones((n, 2)), n + 3)),
    (
        "transfer_details",
        lambda n: wavecore.transfer_details(np.cumsum(np.ones((n, 3)), axis=0), np.eye(3)),
    ),
    ("remove_smallest", lambda n: wavecore.remove_smallest([np.ones(n), np.ones(n)], 0.5)),
    ("surface thin", lambda n: wavecore.encode_surface(np.ones((n, 2, 3)))),
    ("decompose_surface", lambda n: wavecore.decompose_surface(np.ones((2, n)))),
    ("decompose_image", lambda n: wavecore.decompose_image(np.ones((n, 1))).reconstruct(0.2)),
    ("wavedec max", lambda n: wavecore.wavedec(np.ones(n))),
    ("wavedec2 thin", lambda n: wavecore.wavedec2(np.ones((n, 8)))),
    ("grid of 1 × 1 slices bpp", lambda n: wavecore.encode_grid(np.ones((n, 1, 1)), bpp=2.0)),
    (
        "grid of 1 × 2 slices rmse",
        lambda n: wavecore.decode(
            wavecore.encode_grid(np.ones((n, 1, 2)), wavelet="cdf97", rmse=0.01),
            region=(slice(0, n), slice(0, 1), slice(1, 2)),
        ),
    ),
]


@pytest.mark.parametrize("n", [1, 2, 3, 9, 67, 1025])
@pytest.mark.parametrize(("name", "call"), HOSTILE, ids=[n for n, _ in HOSTILE])
def test_hostile_shapes_succeed_or_raise_a_library_error(
    name: str, call: Callable[[int], Any], n: int
) -> None:
    # A clear refusal is fine; MemoryError, TypeError or ValueError are not.
    with contextlib.suppress(WavecoreError):
        call(n)


@pytest.mark.parametrize(
    ("name", "call"),
    [
        ("encode_image 1×N", lambda n: wavecore.encode_image(np.ones((1, n), np.uint8))),
        (
            "encode_curve",
            lambda n: wavecore.encode_curve(
                np.cumsum(np.random.default_rng(1).standard_normal((n, 2)), axis=0)
            ),
        ),
        ("basis_norms", lambda n: wavecore.basis_norms(wavecore.valid_length(n, 4), level=4)),
        (
            "remove_smallest",
            lambda n: wavecore.remove_smallest(
                wavecore.wavedec(np.random.default_rng(2).random(wavecore.valid_length(n, 3))),
                0.5,
            ),
        ),
    ],
)
def test_peak_memory_grows_linearly(name: str, call: Callable[[int], Any]) -> None:
    # 16 times the samples may cost at most about 16 times the memory (20× allows for the
    # fixed part); the old impulse norms took 256 × n floats, the old matrices n log n.
    for n in (1024, 16 * 1024):
        call(n)  # compile, and fill the (small) caches as a second call finds them
    small, _ = _peak_bytes(lambda: call(1024))
    large, _ = _peak_bytes(lambda: call(16 * 1024))
    assert large <= 20 * max(small, 1), (name, small, large)


def test_a_curve_of_many_dimensions_encodes_in_memory_linear_in_its_values() -> None:
    # The block coder sized its tile flags and its output room by the nominal 1-D block (16 384
    # coefficients) for every dimension, however short the curve: 140 MB for these 0.5 MB.
    curve = np.cumsum(np.random.default_rng(5).standard_normal((16, 4096)), axis=0)
    wavecore.encode_curve(curve)  # compile, and fill the (small) caches
    peak, bundle = _peak_bytes(lambda: wavecore.encode_curve(curve))
    assert isinstance(bundle, bytes)
    assert peak < 40 * curve.nbytes, peak
    peak, out = _peak_bytes(lambda: wavecore.decode(bundle))
    assert out.shape == curve.shape
    assert peak < 40 * curve.nbytes, peak
