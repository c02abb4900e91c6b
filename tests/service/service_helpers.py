"""Test data for the service tests (generated, seeded)."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from PIL import Image


def test_image(shape: tuple[int, ...] = (48, 64), seed: int = 0) -> np.ndarray:
    """A smooth gradient with seeded noise, uint8."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[: shape[0], : shape[1]]
    base = 90 + 60 * np.sin(x / 9.0) + 50 * np.cos(y / 7.0)
    if len(shape) == 3:
        base = base[:, :, None] + np.array([0, 25, -25])[: shape[2]]
    return np.clip(base + rng.normal(0, 4, base.shape), 0, 255).astype(np.uint8)


test_image.__test__ = False  # type: ignore[attr-defined]  # a helper, not a test


def image_file(array: np.ndarray, fmt: str = "PNG", **options: Any) -> bytes:
    out = io.BytesIO()
    Image.fromarray(array).save(out, format=fmt, **options)
    return out.getvalue()


def circle(n: int = 64, closed: bool = True) -> list[list[float]]:
    t = np.linspace(0, 2 * np.pi, n, endpoint=not closed)
    r = 1 + 0.1 * np.sin(5 * t)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1).tolist()
