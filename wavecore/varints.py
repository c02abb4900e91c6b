"""LEB128 varints and zigzag signs: the small integers of the binary header (format 2.0) and
of curve-set records, written one way in one place."""

from __future__ import annotations


def encode_varint(value: int) -> bytes:
    """``value >= 0`` as an unsigned LEB128 varint: 7 bits a byte, low bits first.

    >>> encode_varint(300).hex()
    'ac02'
    """
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def zigzag(value: int) -> int:
    """A signed integer as an unsigned one: 0, -1, 1, -2, ... → 0, 1, 2, 3, ...

    >>> [zigzag(v) for v in (0, -1, 1, -2)]
    [0, 1, 2, 3]
    """
    return 2 * value if value >= 0 else -2 * value - 1


def unzigzag(value: int) -> int:
    """The inverse of :func:`zigzag`.

    >>> [unzigzag(v) for v in (0, 1, 2, 3)]
    [0, -1, 1, -2]
    """
    return value >> 1 if not value & 1 else -(value >> 1) - 1
