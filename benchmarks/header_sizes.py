"""Header sizes of typical bundles in formats 4.0 (compact), 3.0 (binary header) and 1.1 (JSON).

    .venv/bin/python benchmarks/header_sizes.py

Each bundle is encoded once; the same header and chunks are then written in each format
(``write_bundle(..., version=(1, 1))`` is the writer of releases before 2.0), so the payload is
identical and only the overhead differs.  ``header`` is ``inspect(...)["header_bytes"]``:
everything but the chunks (preamble, header, chunk table and checks).  The codec writes 4.0
for curves and 3.0 for images and surfaces; the column of the version it writes is the one
in bold.  Prints Markdown tables (docs/bundle-format.md quotes them).

A second table gives the same curves as one-curve *curve sets* (``encode_curves([curve])``, at
the tolerance ``encode_curve`` uses by default: 1e-3 of the bounding-box diagonal): their
header is everything but the coded stream (magic, fields, CRC), in both forms.
"""

from __future__ import annotations

import os

import numpy as np

import wavecore
from wavecore.blockcoder import block_counts, strip_block_checks
from wavecore.bundle import read_bundle, write_bundle
from wavecore.codec.plan import plan_from_header


def cases() -> dict[str, bytes]:
    from skimage import data  # scikit-image's pictures: the figures' usual test set

    t8 = np.linspace(0, 1, 8)
    made = {"curve, 8 points": wavecore.encode_curve(np.stack([t8, np.sin(3 * t8)], 1))}
    for n in (50, 200, 1000, 50_000):
        t = np.linspace(0, 1, n)
        made[f"curve, {n} points"] = wavecore.encode_curve(np.stack([t, np.sin(6 * t) * t], 1))
    t = np.linspace(0, 1, 50_000)
    noisy = np.stack([t, np.sin(6 * t) * t], 1) + np.random.default_rng(5).normal(
        0, 0.01, (50_000, 2)
    )
    made["curve, 50 000 points + noise (σ 0.01)"] = wavecore.encode_curve(noisy)
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
    print("| encode_curve | 8 points | 50 points | 200 points | 1000 points | 50 000 points |")
    print("|---|---:|---:|---:|---:|---:|")
    for d in (2, 3):
        for closed in (False, True):
            cells = []
            for n in (8, 50, 200, 1000, 50_000):
                t = np.linspace(0, 1, n)
                points = np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:d], 1)
                info = wavecore.inspect(wavecore.encode_curve(points, closed=closed))
                cells.append(f"{info['header_bytes']} B ({info['levels']} levels)")
            name = f"{d}-D, {'closed' if closed else 'open'}"
            print(f"| {name} | " + " | ".join(cells) + " |")


def coder_chunks(bundle: bytes) -> list[bytes]:
    """The chunks as the coder wrote them (3.0 and 4.0 add block checks to chunks of several
    code-blocks; ``write_bundle`` adds them again)."""
    parsed = read_bundle(bundle)
    plan = plan_from_header(parsed.header)
    shapes = plan.band_shapes()
    one_axis = len(plan.axes) == 1
    entries = [[tuple(shapes[0])]] + [
        [tuple(entry)] if one_axis else [tuple(band) for band in entry] for entry in shapes[1:]
    ]
    cparams = parsed.header["cparams"]
    if parsed.header["coder"] != "context" or cparams.get("version", 0) < 4:
        return [bytes(chunk or b"") for chunk in parsed.chunks]
    counts = block_counts(entries, cparams["two_d"], cparams["block"])
    return [
        strip_block_checks(bytes(chunk or b""), count, len(entry) if index else 0)[0]
        for index, (chunk, count, entry) in enumerate(
            zip(parsed.chunks, counts, entries, strict=True)
        )
    ]


def deep_levels() -> None:
    """``header_bytes`` of the 50 000-point curve at levels deeper than the default (8)."""
    print()
    t = np.linspace(0, 1, 50_000)
    points = np.stack([t, np.sin(6 * t) * t], 1)
    levels = (8, 10, 12, 13, 14, 15)
    print("| 50 000 points, level | " + " | ".join(map(str, levels)) + " |")
    print("|---|" + "---:|" * len(levels))
    cells = [
        wavecore.inspect(wavecore.encode_curve(points, level=k))["header_bytes"] for k in levels
    ]
    print("| header bytes | " + " | ".join(f"{c} B" for c in cells) + " |")


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.2f}")
    versions = ((1, 1), (3, 0), (4, 0))
    print(
        "| bundle | levels | payload | header 1.1 | header 3.0 | header 4.0 "
        "| bundle 1.1 | bundle 3.0 | bundle 4.0 |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, bundle in cases().items():
        parsed = read_bundle(bundle)
        chunks = coder_chunks(bundle)
        written = {v: write_bundle(parsed.header, chunks, version=v) for v in versions}
        assert written[parsed.version] == bundle  # the same bytes as the codec wrote
        headers, sizes = [], []
        for version, data in written.items():
            info = wavecore.inspect(data)
            assert read_bundle(data).header == parsed.header
            bold = "**" if version == parsed.version else ""
            headers.append(f"{bold}{info['header_bytes']}{bold}")
            sizes.append(f"{bold}{len(data)}{bold}")
        payload = len(bundle) - wavecore.inspect(bundle)["header_bytes"]
        print(
            f"| {name} | {parsed.header['levels']} | {payload} | "
            + " | ".join(headers + sizes)
            + " |"
        )
    curve_sets()
    curve_headers()
    deep_levels()


if __name__ == "__main__":
    main()
