"""The lossless coder (wavecore.losslesscoder): round trips, stripes, hostile chunks."""

from __future__ import annotations

import numpy as np
import pytest

import wavecore
from wavecore import lossless
from wavecore.errors import BundleError
from wavecore.losslesscoder import (
    LOSSLESS_VERSION,
    decode_lossless_levels,
    encode_lossless_levels,
    stripe_count,
)

PARAMS = {"coder": "context", "version": LOSSLESS_VERSION, "two_d": True}


def _picture(shape: tuple[int, ...], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    base = 100 + 50 * np.sin(rows / 9.0) + 40 * np.cos(cols / 7.0)
    if len(shape) == 3:
        base = base[..., None] + 10 * np.arange(shape[2])
    return np.clip(base + rng.normal(0, 5, shape), 0, 255).astype(np.int64)


def _same(a: list, b: list) -> bool:
    for x, y in zip(a, b, strict=True):
        xs, ys = (x, y) if isinstance(x, tuple) else ((x,), (y,))
        if not all(np.array_equal(u, v) for u, v in zip(xs, ys, strict=True)):
            return False
    return True


@pytest.mark.parametrize(
    ("shape", "level"),
    [
        ((37, 23), 0),
        ((37, 23), 2),
        ((64, 48, 3), 1),
        ((400, 30), 0),
        ((401, 33, 4), 2),
        ((1, 5), 0),
    ],
)
def test_round_trip(shape: tuple[int, ...], level: int) -> None:
    data = _picture(shape, sum(shape) + level)
    coeffs = lossless.forward(data, level)
    chunks, params = encode_lossless_levels(coeffs)
    assert params == {"coder": "context", "version": LOSSLESS_VERSION, "two_d": True}
    back = decode_lossless_levels(chunks, lossless.band_shapes(shape, level), params)
    assert _same(back, coeffs)
    # a prefix of the chunks decodes to the first entries
    if level:
        assert _same(
            decode_lossless_levels(chunks[:1], lossless.band_shapes(shape, level), params),
            coeffs[:1],
        )


def test_extreme_values_round_trip() -> None:
    rng = np.random.default_rng(7)
    band = rng.integers(-(2**31), 2**31, (40, 50), dtype=np.int64)
    band[0, :3] = [-(2**31), 2**31 - 1, 0]
    chunks, params = encode_lossless_levels([band])
    assert np.array_equal(decode_lossless_levels(chunks, [(40, 50)], params)[0], band)


def test_stripes_are_coded_apart() -> None:
    """A change in the lower stripe leaves the upper stripe's stream as it was."""
    data = _picture((400, 40), 3)
    assert stripe_count(400) == 2
    other = data.copy()
    other[300, 10] += 7
    one = encode_lossless_levels([data])[0][0]
    two = encode_lossless_levels([other])[0][0]
    assert one != two
    length = one[0] | (one[1] << 7) if one[0] >= 0x80 else one[0]
    head = 2 if one[0] >= 0x80 else 1
    assert one[head : head + length] == two[head : head + length]


def test_prediction_codes_smooth_pictures_small() -> None:
    smooth = np.add.outer(np.arange(128), 2 * np.arange(128)) % 256
    noise = np.random.default_rng(1).integers(0, 256, (128, 128))
    small = len(encode_lossless_levels([smooth])[0][0])
    large = len(encode_lossless_levels([noise])[0][0])
    # the ramp (with its wraps at 256) costs under 0.3 bits a sample, noise near 8
    assert small < 128 * 128 * 0.3 / 8 < 128 * 128 * 0.9 < large


@pytest.mark.parametrize("seed", range(6))
def test_hostile_chunks_give_an_array_or_bundle_error(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shapes = lossless.band_shapes((60, 50), 1)
    chunks, params = encode_lossless_levels(lossless.forward(_picture((60, 50), seed), 1))
    garbage = [bytes(rng.integers(0, 256, rng.integers(0, 300)).astype(np.uint8)) for _ in chunks]
    cut = [c[: len(c) // 2] for c in chunks]
    flipped = [bytes(b ^ 0xFF if k % 13 == 0 else b for k, b in enumerate(c)) for c in chunks]
    for attempt in (garbage, cut, flipped):
        try:
            out = decode_lossless_levels(attempt, shapes, params)
        except BundleError:
            continue
        assert out[0].shape == (30, 25)


def test_stripe_lengths_past_the_end_are_refused() -> None:
    shapes = [(400, 20)]
    with pytest.raises(BundleError, match="stripe lengths"):
        decode_lossless_levels([b"\xff\xff"], shapes, PARAMS)
    with pytest.raises(BundleError, match="do not fit"):
        decode_lossless_levels([b"\x7f\x00"], shapes, PARAMS)


def test_unknown_version_is_refused() -> None:
    with pytest.raises(BundleError, match="version"):
        decode_lossless_levels([b""], [(4, 4)], {**PARAMS, "version": 9})


def test_max_effort_bundles_name_the_context_coders_version_5() -> None:
    image = _picture((48, 40, 3), 9).astype(np.uint8)
    bundle = wavecore.encode_image(image, lossless=True, effort="max")
    assert wavecore.inspect(bundle)["header"]["cparams"] == PARAMS
    assert np.array_equal(wavecore.decode(bundle), image)
    region = (slice(5, 30), slice(3, 20))
    assert np.array_equal(wavecore.decode(bundle, region=region), image[region])


def test_large_negative_parents_round_trip() -> None:
    """Model 2 classes a detail by its parents' signed sum: sums below -4096 (16-bit pictures
    at two levels or more) indexed outside the class table and crashed the process; they take
    the top class now, and sums in (-4096, 0) keep the class every version-5 bundle used."""
    rng = np.random.default_rng(0)
    steps = rng.integers(-50, 51, (128, 96))
    image = (np.cumsum(np.cumsum(steps, 0), 1) % 65536).astype(np.uint16)
    coeffs = lossless.forward(image.astype(np.int64), 4)
    assert 4 * int(coeffs[1][0].min()) < -4096  # the case: a parent sum far below -4096
    bundle = wavecore.encode_image(image, lossless=True, effort="max", level=4)
    assert np.array_equal(wavecore.decode(bundle), image)
    # the classes of negative sums, as the compiled kernel gives them
    from wavecore import _losslesskernels as kernels

    table = kernels.QLOG
    for x in (-1, -100, -3000, -4096):
        assert kernels._parent_class(x, 15) == min(int(table[x + 4096]), 15)
    assert kernels._parent_class(-4097, 15) == kernels._parent_class(-(10**9), 15) == 15
    assert kernels._parent_class(37, 15) == kernels._qlog(37, 15)


@pytest.mark.parametrize(
    ("shape", "level"),
    [((1600, 40), 0), ((1600, 48, 3), 1), ((3200, 24), 3), ((1800, 30, 3), 2)],
)
def test_a_region_decodes_only_its_stripes_and_equals_the_whole(
    shape: tuple[int, ...], level: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Tall pictures have several stripes per level; a region decodes those holding its rows
    (and, from the third level entry on, the parent stripes their contexts read), and gives
    exactly the whole decode's samples."""
    image = _picture(shape, 11).astype(np.uint8)
    bundle = wavecore.encode_image(image, lossless=True, level=level)
    whole = wavecore.decode(bundle)
    assert np.array_equal(whole, image)
    from wavecore import losslesscoder

    decoded: list[int] = []
    real = losslesscoder.kernels.decode_level

    def counting(values, mags, parent, table, stripe, stripes, part):  # type: ignore[no-untyped-def]
        decoded.append(stripe)
        return real(values, mags, parent, table, stripe, stripes, part)

    monkeypatch.setattr(losslesscoder.kernels, "decode_level", counting)
    rows = shape[0]
    chunks = wavecore.inspect(bundle)["chunks"]
    total_stripes = sum(stripe_count(chunk["shapes"][0][0]) for chunk in chunks)
    assert total_stripes > len(chunks)  # several stripes to skip
    for start, stop in ((0, 5), (rows // 2 - 7, rows // 2 + 9), (rows - 30, rows), (0, rows)):
        for cols in (slice(0, shape[1]), slice(3, 17)):
            decoded.clear()
            region = (slice(start, stop), cols)
            assert np.array_equal(wavecore.decode(bundle, region=region), whole[region])
            if stop - start < rows // 4:
                # (the lifting's support wraps around: a window at one end also reads a few
                # samples of the other, so those stripes too)
                assert 0 < len(decoded) < total_stripes  # fewer than all: the point


def test_stripes_needed_passes_a_childs_rows_on_to_its_parent() -> None:
    from wavecore.losslesscoder import stripes_needed

    # three entries: the coarse band, one detail level, and a finer one whose stripes' contexts
    # read their parent rows r >> 1 and the row below
    shapes = [(400, 8), ((400, 8),) * 3, ((800, 16),) * 3]
    wanted_rows = np.zeros(800, dtype=bool)
    wanted_rows[399:401] = True  # rows 399-400: the second of four stripes ends at row 400
    none = np.zeros(400, dtype=bool)
    cols = np.ones(16, dtype=bool)
    masks = [
        [(none, cols[:8])],
        [(none, cols[:8])] * 3,
        [(wanted_rows, cols)] * 3,
    ]
    marks = stripes_needed(shapes, masks)
    assert [m.tolist() for m in marks[2:]] == [[False, True, True, False]]
    # rows 200-399 of the finer level read parent rows 100-200: parent stripes 0 and 1 (of 2);
    # rows 400-599 read 200-300: parent stripe 1
    assert marks[1].tolist() == [True, True]
    assert marks[0].tolist() == [False, False]
