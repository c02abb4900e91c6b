"""Rate control: the searches for the quantizer step that meets a ``quality``, ``bpp`` or
``tolerance`` target (or codes ``keep``), over one decomposition held by :class:`_LossyEncoder`.

They predict rather than try:

* ``quality``: the open loop's squared error at any step is computed from the coefficients
  (``quantize.OpenLoopDistortion``: one compiled pass, weighted by the basis norms, no
  synthesis); the step it gives is quantized and verified by one synthesis, and a miss is
  corrected with the ratio measured (or, once verifications bracket the target, by their
  secant).  ``cdf97`` runs no closed loop (it does not pay for that nearly orthogonal
  wavelet).  ``bspline2``'s small decompositions run it once at the predicted step, after one
  synthesis in open loop has measured how the picture's error compares with the prediction
  (its basis is not orthogonal, so that depends on the picture); a miss is corrected by
  quantizing the closed loop's fit at the new step (``quantize.ClosedLoopFit``, an open
  loop's cost) or, further away, by a closed loop started from that fit (half the
  iterations).
* ``bpp``: the coded size is predicted from a first-order estimate scaled by the coder's
  ratio to it, measured on a sample of code-blocks where there are many; the one full coding
  aims 1 % above the budget, and one that lands a little above is trimmed into the window by
  removing details from a few blocks and coding only those again
  (``blockcoder.CodedBlocks``).  A prediction far off costs a second full coding.
* ``tolerance``: bisection in open loop, then a few closed loops upwards.

Where RDOQ runs (``rdoq.ENABLED``: images quantized in open loop), every open-loop
quantization is re-decided by it, and the searches predict with it: the bpp search's sample
codes RDOQ's integers (re-decided on the sampled blocks alone) against the dead zone's
estimate, as a ratio that moves with the step (:class:`_RatioModel`, sampled twice on pictures
of many blocks), and the quality search verifies RDOQ's error (two more verifications at most,
and the search again without RDOQ where it still misses).

The old searches on measured results stay as fallbacks for pictures whose error or size jumps
with the step.  ``tests/test_ratecontrol.py`` counts the codings and closed loops.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit

from .. import rdoq
from .._kernels import largest_scaled, log_histogram_counts, top_octave
from ..binheader import RESTORED_BASE
from ..blockcoder import BLOCK_SIZE as DEFAULT_BLOCK
from ..blockcoder import PARENT_VERSIONS, CodedBlocks, KnownBlocks, block_lengths, code_blocks
from ..bundle import read_bundle, write_bundle
from ..entropy import CONTEXT_VERSION, encode_levels
from ..errors import BitrateTooLow, InvalidParameter
from ..layout import as_levels, from_levels
from ..quantize import (
    APPROX_ROUNDING,
    DEFAULT_ROUNDING,
    REFINE_ITERATIONS,
    REFINE_MAX_COEFFICIENTS,
    ClosedLoopFit,
    OpenLoopDistortion,
    band_weights,
    dequantize_bands,
    quantize_bands,
    reconstruction_offset,
)
from ..restoration import (
    FILTERED_DTYPES,
    apply_restoration,
    colour_channels,
    fit_restoration,
)
from ..threshold import remove_smallest
from ..transform import run_rows, run_slices
from .decode import decode
from .plan import DEFAULT_CODER
from .plan import Plan as _Plan
from .samples import decompose as _decompose
from .samples import measure_errors as _errors
from .samples import reconstruct_finished
from .samples import unscaled as _unscaled
from .stages import get_colour

#: Without ``keep``/``quality``/``bpp``, images and surfaces are coded to this PSNR (dB).
DEFAULT_QUALITY = 40.0
#: With ``keep``, the quantizer step, relative to the peak: fine enough (about 60 dB) that the
#: thresholding decides what is lost.
KEEP_RELATIVE_STEP = 1.0 / 512.0
_SEARCH_STEPS = 18
_BPP_EVALUATIONS = 24
_MODEL_EVALUATIONS = 24
_QUALITY_EVALUATIONS = 24
_QUALITY_SLACK_DB = 0.02  # quality searches stop within this much above the target
#: Where the closed loop runs, its PSNR is accepted from the target to this much above it, and
#: the open-loop model aims this much above the target, within this much either side (a wider
#: window than the searches' own, so that one closed loop hits it more often).
_QUALITY_ACCEPT_DB = 0.04
_QUALITY_AIM_DB = 0.015
_QUALITY_MODEL_WINDOW_DB = 0.008
#: The tolerance search's closed loops after the first, bisecting up from the open loop's step
#: (to this relative width): the closed loop's largest error is lower, so the step can grow.
_TOLERANCE_CLOSED_LOOPS = 4
_TOLERANCE_STEP_RESOLUTION = 0.01
#: The closed-loop quantizer's squared error, relative to the open loop's at the same step
#: (measured 0.78-0.89 for ``bspline2`` and 0.97-1.0 for ``cdf97`` on scikit-image's pictures at
#: 30-48 dB): where the quality search aims its first closed-loop quantization, from a search of
#: the ten times cheaper open loop.
_TYPICAL_REFINED_RATIO = {"bspline2": 0.81, "cdf97": 0.985}
_OTHER_REFINED_RATIO = 0.9
#: Wavelets whose closed loop does not pay: ``cdf97`` is nearly orthogonal, so the refit
#: moves its coefficients little, and what it gains in squared error it spends in bytes.  At
#: equal bytes it measured +0.002, +0.009, -0.001, +0.002 and +0.041 dB (camera, coins, moon,
#: brick, astronaut at 256² RGB; means over 0.3-4 bpp), for about ten times an open loop's
#: time: the default 40 dB search on a 512² picture spent two thirds of its time there.
_OPEN_LOOP_WAVELETS = frozenset({"cdf97"})
#: The decoded picture's squared error, relative to the coefficient-domain prediction of
#: ``quantize.OpenLoopDistortion`` (per sample, plus the rounding to integers): measured
#: 0.97-1.05 in open loop on scikit-image's pictures at steps 2-20; the closed loop's lower
#: (0.58-0.86 for ``bspline2``, 1.16-1.49 on the moon).  The quality search's first guess.
_TYPICAL_PREDICTED_RATIO = {"bspline2": 0.75}
_OTHER_PREDICTED_RATIO = 1.0
#: The quality search's verifications in open loop (a synthesis each), where the closed loop
#: does not run: the prediction, and corrections with the ratio measured.
_QUALITY_OPEN_VERIFIES = 4
#: Where RDOQ runs, the verifications in open loop it may add (its error moves with the step
#: less smoothly than the dead zone's: the moon at 33 dB needs a fifth, between two that
#: bracket the target), and the window of the result (dB above the target) outside which the
#: quality search runs again without RDOQ.
_QUALITY_RDOQ_VERIFIES = 2
_QUALITY_RDOQ_WINDOW_DB = 0.05
#: Where a closed loop keeps its fit (the quality search), a correction within this much of
#: its step (relative, in log) is quantized from the fit (``quantize.ClosedLoopFit``, the cost
#: of an open loop), and one further away runs a closed loop started from it (a warm start,
#: ``_WARM_ITERATIONS`` instead of ``REFINE_ITERATIONS``).  Quantizing from the fit further
#: away cost bytes (``bspline2`` at 40 dB: +1-2 % at equal PSNR for 4-10 % of the step).
_FIT_REUSE_LOG_STEP = 0.015
_WARM_ITERATIONS = 3
#: ``bspline2``'s closed loop's squared error relative to its open loop's (0.78-0.88 on
#: scikit-image's pictures at 33-45 dB, where the open loop's relative to the prediction is
#: 0.83-1.7): the first closed loop aims with the open loop's ratio, measured by one
#: synthesis, times this.
_AIM_REFINED_RATIO = {"bspline2": 0.84}
#: How close to its aim (dB) the predicted error at the calibration's step must be.
_CALIBRATION_WINDOW_DB = 0.05
#: Where closed loops keep their fit: the verifications (a synthesis each), and the closed
#: loops they may run before the search on measured errors takes over.
_QUALITY_FIT_VERIFIES = 6
_QUALITY_FIT_CLOSED_LOOPS = 3
#: Brackets narrower than this (relative) hold a jump of the error, not a slope: stop there.
_QUALITY_STEP_RESOLUTION = 2e-4
#: The same for the open-loop model that guides the closed loop's search: 2e-3 of the step
#: moves the PSNR by about 0.017 dB, under the 0.04 dB window.
_MODEL_STEP_RESOLUTION = 2e-3
_HEADER_GUESS = 600.0  # bytes, for the size estimate before the real coder has run
_OCTAVE_BINS = 64  # the size estimate's magnitude histograms: bins per octave,
_OCTAVES = 48  # and octaves below each band's largest magnitude
#: What the context coder typically writes, relative to the first-order estimate (0.7-0.9 on
#: scikit-image's pictures): where the bpp search aims its first real coding.
_TYPICAL_CODED_RATIO = 0.8
#: The closed loop's bundle, relative to the open loop's at the same step, measured on seven
#: pictures (scikit-image's and two synthetic ones, 512² or so) at 0.25, 1 and 3 bpp: median
#: 1.008 (0.989-1.041) for ``cdf97``, 0.95 (0.62-1.04) for ``bspline2``, whose closed loop
#: changes more.  Where the open-loop trials aim first; a miss is corrected with the factor
#: measured.
_TYPICAL_CLOSED_SIZE_RATIO = {"cdf97": 1.008, "bspline2": 0.95}
_OTHER_CLOSED_SIZE_RATIO = 1.0
#: The window of the budget the open-loop trials aim at (their predicted closed-loop size),
#: narrow inside the accepted 97.5-100 %, since open-loop codings are cheap.
_OPEN_TRIALS_WINDOW = (0.984, 0.991)
_OPEN_TRIALS_AIM = 0.9875
#: The bpp search's full codings aim this far above the budget (their size predicted from the
#: first-order estimate scaled by a typical ratio, then by the one measured): a coding that
#: lands above the budget, up to ``_TRIM_LIMIT`` times it, is brought into the window by
#: removing details from a few code-blocks and coding only those again (``_trim_to_budget``);
#: one below the window needs another full coding.
_BPP_AIM = 1.03
_TRIM_LIMIT = 1.08
#: Pictures of at least ``_SAMPLING_MIN_BLOCKS`` blocks: their sample of a few whole levels
#: and ~20 blocks of the others predicts the coding within ~1 %, so the first coding aims
#: closer and is trimmed only from closer (re-coding a trim's blocks, and sampling again,
#: cost a 2048² RGB picture up to 0.8 s of CPU at 2 bpp when these were 1.03 and 1.08).
_BPP_AIM_MANY_BLOCKS = 1.01
_TRIM_LIMIT_MANY_BLOCKS = 1.04
#: A coding that lands below the window, from this share of the budget on, is filled into it
#: by promoting details of the dead zone to magnitude 1 in a few code-blocks.
_FILL_LIMIT = 0.85
#: A sampled ratio this far (log) from the one its step was chosen with is sampled again.
_RESAMPLE_LOG_RATIO = 0.03
#: Where RDOQ re-decides the indices (``rdoq.ENABLED``), the bpp prediction's ratio moves with
#: the step (see :class:`_RatioModel`), so pictures of many blocks sample up to this many
#: steps (:func:`_rdoq_sampled_model`: the first where the typical ratio points, the next
#: where the first one's points, unless within this relative step, in log); pictures of few
#: blocks sample once (their sample is every other block, half a coding).  Beyond the sampled
#: steps the ratio model extrapolates with at most this slope (log ratio over log step).
_RDOQ_SAMPLES = 2
_RDOQ_SAMPLE_RESOLUTION = 0.02
_RATIO_MODEL_SLOPE = 1.0
#: There, pictures of many blocks aim their one coding at the middle of the window, not above
#: the budget: two samples predict it within 1-1.5 % (2048² RGB at 0.5-2 bpp), and a trim
#: after RDOQ, whose cheap candidates (values of magnitude 1 in sparse blocks) RDOQ removed
#: already, recoded 76-86 of that picture's 87 blocks and lost PSNR.  (Pictures of few blocks
#: keep their aim above the budget and trim: aiming at the middle, their coding landed below
#: the window more often, and the fills that brought it back lost more: BD-rate -0.58 %
#: instead of -1.06 % on the tuning pictures; aiming 1 % above, -1.03 %.)
_RDOQ_BPP_AIM_MANY_BLOCKS = 0.9875
#: What making a nonzero index one larger costs, relative to a new nonzero (the fill's order).
_LARGER_INDEX_SHARE = 0.25
#: Closed loops (each coded once) the prediction may run before the old search takes over.
_BPP_PREDICTED_CLOSED_LOOPS = 2
#: What the context coder writes relative to the first-order estimate, at 0.5-2 bpp on
#: scikit-image's pictures: 0.72-0.88 for grey (camera, coins, moon, brick), 0.67-0.73 for
#: colour (the astronaut; the chroma planes are coded with the luma as context, which a
#: first-order estimate cannot see).  The first full coding's aim.
_TYPICAL_GREY_RATIO = 0.78
_TYPICAL_COLOUR_RATIO = 0.70
#: Removing a detail of magnitude 1 from a block saves about this share of the block's mean
#: bits per nonzero detail (the first trim's guess; later ones use what the coder measured).
_TRIM_SAVING_SHARE = 0.7
#: Pictures of at least this many code-blocks calibrate the bpp prediction on a sample of
#: about ``_SAMPLED_BLOCKS`` of them (``_sampled_ratio``) before their one full coding.
_SAMPLING_MIN_BLOCKS = 24
_SAMPLED_BLOCKS = 20
_WHOLE_LEVEL_BLOCKS = 4
#: A restoration filter worth less PSNR than this is not written: about 0.1 % of the bytes,
#: for a sixth more decoding time (a 2048² picture at 1 bpp gained 0.0004 dB).
_RESTORE_LEAST_GAIN_DB = 0.005

#: The grids' sample (``_encode_lossy``'s ``half_sample``): every third block of each level of
#: two or more blocks, only single-block levels whole.  At every other block, with levels of
#: up to 4 blocks whole, the sample of the tiled elevation model (41 blocks) held 23 blocks
#: and 71-77 % of the bytes, as dear as most of a full coding; a block's coded size over its
#: first-order entropy varies by 4-8 % between the blocks of a level, so a third of them
#: still predicts the level within a per cent or two.  63 cases (7 grids, 0.3-4 bpp): one
#: full coding each, as before; 15 blocks sampled instead of 23 on that model.
_GRID_SAMPLE_STRIDE = 3
_GRID_WHOLE_LEVEL_BLOCKS = 1
#: The grids' sampled prediction aims at the budget itself, its model solved to 0.4 % of it:
#: the pictures' model window (anything from 98.5 % of the budget to 1.4 % over it) left the
#: tiled elevation model's codings at 98.1-99.7 % of the budget, under a prediction good to
#: 0.3-1.2 % (over, mostly), and those aimed 1 % over it were trimmed back (a trim cost more
#: than a coding).  Only grids of at least ``_SAMPLING_MIN_BLOCKS`` blocks: smaller ones keep
#: the pictures' sample and aim.  63 cases (7 grids, 0.3-4 bpp): one full coding each, as
#: before; blocks coded again 267 instead of 468; RMSE at the same budget 0.997x (geometric
#: mean, 0.963-1.010x).
_GRID_BPP_AIM = 1.0
#: The grids' bpp sample (``_LossyEncoder.reuse_sample``) is taken where this ratio of the
#: coder to the first-order estimate puts the budget (the pictures' typical ratio, 0.78, put
#: it at half the final step on the tiled elevation model at 4 bpp); where the sample then
#: predicts the coding at its own step inside ``_REUSE_WINDOW`` of the budget, the full
#: coding is at that step and codes only the blocks the sample did not.
_GRID_SAMPLE_PRIOR = 0.94
_REUSE_WINDOW = (0.982, 0.995)
#: About how many tasks ``_block_entropies`` cuts its bands into (whole rows of blocks).
_STRIPS_PER_PASS = 16
_TRIM_ROUNDS = 6
#: Where in the window the trim aims, from the budget down (bytes left unused cost PSNR).
_TRIM_AIM = 0.3
#: How much longer a header with the two placeholders is than the real one: the psnr takes
#: 1 to 4 bytes (None, or at most 4 decimals below 9 500 dB: wavecore/binheader.py), the
#: max_error 1 to 9, so at most 3 + 8.
_PLACEHOLDER_EXCESS = 11
_LONGEST_FLOAT = 1.2345678901234567e-300  # 23 characters, the longest repr of a positive float
#: The psnr placeholder: 4 bytes in the binary header, as many as any PSNR the codec measures
#: (rounded down to 4 decimals; no float64 picture passes 9 405 dB: 20 log10 of the largest
#: peak over the smallest nonzero squared error), so the bound is tight by the psnr's bytes.
_PSNR_PLACEHOLDER = 9999.9999


class CodingCounts:
    """What the rate control has run since :meth:`reset`, for tests and benchmarks to read:
    ``full_codings``, entropy codings of a whole picture; ``blocks_recoded``, code-blocks
    coded again after a change of their details (the bpp search's corrections);
    ``sampled_blocks``, code-blocks coded alone to calibrate the bpp prediction."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Set every count to zero."""
        self.full_codings = 0
        self.blocks_recoded = 0
        self.sampled_blocks = 0


#: The counts of every encode in this process (not locked: counts for tests and benchmarks).
coding_counts = CodingCounts()


class _LossyEncoder:
    """Holds one decomposition and codes it at any step, for the rate-control searches.

    Each step can be quantized two ways: in open loop (the dead-zone quantizer alone, cheap) or
    in closed loop (``quantize_bands``' least-squares refinement, about ten times the cost, used
    by default on small decompositions, see :meth:`refines`).  The searches run their trials in
    open loop and the closed loop only where they predict the final bundle to be.  The latest
    quantization and coding of each kind are cached, so the final bundle does not redo them;
    ``codings`` and ``closed_loops`` count the entropy codings and closed-loop quantizations
    (what the searches try to keep few).
    """

    def __init__(self, plan: _Plan, original: np.ndarray, transformed: np.ndarray) -> None:
        self.plan = plan
        self.original = original
        self.coeffs = _decompose(plan, transformed)
        self.kept = self.coeffs
        self.kept_fraction = 1.0
        self.vector_axis = -1 if plan.kind != "image" else None
        self.codings = 0
        self.closed_loops = 0
        #: Whether closed loops keep their fit (``quantize.ClosedLoopFit``) and steps close to
        #: one already run are quantized from it (the quality search's corrections), counted
        #: by ``fit_quantizations``.
        self.reuse_fit = False
        self.fit_quantizations = 0
        self.warm_closed_loops = 0  # closed loops started from an earlier fit (fewer iterations)
        self._fit: tuple[float, ClosedLoopFit] | None = None
        total = sum(
            sum(np.size(band) for band in entry) if isinstance(entry, tuple | list) else entry.size
            for entry in self.coeffs
        )
        self._may_refine = total <= REFINE_MAX_COEFFICIENTS
        self._refines = self._may_refine and plan.wavelet not in _OPEN_LOOP_WAVELETS
        self._rdoq = True
        self._distortion: tuple[float, OpenLoopDistortion] | None = None
        self._predicted: dict[tuple[float, float], float] = {}
        self._quantized: dict[bool, tuple[tuple[float, float], list[Any], dict[str, Any]]] = {}
        self._coded: dict[bool, tuple[tuple[float, float], list[bytes], dict[str, Any]]] = {}
        self._estimates: dict[tuple[float, float], float] = {}
        self._errors_at: dict[tuple[float, float, bool], tuple[float | None, float]] = {}
        self._histogram_cache: tuple[float, list[tuple[np.ndarray, np.ndarray, float]]] | None = (
            None
        )
        self._packed: tuple[list[Any], tuple[Any, ...]] | None = None
        #: Whether the latest reconstruction is kept (``output``) with the key ``(step, kept
        #: fraction, closed)`` it was made at, and the latest bundle (``assembled``) with its
        #: key: a caller that needs what its bundle decodes to (the grids' bpp target) then
        #: need not decode it.  Off by default: a picture's reconstruction is large.
        self.keep_output = False
        #: With ``keep_output``: the latest bundle, with the header and chunks it was written from.
        self.parts: tuple[bytes, dict[str, Any], list[bytes]] | None = None
        self.output: tuple[tuple[float, float, bool], np.ndarray] | None = None
        self.assembled: tuple[bytes, tuple[float, float, bool], dict[str, Any]] | None = None
        #: The bpp sample's least stride over the blocks of its sampled levels: 1 takes every
        #: block of levels of fewer than ``2 * _SAMPLED_BLOCKS`` blocks (a sample as dear as
        #: the full coding); the grids ask for ``_GRID_SAMPLE_STRIDE`` (see
        #: ``_encode_lossy``'s ``half_sample``).
        self.least_sample_stride = 1
        #: Levels of at most this many blocks are coded whole in the bpp sample (pictures of
        #: many blocks; the grids ask for ``_GRID_WHOLE_LEVEL_BLOCKS``).
        self.whole_level_blocks = _WHOLE_LEVEL_BLOCKS
        #: Where the bpp search's sampled prediction aims (a share of the budget) and whether
        #: its model is solved to within 0.4 % of that aim: None keeps the pictures' aim.
        self.bpp_aim: float | None = None
        #: Whether the bpp sample's coded blocks are kept (``_sample``, with its step and kept
        #: fraction), for a full coding at that same step to take rather than code again (the
        #: grids' choice: see ``_GRID_SAMPLE_PRIOR``).
        self.reuse_sample = False
        self._sample: tuple[tuple[float, float], KnownBlocks] | None = None

    def forget_sample(self) -> None:
        """Let the bpp sample's coded blocks and quantization go (the full coding is at
        another step): its bands are freed before the next ones are made."""
        if self._sample is not None:
            self._sample = None
            self._quantized.pop(False, None)

    def keep(self, fraction: float) -> None:
        if fraction == self.kept_fraction:
            return
        self.kept_fraction = fraction
        self.kept = remove_smallest(
            self.coeffs,
            1.0 - fraction,
            wavelet=self.plan.wavelet,
            boundary=list(self.plan.boundary),
            axes=self.plan.axes,
            vector_axis=self.vector_axis,
        )

    def predicted_sse(self, step: float) -> float:
        """The open loop's summed squared error at ``step``, predicted from the coefficients
        (``quantize.OpenLoopDistortion``, colour-weighted): no quantization, no synthesis."""
        if self._distortion is None or self._distortion[0] != self.kept_fraction:
            gains = None
            inverse = get_colour({"id": self.plan.colour}).inverse_matrix
            if inverse is not None:
                channels = self.original.shape[-1]
                columns = (inverse**2).sum(axis=0)  # RGB error per unit of each channel
                alpha = [0.0 if self.plan.opaque else 1.0] * (channels - 3)
                gains = [*map(float, columns), *alpha]
            self._distortion = (
                self.kept_fraction,
                OpenLoopDistortion(
                    self.kept,
                    wavelet=self.plan.wavelet,
                    boundary=list(self.plan.boundary),
                    axes=self.plan.axes,
                    channel_gains=gains,
                ),
            )
        key = (step, self.kept_fraction)
        if key not in self._predicted:
            self._predicted[key] = self._distortion[1](step)
        return self._predicted[key]

    def predictions(self) -> list[tuple[float, float]]:
        """The ``(step, predicted_sse)`` pairs computed so far for the kept fraction."""
        return [(k[0], v) for k, v in self._predicted.items() if k[1] == self.kept_fraction]

    def measured_samples(self) -> int:
        """How many samples the PSNR averages over (an opaque alpha channel left out)."""
        size = self.original.size
        opaque = self.plan.kind == "image" and self.plan.opaque and self.original.ndim == 3
        if opaque and self.original.shape[2] in (2, 4):
            size -= size // self.original.shape[2]
        return max(size, 1)

    def rounding_noise(self) -> float:
        """The squared error that rounding to an integer dtype adds, per sample (about 1/12)."""
        return 1.0 / 12.0 if np.dtype(self.plan.dtype).kind in "iu" else 0.0

    def allow_closed_loop(self, allowed: bool) -> bool:
        """Turn the closed loop on (or off again) where it is off only for the wavelet (a
        fallback of the quality search); whether that changed anything."""
        if self._refines == allowed or not self._may_refine:
            return False
        self._refines = allowed
        return True

    def refines(self) -> bool:
        """Whether the closed loop runs at all (small decompositions); else open = closed."""
        return self._refines

    def _closed(self, closed: bool) -> bool:
        return closed and self._refines

    def rdoq_active(self) -> bool:
        """Whether open-loop quantizations are re-decided by ``rdoq.choose_indices`` (images
        where the closed loop does not run: it aims alone)."""
        return self._rdoq and rdoq.ENABLED and self.plan.kind == "image" and not self._refines

    def use_rdoq(self, allowed: bool) -> None:
        """Allow RDOQ (where :meth:`rdoq_active` finds it on) or not; what was quantized,
        coded or measured before is forgotten."""
        if allowed != self._rdoq:
            self._rdoq = allowed
            self._quantized.clear()
            self._coded.clear()
            self._errors_at.clear()
            self.output = self.assembled = None

    def dead_zone(self, step: float, refine: int = 0) -> tuple[list[Any], dict[str, Any]]:
        """The kept coefficients quantized at ``step`` by ``quantize_bands`` (``refine``
        closed-loop iterations), uncached and without RDOQ."""
        return quantize_bands(
            self.kept,
            step,
            wavelet=self.plan.wavelet,
            boundary=list(self.plan.boundary),
            axes=self.plan.axes,
            refine=refine,
        )

    def quantize(self, step: float, closed: bool = True) -> tuple[list[Any], dict[str, Any]]:
        closed = self._closed(closed)
        key = (step, self.kept_fraction)
        cached = self._quantized.get(closed)
        if cached is None or cached[0] != key:
            fit = self._fit if closed and self.reuse_fit else None
            if fit is not None and (
                fit[0] != self.kept_fraction
                or abs(math.log(step / fit[1].step)) > _FIT_REUSE_LOG_STEP
            ):
                fit = None
            if fit is not None:
                q, params = fit[1].quantize(step)
                self.fit_quantizations += 1
            elif closed and self.reuse_fit:
                warm = self._fit is not None and self._fit[0] == self.kept_fraction
                new_fit = ClosedLoopFit(
                    self.kept,
                    step,
                    wavelet=self.plan.wavelet,
                    boundary=list(self.plan.boundary),
                    axes=self.plan.axes,
                    iterations=_WARM_ITERATIONS if warm else REFINE_ITERATIONS,
                    start=self._fit[1] if warm and self._fit is not None else None,
                )
                self.warm_closed_loops += warm
                # Closed-loop results from an earlier fit are no longer what ``quantize`` gives.
                self._errors_at = {k: v for k, v in self._errors_at.items() if not k[2]}
                self._coded.pop(True, None)
                self._fit = (self.kept_fraction, new_fit)
                q, params = new_fit.quantize(step)
                self.closed_loops += 1
            else:
                q, params = self.dead_zone(step, REFINE_ITERATIONS if closed else 0)
                self.closed_loops += closed
            if self.rdoq_active():
                q = rdoq.choose_indices(self.kept, q, params)
            cached = self._quantized[closed] = (key, q, params)
        return cached[1], cached[2]

    def code(self, step: float, closed: bool = True) -> tuple[list[bytes], dict[str, Any]]:
        closed = self._closed(closed)
        key = (step, self.kept_fraction)
        cached = self._coded.get(closed)
        if cached is None or cached[0] != key:
            # The open loop's own sample at this step (the same indices) is coded already.
            sample = self._sample
            known = sample[1] if sample and not closed and sample[0] == key else None
            chunks, cparams = encode_levels(
                self.quantize(step, closed)[0],
                coder=DEFAULT_CODER,
                version=self.plan.context_version,
                known_blocks=known,
                two_d=self.plan.coded_two_d,
            )
            self.codings += 1
            coding_counts.full_codings += 1
            cached = self._coded[closed] = (key, chunks, cparams)
        return cached[1], cached[2]

    def adopt(
        self,
        step: float,
        closed: bool,
        qcoeffs: list[Any],
        chunks: list[bytes],
        cparams: dict[str, Any],
    ) -> None:
        """Take ``qcoeffs`` (coded as ``chunks``) as the quantization at ``step``: the bpp
        search's trimmed result, whose errors are then measured afresh for the header."""
        closed = self._closed(closed)
        key = (step, self.kept_fraction)
        self._quantized[closed] = (key, qcoeffs, self.quantize(step, closed)[1])
        self._coded[closed] = (key, chunks, cparams)
        self._errors_at.pop((step, self.kept_fraction, closed), None)

    def reconstruct(self, qcoeffs: list[Any], qparams: dict[str, Any]) -> np.ndarray:
        coeffs = dequantize_bands(
            qcoeffs,
            qparams,
            wavelet=self.plan.wavelet,
            boundary=list(self.plan.boundary),
            axes=self.plan.axes,
        )
        decoded = reconstruct_finished(self.plan, coeffs)
        if self.plan.scale:
            # Measured on exactly what decode returns (subnormals rounded, the largest values
            # saturated), brought back to the coded units, where the squares cannot overflow.
            decoded = np.ldexp(decoded, -self.plan.scale)
        return decoded

    def quality(self, step: float, closed: bool = True) -> tuple[float, float]:
        """(PSNR, max error) at ``step``; an exact result counts as infinite PSNR."""
        psnr, max_error = self._measured(step, closed)
        return (math.inf if psnr is None else psnr), max_error

    def mse(self, step: float, closed: bool = True) -> float:
        """The squared error at ``step`` against the peak (from the recorded PSNR)."""
        psnr = self._measured(step, closed)[0]
        return 0.0 if psnr is None else self.plan.peak**2 * 10.0 ** (-psnr / 10.0)

    def _measured(self, step: float, closed: bool = True) -> tuple[float | None, float]:
        """The errors at ``step``, kept for the final bundle's header (no second synthesis)."""
        closed = self._closed(closed)
        key = (step, self.kept_fraction, closed)
        if key not in self._errors_at:
            q, params = self.quantize(step, closed)
            decoded = self.reconstruct(q, params)
            self.kept_output(key, decoded)
            self._errors_at[key] = _errors(self.plan, self.original, decoded)
        return self._errors_at[key]

    def all_measured_meet(self, target: float) -> bool:
        """Whether every step measured so far (at the kept fraction) met ``target`` dB."""
        return all(
            psnr is None or psnr >= target
            for key, (psnr, _) in self._errors_at.items()
            if key[1] == self.kept_fraction
        )

    def kept_output(self, key: tuple[float, float, bool], decoded: np.ndarray) -> None:
        """Keep ``decoded`` as the reconstruction at ``key`` if outputs are kept."""
        if self.keep_output:
            self.output = (key, decoded)

    def output_of(self, bundle: bytes) -> np.ndarray | None:
        """What :func:`wavecore.decode` returns for ``bundle`` (the coded units), if it is the
        latest bundle and its reconstruction was kept; else None."""
        if self.assembled is None or self.output is None or self.assembled[0] is not bundle:
            return None
        if self.output[0] != self.assembled[1]:
            return None
        # The decoder dequantizes with the header's parameters: the same, unless it rounded one.
        if read_bundle(bundle).header.get("qparams") != self.assembled[2]:
            return None
        return self.output[1]

    def _assemble(
        self, step: float, errors: tuple[float | None, float] | None, closed: bool
    ) -> bytes:
        qparams = self.quantize(step, closed)[1]
        chunks, cparams = self.code(step, closed)
        if errors is None:
            errors = self._measured(step, closed)
        header = self.plan.header()
        header.update(
            quantizer=str(qparams.get("name", "deadzone")),
            qparams=qparams,
            coder=str(cparams.get("coder", DEFAULT_CODER)),
            cparams=cparams,
            psnr=errors[0],
            max_error=_unscaled(errors[1], self.plan.scale),
        )
        bundle = write_bundle(header, chunks)
        if self.keep_output:
            self.assembled = (bundle, (step, self.kept_fraction, self._closed(closed)), qparams)
            self.parts = (bundle, header, chunks)
        return bundle

    def bundle(self, step: float, closed: bool = True) -> bytes:
        """The bundle at ``step``, with its measured PSNR and largest error in the header."""
        return self._assemble(step, None, closed)

    def size_bound(self, step: float, closed: bool = True) -> float:
        """An upper bound on ``len(self.bundle(step, closed))`` that skips measuring the errors.

        The placeholders take at least as many bytes as any real psnr and max_error, so the
        real header can only be shorter (by at most :data:`_PLACEHOLDER_EXCESS` bytes).
        """
        return float(len(self._assemble(step, (_PSNR_PLACEHOLDER, _LONGEST_FLOAT), closed)))

    def size_estimate(self, step: float) -> float:
        """A cheap stand-in for :meth:`size_bound`: first-order entropy of every band, in bytes.

        From a histogram of each band's magnitudes (in its quantizer's units) in 1/64-octave
        bins, made once: an estimate at any step then costs microseconds, not a quantization.
        The bpp search uses it to choose where to run the real coder.
        """
        key = (step, self.kept_fraction)
        if key not in self._estimates:
            # Per band: the entropy of its indices' histogram (magnitudes up to 255), the
            # larger magnitudes by their bit length, a bit per sign.  One compiled pass makes
            # the terms (the indices, the histogram, the shares, the selections), NumPy takes
            # their logarithms (its log2 is not the C library's to the bit), and one compiled
            # call adds each band's terms as NumPy's sums would: the estimate is the same
            # number, to the last bit, as NumPy's calls on all the bins gave (the search's
            # steps depend on it), at a third of their time.  About 30 estimates an encode,
            # on the calling thread while the other one waits (a 2048² RGB picture's bpp
            # search spent 6 ms of its 0.27 s in them).
            counts, centres, rounding, band, totals, bands = self._packed_histograms()
            present, shares, used_ends, large, indices, large_ends, signs, sign_ends = (
                _estimate_terms(counts, centres, rounding, band, totals, bands, step)
            )
            bits = _estimated_bits(
                present * np.log2(shares),
                used_ends,
                large * np.log2(indices),
                large_ends,
                signs,
                sign_ends,
            )
            self._estimates[key] = bits / 8.0 + _HEADER_GUESS
        return self._estimates[key]

    def _packed_histograms(
        self,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
        """:meth:`_histograms` as one array each of counts, centres and rounding, the band of
        each bin, each band's total count (as ``counts.sum()`` gives it), and the band count."""
        histograms = self._histograms()
        if self._packed is None or self._packed[0] is not histograms:
            sizes = [counts.size for counts, _, _ in histograms]
            packed = (
                np.concatenate([counts for counts, _, _ in histograms]),
                np.concatenate([centres for _, centres, _ in histograms]),
                np.repeat([rounding for _, _, rounding in histograms], sizes),
                np.repeat(np.arange(len(histograms), dtype=np.int64), sizes),
                np.array([counts.sum() for counts, _, _ in histograms], dtype=np.float64),
                len(histograms),
            )
            self._packed = (histograms, packed)
        return self._packed[1]

    def _histograms(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Per band: bin counts, bin centres (magnitude / band weight) and dead-zone rounding."""
        if self._histogram_cache is None or self._histogram_cache[0] != self.kept_fraction:
            levels = band_weights(
                self.kept,
                wavelet=self.plan.wavelet,
                boundary=list(self.plan.boundary),
                axes=self.plan.axes,
            )
            out = []
            flat, scales, roundings = [], [], []
            for index, (entry, weights) in enumerate(zip(self.kept, levels, strict=True)):
                bands = entry if isinstance(entry, tuple | list) else (entry,)
                rounding = APPROX_ROUNDING if index == 0 else DEFAULT_ROUNDING
                for band, weight in zip(bands, weights, strict=True):
                    flat.append(np.ascontiguousarray(band, dtype=np.float64).reshape(-1))
                    scales.append(1.0 / weight)
                    roundings.append(rounding)
            for (counts, top), rounding in zip(
                _log_histograms(flat, scales), roundings, strict=True
            ):
                used = np.flatnonzero(counts)  # (only the bins in use: a third of them)
                octave, step = np.divmod(used, _OCTAVE_BINS)
                centres = 2.0 ** (top - _OCTAVES + octave - 1) * (
                    2.0 + (2 * step + 1) / _OCTAVE_BINS
                )  # the middle of each bin, halfway along its mantissa range
                centres[used == 0] = 0.0  # bin 0: everything tiny, zeros included
                out.append((counts[used].astype(np.float64), centres, rounding))
            self._histogram_cache = (self.kept_fraction, out)
        return self._histogram_cache[1]


def _log_histograms(bands: list[np.ndarray], scales: list[float]) -> list[tuple[np.ndarray, int]]:
    """``_kernels.log_histogram(band, scale, _OCTAVE_BINS, _OCTAVES)`` of every flat band, in
    two parallel regions over all the bands (slices of each): the largest values, then the
    counts, both exact whatever the slicing (a maximum, and integer counts added up)."""
    sizes = [band.size for band in bands]
    largest = [0.0] * len(bands)
    parts: list[tuple[int, Any]] = []

    def find_largest(item: int, lo: int, hi: int) -> None:
        parts.append((item, largest_scaled(bands[item][lo:hi], scales[item])))

    run_slices(sizes, find_largest)
    for item, value in parts:
        largest[item] = max(largest[item], value)
    tops = [int(top_octave(value)) for value in largest]
    parts.clear()

    def count(item: int, lo: int, hi: int) -> None:
        counts = log_histogram_counts(
            bands[item][lo:hi], scales[item], _OCTAVE_BINS, _OCTAVES, tops[item]
        )
        parts.append((item, counts))

    run_slices(sizes, count)
    totals = [np.zeros(_OCTAVE_BINS * _OCTAVES, dtype=np.int64) for _ in bands]
    for item, counts in parts:
        totals[item] += counts
    return list(zip(totals, tops, strict=True))


#: A guided search whose guide moves the step by less than this (in log) is stalled.
_GUIDE_STALLED = 1e-3


class _Search:
    """Finds the step whose measured value is as large as allowed (``value <= bound``).

    ``measure(step)`` is a positive value that grows or shrinks with the step roughly like a
    power law (bundle size ~ step**-1, squared error ~ step**2).  The search keeps the largest
    value within the bound and the smallest beyond it, interpolates between them in log-log
    (the secant method, clamped so both brackets move), and before it has both extrapolates
    with the expected exponent, at most a factor 16 per step (or asks ``guide(step, value)``
    for the next step, when given).  It stops once a value lies in ``[enough, bound]``.
    """

    def __init__(
        self,
        measure: Callable[[float], float],
        bound: float,
        enough: float,
        slope: float,
        low: float,
        high: float,
        guide: Callable[[float, float], float] | None = None,
        aim: float | None = None,
        resolution: float = 0.0,
    ) -> None:
        self.measure, self.bound, self.enough = measure, bound, enough
        self.guide = guide
        self.resolution = resolution
        if aim is None:
            aim = math.sqrt(bound * enough) if enough > 0 else bound
        self.aim = max(aim, 1e-300)
        self.slope, self.low, self.high = slope, low, high
        self.within: tuple[float, float] | None = None  # (step, value) with value <= bound
        self.beyond: tuple[float, float] | None = None  # (step, value) with value > bound
        self.last: tuple[float, float] | None = None
        # The bracket the secant narrows: the latest evaluations on either side between the
        # two.  Where the value is not monotone in the step (the quantizer's error can dip
        # when the step grows), the largest value within is not always the bracket's end.
        self.inner: tuple[float, float] | None = None
        self.outer: tuple[float, float] | None = None

    def done(self) -> bool:
        return self.within is not None and self.within[1] >= self.enough

    def evaluate(self, step: float) -> float:
        value = max(self.measure(step), 1e-300)
        self.last = (step, value)
        bracketed = self.inner is not None and self.outer is not None
        if value <= self.bound:
            if self.within is None or value > self.within[1]:
                self.within = (step, value)
            if self._narrows(step) if bracketed else self.within == (step, value):
                self.inner = (step, value)
        else:
            if self.beyond is None or value < self.beyond[1]:
                self.beyond = (step, value)
            if self._narrows(step) if bracketed else self.beyond == (step, value):
                self.outer = (step, value)
        return value

    def _narrows(self, step: float) -> bool:
        assert self.inner is not None and self.outer is not None
        return min(self.inner[0], self.outer[0]) < step < max(self.inner[0], self.outer[0])

    def next_step(self) -> float | None:
        if self.inner is not None and self.outer is not None:
            (s0, v0), (s1, v1) = self.inner, self.outer
            if s0 == s1 or abs(math.log(s1 / s0)) <= self.resolution:
                return None
            t = 0.5
            if v0 != v1:
                t = (math.log(self.aim) - math.log(v0)) / (math.log(v1) - math.log(v0))
            t = min(max(t, 0.1), 0.9)
            step = math.exp(math.log(s0) + t * (math.log(s1) - math.log(s0)))
            return None if step in (s0, s1) else step
        assert self.last is not None
        s, v = self.last
        aim = self.aim
        if self.guide is not None:
            step = min(max(self.guide(s, v), self.low), self.high)
            crawls = step > 0 and s > 0 and 0 < abs(math.log(step / s)) <= _GUIDE_STALLED
            if step != s and not crawls:
                return step
            # The guide is stuck or crawls.  Extrapolate as without it, and from beyond the
            # bound to inside it: an aim beyond the bound (where a trim was to take over, and
            # could not: a picture coded nearly exactly, whose size hardly moves with the step)
            # crept up on it a few hundredths of a per cent a coding, 28 codings.
            if v > self.bound > 0:
                aim = min(aim, math.sqrt(self.bound * max(self.enough, 1e-300)))
        exponent = (math.log(aim) - math.log(v)) / self.slope
        step = s * math.exp(min(max(exponent, -math.log(16)), math.log(16)))
        step = min(max(step, self.low), self.high)
        return None if step == s else step

    def run(self, start: float, evaluations: int) -> None:
        step: float | None = start
        for _ in range(evaluations):
            if step is None:
                return
            self.evaluate(step)
            if self.done():
                return
            step = self.next_step()


def _largest_step(ok: Callable[[float], bool], low: float, high: float) -> float:
    """The largest step in ``[low, high]`` (log scale) for which ``ok`` holds; ``ok(low)`` must."""
    if ok(high):
        return high
    for _ in range(_SEARCH_STEPS):
        mid = math.sqrt(low * high)
        if ok(mid):
            low = mid
        else:
            high = mid
    return low


def _encode_lossy(
    plan: _Plan,
    original: np.ndarray,
    transformed: np.ndarray,
    *,
    keep: float | None,
    quality: float | None,
    bpp: float | None,
    tolerance: float | None,
    outputs: list[np.ndarray | None] | None = None,
    half_sample: bool = False,
) -> bytes:
    """The plan's bundle under one target.  ``outputs``, if given, receives what
    :func:`wavecore.decode` returns for it (the coded units) where the rate control made that
    reconstruction on its way (None where it did not): a caller that measures the output
    (:mod:`wavecore.grids`) then need not decode the bundle.  ``half_sample``: the bpp
    search's sample takes every third block of each level of two or more blocks, and codes
    only single-block levels whole (``_GRID_SAMPLE_STRIDE``, ``_GRID_WHOLE_LEVEL_BLOCKS``),
    and the step it predicts is solved for the budget itself (``_GRID_BPP_AIM``): the grids'
    choice; images keep the sample and aim they were tuned with."""
    encoder = _LossyEncoder(plan, original, transformed)
    # Only a bpp target gains from the filter: a quality target is met without it.
    restores = bpp is not None and keep is None and tolerance is None and _restorable(plan)
    encoder.keep_output = outputs is not None or restores
    if half_sample:
        encoder.least_sample_stride = _GRID_SAMPLE_STRIDE
        encoder.whole_level_blocks = _GRID_WHOLE_LEVEL_BLOCKS
        encoder.bpp_aim = _GRID_BPP_AIM
        encoder.reuse_sample = True
    low, high = plan.peak * 2.0**-20, plan.peak * 4.0
    if keep is not None:
        encoder.keep(keep)
        bundle = encoder.bundle(plan.peak * KEEP_RELATIVE_STEP)
    elif tolerance is not None:
        bundle = _encode_to_tolerance(encoder, tolerance, low, high)
    elif bpp is not None:
        bundle = _encode_to_bpp(encoder, bpp, low, high)
        if restores:  # in the bytes the rate control left free under the budget, if they suffice
            pixels = plan.shape[0] * plan.shape[1]
            bundle = _with_restoration(encoder, bundle, math.floor(bpp * pixels / 8.0))
    else:
        target = DEFAULT_QUALITY if quality is None else quality
        bundle = _encode_to_quality(encoder, target, low, high)
    if outputs is not None:
        outputs.append(encoder.output_of(bundle))
    return bundle


def _restorable(plan: _Plan) -> bool:
    """Whether the encoder fits a restoration filter (:mod:`wavecore.restoration`): lossy
    ``uint8`` and ``uint16`` pictures coded with the context coder's version 8."""
    return (
        plan.kind == "image"
        and plan.dtype in FILTERED_DTYPES
        and plan.context_version == RESTORED_BASE
        and plan.scale == 0
    )


def _predicted_gain_db(
    plan: _Plan, header: dict[str, Any], gains: list[tuple[float, int, int]]
) -> float:
    """The PSNR a restoration filter would add, from the fit's changes of squared error."""
    psnr = header.get("psnr")
    if psnr is None:
        return 0.0
    samples = plan.shape[0] * plan.shape[1] * colour_channels(plan.shape)
    before = plan.peak**2 * 10.0 ** (-psnr / 10.0) * samples
    after = before + sum(change for change, _, _ in gains)
    return 10.0 * math.log10(before / after) if after > 0 else math.inf


def _with_restoration(encoder: _LossyEncoder, bundle: bytes, limit: int) -> bytes:
    """``bundle`` with a restoration filter in its header, fitted to what it decodes to, if
    that lowers the error and fits in ``limit`` bytes (the classes that gain least are left
    out until it does); else ``bundle``.  The header's ``psnr`` and ``max_error`` are then
    the filtered picture's."""
    plan = encoder.plan
    if encoder.parts is None or encoder.parts[0] is not bundle:
        return bundle  # (every path ends with a bundle of _assemble's: see its parts)
    decoded = encoder.output_of(bundle)
    if decoded is None:
        decoded = decode(bundle)
    gains: list[tuple[float, int, int]] = []
    restore = fit_restoration(decoded, encoder.original, gains)
    _, header, chunks = encoder.parts
    if restore is not None and _predicted_gain_db(plan, header, gains) < _RESTORE_LEAST_GAIN_DB:
        return bundle
    weakest = sorted(gains, reverse=True)  # the smallest drop of the error first
    while restore is not None:
        # The size with this header's numbers: the filtered picture's take as many bytes, or
        # one more at most (a margin of two keeps the last check from failing).
        size = len(write_bundle(dict(header, restore=restore), chunks))
        if size + 2 <= limit:
            psnr, largest = _errors(plan, encoder.original, apply_restoration(decoded, restore))
            before = header.get("psnr")
            if psnr is None or before is None or psnr <= before:
                return bundle
            errors = {"psnr": psnr, "max_error": _unscaled(largest, plan.scale)}
            restored = write_bundle(dict(header, restore=restore, **errors), chunks)
            if len(restored) <= limit:
                return restored
            size = limit + 1
        # Leave out the weakest classes, about 5 bytes each, until the rest fit.
        for _ in range(max(1, (size + 2 - limit + 4) // 5)):
            if not weakest:
                return bundle
            _, channel, klass = weakest.pop(0)
            item = restore[channel]
            item["taps"][klass] = None
            if all(t is None for t in item["taps"]):
                restore[channel] = None
        if all(item is None for item in restore):
            return bundle
    return bundle


def _encode_to_quality(encoder: _LossyEncoder, target: float, low: float, high: float) -> bytes:
    """:func:`_quality_step`'s bundle.  Where RDOQ runs and the step found misses the window
    (``target`` to ``_QUALITY_RDOQ_WINDOW_DB`` above it: pictures whose error jumps with the
    step, as RDOQ's decisions flip together, like the sawtooth at 40 dB), the search runs
    again without RDOQ."""
    with_rdoq, refines = encoder.rdoq_active(), encoder.refines()
    step = _quality_step(encoder, target, low, high)
    if with_rdoq and step < high:  # (at ``high`` every step meets the target)
        psnr = encoder.quality(step)[0]
        if not target <= psnr <= target + _QUALITY_RDOQ_WINDOW_DB:
            encoder.allow_closed_loop(refines)  # (its fallback may have turned it on)
            encoder.use_rdoq(False)
            step = _quality_step(encoder, target, low, high)
    return encoder.bundle(step)


def _quality_step(encoder: _LossyEncoder, target: float, low: float, high: float) -> float:
    """The largest step whose PSNR meets ``target`` (and exceeds it by at most ~0.04 dB).

    The step is predicted from the coefficients (:meth:`_LossyEncoder.predicted_sse`, a
    compiled pass per trial step, no synthesis), scaled by a typical ratio to what the decoded
    picture measures; the quantization there (closed loop where it runs) is verified by one
    synthesis, and if its PSNR misses the window, the ratio it measured corrects the
    prediction (at most once for a closed loop, twice for an open one).  Only if those miss
    too (rare: pictures whose error jumps with the step) does the search run on measured
    errors.
    """
    peak2 = encoder.plan.peak**2

    def bound_at(db: float) -> float:
        return peak2 * 10.0 ** (-db / 10.0)

    bound = bound_at(target)
    enough = bound_at(target + _QUALITY_SLACK_DB)
    # A uniform quantizer's error is step**2 / 12: the first guess.
    first = min(max(math.sqrt(12.0 * bound), low), high)
    encoder.reuse_fit = True
    predicted = _predicted_quality_step(encoder, target, first, low, high)
    # Every step measured met the target: it may be below what the coarsest quantizer gives
    # (a faint picture at the default 40 dB), and then the largest step is the answer.  The
    # searches below look for an error just under the bound, which no step gives there: they
    # ran to their limits, some 1,400 syntheses (10 s for a 16,384 × 1 column of noise of
    # amplitude 4, 32 s for 65,536 × 1).
    if (
        predicted is None
        and encoder.all_measured_meet(target)
        and encoder.quality(high)[0] >= target
    ):
        return high
    if predicted is None and encoder.allow_closed_loop(True):
        # The open loop's error jumps with the step here (whole bands emptying, as at low
        # quality on smooth pictures): the closed loop's refit is smoother.  If it misses
        # too, the search below runs in open loop (on the sawtooth, the closed loop's
        # search took ten times as long and landed further from the target).
        predicted = _predicted_quality_step(encoder, target, first, low, high)
        if predicted is None:
            encoder.allow_closed_loop(False)
    if predicted is not None:
        return predicted
    encoder.reuse_fit = False  # the search on measured errors runs real closed loops
    step = _searched_quality(encoder, target, bound, enough, first, low, high)
    if encoder.quality(step)[0] > target + _QUALITY_ACCEPT_DB and encoder.allow_closed_loop(True):
        step = _searched_quality(encoder, target, bound, enough, first, low, high)
    return step


def _predicted_quality_step(
    encoder: _LossyEncoder, target: float, first: float, low: float, high: float
) -> float | None:
    """The step from the coefficient-domain prediction, verified, or None when it misses."""
    peak2 = encoder.plan.peak**2
    noise = encoder.rounding_noise()
    samples = encoder.measured_samples()
    ratio = (
        _TYPICAL_PREDICTED_RATIO.get(encoder.plan.wavelet, _OTHER_PREDICTED_RATIO)
        if encoder.refines()
        else _OTHER_PREDICTED_RATIO
    )

    def bound_at(db: float) -> float:
        return peak2 * 10.0 ** (-db / 10.0)

    step = first
    if encoder.refines() and encoder.reuse_fit:
        # The open loop's error relative to the prediction depends on the picture (0.83-1.7:
        # the basis is not orthogonal, and the cross terms between coefficients count); the
        # closed loop's relative to the open loop's much less (0.78-0.88).  One synthesis in
        # open loop calibrates the first, so that the first closed loop lands close, and a
        # correction costs an open loop (quantized from its fit) or a warm closed loop.
        aim = (bound_at(target + _QUALITY_AIM_DB) - noise) * samples
        if aim <= 0:
            return None
        # (The ratio varies little with the step: a step near the target will do.)
        step = _solve_predicted(encoder, aim, step, low, high, _CALIBRATION_WINDOW_DB)
        error = encoder.mse(step, closed=False) - noise
        predicted = encoder.predicted_sse(step) / samples
        if not (error > 0 and predicted > 0):
            return None
        ratio = error / predicted
        wavelet = encoder.plan.wavelet
        ratio *= _AIM_REFINED_RATIO.get(
            wavelet, _TYPICAL_REFINED_RATIO.get(wavelet, _OTHER_REFINED_RATIO)
        )
    measured: list[tuple[float, float]] = []  # (step, squared error) of each verification
    fitted = encoder.refines() and encoder.reuse_fit
    verifies = _QUALITY_FIT_VERIFIES if fitted else 2 if encoder.refines() else None
    closed_loops = seen = encoder.closed_loops
    if verifies is None:
        verifies = _QUALITY_OPEN_VERIFIES + (_QUALITY_RDOQ_VERIFIES if encoder.rdoq_active() else 0)
    for _ in range(verifies):
        aim = (bound_at(target + _QUALITY_AIM_DB) - noise) * samples / ratio
        if aim <= 0:
            return None
        step = _bracketed_step(measured, bound_at(target + _QUALITY_AIM_DB)) or _solve_predicted(
            encoder, aim, step, low, high
        )
        psnr = encoder.quality(step)[0]
        if target <= psnr <= target + _QUALITY_ACCEPT_DB:
            return step
        mse = encoder.mse(step)
        if fitted and encoder.closed_loops != seen:
            # A new fit: the errors measured on the earlier one are not on this curve.
            if encoder.closed_loops - closed_loops >= _QUALITY_FIT_CLOSED_LOOPS:
                return None
            seen = encoder.closed_loops
            measured.clear()
        measured.append((step, mse))
        error, predicted = mse - noise, encoder.predicted_sse(step) / samples
        if not (error > 0 and predicted > 0):
            return None
        ratio = error / predicted
    return None


def _bracketed_step(measured: list[tuple[float, float]], aim: float) -> float | None:
    """Once verifications lie on both sides of ``aim``, the log-log secant between the
    closest two (where the ratio to the prediction drifts with the step, as at very low
    quality, where whole bands empty, the measured points are the better guide)."""
    below = [p for p in measured if p[1] < aim]
    above = [p for p in measured if p[1] > aim]
    if not (below and above):
        return None
    (s0, v0), (s1, v1) = max(below, key=lambda p: p[1]), min(above, key=lambda p: p[1])
    if s0 == s1 or v0 <= 0:
        return None
    t = math.log(aim / v0) / math.log(v1 / v0)
    return math.exp(math.log(s0) + min(max(t, 0.05), 0.95) * math.log(s1 / s0))


def _solve_predicted(
    encoder: _LossyEncoder,
    aim: float,
    start: float,
    low: float,
    high: float,
    window_db: float = _QUALITY_MODEL_WINDOW_DB,
) -> float:
    """The step whose predicted squared error is ``aim`` (within ``window_db``).

    Every prediction made so far is kept (by the encoder), so a correction with a new ratio
    starts from the known points: log-log interpolation between the two that bracket the aim,
    else extrapolation from the nearest with the uniform quantizer's exponent 2.
    """
    tolerance = math.log(10.0) * window_db / 10.0
    step = start
    for _ in range(_MODEL_EVALUATIONS):
        value = encoder.predicted_sse(step)
        if value > 0 and abs(math.log(value / aim)) <= tolerance:
            return step
        known = [(s, v) for s, v in encoder.predictions() if v > 0]
        below = [p for p in known if p[1] < aim]
        above = [p for p in known if p[1] > aim]
        if below and above:
            (s0, v0), (s1, v1) = max(below, key=lambda p: p[1]), min(above, key=lambda p: p[1])
            t = math.log(aim / v0) / math.log(v1 / v0)
            following = math.exp(math.log(s0) + min(max(t, 0.05), 0.95) * math.log(s1 / s0))
        else:
            s0, v0 = min(known, key=lambda p: abs(math.log(p[1] / aim)), default=(step, 0.0))
            if v0 <= 0:
                following = step * 2.0
            else:
                exponent = min(max(math.log(aim / v0) / 2.0, -math.log(16)), math.log(16))
                following = s0 * math.exp(exponent)
        following = min(max(following, low), high)
        if following == step or abs(math.log(following / step)) <= _QUALITY_STEP_RESOLUTION:
            return step
        step = following
    return step


def _predicted_mse(encoder: _LossyEncoder, ratio: float, noise: float, step: float) -> float:
    return encoder.predicted_sse(step) * ratio + noise


def _searched_quality(
    encoder: _LossyEncoder,
    target: float,
    bound: float,
    enough: float,
    first: float,
    low: float,
    high: float,
) -> float:
    """The search on measured errors, for when the prediction misses (its fallback): the
    open loop's first, where that does not land in the window the closed loop's (about ten
    times the cost, only on pictures whose error jumps with the step)."""

    def mse(step: float) -> float:
        return encoder.mse(step)

    if not encoder.refines():
        search = _Search(mse, bound, enough, 2.0, low, high, resolution=_QUALITY_STEP_RESOLUTION)
        search.run(first, _QUALITY_EVALUATIONS)
    else:
        # The fallback: the closed loop's errors bracket the target, steered by the open-loop
        # model scaled by the latest measured ratio until they do.
        ratio = _TYPICAL_REFINED_RATIO.get(encoder.plan.wavelet, _OTHER_REFINED_RATIO)

        def scaled_model_step(step: float, value: float | None) -> float:
            nonlocal ratio
            if value is not None:
                model_value = encoder.mse(step, closed=False)
                if value > 0 and model_value > 0:
                    ratio = value / model_value
            # The resolution stops it where the error jumps across the window (faint noise,
            # whose error steps as whole values flip): else it narrowed the bracket for all
            # its 24 open loops, each time the search below asked.
            model = _Search(
                lambda s: encoder.mse(s, closed=False) * ratio,
                bound,
                enough,
                2.0,
                low,
                high,
                resolution=_MODEL_STEP_RESOLUTION,
            )
            model.run(step, _MODEL_EVALUATIONS)
            return (model.within or model.last or (low, 0.0))[0]

        search = _Search(
            mse,
            bound,
            enough,
            2.0,
            low,
            high,
            guide=scaled_model_step,
            resolution=_QUALITY_STEP_RESOLUTION,
        )
        # (Seeding it with the closed loops already run was tried: on pictures whose error
        # is not monotone in the step it ended further above the target.)
        search.run(scaled_model_step(first, None), _QUALITY_EVALUATIONS)
    if search.within is None or encoder.quality(search.within[0])[0] < target:
        best = encoder.quality(low)[0]
        if best < target:
            msg = (
                f"quality {target} dB cannot be reached for this data (the finest quantizer "
                f"gives {best:.2f} dB); ask for less, or use lossless=True for 8/16-bit images"
            )
            raise InvalidParameter(msg)
        step = _largest_step(lambda s: encoder.quality(s)[0] >= target, low, high)
    else:
        step = search.within[0]
    return step


def _times(measure: Callable[[float], float], factor: float, step: float) -> float:
    return measure(step) * factor


def _ratio_model_size(encoder: _LossyEncoder, model: _RatioModel) -> Callable[[float], float]:
    """The predicted coded size at a step: the first-order estimate times ``model`` there."""
    return lambda step: encoder.size_estimate(step) * model(step)


def _encode_to_tolerance(
    encoder: _LossyEncoder, tolerance: float, low: float, high: float
) -> bytes:
    """The largest step whose largest error stays within ``tolerance``, verified on the bundle.

    The bisection runs in open loop.  Where the closed loop runs, it runs at the step found;
    its largest error there, relative to the open loop's, scales the open-loop errors for a
    second open-loop bisection (the least-squares fit usually lowers the largest error, so the
    step can grow), and a few closed loops bisect between the two steps (the largest error
    is too irregular in the step to predict closely).  The result is the largest step whose
    closed loop met the tolerance, or else the open loop's.
    """
    finest = encoder.quality(low, closed=False)[1]
    if finest > tolerance:
        # Far from the origin (a track in projected metres), the finest step can overflow the
        # quantizer's integers while a coarser one still fits: scan down from the coarsest.
        low = _finest_fitting_step(encoder, tolerance, low, high)
        finest = encoder.quality(low, closed=False)[1]
    if finest > tolerance:
        msg = (
            f"tolerance {tolerance} cannot be met (the finest quantizer leaves a deviation of "
            f"{finest:.3g}); ask for a larger tolerance"
        )
        raise InvalidParameter(msg)
    step = _largest_step(lambda s: encoder.quality(s, closed=False)[1] <= tolerance, low, high)
    closed = False
    if encoder.refines():
        opened, refined = encoder.quality(step, closed=False)[1], encoder.quality(step)[1]
        closed = refined <= tolerance
        if closed and 0 < refined < opened:
            ratio = refined / opened
            fits, beyond = (
                step,
                _largest_step(
                    lambda s: encoder.quality(s, closed=False)[1] * ratio <= tolerance, step, high
                ),
            )
            for trial_index in range(_TOLERANCE_CLOSED_LOOPS):
                if beyond <= fits * (1.0 + _TOLERANCE_STEP_RESOLUTION):
                    break
                trial = beyond if trial_index == 0 else math.sqrt(fits * beyond)
                if encoder.quality(trial)[1] <= tolerance:
                    fits = trial
                else:
                    beyond = trial
            step = fits
    while True:  # verify on the decoded bundle, and tighten until the guarantee holds
        data = encoder.bundle(step, closed)
        decoded = decode(data)
        if encoder.plan.scale:
            decoded = np.ldexp(decoded, -encoder.plan.scale)
        if _errors(encoder.plan, encoder.original, decoded)[1] <= tolerance or step <= low:
            return data
        step, closed = step / 2, False


def _finest_fitting_step(
    encoder: _LossyEncoder, tolerance: float, low: float, high: float
) -> float:
    """The coarsest of ``high / 2**k`` (down to ``low``) whose open loop meets ``tolerance``,
    or ``low`` if none does: a feasible lower end for the bisection when ``low`` is not."""
    step = high
    while step > low:
        if encoder.quality(step, closed=False)[1] <= tolerance:
            return step
        step /= 2.0
    return low


def _encode_to_bpp(encoder: _LossyEncoder, bpp: float, low: float, high: float) -> bytes:
    """The bundle closest below ``bpp`` (whole bundle, header included), within 3 % of it.

    The trials are open-loop codings (a quantization and an entropy coding each), steered by
    the cheap size estimate (first-order entropy) scaled by how the real coder compares with
    it.  Where the closed loop runs, its bundle is the open loop's times a factor close to one
    (``_TYPICAL_CLOSED_SIZE_RATIO``): the trials aim at the budget over that factor, the
    closed loop runs once at the step found and is coded, and if it misses the budget's
    window, once more with the factor it measured.  Only if that misses too (rare) does the
    search code closed loops alone.  If the size jumps between two neighbouring steps, the
    finer one is trimmed by removing its least important details.
    """
    plan = encoder.plan
    pixels = plan.shape[0] * plan.shape[1]
    budget = math.floor(bpp * pixels / 8.0)
    # Stop at anything from 97.5 % (the promise is 97 %; the real header is shorter than the
    # bound by what its two placeholder numbers take beyond the real ones, at most
    # _PLACEHOLDER_EXCESS bytes): each miss costs a coding.
    enough = min(
        budget,
        max(math.ceil(0.97 * bpp * pixels / 8.0) + _PLACEHOLDER_EXCESS, math.ceil(0.975 * budget)),
    )
    # The coarsest step's bundle, by its size with the header's placeholders (up to
    # _PLACEHOLDER_EXCESS bytes over what is written): the least a budget needs.
    coarsest = encoder.size_bound(high) if budget < 64 else None
    if coarsest is not None and budget < coarsest:  # not even that fits: say what it needs
        enough = budget = 0
    if budget > 0 and encoder.refines():
        predicted = _predicted_bpp(encoder, budget, enough, low, high)
        if predicted is not None:
            return predicted
    start: float | None = None
    if encoder.refines() and budget > 0:
        factor = _TYPICAL_CLOSED_SIZE_RATIO.get(encoder.plan.wavelet, _OTHER_CLOSED_SIZE_RATIO)
        open_sizes: dict[tuple[float, float], float] = {}

        def open_size(step: float) -> float:
            key = (step, encoder.kept_fraction)
            if key not in open_sizes:
                open_sizes[key] = encoder.size_bound(step, closed=False)
            return open_sizes[key]

        for _ in range(2):  # the prediction, and at most one correction
            encoder.keep(1.0)
            step = _fit_budget(
                encoder,
                functools.partial(_times, open_size, factor),
                min(budget, math.floor(_OPEN_TRIALS_WINDOW[1] * budget)),
                max(enough, math.ceil(_OPEN_TRIALS_WINDOW[0] * budget)),
                _OPEN_TRIALS_AIM * budget,
                low,
                high,
                start,
            )
            if step is None:
                break
            size = encoder.size_bound(step)
            if _written_enough(budget, enough) <= size <= budget:
                return encoder.bundle(step)
            factor, start = size / open_size(step), step
        encoder.keep(1.0)
    trimmed: list[bytes] = []

    def size_or_trimmed(step: float) -> float:
        """The coded size at ``step``; a little outside the window, adjusted into it."""
        size = encoder.size_bound(step)
        trims = not (trimmed or encoder.refines()) and encoder.kept_fraction == 1
        near = _FILL_LIMIT * budget <= size < enough or budget < size <= trim_limit * budget
        if trims and near:
            data = _trim_to_budget(encoder, step, False, budget, enough)
            if data is not None:
                trimmed.append(data)
                # The trimmed bundle is what the search returns, so it ends the search: its
                # size as written may be up to the placeholders' excess under the stop that
                # bounds need (_written_enough), which would have sent the search on for
                # nothing (33 codings of a 2 KB budget).
                return float(max(len(data), _written_enough(budget, enough)))
        return size

    colour = encoder.plan.colour != "none"
    typical = _TYPICAL_COLOUR_RATIO if colour else _TYPICAL_GREY_RATIO
    ratio: float | _RatioModel = typical
    many_blocks = _code_block_count(encoder) >= _SAMPLING_MIN_BLOCKS
    bpp_aim, trim_limit = (
        (_BPP_AIM_MANY_BLOCKS, _TRIM_LIMIT_MANY_BLOCKS) if many_blocks else (_BPP_AIM, _TRIM_LIMIT)
    )
    if many_blocks and encoder.rdoq_active():
        bpp_aim = _RDOQ_BPP_AIM_MANY_BLOCKS
    # (Pictures of few blocks keep theirs: their sample is every other block, no finer.)
    tight = encoder.bpp_aim is not None and many_blocks and not encoder.refines()
    if tight and encoder.bpp_aim is not None:
        bpp_aim = encoder.bpp_aim
    if encoder.rdoq_active() and start is None and budget > 0:
        samples = _RDOQ_SAMPLES if many_blocks else 1
        ratio, start = _rdoq_sampled_model(encoder, typical, bpp_aim * budget, low, high, samples)
    elif not encoder.refines() and start is None:
        # Where the sample's blocks are kept, it is taken where the grids' ratio points: the
        # full coding then takes them if the sample predicts its own step to fit.
        reuse = tight and encoder.reuse_sample
        prior = _GRID_SAMPLE_PRIOR if reuse else typical
        sample_step = _model_step(
            encoder, lambda s: encoder.size_estimate(s) * prior, bpp_aim * budget, low, high
        )
        sampled = None if sample_step is None else _sampled_ratio_at(encoder, sample_step, typical)
        if reuse and sampled is not None and sample_step is not None:
            sample_size = encoder.size_estimate(sample_step) * sampled
            if _REUSE_WINDOW[0] * budget <= sample_size <= _REUSE_WINDOW[1] * budget:
                start = sample_step
            else:  # coded at another step: the sample's blocks and bands are of no more use
                encoder.forget_sample()
        resample = not many_blocks  # (a sample of many blocks predicts well enough at once)
        if (
            resample
            and sampled is not None
            and abs(math.log(sampled / typical)) > _RESAMPLE_LOG_RATIO
        ):
            # The coder's ratio moves with the step: sampled again where the first one points.
            sampled = _sampled_ratio(encoder, sampled, bpp_aim * budget, low, high) or sampled
        ratio = sampled or typical
    step = _fit_budget(
        encoder,
        size_or_trimmed,
        budget,
        _written_enough(budget, enough),
        0.993 * budget if encoder.refines() else bpp_aim * budget,
        low,
        high,
        start,
        ratio,
        tight=tight,
    )
    if trimmed:
        return trimmed[0]
    if step is None:
        smallest = math.ceil(encoder.size_bound(high) if coarsest is None else coarsest)
        msg = (
            f"bpp {bpp} is below what this {encoder.plan.kind} can be coded in: its smallest "
            f"bundle needs {smallest} bytes = {8 * smallest / pixels:.4f} bpp (header included)"
        )
        raise BitrateTooLow(msg, smallest)
    return _last_bundle(encoder, step)


def _rdoq_sampled_model(
    encoder: _LossyEncoder, ratio: float, aim: float, low: float, high: float, samples: int
) -> tuple[float | _RatioModel, float | None]:
    """Where RDOQ re-decides the indices: the coder's ratio to the first-order estimate as a
    function of the step (:class:`_RatioModel`), from samples of blocks at the steps it
    points to in turn (``samples`` at most, until the step it solves for is one already
    sampled, to ``_RDOQ_SAMPLE_RESOLUTION``), and the step it solves for, where the one full
    coding starts.  The typical ``ratio`` and no start where the picture cannot be
    sampled."""
    model = _RatioModel()
    step = _model_step(encoder, lambda s: encoder.size_estimate(s) * ratio, aim, low, high)
    sampled_at = None
    for _ in range(samples):
        if step is None:
            break
        if sampled_at is not None and abs(math.log(step / sampled_at)) <= _RDOQ_SAMPLE_RESOLUTION:
            break
        measured = _sampled_ratio_at(encoder, step, ratio)
        if measured is None:
            break
        model.add(step, measured)
        sampled_at = step
        step = _model_step(encoder, _ratio_model_size(encoder, model), aim, low, high)
    if sampled_at is None:
        return ratio, None
    return model, step


def _written_enough(budget: int, enough: int) -> int:
    """The least size *bound* to stop at: ``enough`` (97.5 % of the budget, or 97 % and the
    placeholder excess for small budgets), raised so that the bundle as written, up to
    :data:`_PLACEHOLDER_EXCESS` bytes shorter than its bound, still keeps 97.5 %.  Only the
    stops use it; the aims stay where ``enough`` puts them."""
    return min(budget, max(enough, math.ceil(0.975 * budget) + _PLACEHOLDER_EXCESS))


def _last_bundle(encoder: _LossyEncoder, step: float) -> bytes:
    """``encoder.bundle(step)`` as the encoder's last act: the header's errors are measured on
    the synthesis of coefficients dequantized into the encoder's own coefficient arrays (a
    2048² RGB picture's are 100 MB: faulting in fresh pages for them cost 10-30 ms of system
    time, more with two threads faulting at once), which nothing reads afterwards."""
    if (step, encoder.kept_fraction, encoder.refines()) in encoder._errors_at:
        return encoder.bundle(step)  # measured already
    qcoeffs, qparams = encoder.quantize(step)
    plan = encoder.plan
    coeffs = dequantize_bands(
        qcoeffs,
        qparams,
        wavelet=plan.wavelet,
        boundary=list(plan.boundary),
        axes=plan.axes,
        out=encoder.coeffs,
    )
    encoder.coeffs = encoder.kept = []  # overwritten: nothing may use them again
    decoded = reconstruct_finished(plan, coeffs)
    del coeffs
    if plan.scale:  # as _LossyEncoder.reconstruct measures
        decoded = np.ldexp(decoded, -plan.scale)
    encoder.kept_output((step, encoder.kept_fraction, encoder.refines()), decoded)
    return encoder._assemble(step, _errors(plan, encoder.original, decoded), True)


def _code_block_count(encoder: _LossyEncoder) -> int:
    """How many code-blocks the block coder makes of ``encoder``'s levels (0 where the layout
    is not the block coder's)."""
    shapes = as_levels(encoder.kept)  # (only the shapes count here)
    if len(shapes) < 2 or any(len(bands) != 3 for bands in shapes[1:]):
        return 0
    _, regions = block_lengths(shapes, True, DEFAULT_BLOCK, np.zeros(0, dtype=np.int64))
    return len(regions)


def _sampled_ratio(
    encoder: _LossyEncoder, ratio: float, aim: float, low: float, high: float
) -> float | None:
    """The coder's size over the first-order estimate, measured on a sample of the blocks.

    On pictures of many code-blocks, every ``k``-th block (about ``_SAMPLED_BLOCKS`` of them)
    is coded at the step the typical ratio predicts, and each block's first-order entropy is
    computed (a histogram of its magnitudes): the sample's ratio of the two, applied to all
    blocks' entropies, predicts the whole coding, for a fraction of a coding's time.  None
    where there are too few blocks (a coding is cheap there) or the layout is not the block
    coder's.
    """
    step = _model_step(encoder, lambda s: encoder.size_estimate(s) * ratio, aim, low, high)
    return None if step is None else _sampled_ratio_at(encoder, step, ratio)


def _model_step(
    encoder: _LossyEncoder, model: Callable[[float], float], aim: float, low: float, high: float
) -> float | None:
    """The step where ``model`` (a predicted size) is ``aim`` within 0.4 %, or the closest."""
    search = _Search(model, aim * 1.004, aim * 0.996, -1.0, low, high, aim=aim)
    search.run(encoder.plan.peak / 16.0, _MODEL_EVALUATIONS)
    found = search.within or search.last
    return None if found is None else found[0]


def _sampled_ratio_at(encoder: _LossyEncoder, step: float, ratio: float) -> float | None:
    """:func:`_sampled_ratio` at ``step`` (``ratio`` stands in for a sampled level without
    entropy)."""
    shapes = as_levels(encoder.kept)  # (only the shapes count here)
    if len(shapes) < 2 or any(len(bands) != 3 for bands in shapes[1:]):
        return None
    _, regions = block_lengths(shapes, True, DEFAULT_BLOCK, np.zeros(0, dtype=np.int64))
    # Pictures of few blocks sample their levels of several blocks, every other block.
    whole_level, least_stride = (
        (encoder.whole_level_blocks, encoder.least_sample_stride)
        if len(regions) >= _SAMPLING_MIN_BLOCKS
        else (1, 2)
    )
    # Where RDOQ runs, the sample is quantized alone, its first-order entropies are the dead
    # zone's (those of the size estimate) and RDOQ re-decides the sampled blocks only (what
    # the whole pass decides there, for a fraction of its cost): the ratio of the coded
    # blocks to those entropies is then RDOQ's coder over the dead zone's estimate.
    alone = encoder.rdoq_active() and rdoq.METHOD == "fast"
    if alone:
        qcoeffs, qparams = encoder.dead_zone(step)
    else:
        qcoeffs, qparams = encoder.quantize(step, closed=False)
    levels = as_levels(qcoeffs)
    entropies = _block_entropies(levels, regions)
    # Levels of few blocks (the coarse ones, small and dense) are coded whole; the others
    # (the fine ones, most of the bytes) one block in ``stride``, each level by its own ratio.
    entry_of = regions[:, 0]
    counts = np.bincount(entry_of)
    sampled = counts[entry_of] > whole_level
    if not sampled.any():
        return None  # the sample would be the whole picture
    stride = max(least_stride, int(sampled.sum()) // _SAMPLED_BLOCKS)
    rank = np.arange(len(regions)) - np.searchsorted(entry_of, entry_of)  # index in its level
    chosen = ~sampled | (rank % stride == stride // 2)
    sample = np.flatnonzero(chosen)
    if alone:
        rdoq.adapt_deadzone(encoder.kept, qcoeffs, qparams, regions=regions[sample])
    coding_counts.sampled_blocks += int(sample.size)
    # The plan's coder version (pictures 8, surfaces 6: a sampled block reads its parent).
    version = encoder.plan.context_version or CONTEXT_VERSION
    if encoder.reuse_sample and not alone:
        known = code_blocks(levels, True, DEFAULT_BLOCK, sample, version)
        encoder._sample = ((step, encoder.kept_fraction), known)
        lengths = known.lengths
    else:
        lengths, _ = block_lengths(levels, True, DEFAULT_BLOCK, sample, version)
        # Let the sample's quantization go now (the full coding quantizes at another step):
        # its bands are freed before the next ones are made, which can then take their
        # memory instead of faulting in fresh pages.
        del levels, qcoeffs
        encoder._quantized.pop(False, None)
    coded = 0.0
    for entry in range(len(counts)):
        mine = entry_of[sample] == entry
        level_coded = float(lengths[mine].sum())
        if counts[entry] <= whole_level:
            coded += level_coded
            continue
        level_entropy = float(entropies[sample[mine]].sum())
        if level_entropy <= 0:
            coded += float(entropies[entry_of == entry].sum()) * ratio
        else:
            coded += level_coded / level_entropy * float(entropies[entry_of == entry].sum())
    # The chunks' tables of block lengths and the header, as the estimate counts them.
    predicted = coded + 2.0 * len(regions) + _HEADER_GUESS
    return predicted / encoder.size_estimate(step)


class _RatioModel:
    """The coder's size over the first-order estimate as a function of the step, from the
    ratios measured at a few steps (on samples of blocks, or whole codings): linear in
    log-log between the measured steps, extrapolated from the nearest two beyond them.

    With RDOQ the ratio moves with the step far more than without (2048² RGB: 0.98 at step
    0.6, 0.60 at 3.7, 0.64 at 8.8; the dead zone's 0.98, 0.89, 0.69), so one ratio measured
    at one step predicts badly a few per cent of step away.
    """

    def __init__(self) -> None:
        self.points: list[tuple[float, float]] = []  # (log step, log ratio), by step

    def add(self, step: float, ratio: float) -> None:
        """Record ``ratio`` measured on a sample at ``step`` (replacing one at that step)."""
        x = math.log(step)
        self.points = sorted([p for p in self.points if p[0] != x] + [(x, math.log(ratio))])

    def correct(self, step: float, ratio: float) -> None:
        """A whole coding measured ``ratio`` at ``step``: every point is scaled by its
        ratio to the model there (the samples' shape kept, their level corrected)."""
        if not self.points:
            self.add(step, ratio)
            return
        shift = math.log(ratio) - math.log(self(step))
        self.points = [(x, y + shift) for x, y in self.points]

    def __call__(self, step: float) -> float:
        x = math.log(step)
        points = self.points
        if len(points) == 1:
            return math.exp(points[0][1])
        i = min(max(int(np.searchsorted([p[0] for p in points], x)), 1), len(points) - 1)
        (x0, y0), (x1, y1) = points[i - 1], points[i]
        slope = (y1 - y0) / (x1 - x0)
        if not x0 <= x <= x1:
            # Beyond the measured steps the slope is not known: half of it, bounded.
            slope = min(max(0.5 * slope, -_RATIO_MODEL_SLOPE), _RATIO_MODEL_SLOPE)
            x0, y0 = (x0, y0) if x < x0 else (x1, y1)
        return math.exp(y0 + slope * (x - x0))


def _block_entropies(
    levels: list[list[np.ndarray]], regions: np.ndarray, block: int = DEFAULT_BLOCK
) -> np.ndarray:
    """Each code-block's first-order entropy in bytes (magnitudes up to 15, larger ones by
    their bit length, a bit per sign), in the block coder's order: per band, one compiled
    pass counts the magnitudes of each block (``block`` a side, tiling each level's bands
    from the top left, row by row, as ``blockcoder`` does); the bands run over the threads."""
    out = np.zeros(len(regions))
    firsts = np.searchsorted(regions[:, 0], np.arange(len(levels) + 1))
    bands_of = []  # (entry, band, blocks across, per-block counts)
    for entry, bands in enumerate(levels):
        count = int(firsts[entry + 1] - firsts[entry])
        grid_cols = -(-max(band.shape[1] for band in bands) // block)
        for band in bands:
            rows, cols = band.shape[0], band.shape[1]
            if rows == 0 or cols == 0:
                continue
            if ((rows - 1) // block) * grid_cols + (cols - 1) // block >= count:
                msg = f"the code-blocks of level entry {entry} do not tile its bands"
                raise ValueError(msg)  # (a layout the block coder would not make)
            # Per block: magnitudes 0-15 and 16+, then the bit lengths of the 16+.
            bands_of.append((entry, band, grid_cols, np.zeros((count, 18))))
    # Each band in strips of whole rows of blocks (each block's counts made by one call, in
    # the same order as before), the largest strips first: as whole bands, coarse to fine, the
    # three finest (three quarters of the work) came last and left one thread of two idle for
    # up to a third of the pass.
    total = sum(band.size for _, band, _, _ in bands_of)
    tasks = []  # (band, first block row, end block row, values)
    for index, (_, band, _, _) in enumerate(bands_of):
        block_rows = -(-band.shape[0] // block)
        strips = max(1, min(block_rows, round(_STRIPS_PER_PASS * band.size / total)))
        edges = [block_rows * k // strips for k in range(strips + 1)]
        tasks += [
            (index, lo, hi, band.size * (hi - lo) // block_rows)
            for lo, hi in itertools.pairwise(edges)
        ]
    tasks.sort(key=lambda task: -task[3])

    def run(lo: int, hi: int) -> None:
        for index, first, end, _ in tasks[lo:hi]:
            _, band, grid_cols, counts = bands_of[index]
            rows = band[first * block : end * block]
            plane = np.ascontiguousarray(rows, dtype=np.int32)
            plane = plane.reshape(rows.shape[0], rows.shape[1], -1)
            _block_magnitude_counts(
                plane, block, grid_cols, counts[first * grid_cols : end * grid_cols]
            )

    run_rows(run, len(tasks), total, pieces=len(tasks))
    for entry, _, _, counts in bands_of:
        histogram = counts[:, :17]
        sizes = histogram.sum(axis=1, keepdims=True)
        present = histogram > 0
        shares = np.divide(histogram, sizes, out=np.ones_like(histogram), where=present)
        bits = -(histogram * np.log2(shares)).sum(axis=1)
        bits += counts[:, 17] + sizes[:, 0] - histogram[:, 0]  # the large values, the signs
        out[firsts[entry] : firsts[entry + 1]] += bits / 8.0
    return out


@njit(nogil=True, cache=True)
def _estimate_terms(counts, centres, rounding, band, totals, bands, step):  # pragma: no cover
    """The size estimate's terms at ``step``, from the packed histograms (``band`` ascending).

    Each bin's index is ``floor(centre / step + rounding)``.  Per band, in order: the nonzero
    entries of its histogram of the indices up to 255 (weighted by the bins' counts, added in
    the bins' order, as ``np.bincount`` adds them) and their shares of the band's total; the
    counts and indices of the bins beyond 255; the counts of the bins of index 1 or more.
    Each with the end of each band's run (cumulative counts)."""
    size = counts.size
    histogram = np.zeros(bands * 256)
    large_ends = np.zeros(bands, dtype=np.int64)
    sign_ends = np.zeros(bands, dtype=np.int64)
    index_of = np.empty(size)
    for i in range(size):
        index_of[i] = np.floor(centres[i] / step + rounding[i])
    # A band's bins come in ascending order, so runs of them fall into the same cell: each
    # run is added up in a local variable (the same additions in the same order as adding
    # into the cell, without waiting on the cell's store each time).
    cell, total = -1, 0.0
    for i in range(size):
        index = index_of[i]
        here = band[i] * 256 + np.int64(min(index, 255.0))
        if here != cell:
            if cell >= 0:
                histogram[cell] = total
            cell, total = here, histogram[here]
        total += counts[i]
        if index > 255:
            large_ends[band[i]] += 1
        if index >= 1:
            sign_ends[band[i]] += 1
    if cell >= 0:
        histogram[cell] = total
    used_ends = np.zeros(bands, dtype=np.int64)
    for b in range(bands):
        for j in range(256):
            if histogram[b * 256 + j] > 0:
                used_ends[b] += 1
    used_ends = np.cumsum(used_ends)
    large_ends = np.cumsum(large_ends)
    sign_ends = np.cumsum(sign_ends)
    present = np.empty(used_ends[-1] if bands else 0)
    shares = np.empty_like(present)
    k = 0
    for b in range(bands):
        for j in range(256):
            value = histogram[b * 256 + j]
            if value > 0:
                present[k] = value
                shares[k] = value / totals[b]
                k += 1
    large = np.empty(large_ends[-1] if bands else 0)
    indices = np.empty_like(large)
    signs = np.empty(sign_ends[-1] if bands else 0)
    k = m = 0
    for i in range(size):
        if index_of[i] > 255:
            large[k] = counts[i]
            indices[k] = index_of[i]
            k += 1
        if index_of[i] >= 1:
            signs[m] = counts[i]
            m += 1
    return present, shares, used_ends, large, indices, large_ends, signs, sign_ends


@njit(nogil=True, cache=True)
def _pairwise_sum(values, lo, n):  # pragma: no cover - compiled
    """``np.add.reduce(values[lo : lo + n])`` to the bit: NumPy's pairwise summation of
    float64 (eight partial sums over blocks of up to 128 values, halves above that)."""
    if n < 8:
        total = 0.0
        for i in range(lo, lo + n):
            total += values[i]
        return total
    if n <= 128:
        r0, r1, r2, r3 = values[lo], values[lo + 1], values[lo + 2], values[lo + 3]
        r4, r5, r6, r7 = values[lo + 4], values[lo + 5], values[lo + 6], values[lo + 7]
        i = lo + 8
        stop = lo + n - n % 8
        while i < stop:
            r0 += values[i]
            r1 += values[i + 1]
            r2 += values[i + 2]
            r3 += values[i + 3]
            r4 += values[i + 4]
            r5 += values[i + 5]
            r6 += values[i + 6]
            r7 += values[i + 7]
            i += 8
        total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < lo + n:
            total += values[i]
            i += 1
        return total
    half = n // 2
    half -= half % 8
    return _pairwise_sum(values, lo, half) + _pairwise_sum(values, lo + half, n - half)


@njit(nogil=True, cache=True)
def _estimated_bits(entropy, entropy_ends, lengths, length_ends, signs, sign_ends):
    """The size estimate's bits: per band (each array cut at its ``ends``), minus the sum of
    its entropy terms, plus 1.2 × the sum of its bit lengths, plus its signs, in that order,
    band after band (what the Python loop over ``np.add.reduce`` gave, to the bit)."""
    bits = 0.0
    first_e = first_l = first_s = 0
    for band in range(entropy_ends.size):
        last_e, last_l, last_s = entropy_ends[band], length_ends[band], sign_ends[band]
        bits -= _pairwise_sum(entropy, first_e, last_e - first_e)
        bits += 1.2 * _pairwise_sum(lengths, first_l, last_l - first_l)
        bits += _pairwise_sum(signs, first_s, last_s - first_s)
        first_e, first_l, first_s = last_e, last_l, last_s
    return bits


@njit(nogil=True, cache=True)
def _block_magnitude_counts(plane, block, grid_cols, counts):  # pragma: no cover - compiled
    """Per block of ``plane`` (rows, cols, channels): the counts of magnitudes 0-15 and 16+
    (columns 0-16) and the bit lengths of the 16+ (column 17).

    Zeros and ones, most of the values, are counted in local variables over each row's run
    through a block and added once (adding 1.0 to the same cell value after value waited
    on the previous store); the counts are whole numbers, exact in any order, and the bit
    lengths are added in the same order as before."""
    rows, cols, channels = plane.shape
    for r in range(rows):
        base = (r // block) * grid_cols
        for c0 in range(0, cols, block):
            b = base + c0 // block
            zeros = 0
            ones = 0
            for c in range(c0, min(c0 + block, cols)):
                for k in range(channels):
                    v = abs(plane[r, c, k])
                    if v == 0:
                        zeros += 1
                    elif v == 1:
                        ones += 1
                    elif v >= 16:
                        counts[b, 16] += 1.0
                        counts[b, 17] += np.log2(v)
                    else:
                        counts[b, v] += 1.0
            counts[b, 0] += zeros
            counts[b, 1] += ones


def _predicted_bpp(
    encoder: _LossyEncoder, budget: int, enough: int, low: float, high: float
) -> bytes | None:
    """The closed loop's bundle from a predicted step, or None when two of them miss.

    The step comes from the first-order size estimate scaled by a typical ratio of the coder
    (after the closed loop) to it, then by the ratio measured: each try is one closed loop and
    one coding.  (No trimming here: removing details after the least-squares refit, without
    refitting, cost ``bspline2`` 0.6 dB for 2.5 % of the bytes on the camera at 2 bpp.)
    """
    encoder.keep(1.0)
    ratio = _TYPICAL_GREY_RATIO if encoder.plan.colour == "none" else _TYPICAL_COLOUR_RATIO
    ratio *= _TYPICAL_CLOSED_SIZE_RATIO.get(encoder.plan.wavelet, _OTHER_CLOSED_SIZE_RATIO)
    step = encoder.plan.peak / 16.0
    aim = 0.5 * (budget + enough)
    for _ in range(_BPP_PREDICTED_CLOSED_LOOPS):
        model = _Search(
            functools.partial(_times, encoder.size_estimate, ratio),
            aim * 1.004,
            aim * 0.996,
            -1.0,
            low,
            high,
            aim=aim,
        )
        model.run(step, _MODEL_EVALUATIONS)
        found = model.within or model.last
        if found is None:
            return None
        step = found[0]
        size = encoder.size_bound(step)
        if _written_enough(budget, enough) <= size <= budget:
            return encoder.bundle(step)
        ratio = size / encoder.size_estimate(step)
    return None


def _trim_to_budget(
    encoder: _LossyEncoder, step: float, closed: bool, budget: int, enough: int
) -> bytes | None:
    """The coding at ``step``, a little outside ``[enough, budget]``, brought into it by
    changing details of a few code-blocks and coding only those blocks again.

    Above the budget, details of magnitude 1 are removed; below ``enough``, details of the
    dead zone (``|x| >= step / 2``, quantized to 0) are promoted to magnitude 1.  Each
    candidate's cost is the squared error it adds (``2u - 1`` step² units, ``u`` its magnitude
    over its band's step), or saves, per byte it saves, or adds (a share of its block's mean
    bytes per nonzero coefficient, from the coding itself, so the estimate follows the
    coder): the cheapest are changed first, as many as the bytes call for, and the share is
    then corrected by what the coder really wrote.  None (the coding left as it was) if the
    coder is not the block coder, or a few rounds miss.
    """
    qcoeffs, qparams = encoder.quantize(step, closed)
    chunks, cparams = encoder.code(step, closed)
    if not (
        cparams.get("coder") == "context"
        and cparams.get("version") in (4, *PARENT_VERSIONS)
        and cparams.get("two_d") is True
        and isinstance(cparams.get("block"), int)
    ):
        return None
    levels = as_levels(qcoeffs)
    if len(levels) < 2 or any(len(bands) != 3 for bands in levels[1:]):
        return None
    coded = CodedBlocks(
        chunks,
        [[b.shape for b in bands] for bands in levels],
        True,
        cparams["block"],
        cparams["version"],
    )
    original_size = encoder.size_bound(step, closed)
    add = original_size < enough
    target = budget - _TRIM_AIM * (budget - enough)
    share = _TRIM_SAVING_SHARE
    candidates = _trim_candidates(encoder, levels, qparams, coded, add)
    if candidates is None:
        return None
    order, places, saving, values = candidates
    few, many = 0, order.size + 1  # changes known to be too few, and too many
    widest = 0
    for _ in range(_TRIM_ROUNDS):
        count = int(np.searchsorted(saving, abs(original_size - target) / share)) + 1
        if not few < count < many:
            count = (few + many) // 2  # the prediction left the bracket: bisect
        if count <= few or count > order.size:
            break
        widest = max(widest, count)
        trimmed = [[band.copy() for band in bands] for bands in levels]
        for entry, band, flat_index, chosen in places(order[:count]):
            trimmed[entry][band].reshape(-1)[flat_index] = values[chosen]
        # The blocks changed in any round so far: those changed before must be brought back.
        changed = np.unique(places.blocks(order[:widest]))
        coded.recode(trimmed, changed)
        coding_counts.blocks_recoded += int(changed.size)
        encoder.adopt(step, closed, from_levels(qcoeffs, trimmed), coded.chunks(), cparams)
        size = encoder.size_bound(step, closed)
        if enough <= size <= budget:
            return encoder.bundle(step, closed)
        if (size < enough) if add else (size > budget):
            few = count
        else:
            many = count
        if original_size != size:
            share = abs(original_size - size) / saving[count - 1]
    encoder.adopt(step, closed, qcoeffs, chunks, cparams)  # as it was
    return None


class _Places:
    """Where the trim candidates are: ``(entry, band, flat index)`` and block of each."""

    def __init__(
        self, entries: np.ndarray, bands: np.ndarray, flat: np.ndarray, blocks: np.ndarray
    ) -> None:
        self.entries, self.bands, self.flat, self._blocks = entries, bands, flat, blocks

    def __call__(self, chosen: np.ndarray) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Per band: ``(entry, band, flat indices, candidate numbers)`` of ``chosen``."""
        out = []
        entries, bands, flat = self.entries[chosen], self.bands[chosen], self.flat[chosen]
        for entry, band in {(int(e), int(b)) for e, b in zip(entries, bands, strict=True)}:
            mine = (entries == entry) & (bands == band)
            out.append((entry, band, flat[mine], chosen[mine]))
        return out

    def blocks(self, chosen: np.ndarray) -> np.ndarray:
        return self._blocks[chosen]


def _trim_candidates(
    encoder: _LossyEncoder,
    levels: list[list[np.ndarray]],
    qparams: dict[str, Any],
    coded: CodedBlocks,
    add: bool = False,
) -> tuple[np.ndarray, _Places, np.ndarray, np.ndarray] | None:
    """The details to change, cheapest first: their order, places, the cumulative bytes their
    change is expected to save (or, with ``add``, to add; at a share of 1), and each one's new
    value.  Without ``add``, the values of magnitude 1 (made 0); with it, the zeros of the dead
    zone that a ±1 brings closer (from half of where the decoder puts a 1 back on)."""
    block = coded.block
    originals = as_levels(encoder.kept)
    step = float(qparams["step"])
    firsts = np.searchsorted(coded.regions[:, 0], np.arange(len(levels)))
    nonzero = np.zeros(len(coded.regions), dtype=np.float64)
    found: list[tuple[np.ndarray, ...]] = []
    for entry, level_bands in enumerate(levels):
        width = max(band.shape[1] for band in level_bands)
        grid_cols = -(-width // block)
        for index, band in enumerate(level_bands):
            rows, cols = band.shape[0], band.shape[1]
            channels = band.size // max(rows * cols, 1)
            magnitude = np.abs(band.reshape(-1))
            where = np.flatnonzero(magnitude)
            pixel = where // channels
            ids = firsts[entry] + (pixel // cols // block) * grid_cols + (pixel % cols) // block
            nonzero += np.bincount(ids, minlength=nonzero.size)
            if entry == 0:
                continue  # the coarse band stays whole
            band_step = step * float(qparams["weights"][entry][index])
            values = originals[entry][index].reshape(-1)
            if add:
                u = np.abs(values) / band_step
                # Rounded down by the dead zone from half a step over an index on: one more.
                fraction = u - magnitude
                places = np.flatnonzero((fraction >= 0.5) & (fraction < 1.0))
                fraction, larger = fraction[places], magnitude[places] > 0
                pixel = places // channels
                block_ids = (
                    firsts[entry] + (pixel // cols // block) * grid_cols + (pixel % cols) // block
                )
                new = np.where(values[places] < 0, -1, 1) * (magnitude[places] + 1)
                # The decoder puts a 1 back at ``r = 1 + offset`` (below 1 + rounding, often
                # ~1.1), not at 1: a zero at ``u`` made 1 saves ``u² - (r - u)² = r (2u - r)``
                # step² units, nothing below ``u = r / 2`` (counted as saving ``2u - 1``, the
                # fill promoted details that added error: camera at 2 bpp lost 0.32 dB against
                # main at equal bytes, 0.15 dB now).
                rounding = float(qparams["rounding"])
                back = 1.0 + reconstruction_offset(band, rounding)
                saved = back * (2.0 * (fraction + magnitude[places]) - back)
                # The inverse of the error saved, over how many times a new nonzero's bytes an
                # index one larger costs (a nonzero's zero flag and sign are paid already).
                cost = 1.0 / np.maximum(saved, 1e-3)
                weight = np.where(larger, _LARGER_INDEX_SHARE, 1.0)
                # (larger indices measured worse: +0.4 dB lost at 2 bpp)
                keep = ~larger & (saved > 0.0)
                places, block_ids, new, cost, weight = (
                    a[keep] for a in (places, block_ids, new, cost, weight)
                )
            else:
                ones = magnitude[where] == 1
                places, block_ids = where[ones], ids[ones]
                u = np.abs(values[places]) / band_step
                new = np.zeros(places.size, dtype=np.int64)
                cost = np.maximum(2.0 * u - 1.0, 0.05)  # error added
                weight = np.ones(places.size)
            found.append(
                (
                    np.full(places.size, entry),
                    np.full(places.size, index),
                    places,
                    block_ids,
                    cost,
                    new,
                    weight,
                )
            )
    if not found:
        return None
    entries, bands, flat, blocks, cost, new, weight = (
        np.concatenate(parts) for parts in zip(*found, strict=True)
    )
    if entries.size == 0:
        return None
    per_coefficient = coded.lengths() / np.maximum(nonzero, 1.0)  # bytes per nonzero, per block
    saves = np.maximum(per_coefficient[blocks] * weight, 1e-9)
    # Removals: least error added per byte saved first; additions: most error saved per byte
    # added (``cost`` is then the inverse of the error saved).
    order = np.argsort(cost * saves if add else cost / saves, kind="stable")
    return order, _Places(entries, bands, flat, blocks), np.cumsum(saves[order]), new


def _fit_budget(
    encoder: _LossyEncoder,
    size: Callable[[float], float],
    budget: int,
    enough: int,
    aim: float,
    low: float,
    high: float,
    start: float | None,
    ratio: float | _RatioModel = _TYPICAL_CODED_RATIO,
    tight: bool = False,
) -> float | None:
    """The step (and ``encoder``'s kept fraction) whose ``size`` is closest below ``budget``,
    from ``enough`` on when it can; None when even the coarsest step is too big.

    The cheap model (first-order entropy) over-estimates what the context coder writes, by a
    factor that depends on the picture: it is scaled by the latest measured ratio (a typical
    one to begin with) and solved for the next step to code, until the real sizes bracket the
    budget; then the real sizes alone are interpolated.  Both aim at ``aim``.
    """

    def scaled_model_step(step: float, value: float | None) -> float:
        nonlocal ratio
        if value is not None:
            if isinstance(ratio, _RatioModel):
                ratio.correct(step, value / encoder.size_estimate(step))
            else:
                ratio = value / encoder.size_estimate(step)
        # The model only points the way, so a looser window will do for it, unless ``tight``
        # (a ratio measured on a sample is good to a per cent: its step is worth placing).
        high_end, low_end = (
            (aim * 1.004, aim * 0.996)
            if tight
            else (max(budget, aim * 1.004), min(0.985 * budget, aim * 0.996))
        )
        model = _Search(
            _ratio_model_size(encoder, ratio)
            if isinstance(ratio, _RatioModel)
            else functools.partial(_times, encoder.size_estimate, ratio),
            high_end,
            low_end,
            -1.0,
            low,
            high,
            aim=aim,
        )
        model.run(step, _MODEL_EVALUATIONS)
        return (model.within or model.last or (high, 0.0))[0]

    real = _Search(size, budget, enough, -1.0, low, high, guide=scaled_model_step, aim=aim)
    real.run(
        start if start is not None else scaled_model_step(encoder.plan.peak / 16.0, None),
        _BPP_EVALUATIONS,
    )
    if real.within is None:
        real.evaluate(high)
        if real.within is None:
            return None
        real.run(real.next_step() or high, _BPP_EVALUATIONS)
    fits = (real.within[0], int(real.within[1])) if real.within is not None else (high, 0)
    if fits[1] < enough and real.beyond is not None:
        # The size jumps between two neighbouring steps (many coefficients cross a bin edge
        # together, e.g. on pixel-repeated images): take the finer step and drop its least
        # important details, which lowers the size smoothly, until the bundle fits.
        fits = _fill_by_removal(encoder, size, real.beyond[0], fits, budget, enough)
    return fits[0]


def _fill_by_removal(
    encoder: _LossyEncoder,
    size_at: Callable[[float], float],
    step: float,
    fits: tuple[float, int],
    budget: int,
    enough: int,
) -> tuple[float, int]:
    best_removed: float | None = None
    few, many = 0.0, 1.0  # fractions of details removed: too big, small enough
    for _ in range(_SEARCH_STEPS):
        removed = (few + many) / 2
        encoder.keep(1.0 - removed)
        size = size_at(step)
        if size <= budget:
            many = removed
            if size > fits[1]:
                fits, best_removed = (step, int(size)), removed
            if size >= enough:
                break
        else:
            few = removed
    encoder.keep(1.0 - (best_removed if best_removed is not None else 0.0))
    return fits


#: The front ends' entry point (wavecore.codec.encode), under a public name.
encode_lossy = _encode_lossy
