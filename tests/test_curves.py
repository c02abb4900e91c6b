"""Curves: decomposition of any length, closed curves without a seam, detail transfer."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import InvalidParameter


def _blob(n: int, seed: int = 0, d: int = 2) -> np.ndarray:
    """A closed, wobbly curve with n points (no repeated seam point)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    radius = 1 + 0.15 * np.cos(5 * t + 1) + 0.02 * rng.standard_normal(n)
    points = np.stack([radius * np.cos(t), radius * np.sin(t)], axis=1)
    if d == 3:
        points = np.concatenate([points, 0.3 * np.sin(3 * t)[:, None]], axis=1)
    return points


def _stroke(n: int, seed: int = 0) -> np.ndarray:
    """An open, wiggly stroke."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    return np.stack([t, 0.2 * np.sin(5 * t) + 0.01 * rng.standard_normal(n)], axis=1)


@given(n=st.integers(6, 300), closed=st.booleans(), seed=st.integers(0, 50))
@settings(max_examples=40, deadline=None)
def test_any_length_decomposes_and_comes_back_at_its_length(
    n: int, closed: bool, seed: int
) -> None:
    points = _blob(n, seed) if closed else _stroke(n, seed)
    dec = wavecore.decompose_curve(points, closed=closed)
    boundary = "closed" if closed else "open"
    assert wavecore.max_level(dec.length, boundary) >= dec.level >= 1
    assert dec.resampled == (dec.length != n)
    back = dec.reconstruct(match_input=True)
    assert back.shape == points.shape
    if not dec.resampled:
        assert np.allclose(back, points, atol=1e-12)
    else:
        # Re-sampling cuts corners, by less than a segment of the input polygon.
        nodes = np.concatenate([points, points[:1]]) if closed else points
        longest = np.max(np.linalg.norm(np.diff(nodes, axis=0), axis=1))
        assert np.max(np.linalg.norm(back - points, axis=1)) < 0.5 * longest
    if not closed:
        assert np.allclose(back[0], points[0]) and np.allclose(back[-1], points[-1])
    assert dec.reconstruct().shape == (dec.length, 2)


def test_fitting_length_is_used_as_it_is() -> None:
    points = _stroke(130)
    dec = wavecore.decompose_curve(points, level=4)
    assert not dec.resampled
    assert np.allclose(dec.reconstruct(), points, atol=1e-12)
    assert dec.coarse(0).shape == (130, 2)


def test_coarse_at_every_level() -> None:
    dec = wavecore.decompose_curve(_blob(128), level=4, closed=True)
    lengths = [len(dec.coarse(level)) for level in range(5)]
    assert lengths == [128, 64, 32, 16, 8]
    assert np.array_equal(dec.coarse(), dec.coeffs[0])
    with pytest.raises(InvalidParameter, match="deeper"):
        dec.coarse(5)


def test_removing_details_smooths_and_errors_grow() -> None:
    points = _stroke(258, seed=4)
    dec = wavecore.decompose_curve(points, level=5)
    errors = [np.linalg.norm(dec.reconstruct(keep=k) - points) for k in (1.0, 0.6, 0.3, 0.0)]
    assert errors[0] < 1e-10 < errors[1] < errors[2] < errors[3]
    roughness = [np.abs(np.diff(dec.reconstruct(keep=k), 2, axis=0)).sum() for k in (1.0, 0.0)]
    assert roughness[1] < roughness[0] / 3


@pytest.mark.parametrize("keep", [1.0, 0.5, 0.0])
def test_closed_reconstruction_has_no_seam(keep: float) -> None:
    points = _blob(256, seed=2)
    dec = wavecore.decompose_curve(points, level=4, closed=True)
    curve = dec.reconstruct(keep=keep)
    steps = np.linalg.norm(np.diff(np.concatenate([curve, curve[:1]]), axis=0), axis=1)
    seam, others = steps[-1], steps[:-1]
    assert others.min() <= seam <= others.max()
    assert abs(seam - np.median(others)) < 3 * np.std(others) + 1e-12
    # Where the curve starts does not matter: start it elsewhere (by a whole coarse sample),
    # and the result is the same curve, started elsewhere.
    shift = 2**dec.level * 3
    rolled = wavecore.decompose_curve(np.roll(points, -shift, axis=0), level=4, closed=True)
    assert np.allclose(np.roll(rolled.reconstruct(keep=keep), shift, axis=0), curve, atol=1e-9)


def test_open_curve_keeps_its_ends_without_details() -> None:
    points = _stroke(66)
    smooth = wavecore.decompose_curve(points, level=3).reconstruct(keep=0.0)
    assert np.allclose(smooth[0], points[0]) and np.allclose(smooth[-1], points[-1])


def test_time_series_and_3d_paths() -> None:
    series = np.sin(np.linspace(0, 8, 100))
    dec = wavecore.decompose_curve(series)
    assert dec.reconstruct().ndim == 1
    assert dec.reconstruct(match_input=True).shape == (100,)
    path = _blob(96, d=3)
    dec3 = wavecore.decompose_curve(path, closed=True)
    assert np.allclose(dec3.reconstruct(), path)


@pytest.mark.parametrize("frame", ["local", "plain"])
@pytest.mark.parametrize(("closed", "d"), [(False, 2), (True, 2), (True, 3), (False, 1)])
def test_transferring_zero_details_gives_the_base_smooth_curve(
    frame: str, closed: bool, d: int
) -> None:
    level = 3
    if d == 1:
        source = np.sin(np.linspace(0, 3, 66))
        base = np.cos(np.linspace(0, 2, 10))
    elif closed:
        source, base = _blob(128, d=d), 2 * _blob(20, seed=9, d=d)[::-1]
    else:
        source, base = _stroke(66), np.array([[0.0, 0.0], [0.3, 1.0], [1.0, 1.2]])
    boundary = "closed" if closed else "open"
    smooth_source = wavecore.decompose_curve(source, level, closed=closed).reconstruct(keep=0.0)
    new = wavecore.transfer_details(smooth_source, base, closed=closed, level=level, frame=frame)
    coarse = len(wavecore.wavedec(smooth_source, boundary=boundary, level=level)[0])
    base_coarse = wavecore.resample_curve(base, coarse, closed=closed)
    expected = wavecore.waverec(
        [base_coarse, *([None] * level)], boundary=boundary
    )  # the base's own smooth curve
    assert np.allclose(new, expected, atol=1e-9)


@pytest.mark.parametrize("frame", ["local", "plain"])
@pytest.mark.parametrize(("closed", "d"), [(False, 2), (True, 2), (True, 3)])
def test_transfer_onto_the_source_outline_gives_the_source(
    frame: str, closed: bool, d: int
) -> None:
    source = _blob(128, d=d) if closed else _stroke(130)
    dec = wavecore.decompose_curve(source, 3, closed=closed)
    new = wavecore.transfer_details(source, dec.coarse(), closed=closed, level=3, frame=frame)
    assert np.allclose(new, source, atol=1e-9)


def test_local_frame_turns_the_character_with_the_sweep() -> None:
    t = np.linspace(0, 1, 130)
    wiggly = np.stack([t, 0.03 * np.sin(80 * t)], axis=1)
    base = np.stack([np.zeros(6), np.linspace(0, 1, 6)], axis=1)  # vertical, not horizontal
    local = wavecore.transfer_details(wiggly, base, level=3)
    plain = wavecore.transfer_details(wiggly, base, level=3, frame="plain")
    inner = slice(10, -10)
    # The wiggles stood across the horizontal source; on a vertical base, local keeps them
    # across (along x), plain leaves them along y.
    assert np.ptp(local[inner, 0]) > 0.04
    assert np.ptp(plain[inner, 0]) < 0.01


def test_transfer_returns_the_source_length() -> None:
    new = wavecore.transfer_details(_blob(100), _blob(30, seed=3), closed=True)
    assert new.shape == (100, 2)


def test_transfer_to_one_coarse_point_names_the_levels_that_fit() -> None:
    # 16 closed points at level 4 leave one coarse point, which has no direction to follow
    with pytest.raises(InvalidParameter, match=r"level 4 .* 1 point.* from 1 to 3"):
        wavecore.transfer_details(_blob(16), _blob(30), level=4, closed=True)
    with pytest.raises(InvalidParameter, match=r"give level 1$"):
        wavecore.transfer_details(_blob(5), _blob(30), level=3, closed=True)
    assert wavecore.transfer_details(_blob(16), _blob(30), level=3, closed=True).shape == (16, 2)


def test_bad_curves() -> None:
    with pytest.raises(InvalidParameter, match="at least 2 points"):
        wavecore.decompose_curve([[1.0, 2.0]])
    with pytest.raises(InvalidParameter, match="shape"):
        wavecore.decompose_curve(np.zeros((4, 2, 2)))
    with pytest.raises(InvalidParameter, match="finite"):
        wavecore.decompose_curve([[0.0, 1.0], [np.inf, 0.0], [1.0, 1.0]])
    with pytest.raises(InvalidParameter, match="must match"):
        wavecore.transfer_details(_stroke(34), np.zeros((5, 3)))
    with pytest.raises(InvalidParameter, match="frame"):
        wavecore.transfer_details(_stroke(34), _stroke(5), frame="tangent")
    with pytest.raises(InvalidParameter, match="keep"):
        wavecore.decompose_curve(_stroke(34)).reconstruct(keep=2.0)


def test_closed_3d_transfer_has_no_seam() -> None:
    t = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    knotty = np.stack([np.cos(t), np.sin(t), 0.8 * np.sin(2 * t)], axis=1)  # frames twist
    bumps = knotty * (1 + 0.05 * np.cos(24 * t))[:, None]
    base = np.stack([1.5 * np.cos(t[::4]), np.sin(t[::4]), 0.2 * np.cos(t[::4])], axis=1)
    new = wavecore.transfer_details(bumps, base, closed=True, level=3)
    steps = np.linalg.norm(np.diff(np.concatenate([new, new[:1]]), axis=0), axis=1)
    assert steps[:-1].min() <= steps[-1] <= steps[:-1].max()
