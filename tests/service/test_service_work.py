"""The work pool: jobs that stop at the deadline, dead workers, body deadlines, settings.

The jobs run in the real worker processes of the pool (shared by the in-process apps of the
session); the body tests drive the app's ASGI interface directly, with a client that stalls.
"""

from __future__ import annotations

import asyncio
import os
import signal
import time
from pathlib import Path
from typing import Any

import pool_jobs
import pytest
from service_helpers import image_file, test_image

import wavecore
from service.app import create_app
from service.errors import Problem
from service.settings import Settings, SettingsError
from service.work import WorkPool, worker_threads

pytestmark = pytest.mark.anyio


def _alive(pid: int) -> bool:
    """Whether a process is still running (a zombie waiting to be reaped is not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):  # gone, or gone while being read
        return False
    return state != "Z"


async def _wait_until(condition: Any, seconds: float) -> float:
    """Seconds until ``condition()`` held, polling; fails past ``seconds``."""
    start = time.monotonic()
    while not condition():
        if time.monotonic() - start > seconds:
            pytest.fail(f"not within {seconds} s")
        await asyncio.sleep(0.02)
    return time.monotonic() - start


async def test_a_job_past_its_deadline_is_killed_and_its_slot_freed(tmp_path: Path) -> None:
    pool = WorkPool(Settings(request_timeout=3.0))
    await asyncio.to_thread(pool.start)  # warm workers, so the deadline is all the job's
    pid_file = tmp_path / "pid"
    slot = pool.admit()
    assert slot is not None
    began = time.monotonic()
    with pytest.raises(Problem) as caught:
        await pool.run(slot, pool_jobs.spin, str(pid_file), 60.0)
    assert caught.value.status == 503 and caught.value.kind == "timeout"
    assert "WAVECORE_REQUEST_TIMEOUT" in caught.value.detail
    assert time.monotonic() - began < 3.0 + 1.0
    pid = int(pid_file.read_text())
    # The worker that was spinning is ended (its CPU and memory with it) within about a second
    # of the 503, instead of spinning on for the 60 s the job asked for.
    await _wait_until(lambda: not _alive(pid), 1.5)
    slot.release()
    await _wait_until(lambda: pool.in_use == 0, 1.0)
    # and the pool still codes, on a fresh worker
    again = pool.admit()
    assert again is not None
    new_pid = await pool.run(again, pool_jobs.worker_pid)
    again.release()
    assert new_pid != pid and _alive(new_pid)
    # (no pool.shutdown(): the workers are shared with the other in-process apps of the run)


async def test_each_worker_gets_its_share_of_the_cores() -> None:
    """Busy workers must not fight over the cores: each runs the library on
    ``cores // concurrency`` threads (or on ``WAVECORE_THREADS`` when the operator set it)."""
    concurrency = Settings().concurrency
    pool = WorkPool(Settings())
    slot = pool.admit()
    assert slot is not None
    seen = await pool.run(slot, pool_jobs.library_threads)
    slot.release()
    assert seen == str(worker_threads(concurrency))
    if "WAVECORE_THREADS" not in os.environ:
        assert int(seen) == max(1, (os.cpu_count() or 1) // concurrency)


def test_worker_threads_share_out_the_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("WAVECORE_THREADS", raising=False)
    cores = os.cpu_count() or 1
    assert worker_threads(1) == cores
    assert worker_threads(cores) == 1
    assert worker_threads(4 * cores) == 1  # never none
    monkeypatch.setenv("WAVECORE_THREADS", "3")  # the operator's choice wins
    assert worker_threads(cores) == 3
    monkeypatch.setenv("WAVECORE_THREADS", "many")  # refused by Settings; here just ignored
    assert worker_threads(1) == cores


async def test_a_dead_worker_gives_a_503_and_is_replaced() -> None:
    pool = WorkPool(Settings())
    slot = pool.admit()
    assert slot is not None
    with pytest.raises(Problem) as caught:
        await pool.run(slot, pool_jobs.die)
    assert caught.value.status == 503 and caught.value.kind == "worker-lost"
    assert "exit code 3" in caught.value.detail and "Retry-After" in caught.value.headers
    assert isinstance(await pool.run(slot, pool_jobs.worker_pid), int)
    slot.release()
    await _wait_until(lambda: pool.in_use == 0, 1.0)


async def test_an_idle_worker_killed_from_outside_breaks_nothing() -> None:
    """pebble gives up a pool whose worker dies while idle; the next job gets a new pool."""
    pool = WorkPool(Settings(concurrency=1))
    slot = pool.admit()
    assert slot is not None
    victim = await pool.run(slot, pool_jobs.worker_pid)
    os.kill(victim, signal.SIGKILL)  # as the kernel's OOM killer might
    await _wait_until(lambda: not _alive(victim), 2.0)
    await asyncio.sleep(0.5)  # pebble's manager notices within its 0.1 s loop
    try:
        pid = await pool.run(slot, pool_jobs.worker_pid)
    except Problem as exc:  # a job caught in the breakage: a 503, then the pool is back
        assert exc.kind == "worker-lost", exc
        pid = await pool.run(slot, pool_jobs.worker_pid)
    assert pid != victim and _alive(pid)
    slot.release()
    pool.processes.stop()


async def test_memory_error_in_a_worker_gives_a_413() -> None:
    pool = WorkPool(Settings())
    slot = pool.admit()
    assert slot is not None
    with pytest.raises(Problem) as caught:
        await pool.run(slot, pool_jobs.run_out_of_memory)
    assert caught.value.status == 413 and caught.value.kind == "out-of-memory"
    slot.release()


def _rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


async def test_a_worker_gives_a_finished_jobs_memory_back(tmp_path: Path) -> None:
    """wavecore keeps freed arrays in glibc's heap for the next coding (wavecore._heap); a
    worker trims it after each job, so an idle worker stays small."""
    pool = WorkPool(Settings(concurrency=1))
    slot = pool.admit()
    assert slot is not None
    pid_file = tmp_path / "pid"
    assert await pool.run(slot, pool_jobs.allocate, str(pid_file), 64 << 20) == 1
    pid = int(pid_file.read_text())
    idle = _rss_mib(pid)
    # 192 MiB: under the heap's trim threshold, so glibc alone would keep it all
    assert await pool.run(slot, pool_jobs.allocate, str(pid_file), 192 << 20) == 3
    assert int(pid_file.read_text()) == pid
    assert _rss_mib(pid) < idle + 96
    slot.release()
    pool.processes.stop()


async def test_a_worker_keeps_a_small_jobs_freed_heap_for_the_next(tmp_path: Path) -> None:
    """Below KEEP_FREE_BYTES a job's freed heap is kept for the next one: trimmed after every
    512² encode, the next encode faulted its pages in again (3-5 ms, a fifth of its time).
    A large job in between is trimmed, and does not make every later job trim."""
    pool = WorkPool(Settings(concurrency=1))
    slot = pool.admit()
    assert slot is not None
    first = await pool.run(slot, pool_jobs.encode_faults)
    again = [await pool.run(slot, pool_jobs.encode_faults) for _ in range(3)]
    assert await pool.run(slot, pool_jobs.allocate, str(tmp_path / "pid"), 192 << 20) == 3
    assert await pool.run(slot, pool_jobs.encode_large) > 0
    after_large = [await pool.run(slot, pool_jobs.encode_faults) for _ in range(3)]
    slot.release()
    pool.processes.stop()
    assert min(again) < 300, (first, again)
    assert min(after_large) < 300, after_large


@pytest.mark.slow
async def test_a_worker_over_its_memory_cap_gives_a_413_and_shrinks_back(
    tmp_path: Path,
) -> None:
    """``WAVECORE_WORKER_MEMORY_BYTES`` caps each worker's address space (RLIMIT_AS)."""
    pool = WorkPool(Settings(concurrency=1, worker_memory_bytes=1 << 30))
    slot = pool.admit()
    assert slot is not None
    pid_file = tmp_path / "pid"
    assert await pool.run(slot, pool_jobs.allocate, str(pid_file), 128 << 20) == 2  # fits
    with pytest.raises(Problem) as caught:
        await pool.run(slot, pool_jobs.allocate, str(pid_file), 2 << 30)
    assert caught.value.status == 413 and caught.value.kind == "out-of-memory"
    assert "WAVECORE_WORKER_MEMORY_BYTES" in caught.value.detail
    pid = int(pid_file.read_text())
    assert _alive(pid) and _rss_mib(pid) < 512  # the same worker, its memory given back
    slot.release()
    pool.processes.stop()


async def test_exceptions_cross_back_from_the_workers() -> None:
    pool = WorkPool(Settings())
    slot = pool.admit()
    assert slot is not None
    # the library's own exceptions come back as themselves (the app maps them to problems)
    with pytest.raises(wavecore.BundleError):
        await pool.run(slot, wavecore.decode, b"not a bundle")
    # one that cannot be re-created on this side comes back as a RuntimeError naming it
    with pytest.raises(RuntimeError, match="TwoArgumentError: 7: seven is not accepted"):
        await pool.run(slot, pool_jobs.raise_unpicklable)
    slot.release()


async def _call_stalling(app: Any, path: str, first: bytes, total: int) -> tuple[int, bytes]:
    """Send ``first`` of a ``total``-byte body, then nothing: the response's status and body."""
    stalled = asyncio.Event()
    sent: list[dict[str, Any]] = []
    calls = 0

    async def receive() -> dict[str, Any]:
        nonlocal calls
        calls += 1
        if calls == 1:
            return {"type": "http.request", "body": first, "more_body": True}
        stalled.set()
        await asyncio.Event().wait()  # the rest never comes
        return {}

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "query_string": b"",
        "root_path": "",
        "headers": [
            (b"host", b"testserver"),
            (b"content-type", b"application/json"),
            (b"content-length", str(total).encode()),
        ],
        "client": ("127.0.0.1", 40000),
        "server": ("testserver", 80),
    }
    await app(scope, receive, send)
    assert stalled.is_set()
    start = next(m for m in sent if m["type"] == "http.response.start")
    body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    return start["status"], body


async def test_a_stalled_body_gets_a_408_within_the_deadline() -> None:
    app = create_app(Settings(body_timeout=0.5))
    began = time.monotonic()
    status, body = await _call_stalling(app, "/v1/curves/encode", b'{"points": [[0', 1000)
    waited = time.monotonic() - began
    assert status == 408, body
    assert b"urn:wavecore:problem:body-timeout" in body and b"WAVECORE_BODY_TIMEOUT" in body
    assert 0.5 <= waited < 1.5
    assert app.state.pool.in_use == 0 and app.state.pool.intake_bytes == 0


async def test_slow_bodies_hold_no_slot() -> None:
    """With one slot and no queue, ten stalled bodies still leave room for a real request."""
    import httpx

    app = create_app(Settings(concurrency=1, queue_size=0, body_timeout=5.0))
    stalled = [
        asyncio.create_task(_call_stalling(app, "/v1/curves/encode", b"{", 1000)) for _ in range(10)
    ]
    await asyncio.sleep(0.1)
    assert app.state.pool.in_use == 0
    assert app.state.pool.intake_bytes == 10  # one byte each, and nothing more is held
    png = image_file(test_image((64, 80)))
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://testserver") as client:
        r = await client.post("/v1/images/encode", files={"file": ("a.png", png, "image/png")})
    assert r.status_code == 200, r.text
    for task in stalled:
        task.cancel()
    await asyncio.gather(*stalled, return_exceptions=True)


async def test_bodies_arriving_at_once_are_bounded_in_bytes() -> None:
    """Bodies being read hold at most capacity × max_upload_bytes; past that, a quick 503."""
    import httpx

    app = create_app(Settings(concurrency=1, queue_size=0, max_upload_bytes=100))
    first = asyncio.create_task(_call_stalling(app, "/v1/curves/encode", b"x" * 70, 100))
    await asyncio.sleep(0.1)
    assert app.state.pool.intake_bytes == 70
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://testserver") as client:
        r = await client.post("/v1/curves/encode", content=b"y" * 40)
    assert r.status_code == 503 and "retry-after" in r.headers
    assert r.json()["type"] == "urn:wavecore:problem:overloaded"
    assert app.state.pool.intake_bytes == 70  # the refused body gave its bytes back
    first.cancel()
    await asyncio.gather(first, return_exceptions=True)
    assert app.state.pool.intake_bytes == 0


async def test_a_client_sending_less_takes_room_from_the_biggest_sender() -> None:
    """With the intake full of one client's bodies, another client's body takes the room of
    the first one's newest: one address cannot shut everyone out by sending slowly."""
    import httpx

    app = create_app(Settings(concurrency=1, queue_size=0, max_upload_bytes=100))
    first = asyncio.create_task(_call_stalling(app, "/v1/curves/encode", b"x" * 70, 100))
    await asyncio.sleep(0.1)
    assert app.state.pool.intake_bytes == 70
    body = b'{"points": [[0, 0], [1, 1], [2, 0], [3, 1]]}'
    assert 30 < len(body) < 70
    transport = httpx.ASGITransport(app=app, client=("127.0.0.2", 123))
    async with httpx.AsyncClient(transport=transport, base_url="http://testserver") as client:
        r = await client.post(
            "/v1/curves/encode", content=body, headers={"content-type": "application/json"}
        )
    assert r.status_code == 200, r.text
    status, answer = await asyncio.wait_for(first, 5)
    assert status == 503 and b"another that needed room" in answer
    assert app.state.pool.intake_bytes == 0 and not app.state.pool.reading


async def test_a_body_over_the_spool_size_arrives_whole() -> None:
    """Bodies over 1 MiB wait on disk and are replayed in pieces: the route sees all of it."""
    import httpx
    import numpy as np

    noise = np.random.default_rng(5).integers(0, 256, (600, 800, 3), dtype=np.uint8)
    png = image_file(noise)
    assert len(png) > 1 << 20
    app = create_app(Settings())
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://testserver") as client:
        files = {"file": ("noise.png", png, "image/png")}
        r = await client.post("/v1/images/encode", files=files, data={"keep": "0.05"})
    assert r.status_code == 200, r.text
    assert r.headers["x-wavecore-shape"] == "600x800x3"
    assert app.state.pool.in_use == 0 and app.state.pool.intake_bytes == 0


def test_concurrency_reads_the_new_variable_and_the_old_spelling(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("WAVECORE_CONCURRENCY", raising=False)
    monkeypatch.setenv("WAVECORE_THREADS", "3")
    assert Settings().concurrency == 3 and Settings().threads == 3
    monkeypatch.setenv("WAVECORE_CONCURRENCY", "5")  # the new name wins over the old one
    assert Settings().concurrency == 5 and Settings().capacity == 5 + Settings().queue_size
    assert Settings(threads=2).concurrency == 2  # the old keyword too


@pytest.mark.parametrize(
    ("variable", "value"),
    [
        ("WAVECORE_CONCURRENCY", "many"),
        ("WAVECORE_THREADS", "0"),
        ("WAVECORE_BODY_TIMEOUT", "-1"),
        ("WAVECORE_WORKER_MEMORY_BYTES", "1.5"),
        ("WAVECORE_MAX_PIXELS", ""),
    ],
)
def test_a_bad_setting_is_one_line_naming_the_variable(
    monkeypatch: pytest.MonkeyPatch, variable: str, value: str
) -> None:
    monkeypatch.delenv("WAVECORE_CONCURRENCY", raising=False)
    monkeypatch.setenv(variable, value)
    with pytest.raises(SettingsError) as caught:
        Settings.from_env()
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{variable}={value!r}: ")
    with pytest.raises(SettingsError):
        create_app()


async def test_an_answer_whose_send_fails_gives_its_memory_back() -> None:
    """A large answer reserves its bytes of ``answer_memory_bytes`` before its start goes out;
    a send that fails there (a connection torn down) must not keep them for ever, or every
    large answer after would get a 503."""
    from service.work import SPOOL_BYTES, AnswerMemory, _paced

    class Torn(Exception):
        pass

    async def send(message: dict[str, Any]) -> None:
        raise Torn

    memory = AnswerMemory(10 * SPOOL_BYTES)
    paced = _paced(send, 1.0, 5.0, memory)
    await paced({"type": "http.response.start", "status": 200, "headers": []})
    with pytest.raises(Torn):
        await paced({"type": "http.response.body", "body": bytes(3 * SPOOL_BYTES)})
    assert memory.held == 0
    assert memory.take(10 * SPOOL_BYTES) is not None and memory.take(SPOOL_BYTES) is None


async def test_an_answer_takes_the_room_of_the_biggest_holders_newest() -> None:
    """Past ``answer_memory_bytes``, a client's large answer cuts the newest answers of a client
    that would still hold more (its reader gets ClientNotReading), else it is refused."""
    from service.work import SPOOL_BYTES, AnswerMemory, ClientNotReading, _paced

    start = {"type": "http.response.start", "status": 200, "headers": []}

    def body(pieces: int) -> dict[str, Any]:
        return {"type": "http.response.body", "body": bytes(pieces * SPOOL_BYTES)}

    async def never_read(message: dict[str, Any]) -> None:
        if message["type"] == "http.response.body":
            await asyncio.Event().wait()

    memory = AnswerMemory(5 * SPOOL_BYTES)
    held_by_a = []
    for pieces in (3, 2):  # a holds the whole limit in two answers that nobody reads
        paced = _paced(never_read, 30.0, 60.0, memory, "a")
        await paced(start)
        held_by_a.append(asyncio.create_task(paced(body(pieces))))
        await _settle_loop()
    assert memory.held == 5 * SPOOL_BYTES
    sent: list[dict[str, Any]] = []

    async def read(message: dict[str, Any]) -> None:
        sent.append(message)

    paced_b = _paced(read, 30.0, 60.0, memory, "b")
    await paced_b(start)
    await asyncio.wait_for(paced_b(body(2)), 5)
    assert sum(len(m.get("body", b"")) for m in sent) == 2 * SPOOL_BYTES  # b's answer, whole
    with pytest.raises(ClientNotReading, match="make room"):
        await asyncio.wait_for(held_by_a[1], 5)  # a's newest was cut
    assert not held_by_a[0].done()
    # b holding nothing more now, a's 3 pieces are no more than b would hold with 3: refused
    assert memory.take(3 * SPOOL_BYTES, "b") is None
    held_by_a[0].cancel()
    await asyncio.gather(held_by_a[0], return_exceptions=True)
    assert memory.held == 0 and not memory.answers


async def _settle_loop() -> None:
    for _ in range(5):
        await asyncio.sleep(0)
