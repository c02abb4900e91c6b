"""``POST /v1/grids/encode``, in process and against the live server: .npy and TIFF in, the
bound on every sample, NaN cells back through ``/v1/bundles/reconstruct``, problems out."""

from __future__ import annotations

import io

import httpx
import numpy as np
import pytest
import tifffile
from service_helpers import tiled_tiff_declaring

import wavecore

pytestmark = pytest.mark.anyio

PROBLEM = "application/problem+json"


def height_field(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(np.cumsum(rng.standard_normal(shape), axis=-1), axis=-2)


def npy(arr: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, arr)
    return out.getvalue()


def tiff(arr: np.ndarray, **options: object) -> bytes:
    out = io.BytesIO()
    tifffile.imwrite(out, arr, **options)
    return out.getvalue()


async def reconstruct(client: httpx.AsyncClient, bundle: bytes) -> np.ndarray:
    r = await client.post("/v1/bundles/reconstruct", content=bundle)
    assert r.status_code == 200, r.text
    assert r.headers["x-wavecore-kind"] == "grid"
    return np.load(io.BytesIO(r.content))


async def test_npy_with_nan_cells_holds_the_bound(client: httpx.AsyncClient) -> None:
    grid = height_field((60, 75)).astype(">f4")  # big-endian, as some writers produce
    grid[10:20, 30:50] = np.nan
    r = await client.post(
        "/v1/grids/encode",
        files={"file": ("dem.npy", npy(grid), "application/x-npy")},
        data={"max_error": "0.05"},
    )
    assert r.status_code == 200, r.text
    assert float(r.headers["x-wavecore-max-error"]) <= 0.05
    assert float(r.headers["x-wavecore-bound"]) == pytest.approx(0.05)
    out = await reconstruct(client, r.content)
    assert out.shape == grid.shape and out.dtype == np.float32
    assert np.array_equal(np.isnan(out), np.isnan(grid))
    finite = ~np.isnan(grid)
    assert np.max(np.abs(out[finite] - grid[finite])) <= 0.05


async def test_int16_geotiff_lossless_and_volume(client: httpx.AsyncClient) -> None:
    dem = np.rint(height_field((40, 52), seed=1) * 10).astype(np.int16)
    r = await client.post(
        "/v1/grids/encode",
        files={"file": ("dem.tif", tiff(dem), "image/tiff")},
        data={"lossless": "true"},
    )
    assert r.status_code == 200, r.text
    assert r.headers["x-wavecore-dtype"] == "int16"
    assert np.array_equal(await reconstruct(client, r.content), dem)

    volume = height_field((6, 30, 34), seed=2).astype(np.float32)
    r = await client.post(
        "/v1/grids/encode",
        files={"file": ("volume.npy", npy(volume), "application/x-npy")},
        data={"rmse": "0.1"},
    )
    assert r.status_code == 200, r.text
    out = await reconstruct(client, r.content)
    assert out.shape == volume.shape
    assert np.sqrt(np.mean((out - volume) ** 2)) <= 0.1


async def test_geotiff_nodata_cells_decode_as_nan(client: httpx.AsyncClient) -> None:
    grid = height_field((30, 40), seed=3).astype(np.float32)
    grid[5:9, 5:9] = -9999.0
    data = tiff(grid, extratags=[(42113, "s", 0, "-9999", True)])  # GDAL_NODATA
    r = await client.post("/v1/grids/encode", files={"file": ("dem.tif", data, "image/tiff")})
    assert r.status_code == 200, r.text
    out = await reconstruct(client, r.content)
    assert np.isnan(out[5:9, 5:9]).all() and np.count_nonzero(np.isnan(out)) == 16
    info = wavecore.inspect(r.content)
    assert info["kind"] == "grid" and info["max_error"] is not None


@pytest.mark.parametrize(
    ("payload", "fields", "status", "words"),
    [
        (b"not a grid at all", {}, 415, "neither"),
        (npy(np.zeros((3, 4, 5, 6))), {}, 422, "shape"),
        (npy(np.zeros(5)), {}, 422, "shape"),
        (npy(np.zeros((4, 4), dtype=complex)), {}, 422, "dtype"),
        (npy(np.zeros((4, 4))), {"max_error": "-1"}, 422, "max_error"),
        (npy(np.zeros((4, 4))), {"lossless": "true"}, 422, "integer"),
        (npy(np.zeros((4, 4))), {"rmse": "1", "psnr": "30"}, 422, "at most one"),
        (npy(np.zeros((4, 4))), {"wavelet": "nope"}, 422, "nope"),
        (npy(np.zeros((4, 4)))[:-8], {}, 415, "truncated"),
        (npy(np.zeros((64, 64))), {"level": "1000"}, 422, "level 1000 is more than 30"),
        (b"II*\x00garbage", {}, 415, "TIFF"),
        # 16 × 16 heights in tiles of 8192 × 8192: 512 MiB each once decoded (one zstd tile of
        # 16384 × 16384 zeros is 66 kB, and took 2.2 GB)
        (
            tiled_tiff_declaring(np.zeros((16, 16)), 8192),
            {},
            413,
            "tiles or strips of 8192 × 8192",
        ),
    ],
)
async def test_bad_grids_are_problems(
    client: httpx.AsyncClient, payload: bytes, fields: dict, status: int, words: str
) -> None:
    r = await client.post(
        "/v1/grids/encode",
        files={"file": ("in.npy", payload, "application/octet-stream")},
        data=fields,
    )
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM)
    assert words in r.json()["detail"]


async def test_grid_too_large_is_refused_before_work(make_client) -> None:  # type: ignore[no-untyped-def]
    async with make_client(max_pixels=1000) as client:
        r = await client.post(
            "/v1/grids/encode",
            files={"file": ("big.npy", npy(np.zeros((100, 100), np.float32)), "x")},
        )
    assert r.status_code == 413 and r.headers["content-type"].startswith(PROBLEM)
    assert "100×100" in r.json()["detail"]
