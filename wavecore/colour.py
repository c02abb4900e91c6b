"""Luma/chroma transforms applied before the wavelet transform, as JPEG 2000 does.

- :func:`ycbcr_forward` / :func:`ycbcr_inverse`: the irreversible colour transform (ICT, the
  ITU-R BT.601 YCbCr matrix) for lossy coding.  Most of an RGB image's detail is in luma, so
  decorrelating the channels lets the quantizer spend bits where the eye and PSNR want them.
- :func:`rct_forward` / :func:`rct_inverse`: the reversible colour transform (RCT) for lossless
  coding, integer in and integer out, exactly invertible.
- :func:`klt_name` / :func:`klt_matrix`: a per-picture rotation of the colour space for lossy
  coding (the Karhunen–Loève transform of the picture's colour details, chosen by
  :func:`wavecore.codec.choice.choose_colour`), named ``"klt:<a>,<b>,<c>"``: its three angles
  in units of ``pi / KLT_SCALE``, which is all a decoder needs.

Both act on the last axis (``(..., C)`` with ``C >= 3``); channels after the third (alpha) pass
through unchanged.
"""

from __future__ import annotations

import re

import numpy as np

from .errors import InvalidParameter

__all__ = [
    "KLT_LIMIT",
    "KLT_PREFIX",
    "KLT_SCALE",
    "klt_matrix",
    "klt_name",
    "rct_forward",
    "rct_inverse",
    "ycbcr_forward",
    "ycbcr_inverse",
]

_ICT = np.array(
    [
        [0.299, 0.587, 0.114],
        [-0.168736, -0.331264, 0.5],
        [0.5, -0.418688, -0.081312],
    ]
)
_ICT_INVERSE = np.linalg.inv(_ICT)
#: The matrices that :func:`ycbcr_forward` and :func:`ycbcr_inverse` apply (for the codec's
#: fused passes).
YCBCR_MATRIX = np.ascontiguousarray(_ICT)
YCBCR_INVERSE_MATRIX = np.ascontiguousarray(_ICT_INVERSE)


#: A per-picture matrix's colour name starts with this; three integers follow: the angles
#: ``(a, b, c)`` of the rotation ``Rz(a) · Ry(b) · Rx(c)``, in units of ``pi / KLT_SCALE``.
KLT_PREFIX = "klt:"
KLT_SCALE = 4096
#: The angles' ranges: ``a`` and ``c`` in ``[-KLT_LIMIT, KLT_LIMIT]`` (a half turn either
#: way), ``b`` in half that (each fits two bytes of the binary header's varints).
KLT_LIMIT = KLT_SCALE
_CANONICAL_INTEGER = re.compile(r"0|-?[1-9][0-9]{0,3}")


def _rotation(a: float, b: float, c: float) -> np.ndarray:
    """``Rz(a) · Ry(b) · Rx(c)``: an orthonormal matrix (its inverse is its transpose)."""
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    return np.array(
        [
            [ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc],
            [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc],
            [-sb, cb * sc, cb * cc],
        ]
    )


def klt_name(matrix: np.ndarray) -> str:
    """The colour name of an orthonormal 3 × 3 forward ``matrix`` of determinant 1 (a
    rotation), its angles rounded to units of ``pi / KLT_SCALE``.

    Examples
    --------
    >>> import numpy as np
    >>> klt_name(np.eye(3))
    'klt:0,0,0'
    >>> quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    >>> klt_name(quarter)
    'klt:2048,0,0'
    """
    m = np.asarray(matrix, dtype=np.float64)
    b = float(np.arcsin(np.clip(-m[2, 0], -1.0, 1.0)))
    a = float(np.arctan2(m[1, 0], m[0, 0]))
    c = float(np.arctan2(m[2, 1], m[2, 2]))
    units = [int(np.clip(np.rint(v / np.pi * KLT_SCALE), -KLT_LIMIT, KLT_LIMIT)) for v in (a, b, c)]
    units = [0 if u == 0 else u for u in units]  # no "-0"
    return KLT_PREFIX + ",".join(map(str, units))


def klt_matrix(name: str) -> np.ndarray:
    """The forward matrix (a rotation) that a colour name of :func:`klt_name`'s form gives.

    Raises
    ------
    ValueError
        If ``name`` is not three integers after :data:`KLT_PREFIX`, in the canonical form
        :func:`klt_name` writes, with ``a`` and ``c`` of magnitude at most :data:`KLT_LIMIT`
        and ``b`` at most half that.

    Examples
    --------
    >>> np.round(klt_matrix("klt:2048,0,0"), 12).tolist() == [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    True
    """
    if not isinstance(name, str) or not name.startswith(KLT_PREFIX):
        msg = f"a colour matrix's name starts with {KLT_PREFIX!r}"
        raise ValueError(msg)
    parts = name[len(KLT_PREFIX) :].split(",")
    if len(parts) != 3 or not all(_CANONICAL_INTEGER.fullmatch(p) for p in parts):
        msg = f"a colour matrix is three integers after {KLT_PREFIX!r} (as -12, not +12 or 012)"
        raise ValueError(msg)
    a, b, c = (int(p) for p in parts)
    if max(abs(a), abs(c)) > KLT_LIMIT or abs(b) > KLT_LIMIT // 2:
        msg = f"a colour matrix's angles are at most {KLT_LIMIT} (b: {KLT_LIMIT // 2}) in magnitude"
        raise ValueError(msg)
    return _rotation(*(np.pi * v / KLT_SCALE for v in (a, b, c)))


def _check(data: np.ndarray) -> None:
    if data.ndim < 1 or data.shape[-1] < 3:
        msg = f"a colour transform needs at least 3 channels on the last axis, not {data.shape}"
        raise InvalidParameter(msg)


def ycbcr_forward(rgb: np.ndarray) -> np.ndarray:
    """RGB to YCbCr (float64; chroma centred on 0, so no offset is needed).

    Examples
    --------
    >>> import numpy as np
    >>> ycc = ycbcr_forward(np.array([[255.0, 255.0, 255.0]]))
    >>> np.round(ycc, 6).tolist()
    [[255.0, 0.0, 0.0]]
    """
    data = np.asarray(rgb, dtype=np.float64)
    _check(data)
    out = data.copy()
    out[..., :3] = data[..., :3] @ _ICT.T
    return out


def ycbcr_inverse(ycc: np.ndarray) -> np.ndarray:
    """YCbCr back to RGB (float64), the exact inverse of :func:`ycbcr_forward`.

    Examples
    --------
    >>> import numpy as np
    >>> rgb = np.random.default_rng(0).random((4, 4, 3))
    >>> bool(np.allclose(ycbcr_inverse(ycbcr_forward(rgb)), rgb))
    True
    """
    data = np.asarray(ycc, dtype=np.float64)
    _check(data)
    out = data.copy()
    out[..., :3] = data[..., :3] @ _ICT_INVERSE.T
    return out


def rct_forward(rgb: np.ndarray) -> np.ndarray:
    """The reversible colour transform: integers to ``int64`` ``(Y, Cb, Cr, alpha...)``.

    ``Y = floor((R + 2G + B) / 4)``, ``Cb = B - G``, ``Cr = R - G``.

    Examples
    --------
    >>> import numpy as np
    >>> rgb = np.random.default_rng(0).integers(0, 65536, (5, 5, 4))
    >>> bool(np.array_equal(rct_inverse(rct_forward(rgb)), rgb))
    True
    """
    data = np.asarray(rgb)
    _check(data)
    if data.dtype.kind not in "iu":
        msg = f"the reversible colour transform needs integers, not {data.dtype}"
        raise InvalidParameter(msg)
    data = data.astype(np.int64)
    r, g, b = data[..., 0], data[..., 1], data[..., 2]
    out = data.copy()
    out[..., 0] = (r + 2 * g + b) >> 2
    out[..., 1] = b - g
    out[..., 2] = r - g
    return out


def rct_inverse(ycc: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rct_forward` (``int64``)."""
    data = np.asarray(ycc).astype(np.int64)
    _check(data)
    y, cb, cr = data[..., 0], data[..., 1], data[..., 2]
    out = data.copy()
    g = y - ((cb + cr) >> 2)
    out[..., 0] = cr + g
    out[..., 1] = g
    out[..., 2] = cb + g
    return out
