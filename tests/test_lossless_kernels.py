"""The compiled reversible liftings against the lifting formulas written with NumPy.

The oracle below is the module's docstring formulas, one whole-array NumPy step each (the way
``wavecore.lossless`` computed them before it had compiled kernels): the kernels must give the
same integers, bit for bit, on every filter, length, axis and trailing shape, and at the ends of
the int64 range (where both wrap around).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import wavecore
from wavecore import _liftingkernels as kernels
from wavecore import lossless


def _neighbours(s: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ns, nd = len(s), len(d)
    s_right = np.concatenate([s[1:], s[-1:]])[:nd]
    d_left = np.concatenate([d[:1], d])[:ns]
    d_right = np.concatenate([d, d[-1:]])[:ns]
    return s_right, d_left, d_right


def reference_lift(x: np.ndarray, axis: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    data = np.moveaxis(np.asarray(x, dtype=np.int64), axis, 0)
    if name == "bspline2":
        t = data[0::2] - data[1::2]
        s = data[1::2] + (t >> 1)
        e = t - s
        e_before = np.roll(e, 1, axis=0)
        c = s + ((e - e_before) >> 1)
        return np.moveaxis(c, 0, axis), np.moveaxis(c + e_before, 0, axis)
    if data.shape[0] < 2:
        return np.moveaxis(data.copy(), 0, axis), np.moveaxis(data[:0].copy(), 0, axis)
    s = data[0::2].copy()
    d = data[1::2].copy()
    if name == "haar":
        d -= s[: len(d)]
        s[: len(d)] += d >> 1
        return np.moveaxis(s, 0, axis), np.moveaxis(d, 0, axis)
    s_right, _, _ = _neighbours(s, d)
    d -= (s[: len(d)] + s_right) >> 1
    _, d_left, d_right = _neighbours(s, d)
    s += (d_left + d_right + 2) >> 2
    if name == "511c":
        d += _curvature(s, len(d), data.shape[0])
    return np.moveaxis(s, 0, axis), np.moveaxis(d, 0, axis)


def _curvature(s: np.ndarray, nd: int, n: int) -> np.ndarray:
    """5/11-C's correction ``(s[i-1] - s[i] - s[i+1] + s[i+2] + 8) >> 4``, with the coarse
    samples taken from the whole-sample symmetric extension of the ``n`` input samples (coarse
    sample ``k`` is input sample ``2k``, mirrored about the first and the last input sample),
    clamped for signals too short to mirror once."""

    def taps(offset: int) -> np.ndarray:
        position = 2 * (np.arange(nd) + offset)
        position = np.where(position < 0, -position, position)
        position = np.where(position > n - 1, 2 * (n - 1) - position, position)
        return s[np.clip(position // 2, 0, len(s) - 1)]

    return (taps(-1) - taps(0) - taps(1) + taps(2) + 8) >> 4


def reference_unlift(coarse: np.ndarray, detail: np.ndarray, axis: int, name: str) -> np.ndarray:
    s = np.moveaxis(np.asarray(coarse, dtype=np.int64), axis, 0).copy()
    d = np.moveaxis(np.asarray(detail, dtype=np.int64), axis, 0).copy()
    if name == "bspline2":
        e_before = d - s
        e = np.roll(e_before, -1, axis=0)
        v = s - ((e - e_before) >> 1)
        t = e + v
        odd = v - (t >> 1)
        out = np.empty((2 * len(s), *s.shape[1:]), dtype=np.int64)
        out[0::2] = t + odd
        out[1::2] = odd
        return np.moveaxis(out, 0, axis)
    if d.shape[0] == 0:
        return np.moveaxis(s, 0, axis)
    if name == "haar":
        s[: len(d)] -= d >> 1
        d += s[: len(d)]
    else:
        if name == "511c":
            d -= _curvature(s, len(d), len(s) + len(d))
        _, d_left, d_right = _neighbours(s, d)
        s -= (d_left + d_right + 2) >> 2
        s_right, _, _ = _neighbours(s, d)
        d += (s[: len(d)] + s_right) >> 1
    out = np.empty((len(s) + len(d), *s.shape[1:]), dtype=np.int64)
    out[0::2] = s
    out[1::2] = d
    return np.moveaxis(out, 0, axis)


@settings(max_examples=150, deadline=None)
@given(
    hnp.arrays(
        np.int64,
        hnp.array_shapes(min_dims=1, max_dims=3, min_side=1, max_side=13),
        elements=st.integers(-(2**62), 2**62 - 1) | st.integers(-300, 300),
    ),
    st.sampled_from(lossless.FILTERS),
    st.data(),
)
def test_kernels_match_the_numpy_formulas(x: np.ndarray, name: str, data: st.DataObject) -> None:
    axis = data.draw(st.integers(0, x.ndim - 1))
    if name == "bspline2" and x.shape[axis] % 2:
        return  # refused (tested in test_lossless.py)
    expected = reference_lift(x, axis, name)
    got = lossless.lift(x, axis, name)
    for mine, theirs in zip(got, expected, strict=True):
        assert mine.shape == theirs.shape
        assert np.array_equal(mine, theirs)
    assert np.array_equal(lossless.unlift(*got, axis, name), reference_unlift(*got, axis, name))
    # Any integers unlift like the formulas do, not only a lift's output.
    rng = np.random.default_rng(x.size)
    other = [rng.integers(-(2**40), 2**40, size=band.shape) for band in got]
    assert np.array_equal(lossless.unlift(*other, axis, name), reference_unlift(*other, axis, name))


@pytest.mark.parametrize("name", lossless.FILTERS)
def test_threads_do_not_change_the_integers(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # Big enough that the thread pool splits the work, along outer (axis 1) and inner (axis 0).
    image = np.random.default_rng(5).integers(0, 65536, (512, 600, 3))
    results = []
    for threads in ("1", "2", "3"):
        monkeypatch.setenv("WAVECORE_THREADS", threads)
        results.append(lossless.forward(image, 3, (0, 1), [name] * 3))
        assert np.array_equal(lossless.inverse(results[-1], (0, 1), [name] * 3), image)
    for other in results[1:]:
        assert np.array_equal(other[0], results[0][0])
        for bands, first in zip(other[1:], results[0][1:], strict=True):
            assert all(np.array_equal(a, b) for a, b in zip(bands, first, strict=True))


def test_mismatched_bands_are_refused() -> None:
    with pytest.raises(wavecore.InvalidParameter, match="one lifting step"):
        lossless.unlift(np.zeros((5, 3), int), np.zeros((2, 3), int))
    with pytest.raises(wavecore.InvalidParameter, match="one lifting step"):
        lossless.unlift(np.zeros((3, 3), int), np.zeros((2, 4), int))
    with pytest.raises(wavecore.InvalidParameter, match="equal shapes"):
        lossless.unlift(np.zeros((3, 3), int), np.zeros((2, 3), int), 0, "bspline2")


@settings(max_examples=80, deadline=None)
@given(
    hnp.arrays(
        np.int64,
        hnp.array_shapes(min_dims=1, max_dims=2, min_side=0, max_side=30),
        elements=st.integers(-50, 50) | st.integers(-(2**62), 2**62),
    )
)
def test_entropy_counts_are_uniques_counts(band: np.ndarray) -> None:
    expected = np.unique(band, return_counts=True)[1]
    got = lossless._value_counts(band)
    assert got.dtype == expected.dtype
    assert np.array_equal(got, expected)


@pytest.mark.parametrize("source", [np.int64, np.int32, np.uint16, np.uint64, np.int8])
@pytest.mark.parametrize("target", ["uint8", "uint16", "int16", "int32", "uint32"])
def test_integer_cast_matches_the_float_route(source: type, target: str) -> None:
    """The decoder's integer fast path (lossless) gives what rounding through float64 gives."""
    from wavecore.codec.samples import cast

    info = np.iinfo(source)
    values = np.random.default_rng(0).integers(info.min, info.max, 5000, source, endpoint=True)
    values[:4] = [info.min, info.max, 0, 1]
    bounds = np.iinfo(target)
    through_floats = np.clip(np.rint(values.astype(np.float64)), bounds.min, bounds.max)
    got = cast(values.reshape(50, 100), target)
    assert got.dtype == np.dtype(target)
    assert np.array_equal(got.reshape(-1), through_floats.astype(target))


def _numpy_predicted_bits(data: np.ndarray) -> float:
    """The first-order entropy of the MED residuals as ``wavecore.lossless`` computed it before
    its compiled histogram: residual arrays, then ``np.unique``'s counts."""
    planes = [data] if data.ndim == 2 else [data[..., c] for c in range(data.shape[2])]
    total = 0.0
    for plane in planes:
        counts = np.unique(lossless.med_residuals(plane), return_counts=True)[1]
        total -= float(np.sum(counts * np.log2(counts / plane.size)))
    return total


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(
        np.int64,
        st.tuples(st.integers(1, 9), st.integers(1, 9), st.sampled_from([1, 3])),
        elements=st.one_of(st.integers(-300, 300), st.integers(-(2**40), 2**40)),
    )
)
def test_predicted_bits_match_the_residual_arrays(data: np.ndarray) -> None:
    # the entropy that choose_depth compares is the same float, to the bit, whichever way the
    # residuals are counted (compiled histogram, or np.unique when their range is too wide)
    plane = data[..., 0] if data.shape[2] == 1 else data
    assert lossless._predicted_bits(plane) == _numpy_predicted_bits(plane)


@pytest.mark.parametrize("name", ["legall53", "511c"])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6, 7, 9, 16, 33])
def test_row_by_row_lifting_matches_a_pass_per_step(name: str, n: int) -> None:
    # Many inner columns are lifted in one pass over the rows (the correction of 5/11-C two
    # rows behind), a few with a pass per step: lifting each column alone takes the latter.
    x = np.random.default_rng(n).integers(-(2**40), 2**40, (n, 3 * kernels._FUSED_LEAST))
    x[:, ::2] = np.cumsum(x[:, ::2] >> 30, axis=0)  # smooth columns too
    together = lossless.lift(x, 0, name)
    for column in range(x.shape[1]):
        alone = lossless.lift(x[:, column : column + 1], 0, name)
        for a, b in zip(together, alone, strict=True):
            assert np.array_equal(a[:, column : column + 1], b)
