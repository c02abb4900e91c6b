"""The restoration filter: a small filter the encoder fits and the decoder applies to a lossy
picture's decoded samples, as VVC's adaptive loop filter does.

The encoder has both the original and what the decoder will return, so it can fit, by least
squares, a filter that takes the decoded picture closer to the original, and send its taps
in the header (some 30 bytes a channel).  Each colour channel (alpha is never filtered) is
split into :data:`CLASSES` classes by *activity*: the sum over the 5 × 5 neighbourhood of
each sample of the absolute Laplacian ``|4 x − x_N − x_S − x_W − x_E|``, cut at three
thresholds (the encoder takes the activity's quartiles).  Each class has its own 5 × 5
diamond filter, or none.  The diamond is point-symmetric and keeps the mean, so it has six
taps ``c_k``, one per pair of opposite offsets ``±o_k`` (:data:`OFFSETS`); a filtered sample
is, in integers::

    x + ((Σ_k c_k · (x[p + o_k] + x[p − o_k] − 2 x[p]) + 64) >> 7)

clipped to the dtype's range, with the taps ``c_k`` in −64 … 63 (multiples of 1/128).  Samples
outside the picture are mirrored (half-sample symmetric, as ``numpy.pad(mode="symmetric")``).
All of it is integer arithmetic, so every machine decodes the same samples.

Where it applies: lossy ``uint8`` and ``uint16`` pictures at full resolution.  A coarse level
(``level > 0``) and a ``keep`` below 1 decode without it (the filter was fitted to the full
reconstruction); a region decodes :data:`APRON` more samples around itself first, so that it
equals the same crop of the whole picture.

Measured (``benchmarks/postfilter.py``, then ``benchmarks/rate_distortion.py --peers``):
see docs/benchmarks.md.  The bytes: docs/bundle-format.md, "The restoration record".
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from numba import njit

from .errors import BundleError
from .transform import run_rows

__all__ = [
    "APRON",
    "CLASSES",
    "FILTERED_DTYPES",
    "OFFSETS",
    "TAPS",
    "TAP_MAX",
    "TAP_MIN",
    "apply_restoration",
    "check_restore",
    "colour_channels",
    "fit_restoration",
    "largest_activity",
    "record_bound",
]

#: One of each pair of opposite offsets ``(rows, cols)`` of the 5 × 5 diamond, centre excluded.
OFFSETS = ((0, 1), (0, 2), (1, -1), (1, 0), (1, 1), (2, 0))
TAPS = len(OFFSETS)
CLASSES = 4
TAP_MIN, TAP_MAX = -64, 63
TAP_SHIFT = 7
#: Samples a region decodes beyond its edges: the Laplacian (1) inside the 5 × 5 sum (2).
APRON = 3
#: The dtypes the filter applies to, and the largest activity each can give (25 · 4 · max).
FILTERED_DTYPES = {"uint8": 255, "uint16": 65535}
#: A class fits its taps from at least this many samples, else it has none.
LEAST_CLASS_SAMPLES = 8 * TAPS
#: The fit reads every row of a plane of up to this many samples, else every ``k``-th row
#: (a 2048² plane: every 16th), which fits the taps as well at a fraction of the time.
FIT_SAMPLES = 1 << 18
_ROW_PIECES = 16  # fixed, so that the fit's sums do not depend on the thread count


def colour_channels(shape: Any) -> int:
    """How many channels of a picture of ``shape`` are filtered: all but alpha."""
    if len(shape) == 2:
        return 1
    return 1 if shape[2] <= 2 else 3


def largest_activity(dtype: str) -> int:
    return 25 * 4 * FILTERED_DTYPES[dtype]


def record_bound(dtype: str, channels: int) -> int:
    """The most bytes the header's restoration record takes (see docs/bundle-format.md)."""
    threshold_bytes = (largest_activity(dtype).bit_length() + 6) // 7
    return channels * (1 + 3 * threshold_bytes + (TAPS * 7 * CLASSES + 7) // 8)


def check_restore(header: dict[str, Any]) -> None:
    """Raise :class:`BundleError` naming what is wrong with the header's ``restore``."""
    restore = header["restore"]
    dtype, shape = header.get("dtype"), header.get("shape")
    if (
        header.get("kind") != "image"
        or dtype not in FILTERED_DTYPES
        or header.get("quantizer") == "none"
        or not isinstance(shape, list)
        or len(shape) not in (2, 3)
    ):
        msg = "header field 'restore' applies only to lossy uint8 and uint16 images"
        raise BundleError(msg)
    channels = colour_channels(shape)
    if not isinstance(restore, list) or len(restore) != channels:
        msg = f"header field 'restore' must be a list of {channels} channel filters"
        raise BundleError(msg)
    largest = largest_activity(dtype)
    for item in restore:
        if item is None:
            continue
        if not isinstance(item, dict) or set(item) != {"edges", "taps"}:
            msg = "header field 'restore' holds a channel that is not null or {edges, taps}"
            raise BundleError(msg)
        edges, taps = item["edges"], item["taps"]
        if (
            not isinstance(edges, list)
            or len(edges) != CLASSES - 1
            or any(isinstance(e, bool) or not isinstance(e, int) for e in edges)
            or not 0 <= edges[0] <= edges[1] <= edges[2] <= largest
        ):
            msg = (
                f"header field 'restore' edges must be {CLASSES - 1} non-decreasing integers "
                f"from 0 to {largest}"
            )
            raise BundleError(msg)
        if not isinstance(taps, list) or len(taps) != CLASSES or all(t is None for t in taps):
            msg = f"header field 'restore' taps must list {CLASSES} classes, one at least on"
            raise BundleError(msg)
        for row in taps:
            if row is not None and (
                not isinstance(row, list)
                or len(row) != TAPS
                or any(isinstance(t, bool) or not isinstance(t, int) for t in row)
                or not all(TAP_MIN <= t <= TAP_MAX for t in row)
            ):
                msg = (
                    f"header field 'restore' taps must be null or {TAPS} integers from "
                    f"{TAP_MIN} to {TAP_MAX}"
                )
                raise BundleError(msg)


# --- the compiled passes ------------------------------------------------------------------
# They read a plane padded by APRON mirrored samples on every side (``numpy.pad(mode=
# "symmetric")``), so that no index needs mirroring: the Laplacian of the padded plane is the
# mirrored Laplacian, as the extension is symmetric about every edge.


@njit(nogil=True, cache=True)
def _laplacian_rows(padded, out, lo, hi):  # pragma: no cover - compiled
    """``out[a, b]``: the absolute Laplacian at picture sample ``(a − 2, b − 2)``."""
    cols = out.shape[1]
    for a in range(lo, hi):
        i = a + 1
        for b in range(cols):
            j = b + 1
            v = (
                4 * padded[i, j]
                - padded[i - 1, j]
                - padded[i + 1, j]
                - padded[i, j - 1]
                - padded[i, j + 1]
            )
            out[a, b] = v if v >= 0 else -v


@njit(nogil=True, cache=True)
def _box_rows(lap, out, lo, hi):  # pragma: no cover - compiled
    """``out[i, j]``: the sum of ``lap`` over the 5 × 5 samples around picture sample
    ``(i, j)``, for rows ``lo`` to ``hi``."""
    cols = out.shape[1]
    sums = np.empty((hi - lo + 4, cols), dtype=np.int32)
    for a in range(hi - lo + 4):
        for j in range(cols):
            r = lo + a
            sums[a, j] = lap[r, j] + lap[r, j + 1] + lap[r, j + 2] + lap[r, j + 3] + lap[r, j + 4]
    for a in range(hi - lo):
        for j in range(cols):
            out[lo + a, j] = (
                sums[a, j] + sums[a + 1, j] + sums[a + 2, j] + sums[a + 3, j] + sums[a + 4, j]
            )


@njit(nogil=True, cache=True)
def _class_of(a, e0, e1, e2):  # pragma: no cover - compiled
    return (a >= e0) + (a >= e1) + (a >= e2)


@njit(nogil=True, cache=True)
def _filter_rows(padded, activity, edges, taps, on, high, out, lo, hi):  # pragma: no cover
    cols = out.shape[1]
    e0, e1, e2 = edges[0], edges[1], edges[2]
    for i in range(lo, hi):
        r = i + 3
        for j in range(cols):
            q = j + 3
            x = np.int64(padded[r, q])
            c = _class_of(activity[i, j], e0, e1, e2)
            if on[c]:
                x2 = 2 * x
                delta = (
                    64
                    + taps[c, 0] * (padded[r, q + 1] + padded[r, q - 1] - x2)
                    + taps[c, 1] * (padded[r, q + 2] + padded[r, q - 2] - x2)
                    + taps[c, 2] * (padded[r + 1, q - 1] + padded[r - 1, q + 1] - x2)
                    + taps[c, 3] * (padded[r + 1, q] + padded[r - 1, q] - x2)
                    + taps[c, 4] * (padded[r + 1, q + 1] + padded[r - 1, q - 1] - x2)
                    + taps[c, 5] * (padded[r + 2, q] + padded[r - 2, q] - x2)
                )
                x = min(max(x + (delta >> 7), np.int64(0)), high)
            out[i, j] = x


@njit(nogil=True, cache=True)
def _fit_sums(padded, target, activity, edges, sums, lo, hi, stride):  # pragma: no cover
    """Per class ``c``, in ``sums[c]``: the upper triangle of the pair terms' Gram matrix (21),
    their products with ``target − x`` (6), and the count; from the rows ``lo``, ``lo +
    stride``, … below ``hi``."""
    cols = target.shape[1]
    e0, e1, e2 = edges[0], edges[1], edges[2]
    t = np.empty(6)
    for i in range(lo, hi, stride):
        r = i + 3
        for j in range(cols):
            q = j + 3
            x = np.float64(padded[r, q])
            x2 = 2.0 * x
            t[0] = padded[r, q + 1] + padded[r, q - 1] - x2
            t[1] = padded[r, q + 2] + padded[r, q - 2] - x2
            t[2] = padded[r + 1, q - 1] + padded[r - 1, q + 1] - x2
            t[3] = padded[r + 1, q] + padded[r - 1, q] - x2
            t[4] = padded[r + 1, q + 1] + padded[r - 1, q - 1] - x2
            t[5] = padded[r + 2, q] + padded[r - 2, q] - x2
            error = target[i, j] - x
            row = sums[_class_of(activity[i, j], e0, e1, e2)]
            n = 0
            for k in range(6):
                tk = t[k]
                for m in range(k, 6):
                    row[n] += tk * t[m]
                    n += 1
            for k in range(6):
                row[21 + k] += t[k] * error
            row[27] += 1.0


@njit(nogil=True, cache=True)
def _mirror(k, n):  # pragma: no cover - compiled
    """Index ``k`` of a line of ``n`` samples, half-sample symmetric beyond its ends."""
    k = k % (2 * n)
    return 2 * n - 1 - k if k >= n else k


@njit(nogil=True, cache=True)
def _restore_rows(picture, out, channel, edges, taps, on, high, lo, hi):  # pragma: no cover
    """Rows ``lo`` to ``hi`` of one channel of ``picture`` (rows, cols, channels), filtered
    into ``out``: the padded rows they need, their activity and the filter, in one block."""
    rows, cols = picture.shape[0], picture.shape[1]
    count = hi - lo
    padded = np.empty((count + 2 * APRON, cols + 2 * APRON), dtype=np.int32)
    for a in range(count + 2 * APRON):
        i = _mirror(lo - APRON + a, rows)
        for b in range(APRON):
            padded[a, b] = picture[i, _mirror(b - APRON, cols), channel]
            padded[a, cols + APRON + b] = picture[i, _mirror(cols + b, cols), channel]
        for j in range(cols):
            padded[a, APRON + j] = picture[i, j, channel]
    lap = np.empty((count + 4, cols + 4), dtype=np.int32)
    _laplacian_rows(padded, lap, 0, count + 4)
    activity = np.empty((count, cols), dtype=np.int32)
    _box_rows(lap, activity, 0, count)
    filtered = np.empty((count, cols), dtype=np.int32)
    _filter_rows(padded, activity, edges, taps, on, high, filtered, 0, count)
    for a in range(count):
        for j in range(cols):
            out[lo + a, j, channel] = filtered[a, j]


# --- the planes -------------------------------------------------------------------------


def _activity(padded: np.ndarray) -> np.ndarray:
    """Each sample's sum of absolute Laplacians over its 5 × 5 neighbourhood, from the plane
    padded by :data:`APRON` (int32, the plane's shape)."""
    rows, cols = padded.shape[0] - 2 * APRON, padded.shape[1] - 2 * APRON
    lap = np.empty((rows + 4, cols + 4), dtype=np.int32)
    run_rows(lambda lo, hi: _laplacian_rows(padded, lap, lo, hi), rows + 4, lap.size)
    out = np.empty((rows, cols), dtype=np.int32)
    run_rows(lambda lo, hi: _box_rows(lap, out, lo, hi), rows, out.size)
    return out


def _planes(picture: np.ndarray) -> list[np.ndarray]:
    """The colour channels (all but alpha)."""
    if picture.ndim == 2:
        return [picture]
    return [picture[..., c] for c in range(colour_channels(picture.shape))]


def _padded(plane: np.ndarray) -> np.ndarray:
    """``plane`` as int32, padded by :data:`APRON` mirrored samples on every side."""
    return np.pad(plane.astype(np.int32), APRON, mode="symmetric")


def apply_restoration(picture: np.ndarray, restore: list[Any]) -> np.ndarray:
    """``picture`` (a decoded ``uint8`` or ``uint16`` picture, ``(H, W)`` or ``(H, W, C)``)
    with the header's ``restore`` filters applied to its colour channels; a new array.

    Parameters
    ----------
    picture : numpy.ndarray
        The decoder's samples, in the picture's dtype.
    restore : list
        The header's ``restore``: per colour channel ``None`` or ``{"edges", "taps"}``.

    Returns
    -------
    numpy.ndarray
        The filtered picture, of ``picture``'s shape and dtype.
    """
    high = int(np.iinfo(picture.dtype).max)
    out = picture.copy()
    source = picture[..., np.newaxis] if picture.ndim == 2 else picture
    target = out[..., np.newaxis] if out.ndim == 2 else out
    rows = picture.shape[0]
    for channel, item in enumerate(restore):
        if item is None:
            continue
        edges = np.array(item["edges"], dtype=np.int64)
        taps = np.array([t if t is not None else [0] * TAPS for t in item["taps"]], np.int64)
        on = np.array([t is not None for t in item["taps"]])
        run_rows(
            functools.partial(_restore_rows, source, target, channel, edges, taps, on, high),
            rows,
            rows * picture.shape[1],
            per_thread=4,
        )
    return out


def fit_restoration(
    decoded: np.ndarray, original: np.ndarray, gains: list[tuple[float, int, int]] | None = None
) -> list[Any] | None:
    """The ``restore`` filters that take ``decoded`` closer to ``original`` (both ``uint8`` or
    ``uint16``, the same shape), or None where no class of any channel gains.

    Per colour channel: the activity's quartiles as the class edges, then per class the
    least-squares taps, rounded to 1/128; a class keeps them only if they lower its squared
    error (as the Gram matrix predicts it).  The caller measures the filtered picture.
    ``gains``, if given, receives ``(change of squared error, channel, class)`` for each class
    kept (the change is negative), so that a caller short of bytes can drop the weakest.
    """
    result: list[Any] = []
    high = largest_activity(decoded.dtype.name)
    for plane, target in zip(_planes(decoded), _planes(original), strict=True):
        padded = _padded(plane)
        activity = _activity(padded)
        edges = np.quantile(activity[::2, ::2], (0.25, 0.5, 0.75), method="lower")
        changes: list[float] = []
        item = _fit_plane(padded, target, activity, [min(int(e), high) for e in edges], changes)
        result.append(item)
        if gains is not None and item is not None:
            channel = len(result) - 1
            gains.extend((changes[c], channel, c) for c in range(CLASSES) if item["taps"][c])
    return result if any(item is not None for item in result) else None


def _fit_plane(
    padded: np.ndarray,
    target: np.ndarray,
    activity: np.ndarray,
    edges: list[int],
    changes: list[float],
) -> dict[str, Any] | None:
    rows = target.shape[0]
    bounds = np.linspace(0, rows, min(rows, _ROW_PIECES) + 1).astype(int)
    pieces = len(bounds) - 1
    sums = np.zeros((pieces, CLASSES, 28))
    edge_array = np.array(edges, dtype=np.int64)

    stride = max(1, target.size // FIT_SAMPLES)

    def piece(lo: int, hi: int) -> None:
        for p in range(lo, hi):
            first = bounds[p] + (-bounds[p]) % stride  # the rows 0, stride, 2 · stride, …
            _fit_sums(padded, target, activity, edge_array, sums[p], first, bounds[p + 1], stride)

    run_rows(piece, pieces, target.size, pieces=pieces)
    total = sums.sum(axis=0)
    upper = np.triu_indices(TAPS)
    taps: list[list[int] | None] = []
    for c in range(CLASSES):
        gram = np.zeros((TAPS, TAPS))
        gram[upper] = total[c, :21]
        gram = gram + np.triu(gram, 1).T
        found = _class_taps(gram, total[c, 21:27], int(total[c, 27]))
        taps.append(None if found is None else found[0])
        changes.append(0.0 if found is None else found[1])
    if all(t is None for t in taps):
        return None
    return {"edges": edges, "taps": taps}


def _class_taps(gram: np.ndarray, rhs: np.ndarray, count: int) -> tuple[list[int], float] | None:
    if count < LEAST_CLASS_SAMPLES:
        return None
    try:
        solution = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(solution)):
        return None
    scale = 1 << TAP_SHIFT
    taps = np.clip(np.rint(solution * scale), TAP_MIN, TAP_MAX)
    # The change of the class's squared error with these taps, before the integer rounding.
    change = float(taps @ gram @ taps) / scale**2 - 2.0 * float(taps @ rhs) / scale
    if not change < 0.0 or not taps.any():
        return None
    return [int(t) for t in taps], change
