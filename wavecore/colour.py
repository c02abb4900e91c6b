"""Luma/chroma transforms applied before the wavelet transform, as JPEG 2000 does.

- :func:`ycbcr_forward` / :func:`ycbcr_inverse`: the irreversible colour transform (ICT, the
  ITU-R BT.601 YCbCr matrix) for lossy coding.  Most of an RGB image's detail is in luma, so
  decorrelating the channels lets the quantizer spend bits where the eye and PSNR want them.
- :func:`rct_forward` / :func:`rct_inverse`: the reversible colour transform (RCT) for lossless
  coding, integer in and integer out, exactly invertible.

Both act on the last axis (``(..., C)`` with ``C >= 3``); channels after the third (alpha) pass
through unchanged.
"""

from __future__ import annotations

import numpy as np

from .errors import InvalidParameter

__all__ = ["rct_forward", "rct_inverse", "ycbcr_forward", "ycbcr_inverse"]

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
