"""The worked examples of docs/bundle-format.md are what the code gives: "Inspecting a bundle"
(an image, format 3.1) and the 6.0 curve taken apart byte by byte.

The examples' text is generated here from the code's own output and compared with the file:
when the format or the coder changes, this test fails and
``python tests/test_bundle_format_doc.py`` rewrites the examples (then review the diff).
The curve's bytes are split into fields by a reader written here from the specification, not
by the library's, so the example also checks that the bytes are laid out as documented.
"""

from __future__ import annotations

import binascii
import re
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

import wavecore

DOC = Path(__file__).resolve().parents[1] / "docs" / "bundle-format.md"
BEGIN = "<!-- worked example: written by tests/test_bundle_format_doc.py -->"
END = "<!-- end of the worked example -->"
SUMMARY_KEYS = ("version", "kind", "shape", "levels", "coder", "psnr", "total_bytes")
SUMMARY_KEYS += ("header_bytes", "bpp")
CURVE_BEGIN = "<!-- curve example: written by tests/test_bundle_format_doc.py -->"
CURVE_END = "<!-- end of the curve example -->"


def _varint(data: bytes, at: int) -> int:
    """Where the LEB128 varint at ``at`` ends."""
    while data[at] & 0x80:
        at += 1
    return at + 1


def _number(data: bytes, at: int) -> int:
    """Where the 4.0 *number* at ``at`` ends: a varint, then 4 (form 13), 8 (form 14) or a
    varint exponent (form 11)."""
    end = _varint(data, at)
    value, shift = 0, 0
    for byte in data[at:end]:
        value |= (byte & 0x7F) << shift
        shift += 7
    form = value & 15
    extra = {13: 4, 14: 8}.get(form, 0)
    return _varint(data, end) if form == 11 else end + extra


def curve_fields(bundle: bytes) -> list[tuple[str, bytes]]:
    """A 6.0 curve bundle (laid out as 5.0: its chunks are of one block) with no pads,
    extension or scale, split into its documented fields
    (the chunks: their table of block lengths, then the coded block)."""
    assert bundle[:4] == b"\x89W\x06\x00"
    fields = [("preamble: magic `89 57`, major 6, minor 0", bundle[:4])]
    flags = bundle[4:8]
    assert flags[1] >> 6 == 0 and not flags[3] >> 6 & 1 and not flags[2] >> 7  # the simple case
    fields.append(("flags (4 bytes)", flags))
    at = 8
    names = ["`levels`", "`shape` (n)", "`shape` (d)"]
    for name in names:
        end = _varint(bundle, at)
        fields.append((name, bundle[at:end]))
        at = end
    end = _number(bundle, at)
    fields.append(("`peak`, a number", bundle[at:end]))
    at = end
    step = 4 if flags[3] >> 4 & 1 else 8
    fields.append((f"`step`, a float{8 * step}", bundle[at : at + step]))
    at += step
    assert flags[1] >> 5 & 1 and flags[3] >> 7 and flags[3] >> 5 & 1  # derived, defaults
    end = _varint(bundle, at)
    fields.append(("`psnr` (`P`)", bundle[at:end]))
    at = end
    end = _number(bundle, at)
    fields.append(("`max_error`, a number", bundle[at:end]))
    at = end
    levels = bundle[8]
    assert levels == 1  # two chunks: two groups of one chunk each
    info = wavecore.inspect(bundle)
    sizes = [c["bytes"] for c in info["chunks"]]
    starts = [len(bundle) - sum(sizes), len(bundle) - sizes[1]]
    for index, start in enumerate(starts):
        crc = binascii.crc_hqx(bundle[start : start + sizes[index]], 0)
        fields.append((f"CRC-16 of group {index} (chunk {index})", bundle[at : at + 2]))
        assert struct.unpack("<H", bundle[at : at + 2])[0] == crc
        at += 2
    fields.append(("head check: CRC-16 of all the above", bundle[at : at + 2]))
    assert struct.unpack("<H", bundle[at : at + 2])[0] == binascii.crc_hqx(bundle[:at], 0)
    at += 2
    assert at == info["header_bytes"] == starts[0]
    for index, size in enumerate(sizes):
        end = _varint(bundle, at)
        length = bundle[at] if end == at + 1 else None
        assert length is not None and end - at + length == size  # the table delimits it
        fields.append(
            (f"chunk {index}: its one block's length (the coder's table)", bundle[at:end])
        )
        fields.append((f"chunk {index}: the block, {length} bytes", bundle[end : end + length]))
        at = end + length
    assert at == len(bundle)
    return fields


def render_curve() -> str:
    """The 8-point curve of benchmarks/header_sizes.py, field by field."""
    t8 = np.linspace(0, 1, 8)
    bundle = wavecore.encode_curve(np.stack([t8, np.sin(3 * t8)], 1))
    info = wavecore.inspect(bundle)
    lines = [
        "| bytes | hex | field |",
        "|---:|---|---|",
    ]
    for name, raw in curve_fields(bundle):
        shown = raw.hex(" ") if len(raw) <= 8 else raw[:6].hex(" ") + " …"
        lines.append(f"| {len(raw)} | `{shown}` | {name} |")
    header = info["header"]
    lines += [
        "",
        f"{info['header_bytes']} bytes besides the {len(bundle) - info['header_bytes']} of its "
        f"{info['levels'] + 1} chunks ({len(bundle)} in all); the header says `peak` "
        f"{header['peak']!r}, `step` "
        f"{header['qparams']['step']!r} (a float32), `psnr` {header['psnr']!r}, `max_error` "
        f"{header['max_error']!r}, and the weights {header['qparams']['weights']!r} "
        "come from the plan.",
    ]
    return "\n".join(lines)


def _percent(part: int, whole: int) -> str:
    """Two significant digits: 53, 24, 2.5, 0.4."""
    value = 100 * part / whole
    return f"{float(f'{value:.2g}'):g}"


def _needed(info: dict, k: int) -> int:
    """Bytes that decode(level=k) reads: everything but the chunks, then chunks 0 … L − k."""
    chunks = info["chunks"][: info["levels"] - k + 1]
    return int(info["header_bytes"]) + sum(int(c["bytes"]) for c in chunks)


def render() -> str:
    """The example, from the code: camera at 0.5 bpp, then the bytes each level needs."""
    data = pytest.importorskip("skimage.data", reason="the example codes scikit-image's camera")
    camera = data.camera()
    info = wavecore.inspect(wavecore.encode_image(camera, wavelet="bspline2", bpp=0.5))
    summary = repr({k: info[k] for k in SUMMARY_KEYS})
    summary = summary.replace(", 'psnr'", ",\n 'psnr'")
    chunks = repr(info["chunks"][:2]).replace("}, {", "},\n {")
    keys = ", ".join(f'"{k}"' for k in SUMMARY_KEYS)
    lines = [
        "```python",
        ">>> info = wavecore.inspect("
        'wavecore.encode_image(data.camera(), wavelet="bspline2", bpp=0.5))',
        f">>> {{k: info[k] for k in ({keys})}}",
        summary,
        '>>> info["chunks"][:2]',
        chunks,
        "```",
        "",
        "`header_bytes` counts everything but the chunks (preamble, header, chunk table, CRCs). "
        "How",
        "much of a bundle each resolution needs, for camera coded at 1 bpp and losslessly:",
        "",
        "| `decode(level=k)` | shape | bytes needed (1 bpp) | bytes needed (lossless) |",
        "|---|---|---:|---:|",
    ]
    lossy = wavecore.encode_image(camera, bpp=1.0)
    # Five levels, as the lossy bundle (without a level, the lossless coder codes 0 or 1).
    exact = wavecore.encode_image(camera, lossless=True, level=5)
    lossy_info, exact_info = wavecore.inspect(lossy), wavecore.inspect(exact)
    for k in (0, 1, 2, 3, 5):
        shapes = []
        for bundle in (lossy, exact):
            shape = wavecore.decode(bundle, level=k).shape
            shapes.append(" × ".join(str(s) for s in shape))
        if k == 0:
            cells = ["100 %", "100 %"]
        else:
            cells = [
                f"about {_percent(_needed(i, k), int(i['total_bytes']))} %"
                for i in (lossy_info, exact_info)
            ]
        second = f"lossless {shapes[1]}" if k == 0 else shapes[1]
        lines.append(f"| {k} | {shapes[0]} ({second}) | {cells[0]} | {cells[1]} |")
    return "\n".join(lines)


def test_the_bytes_needed_per_level_are_what_decode_reads() -> None:
    """The table's claim, checked on its own: the first ``_needed(k)`` bytes decode at level
    ``k``, and one byte fewer does not."""
    data = pytest.importorskip("skimage.data", reason="the example codes scikit-image's camera")
    bundle = wavecore.encode_image(data.camera()[:256, :256], bpp=1.0)
    info = wavecore.inspect(bundle)
    for k in (1, 2, 3):
        needed = _needed(info, k)
        assert (
            wavecore.decode(bundle[:needed], level=k).shape
            == wavecore.decode(bundle, level=k).shape
        )
        with pytest.raises(wavecore.BundleError):
            wavecore.decode(bundle[: needed - 1], level=k)


def _current(begin: str = BEGIN, end: str = END) -> str:
    text = DOC.read_text(encoding="utf-8")
    match = re.search(re.escape(begin) + r"\n(.*?)\n" + re.escape(end), text, re.S)
    assert match, f"{DOC} has lost its worked-example markers ({begin} … {end})"
    return match.group(1)


def test_the_worked_example_matches_the_code() -> None:
    expected = render()
    assert _current() == expected, (
        "docs/bundle-format.md's worked example no longer matches the code: run "
        "`python tests/test_bundle_format_doc.py` to rewrite it, and review the diff"
    )


def test_the_curve_example_matches_the_code() -> None:
    assert _current(CURVE_BEGIN, CURVE_END) == render_curve(), (
        "docs/bundle-format.md's 5.0 curve example no longer matches the code: run "
        "`python tests/test_bundle_format_doc.py` to rewrite it, and review the diff"
    )


def _rewrite(text: str, begin: str, end: str, body: str) -> str:
    start = text.index(begin) + len(begin) + 1
    return text[:start] + body + "\n" + text[text.index(end) :]


if __name__ == "__main__":
    text = DOC.read_text(encoding="utf-8")
    text = _rewrite(text, BEGIN, END, render())
    text = _rewrite(text, CURVE_BEGIN, CURVE_END, render_curve())
    DOC.write_text(text, encoding="utf-8")
    print(f"rewrote the worked examples in {DOC}", file=sys.stderr)
