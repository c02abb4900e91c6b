"""Grid bundles of the interpolation coder as written before its fine levels were split into
tiles (grid container version 2): ``python tests/golden_grids/make_golden_grids.py`` wrote them
once, on the code of commit 0622d1f; they must keep decoding to the committed arrays.  Do not
regenerate them: they stand for bundles already stored."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import wavecore

HERE = Path(__file__).resolve().parent


def terrain(shape: tuple[int, ...], seed: int, exponent: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    freqs = np.meshgrid(*[np.fft.fftfreq(n) for n in shape], indexing="ij")
    radius2 = sum(f * f for f in freqs)
    radius2.flat[0] = 1.0
    field = np.fft.ifftn(np.fft.fftn(rng.standard_normal(shape)) * radius2 ** (-exponent / 4))
    field = field.real
    return 1000.0 * (field - field.min()) / (field.max() - field.min())


def main() -> None:
    field = terrain((300, 260), 1, 2.2).astype(np.float32)
    volume = terrain((24, 48, 80), 2, 1.8).astype(np.float32)
    volume[5:9, 10:30, 20:40] = np.nan
    for name, data, bound in (("field_v2", field, 0.5), ("volume_nan_v2", volume, 1.0)):
        bundle = wavecore.encode_grid(data, max_error=bound)
        (HERE / f"{name}.wvg").write_bytes(bundle)
        np.save(HERE / f"{name}.npy", wavecore.decode(bundle))


if __name__ == "__main__":
    main()
