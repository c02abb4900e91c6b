"""Compiled loops of the error metrics: the squared and largest error of decoded samples
against the original.  Moved from :mod:`wavecore._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def squared_and_largest_error(decoded, original):
    """(sum of squared differences, largest absolute difference) of two same-shape 1-D arrays."""
    total = 0.0
    largest = 0.0
    for k in range(decoded.size):
        d = np.float64(decoded[k]) - np.float64(original[k])  # float32 pairs too
        total += d * d
        d = abs(d)
        if d > largest or d != d:
            largest = d
    return total, largest


@njit(nogil=True, cache=True)
def squared_and_largest_rounded_error(decoded, original, low, high):
    """:func:`squared_and_largest_error` of float samples rounded to integers and clipped to
    ``[low, high]`` (an integer dtype's range) against ``original``: what the rounded samples
    would measure, in one pass and with no array of them (the grids' RMSE search measures
    every try so)."""
    total = 0.0
    largest = 0.0
    for k in range(decoded.size):
        v = np.rint(decoded[k])
        if v < low:
            v = low
        elif v > high:
            v = high
        d = v - np.float64(original[k])
        total += d * d
        d = abs(d)
        if d > largest or d != d:
            largest = d
    return total, largest


@njit(nogil=True, cache=True)
def squared_and_largest_integer_error(decoded, original):
    """:func:`squared_and_largest_error` of integer samples whose squared differences add up
    below ``2**53``, in integers: the same values (every float partial sum of integers that
    small is exact), in a loop that vectorises (a float sum must keep its order)."""
    total = np.int64(0)
    largest = np.int64(0)
    for k in range(decoded.size):
        d = np.int64(decoded[k]) - np.int64(original[k])
        total += d * d
        if d < 0:
            d = -d
        if d > largest:
            largest = d
    return total, largest
