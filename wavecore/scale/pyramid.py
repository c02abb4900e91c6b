"""Gigapixel images into a Zarr multiscale pyramid whose levels are the wavelet's coarse bands.

The image is cut into tiles (the Zarr chunks, ``tile × tile`` pixels, one channel each, in
OME-Zarr's ``(c, y, x)`` order).  Level ``k + 1`` of the pyramid is the coarse band of one
analysis step of level ``k`` (:func:`wavecore.decompose_image`, ``coarse(1)``: the low-pass
half, in the image's own units), computed tile by tile; the half-size tiles are gathered four
at a time into the next level's chunks.  Every level is stored with the wavecore codec
(:mod:`wavecore.zarr`), and the group carries OME-Zarr 0.5 ``multiscales`` metadata.

Dask does the work: one task per tile and level, so the memory of a worker is a few tiles,
whatever the image's size.  Whatever scheduler is active runs it: the local threads by
default, or a ``dask.distributed`` cluster when a client exists (``wavecore encode
--workers N`` starts a local one, ``--scheduler ADDRESS`` joins a running one).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidParameter
from ..images import decompose_image
from ..tiffchunks import tiff_layouts

try:
    import dask
    import dask.array as da
    import zarr
except ModuleNotFoundError as exc:  # pragma: no cover - exercised only without the extra
    msg = (
        f"wavecore.scale needs the zarr extra ({exc.name} is missing): pip install 'wavecore[zarr]'"
    )
    raise ModuleNotFoundError(msg, name=exc.name) from None

__all__ = ["PyramidInfo", "open_image_source", "read_region", "synthetic_rgb", "write_pyramid"]

DEFAULT_TILE = 1024
PYRAMID_WAVELET = "cdf97"  # its coarse band of n samples has exactly ceil(n / 2)
DEFAULT_IMAGE_CODEC = {"psnr": 40.0}  # the CLI's default for images
TILE_NAME = re.compile(r"_r(\d+)_c(\d+)$")
# The smallest side that one analysis step of the open boundary takes; smaller tiles (the last
# row or column of a level) are halved by averaging pairs.
SMALLEST_SIDE = 8
#: A TIFF's tile or strip, decoded, may take at most this many bytes, or four times a task's
#: window if that is more: each task decodes every TIFF tile or strip under its window whole.
#: (One zstd tile of 16384² zeros is 66 kB of file and 256 MiB decoded, in every task; one strip
#: of a whole big picture would be decoded whole by every task, a cost quadratic in its size.)
TIFF_CHUNK_BYTES = 16 * 2**20


@dataclass(frozen=True)
class PyramidInfo:
    """What :func:`write_pyramid` wrote.

    Attributes
    ----------
    shapes : list of tuple
        Each level's ``(c, y, x)`` shape, full resolution first.
    stored_bytes : int
        The bytes of every chunk of every level.
    raw_bytes : int
        Level 0's uncompressed size.
    """

    shapes: list[tuple[int, ...]]
    stored_bytes: int
    raw_bytes: int


def _halve(plane: np.ndarray, wavelet: str) -> np.ndarray:
    """One level of a 2-D tile: its coarse band, ``ceil(n / 2)`` per side, float64."""
    target = tuple(math.ceil(n / 2) for n in plane.shape)
    if min(plane.shape) >= SMALLEST_SIDE:
        coarse = decompose_image(plane, level=1, wavelet=wavelet).coarse(1)
    else:
        padded = np.pad(plane, [(0, n % 2) for n in plane.shape], mode="edge").astype(np.float64)
        coarse = 0.25 * (
            padded[0::2, 0::2] + padded[1::2, 0::2] + padded[0::2, 1::2] + padded[1::2, 1::2]
        )
    # A wavelet whose coarse band is not exactly half (the paper's interpolating bspline2 has
    # n / 2 + 1 control points) is cropped or edge-padded to the pyramid's grid.
    coarse = coarse[: target[0], : target[1]]
    extra = [(0, t - n) for t, n in zip(target, coarse.shape, strict=True)]
    return np.pad(coarse, extra, mode="edge") if any(e for _, e in extra) else coarse


def _cast(values: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), info.min, info.max).astype(dtype)
    return values.astype(dtype)


def _halve_block(block: np.ndarray, wavelet: str) -> np.ndarray:
    planes = [_halve(plane, wavelet) for plane in block]
    return _cast(np.stack(planes), block.dtype)


def _next_level(level: Any, tile: int, wavelet: str) -> Any:
    chunks = (level.chunks[0], *[tuple(math.ceil(n / 2) for n in c) for c in level.chunks[1:]])
    half = level.map_blocks(_halve_block, wavelet, chunks=chunks, dtype=level.dtype)
    # Tiles of tile / 2 gathered four at a time: the next level's chunks are whole tiles again.
    return half.rechunk((1, tile, tile))


def write_pyramid(
    source: Any,
    store: str | Path,
    *,
    config: dict[str, Any] | None = None,
    tile: int = DEFAULT_TILE,
    levels: int | None = None,
    wavelet: str = PYRAMID_WAVELET,
    name: str = "image",
) -> PyramidInfo:
    """Write an image as a Zarr multiscale pyramid (OME-Zarr 0.5) with the wavecore codec.

    Parameters
    ----------
    source : array_like or dask.array.Array
        ``(H, W)`` or ``(H, W, C)``, integer or float; a Dask array is never loaded whole.
    store : str or Path
        The Zarr store's folder (created; an existing one is replaced).
    config : dict, optional
        The codec's settings (:mod:`wavecore.zarr`) for every level; default ``psnr=40``.
    tile : int
        The chunks' side in pixels (each chunk is one channel of one tile).
    levels : int, optional
        Levels below full resolution; default: until the whole image fits in one tile.
    wavelet : str
        The wavelet whose coarse bands make the levels (default ``"cdf97"``).
    name : str
        The image's name in the metadata.

    Returns
    -------
    PyramidInfo
        The levels' shapes and the stored bytes.
    """
    from ..zarr import CodecConfig

    _check_tile(tile)
    codec = CodecConfig.from_mapping(config or DEFAULT_IMAGE_CODEC).to_dict()
    image = source if isinstance(source, da.Array) else da.from_array(np.asarray(source))
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3 or not 1 <= image.shape[2] <= 4 or min(image.shape[:2]) < 1:
        msg = f"an image is (H, W) or (H, W, C) with 1 to 4 channels, not shape {image.shape}"
        raise InvalidParameter(msg)
    height, width, _ = image.shape
    if levels is None:
        levels = max(0, math.ceil(math.log2(max(height, width) / tile)))
    level0 = image.transpose(2, 0, 1).rechunk((1, tile, tile))
    pyramid = [level0]
    for _ in range(levels):
        pyramid.append(_next_level(pyramid[-1], tile, wavelet))
    group = zarr.open_group(str(store), mode="w", zarr_format=3)
    targets = []
    for index, level in enumerate(pyramid):
        targets.append(
            group.create_array(
                str(index),
                shape=level.shape,
                chunks=(1, tile, tile),
                dtype=level.dtype,
                serializer={"name": "wavecore", "configuration": codec},
                compressors=None,
                dimension_names=("c", "y", "x"),
            )
        )
    group.attrs.update(_ome_metadata(name, len(pyramid), wavelet, codec, tile))
    da.store(pyramid, targets, lock=False)  # type: ignore[arg-type]
    stored = sum(p.stat().st_size for p in Path(store).rglob("*") if p.is_file())
    stored -= sum(p.stat().st_size for p in Path(store).rglob("zarr.json"))
    return PyramidInfo([tuple(p.shape) for p in pyramid], stored, int(level0.nbytes))


def _ome_metadata(
    name: str, count: int, wavelet: str, codec: dict[str, Any], tile: int
) -> dict[str, Any]:
    datasets = [
        {
            "path": str(k),
            "coordinateTransformations": [{"type": "scale", "scale": [1.0, 2.0**k, 2.0**k]}],
        }
        for k in range(count)
    ]
    multiscale = {
        "name": name,
        "axes": [
            {"name": "c", "type": "channel"},
            {"name": "y", "type": "space"},
            {"name": "x", "type": "space"},
        ],
        "datasets": datasets,
        "type": f"wavelet coarse bands ({wavelet})",
        "metadata": {"method": "wavecore.scale.write_pyramid", "wavelet": wavelet},
    }
    return {
        "ome": {"version": "0.5", "multiscales": [multiscale]},
        "wavecore": {"wavelet": wavelet, "codec": codec, "tile": tile},
    }


def read_region(
    store: str | Path,
    *,
    level: int = 0,
    region: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """A window of a pyramid at one resolution, reading only the chunks it touches.

    Parameters
    ----------
    store : str or Path
        What :func:`write_pyramid` wrote.
    level : int
        0 for full resolution, ``k`` for ``1 / 2**k`` of it.
    region : (y0, y1, x0, x1), optional
        The window in full-resolution pixels (default: all); at level ``k`` it covers pixels
        ``y0 // 2**k`` to ``ceil(y1 / 2**k)``.

    Returns
    -------
    numpy.ndarray
        ``(h, w, C)``, or ``(h, w)`` for one channel, in the image's dtype.
    """
    try:
        group: Any = zarr.open_group(str(store), mode="r")
        attrs: Any = group.attrs
        count = len(attrs["ome"]["multiscales"][0]["datasets"])
    except (FileNotFoundError, KeyError, IndexError, TypeError, ValueError) as exc:
        msg = f"{store} is not a pyramid written by wavecore encode ({exc})"
        raise InvalidParameter(msg) from None
    if isinstance(level, bool) or not isinstance(level, int) or not 0 <= level < count:
        msg = f"level must be an integer from 0 to {count - 1}, not {level!r}"
        raise InvalidParameter(msg)
    arr = group[str(level)]
    _, height, width = arr.shape
    full_height, full_width = group["0"].shape[1:]
    y0, y1, x0, x1 = region if region is not None else (0, full_height, 0, full_width)
    if not (0 <= y0 < y1 <= full_height and 0 <= x0 < x1 <= full_width):
        msg = (
            f"region {y0}:{y1},{x0}:{x1} is not a window of the {full_height}×{full_width} "
            "image (y0 < y1 <= height, x0 < x1 <= width)"
        )
        raise InvalidParameter(msg)
    step = 2**level
    window = arr[
        :, y0 // step : min(height, -(-y1 // step)), x0 // step : min(width, -(-x1 // step))
    ]
    out = np.moveaxis(np.asarray(window), 0, -1)
    return out[:, :, 0] if out.shape[2] == 1 else out


def _check_tile(tile: Any) -> None:
    if isinstance(tile, bool) or not isinstance(tile, int) or tile < 16 or tile % 2:
        msg = f"tile must be an even number of pixels >= 16, not {tile!r}"
        raise InvalidParameter(msg)


# --------------------------------------------------------------------------------------------
# Sources: a big TIFF read tile by tile, a folder of tiles, a synthesised image
# --------------------------------------------------------------------------------------------


def open_image_source(path: str | Path, *, tile: int = DEFAULT_TILE) -> Any:
    """A big image as a Dask array ``(H, W)`` or ``(H, W, C)``, without reading it.

    Parameters
    ----------
    path : str or Path
        A TIFF (read tile by tile or strip by strip through tifffile's Zarr view), a ``.npy``
        (memory-mapped), or a folder of tiles named ``<anything>_r<row>_c<col>.<ext>``
        (``.tif``/``.tiff``/``.npy``; ``.png``/``.jpg`` with Pillow), the tiles of a row of
        equal height and of a column of equal width.
    tile : int
        The Dask chunks' side.
    """
    _check_tile(tile)  # before a graph of one task per tile is built
    path = Path(path)
    if path.is_dir():
        return _tile_folder(path)
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            axes, shape, dtype = series.axes, tuple(series.shape), np.dtype(series.dtype)
            layouts = list(tiff_layouts(series))
        if not (axes in ("YX", "YXS") and (len(shape) == 2 or 1 <= shape[2] <= 4)):
            msg = f"{path} holds a TIFF of axes {axes}; expected YX or YXS (grey or RGB)"
            raise InvalidParameter(msg)
        window = tile * tile * (shape[2] if len(shape) == 3 else 1) * dtype.itemsize
        limit = max(TIFF_CHUNK_BYTES, 4 * window)
        largest = max(layouts, key=lambda layout: layout.chunk_bytes, default=None)
        if largest is not None and largest.chunk_bytes > limit:
            msg = (
                f"{path} stores its pixels in tiles or strips of "
                f"{' × '.join(map(str, largest.chunks))}, {largest.chunk_bytes} bytes each once "
                f"decoded, and each task of {tile} × {tile} pixels "
                f"decodes those under it whole; at most {limit} bytes are accepted: save it "
                "tiled (tifffile.imwrite(..., tile=(256, 256)))"
            )
            raise InvalidParameter(msg)
        # Each task opens the file itself and reads its window through tifffile's Zarr view
        # (only the TIFF tiles or strips under it): the tasks carry a path, not an open file,
        # so they run on any worker.
        template = da.empty(shape[:2], chunks=tile, dtype=np.uint8)
        extra = ((shape[2],),) if len(shape) == 3 else ()
        return template.map_blocks(
            _tiff_window,
            str(path),
            tile,
            chunks=(*template.chunks, *extra),
            dtype=dtype,
            new_axis=[2] if extra else None,
        )
    if suffix == ".npy":
        data = np.load(path, mmap_mode="r", allow_pickle=False)
        return da.from_array(data, chunks=(tile, tile, *data.shape[2:]))
    msg = f"{path}: a big image is a .tif/.tiff, a .npy or a folder of tiles, not {suffix!r}"
    raise InvalidParameter(msg)


def _tiff_window(
    template: np.ndarray, path: str, tile: int, block_id: tuple[int, ...] = (0, 0)
) -> np.ndarray:
    import tifffile

    y0, x0 = block_id[0] * tile, block_id[1] * tile
    y1, x1 = y0 + template.shape[0], x0 + template.shape[1]
    with tifffile.imread(path, aszarr=True, series=0, level=0) as store:
        return np.asarray(zarr.open_array(store, mode="r")[y0:y1, x0:x1])


def _read_tile(path: Path) -> np.ndarray:
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        import tifffile

        return np.asarray(tifffile.imread(path))
    if suffix == ".npy":
        return np.load(path, allow_pickle=False)
    try:
        from PIL import Image
    except ModuleNotFoundError:
        msg = f"reading the tile {path.name} needs Pillow: pip install 'wavecore[service]'"
        raise InvalidParameter(msg) from None
    with Image.open(path) as img:
        return np.asarray(img)


def _tile_folder(folder: Path) -> Any:
    grid: dict[tuple[int, int], Path] = {}
    for file in folder.iterdir():
        match = TILE_NAME.search(file.stem)
        if file.is_file() and match:
            grid[(int(match[1]), int(match[2]))] = file
    if not grid:
        msg = f"{folder} holds no tiles named <anything>_r<row>_c<col>.<ext>"
        raise InvalidParameter(msg)
    rows = 1 + max(r for r, _ in grid)
    cols = 1 + max(c for _, c in grid)
    missing = [(r, c) for r in range(rows) for c in range(cols) if (r, c) not in grid]
    if missing:
        msg = f"{folder}: tiles {missing[:5]} are missing from the {rows}×{cols} grid"
        raise InvalidParameter(msg)
    # Only the headers are read here, for the shapes; the pixels are read by the tasks.
    shapes = {key: _tile_shape(file) for key, file in grid.items()}
    blocks = []
    for r in range(rows):
        row = []
        for c in range(cols):
            shape, dtype = shapes[(r, c)]
            delayed = dask.delayed(_read_tile)(grid[(r, c)])
            row.append(da.from_delayed(delayed, shape=shape, dtype=dtype))
        blocks.append(row)
    try:
        return da.concatenate([da.concatenate(row, axis=1) for row in blocks], axis=0)
    except ValueError as exc:
        msg = f"{folder}: the tiles do not fit together ({exc})"
        raise InvalidParameter(msg) from None


def _tile_shape(path: Path) -> tuple[tuple[int, ...], np.dtype[Any]]:
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            return tuple(series.shape), np.dtype(series.dtype)
    if suffix == ".npy":
        data = np.load(path, mmap_mode="r", allow_pickle=False)
        return tuple(data.shape), data.dtype
    arr = _read_tile(path)
    return tuple(arr.shape), arr.dtype


def _synthetic_block(
    template: np.ndarray, tile: int, size: int, seed: int, block_id: tuple[int, ...] = (0, 0)
) -> np.ndarray:
    row, col = block_id[0], block_id[1]
    y = np.arange(row * tile, min(size, (row + 1) * tile))[:, None] / size
    x = np.arange(col * tile, min(size, (col + 1) * tile))[None, :] / size
    rng = np.random.default_rng([seed, row, col])
    channels = []
    for c in range(3):
        smooth = np.sin(2 * np.pi * (3 + c) * x + 5 * y) * np.cos(2 * np.pi * (2 + c) * y)
        texture = 0.15 * np.sin(2 * np.pi * 400 * (x + 0.5 * y + 0.1 * c))
        noise = 0.03 * rng.standard_normal((y.size, x.size))
        channels.append(127.5 + 100 * (0.8 * smooth + texture + noise))
    return np.clip(np.stack(channels, axis=-1), 0, 255).astype(np.uint8)


def synthetic_rgb(size: int, *, tile: int = DEFAULT_TILE, seed: int = 0) -> Any:
    """A ``size × size`` RGB ``uint8`` image made tile by tile (never whole in memory).

    Smooth colour gradients with a fine texture and a little noise, from a fixed seed.
    """
    template = da.empty((size, size), chunks=tile, dtype=np.uint8)
    return template.map_blocks(
        _synthetic_block,
        tile=tile,
        size=size,
        seed=seed,
        chunks=(*template.chunks, (3,)),
        dtype=np.uint8,
        new_axis=2,
    )
