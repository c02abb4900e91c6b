"""Entropy coding of quantized subbands, one chunk per resolution level, coarse to fine.

``encode_levels`` turns the integers of a decomposition (``wavedec2`` layout
``[cA, (cH, cV, cD), ...]`` or ``wavedec`` layout ``[cA, cD, ...]``) into one byte chunk per
list entry, so that the first ``k`` chunks decode to the first ``k`` entries: a prefix of a
bundle is a complete lower-resolution image.

Coders:

``"zlib"``
    The generic baseline: the level's integers as little-endian ``int32``, deflated.
``"context"``
    The default: context modelling and range coding, version 7 for two-dimensional layouts
    and 4 for the others (:mod:`wavecore.blockcoder`): each level is cut into 128 × 128
    code-blocks (every band and channel of the level in each), coded by a compiled binary
    range coder with adaptive probabilities, in threads with the GIL released; version 6's
    detail contexts also read the parent band, one level coarser, and version 7's zero flags
    of ``cH`` and ``cV`` also have models under a neighbourhood along the band's orientation.
    Version 6 still decodes, and so do versions 2 and 3 (constriction's range coder,
    adaptive counts per context class driven from Python; version 3 with a flag per 8 × 8
    tile), by the code below.

The decoder treats its input as hostile: every chunk is checked against the sizes the caller
declares (``shapes``), decompression is bounded by those sizes, and anything wrong raises
:class:`wavecore.errors.BundleError`.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import Any

import constriction
import numpy as np
from numba import njit

from .blockcoder import (
    BLOCK_SIZE,
    ORIENT_VERSION,
    PARENT_VERSION,
    PRIOR_VERSION,
    KnownBlocks,
    decode_blocks,
    encode_blocks,
)
from .errors import BundleError, InvalidParameter
from .layout import as_levels, is_band_group
from .losslesscoder import LOSSLESS_VERSION, decode_lossless_levels

__all__ = ["CODERS", "decode_levels", "encode_levels"]

CODERS = ("context", "zlib")
#: The most elements :func:`decode_levels` accepts in one call (matches the bundle limit).
MAX_ELEMENTS = 1 << 31


def _entries(qcoeffs: Sequence[Any]) -> list[list[np.ndarray]]:
    out = []
    for bands in as_levels(qcoeffs, "qcoeffs"):
        arrays = []
        for arr in bands:
            if arr.dtype.kind not in "iu":
                msg = f"quantized coefficients must be integers, not {arr.dtype}"
                raise InvalidParameter(msg)
            # Only wider integers can fall outside int32: the quantizer's int32 bands skip
            # two full passes over every band (on the calling thread, a serial part of the
            # encode: 2-5 ms of a 2048² RGB one).
            fits = arr.itemsize < 4 or (arr.itemsize == 4 and arr.dtype.kind == "i")
            if arr.size and not fits and (arr.min() < -(2**31) or arr.max() >= 2**31):
                msg = "quantized coefficients must fit in int32"
                raise InvalidParameter(msg)
            arrays.append(arr.astype(np.int32, copy=False))
        out.append(arrays)
    return out


def _check_coder(coder: Any) -> str:
    if coder not in CODERS:
        accepted = ", ".join(repr(c) for c in CODERS)
        msg = f"unknown coder {coder!r}; accepted coders are {accepted}"
        raise InvalidParameter(msg)
    return str(coder)


def encode_levels(
    qcoeffs: Sequence[Any],
    *,
    coder: str = "context",
    version: int | None = None,
    known_blocks: KnownBlocks | None = None,
    two_d: bool | None = None,
) -> tuple[list[bytes], dict[str, Any]]:
    """Entropy-code quantized coefficients, one chunk per resolution level.

    Parameters
    ----------
    qcoeffs : list
        Integer arrays in ``wavedec2`` or ``wavedec`` layout, coarse first (as made by
        :func:`wavecore.quantize.quantize_bands`, or integer lifting for lossless coding).
    coder : {"context", "zlib"}
        ``"context"`` (default) is the context-modelling range coder; ``"zlib"`` the generic
        baseline.
    version : int, optional
        The context coder's version: by default 7 for two-dimensional layouts and 4 for the
        others; 4 codes each chunk independently of the others (the lossless path re-codes
        only the coarse chunks when it tries a deeper decomposition).
    known_blocks : wavecore.blockcoder.KnownBlocks, optional
        Code-blocks of these very coefficients that the context coder has coded already, with
        the same version (:func:`wavecore.blockcoder.code_blocks`): their bytes are taken,
        not coded again.
    two_d : bool, optional
        Whether the layout is ``wavedec2``'s (bands ``(rows, cols[, channels])``): by default,
        whether entry 1 holds three bands.  A decomposition of no levels (``[cA]``) cannot
        tell, and is taken as ``wavedec``'s (``cA`` as 1-D signals along its first axis, one
        per column): a picture coded with no levels says ``True``, so that its coder sees
        rows and columns (1-D, a 1 × N picture was N planes of one value each).

    Returns
    -------
    chunks : list of bytes
        ``chunks[0]`` codes ``cA``, ``chunks[i]`` all bands of entry ``i``.
    params : dict
        JSON-serialisable; :func:`decode_levels` needs it.

    Examples
    --------
    >>> import numpy as np
    >>> q = [np.arange(6, dtype=np.int32).reshape(2, 3), np.array([0, -1, 0, 2], dtype=np.int32)]
    >>> chunks, params = encode_levels(q, coder="zlib")
    >>> len(chunks)
    2
    >>> back = decode_levels(chunks, [(2, 3), (4,)], params)
    >>> bool(np.array_equal(back[1], q[1]))
    True
    """
    coder = _check_coder(coder)
    entries = _entries(qcoeffs)
    if coder == "context":
        return _encode_context(entries, version, known_blocks, two_d)
    chunks = []
    for bands in entries:
        raw = b"".join(band.astype("<i4", copy=False).tobytes() for band in bands)
        chunks.append(zlib.compress(raw, 9))
    return chunks, {"coder": "zlib"}


def _shape_entries(shapes: Sequence[Any]) -> list[list[tuple[int, ...]]]:
    """Normalise ``shapes`` (``[shape, (shape, shape, shape) | shape, ...]``) and bound them."""
    if isinstance(shapes, np.ndarray) or not isinstance(shapes, Sequence):
        msg = "shapes must be a list of band shapes"
        raise BundleError(msg)
    out = []
    total = 0
    for entry in shapes:
        if not isinstance(entry, tuple | list):
            msg = f"band shape entry {entry!r} is not a tuple"
            raise BundleError(msg)
        bands = [tuple(e) for e in entry] if is_band_group(entry) else [tuple(entry)]
        for band in bands:
            if not all(isinstance(n, int | np.integer) and 0 <= n <= MAX_ELEMENTS for n in band):
                msg = f"band shape {band!r} is not a tuple of sizes"
                raise BundleError(msg)
            total += int(np.prod(band, dtype=object))
            if total > MAX_ELEMENTS:
                msg = f"band shapes declare more than {MAX_ELEMENTS} coefficients"
                raise BundleError(msg)
        out.append([tuple(int(n) for n in band) for band in bands])
    return out


def _inflate(chunk: bytes, expected: int) -> bytes:
    """Decompress at most ``expected`` bytes; anything else is a corrupt chunk."""
    try:
        inflater = zlib.decompressobj()
        raw = inflater.decompress(chunk, expected)
        if inflater.unconsumed_tail or not inflater.eof:
            msg = "zlib chunk does not hold exactly the declared number of coefficients"
            raise BundleError(msg)
    except zlib.error as exc:
        msg = f"corrupt zlib chunk: {exc}"
        raise BundleError(msg) from exc
    if len(raw) != expected or inflater.unused_data:
        msg = (
            f"zlib chunk holds {len(raw)} bytes (+{len(inflater.unused_data)} trailing), "
            f"expected {expected}"
        )
        raise BundleError(msg)
    return raw


def decode_levels(
    chunks: Sequence[bytes], shapes: Sequence[Any], params: dict[str, Any]
) -> list[Any]:
    """Decode the first ``len(chunks)`` levels into integer arrays of the given shapes.

    Parameters
    ----------
    chunks : sequence of bytes
        A prefix of what :func:`encode_levels` returned.
    shapes : sequence
        Band shapes for (at least) those entries, in the same layout: ``shape`` for ``cA`` and
        1-D details, a tuple of three shapes for 2-D details.
    params : dict
        As returned by :func:`encode_levels` (treated as untrusted).

    Returns
    -------
    list
        ``int32`` arrays, ``[cA, (cH, cV, cD) | cD, ...]``, one entry per chunk.

    Raises
    ------
    BundleError
        For anything inconsistent or corrupt; never another exception.
    """
    if not isinstance(params, dict) or params.get("coder") not in CODERS:
        msg = f"entropy coder parameters must name a coder in {CODERS}, not {params!r}"
        raise BundleError(msg)
    if isinstance(chunks, bytes | bytearray) or not isinstance(chunks, Sequence):
        msg = "chunks must be a list of byte strings"
        raise BundleError(msg)
    layout = _shape_entries(shapes)
    if len(chunks) > len(layout) or not chunks:
        msg = f"{len(chunks)} chunks given for {len(layout)} band entries"
        raise BundleError(msg)
    layout = layout[: len(chunks)]
    if params["coder"] == "context" and params.get("version") == LOSSLESS_VERSION:
        return decode_lossless_levels(chunks, shapes, params)  # lossless bundles' own coder
    if params["coder"] == "context":
        levels = _decode_context(chunks, layout, params)
    else:
        levels = _decode_zlib(chunks, layout)
    out: list[Any] = []
    for index, (arrays, bands) in enumerate(zip(levels, layout, strict=True)):
        is_single = len(bands) == 1 and not (index > 0 and is_band_group(shapes[index]))
        out.append(arrays[0] if is_single else tuple(arrays))
    return out


def _decode_zlib(
    chunks: Sequence[bytes], layout: list[list[tuple[int, ...]]]
) -> list[list[np.ndarray]]:
    levels = []
    for chunk, bands in zip(chunks, layout, strict=True):
        if not isinstance(chunk, bytes | bytearray | memoryview):
            msg = "each chunk must be bytes"
            raise BundleError(msg)
        sizes = [int(np.prod(b, dtype=np.int64)) for b in bands]
        raw = _inflate(bytes(chunk), 4 * sum(sizes))
        flat = np.frombuffer(raw, dtype="<i4").astype(np.int32)
        arrays, start = [], 0
        for band, size in zip(bands, sizes, strict=True):
            arrays.append(flat[start : start + size].reshape(band))
            start += size
        levels.append(arrays)
    return levels


# --------------------------------------------------------------------------------------------
# The context coder
# --------------------------------------------------------------------------------------------

#: Magnitudes ``0 .. ESCAPE - 1`` are symbols of their own; larger ones send ``ESCAPE`` and then
#: the excess as an exponent (adaptive) and raw mantissa bits.
ESCAPE = 17
_ALPHABET = ESCAPE + 1
_EXPONENTS = 33
#: Upper edges of the activity bins (the activity is a weighted mean of known neighbour
#: magnitudes, in quantizer steps); bin 0 is "every known neighbour is zero".
#: Upper edges of the activity bins, in thousandths of a quantizer step (the activity is a
#: weighted mean of known neighbour magnitudes); bin 0 is "every known neighbour is zero".
_EDGES_MILLI = np.array(
    [0, 100, 200, 350, 550, 800, 1150, 1600, 2200, 3000, 4200, 6000, 9000, 14000], dtype=np.int64
)
_ACTIVITY_EDGES = _EDGES_MILLI / 1000.0
#: ``_EDGES_AT_MOST[v]``: how many edges are ``<= v`` (the look-up of :func:`_bin`).
_EDGES_AT_MOST = np.searchsorted(
    _EDGES_MILLI, np.arange(_EDGES_MILLI[-1] + 1), side="right"
).astype(np.int8)
_BINS = len(_EDGES_MILLI) + 1
#: Three interlaced passes over a band: (even, even); (odd, odd), which sees its four diagonal
#: neighbours; then (even, odd) and (odd, even), which see the four direct ones.
_PASSES = (((0, 0),), ((1, 1),), ((0, 1), (1, 0)))
_CLASSES = len(_PASSES) * _BINS
_APPROX_CLASSES = _BINS
#: Counts are halved once a class has seen this many symbols, so the model follows the data.
_COUNT_LIMIT = 1 << 21
#: Counts are integers (so that every machine computes the same probabilities) in units of
#: 1/_UNIT observation: a symbol never seen keeps a small but nonzero probability.
_UNIT = 32
_PRIOR_WEIGHT = 8
#: Context weights, in halves, so that all context arithmetic is in integers and every machine
#: computes the same classes: the four direct neighbours, the four diagonal ones, the parent,
#: each earlier band of the same level, and the first channel (luma) at the same place.
_W_DIRECT, _W_DIAGONAL, _W_PARENT, _W_SIBLING, _W_LUMA = 4, 2, 2, 1, 6
#: The parent term is (9 · parent + sum of its 3 × 3 neighbourhood) / 18: everything is scaled
#: by 18.
_PARENT_SCALE = 18
#: Version 3 adds the tile flags; version 4 codes independent code-blocks with a compiled
#: binary range coder (:mod:`wavecore.blockcoder`); version 6 adds the parent band to its
#: detail contexts; version 7 adds directional zero-flag models for ``cH`` and ``cV``, and is
#: the default of two-dimensional layouts (one-dimensional ones, curves, keep version 4);
#: version 8 starts version 7's blocks from models trained per level class.  The codec codes
#: pictures with version 8 and surfaces and grids with version 6
#: (``codec.plan.Plan.context_version``).  Versions 2 to 4, 6 and 7 still decode.
CONTEXT_VERSION = ORIENT_VERSION
CONTEXT_VERSIONS = (2, 3, 4, PARENT_VERSION, ORIENT_VERSION, PRIOR_VERSION)
#: Tiles of ``_TILE × _TILE`` detail coefficients: each is flagged as holding a nonzero value
#: or not, and an all-zero tile costs nothing more (most of the finest levels, at most rates).
_TILE = 8
#: Sign contexts per orientation: one for the first pass, then the sums of the known
#: neighbours' signs (each in -2..2) along two directions: diagonals in the second pass,
#: rows and columns in the third.  Textures (brick) have strongly aligned signs.
_SIGN_CONTEXTS = 1 + 25 + 25
_FIRST_SEGMENT = 8
#: At each new level the detail counts keep their shape but shrink to about this many
#: observations, so the model re-learns the level's own statistics quickly.
_LEVEL_MEMORY = 24


def _prior(bins: int) -> np.ndarray:
    """Initial pseudo-counts: geometric magnitudes whose mean grows with the activity bin."""
    centres = np.concatenate([[0.02], _ACTIVITY_EDGES[1:], [20.0]])[:bins]
    counts = np.empty((bins, _ALPHABET))
    k = np.arange(_ALPHABET)
    for b, mean in enumerate(centres):
        ratio = mean / (1.0 + mean)
        p = (1 - ratio) * ratio**k
        p[-1] = ratio**ESCAPE
        counts[b] = np.maximum(np.round(_PRIOR_WEIGHT * _UNIT * p), 1)
    return counts.astype(np.int64)


class _Models:
    """Adaptive symbol counts per context class, identical in encoder and decoder."""

    def __init__(self) -> None:
        self.detail = np.tile(_prior(_BINS), (len(_PASSES), 1))
        self.approx = _prior(_BINS)
        self.exponent = np.full((1, _EXPONENTS), _UNIT // 4, dtype=np.int64)  # one class
        self.sign = np.full((3 * _SIGN_CONTEXTS, 2), _UNIT, dtype=np.int64)
        self.tile = np.full((_BINS, 2), _UNIT, dtype=np.int64)

    def new_level(self) -> None:
        totals = self.detail.sum(axis=1, keepdims=True)
        scaled = (self.detail * (_LEVEL_MEMORY * _UNIT)) // totals
        self.detail = np.maximum(scaled, 1).astype(np.int64)

    @staticmethod
    def model(counts: np.ndarray) -> Any:
        return _model.Categorical(counts.astype(np.float64), perfect=False)

    def learn_exponents(self, exponents: np.ndarray) -> None:
        """The adaptive update of the escape exponents' counts (as after any run)."""
        _add_counts(self.exponent, 0, exponents, _UNIT, _COUNT_LIMIT)


@njit(nogil=True, cache=True)
def _group_by_class(classes, n_classes):
    """Counting sort: ``order`` lists the positions class by class (ascending), each class in
    scan order; class ``c`` occupies ``order[starts[c]:starts[c + 1]]``."""
    starts = np.zeros(n_classes + 1, dtype=np.int64)
    for k in range(classes.size):
        starts[classes[k] + 1] += 1
    for c in range(n_classes):
        starts[c + 1] += starts[c]
    fill = starts[:n_classes].copy()
    order = np.empty(classes.size, dtype=np.int64)
    for k in range(classes.size):
        c = classes[k]
        order[fill[c]] = k
        fill[c] += 1
    return order, starts


@njit(nogil=True, cache=True)
def _add_counts(table, row, symbols, unit, limit):
    """The adaptive update after a segment: count its symbols; halve once the row is full."""
    for k in range(symbols.size):
        table[row, symbols[k]] += unit
    total = 0
    for x in range(table.shape[1]):
        total += table[row, x]
    if total > limit:
        for x in range(table.shape[1]):
            table[row, x] = (table[row, x] + 1) // 2


@njit(nogil=True, cache=True)
def _plan_segments(symbols, order, starts, table, unit, limit, first):
    """The encoder's side of grouped coding (``_Reader._grouped`` is the decoder's), at once.

    Each class's symbols are split into runs of doubling length (``first``, ``2 · first``, …);
    a run is coded with the class's counts as they were before it, and the counts then learn
    it.  Returns the symbols in coding order, the runs' bounds and each run's counts, and
    leaves ``table`` updated exactly as the decoder's run-by-run updates will.
    """
    n_classes = table.shape[0]
    ordered = np.empty(symbols.size, dtype=np.int32)
    for k in range(symbols.size):
        ordered[k] = symbols[order[k]]
    runs = 0
    for c in range(n_classes):
        size, done, length = starts[c + 1] - starts[c], 0, first
        while done < size:
            runs += 1
            done += length
            length *= 2
    bounds = np.empty(runs + 1, dtype=np.int64)
    models = np.empty((runs, table.shape[1]), dtype=np.float64)
    k = 0
    for c in range(n_classes):
        at, length = starts[c], first
        while at < starts[c + 1]:
            stop = min(starts[c + 1], at + length)
            bounds[k] = at
            for x in range(table.shape[1]):
                models[k, x] = table[c, x]
            _add_counts(table, c, ordered[at:stop], unit, limit)
            k += 1
            at = stop
            length *= 2
    bounds[runs] = symbols.size
    return ordered, bounds, models


@njit(nogil=True, cache=True)
def _parent_mix(parent):
    """``9 |p| + Σ 3 × 3 |p|`` at every parent position (the neighbourhood edge-extended)."""
    pr, pc = parent.shape
    mix = np.empty((pr, pc), dtype=np.int64)
    for i in range(pr):
        for j in range(pc):
            value = 9 * abs(np.int64(parent[i, j]))
            for di in range(-1, 2):
                ii = min(max(i + di, 0), pr - 1)
                for dj in range(-1, 2):
                    value += abs(np.int64(parent[ii, min(max(j + dj, 0), pc - 1)]))
            mix[i, j] = value
    return mix


@njit(nogil=True, cache=True)
def _external_sum(total, mix, parent_factor, first, second, third, channels, factors):
    """``total = parent_factor · mix[i // 2, j // 2] + Σ factor · |band[channel, i, j]|``.

    The parent of ``(i, j)`` is ``(i // 2, j // 2)`` and a sibling's sample is ``(i, j)``, both
    clamped to their band (bands of one level differ by a sample or two).  The three bands are
    ``(channels, rows, cols)`` planes; a zero factor leaves one out.  One pass over ``total``.
    """
    rows, cols = total.shape
    pr, pc = mix.shape
    for i in range(rows):
        pi = min(i // 2, pr - 1)
        i1, i2, i3 = (
            min(i, first.shape[1] - 1),
            min(i, second.shape[1] - 1),
            min(i, third.shape[1] - 1),
        )
        for j in range(cols):
            value = parent_factor * mix[pi, min(j // 2, pc - 1)]
            if factors[0]:
                value += factors[0] * abs(first[channels[0], i1, min(j, first.shape[2] - 1)])
            if factors[1]:
                value += factors[1] * abs(second[channels[1], i2, min(j, second.shape[2] - 1)])
            if factors[2]:
                value += factors[2] * abs(third[channels[2], i3, min(j, third.shape[2] - 1)])
            total[i, j] = value


_NO_BAND = np.zeros((1, 1, 1), dtype=np.int64)


def _external(
    shape: tuple[int, int],
    parent: np.ndarray | None,
    siblings: list[tuple[np.ndarray, int, int]],
) -> tuple[np.ndarray, int]:
    """Scaled sum and weight of the context from other, already coded, bands (integers).

    ``parent`` is a plane; each sibling is ``(planes, channel, weight)`` with ``planes`` an
    ``int64`` ``(channels, rows, cols)`` array (at most three siblings).  Only magnitudes count.
    """
    total = np.empty(shape, dtype=np.int64)
    weight = 0
    mix, parent_factor = _NO_BAND[:, :, 0], 0
    if parent is not None and parent.size:
        mix, parent_factor = _parent_mix(parent), _W_PARENT
        weight += _W_PARENT * _PARENT_SCALE
    bands, channels, factors = [_NO_BAND] * 3, [0, 0, 0], [0, 0, 0]
    for slot, (planes, channel, w) in enumerate(s for s in siblings if s[0].size):
        bands[slot], channels[slot], factors[slot] = planes, channel, w * _PARENT_SCALE
        weight += w * _PARENT_SCALE
    _external_sum(
        total,
        np.ascontiguousarray(mix),
        parent_factor,
        bands[0],
        bands[1],
        bands[2],
        np.array(channels, dtype=np.int64),
        np.array(factors, dtype=np.int64),
    )
    return total, weight


#: Which neighbours are already known when a phase is coded (``_PASSES``' order): none for
#: (even, even); the four diagonal ones for (odd, odd); the four direct ones for (even, odd),
#: which are (even, even) or (odd, odd); all eight for (odd, even), whose diagonal neighbours
#: are the (even, odd) positions coded just before.
_KNOWN_NEIGHBOURS = {(0, 0): (False, False), (1, 1): (False, True), (0, 1): (True, False)}
_KNOWN_NEIGHBOURS[1, 0] = (True, True)


@njit(nogil=True, cache=True)
def _phase_classes(
    out,
    ext_sum,
    ext_weight,
    row0,
    col0,
    base,
    edges,
    at_most,
    scale,
    w_direct,
    w_diagonal,
    direct,
    diagonal,
    significant,
    tile,
    truth,
):
    """Context classes of the positions ``(row0 + 2i, col0 + 2j)`` of a plane that lie in
    significant tiles (``significant[i // tile, j // tile]``, in plane coordinates).

    The activity is ``(ext_sum + scale · Σ w · |known neighbour|) / (ext_weight + scale · Σ w)``
    over the neighbours already coded (``out`` holds them; ``direct``/``diagonal`` say which
    they are) and inside the plane; its bin is the number of edges (in thousandths) below it,
    all in integer arithmetic.  Returns the positions' rows and columns in scan order, their
    classes, and (for the encoder, when ``truth`` is the plane rather than a 0 × 0 stand-in)
    the magnitudes there and whether each value is negative.
    """
    rows, cols = out.shape
    n_j = (cols - col0 + 1) // 2
    count = ((rows - row0 + 1) // 2) * n_j
    encoding = truth.shape[0] > 0
    at_rows = np.empty(count, dtype=np.int64)
    at_cols = np.empty(count, dtype=np.int64)
    magnitudes = np.empty(count if encoding else 0, dtype=np.int64)
    negative = np.empty(count if encoding else 0, dtype=np.int64)
    classes = np.empty(count, dtype=np.int64)
    nums = np.empty(count, dtype=np.int64)
    dens = np.empty(count, dtype=np.int64)
    n = 0
    for i in range(row0, rows, 2):
        up, down = i > 0, i < rows - 1
        tile_row = significant[i // tile]
        for t in range(tile_row.size):
            if not tile_row[t]:
                continue  # an all-zero tile: nothing in it is coded
            # This phase's columns in the tile: j = col0 + 2m in [t · tile, (t + 1) · tile).
            for m in range(
                max(0, (t * tile - col0 + 1) // 2), min(n_j, ((t + 1) * tile - col0 + 1) // 2)
            ):
                j = col0 + 2 * m
                left, right = j > 0, j < cols - 1
                num = ext_sum[i, j]
                den = ext_weight
                if direct:
                    total, seen = 0, 0
                    if up:
                        total += abs(out[i - 1, j])
                        seen += 1
                    if down:
                        total += abs(out[i + 1, j])
                        seen += 1
                    if left:
                        total += abs(out[i, j - 1])
                        seen += 1
                    if right:
                        total += abs(out[i, j + 1])
                        seen += 1
                    num += scale * w_direct * total
                    den += scale * w_direct * seen
                if diagonal:
                    total, seen = 0, 0
                    if up and left:
                        total += abs(out[i - 1, j - 1])
                        seen += 1
                    if up and right:
                        total += abs(out[i - 1, j + 1])
                        seen += 1
                    if down and left:
                        total += abs(out[i + 1, j - 1])
                        seen += 1
                    if down and right:
                        total += abs(out[i + 1, j + 1])
                        seen += 1
                    num += scale * w_diagonal * total
                    den += scale * w_diagonal * seen
                at_rows[n] = i
                at_cols[n] = j
                if encoding:
                    value = np.int64(truth[i, j])
                    magnitudes[n] = abs(value)
                    negative[n] = 1 if value < 0 else 0
                nums[n] = num
                dens[n] = den
                n += 1
    # Binned in a loop of its own, with :func:`_bin` written out: calling it here cost 30 %.
    top = edges.size
    last = edges[top - 1]
    for k in range(n):
        num, den = nums[k], dens[k]
        b = np.int64(0)
        if den > 0 and num > 0:  # num = 0 is bin 0: every edge is >= 0
            ratio = (1000.0 * num) / den
            b = np.int64(at_most[np.int64(ratio)]) if ratio < last else np.int64(top)
            if b > 0 and 1000 * num <= edges[b - 1] * den:
                b -= 1
            elif b < top and 1000 * num > edges[b] * den:
                b += 1
        classes[k] = base + b
    if encoding:
        return at_rows[:n], at_cols[:n], classes[:n], magnitudes[:n], negative[:n]
    return at_rows[:n], at_cols[:n], classes[:n], magnitudes, negative


@njit(nogil=True, cache=True)
def _bin(num, den, edges, at_most):
    """How many of the ascending ``edges`` (thousandths) the ratio ``num / den`` exceeds.

    Exact: ``at_most[v]`` (how many edges are ``<= v``) gives the answer from the float ratio
    in one look-up, which can be off by one edge only, and integer comparisons correct that.
    """
    if den <= 0 or num <= 0:  # num = 0 is bin 0: every edge is >= 0
        return np.int64(0)
    top = edges.size
    ratio = (1000.0 * num) / den
    b = np.int64(at_most[np.int64(ratio)]) if ratio < edges[top - 1] else np.int64(top)
    if b > 0 and 1000 * num <= edges[b - 1] * den:
        b -= 1
    elif b < top and 1000 * num > edges[b] * den:
        b += 1
    return b


@njit(nogil=True, cache=True)
def _tile_flags(plane, tile):
    """1 for each ``tile × tile`` tile of the plane that holds a nonzero value (the encoder's)."""
    rows, cols = plane.shape
    flags = np.zeros(((rows + tile - 1) // tile, (cols + tile - 1) // tile), dtype=np.int64)
    for i in range(rows):
        for j in range(cols):
            if plane[i, j] != 0:
                flags[i // tile, j // tile] = 1
    return flags


@njit(nogil=True, cache=True)
def _tile_classes(ext_sum, ext_weight, tile, edges, at_most):
    """Class of each tile's flag: the bin of the mean outside activity over the tile."""
    rows, cols = ext_sum.shape
    n_ti, n_tj = (rows + tile - 1) // tile, (cols + tile - 1) // tile
    sums = np.zeros((n_ti, n_tj), dtype=np.int64)
    for i in range(rows):
        for j in range(cols):
            sums[i // tile, j // tile] += ext_sum[i, j]
    classes = np.empty(n_ti * n_tj, dtype=np.int64)
    for ti in range(n_ti):
        height = min(rows, (ti + 1) * tile) - ti * tile
        for tj in range(n_tj):
            width = min(cols, (tj + 1) * tile) - tj * tile
            classes[ti * n_tj + tj] = _bin(
                sums[ti, tj], ext_weight * height * width, edges, at_most
            )
    return classes


@njit(nogil=True, cache=True)
def _sign_contexts(out, at_rows, at_cols, pass_index, base):
    """Sign context of each listed position, from the signs of the neighbours known.

    One context for the first pass; then the sums of the known neighbours' signs (each in
    -2..2) along the diagonals (second pass) or along the row and the column (third pass).
    Unknown and outside neighbours are zero in ``out``.
    """
    rows, cols = out.shape
    contexts = np.empty(at_rows.size, dtype=np.int64)
    for k in range(at_rows.size):
        i, j = at_rows[k], at_cols[k]
        if pass_index == 0:
            contexts[k] = base
            continue
        up, down, left, right = i > 0, i < rows - 1, j > 0, j < cols - 1
        if pass_index == 1:
            first, second = 0, 0
            if up and left:
                first += np.sign(out[i - 1, j - 1])
            if down and right:
                first += np.sign(out[i + 1, j + 1])
            if up and right:
                second += np.sign(out[i - 1, j + 1])
            if down and left:
                second += np.sign(out[i + 1, j - 1])
            contexts[k] = base + 1 + (first + 2) * 5 + (second + 2)
        else:
            across, along = 0, 0
            if left:
                across += np.sign(out[i, j - 1])
            if right:
                across += np.sign(out[i, j + 1])
            if up:
                along += np.sign(out[i - 1, j])
            if down:
                along += np.sign(out[i + 1, j])
            contexts[k] = base + 26 + (across + 2) * 5 + (along + 2)
    return contexts


@njit(nogil=True, cache=True)
def _commit_phase(out, at_rows, at_cols, magnitudes, nonzero, negative):
    """Write a coded phase into ``out``: the magnitudes at the listed positions, negated where
    ``negative`` says (one entry per index in ``nonzero``)."""
    for k in range(at_rows.size):
        out[at_rows[k], at_cols[k]] = magnitudes[k]
    for k in range(nonzero.size):
        if negative[k]:
            out[at_rows[nonzero[k]], at_cols[nonzero[k]]] *= -1


class _Writer:
    """Codes symbols into one range-coder stream per level (``chunks``)."""

    def __init__(self) -> None:
        self.encoder = _queue.RangeEncoder()
        self.chunks: list[bytes] = []

    def __call__(self, index: int) -> _Writer:
        self.encoder = _queue.RangeEncoder()
        return self

    def _grouped(self, table: np.ndarray, classes: np.ndarray, symbols: np.ndarray) -> None:
        """Code ``symbols`` under the adaptive counts ``table[class]`` (see _plan_segments)."""
        order, starts = _group_by_class(classes, table.shape[0])
        ordered, bounds, models = _plan_segments(
            symbols, order, starts, table, _UNIT, _COUNT_LIMIT, _FIRST_SEGMENT
        )
        encode, categorical = self.encoder.encode, _model.Categorical
        for k in range(len(bounds) - 1):
            encode(ordered[bounds[k] : bounds[k + 1]], categorical(models[k], perfect=False))

    def magnitudes(
        self, models: _Models, counts: np.ndarray, classes: np.ndarray, values: np.ndarray
    ) -> np.ndarray:
        """Code ``values >= 0`` (1-D) with the class of each; escapes follow in the same stream."""
        self._grouped(counts, classes, np.minimum(values, ESCAPE).astype(np.int32))
        excess = values[values >= ESCAPE].astype(np.int64) - ESCAPE
        if excess.size:
            exponents = _bit_length(excess)
            self.encoder.encode(exponents.astype(np.int32), models.model(models.exponent[0]))
            models.learn_exponents(exponents)
            bits = _mantissa_bits(excess, exponents)
            if bits.size:
                self.encoder.encode(bits, _BIT)
        return values

    def grouped(
        self, models: _Models, table: np.ndarray, contexts: np.ndarray, values: np.ndarray
    ) -> np.ndarray:
        """Code small ``values`` under adaptive counts ``table[context]``, context by context."""
        del models
        self._grouped(table, contexts, values.astype(np.int32))
        return values.astype(np.int64)

    def uniform(self, values: np.ndarray, size: int, count: int) -> np.ndarray:
        """Code ``count`` values below ``size``, each equally likely (raw bits, in effect)."""
        del count
        if values.size:
            self.encoder.encode(values.astype(np.int32), _model.Uniform(size))
        return values.astype(np.int64)

    def signs(self, negative: np.ndarray, nonzero: np.ndarray) -> np.ndarray:
        del nonzero
        if negative.size:
            self.encoder.encode(negative.astype(np.int32), _BIT)
        return negative.astype(np.int64)

    def done(self) -> None:
        self.chunks.append(self.encoder.get_compressed().astype("<u4").tobytes())


class _Reader:
    """Decodes the symbols of one level's chunk."""

    def __init__(self, chunk: bytes) -> None:
        if len(chunk) % 4:
            msg = f"context-coded chunk of {len(chunk)} bytes is not a whole number of words"
            raise BundleError(msg)
        words = np.frombuffer(chunk, dtype="<u4").astype(np.uint32)
        try:
            self.decoder = _queue.RangeDecoder(words)
        except Exception as exc:  # constriction reports bad input in its own exception types
            msg = f"corrupt context-coded chunk: {exc}"
            raise BundleError(msg) from exc

    def _decode(self, model: Any, count: int) -> np.ndarray:
        try:
            return np.asarray(self.decoder.decode(model, count), dtype=np.int64)
        except Exception as exc:  # constriction reports bad input in its own exception types
            msg = f"corrupt context-coded chunk: {exc}"
            raise BundleError(msg) from exc

    def _grouped(self, table: np.ndarray, classes: np.ndarray) -> np.ndarray:
        """Decode what :meth:`_Writer._grouped` coded: run by run, learning after each."""
        order, starts = _group_by_class(classes, table.shape[0])
        ordered = np.empty(classes.size, dtype=np.int64)
        decode, categorical = self.decoder.decode, _model.Categorical
        for c in np.flatnonzero(np.diff(starts)):
            at, stop, length = int(starts[c]), int(starts[c + 1]), _FIRST_SEGMENT
            while at < stop:
                end = min(stop, at + length)
                try:
                    run = decode(categorical(table[c].astype(np.float64), perfect=False), end - at)
                except Exception as exc:  # constriction reports bad input in its own types
                    msg = f"corrupt context-coded chunk: {exc}"
                    raise BundleError(msg) from exc
                ordered[at:end] = run
                _add_counts(table, c, run, _UNIT, _COUNT_LIMIT)
                at = end
                length *= 2
        values = np.empty(classes.size, dtype=np.int64)
        values[order] = ordered
        return values

    def magnitudes(
        self, models: _Models, counts: np.ndarray, classes: np.ndarray, truth: None
    ) -> np.ndarray:
        del truth
        values = self._grouped(counts, classes)
        escaped = values == ESCAPE
        count = int(np.count_nonzero(escaped))
        if count:
            exponents = self._decode(models.model(models.exponent[0]), count)
            models.learn_exponents(exponents)
            lengths = np.maximum(exponents - 1, 0)
            bits = self._decode(_BIT, int(lengths.sum()))
            excess = _from_mantissa(exponents, bits)
            values[escaped] = ESCAPE + excess
            if values.max() > _MAX_MAGNITUDE:
                msg = "context-coded chunk decodes to a value beyond int32"
                raise BundleError(msg)
        return values

    def grouped(
        self, models: _Models, table: np.ndarray, contexts: np.ndarray, values: None
    ) -> np.ndarray:
        del models, values
        return self._grouped(table, contexts)

    def uniform(self, values: None, size: int, count: int) -> np.ndarray:
        del values
        return self._decode(_model.Uniform(size), count) if count else np.zeros(0, np.int64)

    def signs(self, negative: None, nonzero: np.ndarray) -> np.ndarray:
        del negative
        count = int(np.count_nonzero(nonzero))
        return self._decode(_BIT, count) if count else np.zeros(0, dtype=np.int64)

    def done(self) -> None:
        pass


_MAX_MAGNITUDE = 2**31 - 1
_MAX_SHIFT = 24


def _bit_length(values: np.ndarray) -> np.ndarray:
    """Number of bits of each non-negative value (0 for 0)."""
    out = np.zeros(values.shape, dtype=np.int64)
    nonzero = values > 0
    out[nonzero] = np.floor(np.log2(values[nonzero])).astype(np.int64) + 1
    # log2 can round up just below a power of two; fix with exact integer checks.
    too_big = nonzero & ((np.int64(1) << np.maximum(out - 1, 0)) > values)
    out[too_big] -= 1
    return out


def _mantissa_bits(excess: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """The bits below the leading one, most significant first, of every value, concatenated."""
    lengths = np.maximum(exponents - 1, 0)
    width = int(lengths.max()) if lengths.size else 0
    if width == 0:
        return np.zeros(0, dtype=np.int32)
    shifts = np.arange(width - 1, -1, -1)
    bits = (excess[:, None] >> shifts[None, :]) & 1
    keep = np.arange(width)[None, :] >= (width - lengths)[:, None]
    return bits[keep].astype(np.int32)


def _from_mantissa(exponents: np.ndarray, bits: np.ndarray) -> np.ndarray:
    lengths = np.maximum(exponents - 1, 0)
    out = np.where(exponents > 0, np.int64(1) << np.maximum(exponents - 1, 0), 0)
    if bits.size:
        owner = np.repeat(np.arange(len(exponents)), lengths)
        ends = np.cumsum(lengths)
        position = np.arange(bits.size) - np.repeat(ends - lengths, lengths)
        weight = np.int64(1) << (np.repeat(lengths, lengths) - 1 - position)
        np.add.at(out, owner, bits * weight)
    return out


def _as_planes(band: np.ndarray, two_d: bool) -> np.ndarray:
    """View a band as ``(rows, cols, channels)``: 1-D layouts get one column."""
    if not two_d or band.ndim < 2:
        return band.reshape(band.shape[0], 1, -1) if band.ndim else band.reshape(1, 1, 1)
    return band.reshape(band.shape[0], band.shape[1], -1)


def _code_approx(io: Any, models: _Models, plane: np.ndarray | None, shape: Any) -> np.ndarray:
    """The coarsest band: differences along rows (first column: down it), Rice-style.

    The residual magnitudes are split into ``shift`` raw low bits and the high part, which goes
    through the adaptive model; the encoder picks ``shift`` from the mean magnitude and sends it
    first, so the coarse band of a lossless or finely quantized image costs few escapes.
    """
    rows, cols = shape
    count = rows * cols
    residual = magnitudes = None
    shift = np.zeros(1, dtype=np.int64)
    if plane is not None:
        residual = plane.astype(np.int64)
        residual[:, 1:] = np.diff(residual, axis=1)
        residual[1:, 0] = np.diff(plane[:, 0].astype(np.int64))
        magnitudes = np.abs(residual).ravel()
        mean = float(magnitudes.mean()) if count else 0.0
        shift[0] = min(_MAX_SHIFT, max(0, math.floor(math.log2(mean)) - 1)) if mean >= 1 else 0
    k = int(io.uniform(None if plane is None else shift, _MAX_SHIFT + 1, 1)[0])
    classes = np.zeros(count, dtype=np.int64)
    high = io.magnitudes(
        models, models.approx, classes, None if magnitudes is None else magnitudes >> k
    )
    magnitude = high << k
    if k:
        low_bits = None if magnitudes is None else magnitudes & ((1 << k) - 1)
        magnitude |= io.uniform(low_bits, 1 << k, count)
    nonzero = magnitude != 0
    negative = io.signs(None if residual is None else residual.ravel()[nonzero] < 0, nonzero)
    signed = magnitude.copy()
    signed[nonzero] *= 1 - 2 * negative
    signed = signed.reshape(rows, cols)
    signed[:, 0] = np.cumsum(signed[:, 0])
    out = np.cumsum(signed, axis=1)
    if np.abs(out).max(initial=0) > _MAX_MAGNITUDE:
        msg = "context-coded chunk decodes to a value beyond int32"
        raise BundleError(msg)
    return out


def _code_detail(
    io: Any,
    models: _Models,
    plane: np.ndarray | None,
    out: np.ndarray,
    parent: np.ndarray | None,
    siblings: list[tuple[np.ndarray, int, int]],
    orientation: int,
    tiles: bool,
) -> None:
    """One detail plane in three interlaced passes, each symbol under its context class.

    ``out`` (zeros, ``int64``) receives the plane.  With ``tiles`` (version 3), a flag per
    ``_TILE × _TILE`` tile comes first, and only the tiles flagged as holding a nonzero value
    are coded; version 2 codes every position.
    """
    shape = out.shape
    ext_sum, ext_weight = _external(shape, parent, siblings)
    rows, cols = shape
    if tiles:
        classes = _tile_classes(ext_sum, ext_weight, _TILE, _EDGES_MILLI, _EDGES_AT_MOST)
        truth = None if plane is None else _tile_flags(plane, _TILE).ravel()
        flags = io.grouped(models, models.tile, classes, truth)
        significant = flags.reshape(-(-rows // _TILE), -(-cols // _TILE)).astype(np.bool_)
    else:
        significant = np.ones((1, 1), dtype=np.bool_)
    tile = _TILE if tiles else max(rows, cols, 1)
    values = _NO_VALUES if plane is None else plane
    for pass_index, phases in enumerate(_PASSES):
        for row0, col0 in phases:
            if row0 >= rows or col0 >= cols:
                continue
            direct, diagonal = _KNOWN_NEIGHBOURS[row0, col0]
            at_rows, at_cols, classes, magnitudes, negatives = _phase_classes(
                out,
                ext_sum,
                ext_weight,
                row0,
                col0,
                pass_index * _BINS,
                _EDGES_MILLI,
                _EDGES_AT_MOST,
                _PARENT_SCALE,
                _W_DIRECT,
                _W_DIAGONAL,
                direct,
                diagonal,
                significant,
                tile,
                values,
            )
            if not at_rows.size:
                continue
            magnitude = io.magnitudes(
                models, models.detail, classes, None if plane is None else magnitudes
            )
            nonzero = np.flatnonzero(magnitude)
            contexts = _sign_contexts(
                out,
                at_rows[nonzero],
                at_cols[nonzero],
                pass_index,
                orientation * _SIGN_CONTEXTS,
            )
            negative = io.grouped(
                models, models.sign, contexts, None if plane is None else negatives[nonzero]
            )
            _commit_phase(out, at_rows, at_cols, magnitude, nonzero, negative)


#: The encoder's plane stand-in when decoding (``_phase_classes`` then gathers no values).
_NO_VALUES = np.zeros((0, 0), dtype=np.int32)


def _code_levels(
    io_for_level: Any,
    entries: list[list[np.ndarray]] | None,
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
    version: int,
) -> list[list[np.ndarray]]:
    """Walk the layout coarse to fine, coding (``entries`` given) or decoding every plane.

    Encoder and decoder run this same function, so their contexts cannot drift apart.
    """
    models = _Models()
    decoded: list[list[np.ndarray]] = []  # per entry, per band: (channels, rows, cols) int64
    for index, band_shapes in enumerate(layout):
        io = io_for_level(index)
        if index > 1:
            models.new_level()
        level_planes: list[np.ndarray] = []
        for k, band_shape in enumerate(band_shapes):
            rows, cols, channels = _plane_dims(band_shape, two_d)
            truth = None if entries is None else _as_planes(entries[index][k], two_d)
            # Channel planes kept apart (channels first), so that each is contiguous.
            result = np.zeros((channels, rows, cols), dtype=np.int64)
            for channel in range(channels):
                plane = None if truth is None else truth[:, :, channel]
                if index == 0:
                    result[channel] = _code_approx(io, models, plane, (rows, cols))
                    continue
                parent = None
                if index >= 2 and k < len(decoded[index - 1]):
                    parent_planes = decoded[index - 1][k]
                    if channel < parent_planes.shape[0]:
                        parent = parent_planes[channel]
                siblings = [(level_planes[s], channel, _W_SIBLING) for s in range(k)]
                if channel > 0:
                    siblings.append((result, 0, _W_LUMA))
                _code_detail(
                    io, models, plane, result[channel], parent, siblings, min(k, 2), version >= 3
                )
            level_planes.append(result)
        decoded.append(level_planes)
        io.done()
    return decoded


def _plane_dims(band_shape: tuple[int, ...], two_d: bool) -> tuple[int, int, int]:
    if not band_shape:
        return 1, 1, 1
    if two_d and len(band_shape) >= 2:
        rows, cols, rest = band_shape[0], band_shape[1], band_shape[2:]
    else:
        rows, cols, rest = band_shape[0], 1, band_shape[1:]
    return int(rows), int(cols), int(np.prod(rest, dtype=np.int64))


_queue = constriction.stream.queue
_model = constriction.stream.model
_BIT = _model.Uniform(2)


def _encode_context(
    entries: list[list[np.ndarray]],
    version: int | None = None,
    known: KnownBlocks | None = None,
    two_d: bool | None = None,
) -> tuple[list[bytes], dict[str, Any]]:
    layout_two_d = len(entries) > 1 and len(entries[1]) == 3
    if two_d is None:
        two_d = layout_two_d
    elif not isinstance(two_d, bool) or (len(entries) > 1 and two_d != layout_two_d):
        form = "wavedec2's" if layout_two_d else "wavedec's"
        msg = f"two_d={two_d!r} does not fit a layout of {len(entries)} entries in {form} form"
        raise InvalidParameter(msg)
    if version is None:
        version = CONTEXT_VERSION if two_d else 4
    if version >= 4:
        chunks = encode_blocks(entries, two_d, BLOCK_SIZE, version, known)
        return chunks, {"coder": "context", "version": version, "two_d": two_d, "block": BLOCK_SIZE}
    layout = [[band.shape for band in bands] for bands in entries]
    writer = _Writer()
    _code_levels(writer, entries, layout, two_d, version)
    return writer.chunks, {"coder": "context", "version": version, "two_d": two_d}


def _decode_context(
    chunks: Sequence[bytes], layout: list[list[tuple[int, ...]]], params: dict[str, Any]
) -> list[list[np.ndarray]]:
    version = params.get("version")
    if version not in CONTEXT_VERSIONS or not isinstance(params.get("two_d"), bool):
        msg = f"context coder parameters {params!r} are not of a version in {CONTEXT_VERSIONS}"
        raise BundleError(msg)
    for chunk in chunks:
        if not isinstance(chunk, bytes | bytearray | memoryview):
            msg = "each chunk must be bytes"
            raise BundleError(msg)
    if version >= 4:
        block = params.get("block")
        if isinstance(block, bool) or not isinstance(block, int):
            msg = f"context coder parameter 'block' must be an integer, not {block!r}"
            raise BundleError(msg)
        return decode_blocks(
            [bytes(c) for c in chunks], layout, params["two_d"], block, version=version
        )
    readers = [_Reader(bytes(chunk)) for chunk in chunks]
    decoded = _code_levels(lambda index: readers[index], None, layout, params["two_d"], version)
    levels = []
    for bands, band_shapes in zip(decoded, layout, strict=True):
        levels.append(
            [
                np.moveaxis(planes, 0, -1).astype(np.int32, order="C").reshape(shape)
                for planes, shape in zip(bands, band_shapes, strict=True)
            ]
        )
    return levels
