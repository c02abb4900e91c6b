"""Idle and slow connections against a real server (``wavecore serve``'s uvicorn and protocol).

uvicorn alone keeps a connection that never finishes its headers for ever: 1 100 idle sockets
against a process limited to 1 024 descriptors stopped ``/healthz`` and filled the log with
failed accepts.  ``service.protocol`` closes such connections after ``header_timeout`` and
answers connections past ``max_connections`` with a 503 at once.  This server has a small cap
(40), a 3 s deadline and a limit of 256 descriptors, so the same attack is small and quick.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
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
    sockets = _open(url, CAP + 10)
    try:
        answers = []
        for sock in sockets:  # the held ones time out here; the refused ones have their answer
            sock.settimeout(0.2)
            try:
                answers.append(sock.recv(4096))
            except TimeoutError:
                answers.append(b"")
        refused = [a for a in answers if a]
        assert len(refused) >= 10
        for answer in refused:
            assert answer.startswith(b"HTTP/1.1 503") and b"Retry-After: " in answer
            assert b"urn:wavecore:problem:overloaded" in answer
    finally:
        for sock in sockets:
            sock.close()


def test_more_sockets_than_descriptors_do_not_stop_the_server(
    guarded_server: tuple[str, Path],
) -> None:
    """300 idle sockets against 256 descriptors: without the guards the server stops accepting
    and logs every failed accept; with them it answers once the idle ones reach their deadline."""
    url, log = guarded_server
    idle = _open(url, 300)
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


def _big_answer_request(url: str) -> tuple[bytes, int]:
    """A 353-byte bundle whose npy answer is 67 MB (a constant 2048² RGBA float32 picture)."""
    import numpy as np

    import wavecore

    bundle = wavecore.encode_image(np.full((2048, 2048, 4), 0.5, np.float32))
    return bundle, 2048 * 2048 * 4 * 4


def _ask_without_reading(url: str, bundle: bytes) -> socket.socket:
    """A socket that asks for ``bundle``'s npy answer and reads none of it (a small buffer)."""
    host, port = url.removeprefix("http://").split(":")
    sock = socket.create_connection((host, int(port)), timeout=30)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    head = (
        "POST /v1/bundles/reconstruct?format=npy HTTP/1.1\r\nHost: x\r\n"
        "Content-Type: application/vnd.wavecore.bundle\r\n"
        f"Content-Length: {len(bundle)}\r\n\r\n"
    )
    sock.sendall(head.encode() + bundle)
    return sock


def test_a_large_answer_arrives_whole_in_pieces(guarded_server: tuple[str, Path]) -> None:
    url, _ = guarded_server
    bundle, size = _big_answer_request(url)
    response = httpx.post(
        url + "/v1/bundles/reconstruct",
        params={"format": "npy"},
        content=bundle,
        headers={"content-type": "application/vnd.wavecore.bundle"},
        timeout=60,
    )
    assert response.status_code == 200 and len(response.content) > size


def test_a_client_that_does_not_read_its_answer_is_cut_and_frees_its_slot(
    guarded_server: tuple[str, Path],
) -> None:
    """The answer goes out in pieces while the request keeps its slot; a client that does not
    read is cut after the send deadline (35 such clients held 2.2 GB of the server for good)."""
    url, log = guarded_server
    bundle, _ = _big_answer_request(url)
    sock = _ask_without_reading(url, bundle)
    try:
        time.sleep(DEADLINE + 6.0)  # decode, then the send deadline
        metrics = httpx.get(url + "/metrics", timeout=5).text
        assert "wavecore_requests_in_flight 0.0" in metrics
        assert "did not read its" in log.read_text()  # ClientNotReading: the answer was cut
    finally:
        sock.close()


def _answer_bytes_held(url: str) -> float:
    metrics = httpx.get(url + "/metrics", timeout=5).text
    line = next(x for x in metrics.splitlines() if x.startswith("wavecore_answer_bytes_held "))
    return float(line.split()[1])


def _wait_for(condition: Callable[[], bool], seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, f"not within {seconds} s"
        time.sleep(0.1)


def test_answers_held_for_slow_readers_are_bounded(guarded_server: tuple[str, Path]) -> None:
    """Answers held while clients read them stay within WAVECORE_ANSWER_MEMORY_BYTES (100 MB
    here): with one 67 MB answer unread, a second gets a 503 naming the setting, and once the
    first is cut at its send deadline the second is served."""
    url, _ = guarded_server
    bundle, size = _big_answer_request(url)
    _wait_for(lambda: _answer_bytes_held(url) == 0, 20)  # any earlier test's answer cut
    sock = _ask_without_reading(url, bundle)

    def second() -> httpx.Response:
        return httpx.post(
            url + "/v1/bundles/reconstruct",
            params={"format": "npy"},
            content=bundle,
            headers={"content-type": "application/vnd.wavecore.bundle"},
            timeout=60,
        )

    try:
        _wait_for(lambda: _answer_bytes_held(url) >= size, 30)
        refused = second()
        assert refused.status_code == 503, refused.status_code
        assert "WAVECORE_ANSWER_MEMORY_BYTES" in refused.json()["detail"]
        assert refused.headers["retry-after"]
    finally:
        sock.close()
    _wait_for(lambda: _answer_bytes_held(url) == 0, 20)
    served = second()
    assert served.status_code == 200 and len(served.content) > size


def test_a_body_past_the_limit_gets_a_413_and_its_connection_closed(live_server: str) -> None:
    """A chunked body past WAVECORE_MAX_UPLOAD_BYTES (20 MiB) gets its 413 and the connection is
    closed, instead of the server reading on what the client keeps sending (until the header
    deadline, 10 s and tens of megabytes later)."""
    host, port = live_server.removeprefix("http://").split(":")
    refused_before = _count_413(live_server)
    sock = socket.create_connection((host, int(port)), timeout=5)
    sock.sendall(
        b"POST /v1/curves/encode HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        b"Transfer-Encoding: chunked\r\n\r\n"
    )
    chunk = b"%x\r\n" % 65536 + b"1" * 65536 + b"\r\n"
    answer = b""
    began = time.monotonic()
    sock.settimeout(0.005)
    try:
        while time.monotonic() - began < 8.0:
            sock.sendall(chunk)
            try:
                data = sock.recv(65536)
            except TimeoutError:
                continue
            if not data:
                break
            answer += data
    except OSError:  # reset or broken pipe: closed while we were still sending
        pass
    finally:
        sock.close()
    closed_after = time.monotonic() - began
    # The answer may be lost to the reset that closing mid-body brings; the server counts it.
    assert not answer or answer.startswith(b"HTTP/1.1 413"), answer[:100]
    assert _count_413(live_server) == refused_before + 1
    assert closed_after < 4.0, closed_after


def _count_413(url: str) -> float:
    metrics = httpx.get(url + "/metrics", timeout=5).text
    return sum(
        float(line.split()[-1])
        for line in metrics.splitlines()
        if line.startswith("wavecore_http_requests_total{") and 'status="413"' in line
    )
