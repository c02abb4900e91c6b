"""Compile every numba kernel once, so that no later call pauses to compile.

``python -m wavecore.warmup`` (run by ``bash scripts/run.sh setup``, the Dockerfile and
``wavecore serve``) runs the transforms and the codec on small inputs of every kind and dtype a
bundle allows: images in ``uint8``, ``uint16``, ``int16``, ``float32`` and ``float64``, grey,
RGB and RGBA, coded lossy (each wavelet; at a quality, a rate and a kept fraction) and
lossless, curves and surfaces, each decoded whole, with ``keep`` and at a coarser ``level``.
The kernels are compiled with ``cache=True``, so the machine code lands in numba's on-disk
cache (next to the sources, or in ``NUMBA_CACHE_DIR``): on a fresh clone this took 48–87 s on
a shared 2-core machine (load average 4–6); once cached, the same run takes 8–20 s, most of it
the codec's own work on the small inputs, not loading (benchmarks/first_run.py measures both).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from typing import TextIO

import numpy as np

from .codec import decode, encode_curve, encode_image, encode_surface
from .curvesets import encode_curves
from .grids import decode_grid, encode_grid
from .multilevel import wavedec, wavedec2, wavedecn, waverec, waverec2, waverecn
from .restoration import (
    CLASSES,
    FILTERED_DTYPES,
    TAPS,
    apply_restoration,
    colour_channels,
    fit_restoration,
)

IMAGE_DTYPES = ("uint8", "uint16", "int16", "float32", "float64")
IMAGE_WAVELETS = ("bspline2", "cdf97", "haar")


def _decode_every_way(bundle: bytes) -> None:
    decode(bundle)
    decode(bundle, keep=0.3)
    decode(bundle, level=1)


def _image(dtype: str, channels: int, rng: np.random.Generator) -> np.ndarray:
    shape = (24, 28) if channels == 1 else (24, 28, channels)
    values = rng.random(shape)
    if dtype in ("float32", "float64"):
        return values.astype(dtype)
    info = np.iinfo(dtype)
    return (info.min + values * (int(info.max) - int(info.min))).astype(dtype)


def _transforms() -> None:
    rng = np.random.default_rng(0)
    for dtype in ("float32", "float64"):
        for boundary, n in (("open", 34), ("closed", 32)):
            for wavelet in IMAGE_WAVELETS:
                if wavelet != "bspline2" and boundary == "open":
                    continue  # Haar and CDF 9/7 use their own sizes: the closed case covers them
                x = rng.random(n).astype(dtype)
                waverec(wavedec(x, wavelet, boundary, level=2), wavelet, boundary)
                pts = rng.random((n, 3)).astype(dtype)
                waverec(wavedec(pts, wavelet, boundary, level=2), wavelet, boundary)
                image = rng.random((n, n + 8)).astype(dtype)
                waverec2(wavedec2(image, wavelet, boundary, level=2), wavelet, boundary)
                colour = rng.random((n, n + 8, 3)).astype(dtype)
                waverec2(wavedec2(colour, wavelet, boundary, level=2), wavelet, boundary)
        grid = rng.random((34, 32, 3)).astype(dtype)
        coeffs = wavedecn(grid, boundary=("open", "closed"), level=2, axes=(0, 1))
        waverecn(coeffs, boundary=("open", "closed"), axes=(0, 1))


def _images(dtype: str) -> Callable[[], None]:
    def run() -> None:
        rng = np.random.default_rng(1)
        for channels in (1, 3, 4):
            image = _image(dtype, channels, rng)
            # A kept fraction is the cheapest lossy target; the quality and rate searches call
            # the same kernels many times, so one of each per dtype is enough.
            # Full resolution decodes take the fused last synthesis level, coarser levels the
            # separate colour pass (on a strided view, for some wavelets): both, for each.
            for wavelet in IMAGE_WAVELETS:
                _decode_every_way(encode_image(image, wavelet=wavelet, keep=0.2))
            if dtype in ("uint8", "uint16"):
                # The default lossless coder (wavecore.losslesscoder) and the block coder.
                _decode_every_way(encode_image(image, lossless=True))
                _decode_every_way(encode_image(image, lossless=True, effort="fast"))
            if dtype in FILTERED_DTYPES:  # the restoration filter's passes, fit and apply
                fit_restoration(image, image[::-1].copy())
                item = {"edges": [0, 1, 2], "taps": [[1] * TAPS] * CLASSES}
                apply_restoration(image, [item] * colour_channels(image.shape))
        _decode_every_way(encode_image(image))  # the default, 40 dB
        decode(encode_image(image[..., :3], bpp=8.0))
        if dtype == "uint8":
            # Large enough for the rate search's sample of code-blocks (``_sampled_ratio``).
            big = (rng.random((320, 320, 3)) * 255).astype(np.uint8)
            decode(encode_image(big, bpp=1.0))

    return run


def _curves() -> None:
    rng = np.random.default_rng(2)
    for dims in (2, 3):
        points = rng.random((60, dims))
        for closed in (False, True):
            for wavelet in IMAGE_WAVELETS:
                decode(encode_curve(points, closed=closed, wavelet=wavelet, keep=0.3))
            _decode_every_way(encode_curve(points, closed=closed))


def _surfaces() -> None:
    rng = np.random.default_rng(3)
    for grid in (rng.random((30, 26)), rng.random((30, 26, 3))):
        for closed in ((False, False), (True, False), (False, True), (True, True)):
            decode(encode_surface(grid, closed=closed, keep=0.3))
        _decode_every_way(encode_surface(grid))


def _curve_sets() -> None:
    rng = np.random.default_rng(4)
    curves = [np.cumsum(rng.normal(size=(80, dims)), axis=0) for dims in (2, 2, 3)]
    for method in ("vertex", "wavelet"):
        decode(encode_curves(curves, closed=[True, False, False], tolerance=0.05, method=method))
    # a mixed-dimension set never takes the vertex form: one plane set compiles its kernels
    # (snapping, lifted and optimal simplification, refinement, bulges), else the first plane
    # set a worker encodes pays about 35 s of CPU compiling them
    decode(encode_curves(curves[:2], closed=[True, False], tolerance=0.05, method="vertex"))


def _grids() -> None:
    rng = np.random.default_rng(5)
    smooth = np.cumsum(np.cumsum(rng.normal(size=(300, 280)), axis=0), axis=1)
    volume = np.cumsum(rng.normal(size=(20, 70, 66)), axis=0)
    for grid in (smooth, smooth.astype(np.float32), volume):
        span = float(np.ptp(grid))
        window = tuple(slice(3, 40) for _ in grid.shape)
        for bundle in (
            encode_grid(grid, max_error=1e-3 * span),
            encode_grid(grid, rmse=1e-3 * span),
            encode_grid(grid, bpp=6.0),
        ):
            decode(bundle)
            decode_grid(bundle, window=window)
    decode(encode_grid(np.round(smooth).astype(np.int16), lossless=True))
    decode(encode_grid(smooth, wavelet="cdf97", max_error=1e-3 * float(np.ptp(smooth))))


def steps() -> Iterator[tuple[str, Callable[[], None]]]:
    """The warm-up's steps, each a (label, function) pair."""
    yield "transforms (wavedec, wavedec2, wavedecn; float32, float64)", _transforms
    for dtype in IMAGE_DTYPES:
        yield f"images {dtype} (grey, RGB, RGBA; lossy and lossless)", _images(dtype)
    yield "curves (open, closed; 2-D, 3-D)", _curves
    yield "surfaces (height fields, 3-D grids; each boundary)", _surfaces
    yield "curve sets (vertex and wavelet forms)", _curve_sets
    yield "grids (max_error, rmse, bpp; 2-D, 3-D; windows; lossless)", _grids


def warm_up(stream: TextIO | None = sys.stderr) -> float:
    """Compile (or load from numba's cache) every kernel; returns the seconds it took.

    Parameters
    ----------
    stream : file-like or None
        Where a progress line per step goes (``None``: silent).

    Returns
    -------
    float
        Wall-clock seconds.
    """
    todo = list(steps())
    start = time.perf_counter()
    for i, (label, run) in enumerate(todo, 1):
        if stream is not None:
            elapsed = time.perf_counter() - start
            print(
                f"wavecore warm-up [{i}/{len(todo)}] {elapsed:5.1f} s  {label}",
                file=stream,
                flush=True,
            )
        run()
    total = time.perf_counter() - start
    if stream is not None:
        print(f"wavecore warm-up done in {total:.1f} s", file=stream, flush=True)
    return total


def main() -> None:
    """``python -m wavecore.warmup``: warm up with progress lines on stderr."""
    print(
        "wavecore: compiling the numba kernels into the on-disk cache "
        "(a minute or two the first time, seconds once cached)",
        file=sys.stderr,
        flush=True,
    )
    warm_up()


if __name__ == "__main__":
    main()
