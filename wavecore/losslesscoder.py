"""The lossless coder: a context-mixing binary arithmetic coder for the integer lifting's bands.

Lossless bundles used to go through the lossy path's block coder (``"context"`` version 4),
whose models are tuned for quantized bands: a few context classes, the bits below the top two
sent raw, 128 × 128 blocks that each learn afresh.  Lossless bands are dense, so they pay for a
stronger model, which this coder (the context coder's version 5) gives them:

* each resolution level is one stream (no blocks): the models learn over the whole level;
* every value is binarised as in the block coder (zero flag, the bit length in unary, the bits
  below the leading one), but each of those bits is coded at a probability mixed, in the
  logistic domain, from three adaptive models with different contexts: the causal neighbours'
  magnitudes (finely classed); the parent band's magnitudes around the same place (or, in the
  coarse band, the local gradients) with the neighbours coarsely; the other orientations and
  the first channel at the same place with the nearest two neighbours.  The mixer's weights are
  learned per decision and orientation (PAQ's logistic mixing, in integers as in lpaq1);
* the coarse band is predicted by LOCO-I's median edge detector from decoded samples;
* signs are mixed from two models of neighbouring, parent, sibling and first-channel signs.

Why our own coder rather than constriction's: the mixing needs a probability per bit computed
from the bits before it, in compiled code; constriction's coders take their models from Python.

Every step is integer arithmetic, so the bytes are the same on every machine.  The bit-level
specification is in ``docs/bundle-format.md`` (section "Context coder version 5").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from . import _losslesskernels as kernels
from .errors import BundleError
from .layout import as_levels, is_band_group
from .transform import run_rows
from .varints import encode_varint

__all__ = [
    "LOSSLESS_VERSION",
    "decode_lossless_levels",
    "encode_lossless_levels",
    "stripes_needed",
]

#: The coder's version in the header: it is the context coder's version 5 (``coder:
#: "context"``, ``cparams {"version": 5, "two_d": true}``), so that the binary header holds it
#: in its one compact byte; versions 2 to 4 are :mod:`wavecore.entropy`'s.
LOSSLESS_VERSION = 5
_MAX_VALUE = 2**31 - 1
#: Rows of a level's first band per stripe, and the most stripes a level is cut into.
STRIPE_ROWS = 192
MAX_STRIPES = 16
#: What one value costs the coder, in the elementwise passes' units of
#: :func:`wavecore.transform.run_rows`'s threading threshold: coding a value takes about 350 ns,
#: a hundred times an elementwise pass, so a 512 × 512 level's two stripes go to two threads
#: (counted as 262,144 elements they stayed on one, and the grey pictures were coded serially).
WORK_PER_VALUE = 64


def _planes(
    shapes: Sequence[tuple[int, int]],
    channels: int,
    approx: bool,
    parent_shapes: Sequence[tuple[int, int]] | None,
) -> tuple[np.ndarray, int, int]:
    """The ``planes`` table of one level: every band of every channel in coding order (channel
    by channel, each channel's bands in the layout's order), and the values' and the parent
    values' total counts.  ``shapes`` are the bands' 2-D shapes (rows, columns)."""
    bands = len(shapes)
    table = np.full((channels * bands, kernels.PLANE_FIELDS), -1, dtype=np.int64)
    offset = 0
    offsets = {}
    for c in range(channels):
        for b, (rows, cols) in enumerate(shapes):
            offsets[c, b] = offset
            offset += rows * cols
    parent_offsets = {}
    parent_total = 0
    if parent_shapes is not None:
        for c in range(channels):
            for b, (rows, cols) in enumerate(parent_shapes):
                parent_offsets[c, b] = parent_total
                parent_total += rows * cols
    for c in range(channels):
        for b, (rows, cols) in enumerate(shapes):
            row = table[c * bands + b]
            row[kernels.P_OFF] = offsets[c, b]
            row[kernels.P_ROWS] = rows
            row[kernels.P_COLS] = cols
            row[kernels.P_ORIENT] = kernels.APPROX if approx else b
            if parent_shapes is not None:
                row[kernels.P_PAR] = parent_offsets[c, b]
                row[kernels.P_PROWS], row[kernels.P_PCOLS] = parent_shapes[b]
            if b >= 1:
                row[kernels.P_SIB1] = offsets[c, 0]
                row[kernels.P_S1ROWS], row[kernels.P_S1COLS] = shapes[0]
            if b >= 2:
                row[kernels.P_SIB2] = offsets[c, 1]
                row[kernels.P_S2ROWS], row[kernels.P_S2COLS] = shapes[1]
            if c > 0:
                row[kernels.P_LUMA] = offsets[0, b]
    return table, offset, parent_total


def _as_2d(shape: tuple[int, ...]) -> tuple[tuple[int, int], int]:
    """A band's (rows, columns) and channel count: ``(rows, cols)`` or ``(rows, cols, ch)``."""
    if len(shape) == 2:
        return (shape[0], shape[1]), 1
    if len(shape) == 3:
        return (shape[0], shape[1]), shape[2]
    msg = f"the lossless coder codes 2-D bands (with channels), not shape {shape}"
    raise BundleError(msg)


def _level_shapes(entry: Any) -> list[tuple[int, ...]]:
    if is_band_group(entry):
        return [tuple(np.shape(b)) if not isinstance(b, tuple) else b for b in entry]
    return [tuple(np.shape(entry)) if not isinstance(entry, tuple) else entry]


def _flatten(bands: Sequence[np.ndarray], channels: int) -> np.ndarray:
    """Channel by channel, band by band, row by row (the coding order)."""
    parts = []
    for c in range(channels):
        for band in bands:
            plane = band if band.ndim == 2 else band[..., c]
            parts.append(np.ascontiguousarray(plane, dtype=np.int64).reshape(-1))
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def stripe_count(rows: int) -> int:
    """The stripes of a level whose first band has ``rows`` rows: one per :data:`STRIPE_ROWS`
    rows (at least one, at most :data:`MAX_STRIPES`), each coded on its own, in parallel."""
    return max(1, min(MAX_STRIPES, rows // STRIPE_ROWS))


def _code_all(jobs: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]]) -> list[bytes]:
    """Code every level (``values, parent, table, stripes`` each): all their stripes at once
    on the thread pool, since an encoder knows every level's values (a one-level picture's
    two chunks, each a single stripe, then take both threads instead of one)."""
    tasks = [(level, stripe) for level, job in enumerate(jobs) for stripe in range(job[3])]
    scratch = [np.zeros(job[0].size, dtype=np.int64) for job in jobs]
    parts: list[bytes] = [b""] * len(tasks)

    def code(lo: int, hi: int) -> None:
        for task in range(lo, hi):
            level, stripe = tasks[task]
            values, parent, table, stripes = jobs[level]
            mags = scratch[level]
            out = np.empty(values.size // stripes + 1024, dtype=np.uint8)
            n = kernels.encode_level(values, mags, parent, table, stripe, stripes, out)
            if n > out.size:
                out = np.empty(n, dtype=np.uint8)
                kernels.encode_level(values, mags, parent, table, stripe, stripes, out)
            parts[task] = out[:n].tobytes()

    work = WORK_PER_VALUE * sum(job[0].size for job in jobs)
    run_rows(code, len(tasks), work, pieces=len(tasks))
    chunks = []
    start = 0
    for job in jobs:
        mine = parts[start : start + job[3]]
        start += job[3]
        lengths = b"".join(encode_varint(len(part)) for part in mine[:-1])
        chunks.append(lengths + b"".join(mine))
    return chunks


def _split(chunk: bytes, stripes: int, index: int) -> list[np.ndarray]:
    """A chunk's stripes (BundleError if its lengths do not fit it)."""
    data = np.frombuffer(chunk, dtype=np.uint8)
    pos, lengths = 0, []
    for _ in range(stripes - 1):
        value = shift = 0
        while True:
            if pos >= len(chunk) or shift > 56:
                msg = f"lossless chunk {index}: its stripe lengths run past its end"
                raise BundleError(msg)
            byte = chunk[pos]
            pos += 1
            value |= (byte & 0x7F) << shift
            shift += 7
            if byte < 0x80:
                break
        lengths.append(value)
    lengths.append(len(chunk) - pos - sum(lengths))
    if lengths[-1] < 0:
        msg = f"lossless chunk {index}: stripes of {sum(lengths[:-1])} bytes do not fit it"
        raise BundleError(msg)
    parts = []
    for length in lengths:
        parts.append(data[pos : pos + length])
        pos += length
    return parts


def _stripe_rows(rows: int, stripes: int, stripe: int) -> tuple[int, int]:
    """The ``[start, stop)`` rows of a band of ``rows`` rows in stripe ``stripe`` (as the
    kernels cut them)."""
    return rows * stripe // stripes, rows * (stripe + 1) // stripes


def stripes_needed(shapes: Sequence[Any], masks: Sequence[Sequence[Any]]) -> list[np.ndarray]:
    """Which stripes of each level a region needs: those holding a row of a band that the
    region's ``masks`` (:func:`wavecore.regions.band_masks`, a ``(rows, cols)`` pair of masks
    per band, in layout order) want, and, from the third entry on, the parent level's stripes
    whose rows those stripes' contexts read (rows ``r >> 1`` and the one below).

    Parameters
    ----------
    shapes : sequence
        The layout's entries (a band's shape, or a tuple of three), coarse first.
    masks : sequence
        One list of mask pairs per entry decoded (at most ``len(shapes)``).

    Returns
    -------
    list of numpy.ndarray
        Per entry decoded, a boolean per stripe.
    """
    levels = []
    for index, band_masks in enumerate(masks):
        rows = [_as_2d(s)[0][0] for s in _level_shapes(shapes[index])]
        stripes = stripe_count(rows[0])
        wanted = np.zeros(stripes, dtype=bool)
        for band_rows, mask in zip(rows, band_masks, strict=True):
            want = np.asarray(mask[0], dtype=bool)
            for s in range(stripes):
                lo, hi = _stripe_rows(band_rows, stripes, s)
                wanted[s] |= bool(want[lo:hi].any())
        levels.append((rows, wanted))
    # Finest first, so that a parent's stripes wanted by its child are passed on up.
    for index in range(len(levels) - 1, 1, -1):
        rows, wanted = levels[index]
        parent_rows, parent_wanted = levels[index - 1]
        for child in np.flatnonzero(wanted).tolist():
            for band_rows, prows in zip(rows, parent_rows, strict=True):
                lo, hi = _stripe_rows(band_rows, len(wanted), child)
                if hi <= lo:
                    continue
                first, last = lo >> 1, min(((hi - 1) >> 1) + 1, prows - 1)
                for p in range(len(parent_wanted)):
                    plo, phi = _stripe_rows(prows, len(parent_wanted), p)
                    if plo <= last and first < phi:
                        parent_wanted[p] = True
    return [wanted for _, wanted in levels]


def _decode_stripes(
    levels: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]],
    wanted: list[np.ndarray | None] | None = None,
) -> None:
    """Decode the stripes of ``levels`` (``values, mags, ancestors, table, parts`` each, none
    looking at another's values) into their ``values``, all at once on the thread pool: every
    stripe, or those ``wanted`` marks (None: all of a level's)."""
    marks = [None] * len(levels) if wanted is None else wanted
    tasks = [
        (level, stripe)
        for level, job in enumerate(levels)
        for stripe in range(len(job[4]))
        if (mark := marks[level]) is None or mark[stripe]
    ]
    damaged: list[int] = []

    def decode(lo: int, hi: int) -> None:
        for task in range(lo, hi):
            level, stripe = tasks[task]
            values, mags, ancestors, table, parts = levels[level]
            stripes = len(parts)
            part = parts[stripe]
            if kernels.decode_level(values, mags, ancestors, table, stripe, stripes, part) < 0:
                damaged.append(stripe)

    # a stripe's share of its level's values, for each stripe decoded
    work = WORK_PER_VALUE * sum(
        levels[level][0].size // len(levels[level][4]) for level, _ in tasks
    )
    run_rows(decode, len(tasks), work, pieces=len(tasks))
    if damaged:
        msg = f"lossless-coded stripe(s) {sorted(damaged)} decode to values beyond int32"
        raise BundleError(msg)


def encode_lossless_levels(coeffs: Sequence[Any]) -> tuple[list[bytes], dict[str, Any]]:
    """Code a 2-D decomposition (``wavedec2`` layout, integers, bands ``(rows, cols)`` or
    ``(rows, cols, channels)``) into one chunk per entry, coarse first."""
    levels = as_levels(coeffs, "coeffs")
    jobs = []
    parent: np.ndarray | None = None
    parent_shapes: list[tuple[int, int]] | None = None
    for index, bands in enumerate(levels):
        dims = [_as_2d(tuple(b.shape)) for b in bands]
        shapes = [d[0] for d in dims]
        channels = dims[0][1]
        table, _, _ = _planes(shapes, channels, index == 0, parent_shapes if index > 1 else None)
        values = _flatten(bands, channels)
        ancestors = parent if index > 1 and parent is not None else np.zeros(0, np.int64)
        jobs.append((values, ancestors, table, stripe_count(shapes[0][0])))
        parent, parent_shapes = values, shapes
    return _code_all(jobs), {"coder": "context", "version": LOSSLESS_VERSION, "two_d": True}


def decode_lossless_levels(
    chunks: Sequence[bytes],
    shapes: Sequence[Any],
    params: dict[str, Any],
    stripes: Sequence[np.ndarray] | None = None,
) -> list[Any]:
    """The inverse of :func:`encode_lossless_levels`: the first ``len(chunks)`` entries of the
    layout ``shapes`` (``[shape, (shape, shape, shape), ...]``).  With ``stripes``
    (:func:`stripes_needed`), only the marked stripes of each level are decoded (a region's);
    the other rows stay 0."""
    if params.get("version") != LOSSLESS_VERSION or params.get("two_d") is not True:
        msg = f"lossless coder parameters {params!r} are not of version {LOSSLESS_VERSION}"
        raise BundleError(msg)
    if any(not isinstance(chunk, bytes | bytearray | memoryview) for chunk in chunks):
        msg = "each chunk must be bytes"
        raise BundleError(msg)
    out: list[Any] = []
    parent: np.ndarray | None = None
    parent_shapes: list[tuple[int, int]] | None = None
    levels = []
    for index, chunk in enumerate(chunks):
        full = _level_shapes(shapes[index])
        dims = [_as_2d(s) for s in full]
        band_shapes = [d[0] for d in dims]
        channels = dims[0][1]
        if any(d[1] != channels for d in dims):
            msg = f"lossless level {index}: bands of unequal channel counts {full}"
            raise BundleError(msg)
        table, total, _ = _planes(
            band_shapes, channels, index == 0, parent_shapes if index > 1 else None
        )
        values = np.zeros(total, dtype=np.int64)
        mags = np.zeros(total, dtype=np.int64)
        ancestors = parent if index > 1 and parent is not None else np.zeros(0, np.int64)
        parts = _split(bytes(chunk), stripe_count(band_shapes[0][0]), index)
        levels.append((values, mags, ancestors, table, parts, full, band_shapes, channels))
        parent, parent_shapes = values, band_shapes
    # The coarse band and the coarsest details look at no other level: decode them together;
    # each finer level looks at the level before it (its parent), so it waits for it.
    marks: list[np.ndarray | None] = [None] * len(levels)
    if stripes is not None:
        for index, mark in enumerate(stripes[: len(levels)]):
            count = len(levels[index][4])
            if len(mark) != count:
                msg = f"lossless level {index}: {len(mark)} stripes asked for, not {count}"
                raise BundleError(msg)
            marks[index] = np.asarray(mark, dtype=bool)
    groups = [(0, levels[:2])] + [(i, [level]) for i, level in enumerate(levels) if i >= 2]
    for first, group in groups:
        if group:
            _decode_stripes([level[:5] for level in group], marks[first : first + len(group)])
    for values, _, _, _, _, full, band_shapes, channels in levels:
        total = values.size
        if total and (values.min() < -_MAX_VALUE - 1 or values.max() > _MAX_VALUE):
            msg = "lossless-coded chunk decodes to a value beyond int32"
            raise BundleError(msg)
        bands = []
        start = 0
        per_band: list[list[np.ndarray]] = [[] for _ in band_shapes]
        for _ in range(channels):
            for b, (rows, cols) in enumerate(band_shapes):
                per_band[b].append(values[start : start + rows * cols].reshape(rows, cols))
                start += rows * cols
        for b, full_shape in enumerate(full):
            planes = per_band[b]
            band = planes[0] if len(full_shape) == 2 else np.stack(planes, axis=-1)
            bands.append(band.astype(np.int32))
        out.append(bands[0] if len(out) == 0 else tuple(bands))
    return out
