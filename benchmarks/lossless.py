"""Lossless sizes: ``encode_image(..., lossless=True)`` against Pillow's PNG (``optimize=True``).

The other lossless peers, each configured as its best users configure it (``peers.py``): WebP
lossless (``method=6``, ``quality=100``), JPEG XL lossless at effort 7 (imagecodecs), and
OpenJPEG's reversible 5/3 with its colour transform on (``mct=1``) as a raw codestream.  Every
peer's file is decoded and checked bit-exact.

    .venv/bin/python benchmarks/lossless.py [--write]

For scikit-image's camera, moon, coins, brick (grey) and astronaut (RGB): our bundle's bytes
(header included) and PNG's, their ratio, bits per pixel, whether the round trip is bit-exact,
and the median encode/decode times of both over a few runs in this process.  With ``--write``
the table replaces the "Lossless" section of ``docs/benchmarks.md`` (between its markers).
"""

from __future__ import annotations

import argparse
import io
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from skimage import data

import wavecore

try:  # run as a script: benchmarks/ is on the path
    import peers
except ImportError:  # imported as benchmarks.lossless
    from benchmarks import peers

IMAGES = ["camera", "moon", "coins", "brick", "astronaut"]
RUNS = 3
DOCS = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
START, END = "<!-- lossless:start -->", "<!-- lossless:end -->"
#: The block coder's path (the default until 2026-12-07), measured beside the default's
#: lossless coder (wavecore.losslesscoder).
FAST: dict[str, Any] = {"lossless": True, "effort": "fast"}


#: CPU seconds (all threads of this process) of the latest ``median_time``, as a median: on
#: a shared machine wall time depends on the load, CPU time much less.
CPU: dict[str, float] = {"last": 0.0}


def median_time(function: Callable[[], Any]) -> tuple[float, Any]:
    times, cpu, result = [], [], None
    for _ in range(RUNS):
        start, cpu_start = time.perf_counter(), time.process_time()
        result = function()
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - cpu_start)
    CPU["last"] = statistics.median(cpu)
    return statistics.median(times), result


def png_bytes(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def peer_sizes(image: np.ndarray) -> dict[str, int]:
    """Bytes of every lossless peer (each decoded and checked bit-exact)."""
    sizes = {}
    for name, (encode, decode) in peers.lossless_peers(colour=image.ndim == 3).items():
        blob = encode(image)
        if not np.array_equal(decode(blob, image), image):
            raise AssertionError(f"{name} is not lossless on this image")
        sizes[name] = len(blob)
    return sizes


def measure(name: str) -> dict[str, Any]:
    image = getattr(data, name)()
    pixels = image.shape[0] * image.shape[1]
    wavecore.encode_image(image, lossless=True)  # compiled and warm, as for PNG
    encode_time, bundle = median_time(lambda: wavecore.encode_image(image, lossless=True))
    cpu = CPU["last"]
    decode_time, decoded = median_time(lambda: wavecore.decode(bundle))
    cpu += CPU["last"]
    png_encode, png = median_time(lambda: png_bytes(image))
    png_cpu = CPU["last"]
    png_decode, _ = median_time(lambda: np.asarray(Image.open(io.BytesIO(png))))
    png_cpu += CPU["last"]
    info = wavecore.inspect(bundle)
    others = peer_sizes(image)
    wavecore.encode_image(image, **FAST)  # compiled and warm
    fast_encode, fast = median_time(lambda: wavecore.encode_image(image, **FAST))
    fast_cpu = CPU["last"]
    fast_decode, fast_decoded = median_time(lambda: wavecore.decode(fast))
    fast_cpu += CPU["last"]
    if not np.array_equal(fast_decoded, image):
        raise AssertionError(f"effort='fast' is not lossless on {name}")
    return {
        "fast": len(fast),
        "fast_lifting": ",".join(wavecore.inspect(fast)["header"]["lifting"]) or "—",
        "fast_encode": fast_encode,
        "fast_decode": fast_decode,
        "fast_cpu": fast_cpu,
        "peers": others,
        "colour": image.ndim == 3,
        "j2k": others["OpenJPEG lossless"],
        "name": name,
        "shape": "×".join(str(s) for s in image.shape),
        "ours": len(bundle),
        "png": len(png),
        "ratio": len(bundle) / len(png),
        "bpp": 8 * len(bundle) / pixels,
        "png_bpp": 8 * len(png) / pixels,
        "exact": bool(np.array_equal(decoded, image)),
        "lifting": ",".join(info["header"]["lifting"]) or "— (predicted)",
        "encode": encode_time,
        "decode": decode_time,
        "png_encode": png_encode,
        "png_decode": png_decode,
        "cpu": cpu,
        "png_cpu": png_cpu,
    }


def table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| image | shape | ours (bytes) | PNG (bytes) | ours / PNG | ours bpp | PNG bpp "
        "| OpenJPEG lossless, mct (bytes) | bit-exact | lifting per level (finest first) "
        "| encode ours / PNG (s) | decode ours / PNG (s) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['shape']} | {r['ours']:,} | {r['png']:,} | {r['ratio']:.3f} "
            f"| {r['bpp']:.3f} | {r['png_bpp']:.3f} | {r['j2k']:,} "
            f"| {'yes' if r['exact'] else 'NO'} "
            f"| {r['lifting']} | {r['encode']:.3f} / {r['png_encode']:.3f} "
            f"| {r['decode']:.3f} / {r['png_decode']:.3f} |"
        )
    total_ours = sum(r["ours"] for r in rows)
    total_png = sum(r["png"] for r in rows)
    total_j2k = sum(r["j2k"] for r in rows)
    times = {key: sum(r[key] for r in rows) for key in ("encode", "decode", "png_encode")}
    times["png_decode"] = sum(r["png_decode"] for r in rows)
    lines.append(
        f"| **all** | | {total_ours:,} | {total_png:,} | {total_ours / total_png:.3f} | | "
        f"| {total_j2k:,} | | | {times['encode']:.3f} / {times['png_encode']:.3f} "
        f"| {times['decode']:.3f} / {times['png_decode']:.3f} |"
    )
    return "\n".join(lines)


def time_summary(rows: list[dict[str, Any]]) -> str:
    """Encode + decode over all the images, ours against PNG's: wall time and CPU time."""
    ours = sum(r["encode"] + r["decode"] for r in rows)
    png = sum(r["png_encode"] + r["png_decode"] for r in rows)
    cpu, png_cpu = sum(r["cpu"] for r in rows), sum(r["png_cpu"] for r in rows)
    fast = sum(r["fast_encode"] + r["fast_decode"] for r in rows)
    fast_cpu = sum(r["fast_cpu"] for r in rows)
    return (
        f"encode + decode, all images: ours {ours:.3f} s, PNG {png:.3f} s ({ours / png:.2f}x); "
        f"CPU ours {cpu:.3f} s, PNG {png_cpu:.3f} s ({cpu / png_cpu:.2f}x); "
        f"load {load_average()}\n"
        f"effort='fast', same run: {fast:.3f} s ({fast / png:.2f}x PNG, {fast / ours:.2f}x "
        f"default); CPU {fast_cpu:.3f} s ({fast_cpu / png_cpu:.2f}x PNG, "
        f"{fast_cpu / cpu:.2f}x default)"
    )


def fast_against_default(rows: list[dict[str, Any]]) -> str:
    """``effort="fast"``'s encode + decode against the default's, wall and CPU, in words."""
    ours = sum(r["encode"] + r["decode"] for r in rows)
    fast = sum(r["fast_encode"] + r["fast_decode"] for r in rows)
    cpu, fast_cpu = sum(r["cpu"] for r in rows), sum(r["fast_cpu"] for r in rows)
    return f"{fast / ours:.2f}× the default's wall time and {fast_cpu / cpu:.2f}× its CPU time"


def peer_table(rows: list[dict[str, Any]]) -> str:
    """Bytes of every lossless peer, and our total against each, grey and colour apart."""
    names = list(rows[0]["peers"])
    lines = [
        "| image | ours | " + " | ".join(names) + " |",
        "|---|---:|" + "---:|" * len(names),
    ]
    for r in rows:
        cells = [f"{r['peers'][n]:,}" if n in r["peers"] else "—" for n in names]
        lines.append(f"| {r['name']} | {r['ours']:,} | " + " | ".join(cells) + " |")
    for group, members in (
        ("grey", [r for r in rows if not r["colour"]]),
        ("colour", [r for r in rows if r["colour"]]),
    ):
        if not members:
            continue
        ours = sum(r["ours"] for r in members)
        cells = []
        for n in names:
            theirs = sum(r["peers"][n] for r in members)
            cells.append(f"{theirs:,} (ours {ours / theirs:.3f}×)")
        lines.append(f"| **{group} total** | {ours:,} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def fast_table(rows: list[dict[str, Any]]) -> str:
    """``effort="fast"``: bytes against the default, JPEG XL e7 and WebP lossless; time
    against PNG."""
    # JPEG XL is measured only where imagecodecs is installed (peers.jxl_available): without
    # it the column says so rather than the table failing.
    jxl, webp = (
        next((n for n in rows[0]["peers"] if n.startswith(p)), f"{p} (not installed)")
        for p in ("JPEG XL", "WebP")
    )

    def cell(r: dict[str, Any], name: str) -> str:
        return f"{r['peers'][name]:,}" if name in r["peers"] else "—"

    lines = [
        f"| image | fast (bytes) | default (bytes) | {jxl} | {webp} | lifting "
        "| encode + decode fast / PNG (s) |",
        "|---|---:|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['fast']:,} | {r['ours']:,} | {cell(r, jxl)} "
            f"| {cell(r, webp)} | {r['fast_lifting']} "
            f"| {r['fast_encode'] + r['fast_decode']:.3f} / "
            f"{r['png_encode'] + r['png_decode']:.3f} |"
        )
    for group, members in (
        ("grey", [r for r in rows if not r["colour"]]),
        ("colour", [r for r in rows if r["colour"]]),
    ):
        if members:
            fast, ours = sum(r["fast"] for r in members), sum(r["ours"] for r in members)
            totals = []
            for n in (jxl, webp):
                if all(n in r["peers"] for r in members):
                    theirs = sum(r["peers"][n] for r in members)
                    totals.append(f"{theirs:,} (fast {fast / theirs:.3f}×)")
                else:
                    totals.append("—")
            lines.append(
                f"| **{group} total** | {fast:,} | {ours:,} (fast {fast / ours:.3f}×) "
                f"| {totals[0]} | {totals[1]} | | |"
            )
    mine = sum(r["fast_encode"] + r["fast_decode"] for r in rows)
    png = sum(r["png_encode"] + r["png_decode"] for r in rows)
    cpu, png_cpu = sum(r["fast_cpu"] for r in rows), sum(r["png_cpu"] for r in rows)
    lines.append(
        f"| **all** | | | | | | {mine:.3f} / {png:.3f} ({mine / png:.2f}×; "
        f"CPU {cpu / png_cpu:.2f}×) |"
    )
    return "\n".join(lines)


def load_average() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def section(rows: list[dict[str, Any]]) -> str:
    return "\n".join(
        [
            START,
            "## Lossless",
            "",
            "`encode_image(image, lossless=True)` against Pillow's PNG with `optimize=True`, on "
            "scikit-image's images; bytes are whole files (our header included); times are "
            f"medians of {RUNS} runs in one process on a shared 2-core machine "
            "(`benchmarks/lossless.py --write` regenerates this table).",
            "",
            table(rows),
            "",
            "Against every lossless peer configured as its best users configure it "
            "(`benchmarks/peers.py`: PNG `optimize=True`, WebP lossless `method=6`, JPEG XL "
            "lossless effort 7 through imagecodecs, OpenJPEG reversible with `mct=1` as a raw "
            "codestream; each file decoded and checked bit-exact), bytes, with our total's "
            f"ratio to each peer's (load average at the end of the run: {load_average()}):",
            "",
            peer_table(rows),
            "",
            "The default is the lossless coder (`wavecore.losslesscoder`, specified in "
            "`docs/bundle-format.md`): each bit of each value (its bit length in unary, the two "
            "bits below the leading one, its sign) is coded at the logistic mix of three "
            "adaptive models (PAQ's mixing, in integers), whose contexts are the neighbours' "
            "magnitudes, the parent band or the predictor's recent errors, and the other bands "
            "or the local gradients.  Without a `level` the encoder codes the picture itself, "
            "predicted by JPEG XL's weighted predictor with LOCO-I's median edge detector as a "
            "fifth sub-predictor, unless one lifting level has a first-order entropy under "
            "0.9 × the picture's (`wavecore.lossless.choose_depth`, which asks a sample of a "
            "tall picture's rows first; from 0.9 to 0.98 the encoder codes a sample both ways "
            "and keeps the smaller).  `moon`, a 2× pixel-repeated enlargement, is coded as "
            "its 256² source (`wavecore.codec.replication`, format 7.0; before, integer Haar "
            "won one level of it, where its details are all zero).  RGB goes through "
            "JPEG 2000's reversible colour transform, with Cr then predicted from Cb at a "
            "weight w/8 chosen per picture (colour `rct-p<w>`).  Each level is coded in stripes "
            "of 192 rows or more (at most 16), in parallel; a region decodes only the stripes "
            "holding its rows, `decode(level=k)` of a bundle coded with fewer levels lifts the "
            "thumbnail from the decoded picture, and damage loses a whole level.  16-bit images "
            "are bit-exact too (tested), but scikit-image ships none to compare.",
            "",
            '### `effort="fast"`',
            "",
            '`encode_image(image, lossless=True, effort="fast")`, the block coder (the default '
            "until 2026-12-07), same images and run: bytes against the default, JPEG XL e7 and "
            "WebP lossless, and encode + decode time against PNG's.",
            "",
            fast_table(rows),
            "",
            "Its transform is the reversible integer lifting of `wavecore.lossless`: per level "
            "LeGall 5/3, JPEG 2000 Part 2's 5/11-C (5/3 with one more predict step, from the "
            "coarse samples' curvature), integer Haar or the closed `bspline2`'s exact integer "
            "lifting, chosen by first-order entropy and confirmed by coding; the context "
            "entropy coder of `wavecore.entropy` in code-blocks.  Without a `level`, the "
            "encoder codes 2 and 3 levels and keeps the smaller (`wavecore.lossless.best_depth`, "
            "which re-codes only the coarse part of the deeper one).  The paper's *open* "
            "`bspline2` has no integer form: its analysis matrix has determinant ±2, and an "
            "integer bijection needs ±1 (see `docs/bundle-format.md`).  Its bundles decode a "
            "region by code-blocks, a coarser level from the coarse chunks alone, and lose "
            "only the damaged blocks.  In this run it took "
            f"{fast_against_default(rows)}.",
            END,
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="update docs/benchmarks.md")
    args = parser.parse_args()
    rows = [measure(name) for name in IMAGES]
    text = section(rows)
    print(text)
    print(time_summary(rows))
    if args.write:
        current = DOCS.read_text() if DOCS.exists() else "# Benchmarks\n"
        if START in current and END in current:
            before, rest = current.split(START, 1)
            after = rest.split(END, 1)[1]
            current = before + text + after
        else:
            current = current.rstrip("\n") + "\n\n" + text + "\n"
        DOCS.write_text(current)


if __name__ == "__main__":
    main()
