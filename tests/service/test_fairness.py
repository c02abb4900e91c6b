"""Clients share the workers and the slots (``service.work.FairDispatcher``, ``WorkPool.admit``).

First come, first served let one client's 66 costly requests fill every slot: another client's
small encode got a 503, then waited 70 s.  Waiting jobs now go round-robin between clients, and
a newcomer takes the slot of the newest waiting job of the client holding most.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pool_jobs
import pytest

import wavecore
from service.errors import Problem
from service.settings import Settings
from service.work import FairDispatcher, WorkPool, _Preempted, client_key

pytestmark = pytest.mark.anyio


async def _settle() -> None:
    for _ in range(5):
        await asyncio.sleep(0)


class _Jobs:
    """Jobs that wait for turns on a dispatcher, and the order in which they got them."""

    def __init__(self, dispatcher: FairDispatcher) -> None:
        self.dispatcher = dispatcher
        self.order: list[str] = []
        self.tasks: list[asyncio.Task[None]] = []

    async def add(self, name: str) -> asyncio.Task[None]:
        async def job() -> None:
            await self.dispatcher.acquire(name[0])  # the client is the name's first letter
            self.order.append(name)

        task = asyncio.create_task(job())
        self.tasks.append(task)
        await _settle()
        return task


async def test_turns_go_to_the_client_served_least_recently() -> None:
    dispatcher = FairDispatcher(1)
    jobs = _Jobs(dispatcher)
    await dispatcher.acquire("a")  # a runs; then a queues three more, b and c one each
    for name in ("a1", "a2", "a3", "b1", "c1"):
        await jobs.add(name)
    assert jobs.order == []
    client = "a"
    for _ in range(5):
        dispatcher.release(client)
        await _settle()
        client = jobs.order[-1][0]
    # first come, first served would be a1 a2 a3 b1 c1
    assert jobs.order == ["b1", "c1", "a1", "a2", "a3"]
    dispatcher.release(client)
    assert dispatcher.free == 1 and not dispatcher.running


async def test_a_freed_worker_goes_to_the_client_with_fewest_running() -> None:
    dispatcher = FairDispatcher(2)
    jobs = _Jobs(dispatcher)
    await dispatcher.acquire("a")
    await dispatcher.acquire("a")
    await jobs.add("a1")  # waiting since before b1
    await jobs.add("b1")
    dispatcher.release("a")
    await _settle()
    assert jobs.order == ["b1"]  # a still has one running, b none
    assert dispatcher.running == {"a": 1, "b": 1}


async def test_a_cancelled_wait_takes_no_turn() -> None:
    dispatcher = FairDispatcher(1)
    jobs = _Jobs(dispatcher)
    await dispatcher.acquire("a")
    gone = await jobs.add("b1")
    gone.cancel()
    await _settle()
    await jobs.add("c1")
    dispatcher.release("a")
    await _settle()
    assert jobs.order == ["c1"]
    dispatcher.release("c")
    assert dispatcher.free == 1 and not dispatcher.running


async def test_preempting_refuses_the_newest_waiting_job() -> None:
    dispatcher = FairDispatcher(1)
    jobs = _Jobs(dispatcher)
    await dispatcher.acquire("a")
    older = await jobs.add("a1")
    newer = await jobs.add("a2")
    assert dispatcher.preempt("a")
    await _settle()
    assert newer.done() and isinstance(newer.exception(), _Preempted)
    assert not older.done()
    assert dispatcher.preempt("a")
    assert not dispatcher.preempt("a")  # nothing of a's left waiting
    assert not dispatcher.preempt("b")
    await _settle()
    assert older.done() and isinstance(older.exception(), _Preempted)
    dispatcher.release("a")
    assert dispatcher.free == 1


def test_clients_are_told_apart_by_address() -> None:
    def key(host: str | None) -> str:
        return client_key({"client": (host, 5000) if host else None})

    assert key("192.0.2.7") == "192.0.2.7"
    assert key("192.0.2.7") != key("192.0.2.8")
    # one IPv6 host usually has a whole /64
    assert key("2001:db8:1:2::7") == key("2001:db8:1:2:ffff::1") == "2001:db8:1:2::/64"
    assert key("2001:db8:1:3::7") != key("2001:db8:1:2::7")
    assert key("::ffff:192.0.2.7") == "192.0.2.7"
    assert key(None) == ""
    assert key("testclient") == "testclient"  # not an address: as given


async def test_a_newcomer_takes_the_slot_of_the_biggest_holders_waiting_job(
    tmp_path: Path,
) -> None:
    pool = WorkPool(Settings(concurrency=1, queue_size=2))
    await asyncio.to_thread(pool.start)
    slots = [pool.admit("a") for _ in range(3)]
    assert all(slots) and pool.admit("a") is None  # one client alone may fill every slot
    running = asyncio.create_task(pool.run(slots[0], pool_jobs.spin, str(tmp_path / "p"), 1.5))
    waiting = [
        asyncio.create_task(pool.run(slot, pool_jobs.worker_pid)) for slot in slots[1:] if slot
    ]
    await asyncio.sleep(0.2)
    newcomer = pool.admit("b")
    assert newcomer is not None
    await _settle()
    refused = waiting[1]  # the newest
    assert refused.done()
    problem = refused.exception()
    assert isinstance(problem, Problem) and problem.status == 503
    assert problem.kind == "overloaded" and "Retry-After" in problem.headers
    slots[2].release()  # as the middleware does once the 503 is sent
    # b's job goes next, before a's older waiting one
    first_done: list[str] = []

    async def track(name: str, work: Any) -> None:
        await work
        first_done.append(name)

    await asyncio.gather(
        track("b", pool.run(newcomer, pool_jobs.worker_pid)),
        track("a", waiting[0]),
        running,
    )
    assert first_done == ["b", "a"]
    for slot in (slots[0], slots[1], newcomer):
        slot.release()
    assert pool.in_use == 0 and not pool.held
    assert pool.dispatch.free == 1


async def test_a_flood_from_one_address_does_not_hold_up_another(one_worker_server: str) -> None:
    """A real server, one worker and 5 queue places: 127.0.0.1 sends 10 decodes of about 0.4 s
    each; 127.0.0.2's small encode gets a 200 in a small part of the flood's time."""
    url = one_worker_server
    bundle = wavecore.encode_image(np.full((1024, 1024, 4), 77, np.uint8), lossless=True)
    points = np.random.default_rng(0).random((50, 2)).tolist()
    headers = {"content-type": "application/vnd.wavecore.bundle"}
    flooder = httpx.AsyncClient(base_url=url, timeout=120)
    other = httpx.AsyncClient(
        base_url=url,
        timeout=120,
        transport=httpx.AsyncHTTPTransport(local_address="127.0.0.2"),
    )
    async with flooder, other:
        began = time.monotonic()

        async def flood() -> int:
            params = {"keep": "0.5", "format": "png"}
            r = await flooder.post(
                "/v1/bundles/reconstruct", params=params, content=bundle, headers=headers
            )
            return r.status_code

        floods = [asyncio.create_task(flood()) for _ in range(10)]
        await asyncio.sleep(0.5)
        asked = time.monotonic()
        answer = await other.post("/v1/curves/encode", json={"points": points})
        waited = time.monotonic() - asked
        statuses = await asyncio.gather(*floods)
        flood_time = time.monotonic() - began
    assert answer.status_code == 200, answer.text
    assert statuses.count(200) >= 5, statuses  # the flood is served too
    # first come, first served: the encode waited for all five queued decodes (or got a 503)
    assert waited < flood_time / 3, (waited, flood_time)
