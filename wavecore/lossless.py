"""The reversible integer transforms of ``encode_image(..., lossless=True)``: LeGall 5/3 and others.

Lossless coding needs a transform that maps integers to integers and back bit-exactly on any
machine, so the decoder must not depend on float rounding.  This module implements the
reversible LeGall 5/3 integer lifting of JPEG 2000 (ISO/IEC 15444-1, annex F), with whole-sample
symmetric extension at both ends:

.. code-block:: text

    d[i] = x[2i+1] - floor((x[2i] + x[2i+2]) / 2)          (predict)
    s[i] = x[2i]   + floor((d[i-1] + d[i] + 2) / 4)         (update)

Why not an integer form of the paper's open ``bspline2`` filters: it does not exist.  The
analysis matrix ``[A; B]`` of the open (endpoint-interpolating) boundary has determinant ±2 at
every size (checked for m = 8 … 34; each of the ``K - 1`` interior sample pairs contributes ½,
each of the ``K`` sum/difference butterflies 2, and the end pairs 1), and a bijection of the
integers that approximates a linear map within a bounded error must preserve volume, so it would
need determinant ±1.  An integer form would have to rescale a coefficient of every level, which
is no longer the paper's transform.  The closed (periodic) ``bspline2`` has determinant ±1, and
this module does implement its exact integer lifting (below, ``"bspline2"``), but periodic
wrapping suits images poorly: on camera, coins and brick it codes 1–4 % larger than 5/3.  It is
offered per level all the same and wins where it wins (the default encoder codes the choices
with and without it).  With ``effort="max"`` (the lossless coder, :mod:`wavecore.losslesscoder`)
the encoder chooses from ``CANDIDATE_SETS[0]`` only: coding a second choice doubled that
coder's encoding time, and ``bspline2`` won none of scikit-image's pictures.

The 5/3 lifting is the standard reversible wavelet, accepts every length (``n`` samples split
into ``ceil(n/2)`` coarse and ``floor(n/2)`` details), so a lossless image needs no padding, and
its low-pass has unit DC gain, so the coarse band is a viewable thumbnail for
``decode(..., level=k)``.

A second reversible filter, the integer Haar (S-transform: ``d = x[2i+1] - x[2i]``,
``s = x[2i] + floor(d / 2)``), is chosen instead of 5/3 for a level when it codes that level's
details in fewer bits: on images that were enlarged by pixel repetition (scikit-image's ``moon``
is a 2× nearest-neighbour enlargement) its details are exactly zero, where 5/3's are not.  The
choice is made per level by :func:`choose_filters` (first-order entropy of the level's details)
and recorded in the bundle header.

A fourth, ``"511c"``, is the 5/11-C of JPEG 2000 Part 2 (ISO/IEC 15444-2, annex H; Adams and
Kossentini 2000): the 5/3 steps, then the details corrected by the coarse samples' curvature,

.. code-block:: text

    d[i] += floor((s[i-1] - s[i] - s[i+1] + s[i+2] + 8) / 16)

with the coarse samples mirrored as the whole-sample symmetric extension of the input mirrors
them.  Its low-pass is 5/3's, so thumbnails are unchanged; its details are smaller on smooth
pictures: on the finest level of camera, coins, brick and astronaut it codes 194, 362, 444 and
1,337 bytes less than 5/3 (0.2–0.5 %), and first-order entropy ranks it right.  Its reach is
three coarse samples, within what region decoding assumes.  JPEG 2000 Part 2's 9/7-M and
13/7-T were measured too: their longer update codes the coarse band better but their finest
details worse, and entropy does not pick them where they win (coins only), so they are left out.

The integer closed ``bspline2`` (even lengths only), with pairs ``E[i] = x[2i]``,
``O[i] = x[2i+1]`` and indices taken modulo ``n / 2``, is five lifting steps:

.. code-block:: text

    t[i] = E[i] - O[i]
    s[i] = O[i] + floor(t[i] / 2)                 (so s = floor((E + O) / 2))
    e[i] = t[i] - s[i]
    c[i] = s[i] + floor((e[i] - e[i-1]) / 2)
    d[i] = c[i] + e[i-1]

Without the floors this is exactly the paper's closed ``A`` and ``B`` (``NOTES.md``):
``c[i] = -1/4 x[2i-2] + 3/4 x[2i-1] + 3/4 x[2i] - 1/4 x[2i+1]`` and
``d[i] = 1/4 x[2i-2] - 3/4 x[2i-1] + 3/4 x[2i] - 1/4 x[2i+1]``; with them, ``c`` and ``d`` stay
within 1 of the real transform.

Only integer arithmetic in ``int64`` is used (floor division by shifts), so the result is the same
everywhere.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from . import _kernels, _losslesskernels, layout
from .errors import InvalidParameter
from .transform import normalize_axis, run_rows

__all__ = [
    "CANDIDATE_SETS",
    "CHROMA_WEIGHTS",
    "FILTERS",
    "LOSSLESS_DEPTHS",
    "Lifted",
    "band_shapes",
    "best_depth",
    "choose_depth",
    "choose_filters",
    "chroma_weight",
    "coarser",
    "colour_name",
    "deepest",
    "filter_choices",
    "forward",
    "inverse",
    "lift",
    "lossless_colour",
    "med_residuals",
    "predict_chroma",
    "predicted_rct_forward",
    "predicted_rct_inverse",
    "unlift",
    "unpredict_chroma",
]

#: The reversible filters, by the names the bundle header uses.
FILTERS = ("legall53", "haar", "bspline2", "511c")
#: The candidate sets of :func:`filter_choices`: without and with the closed ``bspline2``, which
#: entropy ranks too well.  The default encoder codes a choice from each and keeps the smaller;
#: ``effort="max"`` uses the first (one choice, coded once).
CANDIDATE_SETS = (("legall53", "haar", "511c"), FILTERS)
#: The depths (levels) a default lossless encode tries when none is given (:func:`best_depth`,
#: the block coder; ``effort="max"`` takes :func:`choose_depth` instead): the
#: context coder's prediction of the coarse band (LOCO-I's median edge detector) codes it
#: better than further 5/3 levels do.  On scikit-image's pictures, bytes at depths
#: 1 / 2 / 3 / 5: camera 124,826 / 124,811 / 124,985 / 125,148; coins 68,456 / 68,252 / 68,437
#: / 68,530; brick 94,216 / 95,560 / 96,581 / 96,808; astronaut 339,960 / 338,449 / 338,936 /
#: 339,376; moon, a pixel-repeated enlargement, 28,955 / 28,335 / 28,093 / 28,124.  Depth 1
#: would cost a coding of a quarter of the samples more; depth 3 costs a sixteenth.
#: First-order entropy ranks the depths wrongly, so they are coded.
LOSSLESS_DEPTHS = (2, 3)
#: How much smaller (as a fraction) a level's first-order entropy must be than the whole
#: picture's, each under LOCO-I's median edge prediction, for :func:`choose_depth` to lift
#: it: the lossless coder (:mod:`wavecore.losslesscoder`) predicts the picture itself better
#: than one lifting level does on photographs.  On scikit-image's pictures the ratio of the
#: entropies (one level / none) is 0.994 on camera, 0.987 coins, 1.034 brick, 0.972
#: astronaut, where no level codes 1.8 %, 1.0 %, 9.0 % and 0.8 % smaller; and 0.626 on moon,
#: a pixel-repeated enlargement, where one integer Haar level codes 29 % smaller.
DEPTH_GAIN = 0.9
#: :func:`choose_depth` first asks its question of a sample of a tall picture: blocks of
#: ``SAMPLE_ROWS`` rows (even, so that a 2× enlargement keeps its pairs), one every
#: ``SAMPLE_EVERY`` blocks, stacked.  A "no" there is final (the lifting and the residual
#: counts of the whole picture were a tenth of the lossless coder's encode + decode CPU);
#: a "yes" is confirmed on the whole picture, so that the filter chosen is the whole
#: picture's.  Entropy ratios (one level / none) of the sample and of the whole picture, far
#: from 0.9 either way: camera 1.010 and 0.994, coins 1.001 and 0.987, brick 1.057 and 1.034,
#: astronaut 0.984 and 0.972, moon 0.628 and 0.626 (astronaut's choice 22 -> 7 ms of CPU).
SAMPLE_ROWS = 32
SAMPLE_EVERY = 4
#: Entropy ratios from :data:`DEPTH_GAIN` up to this one are too close to call: where the
#: encoder passes :func:`choose_depth` a ``confirm``, it codes the sample both ways and keeps
#: the smaller.  Above it, no picture measured coded smaller with the level (camera, coins,
#: brick: samples' ratios 1.001 to 1.057); below it, a 4× Lanczos enlargement of astronaut
#: (2048², with noise: benchmarks/region_decode.py's) codes 3–4 % smaller with one level, at
#: ratios of 0.91 (grey) and 0.95 (RGB).
CHECK_BELOW = 0.98
#: The blocks of the sample that a close call codes: one in this many (a 2048² picture's 4 of
#: 16, 128 rows, which the lossless coder codes twice in about a quarter of its encode time).
CONFIRM_EVERY = 4
#: The most pixels a close call codes (twice): a wider sample keeps blocks of
#: ``CONFIRM_COLUMNS`` columns, evenly spaced, so that a short, wide picture (a 2 × 2 097 152
#: one, say) is not coded three times over.
CONFIRM_MOST = 1 << 18
CONFIRM_COLUMNS = 256


#: The weights of :func:`predict_chroma`, in eighths: Cr is predicted from Cb as ``w / 8 · Cb``.
CHROMA_WEIGHTS = tuple(range(-8, 9))


#: Lifting steps kept by :func:`filter_choices` for :func:`forward`: ``(coarse, details)`` of
#: each level, under (the filters of the finer levels, finest first; this level's filter).
Lifted = dict[tuple[tuple[str, ...], str], tuple[np.ndarray, Any]]
_Memo = dict[tuple[tuple[str, ...], str], tuple[float, np.ndarray, Any]]

#: The compiled kernels' number for each filter (anything else is lifted as 5/3, as before).
_KINDS = {"legall53": 0, "haar": 1, "bspline2": 2, "511c": 3}


def _middle_view(arr: np.ndarray, axis: int) -> np.ndarray:
    """An ``(outer, n, inner)`` view of a C-contiguous array around ``axis``."""
    outer = int(np.prod(arr.shape[:axis], dtype=np.int64))
    inner = int(np.prod(arr.shape[axis + 1 :], dtype=np.int64))
    return arr.reshape(outer, arr.shape[axis], inner)


def _run_steps(kernel: Any, arrays: tuple[np.ndarray, ...], kind: int) -> None:
    """``kernel(*arrays, kind, ...)`` over the thread pool: split along ``outer`` when there
    is more than one, else along ``inner``.  Every sample is computed the same way whatever
    the split, so the result does not depend on the thread count."""
    outer, inner = arrays[0].shape[0], arrays[0].shape[2]
    work = sum(a.size for a in arrays)
    if outer > 1:
        run_rows(lambda lo, hi: kernel(*arrays, kind, lo, hi, 0, inner), outer, work)
    else:
        run_rows(lambda lo, hi: kernel(*arrays, kind, 0, outer, lo, hi), inner, work)


def lift(x: np.ndarray, axis: int = 0, filter: str = "legall53") -> tuple[np.ndarray, np.ndarray]:
    """One analysis step along ``axis``: ``(coarse, detail)`` as ``int64``.

    ``n`` samples give ``ceil(n / 2)`` coarse samples and ``floor(n / 2)`` details (Haar passes
    an unpaired last sample to the coarse band unchanged; the closed ``bspline2`` needs an even
    ``n``).

    Examples
    --------
    >>> import numpy as np
    >>> s, d = lift(np.array([10, 12, 14, 16, 18]))
    >>> s.tolist(), d.tolist()
    ([10, 14, 18], [0, 0])
    """
    data = np.ascontiguousarray(np.asarray(x, dtype=np.int64))
    axis = normalize_axis(axis, data.ndim)
    n = data.shape[axis]
    if filter == "bspline2":
        _check_even(n)
    view = _middle_view(data, axis)
    coarse = np.empty((view.shape[0], (n + 1) // 2, view.shape[2]), dtype=np.int64)
    detail = np.empty((view.shape[0], n // 2, view.shape[2]), dtype=np.int64)
    _run_steps(_kernels.lift_steps, (view, coarse, detail), _KINDS.get(filter, 0))
    shape = list(data.shape)
    shape[axis] = coarse.shape[1]
    c = coarse.reshape(shape)
    shape[axis] = detail.shape[1]
    return c, detail.reshape(shape)


def _check_even(n: int) -> None:
    if n % 2 or n == 0:
        msg = f"the integer closed bspline2 lifting needs an even length, not {n}"
        raise InvalidParameter(msg)


def unlift(
    coarse: np.ndarray, detail: np.ndarray, axis: int = 0, filter: str = "legall53"
) -> np.ndarray:
    """The exact inverse of :func:`lift`."""
    s = np.ascontiguousarray(np.asarray(coarse, dtype=np.int64))
    d = np.ascontiguousarray(np.asarray(detail, dtype=np.int64))
    axis = normalize_axis(axis, s.ndim)
    ns, nd = s.shape[axis], d.shape[axis] if d.ndim == s.ndim else -1
    if filter == "bspline2" and s.shape != d.shape:
        msg = f"closed bspline2 bands must have equal shapes, not {s.shape} and {d.shape}"
        raise InvalidParameter(msg)
    same_elsewhere = d.ndim == s.ndim and all(
        a == b for k, (a, b) in enumerate(zip(s.shape, d.shape, strict=True)) if k != axis
    )
    if not same_elsewhere or not (nd == 0 or 0 <= ns - nd <= 1):
        msg = (
            f"coarse samples of shape {s.shape} and details of shape {d.shape} do not come "
            f"from one lifting step along axis {axis}"
        )
        raise InvalidParameter(msg)
    shape = list(s.shape)
    shape[axis] = ns + nd
    out = np.empty(shape, dtype=np.int64)
    views = (_middle_view(s, axis), _middle_view(d, axis), _middle_view(out, axis))
    _run_steps(_kernels.unlift_steps, views, _KINDS.get(filter, 0))
    return out


def band_shapes(shape: Sequence[int], level: int, axes: Sequence[int] = (0, 1)) -> list[Any]:
    """Subband shapes of :func:`forward`, in ``wavedec2`` layout (or ``wavedec`` for one axis).

    Examples
    --------
    >>> band_shapes((5, 8), 2)
    [(2, 2), ((1, 2), (2, 2), (1, 2)), ((2, 4), (3, 4), (2, 4))]
    """
    return layout.band_shapes(shape, level, axes, _halves)


def _halves(_: int, n: int) -> tuple[int, int]:
    """One lifting step's split: ``ceil(n / 2)`` coarse samples, ``floor(n / 2)`` details."""
    return (n + 1) // 2, n // 2


def _filters(filters: Sequence[str] | None, level: int) -> list[str]:
    names = ["legall53"] * level if filters is None else list(filters)
    if len(names) != level or any(f not in FILTERS for f in names):
        msg = f"filters must name one of {list(FILTERS)} per level ({level}), not {filters!r}"
        raise InvalidParameter(msg)
    return names


def _entropy_bits(bands: Sequence[np.ndarray]) -> float:
    total = 0.0
    for band in bands:
        counts = _value_counts(band)
        total -= float(np.sum(counts * np.log2(counts / band.size)))
    return total


def _value_counts(band: np.ndarray) -> np.ndarray:
    """How often each distinct value occurs, in increasing order of the values.

    The counts ``np.unique(band, return_counts=True)`` gives, without its sort: a histogram
    when the values span a range not much wider than the band (a band's details do), so the
    entropy, summed over the same counts in the same order, comes out the same to the bit.
    """
    flat = np.ascontiguousarray(band, dtype=np.int64).reshape(-1)
    if flat.size == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = (int(v) for v in _kernels.value_range(flat))
    if hi - lo > 4 * flat.size + (1 << 16):
        return np.unique(flat, return_counts=True)[1]
    counts = _kernels.value_histogram(flat, lo, hi - lo + 1)
    return counts[counts > 0]


def _level_step(coarse: np.ndarray, axes: tuple[int, ...], name: str) -> tuple[np.ndarray, Any]:
    if len(axes) == 1:
        return lift(coarse, axes[0], name)
    low, high = lift(coarse, axes[0], name)
    ll, lh = lift(low, axes[1], name)
    hl, hh = lift(high, axes[1], name)
    return ll, (hl, lh, hh)


def choose_filters(
    data: np.ndarray,
    level: int,
    axes: Sequence[int] = (0, 1),
    candidates: Sequence[str] = FILTERS,
) -> list[str]:
    """Per level (finest first), the candidate whose details have the lowest first-order entropy.

    First-order entropy is only a guide: a context coder may rank the filters differently
    (it does for ``bspline2`` against 5/3), so the codec codes more than one choice and keeps
    the smaller bundle (:func:`filter_choices`).

    Examples
    --------
    >>> import numpy as np
    >>> small = np.random.default_rng(0).integers(0, 256, (16, 16))
    >>> choose_filters(np.kron(small, np.ones((2, 2), int)), 2)  # a 2x pixel-repeated image
    ['haar', 'legall53']
    """
    return _choose(np.asarray(data).astype(np.int64), level, tuple(axes), candidates, {})


def filter_choices(
    data: np.ndarray,
    level: int,
    axes: Sequence[int] = (0, 1),
    candidate_sets: Sequence[Sequence[str]] = CANDIDATE_SETS,
    *,
    lifted: Lifted | None = None,
) -> list[list[str]]:
    """:func:`choose_filters` for each candidate set, without repeats, in the sets' order.

    Each filter is lifted and its entropy measured once per level and path of earlier choices,
    whatever the number of sets that offer it (the encoder's two sets share all but one).
    ``lifted``, a dict, if given, receives the lifting steps of the chosen paths, so that
    :func:`forward` and :func:`best_depth` given it need not lift ``data`` again.

    Examples
    --------
    >>> import numpy as np
    >>> flat = np.zeros((8, 8), dtype=np.uint8)
    >>> filter_choices(flat, 2)  # every filter gives zero details: the first one wins
    [['legall53', 'legall53']]
    """
    coarse = np.asarray(data).astype(np.int64)
    memo: _Memo = {}
    choices: list[list[str]] = []
    on_paths: set[tuple[tuple[str, ...], str]] = set()
    for candidates in candidate_sets:
        chosen = _choose(
            coarse, level, tuple(axes), candidates, memo, keep=lifted is not None, held=on_paths
        )
        if chosen not in choices:
            choices.append(chosen)
        on_paths.update((tuple(chosen[:k]), chosen[k]) for k in range(len(chosen)))
    if lifted is not None:
        # The steps on the chosen paths, for forward() and best_depth() to take.
        lifted.update(
            (key, (low, bands))
            for key, (_, low, bands) in memo.items()
            if key in on_paths and bands is not None
        )
    return choices


def _choose(
    coarse: np.ndarray,
    level: int,
    axes: tuple[int, ...],
    candidates: Sequence[str],
    memo: _Memo,
    keep: bool = False,
    held: set[tuple[tuple[str, ...], str]] | None = None,
) -> list[str]:
    """:func:`choose_filters` on ``int64`` data, with ``memo`` holding each (earlier choices,
    filter)'s detail entropy and coarse band, so that other candidate sets reuse them; with
    ``keep``, also the details of each level's best candidate so far (a beaten one's are let
    go at once, unless ``held``, an earlier set's choice: so that few candidates' details are
    held per level)."""
    chosen: list[str] = []
    for _ in range(level):
        best: tuple[float, str, np.ndarray] | None = None
        for name in candidates:
            if name == "bspline2" and any(coarse.shape[a] % 2 for a in axes):
                continue  # periodic pairs need even lengths
            key = (tuple(chosen), name)
            if key not in memo:
                low, bands = _level_step(coarse, axes, name)
                bits = _entropy_bits(bands if isinstance(bands, tuple) else (bands,))
                memo[key] = (bits, low, bands if keep else None)
            bits, low, _ = memo[key]
            if best is None or bits < best[0]:
                if best is not None:
                    _let_go(memo, (tuple(chosen), best[1]), held)
                best = (bits, name, low)
            else:
                _let_go(memo, key, held)
        assert best is not None
        chosen.append(best[1])
        coarse = best[2]
    return chosen


def _let_go(
    memo: _Memo,
    key: tuple[tuple[str, ...], str],
    held: set[tuple[tuple[str, ...], str]] | None,
) -> None:
    """Drop the details kept for ``key`` (a beaten candidate) unless ``held``: :func:`forward`
    lifts again in the rare case that a later candidate set chooses it after all."""
    if held is not None and key in held:
        return
    bits, low, _ = memo[key]
    memo[key] = (bits, low, None)


def forward(
    data: np.ndarray,
    level: int,
    axes: Sequence[int] = (0, 1),
    filters: Sequence[str] | None = None,
    *,
    lifted: Lifted | None = None,
) -> list[Any]:
    """Multi-level reversible decomposition of integer data, in ``wavedec2`` layout (``int32``).

    ``filters`` names the filter of each level, finest first (default: 5/3 everywhere).
    ``lifted``: the steps :func:`filter_choices` kept for the same ``data`` (a step not in it
    is lifted here), the same result without lifting again; each step taken is removed from it,
    so that its ``int64`` bands go as soon as they are cast.

    With two axes the result is ``[cA, (cH, cV, cD), ...]`` (``cH`` detail along the first
    axis), with one axis ``[cA, cD, ...]``.  Other axes (colour) are carried along.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.random.default_rng(0).integers(0, 65536, (13, 10, 3))
    >>> coeffs = forward(image, 3)
    >>> bool(np.array_equal(inverse(coeffs), image))
    True
    """
    arr = np.asarray(data)
    if arr.dtype.kind not in "iu":
        msg = f"the reversible transform needs integer data, not {arr.dtype}"
        raise InvalidParameter(msg)
    return _forward(arr, _filters(filters, level), tuple(axes), lifted, ())


def _forward(
    arr: np.ndarray,
    names: Sequence[str],
    axes: tuple[int, ...],
    lifted: Lifted | None,
    done: tuple[str, ...],
) -> list[Any]:
    """:func:`forward` of integer ``arr``, the coarse band after the steps ``done`` (finest
    first): each step found in ``lifted`` under the filters before it is taken (out of it)."""
    coarse: np.ndarray | None = None
    details: list[Any] = []
    for k, name in enumerate(names):
        step = None if lifted is None else lifted.pop(((*done, *names[:k]), name), None)
        if step is None:
            if coarse is None:
                coarse = arr.astype(np.int64)
            coarse, bands = _level_step(coarse, axes, name)
        else:
            coarse, bands = step
        if isinstance(bands, tuple):
            details.append(tuple(b.astype(np.int32) for b in bands))
        else:
            details.append(bands.astype(np.int32))
    if coarse is None:  # no levels
        coarse = arr
    return [coarse.astype(np.int32), *reversed(details)]


def inverse(
    coeffs: Sequence[Any], axes: Sequence[int] = (0, 1), filters: Sequence[str] | None = None
) -> np.ndarray:
    """Reconstruct from :func:`forward`'s list, or from a prefix of it (a coarser image).

    ``filters`` is the full list given to :func:`forward` (finest first); a prefix of ``coeffs``
    uses the coarsest ones.
    """
    axes = tuple(axes)
    levels = len(coeffs) - 1
    names = _filters(filters, len(filters) if filters is not None else levels)
    if len(names) < levels:
        msg = f"{levels} detail levels but only {len(names)} filters"
        raise InvalidParameter(msg)
    coarse = np.asarray(coeffs[0], dtype=np.int64)
    # coeffs[1] is the coarsest level present: filter index len(names) - 1, then downwards.
    for index, bands in enumerate(coeffs[1:]):
        name = names[len(names) - 1 - index]
        if len(axes) == 1:
            coarse = unlift(coarse, bands, axes[0], name)
            continue
        cH, cV, cD = bands
        low = unlift(coarse, cV, axes[1], name)
        high = unlift(cH, cD, axes[1], name)
        coarse = unlift(low, high, axes[0], name)
    return coarse


def best_depth(
    data: np.ndarray,
    filters: Sequence[str],
    code: Callable[[list[Any]], list[bytes]],
    depths: Sequence[int] = LOSSLESS_DEPTHS,
    axes: Sequence[int] = (0, 1),
    *,
    lifted: Lifted | None = None,
) -> tuple[int, list[bytes]]:
    """Of ``depths`` (each at most ``len(filters)``), the one whose coding is smallest, and its
    chunks (``code`` turns a :func:`forward` list into one chunk per entry).

    The shallowest depth is coded whole; a deeper one only re-codes what changes, the coarse
    band split further: each level's chunk of the context coder is coded on its own (its blocks
    hold one level), so the finer chunks are the same.  The result is exactly the coding of
    ``forward(data, depth, axes, filters[:depth])``.  ``lifted``: as :func:`forward` takes it.
    """
    ordered = sorted(set(depths))
    first = ordered[0]
    axes = tuple(axes)
    coeffs = forward(data, first, axes, filters[:first], lifted=lifted)
    chunks = code(coeffs)
    best, best_size, chosen = chunks, sum(map(len, chunks)), first
    for depth in ordered[1:]:
        names = _filters(filters[first:depth], depth - first)
        part = code(_forward(coeffs[0], names, axes, lifted, tuple(filters[:first])))
        candidate = [*part, *chunks[1:]]
        size = sum(map(len, candidate))
        if size < best_size:
            best, best_size, chosen = candidate, size, depth
    return chosen, best


def med_residuals(plane: np.ndarray) -> np.ndarray:
    """A 2-D plane less LOCO-I's median-edge prediction from its west, north and north-west
    neighbours (the first row from the west, the first column from the north)."""
    x = np.asarray(plane, dtype=np.int64)
    w = np.zeros_like(x)
    n = np.zeros_like(x)
    nw = np.zeros_like(x)
    w[:, 1:] = x[:, :-1]
    w[1:, 0] = x[:-1, 0]
    n[1:] = x[:-1]
    n[0, 1:] = x[0, :-1]
    nw[1:, 1:] = x[:-1, :-1]
    nw[1:, 0] = x[:-1, 0]
    nw[0, 1:] = x[0, :-1]
    high, low = np.maximum(w, n), np.minimum(w, n)
    prediction = np.where(nw >= high, low, np.where(nw <= low, high, w + n - nw))
    return x - prediction


def _predicted_bits(data: np.ndarray) -> float:
    """First-order entropy of :func:`med_residuals`, channel by channel.

    The residuals are counted by a compiled pass: they lie within ``±spread``, the width of
    the plane's range with 0 (every prediction but the first sample's 0 lies within the
    plane's range); the counts, summed as :func:`_entropy_bits` sums
    them, give the same entropy to the bit at a fraction of the time (a fifth of the
    lossless coder's encode went into the residual arrays)."""
    planes = [data] if data.ndim == 2 else [data[..., c] for c in range(data.shape[2])]
    total = 0.0
    for plane in planes:
        flat = np.ascontiguousarray(plane, dtype=np.int64)
        if flat.size == 0:
            continue
        lo, hi = (int(v) for v in _kernels.value_range(flat.reshape(-1)))
        spread = max(hi, 0) - min(lo, 0)  # the first sample is predicted as 0
        if 2 * spread + 1 > 4 * flat.size + (1 << 16):  # a sparse histogram: count by sorting
            counts = np.unique(med_residuals(flat), return_counts=True)[1]
        else:
            counts = _losslesskernels.med_histogram(flat, -spread, 2 * spread + 1)
            counts = counts[counts > 0]
        total -= float(np.sum(counts * np.log2(counts / flat.size)))
    return total


def choose_depth(
    data: np.ndarray,
    candidates: Sequence[str] = CANDIDATE_SETS[0],
    confirm: Callable[[np.ndarray, list[str]], bool] | None = None,
) -> list[str]:
    """The filters of a lossless encode without a given ``level``: none (the picture coded
    by prediction) or one level, whichever first-order entropy favours by :data:`DEPTH_GAIN`;
    with ``confirm`` (``confirm(sample, filters)``: does one level code the sample smaller?),
    also one level where the entropies are within :data:`CHECK_BELOW` and ``confirm`` says so.

    Examples
    --------
    >>> import numpy as np
    >>> small = np.random.default_rng(0).integers(0, 256, (16, 16))
    >>> choose_depth(np.kron(small, np.ones((2, 2), int)))  # a 2x pixel-repeated image
    ['haar']
    >>> ramp = np.add.outer(np.arange(64), np.arange(64))
    >>> choose_depth(ramp + np.random.default_rng(1).integers(0, 4, (64, 64)))  # predicted
    []
    """
    arr = np.asarray(data).astype(np.int64)
    if min(arr.shape[:2]) < 2:
        return []
    step = SAMPLE_ROWS * SAMPLE_EVERY
    sample = arr
    close = CHECK_BELOW if confirm is not None else DEPTH_GAIN
    if arr.shape[0] >= 2 * step:  # tall: a "no" of the sample is final (SAMPLE_ROWS)
        blocks = [arr[r : r + SAMPLE_ROWS] for r in range(0, arr.shape[0] - SAMPLE_ROWS + 1, step)]
        sample = np.concatenate(blocks)
        chosen, ratio = _one_level(sample, candidates)
        if ratio >= close:
            return []
        if confirm is not None and ratio >= DEPTH_GAIN:  # a close call: a sample's coding
            # (every CONFIRM_EVERY-th block of the sample: coding costs a hundred times the
            # entropy), and, where it says yes, the whole picture's filter (it coded a 4x
            # enlargement 1.1 % smaller than the sample's)
            if len(blocks) >= 2 * CONFIRM_EVERY:
                sample = np.concatenate(blocks[::CONFIRM_EVERY])
            sample = _narrowed(sample)
            return _choose(arr, 1, (0, 1), candidates, {}) if confirm(sample, chosen) else []
    chosen, ratio = _one_level(arr, candidates)
    if ratio < DEPTH_GAIN:
        return chosen
    if confirm is not None and ratio < CHECK_BELOW and confirm(_narrowed(sample), chosen):
        return chosen
    return []


def _narrowed(sample: np.ndarray) -> np.ndarray:
    """At most about :data:`CONFIRM_MOST` pixels of ``sample``: blocks of
    :data:`CONFIRM_COLUMNS` columns, one in every so many, side by side."""
    rows, cols = sample.shape[:2]
    every = -(-rows * cols // CONFIRM_MOST)
    if every <= 1 or cols < 2 * CONFIRM_COLUMNS:
        return sample
    starts = range(0, cols - CONFIRM_COLUMNS + 1, CONFIRM_COLUMNS * every)
    return np.concatenate([sample[:, c : c + CONFIRM_COLUMNS] for c in starts], axis=1)


def _one_level(arr: np.ndarray, candidates: Sequence[str]) -> tuple[list[str], float]:
    """:func:`choose_depth`'s question on ``arr`` (``int64``): the one level's filters, and
    the ratio of its first-order entropy to the picture's."""
    memo: _Memo = {}
    chosen = _choose(arr, 1, (0, 1), candidates, memo)
    detail_bits, coarse, _ = memo[((), chosen[0])]
    one_level = detail_bits + _predicted_bits(coarse)
    whole = _predicted_bits(arr)
    return chosen, one_level / whole if whole > 0 else float("inf")


def deepest(shape: Sequence[int]) -> int:
    """The most lifting levels an image of ``shape`` (rows, columns, ...) takes, each subband
    left non-empty."""
    return max(0, min(int(shape[0]), int(shape[1])).bit_length() - 1)


def coarser(image: np.ndarray, levels: int) -> np.ndarray:
    """The coarse band of ``levels`` LeGall 5/3 levels of a decoded image, in its dtype (clipped
    to it): what ``decode(level=k)`` returns for a lossless bundle coded with fewer than ``k``
    levels, of the shape a ``k``-level bundle's thumbnail has.

    Examples
    --------
    >>> import numpy as np
    >>> coarser(np.full((5, 8), 9, np.uint8), 2).tolist()
    [[9, 9], [9, 9]]
    """
    arr = np.asarray(image)
    coarse = forward(arr, levels, (0, 1))[0] if levels else arr.astype(np.int64)
    if arr.dtype.kind in "iu":
        info = np.iinfo(arr.dtype)
        coarse = np.clip(coarse, info.min, info.max)
    return np.ascontiguousarray(coarse.astype(arr.dtype))


def predict_chroma(ycc: np.ndarray, weight: int) -> np.ndarray:
    """The RCT's ``Cr`` less its prediction from ``Cb``: ``Cr - floor((weight * Cb + 4) / 8)``.

    Reversible (``Cb`` is kept, so :func:`unpredict_chroma` adds the same integer back).
    What RCT leaves of the correlation between its two chroma channels is then coded once
    instead of twice: on astronaut (weight 2) 3,100 bytes less, 0.9 %.  The codec runs this
    fused with the RCT (:func:`predicted_rct_forward`).

    Examples
    --------
    >>> import numpy as np
    >>> ycc = np.random.default_rng(0).integers(-255, 256, (4, 4, 3))
    >>> bool(np.array_equal(unpredict_chroma(predict_chroma(ycc, 3), 3), ycc))
    True
    """
    out = np.array(ycc, dtype=np.int64)
    out[..., 2] -= (weight * out[..., 1] + 4) >> 3
    return out


def unpredict_chroma(ycc: np.ndarray, weight: int) -> np.ndarray:
    """The exact inverse of :func:`predict_chroma`."""
    out = np.array(ycc, dtype=np.int64)
    out[..., 2] += (weight * out[..., 1] + 4) >> 3
    return out


def _per_pixel(kernel: Any, data: np.ndarray, weight: int) -> np.ndarray:
    """``kernel`` over the pixels of an ``(..., channels)`` array, on the thread pool."""
    src = np.ascontiguousarray(data)
    if src.dtype.kind not in "iu":
        msg = f"the reversible colour transform needs integers, not {src.dtype}"
        raise InvalidParameter(msg)
    if src.ndim < 1 or src.shape[-1] < 3:
        msg = f"the reversible colour transform needs 3 or 4 channels, not shape {src.shape}"
        raise InvalidParameter(msg)
    flat = src.reshape(-1, src.shape[-1])
    out = np.empty(flat.shape, dtype=np.int64)
    run_rows(lambda lo, hi: kernel(flat, weight, out, lo, hi), flat.shape[0], flat.size)
    return out.reshape(src.shape)


def predicted_rct_forward(rgb: np.ndarray, weight: int) -> np.ndarray:
    """JPEG 2000's RCT then :func:`predict_chroma`, in one pass: ``int64`` ``(Y, Cb, Cr', ...)``.

    Examples
    --------
    >>> import numpy as np
    >>> from wavecore.colour import rct_forward
    >>> rgb = np.random.default_rng(1).integers(0, 65536, (5, 6, 4))
    >>> bool(np.array_equal(predicted_rct_forward(rgb, -3), predict_chroma(rct_forward(rgb), -3)))
    True
    >>> bool(np.array_equal(predicted_rct_inverse(predicted_rct_forward(rgb, 5), 5), rgb))
    True
    """
    return _per_pixel(_kernels.predicted_rct_forward, rgb, weight)


def predicted_rct_inverse(ycc: np.ndarray, weight: int) -> np.ndarray:
    """The exact inverse of :func:`predicted_rct_forward` (``int64``)."""
    return _per_pixel(_kernels.predicted_rct_inverse, ycc, weight)


def chroma_weight(rgb: np.ndarray) -> int:
    """The weight of :data:`CHROMA_WEIGHTS` whose prediction leaves the smallest details.

    Measured on the RCT's chroma (``Cb = B - G``, ``Cr = R - G``) at every other pixel, by the
    5/3 predict residuals along both axes (the finest details, most of what is coded), summing
    absolute values (the coder's cost follows the logarithm of a magnitude, which the absolute
    value tracks better than the square: least squares, which large edges dominate, picked 0
    on astronaut, where 2 codes best).  0 when no weight makes them smaller.
    """
    data = np.asarray(rgb)
    if data.ndim != 3 or data.shape[2] < 3 or min(data.shape[:2]) < 6:
        return 0
    sub = data[::2, ::2].astype(np.int32)
    residuals = []
    for plane in (sub[..., 2] - sub[..., 1], sub[..., 0] - sub[..., 1]):  # Cb, then Cr
        rows = plane[1:-1] - ((plane[:-2] + plane[2:]) >> 1)
        cols = plane[:, 1:-1] - ((plane[:, :-2] + plane[:, 2:]) >> 1)
        residuals.append(np.concatenate([rows.ravel(), cols.ravel()]))
    b, r = residuals
    costs = [int(np.abs(r - ((w * b + 4) >> 3)).sum()) for w in CHROMA_WEIGHTS]
    best = int(np.argmin(costs))
    return CHROMA_WEIGHTS[best] if costs[best] < costs[CHROMA_WEIGHTS.index(0)] else 0


def colour_name(weight: int) -> str:
    """The header's colour for the RCT with :func:`predict_chroma` of ``weight`` (0: ``rct``)."""
    return "rct" if weight == 0 else f"rct-p{weight}"


def lossless_colour(image: np.ndarray) -> str:
    """The colour transform of a lossless encode: ``"none"`` for grey (or two channels), else
    the RCT, with Cr predicted from Cb at :func:`chroma_weight`'s weight where that pays."""
    if image.ndim != 3 or image.shape[2] < 3:
        return "none"
    return colour_name(chroma_weight(image))
