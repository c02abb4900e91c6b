"""The wavelet core of a grid under an RMSE target: decomposed once, its step found open loop.

:mod:`wavecore.grids` codes ``rmse``, ``psnr`` (and, through the codec's rate control,
``bpp``) targets with the codec's wavelet transform, dead-zone quantizer and context coder.
The context coder is most of the time (some 130 of 190 ms on the benchmark's 1024² float32
field); what this module saves is everything else that a quantize-and-measure loop repeats:

* the grid is decomposed **once**;
* the step that meets the target is found from the coefficients alone
  (:class:`wavecore.quantize.OpenLoopDistortion`, one compiled pass per try, no entropy coding
  and no synthesis), within 0.1 % of the decoded RMSE on the benchmark's synthesized fields
  (1-6 % low on the real elevation model); each try is synthesized and measured in the grid's
  dtype **before** it is entropy coded (a miss, from the cast to an integer dtype or a grid the
  prediction does not fit, steps to where the prediction corrected by the miss meets the
  target, and synthesizes again), so the core is coded **once**;
* the check of the decoded grid against the original is one compiled pass where no cell is
  missing.

The bundle is the one :func:`wavecore.codec.encode.encode_surface_at_step` writes for the
same step; only the work around it differs.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from ._kernels import squared_and_largest_error, squared_and_largest_rounded_error
from .codec.encode import bundle_from_quantized, reconstructed_from_quantized
from .codec.plan import MAX_IMAGE_LEVELS, Plan, fit
from .codec.samples import decompose, peak_of, scaled
from .errors import InvalidParameter
from .filters import get_wavelet
from .quantize import DEFAULT_ROUNDING, OpenLoopDistortion, quantize_bands

__all__ = ["SteppedCore", "squared_and_largest", "squared_and_largest_rounded"]

#: The open-loop search stops when its prediction is within this fraction of its aim.
_PREDICTION_TOLERANCE = 2e-3
_PREDICTION_TRIES = 8


class SteppedCore:
    """A float64 core (``(H, W)``, or ``(H, W, D)``: ``D`` values per point) decomposed once.

    Parameters
    ----------
    values : numpy.ndarray
        The core's samples (float64, finite).
    wavelet, level, boundary
        As for :func:`wavecore.encode_surface`.
    """

    def __init__(
        self, values: np.ndarray, wavelet: str, level: int | None, boundary: tuple[str, str]
    ) -> None:
        coded, scale = scaled(values)
        self.coded, self.scale = coded, scale
        bank = get_wavelet(wavelet)
        fitted, pads, levels = fit(coded, level, bank.name, boundary, MAX_IMAGE_LEVELS)
        self.plan = Plan(
            "surface",
            values.shape,
            "float64",
            bank.name,
            tuple(boundary),
            levels,
            "none",
            pads,
            fitted.shape,
            peak_of(coded, "float64", "surface"),
            scale=scale,
        )
        self.coeffs = decompose(self.plan, fitted)
        self._fitted_size = fitted.size
        self._distortion: OpenLoopDistortion | None = None
        self._predicted: dict[float, float] = {}

    def predicted_rmse(self, step: float) -> float:
        """The RMSE of the core (its own units) quantized at ``step``, predicted open loop
        (kept per step: the search asks again for the step it tried)."""
        if step in self._predicted:
            return self._predicted[step]
        if self._distortion is None:
            self._distortion = OpenLoopDistortion(
                self.coeffs,
                wavelet=self.plan.wavelet,
                boundary=list(self.plan.boundary),
                axes=self.plan.axes,
                rounding=DEFAULT_ROUNDING,
            )
        try:
            coded_step = math.ldexp(step, -self.scale)
            if not coded_step >= sys.float_info.min:  # a step the quantizer refuses
                return 0.0
            squared = self._distortion(coded_step) / self._fitted_size
            predicted = math.ldexp(math.sqrt(max(squared, 0.0)), self.scale)
        except OverflowError:  # tiny data (scaled up) at a huge step
            predicted = math.inf
        self._predicted[step] = predicted
        return predicted

    def step_for(self, rmse: float, first: float) -> float:
        """The step whose predicted RMSE is ``rmse`` (secant steps on the logarithms, from
        ``first``); the RMSE grows with the step nearly in proportion."""
        step, predicted = first, self.predicted_rmse(first)
        previous: tuple[float, float] | None = None
        for _ in range(_PREDICTION_TRIES):
            if not (predicted > 0 and math.isfinite(predicted)):
                return step
            if abs(predicted / rmse - 1.0) <= _PREDICTION_TOLERANCE:
                return step
            slope = 1.0
            if previous is not None and previous[0] != step and previous[1] > 0:
                measured = math.log(predicted / previous[1]) / math.log(step / previous[0])
                slope = min(max(measured, 0.25), 4.0)
            previous = (step, predicted)
            step *= (rmse / predicted) ** (1.0 / slope)
            predicted = self.predicted_rmse(step)
        return step

    def quantized(self, step: float) -> tuple[list[Any], dict[str, Any]]:
        """The core's bands quantized at ``step`` (the data's units) and their parameters."""
        plan = self.plan
        coded_step = math.ldexp(step, -self.scale)
        if not (coded_step > 0 and math.isfinite(coded_step)):
            msg = f"cannot quantize at step {step!r}"
            raise InvalidParameter(msg)
        return quantize_bands(
            self.coeffs,
            coded_step,
            wavelet=plan.wavelet,
            boundary=list(plan.boundary),
            axes=plan.axes,
            rounding=DEFAULT_ROUNDING,
            refine=0,
        )

    def reconstructed(self, step: float) -> tuple[tuple[list[Any], dict[str, Any]], np.ndarray]:
        """The core quantized at ``step`` and what :func:`wavecore.decode` would return for its
        bundle (float64, the core's shape), with no entropy coding: a step can be measured,
        and rejected, before the coder (most of an encoding's time) runs on it."""
        quantized, qparams = self.quantized(step)
        return (quantized, qparams), reconstructed_from_quantized(self.plan, quantized, qparams)

    def code(
        self, quantized: tuple[list[Any], dict[str, Any]], output: np.ndarray
    ) -> tuple[bytes, np.ndarray]:
        """The core bundle of :meth:`reconstructed`'s bands and output, and what
        :func:`wavecore.decode` returns for it: ``output`` itself, unless the header rounded a
        quantizer parameter (then the bundle decoded)."""
        return bundle_from_quantized(
            self.plan, quantized[0], quantized[1], self.coded, "grid", output=output
        )

    def encode(self, step: float) -> tuple[bytes, np.ndarray]:
        """The core bundle quantized at ``step`` (the data's units) and what
        :func:`wavecore.decode` returns for it (float64, the core's shape)."""
        quantized, qparams = self.quantized(step)
        return bundle_from_quantized(self.plan, quantized, qparams, self.coded, "grid")


def squared_and_largest(final: np.ndarray, original: np.ndarray) -> tuple[float, float]:
    """(sum of squared errors, largest error) of ``final`` (any float or integer dtype)
    against ``original`` (float64, the same shape), in one compiled pass."""
    if final.dtype == np.float16:  # the compiled pass has no float16; float32 holds it exactly
        final = final.astype(np.float32)
    total, largest = squared_and_largest_error(
        np.ascontiguousarray(final).reshape(-1), np.ascontiguousarray(original).reshape(-1)
    )
    return float(total), float(largest)


def squared_and_largest_rounded(
    decoded: np.ndarray, original: np.ndarray, dtype: np.dtype[Any]
) -> tuple[float, float]:
    """:func:`squared_and_largest` of ``decoded`` (float64) as an integer ``dtype`` of at most
    32 bits returns it (rounded, clipped to the dtype's range), with no array of that dtype
    made: the same figures, in one compiled pass."""
    info = np.iinfo(dtype)
    total, largest = squared_and_largest_rounded_error(
        np.ascontiguousarray(decoded).reshape(-1),
        np.ascontiguousarray(original).reshape(-1),
        float(info.min),
        float(info.max),
    )
    return float(total), float(largest)
