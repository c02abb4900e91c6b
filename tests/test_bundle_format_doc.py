"""The worked example of docs/bundle-format.md ("Inspecting a bundle") is what the code gives.

The example's text is generated here from the code's own output and compared with the file:
when the format or the coder changes, this test fails and
``python tests/test_bundle_format_doc.py`` rewrites the example (then review the diff).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

import wavecore

DOC = Path(__file__).resolve().parents[1] / "docs" / "bundle-format.md"
BEGIN = "<!-- worked example: written by tests/test_bundle_format_doc.py -->"
END = "<!-- end of the worked example -->"
SUMMARY_KEYS = ("version", "kind", "shape", "levels", "coder", "psnr", "total_bytes")
SUMMARY_KEYS += ("header_bytes", "bpp")


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
    # Five levels, as the lossy bundle (without a level, lossless bundles keep 2 or 3).
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


def _current() -> str:
    text = DOC.read_text(encoding="utf-8")
    match = re.search(re.escape(BEGIN) + r"\n(.*?)\n" + re.escape(END), text, re.S)
    assert match, f"{DOC} has lost its worked-example markers ({BEGIN} … {END})"
    return match.group(1)


def test_the_worked_example_matches_the_code() -> None:
    expected = render()
    assert _current() == expected, (
        "docs/bundle-format.md's worked example no longer matches the code: run "
        "`python tests/test_bundle_format_doc.py` to rewrite it, and review the diff"
    )


if __name__ == "__main__":
    text = DOC.read_text(encoding="utf-8")
    start = text.index(BEGIN) + len(BEGIN) + 1
    end = text.index(END)
    DOC.write_text(text[:start] + render() + "\n" + text[end:], encoding="utf-8")
    print(f"rewrote the worked example in {DOC}", file=sys.stderr)
