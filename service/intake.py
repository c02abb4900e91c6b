"""JSON request bodies → numpy arrays, off the event loop, in a small multiple of the body.

The routes read the raw body (bounded by ``WAVECORE_MAX_UPLOAD_BYTES``) and hand the bytes to
their job, which calls :func:`parse_json_body` on a worker.  Pydantic would build a Python float
and a list per number (about 50 × the body in memory, on the event loop); here:

- msgspec checks the whole document's syntax and splits the top-level object into its fields
  *without* decoding their values (``msgspec.Raw``), so the big arrays are never Python lists;
- an array field made only of numbers, brackets and commas is converted by numpy's C number
  parser (``numpy.fromstring`` with ``sep=","``) straight into a float64 array, and its shape is
  read from the brackets and commas alone, which must form a rectangular nest;
- anything else in an array field (a string, ``null``, an object) is decoded by msgspec against
  the field's type, whose error names the exact element (``points[3][1]``);
- the small fields (``level``, ``keep``, …) are checked by the route's Pydantic model, so their
  422s read as before.

msgspec was chosen over orjson and pysimdjson because it is the one that validates while
parsing: its typed decode gives the failing element's path for free, and ``Raw`` lets the array
fields skip Python objects altogether.  Measured on a 18 MB body of 476 190 two-coordinate
points, each parser in a fresh process (load average 2.9): Pydantic 0.94 s and +169 MB;
orjson + ``np.array`` 0.44 s and +114 MB; msgspec typed decode + ``np.array`` 0.51 s and
+100 MB.  This module, later (load average 4.7): 0.72 s and +45 MB, of which 7.6 MB is the
array (the rest: the brackets and commas, their expected pattern, one slice at a time).
"""

from __future__ import annotations

import math
import re
import warnings
from typing import Any

import msgspec
import numpy as np
from pydantic import BaseModel

from .deps import parse_model
from .errors import Problem, validation_problem

#: Bytes a JSON array of numbers may hold besides brackets and commas.
_NUMBER_BYTES = b"0123456789.eE+- \t\r\n"
_BRACKETS_TO_SPACES = bytes.maketrans(b"[]", b"  ")
_EMPTY_ARRAY = re.compile(rb"\[\s*\]")  # slices are cut at commas, so none is split
_PATH_PART = re.compile(r"\[(\d+)\]|\.([A-Za-z_][A-Za-z_0-9]*)")

#: The msgspec type of an array field of each nesting depth (for exact error paths).
_TYPES: dict[int, Any] = {
    1: list[float],
    2: list[list[float]],
    3: list[list[list[float]]],
}


def _field_error(loc: list[Any], msg: str, kind: str) -> Problem:
    return validation_problem([{"loc": loc, "msg": msg, "type": kind}], prefix=("body",))


def _msgspec_loc(name: str, message: str) -> list[Any]:
    """``Expected `float`, got `str` - at `$[0][1]``` → ``[name, 0, 1]``."""
    at = message.rpartition(" - at `$")[2].rstrip("`")
    loc: list[Any] = [name]
    for index, key in _PATH_PART.findall(at):
        loc.append(int(index) if index else key)
    return loc


def parse_json_body(
    body: bytes | bytearray, options: type[BaseModel], arrays: dict[str, tuple[int, ...]]
) -> tuple[Any, dict[str, np.ndarray]]:
    """Split a JSON object into its validated small fields and its float64 arrays.

    Parameters
    ----------
    body : bytes
        The request body.
    options : type of pydantic.BaseModel
        The model of every field that is not an array (``extra="forbid"``).
    arrays : dict
        Array field name → the numbers of axes it may have (``{"points": (2,)}``).

    Returns
    -------
    options, arrays
        The validated model and one ``float64`` array per array field.

    Raises
    ------
    Problem
        422 ``validation-error`` naming the field for anything that is not such an object:
        invalid JSON, a missing field, a non-number, a wrong nesting, an empty array, a number
        out of float64's range.  A ragged nest is a 422 ``invalid-parameter``.

    Examples
    --------
    >>> from service.schemas import CurveOptions
    >>> opts, arrs = parse_json_body(b'{"points": [[0, 1], [2, 3.5]], "keep": 0.5}',
    ...                              CurveOptions, {"points": (2,)})
    >>> opts.keep, arrs["points"].shape
    (0.5, (2, 2))
    """
    if not body.strip():
        raise _field_error([], "the body is empty; send a JSON object", "missing")
    try:
        fields = msgspec.json.decode(body, type=dict[str, msgspec.Raw])
    except msgspec.ValidationError as exc:
        raise _field_error([], f"the body must be a JSON object ({exc})", "model_type") from None
    except (msgspec.DecodeError, RecursionError, UnicodeDecodeError) as exc:
        # RecursionError: msgspec's bound on nesting (a few hundred levels), not a crash.
        raise validation_problem(
            [{"loc": ["body"], "msg": str(exc), "type": "json_invalid"}]
        ) from None
    parsed: dict[str, np.ndarray] = {}
    for name, ndims in arrays.items():
        raw = fields.pop(name, None)
        if raw is None:
            raise _field_error([name], "Field required", "missing")
        parsed[name] = numeric_array(raw, name, ndims)
    small: dict[str, Any] = {}
    for key, raw in fields.items():
        try:
            small[key] = msgspec.json.decode(raw)
        except msgspec.ValidationError as exc:  # a number beyond float64's range
            raise _field_error(_msgspec_loc(key, str(exc)), str(exc), "finite_number") from None
        except (msgspec.DecodeError, RecursionError, UnicodeDecodeError) as exc:  # bad text
            raise _field_error([key], str(exc), "json_invalid") from None
    return parse_model(options, small), parsed


def numeric_array(text: bytes | msgspec.Raw, name: str, ndims: tuple[int, ...]) -> np.ndarray:
    """A float64 array from the JSON text of a rectangular nest of numbers (valid JSON).

    The text is read in slices of about 256 KiB, cut at commas: only the brackets and commas
    of the whole (a fifth of it or less) and the array itself are ever held besides the body,
    and no step holds the GIL for more than a few milliseconds (/healthz stays quick).
    """
    view = memoryview(text)
    slices = list(_comma_slices(view))
    # The slices are cut at commas, so the commas between them come back with the join.
    structure = b",".join(bytes(view[a:b]).translate(None, _NUMBER_BYTES) for a, b in slices)
    if structure.translate(None, b"[],"):
        return _typed_decode(text, name, ndims)  # strings, null, objects: msgspec names them
    depth = len(structure) - len(structure.lstrip(b"["))
    if depth not in ndims:
        expected = " or ".join(f"{n}-level" for n in ndims)
        msg = f"{name} must be a {expected} nested array of numbers, not {depth}-level"
        raise _field_error([name], msg, "list_type")
    if any(_EMPTY_ARRAY.search(view[a:b]) for a, b in slices):
        # "[]" and "[5]" leave the same brackets behind: an empty array is told apart here.
        if structure == b"[" * depth + b"]" * depth:
            raise _field_error([name], f"{name} is empty: it needs at least one point", "too_short")
        shape = None
    else:
        shape = _shape_of(structure, depth)
    if shape is None or _nest(shape) != structure:
        msg = f"{name} is ragged: every row must have the same number of values"
        errors = [{"loc": ["body", name], "msg": msg, "type": "ragged"}]
        raise Problem("invalid-parameter", msg, errors=errors)
    del structure
    values = np.empty(math.prod(shape), dtype=np.float64)
    filled = 0
    for a, b in slices:
        piece = bytes(view[a:b])
        # Every comma of a valid nest without empty arrays separates two numbers, so a slice
        # cut at commas holds one number more than it has commas; numpy's parser is lenient
        # (a blank field reads as -1), and this count catches any such slip.
        count = piece.count(b",") + 1
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)  # "could not be read to its end"
            try:
                parsed = np.fromstring(piece.translate(_BRACKETS_TO_SPACES), np.float64, sep=",")
            except (ValueError, DeprecationWarning):
                return _typed_decode(text, name, ndims)
        if parsed.size != count or filled + count > values.size:
            return _typed_decode(text, name, ndims)
        values[filled : filled + count] = parsed
        filled += count
    if filled != values.size:
        return _typed_decode(text, name, ndims)
    if not np.isfinite(values).all():
        index = np.unravel_index(int(np.argmin(np.isfinite(values))), shape)
        where = "".join(f"[{i}]" for i in index)
        msg = f"{name}{where} is out of float64's range (about ±1.8e308)"
        raise _field_error([name, *map(int, index)], msg, "finite_number")
    return values.reshape(shape)


def _comma_slices(view: memoryview, size: int = 1 << 18) -> list[tuple[int, int]]:
    """``(start, end)`` slices of about ``size`` bytes, each ending just before a comma."""
    slices = []
    start, n = 0, len(view)
    while start < n:
        end = min(start + size, n)
        while end < n and view[end] != ord(","):
            found = bytes(view[end : end + 4096]).find(b",")
            end = min(end + 4096, n) if found < 0 else end + found
        slices.append((start, end))
        start = end + 1
    return slices


def _shape_of(structure: bytes, depth: int) -> tuple[int, ...] | None:
    """The shape a rectangular nest would have, read from its first element at each level."""
    shape = []
    for level in range(depth):
        # The first block at this level starts at ``level`` and ends at the first run of
        # ``depth - level`` closing brackets; its elements are separated by commas at its top.
        start = level
        end = structure.find(b"]" * (depth - level), start)
        if end < 0:
            return None
        inner = structure[start + 1 : end + (depth - level) - 1]
        if level == depth - 1:
            shape.append(inner.count(b",") + 1)
        else:
            shape.append(inner.count(b"]" * (depth - level - 1) + b",") + 1)
    return tuple(shape)


def _nest(shape: tuple[int, ...]) -> bytes:
    """The brackets and commas of a rectangular nest of ``shape`` (no size is 0)."""
    inner = b"[" + b"," * (shape[-1] - 1) + b"]"
    for size in reversed(shape[:-1]):
        inner = b"[" + b",".join([inner] * size) + b"]"
    return inner


def _typed_decode(text: bytes | msgspec.Raw, name: str, ndims: tuple[int, ...]) -> np.ndarray:
    """The slow, exact path: msgspec against the field's type names the bad element."""
    error: msgspec.ValidationError | None = None
    for ndim in ndims:
        try:
            nested = msgspec.json.decode(bytes(memoryview(text)), type=_TYPES[ndim])
        except msgspec.ValidationError as exc:  # (a subclass of DecodeError: first)
            error = error or exc
            continue
        except (msgspec.DecodeError, RecursionError, UnicodeDecodeError) as exc:
            raise _field_error([name], str(exc), "json_invalid") from None
        try:
            return np.array(nested, dtype=np.float64)
        except ValueError:
            msg = f"{name} is ragged: every row must have the same number of values"
            errors = [{"loc": ["body", name], "msg": msg, "type": "ragged"}]
            raise Problem("invalid-parameter", msg, errors=errors) from None
    message = str(error)
    raise _field_error(_msgspec_loc(name, message), message, "type_error")
