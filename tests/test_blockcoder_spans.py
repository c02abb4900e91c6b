"""How the code-blocks are grouped into tasks for the thread pool changes no byte."""

from __future__ import annotations

import numpy as np
import pytest

from wavecore import blockcoder


def _entries(seed: int) -> list[list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    levels = [[rng.integers(-300, 300, (20, 18, 3)).astype(np.int32)]]
    for rows, cols in ((20, 18), (40, 36), (80, 72)):
        bands = rng.laplace(0, 3, (3, rows, cols, 3)).round().astype(np.int32)
        levels.append(list(bands))
    return levels


@pytest.mark.parametrize("threads", ["1", "2"])
def test_one_span_or_many_give_the_same_bytes(
    threads: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    entries = _entries(4)
    layout = [[band.shape for band in bands] for bands in entries]
    monkeypatch.setenv("WAVECORE_THREADS", threads)
    results = []
    for least in (1, 10**9):  # every run of blocks its own task; one task for all
        monkeypatch.setattr(blockcoder, "_SPAN_MIN_VALUES", least)
        chunks = blockcoder.encode_blocks(entries, True, 16)
        decoded = blockcoder.decode_blocks(chunks, layout, True, 16)
        for bands, originals in zip(decoded, entries, strict=True):
            assert all(np.array_equal(a, b) for a, b in zip(bands, originals, strict=True))
        results.append(chunks)
    assert results[0] == results[1]


def test_small_jobs_stay_on_one_task_and_large_ones_are_split() -> None:
    assert blockcoder._span_count(0) == 1
    assert blockcoder._span_count(blockcoder._SPAN_MIN_VALUES - 1) == 1
    assert blockcoder._span_count(512 * 512) > 2  # a 512 × 512 grey picture is split
    assert blockcoder._span_count(10**9) == blockcoder._SPANS
