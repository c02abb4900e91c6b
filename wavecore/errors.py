"""The exceptions that ``wavecore`` raises.

Every error that comes from bad input is a :class:`WavecoreError`, and every one of those is also
a :class:`ValueError`, so ``except ValueError`` keeps working for callers who do not know this
module::

    WavecoreError (Exception)
    ├── InvalidParameter (ValueError)      a bad argument: unknown name, level, fraction, dtype …
    │   ├── InvalidLength                  a length that does not fit the requested levels
    │   ├── InvalidCoefficients            a coefficient list whose shapes do not fit together
    │   └── BitrateTooLow                  a bpp below the smallest bundle the input takes
    └── BundleError (ValueError)           anything wrong with an encoded bundle
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "BitrateTooLow",
    "BundleError",
    "InvalidCoefficients",
    "InvalidLength",
    "InvalidParameter",
    "WavecoreError",
]


class WavecoreError(Exception):
    """Base class of every exception that ``wavecore`` raises on purpose."""


class InvalidParameter(WavecoreError, ValueError):
    """An argument is not acceptable; the message names it and what would be accepted."""


class InvalidLength(InvalidParameter):
    """A length does not fit the requested number of levels.

    The message names the length, the level, the boundary and the nearest lengths that fit.
    """


class InvalidCoefficients(InvalidParameter):
    """A coefficient list whose shapes do not belong to one decomposition."""


class BitrateTooLow(InvalidParameter):
    """A ``bpp`` target below the smallest bundle the input can be coded in.

    ``smallest_bytes`` is the fewest bytes a target must allow (header included): a ``bpp``
    of ``8 * smallest_bytes`` over the pixels (a grid: its values) codes the input.
    """

    def __init__(self, message: str, smallest_bytes: int) -> None:
        super().__init__(message)
        self.smallest_bytes = smallest_bytes

    def __reduce__(self) -> tuple[Any, ...]:  # pickled across the service's worker processes
        return (type(self), (str(self), self.smallest_bytes))


class BundleError(WavecoreError, ValueError):
    """An encoded bundle is truncated, corrupt, of an unknown version or otherwise unusable."""
