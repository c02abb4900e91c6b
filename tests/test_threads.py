"""The library's parallel regions (wavecore.transform.run_calls / run_slices): every call runs
once, errors reach the caller, nested regions finish, and slices cover each item exactly."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from wavecore.transform import run_calls, run_slices


@pytest.fixture(params=["1", "2", "3"])
def threads(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> int:
    monkeypatch.setenv("WAVECORE_THREADS", request.param)
    return int(request.param)


def test_every_call_runs_once(threads: int) -> None:
    hits = np.zeros(97, dtype=np.int64)
    lock = threading.Lock()

    def hit(k: int) -> None:
        with lock:
            hits[k] += 1

    run_calls([lambda k=k: hit(k) for k in range(hits.size)])
    assert (hits == 1).all()


def test_the_first_error_reaches_the_caller_and_later_regions_still_run(threads: int) -> None:
    def fail() -> None:
        raise ValueError("boom")

    with pytest.raises(ValueError, match="boom"):
        run_calls([lambda: None, fail, lambda: None])
    done: list[int] = []
    run_calls([lambda: done.append(1), lambda: done.append(2)])
    assert sorted(done) == [1, 2]


def test_nested_regions_finish(threads: int) -> None:
    # Each call splits its own work again; with a pool that only waited on its queue, calls
    # blocked on inner regions could hold every thread.
    totals = np.zeros(8, dtype=np.int64)

    def outer(k: int) -> None:
        parts = np.zeros(5, dtype=np.int64)

        def inner(j: int) -> None:
            parts[j] = k * 10 + j

        run_calls([lambda j=j: inner(j) for j in range(parts.size)])
        totals[k] = parts.sum()

    run_calls([lambda k=k: outer(k) for k in range(totals.size)])
    assert totals.tolist() == [sum(k * 10 + j for j in range(5)) for k in range(8)]


@pytest.mark.parametrize("sizes", [[0, 5, 1 << 20, 3, 70_001], [1 << 16] * 3, [], [0]])
def test_slices_cover_every_element_once(threads: int, sizes: list[int]) -> None:
    seen = [np.zeros(size, dtype=np.int64) for size in sizes]
    lock = threading.Lock()

    def mark(item: int, lo: int, hi: int) -> None:
        assert 0 <= lo < hi <= sizes[item]
        with lock:
            seen[item][lo:hi] += 1

    run_slices(sizes, mark)
    assert all((marks == 1).all() for marks in seen)


def test_threaded_passes_give_the_same_bits_as_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """The passes that run in threads from 2^17 elements (a 512² picture's finest 2-D level
    both ways, the last level straight into integers, the open loop's prediction over its small
    bands) give exactly the values of one thread: the rate control's steps depend on them."""
    from skimage import data

    import wavecore.quantize
    import wavecore.transform
    from wavecore import wavedec2, waverec2
    from wavecore.filters import get_wavelet
    from wavecore.quantize import OpenLoopDistortion
    from wavecore.transform import synthesis_2d_integers

    regions: list[int] = []

    def counted(calls: list[Any]) -> None:
        regions.append(len(calls))
        run_calls(calls)

    monkeypatch.setattr(wavecore.transform, "run_calls", counted)
    monkeypatch.setattr(wavecore.quantize, "run_calls", counted)
    image = data.camera().astype(np.float64)
    results = {}
    for count in ("1", "2"):
        monkeypatch.setenv("WAVECORE_THREADS", count)
        regions.clear()
        coeffs = wavedec2(image, "cdf97", level=4)
        predict = OpenLoopDistortion(coeffs, wavelet="cdf97", boundary="open")
        coarse = waverec2(coeffs[:-1], "cdf97")
        cH, cV, cD = coeffs[-1]
        integers = synthesis_2d_integers(
            (coarse, cV, cH, cD),
            get_wavelet("cdf97"),
            ("open", "open"),
            ((0, 512), (0, 512)),
            np.dtype(np.uint8),
            None,
        )
        assert integers is not None
        results[count] = (
            [np.asarray(b) for b in (coeffs[0], *coeffs[-1])],
            waverec2(coeffs, "cdf97"),
            integers,
            [predict(step) for step in (0.5, 3.0, 17.0)],
        )
        # The predictions always hand their bands to run_calls (which runs them in order on
        # one thread); with two, the analysis and both finest syntheses run in regions too.
        assert len(regions) == (3 if count == "1" else 3 + 1 + 1 + 1), regions
    one, two = results["1"], results["2"]
    for a, b in zip(one[0], two[0], strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(one[1], two[1])
    assert np.array_equal(one[2], two[2])
    assert one[3] == two[3]
    assert np.abs(one[1] - image).max() < 1e-6  # and it is the transform, not a stand-in


def test_a_colour_pictures_predicted_error_is_the_same_on_any_thread_count(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Bands with a channel axis (a colour picture's) are summed in slices of their own: the
    float sums must not follow the thread count, or the quality search could pick another step
    (and write other bytes) on another machine."""
    from wavecore import wavedec2
    from wavecore.quantize import OpenLoopDistortion

    rng = np.random.default_rng(3)
    picture = rng.normal(128.0, 40.0, (1104, 1000, 3))  # finest bands of 828 000 values
    predictions = {}
    for count in ("1", "2", "3"):
        monkeypatch.setenv("WAVECORE_THREADS", count)
        coeffs = wavedec2(picture, "cdf97", level=3)
        predict = OpenLoopDistortion(
            coeffs, wavelet="cdf97", boundary="open", channel_gains=(0.6, 0.3, 0.1)
        )
        predictions[count] = [predict(step).hex() for step in (0.7, 4.0, 23.0)]
    assert predictions["1"] == predictions["2"] == predictions["3"]
