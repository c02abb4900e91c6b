"""The decoder fuzz as a program: ``python tests/fuzz_decoder.py --cases 20000 --seed 0``.

Run by ``tests/test_bundle_fuzz_boundscheck.py`` in a subprocess with ``NUMBA_BOUNDSCHECK=1``
and an empty numba cache (numba reads the flag at import, and a cached kernel compiled without
it would not check), so that every index a compiled kernel reads out of bounds raises instead
of reading memory.

Every kind of bundle (grey, colour, RGBA, lossless 8/16-bit, curves open and closed, surfaces,
huge floats in the scaled domain, and every golden bundle in ``tests/golden``) is mutated in a
seeded loop: byte flips (CRCs left as they are, or recomputed as an attacker would),
truncations, inserted and deleted bytes, chunk damage behind valid CRCs, and header edits
(values replaced, removed, nudged, chunk tables reshuffled), written as format 1.1 JSON,
3.0 or 4.0 binary headers (4.0: weights derived or stored), and binary header bytes damaged
behind valid CRCs (huge varints, cut fields).  Each mutant is decoded at a random level, with
and without ``keep``, and inspected.
Acceptable outcomes: an array, a ``BundleError``, or an ``InvalidParameter`` for a level
deeper than the (crafted) bundle says it has.  A ``BundleError`` that wraps an ``IndexError``
(an out-of-bounds access the checks missed, caught only by the decoder's last line of
defence) counts as a failure too.

It prints one JSON line: the counts of each outcome, and the first failures.
"""

from __future__ import annotations

import argparse
import binascii
import json
import random
import struct
import sys
import time
import zlib
from pathlib import Path
from typing import Any

import numpy as np

import wavecore
from wavecore import BundleError, InvalidParameter, binheader
from wavecore.bundle import COMPACT_MAGIC, MAGIC, chunk_groups, deflate_header, read_bundle
from wavecore.codec import replication

GOLDEN = Path(__file__).parent / "golden"


def bundles() -> dict[str, bytes]:
    """Real bundles of every kind, small enough that a case costs milliseconds."""
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:22, 0:19]
    grey = (120 + 60 * np.sin(x / 3) * np.cos(y / 4) + rng.normal(0, 4, x.shape)).clip(0, 255)
    grey8 = grey.astype(np.uint8)
    rgb = np.stack([grey8, grey8[::-1], np.roll(grey8, 5, axis=1)], axis=-1)
    rgba = np.dstack([rgb, np.full(grey8.shape, 255, np.uint8)])
    rgba16 = (rgba.astype(np.uint16) * 257) ^ rng.integers(0, 64, rgba.shape, dtype=np.uint16)
    t = np.linspace(0, 2 * np.pi, 37, endpoint=False)
    curve = np.stack([np.cos(t), np.sin(2 * t), 0.1 * t], axis=1)
    grid = np.stack([np.add.outer(np.arange(12.0), np.zeros(10)), rng.random((12, 10))], -1)
    made = {
        "grey lossy": wavecore.encode_image(grey8, level=2, quality=30),
        "grey float haar keep": wavecore.encode_image(grey / 255, wavelet="haar", keep=0.4),
        "rgb bpp": wavecore.encode_image(rgb, bpp=12.0),
        "rgba opaque": wavecore.encode_image(rgba, quality=33),
        "grey cdf97": wavecore.encode_image(grey8, wavelet="cdf97", quality=35),
        "lossless grey": wavecore.encode_image(grey8, lossless=True, level=2),
        "lossless rgba16": wavecore.encode_image(rgba16, lossless=True),
        "curve closed": wavecore.encode_curve(curve, closed=True, level=2, tolerance=0.01),
        "curve open haar": wavecore.encode_curve(curve[:, :2], wavelet="haar", keep=0.5),
        "series": wavecore.encode_curve(np.sin(t * 3), tolerance=0.02),
        "surface": wavecore.encode_surface(grid, closed=(True, False), level=1, quality=30),
        "height field": wavecore.encode_surface(grid[..., 1], wavelet="haar", quality=35),
        "surface 1e300": wavecore.encode_surface(grid * 1e300, quality=30),
        "surface subnormal": wavecore.encode_surface(grid * 1e-315, quality=30),
    }
    for path in sorted(GOLDEN.glob("*.wvb")):
        made[f"golden {path.stem}"] = path.read_bytes()
    return made


def split(data: bytes) -> tuple[dict[str, Any], list[bytes]]:
    if replication.is_replicated(data):  # 7.0: the header and chunks of the source's bundle
        data = replication.unwrap(data)[1]
    parsed = read_bundle(data)
    return json.loads(json.dumps(parsed.header)), [bytes(c or b"") for c in parsed.chunks]


def assemble(header: bytes, chunks: list[bytes], minor: int = 1) -> bytes:
    """A bundle with correct CRCs around whatever header bytes and chunks it is given."""
    packed = deflate_header(header)
    head = struct.pack("<8sBBH", MAGIC, 1, minor, len(packed) % 65536) + packed
    head += bytes([len(chunks) % 256])
    for chunk in chunks:
        head += struct.pack("<II", len(chunk), zlib.crc32(chunk))
    return head + struct.pack("<I", zlib.crc32(head)) + b"".join(chunks)


def _varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    return bytes(out + bytes([value]))


def assemble2(packed: bytes, chunks: list[bytes]) -> bytes:
    """A format 3.0 bundle with correct CRCs around whatever binary header it is given."""
    head = MAGIC + bytes([3, 0]) + _varint(len(packed)) + packed
    head += b"".join(_varint(len(c)) for c in chunks)
    head += b"".join(struct.pack("<H", binascii.crc_hqx(c, 0)) for c in chunks)
    return head + struct.pack("<I", zlib.crc32(head)) + b"".join(chunks)


def assemble4(packed: bytes, chunks: list[bytes]) -> bytes:
    """A format 4.0 bundle with correct CRCs (a CRC-16 per group, the head's CRC-16)."""
    head = COMPACT_MAGIC + bytes([4, 0]) + packed + b"".join(_varint(len(c)) for c in chunks)
    for first, last in chunk_groups([len(c) for c in chunks]):
        head += struct.pack("<H", binascii.crc_hqx(b"".join(chunks[first : last + 1]), 0))
    return head + struct.pack("<H", binascii.crc_hqx(head, 0)) + b"".join(chunks)


def binary(
    header: dict[str, Any], chunks: list[bytes], rng: random.Random, damage: bool = False
) -> bytes:
    """The crafted header as a 3.0 or a 4.0 binary header (4.0: its weights derived or
    stored), its bytes damaged when ``damage``, with valid CRCs; BundleError when the binary
    header cannot say a value."""
    compact = rng.random() < 0.5
    if compact:
        packed = binheader.pack(header, major=4, derived_weights=rng.random() < 0.5)
    else:
        packed = binheader.pack(header)
    if damage:
        if rng.random() < 0.2:  # a huge varint, or a field cut short
            at = rng.randrange(len(packed))
            packed = packed[:at] + rng.choice([b"\xff" * 11, b"\x80\x00", b""]) + packed[at:]
        packed = mutate_bytes(packed, rng)
    return assemble4(packed, chunks) if compact else assemble2(packed, chunks)


def either(header: dict[str, Any], chunks: list[bytes], rng: random.Random) -> bytes:
    """The crafted bundle in format 3.0 or 4.0 (binary header) or 1.1 (JSON), valid CRCs."""
    if rng.random() < 0.5:
        try:
            return binary(header, chunks, rng)
        except BundleError:  # a value the binary header cannot say
            pass
    return assemble(json.dumps(header).encode(), chunks)


JSON_VALUES: list[Any] = [
    None, True, False, 0, 1, -1, 2, 3, 31, 2**31, 2**63, -(2**40), 0.5, -0.0, 1e308, 5e-324,
    "", "x", "open", "closed", "reversible", "legall53", "context", "zlib", "deadzone",
    [], [0], [1, 1], [0, 0], [[0, 0]], [[0, 0], [0, 0]], [2**27, 2], {}, {"coder": "context"},
]  # fmt: skip


def mutate_value(value: Any, rng: random.Random) -> Any:
    roll = rng.random()
    if roll < 0.35:
        return rng.choice(JSON_VALUES)
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + rng.choice([-3, -2, -1, 1, 2, 3, value, -value - 1, 2**20])
    if isinstance(value, float):
        return rng.choice([value * 2, -value, value * 1e-300, value + 1, 0.0])
    if isinstance(value, list) and value:
        copy = list(value)
        i = rng.randrange(len(copy))
        if rng.random() < 0.3:
            del copy[i]
        elif rng.random() < 0.3:
            copy.append(copy[i])
        else:
            copy[i] = mutate_value(copy[i], rng)
        return copy
    if isinstance(value, dict) and value:
        copy = dict(value)
        key = rng.choice(sorted(copy))
        if rng.random() < 0.2:
            del copy[key]
        else:
            copy[key] = mutate_value(copy[key], rng)
        return copy
    return rng.choice(JSON_VALUES)


def mutate_bytes(raw: bytes, rng: random.Random) -> bytes:
    buffer = bytearray(raw)
    for _ in range(rng.randint(1, 4)):
        action = rng.randrange(4)
        position = rng.randrange(len(buffer) + 1) if buffer else 0
        if action == 0 and buffer:
            buffer[min(position, len(buffer) - 1)] ^= 1 << rng.randrange(8)
        elif action == 1 and buffer:
            buffer[min(position, len(buffer) - 1)] = rng.randrange(256)
        elif action == 2:
            buffer[position:position] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        else:
            del buffer[position : position + rng.randint(1, 8)]
    return bytes(buffer)


def mutant(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    header, chunks = split(data)
    kind = rng.randrange(9)
    if kind == 0:  # raw damage, CRCs as they were: the CRCs must catch it
        return "flip", mutate_bytes(data, rng)
    if kind == 1:  # cut anywhere
        return "truncate", data[: rng.randrange(len(data) + 1)]
    if kind == 2:  # a damaged chunk behind a valid CRC: the entropy decoder must cope
        index = rng.randrange(len(chunks))
        chunks[index] = mutate_bytes(chunks[index], rng)
        return "chunk", either(header, chunks, rng)
    if kind in (3, 4):  # a crafted header behind valid CRCs
        for _ in range(rng.randint(1, 3)):
            key = rng.choice(sorted(header))
            if rng.random() < 0.1:
                del header[key]
            else:
                header[key] = mutate_value(header[key], rng)
        if rng.random() < 0.5:
            try:
                return "binary header", binary(header, chunks, rng)
            except BundleError:  # a value the binary header cannot say
                pass
        return "header", assemble(json.dumps(header).encode(), chunks, minor=rng.choice([1, 2]))
    if kind == 5:  # chunks dropped, duplicated, swapped or emptied, levels left as they were
        action = rng.randrange(4)
        i, j = rng.randrange(len(chunks)), rng.randrange(len(chunks))
        if action == 0:
            del chunks[i]
        elif action == 1:
            chunks.insert(i, chunks[j])
        elif action == 2:
            chunks[i], chunks[j] = chunks[j], chunks[i]
        else:
            chunks[i] = b""
        return "table", either(header, chunks, rng)
    if kind in (7, 8):  # binary header bytes damaged behind valid CRCs
        return "binary bytes", binary(header, chunks, rng, damage=True)
    # header bytes that are not JSON, or JSON that is not an object
    text = json.dumps(header).encode()
    return "header bytes", assemble(mutate_bytes(text, rng), chunks)


def run(cases: int, seed: int) -> dict[str, Any]:
    rng = random.Random(seed)
    made = bundles()
    names = sorted(made)
    counts: dict[str, int] = {}
    failures: list[str] = []

    def outcome(label: str) -> None:
        counts[label] = counts.get(label, 0) + 1

    started = time.perf_counter()
    for case in range(cases):
        name = names[case % len(names)]  # every bundle, in turn
        how, data = mutant(made[name], rng)
        level = rng.choice([0, 0, 0, 1, 2])
        keep = rng.choice([None, None, None, 0.5, 0.0])
        try:
            out = wavecore.decode(data, level=level, keep=keep)
            if not isinstance(out, np.ndarray):
                failures.append(f"{name} {how}: decode returned {type(out).__name__}")
            outcome("array")
        except BundleError as exc:
            cause = exc.__cause__
            if isinstance(cause, IndexError):  # caught only by the last line of defence
                failures.append(f"{name} {how}: out of bounds: {cause}")
            # The decoder's last line of defence: an error no check foresaw, as BundleError.
            fallback = str(exc).startswith(("corrupt bundle:", "header: inconsistent fields"))
            outcome(f"fallback {type(cause).__name__}" if fallback else "BundleError")
        except InvalidParameter as exc:
            if "deeper than the bundle" not in str(exc):
                failures.append(f"{name} {how}: InvalidParameter: {exc}")
            outcome("level too deep")
        except Exception as exc:  # what the fuzz is looking for
            failures.append(f"{name} {how}: {type(exc).__name__}: {exc}"[:300])
            outcome("other " + type(exc).__name__)
        try:
            wavecore.inspect(data)
        except BundleError:
            pass
        except Exception as exc:
            failures.append(f"{name} {how} inspect: {type(exc).__name__}: {exc}"[:300])
    return {
        "cases": cases,
        "bundles": len(names),
        "seconds": round(time.perf_counter() - started, 1),
        "outcomes": counts,
        "failures": len(failures),
        "first_failures": failures[:20],
    }


def boundscheck_is_on() -> bool:
    """Whether numba raises on an out-of-bounds index here (NUMBA_BOUNDSCHECK=1)."""
    from numba import njit

    @njit
    def read(a: np.ndarray, i: int) -> float:
        return a[i]

    try:
        read(np.zeros(3), 5)
    except IndexError:
        return True
    return False


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=20000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    report = run(args.cases, args.seed)
    report["boundscheck"] = boundscheck_is_on()
    print(json.dumps(report))
    return 1 if report["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
