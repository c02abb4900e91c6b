"""A local ``dask.distributed`` cluster set up for the codec: one thread per worker process,
glibc's own memory thresholds and one malloc arena in the workers.

Dask's nanny starts each worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (to hand freed memory
back to the system).  Setting that variable at all fixes glibc's mmap threshold at 128 KiB, so
every full-size float64 array the codec makes is a fresh mapping whose pages the kernel zeroes
and faults in one by one.  Measured on this project's benchmark field (2048², 1 MiB chunks, a
worker of one thread): 14 MB per CPU-second with the variable, 25-32 without; in one process,
22 against 35-40.  Without it glibc adapts its thresholds and reuses the freed arrays; the
memory a worker keeps between tasks is then what its largest chunk needed.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import dask

#: The Dask configuration the workers are spawned under: ``None`` unsets a variable that the
#: nanny would otherwise set (``distributed.nanny.pre-spawn-environ``).  ``MALLOC_ARENA_MAX``:
#: a worker's threads (Dask's executor, Zarr's event loop, its file threads) share one glibc
#: arena, so an array freed by one is reused by the next that asks, instead of each thread's
#: arena keeping its own; the resident rise per worker fell from 5.1 to 4.1 bytes per chunk
#: byte (and its constant from 9.7 to 4.8 MiB) at no measured CPU cost (docs/scale.md).
WORKER_CONFIG: dict[str, Any] = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.nanny.pre-spawn-environ.MALLOC_ARENA_MAX": "1",
}


def local_cluster(
    workers: int, *, environ: Mapping[str, str | None] | None = None, **options: Any
) -> Any:
    """A ``dask.distributed.LocalCluster`` of ``workers`` processes of one thread each.

    One thread per process: a chunk's coding has Python parts between its compiled kernels
    (and the interpolation coder runs on one thread), so it scales by processes: 1 -> 2
    workers measured 1.5-2.3x in ``benchmarks/zarr_scale.py``.  The workers are spawned under
    :data:`WORKER_CONFIG`.

    Parameters
    ----------
    workers : int
        Worker processes.
    environ : mapping, optional
        More environment variables for the worker processes only (``None`` unsets one), on
        top of :data:`WORKER_CONFIG`: e.g. ``{"MALLOC_MMAP_THRESHOLD_": "524288"}`` for a
        memory-tight cluster (docs/scale.md, "Memory per chunk").
    **options
        Passed on to ``LocalCluster`` (``memory_limit``, ``dashboard_address``, ...).

    Returns
    -------
    dask.distributed.LocalCluster
        Close it (or use it in a ``with`` block) when done.
    """
    from dask.distributed import LocalCluster

    settings: dict[str, Any] = {"threads_per_worker": 1, "dashboard_address": None}
    settings.update(options)
    config = dict(WORKER_CONFIG)
    for name, value in (environ or {}).items():
        config[f"distributed.nanny.pre-spawn-environ.{name}"] = value
    # Dask's nanny runs in this process and puts its pre-spawn variables into os.environ
    # before it spawns a worker: ours are put back afterwards, so that they stay the workers'.
    names = {key.rsplit(".", 1)[1] for key in config}
    before = {name: os.environ.get(name) for name in names}
    try:
        with dask.config.set(config):
            return LocalCluster(n_workers=workers, processes=True, **settings)
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
