"""The library's parallel regions (wavecore.transform.run_calls / run_slices): every call runs
once, errors reach the caller, nested regions finish, and slices cover each item exactly."""

from __future__ import annotations

import threading

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
