"""The synthetic fields of the Zarr tests and of their golden chunks (tests/golden_zarr)."""

from __future__ import annotations

import numpy as np


def smooth_field(shape: tuple[int, ...], seed: int, dtype: str = "float32") -> np.ndarray:
    """A smooth field plus a little noise (amplitude about 300), the kind the codec is for."""
    rng = np.random.default_rng(seed)
    grids = np.meshgrid(*[np.linspace(0, 1, n) for n in shape], indexing="ij")
    field = sum(np.sin((3 + i) * g + rng.uniform(0, 6)) for i, g in enumerate(grids))
    field = field + 0.01 * rng.standard_normal(shape)
    return np.asarray(field * 100, dtype=dtype)
