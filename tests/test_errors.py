"""The exception tree that wavecore/errors.py draws, and what wavecore exports of it."""

from __future__ import annotations

import pytest

import wavecore
from wavecore import errors


def test_the_tree_is_as_documented() -> None:
    assert issubclass(errors.InvalidParameter, errors.WavecoreError)
    assert issubclass(errors.InvalidParameter, ValueError)
    assert issubclass(errors.InvalidLength, errors.InvalidParameter)
    assert issubclass(errors.InvalidCoefficients, errors.InvalidParameter)
    assert issubclass(errors.BundleError, errors.WavecoreError)
    assert issubclass(errors.BundleError, ValueError)
    assert not issubclass(errors.BundleError, errors.InvalidParameter)


def test_every_exception_is_exported_by_the_package() -> None:
    for name in errors.__all__:
        assert name in wavecore.__all__
        assert getattr(wavecore, name) is getattr(errors, name)


def test_errors_from_the_library_belong_to_the_tree() -> None:
    with pytest.raises(errors.InvalidLength, match="nearest lengths"):
        wavecore.wavedec([0.0] * 13, level=2)
    with pytest.raises(errors.InvalidParameter, match="accepted"):
        wavecore.wavedec([0.0] * 10, wavelet="db99")
    with pytest.raises(errors.BundleError):
        wavecore.decode(b"not a bundle")
