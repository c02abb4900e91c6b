"""Context coder versions 4, 7 and 8 re-implemented in plain Python from
docs/bundle-format.md ("Context coder version 4: code-blocks", "... version 7: orientation",
"... version 8: priors by level"), for one block of a grey picture's approximation or
coarsest details (no parent band, no luma), and compared byte for byte with the compiled
kernels: the specification is exact enough to re-implement.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavecore._blockpriors import PRIORS
from wavecore.blockcoder import encode_blocks
from wavecore.varints import encode_varint

EDGES = (0, 2, 4, 6, 9, 13, 19, 27, 39, 55, 79, 111, 160)
COST = [round(-256 * math.log2((32 * k + 16) / 32768)) for k in range(1024)]


def _local_class(s: int) -> int:
    return sum(edge < min(s, 255) for edge in EDGES)


def _external_class(e: int) -> int:
    return 0 if e == 0 else 1 if e < 4 else 2 if e < 12 else 3


def _index(ctx: tuple) -> int:
    """A context's index in version 8's tables (the specification's context numbering)."""
    what, *rest = ctx
    if what == "zero":  # kind, local class, external class
        return (rest[0] * 14 + rest[1]) * 4 + rest[2]
    if what == "unary":  # kind, halved class, index
        return 112 + (rest[0] * 15 + rest[1]) * 8 + rest[2]
    if what == "mantissa":  # kind, position, bit length
        return 352 + (rest[0] * 2 + rest[1]) * 35 + rest[2]
    if what == "sign":  # orientation (3: the approximation), sign of W, sign of N
        return 492 + rest[0] * 9 + (rest[1] + 1) * 3 + rest[2] + 1
    if what == "tile":  # near, other
        return 528 + rest[0] * 2 + rest[1]
    return 534 + rest[0] * 4 + rest[1]  # zero_d: local class, external class


class _Coder:
    """LZMA's binary range coder and the adaptive models, as the specification says."""

    def __init__(self, priors: np.ndarray | None = None) -> None:
        self.low, self.range, self.cache, self.pending = 0, 0xFFFFFFFF, 0, 1
        self.out: list[int] = []
        self.models: dict[tuple, list[int]] = {}
        self.priors = priors  # version 8: the block's level class's row of PRIORS

    def model(self, ctx: tuple) -> list[int]:
        if ctx not in self.models:
            p, n = 16384, 0
            if ctx[0] in ("zero", "zero_d"):
                p, n = max(8, 15 - ctx[-2] - ctx[-1]) * 2048, 2
            if self.priors is not None:
                word = int(self.priors[_index(ctx)])
                p, n = word >> 8, word & 0xFF
            self.models[ctx] = [p, n]
        return self.models[ctx]

    @staticmethod
    def adapt(model: list[int], bit: int) -> None:
        shift = min((model[1] + 1).bit_length(), 6)
        model[0] += (32768 - model[0]) >> shift if bit == 0 else -(model[0] >> shift)
        model[1] = min(model[1] + 1, 64)

    def _shift_low(self) -> None:
        if self.low < 0xFF000000 or self.low >= 1 << 32:
            carry = self.low >> 32
            byte = self.cache
            for _ in range(self.pending):
                self.out.append((byte + carry) & 0xFF)
                byte = 0xFF
            self.pending = 0
            self.cache = (self.low >> 24) & 0xFF
        self.pending += 1
        self.low = (self.low & 0x00FFFFFF) << 8

    def _normalise(self) -> None:
        while self.range < 1 << 24:
            self.range <<= 8
            self._shift_low()

    def bit(self, ctx: tuple, bit: int) -> None:
        model = self.model(ctx)
        bound = (self.range >> 15) * model[0]
        if bit == 0:
            self.range = bound
        else:
            self.low += bound
            self.range -= bound
        self.adapt(model, bit)
        self._normalise()

    def raw(self, bit: int) -> None:
        self.range >>= 1
        if bit:
            self.low += self.range
        self._normalise()

    def finish(self) -> bytes:
        for keep in range(1, 5):
            mask = (1 << (32 - 8 * keep)) - 1
            end = (self.low + mask) & ~mask
            if end - self.low < self.range:
                self.low = end
                break
        for _ in range(5):
            self._shift_low()
        data = bytes(self.out[1:]).rstrip(b"\0")
        return data or b"\0"


def _magnitude(coder: _Coder, kind: int, a: int, m: int) -> None:
    """A nonzero magnitude: its bit length in unary, then the bits below the leading one."""
    k = m.bit_length()
    for t in range(k):
        coder.bit(("unary", kind, _local_class(a) >> 1, min(t, 7)), 1 if t < k - 1 else 0)
    for position in range(k - 1):
        bit = (m >> (k - 2 - position)) & 1
        if position < 2:
            coder.bit(("mantissa", kind, position, k), bit)
        else:
            coder.raw(bit)


def reference_block(
    planes: list[np.ndarray],
    detail: bool,
    version: int,
    seen: dict[str, int] | None = None,
    level: int = 0,
) -> bytes:
    """One block holding every plane whole (the block at (0, 0), larger than the planes);
    ``seen`` counts version 7's (and 8's) flags coded under the directional models and its
    planes that settled; ``level``: version 8's level class of the block."""
    seen = {} if seen is None else seen
    coder = _Coder(PRIORS[level] if version == 8 else None)
    flags: list[dict[tuple[int, int], int]] = []
    for p, plane in enumerate(planes):
        rows, cols = plane.shape
        x = plane.astype(np.int64)

        def at(i: int, j: int, x: np.ndarray = x, rows: int = rows, cols: int = cols) -> int:
            return int(x[i, j]) if 0 <= i < rows and 0 <= j < cols else 0

        tiles: dict[tuple[int, int], int] = {}
        if detail:
            for tr in range(-(-rows // 8)):
                for tc in range(-(-cols // 8)):
                    flag = int(np.any(x[tr * 8 : tr * 8 + 8, tc * 8 : tc * 8 + 8]))
                    near = tiles.get((tr, tc - 1), 0) + tiles.get((tr - 1, tc), 0)
                    other = int(any(f.get((tr, tc), 0) for f in flags))
                    coder.bit(("tile", near, other), flag)
                    tiles[(tr, tc)] = flag
            flags.append(tiles)
        residual = np.zeros((rows, cols), dtype=np.int64)
        cost_s = cost_d = 0
        settled = not (detail and version >= 7 and p < 2)
        for i in range(rows):
            for j in range(cols):
                if detail and not tiles[(i // 8, j // 8)]:
                    continue
                source = x if detail else np.abs(residual)
                nb = [
                    abs(int(source[i + di, j + dj])) if i + di >= 0 and 0 <= j + dj < cols else 0
                    for di, dj in ((0, -1), (-1, 0), (-1, -1), (-1, 1), (0, -2), (-2, 0))
                ]
                w, n, nw, ne, ww, nn = nb
                s = 4 * (w + n) + 2 * (nw + ne) + ww + nn
                if detail:
                    value = int(x[i, j])
                    e = sum(
                        2 * abs(at_other) for at_other in (_at(planes[q], i, j) for q in range(p))
                    )
                else:
                    a, b = at(i, j - 1), at(i - 1, j)
                    if i and j:
                        c = at(i - 1, j - 1)
                        pred = (
                            min(a, b)
                            if c >= max(a, b)
                            else max(a, b)
                            if c <= min(a, b)
                            else a + b - c
                        )
                    else:
                        pred = a + b
                    value = int(x[i, j]) - pred
                    residual[i, j] = value
                    e = 0
                kind = int(detail)
                m = abs(value)
                ctx_s = ("zero", kind, _local_class(s), _external_class(e))
                a_unary = s
                if detail and version >= 7 and p < 2:
                    along, across, along2 = (w, n, ww) if p == 0 else (n, w, nn)
                    d = 8 * along + 2 * across + (nw + ne) + 2 * along2
                    ctx_d = ("zero_d", _local_class(d), _external_class(e))
                    directional = cost_d < cost_s
                    before_s, before_d = list(coder.model(ctx_s)), list(coder.model(ctx_d))
                    coder.bit(ctx_d if directional else ctx_s, int(m > 0))
                    if not settled:
                        bit = int(m > 0)
                        q_s = before_s[0] if bit == 0 else 32768 - before_s[0]
                        q_d = before_d[0] if bit == 0 else 32768 - before_d[0]
                        cost_s += COST[q_s >> 5]
                        cost_d += COST[q_d >> 5]
                        coder.adapt(coder.model(ctx_s if directional else ctx_d), bit)
                        settled = abs(cost_s - cost_d) > 8192
                        seen["settled"] = seen.get("settled", 0) + settled
                    if directional:
                        a_unary = d
                        seen["directional"] = seen.get("directional", 0) + 1
                else:
                    coder.bit(ctx_s, int(m > 0))
                if m == 0:
                    continue
                _magnitude(coder, kind, a_unary + e, m)
                sw = int(np.sign(x[i, j - 1])) if detail and j > 0 else 0
                sn = int(np.sign(x[i - 1, j])) if detail and i > 0 else 0
                coder.bit(("sign", p if detail else 3, sw, sn), int(value < 0))
    return coder.finish()


def _at(plane: np.ndarray, i: int, j: int) -> int:
    rows, cols = plane.shape
    return int(plane[i, j]) if i < rows and j < cols else 0


def _runs(rng: np.random.Generator, shape: tuple[int, int], along_rows: bool) -> np.ndarray:
    rows, cols = shape if along_rows else shape[::-1]
    starts = rng.random((rows, -(-cols // 4))) < 0.4
    values = np.where(starts, rng.integers(1, 40, starts.shape), 0)
    band = np.repeat(values, 4, axis=1)[:, :cols] * rng.choice([-1, 1], (rows, cols))
    return (band if along_rows else band.T).astype(np.int32)


@pytest.mark.parametrize("version", [4, 7, 8])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_specification_codes_the_kernels_bytes(version: int, seed: int) -> None:
    """Chunk 0 (the approximation) and chunk 1 (cH with runs along rows, cV along columns,
    cD noise with an empty corner) of one 64 × 64 block each: the reference's bytes are the
    kernels'.  The runs make versions 7 and 8 choose their directional models and settle;
    under version 8 chunk 0 is of level class 1, chunk 1 (the finest) of class 0."""
    rng = np.random.default_rng(seed)
    approx = rng.integers(-500, 500, (21, 22)).astype(np.int32)
    c_d = np.round(rng.laplace(0, 2.0, (21, 22)) * (rng.random((21, 22)) < 0.5)).astype(np.int32)
    c_d[:12, :12] = 0
    details = [_runs(rng, (22, 22), True), _runs(rng, (21, 23), False), c_d]
    entries = [[approx], details]
    chunks = encode_blocks(entries, True, 64, version)
    seen: dict[str, int] = {}
    for chunk, planes, detail in ((chunks[0], [approx], False), (chunks[1], details, True)):
        expected = reference_block(planes, detail, version, seen, level=int(detail is False))
        table = encode_varint(len(expected))  # the chunk's table: its one block's length
        assert chunk == table + expected
    if version >= 7:  # the directional models were used: version 6 writes other bytes
        assert seen["directional"] > 100 and seen["settled"] == 2
        assert encode_blocks(entries, True, 64, 6)[1] != chunks[1]
    if version == 8:  # the priors were used: version 7 writes other bytes in both chunks
        seven = encode_blocks(entries, True, 64, 7)
        assert seven[0] != chunks[0] and seven[1] != chunks[1]
