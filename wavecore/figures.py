"""The paper's three figures, redone on real data: ``python -m wavecore.figures``.

Writes into ``docs/figures/`` (or ``--out DIR``):

* ``curve.png`` — figure 1 on a glyph outline from the DejaVu Sans font that matplotlib ships:
  the original, the curve without details, a new base curve, and the new base with the
  original's details;
* ``image.png`` — figure 2 on scikit-image's ``chelsea`` photograph: the original, the coarse
  image after two levels, and the reconstruction with the smallest 60 % of the details removed
  (with its PSNR); ``mosaic.png`` shows its subbands;
* ``surfaces.png`` — figure 3 on a generated surface of revolution (closed in u, open in v)
  and on a real elevation model that matplotlib ships (``jacksboro_fault_dem.npz``): the
  original, the coarse net after two levels per direction, and the reconstructions with all,
  none and the largest 40 % of the details;
* ``ranking.md`` — the L2 error of removing details ranked by weighted size (the default)
  and by plain magnitude, at the same fractions, on every real input.

Needs the ``figures`` extra (matplotlib, scikit-image); ``wavecore`` itself never imports them,
and this module imports them only inside its functions.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .curves import decompose_curve, transfer_details
from .images import decompose_image
from .multilevel import waverec
from .resample import resample_curve
from .surfaces import decompose_surface

__all__ = [
    "RankingRow",
    "circle_base",
    "dem_height_field",
    "figure_curve",
    "figure_image",
    "figure_surfaces",
    "glyph_outline",
    "main",
    "measure_ranking",
    "photographs",
    "psnr",
    "ranking_markdown",
    "vase_surface",
]

FRACTIONS = (0.3, 0.6, 0.9)
DPI = 80
DEM_WINDOW = np.s_[170:250, 230:310]  # shown at full resolution; the ranking uses all of it
PHOTO_DPI = 64  # photographs compress poorly; this keeps image.png under 200 KB


# --- real inputs -----------------------------------------------------------------------------


def glyph_outline(char: str = "♞", points: int = 256) -> np.ndarray:
    """The outer contour of a glyph of DejaVu Sans (shipped with matplotlib), as a closed curve.

    The font's Bézier outline is flattened by matplotlib and re-sampled uniformly by arc length
    to ``points`` points, counter-clockwise, without a repeated seam point.
    """
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), char, size=100, prop=FontProperties(family="DejaVu Sans"))
    polygons = [np.asarray(p, dtype=np.float64) for p in path.to_polygons()]
    if not polygons:
        msg = f"the font has no outline for {char!r}"
        raise ValueError(msg)

    def area(p: np.ndarray) -> float:
        return 0.5 * float(np.sum(p[:-1, 0] * p[1:, 1] - p[1:, 0] * p[:-1, 1]))

    outer = max(polygons, key=lambda p: abs(area(p)))
    if area(outer) < 0:
        outer = outer[::-1]
    return resample_curve(outer / 100.0, points, closed=True)


def photographs() -> dict[str, np.ndarray]:
    """The photographs scikit-image ships with the package (no download)."""
    from skimage import data

    return {
        "chelsea": data.chelsea(),
        "camera": data.camera(),
        "astronaut": data.astronaut(),
        "coins": data.coins(),
        "moon": data.moon(),
        "brick": data.brick(),
    }


def dem_height_field() -> np.ndarray:
    """The Jacksboro fault elevation model (metres) that matplotlib ships as sample data."""
    from matplotlib import cbook

    dem: Any = cbook.get_sample_data("jacksboro_fault_dem.npz")
    with dem:
        return np.asarray(dem["elevation"], dtype=np.float64)


def vase_surface(nu: int = 64, nv: int = 34) -> np.ndarray:
    """A generated surface of revolution ``(nu, nv, 3)``, closed in u: a fluted vase."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)[:, None]
    v = np.linspace(0, 1, nv)[None, :]
    profile = 0.55 + 0.35 * np.sin(np.pi * (1.4 * v + 0.1)) ** 2 - 0.15 * v
    flutes = 0.04 * np.cos(12 * u) * np.sin(np.pi * v)
    rings = 0.03 * (np.sin(2 * np.pi * 6 * v) > 0.7)
    radius = profile + flutes + rings
    x, y, z = np.broadcast_arrays(radius * np.cos(u), radius * np.sin(u), 1.6 * v)
    return np.stack([x, y, z], axis=-1)


def psnr(reference: np.ndarray, image: np.ndarray, peak: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB (peak: the dtype's maximum for integers, else 1)."""
    if peak is None:
        peak = float(np.iinfo(reference.dtype).max) if reference.dtype.kind in "iu" else 1.0
    mse = float(np.mean((reference.astype(np.float64) - image.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(peak**2 / mse)


# --- weighted against plain ranking ----------------------------------------------------------


@dataclass(frozen=True)
class RankingRow:
    """The L2 errors of one input at one fraction, weighted and plain ranking."""

    name: str
    kind: str
    fraction: float
    weighted: float
    plain: float

    @property
    def ratio(self) -> float:
        """weighted / plain: below 1 means the weighted ranking costs less."""
        return self.weighted / self.plain if self.plain else 1.0


def measure_ranking(
    inputs: dict[str, tuple[str, Callable[[float, bool], np.ndarray], np.ndarray]],
    fractions: Sequence[float] = FRACTIONS,
) -> list[RankingRow]:
    """L2 error of the reconstruction with ``fraction`` removed, for both rankings.

    ``inputs`` maps a name to ``(kind, reconstruct(fraction, weighted), original)``.
    """
    rows = []
    for name, (kind, rebuild, original) in inputs.items():
        reference = original.astype(np.float64)
        for fraction in fractions:
            errors = [
                float(np.linalg.norm(rebuild(fraction, w).astype(np.float64) - reference))
                for w in (True, False)
            ]
            rows.append(RankingRow(name, kind, fraction, errors[0], errors[1]))
    return rows


def ranking_markdown(rows: Sequence[RankingRow]) -> str:
    """The table of :func:`measure_ranking` as Markdown, with a note on where weighted loses."""
    lines = [
        "# Removing details: weighted against plain ranking",
        "",
        "Written by `python -m wavecore.figures`.  L2 error (root of the sum of squared",
        "differences, in the data's units) of the reconstruction after removing the given share",
        "of all detail coefficients, ranked by magnitude × the norm of the coefficient's synthesis",
        "basis function (`weighted=True`, the default of `wavecore.remove_smallest`) or by plain",
        "magnitude (`weighted=False`).  Ratio below 1: weighted costs less.",
        "",
        "| input | kind | removed | L2 weighted | L2 plain | weighted / plain |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.name} | {r.kind} | {r.fraction:.0%} | {r.weighted:.4g} | {r.plain:.4g} "
            f"| {r.ratio:.3f} |"
        )
    worse = [r for r in rows if r.weighted > r.plain]
    lines.append("")
    if worse:
        cases = ", ".join(f"{r.name} at {r.fraction:.0%} ({r.ratio:.3f})" for r in worse)
        lines.append(
            f"**The weighted ranking is not lower everywhere:** {cases}.  The basis is not "
            "orthogonal, so the sum of the removed details' weighted sizes is only an estimate "
            "of the error they leave."
        )
    else:
        lines.append("The weighted ranking gives the lower error on every input and fraction.")
    return "\n".join(lines) + "\n"


# --- figures ---------------------------------------------------------------------------------


def _new_figure(width: float, height: float) -> Any:
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=DPI, layout="constrained")


def _curve_panel(ax: Any, curve: np.ndarray, title: str) -> None:
    closed = np.concatenate([curve, curve[:1]])
    ax.fill(closed[:, 0], closed[:, 1], color="0.9")
    ax.plot(closed[:, 0], closed[:, 1], color="k", lw=1.2)
    ax.set_title(title, fontsize=10)
    ax.set_aspect("equal")
    ax.axis("off")


def circle_base(coarse: np.ndarray, count: int | None = None) -> np.ndarray:
    """A circle as a new base for ``coarse``: same centre, size, start and direction."""
    count = len(coarse) if count is None else count
    rel = coarse - coarse.mean(axis=0)
    radius = float(np.sqrt(np.mean(np.sum(rel**2, axis=1))))
    start = float(np.arctan2(rel[0, 1], rel[0, 0]))
    turn = 1.0 if np.sum(rel[:-1, 0] * rel[1:, 1] - rel[1:, 0] * rel[:-1, 1]) >= 0 else -1.0
    angle = start + turn * np.linspace(0, 2 * np.pi, count, endpoint=False)
    return coarse.mean(axis=0) + radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)


def figure_curve(
    path: Path, outline: np.ndarray, *, level: int = 5, base: np.ndarray | None = None
) -> None:
    """Figure 1: original, without details, a new base curve, new base + original's details.

    The new base defaults to a circle (:func:`circle_base`); the last two panels put the
    original's details on it in the local frame (the default) and as plain displacements.
    """
    dec = decompose_curve(outline, level, closed=True)
    smooth = dec.reconstruct(keep=0.0)
    if base is None:
        base = circle_base(dec.coarse())
    new_local = transfer_details(outline, base, closed=True, level=level)
    new_plain = transfer_details(outline, base, closed=True, level=level, frame="plain")
    fig = _new_figure(12.5, 3.3)
    axes = fig.subplots(1, 5)
    _curve_panel(axes[0], outline, f"(a) original ({len(outline)} points)")
    _curve_panel(axes[1], smooth, f"(b) without details\n({level} levels removed)")
    base_curve = waverec([base, *([None] * level)], boundary="closed")
    _curve_panel(axes[2], base_curve, f"(c) a new base\n({len(base)} control points)")
    closed_base = np.concatenate([base, base[:1]])
    axes[2].plot(closed_base[:, 0], closed_base[:, 1], "o--", color="C3", ms=3, lw=0.8)
    _curve_panel(axes[3], new_local, "(d) new base + details\nlocal frame (default)")
    _curve_panel(axes[4], new_plain, "(d') new base + details\nplain displacements")
    fig.suptitle("Figure 1 — the outline of DejaVu Sans ♞, closed quadratic B-spline wavelets")
    fig.savefig(path, dpi=DPI)


def _show(ax: Any, image: np.ndarray, title: str) -> None:
    shown = image if image.dtype.kind in "iu" else np.clip(image, 0, 255).astype(np.uint8)
    ax.imshow(shown, cmap="gray" if image.ndim == 2 else None, vmin=0, vmax=255)
    ax.set_title(title, fontsize=10)
    ax.axis("off")


def figure_image(
    path: Path, photo: np.ndarray, *, fraction: float = 0.6, mosaic_path: Path | None = None
) -> float:
    """Figure 2: original, coarse after two levels, smallest ``fraction`` removed, with PSNR.

    With ``mosaic_path``, also writes the subband mosaic of the decomposition there.  Returns
    the PSNR of the reconstruction.
    """
    axis = -1 if photo.ndim == 3 else None
    dec = decompose_image(photo, 2, channel_axis=axis)
    rebuilt = dec.reconstruct(keep=1.0 - fraction)
    quality = psnr(photo, rebuilt)
    coarse = dec.coarse(2)
    h, w = photo.shape[:2]
    fig = _new_figure(10.5, 10.5 * h / w / 3 + 0.6)
    axes = fig.subplots(1, 3)
    _show(axes[0], photo, f"original ({w}×{h})")
    _show(axes[1], coarse, f"coarse after two levels ({coarse.shape[1]}×{coarse.shape[0]})")
    _show(axes[2], rebuilt, f"smallest {fraction:.0%} of details removed\nPSNR {quality:.2f} dB")
    fig.suptitle("Figure 2 — scikit-image's chelsea, open quadratic B-spline wavelets")
    fig.savefig(path, dpi=PHOTO_DPI)
    if mosaic_path is not None:
        mosaic = dec.mosaic()
        fig = _new_figure(4.2, 4.2 * mosaic.shape[0] / mosaic.shape[1] + 0.4)
        ax = fig.subplots()
        ax.imshow(mosaic, cmap="gray" if mosaic.ndim == 2 else None)
        ax.set_title("chelsea: coarse image and |details|,\ntwo levels of subbands", fontsize=10)
        ax.axis("off")
        fig.savefig(mosaic_path, dpi=DPI)
    return quality


def _surface_panel(ax: Any, grid: np.ndarray, title: str, *, closed_u: bool, net: bool) -> None:
    from matplotlib import colormaps
    from matplotlib.colors import LightSource

    light = LightSource(azdeg=315, altdeg=35)
    if grid.ndim == 2:  # a height field: x, y are the sample positions
        heights = grid
        u, v = np.meshgrid(
            np.linspace(0, 1, grid.shape[0]), np.linspace(0, 1, grid.shape[1]), indexing="ij"
        )
        grid = np.stack([v, 1 - u, grid], axis=-1)
    if closed_u:
        grid = np.concatenate([grid, grid[:1]], axis=0)
    x, y, z = grid[..., 0], grid[..., 1], grid[..., 2]
    count = max(grid.shape[:2])
    if net:
        ax.plot_wireframe(x, y, z, color="C3", lw=0.8)
        ax.scatter(x.ravel(), y.ravel(), z.ravel(), color="C3", s=4)
    elif closed_u:
        ax.plot_surface(
            x,
            y,
            z,
            color="0.8",
            shade=True,
            lightsource=light,
            rcount=count,
            ccount=count,
            lw=0,
            antialiased=False,
        )
    else:
        colours = light.shade(heights, cmap=colormaps["terrain"], blend_mode="soft", vert_exag=0.05)
        ax.plot_surface(
            x,
            y,
            z,
            facecolors=colours,
            shade=False,
            rcount=count,
            ccount=count,
            lw=0,
            antialiased=False,
        )
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()


def figure_surfaces(path: Path, vase: np.ndarray, dem: np.ndarray, *, keep: float = 0.4) -> None:
    """Figure 3: both surfaces — original, coarse net, all, none and the largest ``keep``."""
    fig = _new_figure(13.0, 6.4)
    rows = [(vase, ("closed", "open"), True), (dem, "open", False)]
    for row, (grid, boundary, closed_u) in enumerate(rows):
        dec = decompose_surface(grid, 2, boundary=boundary)
        scale = (1.0, 1.0, 1.0)
        if grid.ndim == 2:
            scale = (1.0, grid.shape[1] / grid.shape[0], 0.35)
        panels = [
            ("original", grid, False),
            ("coarse net, two levels", dec.coarse(2), closed_u),
            ("with all details", dec.reconstruct(1.0), False),
            ("without details", dec.reconstruct(0.0), False),
            (f"largest {keep:.0%} of details", dec.reconstruct(keep), False),
        ]
        for col, (title, data, net) in enumerate(panels):
            ax = fig.add_subplot(2, 5, row * 5 + col + 1, projection="3d")
            ax.set_box_aspect(scale, zoom=1.25)
            if grid.ndim == 3:
                ax.view_init(elev=25, azim=-60)
            else:
                ax.view_init(elev=45, azim=-110)
            _surface_panel(ax, data, title, closed_u=closed_u, net=net)
    fig.suptitle(
        "Figure 3 — two levels in each direction.  Top: a generated vase, closed in u, open in v."
        f"\nBottom: a {dem.shape[0]}×{dem.shape[1]} window of the Jacksboro fault elevation model"
        " (matplotlib sample data), open × open"
    )
    fig.savefig(path, dpi=DPI)


# --- the script ------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """Write the three figures and the ranking table; print the table."""
    parser = argparse.ArgumentParser(prog="python -m wavecore.figures", description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"), help="output folder")
    args = parser.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    outline = glyph_outline(points=256)
    figure_curve(out / "curve.png", outline)
    photos = photographs()
    quality = figure_image(out / "image.png", photos["chelsea"], mosaic_path=out / "mosaic.png")
    vase, dem = vase_surface(), dem_height_field()
    figure_surfaces(out / "surfaces.png", vase, dem[DEM_WINDOW])

    def rebuild(dec: Any) -> Callable[[float, bool], np.ndarray]:
        return lambda fraction, weighted: dec.reconstruct(1 - fraction, weighted=weighted)

    inputs: dict[str, tuple[str, Callable[[float, bool], np.ndarray], np.ndarray]] = {}
    inputs["glyph ♞ outline"] = (
        f"closed curve, {len(outline)} points, 5 levels",
        rebuild(decompose_curve(outline, 5, closed=True)),
        outline,
    )
    for name, photo in photos.items():
        shape = "×".join(str(s) for s in photo.shape)
        inputs[name] = (
            f"photo {shape} {photo.dtype}, 2 levels",
            rebuild(decompose_image(photo, 2, channel_axis=-1 if photo.ndim == 3 else None)),
            photo,
        )
    inputs["Jacksboro DEM"] = (
        f"height field {dem.shape[0]}×{dem.shape[1]}, 2 levels",
        rebuild(decompose_surface(dem, 2)),
        dem,
    )
    inputs["vase (generated)"] = (
        "surface 64×34×3, closed × open, 2 levels",
        rebuild(decompose_surface(vase, 2, boundary=("closed", "open"))),
        vase,
    )
    rows = measure_ranking(inputs)
    table = ranking_markdown(rows)
    (out / "ranking.md").write_text(table, encoding="utf-8")
    print(table)
    print(f"chelsea, smallest 60% of details removed: PSNR {quality:.2f} dB")
    for name in ("curve.png", "image.png", "mosaic.png", "surfaces.png", "ranking.md"):
        print(f"wrote {out / name} ({(out / name).stat().st_size / 1024:.0f} KiB)")
    print(f"took {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
