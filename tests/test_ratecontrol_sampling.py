"""The bpp prediction's sample on large pictures: each code-block's first-order entropy, from
one compiled pass per band, is the entropy of that block's magnitudes counted directly."""

from __future__ import annotations

import numpy as np
import pytest

from wavecore.blockcoder import BLOCK_SIZE, block_lengths
from wavecore.codec import ratecontrol


def direct_entropies(levels: list[list[np.ndarray]], regions: np.ndarray) -> np.ndarray:
    """Per block and band: -sum n log2(n / N) over the magnitudes 0-15 and 16+, plus the bit
    length of each 16+ and a bit per nonzero (the sign), in bytes."""
    out = np.zeros(len(regions))
    for index, (entry, row0, col0, row1, col1) in enumerate(regions):
        for band in levels[entry]:
            part = np.abs(band[row0:row1, col0:col1].astype(np.int64)).reshape(-1)
            if part.size == 0:
                continue
            counts = np.bincount(np.minimum(part, 16), minlength=17)
            counts = counts[counts > 0].astype(float)
            bits = -np.sum(counts * np.log2(counts / part.size))
            bits += np.sum(np.log2(part[part >= 16])) + np.count_nonzero(part)
            out[index] += bits / 8.0
    return out


@pytest.mark.parametrize(
    ("shape", "channels"), [((2 * BLOCK_SIZE + 37, 3 * BLOCK_SIZE + 5), 3), ((700, 90), None)]
)
def test_block_entropies_count_each_block(shape: tuple[int, int], channels: int | None) -> None:
    rng = np.random.default_rng(3)
    sizes = [shape]
    for _ in range(3):
        sizes.append(((sizes[-1][0] + 1) // 2, (sizes[-1][1] + 1) // 2))
    sizes.reverse()

    def band(rows: int, cols: int) -> np.ndarray:
        full = (rows, cols) if channels is None else (rows, cols, channels)
        sparse = rng.integers(0, 3, full) == 0
        return (rng.laplace(0, 12, full) * sparse).astype(np.int32)  # some of 16 and more

    # Detail bands of one level may differ by one in width (odd sizes): the blocks still tile
    # each from the top left.
    levels = [[band(*sizes[0])]] + [
        [band(r, c), band(r, max(c - 1, 1)), band(r, c)] for r, c in sizes[1:]
    ]
    _, regions = block_lengths(levels, True, BLOCK_SIZE, np.zeros(0, dtype=np.int64))
    assert len(regions) > len(levels)  # several blocks in the fine levels
    found = ratecontrol._block_entropies(levels, regions)
    assert np.allclose(found, direct_entropies(levels, regions), rtol=1e-12, atol=1e-9)


def test_grid_coding_at_the_sample_step_takes_the_sampled_blocks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A grid's bpp sample whose own step predicts a fit is the full coding's step, and that
    coding takes the sample's coded blocks: the same bundle as coding every block."""
    from matplotlib import cbook

    import wavecore

    with cbook.get_sample_data("jacksboro_fault_dem.npz") as data:
        grid = np.tile(np.asarray(data["elevation"]), (3, 3))
    given: list[bool] = []
    encode_levels = ratecontrol.encode_levels

    def counted(qcoeffs: list, *, known_blocks: object = None, **options: object) -> object:
        given.append(known_blocks is not None)
        return encode_levels(qcoeffs, known_blocks=known_blocks, **options)

    monkeypatch.setattr(ratecontrol, "encode_levels", counted)
    reused = wavecore.encode_grid(grid, bpp=2.0)
    assert given == [True]  # one full coding, from the sample
    assert 0.975 * 2.0 * grid.size / 8 <= len(reused) <= 2.0 * grid.size / 8

    def every_block(qcoeffs: list, *, known_blocks: object = None, **options: object) -> object:
        return encode_levels(qcoeffs, **options)

    monkeypatch.setattr(ratecontrol, "encode_levels", every_block)
    assert wavecore.encode_grid(grid, bpp=2.0) == reused
