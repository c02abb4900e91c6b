"""64 concurrent clients, in process and against the live server: every one succeeds; and
(slow) 70 clients trickling their bodies do not stop a normal request."""

from __future__ import annotations

import asyncio

import httpx
import numpy as np
import pytest
from service_helpers import image_file, test_image

import wavecore

pytestmark = pytest.mark.anyio

CLIENTS = 64


async def test_64_concurrent_encodes_all_succeed(client: httpx.AsyncClient) -> None:
    images = [test_image((64, 80), seed=i) for i in range(CLIENTS)]

    async def one(i: int) -> httpx.Response:
        files = {"file": (f"{i}.png", image_file(images[i]), "image/png")}
        return await client.post("/v1/images/encode", files=files, data={"quality": "35"})

    responses = await asyncio.gather(*(one(i) for i in range(CLIENTS)))
    statuses = [r.status_code for r in responses]
    assert statuses == [200] * CLIENTS, statuses
    # each client got its own image's bundle back
    for image, r in zip(images, responses, strict=True):
        decoded = wavecore.decode(r.content)
        assert decoded.shape == image.shape
        assert np.sqrt(np.mean((decoded.astype(float) - image) ** 2)) < 255 * 10 ** (-35 / 20)
    metrics = (await client.get("/metrics")).text
    assert "wavecore_requests_in_flight 0.0" in metrics


async def test_health_answers_while_the_pool_is_busy(client: httpx.AsyncClient) -> None:
    big = image_file(test_image((512, 512), seed=7))
    loop = asyncio.get_running_loop()
    began = loop.time()
    work = [
        asyncio.create_task(client.post("/v1/images/encode", files={"file": ("b.png", big)}))
        for _ in range(6)
    ]
    await asyncio.sleep(0.05)
    start = loop.time()
    r = await client.get("/healthz")
    waited = loop.time() - start
    assert r.status_code == 200
    results = await asyncio.gather(*work)
    wall = loop.time() - began
    assert all(res.status_code == 200 for res in results)
    # The event loop is never blocked by encoding: health answers long before the encodes end
    # (relative, because the machine's load scales both).
    assert waited < wall / 3, (waited, wall)


TRICKLERS = 70


@pytest.mark.slow
async def test_70_trickling_bodies_do_not_stop_a_normal_encode(live_server: str) -> None:
    """70 sockets send their bodies at 1 byte a second (more than the 66 work slots); a
    normal encode meanwhile succeeds, because a slot is taken only once a body is in."""
    host, port = live_server.removeprefix("http://").split(":")
    head = (
        f"POST /v1/curves/encode HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n"
        "Content-Length: 10000\r\n\r\n"
    )
    writers: list[asyncio.StreamWriter] = []
    for _ in range(TRICKLERS):
        _, writer = await asyncio.open_connection(host, int(port))
        writer.write(head.encode())
        writers.append(writer)
    stop = asyncio.Event()

    async def trickle() -> None:
        while not stop.is_set():
            for writer in writers:
                writer.write(b" ")
            await asyncio.gather(*(writer.drain() for writer in writers))
            await asyncio.sleep(1.0)

    trickling = asyncio.create_task(trickle())
    try:
        await asyncio.sleep(2.0)  # every trickler is connected and mid-body
        image = test_image((128, 160), seed=3)
        async with httpx.AsyncClient(base_url=live_server, timeout=60) as client:
            files = {"file": ("n.png", image_file(image), "image/png")}
            r = await client.post("/v1/images/encode", files=files, data={"quality": "35"})
            assert r.status_code == 200, r.text
            assert wavecore.decode(r.content).shape == image.shape
            assert (await client.get("/healthz")).status_code == 200
        assert not trickling.done()  # the tricklers were still sending all along
    finally:
        stop.set()
        await trickling
        for writer in writers:
            writer.close()
