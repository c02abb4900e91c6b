"""Compiled loops of the quantizer stage: dead-zone quantization, dequantization, the band
counts of ones and larger values, and the log histograms the rate control reads.  Moved from
:mod:`wavecore._kernels`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def deadzone_quantize(values, inverse_step, rounding, largest, out):
    """``out = sign(v) · min(floor(|v| · inverse_step + rounding), largest)``, elementwise."""
    for k in range(values.size):
        v = values[k]
        q = min(np.floor(abs(v) * inverse_step + rounding), largest)
        out[k] = -q if v < 0 else q


@njit(nogil=True, cache=True)
def dequantize(q, offset, step, out):
    """``out = sign(q) · (|q| + offset) · step`` for ``q != 0``, and 0 where ``q == 0``."""
    for k in range(q.size):
        v = np.int64(q[k])
        # Selects rather than branches, so that it vectorises; the same values as
        # ``(v + offset) * step`` for positive ``v``, negated for negative ones.
        scaled = (float(abs(v)) + offset) * step
        out[k] = 0.0 if v == 0 else (scaled if v > 0 else -scaled)


@njit(nogil=True, cache=True)
def count_ones_and_more(q):
    """How many values have magnitude 1, and how many 2 or more."""
    ones = 0
    more = 0
    for k in range(q.size):
        a = abs(np.int64(q[k]))
        if a == 1:
            ones += 1
        elif a >= 2:
            more += 1
    return ones, more


@njit(nogil=True, cache=True)
def largest_scaled(values, scale):
    """The largest ``|v| · scale`` (0 for no values): the first pass of :func:`log_histogram`."""
    largest = 0.0
    for k in range(values.size):
        largest = max(largest, abs(values[k]) * scale)
    return largest


@njit(nogil=True, cache=True)
def _log_bin(a, per_octave, octaves, top):
    """The bin of one scaled magnitude ``a`` by ``frexp`` (zeros, subnormals, inf and NaN)."""
    if a == 0:
        return 0
    mantissa, exponent = math.frexp(a)  # a = mantissa · 2**exponent, mantissa in [0.5, 1)
    octave = exponent - top + octaves - 1
    if octave < 0:
        return 0
    return octave * per_octave + int((2.0 * mantissa - 1.0) * per_octave)


_CHUNK = 1024


@njit(nogil=True, cache=True)
def log_histogram_counts(values, scale, per_octave, octaves, top):
    """The counts of :func:`log_histogram` for a given top octave ``top``: its second pass.

    Counts of slices add up to the counts of the whole (so slices can run in threads).  For
    normal numbers the exponent and mantissa are read from the float's bits, which is what
    ``frexp`` returns (exponent ``e - 1022``, ``2 · mantissa - 1`` the fraction bits over
    ``2**52``, exactly), at a fraction of its cost; the rest go through ``frexp``."""
    bins = per_octave * octaves
    counts = np.zeros(bins, dtype=np.int64)
    scaled = np.empty(_CHUNK, dtype=np.float64)
    bits = scaled.view(np.uint64)
    fraction_unit = 2.0**-52
    for start in range(0, values.size, _CHUNK):
        stop = min(start + _CHUNK, values.size)
        for k in range(start, stop):
            scaled[k - start] = abs(values[k]) * scale
        for k in range(stop - start):
            word = bits[k]
            biased = np.int64((word >> np.uint64(52)) & np.uint64(0x7FF))
            if biased == 0 or biased == 0x7FF:  # zero, subnormal, inf or NaN
                counts[_log_bin(scaled[k], per_octave, octaves, top)] += 1
                continue
            octave = biased - 1022 - top + octaves - 1
            if octave < 0:
                counts[0] += 1
                continue
            fraction = np.float64(word & np.uint64(0xFFFFFFFFFFFFF)) * fraction_unit
            counts[octave * per_octave + int(fraction * per_octave)] += 1
    return counts


@njit(nogil=True, cache=True)
def top_octave(largest):
    """The exponent ``frexp`` gives the largest scaled magnitude (0 when it is 0)."""
    return math.frexp(largest)[1] if largest > 0 else 0


@njit(nogil=True, cache=True)
def log_histogram(values, scale, per_octave, octaves):
    """Counts of ``|v| · scale`` in ``per_octave`` bins to an octave (equal steps of the
    mantissa), over the ``octaves`` octaves below the largest; bin 0 also holds everything
    smaller (zeros included).  Returns the counts and the top octave's exponent ``top``: bin
    ``b = per_octave · o + k`` starts at ``2 ** (top - octaves + o) · (1 + k / per_octave)``.
    Exponents come from ``frexp``: no logarithm per value.
    """
    top = top_octave(largest_scaled(values, scale))
    return log_histogram_counts(values, scale, per_octave, octaves, top), top
