"""A round trip through every endpoint, in process and against the live server."""

from __future__ import annotations

import io

import httpx
import numpy as np
import pytest
from PIL import Image
from service_helpers import circle, image_file, test_image

import wavecore

pytestmark = pytest.mark.anyio

BUNDLE = "application/vnd.wavecore.bundle"


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(float) - b.astype(float)) ** 2))
    return 10 * np.log10(255.0**2 / mse) if mse > 0 else float("inf")


async def test_health_and_openapi(client: httpx.AsyncClient) -> None:
    r = await client.get("/healthz")
    assert r.status_code == 200
    assert r.json() == {"status": "ok", "version": wavecore.__version__}
    spec = (await client.get("/openapi.json")).json()
    for path in (
        "/v1/images/encode",
        "/v1/curves/encode",
        "/v1/curves/transfer",
        "/v1/surfaces/encode",
        "/v1/bundles/reconstruct",
        "/v1/bundles/inspect",
    ):
        assert "post" in spec["paths"][path], path
    assert (await client.get("/docs")).status_code == 200
    page = await client.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]


@pytest.mark.parametrize("shape", [(48, 64), (37, 50, 3)])
async def test_image_round_trip(client: httpx.AsyncClient, shape: tuple[int, ...]) -> None:
    image = test_image(shape)
    r = await client.post(
        "/v1/images/encode",
        files={"file": ("in.png", image_file(image), "image/png")},
        data={"quality": "38"},
    )
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == BUNDLE
    bundle = r.content
    assert int(r.headers["x-wavecore-bytes"]) == len(bundle)
    bpp = float(r.headers["x-wavecore-bpp"])
    assert bpp == pytest.approx(8 * len(bundle) / (shape[0] * shape[1]), rel=1e-3)
    assert float(r.headers["x-wavecore-ratio"]) == pytest.approx(image.nbytes / len(bundle), 1e-3)
    assert float(r.headers["x-wavecore-psnr"]) >= 38
    # No wavelet field: "auto" gives photographs cdf97, the measured rate–distortion winner
    # (issue 12), and says so.
    assert wavecore.inspect(bundle)["wavelet"] == "cdf97"
    assert r.headers["x-wavecore-wavelet"] == "cdf97"

    info = (await client.post("/v1/bundles/inspect", content=bundle)).json()
    assert info["kind"] == "image" and info["shape"] == list(shape)
    assert info["total_bytes"] == len(bundle)

    r = await client.post(
        "/v1/bundles/reconstruct", content=bundle, headers={"content-type": BUNDLE}
    )
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    decoded = np.asarray(Image.open(io.BytesIO(r.content)))
    assert decoded.shape == image.shape
    assert np.array_equal(decoded, wavecore.decode(bundle))
    assert psnr(decoded, image) >= 38

    # keep fewer details: a worse reconstruction from the same bundle
    r = await client.post("/v1/bundles/reconstruct", params={"keep": 0.05}, content=bundle)
    fewer = np.asarray(Image.open(io.BytesIO(r.content)))
    assert psnr(fewer, image) < psnr(decoded, image)

    # a coarse level, as .npy (by format) and as WebP (by Accept)
    r = await client.post(
        "/v1/bundles/reconstruct", params={"level": 2, "format": "npy"}, content=bundle
    )
    assert r.headers["content-type"] == "application/x-npy"
    coarse = np.load(io.BytesIO(r.content), allow_pickle=False)
    assert coarse.shape[:2] == wavecore.decode(bundle, level=2).shape[:2]
    assert coarse.shape[0] < shape[0] / 3
    r = await client.post(
        "/v1/bundles/reconstruct", content=bundle, headers={"accept": "image/webp"}
    )
    assert r.headers["content-type"] == "image/webp"
    assert Image.open(io.BytesIO(r.content)).size == (shape[1], shape[0])


async def test_lossless_and_multipart_bundle(client: httpx.AsyncClient) -> None:
    image = test_image((40, 33), seed=3)
    r = await client.post(
        "/v1/images/encode",
        files={"file": ("in.bmp", image_file(image, "BMP"), "image/bmp")},
        data={"lossless": "true", "level": "2"},
    )
    assert r.status_code == 200, r.text
    assert r.headers["x-wavecore-psnr"] == "inf"
    r = await client.post(
        "/v1/bundles/reconstruct",
        files={"bundle": ("b.wcb", r.content, BUNDLE)},
        data={"format": "npy"},
    )
    assert r.status_code == 200, r.text
    assert np.array_equal(np.load(io.BytesIO(r.content)), image)


async def test_lossless_effort_max(client: httpx.AsyncClient) -> None:
    image = test_image((40, 33), seed=4)
    upload = {"file": ("in.png", image_file(image), "image/png")}
    versions = {}
    for effort in ("default", "max", "fast"):
        r = await client.post(
            "/v1/images/encode", files=upload, data={"lossless": "true", "effort": effort}
        )
        assert r.status_code == 200, r.text
        # the library's own bundle for that effort, decoded exactly
        assert r.content == wavecore.encode_image(image, lossless=True, effort=effort)
        assert np.array_equal(wavecore.decode(r.content), image)
        versions[effort] = wavecore.inspect(r.content)["header"]["cparams"]["version"]
    # the lossless coder (the default, and its earlier name), and the block coder
    assert versions == {"default": 5, "max": 5, "fast": 4}


async def test_curve_round_trip(client: httpx.AsyncClient) -> None:
    points = circle(70)
    r = await client.post(
        "/v1/curves/encode", json={"points": points, "closed": True, "tolerance": 1e-3}
    )
    assert r.status_code == 200, r.text
    assert float(r.headers["x-wavecore-max-error"]) <= 1e-3
    bundle = r.content
    r = await client.post("/v1/bundles/reconstruct", content=bundle)
    assert r.status_code == 200 and r.headers["content-type"] == "application/json"
    body = r.json()
    assert body["kind"] == "curve" and body["shape"] == [70, 2]
    error = np.linalg.norm(np.array(body["points"]) - np.array(points), axis=1)
    assert error.max() <= 1e-3
    r = await client.post("/v1/bundles/reconstruct", params={"format": "npy"}, content=bundle)
    assert np.load(io.BytesIO(r.content)).shape == (70, 2)


async def test_curve_wavelet_choice(client: httpx.AsyncClient) -> None:
    points = circle(40)
    r = await client.post(
        "/v1/curves/encode", json={"points": points, "closed": True, "wavelet": "haar"}
    )
    assert r.status_code == 200, r.text
    info = (await client.post("/v1/bundles/inspect", content=r.content)).json()
    assert info["wavelet"] == "haar"
    r = await client.post("/v1/curves/encode", json={"points": points, "wavelet": "db4"})
    assert r.status_code == 422 and "db4" in r.json()["detail"]


async def test_curve_transfer(client: httpx.AsyncClient) -> None:
    t = np.linspace(0, 1, 66)
    wiggly = np.stack([t, 0.05 * np.sin(60 * t)], axis=1)
    base = [[0.0, 0.0], [0.5, 0.5], [1.0, 0.0]]
    r = await client.post(
        "/v1/curves/transfer", json={"source": wiggly.tolist(), "base": base, "level": 3}
    )
    assert r.status_code == 200, r.text
    got = np.array(r.json()["points"])
    expected = wavecore.transfer_details(wiggly, np.array(base), level=3)
    assert got.shape == wiggly.shape
    assert np.allclose(got, expected)


async def test_surface_round_trip_json_and_npy(client: httpx.AsyncClient) -> None:
    u, v = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 24), indexing="ij")
    height = np.sin(3 * u) * np.cos(2 * v)
    r = await client.post("/v1/surfaces/encode", json={"grid": height.tolist(), "quality": 45})
    assert r.status_code == 200, r.text
    body = (await client.post("/v1/bundles/reconstruct", content=r.content)).json()
    assert body["kind"] == "surface" and body["shape"] == [20, 24]
    assert np.abs(np.array(body["grid"]) - height).max() < 0.05

    theta = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.stack(
        [np.cos(theta)[:, None] * (1 + v[:16] * 0), np.sin(theta)[:, None] + 0 * v[:16], v[:16]],
        axis=-1,
    )
    npy = io.BytesIO()
    np.save(npy, ring)
    r = await client.post(
        "/v1/surfaces/encode",
        files={"file": ("ring.npy", npy.getvalue(), "application/x-npy")},
        data={"closed": "true,false", "keep": "0.5"},
    )
    assert r.status_code == 200, r.text
    assert wavecore.inspect(r.content)["boundary"] == ["closed", "open"]
    r = await client.post("/v1/bundles/reconstruct", params={"format": "npy"}, content=r.content)
    assert np.load(io.BytesIO(r.content)).shape == ring.shape


async def test_metrics_count_requests_bytes_and_errors(client: httpx.AsyncClient) -> None:
    await client.post("/v1/bundles/inspect", content=b"not a bundle")
    text = (await client.get("/metrics")).text
    assert (
        'wavecore_http_requests_total{method="POST",route="/v1/bundles/inspect",status="400"}'
        in text
    )
    assert 'wavecore_http_errors_total{kind="invalid-bundle"}' in text
    assert "wavecore_http_request_duration_seconds_bucket" in text
    line = next(
        ln
        for ln in text.splitlines()
        if ln.startswith('wavecore_http_request_body_bytes_total{route="/v1/bundles/inspect"}')
    )
    assert float(line.split()[-1]) >= len(b"not a bundle")


async def test_auto_codes_a_pixel_replicated_picture_at_its_source_size(
    client: httpx.AsyncClient,
) -> None:
    image = test_image((40, 48, 3)).repeat(2, axis=0).repeat(2, axis=1)
    r = await client.post(
        "/v1/images/encode",
        files={"file": ("in.png", image_file(image), "image/png")},
        data={"quality": "38"},
    )
    assert r.status_code == 200, r.text
    assert r.headers["x-wavecore-wavelet"] == "cdf97"  # chosen on the 40 × 48 source
    assert r.headers["x-wavecore-replicated"] == "2"
    assert wavecore.inspect(r.content)["replicated"] == 2
    assert wavecore.decode(r.content).shape == image.shape
    assert psnr(wavecore.decode(r.content), image) >= 38
