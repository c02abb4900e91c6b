"""The lossless pipeline: the reversible colour transform, the integer lifting of
:mod:`wavecore.lossless` (its filters and depth chosen by what codes smallest) and the context
coder (``effort="fast"``) or, by default, the lossless coder (:mod:`wavecore.losslesscoder`),
written as a bundle whose header names the ``reversible`` transform and the ``none`` quantizer.

:func:`wavecore.codec.encode.encode_image` checks the arguments and hands ``lossless=True``
encodes here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import lossless as _lossless
from ..bundle import write_bundle
from ..entropy import encode_levels
from ..errors import InvalidParameter
from ..losslesscoder import WORK_PER_VALUE, encode_lossless_levels
from ..multilevel import default_level
from ..transform import run_rows
from .plan import DEFAULT_CODER, MAX_IMAGE_LEVELS, Plan, codes_two_d, dtype_name
from .samples import peak_of
from .stages import LOSSLESS_WAVELET, NoQuantizer, get_coder, get_colour


def encode_lossless_image(arr: np.ndarray, level: int | None, effort: str = "default") -> bytes:
    """A lossless bundle of an integer image (arguments already checked by ``encode_image``).

    Parameters
    ----------
    arr : numpy.ndarray
        The image, ``(h, w)`` or ``(h, w, c)``, ``uint8`` or ``uint16``.
    level : int or None
        Levels of integer lifting; ``None`` picks the depth that codes smallest.
    effort : {"default", "max", "fast"}
        ``"default"`` and ``"max"`` code with the lossless coder; ``"fast"`` with the block
        coder, a few per cent bigger in less time.

    Returns
    -------
    bytes
        The bundle, which :func:`wavecore.decode` gives back bit-exactly.
    """
    dtype = dtype_name(arr, "image", integer_only=True)
    colour = _lossless.lossless_colour(arr)  # RCT, with Cr predicted from Cb where that pays
    data = get_colour({"id": colour}).forward(arr).astype(np.int64, copy=False)
    # At most as many levels as leave every subband non-empty (5/3 fits any size unpadded).
    deepest = min(arr.shape[:2]).bit_length() - 1
    if effort != "fast":
        return _encode_with_lossless_coder(arr, data, dtype, colour, level, deepest)
    search = level is None
    if level is None:  # the depths of LOSSLESS_DEPTHS that fit, tried by _coded_by_depth
        level = min(default_level(arr.shape[:2], MAX_IMAGE_LEVELS), deepest)
        level = min(level, max(_lossless.LOSSLESS_DEPTHS))
    elif level > deepest:
        msg = (
            f"level {level} is too deep for a lossless {arr.shape[0]}×{arr.shape[1]} image: "
            f"at most {deepest} levels leave every subband non-empty"
        )
        raise InvalidParameter(msg)
    # First-order entropy only guides the choice of filters (the context coder ranks them
    # differently), so code the choice with and without the closed bspline2 and keep the smaller.
    # The choice lifts every level of each choice: kept, they are not lifted again to be coded
    # (a level two choices share is taken by the first, and lifted again for the second).
    lifted: _lossless.Lifted = {}
    choices = _lossless.filter_choices(data, level, lifted=lifted)
    bundles = [
        _coded_by_depth(arr, data, dtype, colour, level, lifting, search=search, lifted=lifted)
        for lifting in choices
    ]
    return min(bundles, key=len)


def _encode_with_lossless_coder(
    arr: np.ndarray, data: np.ndarray, dtype: str, colour: str, level: int | None, deepest: int
) -> bytes:
    """The default: the lossless coder (:mod:`wavecore.losslesscoder`), a few per cent smaller
    than the block coder of ``effort="fast"`` at about 1.4× its encode + decode CPU time."""
    if level is None:  # none (prediction) or one level, by entropy, or close calls by coding
        lifting = _lossless.choose_depth(data, confirm=_one_level_codes_smaller)
    elif level > deepest:
        msg = (
            f"level {level} is too deep for a lossless {arr.shape[0]}×{arr.shape[1]} image: "
            f"at most {deepest} levels leave every subband non-empty"
        )
        raise InvalidParameter(msg)
    else:
        lifting = _lossless.choose_filters(data, level, candidates=_lossless.CANDIDATE_SETS[0])
    level = len(lifting)
    # The lossless coder (wavecore.losslesscoder: the context coder's version 5).
    chunks, cparams = encode_lossless_levels(_lossless.forward(data, level, (0, 1), lifting))
    return _lossless_bundle(arr, dtype, colour, level, lifting, cparams, chunks)


def _one_level_codes_smaller(sample: np.ndarray, filters: list[str]) -> bool:
    """Whether the lossless coder codes ``sample`` lifted one level by ``filters`` in fewer
    bytes than the sample itself (``choose_depth``'s close calls)."""
    sizes = [0, 0]
    choices: list[list[str]] = [[], filters]

    def code(lo: int, hi: int) -> None:
        for slot in range(lo, hi):
            lifting = choices[slot]
            coeffs = _lossless.forward(sample, len(lifting), (0, 1), lifting)
            sizes[slot] = sum(map(len, encode_lossless_levels(coeffs)[0]))

    # The two codings side by side (a sample's level is often a single stripe, one thread);
    # a small sample's on this thread (no pool started, say in the service's fork server).
    run_rows(code, 2, WORK_PER_VALUE * sample.size, pieces=2)
    return sizes[1] < sizes[0]


def _coded_by_depth(
    arr: np.ndarray,
    data: np.ndarray,
    dtype: str,
    colour: str,
    level: int,
    lifting: list[str],
    search: bool = False,
    lifted: _lossless.Lifted | None = None,
) -> bytes:
    """The bundle of ``data`` lifted with ``lifting`` by the context coder, at the depth (of
    ``LOSSLESS_DEPTHS`` up to ``level`` when ``search``) that codes smallest; ``lifted``, the
    steps :func:`wavecore.lossless.filter_choices` kept."""
    coder = get_coder({"id": DEFAULT_CODER})
    coded: list[dict[str, Any]] = []

    def code(coeffs: list[Any]) -> list[bytes]:
        # Context coder version 4: each chunk is coded independently of the others, which
        # best_depth's re-coding of the coarse chunks alone needs (version 6 reads the
        # parent chunk).  As 1-D, a 1 × N picture of no levels was a hundred times slower to
        # code (1 × 262,144: 2 s) and bigger on real pictures (benchmarks/no_levels.py).
        two_d = codes_two_d(len(coeffs) - 1, arr.shape[1])
        chunks, params = encode_levels(coeffs, coder=coder.codec_id, version=4, two_d=two_d)
        coded.append(params)
        return chunks

    # No level given: the depth that codes smallest (wavecore.lossless.LOSSLESS_DEPTHS).
    depths = tuple(d for d in _lossless.LOSSLESS_DEPTHS if d <= level) if search else ()
    level, chunks = _lossless.best_depth(data, lifting, code, depths or (level,), lifted=lifted)
    lifting = lifting[:level]
    return _lossless_bundle(arr, dtype, colour, level, lifting, coded[0], chunks)


def _lossless_bundle(
    arr: np.ndarray,
    dtype: str,
    colour: str,
    level: int,
    lifting: list[str],
    cparams: dict[str, Any],
    chunks: list[bytes],
) -> bytes:
    """The bundle of coded ``chunks``: the plan of a reversible transform, no quantizer."""
    plan = Plan(
        "image",
        arr.shape,
        dtype,
        LOSSLESS_WAVELET,
        ("symmetric", "symmetric"),
        level,
        colour,
        ((0, 0), (0, 0)),
        arr.shape,
        peak_of(arr, dtype, "image"),
        tuple(lifting),
    )
    header = plan.header()
    header.update(
        quantizer=NoQuantizer.codec_id,
        qparams={},
        coder=str(cparams.get("coder", DEFAULT_CODER)),
        cparams=cparams,
        psnr=None,
        max_error=0.0,
    )
    return write_bundle(header, chunks)
