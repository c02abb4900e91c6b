"""The ``wavecore`` command line: encode, decode, inspect, serve.

::

    wavecore encode IN OUT [--keep K | --quality Q | --bpp B] [--lossless] [--wavelet W] [--level L]
    wavecore decode BUNDLE OUT [--keep K] [--level L]
    wavecore inspect BUNDLE [--json]
    wavecore serve [--host H] [--port P] [--workers N]

``IN``/``BUNDLE`` may be a file, a folder or a quoted glob (``"photos/*.png"``); with several
inputs ``OUT`` is a folder, a progress bar runs on stderr and a summary table follows.
Images are read with Pillow (anything it reads); ``.json`` inputs are curves
(``{"points": [...], "closed": false}`` or a bare list of points) and ``.npy`` inputs are
images, unless ``--kind`` says ``curve`` or ``surface``.  Bundles are written as ``.wcb``.
Decoded images are written by ``OUT``'s extension (``.png``, ``.webp``, ``.tiff``, ``.npy``),
curves and surfaces as ``.json`` or ``.npy``.

It lives in ``service`` because it reads and writes image files with Pillow, which ``wavecore``
itself never imports.
"""

from __future__ import annotations

import argparse
import glob
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

import wavecore

from .deps import npy_bytes
from .errors import Problem
from .imaging import encode_array, read_image
from .settings import Settings

BUNDLE_SUFFIX = ".wcb"
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp", ".gif", ".ppm"}
IMAGE_SUFFIXES |= {".pgm", ".pbm", ".tga", ".jp2", ".j2k", ".ico", ".pcx", ".sgi"}
ENCODE_SUFFIXES = IMAGE_SUFFIXES | {".npy", ".json"}


class CLIError(Exception):
    """A user error: printed as ``wavecore: error: ...`` with exit status 1."""


@dataclass
class Row:
    """One line of the summary table."""

    name: str
    values: dict[str, str] = field(default_factory=dict)
    error: str | None = None


# --------------------------------------------------------------------------------------------
# Inputs, outputs, progress
# --------------------------------------------------------------------------------------------


def expand(arg: str, suffixes: set[str]) -> tuple[list[Path], bool]:
    """The files an argument names, and whether it named a set (folder or glob)."""
    path = Path(arg)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in suffixes)
        if not files:
            msg = f"{arg} holds no {'/'.join(sorted(suffixes))} files"
            raise CLIError(msg)
        return files, True
    if glob.has_magic(arg):
        files = sorted(Path(p) for p in glob.glob(arg) if Path(p).is_file())
        if not files:
            msg = f"nothing matches {arg}"
            raise CLIError(msg)
        return files, True
    if not path.is_file():
        msg = f"{arg} does not exist"
        raise CLIError(msg)
    return [path], False


def output_for(source: Path, out: Path, many: bool, suffix: str) -> Path:
    if many or out.is_dir():
        out.mkdir(parents=True, exist_ok=True)
        return out / (source.stem + suffix)
    out.parent.mkdir(parents=True, exist_ok=True)
    return out


class Progress:
    """A one-line progress bar on a terminal (plain lines when not a terminal)."""

    def __init__(self, total: int, stream: TextIO, enabled: bool) -> None:
        self.total, self.stream, self.enabled = total, stream, enabled
        self.tty = stream.isatty()
        self.start = time.perf_counter()

    def update(self, done: int, name: str) -> None:
        if not self.enabled:
            return
        width = 28
        filled = round(width * done / self.total)
        elapsed = time.perf_counter() - self.start
        line = (
            f"[{'#' * filled}{'.' * (width - filled)}] {done}/{self.total} {elapsed:5.1f}s {name}"
        )
        if self.tty:
            self.stream.write("\r\x1b[K" + line[:120])
            if done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


def print_table(rows: Sequence[Row], columns: Sequence[str], stream: TextIO) -> None:
    """A plain aligned table; a failed row shows its error instead of figures."""
    header = ["file", *columns]
    body = [[r.name, *(r.values.get(c, "") for c in columns)] for r in rows if r.error is None]
    widths = [max(len(row[i]) for row in [header, *body]) for i in range(len(header))]
    widths[0] = max(widths[0], *(len(r.name) for r in rows))

    def line(cells: Sequence[str]) -> str:
        parts = [f"{cells[0]:<{widths[0]}}"]
        parts += [f"{c:>{w}}" for c, w in zip(cells[1:], widths[1:], strict=True)]
        return "  ".join(parts)

    print(line(header), file=stream)
    print("  ".join("-" * w for w in widths), file=stream)
    for r in rows:
        if r.error is None:
            print(line([r.name, *(r.values.get(c, "") for c in columns)]), file=stream)
        else:
            print(f"{r.name:<{widths[0]}}  {r.error}", file=stream)
    ok = sum(r.error is None for r in rows)
    print(f"{ok} of {len(rows)} done", file=stream)


def run_many(
    files: Sequence[Path],
    many: bool,
    work: Callable[[Path], Row],
    columns: Sequence[str],
    *,
    quiet: bool = False,
) -> int:
    progress = Progress(len(files), sys.stderr, enabled=many and not quiet)
    rows: list[Row] = []
    for i, path in enumerate(files, 1):
        try:
            rows.append(work(path))
        except (CLIError, Problem, wavecore.WavecoreError, OSError, ValueError) as exc:
            if not many:
                raise
            rows.append(Row(path.name, error=f"error: {_message(exc)}"))
        progress.update(i, path.name)
    if many or not quiet:
        print_table(rows, columns, sys.stdout)
    return 0 if all(r.error is None for r in rows) else 1


def _message(exc: BaseException) -> str:
    if isinstance(exc, Problem):
        return exc.detail
    return str(exc)


def _size(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GB"


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------


def _load_input(path: Path, kind: str | None, max_pixels: int) -> tuple[str, np.ndarray, bool]:
    """(kind, array, closed) of an input file."""
    suffix = path.suffix.lower()
    if suffix == ".json":
        data = json.loads(path.read_text(encoding="utf-8"))
        kind = kind or ("surface" if isinstance(data, dict) and "grid" in data else "curve")
        closed = bool(data.get("closed", False)) if isinstance(data, dict) else False
        key = "grid" if kind == "surface" else "points"
        values = data.get(key) if isinstance(data, dict) else data
        try:
            return kind, np.asarray(values, dtype=np.float64), closed
        except (TypeError, ValueError) as exc:
            msg = f"{path}: {key} must be a rectangular list of numbers ({exc})"
            raise CLIError(msg) from None
    if suffix == ".npy":
        return kind or "image", np.load(path, allow_pickle=False), False
    return kind or "image", read_image(path.read_bytes(), max_pixels=max_pixels), False


def cmd_encode(args: argparse.Namespace) -> int:
    files, many = expand(args.input, ENCODE_SUFFIXES)
    max_pixels = Settings().max_pixels
    targets = {
        name: getattr(args, name)
        for name in ("keep", "quality", "bpp", "tolerance")
        if getattr(args, name) is not None
    }

    def work(path: Path) -> Row:
        start = time.perf_counter()
        kind, data, closed = _load_input(path, args.kind, max_pixels)
        closed = closed or args.closed
        allowed = {"image": {"keep", "quality", "bpp"}, "curve": {"keep", "tolerance"}}
        extra = set(targets) - allowed.get(kind, {"keep", "quality"})
        if extra or (args.lossless and kind != "image"):
            msg = f"--{(sorted(extra) or ['lossless'])[0]} does not apply to a {kind}"
            raise CLIError(msg)
        if kind == "image":
            bundle = wavecore.encode_image(
                data, wavelet=args.wavelet, level=args.level, lossless=args.lossless, **targets
            )
        elif kind == "curve":
            bundle = wavecore.encode_curve(
                data, closed=closed, level=args.level, wavelet=args.wavelet, **targets
            )
        else:
            bundle = wavecore.encode_surface(
                data, closed=(closed, args.closed_v), level=args.level, **targets
            )
        out = output_for(path, Path(args.output), many, BUNDLE_SUFFIX)
        out.write_bytes(bundle)
        info = wavecore.inspect(bundle)
        psnr = info.get("psnr")
        values = {
            "kind": kind,
            "shape": "×".join(str(s) for s in data.shape),
            "input": _size(path.stat().st_size),
            "bundle": _size(len(bundle)),
            "ratio": f"{data.nbytes / len(bundle):.1f}",
            "bpp": f"{8 * len(bundle) / (data.shape[0] * data.shape[1]):.3f}"
            if kind == "image"
            else "",
            "PSNR": "exact" if psnr is None else f"{psnr:.2f}",
            "seconds": f"{time.perf_counter() - start:.2f}",
        }
        return Row(path.name, values)

    columns = ["kind", "shape", "input", "bundle", "ratio", "bpp", "PSNR", "seconds"]
    return run_many(files, many, work, columns, quiet=args.quiet)


def cmd_decode(args: argparse.Namespace) -> int:
    files, many = expand(args.bundle, {BUNDLE_SUFFIX})

    def work(path: Path) -> Row:
        start = time.perf_counter()
        bundle = path.read_bytes()
        kind = wavecore.inspect(bundle)["kind"]
        arr = wavecore.decode(bundle, keep=args.keep, level=args.level)
        default = ".png" if kind == "image" else ".json"
        out = output_for(path, Path(args.output), many, args.format or default)
        suffix = out.suffix.lower()
        if suffix == ".npy":
            data = npy_bytes(arr)
        elif kind == "image" and suffix in (".png", ".webp", ".tif", ".tiff"):
            data = encode_array(arr, {".tif": "tiff"}.get(suffix, suffix[1:]))
        elif kind != "image" and suffix == ".json":
            key = "points" if kind == "curve" else "grid"
            data = json.dumps({key: arr.tolist()}).encode()
        else:
            allowed = ".png, .webp, .tiff, .npy" if kind == "image" else ".json, .npy"
            msg = f"a decoded {kind} can be written as {allowed}, not {suffix or 'no extension'}"
            raise CLIError(msg)
        out.write_bytes(data)
        values = {
            "kind": kind,
            "shape": "×".join(str(s) for s in arr.shape),
            "output": out.name,
            "seconds": f"{time.perf_counter() - start:.2f}",
        }
        return Row(path.name, values)

    return run_many(files, many, work, ["kind", "shape", "output", "seconds"], quiet=args.quiet)


def cmd_inspect(args: argparse.Namespace) -> int:
    files, many = expand(args.bundle, {BUNDLE_SUFFIX})
    if not many:
        info = wavecore.inspect(files[0].read_bytes())
        if args.json:
            from .deps import jsonable

            print(json.dumps(jsonable(info), indent=2))
        else:
            _print_info(info)
        return 0

    def work(path: Path) -> Row:
        info = wavecore.inspect(path.read_bytes())
        psnr = info.get("psnr")
        values = {
            "kind": info["kind"],
            "shape": "×".join(str(s) for s in info["shape"]),
            "wavelet": info["wavelet"],
            "levels": str(info["levels"]),
            "bytes": str(info["total_bytes"]),
            "PSNR": "exact" if psnr is None else f"{psnr:.2f}",
        }
        return Row(path.name, values)

    columns = ["kind", "shape", "wavelet", "levels", "bytes", "PSNR"]
    return run_many(files, many, work, columns, quiet=args.quiet)


def _print_info(info: dict[str, Any]) -> None:
    shape = "×".join(str(s) for s in info["shape"])
    print(f"{info['kind']} {shape} {info['dtype']}, format {info['version']}")
    print(f"wavelet {info['wavelet']}, boundary {'/'.join(info['boundary'])}, "
          f"{info['levels']} levels, colour {info['colour']}")  # fmt: skip
    psnr = info.get("psnr")
    print(f"PSNR {'exact' if psnr is None else f'{psnr:.2f} dB'}, max error {info['max_error']}")
    bpp = f", {info['bpp']:.3f} bpp" if "bpp" in info else ""
    print(f"{info['total_bytes']} bytes ({info['header_bytes']} header){bpp}")
    for chunk in info["chunks"]:
        shapes = " ".join("×".join(map(str, s)) for s in chunk["shapes"])
        size = chunk["bytes"] if chunk["present"] else "missing"
        print(f"  level {chunk['level']:>2}  {','.join(chunk['bands']):<9} {shapes:<30} {size}")


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    uvicorn.run(
        "service.app:create_app",
        factory=True,
        host=args.host,
        port=args.port,
        workers=args.workers,
        log_level=args.log_level,
    )
    return 0


# --------------------------------------------------------------------------------------------
# Parser
# --------------------------------------------------------------------------------------------


def _fraction(text: str) -> float:
    value = float(text)
    if not 0 <= value <= 1:
        msg = f"{text} is not a fraction in [0, 1]"
        raise argparse.ArgumentTypeError(msg)
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wavecore",
        description="Wavelet compression with the local filters of quadratic B-spline wavelets.",
    )
    parser.add_argument("--version", action="version", version=wavecore.__version__)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    enc = sub.add_parser("encode", help="encode images, curves or surfaces into bundles")
    enc.add_argument("input", metavar="IN", help="a file, a folder or a quoted glob")
    enc.add_argument("output", metavar="OUT", help="the bundle (a folder for several inputs)")
    target = enc.add_mutually_exclusive_group()
    target.add_argument("--keep", type=_fraction, help="fraction of details kept")
    target.add_argument("--quality", type=float, help="target PSNR in dB (default 40)")
    target.add_argument("--bpp", type=float, help="target bits per pixel (images)")
    target.add_argument("--tolerance", type=float, help="largest point deviation (curves)")
    target.add_argument("--lossless", action="store_true", help="bit-exact (8/16-bit images)")
    enc.add_argument(
        "--wavelet", default="bspline2", help="bspline2 (default), cdf97, haar (images, curves)"
    )
    enc.add_argument("--level", type=int, help="levels (default: automatic)")
    enc.add_argument("--kind", choices=["image", "curve", "surface"], help="override by suffix")
    enc.add_argument("--closed", action="store_true", help="closed curve / closed first axis")
    enc.add_argument("--closed-v", action="store_true", help="surface: closed second axis")
    enc.add_argument("-q", "--quiet", action="store_true", help="no progress bar or table")
    enc.set_defaults(run=cmd_encode)

    dec = sub.add_parser("decode", help="decode bundles into images, curves or surfaces")
    dec.add_argument("bundle", metavar="BUNDLE", help="a .wcb file, a folder or a quoted glob")
    dec.add_argument("output", metavar="OUT", help="the output file (a folder for several)")
    dec.add_argument("--keep", type=_fraction, help="keep only this fraction of the details")
    dec.add_argument("--level", type=int, default=0, help="k levels coarser (default 0)")
    dec.add_argument("--format", choices=[".png", ".webp", ".tiff", ".npy", ".json"],
                     help="output suffix when OUT is a folder")  # fmt: skip
    dec.add_argument("-q", "--quiet", action="store_true", help="no progress bar or table")
    dec.set_defaults(run=cmd_decode)

    ins = sub.add_parser("inspect", help="describe bundles without decoding them")
    ins.add_argument("bundle", metavar="BUNDLE", help="a .wcb file, a folder or a quoted glob")
    ins.add_argument("--json", action="store_true", help="everything, as JSON")
    ins.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    ins.set_defaults(run=cmd_inspect)

    defaults = Settings()
    srv = sub.add_parser("serve", help="run the web service (uvicorn)")
    srv.add_argument("--host", default=defaults.host, help=f"default {defaults.host}")
    srv.add_argument("--port", type=int, default=defaults.port, help=f"default {defaults.port}")
    srv.add_argument("--workers", type=int, default=defaults.workers, help="processes")
    srv.add_argument("--log-level", default="info")
    srv.set_defaults(run=cmd_serve)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 1 failed, 2 usage)."""
    args = build_parser().parse_args(argv)
    try:
        status: int = args.run(args)
    except (CLIError, Problem, wavecore.WavecoreError, OSError, ValueError) as exc:
        print(f"wavecore: error: {_message(exc)}", file=sys.stderr)
        return 1
    return status


if __name__ == "__main__":
    sys.exit(main())
