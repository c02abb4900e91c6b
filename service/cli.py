"""The ``wavecore`` command line: encode, decode, inspect, serve.

::

    wavecore encode IN OUT [--keep K | --quality Q | --bpp B] [--lossless [--effort fast]]
                           [--wavelet W] [--level L]
    wavecore decode BUNDLE OUT [--keep K] [--level L]
    wavecore inspect BUNDLE [--json]
    wavecore serve [--host H] [--port P] [--workers N]

    wavecore encode BIG.tif|TILES/|BIG.npy OUT.zarr [--quality Q | --max-error E | --lossless]
                    [--tile T] [--workers N | --scheduler ADDRESS]
    wavecore decode STORE.zarr OUT.npy|OUT.tif [--level K] [--region Y0:Y1,X0:X1]

An ``OUT`` ending in ``.zarr`` makes a Zarr store with a multiscale pyramid (OME-Zarr) from an
image of any size, tile by tile with Dask (``wavecore.scale``; needs the zarr extra,
``pip install 'wavecore[zarr]'``); ``decode`` of a ``.zarr`` reads one window at one level.

``IN``/``BUNDLE`` may be a file, a folder or a quoted glob (``"photos/*.png"``); with several
inputs ``OUT`` is a folder, a progress bar runs on stderr and a summary table follows.
Images are read with Pillow (anything it reads); ``.json`` inputs are curves
(``{"points": [...], "closed": false}`` or a bare list of points) and ``.npy`` inputs are
images, unless ``--kind`` says ``curve``, ``surface`` or ``grid``; a ``.npy`` or TIFF that no
image takes (signed or wide integers, NaN cells, a volume) is a grid (``--max-error``,
``--rmse``, ``--psnr``, ``--bpp``, ``--lossless``).  Bundles are written as ``.wcb``
(``.wvb``, the suffix of the test suite's golden bundles, is read too).
Decoded images are written by ``OUT``'s extension (``.png``, ``.webp``, ``.tiff``, ``.npy``),
curves and surfaces as ``.json`` or ``.npy``, grids as ``.npy`` or ``.tiff``.

It lives in ``service`` (installed as ``wavecore_service``) because it reads and writes image
files with Pillow, which ``wavecore`` itself never imports.  With only the core install
(``pip install wavecore``) every command works on ``.npy``, ``.json`` and bundle files: Pillow
and the web stack are imported only when an image file is read or written, or by ``serve``, and
their absence is one line naming the extra to install.
"""

from __future__ import annotations

import argparse
import glob
import importlib
import io
import json
import logging
import re
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

import wavecore

# The one suffix written; both are read (the golden bundles in tests/golden are ``.wvb``).
BUNDLE_SUFFIX = ".wcb"
BUNDLE_SUFFIXES = {".wcb", ".wvb"}
SERVICE_EXTRA = "pip install 'wavecore[service]'"
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp", ".gif", ".ppm"}
IMAGE_SUFFIXES |= {".pgm", ".pbm", ".tga", ".jp2", ".j2k", ".ico", ".pcx", ".sgi"}
ENCODE_SUFFIXES = IMAGE_SUFFIXES | {".npy", ".json", ".geojson", ".svg"}
# Curve files coded as one curve set (a .json with "curves" too; one with "points" stays a curve).
CURVE_FILE_SUFFIXES = {".geojson": "geojson", ".svg": "svg"}


class CLIError(Exception):
    """A user error: printed as ``wavecore: error: ...`` with exit status 1."""


def _service_module(name: str, needed_for: str) -> Any:
    """This package's module ``name``, or a one-line error naming the extra it needs."""
    try:
        return importlib.import_module(f"{__package__}.{name}")
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] in ("service", "wavecore_service"):
            raise
        msg = f"{needed_for} needs the service extra ({exc.name} is missing): {SERVICE_EXTRA}"
        raise CLIError(msg) from None


def _settings() -> Any:
    """The ``WAVECORE_*`` settings; a bad value is one line that names its variable."""
    settings = _service_module("settings", "reading the WAVECORE_* settings")
    from pydantic import ValidationError  # present: the settings module imports it

    try:
        return settings.Settings()
    except ValidationError as exc:
        raise CLIError(_settings_message(exc)) from None


def _settings_message(exc: Any) -> str:
    """``WAVECORE_THREADS='zero': Input should be a valid integer`` for each bad variable."""
    parts = []
    for error in exc.errors():
        loc = [str(part) for part in error.get("loc", ())]
        message = str(error.get("msg", "invalid"))
        if loc:
            variable = "WAVECORE_" + loc[0].upper()
            parts.append(f"{variable}={error.get('input')!r}: {message}")
        else:
            parts.append(f"WAVECORE_* settings: {message}")
    return "bad setting: " + "; ".join(parts)


def _read_image(path: Path) -> np.ndarray:
    imaging = _service_module("imaging", f"reading the image file {path.name}")
    errors = _service_module("errors", f"reading the image file {path.name}")
    try:
        image: np.ndarray = imaging.read_image(path.read_bytes(), max_pixels=_settings().max_pixels)
    except errors.Problem as exc:
        raise CLIError(f"{path}: {exc.detail}") from None
    return image


def _image_file_bytes(arr: np.ndarray, suffix: str) -> bytes:
    imaging = _service_module("imaging", f"writing a {suffix} image")
    errors = _service_module("errors", f"writing a {suffix} image")
    try:
        data: bytes = imaging.encode_array(arr, {".tif": "tiff"}.get(suffix, suffix[1:]))
    except errors.Problem as exc:
        raise CLIError(exc.detail) from None
    return data


def _npy_bytes(arr: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, arr, allow_pickle=False)
    return out.getvalue()


def _grid_tiff_bytes(arr: np.ndarray) -> bytes:
    """A decoded grid as a TIFF in its own dtype (tifffile, of the service extra)."""
    try:
        import tifffile
    except ModuleNotFoundError:
        msg = f"writing a grid as TIFF needs the service extra (tifffile): {SERVICE_EXTRA}"
        raise CLIError(msg) from None
    out = io.BytesIO()
    tifffile.imwrite(out, arr)
    return out.getvalue()


def _jsonable(value: Any) -> Any:
    """Plain JSON types (numpy scalars and arrays as numbers and lists, bytes as hex)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    if isinstance(value, bytes):
        return value.hex()
    return value


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


#: The outputs of the current run and the inputs they come from (reset by :func:`main`):
#: ``a.png`` and ``a.jpg`` would both write ``a.wcb``, the second over the first.
_CLAIMED: dict[Path, Path] = {}


def output_for(source: Path, out: Path, many: bool, suffix: str) -> Path:
    """Where ``source``'s result goes; never onto an input or another result of the run."""
    target = out / (source.stem + suffix) if many or out.is_dir() else out
    where = target.resolve()
    if where == source.resolve():
        msg = f"{target} is the input itself; name another output"
        raise CLIError(msg)
    if _CLAIMED.get(where, source) != source:
        msg = f"{target} is also the output of {_CLAIMED[where]}; rename one of them"
        raise CLIError(msg)
    _CLAIMED[where] = source
    target.parent.mkdir(parents=True, exist_ok=True)
    return target


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
    rows = [replace(r, name=_printable(r.name)) for r in rows]  # file names as printed
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
        except _FILE_ERRORS as exc:
            if not many:
                raise
            rows.append(Row(path.name, error=f"error: {_message(exc)}"))
        progress.update(i, _printable(path.name))
    if many or not quiet:
        print_table(rows, columns, sys.stdout)
    return 0 if all(r.error is None for r in rows) else 1


#: What reading one bad file may raise: a message, then the next file (never a traceback):
#: ``EOFError`` from an empty ``.npy``, ``RecursionError`` from JSON nested too deeply.
_FILE_ERRORS = (
    CLIError,
    wavecore.WavecoreError,
    OSError,
    ValueError,
    EOFError,
    RecursionError,
)


def _message(exc: BaseException) -> str:
    if isinstance(exc, RecursionError):
        return "the file is nested too deeply to read"
    if isinstance(exc, EOFError):
        return f"the file ends too soon ({exc})"
    return _printable(str(exc))


def _printable(text: str) -> str:
    """``text`` with control characters shown escaped: a file named ``\x1b]0;…`` must not
    retitle or clear the terminal it is printed to."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _size(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GB"


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------


def _load_input(path: Path, kind: str | None) -> tuple[str, np.ndarray, bool]:
    """(kind, array, closed) of an input file."""
    suffix = path.suffix.lower()
    if suffix == ".json":
        data = json.loads(path.read_text(encoding="utf-8"))
        kind = kind or ("surface" if isinstance(data, dict) and "grid" in data else "curve")
        closed = data.get("closed", False) if isinstance(data, dict) else False
        if not isinstance(closed, bool):  # bool("false") is True
            msg = f"{path}: 'closed' must be true or false, not {closed!r}"[:300]
            raise CLIError(msg)
        key = "grid" if kind == "surface" else "points"
        values = data.get(key) if isinstance(data, dict) else data
        try:
            return kind, np.asarray(values, dtype=np.float64), closed
        except (TypeError, ValueError) as exc:
            msg = f"{path}: {key} must be a rectangular list of numbers ({exc})"
            raise CLIError(msg) from None
    if suffix == ".npy":
        arr = np.load(path, allow_pickle=False)
        return kind or ("grid" if _only_a_grid(arr) else "image"), arr, False
    if kind == "grid" or (kind is None and suffix in (".tif", ".tiff")):
        grid = _read_grid(path)
        if kind == "grid" or _only_a_grid(grid):
            return "grid", grid, False
    return kind or "image", _read_image(path), False


def _curve_file_format(path: Path) -> str | None:
    """``geojson``/``svg``/``json`` for a file read as a curve set, else ``None``."""
    suffix = path.suffix.lower()
    if suffix in CURVE_FILE_SUFFIXES:
        return CURVE_FILE_SUFFIXES[suffix]
    if suffix == ".json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError):
            return None
        return "json" if isinstance(data, dict) and "curves" in data else None
    return None


def _encode_curve_file(path: Path, args: argparse.Namespace, many: bool) -> Row:
    start = time.perf_counter()
    if args.keep is not None or args.quality is not None or args.bpp is not None:
        msg = "a curve file takes --tolerance (or none), not --keep, --quality or --bpp"
        raise CLIError(msg)
    fmt = _curve_file_format(path) or "json"
    bundle = wavecore.encode_curve_file(
        path.read_bytes(), fmt, tolerance=args.tolerance, wavelet=args.wavelet, level=args.level
    )
    out = output_for(path, Path(args.output), many, BUNDLE_SUFFIX)
    out.write_bytes(bundle)
    info = wavecore.inspect(bundle)
    values = {
        "kind": "curves",
        "shape": f"{info['count']} curves",
        "input": _size(path.stat().st_size),
        "bundle": _size(len(bundle)),
        "ratio": f"{path.stat().st_size / len(bundle):.1f}",
        "bpp": "",
        "PSNR": f"±{info['tolerance']:.3g}",
        "seconds": f"{time.perf_counter() - start:.2f}",
    }
    return Row(path.name, values)


def _only_a_grid(arr: np.ndarray) -> bool:
    """An array that no image codec takes but a grid does: signed or wide integers, NaN cells,
    or a volume (more than 4 values per pixel).  Such ``.npy`` and TIFF inputs are grids."""
    if arr.dtype.kind in "iu" and arr.dtype.name not in ("uint8", "uint16"):
        return True
    if arr.ndim == 3 and arr.shape[2] > 4:
        return True
    return arr.dtype.kind == "f" and bool(np.isnan(arr).any())


def _read_grid(path: Path) -> np.ndarray:
    """A TIFF (GeoTIFF) height map in its own dtype (service/gridfiles.py, through tifffile)."""
    gridfiles = _service_module("gridfiles", f"reading the TIFF file {path.name}")
    settings = _settings()
    try:
        grid: np.ndarray = gridfiles.read_grid_file(
            path.read_bytes(), path.name, max_elements=settings.max_grid_points * 4
        )
    except gridfiles.GridFileError as exc:
        raise CLIError(f"{path}: {exc}") from None
    return grid


def cmd_encode(args: argparse.Namespace) -> int:
    if args.output.rstrip("/").lower().endswith(ZARR_SUFFIX):
        return cmd_encode_zarr(args)
    files, many = expand(args.input, ENCODE_SUFFIXES)
    targets = {
        name: getattr(args, name)
        for name in ("keep", "quality", "bpp", "tolerance", "max_error", "rmse", "psnr")
        if getattr(args, name) is not None
    }

    # No --wavelet: each kind keeps the library's own default (auto for images, bspline2 for
    # curves), the one its measurement picks.
    chosen = {} if args.wavelet is None else {"wavelet": args.wavelet}
    # No --effort: the library's default; a value it refuses is its InvalidParameter.
    effort = {} if args.effort is None else {"effort": args.effort}

    def work(path: Path) -> Row:
        start = time.perf_counter()
        if _curve_file_format(path):
            return _encode_curve_file(path, args, many)
        kind, data, closed = _load_input(path, args.kind)
        closed = closed or args.closed
        allowed = {
            "image": {"keep", "quality", "bpp"},
            "curve": {"keep", "tolerance"},
            "grid": {"quality", "bpp", "max_error", "rmse", "psnr"},
        }
        extra = set(targets) - allowed.get(kind, {"keep", "quality"})
        if extra or (args.lossless and kind not in ("image", "grid")):
            article = "an" if kind[0] in "aeiou" else "a"
            msg = f"--{(sorted(extra) or ['lossless'])[0]} does not apply to {article} {kind}"
            raise CLIError(msg)
        if effort and kind != "image":
            article = "an" if kind[0] in "aeiou" else "a"
            msg = f"--effort does not apply to {article} {kind} (images with --lossless only)"
            raise CLIError(msg)
        if kind == "image":
            bundle = wavecore.encode_image(
                data, level=args.level, lossless=args.lossless, **chosen, **targets, **effort
            )
        elif kind == "grid":
            grid_targets = {("psnr" if k == "quality" else k): v for k, v in targets.items()}
            bundle = wavecore.encode_grid(
                data, level=args.level, lossless=args.lossless, **chosen, **grid_targets
            )
        elif kind == "curve":
            bundle = wavecore.encode_curve(
                data, closed=closed, level=args.level, **chosen, **targets
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


def _decode_curve_file(
    path: Path, bundle: bytes, info: dict[str, Any], args: argparse.Namespace, many: bool
) -> Row:
    start = time.perf_counter()
    written = (wavecore.decode_curves(bundle).metadata or {}).get("format")
    default = {"geojson": ".geojson", "svg": ".svg"}.get(str(written), ".json")
    out = output_for(path, Path(args.output), many, args.format or default)
    suffix = out.suffix.lower()
    formats = {".geojson": "geojson", ".svg": "svg", ".json": "json"}
    if suffix not in formats:
        msg = f"a decoded curve set can be written as .geojson, .svg, .json, not {suffix or 'none'}"
        raise CLIError(msg)
    out.write_bytes(wavecore.decode_curve_file(bundle, formats[suffix]))
    values = {
        "kind": "curves",
        "shape": f"{info['count']} curves",
        "output": out.name,
        "seconds": f"{time.perf_counter() - start:.2f}",
    }
    return Row(path.name, values)


def cmd_decode(args: argparse.Namespace) -> int:
    if args.bundle.rstrip("/").lower().endswith(ZARR_SUFFIX):
        return cmd_decode_zarr(args)
    if args.region is not None:
        msg = "--region applies to a Zarr store (STORE.zarr)"
        raise CLIError(msg)
    files, many = expand(args.bundle, BUNDLE_SUFFIXES)

    def work(path: Path) -> Row:
        start = time.perf_counter()
        bundle = path.read_bytes()
        info = wavecore.inspect(bundle)
        kind = info["kind"]
        if kind == "curves":
            return _decode_curve_file(path, bundle, info, args, many)
        arr = wavecore.decode(bundle, keep=args.keep, level=args.level)
        default = {"image": ".png", "grid": ".npy"}.get(kind, ".json")
        out = output_for(path, Path(args.output), many, args.format or default)
        suffix = out.suffix.lower()
        if suffix == ".npy":
            data = _npy_bytes(arr)
        elif kind == "image" and suffix in (".png", ".webp", ".tif", ".tiff"):
            data = _image_file_bytes(arr, suffix)
        elif kind == "grid" and suffix in (".tif", ".tiff"):
            data = _grid_tiff_bytes(arr)
        elif kind not in ("image", "grid") and suffix == ".json":
            key = "points" if kind == "curve" else "grid"
            data = json.dumps({key: arr.tolist()}).encode()
        else:
            allowed = {"image": ".png, .webp, .tiff, .npy", "grid": ".npy, .tiff"}.get(
                kind, ".json, .npy"
            )
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


# --------------------------------------------------------------------------------------------
# Gigapixel images: Zarr pyramids (the zarr extra)
# --------------------------------------------------------------------------------------------

ZARR_SUFFIX = ".zarr"
ZARR_EXTRA = "pip install 'wavecore[zarr]'"


def _scale_module() -> Any:
    """wavecore.scale, or a one-line error naming the zarr extra."""
    try:
        return importlib.import_module("wavecore.scale")
    except ModuleNotFoundError as exc:
        msg = f"Zarr stores need the zarr extra ({exc.name} is missing): {ZARR_EXTRA}"
        raise CLIError(msg) from None


class _DaskWorkers:
    """A dask.distributed client for the command's duration: local workers or a cluster."""

    def __init__(self, workers: int | None, scheduler: str | None) -> None:
        self.workers, self.scheduler = workers, scheduler
        self.cluster: Any = None
        self.client: Any = None

    def __enter__(self) -> _DaskWorkers:
        if self.workers is None and self.scheduler is None:
            return self  # Dask's own local threads
        from dask.distributed import Client

        if self.scheduler is not None:
            self.client = Client(self.scheduler)
        else:
            self.cluster = _scale_module().local_cluster(self.workers)
            self.client = Client(self.cluster)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def cmd_encode_zarr(args: argparse.Namespace) -> int:
    """An image of any size into a Zarr pyramid, tile by tile."""
    scale = _scale_module()
    wrong = [n for n in ("keep", "bpp", "tolerance") if getattr(args, n) is not None]
    if wrong or args.kind not in (None, "image"):
        msg = f"--{(wrong or ['kind'])[0]} does not apply to a Zarr pyramid"
        raise CLIError(msg)
    if args.effort is not None:
        msg = "--effort does not apply to a Zarr pyramid (single-image lossless bundles only)"
        raise CLIError(msg)
    config: dict[str, Any] = {} if args.wavelet is None else {"wavelet": args.wavelet}
    if args.lossless:
        config["lossless"] = True
    elif args.max_error is not None:
        config["max_error"] = args.max_error
    else:
        config["psnr"] = 40.0 if args.quality is None else args.quality
    if args.level is not None:
        config["level"] = args.level
    if not Path(args.input).exists():
        raise CLIError(f"{args.input} does not exist")
    start = time.perf_counter()
    source = scale.open_image_source(args.input, tile=args.tile)
    with _DaskWorkers(args.workers, args.scheduler):
        info = scale.write_pyramid(
            source, args.output, config=config, tile=args.tile, name=Path(args.input).stem
        )
    if not args.quiet:
        shape = "×".join(str(s) for s in source.shape)
        levels = ", ".join("×".join(str(s) for s in shape[1:]) for shape in info.shapes)
        print(f"{args.input}: {shape} → {args.output}")
        print(f"levels: {levels}")
        print(
            f"stored {_size(info.stored_bytes)} of {_size(info.raw_bytes)} "
            f"(every level; ratio {info.raw_bytes / max(info.stored_bytes, 1):.1f} to the "
            f"full-size pixels), {time.perf_counter() - start:.1f} s"
        )
    return 0


def _region(text: str) -> tuple[int, int, int, int]:
    match = re.fullmatch(r"\s*(\d+):(\d+)\s*,\s*(\d+):(\d+)\s*", text)
    if not match:
        msg = f"{text!r} is not a region Y0:Y1,X0:X1 (full-resolution pixels)"
        raise argparse.ArgumentTypeError(msg)
    y0, y1, x0, x1 = (int(g) for g in match.groups())
    return y0, y1, x0, x1


def cmd_decode_zarr(args: argparse.Namespace) -> int:
    """One window of a pyramid at one level, into .npy or .tif."""
    scale = _scale_module()
    start = time.perf_counter()
    if not Path(args.bundle).is_dir():
        raise CLIError(f"{args.bundle} does not exist")
    arr = scale.read_region(args.bundle, level=args.level, region=args.region)
    out = Path(args.output)
    suffix = out.suffix.lower()
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".npy":
        out.write_bytes(_npy_bytes(arr))
    elif suffix in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(out, arr, photometric="rgb" if arr.ndim == 3 else "minisblack")
    elif suffix in (".png", ".webp"):
        out.write_bytes(_image_file_bytes(arr, suffix))
    else:
        msg = f"a window of a Zarr pyramid is written as .npy, .tif, .png or .webp, not {suffix!r}"
        raise CLIError(msg)
    if not args.quiet:
        shape = "×".join(str(s) for s in arr.shape)
        print(f"{out}: {shape} {arr.dtype}, level {args.level}, "
              f"{time.perf_counter() - start:.2f} s")  # fmt: skip
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    files, many = expand(args.bundle, BUNDLE_SUFFIXES)
    if not many:
        info = wavecore.inspect(files[0].read_bytes())
        if args.json:
            print(json.dumps(_jsonable(info), indent=2))
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
    factor = info.get("replicated", 1)
    if factor > 1:
        print(
            f"an enlargement by pixel replication: its source coded (format "
            f"{info['source_version']}), each pixel repeated {factor} × {factor}"
        )
    for chunk in info["chunks"]:
        shapes = " ".join("×".join(map(str, s)) for s in chunk["shapes"])
        size = chunk["bytes"] if chunk["present"] else "missing"
        print(f"  level {chunk['level']:>2}  {','.join(chunk['bands']):<9} {shapes:<30} {size}")


def cmd_serve(args: argparse.Namespace) -> int:
    _service_module("app", "wavecore serve")  # FastAPI and the rest of the service extra
    try:
        import uvicorn
    except ModuleNotFoundError:
        msg = f"wavecore serve needs the service extra (uvicorn is missing): {SERVICE_EXTRA}"
        raise CLIError(msg) from None
    defaults = _settings()
    host = defaults.host if args.host is None else args.host
    port = defaults.port if args.port is None else args.port
    workers = defaults.workers if args.workers is None else args.workers
    # Checked before the warm-up: uvicorn would fail only after it (port) or take 0 as 1.
    if not 0 <= port <= 65535:
        msg = f"port must be from 0 to 65535, not {port}"
        raise CLIError(msg)
    if workers < 1:
        msg = f"workers must be a whole number of processes >= 1, not {workers}"
        raise CLIError(msg)
    if not args.no_warm_up:
        # Before uvicorn says it is ready: the first requests then never wait for numba to
        # compile (or load from its cache) a kernel. With one worker the kernels stay loaded in
        # this process; extra worker processes load them from the cache this fills.
        logging.basicConfig(level=logging.INFO, format="%(levelname)s:     %(message)s")
        log = logging.getLogger("wavecore")
        log.info(
            "Warming up: compiling the numba kernels (a minute or two the first time; "
            "loaded from numba's cache in seconds afterwards)"
        )
        _warm_up()  # its last line says how long it took
    protocol = _service_module("protocol", "running the service")
    _, _, backlog = protocol.connection_limits()
    uvicorn.run(
        f"{__package__}.app:create_app",
        factory=True,
        host=host,
        port=port,
        workers=workers,
        log_level=args.log_level,
        http=protocol.GuardedH11Protocol,  # deadlines for headers, a cap on connections
        # asyncio accepts up to this many sockets before any is refused: kept under the cap
        backlog=backlog,
    )
    return 0


def _warm_up() -> None:
    from wavecore.warmup import warm_up

    warm_up(stream=sys.stderr)


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
    target.add_argument(
        "--max-error", type=float, help="grids and OUT.zarr: largest error on every value"
    )
    target.add_argument("--rmse", type=float, help="grids: target root-mean-square error")
    target.add_argument("--psnr", type=float, help="grids: target PSNR in dB (against the range)")
    enc.add_argument(
        "--wavelet",
        default=None,
        help="images: auto (default: cdf97, or haar for mostly flat 2x2 blocks), cdf97, bspline2, "
        "haar; curves: bspline2 (default), cdf97, haar",
    )
    enc.add_argument("--level", type=int, help="levels (default: automatic)")
    enc.add_argument(
        "--effort",
        help="images with --lossless: default (the lossless coder, smallest; max is the same) "
        "or fast (the block coder: a few %% bigger, quicker)",
    )
    enc.add_argument(
        "--kind",
        choices=["image", "curve", "surface", "grid"],
        help="override by suffix (a .npy or TIFF of signed integers, NaN cells or more than 4 "
        "values per pixel is a grid)",
    )
    enc.add_argument("--closed", action="store_true", help="closed curve / closed first axis")
    enc.add_argument("--closed-v", action="store_true", help="surface: closed second axis")
    enc.add_argument("-q", "--quiet", action="store_true", help="no progress bar or table")
    enc.add_argument("--tile", type=int, default=1024, help="OUT.zarr: chunk side (default 1024)")
    workers = enc.add_mutually_exclusive_group()
    workers.add_argument("--workers", type=int, help="OUT.zarr: local Dask worker processes")
    workers.add_argument("--scheduler", help="OUT.zarr: a running Dask scheduler's address")
    enc.set_defaults(run=cmd_encode)

    dec = sub.add_parser("decode", help="decode bundles into images, curves or surfaces")
    dec.add_argument("bundle", metavar="BUNDLE", help="a .wcb file, a folder or a quoted glob")
    dec.add_argument("output", metavar="OUT", help="the output file (a folder for several)")
    dec.add_argument("--keep", type=_fraction, help="keep only this fraction of the details")
    dec.add_argument("--level", type=int, default=0, help="k levels coarser (default 0)")
    dec.add_argument("--format", choices=[".png", ".webp", ".tiff", ".npy", ".json", ".geojson",
                                          ".svg"],
                     help="output suffix when OUT is a folder")  # fmt: skip
    dec.add_argument("-q", "--quiet", action="store_true", help="no progress bar or table")
    dec.add_argument(
        "--region", type=_region, help="STORE.zarr: window Y0:Y1,X0:X1 in full-resolution pixels"
    )
    dec.set_defaults(run=cmd_decode)

    ins = sub.add_parser("inspect", help="describe bundles without decoding them")
    ins.add_argument("bundle", metavar="BUNDLE", help="a .wcb file, a folder or a quoted glob")
    ins.add_argument("--json", action="store_true", help="everything, as JSON")
    ins.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    ins.set_defaults(run=cmd_inspect)

    # The defaults come from the WAVECORE_* settings, read only when `serve` runs (so that the
    # other commands work without the service extra and are not stopped by a bad setting).
    srv = sub.add_parser(
        "serve", help=f"run the web service (uvicorn; needs the service extra: {SERVICE_EXTRA})"
    )
    srv.add_argument("--host", help="default WAVECORE_HOST or 127.0.0.1")
    srv.add_argument("--port", type=int, help="default WAVECORE_PORT or 8000")
    srv.add_argument("--workers", type=int, help="processes (default WAVECORE_WORKERS or 1)")
    srv.add_argument("--log-level", default="info")
    srv.add_argument(
        "--no-warm-up",
        action="store_true",
        help="start without compiling the kernels first (the first requests then may wait)",
    )
    srv.set_defaults(run=cmd_serve)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 1 failed, 2 usage)."""
    args = build_parser().parse_args(argv)
    _CLAIMED.clear()  # (a process may run several commands: tests do)
    try:
        status: int = args.run(args)
    except _FILE_ERRORS as exc:
        print(f"wavecore: error: {_message(exc)}", file=sys.stderr)
        return 1
    return status


if __name__ == "__main__":
    sys.exit(main())
