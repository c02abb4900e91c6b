"""Re-sampling curves and padding grids to the lengths the transform accepts."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import InvalidParameter


def _random_curve(rng: np.random.Generator, m: int, d: int = 2) -> np.ndarray:
    return np.cumsum(rng.standard_normal((m, d)), axis=0)


def _steps(points: np.ndarray, closed: bool) -> np.ndarray:
    nodes = np.concatenate([points, points[:1]]) if closed else points
    return np.linalg.norm(np.diff(nodes, axis=0), axis=1)


@given(m=st.integers(2, 60), n=st.integers(2, 200), d=st.integers(2, 4), seed=st.integers(0, 99))
@settings(max_examples=60, deadline=None)
def test_open_resampling_keeps_end_points_and_count(m: int, n: int, d: int, seed: int) -> None:
    points = _random_curve(np.random.default_rng(seed), m, d)
    out = wavecore.resample_curve(points, n)
    assert out.shape == (n, d)
    assert np.array_equal(out[0], points[0])
    assert np.array_equal(out[-1], points[-1])


@given(m=st.integers(3, 60), n=st.integers(2, 200), seed=st.integers(0, 99))
@settings(max_examples=60, deadline=None)
def test_closed_resampling_stays_closed_without_a_seam_point(m: int, n: int, seed: int) -> None:
    points = _random_curve(np.random.default_rng(seed), m)
    out = wavecore.resample_curve(points, n, closed=True)
    assert out.shape == (n, 2)
    assert np.array_equal(out[0], points[0])
    assert not np.allclose(out[-1], out[0])  # the seam is not written out twice
    # Uniform by arc length on the closed polygon: every chord, the one across the seam
    # included, is at most one n-th of the perimeter.
    perimeter = _steps(points, closed=True).sum()
    assert np.all(_steps(out, closed=True) <= perimeter / n * (1 + 1e-9))


def test_closed_curve_with_a_written_out_seam_is_the_same_curve() -> None:
    rng = np.random.default_rng(3)
    points = _random_curve(rng, 20)
    with_seam = np.concatenate([points, points[:1]])
    assert np.allclose(
        wavecore.resample_curve(points, 32, closed=True),
        wavecore.resample_curve(with_seam, 32, closed=True),
    )


@given(
    m=st.integers(2, 40),
    n=st.integers(2, 120),
    direction=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
    step=st.floats(0.01, 10),
)
@settings(max_examples=60, deadline=None)
def test_uniform_points_on_a_line_are_resampled_exactly(
    m: int, n: int, direction: list[float], step: float
) -> None:
    d = np.asarray(direction)
    if np.linalg.norm(d) < 1e-3:
        d = np.array([1.0, 0.0, 0.0])
    origin = np.array([1.0, -2.0, 0.5])
    line = origin + step * np.arange(m)[:, None] * d
    out = wavecore.resample_curve(line, n)
    expected = origin + step * (m - 1) * np.linspace(0, 1, n)[:, None] * d
    assert np.allclose(out, expected, rtol=1e-12, atol=1e-9 * step * m * np.linalg.norm(d))
    # The same count gives the same points back.
    assert np.allclose(wavecore.resample_curve(line, m), line, rtol=1e-12, atol=1e-9 * step * m)


def test_time_series_is_resampled_in_the_index() -> None:
    series = np.sin(np.linspace(0, 6, 41))
    out = wavecore.resample_curve(series, 81)
    assert out.shape == (81,)
    assert np.allclose(out[::2], series)


def test_resampling_rejects_bad_input() -> None:
    with pytest.raises(InvalidParameter, match="at least 2 points"):
        wavecore.resample_curve([[0.0, 1.0]], 5)
    with pytest.raises(InvalidParameter, match="n must be at least 2"):
        wavecore.resample_curve([[0.0, 1.0], [1.0, 1.0]], 1)
    with pytest.raises(InvalidParameter, match="finite"):
        wavecore.resample_curve([[0.0, np.nan], [1.0, 1.0]], 4)
    with pytest.raises(InvalidParameter, match="shape"):
        wavecore.resample_curve(np.zeros((3, 2, 2)), 4)


@given(
    shape=st.tuples(st.integers(1, 40), st.integers(1, 40), st.integers(1, 3)),
    level=st.integers(0, 4),
    boundaries=st.sampled_from([("open", "open"), ("closed", "open"), ("closed", "closed")]),
    dtype=st.sampled_from([np.uint8, np.uint16, np.float32, np.float64]),
)
@settings(max_examples=80, deadline=None)
def test_padding_fits_and_crops_back(
    shape: tuple[int, int, int], level: int, boundaries: tuple[str, str], dtype: type
) -> None:
    rng = np.random.default_rng(sum(shape) + level)
    data = (rng.random(shape) * 200).astype(dtype)
    padded, pads = wavecore.pad_to_fit(data, level, axes=(0, 1), boundary=boundaries)
    assert padded.dtype == data.dtype
    for axis, boundary in enumerate(boundaries):
        assert padded.shape[axis] == wavecore.valid_length(shape[axis], level, boundary)
        assert pads[axis][0] == 0
    assert np.array_equal(wavecore.crop_padding(padded, pads, axes=(0, 1)), data)
    if level:
        coeffs = wavecore.wavedec2(padded, boundary=boundaries, level=level)
        assert np.allclose(wavecore.waverec2(coeffs, boundary=boundaries), padded, atol=1e-3)


def test_closed_padding_blends_across_the_seam() -> None:
    data = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    padded, pads = wavecore.pad_to_fit(data, 2, axes=0, boundary="closed")
    assert pads == ((0, 3),)
    assert padded.tolist() == [0.0, 10.0, 20.0, 30.0, 40.0, 30.0, 20.0, 10.0]


def test_open_padding_repeats_the_edge() -> None:
    padded, _ = wavecore.pad_to_fit(np.array([1.0, 2.0, 3.0]), 1, axes=0)
    assert padded.tolist() == [1.0, 2.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0]


@pytest.mark.parametrize("boundary", ["open", "closed"])
@pytest.mark.parametrize("n", [5, 37, 100, 255, 300])
def test_coarse_crop_is_about_n_over_two_to_the_level(boundary: str, n: int) -> None:
    for level in range(1, 4):
        padded, pads = wavecore.pad_to_fit(np.zeros(n), level, axes=0, boundary=boundary)
        coarse = wavecore.wavedec(padded, boundary=boundary, level=level)[0]
        cropped = wavecore.crop_padding(coarse, pads, axes=0, level=level, boundary=boundary)
        extra = 2 if boundary == "open" else 1
        assert -(-n // 2**level) <= len(cropped) <= -(-n // 2**level) + extra
        assert len(cropped) <= len(coarse)


def test_crop_rejects_mismatched_pads() -> None:
    with pytest.raises(InvalidParameter, match="pads"):
        wavecore.crop_padding(np.zeros((8, 8)), ((0, 1),), axes=(0, 1))


@given(n_in=st.integers(2, 40), n_out=st.integers(2, 80))
@settings(max_examples=40, deadline=None)
def test_grid_resampling_is_exact_for_linear_data(n_in: int, n_out: int) -> None:
    ramp = 3.0 * np.arange(n_in) - 1.0
    grid = np.add.outer(ramp, np.arange(5.0))  # linear along axis 0
    out = wavecore.resample_grid(grid, (n_out,), axes=0)
    expected = np.add.outer(np.linspace(ramp[0], ramp[-1], n_out), np.arange(5.0))
    assert np.allclose(out, expected)


def test_closed_grid_resampling_is_periodic() -> None:
    u = np.arange(12) / 12
    circle = np.stack([np.cos(2 * np.pi * u), np.sin(2 * np.pi * u)], axis=1)
    out = wavecore.resample_grid(circle, (24,), axes=0, boundary="closed")
    assert np.allclose(out[::2], circle)  # the old samples stay, new ones between
    assert np.allclose(out[-1], (circle[-1] + circle[0]) / 2)  # across the seam


def test_fit_grid_and_its_undo() -> None:
    image = np.random.default_rng(0).random((37, 50, 3))
    for method in ("pad", "resample"):
        fitted, fit = wavecore.fit_grid(image, 3, axes=(0, 1), method=method)
        for axis in (0, 1):
            assert wavecore.max_level(fitted.shape[axis]) >= 3
        assert fit.undo(fitted).shape == image.shape
    padded, fit = wavecore.fit_grid(image, 3, axes=(0, 1))
    assert np.array_equal(fit.undo(padded), image)
    assert fit.pads == wavecore.pad_to_fit(image, 3, axes=(0, 1))[1]


def test_minimum_length_and_small_grids() -> None:
    assert wavecore.minimum_length() == 8
    assert wavecore.minimum_length("closed") == wavecore.minimum_length(wavelet="haar") == 2
    with pytest.raises(wavecore.InvalidLength, match="at least 8 samples per axis"):
        wavecore.fit_grid(np.zeros((7, 30)), 1, axes=(0, 1))
    with pytest.raises(InvalidParameter, match="method"):
        wavecore.fit_grid(np.zeros((8, 30)), 1, axes=(0, 1), method="stretch")


@pytest.mark.parametrize("boundary", ["open", "closed"])
@pytest.mark.parametrize("shape", [(37, 21, 3), (64, 64, 3), (9, 130)])
def test_padding_a_conversion_equals_padding_the_converted_array(
    boundary: str, shape: tuple[int, ...]
) -> None:
    # The codec writes its colour transform straight into the padded array: the result must be
    # the padded converted array, edges (repeated or blended from the converted values) included.
    from wavecore.resample import pad_converted_to_fit

    data = np.random.default_rng(5).integers(0, 256, shape, dtype=np.uint8)
    matrix = np.array([[0.3, 0.6, 0.1], [-0.2, -0.3, 0.5], [0.5, -0.4, -0.1]])

    def converted(rows: np.ndarray) -> np.ndarray:
        floats = rows.astype(np.float64)
        return floats @ matrix.T if floats.ndim == 3 else floats * 0.5 - 3.0

    def convert(out: np.ndarray, lo: int, hi: int) -> None:
        out[lo:hi, : data.shape[1]] = converted(data[lo:hi])

    expected, pads = wavecore.pad_to_fit(converted(data), 3, axes=(0, 1), boundary=boundary)
    padded, got_pads = pad_converted_to_fit(
        data,
        3,
        axes=(0, 1),
        boundary=boundary,
        wavelet="bspline2",
        dtype=np.dtype(np.float64),
        convert=convert,
    )
    assert got_pads == pads
    assert padded.dtype == np.float64
    assert np.array_equal(padded, expected)


def test_a_curve_too_long_for_memory_is_an_invalid_parameter() -> None:
    # 3e8 points pass the values' limit; under a 2 GiB address space numpy's MemoryError
    # came out bare
    script = (
        "import resource; resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))\n"
        "import numpy as np, wavecore\n"
        "points = np.random.default_rng(0).standard_normal((66, 2))\n"
        "try:\n"
        "    wavecore.resample_curve(points, 3 * 10**8)\n"
        "except wavecore.InvalidParameter as exc:\n"
        "    print('refused:', exc)\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120
    )
    assert "refused: a curve of 300000000 points of 2 coordinates does not fit" in run.stdout, (
        run.stdout + run.stderr
    )
