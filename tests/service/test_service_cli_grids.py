"""The command line's grids: ``.npy`` and (Geo)TIFF height maps by suffix and content."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

import wavecore
from service.cli import main


def height_field(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(np.cumsum(rng.standard_normal(shape), axis=-1), axis=-2)


def test_npy_with_nan_is_a_grid_with_its_bound(tmp_path: Path) -> None:
    grid = height_field((50, 64)).astype(np.float32)
    grid[5:10, 5:10] = np.nan
    np.save(tmp_path / "dem.npy", grid)
    bundle = tmp_path / "dem.wcb"
    assert main(["encode", str(tmp_path / "dem.npy"), str(bundle), "--max-error", "0.02"]) == 0
    info = wavecore.inspect(bundle.read_bytes())
    assert info["kind"] == "grid" and info["max_error"] == pytest.approx(0.02)
    out = tmp_path / "back.npy"
    assert main(["decode", str(bundle), str(out)]) == 0
    back = np.load(out)
    assert np.array_equal(np.isnan(back), np.isnan(grid))
    finite = ~np.isnan(grid)
    assert np.max(np.abs(back[finite] - grid[finite])) <= 0.02


def test_int16_tiff_is_a_lossless_grid_and_decodes_to_tiff(tmp_path: Path) -> None:
    dem = np.rint(height_field((40, 45), seed=1) * 10).astype(np.int16)
    tifffile.imwrite(tmp_path / "dem.tif", dem)
    bundle = tmp_path / "dem.wcb"
    assert main(["encode", str(tmp_path / "dem.tif"), str(bundle), "--lossless", "-q"]) == 0
    assert wavecore.inspect(bundle.read_bytes())["kind"] == "grid"
    out = tmp_path / "back.tif"
    assert main(["decode", str(bundle), str(out), "-q"]) == 0
    assert np.array_equal(tifffile.imread(out), dem)


def test_kind_grid_on_a_float_npy_and_psnr(tmp_path: Path) -> None:
    grid = height_field((30, 30), seed=2)
    np.save(tmp_path / "field.npy", grid)
    bundle = tmp_path / "field.wcb"
    args = ["encode", str(tmp_path / "field.npy"), str(bundle), "--kind", "grid", "--psnr", "50"]
    assert main(args) == 0
    back = wavecore.decode(bundle.read_bytes())
    span = grid.max() - grid.min()
    assert 20 * np.log10(span) - 10 * np.log10(np.mean((back - grid) ** 2)) >= 50


def test_grid_options_on_an_image_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    np.save(tmp_path / "img.npy", np.zeros((8, 8), np.uint8))
    status = main(["encode", str(tmp_path / "img.npy"), str(tmp_path / "o.wcb"), "--rmse", "1"])
    assert status == 1
    assert "--rmse does not apply" in capsys.readouterr().err


def test_inspect_describes_a_grid(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bundle = tmp_path / "g.wcb"
    bundle.write_bytes(wavecore.encode_grid(height_field((20, 30), seed=3), max_error=0.1))
    assert main(["inspect", str(bundle)]) == 0
    assert capsys.readouterr().out.startswith("grid 20×30 float64")
