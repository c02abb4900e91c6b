"""Peak memory of one request per endpoint, per sample, at the worst shapes.

Each case runs in a fresh Python process: it builds the request's body, runs a small request of
the same kind once (so that the compiled kernels are loaded), gives the freed heap back
(``malloc_trim``, as a worker does after a job), notes its resident memory, resets
the kernel's peak mark (``/proc/self/clear_refs``), then runs the endpoint's job function (what
the server runs on a worker: parse, cost check, decode, code, answer) and reads the peak
(``VmHWM``).  It prints the growth in MiB, the samples the cost check counts for that request
(``service.cost``: the values after padding, times channels or coordinates, times 4 for a
detail transfer, ``4 (d + 1)`` per point of a curve of ``d`` coordinates), and the growth per
counted sample.  The shapes are the worst kinds (thin images and grids, long curves, deep
levels), up to the service's default limits (pixels, points, grid points).  docs/deploy.md,
"Memory per request", is this script's output::

    .venv/bin/python benchmarks/request_memory.py            # every case, one process each
    .venv/bin/python benchmarks/request_memory.py --case NAME
"""

from __future__ import annotations

import ctypes
import gc
import io
import json
import math
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _status(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise KeyError(field)


def _picture(height: int, width: int, channels: int = 0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:height, :width]
    base = 100 + 60 * np.sin(x / 37.0) * np.cos(y / 23.0)
    if channels:
        base = base[:, :, None] + np.arange(channels) * 20
    return np.clip(base + rng.normal(0, 6, base.shape), 0, 255).astype(np.uint8)


def _png(array: np.ndarray) -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(array).save(out, format="PNG", compress_level=1)
    return out.getvalue()


def _npy(array: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, array)
    return out.getvalue()


def _curve(n: int, d: int) -> np.ndarray:
    t = np.linspace(0, 40 * np.pi, n)
    cols = [np.cos(t) * (1 + t / 100), np.sin(t) * (1 + t / 100), t / 50][:d]
    return np.stack(cols, axis=1) + np.random.default_rng(1).normal(0, 1e-3, (n, d))


# name → (endpoint, builder of (job, args) for a given size, the samples the cost check counts)
Case = tuple[str, Callable[[bool], tuple[Callable[..., Any], tuple[Any, ...]]], int]


def _cases() -> dict[str, Case]:
    from wavecore_service.routes import bundles, curves, images, surfaces
    from wavecore_service.settings import Settings

    import wavecore

    settings = Settings()

    def image_case(h: int, w: int, c: int, **options: Any) -> Any:
        def build(small: bool) -> Any:
            shape = (8, 64) if small else (h, w)
            return images.encode_job, (_png(_picture(*shape, c)), dict(options), settings)

        return build

    def curve_case(n: int, d: int, **options: Any) -> Any:
        def build(small: bool) -> Any:
            points = _curve(64 if small else n, d).tolist()
            return curves.encode_job, (json.dumps({"points": points, **options}).encode(), settings)

        return build

    def transfer_case(n: int, level: int | None) -> Any:
        def build(small: bool) -> Any:
            source = _curve(64 if small else n, 2).tolist()
            body = {"source": source, "base": [[0, 0], [1, 0], [2, 1]], "level": level}
            if small:
                body["level"] = 2
            return curves.transfer_job, (json.dumps(body).encode(), settings)

        return build

    def surface_json_case(u: int, v: int, d: int) -> Any:
        def build(small: bool) -> Any:
            rng = np.random.default_rng(3)
            shape = (16, 16) if small else (u, v)
            grid = np.cumsum(rng.normal(size=(*shape, d) if d > 1 else shape), axis=0)
            return surfaces.encode_json_job, (
                json.dumps({"grid": grid.tolist()}).encode(),
                settings,
            )

        return build

    def surface_npy_case(u: int, v: int, d: int) -> Any:
        def build(small: bool) -> Any:
            rng = np.random.default_rng(4)
            shape = (16, 16, d) if small else (u, v, d)
            grid = np.cumsum(rng.normal(size=shape), axis=1)
            return surfaces.encode_npy_job, (_npy(grid), {}, settings)

        return build

    def reconstruct_case(h: int, w: int, c: int, keep: float | None, lossless: bool = False) -> Any:
        def build(small: bool) -> Any:
            shape = (16, 64) if small else (h, w)
            target: dict[str, Any] = {"lossless": True} if lossless else {"quality": 40}
            bundle = wavecore.encode_image(_picture(*shape, c), **target)
            return bundles.reconstruct_job, (bundle, keep, 0, "png", "", settings)

        return build

    def pad(n: int, level: int = 5) -> int:
        return wavecore.valid_length(n, level, "open")

    return {
        "image 2048x2048 grey": ("images/encode", image_case(2048, 2048, 0), pad(2048) ** 2),
        "image 1448x1448 RGB": ("images/encode", image_case(1448, 1448, 3), pad(1448) ** 2 * 3),
        "image 1448x1448 RGB lossless": (
            "images/encode",
            image_case(1448, 1448, 3, lossless=True),
            1448 * 1448 * 3,
        ),
        "image 2x16384 (thin)": ("images/encode", image_case(2, 1 << 14, 0), 8 * (1 << 14)),
        "image 16384x2 (thin)": ("images/encode", image_case(1 << 14, 2, 0), 8 * (1 << 14)),
        "image 2x2097152 (thin, the pixel limit)": (
            "images/encode",
            image_case(2, 1 << 21, 0),
            8 * (1 << 21),
        ),
        "image 1x4194304 lossless (thin, the pixel limit)": (
            "images/encode",
            image_case(1, 1 << 22, 0, lossless=True),
            1 << 22,
        ),
        "image 2097152x2 (tall, the pixel limit)": (
            "images/encode",
            image_case(1 << 21, 2, 0),
            8 * (1 << 21),
        ),
        "curve 10000x3": ("curves/encode", curve_case(10_000, 3), 4 * pad(10_000, 8) * 4),
        "curve 200000x3 (the point limit)": (
            "curves/encode",
            curve_case(200_000, 3),
            4 * pad(200_000, 8) * 4,
        ),
        "curve 10000x1": ("curves/encode", curve_case(10_000, 1), 4 * pad(10_000, 8) * 2),
        "curve 200000x1 (the point limit)": (
            "curves/encode",
            curve_case(200_000, 1),
            4 * pad(200_000, 8) * 2,
        ),
        "transfer 10000x2": ("curves/transfer", transfer_case(10_000, None), 4 * 20_000),
        "transfer 200000x2": ("curves/transfer", transfer_case(200_000, None), 4 * 400_000),
        "transfer 10000x2 level 11": (
            "curves/transfer",
            transfer_case(10_000, 11),
            4 * wavecore.fitting_length(10_000, 11) * 2,
        ),
        "surface JSON 1000x1000": ("surfaces/encode", surface_json_case(1000, 1000, 1), 0),
        "surface JSON 2x10000 (thin)": ("surfaces/encode", surface_json_case(2, 10_000, 1), 0),
        "surface JSON 2x500000 (thin, the grid limit)": (
            "surfaces/encode",
            surface_json_case(2, 500_000, 1),
            0,
        ),
        "surface .npy 600x600x3": ("surfaces/encode", surface_npy_case(600, 600, 3), 0),
        "reconstruct 1448x1448 RGB": (
            "bundles/reconstruct",
            reconstruct_case(1448, 1448, 3, None),
            pad(1448) ** 2 * 3,
        ),
        "reconstruct 1448x1448 RGB keep 0.5": (
            "bundles/reconstruct",
            reconstruct_case(1448, 1448, 3, 0.5),
            pad(1448) ** 2 * 3,
        ),
        "reconstruct 1448x1448 RGB lossless": (
            "bundles/reconstruct",
            reconstruct_case(1448, 1448, 3, None, lossless=True),
            1448 * 1448 * 3,
        ),
        "reconstruct 1448x1448 RGB lossless keep 0.5": (
            "bundles/reconstruct",
            reconstruct_case(1448, 1448, 3, 0.5, lossless=True),
            1448 * 1448 * 3,
        ),
    }


def _grid_samples(name: str) -> int:
    import wavecore

    dims = name.split()[2].split("x")
    u, v = int(dims[0]), int(dims[1])
    d = int(dims[2]) if len(dims) > 2 else 1
    level = max(1, min(5, math.floor(math.log2(max(min(u, v), 8) / 4))))
    fitted = [min(wavecore.valid_length(n, level, "open"), 2 * n + 64) for n in (u, v)]
    return fitted[0] * fitted[1] * d


def run_case(name: str) -> dict[str, Any]:
    endpoint, build, samples = _cases()[name]
    if not samples:
        samples = _grid_samples(name)
    job, args = build(True)
    job(*args)  # load and compile everything once
    job, args = build(False)
    # The freed heap of the set-up (the small request, the body's own making) back to the
    # system first, as a worker trims after a job: the library keeps freed memory for reuse
    # (wavecore._heap), and a job served from it would show no growth at all.
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    Path("/proc/self/clear_refs").write_text("5")
    before = _status("VmRSS")
    start = time.perf_counter()
    job(*args)
    elapsed = time.perf_counter() - start
    growth = _status("VmHWM") - before
    return {
        "case": name,
        "endpoint": endpoint,
        "samples": samples,
        "growth_mib": growth / 2**20,
        "bytes_per_sample": growth / samples,
        "seconds": elapsed,
    }


def main() -> None:
    if "--case" in sys.argv:
        print(json.dumps(run_case(sys.argv[sys.argv.index("--case") + 1])))
        return
    print(f"load average {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print("| endpoint | request | samples counted | peak growth | per sample | time |")
    print("|---|---|---|---|---|---|")
    for name in _cases():
        out = subprocess.run(
            [sys.executable, __file__, "--case", name],
            capture_output=True,
            text=True,
            cwd=ROOT,
            check=False,
            timeout=600,
        )
        if out.returncode:
            print(f"| {name} | failed: {out.stderr.strip().splitlines()[-1]} |")
            continue
        r = json.loads(out.stdout)
        print(
            f"| {r['endpoint']} | {r['case']} | {r['samples']:,} | {r['growth_mib']:.0f} MiB "
            f"| {r['bytes_per_sample']:.0f} B | {r['seconds']:.1f} s |"
        )


if __name__ == "__main__":
    main()
