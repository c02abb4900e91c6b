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
Every value is an integer, and the compiled passes compute them exactly (in floats wide
enough to hold them), so every machine decodes the same samples.

Where it applies: lossy ``uint8`` and ``uint16`` pictures at full resolution (the encoder
fits one for a ``bpp`` target, in the bytes the rate control left free).  A coarse level
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
from .transform import run_calls, run_rows

__all__ = [
    "APRON",
    "CLASSES",
    "FILTERED_DTYPES",
    "OFFSETS",
    "RECORD_GUARD",
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
#: The restoration record's first bytes.  A reader from before the record reads them as the
#: PSNR's head (1: a number follows) and a number of form 12 (null) with value bits, which it
#: refuses by name ("binary header field 'psnr' … number form 12 takes no value bits").
RECORD_GUARD = b"\x01\x1c"
#: A class fits its taps from at least this many samples, else it has none.
LEAST_CLASS_SAMPLES = 8 * TAPS
#: The fit reads every row of a picture of up to this many samples a channel, else a
#: sample of its row blocks (:func:`_sample_blocks`).
FIT_SAMPLES = 1 << 17
_FIT_BLOCK = 16


def colour_channels(shape: Any) -> int:
    """How many channels of a picture of ``shape`` are filtered: all but alpha."""
    if len(shape) == 2:
        return 1
    return 1 if shape[2] <= 2 else 3


def largest_activity(dtype: str) -> int:
    """The largest activity a picture of ``dtype`` (``"uint8"`` or ``"uint16"``) can have:
    25 absolute Laplacians of at most 4 × the dtype's largest value."""
    return 25 * 4 * FILTERED_DTYPES[dtype]


def record_bound(dtype: str, channels: int) -> int:
    """The most bytes the header's restoration record takes (see docs/bundle-format.md): its
    two guard bytes, then per channel a mask, three edges and the taps."""
    threshold_bytes = (largest_activity(dtype).bit_length() + 6) // 7
    per_channel = 1 + 3 * threshold_bytes + (TAPS * 7 * CLASSES + 7) // 8
    return len(RECORD_GUARD) + channels * per_channel


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
# They read a block of rows padded by APRON mirrored samples on every side (_pad_block), so
# that no other index needs mirroring: the Laplacian of the padded plane is the mirrored
# Laplacian, as the extension is symmetric about every edge.


# The passes compute in floats: float32 for uint8 pictures (every value, up to 6 · 64 · 1 020
# + 64 for a filtered sample and 25 · 2 040 for an activity, is an integer below 2**24, so
# exact), float64 for uint16 ones (below 2**53).  Numba widens int32 arithmetic to int64,
# whose multiplications AVX2 lacks; float32 runs eight lanes wide.


@njit(nogil=True, cache=True)
def _laplacian_rows(padded, out, lo, hi):  # pragma: no cover - compiled
    """``out[a, b]``: the absolute Laplacian at picture sample ``(a − 2, b − 2)``."""
    cols = out.shape[1]
    for a in range(lo, hi):
        up, row, down = padded[a], padded[a + 1], padded[a + 2]
        target = out[a]
        for b in range(cols):
            j = b + 1
            x2 = row[j] + row[j]  # not 4 * x: an integer literal would widen float32 to float64
            target[b] = abs(x2 + x2 - up[j] - down[j] - row[j - 1] - row[j + 1])


@njit(nogil=True, cache=True)
def _box_rows(lap, out, lo, hi):  # pragma: no cover - compiled
    """``out[i, j]``: the sum of ``lap`` over the 5 × 5 samples around picture sample
    ``(i, j)``, for rows ``lo`` to ``hi``."""
    cols = out.shape[1]
    sums = np.empty((hi - lo + 4, cols), dtype=out.dtype)
    for a in range(hi - lo + 4):
        row = lap[lo + a]
        target = sums[a]
        for j in range(cols):
            target[j] = row[j] + row[j + 1] + row[j + 2] + row[j + 3] + row[j + 4]
    for a in range(hi - lo):
        s0, s1, s2, s3, s4 = sums[a], sums[a + 1], sums[a + 2], sums[a + 3], sums[a + 4]
        target = out[lo + a]
        for j in range(cols):
            target[j] = s0[j] + s1[j] + s2[j] + s3[j] + s4[j]


@njit(nogil=True, cache=True)
def _filter_rows(padded, activity, edges, taps, constants, out, lo, hi):  # pragma: no cover
    """The filter on rows ``lo`` to ``hi``: ``taps`` is (6, 4), a class's column zero where it
    has none; ``constants`` is (0, 64, 1/128, the dtype's largest value); ``edges``, ``taps``
    and ``constants`` of the planes' float type.  Each row takes one
    pass per filtered class with that class's taps as constants, kept where the sample is of
    the class: no branches, so the compiler vectorises it."""
    cols = out.shape[1]
    e0, e1, e2 = edges[0], edges[1], edges[2]
    # Constants of the planes' float type: a float64 literal would widen float32 arithmetic.
    zero, half, scale, high = constants[0], constants[1], constants[2], constants[3]
    classes = np.empty(cols, dtype=np.int32)
    for i in range(lo, hi):
        up2, up, row, down, down2 = (
            padded[i + 1],
            padded[i + 2],
            padded[i + 3],
            padded[i + 4],
            padded[i + 5],
        )
        level = activity[i]
        target = out[i]
        for j in range(cols):
            a = level[j]
            classes[j] = (a >= e0) + (a >= e1) + (a >= e2)
            target[j] = row[j + 3]
        for c in range(taps.shape[1]):
            k0, k1, k2 = taps[0, c], taps[1, c], taps[2, c]
            k3, k4, k5 = taps[3, c], taps[4, c], taps[5, c]
            if k0 == 0 and k1 == 0 and k2 == 0 and k3 == 0 and k4 == 0 and k5 == 0:
                continue
            for j in range(cols):
                q = j + 3
                x = row[q]
                x2 = x + x
                delta = (
                    half
                    + k0 * (row[q + 1] + row[q - 1] - x2)
                    + k1 * (row[q + 2] + row[q - 2] - x2)
                    + k2 * (down[q - 1] + up[q + 1] - x2)
                    + k3 * (down[q] + up[q] - x2)
                    + k4 * (down[q + 1] + up[q - 1] - x2)
                    + k5 * (down2[q] + up2[q] - x2)
                )
                value = x + np.floor(delta * scale)
                value = zero if value < zero else value
                value = high if value > high else value
                target[j] = value if classes[j] == c else target[j]


@njit(nogil=True, cache=True)
def _fit_sums(padded, target, activity, edges, sums, lo, hi):  # pragma: no cover - compiled
    """Per class ``c``, in ``sums[c]``: the upper triangle of the pair terms' Gram matrix (21),
    their products with ``target − x`` (6), and the count, over rows ``lo`` to ``hi``."""
    cols = target.shape[1]
    e0, e1, e2 = edges[0], edges[1], edges[2]
    t = np.empty(6)
    for i in range(lo, hi):
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
            a = activity[i, j]
            row = sums[(a >= e0) + (a >= e1) + (a >= e2)]
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
def _change_sums(padded, filtered, target, activity, edges, changes):  # pragma: no cover
    """Per class, into ``changes``: how much the squared error against ``target`` changes
    from the unfiltered samples (``padded``'s inner part) to ``filtered``."""
    e0, e1, e2 = edges[0], edges[1], edges[2]
    for i in range(filtered.shape[0]):
        for j in range(filtered.shape[1]):
            wanted = np.float64(target[i, j])
            before = np.float64(padded[i + 3, j + 3]) - wanted
            after = np.float64(filtered[i, j]) - wanted
            a = activity[i, j]
            changes[(a >= e0) + (a >= e1) + (a >= e2)] += after * after - before * before


@njit(nogil=True, cache=True)
def _mirror(k, n):  # pragma: no cover - compiled
    """Index ``k`` of a line of ``n`` samples, half-sample symmetric beyond its ends."""
    k = k % (2 * n)
    return 2 * n - 1 - k if k >= n else k


@njit(nogil=True, cache=True)
def _pad_block(picture, channel, lo, padded):  # pragma: no cover - compiled
    """Rows ``lo − APRON`` on of one channel of ``picture`` (rows, cols, channels), mirrored
    beyond its edges, into ``padded`` (``count + 2 · APRON`` rows, ``cols + 2 · APRON``)."""
    rows, cols = picture.shape[0], picture.shape[1]
    for a in range(padded.shape[0]):
        i = _mirror(lo - APRON + a, rows)
        for b in range(APRON):
            padded[a, b] = picture[i, _mirror(b - APRON, cols), channel]
            padded[a, cols + APRON + b] = picture[i, _mirror(cols + b, cols), channel]
        for j in range(cols):
            padded[a, APRON + j] = picture[i, j, channel]


@njit(nogil=True, cache=True)
def _block(picture, channel, lo, hi, like):  # pragma: no cover - compiled
    """Rows ``lo`` to ``hi`` of one channel, padded, and their activity, in ``like``'s
    dtype (:func:`_work_dtype`)."""
    cols = picture.shape[1]
    count = hi - lo
    padded = np.empty((count + 2 * APRON, cols + 2 * APRON), dtype=like.dtype)
    _pad_block(picture, channel, lo, padded)
    lap = np.empty((count + 4, cols + 4), dtype=like.dtype)
    _laplacian_rows(padded, lap, 0, count + 4)
    activity = np.empty((count, cols), dtype=like.dtype)
    _box_rows(lap, activity, 0, count)
    return padded, activity


@njit(nogil=True, cache=True)
def _restore_rows(picture, out, channel, edges, taps, constants, lo, hi):  # pragma: no cover
    """Rows ``lo`` to ``hi`` of one channel of ``picture`` (rows, cols, channels), filtered
    into ``out``: the padded rows they need, their activity and the filter, in one block."""
    padded, activity = _block(picture, channel, lo, hi, taps)
    filtered = np.empty(activity.shape, dtype=taps.dtype)
    _filter_rows(padded, activity, edges, taps, constants, filtered, 0, hi - lo)
    for a in range(hi - lo):
        for j in range(activity.shape[1]):
            out[lo + a, j, channel] = filtered[a, j]


# --- the pictures -----------------------------------------------------------------------


def _work_dtype(dtype: np.dtype[Any]) -> type[np.floating[Any]]:
    """The float type the passes compute in for a picture of ``dtype`` (exact: see above)."""
    return np.float32 if dtype == np.uint8 else np.float64


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
    work = _work_dtype(picture.dtype)
    out = picture.copy()
    source = picture[..., np.newaxis] if picture.ndim == 2 else picture
    target = out[..., np.newaxis] if out.ndim == 2 else out
    rows = picture.shape[0]
    for channel, item in enumerate(restore):
        if item is None:
            continue
        edges = np.array(item["edges"], dtype=work)
        taps = _tap_table(item["taps"], work)
        constants = _constants(work, high)
        run_rows(
            functools.partial(_restore_rows, source, target, channel, edges, taps, constants),
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

    Per colour channel, from a sample of its rows (:func:`_sample_blocks`): the activity's
    quartiles as the class edges, then per class the least-squares taps, rounded to 1/128;
    a class keeps them only if, applied as the decoder applies them (integers), they lower
    its squared error on the sample.  The caller measures the whole filtered picture.
    ``gains``, if given, receives ``(change of squared error, channel, class)`` for each class
    kept (the change on the sample, scaled to the whole picture; negative), so that a caller
    can tell what the filter is worth, and drop the weakest classes when short of bytes.
    """
    source = decoded[..., np.newaxis] if decoded.ndim == 2 else decoded
    target = original[..., np.newaxis] if original.ndim == 2 else original
    high = int(np.iinfo(decoded.dtype).max)
    blocks = _sample_blocks(decoded.shape[0], decoded.shape[1])
    channels = colour_channels(decoded.shape)
    result: list[Any] = [None] * channels
    found: list[list[tuple[float, int, int]]] = [[] for _ in range(channels)]

    def fit(channel: int) -> None:
        result[channel] = _fit_channel(source, target, channel, blocks, high, found[channel])

    run_calls([functools.partial(fit, c) for c in range(channels)])  # a channel a thread
    if gains is not None:
        gains.extend(g for channel_gains in found for g in channel_gains)
    return result if any(item is not None for item in result) else None


def _sample_blocks(rows: int, cols: int) -> list[tuple[int, int]]:
    """The row blocks a fit reads: every block of :data:`_FIT_BLOCK` rows of a picture of up
    to :data:`FIT_SAMPLES` samples a channel, else every ``k``-th (a 2048² picture: every
    16th), which fits the taps as well at a fraction of the time."""
    step = max(1, (rows * cols) // FIT_SAMPLES)
    starts = range(0, rows, _FIT_BLOCK * step)
    return [(lo, min(lo + _FIT_BLOCK, rows)) for lo in starts]


def _fit_channel(
    source: np.ndarray,
    target: np.ndarray,
    channel: int,
    blocks: list[tuple[int, int]],
    high: int,
    gains: list[tuple[float, int, int]],
) -> dict[str, Any] | None:
    work = _work_dtype(source.dtype)
    like = np.empty(0, dtype=work)
    made = [_block(source, channel, lo, hi, like) for lo, hi in blocks]
    # The original's rows, copied: one array type for the kernels (the caller's original may
    # be read-only or strided, each a signature of its own to compile).
    wanted = [target[lo:hi, :, channel].copy() for lo, hi in blocks]
    # The quartiles from every other row and column of the sample: as good, and 4× cheaper.
    sampled = np.concatenate([activity[::2, ::2].ravel() for _, activity in made])
    quartiles = np.quantile(sampled, (0.25, 0.5, 0.75), method="lower")
    edges = [min(int(e), largest_activity(source.dtype.name)) for e in quartiles]
    edge_array = np.array(edges, dtype=work)
    sums = np.zeros((CLASSES, 28))
    for (lo, hi), (padded, activity), rows in zip(blocks, made, wanted, strict=True):
        _fit_sums(padded, rows, activity, edge_array, sums, 0, hi - lo)
    upper = np.triu_indices(TAPS)
    taps: list[list[int] | None] = []
    for c in range(CLASSES):
        gram = np.zeros((TAPS, TAPS))
        gram[upper] = sums[c, :21]
        gram = gram + np.triu(gram, 1).T
        taps.append(_class_taps(gram, sums[c, 21:27], int(sums[c, 27])))
    if all(t is None for t in taps):
        return None
    # What the taps change, as the decoder applies them, on the sample.
    table = _tap_table(taps, work)
    constants = _constants(work, high)
    changes = np.zeros(CLASSES)
    for (lo, hi), (padded, activity), rows in zip(blocks, made, wanted, strict=True):
        filtered = np.empty(activity.shape, dtype=work)
        _filter_rows(padded, activity, edge_array, table, constants, filtered, 0, hi - lo)
        _change_sums(padded, filtered, rows, activity, edge_array, changes)
    kept = [t if t is not None and changes[c] < 0 else None for c, t in enumerate(taps)]
    if all(t is None for t in kept):
        return None
    # The sample's changes, scaled to the whole channel.
    share = source.shape[0] / sum(hi - lo for lo, hi in blocks)
    gains.extend((float(changes[c]) * share, channel, c) for c in range(CLASSES) if kept[c])
    return {"edges": edges, "taps": kept}


def _constants(work: type[np.floating[Any]], high: int) -> np.ndarray:
    """:func:`_filter_rows`' constants."""
    return np.array([0.0, 64.0, 1.0 / (1 << TAP_SHIFT), high], dtype=work)


def _tap_table(taps: list[Any], work: type[np.floating[Any]]) -> np.ndarray:
    """The kernels' (6, 4) table: column ``c`` holds class ``c``'s taps, or zeros."""
    return np.array([t if t is not None else [0] * TAPS for t in taps], dtype=work).T.copy()


def _class_taps(gram: np.ndarray, rhs: np.ndarray, count: int) -> list[int] | None:
    if count < LEAST_CLASS_SAMPLES:
        return None
    try:
        solution = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(solution)):
        return None
    taps = np.clip(np.rint(solution * (1 << TAP_SHIFT)), TAP_MIN, TAP_MAX)
    return [int(t) for t in taps] if taps.any() else None
