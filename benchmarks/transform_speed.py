"""Transform speed: wavecore's wavedec2 + waverec2 against PyWavelets, and the memory floor.

Run with ``.venv/bin/python benchmarks/transform_speed.py`` (``--size 1026`` for a quick look).
Everything is measured in one process and reported as medians of several runs, because the
machine this project is built on is shared and noisy; the ratios matter more than the seconds.

What is timed, for float64 and float32:

* ours: ``wavedec2`` + ``waverec2``, 5 levels, open boundary, on a ``(2**12 + 2)²`` image;
* PyWavelets: ``wavedec2`` + ``waverec2`` with ``"bior3.1"`` (the same four-tap filters up to
  a factor of √2), ``mode="symmetric"``, 5 levels, on a ``2**12``-square image;
* the memory-bandwidth floor: one ``np.copyto`` of the input (a read and a write of every
  sample) times the number of such full passes our algorithm makes (see ``PASSES``);
* peak extra memory of ours, from ``tracemalloc`` (NumPy reports its buffers to it), as a
  multiple of the input's size.  The coefficients (about 1× the input) and the reconstruction
  (1×) are part of it, so 2× is the least possible.

It also measures, in fresh subprocesses, the first call's cost: importing wavecore and running
a tiny ``wavedec2`` + ``waverec2``, with numba's on-disk cache cold and warm.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable

import numpy as np
import pywt

import wavecore

LEVELS = 5


def passes(levels: int) -> float:
    """Full read-and-write passes over the data that wavedec2 + waverec2 make.

    Each 2-D level is one fused pass in each direction: decomposition reads the level's input
    once and writes its four bands once; reconstruction reads the four bands and writes the
    finer coarse band once.  Level ``l`` works on 4**-(l-1) of the data, so the total is
    2 · (1 + 1/4 + … + 1/4**(levels-1)).
    """
    return 2 * sum(0.25**level for level in range(levels))


def time_once(func: Callable[[], object]) -> float:
    start = time.perf_counter()
    func()
    return time.perf_counter() - start


def interleaved_medians(
    contenders: dict[str, Callable[[], object]], rounds: int
) -> dict[str, float]:
    """Median time of each contender, timing every one of them once per round.

    Interleaving spreads the load of a shared machine evenly over the contenders, so their
    ratios stay meaningful even when the absolute times drift.
    """
    times: dict[str, list[float]] = {name: [] for name in contenders}
    for _ in range(rounds):
        for name, func in contenders.items():
            times[name].append(time_once(func))
    return {name: statistics.median(values) for name, values in times.items()}


def ours(image: np.ndarray) -> np.ndarray:
    return wavecore.waverec2(wavecore.wavedec2(image, "bspline2", "open", LEVELS))


def theirs(image: np.ndarray) -> np.ndarray:
    coeffs = pywt.wavedec2(image, "bior3.1", mode="symmetric", level=LEVELS)
    return pywt.waverec2(coeffs, "bior3.1", mode="symmetric")


def peak_extra(image: np.ndarray) -> float:
    tracemalloc.start()
    tracemalloc.reset_peak()
    ours(image)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / image.nbytes


FIRST_CALL = """
import time
start = time.perf_counter()
import numpy as np
import wavecore
wavecore.waverec2(wavecore.wavedec2(np.ones((66, 66), dtype=np.{dtype}), level=2))
print(time.perf_counter() - start)
"""


def first_call(cache_dir: str, dtype: str) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    out = subprocess.run(
        [sys.executable, "-c", FIRST_CALL.format(dtype=dtype)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip())


def plot(t: dict[str, float], path: str, n: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    names = ("float64", "float32")
    rows = [
        ("PyWavelets bior3.1", "pywt", "tab:gray"),
        ("wavecore bspline2", "ours", "tab:blue"),
        ("memory floor", "copyto", "tab:green"),
    ]
    for i, (label, key, colour) in enumerate(rows):
        scale = passes(LEVELS) if key == "copyto" else 1.0
        values = [t[f"{key} {name}"] * scale for name in names]
        bars = ax.barh([j * 4 + i for j in range(2)], values, color=colour, label=label)
        ax.bar_label(bars, fmt="%.3f s", padding=3, fontsize=8)
    ax.set_yticks([1, 5], [f"{name}" for name in names])
    ax.invert_yaxis()
    ax.set_xlabel("seconds, median (wavedec2 + waverec2, 5 levels)")
    ax.set_title(f"{n}x{n} image, {os.cpu_count()} cores (shared, noisy)", fontsize=10)
    ax.set_xlim(0, max(t.values()) * 1.25)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=4098, help="our image side (2**L*k + 2)")
    parser.add_argument("--repeat", type=int, default=9, help="rounds (runs per median)")
    parser.add_argument("--no-first-call", action="store_true", help="skip the compile timing")
    parser.add_argument("--plot", metavar="PNG", help="also draw the medians as a bar chart")
    args = parser.parse_args()
    n = args.size
    rng = np.random.default_rng(0)
    base = rng.random((n, n))
    print(f"wavecore.wavedec2 + waverec2, {LEVELS} levels, open, {n}x{n}; ", end="")
    print(f"pywt bior3.1 symmetric on {n - 2}x{n - 2}; median of {args.repeat} runs")
    print(f"threads: {os.environ.get('WAVECORE_THREADS') or os.cpu_count()}; ", end="")
    print("load average before: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    contenders: dict[str, Callable[[], object]] = {}
    for dtype in (np.float64, np.float32):
        name = np.dtype(dtype).name
        image = base.astype(dtype)
        peer = np.ascontiguousarray(image[: n - 2, : n - 2])
        dst = np.empty_like(image)
        ours(image)  # compile and warm the caches
        theirs(peer)
        err = np.max(np.abs(ours(image) - image)) / np.max(np.abs(image))
        print(f"{name}: max relative reconstruction error {err:.1e}; ", end="")
        print(f"peak extra memory {peak_extra(image):.2f}x the input")
        contenders[f"ours {name}"] = lambda image=image: ours(image)
        contenders[f"pywt {name}"] = lambda peer=peer: theirs(peer)
        contenders[f"copyto {name}"] = lambda image=image, dst=dst: np.copyto(dst, image)
    t = interleaved_medians(contenders, args.repeat)
    for name in ("float64", "float32"):
        floor = t[f"copyto {name}"] * passes(LEVELS)
        print(f"\n{name}")
        print(f"  ours    {t[f'ours {name}']:8.3f} s")
        print(f"  pywt    {t[f'pywt {name}']:8.3f} s   -> ours is ", end="")
        print(f"{t[f'pywt {name}'] / t[f'ours {name}']:5.2f}x faster")
        print(f"  floor   {floor:8.3f} s   (copyto {t[f'copyto {name}']:.4f} s x ", end="")
        print(
            f"{passes(LEVELS):.2f} passes) -> ours is {t[f'ours {name}'] / floor:5.2f}x the floor"
        )
    print("load average after: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    print(f"\nfloat32 is {t['ours float64'] / t['ours float32']:.2f}x faster than float64 (ours)")
    print(f"pywt: float32 is {t['pywt float64'] / t['pywt float32']:.2f}x faster than float64")
    if args.plot:
        plot(t, args.plot, n)
    if not args.no_first_call:
        with tempfile.TemporaryDirectory() as cache:
            cold = first_call(cache, "float64")
            warm = first_call(cache, "float64")
        print("\nfirst call (import + tiny wavedec2/waverec2, fresh process): ", end="")
        print(f"numba cache cold {cold:.1f} s, warm {warm:.2f} s")


if __name__ == "__main__":
    main()
