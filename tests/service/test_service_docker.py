"""The Dockerfile cannot be built here (no Docker engine): check what it promises instead.

Its set-up step is ``bash scripts/run.sh setup``, which CI runs on every build; these tests
pin the rest: slim Python 3.11 base, a non-root user, the health check (run here for real
against the live server) and ``wavecore serve`` as the command.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

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


def test_the_kernel_warm_up_runs() -> None:
    """The build's ``python -c`` step that fills the numba cache runs (here, with this venv)."""
    run = next(r for r in _instruction("RUN") if "scripts/run.sh setup" in r)
    code = re.search(r'python -c "(.*?)"', run).group(1)  # type: ignore[union-attr]
    assert "encode_curve" in code and "encode_surface" in code and "bpp" in code
    assert subprocess.run([sys.executable, "-c", code], timeout=300).returncode == 0
