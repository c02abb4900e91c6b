"""Frozen lossless bundles: the 5/11-C lifting at both levels, and the RCT with chroma
prediction (colour ``rct-p7``).

The bytes below were written once by this branch's encoder from the integer images of
:func:`_image` (its lossless pipeline with the lifting forced to ``["511c", "511c"]``) and
:func:`_colour_image` (``encode_image(..., lossless=True, level=2)``).  Decoding them must give
those images back exactly, in every later version: a change to the 5/11-C formulas or their
boundary handling, to the chroma prediction, or to the header's lifting code 3 or colour code 3
would break it.
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


COLOUR_BUNDLE = base64.b64decode(
    "iVdWQg0KGgoDABAsMFQwAg4LAw4CAOg/lAAIHy523J92zbxca8fzbh7/ywqUWM8ZkUgk01Mrw50FpNnLbKJSQ2aa"
    "mhd+wCQt9jaxfCFDV8cDpsSLT9/RTKUS5zppZNvb44qQvIdqN1gL6CqnX0H2D4r7so82df1lGBDiEzFRMCSpnvCu"
    "kd7akjjn2cbHR8TbkjC/+0/dUBmhw/GJOaZlHEJnX0H+nhPPzw4d2OlZxuaN/71YZFh4DBX2iehT/uJA7lHXg9z6"
    "lyo6xflozp8urpzK7YSegqu5eiCRA5dVQA6i8gUJ9agwGMf+oQ=="
)


def _colour_image() -> np.ndarray:
    """RGB whose red and blue differences from green move together (14 × 11)."""
    i, j = np.mgrid[0:14, 0:11]
    green = 90 + (i * j * (14 - i)) // 6 + (i * 7 + j * 3) % 4
    chroma = (j * (11 - j) * 3 + i * i) // 4 - 20 + (i * 5 + j) % 3
    rgb = np.stack([green + chroma, green, green + chroma // 2], -1)
    return np.clip(rgb, 0, 255).astype(np.uint8)


def test_frozen_predicted_colour_bundle_decodes_exactly() -> None:
    assert wavecore.inspect(COLOUR_BUNDLE)["colour"] == "rct-p7"
    image = _colour_image()
    assert np.array_equal(wavecore.decode(COLOUR_BUNDLE), image)
    region = wavecore.decode_region(COLOUR_BUNDLE, (slice(3, 9), slice(4, 11)))
    assert np.array_equal(region, image[3:9, 4:11])


# sha256 and length of the default lossless bundles that branch ``integrate`` (commit 40c0b01,
# before the opt-in ``effort="max"`` coder existed) wrote for the pictures below: the default
# path must keep writing these very bytes.
INTEGRATE_DEFAULT = {
    "u16": (6288, "c030bcf48f1e9149b134b64a4c6bf7bceb1d082be053fe3ba51880b1d3838097"),
    "camera_level1": (124672, "8fb046b22fe3ca74acdb49bd34d4eba97cfaac9f2d4e50d8c6d3cbd1b5ac9d6b"),
}


def _u16_picture() -> np.ndarray:
    i, j = np.mgrid[0:60, 0:50]
    return ((i * j * 37 + (i * 7919 + j * 104729) % 251) * 13 % 65536).astype(np.uint16)


def test_default_lossless_bundles_are_integrates_bytes() -> None:
    import hashlib

    from skimage import data

    bundles = {
        "u16": wavecore.encode_image(_u16_picture(), lossless=True),
        "camera_level1": wavecore.encode_image(data.camera(), lossless=True, level=1),
    }
    for name, bundle in bundles.items():
        assert (len(bundle), hashlib.sha256(bundle).hexdigest()) == INTEGRATE_DEFAULT[name], name
    # and the frozen colour bundle above was written by that default path at level 2
    assert wavecore.encode_image(_colour_image(), lossless=True, level=2) == COLOUR_BUNDLE
