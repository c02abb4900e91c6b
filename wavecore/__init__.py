"""wavecore: local filters of quadratic B-spline wavelets (Samavati & Bartels), and a codec.

The public API is what ``__all__`` lists; everything else is internal.
"""

from __future__ import annotations

from . import cdf97 as _cdf97  # noqa: F401  (importing it registers "cdf97")
from .adjoint import synthesis_adjoint, synthesis_step_adjoint
from .codec import decode, encode_curve, encode_image, encode_surface, inspect
from .curves import CurveDecomposition, decompose_curve, fitting_length, transfer_details
from .errors import (
    BundleError,
    InvalidCoefficients,
    InvalidLength,
    InvalidParameter,
    WavecoreError,
)
from .filters import matrices, wavelet_names
from .grids import decode_grid, encode_grid
from .images import ImageDecomposition, decompose_image, subband_mosaic
from .multilevel import (
    default_level,
    max_level,
    valid_length,
    wavedec,
    wavedec2,
    wavedecn,
    waverec,
    waverec2,
    waverecn,
)
from .norms import basis_norms, basis_norms_nd
from .resample import (
    GridFit,
    coarse_extent,
    crop_padding,
    fit_grid,
    minimum_length,
    pad_to_fit,
    resample_curve,
    resample_grid,
)
from .surfaces import SurfaceDecomposition, decompose_surface
from .threshold import remove_smallest
from .transform import analysis_step, synthesis_step

__version__ = "0.1.0"

__all__ = [
    "BundleError",
    "CurveDecomposition",
    "GridFit",
    "ImageDecomposition",
    "InvalidCoefficients",
    "InvalidLength",
    "InvalidParameter",
    "SurfaceDecomposition",
    "WavecoreError",
    "__version__",
    "analysis_step",
    "basis_norms",
    "basis_norms_nd",
    "coarse_extent",
    "crop_padding",
    "decode",
    "decode_grid",
    "decompose_curve",
    "decompose_image",
    "decompose_surface",
    "default_level",
    "encode_curve",
    "encode_grid",
    "encode_image",
    "encode_surface",
    "fit_grid",
    "fitting_length",
    "inspect",
    "matrices",
    "max_level",
    "minimum_length",
    "pad_to_fit",
    "remove_smallest",
    "resample_curve",
    "resample_grid",
    "subband_mosaic",
    "synthesis_adjoint",
    "synthesis_step",
    "synthesis_step_adjoint",
    "transfer_details",
    "valid_length",
    "wavedec",
    "wavedec2",
    "wavedecn",
    "wavelet_names",
    "waverec",
    "waverec2",
    "waverecn",
]
