"""wavecore.layout: the one home of the coefficient layout, checked against the transforms."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from wavecore import lossless, valid_length, wavedec, wavedec2, wavedecn
from wavecore.errors import InvalidCoefficients
from wavecore.filters import get_wavelet
from wavecore.layout import (
    as_keyed,
    as_levels,
    band_names,
    band_shapes,
    from_keyed,
    from_levels,
    is_band_group,
)


def _shapes_of(coeffs: list[Any]) -> list[Any]:
    return [
        tuple(tuple(b.shape) for b in entry) if isinstance(entry, tuple) else tuple(entry.shape)
        for entry in coeffs
    ]


def _rule_split(wavelet: str, boundaries: list[str]) -> Any:
    rules = [get_wavelet(wavelet).rule(b) for b in boundaries]
    return lambda i, n: (rules[i].coarse_length(n), rules[i].detail_length(n))


@pytest.mark.parametrize("wavelet", ["bspline2", "haar", "cdf97"])
@pytest.mark.parametrize("size", [(23, 40), (64, 9)])
def test_band_shapes_are_what_wavedec2_makes(wavelet: str, size: tuple[int, int]) -> None:
    boundary = (
        "open" if "open" in get_wavelet(wavelet).rules else next(iter(get_wavelet(wavelet).rules))
    )
    level = 2
    shape = tuple(valid_length(n, level, boundary, wavelet) for n in size) + (3,)
    data = np.random.default_rng(1).random(shape)
    coeffs = wavedec2(data, wavelet, boundary, level)
    split = _rule_split(wavelet, [boundary, boundary])
    assert band_shapes(shape, level, (0, 1), split) == _shapes_of(coeffs)


@pytest.mark.parametrize("boundary", ["open", "closed"])
def test_band_shapes_are_what_wavedec_makes(boundary: str) -> None:
    n = valid_length(50, 3, boundary, "bspline2")
    data = np.random.default_rng(2).random((n, 2))
    coeffs = wavedec(data, "bspline2", boundary, 3, axis=0)
    split = _rule_split("bspline2", [boundary])
    assert band_shapes((n, 2), 3, (0,), split) == _shapes_of(coeffs)


@pytest.mark.parametrize("shape", [(5, 8), (17, 3), (1, 7)])
def test_band_shapes_are_what_the_integer_lifting_makes(shape: tuple[int, int]) -> None:
    level = min(shape).bit_length() - 1 or 1
    data = np.random.default_rng(3).integers(0, 256, shape)
    coeffs = lossless.forward(data, level, (0, 1), ["haar"] * level)
    assert lossless.band_shapes(shape, level) == _shapes_of(coeffs)


def test_levels_round_trip_both_layouts() -> None:
    rng = np.random.default_rng(4)
    two_d = wavedec2(rng.random((34, 34)), level=2)
    one_d = wavedec(rng.random(34), level=2)
    for coeffs, widths in ((two_d, [1, 3, 3]), (one_d, [1, 1, 1])):
        levels = as_levels(coeffs)
        assert [len(bands) for bands in levels] == widths
        back = from_levels(coeffs, levels)
        assert _shapes_of(back) == _shapes_of(coeffs)
        # A prefix (a coarse decode) keeps the layout of the entries it has.
        assert len(from_levels(coeffs, levels[:2])) == 2


def test_keyed_round_trip_all_three_layouts() -> None:
    rng = np.random.default_rng(5)
    for coeffs, kind in (
        (wavedec(rng.random(34), level=2), "wavedec"),
        (wavedec2(rng.random((34, 34)), level=2), "wavedec2"),
        (wavedecn(rng.random((34, 34)), level=2), "wavedecn"),
    ):
        got, coarse, levels = as_keyed(coeffs)
        assert got == kind
        back = from_keyed(got, coarse, levels)
        for a, b in zip(back[1:], coeffs[1:], strict=True):
            if isinstance(b, dict):
                assert all(np.array_equal(a[k], b[k]) for k in b)
            elif isinstance(b, tuple):
                assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
            else:
                assert np.array_equal(a, b)


def test_names_and_groups() -> None:
    assert band_names(0, 2) == ["cA"]
    assert band_names(1, 2) == ["cH", "cV", "cD"]
    assert band_names(3, 1) == ["cD"]
    assert is_band_group(((1, 2), (1, 2), (2, 2)))
    assert not is_band_group((1, 2))
    assert not is_band_group(np.zeros((2, 2)))


@pytest.mark.parametrize("bad", [[], np.zeros(3)])
def test_malformed_lists_are_refused(bad: Any) -> None:
    with pytest.raises(InvalidCoefficients, match="non-empty list"):
        as_levels(bad)
    with pytest.raises(InvalidCoefficients, match="non-empty list"):
        as_keyed(bad)


def test_bands_that_do_not_fit_are_named_not_left_to_numpy() -> None:
    import wavecore

    coeffs = wavedec2(np.random.default_rng(0).standard_normal((66, 130)), level=2)
    short = [coeffs[0], (coeffs[1][0][:-1], coeffs[1][1], coeffs[1][2]), *coeffs[2:]]
    for bad in (short, [None, *coeffs[1:]], [np.float64(1), (np.float64(1),) * 3]):
        with pytest.raises(InvalidCoefficients, match="do not tile a picture"):
            wavecore.subband_mosaic(bad)
    # the levels swapped: a tuple of three bands where the coarse band belongs
    with pytest.raises(InvalidCoefficients, match="cA must be an array"):
        wavecore.remove_smallest([coeffs[1], coeffs[0], *coeffs[2:]], 0.5)
