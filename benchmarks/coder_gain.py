"""What a change to the block coder's probability models would gain, before it becomes a
coder version (issue 12).

Run with ``.venv/bin/python benchmarks/coder_gain.py capture`` once (a few minutes: it codes
the tuning pictures, camera, moon, coins, brick in grey and astronaut in colour, with
``encode_image(..., bpp=r)`` at the peers' 7 exact rates over 0.25–2 bpp, and keeps the
quantized coefficients each bundle holds), then
``.venv/bin/python benchmarks/coder_gain.py measure [--mix] [--init TABLE] ...`` per variant.

``measure`` codes those same integers again with a *variant* of the version-4 kernels
(``wavecore/_blockkernels.py``), built at run time from its source with the model functions
swapped, and prints the BD-rate of the variant against today's coder per picture.  Both code
the same integers, so each rate point keeps its PSNR and the BD-rate is the mean log ratio of
the whole bundles' bytes (header included).  The variants:

* ``--mix``: every context keeps two probabilities, one adapting fast (shift ``--fast``) and
  one slow (shift ``--slow``), both with today's count-based start, and codes with their
  mean (as AV1 and VVC do);
* ``--collect FILE``: write, per context, the 0s and 1s seen in the first ``--early``
  uses of that context in each block (the statistics a fresh block starts without);
* ``--init FILE``: start every context seen 20 times or more at the probability of that
  table (``--collect``'s), with the count ``--init-count`` (how much the start is trusted).

It is an experiment harness: nothing here is a format, and the variants are not decodable.
"""

from __future__ import annotations

import argparse
import importlib.util
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
WORK = Path(os.environ.get("CODER_GAIN_DIR", "/tmp/coder_gain"))

# The model functions of the variant: two probabilities per context (the second one slow),
# statistics of the early uses after the models, and initial models from a table.
_ADAPT = """@njit(nogil=True, cache=False, inline="always")
def _adapt(models, ctx, p, n, bit):
    m = 2 * ctx
    p1 = models[m] >> 8
    p2 = models[m + 1]
    if n < EARLY:
        models[STATS + 2 * ctx + bit] += 1
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
    if INIT:
        table = np.load(INIT)
        seen = table[:, 0] + table[:, 1]
        good = seen >= 20
        start = np.rint(PROB_ONE * (table[good, 0] + 0.5) / (seen[good] + 1))
        p[good] = np.clip(start, 64, PROB_ONE - 64)
        n[good] = INIT_COUNT
    out = np.zeros(4 * CONTEXTS, dtype=np.int32)
    out[0 : 2 * CONTEXTS : 2] = (p << 8) | n
    out[1 : 2 * CONTEXTS : 2] = p
    return out


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
        f"EARLY = {options.early}\n"
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
        "    models[:] = INITIAL_MODELS",
        "    models[: 2 * CONTEXTS] = INITIAL_MODELS[: 2 * CONTEXTS]",
    )
    src = src.replace(
        "    models = np.empty(CONTEXTS, dtype=np.int32)\n    scratch",
        "    models = np.zeros(4 * CONTEXTS, dtype=np.int32)\n    scratch",
        1,
    )
    src = src.replace(
        "    return out[:pos].copy(), lengths\n",
        "    return out[:pos].copy(), lengths, models[STATS:].copy()\n",
        1,
    )
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


def capture(wavelet: str) -> None:
    """Code the tuning pictures at the exact rates; keep each bundle's integers and PSNR."""
    original = kernels.decode_span
    seen: dict[str, tuple] = {}

    def recording(data_, starts, lengths, planes, blocks, flat, lo, hi):  # type: ignore[no-untyped-def]
        bad = original(data_, starts, lengths, planes, blocks, flat, lo, hi)
        seen["last"] = (flat, planes, blocks)
        return bad

    kernels.decode_span = recording
    out: dict[str, object] = {}
    try:
        for name in NAMES:
            image = getattr(data, name)()
            for k, rate in enumerate(peers.EXACT_RATES):
                bundle = wavecore.encode_image(image, wavelet=wavelet, bpp=rate)
                wavecore.decode(bundle)  # records the integers it holds
                flat, planes, blocks = seen.pop("last")
                key = f"{name}_{k}"
                out[key + "_flat"], out[key + "_planes"], out[key + "_blocks"] = (
                    flat.copy(),
                    planes,
                    blocks,
                )
                out[key + "_bytes"] = len(bundle)
                print(f"{name:10s} {rate:.3f} bpp {len(bundle):7d} bytes", flush=True)
    finally:
        kernels.decode_span = original
    WORK.mkdir(parents=True, exist_ok=True)
    np.savez(WORK / f"capture_{wavelet}.npz", **out)


def measure(options: argparse.Namespace) -> dict[str, float]:
    """BD-rate (percent) of the variant against the version-4 coder, per tuning picture."""
    variant = _load_variant(options)
    captured = np.load(WORK / f"capture_{options.wavelet}.npz")
    start = time.perf_counter()
    stats = np.zeros(1, dtype=np.int64)
    out = {}
    for name in NAMES:
        logs = []
        for k in range(len(peers.EXACT_RATES)):
            key = f"{name}_{k}"
            flat, planes, blocks = (captured[key + s] for s in ("_flat", "_planes", "_blocks"))
            today = int(kernels.encode_span(flat, planes, blocks, 0, len(blocks))[1].sum())
            _, lengths, counts = variant.encode_span(flat, planes, blocks, 0, len(blocks))  # type: ignore[attr-defined]
            stats = stats + counts.astype(np.int64)
            whole = int(captured[key + "_bytes"])
            logs.append(math.log((whole - today + int(lengths.sum())) / whole))
        out[name] = 100.0 * (math.exp(float(np.mean(logs))) - 1.0)
    if options.collect:
        np.save(options.collect, stats.reshape(-1, 2))
    grey = float(np.mean([out[n] for n in GREY]))
    load = Path("/proc/loadavg").read_text().split()[:3]
    print(
        " ".join(f"{n} {v:+.2f} %" for n, v in out.items())
        + f" | grey {grey:+.2f} %, colour {out['astronaut']:+.2f} %"
        + f"  ({time.perf_counter() - start:.0f} s, load {' '.join(load)})",
        flush=True,
    )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=("capture", "measure"))
    parser.add_argument("--wavelet", default="cdf97")
    parser.add_argument("--mix", action="store_true", help="two adaptation rates, mixed")
    parser.add_argument("--fast", type=int, default=4, help="--mix: the fast shift")
    parser.add_argument("--slow", type=int, default=7, help="--mix: the slow shift")
    parser.add_argument("--collect", help="write the early-use statistics here (.npy)")
    parser.add_argument("--early", type=int, default=24, help="--collect: uses per block")
    parser.add_argument("--init", help="initial probabilities from this table (.npy)")
    parser.add_argument("--init-count", type=int, default=4)
    options = parser.parse_args()
    if options.action == "capture":
        capture(options.wavelet)
    else:
        measure(options)


if __name__ == "__main__":
    sys.exit(main())
