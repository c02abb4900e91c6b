"""Rate–distortion-optimised quantization (RDOQ) of the detail bands of an image.

The dead-zone quantizer decides each coefficient alone, from its magnitude.  What a nonzero
index costs depends on its neighbourhood, though: in a quiet place the context coder expects a
zero, and a lone 1 costs its zero flag, its bit length and its sign, some 8 bits; where the
neighbours are busy the same 1 costs two or three.  RDOQ walks every code-block in the coder's
own order and, for each coefficient, keeps whichever of ``t = floor(|x| + TOP_ROUNDING)``,
``t - 1`` and ``0`` minimises ``D + λ R``:

* ``D`` is the squared error in units of the band's step (the band weights make these
  comparable across bands: a unit of every band costs the same in the picture), measured
  against where the dequantizer puts each index (``quantize.reconstruction_offset``);
* ``R`` is the number of bits the coder would spend, from adaptive probabilities that follow
  the coder's own contexts (``_blockkernels``: the local neighbourhood class times the other
  bands' class for the zero flag, the unary bit-length contexts; mantissa and sign bits count
  one bit each), reset at each block as the coder resets them; the other bands' sum holds the
  parent band, as context coder version 6 (two-dimensional layouts) has it: the levels are
  decided coarse to fine, so a level's parents are the indices already chosen;
* ``λ = LAMBDA · step²`` in picture units, which is ``LAMBDA`` in the band's units: the slope
  of an entropy-coded uniform quantizer's distortion–rate curve at high rate is
  ``ln 2 / 6 · step² ≈ 0.12 step²`` per bit; ``LAMBDA`` was calibrated on the tuning pictures.

Then each ``8 × 8`` tile (the coder's all-zero unit) whose few values cost more bits than the
error of dropping them is emptied.  Decisions are greedy (a choice's effect on later contexts
is not looked ahead), and the decoder does not change: RDOQ only picks other integers.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from . import _blockkernels as kernels
from .errors import InvalidParameter
from .layout import as_levels
from .quantize import reconstruction_offset
from .transform import run_rows

__all__ = [
    "ENABLED",
    "FAST_ROUNDINGS",
    "LAMBDA",
    "METHOD",
    "PARENT_WEIGHT",
    "TOP_ROUNDING",
    "adapt_deadzone",
    "choose_indices",
    "optimise_indices",
]

#: Whether the image encoder's rate control re-decides the indices after each open-loop
#: quantization (:func:`choose_indices`), and how: ``METHOD = "fast"`` runs
#: :func:`adapt_deadzone` (one compiled pass, a dead zone that depends on the neighbourhood),
#: ``"full"`` the greedy RDOQ of :func:`optimise_indices`.  Only where the closed loop does not
#: run (``cdf97``, and ``bspline2`` above ``quantize.REFINE_MAX_COEFFICIENTS``): the closed loop
#: aims alone.  The rate control predicts with it (``codec.ratecontrol``): the bpp search's
#: sample of blocks is re-decided on its blocks alone (``regions``) and codes RDOQ's integers,
#: pictures of many blocks sample twice (RDOQ's size over the dead zone's estimate moves with
#: the step) and aim at the middle of the window, and the quality search verifies RDOQ's
#: error (two more verifications at most, and without RDOQ where it still misses).
#: Measured with ``benchmarks/rate_distortion.py --rdoq`` (``encode_image(bpp=r)`` on the
#: tuning pictures, 0.25-2 bpp, cdf97): BD-rate -1.06 % (grey -1.13 %, colour -0.77 %), all 35
#: codings in 97.5-100 % of their budget, encode CPU x1.08 (geometric mean); ``bspline2``'s
#: tuning pictures run the closed loop, where it does not run (RDOQ before the fit was tried:
#: +0.52 %).  On ``benchmarks/codec_speed.py``'s 2048² RGB picture at 0.25-2 bpp: cdf97
#: +0.02 to +0.20 dB, bspline2 +0.46 to +0.62 dB at the budget; encode CPU x1.35 (cdf97) and
#: x1.33 (bspline2) at 1 bpp, interleaved runs.  The quality search at 40 dB: camera -1.1 %
#: bytes, encode CPU x1.35.  Off by default until 6 Dec: the codec's speed targets did not
#: survive it then (2048² RGB at 1 bpp cdf97 0.69x OpenJPEG's time and 9.9 MP/s to encode).
#: On since 6 Dec, when the pass took about half the CPU (the same indices) and the block
#: coder's kernels got faster: ``codec_speed.py`` with it on, cdf97 0.49-0.50x OpenJPEG's time
#: and 14.8-15.2 MP/s, the camera at 40 dB 0.74-0.84x (docs/benchmarks.md).  With context
#: coder version 6 it gains -1.06 % on the grey tuning pictures and -0.57 % on the astronaut.
#: Since the fast pass's table reads the parent band as version 6 does
#: (``FAST_ROUNDINGS``), ``encode_image(bpp=r)`` with it over the previous table: BD-rate
#: -0.23 % on the tuning pictures (docs/benchmarks.md).  ``ENABLED = False`` turns it off.
ENABLED = True
METHOD = "fast"

#: The Lagrange multiplier in units of the band step squared per bit (see the module text).
LAMBDA = 0.1
#: The code-block side of the coder (``blockcoder.BLOCK_SIZE``), where its models restart.
BLOCK = 128
#: The largest candidate is ``floor(|x| + TOP_ROUNDING)``: above the dead zone's 0.27, so that
#: a value just under a bin's edge may round up where its neighbours make that cheap (0.4
#: measured a little better than plain rounding, 0.5, and much better than 0.27).
TOP_ROUNDING = 0.4

# Plane table columns: where a plane lives in the level's flat arrays, its shape, and the
# planes its external context reads (earlier orientations of its channel, and luma).
_OFFSET, _ROWS, _COLS, _SIB1, _SIB2, _LUMA = range(6)

_CLASSES = kernels.LOCAL_CLASSES * kernels.EXTERNAL_CLASSES
#: ``_COST[p >> 3]``: bits to code a 0 whose probability is ``p / 2**15``.
_COST = -np.log2((np.arange(1 << (kernels.PROB_BITS - 3)) * 8 + 4) / kernels.PROB_ONE)


def _initial_zero_models() -> np.ndarray:
    """The coder's starting probabilities of a zero for the detail planes' zero flags."""
    start = kernels.ZERO_BASE + _CLASSES  # the detail kind follows the approximation's
    return (kernels.INITIAL_MODELS[start : start + _CLASSES] >> 8).astype(np.int64)


_ZERO_START = _initial_zero_models()


@njit(nogil=True, cache=True, inline="always")
def _bits(p, bit):
    """Bits to code ``bit`` under a probability ``p`` of a zero (15-bit)."""
    if bit == 0:
        return _COST[p >> 3]
    return _COST[(kernels.PROB_ONE - p) >> 3]


@njit(nogil=True, cache=True, inline="always")
def _adapt(p, n, ctx, bit):
    shift = kernels.RATE[n[ctx]]
    if bit == 0:
        p[ctx] += (kernels.PROB_ONE - p[ctx]) >> shift
    else:
        p[ctx] -= p[ctx] >> shift
    if n[ctx] < kernels.COUNT_CAP:
        n[ctx] += 1


@njit(nogil=True, cache=True, inline="always")
def _magnitude_bits(unary_p, unary_base, v):
    """Bits of a nonzero magnitude ``v``: its unary bit length under the models, then one bit
    per bit below the leading one, then the sign."""
    klass = np.int64(0)
    t = v
    while t:
        t >>= 1
        klass += 1
    bits = np.float64(klass)  # the bits below the leading one, and the sign
    for k in range(1, klass + 1):
        ctx = unary_base + min(k - 1, kernels.UNARY_INDICES - 1)
        bits += _bits(unary_p[ctx], 1 if klass > k else 0)
    return bits


@njit(nogil=True, cache=True, inline="always")
def _adapt_magnitude(unary_p, unary_n, unary_base, v):
    klass = np.int64(0)
    t = v
    while t:
        t >>= 1
        klass += 1
    for k in range(1, klass + 1):
        _adapt(unary_p, unary_n, unary_base + min(k - 1, kernels.UNARY_INDICES - 1), klass > k)


@njit(nogil=True, cache=True, inline="always")
def _at(q, planes, p, i, j):
    """``|q|`` of plane ``p`` at ``(i, j)``; 0 for no plane or outside it."""
    if p < 0 or i >= planes[p, _ROWS] or j >= planes[p, _COLS]:
        return np.int64(0)
    return abs(np.int64(q[planes[p, _OFFSET] + i * planes[p, _COLS] + j]))


@njit(nogil=True, cache=True)
def _optimise_blocks(q, x, planes, offsets, parent_q, parent_planes, lam, zero_start, lo, hi):
    """RDOQ in place of blocks ``lo .. hi - 1`` (row by row over the level's grid of blocks) of
    one level's detail planes (``q`` indices, ``x`` values in step units; ``parent_q`` and
    ``parent_planes``: the level one coarser, already decided, its planes in the same order,
    or no planes).  Blocks touch only their own positions, so runs of blocks go to threads."""
    width = 0
    for p in range(planes.shape[0]):
        width = max(width, planes[p, _COLS])
    grid_cols = (width + BLOCK - 1) // BLOCK
    zero_p = np.empty(_CLASSES, dtype=np.int64)
    zero_n = np.empty(_CLASSES, dtype=np.int64)
    unary_size = (kernels.LOCAL_CLASSES + 1) * kernels.UNARY_INDICES
    unary_p = np.empty(unary_size, dtype=np.int64)
    unary_n = np.empty(unary_size, dtype=np.int64)
    cost = np.zeros(BLOCK * BLOCK, dtype=np.float64)
    tiles_across = (BLOCK + kernels.TILE - 1) // kernels.TILE
    live_tiles = np.zeros(tiles_across * tiles_across, dtype=np.bool_)
    tile = kernels.TILE
    for b in range(lo, hi):
        r0 = (b // grid_cols) * BLOCK
        c0 = (b % grid_cols) * BLOCK
        zero_p[:] = zero_start
        zero_n[:] = 2
        unary_p[:] = kernels.PROB_ONE // 2
        unary_n[:] = 0
        for p in range(planes.shape[0]):
            offset, rows, cols = planes[p, _OFFSET], planes[p, _ROWS], planes[p, _COLS]
            r1 = min(r0 + BLOCK, rows)
            c1 = min(c0 + BLOCK, cols)
            if r1 <= r0 or c1 <= c0:
                continue
            delta = offsets[p]
            # A tile where no candidate is nonzero stays empty, and the coder neither
            # codes nor adapts on its positions: skipped alike.
            for t0 in range(r0, r1, tile):
                for u0 in range(c0, c1, tile):
                    live = False
                    for i in range(t0, min(t0 + tile, r1)):
                        for j in range(u0, min(u0 + tile, c1)):
                            if abs(x[offset + i * cols + j]) + TOP_ROUNDING >= 1.0:
                                live = True
                    live_tiles[((t0 - r0) // tile) * tiles_across + (u0 - c0) // tile] = live
            for i in range(r0, r1):
                tile_row = ((i - r0) // tile) * tiles_across
                for j in range(c0, c1):
                    at = offset + i * cols + j
                    if not live_tiles[tile_row + (j - c0) // tile]:
                        q[at] = 0
                        cost[(i - r0) * BLOCK + (j - c0)] = 0.0
                        continue
                    # the coder's contexts, from the indices already decided
                    s = np.int64(0)
                    if j > c0:
                        s += 4 * abs(np.int64(q[at - 1]))
                        if j > c0 + 1:
                            s += abs(np.int64(q[at - 2]))
                    if i > r0:
                        up = at - cols
                        s += 4 * abs(np.int64(q[up]))
                        if i > r0 + 1:
                            s += abs(np.int64(q[up - cols]))
                        if j > c0:
                            s += 2 * abs(np.int64(q[up - 1]))
                        if j + 1 < c1:
                            s += 2 * abs(np.int64(q[up + 1]))
                    e = 2 * (
                        _at(q, planes, planes[p, _SIB1], i, j)
                        + _at(q, planes, planes[p, _SIB2], i, j)
                    ) + 4 * _at(q, planes, planes[p, _LUMA], i, j)
                    if p < parent_planes.shape[0]:  # version 6: the parent band
                        e += kernels.PARENT_WEIGHT * _at(parent_q, parent_planes, p, i >> 1, j >> 1)
                    ctx = kernels.LOCAL_CLASS[s if s < 255 else 255] * kernels.EXTERNAL_CLASSES
                    ctx += kernels.EXTERNAL_CLASS[min(e, 12)]
                    unary_base = (kernels.LOCAL_CLASS[min(s + e, 255)] >> 1) * kernels.UNARY_INDICES
                    value = x[at]
                    ax = abs(value)
                    top = np.int64(np.floor(ax + TOP_ROUNDING))
                    if top > 2147483647:  # leave the quantizer's own saturation alone
                        top = abs(np.int64(q[at]))
                    best = np.int64(0)
                    best_bits = _bits(zero_p[ctx], 0)
                    best_cost = ax * ax + lam * best_bits
                    low = top - 1 if top > 1 else np.int64(1)
                    for v in range(low, top + 1):
                        err = ax - (v + delta)
                        bits = _bits(zero_p[ctx], 1) + _magnitude_bits(unary_p, unary_base, v)
                        total = err * err + lam * bits
                        if total < best_cost:
                            best = np.int64(v)
                            best_bits = bits
                            best_cost = total
                    q[at] = -best if value < 0 else best
                    cost[(i - r0) * BLOCK + (j - c0)] = best_bits
                    _adapt(zero_p, zero_n, ctx, best != 0)
                    if best:
                        _adapt_magnitude(unary_p, unary_n, unary_base, best)
            # Empty the tiles whose values cost more than the error of dropping them
            # (an empty tile's positions are not coded at all).
            for t0 in range(r0, r1, tile):
                for u0 in range(c0, c1, tile):
                    saved = -1.0  # the tile flag costs about as much either way
                    added = 0.0
                    for i in range(t0, min(t0 + tile, r1)):
                        for j in range(u0, min(u0 + tile, c1)):
                            at = offset + i * cols + j
                            saved += cost[(i - r0) * BLOCK + (j - c0)]
                            if q[at] != 0:
                                ax = abs(x[at])
                                err = ax - (abs(np.int64(q[at])) + delta)
                                added += ax * ax - err * err
                    if added > 0.0 and added < lam * saved:
                        for i in range(t0, min(t0 + tile, r1)):
                            for j in range(u0, min(u0 + tile, c1)):
                                q[offset + i * cols + j] = 0


def optimise_indices(
    coeffs: Sequence[Any],
    qcoeffs: Sequence[Any],
    params: dict[str, Any],
    *,
    lam: float | None = None,
) -> Any:
    """Re-choose the detail indices of an image's quantization for rate and distortion, in
    place.

    Parameters
    ----------
    coeffs : list
        The decomposition that was quantized (``wavedec2`` layout, bands ``(H, W)`` or
        ``(H, W, C)``).
    qcoeffs : list
        Its indices from :func:`wavecore.quantize.quantize_bands`, same layout; the detail
        bands are overwritten.
    params : dict
        ``quantize_bands``' parameters (``step``, ``weights``, ``rounding``).
    lam : float, optional
        The Lagrange multiplier in units of the band step squared per bit (``LAMBDA`` by
        default); 0 returns the indices unchanged.

    Returns
    -------
    list
        ``qcoeffs`` itself (the coarse band is left as it is).
    """
    lam = LAMBDA if lam is None else float(lam)
    levels = as_levels(qcoeffs)
    if lam <= 0 or len(levels) < 2:
        return qcoeffs
    values = as_levels(coeffs)
    step = float(params["step"])
    rounding = float(params["rounding"])
    # The coarsest details have no parent band (context coder version 6).
    parent_q = np.zeros(0, dtype=np.int32)
    parent_planes = np.zeros((0, 6), dtype=np.int64)
    for bands, originals, weights in zip(
        levels[1:], values[1:], params["weights"][1:], strict=True
    ):
        shapes = [band.shape for band in bands]
        channels = shapes[0][2] if len(shapes[0]) == 3 else 1
        table: list[list[int]] = []
        flat_q = []
        flat_x = []
        offsets = []
        offset = 0
        for channel in range(channels):
            for k, (band, original, weight) in enumerate(
                zip(bands, originals, weights, strict=True)
            ):
                plane = band[..., channel] if band.ndim == 3 else band
                source = original[..., channel] if band.ndim == 3 else original
                me = len(table)
                table.append(
                    [
                        offset,
                        plane.shape[0],
                        plane.shape[1],
                        me - k if k > 0 else -1,
                        me - k + 1 if k > 1 else -1,
                        k if channel > 0 else -1,
                    ]
                )
                flat_q.append(np.ascontiguousarray(plane, dtype=np.int32).ravel())
                flat_x.append(np.asarray(source, dtype=np.float64).ravel() / (step * weight))
                offsets.append(reconstruction_offset(band, rounding))
                offset += plane.size
        q = np.concatenate(flat_q)
        x = np.concatenate(flat_x)
        planes = np.array(table, dtype=np.int64)
        shifts = np.array(offsets, dtype=np.float64)
        height = max(row[1] for row in table)
        width = max(row[2] for row in table)
        count = -(-height // BLOCK) * -(-width // BLOCK)
        blocks = functools.partial(
            _optimise_blocks, q, x, planes, shifts, parent_q, parent_planes, lam, _ZERO_START
        )
        run_rows(blocks, count, q.size)
        parent_q, parent_planes = q, planes
        for k, band in enumerate(bands):
            for channel in range(channels):
                row = table[channel * len(bands) + k]
                plane = q[row[0] : row[0] + row[1] * row[2]].reshape(row[1], row[2])
                if band.ndim == 3:
                    band[..., channel] = plane
                else:
                    band[...] = plane
    return qcoeffs


# --------------------------------------------------------------------------------------------
# The fast variant: a dead zone that depends on the neighbourhood (one compiled pass)
# --------------------------------------------------------------------------------------------

#: The dead zone's ``rounding`` by the neighbourhood of a detail, as the coder's zero-flag
#: contexts see it (``_blockkernels``), in the dead-zone quantizer's own integers: the local
#: class of ``L``, the sum of ``|q|`` over its eight neighbours (``L = 0``, ``1 <= L <= 2``,
#: ``L >= 3``) times the external class of ``E = 2 (|q|`` of the other two orientations at the
#: same place ``) + 4 |q|`` of the first channel there (the second and third channels only)
#: ``+ PARENT_WEIGHT |q|`` of the parent, the same band one level coarser at ``(i // 2,
#: j // 2)`` (``E = 0``, ``1 <= E <= 3``, ``E >= 4``): a 3 × 3 table (local class by rows) for
#: the first channel (luma), then one for the others (chroma).  Every term is the dead zone's
#: index, the parent's too (so levels, and the bpp sample's regions, decide independently).
#: A 1 costs some 6-8 bits where everything around is 0 (its zero flag under a quiet context,
#: often its tile's flag, the unary length and the sign) and 2-3 bits among busy neighbours,
#: so the edge between 0 and 1 moves from the quantizer's ``1 - 0.27`` to 1.0 in quiet places
#: and to 0.64 in busy ones; a nonzero parent (context coder version 6) makes a 1 cheaper.
#: Tuned on the tuning pictures (cdf97) against the previous rule (one class of ``A = L`` plus
#: the other orientations and luma, unweighted, no parent: luma ``(0.05, 0.22, 0.33)``, chroma
#: ``(0, 0.12, 0.27)``, tuned with context coder version 4): coordinate search on the BD-rate
#: of bundles at the steps the bpp search took for the peers' seven rates (-0.48 %), then on
#: that and ``encode_image(bpp=r)``'s BD-rate at eleven rates together (the bpp search's trims
#: of a coding just outside the budget's window undo part of it: -0.23 % there, -0.30 % with
#: the luma busy-local, busy-external rounding raised from 0.28 to 0.32, -0.44 % at the fixed
#: steps).  The same table without the parent term: -0.10 % at the fixed steps; the parent
#: added to ``A`` of the previous rule (weight 1): -0.02 %; the parent's decided index instead
#: of its dead zone's: the same within 0.01 %.
FAST_ROUNDINGS = (
    *(0.0, 0.09, 0.17, 0.17, 0.25, 0.32, 0.31, 0.33, 0.36),
    *(0.0, 0.12, 0.1, 0.12, 0.12, 0.22, 0.22, 0.25, 0.32),
)
#: The parent's weight in ``E``: context coder version 6's (``_blockkernels.PARENT_WEIGHT``);
#: 0 for layouts coded with version 4, whose contexts do not read the parent band.
PARENT_WEIGHT = kernels.PARENT_WEIGHT


#: A box's columns run to the end of its rows.
_ALL_COLUMNS = 1 << 62
#: The eight neighbours' offsets (rows, columns), in the order they are summed.
_NEIGHBOUR_ROWS = (-1, -1, -1, 0, 0, 1, 1, 1)
_NEIGHBOUR_COLUMNS = (-1, 0, 1, -1, 1, -1, 0, 1)


@njit(nogil=True, cache=True, inline="always")
def _decide_row(
    i,
    k,
    band,
    sib1,
    sib2,
    parent,
    parent_weight,
    values,
    inverse,
    col_lo,
    col_hi,
    rounding,
    found,
    out,
):
    """Row ``i`` of band ``k`` (``sib1``, ``sib2``: the level's other two; ``parent``: the same
    band one level coarser, ``(0, 0, C)`` for none) for :func:`_neighbourhood_deadzone`: its
    changes appended to ``out`` (``out[0]`` counts them); ``found``: scratch of the band's row
    length.  Returns ``out``, grown if need be."""
    rows, cols, channels = band.shape
    if i >= rows:
        return out
    lowest, highest = 1.0 - max(rounding), 1.0 - min(rounding)
    line = values.reshape(rows, cols * channels)[i]
    inner_rows = min(sib1.shape[0], sib2.shape[0])
    inner_cols = min(sib1.shape[1], sib2.shape[1])
    parent_rows = parent.shape[0] if i >> 1 < parent.shape[0] else 0
    parent_cols = parent.shape[1]
    # Only values between the busiest and the quietest edge depend on the neighbourhood (some
    # 5 % at 1 bpp): they are listed first without a branch (a branch per value mispredicted
    # at every one of them), then decided.
    n = 0
    for t in range(min(col_lo, cols) * channels, min(col_hi, cols) * channels):
        a = abs(line[t] * inverse)
        found[n] = t
        n += (lowest <= a) & (a < highest)
    if out[0] + n >= out.size:
        grown = np.empty(2 * out.size + n, dtype=np.int64)
        grown[: out.size] = out
        out = grown
    for m in range(n):
        t = found[m]
        value = line[t] * inverse
        j = t // channels
        c = t - j * channels
        if 0 < i < rows - 1 and 0 < j < cols - 1 and i < inner_rows and j < inner_cols:
            # Inside the band (and its siblings): every term, without a branch.
            up = band[i - 1]
            mid = band[i]
            down = band[i + 1]
            local = (
                abs(np.int64(up[j - 1, c]))
                + abs(np.int64(up[j, c]))
                + abs(np.int64(up[j + 1, c]))
                + abs(np.int64(mid[j - 1, c]))
                + abs(np.int64(mid[j + 1, c]))
                + abs(np.int64(down[j - 1, c]))
                + abs(np.int64(down[j, c]))
                + abs(np.int64(down[j + 1, c]))
            )
            external = 2 * (abs(np.int64(sib1[i, j, c])) + abs(np.int64(sib2[i, j, c])))
        else:
            local = np.int64(0)
            for e in range(8):
                ii = i + _NEIGHBOUR_ROWS[e]
                jj = j + _NEIGHBOUR_COLUMNS[e]
                if 0 <= ii < rows and 0 <= jj < cols:
                    local += abs(np.int64(band[ii, jj, c]))
            external = np.int64(0)
            if i < sib1.shape[0] and j < sib1.shape[1]:
                external += 2 * abs(np.int64(sib1[i, j, c]))
            if i < sib2.shape[0] and j < sib2.shape[1]:
                external += 2 * abs(np.int64(sib2[i, j, c]))
        if c > 0:
            external += 4 * abs(np.int64(band[i, j, 0]))
        if j >> 1 < parent_cols and parent_rows:
            external += parent_weight * abs(np.int64(parent[i >> 1, j >> 1, c]))
        klass = (9 if c > 0 else 0) + (0 if local == 0 else (3 if local <= 2 else 6))
        klass += 0 if external == 0 else (1 if external <= 3 else 2)
        new = 0
        if abs(value) >= 1.0 - rounding[klass]:
            new = 1 if value > 0 else -1
        if new != band[i, j, c]:
            out[0] += 1
            out[out[0]] = ((i * cols * channels + t) * 3 + k) * 3 + new + 1
    return out


@njit(nogil=True, cache=True)
def _neighbourhood_deadzone(
    q, x, up, parent_weight, inverse_steps, lo, hi, rounding, col_lo, col_hi
):
    """Re-decide between 0 and 1 the details of rows ``lo .. hi - 1`` (columns ``col_lo ..
    col_hi - 1``) of one level, without changing them: the changes, for :func:`_apply`.

    ``q``: three ``(H, W, C)`` int32 bands, the dead zone's indices; ``x``: their values;
    ``up``: the bands one level coarser (``(0, 0, C)`` where there are none), whose ``|q|``
    counts ``parent_weight`` times in the external sum; ``inverse_steps``: per band.  Larger
    indices stay as they are.  Each decision reads the dead zone's indices around it, which no
    call changes, so the result does not depend on how the rows are cut between threads.
    """
    # Row by row across the three bands, so that the other bands' rows a decision reads were
    # read lately (band by band: some 15 % slower); the bands are passed apart (an array
    # taken from the tuple by a variable index is counted up and down).
    q0, q1, q2 = q
    x0, x1, x2 = x
    p0, p1, p2 = up
    rows = max(q0.shape[0], max(q1.shape[0], q2.shape[0]))
    width = max(
        q0.shape[1] * q0.shape[2], max(q1.shape[1] * q1.shape[2], q2.shape[1] * q2.shape[2])
    )
    found = np.empty(width, dtype=np.int64)
    out = np.zeros(width + 1, dtype=np.int64)
    for i in range(lo, min(hi, rows)):
        out = _decide_row(
            i,
            0,
            q0,
            q1,
            q2,
            p0,
            parent_weight,
            x0,
            inverse_steps[0],
            col_lo,
            col_hi,
            rounding,
            found,
            out,
        )
        out = _decide_row(
            i,
            1,
            q1,
            q0,
            q2,
            p1,
            parent_weight,
            x1,
            inverse_steps[1],
            col_lo,
            col_hi,
            rounding,
            found,
            out,
        )
        out = _decide_row(
            i,
            2,
            q2,
            q0,
            q1,
            p2,
            parent_weight,
            x2,
            inverse_steps[2],
            col_lo,
            col_hi,
            rounding,
            found,
            out,
        )
    return out[1 : out[0] + 1]


@njit(nogil=True, cache=True)
def _deadzone_boxes(q, x, up, parent_weight, inverse_steps, boxes, lo, hi, rounding):
    """:func:`_neighbourhood_deadzone` on boxes ``lo .. hi - 1`` of ``boxes`` (rows of
    ``row0, col0, row1, col1``).  A box's decisions read only the dead zone's indices around
    it, so they are the ones the whole level's pass makes there."""
    parts = []
    total = 0
    for b in range(lo, hi):
        part = _neighbourhood_deadzone(
            q,
            x,
            up,
            parent_weight,
            inverse_steps,
            boxes[b, 0],
            boxes[b, 2],
            rounding,
            boxes[b, 1],
            boxes[b, 3],
        )
        parts.append(part)
        total += part.size
    out = np.empty(total, dtype=np.int64)
    at = 0
    for part in parts:
        out[at : at + part.size] = part
        at += part.size
    return out


@njit(nogil=True, cache=True)
def _apply(q, changes):
    """Write ``changes`` (from :func:`_neighbourhood_deadzone`: ``(flat position * 3 + band)
    * 3 + new index + 1``) into the bands ``q``."""
    flat0, flat1, flat2 = q[0].reshape(q[0].size), q[1].reshape(q[1].size), q[2].reshape(q[2].size)
    for code in changes:
        new = code % 3 - 1
        rest = code // 3
        k = rest % 3
        if k == 0:
            flat0[rest // 3] = new
        elif k == 1:
            flat1[rest // 3] = new
        else:
            flat2[rest // 3] = new


def adapt_deadzone(
    coeffs: Sequence[Any],
    qcoeffs: Sequence[Any],
    params: dict[str, Any],
    *,
    roundings: Sequence[float] = FAST_ROUNDINGS,
    regions: np.ndarray | None = None,
    parent_weight: int = PARENT_WEIGHT,
) -> Any:
    """Re-decide the 0/1 details of an image's quantization with a dead zone that depends on
    the neighbourhood, in place (the cheap stand-in for :func:`optimise_indices`).

    Parameters
    ----------
    coeffs, qcoeffs, params
        As for :func:`optimise_indices` (2-D levels of three bands each).
    roundings : sequence of 9 or 18 floats
        The dead zone's ``rounding`` by the local class (rows) and the external class of the
        neighbourhood (``FAST_ROUNDINGS``), for every channel or (18) for the first channel
        and then the others; each in ``(-0.5, 1)``.
    regions : array of shape (n, 5), optional
        Only these boxes are re-decided, rows of ``(level, row0, col0, row1, col1)`` (the
        level as in ``layout.as_levels``, 1 the coarsest details; the block coder's
        ``blockcoder.block_lengths`` regions), each the same in its level's three bands:
        what the whole pass decides there (a box's decisions read only the dead zone's
        indices around them), for a fraction of its cost.  Default: everything.
    parent_weight : int
        The weight of the parent's ``|q|`` (the same band one level coarser, at ``(i // 2,
        j // 2)``) in the external sum: ``PARENT_WEIGHT``, context coder version 6's; 0 for
        version 4's contexts.

    Returns
    -------
    list
        ``qcoeffs`` itself (the coarse band is left as it is).
    """
    levels = as_levels(qcoeffs)
    values = as_levels(coeffs)
    step = float(params["step"])
    rounding = tuple(float(r) for r in roundings)
    if len(rounding) == 9:
        rounding = rounding + rounding
    if len(rounding) != 18 or not all(-0.5 < r < 1.0 for r in rounding):
        msg = f"roundings must be 9 or 18 numbers in (-0.5, 1), not {roundings!r}"
        raise InvalidParameter(msg)
    if parent_weight < 0:
        msg = f"parent_weight must be >= 0, not {parent_weight!r}"
        raise InvalidParameter(msg)
    if regions is not None:
        regions = np.asarray(regions, dtype=np.int64).reshape(-1, 5)
    if any(len(bands) != 3 for bands in levels[1:]):
        return qcoeffs

    def three_d(a: np.ndarray, dtype: Any) -> np.ndarray:
        a = np.ascontiguousarray(a, dtype=dtype)
        return a if a.ndim == 3 else a.reshape(*a.shape[:2], -1)

    q = [tuple(three_d(b, np.int32) for b in bands) for bands in levels[1:]]
    none = (np.zeros((0, 0, q[0][0].shape[2] if q else 1), dtype=np.int32),) * 3
    # Every level decides from the dead zone's indices of its own and its parent's level (as
    # a region does, whatever else is re-decided), so the changes wait until all are decided.
    decided = []
    for entry, (bands, originals, weights) in enumerate(
        zip(q, values[1:], params["weights"][1:], strict=True), start=1
    ):
        boxes = None
        if regions is not None:
            boxes = np.ascontiguousarray(regions[regions[:, 0] == entry, 1:])
            if boxes.shape[0] == 0:
                continue
        x = tuple(three_d(v, np.float64) for v in originals)
        inverse = np.array([1.0 / (step * w) for w in weights], dtype=np.float64)
        up = q[entry - 2] if entry >= 2 else none
        changes = _adapt_level(bands, x, up, int(parent_weight), inverse, rounding, boxes)
        decided.append((bands, changes))
    for bands, changes in decided:
        for part in changes:
            _apply(bands, part)
    for originals, new in zip(levels[1:], q, strict=True):
        for band, b in zip(originals, new, strict=True):
            if not np.may_share_memory(band, b):
                band[...] = b.reshape(band.shape)
    return qcoeffs


def _adapt_level(
    q: tuple[np.ndarray, ...],
    x: tuple[np.ndarray, ...],
    up: tuple[np.ndarray, ...],
    parent_weight: int,
    inverse: np.ndarray,
    rounding: tuple,
    boxes: np.ndarray | None = None,
) -> list[np.ndarray]:
    """:func:`_neighbourhood_deadzone` over the threads by rows (or by ``boxes``, where
    given): the changes, for :func:`_apply`."""
    parts: list[np.ndarray] = []  # (list.append is atomic)

    def decide_boxes(lo: int, hi: int) -> None:
        parts.append(_deadzone_boxes(q, x, up, parent_weight, inverse, boxes, lo, hi, rounding))

    def decide(lo: int, hi: int) -> None:
        parts.append(
            _neighbourhood_deadzone(
                q, x, up, parent_weight, inverse, lo, hi, rounding, 0, _ALL_COLUMNS
            )
        )

    if boxes is None:
        run_rows(decide, max(b.shape[0] for b in q), sum(b.size for b in q))
    else:
        area = int(((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])).sum())
        run_rows(decide_boxes, boxes.shape[0], area * q[0].shape[2] * 3)
    return parts


def choose_indices(coeffs: Sequence[Any], qcoeffs: Sequence[Any], params: dict[str, Any]) -> Any:
    """The encoder's re-decision of an image's detail indices, in place, by ``METHOD``:
    :func:`adapt_deadzone` (``"fast"``) or :func:`optimise_indices` (``"full"``).

    Returns ``qcoeffs`` itself.
    """
    if METHOD == "full":
        return optimise_indices(coeffs, qcoeffs, params)
    return adapt_deadzone(coeffs, qcoeffs, params)
