"""What a change to the block coder's probability models would gain, before it becomes a
coder version (issue 12).

Run with ``.venv/bin/python benchmarks/coder_gain.py capture`` once (a few minutes: it codes
the tuning pictures, camera, moon, coins, brick in grey and astronaut in colour, with
``encode_image(..., bpp=r)`` at the peers' 7 exact rates over 0.25–2 bpp, and keeps the
quantized coefficients each bundle holds), then
``.venv/bin/python benchmarks/coder_gain.py measure [--pairs F,S ...] [--init TABLE] ...``.
``--pictures training`` captures (and measures) scikit-image pictures that are not benchmark
pictures instead (:data:`TRAINING`): train priors there, measure them on the tuning pictures.

``measure`` codes those same integers again with a *variant* of today's kernels
(``wavecore/_blockkernels.py``'s ``encode_span``, built at run time from its source, compiled
once per run, some 90 s) and prints the BD-rate of the variant against context coder version
7 per picture (``rate_distortion.bd_rate`` over the 7 rates; both code the same integers, so
each rate point keeps its PSNR, and the rate is the whole bundle's bytes with the blocks'
bytes and tables swapped: block lengths, block checks and band counts as the bundle stores
them), the grey mean (camera, moon, coins, brick) and astronaut.  The variant keeps each
context's model in one 64-bit word: its count, **two probabilities** coded at their mean,
each adapting by ``2**-min(RATE[n], limit)`` with its own limit, and the 0s and 1s of the
context's first 24 uses in the block.  Its options:

* ``--pairs F,S ...``: the two limits (fast, slow), one measure each; ``6,6`` is version 7
  itself (the two probabilities stay equal: BD-rate 0.00 on every picture, a check);
* ``--collect FILE``: write, per set and context, the 0s and 1s seen in the first 24 uses of
  that context in each block (the statistics a fresh block starts without);
* ``--init FILE``: start every context seen 20 times or more (in its set, else in all) at
  the share of 0s of that table (``--collect``'s), with the count ``--init-count``;
* ``--sets N``: ``N`` sets of initial models (and of statistics), by the block's level
  counted from the finest (0, 1, ..., the coarser levels and the approximation sharing the
  last set).

``priors --init FILE`` writes ``wavecore/_blockpriors.py`` (context coder version 8's table)
from statistics collected with ``--sets 3``.  ``versions`` codes the captured integers with
two of the library's own versions 6, 7 and 8 (``--versions 7 8``, the default), decodes them
back (checked), and prints the BD-rate of the second against the first per picture and the
two versions' ``encode_span`` and ``decode_span`` CPU time, interleaved (``--rounds``).

Measured on 2026-12-06 (``capture`` of cdf97 with version 7; priors collected with
``measure --pictures training --sets 3 --collect``; BD-rate per picture against version 7 on
the same integers; camera, moon, coins, brick | grey mean, astronaut):

* two rates (fast, slow), today's starts: (4,7) −0.08, +0.15, −0.11, −0.10 | −0.03 %,
  −0.08 %; (5,7) −0.11, −0.05, −0.10, −0.13 | −0.10 %, −0.09 %; (4,8) −0.13, +0.06, −0.20,
  −0.17 | −0.11 %, −0.06 %; (5,8) −0.14, −0.10, −0.15, −0.15 | −0.14 %, −0.03 %; then grey
  / astronaut: (4,9) −0.08 / +0.07 %; (5,9) −0.09 / +0.12 %; (6,7) −0.02 / +0.05 %; (6,8)
  −0.00 / +0.18 %; (6,9) +0.06 / +0.35 %; (7,7) +0.08 / +0.25 %; (7,8) +0.17 / +0.45 %;
  (5,6) +0.06 / −0.01 %.  At most −0.14 % grey: not adopted (it would also need 64-bit
  models and a second update per bit);
* priors by level (3 sets), count 4: −0.56, −0.52, −0.96, −0.44 | −0.62 %, −0.62 %; count 8:
  −0.65, −0.56, −1.08, −0.34 | −0.66 %, −0.72 %; count 16: −0.68, −0.53, −1.13, −0.11 |
  −0.61 %, −0.75 %.  Adopted with count 8 as context coder version 8;
* both, count 8: (5,7) −0.74, −0.60, −1.17, −0.47 | −0.75 %, −0.80 %; (5,8) −0.78, −0.65,
  −1.24, −0.49 | −0.79 %, −0.74 %; count 16 with (5,8): −0.74 %, −0.76 %.  The two rates add
  some −0.13 % to the priors.

``versions`` (7 against 8, the library's kernels, 11 rounds, load 1.9 on 2 cores): the same
BD-rates as ``measure``'s count 8 (grey −0.66 %, astronaut −0.72 %), ``encode_span`` 0.111 →
0.110 s (0.998×), ``decode_span`` 0.121 → 0.120 s (0.993×): a block's start is one copy of
another row.

Measured on 2026-11-28 with the harness's earlier form (against version 4, whose model
functions it patched; ``--block`` and ``--parent`` variants since removed): priors by level,
count 8, −0.69 % grey, −0.68 % colour; ``--block 256`` −0.60 % grey, −0.48 % colour;
``--parent 2`` −1.72 % grey, −1.63 % colour (adopted as version 6).

It is an experiment harness: nothing here is a format, and the variants are not decodable.
"""

from __future__ import annotations

import argparse
import importlib.util
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

# The model word of the variant (``measure``): the count ``n`` (bits 0-7), a fast probability
# (8-22) and a slow one (23-37), each one's shift limit (38-41, 42-45), and the 0s and 1s seen
# in the context's first ``EARLY`` uses in the block (46-54, 55-62, ``--collect``).  The
# limits live in the word so that one compiled variant serves every pair and every start.
_MODEL = """EARLY = 24
RATE_FULL = np.array([int(n + 1).bit_length() for n in range(256)], dtype=np.int64)


@njit(nogil=True, cache=True, inline="always")
def _prob(model):
    return (((model >> 8) & 0x7FFF) + ((model >> 23) & 0x7FFF)) >> 1


@njit(nogil=True, cache=True, inline="always")
def _adapted(model, bit):
    n = model & 0xFF
    p1 = (model >> 8) & 0x7FFF
    p2 = (model >> 23) & 0x7FFF
    r = RATE_FULL[n]
    s1 = min(r, (model >> 38) & 0xF)
    s2 = min(r, (model >> 42) & 0xF)
    if bit == 0:
        p1 += (PROB_ONE - p1) >> s1
        p2 += (PROB_ONE - p2) >> s2
    else:
        p1 -= p1 >> s1
        p2 -= p2 >> s2
    rest = model >> 38
    if n < EARLY:
        rest += np.int64(1) << (8 + 9 * bit)
    if n < 255:
        n += 1
    return (rest << 38) | (p2 << 23) | (p1 << 8) | n


"""


def _cut(src: str, start: str, stop: str, new: str = "") -> str:
    i, j = src.index(start), src.index(stop)
    return src[:i] + new + src[j:]


def _swap(src: str, old: str, new: str, count: int) -> str:
    assert src.count(old) == count, (old, src.count(old))
    return src.replace(old, new)


def variant_source() -> str:
    """Today's kernels' source (``encode_span`` only) with the variant's model word."""
    # Compiled afresh each run: numba cannot load the cache of a module loaded from a path.
    src = Path(kernels.__file__).read_text().replace("cache=True", "cache=False")
    src = _swap(src, "from ._blockpriors import", "from wavecore._blockpriors import", 1)
    deco = '@njit(nogil=True, cache=False, inline="always")\n'
    src = _cut(src, deco + "def _adapted", deco + "def _code_bit", _MODEL)
    src = _swap(src, "    p = model >> 8\n", "    p = _prob(model)\n", 2)
    src = _swap(src, "_adapted(p, model & 0xFF, bit)", "_adapted(model, bit)", 2)
    src = _swap(src, "ps = model_s >> 8", "ps = _prob(model_s)", 1)
    src = _swap(src, "pd = model_d >> 8", "pd = _prob(model_d)", 1)
    src = _swap(src, "_adapted(other >> 8, other & 0xFF, bit)", "_adapted(other, bit)", 1)
    src = _swap(
        src,
        "def encode_span(flat, planes, parents, oriented, blocks, lo, hi):",
        "def encode_span(flat, planes, parents, oriented, blocks, lo, hi, init, sets):",
        1,
    )
    src = _swap(
        src,
        "    models = np.empty(CONTEXTS, dtype=np.int32)\n    scratch",
        "    models = np.empty(CONTEXTS, dtype=np.int64)\n"
        "    stats = np.zeros((init.shape[0], CONTEXTS, 2), dtype=np.int64)\n    scratch",
        2,
    )
    src = _swap(
        src,
        "            _fresh_models(models, oriented, blocks[b])\n            end =",
        "            models[:] = init[sets[b]]\n            end =",
        1,
    )
    src = _swap(
        src,
        "        lengths[b - lo] = end - pos\n",
        "        lengths[b - lo] = end - pos\n"
        "        for c in range(CONTEXTS):\n"
        "            stats[sets[b], c, 0] += (models[c] >> 46) & 0x1FF\n"
        "            stats[sets[b], c, 1] += (models[c] >> 55) & 0xFF\n",
        1,
    )
    return _swap(
        src,
        "    return out[:pos].copy(), lengths\n",
        "    return out[:pos].copy(), lengths, stats\n",
        1,
    )


def _load_variant() -> object:
    WORK.mkdir(parents=True, exist_ok=True)
    path = WORK / "variant_kernels.py"
    path.write_text(variant_source())
    spec = importlib.util.spec_from_file_location("variant_kernels", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def prior_models(table: np.ndarray, sets: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Starting probabilities and counts, one row per set, from early-use statistics
    (``--collect``'s ``(sets, CONTEXTS, 2)``): every context seen 20 times or more in its set
    (else in all sets together) starts at its share of 0s, with the count ``count``; the
    others as today (:data:`wavecore._blockkernels.INITIAL_MODELS`)."""
    p = (kernels.INITIAL_MODELS.astype(np.int64) >> 8)[None].repeat(sets, axis=0)
    n = (kernels.INITIAL_MODELS.astype(np.int64) & 0xFF)[None].repeat(sets, axis=0)
    table = table.reshape(-1, kernels.CONTEXTS, 2)
    pooled = table.sum(axis=0)
    for k in range(sets):
        own = table[k] if k < len(table) else pooled
        use = np.where(own.sum(axis=1, keepdims=True) >= 20, own, pooled)
        seen = use.sum(axis=1)
        good = seen >= 20
        start = np.rint(kernels.PROB_ONE * (use[good, 0] + 0.5) / (seen[good] + 1))
        p[k, good] = np.clip(start, 64, kernels.PROB_ONE - 64).astype(np.int64)
        n[k, good] = count
    return p, n


def initial_words(options: argparse.Namespace) -> np.ndarray:
    """The variant's starting model words, one row per set: today's starts (or ``--init``'s
    table's), both probabilities equal, with the shift limits ``--fast`` and ``--slow``."""
    p = (kernels.INITIAL_MODELS.astype(np.int64) >> 8)[None].repeat(options.sets, axis=0)
    n = (kernels.INITIAL_MODELS.astype(np.int64) & 0xFF)[None].repeat(options.sets, axis=0)
    if options.init:
        p, n = prior_models(np.load(options.init), options.sets, options.init_count)
    return (options.slow << 42) | (options.fast << 38) | (p << 23) | (p << 8) | n


def write_priors(options: argparse.Namespace) -> None:
    """Write ``wavecore/_blockpriors.py``: context coder version 8's priors from ``--init``'s
    statistics (collected on :data:`TRAINING` with ``--sets 3``), count ``--init-count``."""
    p, n = prior_models(np.load(options.init), kernels.LEVEL_CLASSES, options.init_count)

    def rows(values: np.ndarray) -> str:
        flat = [str(int(v)) for v in values.ravel()]
        return "\n".join(" ".join(flat[i : i + 14]) for i in range(0, len(flat), 14))

    text = PRIORS_MODULE.format(
        sets=kernels.LEVEL_CLASSES,
        contexts=kernels.CONTEXTS,
        count=options.init_count,
        probabilities=rows(p),
        counts=rows(n),
    )
    (Path(wavecore.__file__).parent / "_blockpriors.py").write_text(text)


PRIORS_MODULE = '''"""Context coder version 8's initial models, by level class (see
``docs/bundle-format.md``, "Context coder version 8").

Written by ``benchmarks/coder_gain.py priors`` from the bits seen in the first 24 uses of each
context of each block, coded with version 7, on scikit-image's pictures that are not benchmark
pictures (``coder_gain.TRAINING``, at the 7 rates of 0.25-2 bpp, cdf97): a context seen 20
times or more in its level class (else in all three together) starts at the share of 0s seen,
``rint(32768 (zeros + 1/2) / (seen + 1))`` clipped to [64, 32704], with the count {count};
the others as in version 7.  Integers only, so every machine starts the same models.
"""

from __future__ import annotations

import numpy as np

#: Level classes (0: the finest level, 1: the next, 2: the coarser ones and the approximation)
#: and contexts per class (``_blockkernels.CONTEXTS``, in its layout).
LEVEL_CLASSES, CONTEXTS = {sets}, {contexts}

#: The probability of a 0 bit (of 2**15) each context starts at, class by class.
_PROBABILITIES = """
{probabilities}
"""

#: The count each context starts with (its adaptation shift starts at ``RATE[count]``).
_COUNTS = """
{counts}
"""

#: ``PRIORS[k, ctx]``: context ``ctx``'s starting model in level class ``k``, as the kernels
#: keep models: ``probability << 8 | count``.
PRIORS = (
    (np.array(_PROBABILITIES.split(), dtype=np.int32) << 8)
    | np.array(_COUNTS.split(), dtype=np.int32)
).reshape(LEVEL_CLASSES, CONTEXTS)
'''


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


def measure(options: argparse.Namespace, variant: object) -> dict[str, float]:
    """BD-rate (percent) of the variant against context coder version 7, per picture, on the
    captured integers (``rate_distortion.bd_rate`` over the 7 rates, the whole bundles' bytes
    with the blocks' bytes and tables swapped)."""
    try:
        import rate_distortion
    except ImportError:
        from benchmarks import rate_distortion
    suffix = "" if options.pictures == "tuning" else f"_{options.pictures}"
    captured = np.load(WORK / f"capture_{options.wavelet}{suffix}.npz")
    names = PICTURES[options.pictures]
    init = initial_words(options)
    start = time.perf_counter()
    stats = np.zeros((options.sets, kernels.CONTEXTS, 2), dtype=np.int64)
    out = {}
    for name in names:
        today, new, quality = [], [], []
        for k in range(len(peers.EXACT_RATES)):
            key = f"{name}_{k}"
            flat, planes, parents, blocks = (
                captured[key + s] for s in ("_flat", "_planes", "_parents", "_blocks")
            )
            lengths = kernels.encode_span(flat, planes, parents, 1, blocks, 0, len(blocks))[1]
            seven = int(lengths.sum()) + table_bytes(flat, planes, blocks, lengths)
            sets = block_sets(planes, blocks, options.sets)
            coder = variant.encode_span  # type: ignore[attr-defined]
            _, lengths, seen = coder(flat, planes, parents, 1, blocks, 0, len(blocks), init, sets)
            stats += seen
            whole = int(captured[key + "_bytes"])
            today.append(whole)
            new.append(
                whole - seven + int(lengths.sum()) + table_bytes(flat, planes, blocks, lengths)
            )
            quality.append(float(captured[key + "_psnr"]))
        out[name] = rate_distortion.bd_rate(today, quality, new, quality)
    if options.collect:
        np.save(options.collect, stats)
    grey = [out[n] for n in names if n in GREY]
    load = Path("/proc/loadavg").read_text().split()[:3]
    print(
        f"fast {options.fast} slow {options.slow} init {options.init} count "
        f"{options.init_count} sets {options.sets}: "
        + " ".join(f"{n} {v:+.2f} %" for n, v in out.items())
        + (f" | grey {np.mean(grey):+.2f} %" if grey else "")
        + f"  ({time.perf_counter() - start:.0f} s, load {' '.join(load)})",
        flush=True,
    )
    return out


def with_levels(planes: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """A captured block table with version 8's level class column (captures made before it
    had six columns)."""
    if blocks.shape[1] == kernels.BLOCK_FIELDS:
        return blocks
    levels = block_sets(planes, blocks, kernels.LEVEL_CLASSES)
    return np.ascontiguousarray(np.column_stack([blocks, levels]))


def versions(wavelet: str, rounds: int, pair: tuple[int, int] = (7, 8)) -> dict[str, float]:
    """BD-rate (percent) of context coder version ``pair[1]`` against ``pair[0]`` (two of 6,
    7 and 8) on the captured integers, per picture, and the CPU time of the two
    (``encode_span`` and ``decode_span`` of every captured coding, the versions interleaved,
    ``rounds`` rounds, medians).

    Both versions code the same integers with the library's own kernels (``oriented`` 0, 1
    or 2, the parents of the capture), so each rate point keeps its PSNR; the rate is the
    whole bundle's bytes with the blocks' bytes and tables swapped (the capture's version
    being the one its ``encode_image`` used).  BD-rate is ``rate_distortion.bd_rate`` over the
    7 points; every coding is decoded back and checked.
    """
    try:
        import rate_distortion
    except ImportError:
        from benchmarks import rate_distortion
    captured = np.load(WORK / f"capture_{wavelet}.npz")
    oriented_of = {6: 0, 7: 1, 8: 2}
    old, new = (oriented_of[v] for v in pair)
    out: dict[str, float] = {}
    points = []
    for name in NAMES:
        rates: dict[int, list[float]] = {old: [], new: []}
        quality = []
        for k in range(len(peers.EXACT_RATES)):
            key = f"{name}_{k}"
            flat, planes, parents, blocks = (
                captured[key + s] for s in ("_flat", "_planes", "_parents", "_blocks")
            )
            blocks = with_levels(planes, blocks)
            sizes = {}
            for oriented in dict.fromkeys((old, new, 1)):
                data_, lengths = kernels.encode_span(
                    flat, planes, parents, oriented, blocks, 0, len(blocks)
                )
                sizes[oriented] = int(lengths.sum()) + table_bytes(flat, planes, blocks, lengths)
                if oriented in (old, new):
                    points.append((oriented, flat, planes, parents, blocks, data_, lengths))
            whole = int(captured[key + "_bytes"])
            for oriented in (old, new):  # the tuning capture was coded by version 7
                rates[oriented].append(whole - sizes[1] + sizes[oriented])
            quality.append(float(captured[key + "_psnr"]))
        out[name] = rate_distortion.bd_rate(rates[old], quality, rates[new], quality)
    grey = np.mean([out[n] for n in GREY])
    print(
        f"{wavelet}: version {pair[1]} against {pair[0]}: "
        + " ".join(f"{n} {v:+.2f} %" for n, v in out.items())
        + f" | grey {grey:+.2f} %",
        flush=True,
    )
    times: dict[tuple[str, int], list[float]] = {}
    for _ in range(rounds):
        for oriented in (old, new):
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
                        bad = kernels.decode_span(
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
                        assert bad == 0 and np.array_equal(target, flat)
                times.setdefault((what, oriented), []).append(time.process_time() - start)
    for what in ("encode", "decode"):
        a, b = (float(np.median(times[(what, o)])) for o in (old, new))
        print(
            f"  {what}_span: version {pair[0]} {a:.3f} s, version {pair[1]} {b:.3f} s "
            f"({b / a:.3f}x)"
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=("capture", "measure", "versions", "priors"))
    parser.add_argument("--wavelet", default="cdf97")
    parser.add_argument("--pictures", choices=tuple(PICTURES), default="tuning")
    parser.add_argument(
        "--pairs",
        nargs="+",
        default=["6,6"],
        help="measure: (fast, slow) shift limits, e.g. 6,6 (version 7's one rate) 4,7",
    )
    parser.add_argument("--collect", help="measure: write the early-use statistics here (.npy)")
    parser.add_argument("--init", help="measure: initial probabilities from this table (.npy)")
    parser.add_argument("--init-count", type=int, default=8)
    parser.add_argument("--sets", type=int, default=1, help="measure: initial models per level")
    parser.add_argument(
        "--versions", nargs=2, type=int, default=[7, 8], help="versions: the two compared"
    )
    parser.add_argument("--rounds", type=int, default=7, help="versions: timing rounds")
    options = parser.parse_args()
    if options.action == "capture":
        capture(options.wavelet, options.pictures)
    elif options.action == "versions":
        versions(options.wavelet, options.rounds, tuple(options.versions))
    elif options.action == "priors":
        write_priors(options)
    else:
        variant = _load_variant()  # compiled once (some 90 s)
        for pair in options.pairs:
            options.fast, options.slow = map(int, pair.split(","))
            measure(options, variant)


if __name__ == "__main__":
    sys.exit(main())
