"""Header sizes of typical bundles in formats 6.0 and 5.0 (curves), 4.0 (compact), 3.1 (the
weights derived), 3.0 (binary header) and 1.1 (JSON), and the largest curve header over a sweep
of curves.

    .venv/bin/python benchmarks/header_sizes.py

Each bundle is encoded once; the same header and chunks are then written in each format
(``write_bundle(..., version=(1, 1))`` is the writer of releases before 2.0), so the payload is
identical and only the overhead differs.  ``header`` is everything but the chunks as the
coder wrote them (preamble, header, chunk lengths, checks; in 3.x, 4.0 and 6.0 also the block
checks and band counts ``write_bundle`` adds inside chunks of several code-blocks).  The
codec writes 6.0 for curves and 3.1 for images and surfaces; the column of the version it
writes is the one in bold.  Prints Markdown tables (docs/bundle-format.md quotes them).

``--images`` prints the images' heads alone, at the default levels and at explicit deeper ones
(up to the deepest the codec accepts: 8 for 512², 10 for 2048²), with 3.0's head of the same
header and chunks beside, then the *worst-case* rows: the largest 3.1 head any image can have,
from a header whose fields take their longest forms at the deepest level a bundle may declare
(3.1 stores no chunk lengths, so no encoding is needed). ``--sweep`` (both also run by default)
encodes curves of 2, 3, 8, 1000 and 50 000 points, 2-D and 3-D, open and closed, smooth and
noisy, at the default level and at every explicit level the plan allows, and prints the largest
header for each length and overall, next to the coder's own tables of block lengths (which
delimit the chunks in 5.0, and are counted as the coder's).

A second table gives the same curves as one-curve *curve sets* (``encode_curves([curve])``, at
the tolerance ``encode_curve`` uses by default: 1e-3 of the bounding-box diagonal): their
header is everything but the coded stream (magic, fields, CRC), in both forms.
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

import wavecore
from wavecore.blockcoder import block_counts, strip_block_checks
from wavecore.bundle import read_bundle, write_bundle
from wavecore.codec.plan import plan_from_header
from wavecore.errors import InvalidParameter


def cases() -> dict[str, bytes]:
    from skimage import data  # scikit-image's pictures: the figures' usual test set

    t8 = np.linspace(0, 1, 8)
    made = {"curve, 8 points": wavecore.encode_curve(np.stack([t8, np.sin(3 * t8)], 1))}
    for n in (50, 200, 1000, 50_000):
        t = np.linspace(0, 1, n)
        made[f"curve, {n} points"] = wavecore.encode_curve(np.stack([t, np.sin(6 * t) * t], 1))
    t = np.linspace(0, 1, 50_000)
    noisy = np.stack([t, np.sin(6 * t) * t], 1) + np.random.default_rng(5).normal(
        0, 0.01, (50_000, 2)
    )
    made["curve, 50 000 points + noise (σ 0.01)"] = wavecore.encode_curve(noisy)
    made["image 512² grey (camera), default"] = wavecore.encode_image(data.camera())
    made["image 512² RGB (astronaut), default"] = wavecore.encode_image(data.astronaut())
    made["image 512² grey (camera), lossless"] = wavecore.encode_image(data.camera(), lossless=True)
    made["image 512² RGB (astronaut), lossless"] = wavecore.encode_image(
        data.astronaut(), lossless=True
    )
    u = np.linspace(0, 2 * np.pi, 64)
    uu, vv = np.meshgrid(u, np.linspace(-1, 1, 48), indexing="ij")
    grid = np.stack([np.cos(uu) * (1 + vv**2), np.sin(uu), vv], -1)
    made["surface 64 × 48 × 3, default"] = wavecore.encode_surface(grid)
    made["height field 256², default"] = wavecore.encode_surface(
        np.add.outer(np.sin(np.linspace(0, 6, 256)), np.cos(np.linspace(0, 4, 256)))
    )
    return made


def curve_points() -> dict[str, np.ndarray]:
    t8 = np.linspace(0, 1, 8)
    made = {"curve, 8 points": np.stack([t8, np.sin(3 * t8)], 1)}
    for n in (50, 200, 1000):
        t = np.linspace(0, 1, n)
        made[f"curve, {n} points"] = np.stack([t, np.sin(6 * t) * t], 1)
    return made


def curve_sets() -> None:
    print()
    print("| one-curve curve set | form | payload | header | bundle | encode_curve bundle |")
    print("|---|---|---:|---:|---:|---:|")
    for name, points in curve_points().items():
        single = len(wavecore.encode_curve(points))
        diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
        for method in ("auto", "wavelet", "vertex"):
            bundle = wavecore.encode_curves(
                [points], closed=False, tolerance=1e-3 * diagonal, method=method
            )
            info = wavecore.inspect(bundle)
            print(
                f"| {name} | {method} ({info['method']}) | {info['payload_bytes']} "
                f"| {info['header_bytes']} | {len(bundle)} | {single} |"
            )


def curve_headers() -> None:
    """``encode_curve``'s overhead (``header_bytes``: everything but the chunks) by length,
    open and closed, in two and three dimensions, with the levels it chose."""
    print()
    print("| encode_curve | 8 points | 50 points | 200 points | 1000 points | 50 000 points |")
    print("|---|---:|---:|---:|---:|---:|")
    for d in (2, 3):
        for closed in (False, True):
            cells = []
            for n in (8, 50, 200, 1000, 50_000):
                t = np.linspace(0, 1, n)
                points = np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:d], 1)
                info = wavecore.inspect(wavecore.encode_curve(points, closed=closed))
                cells.append(f"{info['header_bytes']} B ({info['levels']} levels)")
            name = f"{d}-D, {'closed' if closed else 'open'}"
            print(f"| {name} | " + " | ".join(cells) + " |")


def coder_chunks(bundle: bytes) -> list[bytes]:
    """The chunks as the coder wrote them (3.0 and 4.0 add block checks to chunks of several
    code-blocks; ``write_bundle`` adds them again)."""
    parsed = read_bundle(bundle)
    plan = plan_from_header(parsed.header)
    shapes = plan.band_shapes()
    one_axis = len(plan.axes) == 1
    entries = [[tuple(shapes[0])]] + [
        [tuple(entry)] if one_axis else [tuple(band) for band in entry] for entry in shapes[1:]
    ]
    cparams = parsed.header["cparams"]
    checked = parsed.block_checks  # 3.0 and 4.0; 5.0 stores the chunks as coded
    if not checked or parsed.header["coder"] != "context" or cparams.get("version", 0) < 4:
        return [bytes(chunk or b"") for chunk in parsed.chunks]
    counts = block_counts(entries, cparams["two_d"], cparams["block"])
    return [
        strip_block_checks(bytes(chunk or b""), count, len(entry) if index else 0)[0]
        for index, (chunk, count, entry) in enumerate(
            zip(parsed.chunks, counts, entries, strict=True)
        )
    ]


def _sweep_points(n: int, dims: int, noisy: bool) -> np.ndarray:
    t = np.linspace(0, 1, n)
    points = np.stack([t, np.sin(6 * t) * t, np.cos(3 * t)][:dims], 1)
    if noisy:
        points = points + np.random.default_rng(5).normal(0, 0.01, points.shape)
    return points


def _table_bytes(bundle: bytes) -> int:
    """Bytes of the coder's tables of block lengths in a bundle's chunks."""
    from wavecore.blockcoder import block_table
    from wavecore.bundle import self_delimiting_blocks

    parsed = read_bundle(bundle)
    blocks = self_delimiting_blocks(parsed.header)
    if blocks is None:
        return 0
    return sum(
        block_table(bytes(chunk or b""), count)[0]
        for chunk, count in zip(parsed.chunks, blocks, strict=True)
    )


def sweep(lengths: tuple[int, ...] = (2, 3, 8, 1000, 50_000)) -> int:
    """The largest ``encode_curve`` header over lengths, dimensions, boundaries, smooth and
    noisy points, the default and every explicit level; returns it."""
    print()
    print(
        "| length | encodes | largest header | its case | its bundle | coder's block tables in it |"
    )
    print("|---:|---:|---:|---|---:|---:|")
    overall = 0
    for n in lengths:
        worst: tuple[int, str, int, int] = (-1, "", 0, 0)
        count = 0
        for dims in (2, 3):
            for closed in (False, True):
                for noisy in (False, True):
                    points = _sweep_points(n, dims, noisy)
                    for level in (None, *range(0, 31)):
                        try:
                            bundle = wavecore.encode_curve(points, closed=closed, level=level)
                        except InvalidParameter:
                            if level is not None and level > 3:
                                break  # deeper levels are refused too
                            continue
                        count += 1
                        info = wavecore.inspect(bundle)
                        size = len(bundle) - sum(len(c) for c in coder_chunks(bundle))
                        if size > worst[0]:
                            case = (
                                f"{dims}-D, {'closed' if closed else 'open'}, "
                                f"{'noisy' if noisy else 'smooth'}, level "
                                f"{'default ' if level is None else ''}{info['levels']}"
                            )
                            worst = (size, case, len(bundle), _table_bytes(bundle))
        overall = max(overall, worst[0])
        print(f"| {n} | {count} | {worst[0]} B | {worst[1]} | {worst[2]} | {worst[3]} B |")
    print(f"\nlargest curve header over the sweep: {overall} B (target: at most 48)")
    return overall


def restoration_record_bytes(header: dict) -> int:
    """The bytes of a header's restoration record (docs/bundle-format.md, "The restoration
    record"): what the binary header takes with ``restore`` beyond what it takes without."""
    from wavecore import binheader

    if "restore" not in header:
        return 0
    plain = {k: v for k, v in header.items() if k != "restore"}
    return len(binheader.pack(header)) - len(binheader.pack(plain))


def image_headers() -> int:
    """Images as the codec writes them (3.1): the head (``inspect``'s ``header_bytes``:
    preamble, header, chunk lengths, CRCs), the head of the same header and chunks in 3.0,
    and, apart, the block checks and band counts that 3.x adds inside chunks of several
    code-blocks (2 bytes a block and a few more a chunk: they grow with the picture, the price
    of a damaged block losing only itself); returns the largest head."""
    from skimage import data

    print()
    print(
        "| image | levels | head 3.1 (header_bytes) | of which the restoration record | "
        "head 3.0 | block checks and band counts |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    largest = 0
    rng = np.random.default_rng(1)
    # 2048² RGB: the astronaut enlarged (each pixel 4 × 4), the largest picture here.
    large = np.kron(data.astronaut(), np.ones((4, 4, 1), np.uint8))
    pictures = {
        "camera 512² grey, default": (data.camera(), {}),
        "astronaut 512² RGB, default": (data.astronaut(), {}),
        "astronaut 512² RGB, 1 bpp, 6 levels": (data.astronaut(), {"bpp": 1.0, "level": 6}),
        "astronaut 512² RGB, 1 bpp, 8 levels": (data.astronaut(), {"bpp": 1.0, "level": 8}),
        "astronaut 512² RGB, lossless": (data.astronaut(), {"lossless": True}),
        "2048 × 1536 RGB noise, 0.5 bpp": (
            rng.integers(0, 256, (1536, 2048, 3)).astype(np.uint8),
            {"bpp": 0.5},
        ),
        "RGBA 16-bit 300², lossless": (
            rng.integers(0, 65536, (300, 300, 4)).astype(np.uint16),
            {"lossless": True},
        ),
        "2048² RGB (astronaut × 4), 1 bpp, 9 levels": (large, {"bpp": 1.0, "level": 9}),
        "2048² RGB (astronaut × 4), 1 bpp, 10 levels": (large, {"bpp": 1.0, "level": 10}),
        # Odd shapes padded to the deepest level they allow, 4 channels of 16 bits and
        # float32 colour: every band has its own weight (cV is not cH), chunks of kilobytes.
        "RGBA 16-bit 301 × 517, quality 40, 7 levels": (
            rng.integers(0, 65536, (301, 517, 4)).astype(np.uint16),
            {"quality": 40.0, "level": 7},
        ),
        "float32 RGB 777 × 1001 noise, cdf97, 2 bpp, 8 levels": (
            rng.random((777, 1001, 3)).astype(np.float32),
            {"wavelet": "cdf97", "bpp": 2.0, "level": 8},
        ),
    }
    deepest = 0
    for name, (picture, options) in pictures.items():
        bundle = wavecore.encode_image(picture, **options)
        info = wavecore.inspect(bundle)
        record = restoration_record_bytes(info["header"])
        head = info["header_bytes"] - record  # the 96-byte bound is the head without it
        parsed = read_bundle(bundle)
        older = write_bundle(parsed.header, coder_chunks(bundle), version=(3, 0))
        inside = len(bundle) - info["header_bytes"] - sum(len(c) for c in coder_chunks(bundle))
        old_head = len(older) - sum(len(c) for c in parsed.chunks)
        # Each level adds a chunk length and a CRC-16 (in 3.0 also its weights): the
        # explicitly deeper pictures show what a level costs.
        if "level" in options:
            deepest = max(deepest, head)
        else:
            largest = max(largest, head)
        print(
            f"| {name} | {info['levels']} | {head + record} B | {record} B | {old_head} B "
            f"| {inside} B |"
        )
    print(
        f"\nlargest image head at the default levels: {largest} B without the restoration "
        "record (target: at most 96)"
    )
    print(
        f"largest image head at explicit deeper levels: {deepest} B without the restoration "
        "record (target: at most 96)"
    )
    return max(largest, deepest)


def worst_case_heads() -> int:
    """The largest 3.1 image head the codec can write, from its fields' largest values (no
    encoding needed: since 3.1's head holds no chunk lengths, it depends only on the header
    and the number of levels).  Checks first that the head is exactly that on a real bundle.
    Returns the largest head."""
    import struct

    from wavecore import binheader
    from wavecore.bundle import MAGIC, pinned_weights
    from wavecore.varints import encode_varint

    def head_of(header: dict, pinned: dict | None) -> int:
        packed = binheader.pack(header, pinned=pinned, delimited=True)
        length = len(encode_varint(len(packed)))  # one byte below 128
        return len(MAGIC) + 2 + length + len(packed) + 2 * (header["levels"] + 1) + 4

    from skimage import data

    bundle = wavecore.encode_image(data.astronaut(), bpp=1.0, level=8)
    header = read_bundle(bundle).header
    assert head_of(header, pinned_weights(header)) == wavecore.inspect(bundle)["header_bytes"]
    # The worst cases are heads without a restoration record, which adds at most
    # restoration.record_bound bytes (2 + 31 a channel for uint8, 2 + 34 for uint16).
    header = {k: v for k, v in header.items() if k != "restore"}
    print()
    print("| worst case (3.1, synthetic header) | levels | header | head |")
    print("|---|---:|---:|---:|")
    largest = 0
    # The deepest image a bundle may declare: Haar's open boundary fits any multiple of 2**L,
    # so 4064 × 16384 (fitted 8192 × 16384 = MAX_ELEMENTS; a length may at most double, + 64)
    # takes 13 levels; shape and pads at their longest varints; float64 data whose peak,
    # step and max_error have no short form (9, 8 and 9 bytes); a psnr of 4 bytes (no
    # float64 picture passes 9 405 dB); no pin, then one (3 bytes).
    worst = dict(header)
    worst.update(
        shape=[4064, 16384],  # 2 + 3 varint bytes, the first padded by 4128 (2 more)
        fitted=[8192, 16384],
        colour="none",
        pads=[[0, 4128], [0, 0]],
        dtype="float64",
        wavelet="haar",
        levels=13,
        peak=struct.unpack("<d", struct.pack("<d", math.pi * 1e10))[0],
        psnr=9404.9999,
        max_error=1e-300,  # below float32's normal range: stored as a float64
    )
    worst["qparams"] = dict(header["qparams"], step=math.pi / 7)
    # In colour (a byte more for the channels) 13 levels no longer fit: 12.
    colour = dict(worst, shape=[4094, 8190, 3], fitted=[4096, 8192, 3], levels=12)
    colour["pads"] = [[0, 2], [0, 2]]
    colour["colour"] = "ycbcr"
    # The per-picture colour rotation instead: its three angles at their longest (7 bytes).
    rotated = dict(colour, colour="klt:-4096,-2048,-4096")
    # cdf97 (and bspline2) reach 11 levels at most: 8192 × 16384 fits them.
    deep_cdf97 = dict(worst, wavelet="cdf97", levels=11, shape=[8192, 16384])
    deep_cdf97.update(fitted=[8192, 16384], pads=[[0, 0], [0, 0]])
    # In colour with the rotation: 11 levels of 8192 × 8192 (the channels are not counted).
    deep_rotated = dict(deep_cdf97, shape=[8192, 8192, 3], fitted=[8192, 8192, 3])
    deep_rotated["colour"] = "klt:-4096,-2048,-4096"
    cases_ = {
        "Haar grey 4064 × 16384, 13 levels": (worst, 0),
        "Haar grey 4064 × 16384, 13 levels, one pin more": (worst, 1),
        "Haar RGB 4094 × 8190, 12 levels, one pin more": (colour, 1),
        "Haar RGB 4094 × 8190, 12 levels, colour rotation, one pin more": (rotated, 1),
        "cdf97 grey 8192 × 16384, 11 levels": (deep_cdf97, 0),
        "cdf97 grey 8192 × 16384, 11 levels, one pin more": (deep_cdf97, 1),
        "cdf97 RGB 8192 × 8192, 11 levels, colour rotation, two pins more": (deep_rotated, 2),
    }
    from wavecore.bundle import derived_weights

    for name, (base, extra) in cases_.items():
        candidate = dict(base)
        weights = derived_weights(candidate)
        candidate["qparams"] = dict(candidate["qparams"], weights=weights)
        # The plan's own pins (none here: Haar's weights 2**-6 and 2**-7 are exact ties, which
        # need none), and ``extra`` more as if a weight lay that close to a change of digit.
        pinned = dict(pinned_weights(candidate) or {})
        flat = [w for entry in weights for w in entry]
        free = [index for index in range(len(flat)) if index not in pinned][:extra]
        pinned.update({index: flat[index] for index in free})
        name = f"{name} ({len(pinned)} pins)"
        packed = binheader.pack(candidate, pinned=pinned)
        head = head_of(candidate, pinned)
        largest = max(largest, head)
        print(f"| {name} | {candidate['levels']} | {len(packed)} B | {head} B |")
    # Lossless (coder code 3, no weights): 16-bit grey at 13 levels, every lifting code stored.
    lossless = read_bundle(wavecore.encode_image(data.camera(), lossless=True, level=2)).header
    lossless.update(
        shape=[8192, 16384],
        fitted=[8192, 16384],
        dtype="uint16",
        levels=13,
        lifting=["legall53"] * 13,
        peak=65535.0,
    )
    head = head_of(lossless, None)
    largest = max(largest, head)
    packed = binheader.pack(lossless, delimited=True)
    print(f"| lossless 16-bit grey 8192 × 16384, 13 levels | 13 | {len(packed)} B | {head} B |")
    print(f"\nlargest 3.1 image head possible: {largest} B (target: at most 96)")
    return largest


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.2f}")
    versions = ((1, 1), (3, 0), (3, 1), (4, 0), (5, 0), (6, 0))
    print(
        "| bundle | levels | payload | header 1.1 | header 3.0 | header 3.1 | header 4.0 "
        "| header 5.0 | header 6.0 | bundle 1.1 | bundle 3.0 | bundle 3.1 | bundle 4.0 "
        "| bundle 5.0 | bundle 6.0 |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, bundle in cases().items():
        parsed = read_bundle(bundle)
        chunks = coder_chunks(bundle)
        written = {v: write_bundle(parsed.header, chunks, version=v) for v in versions}
        assert written[parsed.version] == bundle  # the same bytes as the codec wrote
        headers, sizes = [], []
        for version, data in written.items():
            assert read_bundle(data).header == parsed.header
            bold = "**" if version == parsed.version else ""
            header = len(data) - sum(map(len, chunks))
            headers.append(f"{bold}{header}{bold}")
            sizes.append(f"{bold}{len(data)}{bold}")
        payload = sum(map(len, chunks))
        print(
            f"| {name} | {parsed.header['levels']} | {payload} | "
            + " | ".join(headers + sizes)
            + " |"
        )
    curve_sets()
    curve_headers()
    image_headers()
    worst_case_heads()
    sweep()
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    if "--sweep" in sys.argv:
        sweep()
    elif "--images" in sys.argv:
        image_headers()
        worst_case_heads()
    else:
        main()
