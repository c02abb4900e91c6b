"""Lossless depth choice: the block coder's (``effort="fast"``: wavecore.lossless.best_depth,
LOSSLESS_DEPTHS), and the default lossless coder's (wavecore.lossless.choose_depth: prediction
alone, or one level, close calls decided by coding a sample both ways)."""

from __future__ import annotations

import numpy as np
import pytest

import wavecore
from wavecore import lossless


def _texture(shape: tuple[int, ...], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rows = np.arange(shape[0])[:, None]
    cols = np.arange(shape[1])[None, :]
    base = 120 + 60 * np.sin(rows / 3.0) * np.cos(cols / 5.0)
    noise = rng.normal(0, 6, shape)
    if len(shape) == 3:
        base = base[..., None]
    return np.clip(base + noise, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape", [(96, 80), (64, 72, 3)])
def test_fast_is_the_smallest_tried_depth_and_exact(shape: tuple[int, ...]) -> None:
    image = _texture(shape, 1)
    bundle = wavecore.encode_image(image, lossless=True, effort="fast")
    assert np.array_equal(wavecore.decode(bundle), image)
    depth = wavecore.inspect(bundle)["levels"]
    assert depth in lossless.LOSSLESS_DEPTHS
    # best_depth re-codes only the coarse part of a deeper depth: its bundle must be the very
    # bundle a whole coding at that depth gives, and no tried depth may code much smaller.
    direct = {
        d: wavecore.encode_image(image, lossless=True, level=d, effort="fast")
        for d in lossless.LOSSLESS_DEPTHS
    }
    assert bundle == direct[depth]
    # The choice compares the coded chunks; headers differ by a byte per level of the lifting.
    assert len(bundle) <= min(len(b) for b in direct.values()) + len(lossless.LOSSLESS_DEPTHS)


def test_an_explicit_level_is_kept() -> None:
    image = _texture((96, 80), 2)
    bundle = wavecore.encode_image(image, lossless=True, level=4)
    assert wavecore.inspect(bundle)["levels"] == 4
    assert np.array_equal(wavecore.decode(bundle), image)


def test_best_depth_chunks_match_a_whole_coding() -> None:
    from wavecore.entropy import encode_levels

    data = _texture((64, 64), 3).astype(np.int64)
    filters = ["legall53", "haar", "legall53"]

    def code(coeffs: list) -> list[bytes]:
        return encode_levels(coeffs)[0]

    depth, chunks = lossless.best_depth(data, filters, code, (1, 2, 3))
    whole = {d: code(lossless.forward(data, d, (0, 1), filters[:d])) for d in (1, 2, 3)}
    assert chunks == whole[depth]
    assert sum(map(len, chunks)) == min(sum(map(len, c)) for c in whole.values())


def test_tiny_images_stay_exact() -> None:
    for shape in [(1, 1), (2, 3), (5, 4, 3), (3, 9)]:
        image = _texture(shape, 4)
        assert np.array_equal(wavecore.decode(wavecore.encode_image(image, lossless=True)), image)


@pytest.mark.parametrize("shape", [(96, 80), (64, 72, 3)])
def test_max_effort_depth_is_the_entropy_choice_and_exact(shape: tuple[int, ...]) -> None:
    image = _texture(shape, 1)
    bundle = wavecore.encode_image(image, lossless=True, effort="max")
    assert np.array_equal(wavecore.decode(bundle), image)
    header = wavecore.inspect(bundle)["header"]
    assert header["levels"] in (0, 1)
    # The bundle is the very one an explicit level with the chosen filters gives.
    explicit = wavecore.encode_image(image, lossless=True, level=header["levels"], effort="max")
    assert bundle == explicit


def test_max_effort_takes_one_haar_level_of_a_pixel_repeated_picture() -> None:
    """Haar details of a 2x nearest-neighbour enlargement are all zero: one level pays."""
    small = _texture((40, 36), 5)
    big = np.kron(small, np.ones((2, 2), dtype=np.uint8))
    big[0, 1] ^= 1  # one pixel off: not an exact enlargement, which is coded as its source
    bundle = wavecore.encode_image(big, lossless=True, effort="max")
    assert wavecore.inspect(bundle)["header"]["lifting"] == ["haar"]
    assert np.array_equal(wavecore.decode(bundle), big)
    # and it is smaller than prediction alone
    alone = wavecore.encode_image(big, lossless=True, level=0, effort="max")
    assert len(bundle) < len(alone)


@pytest.mark.parametrize("seed", [6, 8])
def test_a_close_call_takes_the_depth_that_codes_smaller(seed: int) -> None:
    """Entropy alone says "no level" for this noisy texture, but the ratio is close enough
    (under CHECK_BELOW) for the encoder to code it both ways: its bundle is the smaller of
    the two explicit depths'."""
    image = _texture((80, 96), seed)
    _, ratio = lossless._one_level(image.astype(np.int64), lossless.CANDIDATE_SETS[0])
    assert lossless.DEPTH_GAIN <= ratio < lossless.CHECK_BELOW
    assert lossless.choose_depth(image.astype(np.int64)) == []
    bundle = wavecore.encode_image(image, lossless=True)
    sizes = [len(wavecore.encode_image(image, lossless=True, level=d)) for d in (0, 1)]
    assert wavecore.inspect(bundle)["levels"] == int(np.argmin(sizes))
    assert len(bundle) == min(sizes)


def test_max_effort_keeps_an_explicit_level() -> None:
    image = _texture((96, 80), 2)
    bundle = wavecore.encode_image(image, lossless=True, level=4, effort="max")
    assert wavecore.inspect(bundle)["levels"] == 4
    assert np.array_equal(wavecore.decode(bundle), image)
    with pytest.raises(wavecore.InvalidParameter, match="too deep"):
        wavecore.encode_image(image, lossless=True, level=8, effort="max")


def _bands(coeffs: list) -> list[np.ndarray]:
    return [b for entry in coeffs for b in (entry if isinstance(entry, tuple) else (entry,))]


def test_kept_lifting_steps_give_the_same_decomposition() -> None:
    # The encoder lifts each level once, for the filter choice, and codes from those steps:
    # they must be the very coefficients a fresh forward() makes, for every choice and depth.
    data = _texture((96, 80), 5).astype(np.int64)
    lifted: lossless.Lifted = {}
    choices = lossless.filter_choices(data, 3, lifted=lifted)
    assert choices == lossless.filter_choices(data, 3)
    for chosen in choices:
        steps = [(tuple(chosen[:k]), chosen[k]) for k in range(3)]
        assert all(step in lifted for step in steps)
        for depth in (1, 2, 3):
            fresh = _bands(lossless.forward(data, depth, (0, 1), chosen[:depth]))
            taken = dict(lifted)
            kept = _bands(lossless.forward(data, depth, (0, 1), chosen[:depth], lifted=taken))
            assert not any(step in taken for step in steps[:depth])  # taken out, let go
            assert len(fresh) == len(kept) == 3 * depth + 1
            for x, y in zip(fresh, kept, strict=True):
                assert x.dtype == y.dtype == np.int32
                assert np.array_equal(x, y)
    # A step missing from the kept ones is lifted: the result is still the same.
    partial = {key: step for key, step in lifted.items() if key[0]}
    chosen = choices[0]
    fresh = _bands(lossless.forward(data, 2, (0, 1), chosen[:2]))
    kept = _bands(lossless.forward(data, 2, (0, 1), chosen[:2], lifted=partial))
    assert all(np.array_equal(x, y) for x, y in zip(fresh, kept, strict=True))


@pytest.mark.parametrize("repeated", [False, True])
def test_max_effort_depth_of_a_tall_picture_asks_a_sample_first(repeated: bool) -> None:
    """A picture of 2 × SAMPLE_ROWS × SAMPLE_EVERY rows or more is first judged on a sample:
    the answer is the whole picture's, for a texture (no) and a 2x enlargement (yes, Haar)."""
    rows = 2 * lossless.SAMPLE_ROWS * lossless.SAMPLE_EVERY
    image = _texture((rows, 48), 7).astype(np.int64)
    if repeated:
        image = np.kron(image[: rows // 2, :24], np.ones((2, 2), dtype=np.int64))
    chosen, ratio = lossless._one_level(image, lossless.CANDIDATE_SETS[0])
    whole = chosen if ratio < lossless.DEPTH_GAIN else []
    assert whole == (["haar"] if repeated else [])
    assert lossless.choose_depth(image) == whole


def test_a_close_call_is_coded_on_the_sample_both_ways() -> None:
    """Entropy ratios between DEPTH_GAIN and CHECK_BELOW are decided by ``confirm`` (the
    encoder codes the sample both ways); outside that band ``confirm`` is never asked."""
    rng = np.random.default_rng(5)
    rows = 4 * lossless.SAMPLE_ROWS * lossless.SAMPLE_EVERY
    # a smooth picture enlarged 4x with a little noise: one level's entropy is a little lower
    small = _texture((rows // 4, 40), 9).astype(np.float64)
    big = np.kron(small, np.ones((4, 4)))
    image = np.clip(big + rng.normal(0, 3.0, big.shape), 0, 255).astype(np.int64)
    chosen, ratio = lossless._one_level(image, lossless.CANDIDATE_SETS[0])
    assert lossless.DEPTH_GAIN <= ratio < lossless.CHECK_BELOW, ratio
    asked: list[tuple[int, ...]] = []

    def says(answer: bool):  # type: ignore[no-untyped-def]
        def confirm(sample: np.ndarray, filters: list[str]) -> bool:
            asked.append(sample.shape)
            assert filters == chosen
            return answer

        return confirm

    assert lossless.choose_depth(image) == []  # no confirm: the entropy alone
    assert lossless.choose_depth(image, confirm=says(False)) == []
    assert lossless.choose_depth(image, confirm=says(True)) == chosen
    # the sample is a quarter of the rows: blocks of SAMPLE_ROWS, one in SAMPLE_EVERY
    assert asked == [(rows // lossless.SAMPLE_EVERY, 160)] * 2
    from skimage import data

    brick = data.brick()[:rows].astype(np.int64)  # far from a level paying (1.03): not asked
    asked.clear()
    assert lossless.choose_depth(brick, confirm=says(True)) == []
    assert asked == []


def test_a_close_call_on_a_short_wide_picture_codes_a_few_column_blocks() -> None:
    """A picture too short for the row sample is its own sample; past CONFIRM_MOST pixels the
    close call codes evenly spaced blocks of CONFIRM_COLUMNS columns, not the whole width."""
    rng = np.random.default_rng(6)
    small = _texture((4, 50_000), 3).astype(np.float64)
    wide = np.kron(small, np.ones((4, 4)))[:, :180_000]
    image = np.clip(wide + rng.normal(0, 3.0, wide.shape), 0, 255).astype(np.int64)
    _, ratio = lossless._one_level(image, lossless.CANDIDATE_SETS[0])
    assert lossless.DEPTH_GAIN <= ratio < lossless.CHECK_BELOW, ratio
    asked: list[tuple[int, ...]] = []

    def confirm(sample: np.ndarray, filters: list[str]) -> bool:
        asked.append(sample.shape)
        return False

    assert lossless.choose_depth(image, confirm=confirm) == []
    (shape,) = asked
    assert shape[0] == 16 and shape[1] % lossless.CONFIRM_COLUMNS == 0
    assert shape[0] * shape[1] <= lossless.CONFIRM_MOST < image.size
