"""The coefficient bundle: a versioned binary container, coarse to fine.

This docstring summarises format versions 6.0 and 5.0 (written for curves) and 3.1 (written
for images and surfaces), and 4.0, 3.0, 2.0 and 1.x, which are still read;
``docs/bundle-format.md`` is the specification.  (7.0, a picture enlarged by pixel
replication, is a 7-byte wrapper around one of these, which :func:`wavecore.decode` and
:func:`wavecore.inspect` unwrap: :mod:`wavecore.codec.replication`.)  Like NumPy's ``.npy``
format, a bundle is a fixed preamble, a bounded self-describing header, then the payload.
All integers are little-endian; a *varint* is unsigned LEB128 (at most 10 bytes, no needless
final zero byte).

Layout (6.0)
------------
5.0's layout with major ``6``, except that a chunk of more than one code-block is stored in
3.0's checked form (block CRC-16s, band counts, prefix check) and is in no group
(:func:`checked_groups`): a damaged block of a long curve loses only itself and a region reads
only its blocks.  Written for curves unless the checks would pass 48 bytes (then 5.0).

Layout (5.0)
------------
``89 57``, the major version ``5`` and the minor ``0``; the binary header in its 4.0 form;
each chunk's length as a varint *only* when the coder's chunks do not delimit themselves
(:func:`self_delimiting_blocks`: the ``context`` coder version 4 starts each chunk with the
lengths of its code-blocks, so the bundle needs no copy of them); a CRC-16 of each group of
:func:`curve_groups` (the coarse chunks, then the finest); the CRC-16 of every byte before
it; the chunks exactly as the coder wrote them (no block checks).  A curve's overhead stays
under 48 bytes whatever its length and levels.

Layout (4.0)
------------
``89 57`` (the first two bytes of the 3.x magic, whose third byte ``V`` is never a major
version), the major version ``4`` and the minor ``0``; the binary header of
:mod:`wavecore.binheader` in its 4.0 form (no length before it: its fields say where it ends;
weights derived from the plan, a float32 step, default coder parameters in no bytes); each
chunk's length, a varint; a CRC-16/XMODEM of each *group* of chunks (:func:`chunk_groups`:
consecutive chunks packed while a group holds at most :data:`GROUP_BYTES`); the CRC-16 of every
byte before it; the chunks, as in 3.0.

Layout (3.1 and 3.0; 2.0 where it says so)
------------------------------------------
3.1 is 3.0's layout; its header may name the quantizer by code 3, whose weights are derived
from the plan but for the *pinned* ones it stores (:func:`pinned_weights`), with a one-byte
check of them all (:func:`wavecore.binheader.weights_check`), verified after the CRC-32.  When
the chunks delimit themselves (:func:`self_delimiting_blocks`: the block coder's), 3.1 stores
no chunk lengths: a reader finds each chunk but the last from its table of block lengths (as
6.0 does), and the last is the rest of the bundle.  The head is then the header and 2 bytes a
level besides 15 of framing: at most 96 bytes for any image (``docs/bundle-format.md``).

==========  ===========  ========================================================================
offset      size         field
==========  ===========  ========================================================================
0           8            magic ``b"\\x89WVB\\r\\n\\x1a\\n"`` (PNG-style: catches 7-bit and newline
                         mangling, stops ``type`` on DOS)
8           1            major version (``3``; ``2`` for 2.0); a reader refuses a major version it
                         does not know
9           1            minor version (``1``; ``0`` for 3.0 and 2.0)
10          v            header length ``H``, a varint, at most ``MAX_HEADER_SIZE``
…           H            the binary header of :mod:`wavecore.binheader` (the same dict as 1.x)
…           v · N        each chunk's byte length, a varint; ``N = levels + 1`` (3.1 whose
                         chunks delimit themselves: absent)
…           2 · N        CRC-16/XMODEM (``binascii.crc_hqx(chunk, 0)``) of every chunk (2.0:
                         of chunks 1 … N - 1 only)
…           4            CRC-32 of every byte before it (2.0: *and then chunk 0*)
…           ...          the chunks, concatenated; nothing may follow the last one.  3.0: a
                         chunk of several code-blocks (context coder version 4 on) carries,
                         after its table of block lengths, a CRC-16 per block, its bands'
                         ``(ones, more)`` counts (detail chunks) and a CRC-16 of all that
                         (see :func:`wavecore.blockcoder.add_block_checks`)
==========  ===========  ========================================================================

Layout (1.x)
------------
The magic; major ``1``; minor ``0``, ``1`` or ``2`` (with ``scale``); a ``uint16`` header length
``H``; the header as UTF-8 JSON, raw DEFLATE (``wbits=-15``), inflating to at most
``MAX_HEADER_SIZE``; a ``uint8`` chunk count ``N``; per chunk its ``uint32`` length and
``uint32`` CRC-32; the CRC-32 of every byte before it; the chunks.

Chunk ``0`` holds the coarsest approximation ``cA_L``; chunk ``i`` (``1 <= i <= L``) holds all
detail subbands of level ``L + 1 - i`` (every channel, every orientation), so chunks run
**coarse to fine**.  A bundle cut after chunk ``i`` still decodes exactly at resolution level
``L - i`` (``decode(data, level=L - i)``); chunk CRCs are checked only for the chunks a decode
uses, so a damaged fine chunk does not hide the coarse image, and a damaged chunk that is needed is
a clear error.  What a chunk's bytes mean is the business of the coder named in the header.

Versions
--------
A reader refuses any major version it does not know and accepts any minor version of those it
does: minor versions only add optional header keys (ignored by older readers) or new values
of an enumerated field (refused clearly by older readers, naming the field; 1.1 added six
``dtype`` values, 1.2 ``scale`` and ``opaque``).  Anything else — a new meaning for a field, a
new layout, an entropy coder whose old bitstreams no longer decode — is a new major version, or
a new coder *name* (which older readers refuse clearly).  2.0 is such a new layout, and so is
3.0 (chunk 0 leaves the CRC-32, block checks inside chunks): a 2.x reader refuses it by its
major version; and 4.0 (a new preamble, which a 3.x reader refuses by its magic bytes).  The golden
bundles in ``tests/golden`` are decoded in every test run to hold this promise.

Header
------
A dict (1.x: a JSON object, stored deflated; 2.0 and 3.0: the binary header, whose extension
holds keys it has no field for) with these keys; readers ignore unknown keys, so a minor
version may add some.

``kind``        ``"image"``, ``"curve"`` or ``"surface"``
``shape``       the original array's shape (list of positive ints)
``dtype``       the original dtype: ``uint8``, ``uint16``, ``float32``, ``float64``; since 1.1
                also ``float16``, ``int8``, ``int16``, ``int32``, ``int64``, ``uint32``
``fit``         how the transformed grid was made from the original: ``"pad"`` (``pads`` says
                how many samples were added before and after on each transformed axis) or
                ``"none"``
``pads``        ``[[before, after], ...]``, one pair per transformed axis
``fitted``      the shape of the transformed array (the original plus pads, colour axis kept)
``wavelet``     ``"bspline2"``, ``"haar"``, ``"cdf97"`` … or ``"reversible"`` (the integer
                lifting of the lossless path, see :mod:`wavecore.lossless`)
``lifting``     only with ``"reversible"``: the integer filter of each level, finest first,
                ``"legall53"``, ``"haar"`` or ``"bspline2"`` (closed, even sizes only)
``boundary``    one of ``"open"`` (the paper's endpoint-interpolating rows), ``"closed"``
                (periodic) or ``"symmetric"`` (mirror extension: ``legall53``, ``cdf97``) per
                transformed axis
``levels``      ``L``, the number of decomposition levels (``N = L + 1`` chunks)
``colour``      ``"none"``, ``"ycbcr"`` (irreversible, lossy) or ``"rct"`` (reversible), or
                ``"rct-p<w>"`` (reversible, Cr less ``floor((w Cb + 4) / 8)``, ``w`` ±1 … ±8),
                or ``"klt:<a>,<b>,<c>"`` (irreversible, lossy: the per-picture rotation of
                the colour space, ``Rz(a) Ry(b) Rx(c)`` with angles in units of pi/4096:
                ``wavecore.colour.klt_matrix``)
``quantizer``   the quantizer's name (``"none"`` for lossless) and ``qparams`` its parameters
``coder``       the entropy coder's name and ``cparams`` its parameters
``peak``        the peak value PSNR is measured against
``psnr``        the encoder's measured PSNR in dB, rounded down to 4 decimals (``null`` when
                exact)
``max_error``   the encoder's measured largest absolute error (per sample, or per point for
                curves)
``scale``       optional, since 1.2: an integer ``s``; the coded values are the original's
                times ``2**-s`` (exact), and decoding multiplies by ``2**s``.  Written only for
                float data whose largest magnitude is beyond ``2**±256``, so that any finite
                float64 (``±1.7e308`` down to subnormals) is coded without overflow.  ``peak``
                is then in the coded units, ``max_error`` in the original's.  Bundles with this
                key are labelled 1.2, every other bundle 1.1.
``opaque``      optional, since 1.2: ``true`` for an image (2 or 4 channels) whose alpha channel
                is fully opaque (the dtype's largest value, 1.0 for floats); the decoder sets
                it so exactly.  A 1.1 reader ignores it and gives the alpha as coded (nearly
                opaque), so it does not make a bundle 1.2 on its own.

Limits and safety
-----------------
A reader checks, in this order and before it allocates anything sized by the bundle: the magic,
the major version, the header length (at most ``MAX_HEADER_SIZE`` bytes; 1.x: compressed and
inflated, inflation stops at that size, so no "deflate bomb" gets through), the binary header's
fields or the JSON, every header field's type and range (the declared element count is at
most ``MAX_ELEMENTS``), the header and table CRC (2.x: with chunk 0), and that the chunk
table's lengths fit in the bytes that are actually present.  Every
failure is a :class:`~wavecore.errors.BundleError` whose message names the field being read.
The codec then checks the kind-specific consistency (``fitted`` = ``shape`` + ``pads``, each
padded length at most ``2 × length + 64``, the lengths fit ``levels`` of the wavelet and boundary,
the colour transform fits the channels) and
the entropy decoder never produces more values than the subband shapes that follow from it.
"""

from __future__ import annotations

import binascii
import contextlib
import functools
import json
import math
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from . import binheader
from ._blocktables import crc16
from .blockcoder import BLOCK_SIZES, CHECK_BYTES, add_block_checks, block_table, strip_block_checks
from .colour import KLT_PREFIX, klt_matrix
from .errors import BundleError
from .restoration import check_restore

__all__ = [
    "COMPACT_MAGIC",
    "COMPACT_VERSION",
    "CURVE_VERSION",
    "CURVE_VERSION_5",
    "GROUP_BYTES",
    "MAGIC",
    "MAX_CHUNKS",
    "MAX_ELEMENTS",
    "MAX_HEADER_SIZE",
    "PIN_MARGIN",
    "Bundle",
    "chunk_groups",
    "curve_groups",
    "deflate_header",
    "derived_weights",
    "inflate_header",
    "pinned_weights",
    "read_bundle",
    "with_header",
    "write_bundle",
    "written_version",
]

MAGIC = b"\x89WVB\r\n\x1a\n"
#: The version this module writes, and the newest it reads.  2.0 (a new major version: the
#: header's encoding and the chunk table's layout changed) has the binary header of
#: :mod:`wavecore.binheader`; every 1.x version is still read.  In 1.x, 1.1 added the dtypes
#: float16, int8–int64 and uint32, and 1.2 the optional ``scale`` key.  3.0 (again a new major
#: version: chunk 0 is no longer under the CRC-32, and block-coded chunks carry block checks)
#: keeps the binary header and adds a CRC-16 per chunk and per code-block.
#: 3.1 (written for images and surfaces since 2026-11-28) is 3.0's layout whose header may name
#: the quantizer by code 3: the weights are the plan's (:func:`derived_weights`), stored only
#: where they might not be (:func:`pinned_weights`), with a one-byte check of them all; chunks
#: that delimit themselves have no lengths in the head (the last runs to the end), which
#: the header says by coder code 3 (:data:`wavecore.binheader.DELIMITED_CONTEXT`), lossless
#: pictures included.  A 3.0 reader refuses such a header by naming the field 'coder' (or
#: 'quantizer'); 3.0 is still written on request (``write_bundle(..., version=(3, 0))``).
#: The version written for images and surfaces (:func:`written_version`).
FORMAT_VERSION = (3, 1)
#: 3.1 stores a weight the plan gives when its unrounded value lies closer than this, relative
#: to it, to a point where its four significant digits change
#: (:func:`wavecore.quantize.band_weight_margins`): floating-point sums of a few thousand
#: terms on another machine (another SIMD width or summation order) differ by some 1e-13
#: relative, so the other weights round to the same digits everywhere.
PIN_MARGIN = 1e-9
#: 4.0, the compact layout (a new major version: a 4-byte preamble, no header length, derived
#: weights, chunks checked in groups and the head by a CRC-16; see ``docs/bundle-format.md``),
#: is written for curves, and is the newest version this module reads.
COMPACT_VERSION = (4, 0)
#: 5.0, the curve layout (a new major version: a 4.0 reader would misread it), written for
#: curves since 2026-11-23: 4.0's preamble (major 5) and header; no chunk lengths when the
#: coder's chunks delimit themselves (context coder version 4: each chunk starts with the
#: lengths of its code-blocks), at most two CRC-16s over the chunks (:func:`curve_groups`),
#: no block checks.  Every curve's overhead is then at most 48 bytes.  The newest version
#: this module reads.
CURVE_VERSION_5 = (5, 0)
#: 6.0, the curve layout with block checks (a new major version: a 5.0 reader would misread
#: it), written for curves since 2026-11-23, evening: 5.0, except that a chunk of *more than
#: one* code-block is stored in 3.0's checked form (a CRC-16 per block, its bands' counts, a
#: prefix check: :func:`wavecore.blockcoder.add_block_checks`) and is in no group
#: (:func:`checked_groups`), so a damaged block loses only itself and a region reads only its
#: blocks.  A curve whose chunks are all of one block (up to about 33 000 points) pays nothing
#: more than in 5.0.  The newest version this module reads.
CURVE_VERSION = (6, 0)
#: Issue 11's bound on a curve's overhead (everything but the coder's chunks, block checks
#: included): a curve whose 6.0 block checks would pass it is written as 5.0.
CURVE_OVERHEAD_LIMIT = 48
#: The major versions this module reads.
READ_MAJORS = (1, 2, 3, 4, 5, 6)
#: The major version of a picture enlarged by pixel replication (format 7.0): a wrapper around
#: a bundle of one of :data:`READ_MAJORS`, which :mod:`wavecore.codec.replication` reads.
REPLICATED_MAJOR = 7
#: The majors that start with :data:`COMPACT_MAGIC` (a 4-byte preamble).
_SHORT_MAJORS = (COMPACT_VERSION[0], CURVE_VERSION_5[0], CURVE_VERSION[0])
#: 4.0's preamble: these two bytes, then the major and the minor version (one byte each).  The
#: third byte of :data:`MAGIC` (``V``) is never a major version, so the two never meet.
COMPACT_MAGIC = b"\x89W"
#: 4.0 checks chunks in *groups*: consecutive chunks, coarse to fine, packed while a group
#: holds at most this many bytes (a longer chunk is a group of its own), each group under one
#: CRC-16.  A CRC-16 detects every error of up to three bits in up to 4 093 bytes, so 1 KiB groups
#: lose no detection strength; a curve's levels (a few bytes to a few hundred each) then
#: share one or two checks, and a large chunk keeps its own.
GROUP_BYTES = 1024
MAX_HEADER_SIZE = 65535
MAX_CHUNKS = 64
#: Largest element count (samples × channels) a bundle may declare: 2**27, about a 6700 × 6700
#: RGB image.  Decoding allocates a few float64 arrays of this size, so this bounds memory use.
MAX_ELEMENTS = 2**27
MAX_LEVELS = 30
#: Largest ``|scale|`` (float64 exponents run from -1074 to 1024).
MAX_SCALE = 1100

_PREAMBLE = struct.Struct("<8sBBH")
_MAGIC_AND_VERSION = struct.Struct("<8sBB")
_U16 = struct.Struct("<H")
_TABLE_ENTRY = struct.Struct("<II")
_CRC = struct.Struct("<I")

KINDS = ("image", "curve", "surface")
DTYPES = (
    "uint8",
    "uint16",
    "float32",
    "float64",
    # since 1.1
    "float16",
    "int8",
    "int16",
    "int32",
    "int64",
    "uint32",
)
COLOURS = ("none", "ycbcr", "rct", *(f"rct-p{w}" for w in range(-8, 9) if w))
FITS = ("pad", "none")
BOUNDARIES = ("open", "closed", "symmetric")
_NAME_MAX = 32


@dataclass(frozen=True)
class Bundle:
    """A parsed bundle: its validated header and the chunk bytes that are present.

    ``chunks[i]`` is ``None`` when the data ends before chunk ``i`` is complete (a truncated
    bundle); use :meth:`chunk` to get a chunk with its CRC checked.
    """

    version: tuple[int, int]
    header: dict[str, Any]
    chunks: tuple[memoryview | None, ...]
    crcs: tuple[int, ...]
    #: How ``crcs`` check the chunks: ``"crc32"`` (1.x) or ``"crc16"`` (2.0 and 3.0:
    #: CRC-16/XMODEM, ``binascii.crc_hqx``; in 2.0 chunk 0 is checked with the header by its
    #: CRC-32 instead).
    checksum: str = "crc32"
    #: Whether block-coded chunks carry a CRC-16 per block after their table (3.0 on).
    block_checks: bool = False
    #: 4.0: for each chunk, the first and last chunk of its group; one CRC-16 (``crcs`` holds
    #: it for every chunk of the group) checks the group's bytes.  None: a check per chunk.
    groups: tuple[tuple[int, int], ...] | None = None
    #: 6.0: for each chunk that carries its own block checks (more than one code-block), its
    #: ``(blocks, bands)``; it is in no group, and it is intact when its prefix check and every
    #: block's CRC-16 match.  None for every other chunk (and in other versions).
    checked: tuple[tuple[int, int] | None, ...] | None = None
    #: 3.1 with chunks that delimit themselves: the last chunk is whatever follows the others,
    #: so a bundle cut inside it shows as that chunk's damage (said so in the error).
    open_ended: bool = False
    _verified: dict[int, bool] = field(default_factory=dict, compare=False, repr=False)

    @property
    def available(self) -> int:
        """How many leading chunks are complete."""
        count = 0
        for chunk in self.chunks:
            if chunk is None:
                break
            count += 1
        return count

    def chunk(self, index: int) -> bytes:
        """Chunk ``index``, after checking it is present and its CRC matches."""
        data = self.chunks[index]
        if data is None:
            msg = (
                f"bundle is truncated: chunk {index} of {len(self.chunks)} is missing; "
                f"only the first {self.available} chunk(s) are complete, so decode a coarser "
                "level or supply the whole bundle"
            )
            raise BundleError(msg)
        if not self._matches(index):
            name = "CRC-16" if self.checksum == "crc16" else "CRC-32"
            what = f"its {name}"
            if self.groups is not None and self.groups[index][0] != self.groups[index][1]:
                first, last = self.groups[index]
                what = f"the {name} of its group (chunks {first} to {last})"
            cut = ""
            if self.open_ended and index == len(self.chunks) - 1:
                cut = ", or the bundle is truncated (this last chunk runs to the end of the bundle)"
            msg = (
                f"chunk {index} is corrupt: {what} does not match the chunk table{cut} (decode "
                "with damaged='zero' to get the rest with its damaged blocks zeroed)"
            )
            raise BundleError(msg)
        return bytes(data)

    def intact(self, index: int) -> bool:
        """Whether chunk ``index`` is present and matches its CRC (4.0: its group's)."""
        return self.chunks[index] is not None and self._matches(index)

    def _matches(self, index: int) -> bool:
        own = self.checked[index] if self.checked is not None else None
        if own is not None:
            key = -1 - index  # each checked chunk's blocks are checked once
            if key not in self._verified:
                self._verified[key] = _blocks_match(self.chunks[index], *own)
            return self._verified[key]
        if self.groups is None:
            data = self.chunks[index]
            return data is not None and _chunk_check(data, self.checksum) == self.crcs[index]
        first, last = self.groups[index]
        if first not in self._verified:  # each group's CRC is computed once
            crc, whole = 0, True
            for part in self.chunks[first : last + 1]:
                if part is None:
                    whole = False
                    break
                crc = crc16(part, crc)
            self._verified[first] = whole and crc == self.crcs[index]
        return self._verified[first]


def _blocks_match(data: memoryview | None, blocks: int, bands: int) -> bool:
    """Whether a chunk in 3.0's checked form is whole: its prefix check and every block's
    CRC-16 match."""
    if data is None:
        return False
    try:
        _, bad, _ = strip_block_checks(data, blocks, bands)
    except BundleError:
        return False
    return not bad.any()


def _chunk_check(data: bytes | memoryview, checksum: str) -> int:
    if checksum == "crc16":
        return crc16(data)
    return zlib.crc32(data)


class _Reader:
    """Reads fields in order; every error names the field it was reading."""

    def __init__(self, data: bytes | bytearray | memoryview) -> None:
        self.view = memoryview(data).cast("B")
        self.offset = 0

    def take(self, size: int, field: str) -> memoryview:
        remaining = len(self.view) - self.offset
        if size > remaining:
            msg = (
                f"bundle is truncated while reading {field}: it needs {size} byte(s) at offset "
                f"{self.offset}, but only {remaining} remain"
            )
            raise BundleError(msg)
        out = self.view[self.offset : self.offset + size]
        self.offset += size
        return out

    def unpack(self, fmt: struct.Struct, field: str) -> tuple[Any, ...]:
        return fmt.unpack(self.take(fmt.size, field))

    def varint(self, field: str, maximum: int) -> int:
        """An unsigned LEB128 number of at most 10 bytes, canonical, and at most ``maximum``."""
        value = shift = 0
        for count in range(binheader.MAX_VARINT_BYTES):
            (byte,) = self.take(1, field)
            value |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                if byte == 0 and count:
                    msg = f"{field} is a varint with a needless trailing zero byte"
                    raise BundleError(msg)
                if value > maximum:
                    msg = f"{field} is {value}, more than the largest, {maximum}"
                    raise BundleError(msg)
                return value
        msg = f"{field} is a varint longer than {binheader.MAX_VARINT_BYTES} bytes"
        raise BundleError(msg)


def written_version(header: dict[str, Any]) -> tuple[int, int]:
    """The version :func:`write_bundle` writes by default: 6.0 for curves (5.0 when 6.0's block
    checks would pass :data:`CURVE_OVERHEAD_LIMIT`), 3.1 for the rest (labelled 3.0 when the
    header has no weights the plan derives and a coder whose chunks do not delimit themselves:
    it is 3.0's).

    Images and surfaces stay in 3.x's layout: the compact layouts' grouped chunk checks and
    shorter head check would weaken their damage handling for a few bytes; 3.1's header
    derives their weights instead (see ``docs/bundle-format.md``).
    """
    return CURVE_VERSION if header.get("kind") == "curve" else FORMAT_VERSION


def write_bundle(
    header: dict[str, Any],
    chunks: Sequence[bytes],
    *,
    version: tuple[int, int] | None = None,
) -> bytes:
    """Serialise a header and its chunks (coarse to fine) into bundle bytes.

    The header is validated exactly as a reader would, so a writer can never produce a bundle
    that its own reader refuses.  ``version`` is None (:func:`written_version`: 6.0 or 5.0 for
    curves, 3.1 for images and surfaces), ``(6, 0)``, ``(5, 0)`` or ``(4, 0)`` (the compact
    layouts), ``(3, 1)`` (3.0 whose header derives the weights from the plan and whose head
    has no chunk lengths when the block coder's chunks delimit themselves; labelled 3.0 when
    neither applies), ``(3, 0)`` (the
    binary header, a CRC-16 per chunk and per code-block), ``(2, 0)`` (no block checks, chunk
    0 under the header's CRC-32), or ``(1, 1)`` for the JSON header that wavecore releases
    before 2.0 read (labelled 1.2 when the header has ``scale``).  ``chunks`` are always as
    the coder wrote them: for 3.0 the block checks are added here, after each chunk's table
    of block lengths (the blocks per chunk follow from the header; the band counts come
    with the coder's chunks, or are found by decoding them).

    Examples
    --------
    >>> header = {"kind": "curve", "shape": [8, 2], "dtype": "float64", "fit": "none",
    ...           "pads": [[0, 0]], "fitted": [8, 2], "wavelet": "bspline2",
    ...           "boundary": ["open"], "levels": 0, "colour": "none", "quantizer": "none",
    ...           "qparams": {}, "coder": "raw", "cparams": {}, "peak": 1.0, "psnr": None,
    ...           "max_error": 0.0}
    >>> data = write_bundle(header, [b"abc"])  # a curve: format 5.0
    >>> data[:4], read_bundle(data).chunk(0)
    (b'\\x89W\\x05\\x00', b'abc')
    >>> read_bundle(write_bundle(header, [b"abc"], version=(3, 0))).version
    (3, 0)
    """
    check_header(header)
    if not 1 <= len(chunks) <= MAX_CHUNKS or len(chunks) != header["levels"] + 1:
        msg = f"a bundle of {header['levels']} levels needs {header['levels'] + 1} chunks"
        raise BundleError(msg)
    if version is None:
        version = written_version(header)
        if version == CURVE_VERSION:
            return _curve_bundle(header, chunks)
    if version[0] == 1:
        return _write_json(header, chunks)
    if version in (COMPACT_VERSION, CURVE_VERSION_5, CURVE_VERSION):
        return _write_compact(header, chunks, version)
    if version not in ((2, 0), (3, 0), FORMAT_VERSION):
        msg = (
            f"cannot write bundle format version {version}; use {CURVE_VERSION}, "
            f"{CURVE_VERSION_5}, {COMPACT_VERSION}, {FORMAT_VERSION}, (3, 0), (2, 0) or (1, 1)"
        )
        raise BundleError(msg)
    pinned = pinned_weights(header) if version == FORMAT_VERSION else None
    delimited = version == FORMAT_VERSION and _delimits_itself(header)
    packed = binheader.pack(header, pinned=pinned, delimited=delimited)
    if len(packed) > MAX_HEADER_SIZE:
        msg = f"header is {len(packed)} bytes, more than MAX_HEADER_SIZE = {MAX_HEADER_SIZE}"
        raise BundleError(msg)
    if version == FORMAT_VERSION and not delimited and packed[3] & 3 != binheader.DERIVED_DEADZONE:
        # Labelled with the oldest minor version that reads it right, as 1.x did: a header
        # without derived weights whose chunk lengths are stored is 3.0's.
        version = (3, 0)
    if version >= (3, 0):
        chunks = _with_block_checks(header, chunks)
    parts = [MAGIC, bytes(version), _varint(len(packed)), packed]
    if delimited:
        # 3.1: chunks that delimit themselves (a table of block lengths first) have no
        # lengths in the head, which is then bounded whatever the chunks' sizes.
        _check_delimited(header, chunks)
    else:
        parts += [_varint(len(chunk)) for chunk in chunks]
    checked = chunks if version >= (3, 0) else chunks[1:]
    parts += [_U16.pack(_crc16(chunk)) for chunk in checked]
    head = b"".join(parts)
    if version >= (3, 0):
        return b"".join([head, _CRC.pack(zlib.crc32(head)), *chunks])
    crc = zlib.crc32(chunks[0], zlib.crc32(head))
    return b"".join([head, _CRC.pack(crc), *chunks])


def _write_compact(
    header: dict[str, Any], chunks: Sequence[bytes], version: tuple[int, int]
) -> bytes:
    """Formats 4.0 and 5.0: preamble, header, chunk lengths (5.0: unless the chunks delimit
    themselves), a CRC-16 per group, the head's CRC-16, the chunks (4.0: with block checks)."""
    packed = _compact_header(header)
    if version == CURVE_VERSION_5:
        return _curve_bytes(packed, header, chunks)
    if version == CURVE_VERSION:
        return _checked_curve_bytes(packed, header, _with_block_checks(header, chunks))
    return _compact_bytes(packed, _with_block_checks(header, chunks))


def _curve_bundle(header: dict[str, Any], chunks: Sequence[bytes]) -> bytes:
    """A curve as :func:`write_bundle` writes it by default: 6.0, unless its block checks
    would take its overhead past :data:`CURVE_OVERHEAD_LIMIT`; then 5.0.

    The checks cost 2 bytes a block and the band counts 2 to 6 bytes a chunk, only in chunks
    of more than one block; that passes the limit only where padding to very deep levels
    makes several chunks of several blocks (levels 14 and 15 of a 50 000-point curve, padded
    to 65 538 points: 53 to 59 bytes); such a curve is written as 5.0, whose damaged blocks
    lose their group and whose regions read whole bands.
    """
    packed = _compact_header(header)
    stored = _with_block_checks(header, chunks)
    checked = _checked_curve_bytes(packed, header, stored)
    if len(checked) - sum(len(chunk) for chunk in chunks) <= CURVE_OVERHEAD_LIMIT:
        return checked
    return _curve_bytes(packed, header, chunks)


def _compact_header(header: dict[str, Any]) -> bytes:
    """The header in 4.0's form (5.0 has the same), weights left out when the plan gives them."""
    derived = False
    weights = header["qparams"].get("weights")
    # The codec's stage registry says which quantizers' weights the plan derives; imported
    # here because the codec package imports this module.
    from .codec.stages import quantizer_of

    if weights is not None and quantizer_of(header).derivable_weights:
        try:
            derived = derived_weights(header) == weights
        except BundleError:
            derived = False
    packed = binheader.pack(header, major=COMPACT_VERSION[0], derived_weights=derived)
    if len(packed) > MAX_HEADER_SIZE:
        msg = f"header is {len(packed)} bytes, more than MAX_HEADER_SIZE = {MAX_HEADER_SIZE}"
        raise BundleError(msg)
    return packed


def _compact_bytes(packed: bytes, chunks: Sequence[bytes]) -> bytes:
    """A 4.0 bundle from its packed header and its chunks as stored (block checks added)."""
    parts = [COMPACT_MAGIC, bytes(COMPACT_VERSION), packed]
    parts += [_varint(len(chunk)) for chunk in chunks]
    for first, last in chunk_groups([len(chunk) for chunk in chunks]):
        crc = 0
        for chunk in chunks[first : last + 1]:
            crc = crc16(chunk, crc)
        parts.append(_U16.pack(crc))
    head = b"".join(parts)
    return b"".join([head, _U16.pack(binascii.crc_hqx(head, 0)), *chunks])


def _curve_bytes(packed: bytes, header: dict[str, Any], chunks: Sequence[bytes]) -> bytes:
    """A 5.0 bundle from its packed header and the chunks as the coder wrote them."""
    blocks = self_delimiting_blocks(header)
    parts = [COMPACT_MAGIC, bytes(CURVE_VERSION_5), packed]
    if blocks is None:
        parts += [_varint(len(chunk)) for chunk in chunks]
    else:
        for index, (chunk, count) in enumerate(zip(chunks, blocks, strict=True)):
            if _delimited_length(memoryview(chunk), count) != len(chunk):
                msg = (
                    f"chunk {index} is not as the block coder writes it: its table of {count} "
                    f"block length(s) does not add up to its {len(chunk)} bytes"
                )
                raise BundleError(msg)
    for first, last in curve_groups(len(chunks)):
        crc = 0
        for chunk in chunks[first : last + 1]:
            crc = crc16(chunk, crc)
        parts.append(_U16.pack(crc))
    head = b"".join(parts)
    return b"".join([head, _U16.pack(binascii.crc_hqx(head, 0)), *map(bytes, chunks)])


def _delimited_length(view: memoryview, count: int) -> int | None:
    """The length of a block-coded chunk at the start of ``view``: its table of ``count``
    block lengths plus those lengths; None when the table is cut short or does not fit."""
    try:
        read, lengths = block_table(view, count)
    except BundleError:
        return None
    return read + int(lengths.sum())


def self_delimiting_blocks(header: dict[str, Any]) -> list[int] | None:
    """How many code-blocks each chunk holds, when the header's coder writes chunks that
    delimit themselves (the ``context`` coder, versions 4, 6, 7 and 8: a chunk starts with the byte
    length of each of its blocks); else None.  Format 5.0 then stores no chunk lengths.

    Raises
    ------
    BundleError
        If the header does not describe a consistent plan.
    """
    if header["cparams"].get("version") not in (4, 6, 7, 8):
        return None
    layout = block_layout(header)
    return None if layout is None else layout[0]


def block_layout(header: dict[str, Any]) -> tuple[list[int], list[int]] | None:
    """How many code-blocks each chunk holds and how many bands it has (0 for chunk 0, whose
    band counts are never stored), when the header's coder codes in independent blocks (the
    ``context`` coder, version 4 on); else None.

    Raises
    ------
    BundleError
        If the header does not describe a consistent plan.
    """
    cparams = header["cparams"]
    version = cparams.get("version")
    if header["coder"] != "context" or isinstance(version, bool) or not isinstance(version, int):
        return None
    two_d, block = cparams.get("two_d"), cparams.get("block")
    if version < 4 or not isinstance(two_d, bool) or isinstance(block, bool):
        return None
    if block not in BLOCK_SIZES:
        return None
    # The plan imports this module (through the codec); hence here.
    from .codec.plan import plan_from_header

    plan = plan_from_header(header)
    try:
        layout = plan.band_shapes()
        # The block coder's grid (docs/bundle-format.md, "Blocks"): B × B positions (1 × B²
        # for bands of one axis) over the largest rows and columns of the chunk's bands.
        # Counted here from the shapes alone, in time linear in the levels, before the
        # head check: blockcoder.block_counts builds the coder's whole tables (cost grows
        # with the channels and blocks a crafted header may declare).
        rows, cols = (block, block) if two_d else (1, block * block)
        counts, band_numbers = [], []
        for index, entry in enumerate(layout):
            bands = [entry] if index == 0 or len(plan.axes) == 1 else list(entry)
            dims = [_plane_rows_cols(tuple(band), two_d) for band in bands]
            height, width = max(d[0] for d in dims), max(d[1] for d in dims)
            counts.append(-(-height // rows) * -(-width // cols))
            band_numbers.append(len(bands) if index else 0)
        return counts, band_numbers
    except BundleError:
        raise
    except Exception as exc:  # a crafted header that passed every check
        msg = f"the header's code-blocks cannot be counted: {type(exc).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc


def _plane_rows_cols(band: tuple[int, ...], two_d: bool) -> tuple[int, int]:
    """Rows and columns of a band's planes as the block coder sees them (1-D bands and bands
    coded on one axis: one row of samples)."""
    if not band:
        return 1, 1
    if two_d and len(band) >= 2:
        return int(band[0]), int(band[1])
    return 1, int(band[0])


def curve_groups(count: int) -> list[tuple[int, int]]:
    """Format 5.0's groups of chunks, ``(first, last)`` each: chunks 0 … N − 2 (the coarse
    levels) and the finest chunk, N − 1; one group when there is one chunk.

    >>> curve_groups(1), curve_groups(2), curve_groups(9)
    ([(0, 0)], [(0, 0), (1, 1)], [(0, 7), (8, 8)])
    """
    return [(0, 0)] if count <= 1 else [(0, count - 2), (count - 1, count - 1)]


def checked_groups(blocks: Sequence[int]) -> list[tuple[int, int]]:
    """Format 6.0's groups of chunks, ``(first, last)`` each, from each chunk's number of
    code-blocks: a chunk of more than one block checks itself and is in no group.  When no
    chunk has several blocks, the groups of 5.0 (:func:`curve_groups`); else the leading
    chunks of one block form one group, and any later chunk of one block is a group of its
    own (the block coder's chunks grow coarse to fine, so there is none).

    >>> checked_groups([1, 1, 1]), checked_groups([1, 1, 2]), checked_groups([2, 2])
    ([(0, 1), (2, 2)], [(0, 1)], [])
    """
    if all(count <= 1 for count in blocks):
        return curve_groups(len(blocks))
    leading = 0
    while blocks[leading] <= 1:
        leading += 1
    groups = [(0, leading - 1)] if leading else []
    groups += [(i, i) for i in range(leading, len(blocks)) if blocks[i] <= 1]
    return groups


def _checked_curve_bytes(packed: bytes, header: dict[str, Any], chunks: Sequence[bytes]) -> bytes:
    """A 6.0 bundle from its packed header and the chunks in their stored form (chunks of
    several blocks with their block checks, as :func:`_with_block_checks` makes them)."""
    layout = block_layout(header)
    count = len(chunks)
    blocks = layout[0] if layout is not None else [1] * count
    parts = [COMPACT_MAGIC, bytes(CURVE_VERSION), packed]
    if self_delimiting_blocks(header) is None:
        parts += [_varint(len(chunk)) for chunk in chunks]
    else:
        _check_delimited(header, chunks)
    for first, last in checked_groups(blocks):
        crc = 0
        for chunk in chunks[first : last + 1]:
            crc = crc16(chunk, crc)
        parts.append(_U16.pack(crc))
    head = b"".join(parts)
    return b"".join([head, _U16.pack(binascii.crc_hqx(head, 0)), *map(bytes, chunks)])


def _delimits_itself(header: dict[str, Any]) -> bool:
    """Whether 3.1 stores no chunk lengths for this header: the ``context`` coder in blocks
    (versions 4 to 8, lossy and lossless), whose chunks start with their blocks' lengths."""
    cparams = header["cparams"]
    return (
        header["coder"] == "context"
        and cparams.get("version") in (4, 5, 6, 7, 8)
        and block_layout(header) is not None
    )


def _check_delimited(header: dict[str, Any], chunks: Sequence[bytes]) -> None:
    """Refuse chunks in their stored form (3.1, 6.0) whose own tables do not give their
    lengths, so that a writer never writes a bundle its reader would cut elsewhere."""
    layout = block_layout(header)
    count = len(chunks)
    blocks, bands = layout if layout is not None else ([1] * count, [0] * count)
    for index, chunk in enumerate(chunks):
        length = _checked_length(memoryview(chunk), blocks[index], bands[index])
        if length != len(chunk):
            msg = (
                f"chunk {index} is not as the block coder writes it: its table of "
                f"{blocks[index]} block length(s) does not add up to its {len(chunk)} bytes"
            )
            raise BundleError(msg)


def _cut_short(view: memoryview, blocks: int, bands: int) -> bool:
    """Whether the last chunk of a 3.1 bundle, ``view`` (the rest of the bundle), is cut
    short: its table (intact, by its prefix check when it has several blocks) asks for more
    bytes than remain, or the bundle ends inside the table.  A damaged table is not a cut;
    the chunk's checks then find the damage."""
    length = _checked_length(view, blocks, bands)
    if length is not None:
        return False
    if blocks <= 1:
        return True  # one block: its length is the only table
    try:
        read, _ = block_table(view, blocks)
    except BundleError:
        return True  # the table itself is cut short (or unreadable)
    position = read + CHECK_BYTES * blocks
    for _ in range(2 * bands):  # the band counts, two varints a band
        for count in range(binheader.MAX_VARINT_BYTES + 1):
            if position >= len(view) or count == binheader.MAX_VARINT_BYTES:
                return position >= len(view)
            position += 1
            if not view[position - 1] & 0x80:
                break
    if position + CHECK_BYTES > len(view):
        return True
    stored = int.from_bytes(view[position : position + CHECK_BYTES], "little")
    return binascii.crc_hqx(view[:position], 0) == stored


def _checked_length(view: memoryview, blocks: int, bands: int) -> int | None:
    """The stored length of a self-delimiting chunk at the start of ``view`` (6.0): its
    table, and for a chunk of several blocks its block checks, band counts and prefix check,
    then the blocks; None when that is cut short or does not fit."""
    if blocks <= 1:
        return _delimited_length(view, blocks)
    try:
        read, lengths = block_table(view, blocks)
    except BundleError:
        return None
    position = read + CHECK_BYTES * blocks
    for _ in range(2 * bands):  # the band counts, two varints a band
        for count in range(binheader.MAX_VARINT_BYTES + 1):
            if position >= len(view) or count == binheader.MAX_VARINT_BYTES:
                return None
            position += 1
            if not view[position - 1] & 0x80:
                break
    total = position + CHECK_BYTES + int(lengths.sum())
    return total if total <= len(view) else None


def with_header(bundle: bytes, header: dict[str, Any]) -> bytes:
    """A complete 4.0, 5.0 or 6.0 ``bundle`` with its header replaced by ``header`` (same
    chunks, same version; but a 5.0 or 6.0 *curve* is written as :func:`write_bundle` writes
    a curve by default, 6.0 unless its checks would pass :data:`CURVE_OVERHEAD_LIMIT`, since
    a shorter header may make room for them).

    For an encoder that adjusts a header field after coding (``encode_curve`` stores a float32
    step when that keeps its tolerance); the header is checked as :func:`write_bundle` checks.
    """
    parsed = read_bundle(bundle)
    if parsed.version[0] not in _SHORT_MAJORS or parsed.available != len(parsed.chunks):
        msg = "with_header takes a complete 4.x, 5.x or 6.x bundle"
        raise BundleError(msg)
    check_header(header)
    if header["levels"] != parsed.header["levels"]:
        msg = "with_header cannot change the number of levels"
        raise BundleError(msg)
    chunks = [bytes(chunk or b"") for chunk in parsed.chunks]
    curve = header["kind"] == "curve" == parsed.header["kind"]
    if curve and parsed.version[0] in (CURVE_VERSION_5[0], CURVE_VERSION[0]):
        checked = parsed.checked or (None,) * len(chunks)
        coded = [  # as the coder wrote them
            chunk if own is None else strip_block_checks(chunk, *own)[0]
            for chunk, own in zip(chunks, checked, strict=True)
        ]
        return _curve_bundle(header, coded)
    packed = _compact_header(header)
    if parsed.version[0] == CURVE_VERSION_5[0]:
        return _curve_bytes(packed, header, chunks)
    if parsed.version[0] == CURVE_VERSION[0]:
        return _checked_curve_bytes(packed, header, chunks)  # already in their stored form
    return _compact_bytes(packed, chunks)


def chunk_groups(lengths: Sequence[int], limit: int = GROUP_BYTES) -> list[tuple[int, int]]:
    """Format 4.0's groups of chunks, ``(first, last)`` each: consecutive chunks, coarse to
    fine, packed while a group holds at most ``limit`` bytes (a longer chunk is alone).

    >>> chunk_groups([150, 4, 1, 1, 10, 2000, 30])
    [(0, 4), (5, 5), (6, 6)]
    """
    groups: list[tuple[int, int]] = []
    first = total = 0
    for index, length in enumerate(lengths):
        if index > first and total + length > limit:
            groups.append((first, index - 1))
            first, total = index, 0
        total += length
    groups.append((first, len(lengths) - 1))
    return groups


def derived_weights(header: dict[str, Any]) -> list[list[float]]:
    """The per-band weights of a ``deadzone`` header as its plan gives them.

    They are :func:`wavecore.quantize.band_weights` of the band shapes that the header's
    ``fitted`` shape, ``levels``, ``wavelet`` and ``boundary`` make: the reciprocal RMS basis
    norm of each band, to four significant digits, exactly what the encoder uses.  A 4.0
    header stores them in no bytes when they are these.

    Raises
    ------
    BundleError
        If the header does not describe a consistent plan.
    """
    plan = _plan_shapes(header)
    try:
        weights = _plan_weights(*plan)
    except Exception as exc:  # a crafted header that passed every check
        msg = f"the header's weights cannot be derived: {type(exc).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc
    return [list(entry) for entry in weights]


def _plan_shapes(
    header: dict[str, Any],
) -> tuple[str, tuple[str, ...], tuple[tuple[tuple[int, ...], ...], ...]]:
    """The wavelet, boundaries and band shapes of a header's plan (what its weights depend
    on)."""
    # The plan imports this module (through the codec); hence here.
    from .codec.plan import plan_from_header

    plan = plan_from_header(header)
    try:
        layout = plan.band_shapes()
    except BundleError:
        raise
    except Exception as exc:  # a crafted header that passed every check
        msg = f"the header's weights cannot be derived: {type(exc).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc
    shapes = tuple(
        (tuple(entry),) if index == 0 or len(plan.axes) == 1 else tuple(map(tuple, entry))
        for index, entry in enumerate(layout)
    )
    return plan.wavelet, tuple(plan.boundary), shapes


def pinned_weights(header: dict[str, Any]) -> dict[int, float] | None:
    """The weights a 3.1 header stores although its plan gives them: by their index among
    every band (coarse first, ``cV`` included), those that differ from
    :func:`derived_weights` and those whose unrounded value lies within :data:`PIN_MARGIN` of
    a change of digit; None when the plan does not give the header's weights (a quantizer
    without derivable weights, or another layout).

    The codec's weights are the plan's, and a weight that close to a change of digit is rare
    (about 2·10⁻⁵ of them), so nearly every header pins none.
    """
    weights = header["qparams"].get("weights")
    # The codec's stage registry says which quantizers' weights the plan derives; imported
    # here because the codec package imports this module.
    from .codec.stages import quantizer_of

    try:
        if weights is None or not quantizer_of(header).derivable_weights:
            return None
        derived = derived_weights(header)
        margins = _margins(header)
    except BundleError:
        return None
    if not isinstance(weights, list) or [len(e) for e in weights] != [len(e) for e in derived]:
        return None
    pins: dict[int, float] = {}
    index = 0
    for stored, plan, margin in zip(weights, derived, margins, strict=True):
        for weight, expected, room in zip(stored, plan, margin, strict=True):
            # A margin of exactly 0 is an exact tie: the plan's norms reach it exactly (Haar's
            # weights 2**-6 = 0.015625 and 2**-7 = 0.0078125: powers of two, from exact means
            # of squares), the same on every machine, and ``f"{w:.4g}"`` rounds it to even
            # everywhere; it needs no pin.
            if weight != expected or 0.0 < room < PIN_MARGIN:
                pins[index] = weight
            index += 1
    return pins


def _margins(header: dict[str, Any]) -> tuple[tuple[float, ...], ...]:
    """The rounding margins of the plan's weights (:func:`_plan_margins`)."""
    plan = _plan_shapes(header)
    try:
        return _plan_margins(*plan)
    except Exception as exc:  # a crafted header that passed every check
        msg = f"the header's weights cannot be derived: {type(exc).__name__}: {exc}"
        raise BundleError(msg[:300]) from exc


@functools.lru_cache(maxsize=64)
def _plan_margins(
    wavelet: str, boundary: tuple[str, ...], shapes: tuple[tuple[tuple[int, ...], ...], ...]
) -> tuple[tuple[float, ...], ...]:
    """``band_weight_margins`` of a layout's band shapes (cached as :func:`_plan_weights`)."""
    from .quantize import band_weight_margins

    coeffs, axes = _stand_ins(boundary, shapes)
    margins = band_weight_margins(coeffs, wavelet=wavelet, boundary=list(boundary), axes=axes)
    return tuple(tuple(entry) for entry in margins)


def _stand_ins(
    boundary: tuple[str, ...], shapes: tuple[tuple[tuple[int, ...], ...], ...]
) -> tuple[list[Any], tuple[int, ...]]:
    """Zero-memory stand-in bands of a layout's shapes (the norms need the shapes only)."""
    import numpy as np

    stand_in = np.zeros(())

    def band(shape: tuple[int, ...]) -> Any:
        return np.broadcast_to(stand_in, shape)

    one_axis = len(boundary) == 1
    coeffs: list[Any] = [band(shapes[0][0])] + [
        band(entry[0]) if one_axis else tuple(band(s) for s in entry) for entry in shapes[1:]
    ]
    return coeffs, (0,) if one_axis else (0, 1)


@functools.lru_cache(maxsize=64)
def _plan_weights(
    wavelet: str, boundary: tuple[str, ...], shapes: tuple[tuple[tuple[int, ...], ...], ...]
) -> tuple[tuple[float, ...], ...]:
    """``band_weights`` of a layout's band shapes (cached: an encoder reads back what it wrote,
    and ``inspect`` and ``decode`` read the same bundles)."""
    from .quantize import band_weights

    coeffs, axes = _stand_ins(boundary, shapes)
    weights = band_weights(coeffs, wavelet=wavelet, boundary=list(boundary), axes=axes)
    return tuple(tuple(entry) for entry in weights)


class _StoredChunk(bytes):
    """A chunk in 3.0's stored form, with its CRC-16 once computed."""

    crc16: int | None = None


def _with_block_checks(header: dict[str, Any], chunks: Sequence[bytes]) -> list[bytes]:
    """The chunks in format 3.0's form: block checks and band counts where the coder codes
    in blocks (context version 4 on), the chunks as they are otherwise.

    The stored form is kept on the coder's chunk when it takes attributes (the block coder's
    chunks do): the rate control writes the same chunks twice (a size bound, then the
    bundle), and the block checks' CRCs of a 2048² picture cost a few milliseconds."""
    # The block structure follows from the plan's band shapes, which the codec package
    # computes; it imports this module, hence the import here.
    from .codec.decode import chunk_block_info

    # What the stored form depends on besides the chunk's bytes: the block structure.
    layout = ("kind", "fitted", "levels", "wavelet", "boundary", "lifting", "coder", "cparams")
    key = json.dumps([header.get(name) for name in layout], sort_keys=True)
    cached: list[tuple[str | None, bytes]] = [
        getattr(chunk, "stored_form", (None, b"")) for chunk in chunks
    ]
    if all(entry[0] == key for entry in cached):
        return [entry[1] for entry in cached]
    info = chunk_block_info(header, chunks)
    if info is None:
        return list(chunks)
    stored = [
        _StoredChunk(add_block_checks(chunk, count, counts))
        for chunk, (count, counts) in zip(chunks, info, strict=True)
    ]
    for chunk, form in zip(chunks, stored, strict=True):
        with contextlib.suppress(AttributeError):  # plain bytes keep nothing
            chunk.stored_form = (key, form)  # type: ignore[attr-defined]
    return list(stored)


def _crc16(chunk: bytes) -> int:
    """CRC-16/XMODEM of a chunk, remembered on a stored chunk."""
    known = getattr(chunk, "crc16", None)
    if known is not None:
        return int(known)
    crc = crc16(chunk)
    if isinstance(chunk, _StoredChunk):
        chunk.crc16 = crc
    return crc


def _write_json(header: dict[str, Any], chunks: Sequence[bytes]) -> bytes:
    """Format 1.1 (1.2 with ``scale``): the deflated JSON header."""
    text = json.dumps(header, separators=(",", ":"), allow_nan=False).encode("utf-8")
    if len(text) > MAX_HEADER_SIZE:
        msg = f"header is {len(text)} bytes, more than MAX_HEADER_SIZE = {MAX_HEADER_SIZE}"
        raise BundleError(msg)
    text = deflate_header(text)
    if len(text) > MAX_HEADER_SIZE:  # incompressible and at the limit
        msg = f"header is {len(text)} bytes compressed, more than {MAX_HEADER_SIZE}"
        raise BundleError(msg)
    minor = 2 if "scale" in header else 1
    parts = [_PREAMBLE.pack(MAGIC, 1, minor, len(text)), text, bytes([len(chunks)])]
    for chunk in chunks:
        parts.append(_TABLE_ENTRY.pack(len(chunk), zlib.crc32(chunk)))
    head = b"".join(parts)
    return b"".join([head, _CRC.pack(zlib.crc32(head)), *chunks])


def _varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def read_bundle(data: Any) -> Bundle:
    """Parse and validate a bundle's preamble, header and chunk table (any version it knows).

    Never raises anything but :class:`BundleError` and never allocates more than the input's
    own size: chunks are views into ``data``.

    Parameters
    ----------
    data : bytes-like
        The bundle.  It may be truncated inside the chunks (the missing chunks come back as
        ``None``); a bundle truncated before the end of its chunk table is an error, and so
        (in version 2.x, whose header CRC covers chunk 0) is one cut inside chunk 0.
    """
    try:
        reader = _Reader(data)
    except TypeError as exc:
        msg = f"a bundle must be bytes, not {type(data).__name__}"
        raise BundleError(msg) from exc
    start = bytes(reader.view[:3])
    if len(start) == 3 and start[:2] == COMPACT_MAGIC and start[2] >= 0x80:
        # Curve sets of version 6 start with these two bytes and 0x80 | their version: not a
        # bundle of this module (no major version reaches 0x80), and said so plainly.
        msg = (
            f"not an image bundle: a curve set (version {start[2] & 0x7F}); decode it with "
            "wavecore.decode or wavecore.decode_curves"
        )
        raise BundleError(msg)
    if len(start) == 3 and start[:2] == COMPACT_MAGIC and start[2] != MAGIC[2]:
        major, minor = reader.take(4, "the preamble")[2:]
        if major == REPLICATED_MAJOR:  # wavecore.codec.replication's wrapper, said plainly
            msg = (
                f"not a bundle of this reader: a picture enlarged by pixel replication (format "
                f"{major}.{minor}) around its source's bundle; decode it with wavecore.decode, "
                "or unwrap it with wavecore.codec.replication.unwrap"
            )
            raise BundleError(msg)
        if major not in _SHORT_MAJORS:
            msg = (
                f"unsupported bundle format version {major}.{minor}: this wavecore reads major "
                f"versions {', '.join(map(str, READ_MAJORS))} (up to "
                f"{CURVE_VERSION[0]}.{CURVE_VERSION[1]} fully); use a wavecore release that "
                "knows this version"
            )
            raise BundleError(msg)
        if major == CURVE_VERSION_5[0]:
            return _read_curve(reader, major, minor)
        if major == CURVE_VERSION[0]:
            return _read_checked_curve(reader, major, minor)
        return _read_compact(reader, major, minor)
    magic, major, minor = reader.unpack(_MAGIC_AND_VERSION, "the preamble")
    if magic != MAGIC:
        msg = f"not a wavecore bundle: the magic bytes are {bytes(magic)!r}, expected {MAGIC!r}"
        raise BundleError(msg)
    if major not in READ_MAJORS or major >= COMPACT_VERSION[0]:
        msg = (
            f"unsupported bundle format version {major}.{minor}: this wavecore reads major "
            f"versions {', '.join(map(str, READ_MAJORS))} (up to "
            f"{CURVE_VERSION[0]}.{CURVE_VERSION[1]} fully); use a wavecore release that "
            "knows this version"
        )
        raise BundleError(msg)
    if major == 1:
        return _read_json(reader, minor)
    return _read_binary(reader, major, minor)


def _read_binary(reader: _Reader, major: int, minor: int) -> Bundle:
    """Formats 2.x and 3.x: the binary header, varint chunk lengths, CRC-16s, then one CRC-32.

    Every 2.x minor version is read in 2.0's layout (a minor version may only add optional
    header keys or enumerated values); 3.x checks every chunk by its CRC-16 and carries block
    checks; a 3.x header with coder code 3 (3.1) has no chunk lengths: the chunks are found
    from their tables of block lengths, the last is the rest of the bundle.
    """
    header_size = reader.varint("the header length", MAX_HEADER_SIZE)
    packed = reader.take(header_size, "the header")
    header, pinned = binheader.unpack_pinned(packed)
    check_header(header)
    count = header["levels"] + 1
    # 3.1 (coder code 3): the chunks delimit themselves, and the head has no lengths (they
    # are found below, once the head is known to be intact).
    delimited = major == 3 and packed[3] >> 2 & 3 == binheader.DELIMITED_CONTEXT
    if delimited and not _delimits_itself(header):
        msg = (
            "binary header field 'coder': code 3 (chunks that delimit themselves) needs the "
            f"context coder in blocks (version 4, 5, 6, 7 or 8), not {header['cparams']!r}"
        )
        raise BundleError(msg)
    lengths = (
        []
        if delimited
        else [reader.varint(f"the length of chunk {i}", 2**40) for i in range(count)]
    )
    first_crc = 0 if major >= 3 else 1  # 2.x: chunk 0 is checked by the CRC-32
    crcs = [0] * first_crc + [
        reader.unpack(_U16, f"the CRC-16 of chunk {i}")[0] for i in range(first_crc, count)
    ]
    head_end = reader.offset
    (crc,) = reader.unpack(_CRC, "the header CRC-32")
    if major >= 3:
        if zlib.crc32(reader.view[:head_end]) != crc:
            msg = "the header or chunk table is corrupt: the header CRC-32 does not match"
            raise BundleError(msg)
        if pinned is not None:  # only once the header is known to be intact
            _add_pinned_weights(header, pinned)
        if delimited:
            layout = block_layout(header)
            blocks, bands = layout if layout is not None else ([1] * count, [0] * count)
            lengths = _delimited_lengths(reader, blocks[:-1], bands[:-1])
            # The finest chunk (the largest, with the longest table) runs to the end: a
            # damaged table there loses only that chunk, and a cut there only its end.
            start = reader.offset + sum(lengths)
            rest = len(reader.view) - start
            if rest < 0 or _cut_short(reader.view[start:], blocks[-1], bands[-1]):
                rest = len(reader.view) + 1  # missing: the bundle was cut inside it
            lengths.append(rest)
        chunks = _take_chunks(reader, lengths)
        return Bundle(
            (major, minor),
            header,
            chunks,
            tuple(crcs),
            "crc16",
            block_checks=True,
            open_ended=delimited,
        )
    remaining = len(reader.view) - reader.offset
    if lengths[0] > remaining:
        msg = (
            f"bundle is truncated inside chunk 0 (it needs {lengths[0]} bytes, {remaining} "
            "remain): the header's CRC-32 covers chunk 0, and every level needs it"
        )
        raise BundleError(msg)
    first = reader.view[reader.offset : reader.offset + lengths[0]]
    if zlib.crc32(first, zlib.crc32(reader.view[:head_end])) != crc:
        msg = "the header, chunk table or chunk 0 is corrupt: the header CRC-32 does not match"
        raise BundleError(msg)
    if pinned is not None:  # a 2.x header with 3.1's quantizer code: read as it says
        _add_pinned_weights(header, pinned)
    crcs[0] = crc16(first)
    chunks = _take_chunks(reader, lengths)
    return Bundle((major, minor), header, chunks, tuple(crcs), "crc16")


def _read_compact(reader: _Reader, major: int, minor: int) -> Bundle:
    """Format 4.x: the header (no length before it), varint chunk lengths, a CRC-16 per group
    of chunks, then the CRC-16 of all that.  Every 4.x minor version is read as 4.0."""
    header, reader.offset, derived = binheader.unpack_from(reader.view, reader.offset)
    check_header(header)
    count = header["levels"] + 1
    lengths = [reader.varint(f"the length of chunk {i}", 2**40) for i in range(count)]
    spans = chunk_groups(lengths)
    crcs = _read_group_crcs(reader, spans, count)
    if derived:  # only once the header is known to be intact
        _add_derived_weights(header)
    chunks, groups = _grouped(_take_chunks(reader, lengths), spans, count)
    return Bundle((major, minor), header, chunks, crcs, "crc16", block_checks=True, groups=groups)


def _read_group_crcs(
    reader: _Reader, spans: Sequence[tuple[int, int]], count: int
) -> tuple[int, ...]:
    """Each chunk's group CRC-16 (one stored per group), after checking the header CRC-16
    that follows them over everything read so far."""
    crcs = [0] * count
    for number, (first, last) in enumerate(spans):
        (crc,) = reader.unpack(_U16, f"the CRC-16 of group {number}")
        crcs[first : last + 1] = [crc] * (last + 1 - first)
    head_end = reader.offset
    (crc,) = reader.unpack(_U16, "the header CRC-16")
    if binascii.crc_hqx(reader.view[:head_end], 0) != crc:
        msg = "the header or chunk table is corrupt: the header CRC-16 does not match"
        raise BundleError(msg)
    return tuple(crcs)


def _grouped(
    read: Sequence[Any], spans: Sequence[tuple[int, int]], count: int
) -> tuple[tuple[Any, ...], tuple[tuple[int, int], ...]]:
    """The chunks with every group that lost one chunk lost whole (a group is read whole),
    and each chunk's group as ``(first, last)``."""
    chunks = list(read)
    groups = [(0, 0)] * count
    for first, last in spans:
        groups[first : last + 1] = [(first, last)] * (last + 1 - first)
        if any(chunk is None for chunk in chunks[first : last + 1]):
            chunks[first : last + 1] = [None] * (last + 1 - first)
    return tuple(chunks), tuple(groups)


def _add_pinned_weights(header: dict[str, Any], pinned: binheader.PinnedWeights) -> None:
    """3.1: the plan's weights with the pinned ones put in, checked against the header's
    check byte (a reader that derives other weights than the writer did is refused)."""
    weights = pinned.apply(derived_weights(header))
    check = binheader.weights_check(weights)
    if check != pinned.check:
        msg = (
            "the quantizer's weights that this reader derives from the plan are not the "
            f"writer's: their check is {check}, the header says {pinned.check} (a wavecore "
            "whose band norms differ from those that wrote the bundle)"
        )
        raise BundleError(msg)
    qparams = header["qparams"]
    header["qparams"] = {
        "name": qparams["name"],
        "step": qparams["step"],
        "weights": weights,
        "rounding": qparams["rounding"],
    }


def _add_derived_weights(header: dict[str, Any]) -> None:
    qparams = header["qparams"]
    header["qparams"] = {
        "name": qparams["name"],
        "step": qparams["step"],
        "weights": derived_weights(header),
        "rounding": qparams["rounding"],
    }


def _read_curve(reader: _Reader, major: int, minor: int) -> Bundle:
    """Format 5.x: the header (no length before it), the chunk lengths unless the chunks
    delimit themselves, a CRC-16 per group of :func:`curve_groups`, the CRC-16 of all that;
    the chunks as the coder wrote them.  Every 5.x minor version is read as 5.0."""
    header, reader.offset, derived = binheader.unpack_from(reader.view, reader.offset)
    check_header(header)
    count = header["levels"] + 1
    blocks = self_delimiting_blocks(header)
    lengths = None
    if blocks is None:
        lengths = [reader.varint(f"the length of chunk {i}", 2**40) for i in range(count)]
    spans = curve_groups(count)
    crcs = _read_group_crcs(reader, spans, count)
    if derived:  # only once the header is known to be intact
        _add_derived_weights(header)
    if lengths is None:
        assert blocks is not None
        lengths = _delimited_lengths(reader, blocks)
    chunks, groups = _grouped(_take_chunks(reader, lengths), spans, count)
    return Bundle((major, minor), header, chunks, crcs, "crc16", groups=groups)


def _read_checked_curve(reader: _Reader, major: int, minor: int) -> Bundle:
    """Format 6.x: 5.0 with chunks of several blocks in 3.0's checked form and in no group
    (:func:`checked_groups`).  Every 6.x minor version is read as 6.0."""
    header, reader.offset, derived = binheader.unpack_from(reader.view, reader.offset)
    check_header(header)
    count = header["levels"] + 1
    layout = block_layout(header)
    blocks, bands = layout if layout is not None else ([1] * count, [0] * count)
    lengths = None
    if self_delimiting_blocks(header) is None:
        lengths = [reader.varint(f"the length of chunk {i}", 2**40) for i in range(count)]
    spans = checked_groups(blocks)
    crcs = _read_group_crcs(reader, spans, count)
    if derived:  # only once the header is known to be intact
        _add_derived_weights(header)
    if lengths is None:
        lengths = _delimited_lengths(reader, blocks, bands)
    chunks, groups = _grouped(_take_chunks(reader, lengths), spans, count)
    checked = tuple((blocks[i], bands[i]) if blocks[i] > 1 else None for i in range(count))
    return Bundle(
        (major, minor),
        header,
        chunks,
        crcs,
        "crc16",
        block_checks=True,
        groups=groups,
        checked=checked,
    )


def _delimited_lengths(
    reader: _Reader, blocks: Sequence[int], bands: Sequence[int] | None = None
) -> list[int]:
    """The lengths of self-delimiting chunks, from their tables of block lengths (6.0, with
    ``bands``: chunks of several blocks carry their block checks); a chunk whose table is cut
    short or does not fit in what remains (a truncated bundle) is missing, and so is every
    chunk after it (its length is 1 more than the bytes that remain)."""
    lengths: list[int] = []
    offset = reader.offset
    missing = len(reader.view) - offset + 1
    for index, count in enumerate(blocks):
        length = None
        if offset < len(reader.view):
            view = reader.view[offset:]
            length = (
                _delimited_length(view, count)
                if bands is None
                else _checked_length(view, count, bands[index])
            )
        if length is None:  # cut short: this chunk and every later one are missing
            lengths += [missing] * (len(blocks) - len(lengths))
            break
        lengths.append(length)
        offset += length
    return lengths


def _take_chunks(reader: _Reader, lengths: Sequence[int]) -> tuple[memoryview | None, ...]:
    chunks: list[memoryview | None] = []
    remaining = len(reader.view) - reader.offset
    for length in lengths:
        if length <= remaining:
            chunks.append(reader.take(length, "a chunk"))
            remaining -= length
        else:
            remaining = -1  # every chunk after a missing one is missing too
            chunks.append(None)
    if remaining > 0:
        msg = f"{remaining} unexpected byte(s) after the last chunk"
        raise BundleError(msg)
    return tuple(chunks)


def _read_json(reader: _Reader, minor: int) -> Bundle:
    """Format 1.x: the deflated JSON header and a table of uint32 lengths and CRC-32s."""
    (header_size,) = reader.unpack(_U16, "the header length")
    if header_size < 2:
        msg = f"header length {header_size} is too short for a JSON object"
        raise BundleError(msg)
    text = reader.take(header_size, "the header")
    header = _parse_header(inflate_header(bytes(text)))
    (count,) = reader.unpack(struct.Struct("<B"), "the chunk count")
    if count != header["levels"] + 1:
        msg = (
            f"chunk count {count} does not match the header's levels = {header['levels']} "
            f"(expected {header['levels'] + 1} chunks)"
        )
        raise BundleError(msg)
    table = [reader.unpack(_TABLE_ENTRY, f"chunk table entry {i}") for i in range(count)]
    head_end = reader.offset
    (crc,) = reader.unpack(_CRC, "the header CRC-32")
    if zlib.crc32(reader.view[:head_end]) != crc:
        msg = "the header or chunk table is corrupt: the header CRC-32 does not match"
        raise BundleError(msg)
    chunks = _take_chunks(reader, [length for length, _ in table])
    return Bundle((1, minor), header, chunks, tuple(c for _, c in table))


def deflate_header(text: bytes) -> bytes:
    """Compress header JSON as the format stores it (raw DEFLATE, best compression)."""
    packer = zlib.compressobj(9, zlib.DEFLATED, -15)
    return packer.compress(text) + packer.flush()


def inflate_header(data: bytes) -> bytes:
    """Inflate a stored header, never to more than ``MAX_HEADER_SIZE`` bytes."""
    inflater = zlib.decompressobj(-15)
    try:
        text = inflater.decompress(data, MAX_HEADER_SIZE + 1)
    except zlib.error as exc:
        msg = f"the header is not valid DEFLATE data: {exc}"
        raise BundleError(msg) from exc
    if len(text) > MAX_HEADER_SIZE:
        msg = f"the header inflates to more than MAX_HEADER_SIZE = {MAX_HEADER_SIZE} bytes"
        raise BundleError(msg)
    if not inflater.eof or inflater.unused_data:
        msg = "the header's DEFLATE stream is incomplete or followed by extra bytes"
        raise BundleError(msg)
    return text


def _parse_header(text: bytes) -> dict[str, Any]:
    try:
        header = json.loads(text.decode("utf-8"), parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        msg = f"the header is not valid UTF-8 JSON: {exc}"
        raise BundleError(msg) from exc
    check_header(header)
    return header


def _reject_constant(name: str) -> None:
    msg = f"the header contains {name}, which is not a number"
    raise BundleError(msg)


def _field(header: dict[str, Any], key: str, kind: type | tuple[type, ...]) -> Any:
    """One header field, type-checked; the error names it."""
    if key not in header:
        msg = f"header field {key!r} is missing"
        raise BundleError(msg)
    value = header[key]
    if isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,)):
        msg = f"header field {key!r} must be {_type_name(kind)}, not a boolean"
        raise BundleError(msg)
    if not isinstance(value, kind):
        msg = f"header field {key!r} must be {_type_name(kind)}, not {type(value).__name__}"
        raise BundleError(msg)
    return value


def _type_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {int: "an integer", float: "a number", str: "a string", list: "a list", dict: "an "
             "object", type(None): "null"}  # fmt: skip
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def _choice(header: dict[str, Any], key: str, choices: Sequence[str]) -> str:
    value = _field(header, key, str)
    if value not in choices:
        msg = f"header field {key!r} is {value[:_NAME_MAX]!r}; expected one of {list(choices)}"
        raise BundleError(msg)
    return value


def _name(header: dict[str, Any], key: str) -> str:
    value = _field(header, key, str)
    if not 0 < len(value) <= _NAME_MAX or not value.replace("_", "").isalnum():
        msg = f"header field {key!r} must be a short alphanumeric name, not {value[:40]!r}"
        raise BundleError(msg)
    return value


def _int_list(header: dict[str, Any], key: str, minimum: int) -> list[int]:
    value = _field(header, key, list)
    if not 1 <= len(value) <= 4:
        msg = f"header field {key!r} must list 1 to 4 sizes, not {len(value)}"
        raise BundleError(msg)
    for item in value:
        if isinstance(item, bool) or not isinstance(item, int) or not minimum <= item:
            msg = f"header field {key!r} must hold integers >= {minimum}, not {item!r}"
            raise BundleError(msg)
        if item > MAX_ELEMENTS:
            msg = f"header field {key!r} declares a size {item} above MAX_ELEMENTS"
            raise BundleError(msg)
    return value


def check_header(header: Any) -> None:
    """Validate a header's fields and limits; raise :class:`BundleError` naming the bad field."""
    if not isinstance(header, dict):
        msg = f"the header must be a JSON object, not {type(header).__name__}"
        raise BundleError(msg)
    _choice(header, "kind", KINDS)
    _choice(header, "dtype", DTYPES)
    _choice(header, "fit", FITS)
    colour = _field(header, "colour", str)
    if colour.startswith(KLT_PREFIX):
        try:
            klt_matrix(colour)
        except ValueError as exc:
            msg = f"header field 'colour' is {colour[:_NAME_MAX]!r}: {exc}"
            raise BundleError(msg) from exc
    else:
        _choice(header, "colour", COLOURS)
    _name(header, "wavelet")
    _name(header, "quantizer")
    _name(header, "coder")
    _field(header, "qparams", dict)
    _field(header, "cparams", dict)
    shape = _int_list(header, "shape", 1)
    fitted = _int_list(header, "fitted", 1)
    for key, dims in (("shape", shape), ("fitted", fitted)):
        if math.prod(dims) > MAX_ELEMENTS:
            msg = (
                f"header field {key!r} declares {math.prod(dims)} elements, more than "
                f"MAX_ELEMENTS = {MAX_ELEMENTS}"
            )
            raise BundleError(msg)
    levels = _field(header, "levels", int)
    if not 0 <= levels <= MAX_LEVELS or levels + 1 > MAX_CHUNKS:
        msg = f"header field 'levels' must be between 0 and {MAX_LEVELS}, not {levels}"
        raise BundleError(msg)
    boundary = _field(header, "boundary", list)
    if not 1 <= len(boundary) <= 2 or any(b not in BOUNDARIES for b in boundary):
        msg = f"header field 'boundary' must list one or two of {list(BOUNDARIES)}"
        raise BundleError(msg)
    pads = _field(header, "pads", list)
    if len(pads) != len(boundary):
        msg = f"header field 'pads' must hold one pair per boundary ({len(boundary)})"
        raise BundleError(msg)
    for pair in pads:
        if (
            not isinstance(pair, list)
            or len(pair) != 2
            or any(isinstance(p, bool) or not isinstance(p, int) or p < 0 for p in pair)
        ):
            msg = f"header field 'pads' must hold pairs of integers >= 0, not {pair!r}"
            raise BundleError(msg)
    for key in ("peak", "max_error"):
        value = _field(header, key, (int, float))
        if not math.isfinite(value) or value < 0:
            msg = f"header field {key!r} must be a finite number >= 0, not {value!r}"
            raise BundleError(msg)
    psnr = _field(header, "psnr", (int, float, type(None)))
    if psnr is not None and not math.isfinite(psnr):
        msg = f"header field 'psnr' must be a finite number or null, not {psnr!r}"
        raise BundleError(msg)
    if "opaque" in header:
        _field(header, "opaque", bool)
    if "restore" in header:
        check_restore(header)
    if "scale" in header:
        scale = _field(header, "scale", int)
        if not -MAX_SCALE <= scale <= MAX_SCALE:
            msg = f"header field 'scale' must be between {-MAX_SCALE} and {MAX_SCALE}, not {scale}"
            raise BundleError(msg)
