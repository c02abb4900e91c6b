"""Issue 15 item 6, the library's part: one API, where the old spellings keep working.

- ``wavelet=`` on ``encode_surface``;
- ``boundary="closed"/"open"`` wherever ``closed=True/False`` is taken;
- ``keep=`` on ``remove_smallest``, beside ``fraction``;
- ``drop_levels=`` on ``decode``, beside ``level``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import wavecore
from wavecore import InvalidParameter, decode, inspect

T = np.linspace(0, 2 * np.pi, 45, endpoint=False)
FLOWER = np.stack([np.cos(T), np.sin(T)], axis=1) * (1 + 0.2 * np.cos(5 * T))[:, None]
U, V = np.meshgrid(np.linspace(0, 1, 22), np.linspace(0, 1, 27), indexing="ij")
HEIGHTS = np.sin(3 * U) * np.cos(2 * V) + 0.1 * U


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, bytes):
        return a == b
    if hasattr(a, "reconstruct"):
        return bool(np.array_equal(a.reconstruct(), b.reconstruct()))
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


# --- encode_surface(wavelet=) -----------------------------------------------------------------


@pytest.mark.parametrize("wavelet", ["haar", "cdf97", "bspline2"])
def test_encode_surface_takes_a_wavelet_and_the_bundle_records_it(wavelet: str) -> None:
    bundle = wavecore.encode_surface(HEIGHTS, quality=45, wavelet=wavelet)
    info = inspect(bundle)
    assert info["wavelet"] == wavelet and info["kind"] == "surface"
    out = decode(bundle)
    span = HEIGHTS.max() - HEIGHTS.min()
    psnr = 10 * np.log10(span**2 / np.mean((out - HEIGHTS) ** 2))
    assert out.shape == HEIGHTS.shape and psnr >= 45


def test_encode_surface_default_is_still_bspline2_and_unchanged() -> None:
    default = wavecore.encode_surface(HEIGHTS, quality=40)
    assert inspect(default)["wavelet"] == "bspline2"
    assert default == wavecore.encode_surface(HEIGHTS, quality=40, wavelet="bspline2")


def test_encode_surface_refuses_an_unknown_wavelet() -> None:
    with pytest.raises(InvalidParameter, match="unknown wavelet 'db99'"):
        wavecore.encode_surface(HEIGHTS, wavelet="db99")
    # a long name is cut in the message, which a service answers with
    with pytest.raises(InvalidParameter, match=r"… \(5002 characters\)") as caught:
        wavecore.encode_surface(HEIGHTS, wavelet="x" * 5000)
    assert len(str(caught.value)) < 400


# --- boundary= beside closed= -----------------------------------------------------------------

#: name → (call with closed=..., call with boundary=...)
BOTH_SPELLINGS: dict[str, Callable[..., Any]] = {
    "encode_curve": lambda **kw: wavecore.encode_curve(FLOWER, tolerance=1e-3, **kw),
    "decompose_curve": lambda **kw: wavecore.decompose_curve(FLOWER, 2, **kw),
    "transfer_details": lambda **kw: wavecore.transfer_details(FLOWER, FLOWER[::5] * 2, **kw),
    "resample_curve": lambda **kw: wavecore.resample_curve(FLOWER, 30, **kw),
}


@pytest.mark.parametrize("name", sorted(BOTH_SPELLINGS))
def test_boundary_is_another_spelling_of_closed(name: str) -> None:
    call = BOTH_SPELLINGS[name]
    assert _same(call(closed=True), call(boundary="closed"))
    assert _same(call(closed=False), call(boundary="open"))
    assert _same(call(), call(boundary="open"))  # neither: open, as before
    assert _same(call(closed=True, boundary="closed"), call(closed=True))  # agreeing: fine
    assert not _same(call(boundary="closed"), call(boundary="open"))  # it is not ignored


@pytest.mark.parametrize("name", sorted(BOTH_SPELLINGS))
def test_disagreeing_or_bad_spellings_are_refused(name: str) -> None:
    call = BOTH_SPELLINGS[name]
    with pytest.raises(InvalidParameter, match=r"closed=True and boundary='open' disagree"):
        call(closed=True, boundary="open")
    with pytest.raises(InvalidParameter, match=r"boundary must be 'open' or 'closed'"):
        call(boundary="periodic")
    with pytest.raises(InvalidParameter, match=r"closed must be True or False"):
        call(closed="yes")


def test_encode_surface_takes_boundary_per_axis_or_for_both() -> None:
    ring = np.stack([np.cos(2 * np.pi * U), np.sin(2 * np.pi * U), V], axis=-1)[:-1]
    by_closed = wavecore.encode_surface(ring, closed=(True, False), quality=40)
    assert by_closed == wavecore.encode_surface(ring, boundary=("closed", "open"), quality=40)
    assert inspect(by_closed)["boundary"] == ["closed", "open"]
    both = wavecore.encode_surface(HEIGHTS, boundary="open", quality=40)
    assert both == wavecore.encode_surface(HEIGHTS, quality=40)
    with pytest.raises(InvalidParameter, match="disagree"):
        wavecore.encode_surface(ring, closed=(True, False), boundary="closed")
    with pytest.raises(InvalidParameter, match="boundary must be"):
        wavecore.encode_surface(ring, boundary=("closed",))


# --- remove_smallest(keep=) -------------------------------------------------------------------


def test_remove_smallest_takes_keep_as_one_minus_fraction() -> None:
    coeffs = wavecore.wavedec2(np.random.default_rng(2).random((34, 34)), level=2)
    for keep in (0.0, 0.25, 0.5, 1.0):
        by_keep = wavecore.remove_smallest(coeffs, keep=keep)
        by_fraction = wavecore.remove_smallest(coeffs, 1.0 - keep)
        for a, b in zip(by_keep[1:], by_fraction[1:], strict=True):
            assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    details = sum(b.size for level in coeffs[1:] for b in level)
    kept = wavecore.remove_smallest(coeffs, keep=0.25)
    assert sum(int(np.count_nonzero(b)) for level in kept[1:] for b in level) == details // 4


def test_remove_smallest_needs_exactly_one_of_fraction_and_keep() -> None:
    coeffs = wavecore.wavedec(np.arange(34.0), level=2)
    with pytest.raises(InvalidParameter, match="not both"):
        wavecore.remove_smallest(coeffs, 0.5, keep=0.5)
    with pytest.raises(InvalidParameter, match="not neither"):
        wavecore.remove_smallest(coeffs)
    with pytest.raises(InvalidParameter, match=r"keep must be in \[0, 1\]"):
        wavecore.remove_smallest(coeffs, keep=1.5)


# --- decode(drop_levels=) ---------------------------------------------------------------------


def test_drop_levels_is_level_under_a_clearer_name() -> None:
    image = (np.add.outer(np.arange(40), np.arange(36)) % 251).astype(np.uint8)
    bundle = wavecore.encode_image(image, lossless=True, level=3)
    for k in range(4):
        assert np.array_equal(decode(bundle, drop_levels=k), decode(bundle, level=k))
        assert np.array_equal(decode(bundle, drop_levels=k, level=k), decode(bundle, level=k))
    assert decode(bundle, drop_levels=2).shape == (10, 9)
    with pytest.raises(InvalidParameter, match="disagree"):
        decode(bundle, drop_levels=1, level=2)
    with pytest.raises(InvalidParameter, match="drop_levels must be"):
        decode(bundle, drop_levels=-1)
    with pytest.raises(InvalidParameter, match="deeper than the bundle"):
        decode(bundle, drop_levels=4)
