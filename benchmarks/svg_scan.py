"""What reading an SVG document costs, against what ``scan_svg`` estimates before the parse.

``wavecore.io.svg.read_svg`` hands the document to svgelements, which parses all of it (every
``<use>`` expanded) before the first point is known.  The service checks the estimate of
``wavecore.io.svg.scan_svg`` (a pass of the standard library's XML parser and regular
expressions) against its sample budget before that parse, at a microsecond a sample.  This
script times both on documents of one kind of content each (20 000 segments, points or
elements by default, ``--count``) and prints, per kind:

* the scan's time, and ``read_svg``'s (default tolerance, as the service calls it): medians of
  ``--rounds`` interleaved rounds;
* the scan's estimate, and its ratio to the read's time (above 1: the estimate is on the
  safe side);
* the points and curves the scan promises at least, and what the read gave.

Run ``.venv/bin/python benchmarks/svg_scan.py``.  The figures are quoted in
docs/benchmarks.md ("What reading an SVG costs").
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from wavecore.errors import InvalidParameter
from wavecore.io.svg import read_svg, scan_svg

_HEAD = '<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink">'


def _path(segment: str, count: int) -> str:
    return f'{_HEAD}<path d="M0 0 {segment * count}"/></svg>'


def _uses(count: int) -> str:
    """``count`` paths drawn by ``<use>`` elements of ten groups of ten of one path."""
    groups = max(count // 100, 1)
    cell = '<path id="p" d="M0 0 l1 1"/>'
    tens = "".join(f'<use xlink:href="#p" x="{j}"/>' for j in range(10))
    hundreds = "".join(f'<use xlink:href="#t" y="{j}"/>' for j in range(10))
    body = "".join(f'<use xlink:href="#h" x="{100 * j}"/>' for j in range(groups))
    return f'{_HEAD}<defs>{cell}<g id="t">{tens}</g><g id="h">{hundreds}</g></defs>{body}</svg>'


KINDS: dict[str, Callable[[int], str]] = {
    "lines (l)": lambda n: _path("l1 1 ", n),
    "implicit lines": lambda n: _path("1 1 ", n),
    "horizontal (h)": lambda n: _path("h1 ", n),
    "quadratics (q)": lambda n: _path("q1 1 2 2 ", n),
    "cubics (c)": lambda n: _path("c1 1 2 2 3 3 ", n),
    "smooth cubics (s)": lambda n: _path("s1 1 2 2 ", n),
    "arcs (a)": lambda n: _path("a5 5 0 1 1 3 3 ", n),
    "packed arcs": lambda n: _path("a" + "5 5 0 113 3 " * n, 1),
    "polyline points": lambda n: (
        f'{_HEAD}<polyline points="' + " ".join(f"{i} {i % 7}" for i in range(n)) + '"/></svg>'
    ),
    "paths of one line": lambda n: (
        _HEAD + "".join(f'<path d="M{i} 0 l1 1"/>' for i in range(n)) + "</svg>"
    ),
    "circles (n / 10)": lambda n: (
        _HEAD + "".join(f'<circle cx="{i}" r="2"/>' for i in range(n // 10)) + "</svg>"
    ),
    "rects (n / 10)": lambda n: (
        _HEAD + "".join(f'<rect x="{i}" width="2" height="3"/>' for i in range(n // 10)) + "</svg>"
    ),
    "rounded rects (n / 10)": lambda n: (
        _HEAD
        + "".join(f'<rect x="{i}" width="2" height="3" rx="0.5"/>' for i in range(n // 10))
        + "</svg>"
    ),
    "paths drawn by <use>": _uses,
    "bare moves (M)": lambda n: _path("M1 1 ", n),
    "closed triangles (M l l Z)": lambda n: _path("M0 0 l1 0 l0 1Z", n // 2),
    # each close looks back over its subpath for the last move: quadratic, so fewer
    "closes in one subpath (n / 5)": lambda n: _path("Z", n // 5),
    "line, close, … (n / 10)": lambda n: _path("l1 1Z", n // 10),
}


def _timed(call: Callable[[], object]) -> tuple[float, object]:
    start = time.perf_counter()
    out = call()
    return time.perf_counter() - start, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=20_000)
    parser.add_argument("--rounds", type=int, default=3)
    options = parser.parse_args()
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, load {_load()}")
    print(
        "| content | bytes | scan | read | estimate | estimate / read "
        "| points ≥ (read) | curves ≥ (read) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for kind, make in KINDS.items():
        document = make(options.count)
        scans, reads = [], []
        work = data = None
        for _ in range(options.rounds):
            seconds, work = _timed(lambda document=document: scan_svg(document))
            scans.append(seconds)
            seconds, data = _timed(lambda document=document: _read(document))
            reads.append(seconds)
        assert work is not None
        scan, read = statistics.median(scans), statistics.median(reads)
        # a document that draws nothing (bare moves) is refused after the whole parse
        points = sum(len(c) for c in data.curves) if data else 0  # type: ignore[attr-defined]
        curves = len(data.curves) if data else 0  # type: ignore[attr-defined]
        print(
            f"| {kind} | {len(document):,} | {scan * 1e3:.0f} ms | {read:.2f} s "
            f"| {work.microseconds / 1e6:.2f} s | {work.microseconds / 1e6 / read:.2f} "  # type: ignore[attr-defined]
            f"| {work.points:,} ({points:,}) | {work.curves:,} ({curves:,}) |",  # type: ignore[attr-defined]
            flush=True,
        )
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, load {_load()}")


def _read(document: str) -> object:
    try:
        return read_svg(document)
    except InvalidParameter:
        return None


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


if __name__ == "__main__":
    main()
