"""Tensor-product surfaces: grids of points ``(U, V, 3)`` and height fields ``(U, V)``.

The paper's figure 3: the filters run along every u-curve and then every v-curve of the grid,
with a boundary per direction — closed in u and open in v for a surface of revolution, open in
both for a terrain patch, closed in both for a torus.

>>> import numpy as np
>>> import wavecore
>>> u = np.linspace(0, 2 * np.pi, 32, endpoint=False)[:, None]
>>> v = np.linspace(0, 1, 18)[None, :]
>>> radius = 1 + 0.3 * np.sin(3 * np.pi * v) + 0.05 * np.cos(8 * u)
>>> vase = np.stack(np.broadcast_arrays(radius * np.cos(u), radius * np.sin(u), 2 * v), axis=-1)
>>> dec = wavecore.decompose_surface(vase, 2, boundary=("closed", "open"))
>>> dec.coarse().shape, dec.reconstruct(keep=0.4).shape
((8, 6, 3), (32, 18, 3))
>>> bool(np.allclose(dec.reconstruct(), vase))
True
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InvalidParameter
from .filters import FilterBank, get_wavelet
from .multilevel import as_int, default_level, wavedecn, waverecn
from .resample import GridFit, fit_grid
from .threshold import keep_largest
from .transform import as_float_array

__all__ = ["SurfaceDecomposition", "decompose_surface"]


@dataclass(frozen=True)
class SurfaceDecomposition:
    """A surface taken apart by :func:`decompose_surface`.

    Attributes
    ----------
    coeffs : list
        ``[cA_L, {"ad": ..., "da": ..., "dd": ...}, ...]`` of the fitted grid, as
        :func:`wavecore.wavedecn` returns it over axes ``(0, 1)``.
    fit : wavecore.resample.GridFit
        How the grid was fitted (padding or re-sampling) and how to undo it.
    wavelet : str
        The wavelet's name.
    height_field : bool
        Whether the input was a height field ``(U, V)`` rather than points ``(U, V, d)``.
    """

    coeffs: list[Any]
    fit: GridFit
    wavelet: str
    height_field: bool

    @property
    def boundary(self) -> tuple[str, ...]:
        """The boundary in u and in v."""
        return self.fit.boundaries

    @property
    def level(self) -> int:
        """The number of levels (the same in both directions)."""
        return len(self.coeffs) - 1

    def coarse(self, level: int | None = None) -> np.ndarray:
        """The coarse grid (control net) after ``level`` levels per direction (default: all).

        ``level=0`` is the fine grid.  With ``fit="pad"`` the padding is cropped away.
        """
        level = self.level if level is None else as_int(level, "level")
        if level > self.level:
            msg = f"level {level} is deeper than the decomposition's {self.level} levels"
            raise InvalidParameter(msg)
        coarse = waverecn(
            self.coeffs[: self.level - level + 1], self.wavelet, self.boundary, axes=(0, 1)
        )
        return self.fit.coarse_view(coarse, level)

    def reconstruct(self, keep: float = 1.0, *, weighted: bool = True) -> np.ndarray:
        """The surface with only the largest ``keep`` share of its details.

        Parameters
        ----------
        keep : float
            In ``[0, 1]``: 1 all details (the input back), 0 none (the smooth surface of the
            coarse net, at full resolution), 0.4 the largest 40 %.
        weighted : bool, keyword-only
            Rank as :func:`wavecore.remove_smallest` does; a point's detail is ranked by its
            vector norm and kept or removed whole.

        Returns
        -------
        numpy.ndarray
            Float, the input's shape.
        """
        coeffs = keep_largest(
            self.coeffs,
            keep,
            wavelet=self.wavelet,
            boundary=self.boundary,
            weighted=weighted,
            axes=(0, 1),
            vector_axis=None if self.height_field else -1,
        )
        return self.fit.undo(waverecn(coeffs, self.wavelet, self.boundary, axes=(0, 1)))


def decompose_surface(
    grid: Any,
    level: int | None = None,
    *,
    boundary: str | Sequence[str] = "open",
    wavelet: str | FilterBank = "bspline2",
    fit: str = "pad",
) -> SurfaceDecomposition:
    """Take a tensor-product surface apart, with a boundary per direction.

    Parameters
    ----------
    grid : array_like
        Points ``(U, V, d)`` (usually ``d = 3``) or a height field ``(U, V)``.  A closed
        direction must not repeat its first row (or column) at the end.
    level : int, optional
        Levels per direction.  Default: the library's one rule, :func:`wavecore.default_level`
        (:func:`wavecore.encode_surface`'s too): up to 5, keeping the coarse net at about 4
        samples per direction or more (at least 1).
    boundary : str or (str, str), keyword-only
        ``"open"`` or ``"closed"`` for both directions, or one per direction:
        ``("closed", "open")`` for a surface of revolution (u around, v along the axis),
        ``"closed"`` for a torus.
    wavelet : str, keyword-only
        ``"bspline2"`` (the paper's; alias ``"chaikin"``), ``"haar"`` or ``"cdf97"`` (alias
        ``"jpeg2000"``); see :func:`wavecore.wavelet_names`.
    fit : {"pad", "resample"}, keyword-only
        How a direction whose length does not fit is made to fit: padding at the end (exact;
        the default), or linear re-sampling to the nearest fitting length (section 4.5).

    Returns
    -------
    SurfaceDecomposition
        With ``coarse(level)`` and ``reconstruct(keep=...)``.

    Examples
    --------
    >>> import numpy as np
    >>> heights = np.add.outer(np.sin(np.linspace(0, 3, 40)), np.cos(np.linspace(0, 5, 50)))
    >>> dec = decompose_surface(heights, 2)
    >>> dec.coarse().shape, bool(np.allclose(dec.reconstruct(), heights))
    ((12, 14), True)
    """
    if fit not in ("pad", "resample"):
        msg = f"fit must be 'pad' (exact) or 'resample' (section 4.5), not {fit!r}"
        raise InvalidParameter(msg)
    arr = as_float_array(grid)
    if arr.ndim not in (2, 3):
        msg = f"a surface must be points (U, V, d) or a height field (U, V), not shape {arr.shape}"
        raise InvalidParameter(msg)
    if not np.all(np.isfinite(arr)):
        msg = "a surface must be finite (no NaN or infinity)"
        raise InvalidParameter(msg)
    bank = get_wavelet(wavelet)
    if level is None:
        level = default_level(arr.shape[:2])  # the library's one rule, as encode_surface's
    level = as_int(level, "level", minimum=1)
    fitted, grid_fit = fit_grid(
        arr, level, axes=(0, 1), boundary=boundary, wavelet=bank, method=fit
    )
    coeffs = wavedecn(fitted, bank, grid_fit.boundaries, level, axes=(0, 1))
    return SurfaceDecomposition(coeffs, grid_fit, bank.name, arr.ndim == 2)
