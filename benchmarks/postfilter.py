"""Post-filter oracle: would a decoder-side restoration filter with signalled coefficients pay?

An experiment harness, not part of the library (no test runs it).  Run with
``.venv/bin/python benchmarks/postfilter.py [capture|measure|cost]`` (``capture`` first, a
few minutes: it keeps the decoded pictures in ``/tmp/postfilter_capture.npz``).

Built since 2026-12-07, in the form ``dia5c4`` over the uint8 output (the ``u8`` column), as
:mod:`wavecore.restoration`: the spec is docs/bundle-format.md's "The restoration record",
what it gains docs/benchmarks.md's paragraph after the fair-peers table.  ``capture`` turns
the library's filter off, so that this harness still measures a filter on plain bundles;
``built`` measures the library's filter (``encode_image(..., bpp=r)`` with it against
without, BD-rate, PSNR gain and bytes per rate, CPU time of encode and decode).

``capture`` codes the tuning pictures (camera, moon, coins, brick in grey, astronaut in
colour) with ``wavecore.encode_image(image, wavelet="cdf97", bpp=r)`` at the peers' 7 exact
rates (``peers.EXACT_RATES``, log-spaced over 0.25–2 bpp) and keeps each bundle, its size
and ``wavecore.decode`` of it (uint8).

``measure`` fits, per picture and rate, on the *decoded* picture a least-squares restoration
filter against the original (what an encoder, which has both, could do and signal), quantizes
its coefficients as a header would carry them, applies them, rounds and clips to uint8 as the
decoder's output would be, and reports the PSNR gain and the BD-rate
(``rate_distortion.bd_rate``, cubic in PSNR, VCEG-M33) of "decoded + filter at bundle bytes +
filter bytes" against "decoded at bundle bytes".  ``--source float`` (the default) filters
the decoder's samples before its final rounding (``_decode`` with a float64 plan: a filter
inside the decoder), ``--source u8`` the uint8 output of ``decode`` (a pass after it).  The
filters (all keep the DC gain 1: the centre tap is 1 minus the others and is not sent):

* ``sep7`` / ``sep5``: separable symmetric 7- (5-) tap filters, one horizontal and one
  vertical (AV1's loop-restoration Wiener form), fitted by alternating least squares;
  3 + 3 (2 + 2) coefficients; ``sep7uN``: a ``sep7`` per N × N restoration unit, each with
  its own on/off bit, as AV1 does;
* ``dia5`` / ``dia7``: non-separable point-symmetric 5×5 (7×7) diamonds (VVC's ALF shapes),
  6 (12) coefficients;
* ``dia5cN`` / ``dia7cN``: a diamond per class of N classes by local activity (the mean
  absolute Laplacian over 5×5 of the decoded picture, thresholds at its N-quantiles, sent as
  2 bytes each), as ALF classifies; ``dia5cNd``: × 3 direction classes (horizontal or
  vertical gradients twice the other's, or neither: ALF's test), 3N filters.  A class whose
  quantized filter would not lower its squared error is off (1 byte);
* ``best:a,b,...``: each of those kinds, the best PSNR kept;
* colour (astronaut), ``--colour ycc`` (the default): Y gets the kind, Cb and Cr one ``dia5``
  each (the filters then run in YCbCr and the result goes back to RGB); ``--colour rgb``:
  each of R, G, B gets the kind.

Coefficients are quantized to multiples of 1/128 as signed 7-bit integers (−64..63, as AV1's
Wiener taps are 1/128 with a few bits each; ``--scale``, ``--bits``), packed: bytes =
ceil(7 × count / 8) + 1 (a mode byte), + the class thresholds.  Where the filtered picture's
PSNR is not above the plain one's the encoder would turn the filter off: that point keeps its
PSNR and pays 1 byte.

``cost`` times a separable 7-tap filter (numpy, float32; and a numba kernel) and ``dia5c4``
(numba; checked equal to ``restore``'s on a crop) on a 2048² RGB picture (``codec_speed``'s)
against ``wavecore.decode`` of a 1 bpp cdf97 bundle of it (CPU-time medians, interleaved).

Measured on 2026-12-06 (cdf97 bundles of today's main, 887473c; BD-rate of decoded + filter,
bundle + filter bytes, against plain decoded; negative pays).  ``float`` is the filter inside
the decoder, on its samples before the final rounding; ``u8`` a pass over ``decode``'s output.
Colour: ``ycc`` filters Y with the kind and Cb, Cr with one ``dia5`` each; ``rgb`` each of
R, G, B with the kind.

=========  ======  =====  =====  =====  =========  =========  =========  =========  =========
kind       camera  moon   coins  brick  grey mean  grey, u8   astro ycc  astro rgb  rgb, u8
=========  ======  =====  =====  =====  =========  =========  =========  =========  =========
sep5       −0.01   −0.04  −0.14  −0.60  −0.20                 −0.40      −0.42
sep7       −0.03   −0.07  −0.16  −0.84  −0.28      −0.17      −0.23      −0.29      −0.40
sep7u256   −0.00   −0.04  −0.07  −0.79  −0.23                 −0.22
sep7u128   +0.07   −0.00  +0.15  −0.47  −0.06                 −0.11
sep7u64    +0.85   +0.84  +1.11  +0.49  +0.82                 +0.98
dia5       −0.00   −0.51  −0.13  −1.59  −0.56      −0.39      −0.44      −0.44      −0.43
dia7       −0.06   −0.57  −0.10  −1.90  −0.66                 −0.17      −0.25
dia5c2     −0.26   −1.16  −0.64  −2.78  −1.21      −0.89      −0.67      −0.80
dia5c4     −0.58   −1.74  −1.15  −3.02  **−1.62**  −1.07      −1.02      −1.33      −1.26
dia5c8     −0.79   −2.10  −1.28  −3.26  −1.86      −1.33      −1.37      −1.39      −1.39
dia7c4     −0.52   −1.88  −1.06  −3.91  −1.84      −1.27      −0.97      −1.11
dia5c4d    −0.69   −1.76  −1.32  −3.71  −1.87      −1.27      −1.35      −1.32
=========  ======  =====  =====  =====  =========  =========  =========  =========  =========

``sep7uN``: AV1's own arrangement, a ``sep7`` per N × N restoration unit, each with an on/off
bit (its coefficients sent raw, not predicted from the previous unit's as AV1 codes them).
Quantizing to 1/256 in 8 bits instead of 1/128 in 7 changes little (float, grey mean: sep7
−0.32, dia5 −0.61, dia5c4 −1.68, dia5c8 −1.91).

PSNR gain in dB at the 7 rates (0.25, 0.354, 0.5, 0.707, 1, 1.414, 2 bpp; float source) and
the filter's bytes (plain PSNR: camera 31.02..48.27, moon 42.57..53.88, coins 27.32..42.28,
brick 37.27..52.94, astronaut 29.50..41.26 dB):

* ``sep7``: camera +0.007 +0.006 +0.008 +0.010 0 0 0; moon +0.021 +0.008 +0.002 0 +0.007 0 0;
  coins +0.026 +0.026 +0.034 +0.018 +0.007 0 0; brick +0.186 +0.160 +0.100 +0.058 0 0 0;
  astronaut (ycc) +0.029 +0.034 +0.044 +0.005 0 +0.018 0 (7 bytes grey, 21 colour; 1 when off);
* ``dia5c4``: camera +0.044 +0.043 +0.041 +0.038 +0.052 +0.101 +0.104; moon +0.095 +0.080
  +0.082 +0.089 +0.114 +0.127 +0.152; coins +0.152 +0.154 +0.128 +0.094 +0.085 +0.074 +0.054;
  brick +0.336 +0.442 +0.388 +0.237 +0.123 +0.063 +0.077; astronaut (ycc) +0.082 +0.098 +0.104
  +0.085 +0.052 +0.036 +0.014 (26–31 bytes grey, 40–45 ycc, 78–93 rgb);
* ``dia5c8``: 43–63 bytes grey, 67–77 ycc, 174–189 rgb; ``dia5c4d``: 59–79 grey, 83–93 ycc.

Where the coefficients go matters at these sizes: the binary header has no free flag bit and
the JSON extension (``binheader.pack`` of camera's header with a ``restore`` key of 3
thresholds and 24 coefficients) takes 87 bytes where the packed field takes 31.  With 56 bytes
more whenever the filter is on (``--extra 56``): ``dia5c4`` grey mean −1.30 %, astronaut
(ycc) −0.74 %; ``dia5c8`` −1.53 % / −1.08 %.

Held-out pictures (not tuning ones: ``coder_gain.TRAINING``'s first six grey ones and chelsea;
``capture --images ...``), float source, BD-rate sep7 / dia5 / dia5c4 / dia5c8: text −1.02 /
−1.03 / −2.12 / −2.13; page −1.23 / −0.96 / −2.83 / −3.09; grass −0.46 / −0.95 / −1.68 /
−1.69; gravel −1.36 / −1.09 / −2.00 / −1.99; cell −10.90 / −4.98 / −0.53 / +0.78; clock −0.32
/ −0.27 / −0.27 / −0.21; grey mean −2.55 / −1.55 / −1.57 / −1.39 (without cell, whose 57–101
dB curve is an outlier: −0.88 / −0.86 / −1.78 / −1.82); chelsea (ycc) −0.26 / −0.36 / −0.75 /
−0.65.  ``dia5c4`` from the uint8 output: grey mean −1.35 (cell +0.05, clock +0.01).  On cell
a strong smoothing pays that the classified diamond's 7-bit taps miss; an encoder trying
``best:sep7,dia5,dia5c4`` and keeping the best (its mode byte says which): tuning grey mean
−1.62 (the same as ``dia5c4``: it always won), held-out −3.26 (cell −10.59, gravel −2.04,
the others as ``dia5c4``).

So a single Wiener filter, separable (AV1's form) or not, does not pay here (grey −0.2 to
−0.7 %, per-unit worse); a 5×5 diamond per class of local activity (ALF's form, 4 classes,
31 bytes) does: −1.6 % grey inside the decoder, −1.1 % as a pass over the uint8 output.

Cost (``cost``, 2048² RGB, 1 bpp cdf97 bundle of 513 kB, CPU-time medians of 7 interleaved
rounds, one thread for the filters; two runs): ``decode`` 0.202 / 0.215 s; a decode to float64
without the fused last level (what a filter before the rounding needs, unless it is fused into
that kernel) 1.39× / 1.58× that; ``sep7`` numpy float32 0.83× / 0.90×, numba 0.37× / 0.35×;
``dia5c4`` numba (activity, class, diamond, from uint8) 0.62× of ``decode``'s CPU time (a
first naive kernel with clamped indices: 1.42×).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numba
import numpy as np
from skimage import data

import wavecore
from wavecore.codec.decode import _decode, _open
from wavecore.colour import YCBCR_INVERSE_MATRIX, YCBCR_MATRIX

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers
from rate_distortion import bd_rate

CAPTURE = Path("/tmp/postfilter_capture.npz")
GREY = ("camera", "moon", "coins", "brick")
IMAGES = (*GREY, "astronaut")
RATES = peers.EXACT_RATES
#: Coefficient quantization: multiples of 1/SCALE as signed BITS-bit integers.
SCALE, BITS = 128, 7


def capture(images: tuple[str, ...] = IMAGES) -> None:
    # The bundles without the library's own restoration filter (wavecore.restoration, built
    # from this harness's ``dia5c4`` since 2026-12-07), so that the oracle measures as before.
    from wavecore.codec import ratecontrol

    ratecontrol._restorable = lambda plan: False  # type: ignore[assignment]
    arrays: dict[str, np.ndarray] = {}
    for name in images:
        image = getattr(data, name)()
        arrays[f"{name}/original"] = image
        sizes = []
        for i, rate in enumerate(RATES):
            bundle = wavecore.encode_image(image, wavelet="cdf97", bpp=rate)
            decoded = wavecore.decode(bundle)
            arrays[f"{name}/{i}"] = decoded
            arrays[f"{name}/bundle{i}"] = np.frombuffer(bundle, dtype=np.uint8)
            sizes.append(len(bundle))
            print(f"{name:9s} {rate:.3f} bpp: {len(bundle)} bytes", flush=True)
        arrays[f"{name}/sizes"] = np.asarray(sizes)
    np.savez_compressed(_capture_path(images), **arrays)


def _capture_path(images: tuple[str, ...]) -> Path:
    return CAPTURE if images == IMAGES else CAPTURE.with_name(f"postfilter_{'_'.join(images)}.npz")


# --- filters --------------------------------------------------------------------------------


def _shift(x: np.ndarray, di: int, dj: int) -> np.ndarray:
    """``x[i + di, j + dj]`` with the edges mirrored (half-sample symmetric)."""
    r = max(abs(di), abs(dj))
    padded = np.pad(x, r, mode="symmetric")
    h, w = x.shape
    return padded[r + di : r + di + h, r + dj : r + dj + w]


def _pair_terms(x: np.ndarray, offsets: list[tuple[int, int]]) -> list[np.ndarray]:
    """For each offset ``o``: ``x[p + o] + x[p - o] - 2 x[p]`` (a zero-DC symmetric pair)."""
    return [_shift(x, di, dj) + _shift(x, -di, -dj) - 2 * x for di, dj in offsets]


def _solve(terms: list[np.ndarray], target: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    a = np.stack([t.ravel() for t in terms], axis=1)
    b = target.ravel()
    if mask is not None:
        a, b = a[mask.ravel()], b[mask.ravel()]
    return np.linalg.lstsq(a, b, rcond=None)[0]


def quantize(coefs: np.ndarray) -> np.ndarray:
    low, high = -(2 ** (BITS - 1)), 2 ** (BITS - 1) - 1
    return np.clip(np.rint(coefs * SCALE), low, high) / SCALE


def coef_bytes(count: int) -> int:
    return math.ceil(BITS * count / 8) + 1


def _sep_apply1(x: np.ndarray, coefs: np.ndarray, axis: int) -> np.ndarray:
    out = x.copy()
    for k, c in enumerate(coefs, start=1):
        off = (k, 0) if axis == 0 else (0, k)
        out += c * (_shift(x, *off) + _shift(x, -off[0], -off[1]) - 2 * x)
    return out


def fit_separable(x: np.ndarray, y: np.ndarray, taps: int, rounds: int = 4) -> np.ndarray:
    """Horizontal then vertical half-filters (``taps // 2`` each), alternating least squares."""
    half = taps // 2
    h = np.zeros(half)
    v = np.zeros(half)
    for _ in range(rounds):
        # out = V(H x): fixing V, out = V x + sum_k h_k V(D_k x), linear in h
        vx = _sep_apply1(x, v, 0)
        terms = [_sep_apply1(t, v, 0) for t in _pair_terms(x, [(0, k) for k in range(1, half + 1)])]
        h = _solve(terms, y - vx, None)
        hx = _sep_apply1(x, h, 1)
        terms = _pair_terms(hx, [(k, 0) for k in range(1, half + 1)])
        v = _solve(terms, y - hx, None)
    return np.concatenate([h, v])


def apply_separable(x: np.ndarray, coefs: np.ndarray) -> np.ndarray:
    half = len(coefs) // 2
    return _sep_apply1(_sep_apply1(x, coefs[:half], 1), coefs[half:], 0)


def diamond(radius: int) -> list[tuple[int, int]]:
    """Half of a diamond's offsets (one of each ``±o`` pair, centre excluded)."""
    out = []
    for di in range(0, radius + 1):
        for dj in range(-radius, radius + 1):
            if abs(di) + abs(dj) <= radius and (di > 0 or dj > 0):
                out.append((di, dj))
    return out


def apply_pairs(x: np.ndarray, offsets: list[tuple[int, int]], coefs: np.ndarray) -> np.ndarray:
    out = x.copy()
    for t, c in zip(_pair_terms(x, offsets), coefs, strict=True):
        out += c * t
    return out


def activity(x: np.ndarray) -> np.ndarray:
    """Mean absolute Laplacian over 5×5 (what the decoder can compute from its own picture)."""
    lap = np.abs(4 * x - _shift(x, 1, 0) - _shift(x, -1, 0) - _shift(x, 0, 1) - _shift(x, 0, -1))
    return _box5(lap)


def _box5(x: np.ndarray) -> np.ndarray:
    out = np.zeros_like(x)
    for di in range(-2, 3):
        for dj in range(-2, 3):
            out += _shift(x, di, dj)
    return out / 25


def direction(x: np.ndarray) -> np.ndarray:
    """0: no dominant direction; 1: horizontal gradients dominate; 2: vertical ones (ALF's
    test, ratio 2, over 5×5)."""
    gh = _box5(np.abs(2 * x - _shift(x, 0, 1) - _shift(x, 0, -1)))
    gv = _box5(np.abs(2 * x - _shift(x, 1, 0) - _shift(x, -1, 0)))
    out = np.zeros(x.shape, dtype=np.int64)
    out[gh > 2 * gv] = 1
    out[gv > 2 * gh] = 2
    return out


def to_uint8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def restore(x: np.ndarray, y: np.ndarray, kind: str) -> tuple[np.ndarray, int]:
    """The filtered picture (float, before the decoder's rounding) and the filter's bytes, for
    one channel ``x`` (the decoded samples) against ``y`` (the original).

    ``kind``: ``sep5``, ``sep7``, ``dia5``, ``dia7``, or ``dia5cN`` / ``dia7cN`` (a diamond per
    class of ``N`` activity classes), ``dia5cNd`` (× 3 direction classes)."""
    if kind in ("sep7", "sep5"):
        coefs = quantize(fit_separable(x, y, int(kind[3])))
        return apply_separable(x, coefs), coef_bytes(len(coefs))
    if kind.startswith("sep7u"):  # AV1's form: a filter per restoration unit, each switchable
        unit = int(kind[5:])
        out = x.copy()
        size = 1
        for i in range(0, x.shape[0], unit):
            for j in range(0, x.shape[1], unit):
                # the unit with 3 samples of its neighbours around it (the picture's edge
                # mirrored, as the filter sees it)
                i0, j0 = max(i - 3, 0), max(j - 3, 0)
                i1, j1 = min(i + unit + 3, x.shape[0]), min(j + unit + 3, x.shape[1])
                xs, ys = x[i0:i1, j0:j1], y[i0:i1, j0:j1]
                coefs = quantize(fit_separable(xs, ys, 7))
                filtered = apply_separable(xs, coefs)
                inner = (slice(i - i0, i - i0 + unit), slice(j - j0, j - j0 + unit))
                before = xs[inner] - ys[inner]
                if np.sum((filtered[inner] - ys[inner]) ** 2) < np.sum(before**2):
                    out[i : i + unit, j : j + unit] = filtered[inner]
                    size += math.ceil(BITS * 6 / 8)
                size += 1 / 8  # its on/off bit
        return out, math.ceil(size)
    offsets = diamond(int(kind[3]) // 2)
    terms = _pair_terms(x, offsets)
    if len(kind) == 4:
        coefs = quantize(_solve(terms, y - x, None))
        return apply_pairs(x, offsets, coefs), coef_bytes(len(coefs))
    count = int(kind[5:].rstrip("d"))
    # thresholds as a header would carry them: 2 bytes each, 1/16 grey level
    act = activity(x)
    edges = np.rint(np.quantile(act, np.arange(1, count) / count) * 16) / 16
    classes = np.searchsorted(edges, act, side="right")
    size = 2 * (count - 1)
    if kind.endswith("d"):
        classes = classes * 3 + direction(x)
    out = x.copy()
    for c in range(int(classes.max()) + 1):
        mask = classes == c
        if mask.sum() < 8 * len(offsets):
            size += 1  # "no filter" for this class
            continue
        coefs = quantize(_solve(terms, y - x, mask))
        change = sum(k * t[mask] for k, t in zip(coefs, terms, strict=True))
        before = x[mask] - y[mask]
        if np.sum((before + change) ** 2) >= np.sum(before**2):
            size += 1  # the encoder turns this class's filter off
            continue
        out[mask] += change
        size += coef_bytes(len(coefs)) - 1  # one mode byte for the lot
    return out, size + 1


KINDS = ("sep5", "sep7", "dia5", "dia7", "dia5c2", "dia5c4", "dia5c8", "dia7c4", "dia5c4d")


def _inputs(store: Any, name: str, i: int, source: str) -> np.ndarray:
    """The decoded picture the filter sees: ``u8`` the decoder's output, ``float`` its samples
    before the final rounding (what a filter inside the decoder would see)."""
    if source == "u8":
        return store[f"{name}/{i}"].astype(np.float64)
    parsed, plan = _open(store[f"{name}/bundle{i}"].tobytes())
    return _decode(parsed, dataclasses.replace(plan, dtype="float64"), None, 0)


def _filtered(x: np.ndarray, y: np.ndarray, kind: str, colour: str) -> tuple[np.ndarray, int]:
    """:func:`restore` over a picture's channels (see ``--colour``)."""
    if x.ndim == 2:
        return restore(x, y, kind)
    if colour == "rgb":
        parts = [restore(x[..., c], y[..., c], kind) for c in range(3)]
        return np.stack([p[0] for p in parts], axis=-1), sum(p[1] for p in parts)
    # in YCbCr: luma gets ``kind``, the chroma one diamond each
    xc, yc = x @ YCBCR_MATRIX.T, y @ YCBCR_MATRIX.T
    parts = [restore(xc[..., c], yc[..., c], kind if c == 0 else "dia5") for c in range(3)]
    filtered = np.stack([p[0] for p in parts], axis=-1) @ YCBCR_INVERSE_MATRIX.T
    return filtered, sum(p[1] for p in parts)


def measure(
    kinds: tuple[str, ...],
    source: str,
    colour: str,
    images: tuple[str, ...] = IMAGES,
    extra_bytes: int = 0,
) -> None:
    store = np.load(_capture_path(images))
    grey_bd: dict[str, list[float]] = {k: [] for k in kinds}
    for name in images:
        original = store[f"{name}/original"]
        sizes = store[f"{name}/sizes"]
        pixels = original.shape[0] * original.shape[1]
        base_rate = [8 * float(s) / pixels for s in sizes]
        decoded = [store[f"{name}/{i}"] for i in range(len(RATES))]
        base_psnr = [peers.psnr(d, original) for d in decoded]
        inputs = [_inputs(store, name, i, source) for i in range(len(RATES))]
        for kind in kinds:
            rates, psnrs, gains, extra = [], [], [], []
            for i in range(len(RATES)):
                y = original.astype(np.float64)
                # "best:a,b,...": the encoder tries each kind and keeps the best (the mode byte
                # every kind counts says which)
                options = kind.split(":")[1].split(",") if kind.startswith("best:") else [kind]
                tried = [_filtered(inputs[i], y, k, colour) for k in options]
                qualities = [peers.psnr(to_uint8(f), original) for f, _ in tried]
                quality = max(qualities)
                size = tried[qualities.index(quality)][1]
                size += extra_bytes
                if quality <= base_psnr[i]:  # the encoder turns it off: one byte says so
                    quality, size = base_psnr[i], 1
                rates.append(8 * float(sizes[i] + size) / pixels)
                psnrs.append(quality)
                gains.append(quality - base_psnr[i])
                extra.append(size)
            bd = bd_rate(base_rate, base_psnr, rates, psnrs)
            if original.ndim == 2:
                grey_bd[kind].append(bd)
            print(
                f"{name:9s} {kind[:7]:7s} BD {bd:+6.2f} %  gains dB "
                + " ".join(f"{g:+.3f}" for g in gains)
                + "  bytes "
                + ",".join(map(str, extra)),
                flush=True,
            )
        print(f"{name:9s} base PSNR " + " ".join(f"{q:.2f}" for q in base_psnr) + " dB", flush=True)
    for kind in kinds:
        if not grey_bd[kind]:
            continue
        print(f"grey mean {kind:7s} BD {np.mean(grey_bd[kind]):+6.2f} %")


@numba.njit(cache=False)
def _sep7_kernel(x: np.ndarray, h: np.ndarray, v: np.ndarray) -> np.ndarray:  # pragma: no cover
    """A separable symmetric 7-tap filter on a (rows, cols) plane, edges mirrored, to uint8."""
    rows, cols = x.shape
    tmp = np.empty((rows, cols), dtype=np.float32)
    out = np.empty((rows, cols), dtype=np.uint8)
    for i in range(rows):
        for j in range(cols):
            c = np.float32(x[i, j])
            acc = c
            for k in range(3):
                left = j - k - 1
                right = j + k + 1
                left = -left - 1 if left < 0 else left
                right = 2 * cols - right - 1 if right >= cols else right
                acc += h[k] * (np.float32(x[i, left]) + np.float32(x[i, right]) - 2 * c)
            tmp[i, j] = acc
    for i in range(rows):
        for j in range(cols):
            c = tmp[i, j]
            acc = c
            for k in range(3):
                up = i - k - 1
                down = i + k + 1
                up = -up - 1 if up < 0 else up
                down = 2 * rows - down - 1 if down >= rows else down
                acc += v[k] * (tmp[up, j] + tmp[down, j] - 2 * c)
            out[i, j] = np.uint8(min(max(acc + np.float32(0.5), np.float32(0)), np.float32(255)))
    return out


@numba.njit(cache=False)
def _dia5c_kernel(
    p: np.ndarray, edges: np.ndarray, coefs: np.ndarray
) -> np.ndarray:  # pragma: no cover
    """``dia5cN`` on a plane padded by 5 (mirrored, float32): activity (|Laplacian| summed
    over 5×5, running sums), its class by ``edges``, the class's 5×5 diamond, to uint8."""
    rows, cols = p.shape[0] - 10, p.shape[1] - 10
    lap = np.empty((rows + 4, cols + 4), dtype=np.float32)
    for i in range(rows + 4):
        a = i + 3
        for j in range(cols + 4):
            b = j + 3
            lap[i, j] = abs(4 * p[a, b] - p[a - 1, b] - p[a + 1, b] - p[a, b - 1] - p[a, b + 1])
    colsum = np.empty((rows, cols + 4), dtype=np.float32)
    colsum[0] = lap[0] + lap[1] + lap[2] + lap[3] + lap[4]
    for i in range(1, rows):
        for j in range(cols + 4):
            colsum[i, j] = colsum[i - 1, j] + lap[i + 4, j] - lap[i - 1, j]
    out = np.empty((rows, cols), dtype=np.uint8)
    n = edges.shape[0]
    for i in range(rows):
        acc = colsum[i, 0] + colsum[i, 1] + colsum[i, 2] + colsum[i, 3] + colsum[i, 4]
        a = i + 5
        for j in range(cols):
            if j:
                acc += colsum[i, j + 4] - colsum[i, j - 1]
            act = acc / 25
            cls = 0
            while cls < n and act >= edges[cls]:
                cls += 1
            b = j + 5
            c2 = 2 * p[a, b]
            k = coefs[cls]
            value = (
                p[a, b]
                + k[0] * (p[a, b + 1] + p[a, b - 1] - c2)
                + k[1] * (p[a, b + 2] + p[a, b - 2] - c2)
                + k[2] * (p[a + 1, b - 1] + p[a - 1, b + 1] - c2)
                + k[3] * (p[a + 1, b] + p[a - 1, b] - c2)
                + k[4] * (p[a + 1, b + 1] + p[a - 1, b - 1] - c2)
                + k[5] * (p[a + 2, b] + p[a - 2, b] - c2)
            )
            out[i, j] = np.uint8(min(max(value + np.float32(0.5), np.float32(0)), np.float32(255)))
    return out


def dia5c_numba(x: np.ndarray, edges: np.ndarray, coefs: np.ndarray) -> np.ndarray:
    """:func:`_dia5c_kernel` on an unpadded plane (any real dtype)."""
    padded = np.pad(x.astype(np.float32), 5, mode="symmetric")
    return _dia5c_kernel(padded, edges.astype(np.float32), coefs.astype(np.float32))


def _sep7_numpy(x: np.ndarray, h: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The same in numpy, float32, a plane at a time."""
    f = x.astype(np.float32)
    for axis, taps in ((1, h), (0, v)):
        pad = [(0, 0), (0, 0)]
        pad[axis] = (3, 3)
        p = np.pad(f, pad, mode="symmetric")
        n = f.shape[axis]
        out = f * np.float32(1 - 2 * taps.sum())
        for k, c in enumerate(taps, start=1):
            lo = np.take(p, np.arange(3 - k, 3 - k + n), axis=axis)
            hi = np.take(p, np.arange(3 + k, 3 + k + n), axis=axis)
            out += np.float32(c) * (lo + hi)
        f = out
    return np.clip(np.rint(f), 0, 255).astype(np.uint8)


def cost(size: int, rounds: int) -> None:
    """CPU seconds (``time.process_time`` medians over ``rounds`` interleaved rounds) of the
    filters on a ``size``² RGB picture against ``wavecore.decode`` of its 1 bpp bundle."""
    from codec_speed import test_image

    image = test_image(size)
    bundle = wavecore.encode_image(image, wavelet="cdf97", bpp=1.0)
    decoded = wavecore.decode(bundle)
    planes = [np.ascontiguousarray(decoded[..., c]) for c in range(3)]
    h = np.array([0.05, -0.02, 0.01], dtype=np.float32)
    edges = np.array([1.0, 2.5, 6.0], dtype=np.float32)
    coefs = np.full((4, 6), 0.02, dtype=np.float32)
    parsed, plan = _open(bundle)
    as_float = dataclasses.replace(plan, dtype="float64")
    runs = {
        "decode (uint8, fused last level)": lambda: wavecore.decode(bundle),
        "decode to float64 (unfused) + rint": lambda: to_uint8(_decode(parsed, as_float, None, 0)),
        "sep7 numpy float32, 3 planes": lambda: [_sep7_numpy(p, h, h) for p in planes],
        "sep7 numba, 3 planes": lambda: [_sep7_kernel(p, h, h) for p in planes],
        "dia5c4 numba, 3 planes": lambda: [dia5c_numba(p, edges, coefs) for p in planes],
    }
    for run in runs.values():  # compile, warm
        run()
    times: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(rounds):
        for key, run in runs.items():
            start = time.process_time()
            run()
            times[key].append(time.process_time() - start)
    base = float(np.median(times["decode (uint8, fused last level)"]))
    print(f"{size}² RGB, 1 bpp cdf97 bundle of {len(bundle)} bytes; CPU s medians of {rounds}")
    for key, values in times.items():
        median = float(np.median(values))
        print(f"{key:38s} {median:.3f} s  ({median / base:.2f}× decode)")


def built(images: tuple[str, ...] = IMAGES) -> None:
    """The library's filter (``wavecore.restoration``) against none: ``encode_image(image,
    wavelet="cdf97", bpp=r)`` at the 7 rates with and without it (the rate control is the
    same: the filter only takes bytes it left free), the BD-rate of the first against the
    second, its PSNR gain and bytes per rate, and the CPU time of encoding and decoding all
    7 (medians of 3 interleaved rounds)."""
    from wavecore.codec import ratecontrol

    restorable = ratecontrol._restorable

    def run(
        image: np.ndarray, on: bool
    ) -> tuple[list[float], list[float], list[int], float, float]:
        ratecontrol._restorable = restorable if on else (lambda plan: False)  # type: ignore[assignment]
        pixels = image.shape[0] * image.shape[1]
        rates, psnrs, sizes, encode, decode = [], [], [], 0.0, 0.0
        for rate in RATES:
            start = time.process_time()
            bundle = wavecore.encode_image(image, wavelet="cdf97", bpp=rate)
            middle = time.process_time()
            decoded = wavecore.decode(bundle)
            encode += middle - start
            decode += time.process_time() - middle
            rates.append(8 * len(bundle) / pixels)
            psnrs.append(peers.psnr(decoded, image))
            sizes.append(len(bundle))
        return rates, psnrs, sizes, encode, decode

    grey: list[float] = []
    for name in images:
        image = getattr(data, name)()
        rounds = [(run(image, False), run(image, True)) for _ in range(3)]
        (r0, p0, s0, _, _), (r1, p1, s1, _, _) = rounds[0]
        bd = bd_rate(r0, p0, r1, p1)
        if image.ndim == 2:
            grey.append(bd)
        encode = np.median([b[3] / a[3] for a, b in rounds])
        decode = np.median([b[4] / a[4] for a, b in rounds])
        print(
            f"{name:9s} BD {bd:+.2f} %  dB "
            + " ".join(f"{b - a:+.3f}" for a, b in zip(p0, p1, strict=True))
            + "  bytes "
            + ",".join(str(b - a) for a, b in zip(s0, s1, strict=True))
            + f"  CPU encode {encode:.2f}×, decode {decode:.2f}×",
            flush=True,
        )
    ratecontrol._restorable = restorable  # type: ignore[assignment]
    if grey:
        print(f"grey mean BD {np.mean(grey):+.2f} %")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("what", choices=("capture", "measure", "cost", "built"))
    parser.add_argument("--kinds", nargs="*", default=list(KINDS))
    parser.add_argument("--source", choices=("u8", "float"), default="float")
    parser.add_argument("--colour", choices=("rgb", "ycc"), default="ycc")
    parser.add_argument("--images", nargs="*", default=list(IMAGES))
    parser.add_argument("--extra", type=int, default=0, help="bytes more when the filter is on")
    parser.add_argument("--size", type=int, default=2048)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--scale", type=int, default=SCALE)
    parser.add_argument("--bits", type=int, default=BITS)
    args = parser.parse_args()
    globals().update(SCALE=args.scale, BITS=args.bits)
    if args.what == "capture":
        capture(tuple(args.images))
    elif args.what == "measure":
        measure(tuple(args.kinds), args.source, args.colour, tuple(args.images), args.extra)
    elif args.what == "built":
        built(tuple(args.images))
    else:
        cost(args.size, args.rounds)


if __name__ == "__main__":
    main()
