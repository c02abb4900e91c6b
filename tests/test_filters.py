"""The filter matrices themselves: biorthogonality, sizes and the paper's printed rows."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import wavecore
from wavecore.errors import InvalidLength, InvalidParameter
from wavecore.filters import (
    _REGISTRY,
    Banded,
    BoundaryRule,
    FilterBank,
    get_wavelet,
    register,
    step_compact,
    step_regular,
    step_sparse,
)

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


@pytest.mark.parametrize(("wavelet", "boundary", "lengths"), CASES)
def test_compressed_rows_equal_the_dense_matrices(
    wavelet: str, boundary: str, lengths: range
) -> None:
    # The fast steps read the matrices in compressed-row form, built without the dense ones.
    for m in [*lengths, 1026]:
        dense = wavecore.matrices(m, wavelet, boundary)
        for matrix, sparse in zip(dense, step_sparse(wavelet, boundary, m), strict=True):
            rebuilt = np.zeros(sparse.shape)
            rows = np.repeat(np.arange(sparse.shape[0]), np.diff(sparse.indptr))
            np.add.at(rebuilt, (rows, sparse.indices), sparse.weights)
            np.testing.assert_array_equal(rebuilt, matrix)
            assert np.all(sparse.weights != 0)


@pytest.mark.parametrize(("wavelet", "boundary", "lengths"), CASES)
def test_regular_interior_is_exactly_the_pattern(
    wavelet: str, boundary: str, lengths: range
) -> None:
    for m in lengths:
        dense = wavecore.matrices(m, wavelet, boundary)
        for matrix, regular in zip(dense, step_regular(wavelet, boundary, m), strict=True):
            taps = regular.pattern.shape[1]
            for b in range(regular.blocks):
                for i in range(regular.p):
                    expected = np.zeros(matrix.shape[1])
                    col = regular.col + b * regular.step
                    expected[col : col + taps] = regular.pattern[i]
                    np.testing.assert_array_equal(matrix[regular.lo + b * regular.p + i], expected)
        if boundary == "open" and wavelet == "bspline2":
            # All rows but the paper's start and end rows are regular.
            A, B, P, Q = step_regular(wavelet, boundary, m)
            r, s = (m + 2) // 2, (m - 2) // 2
            assert (A.blocks, B.blocks, P.blocks, Q.blocks) == (
                r - 4,
                s - 3,
                (m - 4) // 2,
                (m - 8) // 2,
            )
            assert (A.lo, P.lo) == (2, 2)
            assert B.blocks == 0 or B.lo == 2
            assert Q.blocks == 0 or Q.lo == 6


def test_a_new_family_is_one_definition() -> None:
    # A made-up two-tap family registered at run time goes through every code path.
    bank = FilterBank(
        name="test-haar-orthonormal",
        description="orthonormal Haar, only for this test",
        rules={
            b: BoundaryRule(
                A=Banded(pattern=((0.5**0.5, 0.5**0.5),), first=(0, 0), step=(1, 2)),
                B=Banded(pattern=((0.5**0.5, -(0.5**0.5)),), first=(0, 0), step=(1, 2)),
                P=Banded(pattern=((0.5**0.5,), (0.5**0.5,)), first=(0, 0), step=(2, 1)),
                Q=Banded(pattern=((0.5**0.5,), (-(0.5**0.5),)), first=(0, 0), step=(2, 1)),
                extra=0,
                min_length=2,
                periodic=False,
            )
            for b in ("open", "closed")
        },
    )
    register(bank)
    try:
        assert get_wavelet(bank.name) is bank
        image = np.random.default_rng(0).standard_normal((32, 16))
        coeffs = wavecore.wavedec2(image, bank.name, level=3)
        np.testing.assert_allclose(wavecore.waverec2(coeffs, bank.name), image, atol=1e-12)
        # Orthonormal: the energy is preserved band by band.
        energy = np.sum(coeffs[0] ** 2) + sum(np.sum(b**2) for level in coeffs[1:] for b in level)
        np.testing.assert_allclose(energy, np.sum(image**2), rtol=1e-12)
        # Re-registering the name with other filters (details negated) must not reuse the
        # matrices cached for the first definition.
        negated = FilterBank(
            name=bank.name,
            rules={
                b: replace(
                    rule,
                    B=replace(rule.B, pattern=((-(0.5**0.5), 0.5**0.5),)),
                    Q=replace(rule.Q, pattern=((-(0.5**0.5),), (0.5**0.5,))),
                )
                for b, rule in bank.rules.items()
            },
        )
        register(negated)
        again = wavecore.wavedec2(image, bank.name, level=3)
        np.testing.assert_allclose(again[0], coeffs[0], atol=1e-12)
        np.testing.assert_allclose(again[1][2], coeffs[1][2], atol=1e-12)  # detail twice: +
        np.testing.assert_allclose(again[1][0], -coeffs[1][0], atol=1e-12)
        np.testing.assert_allclose(wavecore.waverec2(again, bank.name), image, atol=1e-12)
    finally:
        _REGISTRY.pop(bank.name)


@pytest.mark.parametrize(("wavelet", "boundary", "lengths"), CASES)
def test_compact_form_equals_the_dense_matrices_and_stays_small(
    wavelet: str, boundary: str, lengths: range
) -> None:
    # What the kernels read: the regular interior as a pattern, every other row compressed.
    for m in [*lengths, 1026]:
        dense = wavecore.matrices(m, wavelet, boundary)
        for matrix, (sparse, regular) in zip(
            dense, step_compact(wavelet, boundary, m), strict=True
        ):
            rebuilt = np.zeros(matrix.shape)
            skipped = regular.blocks * regular.p
            for r in range(matrix.shape[0]):
                if regular.blocks and regular.lo <= r < regular.hi:
                    b, i = divmod(r - regular.lo, regular.p)
                    col = regular.col + b * regular.step
                    rebuilt[r, col : col + regular.pattern.shape[1]] = regular.pattern[i]
                    continue
                k = r if r < regular.lo else r - skipped
                for j in range(sparse.indptr[k], sparse.indptr[k + 1]):
                    rebuilt[r, sparse.indices[j]] += sparse.weights[j]
            np.testing.assert_array_equal(rebuilt, matrix)
    # Its size does not grow with the length.
    sizes = [
        sum(
            s.indptr.nbytes + s.indices.nbytes + s.weights.nbytes
            for s, _ in step_compact(wavelet, boundary, m)
        )
        for m in (
            wavecore.valid_length(4096, 1, boundary, wavelet),
            wavecore.valid_length(1 << 20, 1, boundary, wavelet),
        )
    ]
    assert sizes[1] == sizes[0] < 4096
