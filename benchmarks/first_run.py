"""First-run times: what a new user waits for before numba's cache is filled, and after.

Each figure is measured in a new Python process, with ``NUMBA_CACHE_DIR`` pointing at a new
empty folder (the "cold" cache of a fresh clone), then again with that folder filled::

    .venv/bin/python benchmarks/first_run.py            # about 3-5 minutes on 2 busy cores

Prints a small table (and the load average before and after, since the machine is shared).
``--serve`` also starts ``wavecore serve`` on the filled cache and times its start, its first
request (a 512 x 512 RGB PNG encoded at 1 bpp) and the same request again.
"""

from __future__ import annotations

import argparse
import io
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FIRST_TRANSFORM = """
import time, numpy as np
t0 = time.perf_counter()
import wavecore
t1 = time.perf_counter()
x = np.random.default_rng(0).random((514, 514))
wavecore.waverec2(wavecore.wavedec2(x, level=3))
t2 = time.perf_counter()
print(f"{t1 - t0:.3f} {t2 - t1:.3f}")
"""

FIRST_CODEC = """
import time, numpy as np
import wavecore
t1 = time.perf_counter()
rgb = np.random.default_rng(1).integers(0, 256, (256, 256, 3), dtype=np.uint8)
wavecore.decode(wavecore.encode_image(rgb, quality=35))
print(f"{time.perf_counter() - t1:.3f}")
"""


def _python(code: str, env: dict[str, str]) -> list[float]:
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return [float(v) for v in out.stdout.split()]


def _timed(command: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, env=env, check=True, capture_output=True)
    return time.perf_counter() - start


def _serve(env: dict[str, str]) -> tuple[float, float, float]:
    """Seconds from start to "startup complete", of the first encode request, and of the
    faster of the next two (the same request: what it costs once nothing is left to load)."""
    import httpx
    import numpy as np
    from PIL import Image

    script = shutil.which("wavecore", path=str(Path(sys.executable).parent))
    if script is None:
        raise SystemExit("no wavecore console script next to this Python")
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = int(sock.getsockname()[1])
    with tempfile.TemporaryFile() as log:
        start = time.perf_counter()
        proc = subprocess.Popen(
            [script, "serve", "--port", str(port)], env=env, stdout=log, stderr=log
        )
        try:
            while True:
                log.seek(0)
                if b"Application startup complete" in log.read():
                    break
                if proc.poll() is not None:
                    raise SystemExit("wavecore serve exited")
                time.sleep(0.05)
            ready = time.perf_counter() - start
            y, x = np.mgrid[:512, :512]
            rgb = np.stack([x % 256, y % 256, (x + y) % 256], -1).astype(np.uint8)
            buf = io.BytesIO()
            Image.fromarray(rgb).save(buf, format="PNG")
            times = []
            for _ in range(3):
                t = time.perf_counter()
                r = httpx.post(
                    f"http://127.0.0.1:{port}/v1/images/encode",
                    files={"file": ("p.png", buf.getvalue())},
                    data={"bpp": "1"},
                    timeout=120,
                )
                r.raise_for_status()
                times.append(time.perf_counter() - t)
            return ready, times[0], min(times[1:])
        finally:
            proc.terminate()
            proc.wait(timeout=30)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--serve", action="store_true", help="also time wavecore serve")
    args = parser.parse_args()
    print(f"load average before: {Path('/proc/loadavg').read_text().split()[:3]}")
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        imp, transform = _python(FIRST_TRANSFORM, env)
        (codec,) = _python(FIRST_CODEC, env)
        print(f"cold cache: import {imp:.2f} s, first wavedec2+waverec2 {transform:.2f} s, "
              f"first encode_image+decode {codec:.2f} s")  # fmt: skip
        shutil.rmtree(cache)
        os.mkdir(cache)
        warm_cold = _timed([sys.executable, "-m", "wavecore.warmup"], env)
        warm_warm = _timed([sys.executable, "-m", "wavecore.warmup"], env)
        print(f"python -m wavecore.warmup: {warm_cold:.1f} s on an empty cache, "
              f"{warm_warm:.1f} s once filled (process start included)")  # fmt: skip
        imp, transform = _python(FIRST_TRANSFORM, env)
        (codec,) = _python(FIRST_CODEC, env)
        print(f"filled cache: import {imp:.2f} s, first wavedec2+waverec2 {transform:.2f} s, "
              f"first encode_image+decode {codec:.2f} s")  # fmt: skip
        if args.serve:
            ready, first, later = _serve(env)
            print(f"wavecore serve: ready after {ready:.1f} s (warm-up included); "
                  f"a 512x512 RGB PNG at 1 bpp: first request {first:.2f} s, "
                  f"the same again {later:.2f} s")  # fmt: skip
    print(f"load average after: {Path('/proc/loadavg').read_text().split()[:3]}")


if __name__ == "__main__":
    main()
