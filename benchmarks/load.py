"""Load benchmark of the service: N clients × M requests against a real server on loopback.

Starts ``uvicorn --factory service.app:create_app`` on a free port of 127.0.0.1 (or uses
``--url``, which must be a 127.0.0.1 address), then measures, for a 512 × 512 image
(scikit-image's camera, or a generated one when scikit-image is missing):

1. in process: the median time of ``wavecore.encode_image`` (and of Pillow's PNG read plus
   the encode, which is all the work a request does);
2. one client, sequential requests: the median request time, and its ratio to (1);
3. ``--clients`` concurrent clients × ``--requests`` each: requests per second, p50 / p99
   latency, errors;
4. ``--memory-requests`` mixed requests (encode, reconstruct, inspect): the server's resident
   memory (RSS, from /proc) at idle, after warm-up and every 10 %, to show it stays flat.

Every count and the total time are bounded.  Run::

    .venv/bin/python benchmarks/load.py                # the figures in docs/benchmarks.md
    .venv/bin/python benchmarks/load.py --clients 64 --requests 2 --memory-requests 200
"""

from __future__ import annotations

import argparse
import asyncio
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


def rss_mib(pid: int) -> float:
    """Resident memory of a process and its children (uvicorn workers), in MiB."""
    total = 0
    pids = [pid]
    children = Path(f"/proc/{pid}/task/{pid}/children")
    if children.exists():
        pids += [int(p) for p in children.read_text().split()]
    for p in pids:
        try:
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
        except FileNotFoundError:
            pass
    return total / 1024


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def start_server(workers: int, env: dict[str, str]) -> tuple[subprocess.Popen[bytes], str]:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "service.app:create_app", "--factory"]
        + ["--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"]
        + ["--workers", str(workers)],
        cwd=ROOT,
        env={**os.environ, **env},
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/healthz", timeout=2).status_code == 200:
                return proc, url
        except httpx.TransportError:
            time.sleep(0.2)
    proc.kill()
    msg = "the server did not start within 60 s"
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

        # 3. concurrent clients
        load = await concurrent(client, png, args.clients, args.requests)

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
    say(
        f"{args.clients} clients × {args.requests} requests: {load['rps']:.2f} requests/s, "
        f"p50 {load['p50'] * 1e3:.0f} ms, p99 {load['p99'] * 1e3:.0f} ms, "
        f"errors {load['errors']} of {load['requests']:.0f}"
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clients", type=int, default=32)
    parser.add_argument("--requests", type=int, default=4, help="per client")
    parser.add_argument("--repeat", type=int, default=15, help="sequential timings")
    parser.add_argument("--memory-requests", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=1, help="uvicorn processes")
    parser.add_argument("--url", help="an already running server on 127.0.0.1")
    parser.add_argument("--pid", type=int, help="its process id, to read its memory")
    parser.add_argument("--time-limit", type=float, default=900.0, help="seconds, in all")
    args = parser.parse_args(argv)
    if not 1 <= args.clients <= MAX_CLIENTS:
        parser.error(f"--clients must be 1 to {MAX_CLIENTS}")
    total = args.clients * args.requests + args.memory_requests + args.repeat
    if total > MAX_REQUESTS:
        parser.error(f"at most {MAX_REQUESTS} requests in all, not {total}")
    proc = None
    if args.url:
        if urlparse(args.url).hostname not in ("127.0.0.1", "localhost"):
            parser.error("--url must be a loopback address (127.0.0.1)")
        url, pid = args.url.rstrip("/"), args.pid
    else:
        proc, url = start_server(args.workers, {})
        pid = proc.pid
    try:
        asyncio.run(asyncio.wait_for(run(args, url, pid), args.time_limit))
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=10)
    return 0


if __name__ == "__main__":
    sys.exit(main())
