"""Cost against size: time and peak memory per sample of every public entry point.

Each entry point runs over a range of sizes — images from 1 × 64 to 1 × 4 194 304 and squares,
curves of 10 to 200 000 points, grids — and the script prints, per entry point, the time and the
peak traced memory at each size, the slope of log(time) against log(n) over the largest sizes
(1.0 is linear; the target is at most 1.15), and the peak bytes per sample at the largest size.

Time is the best of a few runs (one run at the largest sizes); memory is the peak that
:mod:`tracemalloc` sees (NumPy reports its buffers to it) during a separate run, above what was
allocated before it.  The first run of each entry point at a small size compiles and warms up.

Run: ``python benchmarks/cost.py`` (a few minutes; ``--quick`` stops at 65 536 samples).
The machine may be shared: the script prints the load average next to the figures.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

import wavecore

RNG = np.random.default_rng(0)


def _image_row(n: int) -> np.ndarray:
    return RNG.integers(0, 256, (1, n), dtype=np.uint8)


def _image_column(n: int) -> np.ndarray:
    return RNG.integers(0, 256, (n, 1), dtype=np.uint8)


def _faint_column(n: int) -> np.ndarray:
    """Noise of amplitude 4: even the coarsest quantizer meets the default 40 dB."""
    return RNG.integers(0, 5, (n, 1), dtype=np.uint8)


def _image_square(n: int) -> np.ndarray:
    side = math.isqrt(n)
    y, x = np.mgrid[0:side, 0:side]
    smooth = 128 + 60 * np.sin(x / 17.0) * np.cos(y / 23.0)
    return np.clip(smooth + RNG.normal(0, 8, (side, side)), 0, 255).astype(np.uint8)


def _curve(n: int) -> np.ndarray:
    return np.cumsum(RNG.standard_normal((n, 2)), axis=0)


def _curve3(n: int) -> np.ndarray:
    return np.cumsum(RNG.standard_normal((n, 3)), axis=0)


def _signal(n: int) -> np.ndarray:
    return RNG.standard_normal(wavecore.valid_length(n, 1))


@dataclass
class Case:
    """One entry point: ``prepare(n)`` makes the input (not timed), ``run(input)`` the call."""

    name: str
    sizes: list[int]
    prepare: Callable[[int], Any]
    run: Callable[[Any], Any]
    #: The result is cached by size: time the first call only, and take its peak in it.
    cached: bool = False


ROWS = [64 << (2 * k) for k in range(10)]  # 64 … 16 777 216; trimmed per case
SQUARES = [8**2, 32**2, 128**2, 512**2, 1024**2, 2048**2]
CURVES = [10, 100, 1_000, 5_000, 20_000, 50_000, 200_000]
GRIDS = [8 * 8, 16 * 16, 64 * 64, 256 * 256, 512 * 512]


def _rows(limit: int) -> list[int]:
    return [n for n in ROWS if n <= limit]


def _encoded_row(n: int) -> bytes:
    return wavecore.encode_image(_image_row(n))


def _volume_of_points(n: int) -> np.ndarray:
    """A volume of ``n`` slices of 1 × 1: the 2-D core codes a plane per slice and band."""
    return np.cumsum(RNG.standard_normal((n, 1, 1)), axis=0).astype(np.float32)


def _fresh_norms() -> Callable[[int], Any]:
    """``basis_norms`` on a new length at every call: it caches by length, and a cached call
    would time nothing."""
    calls = itertools.count()

    def run(n: int) -> Any:
        return wavecore.basis_norms(n + 2 * next(calls))

    return run


CASES = [
    Case("encode_image 1×N", _rows(4_194_304), _image_row, wavecore.encode_image),
    Case("encode_image N×1", _rows(262_144), _image_column, wavecore.encode_image),
    Case(
        "encode_image N×2 bspline2",
        _rows(4_194_304),
        lambda n: RNG.integers(0, 256, (n // 2, 2), dtype=np.uint8),
        lambda a: wavecore.encode_image(a, wavelet="bspline2"),
    ),
    Case(
        "encode_image 1×N bpp=2",
        [n for n in _rows(1_048_576) if n >= 4096],  # smaller ones cannot reach 2 bpp
        _image_row,
        lambda a: wavecore.encode_image(a, bpp=2.0),
    ),
    Case(
        "encode_image 1×N keep=0.2",
        _rows(262_144),
        _image_row,
        lambda a: wavecore.encode_image(a, keep=0.2),
    ),
    Case("encode_image square", SQUARES, _image_square, wavecore.encode_image),
    Case(
        "decode 1×N keep=0.5",
        _rows(1_048_576),
        _encoded_row,
        lambda b: wavecore.decode(b, keep=0.5),
    ),
    Case("encode_image N×1 faint", _rows(262_144), _faint_column, wavecore.encode_image),
    Case(
        "encode_image N×1 faint quality=43",  # the searches' worst: see docs/benchmarks.md
        _rows(1_048_576),
        _faint_column,
        lambda a: wavecore.encode_image(a, quality=43.0),
    ),
    Case(
        "encode_image 1×N level=0",
        _rows(4_194_304),
        _image_row,
        lambda a: wavecore.encode_image(a, level=0),
    ),
    Case(
        "encode_image 1×N lossless",
        _rows(4_194_304),
        _image_row,
        lambda a: wavecore.encode_image(a, lossless=True),
    ),
    Case(
        "encode_image 1×N lossless fast",
        _rows(4_194_304),
        _image_row,
        lambda a: wavecore.encode_image(a, lossless=True, effort="fast"),
    ),
    Case(
        "encode_image N×1 lossless fast",
        _rows(4_194_304),
        _image_column,
        lambda a: wavecore.encode_image(a, lossless=True, effort="fast"),
    ),
    Case(
        "decode 1×N lossless fast",
        _rows(4_194_304),
        lambda n: wavecore.encode_image(_image_row(n), lossless=True, effort="fast"),
        wavecore.decode,
    ),
    Case(
        "decompose_image 8×N + reconstruct",  # the library refuses sides below 8
        [n for n in _rows(1_048_576) if n >= 256],
        lambda n: RNG.integers(0, 256, (8, n // 8), dtype=np.uint8),
        lambda a: wavecore.decompose_image(a).reconstruct(keep=0.5),
    ),
    Case("encode_curve", CURVES, _curve, wavecore.encode_curve),
    Case(
        "encode_curve tolerance",
        CURVES,
        _curve,
        lambda p: wavecore.encode_curve(p, tolerance=0.05),
    ),
    Case(
        "decompose_curve + reconstruct",
        CURVES,
        _curve,
        lambda p: wavecore.decompose_curve(p).reconstruct(keep=0.3),
    ),
    Case("resample_curve", CURVES, _curve, lambda p: wavecore.resample_curve(p, len(p) + 7)),
    Case(
        "transfer_details 2-D",
        CURVES,
        _curve,
        lambda p: wavecore.transfer_details(p, _curve(12)),
    ),
    Case(
        "transfer_details 3-D",
        CURVES,
        _curve3,
        lambda p: wavecore.transfer_details(p, _curve3(12)),
    ),
    Case(
        "remove_smallest (wavedec)",
        CURVES,
        lambda n: wavecore.wavedec(_signal(n)),
        lambda c: wavecore.remove_smallest(c, 0.5),
    ),
    Case("wavedec (all levels)", _rows(4_194_304), _signal, wavecore.wavedec),
    Case(
        "wavedec2 8×N (all levels)",
        _rows(1_048_576),
        lambda n: RNG.random((8, wavecore.valid_length(n // 8 + 8, 1))),
        wavecore.wavedec2,
    ),
    Case(
        "wavedec2 N×8 + waverec2",  # many short rows: the column kernels
        _rows(1_048_576),
        lambda n: RNG.random((wavecore.valid_length(n // 8 + 8, 1), 8)),
        lambda a: wavecore.waverec2(wavecore.wavedec2(a)),
    ),
    Case(
        "encode_surface square",
        GRIDS,
        lambda n: RNG.random((math.isqrt(n), math.isqrt(n), 3)),
        wavecore.encode_surface,
    ),
    Case(
        "encode_surface thin 8×N",
        _rows(262_144),
        lambda n: RNG.random((8, max(n // 8, 8), 3)),
        wavecore.encode_surface,
    ),
    Case(
        "decompose_surface thin + reconstruct",
        _rows(1_048_576),
        lambda n: RNG.random((max(n // 8, 8), 8)),
        lambda g: wavecore.decompose_surface(g).reconstruct(keep=0.5),
    ),
    Case(
        "encode_grid N×1×1 volume, bpp=2",
        [n for n in _rows(262_144) if n >= 1024],
        _volume_of_points,
        lambda g: wavecore.encode_grid(g, bpp=2.0),
    ),
    Case(
        "decode N×1×1 volume (cdf97, rmse)",
        [n for n in _rows(262_144) if n >= 1024],
        lambda n: wavecore.encode_grid(_volume_of_points(n), wavelet="cdf97", rmse=0.05),
        wavecore.decode,
    ),
    Case("basis_norms", _rows(4_194_304), lambda n: wavecore.valid_length(n, 1), _fresh_norms()),
]


def _samples(value: Any, n: int) -> int:
    """The number of samples the case works on (for bytes per sample)."""
    if isinstance(value, np.ndarray):
        return int(value.size)
    if isinstance(value, list):
        return int(sum(np.size(c) for c in value))
    return n


def _time(run: Callable[[Any], Any], value: Any, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        run(value)
        best = min(best, time.perf_counter() - start)
    return best


def _peak(run: Callable[[Any], Any], value: Any) -> int:
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        before, _ = tracemalloc.get_traced_memory()
        run(value)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return max(peak - before, 0)


def _slope(sizes: list[int], times: list[float]) -> float:
    """Least-squares slope of log(time) on log(n) over the largest sizes (the last four).

    Below a few milliseconds fixed costs and the memory hierarchy (data that fits a cache or
    not) move the slope more than the algorithm does, so read it with the times beside it.
    """
    xs, ys = np.log(sizes[-4:]), np.log(np.maximum(times[-4:], 1e-9))
    return float(np.polyfit(xs, ys, 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="sizes up to 65 536 only")
    parser.add_argument("--only", default="", help="run the cases whose name contains this")
    parser.add_argument("--start", default="", help="skip the cases before the one named so")
    args = parser.parse_args()
    load = os.getloadavg()
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"cores: {os.cpu_count()}, wavecore {wavecore.__version__}, numpy {np.__version__}\n")
    summary = []
    started = not args.start
    for case in CASES:
        started = started or case.name.startswith(args.start)
        if not started or (args.only and args.only not in case.name):
            continue
        sizes = [n for n in case.sizes if not args.quick or n <= 65_536]
        case.run(case.prepare(sizes[0]))  # compile and warm up
        times, peaks, counts = [], [], []
        print(f"{case.name}")
        for n in sizes:
            value = case.prepare(n)
            samples = _samples(value, n)
            if case.cached:
                start = time.perf_counter()
                peak = _peak(case.run, value)  # tracing slows Python code, not NumPy's
                seconds = time.perf_counter() - start
            else:
                seconds = _time(case.run, value, 3 if samples <= 100_000 else 1)
                peak = _peak(case.run, value)
            times.append(seconds)
            peaks.append(peak)
            counts.append(samples)
            print(
                f"  n = {samples:>10,}: {seconds * 1e3:10.1f} ms  "
                f"{seconds / samples * 1e9:9.1f} ns/sample  peak {peak / 2**20:8.1f} MiB  "
                f"{peak / samples:8.1f} B/sample",
                flush=True,
            )
        slope = _slope(counts, times)
        summary.append((case.name, counts[-1], times[-1], slope, peaks[-1] / counts[-1]))
    load = os.getloadavg()
    print(f"\nload average after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print("\n| entry point | largest n | time at largest | slope log t / log n | peak B/sample |")
    print("|---|---:|---:|---:|---:|")
    for name, n, seconds, slope, per_sample in summary:
        flag = "" if slope <= 1.15 else " ⚠"
        print(f"| {name} | {n:,} | {seconds:.3f} s | {slope:.2f}{flag} | {per_sample:.0f} |")


if __name__ == "__main__":
    main()
