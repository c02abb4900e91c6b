"""The figure script's parts run on small data (no assertions on pixels)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib", reason="figures need the 'figures' extra")
pytest.importorskip("skimage", reason="figures need the 'figures' extra")

from wavecore import figures


def test_importing_wavecore_does_not_import_plotting_libraries() -> None:
    code = (
        "import sys, wavecore\n"
        "bad = [m for m in ('matplotlib', 'skimage', 'PIL') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_real_inputs_load() -> None:
    outline = figures.glyph_outline(points=64)
    assert outline.shape == (64, 2)
    assert not np.allclose(outline[0], outline[-1])  # closed, without a seam point
    dem = figures.dem_height_field()
    assert dem.ndim == 2 and dem.shape[0] > 100 and np.ptp(dem) > 100
    vase = figures.vase_surface(16, 10)
    assert vase.shape == (16, 10, 3)


def test_figures_are_written(tmp_path: Path) -> None:
    outline = figures.glyph_outline(points=64)
    figures.figure_curve(tmp_path / "curve.png", outline, level=3)
    rng = np.random.default_rng(0)
    photo = rng.integers(0, 256, (40, 60, 3), dtype=np.uint8)
    quality = figures.figure_image(
        tmp_path / "image.png", photo, mosaic_path=tmp_path / "mosaic.png"
    )
    assert 0 < quality < 100
    dem = figures.dem_height_field()[:30, :34]
    figures.figure_surfaces(tmp_path / "surfaces.png", figures.vase_surface(16, 10), dem)
    for name in ("curve.png", "image.png", "mosaic.png", "surfaces.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_ranking_table_reports_both_rankings() -> None:
    signal = np.cumsum(np.random.default_rng(1).standard_normal(66))
    import wavecore

    coeffs = wavecore.wavedec(signal, level=3)

    def rebuild(fraction: float, weighted: bool) -> np.ndarray:
        return wavecore.waverec(wavecore.remove_smallest(coeffs, fraction, weighted=weighted))

    rows = figures.measure_ranking({"walk": ("signal", rebuild, signal)}, fractions=(0.0, 0.5))
    assert [r.fraction for r in rows] == [0.0, 0.5]
    assert rows[0].weighted < 1e-9 and rows[1].weighted > 0 and rows[1].plain > 0
    table = figures.ranking_markdown(rows)
    assert table.count("| walk |") == 2
    worse = figures.ranking_markdown([figures.RankingRow("x", "k", 0.5, weighted=2.0, plain=1.0)])
    assert "not lower everywhere" in worse and "x at 50%" in worse


def test_psnr() -> None:
    a = np.zeros((4, 4), dtype=np.uint8)
    b = a.copy()
    assert figures.psnr(a, b) == float("inf")
    b[0, 0] = 255
    assert figures.psnr(a, b) == pytest.approx(10 * np.log10(16))


@pytest.mark.slow
def test_main_writes_everything(tmp_path: Path) -> None:
    assert figures.main(["--out", str(tmp_path)]) == 0
    for name in ("curve.png", "image.png", "mosaic.png", "surfaces.png", "ranking.md"):
        assert (tmp_path / name).stat().st_size > 0
