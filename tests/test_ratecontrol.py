"""Rate control codes few times: the closed loop once where the target is predicted, plus at
most one correction, and the final result is entropy-coded once per closed loop.

The counts come from wrapping the coder and the quantizer where the rate control looks them up
(``wavecore.codec.ratecontrol``), so they count what really runs.  The targets' accuracy is
asserted alongside (97.5-100 % of the bpp budget, the quality within 0.05 dB above the target,
the tolerance met), since a search that codes less must not land less well.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from wavecore import decode, encode_curve, encode_image, encode_surface, rdoq
from wavecore.blockcoder import CodedBlocks
from wavecore.codec import ratecontrol


@dataclass
class Calls:
    """What one encode ran: open- and closed-loop quantizations, and entropy codings split by
    whether they coded a closed-loop result (a candidate for the bundle) or an open-loop trial."""

    open_loops: int = 0
    closed_loops: int = 0
    trial_codings: int = 0
    final_codings: int = 0
    closed_results: list[int] = field(default_factory=list)
    blocks_recoded: int = 0  # by the bpp search's trims (CodedBlocks.recode)
    warm_loops: int = 0  # closed loops started from an earlier one's fit (counted in both)
    fit_quantizations: int = 0  # quantizations from a closed loop's fit at another step
    syntheses: int = 0  # reconstructions to measure an error (each a verification)


@pytest.fixture
def calls(monkeypatch: pytest.MonkeyPatch) -> Iterator[Calls]:
    seen = Calls()
    quantize, code = ratecontrol.quantize_bands, ratecontrol.encode_levels

    def counted_quantize(*args: Any, **kwargs: Any) -> Any:
        q, params = quantize(*args, **kwargs)
        if kwargs.get("refine") == 0:
            seen.open_loops += 1
        else:
            seen.closed_loops += 1
            seen.closed_results.append(id(q))
        return q, params

    def counted_code(q: Any, **kwargs: Any) -> Any:
        if id(q) in seen.closed_results:
            seen.final_codings += 1
        else:
            seen.trial_codings += 1
        return code(q, **kwargs)

    recode = CodedBlocks.recode

    def counted_recode(self: CodedBlocks, entries: Any, indices: Any) -> None:
        seen.blocks_recoded += len(indices)
        recode(self, entries, indices)

    class CountedFit(ratecontrol.ClosedLoopFit):  # type: ignore[misc]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            seen.closed_loops += 1
            seen.warm_loops += kwargs.get("start") is not None

        def quantize(self, step: float) -> Any:
            q, params = super().quantize(step)
            seen.fit_quantizations += step != self.step
            seen.closed_results.append(id(q))
            return q, params

    reconstruct = ratecontrol.reconstruct_finished

    def counted_reconstruct(*args: Any, **kwargs: Any) -> Any:
        seen.syntheses += 1
        return reconstruct(*args, **kwargs)

    monkeypatch.setattr(ratecontrol, "quantize_bands", counted_quantize)
    monkeypatch.setattr(ratecontrol, "ClosedLoopFit", CountedFit)
    monkeypatch.setattr(ratecontrol, "reconstruct_finished", counted_reconstruct)
    monkeypatch.setattr(ratecontrol, "encode_levels", counted_code)
    monkeypatch.setattr(CodedBlocks, "recode", counted_recode)
    yield seen


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(float) - b.astype(float)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(255.0**2 / mse)


def sawtooth(size: int) -> np.ndarray:
    """Sharp ramps in three channels: the request of ``benchmarks/first_run.py --serve``, whose
    size jumps with the step (the bpp search used to run six closed loops on it)."""
    y, x = np.mgrid[:size, :size]
    return np.stack([x % 256, y % 256, (x + y) % 256], -1).astype(np.uint8)


def scikit_image(name: str) -> np.ndarray:
    data = pytest.importorskip(
        "skimage.data", reason="the photographs come from scikit-image (the test extra)"
    )
    image = np.asarray(getattr(data, name)())
    return image[::2, ::2] if name == "astronaut" else image  # 256 × 256 RGB


@pytest.mark.parametrize(
    ("picture", "wavelet", "bpp"),
    [
        ("camera", "cdf97", 1.0),
        ("coins", "cdf97", 0.5),
        ("astronaut", "cdf97", 2.0),
        ("camera", "bspline2", 1.0),
        ("coins", "bspline2", 2.0),
        ("astronaut", "bspline2", 0.5),
    ],
)
def test_bpp_runs_the_closed_loop_at_most_twice_and_codes_it_once_each(
    calls: Calls, picture: str, wavelet: str, bpp: float
) -> None:
    image = scikit_image(picture)
    bundle = encode_image(image, wavelet=wavelet, bpp=bpp)
    actual = 8 * len(bundle) / (image.shape[0] * image.shape[1])
    assert 0.975 * bpp <= actual <= bpp
    if wavelet == "cdf97":  # no closed loop: it does not pay for this nearly orthogonal one
        assert calls.closed_loops == 0
        assert calls.trial_codings == 1  # (other open loops quantize a sample of blocks)
    else:
        # Before, every trial was a closed loop (2 to 4 on these pictures, 6 on the sawtooth).
        assert 1 <= calls.closed_loops <= 2
        assert calls.final_codings == calls.closed_loops  # each closed loop coded exactly once
    # The trials are open-loop quantizations, each coded at most once (a handful suffice).
    assert calls.trial_codings <= calls.open_loops <= 12


def test_bpp_runs_one_closed_loop_on_the_first_run_picture(calls: Calls) -> None:
    image = sawtooth(512)
    bundle = encode_image(image, bpp=1.0)
    assert 0.975 <= 8 * len(bundle) / image.shape[0] ** 2 <= 1.0
    assert (calls.closed_loops, calls.final_codings) == (0, 0)  # cdf97: in open loop


@pytest.mark.parametrize(
    ("picture", "wavelet", "target"),
    [
        ("camera", "cdf97", 40.0),
        ("coins", "cdf97", 32.0),
        ("astronaut", "cdf97", 45.0),
        ("camera", "bspline2", 40.0),
        ("coins", "bspline2", 40.0),
    ],
)
def test_quality_codes_once_with_at_most_two_closed_loops(
    calls: Calls, picture: str, wavelet: str, target: float
) -> None:
    image = scikit_image(picture)
    bundle = encode_image(image, wavelet=wavelet, quality=target)
    assert target <= psnr(decode(bundle), image) <= target + 0.05
    if wavelet == "cdf97":
        # Open loop only, verified by at most four quantizations (the prediction from the
        # coefficients, and corrections with the ratio measured), a synthesis each.
        # (RDOQ's error moves less smoothly with the step: up to two more where it runs.)
        most = 4 + (ratecontrol._QUALITY_RDOQ_VERIFIES if rdoq.ENABLED else 0)
        assert calls.closed_loops == 0 and 1 <= calls.open_loops <= most
        assert calls.syntheses == calls.open_loops
        assert calls.trial_codings == 1 and calls.final_codings == 0
    else:
        # One closed loop from scratch, at the step one synthesis in open loop calibrated;
        # a miss costs a quantization from its fit or a closed loop started from it (about
        # half the cost).  Before, two closed loops from scratch.
        assert calls.closed_loops - calls.warm_loops == 1 and calls.warm_loops <= 1
        assert calls.open_loops == 1  # the calibration (ClosedLoopFit's own are not counted)
        assert calls.syntheses == 1 + calls.closed_loops + calls.fit_quantizations <= 5
        assert calls.final_codings == 1 and calls.trial_codings == 0


def test_surfaces_quality_codes_once(calls: Calls) -> None:
    # Small smooth grids have errors that jump with the step, so the closed loop may run more
    # often there (as before); the bundle is still coded once.
    y, x = np.mgrid[0:1:65j, 0:1:65j]
    grid = np.sin(5 * x) * np.cos(3 * y) + 0.3 * x * y
    encode_surface(grid, quality=45.0)
    assert calls.closed_loops >= 1
    assert calls.final_codings == 1 and calls.trial_codings == 0


@pytest.mark.parametrize("closed", [True, False])
def test_tolerance_bisects_in_open_loop_and_codes_once(calls: Calls, closed: bool) -> None:
    t = np.linspace(0, 2 * np.pi, 3000, endpoint=not closed)
    points = np.stack([np.cos(t) + 0.1 * np.cos(7 * t), np.sin(t) + 0.05 * np.sin(13 * t)], -1)
    tolerance = 2e-3
    bundle = encode_curve(points, closed=closed, tolerance=tolerance)
    assert np.max(np.linalg.norm(decode(bundle) - points, axis=1)) <= tolerance
    # One closed loop at the open loop's step, then a bounded bisection upwards (it used to
    # be one closed loop per bisection step, about 20).
    assert 1 <= calls.closed_loops <= 5
    assert calls.final_codings + calls.trial_codings == 1


def test_keep_runs_one_closed_loop_and_one_coding(calls: Calls) -> None:
    encode_image(sawtooth(128), keep=0.2, wavelet="bspline2")
    assert (calls.closed_loops, calls.final_codings, calls.trial_codings) == (1, 1, 0)
    calls.closed_loops = calls.final_codings = 0
    encode_image(sawtooth(128), keep=0.2)  # cdf97: in open loop
    assert (calls.closed_loops, calls.open_loops, calls.final_codings) == (0, 1, 0)


def generated(name: str) -> np.ndarray:
    """Pictures of known character: a smooth ramp with seeded noise, and seeded texture."""
    rng = np.random.default_rng(7)
    y, x = np.mgrid[:384, :320]
    if name == "ramp":
        return np.clip(0.4 * x + 0.3 * y + rng.normal(0, 3, x.shape), 0, 255).astype(np.uint8)
    smooth = 128 + 60 * np.sin(x / 9.0) * np.cos(y / 13.0)
    return np.clip(smooth + rng.normal(0, 12, x.shape), 0, 255).astype(np.uint8)


def picture(name: str) -> np.ndarray:
    if name == "sawtooth":
        return sawtooth(512)
    if name in ("ramp", "texture"):
        return generated(name)
    return scikit_image(name)


#: One coding's blocks at 512² grey (4 + 5 levels' single blocks): the trims' unit of cost.
_BLOCKS_512 = 9


@pytest.mark.parametrize(
    "name", ["camera", "coins", "moon", "brick", "astronaut", "ramp", "texture"]
)
@pytest.mark.parametrize("bpp", [0.25, 0.5, 1.0, 2.0])
def test_bpp_in_open_loop_is_coded_once(calls: Calls, name: str, bpp: float) -> None:
    image = picture(name)
    if name == "moon":  # a 2× enlargement, coded as its source at 4× the rate: keep it 512²
        image = image.copy()
        image[0, 1] ^= 1
    ratecontrol.coding_counts.reset()
    bundle = encode_image(image, wavelet="cdf97", bpp=bpp)  # open loop
    pixels = image.shape[0] * image.shape[1]
    assert 0.975 * bpp <= 8 * len(bundle) / pixels <= bpp
    # One full coding, predicted from a sample of the blocks where the levels have several;
    # it lands in the window or near it, and then a few blocks get details removed or added
    # and are coded again (before, two or three full codings on these pictures).
    assert calls.closed_loops == 0
    # Context coder version 6 without RDOQ: camera at 2 bpp lands 2 % under the budget, and
    # the trim's six rounds of added details end 18 bytes short of the window (a new detail
    # also changes the contexts of its children, which the trim does not predict): a second
    # coding.  With RDOQ (on by default), whose two samples aim at the middle of the window,
    # the noisy ramp at 0.25 bpp lands at 125 %, then 83 %, then 104 % of its budget, which
    # the trim brings in; the astronaut at 0.25 bpp lands at 84 %, then 105 %, trimmed to
    # 97.6 % as written (a trimmed bundle ends the search even where its written size is
    # under the stop that size bounds need: it went on for 33 codings before).  With context
    # coder version 8 the ramp needs one coding less (two).
    extra = {("ramp", 0.25): 2, ("astronaut", 0.25): 2} if rdoq.ENABLED else {("camera", 2.0): 2}
    codings = extra.get((name, bpp), 1)
    assert calls.trial_codings == codings
    assert ratecontrol.coding_counts.full_codings == codings
    # (Six rounds of recoded blocks and their children, in the case of two codings.  With
    # context coder version 7 and RDOQ's parent-aware table, the coins at 0.25 bpp take a
    # third round of the trim: 21 blocks recoded of its 9.)
    rounds = 8 if codings > 1 else 3 if (name, bpp) == ("coins", 0.25) else 2
    assert ratecontrol.coding_counts.blocks_recoded <= rounds * _BLOCKS_512


def test_a_budget_past_exact_coding_does_not_crawl() -> None:
    # moon's 256² source (what its 2× enlargement codes, at 4× the rate) is coded exactly from
    # about 6 bpp on, where the size hardly moves with the step; the guided search, aiming 3 %
    # over the budget for a trim that cannot help there, crept up on it in steps of a few
    # hundredths of a per cent: 28 codings, 1.6 s.
    image = scikit_image("moon")[::2, ::2]
    ratecontrol.coding_counts.reset()
    bundle = encode_image(image, wavelet="cdf97", bpp=8.0)
    assert 0.975 * 8.0 <= 8 * len(bundle) / image.size <= 8.0
    assert ratecontrol.coding_counts.full_codings <= 8


def test_bpp_on_the_sawtooth_codes_fewer_times(calls: Calls) -> None:
    image = sawtooth(512)
    bundle = encode_image(image, bpp=1.0)
    assert 0.975 <= 8 * len(bundle) / image.shape[0] ** 2 <= 1.0
    # Its size jumps with the step: the search used to code it seven times, with a removal of
    # details at the end; the trim of a coding just above the budget saves some of them.  (The
    # sample of blocks predicts it badly, its blocks differ too much: one more than the four
    # of the search without a sample.)
    assert calls.trial_codings <= 5


@pytest.mark.parametrize(
    "name", ["camera", "coins", "moon", "brick", "astronaut", "ramp", "texture"]
)
@pytest.mark.parametrize("target", [33.0, 42.0])
def test_quality_is_predicted_and_coded_once(calls: Calls, name: str, target: float) -> None:
    image = picture(name)
    bundle = encode_image(image, wavelet="cdf97", quality=target)
    assert target <= psnr(decode(bundle), image) <= target + 0.05
    assert calls.trial_codings + calls.final_codings == 1
    if rdoq.ENABLED and (name, target) == ("moon", 33.0):
        # Since RDOQ's table reads the parent band (6 Dec), RDOQ's error on the moon at 33 dB
        # jumps past the target at every verification, and the search falls back to one
        # closed loop after 20 open ones (the other 89 of 90 quality searches on 15 pictures
        # at 30-45 dB need at most 8 quantizations): a known weak spot of the quality search,
        # held to where it is.
        assert calls.closed_loops <= 1 and calls.open_loops <= 20
    elif name not in ("ramp", "texture"):
        # Photographs: predicted from the coefficients, verified by a few open loops.  (On
        # the noisy ramp at 33 dB whole bands empty at once and the open loop's error jumps
        # with the step; the closed-loop search is the fallback there.)
        # (RDOQ's error moves less smoothly with the step: up to two more where it runs.)
        most = 4 + (ratecontrol._QUALITY_RDOQ_VERIFIES if rdoq.ENABLED else 0)
        assert calls.closed_loops == 0 and 1 <= calls.open_loops <= most


@pytest.mark.parametrize("wavelet", ["cdf97", "bspline2"])
@pytest.mark.parametrize("shape", [(16384, 1), (4096, 2), (128, 128, 3)])
def test_a_quality_every_step_meets_stops_at_the_largest_step(
    calls: Calls, wavelet: str, shape: tuple[int, ...]
) -> None:
    # A faint picture (noise of amplitude 4) at the default 40 dB: even the coarsest quantizer
    # meets the target, so no step has an error just under the bound, which the searches
    # looked for.  They ran to their limits: some 1,400 syntheses, 10 s for the 16,384 × 1
    # column (32 s at 65,536 × 1).  Now a missed prediction checks the largest step first.
    image = np.random.default_rng(5).integers(0, 5, shape).astype(np.uint8)
    bundle = encode_image(image, wavelet=wavelet)
    assert psnr(decode(bundle), image) >= 40.0
    assert calls.open_loops + calls.closed_loops <= 12
    assert calls.syntheses <= 12


@pytest.mark.parametrize("target", [32.0, 42.0])
def test_quality_of_the_sawtooth_is_met(target: float) -> None:
    # (At 45 dB its error jumps over the window at every step tried, as it did before; with
    # its per-picture colour matrix it does at 40 dB too: 40.54 dB in 711 bytes, where YCbCr
    # took 1202 bytes for 40.03 dB.)
    image = sawtooth(256)
    assert target <= psnr(decode(encode_image(image, quality=target)), image) <= target + 0.05


def test_trimmed_bundles_decode_to_what_the_header_says(calls: Calls) -> None:
    # Sizes that land just above the budget are trimmed: the header's PSNR must be the
    # trimmed picture's, measured, not the untrimmed one's (the header keeps 3 decimals).
    from wavecore import inspect

    for bpp in (0.7, 1.1, 1.6):
        image = scikit_image("camera")
        bundle = encode_image(image, bpp=bpp)
        decoded = decode(bundle)
        assert inspect(bundle)["psnr"] == pytest.approx(psnr(decoded, image), abs=6e-4)
        # Format 3.0 stores each band's counts for region decodes: a trim must update them.
        window = (slice(100, 300), slice(250, 420))
        assert np.array_equal(decode(bundle, region=window), decoded[window])
    assert calls.blocks_recoded > 0  # at least one of them was trimmed


def test_a_large_picture_is_coded_once(calls: Calls) -> None:
    # 1024² RGB: 30 code-blocks, enough to calibrate the prediction on a sample of them
    # (the coarse levels whole, a few fine blocks) before the one full coding; before, the
    # first full coding only calibrated the second.
    rng = np.random.default_rng(11)
    y, x = np.mgrid[:1024, :1024]
    waves = [np.sin(x / (17.0 + 5 * c)) * np.cos(y / (23.0 - 3 * c)) for c in range(3)]
    edges = 40.0 * ((x // 96 + y // 80) % 2)
    image = np.stack([60 * w + edges for w in waves], -1) + 128 + rng.normal(0, 6, (1024, 1024, 3))
    image = np.clip(image, 0, 255).astype(np.uint8)
    bundle = encode_image(image, bpp=1.0)
    assert 0.975 <= 8 * len(bundle) / 1024**2 <= 1.0
    assert calls.trial_codings == 1 and calls.closed_loops == 0


@pytest.mark.parametrize(("picture", "bpp"), [("moon", 1.0), ("coins", 0.25)])
def test_the_written_bundle_keeps_97_5_percent_when_its_header_is_shorter_than_the_bound(
    picture: str, bpp: float
) -> None:
    # The search compares size bounds whose placeholder psnr and max_error take up to
    # _PLACEHOLDER_EXCESS bytes more than the real ones: moon at 1 bpp stopped at a bound of
    # 97.5 % and was written 4 bytes short of it (97.49 %).
    image = scikit_image(picture)
    bundle = encode_image(image, wavelet="bspline2", bpp=bpp)
    budget = math.floor(bpp * image.shape[0] * image.shape[1] / 8)
    assert math.ceil(0.975 * budget) <= len(bundle) <= budget
