"""wavecore._heap: freed working memory stays mapped between codings on glibc, and the user's
own tuning of glibc's allocator is left alone."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

GLIBC = platform.libc_ver()[0] == "glibc"

FAULTS = """
import resource
from skimage import data
import wavecore
image = data.camera()
wavecore.decode(wavecore.encode_image(image))
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(8):
    wavecore.decode(wavecore.encode_image(image))
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 8)
"""


def _run(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    clean.pop("GLIBC_TUNABLES", None)
    result = subprocess.run(
        [sys.executable, "-c", code],
        env={**clean, **env},
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    )
    return result.stdout.strip()


@pytest.mark.skipif(not GLIBC, reason="the settings are glibc's mallopt")
def test_the_settings_are_made_on_glibc_unless_the_environment_tunes_malloc() -> None:
    code = "from wavecore import _heap; print(_heap.keep_freed_memory())"
    assert _run(code) == "True"
    assert _run(code, MALLOC_ARENA_MAX="2") == "False"  # as Dask's workers are started
    assert _run(code, GLIBC_TUNABLES="glibc.malloc.top_pad=0") == "False"


@pytest.mark.skipif(not GLIBC, reason="page faults of glibc's heap")
def test_repeated_codings_do_not_fault_their_arrays_in_again() -> None:
    """With glibc's defaults each encode + decode of the 512² camera on one thread faulted
    some 1 200 pages in afresh (its working arrays, freed by the one before); kept mapped,
    about a hundred."""
    pytest.importorskip("skimage.data", reason="scikit-image (the figures extra) has the camera")
    one = {"WAVECORE_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    tuned = float(_run(FAULTS, **one))
    untuned = float(_run(FAULTS, MALLOC_ARENA_MAX="8", **one))  # glibc's own settings
    assert tuned < 400 < untuned


BIG_FAULTS = """
import resource
import numpy as np
import wavecore
# 2 100 x 2 100: each float plane is 35 MB, above the largest mmap threshold glibc adapts to.
image = np.random.default_rng(0).integers(0, 256, (2100, 2100), dtype=np.uint8)
# Warm up to the peak: the bpp search's work (its samples, RDOQ's passes when on) varies from
# one coding to the next, and after one coding the heap has not always grown to its largest.
for _ in range(3):
    wavecore.decode(wavecore.encode_image(image, bpp=0.5))
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(2):
    wavecore.decode(wavecore.encode_image(image, bpp=0.5))
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 2)
"""


@pytest.mark.skipif(not GLIBC, reason="page faults of glibc's heap")
def test_arrays_above_the_mmap_threshold_are_not_faulted_in_again() -> None:
    """Arrays of more than 32 MiB were mapped afresh by every coding whatever the threshold
    (a 2048² RGB encode faulted some 2 700 pages); from the heap, they are reused."""
    one = {"WAVECORE_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    tuned = float(_run(BIG_FAULTS, **one))
    # the previous settings: a pad and the largest threshold, mappings still allowed
    mapped = float(
        _run(BIG_FAULTS, MALLOC_TOP_PAD_="16777216", MALLOC_MMAP_THRESHOLD_="33554432", **one)
    )
    assert tuned * 3 < mapped  # measured: 7-130 against 1 200 faults a coding
