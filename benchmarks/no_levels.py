"""Pictures of no levels coded as 2-D against the 1-D layout they had before 2026-12-07.

A bundle of 0 levels holds ``cA`` alone, which does not say whether its layout is 2-D; the
encoder used to leave it 1-D (one plane per column: a 1 × N picture was N planes of one value),
and now codes it as 2-D (``Plan.coded_two_d``; docs/bundle-format.md, "Pictures and surfaces of
no levels").  This codes a 1 × 262,144 picture (scikit-image's camera, its rows end to end),
white noise of that shape, and the camera itself, both ways in one process (the old way by
patching the encoder back), and prints bytes, PSNR and encode time (first call of each mode
after a warm-up of both).  Run: ``.venv/bin/python benchmarks/no_levels.py``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from skimage import data

import wavecore
import wavecore.codec.plan as plan_module
import wavecore.codec.reversible as reversible

CASES: tuple[dict[str, Any], ...] = (
    {"level": 0},
    {"level": 0, "bpp": 2.0},
    {"lossless": True, "effort": "fast"},
    {"lossless": True, "effort": "fast", "level": 0},
)


@contextmanager
def one_d() -> Iterator[None]:
    """The encoder as before: a decomposition of no levels in the 1-D layout."""
    prop = plan_module.Plan.coded_two_d
    encode_levels = reversible.encode_levels

    def old_rule(self: plan_module.Plan) -> bool:
        return len(self.boundary) == 2 and self.levels > 0

    def as_layout(coeffs: Any, **kwargs: Any) -> Any:
        return encode_levels(coeffs, **{**kwargs, "two_d": None})

    plan_module.Plan.coded_two_d = property(old_rule)  # type: ignore[assignment]
    reversible.encode_levels = as_layout  # type: ignore[assignment]
    try:
        yield
    finally:
        plan_module.Plan.coded_two_d = prop  # type: ignore[method-assign]
        reversible.encode_levels = encode_levels  # type: ignore[assignment]


def row(image: np.ndarray, options: dict[str, Any]) -> str:
    start = time.perf_counter()
    bundle = wavecore.encode_image(image, **options)
    took = time.perf_counter() - start
    back = wavecore.decode(bundle)
    if options.get("lossless"):
        assert np.array_equal(back, image)
        quality = "exact"
    else:
        quality = f"{wavecore.inspect(bundle)['psnr']:.2f} dB"
    return f"{len(bundle):7d} B {quality:>9s} {took:6.2f} s"


def main() -> None:
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load {load}")
    pictures = {
        "camera rows 1 × 262144": data.camera().reshape(1, -1).copy(),
        "noise 1 × 262144": np.random.default_rng(0).integers(0, 256, (1, 262144), np.uint8),
        "camera 512 × 512": data.camera(),
    }
    for image in pictures.values():  # compile every kernel both ways first
        small = np.ascontiguousarray(image[:, :600])
        for options in CASES:
            row(small, options)
            with one_d():
                row(small, options)
    for name, image in pictures.items():
        for options in CASES:
            if options.get("level") is None and min(image.shape) > 1:
                continue  # pictures that fit levels are not coded without them by default
            with one_d():
                before = row(image, options)
            after = row(image, options)
            print(f"{name:24s} {options!s:48s} 1-D {before} | 2-D {after}", flush=True)


if __name__ == "__main__":
    main()
