"""wavecore: local filters of quadratic B-spline wavelets (Samavati & Bartels), and a codec.

The public API is what ``__all__`` lists; everything else is internal.
"""

from __future__ import annotations

from . import cdf97 as _cdf97  # noqa: F401  (importing it registers "cdf97")
from .adjoint import synthesis_adjoint, synthesis_step_adjoint
from .codec import decode, decode_region, encode_curve, encode_image, encode_surface, inspect
from .curves import CurveDecomposition, decompose_curve, fitting_length, transfer_details
from .curvesets import CurveSet, decode_curves, encode_curves
from .errors import (
    BitrateTooLow,
    BundleError,
    InvalidCoefficients,
    InvalidLength,
    InvalidParameter,
    WavecoreError,
)
from .filters import matrices, wavelet_names
from .grids import decode_grid, encode_grid
from .images import ImageDecomposition, decompose_image, subband_mosaic
from .io import decode_file as decode_curve_file
from .io import encode_file as encode_curve_file
from .io import format_from_suffix as curve_file_format
from .io import read_curves as read_curve_file
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
    "BitrateTooLow",
    "BundleError",
    "CurveDecomposition",
    "CurveSet",
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
    "curve_file_format",
    "decode",
    "decode_curve_file",
    "decode_curves",
    "decode_grid",
    "decode_region",
    "decompose_curve",
    "decompose_image",
    "decompose_surface",
    "default_level",
    "encode_curve",
    "encode_curve_file",
    "encode_curves",
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
    "read_curve_file",
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
