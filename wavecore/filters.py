"""Filter definitions, as data.

A wavelet here is a :class:`FilterBank`: for each boundary it holds the four banded matrices of
the paper's section 2 (analysis ``A``, ``B``; synthesis ``P``, ``Q``) in the paper's own block
form — explicit *start* rows, a *regular* pattern that repeats down the diagonal, explicit *end*
rows — and the size rule that says which fine lengths it accepts.  Everything else (the fast
steps, the dense matrices, the size functions) is derived from that data, so a new filter family
is one new definition at the bottom of this file.

Index conventions are 0-based.  The closed (periodic) alignment is the one verified in
``NOTES.md``: Chaikin's rule ``f[2i] = 3/4 c[i] + 1/4 c[i+1]``, ``f[2i+1] = 1/4 c[i] + 3/4 c[i+1]``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .errors import InvalidLength, InvalidParameter

__all__ = [
    "BOUNDARIES",
    "Banded",
    "BoundaryRule",
    "FilterBank",
    "Regular",
    "Sparse",
    "get_wavelet",
    "matrices",
    "wavelet_names",
]

BOUNDARIES = ("open", "closed")


@dataclass(frozen=True)
class Banded:
    """One banded matrix in the paper's block form.

    Parameters
    ----------
    pattern : tuple of tuple of float
        The regular block: ``p`` rows of ``w`` weights, placed again and again down the
        diagonal.
    first : tuple of int
        ``(row, column)`` of the first placement of ``pattern`` (the column may be negative
        for periodic matrices, where columns wrap).
    step : tuple of int
        How far each next placement moves, ``(rows, columns)``; ``rows`` is always ``p``.
    start : tuple of tuple of float
        Dense rows placed at the top-left corner (the paper's ``X_s`` block); empty when closed.
    end : tuple of tuple of float
        Dense rows placed at the bottom-right corner (the paper's ``X_e`` block).
    """

    pattern: tuple[tuple[float, ...], ...]
    first: tuple[int, int]
    step: tuple[int, int]
    start: tuple[tuple[float, ...], ...] = ()
    end: tuple[tuple[float, ...], ...] = ()

    def dense(self, rows: int, cols: int, periodic: bool) -> np.ndarray:
        """Build the ``rows × cols`` matrix (float64).

        Periodic matrices wrap columns modulo ``cols`` and *add* the taps that land on the same
        column, which is what tiny closed sizes need (see ``NOTES.md``).
        """
        out = np.zeros((rows, cols))
        if self.start:
            start = np.array(self.start, dtype=float)
            out[: start.shape[0], : start.shape[1]] += start
        if self.end:
            end = np.array(self.end, dtype=float)
            out[rows - end.shape[0] :, cols - end.shape[1] :] += end
        pattern = np.array(self.pattern, dtype=float)
        p, w = pattern.shape
        regular_rows = rows - len(self.start) - len(self.end)
        if regular_rows < 0 or regular_rows % p:
            msg = f"{rows} rows cannot hold the start, end and regular blocks"
            raise InvalidLength(msg)
        row, col = self.first
        for _ in range(regular_rows // p):
            columns = np.arange(col, col + w)
            if periodic:
                columns %= cols
            elif columns[0] < 0 or columns[-1] >= cols:
                msg = f"a regular row does not fit in {cols} columns"
                raise InvalidLength(msg)
            for i in range(p):
                np.add.at(out[row + i], columns, pattern[i])
            row += self.step[0]
            col += self.step[1]
        return out

    def _check_rows(self, rows: int) -> int:
        p = len(self.pattern)
        regular_rows = rows - len(self.start) - len(self.end)
        if regular_rows < 0 or regular_rows % p:
            msg = f"{rows} rows cannot hold the start, end and regular blocks"
            raise InvalidLength(msg)
        return regular_rows // p

    def sparse(self, rows: int, cols: int, periodic: bool) -> Sparse:
        """The same matrix as :meth:`dense`, in compressed-row form, built without it."""
        blocks = self._check_rows(rows)
        return self._rows(rows, cols, periodic, np.arange(blocks), 0, 0)

    def _rows(
        self,
        rows: int,
        cols: int,
        periodic: bool,
        placements: np.ndarray,
        skip_lo: int,
        skip_hi: int,
    ) -> Sparse:
        """Compressed rows from the start and end blocks and the given ``placements``.

        Rows ``[skip_lo, skip_hi)`` are left out of the row pointers (they are the regular
        interior, which the kernels compute from the pattern): row ``r >= skip_hi`` has its
        entries at ``indptr[r - (skip_hi - skip_lo)]``.
        """
        pattern = np.array(self.pattern, dtype=float)
        p, w = pattern.shape
        parts_r, parts_c, parts_v = [], [], []
        for block, row0, col0 in (
            (self.start, 0, 0),
            (self.end, rows - len(self.end), cols - (len(self.end[0]) if self.end else 0)),
        ):
            if block:
                dense = np.array(block, dtype=float)
                r, c = np.nonzero(dense)
                parts_r.append(r + row0)
                parts_c.append(c + col0)
                parts_v.append(dense[r, c])
        count = len(placements)
        b = placements[:, None, None]
        i = np.arange(p)[None, :, None]
        t = np.arange(w)[None, None, :]
        r = np.broadcast_to(self.first[0] + b * self.step[0] + i, (count, p, w)).ravel()
        c = np.broadcast_to(self.first[1] + b * self.step[1] + t, (count, p, w)).ravel()
        if periodic:
            c = c % cols
        elif count and (c.min() < 0 or c.max() >= cols):
            msg = f"a regular row does not fit in {cols} columns"
            raise InvalidLength(msg)
        parts_r.append(r)
        parts_c.append(c)
        parts_v.append(np.broadcast_to(pattern[None], (count, p, w)).ravel())
        all_r, all_c, all_v = (np.concatenate(x) for x in (parts_r, parts_c, parts_v))
        # Taps that land on the same entry add up (start/end overlap, tiny periodic sizes).
        flat = all_r.astype(np.int64) * cols + all_c
        keys, inverse = np.unique(flat, return_inverse=True)
        values = np.zeros(len(keys))
        np.add.at(values, inverse, all_v)
        keep = values != 0
        keys, values = keys[keep], values[keep]
        out_r, out_c = np.divmod(keys, cols)
        if np.any((out_r >= skip_lo) & (out_r < skip_hi)):
            msg = "an entry outside the placements fell into the regular interior"
            raise AssertionError(msg)
        out_r = np.where(out_r >= skip_hi, out_r - (skip_hi - skip_lo), out_r)
        indptr = np.zeros(rows - (skip_hi - skip_lo) + 1, dtype=np.intp)
        np.add.at(indptr, out_r + 1, 1)
        return Sparse(
            indptr=np.cumsum(indptr),
            indices=out_c.astype(np.intp),
            weights=values,
            shape=(rows, cols),
        )

    def compact(self, rows: int, cols: int, periodic: bool) -> tuple[Sparse, Regular]:
        """The matrix as its regular interior plus compressed rows for every other row.

        Takes memory and time independent of the size: the interior is the pattern, and only
        the start rows, end rows and wrapped placements are stored (row pointers cover those
        rows only; see :meth:`_rows`).  Without a regular interior (tiny sizes) every row is
        stored.
        """
        blocks = self._check_rows(rows)
        regular = self.regular(rows, cols)
        if not regular.blocks:
            return self.sparse(rows, cols, periodic), regular
        p = regular.p
        first_block = (regular.lo - self.first[0]) // p
        outside = np.concatenate(
            [np.arange(first_block), np.arange(first_block + regular.blocks, blocks)]
        )
        sparse = self._rows(rows, cols, periodic, outside, regular.lo, regular.hi)
        return sparse, regular

    def regular(self, rows: int, cols: int) -> Regular:
        """The placements of ``pattern`` that neither wrap nor meet the start or end rows."""
        blocks = self._check_rows(rows)
        pattern = np.array(self.pattern, dtype=float)
        p, w = pattern.shape
        row0, col0 = self.first
        step = self.step[1]
        b_lo, b_hi = 0, blocks
        if step > 0:
            b_lo = max(0, -(col0 // step)) if col0 < 0 else 0
            b_hi = min(blocks, (cols - w - col0) // step + 1)
        if row0 < len(self.start) or row0 + blocks * p > rows - len(self.end) or b_hi <= b_lo:
            return Regular(lo=0, blocks=0, p=p, col=0, step=step, pattern=pattern)
        return Regular(
            lo=row0 + b_lo * p,
            blocks=b_hi - b_lo,
            p=p,
            col=col0 + b_lo * step,
            step=step,
            pattern=pattern,
        )


@dataclass(frozen=True)
class BoundaryRule:
    """The four matrices of one wavelet at one boundary, and its size rule.

    One analysis step takes ``m`` fine samples to ``(m + extra) // 2`` coarse samples and
    ``(m - extra) // 2`` details; ``m`` must be even and at least ``min_length``.
    """

    A: Banded
    B: Banded
    P: Banded
    Q: Banded
    extra: int
    min_length: int
    periodic: bool

    def coarse_length(self, m: int) -> int:
        """Number of coarse samples one step makes from ``m`` fine samples."""
        return (m + self.extra) // 2

    def detail_length(self, m: int) -> int:
        """Number of details one step makes from ``m`` fine samples."""
        return (m - self.extra) // 2

    def fine_length(self, coarse: int, detail: int) -> int:
        """The fine length that one synthesis step makes from these coefficient lengths."""
        return coarse + detail

    def fits(self, m: int, level: int) -> bool:
        """Whether ``m`` fine samples can be decomposed ``level`` times."""
        for _ in range(level):
            if m % 2 or m < self.min_length:
                return False
            m = self.coarse_length(m)
        return True

    def smallest_k(self, level: int) -> int:
        """Smallest ``k`` such that ``2**level * k + extra`` fits ``level`` levels."""
        k = 1
        while level and not self.fits((1 << level) * k + self.extra, level):
            k += 1
        return k


@dataclass(frozen=True)
class FilterBank:
    """A wavelet family: its name, aliases, and one :class:`BoundaryRule` per boundary.

    Parameters
    ----------
    name : str
        The canonical name (``"bspline2"``).
    rules : mapping of str to BoundaryRule
        One rule for each of :data:`BOUNDARIES`.
    aliases : tuple of str
        Other accepted names.
    description : str
        One line for documentation and error messages.
    """

    name: str
    rules: Mapping[str, BoundaryRule]
    aliases: tuple[str, ...] = ()
    description: str = ""
    notes: str = field(default="", repr=False)

    def rule(self, boundary: str) -> BoundaryRule:
        """The :class:`BoundaryRule` for ``boundary``, with a clear error for unknown names."""
        try:
            return self.rules[boundary]
        except (KeyError, TypeError):
            accepted = ", ".join(repr(b) for b in BOUNDARIES)
            msg = f"unknown boundary {boundary!r} (boundary=); accepted boundaries are {accepted}"
            raise InvalidParameter(msg) from None


_Q = 0.25
_H = 0.5
_T = 0.75

# The paper's quadratic B-spline filters, eqs. (4)–(19), and their closed form (section 4.4).
BSPLINE2 = FilterBank(
    name="bspline2",
    aliases=("chaikin",),
    description="local filters of quadratic B-spline wavelets (Samavati & Bartels)",
    rules={
        "open": BoundaryRule(
            A=Banded(
                start=((1, 0, 0, 0), (-_H, 1, _T, -_Q)),
                pattern=((-_Q, _T, _T, -_Q),),
                first=(2, 2),
                step=(1, 2),
                end=((-_Q, _T, 1, -_H), (0, 0, 0, 1)),
            ),
            B=Banded(
                start=((-_H, 1, -_T, _Q, 0, 0), (0, 0, -_Q, _T, -_T, _Q)),
                pattern=((_Q, -_T, _T, -_Q),),
                first=(2, 4),
                step=(1, 2),
                end=((_Q, -_T, 1, -_H),),
            ),
            P=Banded(
                start=((1, 0), (_H, _H)),
                pattern=((_T, _Q), (_Q, _T)),
                first=(2, 1),
                step=(2, 1),
                end=((_H, _H), (0, 1)),
            ),
            Q=Banded(
                start=(
                    (0, 0, 0),
                    (_H, 0, 0),
                    (-_T, _Q, 0),
                    (-_Q, _T, 0),
                    (0, -_T, -_Q),
                    (0, -_Q, -_T),
                ),
                pattern=((_T, -_Q), (_Q, -_T)),
                first=(6, 2),
                step=(2, 1),
                end=((_H,), (0,)),
            ),
            extra=2,
            min_length=8,
            periodic=False,
        ),
        "closed": BoundaryRule(
            A=Banded(pattern=((-_Q, _T, _T, -_Q),), first=(0, -2), step=(1, 2)),
            B=Banded(pattern=((_Q, -_T, _T, -_Q),), first=(0, -2), step=(1, 2)),
            P=Banded(pattern=((_T, _Q), (_Q, _T)), first=(0, 0), step=(2, 1)),
            Q=Banded(pattern=((_T, -_Q), (_Q, -_T)), first=(0, 0), step=(2, 1)),
            extra=0,
            min_length=2,
            periodic=True,
        ),
    },
)

# Haar in the paper's (averaging) normalisation: c = (a + b) / 2, d = (a - b) / 2.  It has no
# boundary rows, so "open" and "closed" are the same matrices and the same size rule
# (any even length; 2**L * k for L levels).
_HAAR_RULE = BoundaryRule(
    A=Banded(pattern=((_H, _H),), first=(0, 0), step=(1, 2)),
    B=Banded(pattern=((_H, -_H),), first=(0, 0), step=(1, 2)),
    P=Banded(pattern=((1,), (1,)), first=(0, 0), step=(2, 1)),
    Q=Banded(pattern=((1,), (-1,)), first=(0, 0), step=(2, 1)),
    extra=0,
    min_length=2,
    periodic=False,
)
HAAR = FilterBank(
    name="haar",
    description="Haar wavelets, the paper's baseline (averaging normalisation)",
    rules={"open": _HAAR_RULE, "closed": _HAAR_RULE},
)

_REGISTRY: dict[str, FilterBank] = {}

# Functions that forget what they cached under a wavelet's name (here and in transform.py).
CACHE_CLEARERS: list[Callable[[], None]] = []


def register(bank: FilterBank) -> FilterBank:
    """Make ``bank`` available by its name and aliases; returns it, for use as a decorator.

    Registering a different bank under a name already in use replaces it, and drops every
    cached matrix so that nothing computed for the old one is used again.
    """
    keys = (bank.name, *bank.aliases)
    if any(key in _REGISTRY and _REGISTRY[key] is not bank for key in keys):
        for clear in CACHE_CLEARERS:
            clear()
    for key in keys:
        _REGISTRY[key] = bank
    return bank


register(BSPLINE2)
register(HAAR)


def wavelet_names() -> list[str]:
    """The accepted wavelet names, aliases included, sorted."""
    return sorted(_REGISTRY)


def get_wavelet(wavelet: str | FilterBank) -> FilterBank:
    """Look a wavelet up by name (or pass a :class:`FilterBank` through).

    Raises
    ------
    InvalidParameter
        For an unknown name; the message lists the accepted ones.
    """
    if isinstance(wavelet, FilterBank):
        return wavelet
    try:
        return _REGISTRY[wavelet]
    except (KeyError, TypeError):
        accepted = ", ".join(repr(n) for n in wavelet_names())
        given = repr(wavelet)
        if len(given) > 80:  # a client's 5 kB name is not echoed back whole
            given = given[:60] + f"… ({len(given)} characters)"
        msg = f"unknown wavelet {given}; accepted wavelets are {accepted}"
        raise InvalidParameter(msg) from None


@dataclass(frozen=True)
class Sparse:
    """A matrix in compressed-row form, as the fast kernels read it."""

    indptr: np.ndarray
    indices: np.ndarray
    weights: np.ndarray
    shape: tuple[int, int]

    @classmethod
    def from_dense(cls, dense: np.ndarray) -> Sparse:
        rows, cols = np.nonzero(dense)
        indptr = np.zeros(dense.shape[0] + 1, dtype=np.intp)
        np.add.at(indptr, rows + 1, 1)
        return cls(
            indptr=np.cumsum(indptr),
            indices=cols.astype(np.intp),
            weights=dense[rows, cols],
            shape=(int(dense.shape[0]), int(dense.shape[1])),
        )

    def as_dtype(self, dtype: np.dtype) -> np.ndarray:
        return self.weights.astype(dtype)


def check_fine_length(rule: BoundaryRule, m: int, wavelet: str, boundary: str) -> None:
    """Raise :class:`InvalidLength` unless one step can take ``m`` fine samples."""
    if m % 2 or m < rule.min_length:
        msg = (
            f"length {m} does not fit one level of the {boundary} boundary of {wavelet!r}: "
            f"it needs an even length of at least {rule.min_length} (wavecore.pad_to_fit and "
            "the decompose_* functions fit any size)"
        )
        raise InvalidLength(msg)


#: The longest length :func:`matrices` builds: dense matrices cost m² (2048: 64 MiB for all four).
MAX_DENSE_LENGTH = 2048


@lru_cache(maxsize=4)
def _step_matrices(bank_name: str, boundary: str, m: int) -> tuple[np.ndarray, ...]:
    bank = get_wavelet(bank_name)
    rule = bank.rule(boundary)
    check_fine_length(rule, m, bank.name, boundary)
    r, s = rule.coarse_length(m), rule.detail_length(m)
    mats = (
        rule.A.dense(r, m, rule.periodic),
        rule.B.dense(s, m, rule.periodic),
        rule.P.dense(m, r, rule.periodic),
        rule.Q.dense(m, s, rule.periodic),
    )
    for mat in mats:
        mat.setflags(write=False)
    return mats


def _rows_and_columns(rule: BoundaryRule, m: int) -> dict[str, tuple[int, int]]:
    r, s = rule.coarse_length(m), rule.detail_length(m)
    return {"A": (r, m), "B": (s, m), "P": (m, r), "Q": (m, s)}


#: The longest fine length whose :func:`step_sparse` is cached (about 400 bytes a sample).
SPARSE_CACHED_LENGTH = 1 << 16


def step_sparse(bank_name: str, boundary: str, m: int) -> tuple[Sparse, Sparse, Sparse, Sparse]:
    """The four step matrices for fine length ``m`` in compressed-row form (cached up to
    :data:`SPARSE_CACHED_LENGTH`).

    Built from the compact form (:func:`step_compact`) by writing the regular interior out,
    without a dense matrix and without sorting, so that large lengths cost memory and time in
    proportion to ``m``.  It stores every row, so only a few short ones are kept, and long
    ones are built anew (a cache of eight 1M-sample lengths would hold 3 GB); the transform
    itself reads :func:`step_compact`.
    """
    if m > SPARSE_CACHED_LENGTH:
        return _step_sparse(bank_name, boundary, m)
    return _step_sparse_cached(bank_name, boundary, m)


@lru_cache(maxsize=8)
def _step_sparse_cached(
    bank_name: str, boundary: str, m: int
) -> tuple[Sparse, Sparse, Sparse, Sparse]:
    return _step_sparse(bank_name, boundary, m)


def _step_sparse(bank_name: str, boundary: str, m: int) -> tuple[Sparse, Sparse, Sparse, Sparse]:
    compact = step_compact(bank_name, boundary, m)
    return tuple(_full_rows(sparse, regular) for sparse, regular in compact)  # type: ignore[return-value]


def _full_rows(sparse: Sparse, regular: Regular) -> Sparse:
    """Every row of a matrix in compact form, in compressed-row form."""
    if not regular.blocks:
        return sparse
    lo = regular.lo
    head_end = int(sparse.indptr[lo])
    phase_columns = [np.flatnonzero(regular.pattern[i]) for i in range(regular.p)]
    per_block = sum(len(c) for c in phase_columns)
    starts = regular.col + regular.step * np.arange(regular.blocks)
    columns = np.concatenate([starts[:, None] + c[None, :] for c in phase_columns], axis=1)
    weights = np.concatenate(
        [
            np.broadcast_to(regular.pattern[i, c], (regular.blocks, len(c)))
            for i, c in enumerate(phase_columns)
        ],
        axis=1,
    )
    counts = np.tile([len(c) for c in phase_columns], regular.blocks)
    tail_ptr = sparse.indptr[lo:] - head_end
    middle_end = head_end + regular.blocks * per_block
    indptr = np.concatenate(
        [sparse.indptr[: lo + 1], head_end + np.cumsum(counts), middle_end + tail_ptr[1:]]
    )
    return Sparse(
        indptr=indptr.astype(np.intp),
        indices=np.concatenate(
            [sparse.indices[:head_end], columns.ravel(), sparse.indices[head_end:]]
        ).astype(np.intp),
        weights=np.concatenate(
            [sparse.weights[:head_end], weights.ravel(), sparse.weights[head_end:]]
        ),
        shape=sparse.shape,
    )


@lru_cache(maxsize=1024)
def step_compact(
    bank_name: str, boundary: str, m: int
) -> tuple[
    tuple[Sparse, Regular], tuple[Sparse, Regular], tuple[Sparse, Regular], tuple[Sparse, Regular]
]:
    """``A, B, P, Q`` for fine length ``m`` as (boundary rows, regular interior) (cached).

    What the transform's kernels read.  Its size does not grow with ``m``, so many lengths can
    be cached; :func:`step_sparse` stores every row.
    """
    bank = get_wavelet(bank_name)
    rule = bank.rule(boundary)
    check_fine_length(rule, m, bank.name, boundary)
    sizes = _rows_and_columns(rule, m)
    A, B, P, Q = (
        getattr(rule, name).compact(*sizes[name], rule.periodic) for name in ("A", "B", "P", "Q")
    )
    return A, B, P, Q


@dataclass(frozen=True)
class Regular:
    """The rows of a banded matrix that are one repeated pattern, for the vectorised kernels.

    Rows ``lo + b * p + i`` (``0 <= b < blocks``, ``0 <= i < p``) hold ``pattern[i]`` in
    columns ``col + b * step`` onwards, with no wrap-around; every other row is taken from the
    compressed-row form.
    """

    lo: int
    blocks: int
    p: int
    col: int
    step: int
    pattern: np.ndarray

    @property
    def hi(self) -> int:
        return self.lo + self.blocks * self.p


@lru_cache(maxsize=256)
def step_regular(
    bank_name: str, boundary: str, m: int
) -> tuple[Regular, Regular, Regular, Regular]:
    """The regular interior of each of ``A, B, P, Q`` for fine length ``m`` (cached)."""
    bank = get_wavelet(bank_name)
    rule = bank.rule(boundary)
    check_fine_length(rule, m, bank.name, boundary)
    sizes = _rows_and_columns(rule, m)
    A, B, P, Q = (getattr(rule, name).regular(*sizes[name]) for name in ("A", "B", "P", "Q"))
    return A, B, P, Q


def matrices(
    m: int, wavelet: str = "bspline2", boundary: str = "open"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Dense analysis and synthesis matrices ``(A, B, P, Q)`` for a fine length ``m``.

    ``A`` is ``r × m``, ``B`` is ``s × m``, ``P`` is ``m × r`` and ``Q`` is ``m × s``, with
    ``C = A @ F``, ``D = B @ F`` and ``F = P @ C + Q @ D``.  Meant for checks and for teaching;
    the transform itself never forms them.

    Parameters
    ----------
    m : int
        The fine length.  Open ``bspline2`` needs an even ``m >= 8``; closed and Haar any even
        ``m >= 2``.  At most 2048: the matrices are dense.
    wavelet : str
        A name from :func:`wavelet_names`.
    boundary : {"open", "closed"}
        Endpoint-interpolating or periodic.

    Returns
    -------
    A, B, P, Q : numpy.ndarray
        Fresh float64 arrays.

    Examples
    --------
    >>> import numpy as np
    >>> A, B, P, Q = matrices(8)
    >>> A.shape, B.shape
    ((5, 8), (3, 8))
    >>> bool(np.allclose(np.vstack([A, B]) @ np.hstack([P, Q]), np.eye(8)))
    True
    """
    bank = get_wavelet(wavelet)
    bank.rule(boundary)
    m = _as_length(m)
    if m > MAX_DENSE_LENGTH:
        msg = (
            f"matrices() builds dense m × m matrices, for checks and teaching: m must be at most "
            f"{MAX_DENSE_LENGTH}, not {m} (the transform itself takes any length)"
        )
        raise InvalidParameter(msg)
    A, B, P, Q = _step_matrices(bank.name, boundary, m)
    return A.copy(), B.copy(), P.copy(), Q.copy()


def _as_length(m: object) -> int:
    if isinstance(m, bool) or not isinstance(m, int | np.integer):
        msg = f"a length must be an integer, not {m!r}"
        raise InvalidParameter(msg)
    return int(m)


CACHE_CLEARERS.extend(
    [
        _step_matrices.cache_clear,
        _step_sparse_cached.cache_clear,
        step_regular.cache_clear,
        step_compact.cache_clear,
    ]
)
