"""The filter matrices themselves: biorthogonality, sizes and the paper's printed rows."""

from __future__ import annotations

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidLength, InvalidParameter

CASES = [
    ("bspline2", "open", range(8, 72, 2)),
    ("bspline2", "closed", range(2, 40, 2)),
    ("haar", "open", range(2, 40, 2)),
    ("haar", "closed", range(2, 40, 2)),
]


@pytest.mark.parametrize(("wavelet", "boundary", "lengths"), CASES)
def test_biorthogonal_both_ways(wavelet: str, boundary: str, lengths: range) -> None:
    for m in lengths:
        A, B, P, Q = wavecore.matrices(m, wavelet, boundary)
        analysis = np.vstack([A, B])
        synthesis = np.hstack([P, Q])
        assert analysis.shape == synthesis.shape == (m, m)
        np.testing.assert_allclose(analysis @ synthesis, np.eye(m), atol=1e-13)
        np.testing.assert_allclose(synthesis @ analysis, np.eye(m), atol=1e-13)


def test_open_sizes_follow_the_paper() -> None:
    for m in range(8, 40, 2):
        A, B, P, Q = wavecore.matrices(m)
        assert A.shape == ((m + 2) // 2, m)
        assert B.shape == ((m - 2) // 2, m)
        assert P.shape == (m, (m + 2) // 2)
        assert Q.shape == (m, (m - 2) // 2)


def test_open_rows_are_the_printed_ones() -> None:
    A, B, P, Q = wavecore.matrices(12)
    np.testing.assert_array_equal(A[0, :4], [1, 0, 0, 0])
    np.testing.assert_array_equal(A[1, :4], [-0.5, 1, 0.75, -0.25])
    np.testing.assert_array_equal(A[2, 2:6], [-0.25, 0.75, 0.75, -0.25])
    np.testing.assert_array_equal(A[-2, -4:], [-0.25, 0.75, 1, -0.5])
    np.testing.assert_array_equal(A[-1, -4:], [0, 0, 0, 1])
    np.testing.assert_array_equal(B[0, :6], [-0.5, 1, -0.75, 0.25, 0, 0])
    np.testing.assert_array_equal(B[1, :6], [0, 0, -0.25, 0.75, -0.75, 0.25])
    np.testing.assert_array_equal(B[2, 4:8], [0.25, -0.75, 0.75, -0.25])
    np.testing.assert_array_equal(B[-1, -4:], [0.25, -0.75, 1, -0.5])
    np.testing.assert_array_equal(P[:2, :2], [[1, 0], [0.5, 0.5]])
    np.testing.assert_array_equal(P[2:4, 1:3], [[0.75, 0.25], [0.25, 0.75]])
    np.testing.assert_array_equal(P[-2:, -2:], [[0.5, 0.5], [0, 1]])
    np.testing.assert_array_equal(
        Q[:6, :3],
        [
            [0, 0, 0],
            [0.5, 0, 0],
            [-0.75, 0.25, 0],
            [-0.25, 0.75, 0],
            [0, -0.75, -0.25],
            [0, -0.25, -0.75],
        ],
    )
    np.testing.assert_array_equal(Q[6:8, 2:4], [[0.75, -0.25], [0.25, -0.75]])
    np.testing.assert_array_equal(Q[-2:, -1], [0.5, 0])
    # Every matrix row is a local filter: at most four (six for B's second start row) taps.
    assert max(np.count_nonzero(row) for row in np.vstack([A, B])) <= 4


def test_closed_alignment_matches_the_notes() -> None:
    A, B, P, Q = wavecore.matrices(12, boundary="closed")
    n = 6
    for j in range(n):
        cols = [(2 * j - 2) % 12, (2 * j - 1) % 12, 2 * j, 2 * j + 1]
        np.testing.assert_array_equal(A[j, cols], [-0.25, 0.75, 0.75, -0.25])
        np.testing.assert_array_equal(B[j, cols], [0.25, -0.75, 0.75, -0.25])
        np.testing.assert_array_equal(
            P[[2 * j, 2 * j + 1]][:, [j, (j + 1) % n]], [[0.75, 0.25], [0.25, 0.75]]
        )
        np.testing.assert_array_equal(
            Q[[2 * j, 2 * j + 1]][:, [j, (j + 1) % n]], [[0.75, -0.25], [0.25, -0.75]]
        )


def test_bad_lengths_and_names() -> None:
    with pytest.raises(InvalidLength, match="at least 8"):
        wavecore.matrices(6)
    with pytest.raises(InvalidLength, match="even"):
        wavecore.matrices(11, boundary="closed")
    with pytest.raises(InvalidParameter, match=r"'bspline2'.*'haar'"):
        wavecore.matrices(8, wavelet="db4")
    with pytest.raises(InvalidParameter, match="'closed'"):
        wavecore.matrices(8, boundary="periodic")
    assert wavecore.matrices(8, "chaikin")[0].tolist() == wavecore.matrices(8)[0].tolist()
