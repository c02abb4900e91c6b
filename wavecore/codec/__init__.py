"""The codec: the one package that composes the coding stages into bundles, and back.

``encode_image`` / ``encode_curve`` / ``encode_surface`` run

    front end (shape, dtype, colour, size fitting) → transform → threshold (``keep``) →
    quantize → entropy code → bundle,

and :func:`decode` runs the same path backwards, as far as the requested resolution level needs.

Contract notes for the owners of ``quantize.py`` and ``entropy.py`` (read by them):

* ``dequantize_bands`` is called with a *prefix* of the layout, ``[cA, level L, ..., level k+1]``,
  when ``decode(..., level=k)`` asks for a coarse image, so ``params`` must describe the bands
  from the coarse end (per-level lists indexed from ``cA``), and nothing may be recomputed from
  the shape of the finest band that is handed in.
* ``decode_levels`` is likewise given only the first ``L - k + 1`` chunks and shapes.
* Everything in ``params`` must survive a JSON round trip (it is stored in the bundle header),
  and the decoder side must treat it as untrusted: a crafted header can hold any JSON there.
  As a last line of defence :func:`decode` turns any exception other than ``BundleError`` that
  escapes the decoding stages into a ``BundleError``, but please raise ``BundleError`` yourself.
* The lossless path hands ``encode_levels`` the integer LeGall 5/3 / integer Haar coefficients
  (``int32``, magnitudes up to about 2**20 for 16-bit RGB) with no quantizer.
* ``bpp`` counts the whole bundle, header included, and ``params`` live in the header (stored
  deflated): a float with 17 significant digits costs about 10 bytes even deflated, so rounding
  steps to ~6 significant digits (and quantizing with the rounded value) buys bits at low rates.
* Golden bundles (``tests/golden``) are decoded in every test run: once they are committed, a
  coder or quantizer whose old bitstreams/params no longer decode the same needs a new name (or
  a version key in ``params``), never a silent change behind the old one.

The package, one module per concern:

* :mod:`.plan`: the caller's arguments checked, and the plan (what a bundle's header records
  about how the data was transformed): sizes and levels, header dict <-> plan;
* :mod:`.stages`: the stage registry (transforms ``wavelet``/``reversible``, quantizers
  ``deadzone``/``none``, coders ``context``/``zlib``, colours ``none``/``ycbcr``/``rct``), each
  with a ``codec_id`` and ``get_config``/``from_config``, and the one map from header fields to
  stage configs (:func:`~.stages.pipeline`) that decoding dispatches through;
* :mod:`.samples`: the sample domain: colour, dtype, scaling of huge or tiny floats, the
  transform both ways, and the error metrics (PSNR, largest error);
* :mod:`.ratecontrol`: the searches for a step that meets ``quality``, ``bpp`` or
  ``tolerance``;
* :mod:`.encode`: the front ends ``encode_image``/``encode_curve``/``encode_surface``;
* :mod:`.reversible`: the lossless pipeline (reversible colour, integer lifting, its coders);
* :mod:`.replication`: pictures enlarged by pixel replication, coded as their source inside
  a 7-byte wrapper (format 7.0), and enlarged again when decoded;
* :mod:`.fixedstep`: a surface coded at one given step, what the grid containers build on;
* :mod:`.decode`: ``decode`` (the pipeline backwards, through the registry) and ``inspect``;
* :mod:`.chunks`: the coded chunks read for decoding, whole or block by block, checked, only
  the blocks a region needs, damaged blocks zeroed;
* :mod:`.extents`: what a decode at a level returns (shape, offsets) and a region checked
  against it.

The coefficient layout lives in :mod:`wavecore.layout`, the default level in
:func:`wavecore.default_level`.
"""

from __future__ import annotations

from .decode import decode, decode_region, inspect
from .encode import DEFAULT_RELATIVE_TOLERANCE as DEFAULT_RELATIVE_TOLERANCE
from .encode import encode_curve, encode_image, encode_surface
from .plan import DEFAULT_CODER as DEFAULT_CODER
from .ratecontrol import DEFAULT_QUALITY as DEFAULT_QUALITY
from .ratecontrol import KEEP_RELATIVE_STEP as KEEP_RELATIVE_STEP

# The three compiled passes tests/test_colour.py checks, under the names it imports.
from .samples import cast as _cast  # noqa: F401
from .samples import to_integers as _to_integers  # noqa: F401
from .samples import ycbcr_from as _ycbcr_from  # noqa: F401
from .stages import LOSSLESS_WAVELET as LOSSLESS_WAVELET

__all__ = ["decode", "decode_region", "encode_curve", "encode_image", "encode_surface", "inspect"]
