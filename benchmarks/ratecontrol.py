"""Rate control: codings per target, encode time, and the compression at equal bytes.

Run with ``.venv/bin/python benchmarks/ratecontrol.py`` for this checkout, or with
``--before DIR`` to compare against another copy of the code (say ``git archive main | tar -x
-C /tmp/before``): each side then runs in its own process (``PYTHONPATH=DIR``), one after the
other, and the table gives both and their ratios.  The pictures:

* 512 × 512 RGB sawtooth ramps at 1 bpp (the request of ``benchmarks/first_run.py --serve``),
* 512 × 512 RGB smooth (seeded low-frequency waves) at 1 bpp,
* scikit-image's astronaut, 512 × 512 RGB, at 1 bpp,
* scikit-image's camera, 512 × 512 grey, at the default quality (40 dB, its search included),
* the camera with ``bspline2`` at 40 dB and at 1 bpp (the wavelet whose closed loop gains most),
* a 5 000-point closed curve at the default tolerance.

For each: the entropy codings, the closed-loop quantizations and the syntheses (the searches'
verifications) one encode runs (counted by wrapping the library's coder, closed loop and
reconstruction), the code-blocks the bpp trims code again, the encode and decode times
(medians of ``--repeat``), bytes and PSNR; and OpenJPEG (through Pillow, raw codestream,
irreversible 9/7, colour transform on for RGB) at our bytes, as ``benchmarks/codec_speed.py``
configures it.  The compression check compares the two sides at
equal bytes: the PSNR difference less the local slope of PSNR against log(bytes) (measured on
the ``--before`` side) times the log of the bytes ratio.  The machine may be shared: the load
average is printed, and only same-run ratios mean much.
"""

from __future__ import annotations

import argparse
import functools
import io
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def pictures() -> dict[str, tuple[np.ndarray, dict[str, Any]]]:
    from PIL import Image
    from skimage import data

    y, x = np.mgrid[:512, :512]
    saw = np.stack([x % 256, y % 256, (x + y) % 256], -1).astype(np.uint8)
    waves = [np.sin(x / 40.0 + c) * np.cos(y / 55.0 - c) for c in (0.0, 1.0, 2.0)]
    smooth = np.clip(128 + 60 * np.stack(waves, -1), 0, 255).astype(np.uint8)
    astronaut = np.asarray(Image.fromarray(data.astronaut()).resize((512, 512)))
    camera = data.camera()
    return {
        "sawtooth RGB bpp=1": (saw, {"bpp": 1.0}),
        "smooth RGB bpp=1": (smooth, {"bpp": 1.0}),
        "astronaut RGB bpp=1": (astronaut, {"bpp": 1.0}),
        "camera grey q=40 (default)": (camera, {}),
        "camera grey bspline2 q=40": (camera, {"wavelet": "bspline2"}),
        "camera grey bspline2 bpp=1": (camera, {"wavelet": "bspline2", "bpp": 1.0}),
    }


def curve() -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, 5000, endpoint=False)
    return np.stack([np.cos(t) + 0.1 * np.cos(7 * t), np.sin(t) + 0.05 * np.sin(13 * t)], -1)


class Counter:
    """Counts calls of the entropy coder and of the closed loop, wherever the code refers to
    them (module attributes of the same function objects), so any layout of the package works."""

    def __init__(self) -> None:
        import wavecore.codec.samples
        import wavecore.entropy
        import wavecore.quantize

        self.counts = {"codings": 0, "closed loops": 0, "syntheses": 0, "blocks recoded": 0}
        targets = {
            "codings": wavecore.entropy.encode_levels,
            "closed loops": wavecore.quantize._refine,  # warm-started ones included
            "syntheses": wavecore.codec.samples.reconstruct,  # the searches' verifications
        }
        for name, function in targets.items():
            wrapped = self._wrap(name, function)
            for module in list(sys.modules.values()):
                if not getattr(module, "__name__", "").startswith("wavecore"):
                    continue
                for attribute, value in list(vars(module).items()):
                    if value is function:
                        setattr(module, attribute, wrapped)

        # The bpp trims code a few blocks again (``CodedBlocks.recode``, where it exists).
        import wavecore.blockcoder

        coded_blocks = getattr(wavecore.blockcoder, "CodedBlocks", None)
        if coded_blocks is not None:
            recode = coded_blocks.recode

            def counted_recode(blocks: Any, entries: Any, indices: Any) -> None:
                self.counts["blocks recoded"] += len(indices)
                recode(blocks, entries, indices)

            coded_blocks.recode = counted_recode

    def _wrap(self, name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        def counted(*args: Any, **kwargs: Any) -> Any:
            self.counts[name] += 1
            return function(*args, **kwargs)

        return counted

    def reset(self) -> None:
        for key in self.counts:
            self.counts[key] = 0


def median_time(run: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Median wall seconds of ``repeat`` runs, and the CPU seconds (all threads) of that run:
    on a shared machine the wall time depends on the load, the CPU time much less."""
    times = []
    for _ in range(repeat):
        start, cpu = time.perf_counter(), time.process_time()
        run()
        times.append((time.perf_counter() - start, time.process_time() - cpu))
    return sorted(times)[len(times) // 2]


def psnr(a: np.ndarray, b: np.ndarray, peak: float = 255.0) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(peak**2 / mse)


def openjpeg(image: np.ndarray, budget: int, repeat: int) -> dict[str, float]:
    from PIL import Image

    def encode() -> bytes:
        buffer = io.BytesIO()
        Image.fromarray(image).save(
            buffer,
            format="JPEG2000",
            quality_mode="rates",
            quality_layers=[image.size * 8 / (8.0 * budget)],
            irreversible=True,
            mct=1 if image.ndim == 3 else 0,
            no_jp2=True,
            num_resolutions=6,
        )
        return buffer.getvalue()

    def decode(blob: bytes) -> np.ndarray:
        picture = Image.open(io.BytesIO(blob))
        picture.load()
        return np.asarray(picture)

    blob = encode()
    return {
        "encode": median_time(encode, repeat)[0],
        "decode": median_time(lambda: decode(blob), repeat)[0],
        "bytes": len(blob),
        "psnr": psnr(decode(blob), image),
    }


def timed_case(
    counter: Counter, encode: Callable[[], bytes], repeat: int
) -> tuple[dict[str, Any], bytes]:
    """Codings and closed loops of one encode, then encode and decode medians (wall and CPU)."""
    import wavecore

    encode()  # compile and warm up
    counter.reset()
    bundle = encode()
    case: dict[str, Any] = dict(counter.counts)
    case["encode"], case["encode cpu"] = median_time(encode, repeat)
    case["decode"], _ = median_time(lambda: wavecore.decode(bundle), repeat)
    case["bytes"] = len(bundle)
    return case, bundle


def measure(repeat: int, slopes: bool) -> dict[str, Any]:
    """This process's figures (the code on ``sys.path``), as a JSON-ready dict."""
    import wavecore

    counter = Counter()
    out: dict[str, Any] = {"load before": load(), "cases": {}}
    for name, (image, options) in pictures().items():
        case, bundle = timed_case(
            counter, functools.partial(wavecore.encode_image, image, **options), repeat
        )
        case["psnr"] = psnr(wavecore.decode(bundle), image)
        case["openjpeg"] = openjpeg(image, len(bundle), repeat)
        if slopes:  # PSNR against log(bytes) around this point, for the equal-bytes comparison
            points = []
            for factor in (0.95, 1.05):
                near = dict(options)
                if "bpp" in near:
                    near["bpp"] *= factor
                else:
                    near["quality"] = near.get("quality", 40.0) + (0.5 if factor > 1 else -0.5)
                other = wavecore.encode_image(image, **near)
                points.append((math.log(len(other)), psnr(wavecore.decode(other), image)))
            (x0, y0), (x1, y1) = points
            case["slope"] = (y1 - y0) / (x1 - x0)
        out["cases"][name] = case
    points = curve()
    case, bundle = timed_case(
        counter, functools.partial(wavecore.encode_curve, points, closed=True), repeat
    )
    case["max error"] = float(np.max(np.linalg.norm(wavecore.decode(bundle) - points, axis=1)))
    out["cases"]["curve 5000 points, default tolerance"] = case
    out["load after"] = load()
    return out


def run_side(path: str | None, repeat: int, slopes: bool) -> dict[str, Any]:
    env = dict(os.environ)
    if path is not None:
        env["PYTHONPATH"] = path
    args = [sys.executable, __file__, "--json", "--repeat", str(repeat)]
    if slopes:
        args.append("--slopes")
    result = subprocess.run(args, env=env, capture_output=True, text=True, check=True)
    return dict(json.loads(result.stdout.strip().splitlines()[-1]))


def table(before: dict[str, Any] | None, after: dict[str, Any]) -> list[str]:
    lines = []
    for name, now in after["cases"].items():
        lines.append(f"{name}:")
        old = before["cases"][name] if before is not None else None
        for label, case in (("before", old), ("after", now)):
            if case is None:
                continue
            line = (
                f"  {label:6s} codings {case['codings']:2d} "
                f"(+{case.get('blocks recoded', 0)} blocks), "
                f"closed loops {case['closed loops']:2d}, "
                f"syntheses {case.get('syntheses', 0):2d}, encode {case['encode']:.3f} s "
                f"(CPU {case['encode cpu']:.3f} s), "
                f"decode {case['decode']:.3f} s, "
                f"{case['bytes']} B"
            )
            if "psnr" in case:
                peer = case["openjpeg"]
                ours = case["encode"] + case["decode"]
                theirs = peer["encode"] + peer["decode"]
                line += (
                    f", {case['psnr']:.3f} dB; OpenJPEG at these bytes: encode "
                    f"{peer['encode']:.3f} s, decode {peer['decode']:.3f} s, "
                    f"{peer['psnr']:.3f} dB; ours/OpenJPEG (enc+dec) {ours / theirs:.1f}x"
                )
            else:
                line += f", largest deviation {case['max error']:.3g}"
            lines.append(line)
        if old is not None:
            line = (
                f"  after/before encode time {now['encode'] / old['encode']:.2f}x "
                f"(CPU {now['encode cpu'] / old['encode cpu']:.2f}x)"
            )
            if "slope" in old:
                shift = math.log(now["bytes"] / old["bytes"])
                gain = now["psnr"] - old["psnr"] - old["slope"] * shift
                line += (
                    f"; PSNR at equal bytes {gain:+.3f} dB (slope {old['slope']:.2f} dB per "
                    f"log-byte, bytes {now['bytes'] / old['bytes'] - 1:+.2%})"
                )
            else:
                line += f"; bytes {now['bytes'] / old['bytes'] - 1:+.2%}"
            lines.append(line)
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--before", help="a copy of the code to compare against")
    parser.add_argument("--after", help="the code to measure (default: the one installed)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--slopes", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.json:
        print(json.dumps(measure(args.repeat, args.slopes)))
        return
    print(f"load average before: {load()}")
    before = run_side(args.before, args.repeat, True) if args.before else None
    after = run_side(args.after, args.repeat, False)
    for line in table(before, after):
        print(line)
    print(f"load average after: {load()}")


if __name__ == "__main__":
    main()
