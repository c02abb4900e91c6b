"""Fixtures shared by the whole test suite.

``live_server`` is a real uvicorn process serving ``service.app:create_app`` on a free port of
127.0.0.1, started once per session (the service tests and the browser tests both use it).
Its settings come from ``WAVECORE_*`` variables given to the process; it logs to a file that
is printed if it fails to start.
"""

from __future__ import annotations

import os
import resource
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


# Modules of a minute or more that are whole `long` runs (64 concurrent clients, a busy pool),
# marked here so that the default run leaves them out without editing them.
LONG_MODULES = {"test_service_concurrency.py"}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Marks the tests of ``LONG_MODULES`` ``long`` (before ``-m`` selects)."""
    for item in items:
        if item.path.name in LONG_MODULES:
            item.add_marker(pytest.mark.long)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def start_server(
    log: Path,
    env: dict[str, str] | None = None,
    timeout: float = 300.0,
    descriptors: int | None = None,
) -> tuple[subprocess.Popen[bytes], str]:
    """Start the service as ``wavecore serve`` runs it (uvicorn with the service's connection
    guards, ``service.protocol``; no warm-up) and wait for ``/healthz``.

    ``/healthz`` answers once every worker is warm, and the first server of a run on a clean
    clone warms them by compiling numba's kernels (a minute or two on a loaded machine; CI
    once took more than 60 s): ``timeout`` is the pool's own bound, ``service.work.WARM_TIMEOUT``.
    """
    import httpx

    port = free_port()

    def limit_descriptors() -> None:  # in the child, before it runs the server
        if descriptors is not None:
            resource.setrlimit(resource.RLIMIT_NOFILE, (descriptors, descriptors))

    with log.open("wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve", "--no-warm-up"]
            + ["--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"],
            cwd=ROOT,
            stdout=out,
            stderr=subprocess.STDOUT,
            env={**os.environ, **(env or {})},
            preexec_fn=limit_descriptors,
        )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + timeout
    while True:
        if proc.poll() is not None:
            msg = f"the server exited with {proc.returncode}:\n{log.read_text()}"
            raise RuntimeError(msg)
        try:
            if httpx.get(url + "/healthz", timeout=2).status_code == 200:
                return proc, url
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            stop_server(proc)
            msg = f"the server did not answer on {url} within {timeout} s:\n{log.read_text()}"
            raise RuntimeError(msg)
        time.sleep(0.1)


def stop_server(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _served(
    tmp_path_factory: pytest.TempPathFactory,
    name: str,
    env: dict[str, str] | None = None,
    descriptors: int | None = None,
) -> Iterator[tuple[str, Path]]:
    """A real server for a session fixture: its URL and its log, stopped afterwards."""
    pytest.importorskip("service.app", reason="the service extra is not installed")
    log = tmp_path_factory.mktemp(name) / "uvicorn.log"
    try:
        proc, url = start_server(log, env=env, descriptors=descriptors)
    except RuntimeError as exc:
        pytest.fail(str(exc))
    try:
        yield url, log
    finally:
        stop_server(proc)


@pytest.fixture(scope="session")
def live_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL (``http://127.0.0.1:<port>``) of a real uvicorn process with default settings."""
    for url, _ in _served(tmp_path_factory, "live-server"):
        yield url


@pytest.fixture(scope="session")
def guarded_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    """A server with a small connection cap (40), 3 s deadlines for headers and for reading an
    answer, 100 MB for answers held, and 256 descriptors
    (tests/service/test_connection_guards.py); its URL and its log."""
    env = {
        "WAVECORE_MAX_CONNECTIONS": "40",
        "WAVECORE_HEADER_TIMEOUT": "3",
        "WAVECORE_SEND_TIMEOUT": "3",
        "WAVECORE_ANSWER_MEMORY_BYTES": "100000000",  # one 67 MB answer, not two
    }
    yield from _served(tmp_path_factory, "guarded-server", env, descriptors=256)


@pytest.fixture(scope="session")
def small_limit_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A second real server that accepts at most 100 kB per request (for 413 messages)."""
    env = {"WAVECORE_MAX_UPLOAD_BYTES": "100000"}
    for url, _ in _served(tmp_path_factory, "small-limit-server", env):
        yield url


@pytest.fixture(scope="session")
def one_worker_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A real server with one worker and five queue places (tests/service/test_fairness.py)."""
    env = {"WAVECORE_CONCURRENCY": "1", "WAVECORE_QUEUE_SIZE": "5"}
    for url, _ in _served(tmp_path_factory, "one-worker-server", env):
        yield url
