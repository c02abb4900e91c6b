"""Probes of issue 12's remaining gap: cdf97 on grey pictures against AVIF speed 6.

An experiment harness, not part of the library (no test runs it), for the question the last
fair-peers run left: cdf97 is 8.0 % over AVIF on the grey tuning pictures (camera −2.8, moon
+11.0, coins +9.9, brick +13.9; docs/benchmarks.md), where every other target of the issue is
met.  Each probe measures one kind of change on the tuning pictures (camera, moon, coins,
brick; astronaut for colour where it applies) and prints BD-rates (``rate_distortion.bd_rate``
over each curve's rates; negative: the change needs fewer bytes for the same PSNR):

* ``coder``: the block coder's entropy model (context coder version 8).  Codes the integers
  that ``coder_gain.py capture`` kept (run it first: the 7 exact rates of ``encode_image(...,
  bpp=r)``) with a variant of ``_blockkernels.encode_span`` built from its source (encoder
  only: sizes, nothing decodable), against version 8 on the same integers.  ``--configs``
  are lists ``[lr, w1, w2, w3, bias, mix, signs, inherit, count]``:

  - ``mix`` 1: each detail zero flag is coded at the logistic mix (floating point, as PAQ
    mixes) of version 8's model and two more: (parent magnitude, sibling class, coarse local
    class) and the nonzero pattern of the six causal neighbours and the parent; weights
    ``w1..w3`` (and a bias input of size ``bias``) per orientation and local class, learnt
    at rate ``lr``, reset at every block;
  - ``signs`` 1, 2, 3: the sign under (W, N) and two more signs: (parent, first sibling),
    (NW, NE), (parent, first channel);
  - ``inherit`` n > 0: a block starts every context that its parent block saw at least ``n``
    more times than version 8's prior from the parent block's final probability, with the
    count ``count`` (the parent block is decoded first anyway).

* ``lossless-coder``: the same integers (re-captured here through ``wavecore.decode``) coded
  by context coder version 5, the lossless coder (one context-mixing stream per level), over
  version 8's bytes, at 0.25, 0.5, 1 and 2 bpp.
* ``steps``: the quantizer's per-band steps.  ``encode_image(..., bpp=r)`` with
  ``quantize.band_weights`` scaled (the finest level, the next, the diagonal bands, the
  approximation) against the library's weights (the inverse basis norms).
* ``levels``: ``encode_image(..., level=L, bpp=r)`` for L = 3, 4, 6 against the default 5, and
  the best of 3-6 at each rate against 5.
* ``wavelets``: PyWavelets' biorthogonal filters (periodic, 5 levels; sides cut to multiples
  of 32) through one plain quantizer (the library's dead zone, weights from each basis's
  norms) and version 8's coder, against ``bior4.4`` (CDF 9/7) in the same setting.

* ``blocks``: ``encode_image(..., bpp=r)`` with the context coder's block side (``--sides``)
  against the default 128.
* ``directional``: direction-adaptive lifting of CDF 9/7 (``--adl``: tuples ``(levels,
  block, penalty)``), through the ``wavelets`` setting, against the same lifting with no
  directions; the direction maps counted at their zeroth-order entropy.
* ``dq``: dependent quantization (VVC's two quantizers, four states) against one scalar
  quantizer, both decided by the same trellis (squared error + λ × a static rate model) at
  each of ``--multipliers``; coded by version 8, and as ideal zeroth-order entropies per band
  (and per quantizer for dependent quantization).
* ``alignment``: where the gap comes from.  Each grey picture cut to (H − 8) × (W − 8) at
  several offsets (``--offsets``), cdf97 (``encode_image(..., bpp=r)``) against AVIF speed 6
  on each cut: BD-rate and the PSNR difference per rate; and each cut's *JPEG lattice
  score*: for the 8 × 8 DCT coefficients of the cut's aligned blocks at 14 low-frequency AC
  positions, the largest ``mean cos(2π x / q)`` over steps q = 3 … 40 of the coefficients
  at least q / 2 from zero (near 1 when they lie on a quantizer's lattice, as a decoded
  JPEG's do; near 0 for a smooth density; the median over the positions is printed), and
  the share of its aligned 2 × 2 blocks that are flat (1 where a picture enlarged by pixel
  replication is cut at an even offset); then the same on moon's 256² source (every other
  pixel).
* ``edges``: cdf97's and AVIF's squared error on one picture (``--picture``, brick) at one
  rate (``--rate``, 0.25 bpp) by distance to the nearest edge.

Run with ``.venv/bin/python benchmarks/grey_gap.py PROBE``.  What each gave: docs/benchmarks.md,
"Issue 12's grey gap: what else was measured".
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from skimage import data

import wavecore
import wavecore._blockkernels as kernels
import wavecore.blockcoder as blockcoder
import wavecore.codec.chunks as codec_chunks
import wavecore.codec.ratecontrol as ratecontrol
import wavecore.entropy as entropy
import wavecore.losslesscoder as losslesscoder
import wavecore.quantize as quantize

sys.path.insert(0, str(Path(__file__).resolve().parent))
import coder_gain
import peers
from rate_distortion import bd_rate

GREY = ("camera", "moon", "coins", "brick")
NAMES = (*GREY, "astronaut")

# ---------------------------------------------------------------------------------------------
# coder: a variant of version 8's encoder


def _swap(src: str, old: str, new: str, count: int = 1) -> str:
    return coder_gain._swap(src, old, new, count)


_MIXED_FLAG = """                if approx or wts[WSETS * 4 + 2] == 0.0:
                    low, rng, models[_u(coded)] = _code_bit(low, rng, models[_u(coded)], nonzero)
                else:
                    o = planes_orient
                    P = abs(np.int64(flat[_u(pr + (j >> 1))])) if j < lp else np.int64(0)
                    es = e - PARENT_WEIGHT * P
                    vW = abs(np.int64(flat[at - 1])) if j > c0 else 0
                    vN = abs(np.int64(flat[at - cols])) if i > r0 else 0
                    vNW = abs(np.int64(flat[at - cols - 1])) if i > r0 and j > c0 else 0
                    vNE = abs(np.int64(flat[at - cols + 1])) if i > r0 and j + 1 < c1 else 0
                    vWW = abs(np.int64(flat[at - 2])) if j > c0 + 1 else 0
                    vNN = abs(np.int64(flat[at - 2 * cols])) if i > r0 + 1 else 0
                    ql = 0 if s == 0 else (1 if s < 4 else (2 if s < 12 else (3 if s < 32 else 4)))
                    c2 = EXTRA_BASE + ((o * 4 + min(P, 3)) * 4 + _external_class(es)) * 5 + ql
                    pat = ((vW > 0) * 1 + (vN > 0) * 2 + (vNW > 0) * 4 + (vNE > 0) * 8
                           + (vWW > 0) * 16 + (vNN > 0) * 32 + (P > 0) * 64
                           + (max(vW, vN) > 1) * 128)
                    c3 = EXTRA_BASE + C2_SIZE + o * 256 + pat
                    wset = (o * 14 + LOCAL_CLASS[min(s, 255)]) * 4
                    p1 = (models[_u(coded)] >> 8) / 32768.0
                    p2 = (models[_u(c2)] >> 8) / 32768.0
                    p3 = (models[_u(c3)] >> 8) / 32768.0
                    t1 = np.log(p1 / (1.0 - p1))
                    t2 = np.log(p2 / (1.0 - p2))
                    t3 = np.log(p3 / (1.0 - p3))
                    dot = wts[wset] * t1 + wts[wset + 1] * t2 + wts[wset + 2] * t3 + wts[wset + 3]
                    pm = 1.0 / (1.0 + np.exp(-dot))
                    pi = min(32767, max(1, int(pm * 32768.0 + 0.5)))
                    bound = (rng >> PROB_BITS) * pi
                    if nonzero == 0:
                        rng = bound
                    else:
                        low += bound
                        rng -= bound
                    err = (1.0 - nonzero) - pm
                    lr = wts[WSETS * 4]
                    wts[wset] += lr * err * t1
                    wts[wset + 1] += lr * err * t2
                    wts[wset + 2] += lr * err * t3
                    wts[wset + 3] += lr * err * wts[WSETS * 4 + 1]
                    m = models[_u(coded)]
                    models[_u(coded)] = _adapted(m >> 8, m & 0xFF, nonzero)
                    m = models[_u(c2)]
                    models[_u(c2)] = _adapted(m >> 8, m & 0xFF, nonzero)
                    m = models[_u(c3)]
                    models[_u(c3)] = _adapted(m >> 8, m & 0xFF, nonzero)
"""

_SIGN = """                at_ctx = sign_base + (sw + 1) * 3 + sn + 1
                mode = wts[WSETS * 4 + 3]
                if not approx and mode > 0:
                    sp = _sign_of(flat[_u(pr + (j >> 1))]) if j < lp else np.int64(0)
                    sa = _sign_of(flat[_u(s1 + j)]) if j < l1 else np.int64(0)
                    if mode == 2:
                        sa = _sign_of(flat[_u(at - cols - 1)]) if i > r0 and j > c0 else 0
                        sp = _sign_of(flat[_u(at - cols + 1)]) if i > r0 and j + 1 < c1 else 0
                    if mode == 3:
                        sa = _sign_of(flat[_u(y0 + j)]) if j < ly else np.int64(0)
                    at_ctx = SIGN_X + (
                        ((planes_orient * 3 + sw + 1) * 3 + sn + 1) * 3 + sp + 1
                    ) * 3 + sa + 1
"""

_BLOCK_START = """            _fresh_models(models[:CONTEXTS], oriented, blocks[b])
            models[CONTEXTS:] = 16384 << 8
            for k in range(WSETS):
                wts[4 * k] = cfg[1]
                wts[4 * k + 1] = cfg[2]
                wts[4 * k + 2] = cfg[3]
                wts[4 * k + 3] = 0.0
            wts[WSETS * 4] = cfg[0]
            wts[WSETS * 4 + 1] = cfg[4]
            wts[WSETS * 4 + 2] = cfg[5]
            wts[WSETS * 4 + 3] = cfg[6]
            q = pidx[b]
            if cfg[7] > 0 and q >= 0:
                for c in range(CONTEXTS):
                    m = saved[q, c]
                    if (m & 0xFF) - (models[c] & 0xFF) >= cfg[7]:
                        models[c] = ((m >> 8) << 8) | min(m & 0xFF, np.int64(cfg[8]))
            end = _encode_block(
                flat, planes, parents, oriented, blocks[b], out, pos, models, wts, scratch, flags
            )
            saved[b, :] = models[:CONTEXTS]"""


def variant_source() -> str:
    """Version 8's encoder with the probes' switches (see the module text)."""
    src = Path(kernels.__file__).read_text().replace("cache=True", "cache=False")
    src = _swap(src, "from ._blockpriors import", "from wavecore._blockpriors import")
    deco = '@njit(nogil=True, cache=False, inline="always")\n'
    plain = "@njit(nogil=True, cache=False)\n"
    src = coder_gain._cut(src, deco + "def _decode_rows(", plain + "def _encode_block(")
    src = coder_gain._cut(src, plain + "def _decode_block(", plain + "def _block_is_empty(")
    src = coder_gain._cut(src, plain + "def decode_span(", plain + "def write_varints(")
    # numba would not inline the rows' loop with the extra arguments: compiled as a call.
    src = _swap(src, deco + "def _encode_rows(", plain + "def _encode_rows(")
    src = _swap(src, "    models,\n    scratch,\n", "    models,\n    wts,\n    scratch,\n")
    call = "                models,\n                scratch,\n"
    src = _swap(src, call, call.replace("scratch", "wts,\n                scratch"), 3)
    src = _swap(
        src,
        "    along,\n    directional,\n):\n",
        "    along,\n    directional,\n    planes_orient,\n):\n",
    )
    src = _swap(
        src,
        "        kind = 0 if approx else 1\n",
        "        kind = 0 if approx else 1\n        orient_here = min(planes[p, P_ORIENT], 2)\n",
    )
    for tail in ("0,\n                False,\n", "along,\n                True,\n"):
        src = src.replace(
            tail + "            )", tail + "                orient_here,\n            )"
        )
    src = _swap(src, "pos, models, scratch, flags):", "pos, models, wts, scratch, flags):")
    src = _swap(
        src,
        "def encode_span(flat, planes, parents, oriented, blocks, lo, hi):",
        "def encode_span(flat, planes, parents, oriented, blocks, lo, hi, cfg, pidx):",
    )
    src = _swap(
        src,
        "    models = np.empty(CONTEXTS, dtype=np.int32)\n    scratch",
        "    models = np.empty(CONTEXTS + EXTRA, dtype=np.int32)\n"
        "    wts = np.zeros(WSETS * 4 + 8, dtype=np.float64)\n"
        "    saved = np.zeros((hi, CONTEXTS), dtype=np.int32)\n    scratch",
    )
    src = _swap(
        src,
        "            _fresh_models(models, oriented, blocks[b])\n            end = _encode_block(\n"
        "                flat, planes, parents, oriented, blocks[b], out, pos, models, scratch, "
        "flags\n            )",
        _BLOCK_START,
    )
    flag = (
        "                low, rng, models[_u(coded)] = "
        "_code_bit(low, rng, models[_u(coded)], nonzero)\n"
    )
    src = _swap(src, flag, _MIXED_FLAG)
    src = _swap(src, "                at_ctx = sign_base + (sw + 1) * 3 + sn + 1\n", _SIGN)
    return _swap(
        src,
        "CONTEXTS = ZERO_DIR_BASE + ZERO_DIR_SIZE\n",
        "CONTEXTS = ZERO_DIR_BASE + ZERO_DIR_SIZE\nEXTRA_BASE = CONTEXTS\nC2_SIZE = 3 * 4 * 4 * 5\n"
        "SIGN_X = EXTRA_BASE + C2_SIZE + 3 * 256\nEXTRA = C2_SIZE + 3 * 256 + 3 * 81\n"
        "WSETS = 3 * 14\n",
    )


def _load_variant() -> Any:
    coder_gain.WORK.mkdir(parents=True, exist_ok=True)
    path = coder_gain.WORK / "grey_gap_kernels.py"
    path.write_text(variant_source())
    spec = importlib.util.spec_from_file_location("grey_gap_kernels", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def parent_index(planes: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """Each block's parent block (version 6's), or -1 (the approximation and chunk 1)."""
    starts = sorted({int(x) for x in blocks[:, kernels.B_PLANE_LO]})
    side = blockcoder.BLOCK_SIZE
    where = {
        (int(r[kernels.B_PLANE_LO]), int(r[kernels.B_ROW0]), int(r[kernels.B_COL0])): b
        for b, r in enumerate(blocks)
    }
    out = np.full(len(blocks), -1, dtype=np.int64)
    for b, row in enumerate(blocks):
        k = starts.index(int(row[kernels.B_PLANE_LO]))
        if k < 2:
            continue
        r = (int(row[kernels.B_ROW0]) // 2) // side * side
        c = (int(row[kernels.B_COL0]) // 2) // side * side
        out[b] = where.get((starts[k - 1], r, c), -1)
    return out


def coder(configs: list[list[float]]) -> None:
    captured = np.load(coder_gain.WORK / "capture_cdf97.npz")
    variant = _load_variant()  # compiled at its first call (some 90 s)
    for config in configs:
        cfg = np.array(config, dtype=np.float64)
        out = {}
        for name in NAMES:
            today, new, quality = [], [], []
            for k in range(len(peers.EXACT_RATES)):
                key = f"{name}_{k}"
                flat, planes, parents, blocks = (
                    captured[key + s] for s in ("_flat", "_planes", "_parents", "_blocks")
                )
                blocks = coder_gain.with_levels(planes, blocks)
                span = (flat, planes, parents, 2, blocks, 0, len(blocks))
                lengths = kernels.encode_span(*span)[1]
                eight = int(lengths.sum()) + coder_gain.table_bytes(flat, planes, blocks, lengths)
                lengths = variant.encode_span(*span, cfg, parent_index(planes, blocks))[1]
                other = int(lengths.sum()) + coder_gain.table_bytes(flat, planes, blocks, lengths)
                whole = int(captured[key + "_bytes"])
                today.append(whole)
                new.append(whole - eight + other)
                quality.append(float(captured[key + "_psnr"]))
            out[name] = bd_rate(today, quality, new, quality)
        _report(str(config), out)


# ---------------------------------------------------------------------------------------------
# lossless-coder, steps, levels, wavelets


def _report(label: str, out: dict[str, float]) -> None:
    grey = [out[n] for n in GREY if n in out]
    print(
        f"{label:34s} "
        + " ".join(f"{n} {v:+.2f}" for n, v in out.items())
        + (f" | grey {np.mean(grey):+.2f} %" if grey else ""),
        flush=True,
    )


def lossless_coder() -> None:
    seen: dict[str, Any] = {}
    original = codec_chunks.decode_blocks

    def recording(*args: Any, **kwargs: Any) -> Any:
        seen["levels"] = original(*args, **kwargs)
        return seen["levels"]

    codec_chunks.decode_blocks = recording  # type: ignore[assignment]
    try:
        for name in NAMES:
            image = getattr(data, name)()
            ratios = []
            for rate in (0.25, 0.5, 1.0, 2.0):
                wavecore.decode(wavecore.encode_image(image, wavelet="cdf97", bpp=rate))
                q = seen.pop("levels")
                levels = [q[0][0], *(tuple(x) for x in q[1:])]
                eight = sum(map(len, entropy.encode_levels(levels, version=8)[0]))
                five = sum(map(len, losslesscoder.encode_lossless_levels(levels)[0]))
                ratios.append(f"{rate} bpp {five / eight:.3f}")
            print(f"{name:10s} version 5 / version 8 bytes: " + ", ".join(ratios), flush=True)
    finally:
        codec_chunks.decode_blocks = original  # type: ignore[assignment]


def _curve(image: np.ndarray, **options: Any) -> tuple[list[int], list[float]]:
    rates, quality = [], []
    for rate in peers.EXACT_RATES:
        bundle = wavecore.encode_image(image, wavelet="cdf97", bpp=rate, **options)
        rates.append(len(bundle))
        quality.append(peers.psnr(image, wavecore.decode(bundle)))
    return rates, quality


def steps(trials: list[str]) -> None:
    original = quantize.band_weights
    scale: dict[str, Any] = {}

    def scaled(coeffs: Any, **kwargs: Any) -> list[list[float]]:
        weights = original(coeffs, **kwargs)
        finest = len(weights) - 1
        out = [[w * scale.get("approx", 1.0) for w in weights[0]]]
        for index, level in enumerate(weights[1:], start=1):
            factor = scale.get(f"level{finest - index}", 1.0)
            level = [w * factor for w in level]
            level[2] *= scale.get("diag", 1.0)
            out.append([float(f"{w:.4g}") for w in level])
        return out

    quantize.band_weights = scaled  # type: ignore[assignment]
    ratecontrol.band_weights = scaled  # type: ignore[attr-defined]
    try:
        base = {n: _curve(getattr(data, n)()) for n in GREY}
        for trial in trials:
            scale.clear()
            scale.update(ast.literal_eval("{" + trial + "}"))
            out = {n: bd_rate(*base[n], *_curve(getattr(data, n)())) for n in GREY}
            _report(trial, out)
    finally:
        quantize.band_weights = original  # type: ignore[assignment]
        ratecontrol.band_weights = original  # type: ignore[attr-defined]


def levels() -> None:
    """Each depth against the default 5, and the best depth at each rate (the per-rate
    envelope of 3-6 levels, PSNR at the exact rates) against 5."""
    for name in NAMES:
        image = getattr(data, name)()
        curves = {depth: _curve(image, level=depth) for depth in (3, 4, 5, 6)}
        out = {f"L{d}": bd_rate(*curves[5], *curves[d]) for d in (3, 4, 6)}
        at_rates = {
            depth: [
                p
                for p, _ in peers.at_rates(
                    [
                        (8 * b / image.shape[0] / image.shape[1], q, 0.0)
                        for b, q in zip(*c, strict=True)
                    ]
                )
            ]
            for depth, c in curves.items()
        }
        with warnings.catch_warnings():  # the top rate, past every curve's end, is NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            best = np.nanmax(np.array(list(at_rates.values())), axis=0)
        out["best per rate"] = peers.bd_rate(peers.EXACT_RATES, at_rates[5], list(best))
        print(f"{name:10s} " + " ".join(f"{k} {v:+.2f} %" for k, v in out.items()), flush=True)


def blocks(sides: list[int]) -> None:
    """``encode_image(..., bpp=r)`` with the context coder's block side (where its models
    restart; readers take 16-256) set to each of ``sides``, against the default 128."""
    import wavecore.rdoq as rdoq

    entropies = ratecontrol._block_entropies
    saved = (entropy.BLOCK_SIZE, ratecontrol.DEFAULT_BLOCK, rdoq.BLOCK, entropies.__defaults__)
    try:
        base = {n: _curve(getattr(data, n)()) for n in NAMES}
        for side in sides:
            entropy.BLOCK_SIZE = ratecontrol.DEFAULT_BLOCK = rdoq.BLOCK = side  # type: ignore[misc]
            entropies.__defaults__ = (side,)
            out = {n: bd_rate(*base[n], *_curve(getattr(data, n)())) for n in NAMES}
            _report(f"block {side}", out)
    finally:
        (
            entropy.BLOCK_SIZE,  # type: ignore[misc]
            ratecontrol.DEFAULT_BLOCK,
            rdoq.BLOCK,
            entropies.__defaults__,
        ) = saved


# ---------------------------------------------------------------------------------------------
# dq: dependent (trellis-coded) quantization as VVC has it, against scalar quantization, both
# decided by the same trellis and rate model, coded by version 8 (which does not see the state)

#: VVC's four states: states 0 and 1 use Q0 (even multiples of the step), 2 and 3 use Q1 (odd
#: multiples, and zero); the parity of each index moves the state.
_DQ_NEXT = np.array([[0, 2], [2, 0], [1, 3], [3, 1]], dtype=np.int64)


def _dq_value(k: int, quantizer: int) -> float:
    if quantizer == 0 or k == 0:
        return 2.0 * k if quantizer == 0 else 0.0
    return 2.0 * k - (1.0 if k > 0 else -1.0)


def _trellis_kernel() -> Callable[..., Any]:
    from numba import njit

    @njit(cache=False)
    def trellis(v, r0, r1, lam, dependent):  # type: ignore[no-untyped-def]
        """Indices minimising sum (v - value)^2 + lam * bits along the band (raster order).
        ``dependent``: VVC's 4-state machine (values in units of the step); else one scalar
        quantizer of the same step.  bits: r0 for a zero, r1 + 1 + 2 log2|k| otherwise."""
        n = v.size
        states = 4 if dependent else 1
        big = 1e300
        cost = np.full(states, big)
        cost[0] = 0.0
        back_state = np.zeros((n, states), dtype=np.int8)
        back_k = np.zeros((n, states), dtype=np.int64)
        for i in range(n):
            x = v[i]
            a = abs(x)
            sg = 1 if x >= 0 else -1
            new = np.full(states, big)
            for s in range(states):
                if cost[s] >= big:
                    continue
                q = 0 if (not dependent or s < 2) else 1
                for c in range(3):
                    if dependent and q == 0:
                        fl = int(a / 2.0)
                        k = 0 if c == 0 else sg * (fl + c - 1)
                        value = 2.0 * k
                    elif dependent:
                        m = max(1, int((a + 1.0) / 2.0))
                        k = 0 if c == 0 else sg * (m + c - 1)
                        value = 0.0 if k == 0 else 2.0 * k - sg
                    else:
                        fl = int(a)
                        k = 0 if c == 0 else sg * (fl + c - 1)
                        value = float(k)
                    if c > 0 and k == 0:
                        continue
                    bits = r0 if k == 0 else r1 + 1.0 + 2.0 * np.log2(abs(k))
                    j = cost[s] + (x - value) ** 2 + lam * bits
                    t = _DQ_NEXT[s, abs(k) & 1] if dependent else 0
                    if j < new[t]:
                        new[t] = j
                        back_state[i, t] = s
                        back_k[i, t] = k
            cost = new
        out = np.zeros(n, dtype=np.int64)
        s = int(np.argmin(cost))
        for i in range(n - 1, -1, -1):
            out[i] = back_k[i, s]
            s = back_state[i, s]
        return out

    return trellis  # type: ignore[no-any-return]


def _dq_values(k: np.ndarray, dependent: bool) -> tuple[np.ndarray, np.ndarray]:
    """The decoder's values (units of the step) of a band's indices in raster order, and the
    quantizer (0 or 1) each was read with."""
    if not dependent:
        return k.astype(float), np.zeros(k.size, dtype=np.int64)
    out = np.empty(k.size)
    quantizers = np.empty(k.size, dtype=np.int64)
    state = 0
    for i, index in enumerate(k.tolist()):
        quantizers[i] = 0 if state < 2 else 1
        out[i] = _dq_value(index, int(quantizers[i]))
        state = int(_DQ_NEXT[state, abs(index) & 1])
    return out, quantizers


def _entropy_bits(k: np.ndarray, classes: np.ndarray) -> float:
    """Zeroth-order entropy of the magnitudes (capped at 15, longer ones by an Exp-Golomb
    tail) under each class, plus a bit per sign: what an ideal static model per band and
    class would spend."""
    magnitude = np.abs(k)
    capped = np.minimum(magnitude, 15)
    bits = float(np.count_nonzero(magnitude)) + float(
        np.sum(2 * np.floor(np.log2(np.maximum(magnitude - 14, 1))))
    )
    for c in np.unique(classes):
        counts = np.bincount(capped[classes == c], minlength=16).astype(float)
        p = counts[counts > 0] / counts.sum()
        bits += float(-(counts[counts > 0] * np.log2(p)).sum())
    return bits


def dq(multipliers: list[float]) -> None:
    """BD-rate of dependent quantization against scalar quantization on the grey tuning
    pictures (cut to sides of multiples of 32 for 5 cdf97 levels), each at its best trellis
    multiplier of ``multipliers`` (lambda in units of the step squared per bit)."""
    trellis = _trellis_kernel()
    for name in GREY:
        image = getattr(data, name)()
        image = image[: image.shape[0] // 32 * 32, : image.shape[1] // 32 * 32]
        coeffs = wavecore.wavedec2(image.astype(float), "cdf97", level=5)
        weights = quantize.band_weights(coeffs, wavelet="cdf97", boundary="open")
        curves: dict[str, tuple[list[float], list[float]]] = {}
        for dependent in (False, True):
            for lam in multipliers:
                rates, quality, ideal = [], [], []
                for step in np.geomspace(0.6, 40.0, 14):
                    q_levels: list[Any] = []
                    r_levels: list[Any] = []
                    bits = 0.0
                    for li, level in enumerate(coeffs):
                        bands = [level] if li == 0 else list(level)
                        qs, rs = [], []
                        for band, weight in zip(bands, weights[li], strict=True):
                            # Both place their values on multiples of this unit (dependent
                            # quantization's two quantizers take every other one each).
                            unit = step * weight
                            v = (band / unit).ravel()
                            if li == 0:
                                k = np.rint(v).astype(np.int64)
                                values = k.astype(float)
                            else:
                                p0 = min(max(float(np.mean(np.abs(v) < 0.6)), 1e-3), 1 - 1e-3)
                                k = trellis(v, -np.log2(p0), -np.log2(1 - p0), lam, dependent)
                                values, classes = _dq_values(k, dependent)
                                bits += _entropy_bits(k, classes)
                            qs.append(k.reshape(band.shape).astype(np.int32))
                            rs.append((values * unit).reshape(band.shape))
                        q_levels.append(qs[0] if li == 0 else tuple(qs))
                        r_levels.append(rs[0] if li == 0 else tuple(rs))
                    size = sum(map(len, entropy.encode_levels(q_levels, version=8)[0]))
                    back = np.clip(np.rint(wavecore.waverec2(r_levels, "cdf97")), 0, 255)
                    bpp = 8 * size / image.size
                    if 0.15 <= bpp <= 2.6:
                        rates.append(size)
                        ideal.append(bits / 8)
                        quality.append(peers.psnr(image, back.astype(np.uint8)))
                label = f"{'dq' if dependent else 'scalar'} {lam}"
                curves[label] = (rates, quality)
                curves[label + " ideal"] = (ideal, quality)
        for kind in ("", " ideal"):
            base = curves[f"scalar {multipliers[0]}{kind}"]
            out = {
                key: bd_rate(*base, *curve)
                for key, curve in curves.items()
                if key.endswith(" ideal") == bool(kind)
            }
            print(
                f"{name:8s}{kind or ' coded'} " + " ".join(f"{k} {v:+.2f}" for k, v in out.items()),
                flush=True,
            )


def _pywt_norms(pywt: Any, wavelet: str, shape: tuple[int, ...]) -> list[list[float]]:
    zero = pywt.wavedec2(np.zeros(shape), wavelet, mode="periodization", level=5)
    out = []
    for index, entry in enumerate(zero):
        bands = [entry] if index == 0 else list(entry)
        row = []
        for band in bands:
            band[band.shape[0] // 2, band.shape[1] // 2] = 1.0
            synthesis = pywt.waverec2(zero, wavelet, mode="periodization")
            row.append(float(np.linalg.norm(synthesis)))
            band[band.shape[0] // 2, band.shape[1] // 2] = 0.0
        out.append(row)
    return out


def _plain_point(
    image: np.ndarray,
    coeffs: list[Any],
    step: float,
    norms: list[list[float]],
    synthesize: Callable[[list[Any]], np.ndarray],
    extra_bytes: float = 0.0,
) -> tuple[float, float]:
    """Bytes and PSNR of ``wavedec2``-layout coefficients through the library's dead-zone
    quantizer (weights from ``norms``) and version 8's coder, plus ``extra_bytes``."""
    indices: list[Any] = []
    values: list[Any] = []
    for index, entry in enumerate(coeffs):
        bands = [entry] if index == 0 else list(entry)
        rounding = quantize.APPROX_ROUNDING if index == 0 else quantize.DEFAULT_ROUNDING
        offset = 0.0 if index == 0 else 0.12  # towards the bin's centroid, as decoders do
        ints, backs = [], []
        for band, norm in zip(bands, norms[index], strict=True):
            band_step = step / norm
            k = np.sign(band) * np.floor(np.abs(band) / band_step + rounding)
            ints.append(k.astype(np.int32))
            backs.append(np.sign(k) * (np.abs(k) + offset * (k != 0)) * band_step)
        indices.append(ints[0] if index == 0 else tuple(ints))
        values.append(backs[0] if index == 0 else tuple(backs))
    size = sum(map(len, entropy.encode_levels(indices, version=8)[0])) + extra_bytes
    back = np.clip(np.rint(synthesize(values)), 0, 255)
    return size, peers.psnr(image.astype(np.uint8), back.astype(np.uint8))


def _pywt_point(
    pywt: Any, image: np.ndarray, wavelet: str, step: float, norms: list[list[float]]
) -> tuple[float, float]:
    coeffs = pywt.wavedec2(image, wavelet, mode="periodization", level=5)
    return _plain_point(
        image, coeffs, step, norms, lambda c: pywt.waverec2(c, wavelet, mode="periodization")
    )


def wavelets(names: list[str]) -> None:
    import pywt

    out: dict[str, list[float]] = {w: [] for w in names}
    for picture in GREY:
        image = getattr(data, picture)().astype(np.float64)
        image = image[: image.shape[0] // 32 * 32, : image.shape[1] // 32 * 32]
        curves = {}
        for wavelet in names:
            norms = _pywt_norms(pywt, wavelet, image.shape)
            points = [_pywt_point(pywt, image, wavelet, s, norms) for s in np.geomspace(3, 40, 8)]
            curves[wavelet] = ([p[0] for p in points], [p[1] for p in points])
        for wavelet in names:
            out[wavelet].append(bd_rate(*curves[names[0]], *curves[wavelet]))
        print(f"{picture:10s} " + " ".join(f"{w} {out[w][-1]:+.2f} %" for w in names), flush=True)
    print("grey mean  " + " ".join(f"{w} {np.mean(out[w]):+.2f} %" for w in names))


# ---------------------------------------------------------------------------------------------
# directional: direction-adaptive lifting (ADL: Ding, Wu, Xu and Li, 2007) of CDF 9/7, against
# the same lifting with no directions

_CDF97_LIFTS = (-1.586134342059924, -0.052980118572961, 0.882911075530934, 0.443506852043971)
_CDF97_SCALE = 1.230174104914001
#: Column offsets per row of the directions tried: 0 is the separable transform.
_ADL_SHIFTS = (0.0, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0, 2.0, -2.0)


def _shifted_columns(plane: np.ndarray, shift: float) -> np.ndarray:
    """``plane[:, j + shift]``, mirrored at the ends (cubic splines between samples)."""
    from scipy import ndimage

    if shift == 0:
        return plane
    if float(shift).is_integer():
        width = plane.shape[1]
        j = np.abs(np.arange(width) + int(shift))
        return plane[:, np.where(j >= width, 2 * (width - 1) - j, j)]
    return ndimage.shift(plane, (0, -shift), order=3, mode="mirror")


def _along(plane: np.ndarray, shifts: np.ndarray, sign: int) -> np.ndarray:
    out = np.empty_like(plane)
    for shift in np.unique(shifts):
        where = shifts == shift
        out[where] = _shifted_columns(plane, sign * shift)[where]
    return out


def _adl_lift(x: np.ndarray, shifts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One level along axis 0: each lifting step reads its neighbours above (at ``j + t``)
    and below (at ``j - t``), ``t`` the direction of the row pair; any ``t`` inverts."""
    even, odd = x[0::2].copy(), x[1::2].copy()
    for index, weight in enumerate(_CDF97_LIFTS):
        if index % 2 == 0:
            odd += weight * (_along(even, shifts, 1) + _along(np.roll(even, -1, 0), shifts, -1))
        else:
            even += weight * (_along(np.roll(odd, 1, 0), shifts, 1) + _along(odd, shifts, -1))
    return even / _CDF97_SCALE, odd * _CDF97_SCALE


def _adl_unlift(low: np.ndarray, high: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    even, odd = low * _CDF97_SCALE, high / _CDF97_SCALE
    for index in range(3, -1, -1):
        weight = _CDF97_LIFTS[index]
        if index % 2 == 0:
            odd -= weight * (_along(even, shifts, 1) + _along(np.roll(even, -1, 0), shifts, -1))
        else:
            even -= weight * (_along(np.roll(odd, 1, 0), shifts, 1) + _along(odd, shifts, -1))
    x = np.empty((2 * even.shape[0], even.shape[1]))
    x[0::2], x[1::2] = even, odd
    return x


def _adl_directions(x: np.ndarray, block: int, penalty: float) -> tuple[np.ndarray, np.ndarray]:
    """Per block of ``block`` columns and ``block // 2`` row pairs, the direction whose whole
    lifting leaves the least sum of ``|high|`` (times ``1 + penalty`` off the separable one):
    the map per row pair, and the indices per block."""
    height, width = x.shape[0] // 2, x.shape[1]
    tall, wide = max(1, block // 2), block
    rows, cols = -(-height // tall), -(-width // wide)
    costs = []
    for shift in _ADL_SHIFTS:
        high = np.abs(_adl_lift(x, np.full((height, width), shift))[1])
        padded = np.zeros((rows * tall, cols * wide))
        padded[:height, :width] = high
        cost = padded.reshape(rows, tall, cols, wide).sum(axis=(1, 3))
        costs.append(cost * (1.0 + (penalty if shift else 0.0)))
    picks = np.argmin(np.stack(costs), axis=0)
    shifts = np.asarray(_ADL_SHIFTS)[picks]
    return np.repeat(np.repeat(shifts, tall, 0), wide, 1)[:height, :width], picks


def _adl_analysis(
    image: np.ndarray, directional_levels: int, block: int, penalty: float
) -> tuple[list[Any], list[tuple[np.ndarray, np.ndarray]], list[np.ndarray]]:
    """Five levels in ``wavedec2`` layout; the finest ``directional_levels`` choose directions
    for the vertical step and for the horizontal step of its low half.  Also the maps and the
    chosen indices."""
    approx = image
    details, maps, picks = [], [], []
    for level in range(5):
        if level < directional_levels:
            vertical, vertical_picks = _adl_directions(approx, block, penalty)
            picks.append(vertical_picks)
        else:
            vertical = np.zeros((approx.shape[0] // 2, approx.shape[1]))
        low, high = _adl_lift(approx, vertical)
        if level < directional_levels:
            horizontal, horizontal_picks = _adl_directions(low.T, block, penalty)
            picks.append(horizontal_picks)
        else:
            horizontal = np.zeros((low.shape[1] // 2, low.shape[0]))
        low_low, low_high = _adl_lift(low.T, horizontal)
        high_low, high_high = _adl_lift(high.T, np.zeros_like(horizontal))
        details.append((high_low.T, low_high.T, high_high.T))  # pywt's (cH, cV, cD)
        maps.append((vertical, horizontal))
        approx = low_low.T
    return [approx, *details[::-1]], maps[::-1], picks


def _adl_synthesis(coeffs: list[Any], maps: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    approx = coeffs[0]
    for (horizontal_detail, vertical_detail, diagonal), (vertical, horizontal) in zip(
        coeffs[1:], maps, strict=True
    ):
        low = _adl_unlift(approx.T, vertical_detail.T, horizontal).T
        high = _adl_unlift(horizontal_detail.T, diagonal.T, np.zeros_like(horizontal)).T
        approx = _adl_unlift(low, high, vertical)
    return approx


def _adl_side_bytes(picks: list[np.ndarray]) -> float:
    """The direction maps at their zeroth-order entropy, per map (an ideal static model)."""
    bits = 0.0
    for chosen in picks:
        counts = np.bincount(chosen.ravel(), minlength=len(_ADL_SHIFTS))
        used = counts[counts > 0]
        bits += -float(np.sum(used * np.log2(used / used.sum())))
    return bits / 8


def _adl_norms(shape: tuple[int, ...]) -> list[list[float]]:
    """Each band's synthesis norm, for the separable lifting (directions keep it near)."""
    zero, flat_maps, _ = _adl_analysis(np.zeros(shape), 0, 16, 0.0)
    out = []
    for index, entry in enumerate(zero):
        row = []
        for band in [entry] if index == 0 else list(entry):
            band[band.shape[0] // 2, band.shape[1] // 2] = 1.0
            row.append(float(np.linalg.norm(_adl_synthesis(zero, flat_maps))))
            band[band.shape[0] // 2, band.shape[1] // 2] = 0.0
        out.append(row)
    return out


def _adl_curve(
    image: np.ndarray, coeffs: list[Any], maps: Any, norms: list[list[float]], side: float
) -> tuple[list[float], list[float]]:
    points = [
        _plain_point(image, coeffs, s, norms, lambda c: _adl_synthesis(c, maps), side)
        for s in np.geomspace(3, 40, 8)
    ]
    return [p[0] for p in points], [p[1] for p in points]


def directional(configs: list[tuple[int, int, float]]) -> None:
    """Each ``(levels, block, penalty)`` against the same lifting with no directions."""
    out: dict[tuple[int, int, float], list[float]] = {c: [] for c in configs}
    for picture in GREY:
        image = getattr(data, picture)().astype(np.float64)
        image = image[: image.shape[0] // 32 * 32, : image.shape[1] // 32 * 32]
        norms = _adl_norms(image.shape)
        base = _adl_curve(image, *_adl_analysis(image, 0, 16, 0.0)[:2], norms, 0.0)
        line = []
        for config in configs:
            coeffs, maps, picks = _adl_analysis(image, *config)
            assert np.allclose(_adl_synthesis(coeffs, maps), image)  # any direction inverts
            side = _adl_side_bytes(picks)
            rates, psnrs = _adl_curve(image, coeffs, maps, norms, side)
            out[config].append(bd_rate(*base, rates, psnrs))
            free = bd_rate(*base, [r - side for r in rates], psnrs)
            line.append(f"{config} {out[config][-1]:+.2f} % ({side:.0f} B of maps; {free:+.2f} %)")
        print(f"{picture:8s} " + " | ".join(line), flush=True)
    print("grey mean " + " | ".join(f"{c} {np.mean(v):+.2f} %" for c, v in out.items()))


# ---------------------------------------------------------------------------------------------
# alignment: the gap per cut of each picture, against how well the cut lines up with 8 × 8 blocks


def _lattice_score(image: np.ndarray) -> float:
    """The median over 14 low-frequency AC positions of the 8 × 8 DCT of ``image``'s aligned
    blocks of the largest ``mean cos(2π x / q)`` over steps q = 3 … 40, the mean over the
    coefficients x at least q / 2 from zero (and at least 100 of them): near 1 if they lie on
    a quantizer's lattice (a decoded JPEG), near 0 if their density is smooth."""
    from scipy.fft import dctn

    rows, cols = image.shape[0] // 8 * 8, image.shape[1] // 8 * 8
    blocks = image[:rows, :cols].astype(np.float64).reshape(rows // 8, 8, cols // 8, 8)
    dct = dctn(blocks.transpose(0, 2, 1, 3) - 128.0, axes=(2, 3), norm="ortho")
    scores = []
    for u in range(5):
        for v in range(5):
            if 0 < u + v <= 4:
                x = dct[:, :, u, v].ravel()
                best = 0.0
                for step in np.arange(3.0, 40.5, 0.25):
                    away = x[np.abs(x) >= step / 2]
                    if away.size >= 100:
                        best = max(best, float(np.cos(2 * np.pi * away / step).mean()))
                scores.append(best)
    return float(np.median(scores))


def _flat_pairs(image: np.ndarray) -> float:
    """The share of ``image``'s aligned 2 × 2 blocks whose four pixels are equal (1 for a
    picture enlarged by pixel replication, cut at an even offset)."""
    rows, cols = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
    blocks = image[:rows, :cols].reshape(rows // 2, 2, cols // 2, 2)
    return float((blocks == blocks[:, :1, :, :1]).all(axis=(1, 3)).mean())


def _against_avif(image: np.ndarray) -> str:
    """cdf97's BD-rate against AVIF speed 6 on ``image``, and the PSNR difference per rate."""
    theirs = [p for p, _ in peers.at_rates(peers.sweep(image, peers.lossy_peers(False)["AVIF s6"]))]
    points = []
    for rate in peers.EXACT_RATES:
        bundle = wavecore.encode_image(image, wavelet="cdf97", bpp=rate)
        back = wavecore.decode(bundle)
        points.append((8 * len(bundle) / image.size, peers.psnr(image, back), 0.0))
    ours = [p for p, _ in peers.at_rates(points)]
    differences = " ".join(f"{a - b:+.2f}" for a, b in zip(ours, theirs, strict=True))
    gap = peers.bd_rate(peers.EXACT_RATES, theirs, ours)
    return f"BD-rate {gap:+.2f} %, dB per rate {differences}"


def alignment(offsets: list[tuple[int, int]]) -> None:
    for picture in GREY:
        full = getattr(data, picture)()
        for dy, dx in offsets:
            cut = np.ascontiguousarray(
                full[dy : full.shape[0] - 8 + dy, dx : full.shape[1] - 8 + dx]
            )
            print(
                f"{picture:8s} offset {dy},{dx}: lattice {_lattice_score(cut):.2f}, "
                f"flat 2 × 2 {_flat_pairs(cut):.2f}, {_against_avif(cut)}",
                flush=True,
            )
    source = np.ascontiguousarray(data.moon()[::2, ::2])  # moon before its pixel replication
    print(f"moon's 256² source: {_against_avif(source)}")


def edges(picture: str, rate: float) -> None:
    """Squared error of cdf97 and of AVIF speed 6 (its largest file within ``rate``) on
    ``picture`` by distance to the nearest edge (Gaussian gradient magnitude, σ 1.5, above 8)."""
    from scipy import ndimage

    image = getattr(data, picture)()
    bundle = wavecore.encode_image(image, wavelet="cdf97", bpp=rate)
    ours = wavecore.decode(bundle).astype(np.float64)
    blob = b""
    for quality in range(2, 99):
        candidate = peers._pillow(image, "AVIF", quality=quality, speed=6, subsampling="4:0:0")
        if 8 * len(candidate) <= rate * image.size * 1.01:
            blob = candidate
    theirs = peers._decode(blob, image).astype(np.float64)
    print(
        f"{picture} cdf97 {8 * len(bundle) / image.size:.3f} bpp {peers.psnr(image, ours):.2f} dB, "
        f"AVIF {8 * len(blob) / image.size:.3f} bpp {peers.psnr(image, theirs):.2f} dB"
    )
    original = image.astype(np.float64)
    edge = ndimage.gaussian_gradient_magnitude(original, 1.5) > 8
    distance = ndimage.distance_transform_edt(~edge)
    for low, high in ((0, 1), (1, 2), (2, 3), (3, 5), (5, 8), (8, 12), (12, np.inf)):
        where = (distance >= low) & (distance < high)
        print(
            f"  distance {low}–{high}: {where.mean():.3f} of the pixels, squared error "
            f"cdf97 {((ours - original)[where] ** 2).mean():.2f}, "
            f"AVIF {((theirs - original)[where] ** 2).mean():.2f}"
        )


PROBES: dict[str, Callable[[argparse.Namespace], None]] = {
    "coder": lambda o: coder([ast.literal_eval(c) for c in o.configs]),
    "lossless-coder": lambda o: lossless_coder(),
    "steps": lambda o: steps(o.trials),
    "levels": lambda o: levels(),
    "wavelets": lambda o: wavelets(o.wavelets),
    "blocks": lambda o: blocks(o.sides),
    "dq": lambda o: dq(o.multipliers),
    "directional": lambda o: directional([ast.literal_eval(c) for c in o.adl]),
    "alignment": lambda o: alignment([ast.literal_eval(c) for c in o.offsets]),
    "edges": lambda o: edges(o.picture, o.rate),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("probe", choices=tuple(PROBES))
    parser.add_argument(
        "--configs",
        nargs="+",
        default=[
            "[0, 1, 0, 0, 0, 0, 0, 0, 0]",
            "[0.003, 1, 0, 0, 0.5, 1, 0, 0, 0]",
            "[0.003, 0.6, 0.2, 0.2, 0.5, 1, 0, 0, 0]",
            "[0.003, 0.5, 0.3, 0.3, 0.5, 1, 0, 0, 0]",
            "[0.02, 0.5, 0.3, 0.3, 0.5, 1, 0, 0, 0]",
            "[0, 1, 0, 0, 0, 0, 1, 0, 0]",
            "[0, 1, 0, 0, 0, 0, 2, 0, 0]",
            "[0, 1, 0, 0, 0, 0, 3, 0, 0]",
            "[0, 1, 0, 0, 0, 0, 0, 16, 8]",
            "[0, 1, 0, 0, 0, 0, 0, 8, 4]",
        ],
        help="coder: [lr, w1, w2, w3, bias, mix, signs, inherit, count] lists",
    )
    parser.add_argument(
        "--trials",
        nargs="+",
        default=[
            "'level0': 1.1",
            "'level0': 0.9",
            "'level1': 1.1",
            "'diag': 1.1",
            "'diag': 0.9",
            "'approx': 0.8",
        ],
        help="steps: band weight factors ('level0' the finest level, 'diag', 'approx')",
    )
    parser.add_argument("--wavelets", nargs="+", default=["bior4.4", "bior6.8", "bior2.2"])
    parser.add_argument("--sides", nargs="+", type=int, default=[256, 64])
    parser.add_argument("--multipliers", nargs="+", type=float, default=[0.05, 0.1, 0.2])
    parser.add_argument(
        "--adl",
        nargs="+",
        default=["(1, 32, 0.02)", "(1, 16, 0.02)", "(1, 8, 0.05)", "(2, 16, 0.1)", "(3, 16, 0.05)"],
        help="directional: (levels, block, penalty) tuples",
    )
    parser.add_argument(
        "--offsets",
        nargs="+",
        default=["(0, 0)", "(8, 8)", "(2, 2)", "(4, 4)", "(1, 1)", "(3, 3)"],
        help="alignment: (rows, columns) offsets of the cuts",
    )
    parser.add_argument("--picture", default="brick", help="edges: the picture")
    parser.add_argument("--rate", type=float, default=0.25, help="edges: the rate, bpp")
    options = parser.parse_args()
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, load {_load()}", flush=True)
    PROBES[options.probe](options)
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, load {_load()}", flush=True)


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


if __name__ == "__main__":
    sys.exit(main())
