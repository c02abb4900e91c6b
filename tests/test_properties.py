"""Perfect reconstruction as properties: wavelet × boundary × dtype × length × level × axis × shape.

The bound is on the relative error ``max|x' - x| / max|x|``: 1e-12 when the work is done in
float64 (float64 and integer input) and 1e-5 in float32.  The default run keeps the example count
modest; ``-m slow`` runs the same properties with many more examples.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore.filters import get_wavelet
from wavecore.transform import work_dtype

WAVELETS = ["bspline2", "haar"]
BOUNDARIES = ["open", "closed"]
DTYPES = [np.float64, np.float32, np.int16, np.uint8, np.int64]
TRAILING = [(), (1,), (2,), (3,), (2, 3)]

FAST = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
MANY = settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def tolerance(dtype: Any) -> float:
    return 1e-5 if work_dtype(np.dtype(dtype)) == np.float32 else 1e-12


def make_data(seed: int, shape: tuple[int, ...], dtype: Any) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        return (rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 4)).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(max(info.min, -30000), min(info.max, 30000), shape, endpoint=True).astype(
        dtype
    )


def relative_error(rebuilt: np.ndarray, data: np.ndarray) -> float:
    data = data.astype(np.float64)
    scale = float(np.max(np.abs(data))) or 1.0
    return float(np.max(np.abs(rebuilt.astype(np.float64) - data))) / scale


@st.composite
def lengths(draw: st.DrawFn, wavelet: str, boundary: str, level: int) -> int:
    rule = get_wavelet(wavelet).rule(boundary)
    k = draw(st.integers(rule.smallest_k(level), rule.smallest_k(level) + 6))
    return (1 << level) * k + rule.extra


@st.composite
def one_axis_cases(draw: st.DrawFn) -> tuple[Any, ...]:
    wavelet = draw(st.sampled_from(WAVELETS))
    boundary = draw(st.sampled_from(BOUNDARIES))
    level = draw(st.integers(0, 4))
    n = draw(lengths(wavelet, boundary, level))
    trailing = draw(st.sampled_from(TRAILING))
    axis = draw(st.integers(0, len(trailing)))
    shape = (*trailing[:axis], n, *trailing[axis:])
    if draw(st.booleans()):
        axis -= len(shape)  # negative axes name the same axis
    dtype = draw(st.sampled_from(DTYPES))
    return wavelet, boundary, level, shape, axis, dtype, draw(st.integers(0, 2**32 - 1))


def check_one_axis(case: tuple[Any, ...]) -> None:
    wavelet, boundary, level, shape, axis, dtype, seed = case
    data = make_data(seed, shape, dtype)
    coeffs = wavecore.wavedec(data, wavelet, boundary, level, axis)
    assert len(coeffs) == level + 1
    assert all(c.dtype == work_dtype(data.dtype) for c in coeffs)
    rebuilt = wavecore.waverec(coeffs, wavelet, boundary, axis)
    assert rebuilt.shape == data.shape
    assert rebuilt.dtype == work_dtype(data.dtype)
    assert relative_error(rebuilt, data) <= tolerance(dtype)


@st.composite
def two_axis_cases(draw: st.DrawFn) -> tuple[Any, ...]:
    wavelet = draw(st.sampled_from(WAVELETS))
    boundaries = (draw(st.sampled_from(BOUNDARIES)), draw(st.sampled_from(BOUNDARIES)))
    level = draw(st.integers(0, 3))
    sizes = [draw(lengths(wavelet, b, level)) for b in boundaries]
    trailing = draw(st.sampled_from(TRAILING[:4]))
    ndim = 2 + len(trailing)
    # Where the two axes go, and in which order: the fused pass (last two axes, in order) and
    # the per-axis path (any other layout) must both reconstruct.
    positions = draw(st.permutations(range(ndim)))[:2]
    shape = [0] * ndim
    rest = iter(trailing)
    for i in range(ndim):
        shape[i] = sizes[positions.index(i)] if i in positions else next(rest)
    dtype = draw(st.sampled_from(DTYPES))
    seed = draw(st.integers(0, 2**32 - 1))
    return wavelet, boundaries, level, tuple(shape), tuple(positions), dtype, seed


def check_two_axes(case: tuple[Any, ...]) -> None:
    wavelet, boundaries, level, shape, axes, dtype, seed = case
    data = make_data(seed, shape, dtype)
    coeffs = wavecore.wavedec2(data, wavelet, boundaries, level, axes)
    rebuilt = wavecore.waverec2(coeffs, wavelet, boundaries, axes)
    assert rebuilt.shape == data.shape
    assert rebuilt.dtype == work_dtype(data.dtype)
    assert relative_error(rebuilt, data) <= tolerance(dtype)
    # The n-D functions are the same transform.
    coeffs_n = wavecore.wavedecn(data, wavelet, boundaries, level, axes)
    np.testing.assert_array_equal(coeffs_n[0], coeffs[0])
    for bands, bands_n in zip(coeffs[1:], coeffs_n[1:], strict=True):
        for band, key in zip(bands, ("da", "ad", "dd"), strict=True):
            np.testing.assert_array_equal(band, bands_n[key])


@FAST
@given(one_axis_cases())
def test_wavedec_waverec_reconstruct(case: tuple[Any, ...]) -> None:
    check_one_axis(case)


@FAST
@given(two_axis_cases())
def test_wavedec2_waverec2_reconstruct(case: tuple[Any, ...]) -> None:
    check_two_axes(case)


@FAST
@given(
    wavelet=st.sampled_from(WAVELETS),
    boundaries=st.tuples(*[st.sampled_from(BOUNDARIES)] * 3),
    level=st.integers(0, 2),
    dtype=st.sampled_from([np.float64, np.float32]),
    channels=st.integers(1, 3),
    seed=st.integers(0, 2**32 - 1),
)
def test_wavedecn_three_axes_reconstruct(
    wavelet: str, boundaries: tuple[str, str, str], level: int, dtype: Any, channels: int, seed: int
) -> None:
    shape = tuple(
        wavecore.valid_length(1, level, b, wavelet) + 2**level * (seed >> (4 * i) & 3)
        for i, b in enumerate(boundaries)
    )
    data = make_data(seed, (*shape, channels), dtype)
    coeffs = wavecore.wavedecn(data, wavelet, boundaries, level, axes=(0, 1, 2))
    rebuilt = wavecore.waverecn(coeffs, wavelet, boundaries, axes=(0, 1, 2))
    assert rebuilt.dtype == data.dtype
    assert relative_error(rebuilt, data) <= tolerance(dtype)


@FAST
@given(two_axis_cases())
def test_fused_level_equals_one_step_per_axis(case: tuple[Any, ...]) -> None:
    # One level of wavedec2 against analysis_step applied axis by axis, and back.
    wavelet, boundaries, _, shape, axes, dtype, seed = case
    bank = get_wavelet(wavelet)
    assume(all(bank.rule(b).fits(shape[a], 1) for a, b in zip(axes, boundaries, strict=True)))
    data = make_data(seed, shape, dtype)
    coarse, (ch, cv, cd) = wavecore.wavedec2(data, wavelet, boundaries, 1, axes)
    low, high = wavecore.analysis_step(data, wavelet, boundaries[0], axes[0])
    aa, ad = wavecore.analysis_step(low, wavelet, boundaries[1], axes[1])
    da, dd = wavecore.analysis_step(high, wavelet, boundaries[1], axes[1])
    atol = tolerance(dtype) * max(1.0, float(np.max(np.abs(data.astype(float)))))
    for ours, ref in ((coarse, aa), (ch, da), (cv, ad), (cd, dd)):
        assert ours.shape == ref.shape
        np.testing.assert_allclose(ours, ref, rtol=0, atol=atol)
    rebuilt = wavecore.synthesis_step(
        wavecore.synthesis_step(aa, ad, wavelet, boundaries[1], axes[1]),
        wavecore.synthesis_step(da, dd, wavelet, boundaries[1], axes[1]),
        wavelet,
        boundaries[0],
        axes[0],
    )
    np.testing.assert_allclose(
        wavecore.waverec2([coarse, (ch, cv, cd)], wavelet, boundaries, axes),
        rebuilt,
        rtol=0,
        atol=atol,
    )


@pytest.mark.slow
@MANY
@given(one_axis_cases())
def test_wavedec_waverec_reconstruct_many(case: tuple[Any, ...]) -> None:
    check_one_axis(case)


@pytest.mark.slow
@MANY
@given(two_axis_cases())
def test_wavedec2_waverec2_reconstruct_many(case: tuple[Any, ...]) -> None:
    check_two_axes(case)
