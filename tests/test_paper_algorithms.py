"""The paper's three algorithms (section 3), written as printed, against our fast steps.

The listings use 1-based indices and loops; they are copied here literally (``F[0]`` is an unused
slot so that ``F[1]`` is the paper's ``F_1``).  RECONSTRUCTION's first lines are garbled in the
text copy; its start (``E_1`` … ``E_6``, ``j = 7``, ``for i = 3 to s - 1``) is taken from
``NOTES.md``, where it was read off the matrix Q of eqs. (16)–(19).  The entries may be vectors
(curve points), as the paper says; ``0 * D[1]`` keeps E's shape for that reason.

Two small vectors are worked by hand in the comments; the expected numbers are the hand results.
"""

from __future__ import annotations

import numpy as np
import pytest

import wavecore


def reduce_resolution(f: np.ndarray) -> np.ndarray:
    m = len(f)
    F = [None, *f]
    C: list = [None] * (m + 2)
    C[1] = F[1]
    C[2] = -1 / 2 * F[1] + F[2] + 3 / 4 * F[3] - 1 / 4 * F[4]
    j = 3
    for i in range(3, m - 5 + 1, 2):  # for i = 3 to m - 5 step 2
        C[j] = -1 / 4 * F[i] + 3 / 4 * F[i + 1] + 3 / 4 * F[i + 2] - 1 / 4 * F[i + 3]
        j = j + 1
    C[j] = -1 / 4 * F[m - 3] + 3 / 4 * F[m - 2] + F[m - 1] - 1 / 2 * F[m]
    C[j + 1] = F[m]
    return np.array(C[1 : j + 2])  # C[1 .. j + 1]


def find_details(f: np.ndarray) -> np.ndarray:
    m = len(f)
    F = [None, *f]
    D: list = [None] * (m + 2)
    D[1] = -1 / 2 * F[1] + F[2] - 3 / 4 * F[3] + 1 / 4 * F[4]
    D[2] = -1 / 4 * F[3] + 3 / 4 * F[4] - 3 / 4 * F[5] + 1 / 4 * F[6]
    j = 3
    for i in range(5, m - 5 + 1, 2):  # for i = 5 to m - 5 step 2
        D[j] = 1 / 4 * F[i] - 3 / 4 * F[i + 1] + 3 / 4 * F[i + 2] - 1 / 4 * F[i + 3]
        j = j + 1
    D[j] = 1 / 4 * F[m - 3] - 3 / 4 * F[m - 2] + F[m - 1] - 1 / 2 * F[m]
    return np.array(D[1 : j + 1])  # D[1 .. j]


def reconstruction(c: np.ndarray, d: np.ndarray) -> np.ndarray:
    r, s = len(c), len(d)
    C = [None, *c]
    D = [None, *d]
    E: list = [None] * (r + s + 2)
    F: list = [None] * (r + s + 2)
    E[1] = 0 * D[1]
    E[2] = 1 / 2 * D[1]
    E[3] = -3 / 4 * D[1] + 1 / 4 * D[2]
    E[4] = -1 / 4 * D[1] + 3 / 4 * D[2]
    E[5] = -3 / 4 * D[2] - 1 / 4 * D[3]
    E[6] = -1 / 4 * D[2] - 3 / 4 * D[3]
    j = 7
    for i in range(3, s - 1 + 1):  # for i = 3 to s - 1
        E[j] = 3 / 4 * D[i] - 1 / 4 * D[i + 1]
        E[j + 1] = 1 / 4 * D[i] - 3 / 4 * D[i + 1]
        j = j + 2
    E[j] = 1 / 2 * D[s]
    E[j + 1] = 0 * D[s]
    F[1] = C[1] + E[1]
    F[2] = 1 / 2 * C[1] + 1 / 2 * C[2] + E[2]
    j = 3
    for i in range(2, r - 2 + 1):  # for i = 2 to r - 2
        F[j] = 3 / 4 * C[i] + 1 / 4 * C[i + 1] + E[j]
        F[j + 1] = 1 / 4 * C[i] + 3 / 4 * C[i + 1] + E[j + 1]
        j = j + 2
    F[j] = 1 / 2 * C[r - 1] + 1 / 2 * C[r] + E[j]
    F[j + 1] = C[r] + E[j + 1]
    return np.array(F[1 : j + 2])  # F[1 .. j + 1]


def test_m8_worked_by_hand() -> None:
    f = np.array([4.0, 8, 0, 4, 12, 4, 8, 0])
    # C1 = F1 = 4
    # C2 = -1/2·4 + 8 + 3/4·0 - 1/4·4 = -2 + 8 - 1 = 5
    # loop i = 3 (to m-5 = 3): C3 = -1/4·0 + 3/4·4 + 3/4·12 - 1/4·4 = 3 + 9 - 1 = 11
    # C4 = -1/4·F5 + 3/4·F6 + F7 - 1/2·F8 = -3 + 3 + 8 - 0 = 8
    # C5 = F8 = 0
    coarse = [4, 5, 11, 8, 0]
    # D1 = -1/2·4 + 8 - 3/4·0 + 1/4·4 = -2 + 8 + 1 = 7
    # D2 = -1/4·0 + 3/4·4 - 3/4·12 + 1/4·4 = 3 - 9 + 1 = -5
    # loop i = 5 to 3: empty
    # D3 = 1/4·12 - 3/4·4 + 8 - 1/2·0 = 3 - 3 + 8 = 8
    details = [7, -5, 8]
    # RECONSTRUCTION: E = (0, 3.5, -6.5, -5.5, 1.75, -4.75, 4, 0)
    # F1 = 4 + 0 = 4;  F2 = 2 + 2.5 + 3.5 = 8;  F3 = 3.75 + 2.75 - 6.5 = 0;
    # F4 = 1.25 + 8.25 - 5.5 = 4;  F5 = 8.25 + 2 + 1.75 = 12;  F6 = 2.75 + 6 - 4.75 = 4;
    # F7 = 4 + 0 + 4 = 8;  F8 = 0 + 0 = 0  — the input again.
    _check_worked_example(f, coarse, details)


def test_m10_worked_by_hand() -> None:
    f = np.array([0.0, 4, 8, 4, 0, 4, 8, 12, 8, 4])
    # C1 = 0;  C2 = 0 + 4 + 6 - 1 = 9
    # i = 3: C3 = -2 + 3 + 0 - 1 = 0;  i = 5: C4 = 0 + 3 + 6 - 3 = 6
    # C5 = -1/4·8 + 3/4·12 + 8 - 1/2·4 = -2 + 9 + 8 - 2 = 13;  C6 = F10 = 4
    coarse = [0, 9, 0, 6, 13, 4]
    # D1 = 0 + 4 - 6 + 1 = -1;  D2 = -2 + 3 - 0 + 1 = 2
    # i = 5: D3 = 0 - 3 + 6 - 3 = 0
    # D4 = 1/4·8 - 3/4·12 + 8 - 1/2·4 = 2 - 9 + 8 - 2 = -1
    details = [-1, 2, 0, -1]
    # E = (0, -0.5, 1.25, 1.75, -1.5, -0.5, 0.25, 0.75, -0.5, 0)   (loop i = 3 gives E7, E8)
    # F = (0, 4.5-0.5, 6.75+1.25, 2.25+1.75, 1.5-1.5, 4.5-0.5, 4.5+3.25+0.25,
    #      1.5+9.75+0.75, 6.5+2-0.5, 4) = (0, 4, 8, 4, 0, 4, 8, 12, 8, 4)
    _check_worked_example(f, coarse, details)


def _check_worked_example(f: np.ndarray, coarse: list[float], details: list[float]) -> None:
    np.testing.assert_array_equal(reduce_resolution(f), coarse)
    np.testing.assert_array_equal(find_details(f), details)
    np.testing.assert_array_equal(reconstruction(np.array(coarse), np.array(details)), f)
    c, d = wavecore.analysis_step(f)
    np.testing.assert_allclose(c, coarse, atol=1e-14)
    np.testing.assert_allclose(d, details, atol=1e-14)
    np.testing.assert_allclose(wavecore.synthesis_step(c, d), f, atol=1e-14)


@pytest.mark.parametrize("m", range(8, 64, 2))
def test_listings_equal_the_fast_steps(m: int) -> None:
    f = np.random.default_rng(m).standard_normal(m)
    c, d = wavecore.analysis_step(f)
    np.testing.assert_allclose(reduce_resolution(f), c, atol=1e-13)
    np.testing.assert_allclose(find_details(f), d, atol=1e-13)
    np.testing.assert_allclose(reconstruction(c, d), wavecore.synthesis_step(c, d), atol=1e-13)
    # With arbitrary (not analysed) coefficients too: RECONSTRUCTION is P C + Q D for any C, D.
    rng = np.random.default_rng(m + 1)
    c2, d2 = rng.standard_normal(len(c)), rng.standard_normal(len(d))
    np.testing.assert_allclose(reconstruction(c2, d2), wavecore.synthesis_step(c2, d2), atol=1e-13)


@pytest.mark.parametrize("m", [8, 14, 34])
def test_listings_on_curve_points(m: int) -> None:
    # "F_i can be viewed as a coordinate vector": the listings run unchanged on 3-D points.
    points = np.random.default_rng(m).standard_normal((m, 3))
    c, d = wavecore.analysis_step(points)
    np.testing.assert_allclose(reduce_resolution(points), c, atol=1e-13)
    np.testing.assert_allclose(find_details(points), d, atol=1e-13)
    np.testing.assert_allclose(reconstruction(c, d), points, atol=1e-13)
