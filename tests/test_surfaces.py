"""Surfaces: points and height fields, a boundary per direction, all / none / some details."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import InvalidLength, InvalidParameter


def _revolution(nu: int, nv: int, seed: int = 0) -> np.ndarray:
    """A vase: closed in u (around), open in v (along the axis), with a little relief."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)[:, None]
    v = np.linspace(0, 1, nv)[None, :]
    radius = 1 + 0.3 * np.sin(3 * np.pi * v) + 0.05 * np.cos(8 * u) + 0.01 * rng.random((nu, nv))
    x, y, z = np.broadcast_arrays(radius * np.cos(u), radius * np.sin(u), 2 * v)
    return np.stack([x, y, z], axis=-1)


def _torus(nu: int, nv: int) -> np.ndarray:
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)[:, None]
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)[None, :]
    r = 0.4 + 0.03 * np.sin(5 * u + 3 * v)
    x, y, z = np.broadcast_arrays(
        (1 + r * np.cos(v)) * np.cos(u), (1 + r * np.cos(v)) * np.sin(u), r * np.sin(v)
    )
    return np.stack([x, y, z], axis=-1)


def _terrain(nu: int, nv: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(np.cumsum(rng.standard_normal((nu, nv)), axis=0), axis=1) / 10


CASES = [
    ("revolution", _revolution(32, 18), ("closed", "open")),
    ("patch", _terrain(34, 50), "open"),
    ("torus", _torus(32, 16), "closed"),
    ("height field, odd size", _terrain(45, 61), "open"),
    ("revolution, odd size", _revolution(30, 21), ("closed", "open")),
]


@pytest.mark.parametrize(("name", "grid", "boundary"), CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("fit", ["pad", "resample"])
def test_all_none_and_some_details(name: str, grid: np.ndarray, boundary: object, fit: str) -> None:
    dec = wavecore.decompose_surface(grid, 2, boundary=boundary, fit=fit)
    full = dec.reconstruct()
    assert full.shape == grid.shape
    if fit == "pad" or dec.fit.fitted == dec.fit.original:
        assert np.allclose(full, grid, atol=1e-10)
    errors = [np.linalg.norm(dec.reconstruct(keep=k) - full) for k in (1.0, 0.4, 0.0)]
    assert errors[0] < 1e-9 < errors[1] < errors[2]
    coarse = dec.coarse()
    assert coarse.shape[2:] == grid.shape[2:]
    for n, c in zip(grid.shape[:2], coarse.shape[:2], strict=False):
        assert c <= -(-n // 4) + 2


def test_closed_direction_has_no_seam() -> None:
    grid = _revolution(64, 18)
    dec = wavecore.decompose_surface(grid, 2, boundary=("closed", "open"))
    smooth = dec.reconstruct(keep=0.0)
    steps = np.linalg.norm(np.diff(np.concatenate([smooth, smooth[:1]]), axis=0), axis=-1)
    seam, others = steps[-1], steps[:-1]
    assert np.all(others.min(axis=0) <= seam + 1e-12)
    assert np.all(seam <= others.max(axis=0) + 1e-12)
    # Starting the circles elsewhere (by a whole coarse sample) gives the same surface.
    rolled = wavecore.decompose_surface(np.roll(grid, -8, axis=0), 2, boundary=("closed", "open"))
    assert np.allclose(np.roll(rolled.reconstruct(keep=0.0), 8, axis=0), smooth, atol=1e-9)


def test_point_details_are_removed_whole() -> None:
    dec = wavecore.decompose_surface(_torus(32, 16), 2, boundary="closed")
    kept = wavecore.remove_smallest(dec.coeffs, 0.6, boundary="closed")
    for level in kept[1:]:
        for band in level.values():
            zero = np.all(band == 0, axis=-1)
            assert np.array_equal(zero, np.any(band == 0, axis=-1))


def test_coarse_levels() -> None:
    dec = wavecore.decompose_surface(_revolution(32, 18), 2, boundary=("closed", "open"))
    assert [dec.coarse(k).shape for k in range(3)] == [(32, 18, 3), (16, 10, 3), (8, 6, 3)]
    with pytest.raises(InvalidParameter, match="deeper"):
        dec.coarse(3)


@given(
    nu=st.integers(8, 40),
    nv=st.integers(8, 40),
    d=st.sampled_from([0, 1, 3]),
    boundary=st.sampled_from(["open", "closed", ("closed", "open")]),
)
@settings(max_examples=30, deadline=None)
def test_any_grid_round_trips(nu: int, nv: int, d: int, boundary: object) -> None:
    rng = np.random.default_rng(nu * 100 + nv)
    grid = rng.standard_normal((nu, nv, d) if d else (nu, nv))
    dec = wavecore.decompose_surface(grid, boundary=boundary)
    assert np.allclose(dec.reconstruct(), grid, atol=1e-10)


def test_bad_surfaces() -> None:
    with pytest.raises(InvalidParameter, match="height field"):
        wavecore.decompose_surface(np.zeros(20))
    with pytest.raises(InvalidParameter, match="finite"):
        wavecore.decompose_surface(np.full((20, 20), np.nan))
    with pytest.raises(InvalidLength, match="at least 8"):
        wavecore.decompose_surface(np.zeros((20, 4, 3)))
    with pytest.raises(InvalidParameter, match="fit"):
        wavecore.decompose_surface(np.zeros((20, 20)), fit="stretch")
    with pytest.raises(InvalidParameter, match="keep"):
        wavecore.decompose_surface(np.zeros((20, 20))).reconstruct(keep=1.5)
