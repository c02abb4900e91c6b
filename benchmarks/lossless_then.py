"""The default lossless encode + decode now against the default when issue 12 was filed.

Issue 12 asks that lossless coding stay "at least as fast as today": this checks out the
commit of that day (``8184d20``, main on 2026-11-22 at 20:56 UTC, or ``--then REV``) into a
temporary git worktree and times, in alternating subprocesses, that checkout's
``encode_image(image, lossless=True)`` + ``decode`` and today's on scikit-image's camera,
moon, coins, brick and astronaut, each against Pillow's PNG (``optimize=True``) in the same
process.  The first run of the old checkout compiles its kernels and is not counted.

    .venv/bin/python benchmarks/lossless_then.py [--then REV] [--rounds 2]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: One process's measurement: bytes and medians of ``lossless.RUNS``, ours and PNG's, on the
#: five pictures.
TIMING = r"""
import numpy as np
from PIL import Image
from skimage import data
import io
import wavecore
from lossless import median_time, png_bytes  # benchmarks/lossless.py's, on this wavecore

ours = theirs = 0.0
size = 0
for name in ["camera", "moon", "coins", "brick", "astronaut"]:
    image = getattr(data, name)()
    wavecore.decode(wavecore.encode_image(image, lossless=True))  # warm
    encode, bundle = median_time(lambda: wavecore.encode_image(image, lossless=True))
    decode, out = median_time(lambda: wavecore.decode(bundle))
    assert np.array_equal(out, image), name
    png_encode, blob = median_time(lambda: png_bytes(image))
    png_decode, _ = median_time(lambda: np.asarray(Image.open(io.BytesIO(blob))))
    ours += encode + decode
    theirs += png_encode + png_decode
    size += len(bundle)
print(f"{size} {ours:.4f} {theirs:.4f}")
"""


def measure(source: Path) -> tuple[int, float, float]:
    # that checkout's wavecore first; this checkout's benchmarks/ for the timing helpers
    env = {**os.environ, "PYTHONPATH": f"{source}{os.pathsep}{ROOT / 'benchmarks'}"}
    out = subprocess.run(
        [sys.executable, "-c", TIMING],
        env=env,
        cwd=source,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return int(out[0]), float(out[1]), float(out[2])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--then", default="8184d20", help="the commit to compare with")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        then = Path(tmp) / "then"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(then), args.then],
            check=True,
            capture_output=True,
        )
        try:
            measure(then)  # compiles the old kernels into its own cache
            print(f"load average before: {os.getloadavg()}")
            print("| code | bytes | encode + decode (s) | PNG (s) | ours / PNG |")
            print("|---|---:|---:|---:|---:|")
            ratios: dict[str, list[float]] = {"then": [], "now": []}
            for _ in range(args.rounds):
                for label, source in (("then", then), ("now", ROOT)):
                    size, ours, png = measure(source)
                    ratios[label].append(ours / png)
                    name = f"{args.then} (then)" if label == "then" else "this checkout"
                    print(f"| {name} | {size:,} | {ours:.3f} | {png:.3f} | {ours / png:.2f} |")
            print(f"load average after: {os.getloadavg()}")
            now, old = min(ratios["now"]), max(ratios["now"])
            print(
                f"now/PNG {now:.2f}-{old:.2f}, then/PNG {min(ratios['then']):.2f}-"
                f"{max(ratios['then']):.2f}"
            )
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(then)],
                check=False,
                capture_output=True,
            )


if __name__ == "__main__":
    main()
