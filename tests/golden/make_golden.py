"""Add golden bundles for new cases (run when a format or coder version is added on purpose).

    .venv/bin/python tests/golden/make_golden.py

Writes, next to this script, one ``<name>.wvb`` bundle and one ``<name>.npy`` decoded array per
case that ``MANIFEST.json`` does not list yet, and adds each to the manifest with its SHA-256,
format version and the arguments that made it.  Committed cases are never rewritten: they are
what older versions wrote, and must keep decoding (``--replace NAME`` rewrites one on purpose).
``tests/test_golden.py`` decodes every committed bundle on every test run and compares it with
the committed array, so a change to the format, the quantizer or the entropy coder that would
break old bundles fails the tests instead of passing silently.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

import wavecore
from wavecore.bundle import read_bundle, write_bundle

HERE = Path(__file__).resolve().parent


def inputs() -> dict[str, tuple[str, np.ndarray, dict[str, Any]]]:
    rng = np.random.default_rng(2026)
    y, x = np.mgrid[0:40, 0:33] / 40.0
    grey = (128 + 90 * np.sin(7 * x) * np.cos(5 * y) + rng.normal(0, 5, x.shape)).clip(0, 255)
    y, x = np.mgrid[0:24, 0:30] / 30.0
    rgb = np.stack([100 + 80 * np.sin(5 * x), 120 + 70 * np.cos(4 * y), 60 + 150 * x * y], -1)
    rgba16 = rng.integers(0, 65536, (17, 23, 4)).astype(np.uint16)
    small = rng.integers(0, 256, (16, 16))
    repeated = np.kron(small, np.ones((2, 2), dtype=int)).astype(np.uint8)
    y, x = np.mgrid[0:64, 0:64]
    periodic = (128 + 100 * np.sin(2 * np.pi * x / 32) * np.cos(2 * np.pi * y / 32)).astype(
        np.uint8
    )
    t = np.linspace(0, 1, 50)
    open_curve = np.stack([t, np.sin(6 * t) * t], axis=1)
    s = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    t = np.linspace(0, 1, 1500)
    noisy_curve = np.stack([t, np.sin(9 * t)], axis=1)
    noisy_curve += np.random.default_rng(44).normal(0, 0.01, (1500, 2))  # its own: the rest stay
    closed_curve = np.stack([np.cos(s), np.sin(s), 0.2 * np.sin(3 * s)], axis=1)
    u = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    v = np.linspace(-1, 1, 14)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    radius = 1 + 0.3 * vv**2
    surface = np.stack([radius * np.cos(uu), radius * np.sin(uu), vv], axis=-1)
    y, x = np.mgrid[0:96, 0:130]
    sparse = 60 + x + 0.5 * y + 120 * ((x - 70) ** 2 + (y - 40) ** 2 < 200)
    y, x = np.mgrid[0:300, 0:270] / 300.0
    waves = 128 + 60 * np.sin(23 * x * (1 + y)) + 40 * np.cos(17 * y) * (x > 0.5)
    blocks_picture = (waves + rng.normal(0, 4, x.shape)).clip(0, 255).astype(np.uint8)
    y, x = np.mgrid[0:48, 0:40] / 40.0
    base = 120 + 60 * np.sin(9 * x) * np.cos(6 * y)
    tint = np.stack([base, 0.5 * base + 40, 255 - base], -1)
    tinted = (tint + np.random.default_rng(45).normal(0, 3, tint.shape)).clip(0, 255)
    tinted = tinted.astype(np.uint8)
    y, x = np.mgrid[0:520, 0:264] / 300.0
    waves = 128 + 60 * np.sin(23 * x * (1 + y)) + 40 * np.cos(17 * y) * (x > 0.5)
    noise = np.random.default_rng(66).normal(0, 4, x.shape)  # its own: the rest stay
    parent_picture = (waves + noise).clip(0, 255).astype(np.uint8)
    return {
        "image_grey_u8_lossy": (
            "image",
            grey.astype(np.uint8),
            {"level": 3, "quality": 35.0},
        ),
        "image_rgb_u8_bpp": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 6.0}),
        "image_rgba_u16_lossless": ("image", rgba16, {"lossless": True}),
        "image_grey_u8_lossless_repeated": ("image", repeated, {"lossless": True, "level": 3}),
        "image_grey_u8_lossless_periodic": ("image", periodic, {"lossless": True, "level": 3}),
        "image_grey_u8_cdf97_quality": (
            "image",
            grey.astype(np.uint8)[:33, :29],
            {"wavelet": "cdf97", "quality": 38.0},
        ),
        "image_f32_haar_keep": (
            "image",
            (grey[:20, :20] / 255).astype(np.float32),
            {"wavelet": "haar", "keep": 0.5},
        ),
        "curve_open_tolerance": ("curve", open_curve, {"tolerance": 1e-3}),
        "curve_closed_3d_keep": ("curve", closed_curve, {"closed": True, "keep": 0.5}),
        "surface_closed_open": ("surface", surface, {"closed": (True, False), "quality": 45.0}),
        # Context coder version 3 (tile flags): a picture whose fine details are mostly zero
        # tiles, a colour one at a set rate, lossless 16-bit, and a closed surface.
        "image_grey_u8_sparse_ctx3": ("image", sparse, {"quality": 32.0}),
        "image_rgb_u8_bpp_ctx3": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 8.0}),
        "image_rgba_u16_lossless_ctx3": ("image", rgba16, {"lossless": True}),
        "surface_closed_open_ctx3": (
            "surface",
            surface,
            {"closed": (True, False), "quality": 40.0},
        ),
        # Context coder version 4 (independent code-blocks, the compiled binary range coder): a
        # grey picture whose finest bands span several 128 × 128 blocks, colour at a set rate,
        # lossless 16-bit RGBA, a curve (the 1-D layout) and a closed surface.
        "image_grey_u8_blocks_ctx4": ("image", blocks_picture, {"quality": 36.0}),
        "image_rgb_u8_bpp_ctx4": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 8.0}),
        "image_rgba_u16_lossless_ctx4": ("image", rgba16, {"lossless": True}),
        "curve_open_tolerance_ctx4": ("curve", open_curve, {"tolerance": 1e-4}),
        "surface_closed_open_ctx4": (
            "surface",
            surface,
            {"closed": (True, False), "quality": 42.0},
        ),
        # Context coder version 6 (the parent band in the detail contexts): a grey picture
        # whose two finest levels span several 128 × 128 blocks (so blocks of the finest
        # level have different parent blocks), colour at a set rate, and a closed surface.
        "image_grey_u8_parent_ctx6": ("image", parent_picture, {"quality": 36.0}),
        "image_rgb_u8_bpp_ctx6": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 8.0}),
        "surface_closed_open_ctx6": (
            "surface",
            surface,
            {"closed": (True, False), "quality": 42.0},
        ),
        # Context coder version 7 (directional zero-flag models for cH and cV, chosen per plane
        # of a block by their running costs): the same three cases as version 6's.
        "image_grey_u8_parent_ctx7": ("image", parent_picture, {"quality": 36.0}),
        "image_rgb_u8_bpp_ctx7": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 8.0}),
        "surface_closed_open_ctx7": (
            "surface",
            surface,
            {"closed": (True, False), "quality": 42.0},
        ),
        # Context coder version 8 (version 7 whose blocks start from models trained per level
        # class): version 7's two picture cases (surfaces stay on version 6).
        "image_grey_u8_parent_ctx8": ("image", parent_picture, {"quality": 36.0}),
        "image_rgb_u8_bpp_ctx8": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 8.0}),
        # A per-picture colour matrix (colour "klt:<m>": colour code 3 with weight 0 and nine
        # integers): a tinted picture, whose details the matrix decorrelates better than YCbCr.
        "image_rgb_u8_klt": ("image", tinted, {"quality": 38.0}),
        # Format 2.0 (the binary header): a curve, grey and colour pictures at their default
        # quality, lossless 16-bit RGBA (with its lifting list), a surface and huge floats
        # (the ``scale`` field).
        "v2_curve_default": ("curve", open_curve, {}),
        "v2_image_grey_u8_default": ("image", blocks_picture, {}),
        "v2_image_rgb_u8_default": ("image", rgb.clip(0, 255).astype(np.uint8), {}),
        "v2_image_rgba_u16_lossless": ("image", rgba16, {"lossless": True}),
        "v2_surface_closed_open": ("surface", surface, {"closed": (True, False)}),
        "v2_surface_scaled": ("surface", surface * 1e300, {"quality": 40.0}),
        # Format 3.0 (a CRC-16 per chunk and per code-block, band counts for region decodes):
        # a grey picture whose finest bands span several blocks, lossy and lossless, colour at
        # a set rate, a surface and a curve (one block per chunk: as in 2.0).  Committed as "2.1"
        # on the branch that made them, renumbered 3.0 before any release (a new layout).
        "v3_0_image_grey_u8_blocks": ("image", blocks_picture, {"quality": 38.0}),
        "v3_0_image_grey_u8_lossless": ("image", blocks_picture, {"lossless": True}),
        "v3_0_image_rgb_u8_bpp": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 6.0}),
        "v3_0_surface_closed_open": ("surface", surface, {"closed": (True, False)}),
        "v3_0_curve_default": ("curve", open_curve, {}),
        # Format 4.0 (the compact layout encode_curve writes: a 4-byte preamble, weights
        # derived from the plan, a float32 step, chunks checked in groups): the default curve;
        # a closed 3-D one with ``keep`` (its step a short binary number); a 1-D series with
        # haar; a noisy curve whose chunks fall into several groups; and an image written in
        # 4.0 on purpose (readers take every kind in it; the codec writes images in 3.0).
        "v4_0_curve_default": ("curve", open_curve, {}),
        "v4_0_curve_closed_3d_keep": ("curve", closed_curve, {"closed": True, "keep": 0.5}),
        "v4_0_curve_series_haar": (
            "curve",
            np.sin(np.linspace(0, 9, 77)) * 40.0,
            {"wavelet": "haar", "tolerance": 0.05},
        ),
        "v4_0_curve_noisy_groups": ("curve", noisy_curve, {"tolerance": 0.002, "level": 4}),
        "v4_0_image_grey_u8": (
            "image",
            grey.astype(np.uint8),
            {"quality": 40.0, "format_version": (4, 0)},
        ),
        # Format 5.0 (the curve layout encode_curve writes: no chunk lengths where the block
        # coder's chunks delimit themselves, two CRC-16 groups, no block checks): the same
        # curves as 4.0's, a noisy curve of 10 levels whose finest chunk is kilobytes, and an
        # image written in 5.0 on purpose (tests/test_bundle_curve5.py codes a curve whose
        # finest band spans two code-blocks: its decoded array is too large to commit).
        "v5_0_curve_default": ("curve", open_curve, {}),
        "v5_0_curve_closed_3d_keep": ("curve", closed_curve, {"closed": True, "keep": 0.5}),
        "v5_0_curve_series_haar": (
            "curve",
            np.sin(np.linspace(0, 9, 77)) * 40.0,
            {"wavelet": "haar", "tolerance": 0.05},
        ),
        "v5_0_curve_noisy_deep": ("curve", noisy_curve, {"tolerance": 0.002, "level": 9}),
        "v5_0_image_grey_u8": (
            "image",
            grey.astype(np.uint8),
            {"quality": 40.0, "format_version": (5, 0)},
        ),
        # Format 6.0 (the curve layout with block checks in chunks of more than one code-block):
        # the default curve (every chunk of one block: laid out as 5.0), and a float32 series
        # of 33 000 points at one level whose two chunks have two blocks each (float32 keeps
        # its decoded array small enough to commit).
        "v6_0_curve_default": ("curve", open_curve, {}),
        "v6_0_curve_series_two_blocks": (
            "curve",
            (np.sin(40 * np.linspace(0, 1, 33_000)) * np.linspace(0, 1, 33_000)).astype(np.float32),
            {"level": 1, "tolerance": 1e-3},
        ),
        # Format 3.1 (3.0's layout without chunk lengths, the chunks delimiting themselves, said
        # by coder code 3; the header's quantizer code 3 derives the weights from the plan,
        # storing only pinned ones and a check byte; rewritten on 2026-11-28 before 3.1's
        # release, when the lengths went), and a lossless picture (coder code 3 alone):
        # a grey picture whose finest bands
        # span several blocks, colour at a set rate, a surface, and a picture one of whose
        # weights is not the plan's (its approximation's, one up in the last digit), so that
        # it is pinned.
        "v3_1_image_rgba_u16_lossless": ("image", rgba16, {"lossless": True}),
        "v3_1_image_grey_u8_blocks": ("image", blocks_picture, {"quality": 38.0}),
        # (At 6 bpp this picture now fits losslessly: 4 keeps it lossy.)
        "v3_1_image_rgb_u8_bpp": ("image", rgb.clip(0, 255).astype(np.uint8), {"bpp": 4.0}),
        "v3_1_surface_closed_open": ("surface", surface, {"closed": (True, False)}),
        "v3_1_image_grey_u8_pinned": (
            "image",
            grey.astype(np.uint8),
            {"quality": 40.0, "nudge_weight": True},
        ),
        # Format 7.0 (a picture enlarged by pixel replication: its source's bundle behind a
        # 7-byte wrapper naming the factor): the 2× enlargement of a random picture, lossy and
        # lossless, and a colour picture enlarged 4× at a set rate.
        "v7_0_image_grey_u8_replicated": ("image", repeated, {"quality": 40.0}),
        "v7_0_image_grey_u8_replicated_lossless": ("image", repeated, {"lossless": True}),
        "v7_0_image_rgb_u8_replicated_bpp": (
            "image",
            np.kron(rgb.clip(0, 255).astype(np.uint8)[:16, :24], np.ones((4, 4, 1), np.uint8)),
            {"bpp": 0.4},
        ),
        # Format 1.2 (the JSON header with ``scale``), written by the 1.x writer that
        # ``write_bundle(..., version=(1, 1))`` keeps: no earlier golden bundle had it.
        "surface_scaled_v1_2": (
            "surface",
            surface * 1e300,
            {"quality": 40.0, "format_version": (1, 1)},
        ),
    }


def main() -> None:
    replace = set(sys.argv[sys.argv.index("--replace") + 1 :]) if "--replace" in sys.argv else set()
    path = HERE / "MANIFEST.json"
    manifest: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    encoders = {
        "image": wavecore.encode_image,
        "curve": wavecore.encode_curve,
        "surface": wavecore.encode_surface,
    }
    for name, (kind, data, kwargs) in inputs().items():
        if name in manifest and name not in replace:
            continue
        options = {k: v for k, v in kwargs.items() if k not in ("format_version", "nudge_weight")}
        bundle = encoders[kind](data, **options)
        if kwargs.get("nudge_weight"):  # a weight the plan does not give: 3.1 pins it
            parsed = read_bundle(bundle)
            weights = parsed.header["qparams"]["weights"]
            weight = weights[0][0]
            weights[0][0] = float(f"{weight + 10 ** (math.floor(math.log10(weight)) - 3):.4g}")
            chunks = [parsed.chunk(i) for i in range(len(parsed.chunks))]
            bundle = write_bundle(parsed.header, chunks)
        if "format_version" in kwargs:  # the same bundle in an older format
            parsed = read_bundle(bundle)
            chunks = [parsed.chunk(i) for i in range(len(parsed.chunks))]
            bundle = write_bundle(parsed.header, chunks, version=kwargs["format_version"])
        decoded = wavecore.decode(bundle)
        (HERE / f"{name}.wvb").write_bytes(bundle)
        np.save(HERE / f"{name}.npy", decoded, allow_pickle=False)
        info = wavecore.inspect(bundle)
        manifest[name] = {
            "sha256": hashlib.sha256(bundle).hexdigest(),
            "bytes": len(bundle),
            "version": info["version"],
            "kind": kind,
            "arguments": {k: list(v) if isinstance(v, tuple) else v for k, v in kwargs.items()},
            "lossless": info["lossless"],
            "coder": info["coder"],
            "cparams": info["header"]["cparams"],
            "lifting": info["header"].get("lifting"),
            "quantizer": info["quantizer"],
        }
        print(f"{name}: {len(bundle)} bytes, {info['coder']}, psnr {info['psnr']}")
    path.write_text(json.dumps(manifest, indent=2) + "\n")


if __name__ == "__main__":
    main()
