"""What a decode at a resolution level returns: its shape, where its first sample sits in the
level's approximation, and a region checked against it (the arithmetic :func:`.decode.decode`,
its region decode and :func:`.decode.inspect` share)."""

from __future__ import annotations

from typing import Any

from ..errors import BundleError
from ..regions import check_region
from ..resample import coarse_extent
from .plan import Plan


def output_shape(plan: Plan, level: int) -> list[int]:
    """The samples per transformed axis that a decode at ``level`` returns."""
    if plan.transform.lossless:
        out = []
        for n in plan.fitted[: len(plan.axes)]:
            for _ in range(level):
                n = (n + 1) // 2
            out.append(n)
        return out
    if level == 0:
        return [plan.fitted[a] - sum(plan.pads[a]) for a in range(len(plan.axes))]
    return [
        coarse_extent(
            plan.fitted[a] - sum(plan.pads[a]),
            plan.pads[a],
            level,
            boundary=plan.boundary[a],
            wavelet=plan.wavelet,
        )
        for a in range(len(plan.axes))
    ]


def level_shape(plan: Plan, level: int) -> list[int]:
    """The shape ``decode(level=level)`` returns."""
    shape = list(plan.shape)
    for axis, n in enumerate(output_shape(plan, level)):
        shape[axis] = n
    return shape


def output_offsets(plan: Plan, level: int) -> list[int]:
    """Where a decode's first sample sits in the level's approximation, per axis (the
    padding before it: the fine data only, coarse levels are never padded before)."""
    if plan.transform.lossless or level:
        return [0] * len(plan.axes)
    return [before for before, _ in plan.pads]


def region_slices(plan: Plan, level: int, region: Any) -> tuple[slice, ...]:
    """``region`` checked against what a decode at ``level`` returns (InvalidParameter)."""
    try:
        shape = output_shape(plan, level)
    except Exception as exc:  # a crafted header whose padding does not fit its levels
        msg = f"header: the padding does not fit the levels ({type(exc).__name__}: {exc})"
        raise BundleError(msg[:300]) from exc
    return check_region(region, shape, len(plan.axes))
