"""Images: grey, RGB and RGBA, any size and dtype, through the 2-D transform and back.

The paper's figure 2: decompose a photograph, look at the coarse image, and reconstruct it with
the smallest details removed.

Dtype policy (as scikit-image writes one down)
    The transform runs in float64 whatever the input.  :meth:`ImageDecomposition.reconstruct`
    gives back the input's dtype: integer images are rounded to the nearest integer and clipped
    to the dtype's range; float images are cast back (float16/float32 unchanged by a round
    trip, float64 to within rounding).  Coarse images and mosaics are float64 for viewing.
    Boolean and complex images are refused.

Any size
    Each side is fitted to a length the transform accepts, by padding at the end (``fit="pad"``,
    exact, the default) or by re-sampling (``fit="resample"``, the paper's section 4.5).  The
    reconstruction always has the input's exact shape.  A side shorter than one level needs
    (8 pixels for the open ``bspline2`` boundary) is an error that names the minimum.

>>> import numpy as np
>>> import wavecore
>>> photo = np.random.default_rng(0).integers(0, 256, (45, 70, 3), dtype=np.uint8)
>>> dec = wavecore.decompose_image(photo, level=2, channel_axis=-1)
>>> dec.coarse(2).shape, dec.mosaic().shape
((13, 19, 3), (46, 70, 3))
>>> back = dec.reconstruct()
>>> back.dtype, bool(np.array_equal(back, photo))
(dtype('uint8'), True)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .arguments import as_array
from .errors import InvalidCoefficients, InvalidParameter
from .filters import FilterBank, get_wavelet
from .multilevel import as_int, default_level, wavedec2, waverec2
from .resample import GridFit, fit_grid
from .threshold import keep_largest
from .transform import normalize_axis

__all__ = ["ImageDecomposition", "decompose_image", "subband_mosaic"]


def _check_dtype(dtype: np.dtype[Any]) -> None:
    if dtype.kind in "iuf":
        return
    hint = " (convert it to uint8 first)" if dtype.kind == "b" else ""
    msg = f"cannot decompose an image of dtype {dtype}{hint}; use an integer or float dtype"
    raise InvalidParameter(msg)


def _to_dtype(data: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    """Float results in ``dtype``: integers rounded and clipped to the dtype's range."""
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        return np.clip(np.rint(data), info.min, info.max).astype(dtype)
    return data.astype(dtype)


@dataclass(frozen=True)
class ImageDecomposition:
    """An image taken apart by :func:`decompose_image`.

    Attributes
    ----------
    coeffs : list
        ``[cA_L, (cH_L, cV_L, cD_L), ..., (cH_1, cV_1, cD_1)]`` of the fitted image, float64,
        with the channels (if any) on the last axis.
    fit : wavecore.resample.GridFit
        How the image was fitted (padding or re-sampling) and how to undo it.
    shape : tuple of int
        The input's shape.
    dtype : numpy.dtype
        The input's dtype.
    channel_axis : int or None
        The input's channel axis (non-negative), or ``None`` for a grey image.
    wavelet, boundary : str
        As used for the transform.
    """

    coeffs: list[Any]
    fit: GridFit
    shape: tuple[int, ...]
    dtype: np.dtype[Any]
    channel_axis: int | None
    wavelet: str
    boundary: str

    @property
    def level(self) -> int:
        """The number of levels."""
        return len(self.coeffs) - 1

    def _restore_layout(self, data: np.ndarray) -> np.ndarray:
        if self.channel_axis is None:
            return data
        return np.moveaxis(data, -1, self.channel_axis)

    def coarse(self, level: int | None = None) -> np.ndarray:
        """The coarse image after ``level`` levels (default: all), over the original's extent.

        Float64 in the input's value range; about ``1/2**level`` of the input's size per side
        (padding cropped away).  ``level=0`` gives the full-size image as float.
        """
        level = self.level if level is None else as_int(level, "level")
        if level > self.level:
            msg = f"level {level} is deeper than the decomposition's {self.level} levels"
            raise InvalidParameter(msg)
        coarse = waverec2(self.coeffs[: self.level - level + 1], self.wavelet, self.boundary)
        return self._restore_layout(self.fit.coarse_view(coarse, level))

    def reconstruct(self, keep: float = 1.0, *, weighted: bool = True) -> np.ndarray:
        """The image with only the largest ``keep`` share of its details, in the input's dtype.

        Parameters
        ----------
        keep : float
            In ``[0, 1]``; 1 (the default) gives the input back (exactly for integer, float16
            and float32 images with ``fit="pad"``), 0 the coarse image at full size.
        weighted : bool, keyword-only
            Rank details by their effect on the reconstruction (see
            :func:`wavecore.remove_smallest`); every colour channel's numbers are ranked on
            their own.  The share counts the details of the fitted image: with
            ``fit="pad"`` that includes the few padded rows and columns, whose flat details
            are among the first removed.

        Returns
        -------
        numpy.ndarray
            The input's shape and dtype.
        """
        coeffs = keep_largest(
            self.coeffs,
            keep,
            wavelet=self.wavelet,
            boundary=self.boundary,
            weighted=weighted,
            vector_axis=None,
        )
        fine = self.fit.undo(waverec2(coeffs, self.wavelet, self.boundary))
        return _to_dtype(self._restore_layout(fine), self.dtype)

    def mosaic(self) -> np.ndarray:
        """All subbands in one picture of the fitted size (see :func:`subband_mosaic`)."""
        return self._restore_layout(subband_mosaic(self.coeffs))


def decompose_image(
    image: Any,
    level: int | None = None,
    *,
    channel_axis: int | None = None,
    wavelet: str | FilterBank = "bspline2",
    boundary: str = "open",
    fit: str = "pad",
) -> ImageDecomposition:
    """Take an image of any size apart with the 2-D transform.

    Parameters
    ----------
    image : array_like
        ``(H, W)`` for grey, or with a channel axis (RGB, RGBA, any count).  Integer or float.
    level : int, optional
        Number of levels.  Default: the library's one rule, :func:`wavecore.default_level`
        (the codec's too): up to 5, keeping the coarsest image at about 4 pixels per side or
        more (at least 1).
    channel_axis : int or None, keyword-only
        The axis of the colour channels, as in scikit-image; ``None`` for a grey image.
    wavelet : str, keyword-only
        ``"bspline2"`` (the paper's; alias ``"chaikin"``), ``"haar"`` or ``"cdf97"`` (alias
        ``"jpeg2000"``); see :func:`wavecore.wavelet_names`.
    boundary : {"open", "closed"}, keyword-only
        ``"open"`` (endpoint interpolating) suits photographs; ``"closed"`` treats the image as
        periodic.
    fit : {"pad", "resample"}, keyword-only
        How a side whose length does not fit is made to fit: edge padding at the end (exact;
        the default) or linear re-sampling to the nearest fitting length (the paper's
        section 4.5).  The reconstruction has the input's shape either way.

    Returns
    -------
    ImageDecomposition
        With ``coarse(level)``, ``reconstruct(keep=...)`` and ``mosaic()``.

    Raises
    ------
    InvalidParameter
        For a wrong number of dimensions, a bad ``channel_axis`` or an unsupported dtype.
    InvalidLength
        If a side is too small for one level (the message names the minimum).

    Examples
    --------
    >>> import numpy as np
    >>> grey = np.linspace(0, 1, 30 * 40).reshape(30, 40).astype(np.float32)
    >>> dec = decompose_image(grey)
    >>> dec.level, dec.reconstruct().dtype, bool(np.array_equal(dec.reconstruct(), grey))
    (2, dtype('float32'), True)
    >>> decompose_image(np.zeros((5, 40)))
    Traceback (most recent call last):
      ...
    wavecore.errors.InvalidLength: a grid of 5×40 samples is too small: axis 0 has 5, and one \
level of the open boundary of 'bspline2' needs at least 8 samples per axis
    """
    if fit not in ("pad", "resample"):
        msg = f"fit must be 'pad' (exact) or 'resample' (section 4.5), not {fit!r}"
        raise InvalidParameter(msg)
    arr = as_array(image, what="the image")
    _check_dtype(arr.dtype)
    bank = get_wavelet(wavelet)
    if channel_axis is None:
        if arr.ndim != 2:
            hint = " (for a colour image pass channel_axis=-1)" if arr.ndim == 3 else ""
            msg = f"a grey image must have 2 dimensions, not shape {arr.shape}{hint}"
            raise InvalidParameter(msg)
        axis = None
        work = arr
    else:
        if arr.ndim != 3:
            msg = f"an image with channel_axis must have 3 dimensions, not shape {arr.shape}"
            raise InvalidParameter(msg)
        axis = normalize_axis(channel_axis, 3)
        work = np.moveaxis(arr, axis, -1)
    sizes = work.shape[:2]
    if level is None:
        level = default_level(sizes)
    level = as_int(level, "level", minimum=1)
    fitted, grid_fit = fit_grid(
        work.astype(np.float64), level, axes=(0, 1), boundary=boundary, wavelet=bank, method=fit
    )
    coeffs = wavedec2(fitted, bank, boundary, level)
    return ImageDecomposition(
        coeffs, grid_fit, arr.shape, arr.dtype, axis, bank.name, grid_fit.boundaries[0]
    )


def _view_coarse(band: np.ndarray) -> np.ndarray:
    low, high = float(np.min(band)), float(np.max(band))
    return (band - low) / (high - low) if high > low else np.zeros_like(band)


def _view_detail(band: np.ndarray) -> np.ndarray:
    magnitude = np.abs(band)
    # A robust scale: a few large edges would otherwise leave the rest of the band black.
    scale = float(np.percentile(magnitude, 99.5)) if magnitude.size else 0.0
    if scale <= 0:
        scale = float(magnitude.max()) if magnitude.size else 0.0
    return np.clip(magnitude / scale, 0.0, 1.0) if scale > 0 else np.zeros_like(band)


def subband_mosaic(coeffs: Sequence[Any]) -> np.ndarray:
    """Lay out a 2-D decomposition as one picture: the classic wavelet mosaic.

    The coarse image sits in the top-left corner; at each level, its ``cV`` band (details along
    the second axis) goes to its right, ``cH`` below it and ``cD`` diagonally.  The coarse image
    is stretched to ``[0, 1]``; each detail band shows its magnitude, scaled by its own 99.5th
    percentile, so black means "no detail".  The mosaic has exactly the fine data's shape.

    Parameters
    ----------
    coeffs : list
        As :func:`wavecore.wavedec2` returns it (channels, if any, on trailing axes).

    Returns
    -------
    numpy.ndarray
        Float64 in ``[0, 1]``.

    Examples
    --------
    >>> import numpy as np
    >>> import wavecore
    >>> image = np.random.default_rng(0).random((34, 18))
    >>> subband_mosaic(wavecore.wavedec2(image, level=2)).shape
    (34, 18)
    """
    if isinstance(coeffs, np.ndarray) or not len(coeffs):
        msg = "coeffs must be a non-empty list [cA_L, (cH_L, cV_L, cD_L), ...]"
        raise InvalidCoefficients(msg)
    picture = _view_coarse(as_array(coeffs[0], np.float64, "the coarse band"))
    for bands in coeffs[1:]:
        if not isinstance(bands, tuple | list) or len(bands) != 3:
            msg = "each level's details must be a tuple (cH, cV, cD)"
            raise InvalidCoefficients(msg)
        ch, cv, cd = (_view_detail(as_array(b, np.float64, "a detail band")) for b in bands)
        try:
            top = np.concatenate([picture, cv], axis=1)
            bottom = np.concatenate([ch, cd], axis=1)
            picture = np.concatenate([top, bottom], axis=0)
        except ValueError:  # numpy's words for bands that do not tile (or have no axes)
            shapes = ", ".join(str(b.shape) for b in (picture, ch, cv, cd))
            msg = f"the bands do not tile a picture (coarse, cH, cV, cD: {shapes})"
            raise InvalidCoefficients(msg) from None
    return picture
