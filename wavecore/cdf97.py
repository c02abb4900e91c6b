"""The CDF 9/7 wavelet (JPEG 2000's irreversible filter), registered as ``"cdf97"``.

JPEG 2000 computes it by lifting: with ``s = x[0::2]`` and ``d = x[1::2]``,

    d += α (s + s→),  s += β (d← + d),  d += γ (s + s→),  s += δ (d← + d),
    s /= K,  d *= K / 2,

where ``s→`` is the next even sample and ``d←`` the previous odd one.  The scaling makes the
analysis low-pass average (DC gain 1), as ``bspline2`` and ``haar`` do here, so coarse
coefficients stay in the data's units; the filters are PyWavelets' ``bior4.4`` divided by √2.

The library applies every filter as banded matrices (:mod:`wavecore.filters`), so this module
*derives* the matrices from the lifting steps: it runs the lifting on unit impulses for one
small length, reads off the start rows, the repeating pattern and the end rows, and registers
the resulting :class:`~wavecore.filters.FilterBank`.  The tests check the matrices against
the lifting itself for many lengths, and biorthogonality.

Boundaries:

``"open"``
    Whole-sample symmetric extension (``x[-1] = x[1]``, ``x[m] = x[m-2]``), as in JPEG 2000.
    A step takes an even ``m >= 8`` samples to ``m / 2`` coarse and ``m / 2`` details.
``"closed"``
    Periodic (``x[m] = x[0]``); any even ``m >= 2``.
"""

from __future__ import annotations

import numpy as np

from .filters import Banded, BoundaryRule, FilterBank, register

__all__ = ["CDF97", "lifting_analysis", "lifting_synthesis"]

ALPHA = -1.586134342059924
BETA = -0.052980118572961
GAMMA = 0.882911075530934
DELTA = 0.443506852043971
K = 1.230174104914001

#: The length whose impulse responses give the blocks: large enough that the start and end
#: blocks never meet the middle.
_DERIVE_LENGTH = 40
_OPEN_MIN_LENGTH = 8


def _neighbours(v: np.ndarray, periodic: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(v[i - 1], v[i + 1])`` along axis 0, periodic or whole-sample symmetric."""
    if periodic:
        return np.roll(v, 1, axis=0), np.roll(v, -1, axis=0)
    # Symmetric about the first and last *samples*: x[-1] = x[1] makes d[-1] = d[0] for the
    # odd phase and x[m] = x[m - 2] makes s[n] = s[n - 1] for the even phase.
    return np.concatenate([v[:1], v[:-1]]), np.concatenate([v[1:], v[-1:]])


def lifting_analysis(x: np.ndarray, periodic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """One analysis step by lifting along axis 0 (the reference the matrices are built from).

    Examples
    --------
    >>> import numpy as np
    >>> s, d = lifting_analysis(np.full(8, 3.0))
    >>> bool(np.allclose(s, 3.0) and np.allclose(d, 0.0))
    True
    """
    x = np.asarray(x, dtype=np.float64)
    s, d = x[0::2].copy(), x[1::2].copy()
    for weight in (ALPHA, GAMMA):
        d += weight * (s + _neighbours(s, periodic)[1])
        s += (BETA if weight == ALPHA else DELTA) * (_neighbours(d, periodic)[0] + d)
    return s / K, d * (K / 2)


def lifting_synthesis(s: np.ndarray, d: np.ndarray, periodic: bool = False) -> np.ndarray:
    """Invert :func:`lifting_analysis`: undo the steps in reverse order.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).random(12)
    >>> bool(np.allclose(lifting_synthesis(*lifting_analysis(x)), x))
    True
    """
    s = np.asarray(s, dtype=np.float64) * K
    d = np.asarray(d, dtype=np.float64) / (K / 2)
    for weight in (GAMMA, ALPHA):
        s -= (DELTA if weight == GAMMA else BETA) * (_neighbours(d, periodic)[0] + d)
        d -= weight * (s + _neighbours(s, periodic)[1])
    x = np.empty((s.shape[0] + d.shape[0], *s.shape[1:]))
    x[0::2], x[1::2] = s, d
    return x


def lifting_matrices(m: int, periodic: bool) -> tuple[np.ndarray, ...]:
    """Dense ``(A, B, P, Q)`` for fine length ``m``, from the lifting applied to impulses."""
    A, B = lifting_analysis(np.eye(m), periodic)
    half = m // 2
    eye = np.eye(half)
    P = lifting_synthesis(eye, np.zeros((half, half)), periodic)
    Q = lifting_synthesis(np.zeros((half, half)), eye, periodic)
    return A, B, P, Q


def _clean(block: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in np.where(abs(block) < 1e-14, 0, block))


def _banded(matrix: np.ndarray, p: int, column_step: int, periodic: bool) -> Banded:
    """Split ``matrix`` into start rows, a pattern repeated every ``p`` rows, and end rows."""
    rows, cols = matrix.shape
    matrix = np.where(abs(matrix) < 1e-14, 0.0, matrix)
    middle = (rows // 2) // p * p
    nonzero = np.flatnonzero(np.any(matrix[middle : middle + p] != 0, axis=0))
    lo, hi = int(nonzero[0]), int(nonzero[-1]) + 1
    pattern = matrix[middle : middle + p, lo:hi]
    if periodic:
        first_col = lo - (middle // p) * column_step
        return Banded(pattern=_clean(pattern), first=(0, first_col), step=(p, column_step))

    def regular_at(row: int) -> bool:
        col = lo + (row - middle) // p * column_step
        if row < 0 or row + p > rows or col < 0 or col + (hi - lo) > cols:
            return False
        expected = np.zeros((p, cols))
        expected[:, col : col + hi - lo] = pattern
        return bool(np.allclose(matrix[row : row + p], expected, rtol=0, atol=1e-13))

    top = middle
    while regular_at(top - p):
        top -= p
    bottom = middle + p
    while regular_at(bottom):
        bottom += p
    start, end = matrix[:top], matrix[bottom:]
    start_width = int(np.flatnonzero(np.any(start != 0, axis=0)).max()) + 1 if top else 0
    end_from = int(np.flatnonzero(np.any(end != 0, axis=0)).min()) if bottom < rows else cols
    return Banded(
        pattern=_clean(pattern),
        first=(top, lo + (top - middle) // p * column_step),
        step=(p, column_step),
        start=_clean(start[:, :start_width]),
        end=_clean(end[:, end_from:]),
    )


def _rule(periodic: bool) -> BoundaryRule:
    A, B, P, Q = lifting_matrices(_DERIVE_LENGTH, periodic)
    return BoundaryRule(
        A=_banded(A, 1, 2, periodic),
        B=_banded(B, 1, 2, periodic),
        P=_banded(P, 2, 1, periodic),
        Q=_banded(Q, 2, 1, periodic),
        extra=0,
        min_length=2 if periodic else _OPEN_MIN_LENGTH,
        periodic=periodic,
    )


CDF97 = register(
    FilterBank(
        name="cdf97",
        aliases=("jpeg2000",),
        description="CDF 9/7, the irreversible filter of JPEG 2000 (lifting, symmetric extension)",
        rules={"open": _rule(False), "closed": _rule(True)},
    )
)
