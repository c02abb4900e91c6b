"""A small demonstration of the transform: ``python -m wavecore.demo``."""

from __future__ import annotations

import numpy as np

from . import max_level, wavedec, waverec


def main() -> None:
    """Decompose a noisy circle, drop its details, and print what happened."""
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rng = np.random.default_rng(0)
    curve = np.c_[np.cos(t), np.sin(t)] + 0.02 * rng.standard_normal((64, 2))
    levels = max_level(len(curve), "closed")
    coeffs = wavedec(curve, boundary="closed", level=3)
    smooth = waverec([coeffs[0]] + [None] * 3, boundary="closed")
    exact = waverec(coeffs, boundary="closed")
    print(f"closed curve of {len(curve)} points allows {levels} levels; used 3")
    print("coefficient lengths:", [len(c) for c in coeffs])
    print(f"max reconstruction error with all details: {np.abs(exact - curve).max():.2e}")
    print(f"max deviation without details: {np.abs(smooth - curve).max():.3f}")


if __name__ == "__main__":
    main()
