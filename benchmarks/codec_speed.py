"""Codec speed: encode + decode of a 2048 × 2048 RGB image at about 1 bpp, against OpenJPEG.

Run with ``.venv/bin/python benchmarks/codec_speed.py`` (``--size 1024`` for a quick look,
``--profile`` to print where our time goes).  In one process, medians of ``--repeat`` runs:

* ours: ``wavecore.encode_image(image, wavelet=w, bpp=1.0)`` (rate control included: it searches
  the quantizer step that meets the rate) and ``wavecore.decode`` of the bundle;
* ours at a fixed step: ``encode_image(image, wavelet=w, quality=q)`` is also a search, so the
  single pass (transform, quantize, entropy code, and back) is timed through the stages;
* Pillow's JPEG 2000 (OpenJPEG, ``quality_mode="rates"``, irreversible 9/7, the same rate)
  ``save`` and ``open(...).load()``.

The picture is scikit-image's astronaut, enlarged to 2048 × 2048 with Lanczos and given a
little noise so that the fine subbands are not empty.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import re
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image
from skimage import data

import wavecore
from wavecore.colour import ycbcr_forward
from wavecore.entropy import decode_levels, encode_levels
from wavecore.quantize import dequantize_bands, quantize_bands

DOC = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
START, END = "<!-- codec-speed:start -->", "<!-- codec-speed:end -->"


def write_section(lines: list[str]) -> None:
    """Replace the table of the "Codec speed" section (between its markers) with ``lines``."""
    text = DOC.read_text() if DOC.exists() else "# Benchmarks\n"
    body = "\n".join(["```text", *lines, "```"])
    if START in text and END in text:
        pattern = re.escape(START) + ".*?" + re.escape(END)
        text = re.sub(pattern, lambda _: f"{START}\n{body}\n{END}", text, flags=re.S)
    else:
        text = text.rstrip("\n") + f"\n\n## Codec speed\n\n{START}\n{body}\n{END}\n"
    DOC.write_text(text)


def test_image(size: int) -> np.ndarray:
    image = Image.fromarray(data.astronaut()).resize((size, size), Image.Resampling.LANCZOS)
    noise = np.random.default_rng(0).normal(0, 2.0, (size, size, 3))
    return np.clip(np.asarray(image, dtype=np.float64) + noise, 0, 255).astype(np.uint8)


def median_time(run: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def openjpeg(
    image: np.ndarray, rate: float
) -> tuple[bytes, Callable[[], bytes], Callable[[], np.ndarray]]:
    ratio = 24.0 / rate  # 24 raw bits per pixel

    def encode() -> bytes:
        buffer = io.BytesIO()
        Image.fromarray(image).save(
            buffer,
            format="JPEG2000",
            quality_mode="rates",
            quality_layers=[ratio],
            irreversible=True,
            num_resolutions=6,
        )
        return buffer.getvalue()

    blob = encode()

    def decode() -> np.ndarray:
        decoded = Image.open(io.BytesIO(blob))
        decoded.load()
        return np.asarray(decoded)

    return blob, encode, decode


def single_pass(image: np.ndarray, wavelet: str, step: float) -> dict[str, Callable[[], object]]:
    """The stages of one encode and one decode at a fixed step (no rate search)."""
    x = ycbcr_forward(image.astype(np.float64))  # as encode_image does for colour pictures
    padded, _ = wavecore.pad_to_fit(x, 5, axes=(0, 1), boundary="open", wavelet=wavelet)
    state: dict[str, object] = {}

    def transform() -> None:
        state["coeffs"] = wavecore.wavedec2(padded, wavelet, "open", 5)

    def quantize() -> None:
        state["q"], state["qp"] = quantize_bands(
            state["coeffs"],
            step,
            wavelet=wavelet,
            boundary="open",  # type: ignore[arg-type]
        )

    def entropy_encode() -> None:
        state["chunks"], state["cp"] = encode_levels(state["q"])  # type: ignore[arg-type]

    def entropy_decode() -> None:
        shapes = (
            [state["q"][0].shape]
            + [  # type: ignore[index]
                tuple(b.shape for b in e)
                for e in state["q"][1:]  # type: ignore[index]
            ]
        )
        state["q2"] = decode_levels(state["chunks"], shapes, state["cp"])  # type: ignore[arg-type]

    def dequantize() -> None:
        state["c2"] = dequantize_bands(
            state["q2"],
            state["qp"],
            wavelet=wavelet,
            boundary="open",  # type: ignore[arg-type]
        )

    def inverse() -> None:
        wavecore.waverec2(state["c2"], wavelet, "open")  # type: ignore[arg-type]

    return {
        "transform": transform,
        "quantize": quantize,
        "entropy encode": entropy_encode,
        "entropy decode": entropy_decode,
        "dequantize": dequantize,
        "inverse transform": inverse,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=2048)
    parser.add_argument("--rate", type=float, default=1.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--wavelets", default="bspline2,cdf97")
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--write", action="store_true", help="put the table in docs/benchmarks.md")
    args = parser.parse_args()
    report: list[str] = []

    def say(line: str) -> None:
        print(line, flush=True)
        report.append(line)

    image = test_image(args.size)
    blob, j2k_encode, j2k_decode = openjpeg(image, args.rate)
    wavecore.decode(wavecore.encode_image(image[:64, :64], bpp=2.0))  # compile and warm up
    t_j2k_enc = median_time(j2k_encode, args.repeat)
    t_j2k_dec = median_time(j2k_decode, args.repeat)
    pixels = args.size * args.size
    say(f"{args.size}x{args.size} RGB at {args.rate} bpp, medians of {args.repeat} runs")
    say(
        f"OpenJPEG   encode {t_j2k_enc:6.2f} s  decode {t_j2k_dec:6.2f} s  "
        f"total {t_j2k_enc + t_j2k_dec:6.2f} s  ({8 * len(blob) / pixels:.3f} bpp)"
    )
    for wavelet in args.wavelets.split(","):
        bundle = wavecore.encode_image(image, wavelet=wavelet, bpp=args.rate)
        t_enc = median_time(
            lambda w=wavelet: wavecore.encode_image(image, wavelet=w, bpp=args.rate), args.repeat
        )
        t_dec = median_time(lambda b=bundle: wavecore.decode(b), args.repeat)
        total = t_enc + t_dec
        say(
            f"{wavelet:10s} encode {t_enc:6.2f} s  decode {t_dec:6.2f} s  total {total:6.2f} s"
            f"  ({8 * len(bundle) / pixels:.3f} bpp)  ratio to OpenJPEG "
            f"{total / (t_j2k_enc + t_j2k_dec):.2f}x"
        )
        info = wavecore.inspect(bundle)
        step_guess = float(info["header"]["qparams"]["step"])
        stages = single_pass(image, wavelet, step_guess)
        line = []
        for name, stage in stages.items():
            line.append(f"{name} {median_time(stage, args.repeat):.3f}")
        say(f"{'':10s} one pass at the chosen step (s): " + ", ".join(line))
        if args.profile:
            profiler = cProfile.Profile()
            profiler.enable()
            wavecore.decode(wavecore.encode_image(image, wavelet=wavelet, bpp=args.rate))
            profiler.disable()
            pstats.Stats(profiler).sort_stats("cumulative").print_stats(18)
    if args.write:
        write_section(report)


if __name__ == "__main__":
    main()
