"""Curves: take a curve apart into a coarse outline and details, and put details on a new base.

The paper's figure 1: a curve ``(n, d)`` — a 2-D drawing, a 3-D path, a time series with
``d = 1`` — open (endpoint interpolating) or closed (periodic).  A curve of any length is first
re-sampled uniformly by arc length to the nearest length that fits (section 4.5); a curve
whose length already fits is used as it is, so that it comes back exactly.

>>> import numpy as np
>>> import wavecore
>>> t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
>>> flower = np.stack([np.cos(t), np.sin(t)], axis=1) * (1 + 0.2 * np.cos(7 * t))[:, None]
>>> dec = wavecore.decompose_curve(flower, closed=True)
>>> dec.level, dec.length, dec.coarse().shape        # 100 points re-sampled to 96
(4, 96, (6, 2))
>>> dec.reconstruct(keep=0.0).shape                  # the smooth outline, details removed
(96, 2)
>>> dec.reconstruct(match_input=True).shape          # back at the input's 100 positions
(100, 2)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .arguments import closed_flags
from .errors import InvalidParameter
from .filters import FilterBank, get_wavelet
from .multilevel import (
    DEFAULT_MOST_CURVE_LEVELS,
    as_int,
    check_level_bound,
    default_level,
    growth_limit,
    wavedec,
    waverec,
)
from .resample import resample_curve
from .threshold import keep_largest
from .transform import as_float_array

__all__ = ["CurveDecomposition", "decompose_curve", "fitting_length", "transfer_details"]


def fitting_length(
    n: int, level: int, boundary: str = "open", wavelet: str | FilterBank = "bspline2"
) -> int:
    """The length nearest to ``n`` that fits ``level`` levels (the longer one on a tie).

    A ``level`` whose fitting length would be more than ``2 * n + 64`` is refused
    (:class:`~wavecore.InvalidParameter`, naming the largest accepted level).

    Examples
    --------
    >>> fitting_length(100, 3), fitting_length(99, 3, "closed"), fitting_length(5, 2)
    (98, 96, 14)
    """
    rule = get_wavelet(wavelet).rule(boundary)
    n = as_int(n, "n", minimum=1)
    level = as_int(level, "level")
    check_level_bound(
        level,
        rule,
        growth_limit(n),
        f"length {n} (fitted, it may grow to at most {growth_limit(n)})",
    )
    if level == 0:
        return n
    step = 1 << level
    k_min = rule.smallest_k(level)
    k_below = max(k_min, (n - rule.extra) // step)
    below = step * k_below + rule.extra
    above = step * max(k_min, -(-(n - rule.extra) // step)) + rule.extra
    return below if n - below < above - n else above


def _as_points(points: Any, name: str) -> tuple[np.ndarray, bool]:
    arr = as_float_array(points)
    flat = arr.ndim == 1
    if flat:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] == 0:
        msg = f"{name} must have shape (n, d) or (n,), not {np.shape(points)}"
        raise InvalidParameter(msg)
    if len(arr) < 2:
        msg = f"{name} needs at least 2 points, got {len(arr)}"
        raise InvalidParameter(msg)
    if not np.all(np.isfinite(arr)):
        msg = f"{name} must be finite (no NaN or infinity)"
        raise InvalidParameter(msg)
    return arr, flat


def _arc_parameters(points: np.ndarray, closed: bool) -> np.ndarray:
    """Each point's position along the curve in [0, 1) (closed) or [0, 1] (open)."""
    if points.shape[1] == 1:  # time series: the index is the parameter (see resample_curve)
        steps = np.ones(len(points) - (0 if closed else 1))
    else:
        nodes = np.concatenate([points, points[:1]]) if closed else points
        steps = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(steps)])
    total = s[-1] if s[-1] > 0 else 1.0
    return s[: len(points)] / total


@dataclass(frozen=True)
class CurveDecomposition:
    """A curve taken apart by :func:`decompose_curve`.

    Attributes
    ----------
    coeffs : list of numpy.ndarray
        ``[cA_L, cD_L, ..., cD_1]`` of the fitted curve, points along axis 0 (as
        :func:`wavecore.wavedec` returns them).
    closed : bool
        Whether the curve is periodic.
    wavelet : str
        The wavelet's name.
    input_length : int
        The number of points the input had.
    input_parameters : numpy.ndarray or None
        The input points' arc-length positions in ``[0, 1]`` when the curve was re-sampled,
        ``None`` when it was used as it is.
    flat : bool
        Whether the input was 1-D (then results are 1-D too).
    """

    coeffs: list[np.ndarray]
    closed: bool
    wavelet: str
    input_length: int
    input_parameters: np.ndarray | None
    flat: bool = False

    @property
    def boundary(self) -> str:
        """``"closed"`` or ``"open"``."""
        return "closed" if self.closed else "open"

    @property
    def level(self) -> int:
        """The number of levels."""
        return len(self.coeffs) - 1

    @property
    def length(self) -> int:
        """The number of points of the fitted (possibly re-sampled) curve."""
        n = self.coeffs[0].shape[0]
        for detail in self.coeffs[1:]:
            n += detail.shape[0]
        return n

    @property
    def resampled(self) -> bool:
        """Whether the input was re-sampled to fit (so that it does not come back exactly)."""
        return self.input_parameters is not None

    def coarse(self, level: int | None = None) -> np.ndarray:
        """The coarse curve (control points) after ``level`` levels: the main outline.

        ``level=0`` is the fitted fine curve; the default is the coarsest, ``self.level``.
        """
        level = self.level if level is None else as_int(level, "level")
        if level > self.level:
            msg = f"level {level} is deeper than the decomposition's {self.level} levels"
            raise InvalidParameter(msg)
        points = waverec(self.coeffs[: self.level - level + 1], self.wavelet, self.boundary)
        return points[:, 0] if self.flat else points

    def reconstruct(
        self, keep: float = 1.0, *, weighted: bool = True, match_input: bool = False
    ) -> np.ndarray:
        """The curve from its coarse outline and the largest ``keep`` share of its details.

        Parameters
        ----------
        keep : float
            Share of the details to keep, in ``[0, 1]``: 1 keeps all (the fitted curve), 0 none
            (the smooth curve without details, at full resolution).
        weighted : bool, keyword-only
            Rank details as :func:`wavecore.remove_smallest` does.
        match_input : bool, keyword-only
            Give back the input's number of points, at the input points' arc-length positions
            (re-sampling the result back); otherwise the fitted length.  No effect when the
            input was not re-sampled.

        Returns
        -------
        numpy.ndarray
            Points ``(length, d)``, or ``(input_length, d)`` with ``match_input``.
        """
        coeffs = keep_largest(
            self.coeffs,
            keep,
            wavelet=self.wavelet,
            boundary=self.boundary,
            weighted=weighted,
            vector_axis=-1,
        )
        points = waverec(coeffs, self.wavelet, self.boundary)
        if match_input and self.input_parameters is not None:
            points = _evaluate(points, self.input_parameters, self.closed)
        return points[:, 0] if self.flat else points


def _evaluate(points: np.ndarray, parameters: np.ndarray, closed: bool) -> np.ndarray:
    """The polyline through uniformly spaced ``points`` evaluated at ``parameters``."""
    m = len(points)
    if closed:
        grid = np.arange(m + 1) / m
        nodes = np.concatenate([points, points[:1]])
    else:
        grid = np.linspace(0.0, 1.0, m)
        nodes = points
    return np.stack([np.interp(parameters, grid, nodes[:, j]) for j in range(points.shape[1])], 1)


def decompose_curve(
    points: Any,
    level: int | None = None,
    *,
    closed: bool | None = None,
    wavelet: str | FilterBank = "bspline2",
    boundary: str | None = None,
) -> CurveDecomposition:
    """Take a curve of any length apart into a coarse outline and details at every level.

    Parameters
    ----------
    points : array_like, shape (n, d) or (n,)
        The curve.  A closed curve may or may not repeat its first point at the end.
    level : int, optional
        Number of levels.  Default: the library's one rule, as :func:`wavecore.encode_curve`
        uses it (:func:`wavecore.default_level` of ``[n]`` with ``most=8``): the most levels,
        up to 8, with ``n >= 4 * 2**level``, so that the curve is re-sampled by at most an
        eighth of its length.
    closed : bool, keyword-only
        Periodic (closed boundary) or endpoint interpolating (open boundary, the default).
    wavelet : str, keyword-only
        ``"bspline2"`` (the paper's; alias ``"chaikin"``), ``"haar"`` or ``"cdf97"`` (alias
        ``"jpeg2000"``); see :func:`wavecore.wavelet_names`.
    boundary : {"open", "closed"}, optional, keyword-only
        The same choice as ``closed``, spelled as elsewhere in the library; give either (both
        only when they agree).

    Returns
    -------
    CurveDecomposition
        With ``coarse(level)`` and ``reconstruct(keep=..., match_input=...)``.

    Notes
    -----
    A length that fits ``level`` levels is used as it is (``reconstruct()`` gives the input
    back); any other is re-sampled uniformly by arc length to :func:`fitting_length`.

    Examples
    --------
    >>> import numpy as np
    >>> zigzag = np.stack([np.arange(34.0), np.arange(34) % 2], axis=1)
    >>> dec = decompose_curve(zigzag, level=2)
    >>> dec.resampled, bool(np.allclose(dec.reconstruct(), zigzag))
    (False, True)
    >>> smooth = dec.reconstruct(keep=0.0)
    >>> bool(np.ptp(smooth[8:-8, 1]) < 0.01)           # the zigzag is gone
    True
    """
    (closed,) = closed_flags(closed, boundary, 1)
    arr, flat = _as_points(points, "points")
    bank = get_wavelet(wavelet)
    boundary = "closed" if closed else "open"
    if closed and len(arr) > 2 and np.array_equal(arr[0], arr[-1]):
        arr = arr[:-1]
    n = len(arr)
    if level is None:
        # The library's one rule, as encode_curve uses it: at most 8 levels, at least 4 coarse
        # points, so the fitting length is within an eighth of n (no large re-sampling).
        level = default_level([n], DEFAULT_MOST_CURVE_LEVELS)
    level = as_int(level, "level", minimum=1)
    check_level_bound(
        level,
        bank.rule(boundary),
        growth_limit(n),
        f"a curve of {n} points (re-sampled to fit, it may grow to {growth_limit(n)} points)",
    )
    m = fitting_length(n, level, boundary, bank)
    parameters = None
    if m != n:
        parameters = _arc_parameters(arr, closed)
        arr = resample_curve(arr, m, closed=closed)
    coeffs = wavedec(arr, bank, boundary, level)
    return CurveDecomposition(coeffs, bool(closed), bank.name, n, parameters, flat)


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length; a zero row takes the nearest non-zero row's direction."""
    norms = np.linalg.norm(vectors, axis=1)
    scale = norms.max() if len(norms) else 0.0
    good = norms > 1e-12 * max(scale, 1e-300)
    if not np.any(good):
        out = np.zeros_like(vectors)
        out[:, 0] = 1.0
        return out
    index = np.arange(len(vectors))
    nearest = np.flatnonzero(good)
    pick = nearest[np.clip(np.searchsorted(nearest, index), 0, len(nearest) - 1)]
    return vectors[pick] / norms[pick][:, None]


def _tangents(points: np.ndarray, closed: bool) -> np.ndarray:
    if closed:
        diff = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        diff = np.gradient(points, axis=0)
    return _unit(diff)


def _reflections(normals: np.ndarray) -> np.ndarray:
    """``I - 2 v vᵀ / (vᵀ v)`` for each row ``v`` (the identity where ``v`` is zero)."""
    squared = np.sum(normals * normals, axis=1)
    scale = np.divide(2.0, squared, out=np.zeros_like(squared), where=squared > 0)
    return np.eye(3) - scale[:, None, None] * normals[:, :, None] * normals[:, None, :]


def _frames(points: np.ndarray, closed: bool) -> np.ndarray:
    """Orthonormal frames ``(m, d, d)`` along a 2-D or 3-D curve; row 0 is the tangent."""
    t = _tangents(points, closed)
    if points.shape[1] == 2:
        normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
        return np.stack([t, normal], axis=1)
    # 3-D: a rotation-minimizing frame by double reflection (Wang, Jüttler, Zheng & Liu 2008),
    # so the frame does not spin about the tangent and details keep their side of the curve.
    m = len(points)
    seed = np.eye(3)[np.argmin(np.abs(t[0]))]
    r0 = _unit((seed - (seed @ t[0]) * t[0])[None])[0]
    # Each step's double reflection is an orthogonal map M_i that takes t[i] to t[i + 1], so
    # r[i] = M_{i-1} … M_0 r[0]: a prefix product, computed by doubling (log2 m rounds of
    # batched 3 × 3 products) rather than by a Python loop over the points (minutes at 10**5).
    eye = np.eye(3)
    v1 = points[1:] - points[:-1]
    first = _reflections(v1)
    t_left = np.einsum("mij,mj->mi", first, t[:-1])
    second = _reflections(t[1:] - t_left)
    prefix = np.empty((m, 3, 3))
    prefix[0] = eye
    prefix[1:] = second @ first
    shift = 1
    while shift < m:
        prefix[shift:] = prefix[shift:] @ prefix[:-shift]
        shift *= 2
    r = prefix @ r0
    # The maps are orthogonal and keep r across t; this only removes the rounding.
    r = r - np.sum(r * t, axis=1)[:, None] * t
    r = r / np.maximum(np.linalg.norm(r, axis=1), 1e-300)[:, None]
    if closed:
        # The frame need not close up (holonomy): carry it once more across the seam, and
        # spread the angle it is off by evenly along the curve, so that there is no jump.
        v1 = points[0] - points[-1]
        c1 = v1 @ v1
        r_left = r[-1] - (2 / c1) * (v1 @ r[-1]) * v1 if c1 > 0 else r[-1]
        t_left = t[-1] - (2 / c1) * (v1 @ t[-1]) * v1 if c1 > 0 else t[-1]
        v2 = t[0] - t_left
        c2 = v2 @ v2
        r_end = r_left - (2 / c2) * (v2 @ r_left) * v2 if c2 > 0 else r_left
        angle = np.arctan2(np.cross(r[0], r_end) @ t[0], r[0] @ r_end)
        turn = -angle * np.arange(m) / m
        side = np.cross(t, r)
        r = np.cos(turn)[:, None] * r + np.sin(turn)[:, None] * side
    return np.stack([t, r, np.cross(t, r)], axis=1)


def transfer_details(
    source: Any,
    base: Any,
    *,
    closed: bool | None = None,
    level: int | None = None,
    frame: str = "local",
    wavelet: str | FilterBank = "bspline2",
    boundary: str | None = None,
) -> np.ndarray:
    """Put the details of ``source`` onto a new coarse curve ``base`` (the paper's figure 1 (d)).

    Parameters
    ----------
    source : array_like, shape (n, d)
        The curve whose details ("character") to take.
    base : array_like, shape (k, d)
        The new coarse curve: it becomes the new ``cA_L``, re-sampled by arc length to the
        coarse length of ``source``'s decomposition unless it has that length already.
    closed : bool, keyword-only
        Whether both curves are closed.
    level : int, optional, keyword-only
        Levels of details to transfer; default as in :func:`decompose_curve`.
    frame : {"local", "plain"}, keyword-only
        ``"plain"`` adds the details as the fixed displacement vectors the paper uses.
        ``"local"`` (the default) expresses each level's displacements in the tangent/normal
        frame of the smooth curve they sit on and re-applies them in the new curve's frame
        (Finkelstein & Salesin, *Multiresolution curves*, 1994).  The default is ``"local"``
        because a new base rarely runs in the same directions as the old one: plain
        displacements keep pointing where they pointed in the source, so a bump that stood
        out of the source's outline lies along the new curve instead, while local ones turn
        with the sweep and keep the character across the curve.  When the base runs like the
        source's own outline both give the same curve.
        The frame is the tangent and its left normal for ``d = 2``, and a rotation-minimizing
        frame for ``d = 3`` (on a closed curve its leftover twist is spread evenly along the
        curve, so that it closes up).  For ``d = 1`` (a time series) and ``d > 3`` there is no
        natural frame, and ``"local"`` falls back to plain displacements.
    wavelet : str, keyword-only
        As in :func:`decompose_curve`: ``"bspline2"`` (alias ``"chaikin"``), ``"haar"`` or
        ``"cdf97"`` (alias ``"jpeg2000"``).
    boundary : {"open", "closed"}, optional, keyword-only
        The same choice as ``closed``, spelled as elsewhere in the library; give either (both
        only when they agree).

    Returns
    -------
    numpy.ndarray
        The new curve, with as many points as ``source`` (re-sampled back by arc length when
        ``source`` had to be re-sampled to fit).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 66)
    >>> wiggly = np.stack([t, 0.05 * np.sin(60 * t)], axis=1)        # a wiggly horizontal line
    >>> base = np.array([[0.0, 0.0], [0.0, 1.0]])                     # a vertical line
    >>> new = transfer_details(wiggly, base, level=2)
    >>> plain = transfer_details(wiggly, base, level=2, frame="plain")
    >>> bool(np.ptp(new[5:-5, 0]) > 0.05 > 0.01 > np.ptp(plain[5:-5, 0]))  # across vs along
    True
    """
    (closed,) = closed_flags(closed, boundary, 1)
    if frame not in ("local", "plain"):
        msg = f"frame must be 'local' or 'plain', not {frame!r}"
        raise InvalidParameter(msg)
    src_points, flat = _as_points(source, "source")
    base_points, _ = _as_points(base, "base")
    if base_points.shape[1] != src_points.shape[1]:
        msg = (
            f"base has {base_points.shape[1]}-D points but source has "
            f"{src_points.shape[1]}-D points; they must match"
        )
        raise InvalidParameter(msg)
    dec = decompose_curve(src_points, level, closed=closed, wavelet=wavelet)
    bnd = dec.boundary
    if closed and len(base_points) > 2 and np.array_equal(base_points[0], base_points[-1]):
        base_points = base_points[:-1]
    coarse_length = len(dec.coeffs[0])
    if coarse_length < 2:
        # one coarse point has no direction: no base can stand in for it
        deepest = dec.level - 1
        while (
            deepest > 0
            and len(decompose_curve(src_points, deepest, closed=closed, wavelet=wavelet).coeffs[0])
            < 2
        ):
            deepest -= 1
        offer = {0: "no level fits it", 1: "give level 1"}.get(
            deepest, f"give a level from 1 to {deepest}"
        )
        msg = (
            f"level {dec.level} leaves source a coarse curve of {coarse_length} point, which no "
            f"base can stand in for; {offer}"
        )
        raise InvalidParameter(msg)
    new = (
        base_points
        if len(base_points) == coarse_length
        else resample_curve(base_points, coarse_length, closed=closed)
    )
    if frame == "plain" or src_points.shape[1] not in (2, 3):
        result = waverec([new, *dec.coeffs[1:]], dec.wavelet, bnd)
    else:
        old = dec.coeffs[0]
        for detail in dec.coeffs[1:]:
            smooth_old = waverec([old, None], dec.wavelet, bnd)
            fine_old = waverec([old, detail], dec.wavelet, bnd)
            smooth_new = waverec([new, None], dec.wavelet, bnd)
            local = np.einsum("mij,mj->mi", _frames(smooth_old, closed), fine_old - smooth_old)
            new = smooth_new + np.einsum("mij,mi->mj", _frames(smooth_new, closed), local)
            old = fine_old
        result = new
    if len(result) != dec.input_length:
        result = resample_curve(result, dec.input_length, closed=closed)
    return result[:, 0] if flat else result
