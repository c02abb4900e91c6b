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
from test_bundle_fuzz import assemble2  # a 3.0 bundle around a header's bytes

import wavecore
from wavecore import binheader
from wavecore.bundle import read_bundle

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
# before the opt-in ``effort="max"`` coder existed) wrote for the pictures below, in format 3.0:
# the block coder's path (the default until 2026-12-07, now ``effort="fast"``) must keep writing
# these very chunks (since 2026-11-28 in 3.1, whose head
# stores no chunk lengths: the test puts the same header and chunks back into 3.0's head).
INTEGRATE_DEFAULT = {
    "u16": (6288, "c030bcf48f1e9149b134b64a4c6bf7bceb1d082be053fe3ba51880b1d3838097"),
    "camera_level1": (124672, "8fb046b22fe3ca74acdb49bd34d4eba97cfaac9f2d4e50d8c6d3cbd1b5ac9d6b"),
}


def _u16_picture() -> np.ndarray:
    i, j = np.mgrid[0:60, 0:50]
    return ((i * j * 37 + (i * 7919 + j * 104729) % 251) * 13 % 65536).astype(np.uint16)


def test_fast_lossless_bundles_are_integrates_bytes() -> None:
    import hashlib

    from skimage import data

    bundles = {
        "u16": wavecore.encode_image(_u16_picture(), lossless=True, effort="fast"),
        "camera_level1": wavecore.encode_image(
            data.camera(), lossless=True, level=1, effort="fast"
        ),
    }
    for name, bundle in bundles.items():
        parsed = read_bundle(bundle)
        assert parsed.version == (3, 1)
        chunks = [bytes(chunk or b"") for chunk in parsed.chunks]  # as stored, checks included
        three = assemble2(binheader.pack(parsed.header), chunks, (3, 0))
        assert (len(three), hashlib.sha256(three).hexdigest()) == INTEGRATE_DEFAULT[name], name
    # and the frozen colour bundle above (3.0) was written by that default path at level 2
    again = read_bundle(
        wavecore.encode_image(_colour_image(), lossless=True, level=2, effort="fast")
    )
    frozen = read_bundle(COLOUR_BUNDLE)
    assert again.header == frozen.header
    assert [bytes(c or b"") for c in again.chunks] == [bytes(c or b"") for c in frozen.chunks]


# Bundles of the lossless coder (the default since 2026-12-07, before it ``effort="max"``; the
# context coder's version 5), frozen as commit 791a382 wrote them: later work on its kernels
# (speed, a new version) must keep decoding them.  The grey one is the picture predicted
# without levels in two stripes (400 rows: the weighted predictor, the stripes' split); the
# colour one has two 5/3 levels (the details' parent, sibling and first-channel contexts).
MAX_GREY_BUNDLE = base64.b64decode(
    "iVdWQg0KGgoDAA4QMFQwAJADBgDoPxUACMIKk7FCTmiGoAWBhy+kN8BW60Bc226jOhpqUtZgbQT/DCJo5K70S7gU"
    "JJTMmdqdK3epDc63zcrdaFizZv6I/oqRMYoCbltlsIIoCxUMsuD8xHTVrlFeWzH+2ok68/+QT1I9BZ01AQkuGxYa"
    "uDWBAfduCWe9HWPYmr/Fd2cKT3U4DlrMuCNBSuKIKIUViRzQYF7+rp4wet1KToXDYfH00bnEEpTn16AeSu7ZqY3Y"
    "stYwjZUAW6R4rW6Ox12rdZpUJiWLG8MTOHHauKRXGxSwJ7Sbrv4YuHEdcu0qg8w4kok3xbiv4CxnHFBV1zV8q+wP"
    "mf8ngU4a1a00r+Pi2mrePwhU+aPrudJmCnhyD6wLhG2jRswN5UhVVQNtD5+subZPqQZEPeZvxLe9wRVcWJ1rasB/"
    "+QWljJwoiWHFHMsa77T+HS8KRYauIDefzHSjiWIs0V3PiWfDA9l2uYcJ4O9d7UuBI/B7mU8LuMVdNpqgHVTtAhkH"
    "J+cyD1jOcBEmbDtk1FsSmYGqi8amIj+6bg3u5YVlYtOd6/oJDlS3kRWNavxMrA/YXps0s7i/D1z0AKwXK3QV2KWk"
    "ZnnzdOJF0WmFcxdMD++NjITtYrQ575GS20PVmnP3PjB/vOm5SVBvA4JXzSkjKAhz4NEEemMiqMxc+ca5yf9riAC1"
    "E2Tp+q2ssl+BanTNNdSWfctAHCVMowLv7ekadqKhPMW8KgAD4A6OnN679NQZZQCfbs+g3McqKr6kvtdyKJpAsxFq"
    "4mGuwgrtO+q8WmWaRXfmRvBn1LHHLVnlJRt7i1pVIzMvytrCNZvl7XWZgEUfD4JI5BGiqA8B7EGqbISljplD5+1H"
    "s1OeNfP6+sOGXh23hW7v45MuP8OmNjof0UgqDMrgf5hRwBSqQ2KorlA3B7jSwRcBflcNamGaA/s+wwmwvxVrHzye"
    "V2lYBpbdB5iSpMGyw7zvUGYwOmux7VySHSx8laW/L4FibJH/l4uCJfa0aBDJdQXr0fSCYbkOfL+duzXlmDYSRLr/"
    "x4ZypeB+yU/OBXcw7HhBZCBIaVaGnbK1MQy2YASom8zd8rWPnytFEMinGxZBWO+WFrgT4eTW6n7Pa87+YEhkFLzo"
    "srUwVNsgV1jcJH9EMXmdZJNs2pmHqsjfiHv5PqOgY0KHKulYlYRO+S8K+b5WTBl5prvyk+9hx5JPBYAsXi1wMDW+"
    "ym5OhDF6S7akrrYU3bS82LRk3rDj/TdbXfoGU09IrjO4jnjV2bWKUPHAYhiUI/NNigx88lTyDN6iPr2PVtLCeKU5"
    "lqyFXU8ws1hZcMPclDWxLuUA8XWMPDKSTcEJA0RcC1B8VxD1YO541M/GizRdSD6TiQPc49e+/i60+bn02CUUeoEY"
    "I+Y+cCPxh5gGf4IwuDVboMVqRJKQAQfLjh25ck2jIh3ZSCWXtdLEQ6k2zZ/FEIDJwWaFwNo8qRGZkO+ojzUpK1s0"
    "OoLBY3lvWyLwML/jX3Rn0C5aB3Lpy4nVZxC0gdAUO6M5uA1M3195t60brhItr/O0f99NfwR14faT7gZ1mCZ5Z0O/"
    "rte2XVnXTHNELZildHKxG9JBgBAHYH3sQq3aVDeMFn243L7ZXAgsZeSCTTtLjCmrj5qAyRkXhNODRA2hYGkl7/tJ"
    "W2hTecddMifcMWQoXxZ2xegj4TgzxahRePv3w967aHIqiUNvh1PWKM0k/u/HJs1qj5q2R2sHJlnm8m8ohT3160Yn"
    "y4DlGG4LtFym0czQXmWhN5Ij1GZGx0Dm4VvLHGzV9oedzroxW0ZxqqjSPRpLQrdOhVJBUN3U/HLzzDo="
)
MAX_COLOUR_BUNDLE = base64.b64decode(
    "iVdWQg0KGgoDABAsMFQwAhgUAxACAOg/FQAITowB/wJOVhyszCSitsETAdMS8b5gRFv3B7lAOJb9nIRZqSdJ5RDm"
    "raUv9ZcGKgOaKdGuHmzcafiTraleQaihLhJu3WVEE0lG4hWKrxzMtxnNiIQlGMYpYhJ7Jpq1mOwgFr7KbC733y+b"
    "8CYuDmxHc7UxW9/BtKs4+H/C1boVYxIgMiefHZsDEuewyw0RpCDt9btNKJyxvqXx3z0t+TmNxPrYrm5y/LyqyZAj"
    "Xx+rSyt9zKq0Z/4N3sM9RbH/bRiUQCGJJ0//4jnKVMmHbjznLbqw/9spUUpfCZVGCA140Szr04JwZnyHa+FRuR73"
    "LtXk4n2BZGw8Bdm7wq3+TuADcx82n66RRGr0vLCgC3VmgH7U5iwwF49PIB+VL/toteyU/iFDv2vtwhKI4db10Vdq"
    "5OzsTb7Kjphq9gJu4JLg4szW1ePK3bhNqOelLmvFcIue2LpXEVs/B2YTSahl8l+Mr2iWNFAbIcRWHvht8G2BB38n"
    "DDT7PgxksRnj8GqTpp69i97no3Eq5ij4y1iAAuzaa6Jf7O0e+WBa5THpeTrr8W3tG64TsXAq5BE5DtEm0dyIS7rf"
    "yjXn6QG27oavPNPb215bojzRjbmYFsa6oHafDPhG9Vcnljh9vFIzu1gL2YjQeLjMkGqHeraPR55UsEYXKsmxi1Vh"
    "1VcLvNlDW29O/oAd3Ev5feVyPLsOF1LJCD7MQ7AnCRlrpd4tm1INiTdtd8NK8wzzo/quQotKyiHfeqbyy1aMnA9W"
    "pG6k09XK9Ug1YTyuShH1jpTyEkrxUKqs3gwV5GVmrKFPdcraae7npEqzXCrbUFeHAA=="
)


def _max_grey_image() -> np.ndarray:
    i, j = np.mgrid[0:400, 0:6]
    return ((i * 3 + j * 17 + (i * j) % 7 + (i * 7919 + j * 104729) % 11) % 256).astype(np.uint8)


def _max_colour_image() -> np.ndarray:
    i, j = np.mgrid[0:24, 0:20]
    green = 80 + (i * j * (24 - i)) // 9 + (i * 7 + j * 3) % 5
    chroma = (j * (20 - j) * 2 + i * i) // 5 - 15 + (i * 5 + j) % 3
    rgb = np.stack([green + chroma, green, green + chroma // 2], -1)
    return np.clip(rgb, 0, 255).astype(np.uint8)


def test_frozen_lossless_coder_bundles_decode_exactly() -> None:
    grey, colour = wavecore.inspect(MAX_GREY_BUNDLE), wavecore.inspect(MAX_COLOUR_BUNDLE)
    assert grey["header"]["levels"] == 0 and colour["header"]["levels"] == 2
    for info in (grey, colour):
        assert info["header"]["cparams"]["version"] == 5
    assert np.array_equal(wavecore.decode(MAX_GREY_BUNDLE), _max_grey_image())
    assert np.array_equal(wavecore.decode(MAX_COLOUR_BUNDLE), _max_colour_image())
