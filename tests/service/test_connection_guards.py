"""Idle and slow connections against a real server (``wavecore serve``'s uvicorn and protocol).

uvicorn alone keeps a connection that never finishes its headers for ever: 1 100 idle sockets
against a process limited to 1 024 descriptors stopped ``/healthz`` and filled the log with
failed accepts.  ``service.protocol`` closes such connections after ``header_timeout`` and
answers connections past ``max_connections`` with a 503 at once.  This server has a small cap
(40), a 3 s deadline and a limit of 128 descriptors, so the same attack is small and quick.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import httpx

# the server: ``guarded_server`` in tests/conftest.py
CAP, DEADLINE = 40, 3.0


def _open(url: str, count: int, first_bytes: bytes = b"") -> list[socket.socket]:
    host, port = url.removeprefix("http://").split(":")
    sockets = []
    for _ in range(count):
        sock = socket.create_connection((host, int(port)), timeout=5)
        if first_bytes:
            sock.sendall(first_bytes)
        sockets.append(sock)
    return sockets


def _closed_by_server(sock: socket.socket) -> bool:
    sock.settimeout(0.5)
    try:
        while chunk := sock.recv(4096):  # a 503 first, for the refused ones
            del chunk
    except TimeoutError:
        return False
    except OSError:
        return True
    return True


def test_idle_and_slow_headers_are_closed_after_the_deadline(
    guarded_server: tuple[str, Path],
) -> None:
    url, _ = guarded_server
    idle = _open(url, 10)
    slow = _open(url, 10, b"GET /healthz HTTP/1.1\r\nHost: x\r\n")  # never ends its headers
    time.sleep(DEADLINE + 1.0)
    try:
        assert all(_closed_by_server(sock) for sock in idle + slow)
    finally:
        for sock in idle + slow:
            sock.close()


def test_past_the_cap_a_connection_gets_a_503_at_once(guarded_server: tuple[str, Path]) -> None:
    url, _ = guarded_server
    idle = _open(url, CAP)
    try:
        refused = httpx.get(url + "/healthz", timeout=5)
        assert refused.status_code == 503 and refused.headers["retry-after"]
        assert refused.json()["type"] == "urn:wavecore:problem:overloaded"
    finally:
        for sock in idle:
            sock.close()


def test_more_sockets_than_descriptors_do_not_stop_the_server(
    guarded_server: tuple[str, Path],
) -> None:
    """150 idle sockets against 128 descriptors: without the guards the server stops accepting
    and logs every failed accept; with them it answers once the idle ones reach their deadline."""
    url, log = guarded_server
    idle = _open(url, 150)
    try:
        time.sleep(DEADLINE + 1.0)
        assert httpx.get(url + "/healthz", timeout=5).status_code == 200
    finally:
        for sock in idle:
            sock.close()
    assert "Too many open files" not in log.read_text()


def test_a_kept_alive_client_is_not_cut_between_requests(
    guarded_server: tuple[str, Path],
) -> None:
    url, _ = guarded_server
    with httpx.Client(base_url=url, timeout=10) as client:
        for _ in range(3):
            assert client.get("/healthz").status_code == 200
            time.sleep(2.0)  # 6 s in all, past the header deadline; within uvicorn's keep-alive
        response = client.post(
            "/v1/curves/encode", json={"points": [[0, 0], [1, 1], [2, 0], [3, 1]]}
        )
        assert response.status_code == 200
