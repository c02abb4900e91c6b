"""Region decodes: ``decode(bundle, region=...)`` equals the full decode cropped, exactly.

A region decode reads only the code-blocks whose coefficients reach the region and zeroes the
rest, so a support worked out too small shows up here as a mismatch (the synthesis would read a
zeroed coefficient).  Hypothesis picks regions and levels; fixed cases cover every wavelet and
boundary, edges, 1 × N and N × 1 pictures, colour, curves, surfaces and old bundles.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wavecore
from wavecore import BundleError, InvalidParameter, decode, decode_region, inspect
from wavecore.blockcoder import block_counts, needed_blocks
from wavecore.bundle import read_bundle
from wavecore.codec.plan import plan_from_header
from wavecore.regions import band_masks

GOLDEN = Path(__file__).parent / "golden"
FAST = settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))


def _picture(shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    """Smooth structure plus noise: many nonzero details at every level."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    base = 128 + 60 * np.sin(x / 7.0) * np.cos(y / 5.0) + rng.normal(0, 12, shape[:2])
    if len(shape) == 3:
        base = base[..., None] + np.arange(shape[2]) * 20
    return base.clip(0, 255).astype(np.uint8)


def _bundles() -> dict[str, bytes]:
    grey = _picture((300, 270))
    rgb = _picture((270, 300, 3), 1)
    out = {
        f"{wavelet} grey": wavecore.encode_image(grey, wavelet=wavelet, quality=42, level=4)
        for wavelet in ("cdf97", "bspline2", "haar")
    }
    out["cdf97 rgb"] = wavecore.encode_image(rgb, quality=40)
    # the block coder's (the lossless coder's stripes: tests/test_lossless_coder.py)
    out["lossless rgb"] = wavecore.encode_image(rgb, lossless=True, level=4, effort="fast")
    out["lossless grey"] = wavecore.encode_image(grey, lossless=True, effort="fast")
    rng = np.random.default_rng(3)
    surface = np.cumsum(rng.normal(size=(150, 290, 3)), axis=1)
    out["surface closed"] = wavecore.encode_surface(surface, closed=(True, False), quality=45)
    out["surface open"] = wavecore.encode_surface(surface, quality=45)
    return out


BUNDLES = _bundles()
NAMES = sorted(BUNDLES)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b))


@pytest.mark.parametrize("name", NAMES)
def test_every_bundle_spans_several_blocks(name: str) -> None:
    """Otherwise the region tests below would not skip anything."""
    parsed = read_bundle(BUNDLES[name])
    cparams = parsed.header["cparams"]
    counts = block_counts(_entries(parsed.header), cparams["two_d"], cparams["block"])
    assert max(counts) > 1


def _entries(header: dict[str, Any]) -> list[list[tuple[int, ...]]]:
    plan = plan_from_header(header)
    shapes = plan.band_shapes()
    two_axes = len(plan.axes) == 2
    return [[tuple(shapes[0])]] + [
        [tuple(b) for b in entry] if two_axes else [tuple(entry)] for entry in shapes[1:]
    ]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    "region",
    [
        (slice(0, 1), slice(0, 1)),
        (slice(-1, None), slice(-1, None)),
        (slice(130, 135), slice(128, 129)),
        (slice(None), slice(200, None)),
        (slice(5, 140, 3), slice(None, None, 7)),
        ((40, 90), (0, 300)),
        (slice(100, 101),),
    ],
)
def test_a_region_equals_the_full_decode_cropped(name: str, region: Any) -> None:
    bundle = BUNDLES[name]
    full = decode(bundle)
    assert _same(decode(bundle, region=region), full[_as_slices(region)])
    assert _same(decode_region(bundle, region), full[_as_slices(region)])


def _as_slices(region: Any) -> tuple[slice, ...]:
    return tuple(slice(*item) if isinstance(item, tuple) else item for item in region)


@FAST
@given(data=st.data())
@pytest.mark.parametrize("name", NAMES)
def test_any_region_at_any_level_is_exact(name: str, data: st.DataObject) -> None:
    bundle = BUNDLES[name]
    level = data.draw(st.integers(0, inspect(bundle)["levels"]), label="level")
    full = decode(bundle, level=level)
    region = []
    for n in full.shape[:2]:
        start = data.draw(st.integers(0, n - 1))
        stop = data.draw(st.integers(start + 1, n))
        region.append(slice(start, stop))
    assert _same(decode(bundle, level=level, region=tuple(region)), full[tuple(region)])


@pytest.mark.parametrize(
    "shape", [(1, 300), (300, 1), (2, 517), (517, 3), (1, 1), (129, 129), (255, 257)]
)
@pytest.mark.parametrize("lossless", [False, True])
def test_thin_and_odd_shapes(shape: tuple[int, int], lossless: bool) -> None:
    image = _picture(shape, 5)
    bundle = wavecore.encode_image(
        image, lossless=lossless, **({} if lossless else {"quality": 45})
    )
    full = decode(bundle)
    rows, cols = shape
    for region in [
        (slice(0, rows), slice(0, cols)),
        (slice(rows // 2, rows // 2 + 1), slice(cols // 3, cols // 3 + 2)),
        (slice(rows - 1, rows), slice(max(cols - 5, 0), cols)),
    ]:
        assert _same(decode(bundle, region=region), full[region])


def test_a_curve_region_is_a_run_of_points() -> None:
    t = np.linspace(0, 40 * np.pi, 40000)
    curve = np.stack([np.cos(t) * (1 + t), np.sin(3 * t)], axis=1)
    for closed in (False, True):
        bundle = wavecore.encode_curve(curve, closed=closed, tolerance=1e-3)
        full = decode(bundle)
        for region in [(slice(0, 10),), slice(20000, 20100), (slice(-7, None),)]:
            expected = full[region]
            assert _same(decode(bundle, region=region), expected)


def test_a_region_reads_only_the_blocks_it_needs() -> None:
    """A small window in a large picture: most blocks are never decoded or checked."""
    bundle = wavecore.encode_image(_picture((1100, 1000)), quality=40)
    parsed = read_bundle(bundle)
    plan = plan_from_header(parsed.header)
    entries = _entries(parsed.header)
    cparams = parsed.header["cparams"]
    masks = band_masks(plan.transform, plan.fitted, plan.levels, 0, [(500, 520), (600, 620)])
    wanted = needed_blocks(entries, True, cparams["block"], masks)
    assert sum(block_counts(entries, True, cparams["block"])) == len(wanted)
    assert wanted.sum() <= len(wanted) // 3
    # Damage a block the window does not need: the window still decodes, exactly.
    damaged = bytearray(bundle)
    damaged[-10] ^= 0x55  # inside the last block of the finest chunk
    region = (slice(500, 520), slice(600, 620))
    assert _same(decode(bytes(damaged), region=region), decode(bundle)[region])
    with pytest.raises(BundleError, match=r"chunk \d+ is corrupt"):
        decode(bytes(damaged))


def test_old_bundles_decode_a_region_too() -> None:
    """Formats 1.x and 2.0 and the older coders: decoded whole, then cropped."""
    names = sorted(p.stem for p in GOLDEN.glob("*.wvb") if "curve" not in p.stem)
    assert len(names) >= 10
    for name in names:
        bundle = (GOLDEN / f"{name}.wvb").read_bytes()
        full = decode(bundle)
        region = (slice(1, max(2, full.shape[0] // 2)), slice(full.shape[1] // 3, None))
        assert _same(decode(bundle, region=region), full[region]), name


def test_keep_with_a_region_is_the_kept_decode_cropped() -> None:
    bundle = BUNDLES["cdf97 grey"]
    region = (slice(10, 50), slice(200, 260))
    assert _same(decode(bundle, keep=0.3, region=region), decode(bundle, keep=0.3)[region])


@pytest.mark.parametrize(
    ("region", "message"),
    [
        ((slice(5, 5), slice(0, 3)), "axis 0 selects no samples"),
        ((slice(0, 3), slice(400, 500)), "axis 1 selects no samples"),
        ((slice(0, 3, -1),), "step must be positive"),
        ((slice(0, 3), slice(0, 3), slice(0, 1)), "tuple of 1 to 2 slices"),
        ("rows", "tuple of 1 to 2 slices"),
        ((3, slice(0, 3)), "must be a slice or a"),
        ((slice(0.5, 3),), "start must be an integer"),
        ((), "tuple of 1 to 2 slices"),
    ],
)
def test_bad_regions_are_refused_by_name(region: Any, message: str) -> None:
    with pytest.raises(InvalidParameter, match=message):
        decode(BUNDLES["cdf97 grey"], region=region)


def test_a_region_is_checked_against_the_level_shape() -> None:
    bundle = BUNDLES["haar grey"]
    coarse = decode(bundle, level=2)
    assert _same(decode(bundle, level=2, region=(slice(70, 80),)), coarse[70:80])
    with pytest.raises(InvalidParameter, match="selects no samples"):
        decode(bundle, level=2, region=(slice(coarse.shape[0], None),))


@pytest.mark.parametrize("name", ["v3_0_image_grey_u8_blocks", "v3_0_image_grey_u8_lossless"])
def test_a_3_0_golden_region_equals_its_committed_decode(name: str) -> None:
    """The committed decode (tests/golden/*.npy), cropped: independent of today's full decode."""
    bundle = (GOLDEN / f"{name}.wvb").read_bytes()
    expected = np.load(GOLDEN / f"{name}.npy")
    assert read_bundle(bundle).version == (3, 0)
    for region in [(slice(0, 17), slice(250, 300)), (slice(190, 260), slice(3, 9))]:
        assert _same(decode(bundle, region=region), expected[region])


@pytest.mark.parametrize("wavelet", ["bspline2", "haar", "cdf97"])
@pytest.mark.parametrize("boundary", ["open", "closed"])
def test_supports_from_the_compact_form_equal_those_of_every_row(
    wavelet: str, boundary: str
) -> None:
    """The columns a region reads come from the compact form's pattern, not from every row
    written out; they are the same columns."""
    from wavecore.filters import get_wavelet, step_compact, step_sparse
    from wavecore.regions import _rows_columns, compact_rows_columns

    rule = get_wavelet(wavelet).rule(boundary)
    rng = np.random.default_rng(3)
    for m in [*range(max(2, rule.min_length), 40, 2), 1000, 4098]:
        full = step_sparse(wavelet, boundary, m)
        compact = step_compact(wavelet, boundary, m)
        for which in (2, 3):  # P and Q
            for rows in [np.arange(m), rng.integers(0, m, 9), np.array([0, m - 1])]:
                expected = _rows_columns(full[which].indptr, full[which].indices, rows)
                got = compact_rows_columns(*compact[which], rows)
                assert np.array_equal(np.unique(got), np.unique(expected)), (m, which)


def test_a_crafted_long_axis_is_refused_before_its_supports_cost_memory() -> None:
    """A 390-byte curve bundle whose header declares 4 million points: a region decode once
    wrote out every row of each level's synthesis matrices (1.3 GB, 3.4 s, then kept in a
    cache) before a chunk was read; now its error comes first, at the sides' cost."""
    import json
    import sys
    import tracemalloc

    sys.path.insert(0, str(Path(__file__).parent))
    import fuzz_decoder

    t = np.linspace(0, 6, 64)
    curve = np.stack([np.cos(t), np.sin(t)], 1)
    header, chunks = fuzz_decoder.split(wavecore.encode_curve(curve, level=3, tolerance=0.01))
    n = 4_000_000
    fitted = wavecore.valid_length(n, header["levels"], "open", "bspline2")
    header.update(shape=[n, 2], fitted=[fitted, 2], pads=[[0, fitted - n]])
    crafted = fuzz_decoder.assemble(json.dumps(header).encode(), chunks)
    tracemalloc.start()
    try:
        with pytest.raises(BundleError):
            decode_region(crafted, (slice(0, 10),))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20  # the masks: a few bytes a declared sample
