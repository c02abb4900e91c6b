"""What a change to the block coder's probability models would gain, before it becomes a
coder version (issue 12).

Run with ``.venv/bin/python benchmarks/coder_gain.py capture`` once (a few minutes: it codes
the tuning pictures, camera, moon, coins, brick in grey and astronaut in colour, with
``encode_image(..., bpp=r)`` at the peers' 7 exact rates over 0.25–2 bpp, and keeps the
quantized coefficients each bundle holds), then
``.venv/bin/python benchmarks/coder_gain.py measure [--mix] [--init TABLE] ...`` per variant.
``--pictures training`` captures (and measures) scikit-image pictures that are not benchmark
pictures instead (:data:`TRAINING`): train priors there, measure them on the tuning pictures.

``measure`` codes those same integers again with a *variant* of the version-4 kernels
(``wavecore/_blockkernels.py``), built at run time from its source with the model functions
swapped, and prints the BD-rate of the variant against today's coder per picture.  Both code
the same integers, so each rate point keeps its PSNR and the BD-rate is the mean log ratio of
the whole bundles' bytes (header included; the block tables, block checks and band counts,
which depend on the number of blocks, counted as the bundle stores them).  The variants:

* ``--mix``: every context keeps two probabilities, one adapting fast (shift ``--fast``) and
  one slow (shift ``--slow``), both with today's count-based start, and codes with their
  mean (as AV1 and VVC do);
* ``--collect FILE``: write, per context (and per set, ``--sets``), the 0s and 1s seen in the
  first ``--early`` uses of that context in each block (the statistics a fresh block starts
  without);
* ``--init FILE``: start every context seen 20 times or more at the probability of that
  table (``--collect``'s), with the count ``--init-count`` (how much the start is trusted);
* ``--sets N``: ``N`` sets of initial models (and of statistics), by the block's level
  counted from the finest (0, 1, ..., the coarser levels sharing the last set);
* ``--block SIDE``: the same integers cut into blocks of ``SIDE`` × ``SIDE`` (bundles already
  carry the block side: this needs no new coder version);
* ``--parent W``: the parent band's magnitude (the same orientation and channel one level
  coarser, at ``(i // 2, j // 2)``), times ``W``, joins the external activity ``e`` of the
  zero flag and bit-length contexts.  A block would then need its parent block decoded first.
  Context coder version 6 adopted it with weight 2: the variant sets the kernels' own
  ``PARENT_WEIGHT`` (``measure``'s "today's coder" stays version 4, no parent).

Measured on 2026-11-28 (``capture`` of cdf97; priors collected on :data:`TRAINING`, early 24;
BD-rate per picture against version 4 on the same integers, grey mean / astronaut):

* priors, one set, count 2 / 4 / 8: −0.48 / −0.57 / −0.58 % grey, −0.44 / −0.58 / −0.67 %
  colour (early 128: the same within 0.03);
* priors by level, ``--sets 3`` (or 5), count 8: −0.69 % grey (camera −0.71, moon −0.66,
  coins −1.14, brick −0.24), −0.68 % colour; count 16: −0.63 / −0.70 %; 32: −0.52 / −0.67 %.
  Trained on the tuning pictures themselves (an upper bound, not a fair figure): −0.73 /
  −0.67 %, so priors of this form are worth some 0.7 %;
* ``--block 256``: −0.60 % grey (camera −0.35, moon −0.67, coins −0.85, brick −0.54),
  −0.48 % colour; with ``--sets 3`` priors trained at 256, count 8: −1.17 % grey, −1.01 %
  colour;
* ``--parent 1 / 2 / 4``: −1.54 / −1.72 / −1.42 % grey, −1.43 / −1.63 / −1.32 % colour
  (weight 2: camera −0.98, moon −2.36, coins −1.82, brick −1.71, astronaut −1.63); with
  ``--sets 3`` priors trained with it, count 8: −2.39 % grey, −2.30 % colour.  The parent
  term cost the variant's encoder 1.9 % more CPU (median of 7 interleaved runs over 3 rates of
  the 5 pictures, the same variant with ``--parent 0`` as the peer);
* bspline2 (its own ``capture``): ``--block 256`` −0.61 % grey, −0.49 % colour; ``--parent 2``
  −0.93 / −1.08 %; the cdf97 priors above (``--sets 3``, count 8) −0.33 / −0.33 %.

``versions`` codes the captured integers with context coder versions 6 and 7 (the library's
own kernels, ``oriented`` 0 and 1) and prints the BD-rate of 7 against 6 per picture
(``rate_distortion.bd_rate`` over the 7 rates, the whole bundles' bytes at their PSNRs) and
the two versions' ``encode_span`` and ``decode_span`` CPU time, interleaved (``--rounds``).
Run on 2026-12-06: see docs/bundle-format.md, "Context coder version 7".  (``measure``'s
variant source still patches model functions the kernels no longer have.)

It is an experiment harness: nothing here is a format, and the variants are not decodable.
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from skimage import data

import wavecore
import wavecore._blockkernels as kernels

try:  # run as a script: benchmarks/ is on the path
    import peers
except ImportError:  # imported as benchmarks.coder_gain
    from benchmarks import peers

NAMES = ("camera", "moon", "coins", "brick", "astronaut")
GREY = NAMES[:4]
#: Pictures to train priors on (``capture --pictures training``): scikit-image's pictures that
#: ship with it, none of them a benchmark picture (grey, then colour).
TRAINING = (
    "text",
    "page",
    "grass",
    "gravel",
    "cell",
    "clock",
    "chelsea",
    "coffee",
    "rocket",
    "hubble_deep_field",
    "immunohistochemistry",
    "retina",
)
PICTURES = {"tuning": NAMES, "training": TRAINING}
WORK = Path(os.environ.get("CODER_GAIN_DIR", "/tmp/coder_gain"))

# The model functions of the variant: two probabilities per context (the second one slow),
# statistics of the early uses after the models, and initial models from a table.
_ADAPT = """@njit(nogil=True, cache=False, inline="always")
def _adapt(models, ctx, p, n, bit):
    m = 2 * ctx
    p1 = models[m] >> 8
    p2 = models[m + 1]
    if n < EARLY:
        models[models[STATS] + 2 * ctx + bit] += 1
    s1 = min(RATE[n], FAST) if MIX else min(RATE[n], RATE_LIMIT)
    s2 = min(RATE[n], SLOW)
    if bit == 0:
        p1 += (PROB_ONE - p1) >> s1
        p2 += (PROB_ONE - p2) >> s2
    else:
        p1 -= p1 >> s1
        p2 -= p2 >> s2
    if n < 255:
        n += 1
    models[m] = (p1 << 8) | n
    models[m + 1] = p2


@njit(nogil=True, cache=False, inline="always")
def _prob(models, ctx):
    w = models[2 * ctx]
    if MIX:
        return ((w >> 8) + models[2 * ctx + 1]) >> 1, w & 0xFF
    return w >> 8, w & 0xFF


"""

_INIT = """def _initial_models() -> np.ndarray:
    p = np.full(CONTEXTS, PROB_ONE // 2, dtype=np.int64)
    n = np.zeros(CONTEXTS, dtype=np.int64)
    for kind in range(2):
        for local in range(LOCAL_CLASSES):
            for external in range(EXTERNAL_CLASSES):
                ctx = ZERO_BASE + (kind * LOCAL_CLASSES + local) * EXTERNAL_CLASSES + external
                p[ctx] = max(8, 15 - local - external) * PROB_ONE // 16
                n[ctx] = 2
    p = np.tile(p, (SETS, 1))
    n = np.tile(n, (SETS, 1))
    if INIT:
        table = np.load(INIT).reshape(-1, CONTEXTS, 2)
        pooled = table.sum(axis=0)
        for k in range(SETS):
            own = table[k] if k < len(table) else pooled
            use = np.where((own[:, :1] + own[:, 1:] >= 20), own, pooled)
            seen = use[:, 0] + use[:, 1]
            good = seen >= 20
            start = np.rint(PROB_ONE * (use[good, 0] + 0.5) / (seen[good] + 1))
            p[k, good] = np.clip(start, 64, PROB_ONE - 64)
            n[k, good] = INIT_COUNT
    out = np.zeros((SETS, 2 * CONTEXTS), dtype=np.int32)
    out[:, 0::2] = (p << 8) | n
    out[:, 1::2] = p
    return out


@njit(nogil=True, cache=False)
def _fresh_set(models, k):
    models[: 2 * CONTEXTS] = INITIAL_MODELS[k]
    models[STATS] = STATS + 1 + k * 2 * CONTEXTS


"""


def _cut(src: str, start: str, stop: str, new: str = "") -> str:
    i, j = src.index(start), src.index(stop)
    return src[:i] + new + src[j:]


def variant_source(options: argparse.Namespace) -> str:
    """The version-4 kernels' source with the variant's model functions (encoder only)."""
    src = Path(kernels.__file__).read_text().replace("cache=True", "cache=False")
    knobs = (
        f"MIX = {int(options.mix)}\nFAST = {options.fast}\nSLOW = {options.slow}\n"
        f"INIT = {options.init or ''!r}\nINIT_COUNT = {options.init_count}\n"
        f"EARLY = {options.early}\nSETS = {options.sets}\n"
    )
    src = src.replace("from numba import njit\n", "from numba import njit\n" + knobs, 1)
    deco = '@njit(nogil=True, cache=False, inline="always")\n'
    src = _cut(src, deco + "def _adapt", deco + "def _encode_bit", _ADAPT)
    src = src.replace(
        "    model = models[ctx]\n    p = model >> 8\n", "    p, count = _prob(models, ctx)\n"
    )
    src = src.replace(
        "_adapt(models, ctx, p, model & 0xFF, bit)", "_adapt(models, ctx, p, count, bit)"
    )
    src = src.replace("), RATE_LIMIT\n)", "), max(RATE_LIMIT, SLOW)\n)").replace(
        "for n in range(COUNT_CAP + 1)", "for n in range(256)"
    )
    src = src.replace(
        "CONTEXTS = TILE_BASE + TILE_SIZE\n",
        "CONTEXTS = TILE_BASE + TILE_SIZE\nSTATS = 2 * CONTEXTS\n",
    )
    src = _cut(src, "def _initial_models", "INITIAL_MODELS = _initial_models()", _INIT)
    src = src.replace(
        "def encode_span(flat, planes, parents, blocks, lo, hi):",
        "def encode_span(flat, planes, parents, blocks, lo, hi, sets):",
    )
    src = src.replace(
        "            _fresh_models(models)\n            end =",
        "            _fresh_set(models, sets[b])\n            end =",
    )
    src = src.replace(
        "    models = np.empty(CONTEXTS, dtype=np.int32)\n    scratch",
        "    models = np.zeros(STATS + 1 + 2 * CONTEXTS * SETS, dtype=np.int32)\n    scratch",
        1,
    )
    src = src.replace(
        "    return out[:pos].copy(), lengths\n",
        "    return out[:pos].copy(), lengths, models[STATS + 1 :].copy()\n",
        1,
    )
    # The parent term is the kernels' own (context coder version 6): its weight, here.
    src = src.replace("PARENT_WEIGHT = 2\n", f"PARENT_WEIGHT = {options.parent}\n", 1)
    plain = "@njit(nogil=True, cache=False)\n"
    src = _cut(src, plain + "def decode_span", plain + "def write_varints")
    return _cut(src, plain + "def _decode_block(", plain + "def _block_is_empty")


def _load_variant(options: argparse.Namespace) -> object:
    WORK.mkdir(parents=True, exist_ok=True)
    path = WORK / "variant_kernels.py"
    path.write_text(variant_source(options))
    spec = importlib.util.spec_from_file_location("variant_kernels", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def capture(wavelet: str, pictures: str = "tuning") -> None:
    """Code the tuning (or training) pictures at the exact rates; keep each bundle's integers."""
    original = kernels.decode_span
    seen: dict[str, tuple] = {}

    def recording(data_, starts, lengths, planes, parents, oriented, blocks, flat, lo, hi):  # type: ignore[no-untyped-def]
        bad = original(data_, starts, lengths, planes, parents, oriented, blocks, flat, lo, hi)
        seen["last"] = (flat, planes, parents, blocks)
        return bad

    kernels.decode_span = recording
    out: dict[str, object] = {}
    try:
        for name in PICTURES[pictures]:
            image = getattr(data, name)()
            for k, rate in enumerate(peers.EXACT_RATES):
                bundle = wavecore.encode_image(image, wavelet=wavelet, bpp=rate)
                back = wavecore.decode(bundle)  # records the integers it holds
                flat, planes, parents, blocks = seen.pop("last")
                key = f"{name}_{k}"
                out[key + "_flat"], out[key + "_planes"], out[key + "_blocks"] = (
                    flat.copy(),
                    planes,
                    blocks,
                )
                out[key + "_parents"] = parents
                out[key + "_bytes"] = len(bundle)
                out[key + "_psnr"] = peers.psnr(image, back)
                print(f"{name:10s} {rate:.3f} bpp {len(bundle):7d} bytes", flush=True)
    finally:
        kernels.decode_span = original
    WORK.mkdir(parents=True, exist_ok=True)
    suffix = "" if pictures == "tuning" else f"_{pictures}"
    np.savez(WORK / f"capture_{wavelet}{suffix}.npz", **out)


def retile(planes: np.ndarray, blocks: np.ndarray, side: int) -> np.ndarray:
    """The block table of the same planes cut into ``side`` × ``side`` blocks (2-D)."""
    tables = []
    for lo, hi in dict.fromkeys(map(tuple, blocks[:, [kernels.B_PLANE_LO, kernels.B_PLANE_HI]])):
        height = int(planes[lo:hi, kernels.P_ROWS].max())
        width = int(planes[lo:hi, kernels.P_COLS].max())
        for r in range(0, height, side):
            for c in range(0, width, side):
                tables.append([lo, hi, r, c, r + side, c + side])
    return np.array(tables, dtype=np.int64).reshape(-1, kernels.BLOCK_FIELDS)


def with_parents(planes: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """Each plane's parent for ``--parent`` (-1: none): a detail plane's parent is the plane at
    the same place in the previous chunk when that chunk is a detail chunk of as many planes
    (as ``blockcoder``'s version 6 finds it)."""
    bounds = list(dict.fromkeys(map(tuple, blocks[:, [kernels.B_PLANE_LO, kernels.B_PLANE_HI]])))
    parent = np.full(len(planes), -1, dtype=np.int64)
    for (lo0, hi0), (lo, hi) in itertools.pairwise(bounds[1:]):
        if hi - lo == hi0 - lo0:
            parent[lo:hi] = np.arange(lo0, hi0)
    return parent


def block_sets(planes: np.ndarray, blocks: np.ndarray, count: int) -> np.ndarray:
    """Each block's set of initial models: its level counted from the finest (0), the
    coarser ones sharing the last set."""
    chunk = np.unique(blocks[:, kernels.B_PLANE_LO], return_inverse=True)[1]
    return np.minimum(chunk.max() - chunk, count - 1).astype(np.int64)


def table_bytes(
    flat: np.ndarray, planes: np.ndarray, blocks: np.ndarray, lengths: np.ndarray
) -> int:
    """What a bundle stores per chunk beside its blocks: each block's varint length and, in
    chunks of several blocks (bundle format 3.0), a CRC-16 of each block, the band counts of a
    detail chunk (two varints a band) and a CRC-16 of that prefix."""
    total = 0
    chunks = blocks[:, kernels.B_PLANE_LO]
    for index, lo in enumerate(np.unique(chunks)):
        mine = chunks == lo
        total += len(kernels.write_varints(lengths[mine].astype(np.int64)))
        if mine.sum() <= 1:
            continue
        total += 2 * int(mine.sum()) + 2
        if index == 0:
            continue
        hi = int(blocks[mine][0, kernels.B_PLANE_HI])
        counts = np.zeros((3, 2), dtype=np.int64)
        for q in range(int(lo), hi):
            start = int(planes[q, kernels.P_OFFSET])
            values = np.abs(
                flat[start : start + planes[q, kernels.P_ROWS] * planes[q, kernels.P_COLS]]
            )
            band = int(planes[q, kernels.P_ORIENT])
            counts[band] += (int((values == 1).sum()), int((values >= 2).sum()))
        total += len(kernels.write_varints(counts.ravel()))
    return total


def measure(options: argparse.Namespace) -> dict[str, float]:
    """BD-rate (percent) of the variant against the version-4 coder, per picture."""
    variant = _load_variant(options)
    suffix = "" if options.pictures == "tuning" else f"_{options.pictures}"
    captured = np.load(WORK / f"capture_{options.wavelet}{suffix}.npz")
    names = PICTURES[options.pictures]
    start = time.perf_counter()
    stats = np.zeros(1, dtype=np.int64)
    out = {}
    for name in names:
        logs = []
        for k in range(len(peers.EXACT_RATES)):
            key = f"{name}_{k}"
            flat, planes, blocks = (captured[key + s] for s in ("_flat", "_planes", "_blocks"))
            none = np.full(len(planes), -1, dtype=np.int64)  # version 4: no parent
            lengths = kernels.encode_span(flat, planes, none, 0, blocks, 0, len(blocks))[1]
            today = int(lengths.sum()) + table_bytes(flat, planes, blocks, lengths)
            if options.block:
                blocks = retile(planes, blocks, options.block)
            sets = block_sets(planes, blocks, options.sets)
            parents = with_parents(planes, blocks) if options.parent else none
            coder = variant.encode_span  # type: ignore[attr-defined]
            _, lengths, counts = coder(flat, planes, parents, blocks, 0, len(blocks), sets)
            stats = stats + counts.astype(np.int64)
            whole = int(captured[key + "_bytes"])
            new = int(lengths.sum()) + table_bytes(flat, planes, blocks, lengths)
            logs.append(math.log((whole - today + new) / whole))
        out[name] = 100.0 * (math.exp(float(np.mean(logs))) - 1.0)
    if options.collect:
        np.save(options.collect, stats.reshape(-1, 2))
    grey = [out[n] for n in names if captured[f"{n}_0_planes"][-1, kernels.P_LUMA] < 0]
    colour = [out[n] for n in names if captured[f"{n}_0_planes"][-1, kernels.P_LUMA] >= 0]
    load = Path("/proc/loadavg").read_text().split()[:3]
    print(
        " ".join(f"{n} {v:+.2f} %" for n, v in out.items())
        + f" | grey {np.mean(grey):+.2f} %, colour {np.mean(colour):+.2f} %"
        + f"  ({time.perf_counter() - start:.0f} s, load {' '.join(load)})",
        flush=True,
    )
    return out


def versions(wavelet: str, rounds: int) -> dict[str, float]:
    """BD-rate (percent) of context coder version 7 against version 6 on the captured
    integers, per picture, and the CPU time of the two (``encode_span`` and ``decode_span``
    of every captured coding, the versions interleaved, ``rounds`` rounds, medians).

    Both versions code the same integers with the library's own kernels (``oriented`` 0 and
    1, the parents of the capture), so each rate point keeps its PSNR; the rate is the whole
    bundle's bytes with the blocks' bytes and tables swapped.  BD-rate is
    ``rate_distortion.bd_rate`` over the 7 points.
    """
    try:
        import rate_distortion
    except ImportError:
        from benchmarks import rate_distortion
    captured = np.load(WORK / f"capture_{wavelet}.npz")
    out: dict[str, float] = {}
    points = []
    for name in NAMES:
        rates: dict[int, list[float]] = {0: [], 1: []}
        quality = []
        for k in range(len(peers.EXACT_RATES)):
            key = f"{name}_{k}"
            flat, planes, parents, blocks = (
                captured[key + s] for s in ("_flat", "_planes", "_parents", "_blocks")
            )
            sizes = {}
            for oriented in (0, 1):
                data_, lengths = kernels.encode_span(
                    flat, planes, parents, oriented, blocks, 0, len(blocks)
                )
                sizes[oriented] = int(lengths.sum()) + table_bytes(flat, planes, blocks, lengths)
                points.append((oriented, flat, planes, parents, blocks, data_, lengths))
            whole = int(captured[key + "_bytes"])
            for oriented in (0, 1):  # the capture was coded by the default (version 7)
                rates[oriented].append(whole - sizes[1] + sizes[oriented])
            quality.append(float(captured[key + "_psnr"]))
        out[name] = rate_distortion.bd_rate(rates[0], quality, rates[1], quality)
    grey = np.mean([out[n] for n in GREY])
    print(
        f"{wavelet}: version 7 against 6: "
        + " ".join(f"{n} {v:+.2f} %" for n, v in out.items())
        + f" | grey {grey:+.2f} %",
        flush=True,
    )
    times: dict[tuple[str, int], list[float]] = {}
    for _ in range(rounds):
        for oriented in (0, 1):
            for what in ("encode", "decode"):
                start = time.process_time()
                for o, flat, planes, parents, blocks, data_, lengths in points:
                    if o != oriented:
                        continue
                    if what == "encode":
                        kernels.encode_span(flat, planes, parents, o, blocks, 0, len(blocks))
                    else:
                        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
                        target = np.zeros_like(flat)
                        kernels.decode_span(
                            data_,
                            starts,
                            lengths,
                            planes,
                            parents,
                            o,
                            blocks,
                            target,
                            0,
                            len(blocks),
                        )
                times.setdefault((what, oriented), []).append(time.process_time() - start)
    for what in ("encode", "decode"):
        six, seven = (float(np.median(times[(what, o)])) for o in (0, 1))
        print(f"  {what}_span: version 6 {six:.3f} s, version 7 {seven:.3f} s ({seven / six:.3f}x)")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=("capture", "measure", "versions"))
    parser.add_argument("--wavelet", default="cdf97")
    parser.add_argument("--pictures", choices=tuple(PICTURES), default="tuning")
    parser.add_argument("--block", type=int, default=0, help="code in blocks of this side")
    parser.add_argument("--mix", action="store_true", help="two adaptation rates, mixed")
    parser.add_argument("--fast", type=int, default=4, help="--mix: the fast shift")
    parser.add_argument("--slow", type=int, default=7, help="--mix: the slow shift")
    parser.add_argument("--collect", help="write the early-use statistics here (.npy)")
    parser.add_argument("--early", type=int, default=24, help="--collect: uses per block")
    parser.add_argument("--init", help="initial probabilities from this table (.npy)")
    parser.add_argument("--init-count", type=int, default=4)
    parser.add_argument("--parent", type=int, default=0, help="weight of the parent band")
    parser.add_argument("--sets", type=int, default=1, help="initial models per level")
    parser.add_argument("--rounds", type=int, default=7, help="versions: timing rounds")
    options = parser.parse_args()
    if options.action == "capture":
        capture(options.wavelet, options.pictures)
    elif options.action == "versions":
        versions(options.wavelet, options.rounds)
    else:
        measure(options)


if __name__ == "__main__":
    sys.exit(main())
