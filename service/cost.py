"""What a request will cost, computed before the work starts, and the 413 when it is too much.

The cost of a request is the number of samples the library will hold while coding it: the
input's values after the padding (or re-sampling) that its ``level`` implies, times its
channels or coordinates.  Every endpoint's memory is a small constant per such sample
(docs/deploy.md, "Memory per request", measures it), so bounding the samples bounds the memory
and the time of any request, whatever its shape: a 4 KB PNG of 1 × 4 194 304 pixels is padded
to 8 rows for one level, 33 554 432 samples, and is refused here before a pixel is decoded.

The limit is :data:`SAMPLES_PER_PIXEL` × ``WAVECORE_MAX_PIXELS``: the largest image the server
accepts anyway (4 channels) with room for its padding, so no request that was served before is
refused, and one request's working memory stays within the budget of docs/deploy.md.

The helpers mirror how ``wavecore``'s codec chooses its default level and pads (public
``valid_length`` and ``fitting_length``); if they drift, the check only becomes a little looser
or tighter, and the codec's own checks still hold.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import wavecore
from wavecore.codec.choice import AUTO, AUTO_CANDIDATES
from wavecore.codec.plan import level_arg

from .errors import Problem
from .settings import Settings

#: Working samples allowed per pixel of ``WAVECORE_MAX_PIXELS``: 4 channels, plus a quarter
#: for the padding of a large image to a length that fits its levels.
SAMPLES_PER_PIXEL = 5

#: A curve file (GeoJSON, SVG) is coded as one curve set, whose cost is its time, not its
#: memory: both of its forms are searched curve by curve (the vertex form's optimal
#: simplification, some 90 µs a 2-D point; the wavelet form's step search, in closed loop;
#: 6 ms a curve of 2 points, 17-26 ms one of 30-100; benchmarks/curves.py ``--set-cost``).  A
#: point counts this many samples and a curve this many more: at most about 1 µs a counted
#: sample, so the largest set accepted takes some 20 s, as long as the slowest requests of the
#: other endpoints.  Counted by memory alone, a GeoJSON of 20 000 triangles (1.6 MB) passed,
#: and took 146 s: a worker held until the request timeout.
CURVE_SET_POINT_SAMPLES = 100
CURVE_SET_CURVE_SAMPLES = 16384
#: Samples each curve of a curve-set bundle counts when it is reconstructed, besides its points:
#: a 258-byte bundle of 1,048,576 one-point curves took 1.3 s to decode and 12 s and 1.5 GB to
#: write as SVG (some 12 µs and 1.4 kB a curve; 5 s as JSON, 7 s as GeoJSON).
CURVE_DECODE_CURVE_SAMPLES = 64
#: And each byte of its metadata's JSON: parsed, then written out again, a byte of ``{},``
#: takes some 32 bytes (a 29 kB bundle with 31 MB of empty objects took 1.0 GB to
#: reconstruct), about half a sample of the codec's working memory.
CURVE_METADATA_SAMPLES_PER_BYTE = 1

#: Working values per coordinate of a detail transfer: the local frames (``d × d`` per point)
#: and the three reconstructions per level hold about 4 times what a codec pass holds
#: (benchmarks/request_memory.py: 284 B per coordinate against the codec's 47–63 B).
TRANSFER_FACTOR = 4

#: Working values per curve point and coordinate: the quantizer's closed loop keeps per-point
#: state beside the coordinates (benchmarks/request_memory.py at 200 000 points: 577 B per point
#: in 1-D, 909 B in 3-D), so a point of ``d`` coordinates counts ``4 (d + 1)`` samples.
CURVE_FACTOR = 4

#: Samples each plane of a bundle counts when its context coder is one of the legacy versions
#: that still decode (2 and 3): they decode plane by plane in Python, some 35-65 µs a plane,
#: the time a picture's decode takes for about a thousand samples (40-80 ns each).  A volume
#: is a plane per slice and band: a crafted bundle of 327,680 slices of 1 × 1 (240 KB), which
#: the samples alone let through, took 37 s to decode (later versions: 4 µs a slice).
LEGACY_PLANE_SAMPLES = 1024
LEGACY_CODER_VERSIONS = (2, 3)

#: The codec's deepest default levels (``most`` of ``wavecore.default_level``).
DEFAULT_MOST_LEVELS = {"image": 5, "surface": 5, "curve": 8}


def sample_limit(settings: Settings) -> int:
    """The most samples one request may code (``SAMPLES_PER_PIXEL × max_pixels``)."""
    return SAMPLES_PER_PIXEL * settings.max_pixels


def check(samples: int, what: str, settings: Settings) -> None:
    """Refuse with 413 ``too-costly`` when ``samples`` is over the limit.

    >>> try:
    ...     check(12, "a 3 × 4 grid", Settings(max_pixels=2))
    ... except Problem as problem:
    ...     print(problem.status, problem.detail.replace("; ", ";\\n"))
    413 a 3 × 4 grid means coding 12 samples;
    this server codes at most 10 in one request (5 × WAVECORE_MAX_PIXELS)
    """
    limit = sample_limit(settings)
    if samples > limit:
        msg = (
            f"{what} means coding {samples} samples; this server codes at most {limit} "
            f"in one request ({SAMPLES_PER_PIXEL} × WAVECORE_MAX_PIXELS)"
        )
        raise Problem("too-costly", msg)


def _default_level(sizes: Sequence[int], most: int) -> int:
    # The codec's own rule (the library's one default-level rule), not a copy of it.
    return wavecore.default_level(sizes, most)


def padded_lengths(
    sizes: Sequence[int],
    level: int | None,
    boundaries: Sequence[str],
    wavelet: str,
    kind: str,
) -> tuple[list[int], int]:
    """The lengths the codec pads ``sizes`` to for ``level`` (its default when ``None``).

    A length the codec would refuse to pad (beyond ``2 n + 64``) counts as that bound: the
    codec answers those with its own 422, which names the level.

    >>> padded_lengths([1, 4_194_304], None, ["open", "open"], "bspline2", "image")
    ([8, 4194304], 1)

    (one level of the open B-spline needs ``2 k + 2`` samples with ``k >= 3``: one row
    becomes 8; 4 194 304 is already of that form.)
    """
    if level is None:
        level = _default_level(sizes, DEFAULT_MOST_LEVELS[kind])
    elif level > 30:
        level_arg(level)  # the codec's own 422, naming the level sent, before any work
    fitted = [
        min(wavecore.valid_length(n, level, b, wavelet), 2 * n + 64)
        for n, b in zip(sizes, boundaries, strict=True)
    ]
    return fitted, level


def check_image(
    width: int, height: int, bands: int, options: dict[str, Any], settings: Settings
) -> None:
    """The cost of encoding a ``width × height`` image of ``bands`` channels."""
    if options.get("lossless"):
        fitted = [height, width]  # the reversible 5/3 lifting fits every size, unpadded
    else:
        wavelet = options.get("wavelet", AUTO)
        # "auto" codes with one of its candidates: count the one that pads more.
        fitted = [0, 0]
        for name in AUTO_CANDIDATES if wavelet == AUTO else (wavelet,):
            padded, _ = padded_lengths(
                [height, width], options.get("level"), ["open", "open"], name, "image"
            )
            fitted = [max(a, b) for a, b in zip(fitted, padded, strict=True)]
    samples = fitted[0] * fitted[1] * bands
    what = f"a {width} × {height} image with {bands} channel{'s' * (bands > 1)}"
    if fitted != [height, width]:
        what += f", padded to {fitted[1]} × {fitted[0]} for its levels,"
    check(samples, what, settings)


def check_grid(
    shape: Sequence[int], closed: Sequence[bool], level: int | None, settings: Settings
) -> None:
    """The cost of encoding a surface grid ``(U, V[, d])``."""
    boundaries = ["closed" if c else "open" for c in closed]
    fitted, _ = padded_lengths(list(shape[:2]), level, boundaries, "bspline2", "surface")
    dims = shape[2] if len(shape) > 2 else 1
    check(fitted[0] * fitted[1] * dims, f"a {shape[0]} × {shape[1]} grid", settings)


def curve_set_samples(points: int, curves: int) -> int:
    """What a curve set of ``curves`` curves and ``points`` points in all counts (see
    :data:`CURVE_SET_POINT_SAMPLES`)."""
    return CURVE_SET_POINT_SAMPLES * points + CURVE_SET_CURVE_SAMPLES * curves


def check_curve(
    n: int, dims: int, closed: bool, level: int | None, wavelet: str, settings: Settings
) -> None:
    """The cost of encoding a curve of ``n`` points of ``dims`` coordinates."""
    boundary = "closed" if closed else "open"
    fitted, _ = padded_lengths([n], level, [boundary], wavelet, "curve")
    check(CURVE_FACTOR * fitted[0] * (dims + 1), f"a curve of {n} points", settings)


def check_transfer(n: int, dims: int, closed: bool, level: int | None, settings: Settings) -> None:
    """Bound ``level`` by what ``source`` holds (422), then the cost of the transfer (413).

    ``transfer_details`` re-samples ``source`` to a length that fits ``level`` levels, about
    ``2**level`` times a few points however short the source: a 100-byte body with ``level``
    30 would ask for billions of points.  Like the codec's padding, the re-sampled length may
    be at most ``2 n + 64``.
    """
    if level is None:
        check(TRANSFER_FACTOR * n * dims, f"transferring the details of {n} points", settings)
        return
    boundary = "closed" if closed else "open"
    bound = 2 * n + 64

    def fits(lvl: int) -> bool:
        # The library refuses a level whose fitting length would pass its own growth limit.
        try:
            return wavecore.fitting_length(n, lvl, boundary) <= bound
        except wavecore.InvalidParameter:
            return False

    if not fits(level):
        deepest = 0
        while deepest < 30 and fits(deepest + 1):
            deepest += 1
        # a transfer needs one level at least (the library refuses level 0)
        offer = f"give a level from 1 to {deepest}" if deepest else "no level fits it"
        msg = (
            f"level {level} is too deep for a source of {n} points: it would re-sample it past "
            f"{bound} points; {offer}"
        )
        errors = [{"loc": ["body", "level"], "msg": msg, "type": "less_than_equal"}]
        raise Problem("invalid-parameter", msg, errors=errors)
    m = wavecore.fitting_length(n, level, boundary)
    what = f"transferring the details of {n} points re-sampled to {m} for {level} levels"
    check(TRANSFER_FACTOR * m * dims, what, settings)


def check_bundle(info: dict[str, Any], settings: Settings) -> None:
    """The cost of decoding a bundle, from what its header declares (its padded ``fitted``)."""
    header = info.get("header") or {}
    declared = header.get("fitted") or info.get("shape") or []
    try:
        sizes = [int(s) for s in declared]
    except (TypeError, ValueError):
        sizes = [int(s) for s in info.get("shape", [])]
    samples = math.prod(max(s, 0) for s in sizes)
    shape = " × ".join(str(s) for s in sizes)
    what = f"a bundle that decodes {shape} samples"
    cparams = header.get("cparams") or {}
    if cparams.get("coder") == "context" and cparams.get("version") in LEGACY_CODER_VERSIONS:
        planes = _planes(info.get("chunks") or [], bool(cparams.get("two_d", True)))
        samples += LEGACY_PLANE_SAMPLES * planes
        what += f" in {planes} planes of context coder version {cparams['version']}"
    check(samples, what, settings)


def _planes(chunks: Sequence[dict[str, Any]], two_d: bool) -> int:
    """The planes the block coder codes for a bundle's chunks (from ``inspect``): one per band
    and channel (a 2-D band's axes past its second, a 1-D band's past its first)."""
    planes = 0
    for chunk in chunks:
        for shape in chunk.get("shapes") or []:
            tail = shape[2:] if two_d and len(shape) >= 2 else shape[1:]
            planes += math.prod(max(int(n), 0) for n in tail)
    return planes


def check_grid_data(shape: Sequence[int], level: int | None, settings: Settings) -> None:
    """The cost of encoding a height field ``(H, W)`` or a volume ``(D, H, W)`` as a grid.

    A volume's slices are coded together (``D`` values per point of the 2-D transform), and
    the outlier pass and NaN fill hold a few more arrays of the grid's size: counted as twice
    the padded samples.
    """
    rows, cols = (shape[-2], shape[-1]) if len(shape) == 3 else (shape[0], shape[1])
    slices = shape[0] if len(shape) == 3 else 1
    fitted, _ = padded_lengths([rows, cols], level, ["open", "open"], "cdf97", "surface")
    size = "×".join(str(s) for s in shape)
    check(2 * fitted[0] * fitted[1] * slices, f"a {size} grid", settings)
