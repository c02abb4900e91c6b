"""wavecore as a Zarr chunk codec, for numcodecs, zarr-python 3, xarray and Dask.

Large arrays live chunked in Zarr and are worked on in parallel by Dask; wavecore plugs into
both as a codec and builds no scheduler of its own.  Two classes, one chunk format:

- :class:`WavecoreCodec` is a ``numcodecs`` codec (id ``wavecore``, found through the
  ``numcodecs.codecs`` entry point): the compressor of Zarr format 2 arrays, and usable on its
  own (``numcodecs.get_codec({"id": "wavecore", "max_error": 0.01})``).
- :class:`WavecoreZarrCodec` is the zarr-python 3 array-to-bytes codec (name ``wavecore``,
  the ``zarr.codecs`` entry point): ``zarr.create_array(..., serializer={"name": "wavecore",
  "configuration": {"max_error": 0.01}})``.

Configuration (both): ``wavelet`` (default none: ``max_error`` by the interpolation coder,
the other targets by ``cdf97``), ``level`` (default automatic) and at most
one target: ``max_error`` (an absolute bound that holds on every value), ``psnr`` (dB against
each chunk's range, met or exceeded), ``bpp`` (bits per value of each coded slice's bundle;
of the chunk's bundle where it is coded whole, below) or ``lossless=True`` (integer data,
bit-exact).  No target: ``psnr=60``.

Chunks of any shape (partial edge chunks too) of 2-D and 3-D float or integer data.  A 3-D
chunk is coded as a stack of 2-D slices along its first axis (today's public API codes 2-D
grids); OME-Zarr's ``(c, y, x)`` images are then coded one channel at a time.  A 3-D chunk of
small slices (at most 64 × 64 values each, more than one) is coded whole by
:func:`wavecore.encode_grid` (mode 3) under a ``psnr`` or ``bpp`` target too: a bundle per
slice cost 7-25 ms and some 50 bytes whatever its size (a chunk of 65 536 slices of 1 × 1 did
not finish in 10 minutes).

The chunk format (little-endian)::

    b"WZC1"  u8 mode  u8 len(dtype)  dtype.str  u8 ndim  u32 shape[ndim]
    mode 0 (wavelet):  f64 offset  u32 n_slices  (u32 len  bundle) * n_slices
                       corrections: f64 step  u32 n  u32 len  zlib(u32 index deltas, i64 q)
                       exact values: u32 n  u32 len  zlib(u32 index deltas, values in dtype)
    mode 1 (raw):      zlib(the values in dtype)      (lossless integers too wide for 16 bits)
    mode 2 (constant): one value in dtype             (every value the same: empty chunks)
    mode 3 (grid):     a wavecore.encode_grid bundle  (max_error on finite or NaN values)

``max_error`` is coded by :func:`wavecore.encode_grid` (mode 3), NaN cells kept exactly.
Without a named wavelet that is its interpolation coder (multilevel interpolation quantized in
the loop, the bound held by construction: the fastest path, ~80 MB per CPU-second on the
benchmark's 512² float32 chunks); with one, one quantization of that wavelet's bands at a step
from the bound, the values past the bound corrected (SPERR's outliers). Chunks with infinite
values keep mode 0. In mode 0 the bound is guaranteed the same way: the chunk is
coded, decoded, and every value
whose error exceeds the bound gets a correction, a whole number of steps of ``2 × max_error``
(``2 × floor(max_error) + 1`` for integers); a value that still misses after the cast to its
dtype (or is NaN or infinite) is stored exactly.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from . import decode, encode_image, encode_surface, inspect
from .bundle import MAX_ELEMENTS
from .errors import BitrateTooLow, BundleError, InvalidParameter
from .filters import get_wavelet
from .grids import LAYOUT_FIELD, LAYOUT_VOLUME, any_infinite, checked_grid, encode_layout
from .inflate import inflate

try:
    import numcodecs
    from numcodecs.abc import Codec as _NumcodecsCodec
except ModuleNotFoundError as exc:  # pragma: no cover - exercised only without the extra
    msg = (
        f"wavecore.zarr needs the zarr extra ({exc.name} is missing): pip install 'wavecore[zarr]'"
    )
    raise ModuleNotFoundError(msg, name=exc.name) from None
try:
    from zarr.abc.codec import ArrayBytesCodec
    from zarr.core.buffer import Buffer, NDBuffer
except ModuleNotFoundError as exc:  # pragma: no cover - exercised only without the extra
    msg = (
        f"wavecore.zarr needs the zarr extra ({exc.name} is missing): pip install 'wavecore[zarr]'"
    )
    raise ModuleNotFoundError(msg, name=exc.name) from None

__all__ = [
    "CodecConfig",
    "WavecoreCodec",
    "WavecoreZarrCodec",
    "decode_chunk",
    "encode_chunk",
]

MAGIC = b"WZC1"
MODE_WAVELET, MODE_RAW, MODE_CONSTANT, MODE_GRID = 0, 1, 2, 3
# The wavelet of the psnr and bpp targets when none is named (max_error chunks without a named
# wavelet go to encode_grid's interpolation coder instead: see the module's docstring).
DEFAULT_WAVELET = "cdf97"
DEFAULT_PSNR = 60.0
# The bundle is coded to an RMSE of max_error / RMS_SHARE and the values past the bound are
# corrected.  On two 512 × 512 chunks of benchmarks/zarr_scale.py's field at 1e-3 × range, the
# chunks' bytes for 1.5, 2, 2.5, 3, 4, 6, 8, 12 were 22516, 9999, 4707, 2614, 2114, 2212,
# 2515, 3100: corrections cost more than the finer coding that avoids them.
RMS_SHARE = 4.0
# The finest quantizer reaches about 130 dB; a bound finer than that is met by the corrections.
MAX_PSNR = 110.0
_INTEGER_KINDS = "iu"


@dataclass(frozen=True)
class CodecConfig:
    """The codec's settings, checked.

    Attributes
    ----------
    wavelet : str or None
        The wavelet's name (see :func:`wavecore.wavelet_names`); ``None`` (the default): a
        ``max_error`` chunk is coded by :func:`wavecore.encode_grid`'s interpolation coder, the
        other targets by ``cdf97``.
    level : int or None
        Decomposition levels; ``None`` for automatic.
    max_error, psnr, bpp : float or None
        At most one target.
    lossless : bool
        Bit-exact coding of integer data.
    """

    wavelet: str | None = None
    level: int | None = None
    max_error: float | None = None
    psnr: float | None = None
    bpp: float | None = None
    lossless: bool = False

    @classmethod
    def from_mapping(cls, config: Mapping[str, Any]) -> CodecConfig:
        """Check a configuration (the codec's JSON keys) and fill in the defaults."""
        known = {"wavelet", "level", "max_error", "psnr", "bpp", "lossless"}
        if not isinstance(config, Mapping):
            example = "{'max_error': 0.01}"
            msg = f"the codec's settings must be a mapping such as {example}, not {config!r}"
            raise InvalidParameter(msg[:300])
        unknown = sorted(set(config) - known - {"id"})
        if unknown:
            msg = f"unknown wavecore codec setting(s) {unknown}; accepted: {sorted(known)}"
            raise InvalidParameter(msg)
        wavelet = config.get("wavelet") or None
        if wavelet is not None and not isinstance(wavelet, str):
            msg = f"wavelet must be a name such as 'cdf97' or 'bspline2', not {wavelet!r}"
            raise InvalidParameter(msg)
        if wavelet is not None:
            wavelet = get_wavelet(wavelet).name  # an unknown name raises InvalidParameter
        level = config.get("level")
        if level is not None and (
            isinstance(level, bool) or not isinstance(level, int | np.integer) or level < 1
        ):
            msg = f"level must be None or an integer >= 1, not {level!r}"
            raise InvalidParameter(msg)
        lossless = config.get("lossless", False)
        if not isinstance(lossless, bool | np.bool_):
            msg = f"lossless must be true or false, not {lossless!r}"
            raise InvalidParameter(msg)
        targets = {}
        for name in ("max_error", "psnr", "bpp"):
            value = config.get(name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int | float | np.number):
                msg = f"{name} must be a positive number, not {value!r}"
                raise InvalidParameter(msg)
            if not (math.isfinite(float(value)) and float(value) > 0):
                msg = f"{name} must be a positive finite number, not {value!r}"
                raise InvalidParameter(msg)
            targets[name] = float(value)
        if len(targets) + bool(lossless) > 1:
            given = sorted(targets) + (["lossless"] if lossless else [])
            msg = f"give one target of max_error, psnr, bpp or lossless, not {given}"
            raise InvalidParameter(msg)
        return cls(
            wavelet=wavelet,
            level=None if level is None else int(level),
            lossless=bool(lossless),
            **targets,
        )

    def to_dict(self) -> dict[str, Any]:
        """The settings that differ from the defaults, as JSON-ready values."""
        out: dict[str, Any] = {} if self.wavelet is None else {"wavelet": self.wavelet}
        if self.level is not None:
            out["level"] = self.level
        for name in ("max_error", "psnr", "bpp"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        if self.lossless:
            out["lossless"] = True
        return out


# --------------------------------------------------------------------------------------------
# The one function pair that codes a chunk
# --------------------------------------------------------------------------------------------


def encode_chunk(array: Any, config: CodecConfig | Mapping[str, Any]) -> bytes:
    """Code one chunk.

    Parameters
    ----------
    array : array_like
        A 2-D or 3-D chunk of any shape, float or integer (bool is taken as ``uint8``).
    config : CodecConfig or mapping
        The codec's settings (see the module's docstring).

    Returns
    -------
    bytes
        The chunk in the format of the module's docstring; :func:`decode_chunk` reverses it.

    Raises
    ------
    InvalidParameter
        For a chunk of another dimension or dtype, or ``lossless`` on float data.

    Examples
    --------
    >>> import numpy as np
    >>> field = np.sin(np.linspace(0, 6, 50))[:, None] * np.cos(np.linspace(0, 4, 37))
    >>> out = decode_chunk(encode_chunk(field, {"max_error": 1e-3}))
    >>> out.shape, bool(np.max(np.abs(out - field)) <= 1e-3)
    ((50, 37), True)
    """
    cfg = config if isinstance(config, CodecConfig) else CodecConfig.from_mapping(config)
    arr = _checked_chunk(array)
    head = _head(arr)
    if arr.size and _is_constant(arr):
        return head(MODE_CONSTANT) + arr.reshape(-1)[:1].tobytes()
    if arr.size == 0:
        return head(MODE_CONSTANT)
    integer = arr.dtype.kind in _INTEGER_KINDS
    if cfg.lossless and not integer:
        msg = (
            f"lossless applies to integer data, not {arr.dtype}; "
            "give max_error for a bound that holds on every value"
        )
        raise InvalidParameter(msg)
    slices = arr.reshape((-1, *arr.shape[-2:]))
    if integer:
        low, high = int(arr.min()), int(arr.max())
        if high - low >= 2**53 or high >= 2**63:
            # Beyond float64's whole numbers: stored as they are (zlib), whatever the target.
            return head(MODE_RAW) + zlib.compress(arr.tobytes(), 6)
        if cfg.lossless and high - low < 2**16:
            return _lossless_chunk(head, slices, low, high, cfg.level)
    if cfg.lossless:
        cfg = replace(cfg, lossless=False, max_error=0.5)  # integers within 0.5 are exact
    elif cfg.max_error is not None and not any_infinite(arr):
        # encode_grid, untiled: a chunk is already the unit of a window, and tiles above 256²
        # would cost the encoder some 14 % and each chunk bytes (~140 B a 1024² chunk).
        checked = checked_grid(arr, (2, 3), "grid")
        grid = encode_layout(
            checked,
            LAYOUT_VOLUME if checked.ndim == 3 else LAYOUT_FIELD,
            wavelet=cfg.wavelet,
            level=cfg.level,
            boundary=("open", "open"),
            max_error=cfg.max_error,
            tiles=False,
        )
        return head(MODE_GRID) + grid
    if cfg.max_error is None and cfg.psnr is None and cfg.bpp is None:
        cfg = replace(cfg, psnr=DEFAULT_PSNR)
    if cfg.max_error is None and _small_slices(arr) and not any_infinite(arr):
        # A bundle a slice costs some 7-25 ms and 50 bytes of header whatever the slice's
        # size: a volume of small slices is coded whole (its PSNR against the chunk's range,
        # its bpp over the chunk's bundle), the 2-D core taking the slices as channels.
        grid = encode_layout(
            checked_grid(arr, (3,), "grid"),
            LAYOUT_VOLUME,
            wavelet=cfg.wavelet,
            level=cfg.level,
            boundary=("open", "open"),
            psnr=cfg.psnr,
            bpp=cfg.bpp,
            tiles=False,
        )
        return head(MODE_GRID) + grid
    values = slices.astype(np.float64)
    finite = np.isfinite(values)
    if not finite.all():
        # NaN and infinities are stored exactly below; the wavelet sees the finite mean there.
        values = np.where(finite, values, np.mean(values[finite]) if finite.any() else 0.0)
    bundles = [_code_slice(plane, cfg) for plane in values]
    decoded = np.stack([_decode_slice(bundle, values.shape[1:]) for bundle in bundles])
    step, q, exact = _corrections(slices, decoded, finite, cfg.max_error)
    out = [head(MODE_WAVELET), struct.pack("<dI", 0.0, len(bundles))]
    out += [struct.pack("<I", len(b)) + b for b in bundles]
    out.append(_pack_corrections(step, q, exact, slices))
    coded = b"".join(out)
    if exact.size * 4 > arr.size:
        # A bound near the dtype's own resolution: most values are stored exactly anyway, and
        # the values as they are (zlib) are smaller and exact.
        raw = head(MODE_RAW) + zlib.compress(arr.tobytes(), 6)
        if len(raw) < len(coded):
            return raw
    return coded


def decode_chunk(data: Any) -> np.ndarray:
    """Decode what :func:`encode_chunk` made, in its own shape and dtype.

    Raises
    ------
    BundleError
        For bytes that are not a wavecore chunk, or a truncated or corrupt one.
    """
    try:
        buf = _bytes(data)
    except (TypeError, ValueError) as exc:  # objects, or an array of references
        msg = f"a wavecore chunk is bytes or a buffer, not {type(data).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc
    try:
        return _decode_chunk(buf)
    except BundleError:
        raise
    except (struct.error, ValueError, TypeError, zlib.error, IndexError) as exc:
        msg = f"corrupt wavecore chunk: {type(exc).__name__}: {exc}"
        raise BundleError(msg) from exc


#: A 3-D chunk whose slices hold at most this many values, and that has more than one, is
#: coded whole under a ``psnr`` or ``bpp`` target (mode 3), not a bundle per slice.
SMALL_SLICE = 64 * 64


def _small_slices(arr: np.ndarray) -> bool:
    return arr.ndim == 3 and arr.shape[0] > 1 and arr.shape[1] * arr.shape[2] <= SMALL_SLICE


def _lossless_chunk(head: Any, slices: np.ndarray, low: int, high: int, level: int | None) -> bytes:
    """Integers spanning under 2**16: each slice less the chunk's minimum, coded losslessly."""
    narrow = np.uint8 if high - low < 2**8 else np.uint16
    planes = [(plane.astype(np.int64) - low).astype(narrow) for plane in slices]
    bundles = [
        encode_image(plane, lossless=True, level=_lossless_level(plane, level)) for plane in planes
    ]
    empty = np.zeros(0, dtype=np.int64)
    out = [head(MODE_WAVELET), struct.pack("<dI", float(low), len(bundles))]
    out += [struct.pack("<I", len(b)) + b for b in bundles]
    out.append(_pack_corrections(0.0, (empty, empty), empty, slices))
    return b"".join(out)


def _lossless_level(plane: np.ndarray, level: int | None) -> int | None:
    # The lossless filters leave every subband non-empty only up to log2 of the shorter side.
    if level is None:
        return None
    return max(0, min(level, min(plane.shape).bit_length() - 1))


def _code_slice(plane: np.ndarray, cfg: CodecConfig) -> bytes:
    """One 2-D slice (float64, finite) into a bundle of today's public API."""
    wavelet = cfg.wavelet or DEFAULT_WAVELET
    if cfg.bpp is not None:
        try:
            return encode_image(plane, wavelet=wavelet, level=cfg.level, bpp=cfg.bpp)
        except BitrateTooLow as exc:  # said of the chunk's slice, not of an image
            smallest = exc.smallest_bytes
            msg = (
                f"bpp {cfg.bpp} is below what a {plane.shape[0]} × {plane.shape[1]} slice of "
                f"this chunk can be coded in: bpp {8 * smallest / plane.size:.4f} "
                f"({smallest} bytes a slice) codes it"
            )
            raise BitrateTooLow(msg, smallest) from None
    if cfg.psnr is not None:
        psnr = cfg.psnr
    else:
        assert cfg.max_error is not None
        span = float(plane.max() - plane.min())
        if span <= cfg.max_error:
            # Within the bound of a constant: the coarsest coding, corrected where needed.
            psnr = 20.0
        else:
            psnr = min(20.0 * math.log10(span * RMS_SHARE / cfg.max_error), MAX_PSNR)
    return encode_surface(plane, wavelet=wavelet, level=cfg.level, quality=psnr)


def _decode_slice(bundle: bytes, shape: tuple[int, ...]) -> np.ndarray:
    """A slice's bundle decoded, once its header says it has the chunk's slice ``shape``."""
    declared = tuple(inspect(bundle).get("shape") or ())
    if declared != tuple(shape):
        msg = f"wavecore chunk: a slice's bundle has shape {declared}, the chunk's slices {shape}"
        raise BundleError(msg)
    return np.asarray(decode(bundle), dtype=np.float64)


def _check_count(count: int, size: int, what: str) -> None:
    if count > size:
        msg = f"wavecore chunk: {count} {what} for {size} values"
        raise BundleError(msg)


def _inflate(data: bytes, expected: int, what: str) -> bytes:
    """``data`` decompressed, which must give ``expected`` bytes: no more is ever inflated."""
    raw = inflate(data, expected, f"wavecore chunk's {what}")
    if len(raw) != expected:
        msg = f"wavecore chunk: its {what} inflate to other than {expected} bytes"
        raise BundleError(msg)
    return raw


# --------------------------------------------------------------------------------------------
# Corrections: the bound on every value
# --------------------------------------------------------------------------------------------


def _reconstructed(
    decoded: np.ndarray, step: float, index: np.ndarray, q: np.ndarray, dtype: np.dtype[Any]
) -> np.ndarray:
    """The decoded values plus the corrections, cast to ``dtype`` (the decoder's arithmetic)."""
    flat = decoded.reshape(-1).copy()
    if index.size:
        flat[index] += q.astype(np.float64) * step
    return _cast(flat, dtype).reshape(decoded.shape)


def _cast(values: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    if dtype.kind in _INTEGER_KINDS:
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), float(info.min), float(info.max)).astype(dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        return values.astype(dtype)


def _corrections(
    original: np.ndarray, decoded: np.ndarray, finite: np.ndarray, bound: float | None
) -> tuple[float, tuple[np.ndarray, np.ndarray], np.ndarray]:
    """(step, (index, q)) of the quantized corrections, and the indices stored exactly."""
    dtype = original.dtype
    flat = original.reshape(-1)
    finite_flat = finite.reshape(-1)
    empty = np.zeros(0, dtype=np.int64)
    if bound is None:
        return 0.0, (empty, empty), np.flatnonzero(~finite_flat)
    integer = dtype.kind in _INTEGER_KINDS
    step = 2.0 * math.floor(bound) + 1.0 if integer else 2.0 * bound
    exact_values = flat.astype(np.float64)
    as_stored = _cast(decoded.reshape(-1), dtype)
    if integer:  # in whole numbers: float64 would round values past 2**53
        error = np.abs(as_stored.astype(np.int64) - flat.astype(np.int64)).astype(np.float64)
    else:
        error = np.abs(as_stored.astype(np.float64) - exact_values)
    over = np.flatnonzero((error > bound) & finite_flat)
    residual = exact_values[over] - decoded.reshape(-1)[over]
    with np.errstate(over="ignore", invalid="ignore"):
        q = np.rint(residual / step)
    usable = np.isfinite(q) & (np.abs(q) < 2**62)
    index, q = over[usable], q[usable].astype(np.int64)
    fixed = _reconstructed(decoded, step, index, q, dtype).reshape(-1)
    if integer:
        still = np.abs(fixed.astype(np.int64) - flat.astype(np.int64)) > bound
    else:
        still = ~(np.abs(fixed.astype(np.float64) - exact_values) <= bound)
    still &= finite_flat
    still[over[~usable]] = True
    keep = ~still[index]
    exact = np.flatnonzero(still | ~finite_flat)
    return step, (index[keep], q[keep]), exact


def _pack_indices(index: np.ndarray) -> bytes:
    deltas = np.diff(index, prepend=0).astype("<u4")
    return deltas.tobytes()


def _unpack_indices(raw: bytes, n: int) -> np.ndarray:
    deltas = np.frombuffer(raw, dtype="<u4", count=n)
    return np.cumsum(deltas, dtype=np.int64)


def _pack_corrections(
    step: float, corrections: tuple[np.ndarray, np.ndarray], exact: np.ndarray, original: np.ndarray
) -> bytes:
    index, q = corrections
    part = zlib.compress(_pack_indices(index) + q.astype("<i8").tobytes(), 6)
    values = original.reshape(-1)[exact]
    dtype = original.dtype.newbyteorder("<")
    tail = zlib.compress(_pack_indices(exact) + values.astype(dtype).tobytes(), 6)
    return b"".join(
        [
            struct.pack("<dII", step, index.size, len(part)),
            part,
            struct.pack("<II", exact.size, len(tail)),
            tail,
        ]
    )


# --------------------------------------------------------------------------------------------
# Decoding
# --------------------------------------------------------------------------------------------


def _decode_chunk(buf: bytes) -> np.ndarray:
    if buf[:4] != MAGIC:
        msg = f"not a wavecore chunk: starts with {buf[:4]!r}, not {MAGIC!r}"
        raise BundleError(msg)
    mode, dlen = buf[4], buf[5]
    pos = 6
    dtype = np.dtype(buf[pos : pos + dlen].decode("ascii"))
    if dtype.kind not in "iufb" or dtype.itemsize > 8:
        msg = f"wavecore chunk of dtype {dtype}; expected an integer or float dtype"
        raise BundleError(msg)
    pos += dlen
    ndim = buf[pos]
    pos += 1
    shape = struct.unpack_from(f"<{ndim}I", buf, pos)
    pos += 4 * ndim
    size = math.prod(shape)
    if size > MAX_ELEMENTS:  # before anything of that size is made: 26 bytes could ask 4 GB
        msg = f"wavecore chunk of shape {shape}: {size} values, more than {MAX_ELEMENTS}"
        raise BundleError(msg)
    if mode == MODE_CONSTANT:
        if size == 0:
            return np.zeros(shape, dtype=dtype)
        value = np.frombuffer(buf, dtype=dtype, count=1, offset=pos)
        return np.full(shape, value[0], dtype=dtype)
    if mode == MODE_RAW:
        raw = _inflate(buf[pos:], size * dtype.itemsize, "values")
        return np.frombuffer(raw, dtype=dtype).reshape(shape)
    if mode == MODE_GRID:
        grid = np.asarray(decode(buf[pos:]))
        if grid.shape != shape:
            msg = f"wavecore chunk: its grid has shape {grid.shape}, the chunk {shape}"
            raise BundleError(msg)
        return grid.astype(dtype, copy=False)
    if mode != MODE_WAVELET:
        msg = f"wavecore chunk mode {mode}; expected 0, 1, 2 or 3"
        raise BundleError(msg)
    offset, n_slices = struct.unpack_from("<dI", buf, pos)
    pos += 12
    planes = []
    slice_shape = shape[1:] if ndim == 3 else shape
    for _ in range(n_slices):
        (length,) = struct.unpack_from("<I", buf, pos)
        pos += 4
        planes.append(_decode_slice(buf[pos : pos + length], slice_shape))
        pos += length
    decoded = np.stack(planes) + offset if planes else np.zeros((0, 0, 0))
    if decoded.size != size:
        msg = f"wavecore chunk: slices hold {decoded.size} values, the shape {shape} needs {size}"
        raise BundleError(msg)
    step, n_q, length = struct.unpack_from("<dII", buf, pos)
    pos += 16
    _check_count(n_q, size, "corrections")
    raw = _inflate(buf[pos : pos + length], 12 * n_q, "corrections")
    pos += length
    index = _unpack_indices(raw, n_q)
    q = np.frombuffer(raw, dtype="<i8", count=n_q, offset=4 * n_q)
    out = _reconstructed(decoded, step, index, q, dtype).reshape(-1)
    n_exact, length = struct.unpack_from("<II", buf, pos)
    pos += 8
    _check_count(n_exact, size, "exact values")
    raw = _inflate(buf[pos : pos + length], (4 + dtype.itemsize) * n_exact, "exact values")
    exact = _unpack_indices(raw, n_exact)
    out[exact] = np.frombuffer(
        raw, dtype=dtype.newbyteorder("<"), count=n_exact, offset=4 * n_exact
    )
    return out.reshape(shape)


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _bytes(data: Any) -> bytes:
    if isinstance(data, bytes):
        return data
    try:
        return memoryview(data).cast("B").tobytes()
    except TypeError:
        return np.ascontiguousarray(np.asarray(data)).view(np.uint8).tobytes()


def _checked_chunk(array: Any) -> np.ndarray:
    arr = np.asarray(array)
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8)
    if arr.dtype.kind not in "iuf" or arr.dtype.itemsize > 8:
        msg = f"the wavecore codec takes integer or float data, not dtype {arr.dtype}"
        raise InvalidParameter(msg)
    if arr.ndim not in (2, 3):
        msg = (
            f"the wavecore codec takes 2-D or 3-D chunks, not shape {arr.shape}; "
            "a Zarr format 2 array passes its chunks' shape only without filters"
        )
        raise InvalidParameter(msg)
    if arr.size > MAX_ELEMENTS:
        msg = (
            f"chunk shape {arr.shape} holds {arr.size} values, more than {MAX_ELEMENTS} "
            "(what a decoder accepts); use smaller chunks"
        )
        raise InvalidParameter(msg)
    return np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("="))


def _head(arr: np.ndarray) -> Any:
    dtype = arr.dtype.newbyteorder("<").str.encode("ascii")
    shape = struct.pack(f"<B{arr.ndim}I", arr.ndim, *arr.shape)

    def head(mode: int) -> bytes:
        return MAGIC + bytes([mode, len(dtype)]) + dtype + shape

    return head


def _is_constant(arr: np.ndarray) -> bool:
    flat = arr.reshape(-1)
    first = flat[:1]
    if arr.dtype.kind == "f" and np.isnan(first[0]):
        return bool(np.isnan(flat).all())
    # Most chunks differ within their first values: told apart without a pass over the chunk.
    if not (flat[:64] == first).all():
        return False
    return bool((flat == first).all())


# --------------------------------------------------------------------------------------------
# numcodecs and zarr-python 3
# --------------------------------------------------------------------------------------------


class WavecoreCodec(_NumcodecsCodec):
    """The numcodecs codec ``wavecore``: a 2-D or 3-D chunk in, bytes out.

    Parameters
    ----------
    wavelet : str, optional
        Default none: ``max_error`` by :func:`wavecore.encode_grid`'s interpolation coder,
        the other targets by ``cdf97``.
    level : int, optional
        Default automatic.
    max_error, psnr, bpp : float, optional
        At most one target (see :mod:`wavecore.zarr`).
    lossless : bool
        Bit-exact, for integer data.

    Examples
    --------
    >>> import numcodecs, numpy as np
    >>> codec = numcodecs.get_codec({"id": "wavecore", "max_error": 0.5})
    >>> chunk = np.arange(35 * 20, dtype=np.float32).reshape(35, 20)
    >>> bool(np.abs(codec.decode(codec.encode(chunk)) - chunk).max() <= 0.5)
    True
    """

    codec_id = "wavecore"

    def __init__(
        self,
        wavelet: str | None = None,
        level: int | None = None,
        max_error: float | None = None,
        psnr: float | None = None,
        bpp: float | None = None,
        lossless: bool = False,
    ) -> None:
        self.config = CodecConfig.from_mapping(
            {
                "wavelet": wavelet,
                "level": level,
                "max_error": max_error,
                "psnr": psnr,
                "bpp": bpp,
                "lossless": lossless,
            }
        )
        for name, value in self.config.to_dict().items():
            setattr(self, name, value)

    def encode(self, buf: Any) -> bytes:
        """Code a chunk (an array of 2 or 3 dimensions)."""
        return encode_chunk(buf, self.config)

    def decode(self, buf: Any, out: Any = None) -> np.ndarray:
        """Decode a chunk; with ``out``, into it (same number of values)."""
        arr = decode_chunk(buf)
        if out is None:
            return arr
        target = np.asarray(out)
        if target.nbytes != arr.nbytes:
            msg = (
                f"out holds {target.nbytes} bytes; the chunk decodes to {arr.size} values of "
                f"{arr.dtype} ({arr.nbytes} bytes)"
            )
            raise InvalidParameter(msg)
        target.reshape(-1).view(arr.dtype)[:] = arr.reshape(-1)
        return target

    def get_config(self) -> dict[str, Any]:
        """The JSON configuration, with ``id``."""
        return {"id": self.codec_id, **self.config.to_dict()}

    def __repr__(self) -> str:
        settings = ", ".join(f"{k}={v!r}" for k, v in self.config.to_dict().items())
        return f"WavecoreCodec({settings})"


numcodecs.register_codec(WavecoreCodec)


class WavecoreZarrCodec(ArrayBytesCodec):
    """The zarr-python 3 array-to-bytes codec ``wavecore`` (the ``serializer``).

    ``zarr.create_array(store, shape=..., chunks=..., dtype="float32",
    serializer={"name": "wavecore", "configuration": {"max_error": 0.01}}, compressors=None)``;
    the configuration is that of :class:`WavecoreCodec`.
    """

    is_fixed_size = False

    def __init__(self, **configuration: Any) -> None:
        self.config = CodecConfig.from_mapping(configuration)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> WavecoreZarrCodec:
        """The codec of ``{"name": "wavecore", "configuration": {...}}``."""
        name = data.get("name", "wavecore")
        if name != "wavecore":
            msg = f"codec name {name!r} is not 'wavecore'"
            raise InvalidParameter(msg)
        return cls(**dict(data.get("configuration") or {}))

    def to_dict(self) -> dict[str, Any]:
        """``{"name": "wavecore", "configuration": {...}}``, as stored in zarr.json."""
        return {"name": "wavecore", "configuration": self.config.to_dict()}

    def __eq__(self, other: object) -> bool:
        return isinstance(other, WavecoreZarrCodec) and other.config == self.config

    def __hash__(self) -> int:
        return hash(self.config)

    def __repr__(self) -> str:
        settings = ", ".join(f"{k}={v!r}" for k, v in self.config.to_dict().items())
        return f"WavecoreZarrCodec({settings})"

    async def _decode_single(self, chunk_bytes: Buffer, chunk_spec: Any) -> NDBuffer:
        arr = decode_chunk(chunk_bytes.as_numpy_array())
        arr = arr.astype(chunk_spec.dtype.to_native_dtype(), copy=False).reshape(chunk_spec.shape)
        return chunk_spec.prototype.nd_buffer.from_numpy_array(arr)

    async def _encode_single(self, chunk_array: NDBuffer, chunk_spec: Any) -> Buffer:
        data = encode_chunk(chunk_array.as_numpy_array(), self.config)
        return chunk_spec.prototype.buffer.from_bytes(data)

    def compute_encoded_size(self, input_byte_length: int, chunk_spec: Any) -> int:
        raise NotImplementedError  # the coded size depends on the data
