"""Entropy coding of quantized subbands, one chunk per resolution level, coarse to fine.

``encode_levels`` turns the integers of a decomposition (``wavedec2`` layout
``[cA, (cH, cV, cD), ...]`` or ``wavedec`` layout ``[cA, cD, ...]``) into one byte chunk per
list entry, so that the first ``k`` chunks decode to the first ``k`` entries: a prefix of a
bundle is a complete lower-resolution image.

Coders:

``"zlib"``
    The generic baseline: the level's integers as little-endian ``int32``, deflated.
``"context"``
    The default: a context-modelling range coder (for now it falls back to ``"zlib"``).

The decoder treats its input as hostile: every chunk is checked against the sizes the caller
declares (``shapes``), decompression is bounded by those sizes, and anything wrong raises
:class:`wavecore.errors.BundleError`.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import Any

import constriction
import numpy as np
from numba import njit

from .errors import BundleError, InvalidParameter

__all__ = ["CODERS", "decode_levels", "encode_levels"]

CODERS = ("context", "zlib")
#: The most elements :func:`decode_levels` accepts in one call (matches the bundle limit).
MAX_ELEMENTS = 1 << 31


def _entries(qcoeffs: Sequence[Any]) -> list[list[np.ndarray]]:
    if isinstance(qcoeffs, np.ndarray) or not len(qcoeffs):
        msg = "qcoeffs must be a non-empty list [cA, details of level L, ..., details of level 1]"
        raise InvalidParameter(msg)
    out = []
    for entry in qcoeffs:
        bands = list(entry) if isinstance(entry, tuple | list) else [entry]
        arrays = []
        for band in bands:
            arr = np.asarray(band)
            if arr.dtype.kind not in "iu":
                msg = f"quantized coefficients must be integers, not {arr.dtype}"
                raise InvalidParameter(msg)
            if arr.size and (arr.min() < -(2**31) or arr.max() >= 2**31):
                msg = "quantized coefficients must fit in int32"
                raise InvalidParameter(msg)
            arrays.append(arr.astype(np.int32, copy=False))
        out.append(arrays)
    return out


def _check_coder(coder: Any) -> str:
    if coder not in CODERS:
        accepted = ", ".join(repr(c) for c in CODERS)
        msg = f"unknown coder {coder!r}; accepted coders are {accepted}"
        raise InvalidParameter(msg)
    return str(coder)


def encode_levels(
    qcoeffs: Sequence[Any], *, coder: str = "context"
) -> tuple[list[bytes], dict[str, Any]]:
    """Entropy-code quantized coefficients, one chunk per resolution level.

    Parameters
    ----------
    qcoeffs : list
        Integer arrays in ``wavedec2`` or ``wavedec`` layout, coarse first (as made by
        :func:`wavecore.quantize.quantize_bands`, or integer lifting for lossless coding).
    coder : {"context", "zlib"}
        ``"context"`` (default) is the context-modelling range coder; ``"zlib"`` the generic
        baseline.

    Returns
    -------
    chunks : list of bytes
        ``chunks[0]`` codes ``cA``, ``chunks[i]`` all bands of entry ``i``.
    params : dict
        JSON-serialisable; :func:`decode_levels` needs it.

    Examples
    --------
    >>> import numpy as np
    >>> q = [np.arange(6, dtype=np.int32).reshape(2, 3), np.array([0, -1, 0, 2], dtype=np.int32)]
    >>> chunks, params = encode_levels(q, coder="zlib")
    >>> len(chunks)
    2
    >>> back = decode_levels(chunks, [(2, 3), (4,)], params)
    >>> bool(np.array_equal(back[1], q[1]))
    True
    """
    coder = _check_coder(coder)
    entries = _entries(qcoeffs)
    if coder == "context":
        return _encode_context(entries)
    chunks = []
    for bands in entries:
        raw = b"".join(band.astype("<i4", copy=False).tobytes() for band in bands)
        chunks.append(zlib.compress(raw, 9))
    return chunks, {"coder": "zlib"}


def _shape_entries(shapes: Sequence[Any]) -> list[list[tuple[int, ...]]]:
    """Normalise ``shapes`` (``[shape, (shape, shape, shape) | shape, ...]``) and bound them."""
    if isinstance(shapes, np.ndarray) or not isinstance(shapes, Sequence):
        msg = "shapes must be a list of band shapes"
        raise BundleError(msg)
    out = []
    total = 0
    for entry in shapes:
        if not isinstance(entry, tuple | list):
            msg = f"band shape entry {entry!r} is not a tuple"
            raise BundleError(msg)
        if entry and all(isinstance(e, tuple | list) for e in entry):
            bands = [tuple(e) for e in entry]
        else:
            bands = [tuple(entry)]
        for band in bands:
            if not all(isinstance(n, int | np.integer) and 0 <= n <= MAX_ELEMENTS for n in band):
                msg = f"band shape {band!r} is not a tuple of sizes"
                raise BundleError(msg)
            total += int(np.prod(band, dtype=object))
            if total > MAX_ELEMENTS:
                msg = f"band shapes declare more than {MAX_ELEMENTS} coefficients"
                raise BundleError(msg)
        out.append([tuple(int(n) for n in band) for band in bands])
    return out


def _inflate(chunk: bytes, expected: int) -> bytes:
    """Decompress at most ``expected`` bytes; anything else is a corrupt chunk."""
    try:
        inflater = zlib.decompressobj()
        raw = inflater.decompress(chunk, expected)
        if inflater.unconsumed_tail or not inflater.eof:
            msg = "zlib chunk does not hold exactly the declared number of coefficients"
            raise BundleError(msg)
    except zlib.error as exc:
        msg = f"corrupt zlib chunk: {exc}"
        raise BundleError(msg) from exc
    if len(raw) != expected or inflater.unused_data:
        msg = (
            f"zlib chunk holds {len(raw)} bytes (+{len(inflater.unused_data)} trailing), "
            f"expected {expected}"
        )
        raise BundleError(msg)
    return raw


def decode_levels(
    chunks: Sequence[bytes], shapes: Sequence[Any], params: dict[str, Any]
) -> list[Any]:
    """Decode the first ``len(chunks)`` levels into integer arrays of the given shapes.

    Parameters
    ----------
    chunks : sequence of bytes
        A prefix of what :func:`encode_levels` returned.
    shapes : sequence
        Band shapes for (at least) those entries, in the same layout: ``shape`` for ``cA`` and
        1-D details, a tuple of three shapes for 2-D details.
    params : dict
        As returned by :func:`encode_levels` (treated as untrusted).

    Returns
    -------
    list
        ``int32`` arrays, ``[cA, (cH, cV, cD) | cD, ...]``, one entry per chunk.

    Raises
    ------
    BundleError
        For anything inconsistent or corrupt; never another exception.
    """
    if not isinstance(params, dict) or params.get("coder") not in CODERS:
        msg = f"entropy coder parameters must name a coder in {CODERS}, not {params!r}"
        raise BundleError(msg)
    if isinstance(chunks, bytes | bytearray) or not isinstance(chunks, Sequence):
        msg = "chunks must be a list of byte strings"
        raise BundleError(msg)
    layout = _shape_entries(shapes)
    if len(chunks) > len(layout) or not chunks:
        msg = f"{len(chunks)} chunks given for {len(layout)} band entries"
        raise BundleError(msg)
    layout = layout[: len(chunks)]
    if params["coder"] == "context":
        levels = _decode_context(chunks, layout, params)
    else:
        levels = _decode_zlib(chunks, layout)
    out: list[Any] = []
    for index, (arrays, bands) in enumerate(zip(levels, layout, strict=True)):
        is_single = len(bands) == 1 and not (
            index > 0 and isinstance(shapes[index], tuple | list) and _is_nested(shapes[index])
        )
        out.append(arrays[0] if is_single else tuple(arrays))
    return out


def _is_nested(entry: Any) -> bool:
    return bool(entry) and all(isinstance(e, tuple | list) for e in entry)


def _decode_zlib(
    chunks: Sequence[bytes], layout: list[list[tuple[int, ...]]]
) -> list[list[np.ndarray]]:
    levels = []
    for chunk, bands in zip(chunks, layout, strict=True):
        if not isinstance(chunk, bytes | bytearray | memoryview):
            msg = "each chunk must be bytes"
            raise BundleError(msg)
        sizes = [int(np.prod(b, dtype=np.int64)) for b in bands]
        raw = _inflate(bytes(chunk), 4 * sum(sizes))
        flat = np.frombuffer(raw, dtype="<i4").astype(np.int32)
        arrays, start = [], 0
        for band, size in zip(bands, sizes, strict=True):
            arrays.append(flat[start : start + size].reshape(band))
            start += size
        levels.append(arrays)
    return levels


# --------------------------------------------------------------------------------------------
# The context coder
# --------------------------------------------------------------------------------------------

#: Magnitudes ``0 .. ESCAPE - 1`` are symbols of their own; larger ones send ``ESCAPE`` and then
#: the excess as an exponent (adaptive) and raw mantissa bits.
ESCAPE = 17
_ALPHABET = ESCAPE + 1
_EXPONENTS = 33
#: Upper edges of the activity bins (the activity is a weighted mean of known neighbour
#: magnitudes, in quantizer steps); bin 0 is "every known neighbour is zero".
#: Upper edges of the activity bins, in thousandths of a quantizer step (the activity is a
#: weighted mean of known neighbour magnitudes); bin 0 is "every known neighbour is zero".
_EDGES_MILLI = np.array(
    [0, 100, 200, 350, 550, 800, 1150, 1600, 2200, 3000, 4200, 6000, 9000, 14000], dtype=np.int64
)
_ACTIVITY_EDGES = _EDGES_MILLI / 1000.0
_BINS = len(_EDGES_MILLI) + 1
#: Three interlaced passes over a band: (even, even); (odd, odd), which sees its four diagonal
#: neighbours; then (even, odd) and (odd, even), which see the four direct ones.
_PASSES = (((0, 0),), ((1, 1),), ((0, 1), (1, 0)))
_CLASSES = len(_PASSES) * _BINS
_APPROX_CLASSES = _BINS
#: Counts are halved once a class has seen this many symbols, so the model follows the data.
_COUNT_LIMIT = 1 << 21
#: Counts are integers (so that every machine computes the same probabilities) in units of
#: 1/_UNIT observation: a symbol never seen keeps a small but nonzero probability.
_UNIT = 32
_PRIOR_WEIGHT = 8
#: Context weights, in halves, so that all context arithmetic is in integers and every machine
#: computes the same classes: the four direct neighbours, the four diagonal ones, the parent,
#: each earlier band of the same level, and the first channel (luma) at the same place.
_W_DIRECT, _W_DIAGONAL, _W_PARENT, _W_SIBLING, _W_LUMA = 4, 2, 2, 1, 6
#: The parent term is (9 · parent + sum of its 3 × 3 neighbourhood) / 18: everything is scaled
#: by 18.
_PARENT_SCALE = 18
CONTEXT_VERSION = 2
#: Sign contexts per orientation: one for the first pass, then the sums of the known
#: neighbours' signs (each in -2..2) along two directions: diagonals in the second pass,
#: rows and columns in the third.  Textures (brick) have strongly aligned signs.
_SIGN_CONTEXTS = 1 + 25 + 25
_FIRST_SEGMENT = 8
#: At each new level the detail counts keep their shape but shrink to about this many
#: observations, so the model re-learns the level's own statistics quickly.
_LEVEL_MEMORY = 24


def _prior(bins: int) -> np.ndarray:
    """Initial pseudo-counts: geometric magnitudes whose mean grows with the activity bin."""
    centres = np.concatenate([[0.02], _ACTIVITY_EDGES[1:], [20.0]])[:bins]
    counts = np.empty((bins, _ALPHABET))
    k = np.arange(_ALPHABET)
    for b, mean in enumerate(centres):
        ratio = mean / (1.0 + mean)
        p = (1 - ratio) * ratio**k
        p[-1] = ratio**ESCAPE
        counts[b] = np.maximum(np.round(_PRIOR_WEIGHT * _UNIT * p), 1)
    return counts.astype(np.int64)


class _Models:
    """Adaptive symbol counts per context class, identical in encoder and decoder."""

    def __init__(self) -> None:
        self.detail = np.tile(_prior(_BINS), (len(_PASSES), 1))
        self.approx = _prior(_BINS)
        self.exponent = np.full(_EXPONENTS, _UNIT // 4, dtype=np.int64)
        self.sign = np.full((3 * _SIGN_CONTEXTS, 2), _UNIT, dtype=np.int64)

    def new_level(self) -> None:
        totals = self.detail.sum(axis=1, keepdims=True)
        scaled = (self.detail * (_LEVEL_MEMORY * _UNIT)) // totals
        self.detail = np.maximum(scaled, 1).astype(np.int64)

    @staticmethod
    def model(counts: np.ndarray) -> Any:
        return _model.Categorical(counts.astype(np.float64), perfect=False)

    @staticmethod
    def update(counts: np.ndarray, symbols: np.ndarray) -> None:
        counts += _UNIT * np.bincount(symbols, minlength=len(counts))
        if counts.sum() > _COUNT_LIMIT:
            counts[:] = (counts + 1) // 2


def _groups(classes: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """``(class, positions)`` for each class present, ascending, positions in scan order."""
    small = classes.astype(np.uint8)  # fewer than 256 classes: NumPy radix-sorts bytes
    order = np.argsort(small, kind="stable")
    ordered = small[order]
    edges = np.flatnonzero(np.diff(ordered)) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(order)]])
    return [(int(ordered[a]), order[a:b]) for a, b in zip(starts, stops, strict=True) if b > a]


def _segments(count: int) -> list[slice]:
    """Split ``count`` symbols into runs of doubling length; the model adapts between runs."""
    out, start, size = [], 0, _FIRST_SEGMENT
    while start < count:
        out.append(slice(start, min(count, start + size)))
        start += size
        size *= 2
    return out


def _fit(arr: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Crop or edge-extend a 2-D array to ``rows × cols`` (bands of one level differ a little)."""
    arr = arr[:rows, :cols]
    if arr.shape != (rows, cols):
        arr = np.pad(arr, ((0, rows - arr.shape[0]), (0, cols - arr.shape[1])), mode="edge")
    return arr


def _external(
    shape: tuple[int, int], parent: np.ndarray | None, siblings: list[tuple[np.ndarray, int]]
) -> tuple[np.ndarray, int]:
    """Scaled sum and weight of the context from other, already coded, bands (integers)."""
    rows, cols = shape
    total = np.zeros(shape, dtype=np.int64)
    weight = 0
    if parent is not None and parent.size:
        padded = np.pad(parent, 1, mode="edge")
        box = np.zeros(parent.shape, dtype=np.int64)
        for di in (0, 1, 2):
            for dj in (0, 1, 2):
                box += padded[di : di + parent.shape[0], dj : dj + parent.shape[1]]
        mix = 9 * parent + box  # 18 × the mean of the parent and its neighbourhood's mean
        total += _W_PARENT * _fit(np.repeat(np.repeat(mix, 2, 0), 2, 1), rows, cols)
        weight += _W_PARENT * _PARENT_SCALE
    for sibling, w in siblings:
        if sibling.size:
            total += (w * _PARENT_SCALE) * _fit(sibling, rows, cols)
            weight += w * _PARENT_SCALE
    return total, weight


@njit(nogil=True, cache=True)
def _phase_classes(
    magnitude, known, ext_sum, ext_weight, row0, col0, base, edges, scale, w_direct, w_diagonal
):
    """Context class of every position ``(row0 + 2i, col0 + 2j)`` of a plane.

    The activity is ``(ext_sum + scale · Σ w · |known neighbour|) / (ext_weight + scale · Σ w)``
    over the eight neighbours already coded; its bin is the number of edges (in thousandths)
    below it, all in integer arithmetic.
    """
    rows, cols = magnitude.shape
    n_i = (rows - row0 + 1) // 2
    n_j = (cols - col0 + 1) // 2
    out = np.empty(n_i * n_j, dtype=np.int64)
    k = 0
    for i in range(row0, rows, 2):
        for j in range(col0, cols, 2):
            num = ext_sum[i, j]
            den = ext_weight
            for di in (-1, 0, 1):
                ii = i + di
                if ii < 0 or ii >= rows:
                    continue
                for dj in (-1, 0, 1):
                    jj = j + dj
                    if (di == 0 and dj == 0) or jj < 0 or jj >= cols or not known[ii, jj]:
                        continue
                    w = w_diagonal if di != 0 and dj != 0 else w_direct
                    num += scale * w * magnitude[ii, jj]
                    den += scale * w
            b = 0
            if den > 0:
                for e in edges:
                    if 1000 * num > e * den:
                        b += 1
            out[k] = base + b
            k += 1
    return out


class _Writer:
    """Codes symbols into one range-coder stream per level (``chunks``)."""

    def __init__(self) -> None:
        self.encoder = _queue.RangeEncoder()
        self.chunks: list[bytes] = []

    def __call__(self, index: int) -> _Writer:
        self.encoder = _queue.RangeEncoder()
        return self

    def magnitudes(
        self, models: _Models, counts: np.ndarray, classes: np.ndarray, values: np.ndarray
    ) -> np.ndarray:
        """Code ``values >= 0`` (1-D) with the class of each; escapes follow in the same stream."""
        symbols = np.minimum(values, ESCAPE).astype(np.int32)
        for cls, members in _groups(classes):
            picked = symbols[members]
            for part in _segments(len(picked)):
                self.encoder.encode(picked[part], models.model(counts[cls]))
                models.update(counts[cls], picked[part])
        excess = values[values >= ESCAPE].astype(np.int64) - ESCAPE
        if excess.size:
            exponents = _bit_length(excess)
            self.encoder.encode(exponents.astype(np.int32), models.model(models.exponent))
            models.update(models.exponent, exponents)
            bits = _mantissa_bits(excess, exponents)
            if bits.size:
                self.encoder.encode(bits, _BIT)
        return values

    def grouped(
        self, models: _Models, table: np.ndarray, contexts: np.ndarray, values: np.ndarray
    ) -> np.ndarray:
        """Code small ``values`` under adaptive counts ``table[context]``, context by context."""
        symbols = values.astype(np.int32)
        for ctx, members in _groups(contexts):
            picked = symbols[members]
            for part in _segments(len(picked)):
                self.encoder.encode(picked[part], models.model(table[ctx]))
                models.update(table[ctx], picked[part])
        return values.astype(np.int64)

    def uniform(self, values: np.ndarray, size: int, count: int) -> np.ndarray:
        """Code ``count`` values below ``size``, each equally likely (raw bits, in effect)."""
        del count
        if values.size:
            self.encoder.encode(values.astype(np.int32), _model.Uniform(size))
        return values.astype(np.int64)

    def signs(self, negative: np.ndarray, nonzero: np.ndarray) -> np.ndarray:
        del nonzero
        if negative.size:
            self.encoder.encode(negative.astype(np.int32), _BIT)
        return negative.astype(np.int64)

    def done(self) -> None:
        self.chunks.append(self.encoder.get_compressed().astype("<u4").tobytes())


class _Reader:
    """Decodes the symbols of one level's chunk."""

    def __init__(self, chunk: bytes) -> None:
        if len(chunk) % 4:
            msg = f"context-coded chunk of {len(chunk)} bytes is not a whole number of words"
            raise BundleError(msg)
        words = np.frombuffer(chunk, dtype="<u4").astype(np.uint32)
        try:
            self.decoder = _queue.RangeDecoder(words)
        except Exception as exc:  # constriction reports bad input in its own exception types
            msg = f"corrupt context-coded chunk: {exc}"
            raise BundleError(msg) from exc

    def _decode(self, model: Any, count: int) -> np.ndarray:
        try:
            return np.asarray(self.decoder.decode(model, count), dtype=np.int64)
        except Exception as exc:  # constriction reports bad input in its own exception types
            msg = f"corrupt context-coded chunk: {exc}"
            raise BundleError(msg) from exc

    def magnitudes(
        self, models: _Models, counts: np.ndarray, classes: np.ndarray, truth: None
    ) -> np.ndarray:
        del truth
        values = np.empty(classes.shape, dtype=np.int64)
        for cls, members in _groups(classes):
            picked = np.empty(len(members), dtype=np.int64)
            for part in _segments(len(picked)):
                picked[part] = self._decode(models.model(counts[cls]), part.stop - part.start)
                models.update(counts[cls], picked[part])
            values[members] = picked
        escaped = values == ESCAPE
        count = int(np.count_nonzero(escaped))
        if count:
            exponents = self._decode(models.model(models.exponent), count)
            models.update(models.exponent, exponents)
            lengths = np.maximum(exponents - 1, 0)
            bits = self._decode(_BIT, int(lengths.sum()))
            excess = _from_mantissa(exponents, bits)
            values[escaped] = ESCAPE + excess
            if values.max() > _MAX_MAGNITUDE:
                msg = "context-coded chunk decodes to a value beyond int32"
                raise BundleError(msg)
        return values

    def grouped(
        self, models: _Models, table: np.ndarray, contexts: np.ndarray, values: None
    ) -> np.ndarray:
        del values
        out = np.empty(contexts.shape, dtype=np.int64)
        for ctx, members in _groups(contexts):
            picked = np.empty(len(members), dtype=np.int64)
            for part in _segments(len(picked)):
                picked[part] = self._decode(models.model(table[ctx]), part.stop - part.start)
                models.update(table[ctx], picked[part])
            out[members] = picked
        return out

    def uniform(self, values: None, size: int, count: int) -> np.ndarray:
        del values
        return self._decode(_model.Uniform(size), count) if count else np.zeros(0, np.int64)

    def signs(self, negative: None, nonzero: np.ndarray) -> np.ndarray:
        del negative
        count = int(np.count_nonzero(nonzero))
        return self._decode(_BIT, count) if count else np.zeros(0, dtype=np.int64)

    def done(self) -> None:
        pass


_MAX_MAGNITUDE = 2**31 - 1
_MAX_SHIFT = 24


def _bit_length(values: np.ndarray) -> np.ndarray:
    """Number of bits of each non-negative value (0 for 0)."""
    out = np.zeros(values.shape, dtype=np.int64)
    nonzero = values > 0
    out[nonzero] = np.floor(np.log2(values[nonzero])).astype(np.int64) + 1
    # log2 can round up just below a power of two; fix with exact integer checks.
    too_big = nonzero & ((np.int64(1) << np.maximum(out - 1, 0)) > values)
    out[too_big] -= 1
    return out


def _mantissa_bits(excess: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """The bits below the leading one, most significant first, of every value, concatenated."""
    lengths = np.maximum(exponents - 1, 0)
    width = int(lengths.max()) if lengths.size else 0
    if width == 0:
        return np.zeros(0, dtype=np.int32)
    shifts = np.arange(width - 1, -1, -1)
    bits = (excess[:, None] >> shifts[None, :]) & 1
    keep = np.arange(width)[None, :] >= (width - lengths)[:, None]
    return bits[keep].astype(np.int32)


def _from_mantissa(exponents: np.ndarray, bits: np.ndarray) -> np.ndarray:
    lengths = np.maximum(exponents - 1, 0)
    out = np.where(exponents > 0, np.int64(1) << np.maximum(exponents - 1, 0), 0)
    if bits.size:
        owner = np.repeat(np.arange(len(exponents)), lengths)
        ends = np.cumsum(lengths)
        position = np.arange(bits.size) - np.repeat(ends - lengths, lengths)
        weight = np.int64(1) << (np.repeat(lengths, lengths) - 1 - position)
        np.add.at(out, owner, bits * weight)
    return out


def _as_planes(band: np.ndarray, two_d: bool) -> np.ndarray:
    """View a band as ``(rows, cols, channels)``: 1-D layouts get one column."""
    if not two_d or band.ndim < 2:
        return band.reshape(band.shape[0], 1, -1) if band.ndim else band.reshape(1, 1, 1)
    return band.reshape(band.shape[0], band.shape[1], -1)


def _code_approx(io: Any, models: _Models, plane: np.ndarray | None, shape: Any) -> np.ndarray:
    """The coarsest band: differences along rows (first column: down it), Rice-style.

    The residual magnitudes are split into ``shift`` raw low bits and the high part, which goes
    through the adaptive model; the encoder picks ``shift`` from the mean magnitude and sends it
    first, so the coarse band of a lossless or finely quantized image costs few escapes.
    """
    rows, cols = shape
    count = rows * cols
    residual = magnitudes = None
    shift = np.zeros(1, dtype=np.int64)
    if plane is not None:
        residual = plane.astype(np.int64)
        residual[:, 1:] = np.diff(residual, axis=1)
        residual[1:, 0] = np.diff(plane[:, 0].astype(np.int64))
        magnitudes = np.abs(residual).ravel()
        mean = float(magnitudes.mean()) if count else 0.0
        shift[0] = min(_MAX_SHIFT, max(0, math.floor(math.log2(mean)) - 1)) if mean >= 1 else 0
    k = int(io.uniform(None if plane is None else shift, _MAX_SHIFT + 1, 1)[0])
    classes = np.zeros(count, dtype=np.int64)
    high = io.magnitudes(
        models, models.approx, classes, None if magnitudes is None else magnitudes >> k
    )
    magnitude = high << k
    if k:
        low_bits = None if magnitudes is None else magnitudes & ((1 << k) - 1)
        magnitude |= io.uniform(low_bits, 1 << k, count)
    nonzero = magnitude != 0
    negative = io.signs(None if residual is None else residual.ravel()[nonzero] < 0, nonzero)
    signed = magnitude.copy()
    signed[nonzero] *= 1 - 2 * negative
    signed = signed.reshape(rows, cols)
    signed[:, 0] = np.cumsum(signed[:, 0])
    out = np.cumsum(signed, axis=1)
    if np.abs(out).max(initial=0) > _MAX_MAGNITUDE:
        msg = "context-coded chunk decodes to a value beyond int32"
        raise BundleError(msg)
    return out


def _sign_contexts(
    signs: np.ndarray,
    row0: int,
    col0: int,
    block_shape: tuple[int, ...],
    pass_index: int,
    orientation: int,
) -> np.ndarray:
    """Sign context of every position of a pass, from the signs of the neighbours known."""
    n_i, n_j = block_shape[0], block_shape[1]
    base = orientation * _SIGN_CONTEXTS
    if pass_index == 0:
        return np.full((n_i, n_j), base, dtype=np.int64)

    def at(di: int, dj: int) -> np.ndarray:
        r, c = 1 + row0 + di, 1 + col0 + dj
        return signs[r : r + 2 * n_i - 1 : 2, c : c + 2 * n_j - 1 : 2]

    if pass_index == 1:
        first, second = at(-1, -1) + at(1, 1), at(-1, 1) + at(1, -1)
        return base + 1 + (first + 2) * 5 + (second + 2)
    across, down = at(0, -1) + at(0, 1), at(-1, 0) + at(1, 0)
    return base + 26 + (across + 2) * 5 + (down + 2)


def _code_detail(
    io: Any,
    models: _Models,
    plane: np.ndarray | None,
    shape: tuple[int, int],
    parent: np.ndarray | None,
    siblings: list[tuple[np.ndarray, int]],
    orientation: int = 0,
) -> np.ndarray:
    """One detail plane in three interlaced passes, each symbol under its context class."""
    ext_sum, ext_weight = _external(shape, parent, siblings)
    magnitude_plane = None if plane is None else np.abs(plane.astype(np.int64))
    known_magnitude = np.zeros(shape, dtype=np.int64)
    known = np.zeros(shape, dtype=np.bool_)
    signs = np.zeros((shape[0] + 2, shape[1] + 2), dtype=np.int64)  # known signs, zero-padded
    out = np.zeros(shape, dtype=np.int64)
    for pass_index, phases in enumerate(_PASSES):
        for row0, col0 in phases:
            where = (slice(row0, None, 2), slice(col0, None, 2))
            classes = _phase_classes(
                known_magnitude,
                known,
                ext_sum,
                ext_weight,
                row0,
                col0,
                pass_index * _BINS,
                _EDGES_MILLI,
                _PARENT_SCALE,
                _W_DIRECT,
                _W_DIAGONAL,
            )
            if not classes.size:
                continue
            truth = None if magnitude_plane is None else magnitude_plane[where].ravel()
            magnitude = io.magnitudes(models, models.detail, classes, truth)
            nonzero = magnitude != 0
            block_shape = out[where].shape
            contexts = _sign_contexts(signs, row0, col0, block_shape, pass_index, orientation)
            negative = io.grouped(
                models,
                models.sign,
                contexts.ravel()[nonzero],
                None if plane is None else (plane[where].ravel()[nonzero] < 0),
            )
            signed = magnitude.copy()
            signed[nonzero] *= 1 - 2 * negative
            out[where] = signed.reshape(block_shape)
            known_magnitude[where] = magnitude.reshape(block_shape)
            known[where] = True
            signs[1 + row0 :: 2, 1 + col0 :: 2][: block_shape[0], : block_shape[1]] = np.sign(
                out[where]
            )
    return out


def _code_levels(
    io_for_level: Any,
    entries: list[list[np.ndarray]] | None,
    layout: list[list[tuple[int, ...]]],
    two_d: bool,
) -> list[list[np.ndarray]]:
    """Walk the layout coarse to fine, coding (``entries`` given) or decoding every plane.

    Encoder and decoder run this same function, so their contexts cannot drift apart.
    """
    models = _Models()
    decoded: list[list[np.ndarray]] = []  # per entry, per band: (rows, cols, channels) int64
    for index, band_shapes in enumerate(layout):
        io = io_for_level(index)
        if index > 1:
            models.new_level()
        level_planes: list[np.ndarray] = []
        for k, band_shape in enumerate(band_shapes):
            dims = _plane_dims(band_shape, two_d)
            truth = None if entries is None else _as_planes(entries[index][k], two_d)
            result = np.zeros(dims, dtype=np.int64)
            for channel in range(dims[2]):
                plane = None if truth is None else truth[:, :, channel]
                if index == 0:
                    result[:, :, channel] = _code_approx(io, models, plane, dims[:2])
                    continue
                parent = None
                if index >= 2 and k < len(decoded[index - 1]):
                    parent_planes = decoded[index - 1][k]
                    if channel < parent_planes.shape[2]:
                        parent = np.abs(parent_planes[:, :, channel])
                siblings = [(np.abs(level_planes[s][:, :, channel]), _W_SIBLING) for s in range(k)]
                if channel > 0:
                    siblings.append((np.abs(result[:, :, 0]), _W_LUMA))
                result[:, :, channel] = _code_detail(
                    io, models, plane, dims[:2], parent, siblings, min(k, 2)
                )
            level_planes.append(result)
        decoded.append(level_planes)
        io.done()
    return decoded


def _plane_dims(band_shape: tuple[int, ...], two_d: bool) -> tuple[int, int, int]:
    if not band_shape:
        return 1, 1, 1
    if two_d and len(band_shape) >= 2:
        rows, cols, rest = band_shape[0], band_shape[1], band_shape[2:]
    else:
        rows, cols, rest = band_shape[0], 1, band_shape[1:]
    return int(rows), int(cols), int(np.prod(rest, dtype=np.int64))


_queue = constriction.stream.queue
_model = constriction.stream.model
_BIT = _model.Uniform(2)


def _encode_context(entries: list[list[np.ndarray]]) -> tuple[list[bytes], dict[str, Any]]:
    two_d = len(entries) > 1 and len(entries[1]) == 3
    layout = [[band.shape for band in bands] for bands in entries]
    writer = _Writer()
    _code_levels(writer, entries, layout, two_d)
    return writer.chunks, {"coder": "context", "version": CONTEXT_VERSION, "two_d": two_d}


def _decode_context(
    chunks: Sequence[bytes], layout: list[list[tuple[int, ...]]], params: dict[str, Any]
) -> list[list[np.ndarray]]:
    if params.get("version") != CONTEXT_VERSION or not isinstance(params.get("two_d"), bool):
        msg = f"context coder parameters {params!r} are not version {CONTEXT_VERSION}'s"
        raise BundleError(msg)
    readers = []
    for chunk in chunks:
        if not isinstance(chunk, bytes | bytearray | memoryview):
            msg = "each chunk must be bytes"
            raise BundleError(msg)
        readers.append(_Reader(bytes(chunk)))
    planes = _code_levels(lambda index: readers[index], None, layout, params["two_d"])
    levels = []
    for bands, band_shapes in zip(planes, layout, strict=True):
        levels.append(
            [
                plane.reshape(shape).astype(np.int32)
                for plane, shape in zip(bands, band_shapes, strict=True)
            ]
        )
    return levels
