"""Region decode against a full decode: a 256 × 256 window of a 2048 × 2048 bundle.

The picture is issue 11's: scikit-image's astronaut enlarged to 2048² with Lanczos (Pillow),
plus a little noise, coded at 1 bpp (RGB, and its grey version), with the default wavelet and
with bspline2, and losslessly (the default lossless coder, whose stripes decode apart, and the
block coder of ``effort="fast"``).  For each bundle: the median time of ``wavecore.decode(bundle)``
and of ``wavecore.decode(bundle, region=...)`` for a 256² window in the middle and at a corner,
their ratio, and a check that the window equals the full decode cropped.  Also the bytes that
format 3.0's block checks add (the same chunks written as 3.0 and as 2.0), and the 3.1 bundle
the codec writes (3.0's checks, no chunk lengths).

Run: ``python benchmarks/region_decode.py [--repeat 5]``.  One process; the machine may be
shared, so the load average is printed with the figures.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from PIL import Image
from skimage import data

import wavecore
from wavecore.blockcoder import block_counts, strip_block_checks
from wavecore.bundle import read_bundle, write_bundle
from wavecore.codec.plan import plan_from_header

SIDE = 2048
WINDOW = 256


def picture() -> np.ndarray:
    rgb = Image.fromarray(data.astronaut()).resize((SIDE, SIDE), Image.Resampling.LANCZOS)
    noise = np.random.default_rng(0).normal(0, 2.0, (SIDE, SIDE, 3))
    return (np.asarray(rgb, dtype=np.float64) + noise).clip(0, 255).round().astype(np.uint8)


def median_time(run: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def coder_chunks(bundle: bytes) -> tuple[dict[str, Any], list[bytes], list[int]]:
    """A bundle's header, its chunks as the coder wrote them (block checks taken out) and
    each chunk's number of code-blocks."""
    parsed = read_bundle(bundle)
    plan = plan_from_header(parsed.header)
    shapes = plan.band_shapes()
    entries = [[tuple(shapes[0])]] + [[tuple(band) for band in entry] for entry in shapes[1:]]
    cparams = parsed.header["cparams"]
    counts = block_counts(entries, cparams["two_d"], cparams["block"])
    chunks = [
        strip_block_checks(bytes(chunk or b""), count, len(entry) if index else 0)[0]
        for index, (chunk, count, entry) in enumerate(
            zip(parsed.chunks, counts, entries, strict=True)
        )
    ]
    return parsed.header, chunks, counts


def checks_overhead(bundle: bytes) -> int | str:
    """Bytes that format 3.0's block checks add: the same coded chunks written as 3.0 and 2.0
    (3.1, as the codec writes it, keeps those checks and drops the chunk lengths); "—" for
    the lossless coder's bundles, which have no blocks."""
    if "block" not in read_bundle(bundle).header["cparams"]:
        return "—"
    header, chunks, _ = coder_chunks(bundle)
    return len(write_bundle(header, chunks, version=(3, 0))) - len(
        write_bundle(header, chunks, version=(2, 0))
    )


def block_check_sizes() -> None:
    """What format 3.0 adds to the 512² pictures of benchmarks/header_sizes.py, and the 3.1
    bundle the codec writes from the same chunks."""
    pictures = {
        "image 512² grey (camera)": data.camera(),
        "image 512² RGB (astronaut)": data.astronaut(),
    }
    print(
        "| bundle | bytes 2.0 | bytes 3.0 | 3.0 adds | bytes 3.1 (written) "
        "| blocks in chunks of several |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for name, image in pictures.items():
        # lossless: the block coder's (the default lossless coder has no code-blocks)
        fast: dict[str, Any] = {"lossless": True, "effort": "fast"}
        for label, options in (("default", {}), ("lossless fast", fast)):
            bundle = wavecore.encode_image(image, **options)
            header, chunks, counts = coder_chunks(bundle)
            old = len(write_bundle(header, chunks, version=(2, 0)))
            three = len(write_bundle(header, chunks, version=(3, 0)))
            several = sum(n for n in counts if n > 1)
            print(
                f"| {name}, {label} | {old} | {three} | {three - old} | {len(bundle)} | {several} |"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--sizes-only", action="store_true", help="only the 512² byte counts")
    args = parser.parse_args()
    block_check_sizes()
    if args.sizes_only:
        return
    rgb = picture()
    grey = np.asarray(Image.fromarray(rgb).convert("L"))
    cases = {
        "grey 1 bpp (default wavelet)": wavecore.encode_image(grey, bpp=1.0),
        "grey 1 bpp bspline2": wavecore.encode_image(grey, bpp=1.0, wavelet="bspline2"),
        "RGB 1 bpp (default wavelet)": wavecore.encode_image(rgb, bpp=1.0),
        "grey lossless": wavecore.encode_image(grey, lossless=True),
        "grey lossless fast": wavecore.encode_image(grey, lossless=True, effort="fast"),
    }
    middle = slice(SIDE // 2 - WINDOW // 2, SIDE // 2 + WINDOW // 2)
    windows = {"middle": (middle, middle), "corner": (slice(0, WINDOW), slice(0, WINDOW))}
    print(f"load average before: {os.getloadavg()}")
    print(f"{SIDE}² pictures, {WINDOW}² windows, median of {args.repeat} decodes")
    print("| bundle | bytes | block checks (B) | full decode | window | region decode | speed-up |")
    print("|---|---:|---:|---:|---|---:|---:|")
    for name, bundle in cases.items():
        wavecore.decode(bundle)  # warm-up: compile, caches
        full = median_time(lambda b=bundle: wavecore.decode(b), args.repeat)
        reference = wavecore.decode(bundle)
        overhead = checks_overhead(bundle)
        for where, window in windows.items():
            part = wavecore.decode(bundle, region=window)
            assert np.array_equal(part, reference[window]), (name, where)
            region = median_time(
                lambda b=bundle, w=window: wavecore.decode(b, region=w), args.repeat
            )
            print(
                f"| {name} | {len(bundle)} | {overhead} | {full * 1e3:.0f} ms | {where} | "
                f"{region * 1e3:.1f} ms | {full / region:.1f}× |"
            )
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
