"""``POST /v1/bundles/reconstruct?region=Y0:Y1,X0:X1``: a window of the decode, or a 422
problem naming what is wrong with the region."""

from __future__ import annotations

import io

import httpx
import numpy as np
import pytest
from service_helpers import test_image

import wavecore

pytestmark = pytest.mark.anyio
BUNDLE = "application/vnd.wavecore.bundle"


async def test_a_region_is_the_decode_cropped(client: httpx.AsyncClient) -> None:
    image = test_image((300, 280, 3), seed=4)
    bundle = wavecore.encode_image(image, quality=40)
    full = wavecore.decode(bundle)
    for text, window in [
        ("10:50,200:280", (slice(10, 50), slice(200, 280))),
        ("-20:,:7", (slice(-20, None), slice(None, 7))),
        ("0:300:3", (slice(0, 300, 3),)),
    ]:
        r = await client.post(
            "/v1/bundles/reconstruct",
            params={"region": text, "format": "npy"},
            content=bundle,
            headers={"content-type": BUNDLE},
        )
        assert r.status_code == 200, r.text
        part = np.load(io.BytesIO(r.content), allow_pickle=False)
        assert np.array_equal(part, full[window])
    r = await client.post(
        "/v1/bundles/reconstruct", params={"region": "2:9,3:5", "level": 1}, content=bundle
    )
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    assert r.headers["x-wavecore-shape"] == "7x2x3"


@pytest.mark.parametrize(
    ("region", "needle"),
    [
        ("10-50,0:3", "is not start:stop"),
        ("a:b", "is not start:stop"),
        ("5:5,0:3", "selects no samples"),
        ("0:3,0:3,0:1", "tuple of 1 to 2 slices"),
        ("0:3:-1", "step must be positive"),
    ],
)
async def test_a_bad_region_is_a_422_problem(
    client: httpx.AsyncClient, region: str, needle: str
) -> None:
    bundle = wavecore.encode_image(test_image((40, 30)), quality=40)
    r = await client.post("/v1/bundles/reconstruct", params={"region": region}, content=bundle)
    assert r.status_code == 422
    assert r.headers["content-type"].startswith("application/problem+json")
    problem = r.json()
    assert problem["type"].endswith("invalid-parameter") and needle in problem["detail"]
