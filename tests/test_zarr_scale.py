"""Dask at scale and gigapixel pyramids: a real LocalCluster, real Zarr stores on disk."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("zarr", reason="the Zarr tests need the zarr extra (pip install '.[zarr]')")
da = pytest.importorskip("dask.array", reason="the zarr extra installs dask")
distributed = pytest.importorskip("dask.distributed", reason="the zarr extra installs it")
tifffile = pytest.importorskip("tifffile", reason="the zarr extra installs tifffile")

import zarr  # noqa: E402
from zarr_fields import smooth_field  # noqa: E402

from service.cli import main  # noqa: E402
from wavecore.errors import InvalidParameter  # noqa: E402
from wavecore.scale import (  # noqa: E402
    open_image_source,
    read_region,
    synthetic_rgb,
    write_pyramid,
)


@pytest.fixture(scope="module")
def client() -> object:
    # Two thread workers: a real scheduler and real workers, without the seconds that new
    # processes need to load the compiled kernels (the benchmark uses processes).
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as c,
    ):
        yield c


def test_dask_writes_and_reads_a_store_in_parallel(client: object, tmp_path: Path) -> None:
    field = smooth_field((256, 192), seed=30)
    bound = 0.5  # half the noise's standard deviation
    source = da.from_array(field, chunks=(64, 64))
    store = tmp_path / "field.zarr"
    target = zarr.create_array(
        store,
        shape=field.shape,
        chunks=(64, 64),
        dtype="float32",
        serializer={"name": "wavecore", "configuration": {"max_error": bound}},
        compressors=None,
    )
    with distributed.get_task_stream(client) as stream:  # type: ignore[arg-type]
        source.store(target, lock=False)
        back = da.from_zarr(store)
        worst = float(abs(back.astype("float64") - field.astype("float64")).max().compute())
    assert worst <= bound
    assert len({task["worker"] for task in stream.data}) == 2  # both workers coded chunks
    chunk_files = [p for p in store.rglob("*") if p.is_file() and p.name != "zarr.json"]
    assert len(chunk_files) == 4 * 3
    assert sum(p.stat().st_size for p in chunk_files) < field.nbytes / 3


def test_pyramid_levels_are_coarse_bands(tmp_path: Path) -> None:
    image = synthetic_rgb(200, tile=32, seed=3)
    store = tmp_path / "p.zarr"
    info = write_pyramid(image, store, config={"lossless": True}, tile=64)
    assert info.shapes == [(3, 200, 200), (3, 100, 100), (3, 50, 50)]
    full = np.asarray(image)
    assert np.array_equal(read_region(store, level=0), full)
    # The coarse band of a low-pass filter: close to the 2 × 2 means, away from the tiles' edges.
    half = read_region(store, level=1).astype(np.float64)
    means = full.reshape(100, 2, 100, 2, 3).mean(axis=(1, 3))
    assert half.shape == means.shape
    assert np.median(np.abs(half - means)) < 6
    meta = json.loads((store / "zarr.json").read_text())["attributes"]["ome"]
    assert meta["version"] == "0.5"
    scales = [
        d["coordinateTransformations"][0]["scale"] for d in meta["multiscales"][0]["datasets"]
    ]
    assert scales == [[1.0, 2.0**k, 2.0**k] for k in range(3)]


def test_region_reads_only_its_chunks(tmp_path: Path) -> None:
    image = synthetic_rgb(256, tile=64, seed=4)
    store = tmp_path / "r.zarr"
    write_pyramid(image, store, config={"lossless": True}, tile=64)
    # Damage every chunk of level 0 outside the window: the window still reads.
    window = (0, 60, 64, 120)
    for path in (store / "0").rglob("*"):
        if path.is_file() and path.name != "zarr.json":
            parts = path.relative_to(store / "0").parts  # ("c", channel, row, col)
            if (int(parts[-2]), int(parts[-1])) != (0, 1):
                path.write_bytes(b"damaged")
    out = read_region(store, level=0, region=window)
    assert np.array_equal(out, np.asarray(image)[0:60, 64:120])
    with pytest.raises(InvalidParameter, match="region"):
        read_region(store, region=(0, 300, 0, 10))
    with pytest.raises(InvalidParameter, match="level"):
        read_region(store, level=9)


def test_cli_big_tiff_to_pyramid_and_window(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    image = np.asarray(synthetic_rgb(200, tile=64, seed=5))
    tiff = tmp_path / "big.tif"
    tifffile.imwrite(tiff, image, tile=(64, 64), photometric="rgb")
    store = tmp_path / "big.zarr"
    assert main(["encode", str(tiff), str(store), "--lossless", "--tile", "64"]) == 0
    assert "levels: 200×200, 100×100, 50×50" in capsys.readouterr().out
    out = tmp_path / "w.npy"
    args = ["decode", str(store), str(out), "--level", "1", "--region", "10:100,40:200"]
    assert main(args) == 0
    window = np.load(out)
    assert window.shape == (45, 80, 3)
    assert np.array_equal(window, read_region(store, level=1)[5:50, 20:100])


def test_a_tiff_whose_tiles_decode_far_larger_is_refused_from_its_tags(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # 37 kB of file whose one zlib tile decodes to 36 MB, in every task under it; the check
    # reads the tags, before a task is built
    bomb = tmp_path / "bomb.tif"
    tifffile.imwrite(bomb, np.zeros((64, 64), np.uint8), tile=(6016, 6016), compression="zlib")
    assert bomb.stat().st_size < 100_000
    with pytest.raises(InvalidParameter, match=r"tiles or strips of 6016 × 6016, 36192256 bytes"):
        open_image_source(bomb, tile=64)
    assert main(["encode", str(bomb), str(tmp_path / "b.zarr"), "--tile", "64"]) == 1
    assert "save it tiled" in capsys.readouterr().err
    # strips of a few rows, and one strip of a small picture, still read
    image = np.asarray(synthetic_rgb(96, tile=64, seed=3))
    for name, options in (("strips", {"rowsperstrip": 8}), ("one", {})):
        path = tmp_path / f"{name}.tif"
        tifffile.imwrite(path, image, photometric="rgb", **options)
        assert np.array_equal(np.asarray(open_image_source(path, tile=64)), image)


def test_cli_tile_folder_with_max_error(tmp_path: Path) -> None:
    image = np.asarray(synthetic_rgb(160, tile=64, seed=6))
    folder = tmp_path / "tiles"
    folder.mkdir()
    for r in range(2):
        for c in range(2):
            np.save(
                folder / f"scan_r{r}_c{c}.npy", image[r * 80 : (r + 1) * 80, c * 80 : (c + 1) * 80]
            )
    store = tmp_path / "t.zarr"
    assert main(["encode", str(folder), str(store), "--max-error", "3", "--tile", "64", "-q"]) == 0
    back = read_region(store)
    assert np.abs(back.astype(int) - image.astype(int)).max() <= 3


def test_cli_zarr_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["encode", str(tmp_path / "none.tif"), str(tmp_path / "o.zarr")]) == 1
    assert "does not exist" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["encode", str(empty), str(tmp_path / "o.zarr")]) == 1
    assert "_r<row>_c<col>" in capsys.readouterr().err
    assert main(["decode", str(tmp_path / "nothing.zarr"), str(tmp_path / "o.npy")]) == 1
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--tile", "0"], "tile must be an even number"),  # was a ZeroDivisionError in Dask
        (["--tile", "-64"], "tile must be an even number"),
        (["--workers", "0"], "workers must be a whole number"),  # was a wait for ever
        (["--workers", "-2"], "workers must be a whole number"),
    ],
)
def test_cli_bad_tiles_and_worker_counts_are_one_line_errors(
    option: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    picture = tmp_path / "small.npy"
    np.save(picture, np.zeros((40, 40), dtype=np.uint8))
    assert main(["encode", str(picture), str(tmp_path / "o.zarr"), "-q", *option]) == 1
    assert message in capsys.readouterr().err
