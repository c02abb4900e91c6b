"""Tall, thin pictures against wide ones of the same size: the transform and the encoder.

A picture of many short rows used to pay the row kernels' set-up once per row (and the fused
2-D levels once per fine row), so a 65 536 × 8 level took some 20 times as long a sample as an
8 × 65 536 one.  Short rows now run through the column kernels, one step per axis.  This runs
both in one process: "row kernels" is the old dispatch (``transform._MANY_ROWS`` set out of
reach), "now" the new, and "wide" the transposed picture, for reference.  Times are medians of
``--repeats`` runs, in ns per sample of the fitted picture (or per pixel for the encoder).

    .venv/bin/python benchmarks/tall_thin.py
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import wavecore
from wavecore import transform
from wavecore.adjoint import synthesis_adjoint

RNG = np.random.default_rng(7)


def _median_seconds(call: Callable[[], Any], repeats: int) -> float:
    call()  # warm: compile, and fill the caches of the matrices
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _dispatches(call: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """(old dispatch, new dispatch) medians, interleaved so that both see the same load."""
    many = transform._MANY_ROWS
    old, new = [], []
    for _ in range(repeats):
        transform._MANY_ROWS = 1 << 62
        try:
            old.append(_median_seconds(call, 1))
        finally:
            transform._MANY_ROWS = many
        new.append(_median_seconds(call, 1))
    return statistics.median(old), statistics.median(new)


def _transform_round_trip(picture: np.ndarray, wavelet: str) -> Callable[[], Any]:
    def run() -> None:
        coeffs = wavecore.wavedec2(picture, wavelet)
        wavecore.waverec2(coeffs, wavelet)
        synthesis_adjoint(picture, wavelet, level=len(coeffs) - 1)

    return run


def _encoder(picture: np.ndarray, options: dict[str, Any]) -> Callable[[], bytes]:
    return lambda: wavecore.encode_image(picture, **options)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--pixels", type=int, default=1 << 19, help="samples per picture")
    args = parser.parse_args()
    load = os.getloadavg()
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; cores {os.cpu_count()}")
    print("\nwavedec2 + waverec2 + synthesis_adjoint, all levels (ns/sample)")
    print("| wavelet | tall shape | row kernels | now | speed-up | wide (transposed) |")
    print("|---|---|---:|---:|---:|---:|")
    for wavelet in ("cdf97", "bspline2"):
        for width in (8, 16, 32):
            rows = wavecore.valid_length(args.pixels // width, 2, "open", wavelet)
            cols = wavecore.valid_length(width, 1, "open", wavelet)
            tall = RNG.uniform(0, 255, (rows, cols))
            old, new = _dispatches(_transform_round_trip(tall, wavelet), args.repeats)
            wide = _median_seconds(
                _transform_round_trip(np.ascontiguousarray(tall.T), wavelet), args.repeats
            )
            per = 1e9 / tall.size
            print(
                f"| {wavelet} | {rows} × {cols} | {old * per:.1f} | {new * per:.1f} | "
                f"{old / new:.2f}× | {wide * per:.1f} |"
            )
    print("\nencode_image (ms; noise of amplitude 4 for the quality targets)")
    print("| picture | options | row kernels | now | speed-up | wide (transposed) |")
    print("|---|---|---:|---:|---:|---:|")
    cases: list[tuple[str, np.ndarray, dict[str, Any]]] = [
        ("65 536 × 1 faint", RNG.integers(0, 5, (65_536, 1), dtype=np.uint8), {"quality": 43}),
        ("262 144 × 1 faint", RNG.integers(0, 5, (262_144, 1), dtype=np.uint8), {"quality": 43}),
        ("524 288 × 2 noise", RNG.integers(0, 256, (524_288, 2), dtype=np.uint8), {}),
        (
            "524 288 × 2 noise",
            RNG.integers(0, 256, (524_288, 2), dtype=np.uint8),
            {"wavelet": "bspline2"},
        ),
        ("65 536 × 16 RGB", RNG.integers(0, 256, (65_536, 16, 3), dtype=np.uint8), {}),
    ]
    repeats = max(1, args.repeats // 2)
    for name, picture, options in cases:
        wide_picture = np.ascontiguousarray(np.swapaxes(picture, 0, 1))
        old, new = _dispatches(_encoder(picture, options), repeats)
        wide = _median_seconds(_encoder(wide_picture, options), repeats)
        print(
            f"| {name} | {options or 'default'} | {old * 1e3:.0f} | {new * 1e3:.0f} | "
            f"{old / new:.2f}× | {wide * 1e3:.0f} |"
        )
    load = os.getloadavg()
    print(f"\nload average after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


if __name__ == "__main__":
    main()
