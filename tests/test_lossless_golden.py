"""A frozen lossless bundle whose header names the 5/11-C lifting at both levels.

The bytes below were written once by this branch's encoder (its lossless pipeline with the
lifting forced to ``["511c", "511c"]``) from the integer image of :func:`_image`.  Decoding
them must give that image back exactly, in every later version: a change to the 5/11-C
formulas, their boundary handling, or the header's lifting code 3 would break it.
"""

from __future__ import annotations

import base64

import numpy as np

import wavecore

BUNDLE = base64.b64decode(
    "iVdWQg0KGgoDAA4QMFQwAhcTAg/oP5QACBo9gwGCuiYKQnGIMTOFGfwVmwPvVUhX9uONhh33U2WEBJlVYkrO5oI8"
    "91EK7n9qjc9VI2imfRxSEUoGQ3q6L6LkUIuMe/t7w0gdR40092vSmuHVGuCADolSMf6bthY1GE3ibtcrgQH/g4gq"
    "Xfr9z6Py8A/HfbX2Xak1Sbiu6MfBEGfXk6k+Yk3rGnmPGMnLyytch2gXFvQun2PXbQwefynJQY4aIOUGbH9QtN4S"
    "JWXhMe2ngLpBjiV89k9itV/5PC7ok6IE+o0Ut8rQRR0TV/3pORYYgxh4TJ+R+ZCF+7/eXmScWE9jDwE="
)


def _image() -> np.ndarray:
    """A smooth bump with a little integer texture, odd sizes (23 × 19) on both axes."""
    i, j = np.mgrid[0:23, 0:19]
    return ((i * j * (23 - i) * (19 - j)) // 120 + (i * 7919 + j * 104729) % 5).astype(np.uint8)


def test_frozen_5_11_c_bundle_decodes_exactly() -> None:
    assert wavecore.inspect(BUNDLE)["header"]["lifting"] == ["511c", "511c"]
    assert np.array_equal(wavecore.decode(BUNDLE), _image())


def test_frozen_5_11_c_bundle_decodes_by_region_and_level() -> None:
    image = _image()
    region = wavecore.decode_region(BUNDLE, (slice(5, 17), slice(2, 11)))
    assert np.array_equal(region, image[5:17, 2:11])
    # The coarse level is the 5/3 low-pass (5/11-C shares it): its size is ceil(n / 2).
    assert wavecore.decode(BUNDLE, level=1).shape == (12, 10)
