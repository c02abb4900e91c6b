"""Request and response bodies (Pydantic, ``extra="forbid"``: a misspelt field is a 422).

Numbers must be finite: JSON has no NaN, and Python's ``json`` module's ``NaN``/``Infinity``
extensions are refused too.  Size limits depend on the settings, so the routes check them.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

Number = float
Points = list[list[Number]]


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class CurveOptions(_Body):
    """The fields of :class:`CurveEncodeRequest` besides ``points``."""

    closed: bool = Field(default=False, description="A closed curve (periodic) or an open one.")
    level: int | None = Field(default=None, ge=0, description="Levels; null picks up to 8.")
    keep: float | None = Field(default=None, ge=0, le=1, description="Fraction of details kept.")
    tolerance: float | None = Field(
        default=None,
        gt=0,
        description="Largest allowed point deviation (default 1e-3 × the diagonal).",
    )
    wavelet: str = Field(
        default="bspline2",
        description="bspline2 (the paper's, smooth; the curve default), haar (piecewise "
        "constant) or cdf97.  Images default to auto instead (POST /v1/images/encode).",
    )


class CurveEncodeRequest(CurveOptions):
    """A curve to encode: ``points`` in order, ``(n, d)`` with ``d`` from 1 to 3."""

    points: Points = Field(
        min_length=1,
        description="The points in order: [[x, y], …] or [[x, y, z], …].",
        examples=[[[0, 0], [1, 2], [2, 1], [3, 3], [4, 0], [5, 1]]],
    )


class SurfaceOptions(_Body):
    """The fields of :class:`SurfaceEncodeRequest` besides ``grid``."""

    closed: tuple[bool, bool] = Field(
        default=(False, False), description="Per grid axis: periodic (true) or open (false)."
    )
    level: int | None = Field(default=None, ge=0, description="Levels; null picks up to 5.")
    keep: float | None = Field(default=None, ge=0, le=1, description="Fraction of details kept.")
    quality: float | None = Field(
        default=None, gt=0, description="Target PSNR in dB against the data range (default 40)."
    )


class SurfaceEncodeRequest(SurfaceOptions):
    """A surface to encode: a ``(U, V, d)`` grid of points or a ``(U, V)`` height field."""

    grid: list[Points] | list[list[Number]] = Field(
        description="[[[x, y, z], …], …] (U rows of V points) or [[z, …], …] (a height field).",
        examples=[[[0.0, 0.1, 0.2, 0.1], [0.1, 0.3, 0.4, 0.2], [0.0, 0.2, 0.3, 0.1]]],
    )


class SurfaceUploadParams(_Body):
    """The form fields that come with an uploaded ``.npy`` surface."""

    closed: tuple[bool, bool] = (False, False)
    level: int | None = Field(default=None, ge=0)
    keep: float | None = Field(default=None, ge=0, le=1)
    quality: float | None = Field(default=None, gt=0)


class TransferOptions(_Body):
    """The fields of :class:`TransferRequest` besides ``source`` and ``base``."""

    closed: bool = False
    level: int | None = Field(default=None, ge=0, description="Levels of details to transfer.")


class TransferRequest(TransferOptions):
    """The paper's figure 1 (d): the details of ``source`` put onto the coarse curve ``base``."""

    source: Points = Field(min_length=1, description="The curve whose details to take.")
    base: Points = Field(min_length=1, description="The new coarse curve.")


class ReconstructParams(_Body):
    """``keep``, ``level``, ``format`` and ``region`` of a reconstruction."""

    keep: float | None = Field(default=None, ge=0, le=1)
    level: int = Field(default=0, ge=0)
    format: Literal["png", "webp", "tiff", "npy", "json", "geojson", "svg"] | None = None
    region: str | None = Field(default=None, max_length=200)


class PointsResult(BaseModel):
    """A decoded curve (``points``) or the result of a detail transfer."""

    kind: Literal["curve"] = "curve"
    shape: list[int]
    dtype: str
    points: list[Any]


class GridResult(BaseModel):
    """A decoded surface."""

    kind: Literal["surface"] = "surface"
    shape: list[int]
    dtype: str
    grid: list[Any]


class Health(BaseModel):
    status: Literal["ok"] = "ok"
    version: str


class ProblemDetails(BaseModel):
    """RFC 9457 problem details (``application/problem+json``)."""

    type: str = Field(examples=["urn:wavecore:problem:invalid-bundle"])
    title: str
    status: int
    detail: str
    instance: str | None = None
    errors: list[dict[str, Any]] | None = None
