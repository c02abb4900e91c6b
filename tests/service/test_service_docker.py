"""The Dockerfile cannot be built here (no Docker engine): check what it promises instead.

Its set-up step is ``bash scripts/run.sh setup``, which CI runs on every build; these tests
pin the rest: slim Python 3.11 base, a non-root user, the health check (run here for real
against the live server) and ``wavecore serve`` as the command.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = (ROOT / "Dockerfile").read_text()


def _instruction(name: str) -> list[str]:
    joined = DOCKERFILE.replace("\\\n", " ")
    return [line.split(None, 1)[1] for line in joined.splitlines() if line.startswith(name + " ")]


def test_base_user_setup_and_command() -> None:
    assert _instruction("FROM") == ["python:3.11-slim"]
    assert any("bash scripts/run.sh setup" in run for run in _instruction("RUN"))
    users = _instruction("USER")
    assert users and users[-1] not in ("root", "0")
    command = json.loads(_instruction("CMD")[-1])
    assert command[-5:] == ["serve", "--host", "0.0.0.0", "--port", "8000"]
    assert command[0].endswith("/wavecore")
    # what the image copies is what the set-up needs, and .dockerignore keeps the rest out
    copied = {c.split()[0] for c in _instruction("COPY")}
    assert {"pyproject.toml", "scripts", "wavecore", "service"} <= copied
    ignored = (ROOT / ".dockerignore").read_text().split()
    assert ".venv" in ignored and ".git" in ignored


def test_healthcheck_command_works(live_server: str) -> None:
    check = _instruction("HEALTHCHECK")[-1]
    exec_form = json.loads(re.search(r"CMD\s+(\[.*\])", check).group(1))  # type: ignore[union-attr]
    assert exec_form[1] == "-c" and "/healthz" in exec_form[2]
    code = exec_form[2].replace("http://127.0.0.1:8000", live_server)
    assert subprocess.run([sys.executable, "-c", code], timeout=30).returncode == 0
    dead = exec_form[2].replace("127.0.0.1:8000", "127.0.0.1:9")  # nothing listens on port 9
    assert (
        subprocess.run([sys.executable, "-c", dead], capture_output=True, timeout=30).returncode
        != 0
    )


def test_the_image_compiles_every_kernel_for_a_portable_cpu() -> None:
    """The set-up step warms every kernel up (scripts/run.sh setup runs wavecore.warmup), for
    numba's generic CPU, at build and run time alike (numba keys its cache by the CPU)."""
    env = " ".join(_instruction("ENV")).split()
    assert "NUMBA_CPU_NAME=generic" in env and "NUMBA_CACHE_DIR=/opt/numba-cache" in env
    setup = (ROOT / "scripts" / "run.sh").read_text()
    block = setup[setup.index("    setup)") : setup.index(";;", setup.index("    setup)"))]
    assert "-m wavecore.warmup" in block


@pytest.mark.long
def test_the_warm_up_fills_a_generic_cpu_cache(tmp_path: Path) -> None:
    """What the build runs: ``python -m wavecore.warmup`` with the image's variables, into an
    empty cache; then a new process with the same variables encodes without compiling."""
    env = {**os.environ, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp_path)}
    run = subprocess.run(
        [sys.executable, "-m", "wavecore.warmup"], env=env, capture_output=True, text=True,
        timeout=1200,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "warm-up [1/" in run.stderr and "warm-up done" in run.stderr
    assert any(tmp_path.rglob("*.nbc")), "nothing was cached"
    check = (
        "import time, numpy as np, wavecore\n"
        "rgb = np.random.default_rng(0).integers(0, 256, (200, 300, 3), dtype=np.uint8)\n"
        "for _ in range(2):\n"
        "    t = time.perf_counter()\n"
        "    wavecore.decode(wavecore.encode_image(rgb, bpp=1.0))\n"
        "    print(time.perf_counter() - t)\n"
    )
    run = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    first, again = (float(v) for v in run.stdout.split())
    # Compiling the codec's kernels would add tens of seconds to the first call; loading them
    # from the cache adds a fraction of one (the bound is loose: the machine may be busy).
    assert first - again < 1.5, (first, again)
