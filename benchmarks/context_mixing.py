"""What stronger zero-flag modelling could save, estimated before building a coder version 5.

Run with ``.venv/bin/python benchmarks/context_mixing.py`` (a minute).  For each tuning picture
(cdf97, 5 levels, dead-zone quantization at a fine and a coarse step) it walks every code-block
as the context coder (version 4) does, visiting the zero flags it codes (detail planes, tiles
that hold a value), and adds up each flag's ideal code length, ``-log2 p``, under:

* ``v4``: the coder's own model (local class × external class, the same start and adaptation);
* ``apm``: v4's probability refined by an adaptive probability map (secondary estimation, 33
  buckets over the stretched probability, interpolated) whose context is the pattern of
  nonzero causal neighbours (W, N, NW, NE, WW, NN) × the band's orientation × whether the other
  bands are nonzero there; output ``(p + 3 apm) / 4``;
* ``mix2`` / ``mix3``: a logistic mixer (weights per local class, learning rate 0.01–0.02) of
  v4 with the pattern model (and a model of the count of nonzero neighbours × orientation),
  then the same map.

It prints the saving of each against v4 as a share of the *whole* coded size (the coder's real
bytes at that step), which is what a version 5 would gain at most from its zero flags
(arithmetic in floats here; a coder needs the same in integers).  Not a coder: no bits are
written, so it is an estimate of modelling, not of a bitstream.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from skimage import data

import wavecore
from wavecore import _blockkernels as kernels
from wavecore.colour import ycbcr_forward
from wavecore.entropy import encode_levels
from wavecore.quantize import quantize_bands

PICTURES = ("camera", "moon", "coins", "brick", "astronaut")
STEPS = (5.0, 20.0)
#: (label, mixer learning rate, models mixed: 1 = v4 alone, 2 = v4 + pattern, 3 = all three)
CONFIGS = (("apm", 0.0, 1), ("mix2", 0.02, 2), ("mix3", 0.01, 3))
_PATTERNS = 3 * 64 * 2
_K = kernels


@njit(cache=True)
def _squash(x):
    return 1.0 / (1.0 + math.exp(-min(max(x, -30.0), 30.0)))


@njit(cache=True)
def _clip(p):
    return min(max(p, 1e-4), 1.0 - 1e-4)


@njit(cache=True)
def _adapt(probs, counts, ctx, bit):
    probs[ctx] += (bit - probs[ctx]) / (1 << _K.RATE[counts[ctx]])
    if counts[ctx] < _K.COUNT_CAP:
        counts[ctx] += 1


@njit(cache=True)
def _abs_at(flat, at, ok):
    return abs(np.int64(flat[at])) if ok else np.int64(0)


@njit(cache=True)
def _estimate(flat, planes, blocks, start, rate, models):
    """Ideal bits of the coded zero flags: (v4's, the refined model's)."""
    tile = _K.TILE
    classes = _K.LOCAL_CLASSES * _K.EXTERNAL_CLASSES
    bits_v4 = 0.0
    bits_new = 0.0
    for b in range(blocks.shape[0]):
        block = blocks[b]
        r0, c0 = block[_K.B_ROW0], block[_K.B_COL0]
        p0 = 1.0 - start / 32768.0
        n0 = np.zeros(classes, dtype=np.int64)
        p1 = np.full(3 * 8 * 4, 0.5)
        n1 = np.zeros(3 * 8 * 4, dtype=np.int64)
        p2 = np.full(_PATTERNS, 0.5)
        n2 = np.zeros(_PATTERNS, dtype=np.int64)
        weights = np.zeros((_K.LOCAL_CLASSES, 3))
        weights[:, 0] = 1.0
        apm = np.empty((_PATTERNS, 33))
        for k in range(33):
            apm[:, k] = _squash((k - 16) / 2.0)
        for p in range(block[_K.B_PLANE_LO], block[_K.B_PLANE_HI]):
            if planes[p, _K.P_KIND] == 0:
                continue
            offset, rows, cols = planes[p, _K.P_OFFSET], planes[p, _K.P_ROWS], planes[p, _K.P_COLS]
            r1, c1 = min(block[_K.B_ROW1], rows), min(block[_K.B_COL1], cols)
            orient = planes[p, _K.P_ORIENT]
            for i in range(r0, r1):
                for j in range(c0, c1):
                    t0 = r0 + ((i - r0) // tile) * tile
                    u0 = c0 + ((j - c0) // tile) * tile
                    live = False
                    for a in range(t0, min(t0 + tile, r1)):
                        for c in range(u0, min(u0 + tile, c1)):
                            live |= flat[offset + a * cols + c] != 0
                    if not live:
                        continue
                    at = offset + i * cols + j
                    e = np.int64(0)
                    for slot, weight in ((_K.P_SIB1, 2), (_K.P_SIB2, 2), (_K.P_LUMA, 4)):
                        q = planes[p, slot]
                        if q >= 0 and i < planes[q, _K.P_ROWS] and j < planes[q, _K.P_COLS]:
                            other = planes[q, _K.P_OFFSET] + i * planes[q, _K.P_COLS] + j
                            e += weight * abs(np.int64(flat[other]))
                    bit = 1 if flat[at] != 0 else 0
                    w_ = _abs_at(flat, at - 1, j > c0)
                    n_ = _abs_at(flat, at - cols, i > r0)
                    nw = _abs_at(flat, at - cols - 1, i > r0 and j > c0)
                    ne = _abs_at(flat, at - cols + 1, i > r0 and j + 1 < c1)
                    ww = _abs_at(flat, at - 2, j > c0 + 1)
                    nn = _abs_at(flat, at - 2 * cols, i > r0 + 1)
                    s = 4 * (w_ + n_) + 2 * (nw + ne) + ww + nn
                    local = _K.LOCAL_CLASS[min(s, 255)]
                    ctx0 = local * _K.EXTERNAL_CLASSES + _K.EXTERNAL_CLASS[min(e, 12)]
                    count = (w_ > 0) + (n_ > 0) + (nw > 0) + (ne > 0)
                    if w_ > 1 or n_ > 1:
                        count = 5 + (w_ + n_ > 4) + (w_ + n_ > 10)
                    ctx1 = (orient * 8 + count) * 4 + _K.EXTERNAL_CLASS[min(e, 12)]
                    pattern = (w_ > 0) | (n_ > 0) << 1 | (nw > 0) << 2 | (ne > 0) << 3
                    pattern |= (ww > 0) << 4 | (nn > 0) << 5
                    ctx2 = (orient * 64 + pattern) * 2 + (1 if e > 0 else 0)
                    x = np.array(
                        [
                            math.log(_clip(p0[ctx0]) / (1 - _clip(p0[ctx0]))),
                            math.log(_clip(p2[ctx2]) / (1 - _clip(p2[ctx2]))),
                            math.log(_clip(p1[ctx1]) / (1 - _clip(p1[ctx1]))),
                        ]
                    )
                    bits_v4 -= math.log2(_clip(p0[ctx0]) if bit else 1 - _clip(p0[ctx0]))
                    dot = 0.0
                    for m in range(models):
                        dot += weights[local, m] * x[m]
                    mixed = _squash(dot)
                    z = min(max(dot * 2.0 + 16.0, 0.0), 31.999)
                    k = int(z)
                    frac = z - k
                    mapped = apm[ctx2, k] * (1 - frac) + apm[ctx2, k + 1] * frac
                    final = _clip(0.25 * mixed + 0.75 * mapped)
                    bits_new -= math.log2(final if bit else 1 - final)
                    apm[ctx2, k] += (bit - apm[ctx2, k]) * (1 - frac) * 0.02
                    apm[ctx2, k + 1] += (bit - apm[ctx2, k + 1]) * frac * 0.02
                    for m in range(models):
                        weights[local, m] += rate * (bit - mixed) * x[m]
                    _adapt(p0, n0, ctx0, bit)
                    _adapt(p1, n1, ctx1, bit)
                    _adapt(p2, n2, ctx2, bit)
    return bits_v4, bits_new


def _flat(q: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coder's flat layout of quantized bands: ``(flat, planes, blocks)``."""
    from wavecore.blockcoder import _copy_planes, _plane_views, _structure  # the coder's own

    entries = [[q[0]], *(list(level) for level in q[1:])]
    layout = [[band.shape for band in bands] for bands in entries]
    planes, blocks, _, total = _structure(layout, True, 128)
    flat = np.empty(total, dtype=np.int32)
    views = _plane_views(entries, True)
    targets = [
        flat[s : s + v.size].reshape(v.shape)
        for s, v in zip(planes[:, _K.P_OFFSET], views, strict=True)
    ]
    _copy_planes(views, targets, int(total))
    return flat, planes, blocks


def main() -> None:
    detail = slice(_K.ZERO_BASE + _K.LOCAL_CLASSES * _K.EXTERNAL_CLASSES, None)
    start = (_K.INITIAL_MODELS[detail][: _K.LOCAL_CLASSES * _K.EXTERNAL_CLASSES] >> 8).astype(
        np.float64
    )
    print("saving against v4 as a share of the whole coded size (negative: fewer bits)")
    for name in PICTURES:
        image = getattr(data, name)().astype(np.float64)
        image = image[: image.shape[0] // 32 * 32, : image.shape[1] // 32 * 32]
        if image.ndim == 3:
            image = ycbcr_forward(image)
        coeffs = wavecore.wavedec2(image - 128, "cdf97", "open", 5)
        for step in STEPS:
            q, _ = quantize_bands(coeffs, step, wavelet="cdf97", boundary="open", refine=0)
            total = 8 * sum(map(len, encode_levels(q)[0]))
            flat, planes, blocks = _flat(q)
            cells = []
            for label, rate, models in CONFIGS:
                v4, new = _estimate(flat, planes, blocks, start, rate, models)
                cells.append(f"{label} {100 * (new - v4) / total:+.2f} %")
            print(
                f"{name:10s} step {step:4g}: {total // 8:6d} B, zero flags "
                f"{100 * v4 / total:4.1f} %"
                f" of the bits; " + ", ".join(cells),
                flush=True,
            )


if __name__ == "__main__":
    main()
