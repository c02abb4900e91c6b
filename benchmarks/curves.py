"""Curve sets against the simple baselines: bytes against the largest deviation.

Data:

* glyph outlines of four fonts that matplotlib ships (``TextPath``: every contour closed, its
  Bézier segments sampled at 12 points each), one curve set per font;
* a long random-walk track (open, 5 000 points: heading and speed wander, as a GPS log does).

Methods, each swept over the tolerance ``t`` (relative to the glyph size, or to the track's
bounding-box diagonal):

* ``wavecore``: :func:`wavecore.encode_curves` (the whole file) as it is called by default
  (``method="auto"``: the smaller of its wavelet and vertex forms);
* ``wavecore wavelet``: the wavelet form alone (``method="wavelet"``, bspline2: format 1);
* ``wavecore vertex``: the vertex form alone (``method="vertex"``: format 2, or 3 with bulged
  segments where that is smaller);
* ``dp+zlib``: Douglas–Peucker at ``t - q/√2``, the kept points quantized to ``q = t/2``,
  per-curve varint counts and zigzag varint deltas, zlib level 9 (written here);
* ``polyline``: the same Douglas–Peucker and quantization, written as Google's encoded polyline
  (the ``polyline`` package, precision 0 on the quantized integers), one string per curve.

The largest deviation is measured here, exactly and independently of wavecore (every point to
every segment): from each original point to the decoded polyline and back, the larger of the
two.  The comparison at *equal largest deviation* interpolates the baseline's bytes (log–log)
at wavecore's measured deviation; the baselines are also run at looser settings
(``PEER_EXTRA_TOLERANCES``) so that it is always an interpolation between two measured points,
and the script stops rather than clamp.

Run ``python benchmarks/curves.py --write`` to redraw the figure ``docs/figures/curves_rate.png``;
the table and summary lines it prints are what ``docs/benchmarks.md`` quotes.

``--set-cost`` times :func:`wavecore.encode_curves` (the default ``method="auto"``) on random
walks of 1, 2 and 3 dimensions, one long curve and many short ones, against what the service's
cost check counts for them (``service.cost.curve_set_samples``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import zlib
from pathlib import Path

import numpy as np

import wavecore

ROOT = Path(__file__).resolve().parent.parent
FONTS = ("DejaVu Sans", "DejaVu Serif", "STIXGeneral", "cmr10")
TEXT = "Wavelets & curves 2026"
GLYPH_SIZE = 100.0
SAMPLES_PER_BEZIER = 12
RELATIVE_TOLERANCES = (0.001, 0.003, 0.01, 0.03, 0.1)
#: Extra settings for the peers only, so that their measured deviations span wavecore's (the
#: peers land at 0.55-0.86 of their setting): every comparison at equal deviation is then an
#: interpolation between two measured points, never a clamp at the sweep's end.
PEER_EXTRA_TOLERANCES = (0.14, 0.2)
#: wavecore's rows: (name, encode_curves keywords)
WAVECORE = (
    ("wavecore", {}),
    ("wavecore wavelet", {"method": "wavelet"}),
    ("wavecore vertex", {"method": "vertex"}),
)


# --- data --------------------------------------------------------------------------------------


def glyph_contours(family: str) -> list[np.ndarray]:
    """The closed contours of ``TEXT`` in ``family``, Béziers sampled densely."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.path import Path as MplPath
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), TEXT, size=GLYPH_SIZE, prop=FontProperties(family=family))
    contours: list[np.ndarray] = []
    current: list[np.ndarray] = []
    params = np.linspace(0, 1, SAMPLES_PER_BEZIER + 1)[1:]
    for bezier, code in path.iter_bezier():
        if code == MplPath.MOVETO:
            if len(current) > 2:
                contours.append(np.concatenate(current))
            current = [bezier.control_points[:1]]
            continue
        if code == MplPath.CLOSEPOLY:
            continue
        if code == MplPath.LINETO:
            current.append(bezier.control_points[-1:])
        else:
            current.append(bezier(params))
    if len(current) > 2:
        contours.append(np.concatenate(current))
    out = []
    for contour in contours:
        keep = np.concatenate([[True], np.any(np.diff(contour, axis=0) != 0, axis=1)])
        contour = contour[keep]
        if np.array_equal(contour[0], contour[-1]):
            contour = contour[:-1]
        if len(contour) >= 3:
            out.append(contour)
    return out


def random_walk_track(n: int = 5000, seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    heading = np.cumsum(rng.normal(0, 0.08, n))
    speed = 1.0 + 0.5 * np.sin(np.cumsum(rng.normal(0, 0.05, n)))
    steps = speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return np.cumsum(steps, axis=0) + rng.normal(0, 0.05, (n, 2))


# --- the exact deviation --------------------------------------------------------------------------


def _to_polyline(source: np.ndarray, target: np.ndarray, closed: bool) -> float:
    nodes = np.concatenate([target, target[:1]]) if closed else target
    if len(nodes) == 1:
        return float(np.max(np.linalg.norm(source - nodes[0], axis=1)))
    a, b = nodes[:-1], nodes[1:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    worst = 0.0
    for start in range(0, len(source), 256):
        p = source[start : start + 256, None, :]
        t = np.clip(np.einsum("pij,ij->pi", p - a, ab) / length2, 0.0, 1.0)
        gap = p - (a + t[..., None] * ab)
        worst = max(worst, float(np.sqrt(np.einsum("pij,pij->pi", gap, gap).min(axis=1)).max()))
    return worst


def deviation(originals: list[np.ndarray], decoded: list[np.ndarray], closed: bool) -> float:
    """The largest distance, both ways, between each original polyline and its decoded one."""
    worst = 0.0
    for original, back in zip(originals, decoded, strict=True):
        back = np.asarray(back, dtype=np.float64)
        if closed and len(back) > 2 and np.array_equal(back[0], back[-1]):
            back = back[:-1]
        worst = max(
            worst, _to_polyline(original, back, closed), _to_polyline(back, original, closed)
        )
    return worst


# --- baselines ---------------------------------------------------------------------------------


def douglas_peucker(points: np.ndarray, tolerance: float) -> np.ndarray:
    """Indices of the points Douglas–Peucker keeps (iterative; the ends always kept)."""
    keep = np.zeros(len(points), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        first, last = stack.pop()
        if last - first < 2:
            continue
        a, b = points[first], points[last]
        inner = points[first + 1 : last]
        ab = b - a
        length2 = float(ab @ ab)
        if length2 > 0:
            t = np.clip((inner - a) @ ab / length2, 0.0, 1.0)
            gap = inner - (a + t[:, None] * ab)
        else:
            gap = inner - a
        distances = np.sqrt(np.einsum("ij,ij->i", gap, gap))
        index = int(np.argmax(distances))
        if distances[index] > tolerance:
            middle = first + 1 + index
            keep[middle] = True
            stack.append((first, middle))
            stack.append((middle, last))
    return np.flatnonzero(keep)


def _simplified(curves: list[np.ndarray], closed: bool, tolerance: float) -> list[np.ndarray]:
    """Douglas–Peucker points of each curve quantized to integers of step ``tolerance / 2``."""
    step = tolerance / 2
    dp_tolerance = tolerance - step / math.sqrt(2)
    out = []
    for curve in curves:
        ring = np.concatenate([curve, curve[:1]]) if closed else curve
        if closed:  # split at the farthest point so that both halves are simplified well
            far = int(np.argmax(np.linalg.norm(curve - curve[0], axis=1)))
            first = douglas_peucker(ring[: far + 1], dp_tolerance)
            second = far + douglas_peucker(ring[far:], dp_tolerance)
            kept = np.unique(np.concatenate([first, second]))[:-1]
        else:
            kept = douglas_peucker(ring, dp_tolerance)
        out.append(np.rint(ring[kept] / step).astype(np.int64))
    return out


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def dp_zlib(curves: list[np.ndarray], closed: bool, tolerance: float):
    quantized = _simplified(curves, closed, tolerance)
    raw = bytearray(_varint(len(quantized)))
    previous = np.zeros(2, dtype=np.int64)
    for q in quantized:
        raw += _varint(len(q))
        deltas = np.diff(np.concatenate([previous[None], q]), axis=0)
        previous = q[0]
        for value in deltas.ravel():
            value = int(value)
            raw += _varint(2 * value if value >= 0 else -2 * value - 1)
    data = zlib.compress(bytes(raw), 9) + b"\0" * 8  # + the step, a float64
    return len(data), [q * (tolerance / 2) for q in quantized]


def google_polyline(curves: list[np.ndarray], closed: bool, tolerance: float):
    import polyline

    quantized = _simplified(curves, closed, tolerance)
    text = "\n".join(polyline.encode([tuple(map(float, p)) for p in q], 0) for q in quantized)
    return len(text.encode()) + 8, [q * (tolerance / 2) for q in quantized]


def wavecore_curves(curves: list[np.ndarray], closed: bool, tolerance: float, options: dict):
    bundle = wavecore.encode_curves(curves, closed=closed, tolerance=tolerance, **options)
    return len(bundle), wavecore.decode(bundle)


# --- what the vertex form's simplification leaves on the table (``--ideas``) ------------------


def _optimal_counts(points, lattice_points, offsets, tolerance, window):
    """Fewest vertices of each closed curve started at its point 0 (Imai–Iri): a shortest path
    in the visibility graph, every edge ``i -> j`` (``j - i <= window``) tested exactly (every
    point between within ``tolerance`` of the lattice segment), not assumed from a reach."""
    from numba import njit

    @njit(cache=False)
    def fits(points, nodes, first, n, a, b, tolerance):
        end = first + (b % n)
        start = first + (a % n)
        ax, ay = nodes[start, 0], nodes[start, 1]
        bx, by = nodes[end, 0] - ax, nodes[end, 1] - ay
        length2 = bx * bx + by * by
        for k in range(a + 1, b):
            px = points[first + (k % n), 0] - ax
            py = points[first + (k % n), 1] - ay
            t = 0.0
            if length2 > 0.0:
                t = min(1.0, max(0.0, (px * bx + py * by) / length2))
            gx, gy = px - t * bx, py - t * by
            if gx * gx + gy * gy > tolerance * tolerance:
                return False
        return True

    @njit(cache=False)
    def shortest(points, nodes, offsets, tolerance, window):
        out = np.zeros(len(offsets) - 1, dtype=np.int64)
        for c in range(len(offsets) - 1):
            first, n = offsets[c], offsets[c + 1] - offsets[c]
            dist = np.full(n + 1, 1 << 40, dtype=np.int64)
            dist[0] = 0
            for a in range(n):
                for b in range(a + 1, min(n, a + window) + 1):
                    if dist[a] + 1 < dist[b] and fits(points, nodes, first, n, a, b, tolerance):
                        dist[b] = dist[a] + 1
            out[c] = dist[n]
        return out

    return shortest(points, lattice_points, offsets, tolerance, window)


def simplification_ideas(sets: list) -> None:
    """Print, per glyph set and tolerance, the vertices greedy farthest reach keeps (as the
    vertex form runs it, on the rounded lattice of step 1.4 t) against an exact optimum from the
    same start (Imai–Iri, window 512) and against the best start of all (every point of each
    contour's first span tried), so that the ideas left in docs/curves.md are measured."""
    from wavecore import curvecoder

    window = 512
    for name, curves, closed, scale in sets:
        if not closed:
            continue
        points = np.ascontiguousarray(np.concatenate(curves))
        offsets = np.zeros(len(curves) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([len(c) for c in curves])
        flags = np.ones(len(curves), dtype=np.int64)
        cells = []
        for relative in RELATIVE_TOLERANCES:
            tolerance = relative * scale
            step = 1.4 * tolerance
            nodes = np.ascontiguousarray(np.rint(points / step) * step)
            zeros = np.zeros(len(curves), dtype=np.int64)
            keep = curvecoder.reach_set(points, nodes, offsets, flags, zeros, tolerance, window)
            greedy = np.add.reduceat(keep, offsets[:-1])
            optimal = _optimal_counts(points, nodes, offsets, tolerance, window)
            kept = np.flatnonzero(keep)
            spans = [
                int(kept[np.searchsorted(kept, offsets[c]) + 1] - offsets[c])
                for c in range(len(curves))
            ]
            usual = greedy.copy()  # the encoder's rule: point 0 or one of the first 3 vertices
            for nth in (1, 2, 3):
                trial = zeros.copy()
                for c in range(len(curves)):
                    inside = kept[
                        np.searchsorted(kept, offsets[c]) : np.searchsorted(kept, offsets[c + 1])
                    ]
                    if len(inside) > nth:
                        trial[c] = inside[nth] - offsets[c]
                found = curvecoder.reach_set(
                    points, nodes, offsets, flags, trial, tolerance, window
                )
                usual = np.minimum(usual, np.add.reduceat(found, offsets[:-1]))
            every = greedy.copy()
            for k in range(1, max(spans) + 1):
                trial = np.minimum(k, spans).astype(np.int64)
                found = curvecoder.reach_set(
                    points, nodes, offsets, flags, trial, tolerance, window
                )
                every = np.minimum(every, np.add.reduceat(found, offsets[:-1]))
            cells.append(
                f"t={relative:g}: greedy {greedy.sum()}, optimal {optimal.sum()}; "
                f"starts as encoded {usual.sum()}, best start {every.sum()}"
            )
        print(f"{name}: " + "; ".join(cells), flush=True)


# --- version 5's priors (``--train-priors``) ----------------------------------------------------

#: Training glyphs: fonts matplotlib ships that the benchmark does not measure, another text.
TRAIN_FONTS = ("DejaVu Sans Mono", "DejaVu Serif Display", "cmss10", "cmtt10", "cmb10")
TRAIN_TEXT = "Quick zebras jump over 13 lazy fox dogs, ship 4780 bytes! (Hm: 5 & 9?) gwyQ"


def training_bundles():
    """The training fonts' glyph sets (TRAIN_TEXT, never the benchmark's TEXT) coded in the
    vertex form at every tolerance of the sweep and between: ``(bundle, coded_vertices)``."""
    from wavecore.curvesets import coded_vertices

    global TEXT
    kept_text, TEXT = TEXT, TRAIN_TEXT
    try:
        sets = [glyph_contours(family) for family in TRAIN_FONTS]
    finally:
        TEXT = kept_text
    for contours in sets:
        for relative in (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1):
            bundle = wavecore.encode_curves(
                contours, tolerance=relative * GLYPH_SIZE, method="vertex"
            )
            yield bundle, coded_vertices(bundle)


def train_priors() -> str:
    """The final models of version 4's streams on the training glyphs (every tolerance of
    the sweep and between), averaged into :data:`wavecore.curvecoder`'s prior table."""
    from wavecore import curvecoder

    states = []
    for _, info in training_bundles():
        lattice, counts, closed, repeated, bulges = info["coded"]
        models = curvecoder.initial_models(False)
        curvecoder.encode_set(
            lattice,
            counts,
            closed,
            repeated,
            info["closed_mode"],
            info["order"],
            bulges if info["bulged"] else None,
            info["from_last"],
            models=models,
        )
        states.append(models)
    return curvecoder.trained_table(states)


def train_copy_priors() -> str:
    """Version 6's copy models: their final states on the training glyphs coded as version 6
    (the copies as the encoder chooses them), averaged as :func:`train_priors` does."""
    from wavecore import curvecoder
    from wavecore.curvesets import check_size

    states = []
    for bundle, info in training_bundles():
        if info["version"] != 6:
            continue
        lattice, counts, closed, repeated, bulges = info["coded"]
        copies = np.zeros((len(counts), 5), dtype=np.int64)
        curvecoder.decode_bulged_set(  # the copies' sources and fractions
            bytes(bundle[: -check_size(bundle)][-info["stream"] :]),
            len(counts),
            2,
            info["closed_mode"],
            info["closed_mode"] == 1,
            len(lattice),
            info["order"],
            info["bulged"],
            info["from_last"],
            True,
            copies,
        )
        models = curvecoder.initial_models(True)
        models[2 * curvecoder.COPY_BASE :: 2] = curvecoder.PROB_HALF  # learnt from one half
        models[2 * curvecoder.COPY_BASE + 1 :: 2] = 0
        curvecoder.encode_set(
            lattice,
            counts,
            closed,
            repeated,
            info["closed_mode"],
            info["order"],
            bulges if info["bulged"] else None,
            info["from_last"],
            models=models,
            sources=copies[:, 0].copy(),
            fractions=copies[:, 1:].copy(),
        )
        states.append(models)
    print(f"# {len(states)} training sets coded as version 6", file=sys.stderr)
    return curvecoder.trained_table(states, first=curvecoder.COPY_BASE, stop=curvecoder.ALL_MODELS)


# --- the run -------------------------------------------------------------------------------


def run_set(name: str, curves: list[np.ndarray], closed: bool, scale: float) -> list[dict]:
    rows = []
    methods = [
        (name, lambda c, t, o=options: wavecore_curves(c, closed, t, o))
        for name, options in WAVECORE
    ]
    methods += [("dp+zlib", lambda c, t: dp_zlib(c, closed, t))]
    methods += [("polyline", lambda c, t: google_polyline(c, closed, t))]
    for relative in RELATIVE_TOLERANCES + PEER_EXTRA_TOLERANCES:
        tolerance = relative * scale
        for method, encode in methods:
            if relative in PEER_EXTRA_TOLERANCES and method.startswith("wavecore"):
                continue
            start = time.perf_counter()
            size, decoded = encode(curves, tolerance)
            seconds = time.perf_counter() - start
            rows.append(
                {
                    "set": name,
                    "method": method,
                    "tolerance": relative,
                    "bytes": size,
                    "deviation": deviation(curves, decoded, closed) / scale,
                    "seconds": seconds,
                }
            )
            print(
                f"{name:14s} {method:18s} t={relative:<6g} {size:7d} B  "
                f"dev={rows[-1]['deviation']:.5f}  {seconds:.2f} s",
                flush=True,
            )
    return rows


def at_equal_deviation(rows: list[dict], method: str, peer: str) -> list[tuple[str, float, float]]:
    """wavecore's bytes / the peer's bytes interpolated (log-log) at wavecore's deviation."""
    out = []
    for name in dict.fromkeys(r["set"] for r in rows):
        mine = [r for r in rows if r["set"] == name and r["method"] == method]
        theirs = sorted(
            (r["deviation"], r["bytes"]) for r in rows if r["set"] == name and r["method"] == peer
        )
        xs = np.log([d for d, _ in theirs])
        ys = np.log([b for _, b in theirs])
        for r in mine:
            if not xs[0] <= np.log(r["deviation"]) <= xs[-1]:
                msg = f"{name} {method} t={r['tolerance']}: {peer}'s sweep does not reach it"
                raise SystemExit(msg)  # a clamp would compare at unequal deviations
            peer_bytes = float(np.exp(np.interp(np.log(r["deviation"]), xs, ys)))
            out.append((name, r["tolerance"], r["bytes"] / peer_bytes))
    return out


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["set"] for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(3.2 * len(names), 3.2), sharey=False)
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        for method in dict.fromkeys(r["method"] for r in rows):
            pts = sorted(
                (r["deviation"], r["bytes"])
                for r in rows
                if r["set"] == name and r["method"] == method
            )
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, label=method)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("largest deviation (relative)", fontsize=8)
        ax.tick_params(labelsize=7)
    np.atleast_1d(axes)[0].set_ylabel("bytes", fontsize=8)
    np.atleast_1d(axes)[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def table(rows: list[dict]) -> str:
    methods = list(dict.fromkeys(r["method"] for r in rows))
    lines = [
        "| set | t | " + " | ".join(methods) + " |",
        "|---|---|" + "---|" * len(methods),
    ]
    for name in dict.fromkeys(r["set"] for r in rows):
        for relative in RELATIVE_TOLERANCES:
            cells = []
            for method in methods:
                (r,) = [
                    r
                    for r in rows
                    if r["set"] == name and r["method"] == method and r["tolerance"] == relative
                ]
                cells.append(f"{r['bytes']} B / {r['deviation']:.4f}")
            lines.append(f"| {name} | {relative:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def set_cost() -> None:
    """Seconds of ``encode_curves`` per point and per curve, and per counted sample."""
    sys.path.insert(0, str(ROOT))  # the service's package, beside the library's
    from service.cost import curve_set_samples

    rng = np.random.default_rng(0)
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {os.getloadavg()[0]:.2f}")
    print("| dims | curves × points | seconds | µs a point | ms a curve | ns a counted sample |")
    print("|---:|---:|---:|---:|---:|---:|")
    for dims in (2, 1, 3):
        for count, points in ((1, 20_000), (1_000, 2), (400, 5), (200, 30), (50, 100)):
            curves = [np.cumsum(rng.standard_normal((points, dims)), axis=0) for _ in range(count)]
            wavecore.encode_curves(curves[:2])  # compile
            start = time.perf_counter()
            wavecore.encode_curves(curves)
            seconds = time.perf_counter() - start
            counted = curve_set_samples(count * points, count)
            print(
                f"| {dims} | {count} × {points} | {seconds:.2f} | "
                f"{seconds / (count * points) * 1e6:.1f} | {seconds / count * 1e3:.2f} | "
                f"{seconds / counted * 1e9:.0f} |",
                flush=True,
            )
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {os.getloadavg()[0]:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--write",
        action="store_true",
        help="redraw docs/figures/curves_rate.png (the printed table is what the docs quote)",
    )
    parser.add_argument("--quick", action="store_true", help="one font, a short track")
    parser.add_argument(
        "--ideas",
        action="store_true",
        help="only the vertex counts of greedy reach against an optimal simplification",
    )
    parser.add_argument(
        "--train-priors",
        action="store_true",
        help="print version 5's prior table and version 6's copy models' (two lines), learnt on "
        "fonts and text the benchmark does not use",
    )
    parser.add_argument(
        "--set-cost",
        action="store_true",
        help="only the time of encode_curves per point and per curve (the service's cost model)",
    )
    args = parser.parse_args()
    if args.set_cost:
        set_cost()
        return
    if args.train_priors:
        print(train_priors())
        print(train_copy_priors())
        return
    sets = []
    for family in FONTS[:1] if args.quick else FONTS:
        contours = glyph_contours(family)
        sets.append((family, contours, True, GLYPH_SIZE))
    track = random_walk_track(1000 if args.quick else 5000)
    diagonal = float(np.linalg.norm(np.ptp(track, axis=0)))
    sets.append(("random walk", [track], False, diagonal))
    for name, curves, _, _ in sets:
        print(f"{name}: {len(curves)} curves, {sum(len(c) for c in curves)} points")
    if args.ideas:
        simplification_ideas(sets)
        return
    start = time.perf_counter()
    rows = []
    for name, curves, closed, scale in sets:
        rows += run_set(name, curves, closed, scale)
    print(f"load average {os.getloadavg()[0]:.2f}; {time.perf_counter() - start:.0f} s")
    text = table(rows)
    print(text)
    summary = []
    for method, _ in WAVECORE:
        for peer in ("dp+zlib", "polyline"):
            ratios = at_equal_deviation(rows, method, peer)
            glyph = [q for name, _, q in ratios if name != "random walk"]
            track = [q for name, _, q in ratios if name == "random walk"]
            summary.append(
                f"- {method} / {peer} at equal largest deviation: glyphs "
                f"{min(glyph):.2f}–{max(glyph):.2f} (median {np.median(glyph):.2f}), "
                f"track {min(track):.2f}–{max(track):.2f}"
            )
    print("\n".join(summary))
    if args.write:
        figure = ROOT / "docs" / "figures" / "curves_rate.png"
        plot(rows, figure)
        print(f"wrote {figure}")


if __name__ == "__main__":
    sys.exit(main())
