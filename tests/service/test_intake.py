"""JSON bodies → arrays (service/intake.py): exact numbers, exact errors, any nesting."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from service.errors import Problem
from service.intake import parse_json_body
from service.schemas import CurveOptions, SurfaceOptions

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(np.float64, hnp.array_shapes(min_dims=2, max_dims=3, max_side=7), elements=finite),
    st.sampled_from([(",", ":"), (", ", ": "), (" , ", " : ")]),
)
def test_any_rectangular_nest_reads_back_exactly(array: np.ndarray, separators: Any) -> None:
    body = json.dumps({"grid": array.tolist(), "level": 1}, separators=separators).encode()
    options, arrays = parse_json_body(body, SurfaceOptions, {"grid": (2, 3)})
    assert options.level == 1
    np.testing.assert_array_equal(arrays["grid"], array)  # bit for bit: Python's repr round-trips


def test_long_bodies_are_read_in_slices_exactly() -> None:
    # More than one 256 KiB slice: the cuts fall between rows and inside rows.
    array = np.random.default_rng(5).normal(size=(30_000, 3)) * 1e-5
    body = json.dumps({"points": array.tolist()}).encode()
    assert len(body) > 3 * 2**18
    _, arrays = parse_json_body(body, CurveOptions, {"points": (2,)})
    np.testing.assert_array_equal(arrays["points"], array)


@pytest.mark.parametrize(
    ("body", "status", "loc"),
    [
        (b'{"points": [[0, 1], [2, "3"]]}', 422, ["body", "points", 1, 1]),
        (b'{"points": [[0, 1], [2, null]]}', 422, ["body", "points", 1, 1]),
        (b'{"points": [[0, 1], [2, 1e400]]}', 422, ["body", "points", 1, 1]),
        (b'{"points": [[0, 1], [2]]}', 422, ["body", "points"]),
        (b'{"points": [[0, 1], []]}', 422, ["body", "points"]),
        (b'{"points": [[]]}', 422, ["body", "points"]),
        (b'{"points": [1, 2]}', 422, ["body", "points"]),
        (b'{"points": [[[1, 2]]]}', 422, ["body", "points"]),
        (b'{"keep": 0.5}', 422, ["body", "points"]),
        (b'{"points": [[0, 1]], "keep": 7}', 422, ["body", "keep"]),
        (b'{"points": [[0, 1]], "keep": 1e400}', 422, ["body", "keep"]),
        (b'{"points": [[0, 1]], "nope": 1}', 422, ["body", "nope"]),
    ],
)
def test_errors_name_the_element(body: bytes, status: int, loc: list[Any]) -> None:
    with pytest.raises(Problem) as caught:
        parse_json_body(body, CurveOptions, {"points": (2,)})
    assert caught.value.status == status
    assert caught.value.errors is not None and caught.value.errors[0]["loc"] == loc


@pytest.mark.parametrize(
    "body",
    [b"", b"   ", b"[]", b"null", b'"text"', b"{", b'{"points": [[NaN, 1]]}', b"\xff\xfe"],
)
def test_what_is_not_a_json_object_is_a_422(body: bytes) -> None:
    with pytest.raises(Problem) as caught:
        parse_json_body(body, CurveOptions, {"points": (2,)})
    assert caught.value.kind == "validation-error"
