"""A 20 MB JSON body against a real server: /healthz latency and the server's memory meanwhile.

Starts ``uvicorn --factory service.app:create_app`` on a free port of 127.0.0.1 (one thread,
like the Deployment), warms it up, then for each body:

- resets the server's peak-RSS mark (``/proc/<pid>/clear_refs``) and notes its RSS;
- posts the body while another client asks ``/healthz`` every 20 ms;
- prints the post's status and time, the /healthz p50 / p99 / max, and the server's peak RSS
  growth (``VmHWM`` − RSS before) in MB and as a multiple of the body.

Bodies: a 1000 × 1000 height field of 17-digit floats (the largest grid, encoded: 200), and
a curve of 476 190 points (over the 200 000-point limit: parsed, then a 422).  Run::

    .venv/bin/python benchmarks/json_intake.py
"""

from __future__ import annotations

import json
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: /healthz every 20 ms until a line arrives on stdin; prints each latency in seconds.
PROBE = """
import sys, threading, time, httpx
stop = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), stop.set()), daemon=True).start()
with httpx.Client(base_url=sys.argv[1], timeout=30) as client:
    while not stop.is_set():
        start = time.perf_counter()
        client.get("/healthz").raise_for_status()
        print(time.perf_counter() - start)
        time.sleep(0.02)
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _status(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise KeyError(field)


def _bodies() -> dict[str, bytes]:
    rng = np.random.default_rng(0)
    grid = rng.random((1000, 1000)).tolist()
    curve = (rng.random((476_190, 2)) * 1000).tolist()
    return {
        "surface 1000 × 1000 (200)": json.dumps({"grid": grid}).encode(),
        "curve 476 190 points (422)": json.dumps({"points": curve}).encode(),
    }


def _tree(pid: int) -> list[int]:
    """The server and every process under it (the worker pool parses the bodies)."""
    pids, i = [pid], 0
    while i < len(pids):
        for task in Path(f"/proc/{pids[i]}/task").iterdir():
            pids += [int(c) for c in (task / "children").read_text().split()]
        i += 1
    return pids


def _measure(url: str, pid: int, path: str, body: bytes) -> str:
    pids = _tree(pid)
    for p in pids:
        Path(f"/proc/{p}/clear_refs").write_text("5")  # reset VmHWM to the current RSS
    # Each process's own peak, summed: an upper bound of the whole server's growth.
    before = sum(_status(p, "VmRSS") for p in pids)
    # The prober is its own process, so that this one's upload does not delay its timing.
    prober = subprocess.Popen(
        [sys.executable, "-c", PROBE, url], stdin=subprocess.PIPE, stdout=subprocess.PIPE
    )
    time.sleep(0.5)
    start = time.perf_counter()
    with httpx.Client(base_url=url, timeout=120) as client:
        r = client.post(path, content=body, headers={"content-type": "application/json"})
    elapsed = time.perf_counter() - start
    out, _ = prober.communicate(b"stop\n", timeout=30)
    latencies = [float(x) for x in out.split()]
    growth = sum(_status(p, "VmHWM") for p in pids) - before
    q = statistics.quantiles(latencies, n=100, method="inclusive")
    return (
        f"{len(body) / 1e6:.1f} MB -> {r.status_code} in {elapsed:.2f} s; /healthz "
        f"p50 {1000 * q[49]:.1f} ms, p99 {1000 * q[98]:.1f} ms, max {1000 * max(latencies):.1f} "
        f"ms ({len(latencies)} probes); peak RSS growth {growth / 1e6:.0f} MB "
        f"= {growth / len(body):.2f} x the body"
    )


def main() -> None:
    # ``--root DIR``: serve another checkout (e.g. the previous commit's, for a same-run ratio).
    root = Path(sys.argv[sys.argv.index("--root") + 1]) if "--root" in sys.argv else ROOT
    bodies = _bodies()
    port = _free_port()
    env = {**os.environ, "WAVECORE_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "service.app:create_app", "--factory"]
        + ["--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"],
        cwd=root,
        env={**env, "PYTHONPATH": str(root)},
    )
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.1)
        # Warm-up: compile the kernels and load every module once.
        small = {"grid": np.random.default_rng(1).random((64, 64)).tolist()}
        httpx.post(url + "/v1/surfaces/encode", json=small, timeout=60).raise_for_status()
        httpx.post(url + "/v1/curves/encode", json={"points": small["grid"]}, timeout=60)
        print(f"serving {root}; load average {Path('/proc/loadavg').read_text().split()[:3]}")
        for name, body in bodies.items():
            path = "/v1/surfaces/encode" if name.startswith("surface") else "/v1/curves/encode"
            print(f"{name}: {_measure(url, proc.pid, path, body)}")
    finally:
        proc.terminate()
        proc.wait(timeout=10)


if __name__ == "__main__":
    main()
