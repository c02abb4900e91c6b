"""The stage registry: each coding stage is a small class found by its id.

After numcodecs' ``Codec`` and registry (``numcodecs/abc.py``, ``numcodecs/registry.py``): a
stage has a ``codec_id``, ``get_config()`` (a JSON-ready dict holding ``"id"`` and the stage's
parameters) and ``from_config(config)``; :func:`get_stage` finds the class by the config's id,
so decoding dispatches through the registry instead of testing names.  Four kinds of stage:

* transforms: ``"wavelet"`` (the lossy filter banks, padded to a size that fits) and
  ``"reversible"`` (the integer lifting of lossless bundles: one pipeline among others);
* quantizers: ``"deadzone"`` and ``"none"`` (integers coded as they are);
* entropy coders: ``"context"`` and ``"zlib"`` (:mod:`wavecore.entropy`);
* colour transforms: ``"none"``, ``"ycbcr"`` and ``"rct"`` (:mod:`wavecore.colour`), and
  ``"rct-p<w>"``, the RCT with Cr predicted from Cb (lossless only, ``w`` in -8 … 8, not 0).

The bundle header (format 1.x) keeps its fields as they are; :func:`pipeline` is the one place
that maps them to stage configs.  A stage whose bitstream changes gets a new id, so that old
bundles keep decoding (tests/golden proves it).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np

from .. import lossless as _lossless
from ..colour import (
    KLT_PREFIX,
    YCBCR_INVERSE_MATRIX,
    klt_matrix,
    rct_forward,
    rct_inverse,
    ycbcr_forward,
    ycbcr_inverse,
)
from ..entropy import decode_levels, encode_levels
from ..errors import BundleError, InvalidLength, InvalidParameter
from ..filters import get_wavelet
from ..layout import band_shapes
from ..multilevel import wavedec, wavedec2, waverec, waverec2
from ..quantize import dequantize_bands
from ..resample import crop_padding
from ..threshold import remove_smallest

#: The header's ``wavelet`` for lossless bundles: the reversible transform's id.
LOSSLESS_WAVELET = "reversible"


class Stage:
    """A coding stage: an id, and a config that makes it again."""

    codec_id: ClassVar[str] = ""
    kind: ClassVar[str] = ""

    def get_config(self) -> dict[str, Any]:
        """The stage as a JSON-ready dict: ``{"id": codec_id, **parameters}``."""
        return {"id": self.codec_id}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> Stage:
        """The stage that :meth:`get_config` describes."""
        del config
        return cls()


_REGISTRY: dict[tuple[str, str], type[Stage]] = {}


def register_stage(cls: type[Stage]) -> type[Stage]:
    """Register a stage class under its kind and id (a decorator)."""
    _REGISTRY[cls.kind, cls.codec_id] = cls
    return cls


def registered_stages() -> list[tuple[str, str]]:
    """Every registered stage as ``(kind, codec_id)``, sorted."""
    return sorted(_REGISTRY)


def get_stage(kind: str, config: dict[str, Any]) -> Stage:
    """The stage of ``kind`` (``"transform"``, ``"quantizer"``, ``"coder"`` or ``"colour"``)
    that ``config`` describes.

    Raises
    ------
    BundleError
        If no stage of that kind has the config's id (a config comes from a bundle header).

    Examples
    --------
    >>> get_stage("coder", {"id": "zlib"}).get_config()
    {'coder': 'zlib', 'id': 'zlib'}
    """
    stage_id = config.get("id") if isinstance(config, dict) else None
    cls = _REGISTRY.get((kind, stage_id)) if isinstance(stage_id, str) else None
    if cls is None:
        known = sorted(i for k, i in _REGISTRY if k == kind)
        msg = f"unknown {kind} stage {str(stage_id)[:40]!r}; known ones are {known}"
        raise BundleError(msg)
    return cls.from_config(config)


# --------------------------------------------------------------------------------------------
# Transforms
# --------------------------------------------------------------------------------------------


class Geometry(Protocol):
    """What a stage needs to know of the plan (:class:`wavecore.codec.plan.Plan` has it)."""

    @property
    def kind(self) -> str: ...
    @property
    def levels(self) -> int: ...
    @property
    def axes(self) -> tuple[int, ...]: ...
    @property
    def pads(self) -> tuple[tuple[int, int], ...]: ...


class Transform(Stage):
    """A multilevel transform: coefficient shapes, the inverse, and ``keep`` before it."""

    kind = "transform"
    lossless: ClassVar[bool] = False

    def header_fields(self) -> dict[str, Any]:
        """Header keys beyond ``wavelet`` and ``boundary`` that this transform needs."""
        return {}

    def band_shapes(self, fitted: Sequence[int], levels: int, axes: Sequence[int]) -> list[Any]:
        raise NotImplementedError

    def forward(self, data: np.ndarray, levels: int) -> list[Any]:
        raise NotImplementedError

    def inverse(self, coeffs: list[Any], geometry: Geometry) -> np.ndarray:
        raise NotImplementedError

    def keep(self, coeffs: list[Any], keep: float, geometry: Geometry) -> list[Any]:
        raise NotImplementedError

    def crop(self, data: np.ndarray, geometry: Geometry, level: int) -> np.ndarray:
        raise NotImplementedError

    def check_header(self, header: dict[str, Any]) -> list[str]:
        """The header's rules for this transform; returns the ``lifting`` it keeps."""
        raise NotImplementedError


@register_stage
class WaveletTransform(Transform):
    """The lossy filter banks (``bspline2``, ``haar``, ``cdf97``), padded to a size that fits."""

    codec_id = "wavelet"

    def __init__(self, wavelet: str, boundary: Sequence[str]) -> None:
        self.wavelet = wavelet
        self.boundary = tuple(boundary)

    def get_config(self) -> dict[str, Any]:
        return {"id": self.codec_id, "wavelet": self.wavelet, "boundary": list(self.boundary)}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> WaveletTransform:
        return cls(config["wavelet"], config["boundary"])

    def band_shapes(self, fitted: Sequence[int], levels: int, axes: Sequence[int]) -> list[Any]:
        bank = get_wavelet(self.wavelet)
        rules = [bank.rule(b) for b in self.boundary]
        return band_shapes(
            fitted,
            levels,
            axes,
            lambda i, n: (rules[i].coarse_length(n), rules[i].detail_length(n)),
        )

    def forward(self, data: np.ndarray, levels: int) -> list[Any]:
        if len(self.boundary) == 1:
            return wavedec(data, self.wavelet, self.boundary[0], levels, axis=0)
        return wavedec2(data, self.wavelet, list(self.boundary), levels, axes=(0, 1))

    def inverse(self, coeffs: list[Any], geometry: Geometry | None = None) -> np.ndarray:
        if len(self.boundary) == 1:
            return waverec(coeffs, self.wavelet, self.boundary[0], axis=0)
        return waverec2(coeffs, self.wavelet, list(self.boundary), axes=(0, 1))

    def keep(self, coeffs: list[Any], keep: float, geometry: Geometry) -> list[Any]:
        return remove_smallest(
            coeffs,
            1.0 - keep,
            wavelet=self.wavelet,
            boundary=list(self.boundary),
            axes=geometry.axes,
            vector_axis=None if geometry.kind == "image" else -1,
        )

    def crop(self, data: np.ndarray, geometry: Geometry, level: int) -> np.ndarray:
        return crop_padding(
            data,
            geometry.pads,
            axes=geometry.axes,
            level=level,
            boundary=list(self.boundary),
            wavelet=self.wavelet,
        )

    def check_header(self, header: dict[str, Any]) -> list[str]:
        """The levels must fit the fitted lengths (raises ``BundleError``); no lifting."""
        fitted, levels = header["fitted"], header["levels"]
        try:
            bank = get_wavelet(self.wavelet)
            for axis, b in enumerate(self.boundary):
                if not bank.rule(b).fits(fitted[axis], levels):
                    msg = f"length {fitted[axis]} does not fit {levels} levels"
                    raise InvalidLength(msg)
        except InvalidParameter as exc:
            msg = f"header: wavelet {self.wavelet!r}, boundary {list(self.boundary)}, levels: {exc}"
            raise BundleError(msg) from exc
        return []  # the key means nothing for the other wavelets: ignored, as unknown keys are


@register_stage
class ReversibleTransform(Transform):
    """The integer lifting of lossless bundles: one reversible filter per level, finest first."""

    codec_id = LOSSLESS_WAVELET
    lossless = True

    def __init__(self, lifting: Sequence[str]) -> None:
        self.lifting = tuple(lifting)

    def get_config(self) -> dict[str, Any]:
        return {"id": self.codec_id, "lifting": list(self.lifting)}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> ReversibleTransform:
        lifting = config.get("lifting")  # checked by check_header when it comes from a header
        return cls(lifting if isinstance(lifting, list | tuple) else [])

    def header_fields(self) -> dict[str, Any]:
        return {"lifting": list(self.lifting)}

    def band_shapes(self, fitted: Sequence[int], levels: int, axes: Sequence[int]) -> list[Any]:
        return _lossless.band_shapes(fitted, levels, axes)

    def forward(self, data: np.ndarray, levels: int) -> list[Any]:
        return _lossless.forward(data, levels, (0, 1), list(self.lifting))

    def inverse(self, coeffs: list[Any], geometry: Geometry) -> np.ndarray:
        return _lossless.inverse(coeffs, geometry.axes, self.lifting)

    def keep(self, coeffs: list[Any], keep: float, geometry: Geometry) -> list[Any]:
        """Drop the smallest integer details (then :meth:`inverse` is still exact)."""
        kept = remove_smallest(
            [np.asarray(coeffs[0], dtype=np.float64), *coeffs[1:]],
            1.0 - keep,
            wavelet="haar",  # 5/3 norms are not tabulated; rank by plain magnitude instead
            weighted=False,
            axes=geometry.axes,
            vector_axis=None,
        )
        ints: list[Any] = [np.asarray(coeffs[0])]
        for bands in kept[1:]:
            ints.append(tuple(np.asarray(b).astype(np.int64) for b in bands))
        return ints

    def crop(self, data: np.ndarray, geometry: Geometry, level: int) -> np.ndarray:
        return data  # the lifting fits every size; nothing was padded

    def check_header(self, header: dict[str, Any]) -> list[str]:
        """The lossless header's own rules; returns its ``lifting`` (raises ``BundleError``)."""
        kind, colour, boundary = header["kind"], header["colour"], header["boundary"]
        pads, levels, fitted = header["pads"], header["levels"], header["fitted"]
        lossy_colour = colour == "ycbcr" or str(colour).startswith(KLT_PREFIX)
        if kind != "image" or lossy_colour or header["dtype"] not in ("uint8", "uint16"):
            msg = "header: the lossless wavelet is only for uint8/uint16 images"
            raise BundleError(msg)
        if any(b != "symmetric" for b in boundary):
            msg = f"header field 'boundary' must be symmetric for lossless, not {list(boundary)}"
            raise BundleError(msg)
        if any(before or after for before, after in pads):
            msg = "header: a lossless bundle is never padded"
            raise BundleError(msg)
        lifting = header.get("lifting")
        if (
            not isinstance(lifting, list)
            or len(lifting) != levels
            or any(name not in _lossless.FILTERS for name in lifting)
        ):
            msg = (
                f"header field 'lifting' must list one of {list(_lossless.FILTERS)} per level "
                f"({levels}), not {str(lifting)[:80]}"
            )
            raise BundleError(msg)
        sizes = list(fitted[:2])
        for index, name in enumerate(lifting):
            if name == "bspline2" and any(n % 2 for n in sizes):
                msg = (
                    f"header field 'lifting': level {index + 1} has odd sizes {sizes} for bspline2"
                )
                raise BundleError(msg)
            sizes = [(n + 1) // 2 for n in sizes]
        return list(lifting)


def transform_config(
    wavelet: str, boundary: Sequence[str], lifting: Sequence[str] | None
) -> dict[str, Any]:
    """The header's ``wavelet``, ``boundary`` and ``lifting`` fields as a transform config.

    The header names the transform by its ``wavelet`` field: ``"reversible"`` is the lossless
    lifting, and any other value a filter bank's name (the header format keeps its fields).
    """
    if wavelet == ReversibleTransform.codec_id:
        return {"id": ReversibleTransform.codec_id, "lifting": lifting}
    return {"id": WaveletTransform.codec_id, "wavelet": wavelet, "boundary": list(boundary)}


def transform_of(wavelet: str, boundary: Sequence[str], lifting: Sequence[str]) -> Transform:
    """The transform stage of a plan's fields."""
    return get_transform(transform_config(wavelet, boundary, list(lifting)))


# --------------------------------------------------------------------------------------------
# Quantizers
# --------------------------------------------------------------------------------------------


class Quantizer(Stage):
    kind = "quantizer"
    #: Whether its dequantization places values by each band's counts of nonzero values, so a
    #: block that is lost or not read gets stand-ins from those counts (``fill_stand_ins``)
    #: and, before bundle format 3.0 (which stores the counts), every block must be read.
    uses_band_counts: ClassVar[bool] = False
    #: The ``qparams`` field that holds one global step (which the encoder may round to a
    #: float32), or None when it has none.
    step_field: ClassVar[str | None] = None
    #: Whether its ``qparams`` may hold per-band weights that the plan derives (which the
    #: compact header then leaves out).
    derivable_weights: ClassVar[bool] = False

    def decode(self, qcoeffs: list[Any], geometry: Geometry) -> list[Any]:
        raise NotImplementedError


@register_stage
class DeadzoneQuantizer(Quantizer):
    """:func:`wavecore.quantize.quantize_bands`' weighted dead-zone quantizer."""

    codec_id = "deadzone"
    uses_band_counts = True
    step_field = "step"
    derivable_weights = True

    def __init__(self, params: dict[str, Any]) -> None:
        self.params = params

    def get_config(self) -> dict[str, Any]:
        return {**self.params, "id": self.codec_id}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> DeadzoneQuantizer:
        return cls({k: v for k, v in config.items() if k != "id"})

    def decode(self, qcoeffs: list[Any], geometry: Geometry) -> list[Any]:
        try:
            # The steps are stored in the params: the wavelet and boundary are not needed.
            return dequantize_bands(
                qcoeffs, self.params, wavelet="haar", boundary="open", axes=geometry.axes
            )
        except InvalidParameter as exc:
            msg = f"header field 'qparams' does not fit the bundle: {exc}"
            raise BundleError(msg[:300]) from exc


@register_stage
class NoQuantizer(Quantizer):
    """Integers coded as they are (lossless bundles)."""

    codec_id = "none"

    def decode(self, qcoeffs: list[Any], geometry: Geometry) -> list[Any]:
        return qcoeffs


# --------------------------------------------------------------------------------------------
# Entropy coders
# --------------------------------------------------------------------------------------------


class Coder(Stage):
    """One of :mod:`wavecore.entropy`'s coders; its config is the ``cparams`` it writes."""

    kind = "coder"

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        self.params = {"coder": self.codec_id} if params is None else params

    def get_config(self) -> dict[str, Any]:
        return {**self.params, "id": self.codec_id}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> Coder:
        params = {k: v for k, v in config.items() if k != "id"}
        return cls(params or None)

    def encode(self, qcoeffs: list[Any]) -> tuple[list[bytes], dict[str, Any]]:
        """``(chunks, cparams)``: one chunk per layout entry, and the header's parameters."""
        return encode_levels(qcoeffs, coder=self.codec_id)

    def decode(self, chunks: list[bytes], shapes: list[Any]) -> list[Any]:
        return decode_levels(chunks, shapes, self.params)


@register_stage
class ContextCoder(Coder):
    codec_id = "context"


@register_stage
class ZlibCoder(Coder):
    codec_id = "zlib"


# --------------------------------------------------------------------------------------------
# Colour transforms
# --------------------------------------------------------------------------------------------


class Colour(Stage):
    kind = "colour"
    #: The inverse as a 3 × 3 matrix, when it is one: the decoder then fuses it with the
    #: rounding to integers in one compiled pass.
    inverse_matrix: np.ndarray | None = None

    def forward(self, data: np.ndarray) -> np.ndarray:
        return data

    def inverse(self, data: np.ndarray) -> np.ndarray:
        return data


@register_stage
class NoColour(Colour):
    codec_id = "none"


@register_stage
class YCbCr(Colour):
    codec_id = "ycbcr"
    inverse_matrix: np.ndarray | None = YCBCR_INVERSE_MATRIX

    def forward(self, data: np.ndarray) -> np.ndarray:
        return ycbcr_forward(data)

    def inverse(self, data: np.ndarray) -> np.ndarray:
        return ycbcr_inverse(data)


class MatrixColour(Colour):
    """A per-picture rotation of the first three channels (``klt:<a>,<b>,<c>``,
    :func:`wavecore.colour.klt_matrix`); not registered: :func:`get_colour` makes one for
    each name."""

    def __init__(self, name: str) -> None:
        try:
            self.matrix = klt_matrix(name)
        except ValueError as exc:
            msg = f"header field 'colour': {exc}"
            raise BundleError(msg) from exc
        self.name = name
        self.unmix = np.ascontiguousarray(self.matrix.T)  # a rotation: its inverse
        self.inverse_matrix = self.unmix

    def get_config(self) -> dict[str, Any]:
        return {"id": self.name}

    def forward(self, data: np.ndarray) -> np.ndarray:
        out = np.array(data, dtype=np.float64)
        out[..., :3] = out[..., :3] @ self.matrix.T
        return out

    def inverse(self, data: np.ndarray) -> np.ndarray:
        out = np.array(data, dtype=np.float64)
        out[..., :3] = out[..., :3] @ self.unmix.T
        return out


@register_stage
class ReversibleColour(Colour):
    codec_id = "rct"

    def forward(self, data: np.ndarray) -> np.ndarray:
        return rct_forward(data)

    def inverse(self, data: np.ndarray) -> np.ndarray:
        return rct_inverse(data)


class PredictedReversibleColour(Colour):
    """The RCT with Cr predicted from Cb (:func:`wavecore.lossless.predict_chroma`): one
    registered id per weight, ``rct-p<weight>``, so the header's colour name carries it."""

    weight: ClassVar[int] = 0

    def forward(self, data: np.ndarray) -> np.ndarray:
        return _lossless.predicted_rct_forward(data, self.weight)

    def inverse(self, data: np.ndarray) -> np.ndarray:
        return _lossless.predicted_rct_inverse(data, self.weight)


for _weight in _lossless.CHROMA_WEIGHTS:
    if _weight:
        register_stage(
            type(
                f"PredictedReversibleColour{_weight + 8}",
                (PredictedReversibleColour,),
                {"codec_id": _lossless.colour_name(_weight), "weight": _weight},
            )
        )


# --------------------------------------------------------------------------------------------
# The header's fields -> the stages
# --------------------------------------------------------------------------------------------


def get_transform(config: dict[str, Any]) -> Transform:
    """:func:`get_stage` for a transform."""
    stage = get_stage("transform", config)
    assert isinstance(stage, Transform)
    return stage


def get_quantizer(config: dict[str, Any]) -> Quantizer:
    """:func:`get_stage` for a quantizer."""
    stage = get_stage("quantizer", config)
    assert isinstance(stage, Quantizer)
    return stage


def quantizer_of(header: dict[str, Any]) -> Quantizer:
    """The quantizer stage a header names (``quantizer`` and ``qparams``)."""
    return get_quantizer({**header["qparams"], "id": header["quantizer"]})


def get_coder(config: dict[str, Any]) -> Coder:
    """:func:`get_stage` for an entropy coder."""
    stage = get_stage("coder", config)
    assert isinstance(stage, Coder)
    return stage


def get_colour(config: dict[str, Any]) -> Colour:
    """:func:`get_stage` for a colour transform (and a per-picture matrix's name)."""
    name = config.get("id") if isinstance(config, dict) else None
    if isinstance(name, str) and name.startswith(KLT_PREFIX):
        return MatrixColour(name)
    stage = get_stage("colour", config)
    assert isinstance(stage, Colour)
    return stage


class Pipeline(NamedTuple):
    """The four stages of one bundle, in encoding order."""

    colour: Colour
    transform: Transform
    quantizer: Quantizer
    coder: Coder


def pipeline(header: dict[str, Any]) -> Pipeline:
    """The stages a (checked) header describes: the one map from header fields to configs.

    The header stores ``wavelet``/``boundary``/``lifting`` for the transform, ``quantizer``
    and ``qparams``, ``coder`` and ``cparams``, and ``colour``; each becomes one stage config.
    """
    transform = transform_config(header["wavelet"], header["boundary"], header.get("lifting"))
    coder = {**header["cparams"], "id": header["coder"]}
    return Pipeline(
        get_colour({"id": header["colour"]}),
        get_transform(transform),
        quantizer_of(header),
        get_coder(coder),
    )
