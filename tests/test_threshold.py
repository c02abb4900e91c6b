"""remove_smallest: exact counts, every layout, vector details, error that grows with fraction."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import InvalidCoefficients, InvalidParameter
from wavecore.threshold import kth_smallest


def _detail_bands(coeffs: list[Any]) -> list[np.ndarray]:
    bands: list[np.ndarray] = []
    for level in coeffs[1:]:
        if isinstance(level, dict):
            bands.extend(level.values())
        elif isinstance(level, tuple):
            bands.extend(level)
        else:
            bands.append(level)
    return bands


def _count(coeffs: list[Any], vector: bool) -> tuple[int, int]:
    """(non-zero details, all details); a vector detail counts once."""
    nonzero = total = 0
    for band in _detail_bands(coeffs):
        size = np.linalg.norm(band, axis=-1) if vector else np.abs(band)
        nonzero += int(np.count_nonzero(size))
        total += size.size
    return nonzero, total


def _decompositions() -> list[tuple[str, list[Any], bool, dict[str, Any]]]:
    rng = np.random.default_rng(7)
    signal = rng.standard_normal(66)
    curve = np.cumsum(rng.standard_normal((64, 2)), axis=0)
    image = rng.random((34, 50))
    rgb = rng.random((18, 34, 3))
    surface = rng.standard_normal((32, 18, 3))
    return [
        ("wavedec", wavecore.wavedec(signal, level=3), False, {}),
        (
            "curve",
            wavecore.wavedec(curve, boundary="closed", level=3),
            True,
            {"boundary": "closed"},
        ),
        ("wavedec2", wavecore.wavedec2(image, level=2), False, {}),
        ("rgb", wavecore.wavedec2(rgb, level=2), False, {"vector_axis": None}),
        (
            "surface",
            wavecore.wavedecn(surface, boundary=("closed", "open"), level=2, axes=(0, 1)),
            True,
            {"boundary": ("closed", "open")},
        ),
        ("haar", wavecore.wavedec2(image[:32, :48], "haar", level=3), False, {"wavelet": "haar"}),
    ]


CASES = _decompositions()


@pytest.mark.parametrize(("name", "coeffs", "vector", "options"), CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("weighted", [True, False])
@pytest.mark.parametrize("fraction", [0.0, 0.01, 0.25, 0.5, 0.6, 0.999, 1.0])
def test_removes_exactly_the_requested_count(
    name: str,
    coeffs: list[Any],
    vector: bool,
    options: dict[str, Any],
    weighted: bool,
    fraction: float,
) -> None:
    kept = wavecore.remove_smallest(coeffs, fraction, weighted=weighted, **options)
    nonzero_before, total = _count(coeffs, vector)
    assert nonzero_before == total  # random data: no detail is zero to begin with
    nonzero_after, _ = _count(kept, vector)
    assert total - nonzero_after == int(np.floor(fraction * total + 0.5))
    assert np.array_equal(kept[0], coeffs[0])
    assert type(kept[1]) is type(coeffs[1])


@pytest.mark.parametrize(("name", "coeffs", "vector", "options"), CASES, ids=[c[0] for c in CASES])
def test_fraction_zero_changes_nothing_and_one_leaves_the_coarse(
    name: str, coeffs: list[Any], vector: bool, options: dict[str, Any]
) -> None:
    same = wavecore.remove_smallest(coeffs, 0.0, **options)
    for a, b in zip(_detail_bands(same), _detail_bands(coeffs), strict=True):
        assert np.array_equal(a, b)
    none = wavecore.remove_smallest(coeffs, 1.0, **options)
    assert all(not np.any(band) for band in _detail_bands(none))


def test_does_not_modify_its_input() -> None:
    coeffs = CASES[2][1]
    before = [band.copy() for band in _detail_bands(coeffs)]
    wavecore.remove_smallest(coeffs, 0.7)
    for a, b in zip(_detail_bands(coeffs), before, strict=True):
        assert np.array_equal(a, b)


def _photo_crops() -> list[np.ndarray]:
    from skimage import data

    return [
        getattr(data, name)()[:130, :130].astype(np.float64)
        for name in ("camera", "coins", "moon", "brick")
    ]


@pytest.mark.parametrize("weighted", [True, False])
def test_error_grows_with_fraction_on_photographs(weighted: bool) -> None:
    for image in _photo_crops():
        coeffs = wavecore.wavedec2(image, level=4)
        errors = [
            np.linalg.norm(
                wavecore.waverec2(wavecore.remove_smallest(coeffs, f, weighted=weighted)) - image
            )
            for f in np.linspace(0, 1, 21)
        ]
        assert errors[0] < 1e-9
        # The basis is not orthogonal, so this is a property of real data, not a theorem.
        assert all(b >= a - 1e-9 for a, b in itertools.pairwise(errors))
        assert errors[-1] > errors[10] > errors[2]


@given(seed=st.integers(0, 10_000), weighted=st.booleans())
@settings(max_examples=30, deadline=None)
def test_error_trend_on_random_images(seed: int, weighted: bool) -> None:
    image = np.random.default_rng(seed).random((34, 34))
    coeffs = wavecore.wavedec2(image, level=3)
    errors = [
        np.linalg.norm(
            wavecore.waverec2(wavecore.remove_smallest(coeffs, f, weighted=weighted)) - image
        )
        for f in (0.0, 0.1, 0.5, 0.8)
    ]
    assert errors[0] < 1e-10 < errors[1] < errors[2] < errors[3]


def test_weighted_ranking_costs_less_than_plain_on_photographs() -> None:
    for image in _photo_crops():
        coeffs = wavecore.wavedec2(image, level=4)
        for fraction in (0.6, 0.9):
            weighted = wavecore.waverec2(wavecore.remove_smallest(coeffs, fraction))
            plain = wavecore.waverec2(wavecore.remove_smallest(coeffs, fraction, weighted=False))
            assert np.linalg.norm(weighted - image) < np.linalg.norm(plain - image)


def test_vector_details_are_kept_or_removed_whole() -> None:
    curve = np.cumsum(np.random.default_rng(2).standard_normal((34, 3)), axis=0)
    kept = wavecore.remove_smallest(wavecore.wavedec(curve, level=2), 0.5)
    for band in kept[1:]:
        zero_rows = np.all(band == 0, axis=1)
        assert np.array_equal(zero_rows, np.any(band == 0, axis=1))


def test_ties_are_broken_deterministically() -> None:
    coeffs = [np.zeros(6), np.ones(4), np.ones(8)]
    a = wavecore.remove_smallest(coeffs, 0.5, weighted=False)
    b = wavecore.remove_smallest(coeffs, 0.5, weighted=False)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert sum(int(np.count_nonzero(d)) for d in a[1:]) == 6


def test_other_transformed_axis() -> None:
    data = np.random.default_rng(5).random((3, 34))
    coeffs = wavecore.wavedec(data, level=2, axis=1)
    kept = wavecore.remove_smallest(coeffs, 0.5, axes=(1,), vector_axis=None)
    assert sum(int(np.count_nonzero(d)) for d in kept[1:]) == 3 * (16 + 8) // 2


def test_bad_input() -> None:
    coeffs = wavecore.wavedec(np.zeros(18), level=1)
    for bad in (-0.1, 1.5, float("nan"), "half", True):
        with pytest.raises(InvalidParameter, match="fraction"):
            wavecore.remove_smallest(coeffs, bad)
    with pytest.raises(InvalidCoefficients):
        wavecore.remove_smallest(np.zeros(5), 0.5)
    with pytest.raises(InvalidCoefficients, match="None"):
        wavecore.remove_smallest([np.zeros(10), None], 0.5)
    points = wavecore.wavedec(np.zeros((18, 2)), level=1)
    with pytest.raises(InvalidParameter, match="vector_axis"):
        wavecore.remove_smallest(points, 0.5, vector_axis=0)


def test_coarse_only_list_is_returned_unchanged() -> None:
    out = wavecore.remove_smallest([np.arange(5.0)], 0.5)
    assert len(out) == 1
    assert np.array_equal(out[0], np.arange(5.0))


def test_mismatched_band_shapes_are_refused() -> None:
    coeffs = wavecore.wavedec2(np.zeros((34, 34)), level=2)
    ch, cv, cd = coeffs[1]
    broken = [coeffs[0], (ch[:-1], cv, cd), coeffs[2]]
    with pytest.raises(InvalidCoefficients, match="same decomposition"):
        wavecore.remove_smallest(broken, 0.5)


def test_plain_ranking_takes_bands_of_any_lengths() -> None:
    # Integer lifting schemes (the codec's lossless 5/3) split odd lengths unevenly.
    coeffs = [np.arange(1.0, 6.0), np.arange(1.0, 5.0), np.arange(1.0, 10.0)]
    kept = wavecore.remove_smallest(coeffs, 0.5, weighted=False)
    assert sum(int(np.count_nonzero(d)) for d in kept[1:]) == 6


@settings(max_examples=300, deadline=None)
@given(
    values=st.lists(
        st.one_of(st.sampled_from([0.0, 1.0, 2.5, math.nan]), st.floats(0, 10)),
        min_size=1,
        max_size=80,
    ),
    data=st.data(),
)
def test_kth_smallest_is_the_sorted_value(values: list[float], data: st.DataObject) -> None:
    array = np.array(values)
    k = data.draw(st.integers(0, array.size - 1))
    got, want = kth_smallest(array, k), np.sort(array)[k]
    assert got == want or (math.isnan(got) and math.isnan(want))


def test_kth_smallest_inside_a_run_of_zeros() -> None:
    """Where NumPy's partition slows down (k inside a large run of equal values among
    others): the run's value, and the values on either side, exactly."""
    rng = np.random.default_rng(4)
    values = np.abs(rng.standard_normal(100_000))
    values[rng.random(values.size) < 0.6] = 0.0
    ordered = np.sort(values)
    zeros = int(np.count_nonzero(values == 0))
    for k in (0, zeros // 2, zeros - 1, zeros, zeros + 1, values.size - 1):
        assert kth_smallest(values, k) == ordered[k]
