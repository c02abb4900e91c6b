"""``python -m wavecore.warmup`` compiles every kernel that the codec and transforms use.

After the warm-up, a sweep over more than it runs (every dtype a bundle allows, 1–4 channels,
every target and wavelet, curves of 1–3 coordinates, surfaces of 1–3 values per point) must
not compile any new signature: otherwise a request of that kind would pause to compile.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SWEEP = textwrap.dedent(
    """
    import sys
    import numba
    import numpy as np
    import wavecore
    from wavecore import warmup

    def signatures():
        found = {}
        for name, module in list(sys.modules.items()):
            if name.startswith("wavecore"):
                for attr, obj in vars(module).items():
                    if isinstance(obj, numba.core.registry.CPUDispatcher):
                        found[name + "." + attr] = len(obj.signatures)
        return found

    def every_way(bundle):
        wavecore.decode(bundle)
        wavecore.decode(bundle, keep=0.3)
        wavecore.decode(bundle, level=1)

    warmup.warm_up(stream=None)
    before = signatures()
    assert before and sum(before.values()) > len(before) / 2, before
    rng = np.random.default_rng(5)
    targets = [{}, {"wavelet": "haar"}, {"wavelet": "cdf97"}, {"bpp": 8.0}, {"quality": 30},
               {"keep": 0.5}, {"wavelet": "haar", "quality": 50}, {"level": 1, "keep": 0.1}]
    for dtype in ("uint8", "uint16", "int16", "float32", "float64"):
        for channels in (1, 2, 3, 4):
            shape = (40, 30) if channels == 1 else (40, 30, channels)
            values = rng.random(shape)
            if dtype.startswith("float"):
                image = values.astype(dtype)
            else:
                info = np.iinfo(dtype)
                image = (info.min + values * (int(info.max) - int(info.min))).astype(dtype)
            exact = [{"lossless": True}, {"lossless": True, "effort": "max"}]
            cases = targets + (exact if dtype in ("uint8", "uint16") else [])
            for target in cases:
                every_way(wavecore.encode_image(image, **target))
    for dims in (1, 2, 3):
        points = rng.random(80) if dims == 1 else rng.random((80, dims))
        for closed in (False, True):
            for target in ({}, {"tolerance": 1e-2}, {"keep": 0.1}, {"wavelet": "haar"},
                           {"wavelet": "cdf97", "tolerance": 1e-4}):
                every_way(wavecore.encode_curve(points, closed=closed, **target))
    for grid in (rng.random((20, 30)), rng.random((20, 30, 3)), rng.random((20, 30, 2))):
        for closed in ((False, False), (True, False), (False, True), (True, True)):
            for target in ({}, {"quality": 60}, {"keep": 0.5}):
                every_way(wavecore.encode_surface(grid, closed=closed, **target))
    after = signatures()
    new = {k: (before.get(k, 0), v) for k, v in after.items() if v != before.get(k, 0)}
    print(new)
    """
)


@pytest.mark.long
def test_the_warm_up_leaves_nothing_to_compile() -> None:
    # A new process, so that nothing this test session compiled before counts.
    run = subprocess.run(
        [sys.executable, "-c", SWEEP], capture_output=True, text=True, timeout=1800
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "{}", f"compiled after the warm-up: {run.stdout}"
