"""The closed loop kept as a fit (``quantize.ClosedLoopFit``): at its own step it is the closed
loop of ``quantize_bands``; near it, quantizing the fit or starting a closed loop from it comes
close to a closed loop from scratch, which is what lets the quality search run one."""

from __future__ import annotations

import numpy as np
import pytest

from wavecore import wavedec2, waverec2
from wavecore.layout import as_levels
from wavecore.quantize import ClosedLoopFit, dequantize_bands, quantize_bands

OPTIONS = {"wavelet": "bspline2", "boundary": "open"}


def picture() -> np.ndarray:
    # Smooth waves, edges and seeded noise: details of every size, on a size bspline2 fits.
    rng = np.random.default_rng(5)
    y, x = np.mgrid[:130, :130]
    image = 128 + 50 * np.sin(x / 9.0) * np.cos(y / 13.0) + 40.0 * ((x // 32 + y // 24) % 2)
    return image + rng.normal(0, 4, image.shape)


def squared_error(image: np.ndarray, q: list, params: dict) -> float:
    back = waverec2(dequantize_bands(q, params, **OPTIONS), "bspline2", "open")
    return float(np.sum((back - image) ** 2))


def same(a: list, b: list) -> bool:
    return all(
        np.array_equal(x, y)
        for la, lb in zip(as_levels(a), as_levels(b), strict=True)
        for x, y in zip(la, lb, strict=True)
    )


@pytest.mark.parametrize("step", [3.0, 12.0])
def test_the_fit_at_its_own_step_is_the_closed_loop(step: float) -> None:
    coeffs = wavedec2(picture(), "bspline2", "open", level=3)
    q, params = quantize_bands(coeffs, step, refine=6, **OPTIONS)
    fitted, fitted_params = ClosedLoopFit(coeffs, step, iterations=6, **OPTIONS).quantize(step)
    assert same(q, fitted) and params == fitted_params


def test_near_steps_from_the_fit_come_close_to_a_closed_loop() -> None:
    image = picture()
    coeffs = wavedec2(image, "bspline2", "open", level=3)
    fit = ClosedLoopFit(coeffs, 8.0, **OPTIONS)
    for step in (7.92, 8.08):  # within the rate control's 1.5 %
        cold = squared_error(image, *quantize_bands(coeffs, step, refine=6, **OPTIONS))
        opened = squared_error(image, *quantize_bands(coeffs, step, refine=0, **OPTIONS))
        from_fit = squared_error(image, *fit.quantize(step))
        # Most of the closed loop's gain over the open loop is kept.
        assert from_fit < cold + 0.25 * (opened - cold)
    # A closed loop started from the fit, with half the iterations, lands where one from
    # scratch does (its error within 0.3 %; three iterations from scratch are 1-1.5 % off),
    # further away too.
    step = 8.8
    cold = squared_error(image, *quantize_bands(coeffs, step, refine=6, **OPTIONS))
    warm = ClosedLoopFit(coeffs, step, iterations=3, start=fit, **OPTIONS)
    assert squared_error(image, *warm.quantize(step)) == pytest.approx(cold, rel=0.003)
