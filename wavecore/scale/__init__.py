"""Data larger than one machine's request: multiscale pyramids in Zarr, built by Dask.

Needs the zarr extra (``pip install 'wavecore[zarr]'``); ``import wavecore`` never loads it.
"""

from __future__ import annotations

from .cluster import WORKER_CONFIG, local_cluster
from .pyramid import (
    PyramidInfo,
    open_image_source,
    read_region,
    synthetic_rgb,
    write_pyramid,
)

__all__ = [
    "WORKER_CONFIG",
    "PyramidInfo",
    "local_cluster",
    "open_image_source",
    "read_region",
    "synthetic_rgb",
    "write_pyramid",
]
