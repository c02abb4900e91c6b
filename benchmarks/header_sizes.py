"""Header sizes of typical bundles in format 3.0 (binary header) against 1.1 (JSON header).

    .venv/bin/python benchmarks/header_sizes.py

Each bundle is encoded once; the same header and chunks are then written in both formats
(``write_bundle(..., version=(1, 1))`` is the writer of releases before 2.0), so the payload is
identical and only the overhead differs.  ``header`` is ``inspect(...)["header_bytes"]``:
everything but the chunks (preamble, header, chunk table and checks).  Prints a Markdown table
(docs/bundle-format.md quotes it).

A second table gives the same curves as one-curve *curve sets* (``encode_curves([curve])``, at
the tolerance ``encode_curve`` uses by default: 1e-3 of the bounding-box diagonal): their
header is everything but the coded stream (magic, fields, CRC), in both forms.
"""

from __future__ import annotations

import os

import numpy as np

import wavecore
from wavecore.bundle import read_bundle, write_bundle


def cases() -> dict[str, bytes]:
    from skimage import data  # scikit-image's pictures: the figures' usual test set

    t8 = np.linspace(0, 1, 8)
    made = {"curve, 8 points": wavecore.encode_curve(np.stack([t8, np.sin(3 * t8)], 1))}
    for n in (50, 200, 1000):
        t = np.linspace(0, 1, n)
        made[f"curve, {n} points"] = wavecore.encode_curve(np.stack([t, np.sin(6 * t) * t], 1))
    made["image 512² grey (camera), default"] = wavecore.encode_image(data.camera())
    made["image 512² RGB (astronaut), default"] = wavecore.encode_image(data.astronaut())
    made["image 512² grey (camera), lossless"] = wavecore.encode_image(data.camera(), lossless=True)
    made["image 512² RGB (astronaut), lossless"] = wavecore.encode_image(
        data.astronaut(), lossless=True
    )
    u = np.linspace(0, 2 * np.pi, 64)
    uu, vv = np.meshgrid(u, np.linspace(-1, 1, 48), indexing="ij")
    grid = np.stack([np.cos(uu) * (1 + vv**2), np.sin(uu), vv], -1)
    made["surface 64 × 48 × 3, default"] = wavecore.encode_surface(grid)
    made["height field 256², default"] = wavecore.encode_surface(
        np.add.outer(np.sin(np.linspace(0, 6, 256)), np.cos(np.linspace(0, 4, 256)))
    )
    return made


def curve_points() -> dict[str, np.ndarray]:
    t8 = np.linspace(0, 1, 8)
    made = {"curve, 8 points": np.stack([t8, np.sin(3 * t8)], 1)}
    for n in (50, 200, 1000):
        t = np.linspace(0, 1, n)
        made[f"curve, {n} points"] = np.stack([t, np.sin(6 * t) * t], 1)
    return made


def curve_sets() -> None:
    print()
    print("| one-curve curve set | form | payload | header | bundle | encode_curve bundle |")
    print("|---|---|---:|---:|---:|---:|")
    for name, points in curve_points().items():
        single = len(wavecore.encode_curve(points))
        diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
        for method in ("auto", "wavelet", "vertex"):
            bundle = wavecore.encode_curves(
                [points], closed=False, tolerance=1e-3 * diagonal, method=method
            )
            info = wavecore.inspect(bundle)
            print(
                f"| {name} | {method} ({info['method']}) | {info['payload_bytes']} "
                f"| {info['header_bytes']} | {len(bundle)} | {single} |"
            )


def curve_headers() -> None:
    """``encode_curve``'s overhead (``header_bytes``: everything but the chunks) by length,
    open and closed, in two and three dimensions, with the levels it chose."""
    print()
    print("| encode_curve | 8 points | 50 points | 1000 points | 50 000 points |")
    print("|---|---:|---:|---:|---:|")
    for d in (2, 3):
        for closed in (False, True):
            cells = []
            for n in (8, 50, 1000, 50_000):
                t = np.linspace(0, 1, n)
                points = np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:d], 1)
                info = wavecore.inspect(wavecore.encode_curve(points, closed=closed))
                cells.append(f"{info['header_bytes']} B ({info['levels']} levels)")
            name = f"{d}-D, {'closed' if closed else 'open'}"
            print(f"| {name} | " + " | ".join(cells) + " |")


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.2f}")
    print("| bundle | levels | payload | header 1.1 | header 3.0 | bundle 1.1 | bundle 3.0 |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, bundle in cases().items():
        parsed = read_bundle(bundle)
        chunks = [parsed.chunk(i) for i in range(len(parsed.chunks))]
        old = write_bundle(parsed.header, chunks, version=(1, 1))
        payload = sum(map(len, chunks))
        new_header = wavecore.inspect(bundle)["header_bytes"]
        old_header = wavecore.inspect(old)["header_bytes"]
        assert new_header == len(bundle) - payload and old_header == len(old) - payload
        print(
            f"| {name} | {parsed.header['levels']} | {payload} | {old_header} | {new_header} "
            f"| {len(old)} | {len(bundle)} |"
        )
    curve_sets()
    curve_headers()


if __name__ == "__main__":
    main()
