"""Luma/chroma transforms applied before the wavelet transform, as JPEG 2000 does.

- :func:`ycbcr_forward` / :func:`ycbcr_inverse`: the irreversible colour transform (ICT, the
  ITU-R BT.601 YCbCr matrix) for lossy coding.  Most of an RGB image's detail is in luma, so
  decorrelating the channels lets the quantizer spend bits where the eye and PSNR want them.
- :func:`rct_forward` / :func:`rct_inverse`: the reversible colour transform (RCT) for lossless
  coding, integer in and integer out, exactly invertible.
- :func:`klt_name` / :func:`klt_matrix`: a per-picture 3 × 3 matrix for lossy coding (the
  Karhunen–Loève transform of the picture's colour details, chosen by
  :func:`wavecore.codec.choice.choose_colour`), named ``"klt:<nine integers>"``: the matrix
  in units of ``1 / KLT_SCALE``, row by row, which is all a decoder needs.

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


#: A per-picture matrix's colour name starts with this; nine integers follow.
KLT_PREFIX = "klt:"
#: Its entries are integers in units of ``1 / KLT_SCALE`` …
KLT_SCALE = 4096
#: … of magnitude at most this (each one fits two bytes of the binary header's varints).
KLT_LIMIT = 8191
_CANONICAL_INTEGER = re.compile(r"0|-?[1-9][0-9]{0,3}")
#: A matrix's smallest singular value over its largest must be at least this: the decoder's
#: inverse then amplifies an error by at most a thousandfold.
_KLT_MIN_CONDITION = 1e-3


def klt_name(matrix: np.ndarray) -> str:
    """The colour name of a 3 × 3 forward ``matrix``, rounded to units of ``1 / KLT_SCALE``.

    Examples
    --------
    >>> import numpy as np
    >>> klt_name(np.eye(3))
    'klt:4096,0,0,0,4096,0,0,0,4096'
    """
    units = np.rint(np.asarray(matrix, dtype=np.float64).reshape(9) * KLT_SCALE).astype(int)
    return KLT_PREFIX + ",".join(str(int(u)) for u in units)


def klt_matrix(name: str) -> np.ndarray:
    """The forward matrix that a colour name of :func:`klt_name`'s form gives.

    Raises
    ------
    ValueError
        If ``name`` is not nine integers of at most :data:`KLT_LIMIT` after
        :data:`KLT_PREFIX`, in the canonical form :func:`klt_name` writes, or they make a
        matrix too close to singular to invert safely.

    Examples
    --------
    >>> klt_matrix("klt:4096,0,0,0,2048,0,0,0,-4096").diagonal().tolist()
    [1.0, 0.5, -1.0]
    """
    if not isinstance(name, str) or not name.startswith(KLT_PREFIX):
        msg = f"a colour matrix's name starts with {KLT_PREFIX!r}"
        raise ValueError(msg)
    parts = name[len(KLT_PREFIX) :].split(",")
    if len(parts) != 9 or not all(_CANONICAL_INTEGER.fullmatch(p) for p in parts):
        msg = f"a colour matrix is nine integers after {KLT_PREFIX!r} (as -12, not +12 or 012)"
        raise ValueError(msg)
    units = [int(p) for p in parts]
    if any(abs(u) > KLT_LIMIT for u in units):
        msg = f"a colour matrix's integers are at most {KLT_LIMIT} in magnitude"
        raise ValueError(msg)
    matrix = np.array(units, dtype=np.float64).reshape(3, 3) / KLT_SCALE
    singular = np.linalg.svd(matrix, compute_uv=False)
    if not singular[-1] >= _KLT_MIN_CONDITION * singular[0]:
        msg = "a colour matrix must be invertible (its condition number is at most 1000)"
        raise ValueError(msg)
    return matrix


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
