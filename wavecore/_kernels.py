"""The compiled loops, regrouped by stage; this module keeps the names its callers use.

* :mod:`wavecore._transformkernels`: the transform's analysis and synthesis steps and 2-D levels;
* :mod:`wavecore._colourkernels`: colour matrices into floats, and the decoder's last pass;
* :mod:`wavecore._metrickernels`: squared and largest errors;
* :mod:`wavecore._quantkernels`: dead-zone quantization, dequantization, band counts, log
  histograms;
* :mod:`wavecore._liftingkernels`: the lossless liftings, value ranges and histograms, the
  predicted RCT.
"""

from __future__ import annotations

from ._colourkernels import (
    colour_to_floats as colour_to_floats,
)
from ._colourkernels import (
    colour_to_integers as colour_to_integers,
)
from ._colourkernels import (
    finite_floats as finite_floats,
)
from ._liftingkernels import (
    lift_steps as lift_steps,
)
from ._liftingkernels import (
    predicted_rct_forward as predicted_rct_forward,
)
from ._liftingkernels import (
    predicted_rct_inverse as predicted_rct_inverse,
)
from ._liftingkernels import (
    unlift_steps as unlift_steps,
)
from ._liftingkernels import (
    value_histogram as value_histogram,
)
from ._liftingkernels import (
    value_range as value_range,
)
from ._metrickernels import (
    squared_and_largest_error as squared_and_largest_error,
)
from ._metrickernels import (
    squared_and_largest_integer_error as squared_and_largest_integer_error,
)
from ._metrickernels import (
    squared_and_largest_rounded_error as squared_and_largest_rounded_error,
)
from ._quantkernels import (
    count_ones_and_more as count_ones_and_more,
)
from ._quantkernels import (
    deadzone_quantize as deadzone_quantize,
)
from ._quantkernels import (
    dequantize as dequantize,
)
from ._quantkernels import (
    largest_scaled as largest_scaled,
)
from ._quantkernels import (
    log_histogram as log_histogram,
)
from ._quantkernels import (
    log_histogram_counts as log_histogram_counts,
)
from ._quantkernels import (
    top_octave as top_octave,
)
from ._transformkernels import (
    MAX_TAPS as MAX_TAPS,
)
from ._transformkernels import (
    analysis3 as analysis3,
)
from ._transformkernels import (
    analysis_2d as analysis_2d,
)
from ._transformkernels import (
    analysis_last as analysis_last,
)
from ._transformkernels import (
    analysis_mid as analysis_mid,
)
from ._transformkernels import (
    synthesis_2d as synthesis_2d,
)
from ._transformkernels import (
    synthesis_2d_integers as synthesis_2d_integers,
)
from ._transformkernels import (
    synthesis_columns as synthesis_columns,
)
from ._transformkernels import (
    synthesis_last as synthesis_last,
)
from ._transformkernels import (
    synthesis_mid as synthesis_mid,
)
