"""Load benchmark of the service: N clients × M requests against a real server on loopback.

Starts ``uvicorn --factory service.app:create_app`` on a free port of 127.0.0.1 (or uses
``--url``, which must be a 127.0.0.1 address), then measures, for a 512 × 512 image
(scikit-image's camera, or a generated one when scikit-image is missing):

1. in process: the median time of ``wavecore.encode_image`` (and of Pillow's PNG read plus
   the encode, which is all the work a request does);
2. one client, sequential requests: the median request time, and its ratio to (1);
3. throughput: ``--sequential`` requests sent one after another by one client, then
   ``--clients`` concurrent clients × ``--requests`` each (requests per second, p50 / p99
   latency, errors), and the ratio of the two throughputs, measured back to back;
4. ``--memory-requests`` mixed requests (encode, reconstruct, inspect): the server's resident
   memory (RSS, from /proc, the server and all its descendants: the worker processes) at idle,
   after warm-up and every 10 %, to show it stays flat.

``--deadline`` measures instead what a request past its deadline leaves running: it starts a
server with ``WAVECORE_REQUEST_TIMEOUT=1``, sends a 2048 × 2048 RGB encode (several seconds of
work), and prints the CPU time and RSS of every worker process for 3 s after the 503.

``--env NAME=VALUE`` passes settings to the server; ``--server-root`` serves another checkout
of the project (e.g. ``git archive main``), to compare against it in the same conditions.

Every count and the total time are bounded.  Run::

    .venv/bin/python benchmarks/load.py                # the figures in docs/benchmarks.md
    .venv/bin/python benchmarks/load.py --clients 64 --requests 2 --memory-requests 200
    .venv/bin/python benchmarks/load.py --deadline
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import urlparse

import httpx
import numpy as np
from PIL import Image

import wavecore

ROOT = Path(__file__).resolve().parents[1]
MAX_CLIENTS = 256
MAX_REQUESTS = 5000


def test_image() -> np.ndarray:
    try:
        from skimage import data

        return np.asarray(data.camera())
    except ImportError:  # a smooth field with seeded noise, same size
        rng = np.random.default_rng(0)
        y, x = np.mgrid[:512, :512]
        base = 120 + 60 * np.sin(x / 23) * np.cos(y / 31) + rng.normal(0, 6, (512, 512))
        return np.clip(base, 0, 255).astype(np.uint8)


def png_bytes(image: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(image).save(out, format="PNG")
    return out.getvalue()


def descendants(pid: int) -> list[int]:
    """A process and all its descendants (uvicorn workers, the fork server, the coders)."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        for task in Path(f"/proc/{p}/task").glob("*/children"):
            with contextlib.suppress(FileNotFoundError, ProcessLookupError):
                todo += [int(c) for c in task.read_text().split()]
    return found


def proc_rss_mib(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except (FileNotFoundError, ProcessLookupError):
        pass
    return 0.0


def proc_cpu_seconds(pid: int) -> float | None:
    """User + system CPU time of a live process; ``None`` once it is gone (or a zombie)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    if fields[0] == "Z":
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def tree_cpu_seconds(pid: int | None) -> float:
    """CPU time spent so far by a process and its live descendants (0 without a pid)."""
    if pid is None:
        return 0.0
    return sum(proc_cpu_seconds(p) or 0.0 for p in descendants(pid))


def rss_mib(pid: int) -> float:
    """Resident memory of a process and all its descendants, in MiB."""
    return sum(proc_rss_mib(p) for p in descendants(pid))


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def start_server(
    workers: int, env: dict[str, str], root: Path = ROOT
) -> tuple[subprocess.Popen[bytes], str]:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "service.app:create_app", "--factory"]
        + ["--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"]
        + ["--workers", str(workers)],
        cwd=root,
        env={**os.environ, **env, "PYTHONPATH": str(root)},
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 180  # the workers warm up before the server answers
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/healthz", timeout=2).status_code == 200:
                return proc, url
        except httpx.TransportError:
            time.sleep(0.2)
    proc.kill()
    msg = "the server did not start within 180 s"
    raise RuntimeError(msg)


async def encode(client: httpx.AsyncClient, png: bytes) -> tuple[float, int, bytes]:
    start = time.perf_counter()
    r = await client.post("/v1/images/encode", files={"file": ("camera.png", png, "image/png")})
    return time.perf_counter() - start, r.status_code, r.content


async def concurrent(
    client: httpx.AsyncClient, png: bytes, clients: int, requests: int
) -> dict[str, float]:
    latencies: list[float] = []
    errors = 0

    async def one_client() -> None:
        nonlocal errors
        for _ in range(requests):
            seconds, status, _ = await encode(client, png)
            latencies.append(seconds)
            errors += status != 200

    start = time.perf_counter()
    await asyncio.gather(*(one_client() for _ in range(clients)))
    wall = time.perf_counter() - start
    return {
        "requests": len(latencies),
        "errors": errors,
        "rps": len(latencies) / wall,
        "p50": percentile(latencies, 50),
        "p99": percentile(latencies, 99),
        "wall": wall,
    }


async def memory_run(
    client: httpx.AsyncClient, png: bytes, bundle: bytes, total: int, pid: int | None
) -> tuple[list[tuple[int, float]], int]:
    """Mixed requests from 8 clients; RSS sampled every 10 %."""
    samples: list[tuple[int, float]] = []
    done = 0
    errors = 0
    step = max(1, total // 10)

    async def one(i: int) -> int:
        kind = i % 4
        if kind == 0:
            return (await encode(client, png))[1]
        if kind == 3:
            r = await client.post("/v1/bundles/inspect", content=bundle)
        else:
            params = {"keep": round(0.05 + 0.9 * (i % 7) / 6, 3)}
            r = await client.post("/v1/bundles/reconstruct", params=params, content=bundle)
        return r.status_code

    queue: asyncio.Queue[int] = asyncio.Queue()
    for i in range(total):
        queue.put_nowait(i)

    async def worker() -> None:
        nonlocal done, errors
        while not queue.empty():
            i = queue.get_nowait()
            errors += (await one(i)) != 200
            done += 1
            if pid is not None and done % step == 0:
                samples.append((done, rss_mib(pid)))

    await asyncio.gather(*(worker() for _ in range(8)))
    return samples, errors


async def run(args: argparse.Namespace, url: str, pid: int | None) -> list[str]:
    image = test_image()
    png = png_bytes(image)
    lines: list[str] = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    wavecore.encode_image(image)  # compile once
    bundle = wavecore.encode_image(image)
    timeout = httpx.Timeout(args.time_limit)
    limits = httpx.Limits(max_connections=MAX_CLIENTS, max_keepalive_connections=MAX_CLIENTS)
    async with httpx.AsyncClient(base_url=url, timeout=timeout, limits=limits) as client:
        idle = rss_mib(pid) if pid else None
        for _ in range(3):  # warm-up: the compiled kernels of the server process
            await encode(client, png)
        warm = rss_mib(pid) if pid else None

        # 1 and 2, interleaved so that other load on the machine hits both alike: in process
        # (encode alone, and Pillow's PNG read + encode), then one request, one at a time
        encode_times, read_encode_times, request_times = [], [], []
        for _ in range(args.repeat):
            t = time.perf_counter()
            wavecore.encode_image(image)
            encode_times.append(time.perf_counter() - t)
            t = time.perf_counter()
            wavecore.encode_image(np.asarray(Image.open(io.BytesIO(png))))
            read_encode_times.append(time.perf_counter() - t)
            seconds, status, _ = await encode(client, png)
            if status != 200:
                msg = f"encode failed with {status}"
                raise RuntimeError(msg)
            request_times.append(seconds)
        in_process = statistics.median(encode_times)
        in_process_read = statistics.median(read_encode_times)
        one_request = statistics.median(request_times)
        ratios = [r / e for r, e in zip(request_times, encode_times, strict=True)]

        # 3. throughput: one client in sequence, then concurrent clients, back to back, in
        # rounds, so that a change in the machine's other load hits both alike
        # (and the cores the server used: its CPU seconds over each phase's wall time)
        sequential_rps, concurrent_rps, round_ratios = [], [], []
        sequential_cores, concurrent_cores = [], []
        loads = []
        for _ in range(args.rounds):
            start, cpu = time.perf_counter(), tree_cpu_seconds(pid)
            for _ in range(args.sequential):
                await encode(client, png)
            wall = time.perf_counter() - start
            sequential_rps.append(args.sequential / wall)
            sequential_cores.append((tree_cpu_seconds(pid) - cpu) / wall)
            cpu = tree_cpu_seconds(pid)
            loads.append(await concurrent(client, png, args.clients, args.requests))
            concurrent_rps.append(loads[-1]["rps"])
            concurrent_cores.append((tree_cpu_seconds(pid) - cpu) / loads[-1]["wall"])
            round_ratios.append(concurrent_rps[-1] / sequential_rps[-1])
        load = {
            "rps": statistics.median(concurrent_rps),
            "requests": sum(x["requests"] for x in loads),
            "errors": sum(x["errors"] for x in loads),
            "p50": statistics.median(x["p50"] for x in loads),
            "p99": max(x["p99"] for x in loads),
        }

        # 4. memory over many requests
        samples, memory_errors = await memory_run(client, png, bundle, args.memory_requests, pid)
        after = rss_mib(pid) if pid else None

    say(f"image: 512×512 grey camera, PNG {len(png)} bytes; bundle {len(bundle)} bytes")
    say(f"in-process encode_image median:           {in_process * 1e3:8.1f} ms")
    say(f"in-process PNG read + encode_image median: {in_process_read * 1e3:8.1f} ms")
    say(f"one client, POST /v1/images/encode median: {one_request * 1e3:8.1f} ms")
    say(f"ratio request / in-process encode:         {one_request / in_process:8.3f}")
    say(f"ratio request / in-process read + encode:  {one_request / in_process_read:8.3f}")
    say(f"median of the paired ratios request / encode: {statistics.median(ratios):.3f}")
    rounds = f"{args.rounds} rounds"
    say(
        f"one client, {args.sequential} requests in sequence ({rounds}): "
        + ", ".join(f"{x:.2f}" for x in sequential_rps)
        + " requests/s"
    )
    say(
        f"{args.clients} clients × {args.requests} requests ({rounds}): "
        + ", ".join(f"{x:.2f}" for x in concurrent_rps)
        + f" requests/s; p50 {load['p50'] * 1e3:.0f} ms (median), p99 {load['p99'] * 1e3:.0f} ms "
        f"(max), errors {load['errors']} of {load['requests']:.0f}"
    )
    say(
        f"throughput ratio {args.clients} clients / one client in sequence, per round: "
        + ", ".join(f"{x:.2f}" for x in round_ratios)
        + f"; median {statistics.median(round_ratios):.2f}"
    )
    if pid:
        say(
            "cores used by the server (CPU s / wall s), sequential | concurrent, per round: "
            + ", ".join(
                f"{a:.2f} | {b:.2f}"
                for a, b in zip(sequential_cores, concurrent_cores, strict=True)
            )
        )
    if pid:
        trail = ", ".join(f"{n}: {m:.0f}" for n, m in samples)
        say(f"server RSS (MiB): idle {idle:.0f}, after warm-up {warm:.0f}, end {after:.0f}")
        say(f"RSS over {args.memory_requests} mixed requests (requests: MiB): {trail}")
        if len(samples) >= 4:
            later = [m for _, m in samples[len(samples) // 2 :]]
            say(
                f"RSS growth over the second half: {later[-1] - later[0]:+.1f} MiB "
                f"(max {max(later):.0f} MiB); memory-run errors {memory_errors}"
            )
    else:
        say(f"memory-run errors {memory_errors} (RSS not measured: --url without --pid)")
    return lines


async def deadline_run(url: str, pid: int) -> None:
    """One encode past a 1 s deadline: what its worker does after the 503."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[:2048, :2048]
    smooth = 120 + 60 * np.sin(x / 37)[:, :, None] * np.cos(y / 53)[:, :, None]
    image = np.clip(smooth + rng.normal(0, 8, (2048, 2048, 3)), 0, 255).astype(np.uint8)
    png = png_bytes(image)
    workers = descendants(pid)  # the server too: with threads, jobs run inside it
    before = {p: proc_cpu_seconds(p) for p in workers}
    async with httpx.AsyncClient(base_url=url, timeout=120) as client:
        start = time.perf_counter()
        r = await client.post("/v1/images/encode", files={"file": ("big.png", png, "image/png")})
        answered = time.perf_counter() - start
        print(f"2048×2048 RGB encode, WAVECORE_REQUEST_TIMEOUT=1: {r.status_code} after "
              f"{answered:.2f} s ({r.headers.get('content-type')})")  # fmt: skip
        # the job's worker: gone already, or still spending CPU
        busy = [
            p
            for p in workers
            if proc_cpu_seconds(p) is None or (proc_cpu_seconds(p) or 0) > (before[p] or 0) + 0.3
        ]
        print(f"processes of the server gone or that spent > 0.3 s CPU on the job: {busy}")
        for wait in (0.0, 0.1, 0.1, 0.1, 0.2, 0.5, 1.0, 1.0):
            await asyncio.sleep(wait)
            rows = []
            for p in busy:
                cpu = proc_cpu_seconds(p)
                state = "gone" if cpu is None else f"{cpu:.2f} s CPU, {proc_rss_mib(p):.0f} MiB"
                rows.append(f"{p}: {state}")
            print(f"  +{time.perf_counter() - start - answered:4.2f} s after the 503: "
                  + "; ".join(rows))  # fmt: skip
        small = {"file": ("s.png", png_bytes(image[:128, :128]))}
        for _ in range(3):
            start = time.perf_counter()
            r = await client.post("/v1/images/encode", files=small)
            took = time.perf_counter() - start
            print(f"a 128×128 encode after it: {r.status_code} in {took:.2f} s; "
                  f"server RSS {rss_mib(pid):.0f} MiB")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clients", type=int, default=32)
    parser.add_argument("--requests", type=int, default=2, help="per client and round")
    parser.add_argument("--rounds", type=int, default=3, help="sequential + concurrent rounds")
    parser.add_argument("--repeat", type=int, default=15, help="sequential timings")
    parser.add_argument("--sequential", type=int, default=8, help="per round, one client")
    parser.add_argument("--memory-requests", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=1, help="uvicorn processes")
    parser.add_argument("--url", help="an already running server on 127.0.0.1")
    parser.add_argument("--pid", type=int, help="its process id, to read its memory")
    parser.add_argument("--time-limit", type=float, default=900.0, help="seconds, in all")
    parser.add_argument("--env", action="append", default=[], help="NAME=VALUE for the server")
    parser.add_argument("--server-root", type=Path, default=ROOT, help="the checkout to serve")
    parser.add_argument("--deadline", action="store_true", help="the timed-out job's worker")
    args = parser.parse_args(argv)
    env = dict(item.split("=", 1) for item in args.env)
    if args.deadline:
        env["WAVECORE_REQUEST_TIMEOUT"] = "1"
    if not 1 <= args.clients <= MAX_CLIENTS:
        parser.error(f"--clients must be 1 to {MAX_CLIENTS}")
    total = (
        args.rounds * (args.clients * args.requests + args.sequential)
        + args.memory_requests
        + args.repeat
    )
    if total > MAX_REQUESTS:
        parser.error(f"at most {MAX_REQUESTS} requests in all, not {total}")
    proc = None
    if args.url:
        if urlparse(args.url).hostname not in ("127.0.0.1", "localhost"):
            parser.error("--url must be a loopback address (127.0.0.1)")
        url, pid = args.url.rstrip("/"), args.pid
    else:
        proc, url = start_server(args.workers, env, args.server_root)
        pid = proc.pid
    print(f"load average before: {Path('/proc/loadavg').read_text().strip()}", flush=True)
    try:
        if args.deadline:
            if pid is None:
                parser.error("--deadline needs the server's --pid")
            asyncio.run(asyncio.wait_for(deadline_run(url, pid), args.time_limit))
        else:
            asyncio.run(asyncio.wait_for(run(args, url, pid), args.time_limit))
        print(f"load average after: {Path('/proc/loadavg').read_text().strip()}")
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=10)
    return 0


if __name__ == "__main__":
    sys.exit(main())
