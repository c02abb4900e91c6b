"""wavecore as a Zarr codec on dask.distributed: throughput, scaling, memory, ratio against peers.

Run with ``.venv/bin/python benchmarks/zarr_scale.py`` (the issue's 16 384 × 16 384 float32
field, 1 GiB) or ``--size 2048`` for a quick look; ``--pyramid 8192`` adds a synthesised RGB
image of that side written as a Zarr pyramid (``wavecore.scale.write_pyramid``).

The field is smooth (a sum of random plane waves whose amplitude falls as 1/f², fixed seed),
made chunk by chunk from the global coordinates, so it is never whole in memory.  It is written
into a Zarr store (format 3, the ``wavecore`` serializer) at ``max_error = 1e-3 × range``:

* once on a ``LocalCluster`` of 1 worker process and once on 2 (one thread each, and one
  library thread: ``WAVECORE_THREADS=1``), each after a warm-up that loads the compiled
  kernels; throughput = raw bytes / wall seconds of ``store``, per worker; parallel efficiency
  = throughput(2) / (2 × throughput(1));
* peak memory per worker: each worker samples its own resident set every 20 ms during the
  write (psutil); reported as the peak, and as the peak above the worker's resident set before
  the write, against the chunk's bytes (the target: ≤ 4 × chunk + a constant), for each
  worker apart (never summed), with the bytes of task results Dask held in it (chunks read
  and not yet coded); ``--trace`` adds each worker's allocations' peak (tracemalloc).  The
  field is made on a cluster of its own, so that the timed workers start alike, fresh; run two
  ``--chunk`` sizes to separate the bytes per chunk byte from the constant;
* the store is read back in parallel and its largest error over every value is checked
  against the bound;
* the peers code every chunk of the same field on the same cluster at the same bound:
  numcodecs' Zstd (lossless, level 3), and through imagecodecs ZFP (fixed accuracy), SZ3
  (absolute bound) and SPERR (point-wise error); their largest errors are measured too.

``--fit-chunks 512,1024,2048`` measures only the memory: one fresh worker writes the field in
chunks of each side, and a least-squares line through its resident rises over idle gives the
bytes per chunk byte and the constant apart, with the worker's MB per CPU-second.
``--worker-env NAME=VALUE`` (``NAME=`` unsets) changes the timed workers' environment on top of
``wavecore.scale.WORKER_CONFIG``, e.g. ``--worker-env MALLOC_ARENA_MAX=`` for glibc's default.

The machine may be shared: the load average is printed at the start and the end.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("WAVECORE_THREADS", "1")  # one thread per worker: scaling by workers

import dask.array as da
import numpy as np
import zarr
from dask.distributed import Client, LocalCluster

from wavecore.scale import local_cluster

SEED = 20261122
WAVES = 40


def _waves(seed: int) -> list[tuple[float, float, float, float]]:
    rng = np.random.default_rng(seed)
    waves = []
    for _ in range(WAVES):
        f = rng.uniform(1, 48)  # cycles over the whole field
        angle = rng.uniform(0, 2 * np.pi)
        waves.append((f * np.cos(angle), f * np.sin(angle), rng.uniform(0, 2 * np.pi), f**-2))
    return waves


def field_block(template: np.ndarray, size: int, chunk: int, block_id: tuple[int, int]) -> Any:
    """The field's values over one chunk (float32), from the global coordinates."""
    y0, x0 = block_id[0] * chunk, block_id[1] * chunk
    y = (y0 + np.arange(template.shape[0]))[:, None] / size
    x = (x0 + np.arange(template.shape[1]))[None, :] / size
    fy, fx, phase, amplitude = (np.array(v) for v in zip(*_waves(SEED), strict=True))
    # sin(Y + X) = sin Y cos X + cos Y sin X: each wave is separable, and the sum of the 40
    # waves is one (rows × 80) @ (80 × cols) product, ~100x faster than 40 full-size sines.
    wave_y = 2 * np.pi * fy * y + phase  # (rows, waves)
    wave_x = 2 * np.pi * fx[:, None] * x  # (waves, cols)
    rows = np.hstack([amplitude * np.sin(wave_y), amplitude * np.cos(wave_y)])
    cols = np.vstack([np.cos(wave_x), np.sin(wave_x)])
    return (rows @ cols).astype(np.float32)


def make_field(size: int, chunk: int) -> Any:
    template = da.empty((size, size), chunks=chunk, dtype=np.float32)
    return template.map_blocks(field_block, size, chunk, dtype=np.float32)


# --------------------------------------------------------------------------------------------
# Worker-side memory sampling
# --------------------------------------------------------------------------------------------


def start_sampling(dask_worker: Any, trace: bool = False) -> int:
    """Start sampling this worker's resident set (kept on the worker object between calls);
    ``trace``: also trace its allocations (tracemalloc: slower, so not in the timed runs)."""
    import tracemalloc

    import psutil

    if trace:
        tracemalloc.start()

    process = psutil.Process()
    baseline = process.memory_info().rss
    cpu = process.cpu_times()
    state = {"peak": baseline, "stop": False, "cpu": cpu.user + cpu.system, "held": 0, "at": 0}
    worker_state = getattr(dask_worker, "state", None)  # None: the process itself (no Dask)

    def run() -> None:
        while not state["stop"]:
            rss = process.memory_info().rss
            # The bytes of task results the worker holds (chunks read and not yet consumed,
            # or fetched from the other worker): Dask's "managed" memory, beside the codec's.
            held = int(worker_state.nbytes) if worker_state is not None else 0
            state["held"] = max(state["held"], held)
            if rss > state["peak"]:
                state["peak"], state["at"] = rss, held
            time.sleep(0.02)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    dask_worker.wavecore_sampler = (state, thread, baseline)
    return int(baseline)


def stop_sampling(dask_worker: Any) -> dict[str, int]:
    import tracemalloc

    import psutil

    state, thread, baseline = dask_worker.wavecore_sampler
    state["stop"] = True
    thread.join()
    traced = tracemalloc.get_traced_memory()[1] if tracemalloc.is_tracing() else 0
    tracemalloc.stop()
    cpu = psutil.Process().cpu_times()
    seconds = cpu.user + cpu.system - state["cpu"]
    return {
        "baseline": int(baseline),
        "peak": int(state["peak"]),
        "cpu_seconds": seconds,
        "held_max": int(state["held"]),
        "held_at_peak": int(state["at"]),
        "traced_peak": int(traced),
    }


def warm_up() -> bool:
    """Load what a worker's first chunk would: the compiled kernels, and Zarr's codec pipeline
    and Dask's array modules (a small array written and read), so that the time and the
    resident rise measured after it are the coding's, not first-use imports.  The probe is
    small, so the worker's heap is not grown to a full chunk's needs beforehand."""
    import dask.array  # noqa: F401  (the store tasks' module)

    from wavecore.zarr import decode_chunk, encode_chunk

    probe = field_block(np.empty((96, 80)), 1024, 96, (1, 1))
    config = {"max_error": 1e-3 * float(np.ptp(probe))}
    decode_chunk(encode_chunk(probe, config))
    with tempfile.TemporaryDirectory() as folder:
        array = zarr.create_array(
            folder,
            shape=probe.shape,
            chunks=(48, 40),
            dtype="float32",
            serializer={"name": "wavecore", "configuration": config},
            compressors=None,
        )
        array[:] = probe
        np.asarray(array[:])
    return True


# --------------------------------------------------------------------------------------------
# Peers, chunk by chunk on the cluster
# --------------------------------------------------------------------------------------------


def peer_chunk(source: str, chunk: int, block_id: tuple[int, int], bound: float) -> dict[str, Any]:
    """Every peer's bytes, largest error and seconds on one chunk of the stored raw field."""
    import imagecodecs
    import numcodecs

    y0, x0 = block_id[0] * chunk, block_id[1] * chunk
    data = np.ascontiguousarray(zarr.open_array(source, mode="r")[y0 : y0 + chunk, x0 : x0 + chunk])
    out: dict[str, Any] = {}
    coders = {
        "zstd": (lambda a: numcodecs.Zstd(level=3).encode(a), None),
        "zfp": (
            lambda a: imagecodecs.zfp_encode(a, level=bound, mode="a"),
            imagecodecs.zfp_decode,
        ),
        "sz3": (
            lambda a: imagecodecs.sz3_encode(a, mode="abs", abs=bound),
            lambda b: imagecodecs.sz3_decode(b, shape=data.shape, dtype=data.dtype),
        ),
        "sperr": (
            lambda a: imagecodecs.sperr_encode(a, level=bound, mode="pwe"),
            lambda b: imagecodecs.sperr_decode(b),
        ),
    }
    for name, (encode, decode) in coders.items():
        start = time.perf_counter()
        coded = bytes(encode(data))
        seconds = time.perf_counter() - start
        error = 0.0
        if decode is not None:
            back = np.asarray(decode(coded)).reshape(data.shape)
            error = float(np.max(np.abs(back.astype(np.float64) - data)))
        out[name] = {"bytes": len(coded), "error": error, "seconds": seconds}
    return out


# --------------------------------------------------------------------------------------------
# The runs
# --------------------------------------------------------------------------------------------


#: More environment for the timed workers (``--worker-env``), on top of ``WORKER_CONFIG``.
WORKER_ENV: dict[str, str | None] = {}


def cluster(workers: int) -> tuple[LocalCluster, Client]:
    c = local_cluster(workers, environ=WORKER_ENV, memory_limit=None)
    return c, Client(c)


def stored_bytes(store: Path) -> int:
    return sum(p.stat().st_size for p in store.rglob("*") if p.is_file() and p.name != "zarr.json")


def write_run(
    client: Client, source: Path, chunk: int, bound: float, store: Path, trace: bool = False
) -> dict[str, Any]:
    """Re-code the raw field at ``source`` into ``store``: the time is reading raw chunks,
    coding and writing them (the synthesis of the field, 15x the coding, is not timed)."""
    client.run(warm_up)
    field = da.from_zarr(str(source))
    target = zarr.create_array(
        store,
        shape=field.shape,
        chunks=(chunk, chunk),
        dtype="float32",
        serializer={"name": "wavecore", "configuration": {"max_error": bound}},
        compressors=None,
        overwrite=True,
    )
    client.run(start_sampling, trace=trace)
    start = time.perf_counter()
    field.store(target, lock=False)
    seconds = time.perf_counter() - start
    memory = client.run(stop_sampling)
    return {"seconds": seconds, "memory": list(memory.values())}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=16384, help="field side (default 16384)")
    parser.add_argument("--chunk", type=int, default=512, help="chunk side (default 512)")
    parser.add_argument("--workers", default="1,2", help="worker counts to time (default 1,2)")
    parser.add_argument("--no-peers", action="store_true", help="skip the peer codecs")
    parser.add_argument("--pyramid", type=int, default=0, help="also an RGB pyramid this side")
    parser.add_argument("--pyramid-tile", type=int, default=1024)
    parser.add_argument("--pyramid-lossless", action="store_true", help="lossless, not 40 dB")
    parser.add_argument(
        "--pyramid-max-error",
        type=float,
        default=0.0,
        help="code the pyramid to this max_error (the CLI's --max-error), not 40 dB",
    )
    parser.add_argument(
        "--memory-chunks",
        default="",
        help="only measure one process's peak memory coding chunks of these sides (256,512,1024)",
    )
    parser.add_argument(
        "--trace",
        action="store_true",
        help="also trace each worker's allocations (tracemalloc; slows the timed runs)",
    )
    parser.add_argument(
        "--fit-chunks",
        default="",
        help="only measure 1 worker's resident rise writing the field in chunks of these sides "
        "(512,1024) and fit bytes per chunk byte + a constant",
    )
    parser.add_argument(
        "--worker-env",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set (NAME= unsets) a variable in the timed workers' environment (repeatable)",
    )
    parser.add_argument("--json", type=Path, help="write the figures here too")
    parser.add_argument("--keep", type=Path, help="keep the stores in this folder")
    args = parser.parse_args(argv)

    load_start = Path("/proc/loadavg").read_text().split()[:3]
    print(f"load average at start: {' '.join(load_start)}; cpus: {os.cpu_count()}")
    for setting in args.worker_env:
        name, _, value = setting.partition("=")
        WORKER_ENV[name] = value or None
    if WORKER_ENV:
        print(f"workers' environment: {WORKER_ENV}")
    if args.memory_chunks:
        return memory_curve([int(n) for n in args.memory_chunks.split(",")])
    if args.fit_chunks:
        return worker_memory_fit(args.size, [int(n) for n in args.fit_chunks.split(",")])
    work = args.keep or Path(tempfile.mkdtemp(prefix="zarr_scale_"))
    work.mkdir(parents=True, exist_ok=True)
    size, chunk = args.size, args.chunk
    raw = size * size * 4
    chunk_bytes = chunk * chunk * 4
    results: dict[str, Any] = {"size": size, "chunk": chunk, "raw_bytes": raw}
    print(f"field {size}×{size} float32 ({raw / 2**20:.0f} MiB), chunks {chunk}×{chunk}")

    counts = [int(w) for w in args.workers.split(",")]
    runs: dict[int, Any] = {}
    # Synthesised once (its cost is many times the coding's), stored uncompressed, untimed, on
    # a cluster of its own: the timed runs' workers start alike, fresh (a worker that had made
    # the field would start with a heap already grown, and show a smaller rise).  The range,
    # the check of the bound and the peers read it from there.
    source = work / "field_raw.zarr"
    c, client = cluster(max(counts))
    try:
        make_field(size, chunk).to_zarr(str(source), overwrite=True, compressors=None)
        stored = da.from_zarr(str(source))
        low, high = (float(v) for v in da.compute(stored.min(), stored.max()))
    finally:
        client.close()
        c.close()
    bound = 1e-3 * (high - low)
    results.update(range=high - low, bound=bound)
    print(f"range {high - low:.6g}; max_error = 1e-3 × range = {bound:.6g}")
    for workers in counts:
        c, client = cluster(workers)
        try:
            store = work / f"wavecore_{workers}.zarr"
            run = write_run(client, source, chunk, results["bound"], store, args.trace)
            run["stored_bytes"] = stored_bytes(store)
            run["throughput_per_worker"] = raw / run["seconds"] / workers
            peaks = [m["peak"] for m in run["memory"]]
            cpu = sum(m["cpu_seconds"] for m in run["memory"])
            run["cpu_seconds"] = cpu
            run["throughput_per_cpu_second"] = raw / cpu
            run["cpu_share"] = cpu / (run["seconds"] * workers)
            above = [m["peak"] - m["baseline"] for m in run["memory"]]
            run["peak_rss_max"] = max(peaks)
            run["peak_above_baseline_max"] = max(above)
            runs[workers] = run
            print(
                f"{workers} worker(s): {run['seconds']:.1f} s, "
                f"{run['throughput_per_worker'] / 1e6:.2f} MB/s per worker; workers' CPU "
                f"{cpu:.1f} s ({run['cpu_share']:.0%} of their wall time; "
                f"{raw / cpu / 1e6:.2f} MB per CPU-second); "
                f"peak RSS per worker {max(peaks) / 2**20:.0f} MiB "
                f"({max(above) / 2**20:.0f} MiB above its idle size = "
                f"{max(above) / chunk_bytes:.1f} × the {chunk_bytes / 2**20:.0f} MiB chunk)"
            )
            # Each worker's own figures (not a sum over workers): its resident rise, and the
            # task results Dask held in it (chunks read or fetched and not yet coded), at most
            # and at the moment of its resident peak.
            for number, m in enumerate(run["memory"]):
                print(
                    f"  worker {number}: {(m['peak'] - m['baseline']) / 2**20:.1f} MiB above "
                    f"idle = {(m['peak'] - m['baseline']) / chunk_bytes:.1f} × the chunk; "
                    f"chunks held by Dask: at most {m['held_max'] / 2**20:.1f} MiB, "
                    f"{m['held_at_peak'] / 2**20:.1f} MiB at the resident peak"
                    + (
                        f"; allocations' peak {m['traced_peak'] / 2**20:.1f} MiB = "
                        f"{m['traced_peak'] / chunk_bytes:.1f} × the chunk"
                        if args.trace
                        else ""
                    )
                )
            if workers == counts[-1]:
                # Read back in parallel: the bound on every value.
                back = da.from_zarr(str(store)).astype(np.float64)
                exact = da.from_zarr(str(source)).astype(np.float64)
                worst = float(abs(back - exact).max().compute())
                results["largest_error"] = worst
                results["largest_error_over_bound"] = worst / results["bound"]
                print(f"largest error {worst:.6g} = {worst / results['bound']:.4f} × the bound")
                if not args.no_peers:
                    n = math.ceil(size / chunk)
                    futures = client.map(
                        peer_chunk,
                        [str(source)] * n * n,
                        [chunk] * n * n,
                        [(i, j) for i in range(n) for j in range(n)],
                        [results["bound"]] * n * n,
                    )
                    peers: dict[str, Any] = {}
                    for part in client.gather(futures):
                        for name, figures in part.items():
                            entry = peers.setdefault(name, {"bytes": 0, "error": 0.0, "seconds": 0})
                            entry["bytes"] += figures["bytes"]
                            entry["error"] = max(entry["error"], figures["error"])
                            entry["seconds"] += figures["seconds"]
                    results["peers"] = peers
        finally:
            client.close()
            c.close()
    results["runs"] = {str(k): v for k, v in runs.items()}
    ours = runs[counts[-1]]["stored_bytes"]
    results["ratio"] = raw / ours
    if 1 in runs and 2 in runs:
        speedup = runs[1]["seconds"] / runs[2]["seconds"]
        results["speedup_1_to_2"] = speedup
        results["efficiency_1_to_2"] = speedup / 2
        print(f"1 → 2 workers: speed-up {speedup:.2f}×, parallel efficiency {speedup / 2:.0%}")
        # On a shared machine the workers get what the others leave: the CPU time per MB
        # says what the coding itself costs, and its change from 1 to 2 workers what the
        # parallel run adds (scheduling, transfers); 100 % means none.
        cpu_efficiency = runs[1]["cpu_seconds"] / runs[2]["cpu_seconds"]
        results["cpu_efficiency_1_to_2"] = cpu_efficiency
        print(f"CPU seconds 1 worker / 2 workers: {cpu_efficiency:.0%} (100 %: no parallel cost)")
    print(f"\ncompression ratio at max_error {results['bound']:.4g} (raw {raw / 2**20:.0f} MiB):")
    print(f"  {'codec':<9} {'bytes':>12} {'ratio':>8} {'largest error / bound':>22} {'MB/s':>8}")
    print(f"  {'wavecore':<9} {ours:>12} {raw / ours:>8.1f} "
          f"{results['largest_error_over_bound']:>22.4f} "
          f"{runs[counts[-1]]['throughput_per_worker'] / 1e6:>8.2f}")  # fmt: skip
    for name, entry in results.get("peers", {}).items():
        rate = raw / entry["seconds"] / 1e6 if entry["seconds"] else float("inf")
        error = entry["error"] / results["bound"] if name != "zstd" else 0.0
        print(f"  {name:<9} {entry['bytes']:>12} {raw / entry['bytes']:>8.1f} "
              f"{error:>22.4f} {rate:>8.2f}")  # fmt: skip
        entry["ratio"] = raw / entry["bytes"]
    if "sz3" in results.get("peers", {}):
        print(f"  wavecore / SZ3 ratio: {results['ratio'] / results['peers']['sz3']['ratio']:.2f}")

    if args.pyramid:
        results["pyramid"] = pyramid_run(args, work)
    load_end = Path("/proc/loadavg").read_text().split()[:3]
    print(f"load average at end: {' '.join(load_end)}")
    results["load"] = {"start": load_start, "end": load_end}
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0


def memory_curve(sides: list[int]) -> int:
    """Peak memory while one chunk is coded, per chunk size, and the fitted bytes per chunk byte.

    Two measures: the resident set's rise above the process before the chunk (psutil, sampled
    every 20 ms), and the peak of the Python and NumPy allocations (tracemalloc, exact; not
    the compiled kernels' own scratch).  A least-squares line over the sizes separates the
    slope (bytes per chunk byte, the issue's "4 × the chunk") from the constant.
    """
    import tracemalloc
    from types import SimpleNamespace

    from wavecore.zarr import decode_chunk, encode_chunk

    warm_up()
    rows = []
    for side in sides:
        data = field_block(np.empty((side, side)), 4 * side, side, (1, 1))
        bound = 1e-3 * float(np.ptp(data))
        holder = SimpleNamespace()
        start_sampling(holder)
        tracemalloc.start()
        start = time.perf_counter()
        coded = encode_chunk(data, {"max_error": bound})
        seconds = time.perf_counter() - start
        traced = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        memory = stop_sampling(holder)
        decode_chunk(coded)
        above = memory["peak"] - memory["baseline"]
        rows.append((data.nbytes, above, traced))
        print(
            f"chunk {side}×{side} float32 ({data.nbytes / 2**20:.2f} MiB): resident peak "
            f"{above / 2**20:.1f} MiB above the process before it = {above / data.nbytes:.1f} × "
            f"the chunk; allocations' peak {traced / 2**20:.1f} MiB = "
            f"{traced / data.nbytes:.2f} ×; encode {seconds:.2f} s"
        )
    if len(rows) > 1:
        size = np.array([r[0] for r in rows], dtype=np.float64)
        for name, column in (("resident", 1), ("allocations", 2)):
            slope, constant = np.polyfit(size, [r[column] for r in rows], 1)
            print(
                f"{name}: {slope:.2f} bytes per chunk byte + {constant / 2**20:.1f} MiB "
                "(least squares over the sizes)"
            )
    print(f"load average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    return 0


def worker_memory_fit(size: int, sides: list[int]) -> int:
    """One worker's resident rise over its idle size while it writes the field, for each chunk
    side, and a least-squares line through them: bytes per chunk byte and a constant.

    Each side gets its own raw source (made on a cluster of its own) and a fresh worker, so
    every run starts alike; the CPU seconds are the worker's own (MB per CPU-second)."""
    rows = []
    raw = size * size * 4
    with tempfile.TemporaryDirectory(prefix="zarr_fit_") as folder:
        for side in sides:
            source = Path(folder) / f"raw_{side}.zarr"
            c = local_cluster(1, memory_limit=None)
            client = Client(c)
            try:
                make_field(size, side).to_zarr(str(source), overwrite=True, compressors=None)
                stored = da.from_zarr(str(source))
                low, high = (float(v) for v in da.compute(stored.min(), stored.max()))
            finally:
                client.close()
                c.close()
            c, client = cluster(1)
            try:
                run = write_run(client, source, side, 1e-3 * (high - low), Path(folder) / "w.zarr")
            finally:
                client.close()
                c.close()
            (memory,) = run["memory"]
            above = memory["peak"] - memory["baseline"]
            chunk_bytes = side * side * 4
            rate = raw / memory["cpu_seconds"] / 1e6
            rows.append((chunk_bytes, above, rate))
            print(
                f"chunk {side}² ({chunk_bytes / 2**20:.0f} MiB): {above / 2**20:.1f} MiB above "
                f"idle = {above / chunk_bytes:.1f} × the chunk; {rate:.1f} MB per CPU-second "
                f"({raw / run['seconds'] / 1e6:.1f} MB/s wall)"
            )
    if len(rows) > 1:
        slope, constant = np.polyfit([r[0] for r in rows], [r[1] for r in rows], 1)
        print(
            f"resident rise per worker: {slope:.2f} bytes per chunk byte + "
            f"{constant / 2**20:.1f} MiB (least squares over {len(rows)} chunk sizes)"
        )
    print(f"load average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    return 0


def pyramid_run(args: argparse.Namespace, work: Path) -> dict[str, Any]:
    from wavecore.scale import synthetic_rgb, write_pyramid

    side, tile = args.pyramid, args.pyramid_tile
    config: dict[str, Any] = {"psnr": 40.0}
    if args.pyramid_lossless:
        config = {"lossless": True}
    elif args.pyramid_max_error:
        config = {"max_error": args.pyramid_max_error}
    c, client = cluster(2)
    try:
        client.run(warm_up)
        image = synthetic_rgb(side, tile=tile, seed=SEED)
        client.run(start_sampling)
        start = time.perf_counter()
        info = write_pyramid(image, work / "pyramid.zarr", config=config, tile=tile)
        seconds = time.perf_counter() - start
        memory = list(client.run(stop_sampling).values())
    finally:
        client.close()
        c.close()
    raw = side * side * 3
    peak = max(m["peak"] for m in memory)
    above = max(m["peak"] - m["baseline"] for m in memory)
    print(
        f"\nRGB pyramid {side}×{side} ({raw / 2**20:.0f} MiB), tiles {tile}, {config}, 2 workers: "
        f"{seconds:.1f} s ({raw / seconds / 1e6:.2f} MB/s), {len(info.shapes)} levels, "
        f"stored {info.stored_bytes / 2**20:.1f} MiB (ratio {raw / info.stored_bytes:.1f}), "
        f"peak RSS per worker {peak / 2**20:.0f} MiB ({above / 2**20:.0f} MiB above idle)"
    )
    return {
        "side": side,
        "tile": tile,
        "config": config,
        "seconds": seconds,
        "levels": [list(s) for s in info.shapes],
        "stored_bytes": info.stored_bytes,
        "peak_rss_max": peak,
        "peak_above_baseline_max": above,
    }


if __name__ == "__main__":
    sys.exit(main())
