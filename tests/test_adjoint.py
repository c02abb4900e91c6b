"""wavecore.adjoint: <S c, y> = <c, S* y> for the synthesis S, one step and many levels."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from wavecore import synthesis_step, valid_length, wavedec, wavedec2, waverec, waverec2
from wavecore.adjoint import synthesis_adjoint, synthesis_step_adjoint
from wavecore.errors import InvalidLength, InvalidParameter
from wavecore.filters import get_wavelet
from wavecore.layout import as_levels

CASES = [("bspline2", "open"), ("bspline2", "closed"), ("haar", "open"), ("cdf97", None)]


def _boundary(wavelet: str, boundary: str | None) -> str:
    return boundary if boundary is not None else next(iter(get_wavelet(wavelet).rules))


def _inner(a: list[Any], b: list[Any]) -> float:
    return sum(
        float(np.sum(x * y))
        for u, v in zip(as_levels(a), as_levels(b), strict=True)
        for x, y in zip(u, v, strict=True)
    )


@pytest.mark.parametrize(("wavelet", "boundary"), CASES)
@pytest.mark.parametrize("axis", [0, 1, -1])
def test_one_step_is_the_transpose(wavelet: str, boundary: str | None, axis: int) -> None:
    rng = np.random.default_rng(11)
    b = _boundary(wavelet, boundary)
    n = valid_length(21, 1, b, wavelet)
    shape = [5, 3, 4]
    shape[axis] = n
    y = rng.standard_normal(shape)
    coarse, detail = wavedec(rng.standard_normal(shape), wavelet, b, 1, axis=axis)
    ct, dt = synthesis_step_adjoint(y, wavelet, b, axis)
    assert ct.shape == coarse.shape and dt.shape == detail.shape
    lhs = float(np.sum(synthesis_step(coarse, detail, wavelet, b, axis) * y))
    rhs = float(np.sum(coarse * ct) + np.sum(detail * dt))
    assert lhs == pytest.approx(rhs, rel=1e-10, abs=1e-10)


@pytest.mark.parametrize(("wavelet", "boundary"), CASES)
def test_many_levels_in_two_dimensions(wavelet: str, boundary: str | None) -> None:
    rng = np.random.default_rng(12)
    b = _boundary(wavelet, boundary)
    shape = (valid_length(40, 3, b, wavelet), valid_length(27, 3, b, wavelet), 2)
    c = wavedec2(rng.standard_normal(shape), wavelet, b, 3)
    y = rng.standard_normal(shape)
    back = synthesis_adjoint(y, wavelet, b, 3)
    lhs = float(np.sum(waverec2(c, wavelet, b) * y))
    assert lhs == pytest.approx(_inner(c, back), rel=1e-10, abs=1e-10)


@pytest.mark.parametrize(("wavelet", "boundary"), CASES)
def test_many_levels_along_one_axis(wavelet: str, boundary: str | None) -> None:
    rng = np.random.default_rng(13)
    b = _boundary(wavelet, boundary)
    n = valid_length(70, 4, b, wavelet)
    c = wavedec(rng.standard_normal((n, 3)), wavelet, b, 4, axis=0)
    y = rng.standard_normal((n, 3))
    back = synthesis_adjoint(y, wavelet, b, 4, axes=(0,))
    lhs = float(np.sum(waverec(c, wavelet, b, axis=0) * y))
    assert lhs == pytest.approx(_inner(c, back), rel=1e-10, abs=1e-10)


def test_the_adjoint_is_not_the_analysis() -> None:
    """bspline2 is not orthogonal: what the closed loop needs differs from wavedec's output."""
    y = np.random.default_rng(14).standard_normal(34)
    adjoint = synthesis_adjoint(y, level=1, axes=(0,))
    analysis = wavedec(y, level=1)
    assert not np.allclose(adjoint[0], analysis[0])


def test_bad_input_gets_a_clear_error() -> None:
    with pytest.raises(InvalidLength):
        synthesis_step_adjoint(np.zeros(13))
    with pytest.raises(InvalidParameter, match="boundary"):
        synthesis_step_adjoint(np.zeros(14), boundary="nope")
    with pytest.raises(InvalidParameter, match="axes"):
        synthesis_adjoint(np.zeros((14, 14)), axes=(0, 0))
    with pytest.raises(InvalidParameter, match="level"):
        synthesis_adjoint(np.zeros((14, 14)), level=-1)


@pytest.mark.parametrize(
    ("wavelet", "boundaries"),
    [
        ("bspline2", ("open", "open")),
        ("bspline2", ("closed", "open")),
        ("bspline2", ("open", "closed")),
        ("haar", ("open", "open")),
        ("cdf97", (None, None)),
    ],
)
@pytest.mark.parametrize("trailing", [(), (3,)])
def test_two_dimensional_levels_match_one_axis_at_a_time(
    wavelet: str, boundaries: tuple[str | None, str | None], trailing: tuple[int, ...]
) -> None:
    """Each level over axes (0, 1) runs as one fused pass; it must give what the adjoint of one
    step along axis 0 and then along axis 1 gives (the definition), bit for bit, since the
    quantizer's closed loop iterates on it."""
    rng = np.random.default_rng(15)
    b0, b1 = (_boundary(wavelet, b) for b in boundaries)
    levels = 3
    shape = (valid_length(70, levels, b0, wavelet), valid_length(45, levels, b1, wavelet))
    y = rng.standard_normal(shape + trailing)
    fused = synthesis_adjoint(y, wavelet, (b0, b1), levels)
    coarse, details = y, []
    for _ in range(levels):
        low, high = synthesis_step_adjoint(coarse, wavelet, b0, 0)
        c_h, c_d = synthesis_step_adjoint(high, wavelet, b1, 1)
        coarse, c_v = synthesis_step_adjoint(low, wavelet, b1, 1)
        details.append((c_h, c_v, c_d))
    expected = [coarse, *reversed(details)]
    for got, want in zip(as_levels(fused), as_levels(expected), strict=True):
        for a, b in zip(got, want, strict=True):
            assert a.shape == b.shape
            np.testing.assert_array_equal(a, b)


def test_long_steps_do_not_accumulate_in_the_cache() -> None:
    # A service worker codes curves of many lengths; each long step's transpose holds ~72 B a
    # sample, so only a few of them may stay cached (1.8 GB at 128 lengths of 200 000).
    from wavecore import adjoint

    rng = np.random.default_rng(5)
    adjoint._transposed_long.cache_clear()
    lengths = [
        valid_length(adjoint._LONG_STEP + 1000 * k, 1, "open", "bspline2") for k in range(12)
    ]
    for n in lengths:
        y = rng.standard_normal(n)
        coarse, detail = synthesis_adjoint(y, "bspline2", "open", 1, axes=(0,))[0:2]
        # Still the transpose: <S c, y> = <c, S* y> for a random c.
        c = [rng.standard_normal(coarse.shape), rng.standard_normal(detail.shape)]
        assert np.isclose(
            float(np.sum(waverec(c, "bspline2", "open") * y)), _inner(c, [coarse, detail])
        )
    assert 1 <= adjoint._transposed_long.cache_info().currsize <= 8


@pytest.mark.parametrize(("wavelet", "boundary"), CASES)
def test_the_compact_transposes_are_the_transposes(wavelet: str, boundary: str | None) -> None:
    """The fused adjoint's form of ``P.T`` and ``Q.T`` (boundary rows compressed, one regular
    interior run) holds exactly the matrices' entries, at every length up to 300."""
    from wavecore import matrices
    from wavecore.adjoint import _transposed_compact

    bound = _boundary(wavelet, boundary)
    lengths = sorted({valid_length(n, 1, bound, wavelet) for n in range(2, 300)})
    for m in lengths:
        _, _, P, Q = matrices(m, wavelet, bound)
        for compact, dense in zip(_transposed_compact(wavelet, bound, m), (P.T, Q.T), strict=True):
            ptr, idx, weights, (lo, blocks, col), pattern = compact
            rebuilt = np.zeros_like(dense)
            for r in range(dense.shape[0]):
                if lo <= r < lo + blocks:
                    start = col + 2 * (r - lo)
                    rebuilt[r, start : start + pattern.shape[1]] = pattern[0]
                else:
                    k = r if r < lo else r - blocks
                    rebuilt[r, idx[ptr[k] : ptr[k + 1]]] = weights[ptr[k] : ptr[k + 1]]
            np.testing.assert_array_equal(rebuilt, dense)
