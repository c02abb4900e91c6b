"""Issue 10's slow decoder fuzz: 20 000 mutants of every kind of bundle, bounds checked.

``tests/fuzz_decoder.py`` runs in a subprocess, because numba reads ``NUMBA_BOUNDSCHECK`` when
it is imported, and with its own empty numba cache, because a kernel cached without the flag
would be loaded unchecked.  Every mutant must decode to an array or raise ``BundleError`` (or
``InvalidParameter`` for a level deeper than the crafted bundle has), and no compiled kernel may
index out of bounds.  The fast default run has ``test_bundle_fuzz.py`` and
``test_bundle_headers.py``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

FUZZ = Path(__file__).with_name("fuzz_decoder.py")
CASES = 20_000


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_twenty_thousand_mutants_with_numba_boundscheck(tmp_path: Path) -> None:
    env = {
        **os.environ,
        "NUMBA_BOUNDSCHECK": "1",
        "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"),
    }
    done = subprocess.run(
        [sys.executable, str(FUZZ), "--cases", str(CASES), "--seed", "0"],
        env=env,
        capture_output=True,
        text=True,
        timeout=1700,
        check=False,
    )
    assert done.stdout.strip(), done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["boundscheck"] is True, "numba did not take NUMBA_BOUNDSCHECK=1"
    assert report["cases"] == CASES and report["bundles"] >= 28
    assert report["failures"] == 0, report["first_failures"]
    assert done.returncode == 0, done.stderr[-3000:]
    outcomes = report["outcomes"]
    # The mutants reach every stage: some decode, most are refused.
    assert outcomes.get("array", 0) > 100 and outcomes.get("BundleError", 0) > CASES // 4
