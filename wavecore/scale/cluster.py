"""A local ``dask.distributed`` cluster set up for the codec: one thread per worker process,
one malloc arena, and glibc's thresholds set for chunk-sized arrays.

Dask's nanny starts each worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (to hand freed memory
back to the system).  Setting that variable alone fixes glibc's mmap threshold at 128 KiB, so
every full-size float64 array the codec makes is a fresh mapping whose pages the kernel zeroes
and faults in one by one.  Measured on this project's benchmark field (2048², 1 MiB chunks, a
worker of one thread): 14 MB per CPU-second with the variable, 25-32 without; in one process,
22 against 35-40.  The workers get a trim threshold of 8 MiB with an mmap threshold of 32 MiB
instead (:data:`WORKER_CONFIG`): arrays of a chunk's size come from the heap and are reused,
and only free memory beyond 8 MiB at the heap's top goes back to the system.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import dask

from ..errors import InvalidParameter

#: The Dask configuration the workers are spawned under (``distributed.nanny.pre-spawn-environ``;
#: ``None`` would unset a variable that the nanny sets otherwise).  ``MALLOC_ARENA_MAX``: a
#: worker's threads (Dask's executor, Zarr's event loop, its file threads) share one glibc
#: arena, so an array freed by one is reused by the next that asks (the resident rise per
#: worker fell from 5.1 to 4.1 bytes per chunk byte, its constant from 9.7 to 4.8 MiB, at no
#: measured CPU cost).  ``MALLOC_MMAP_THRESHOLD_`` (32 MiB, the ceiling of glibc's dynamic one):
#: arrays below it come from the heap, where the dynamic threshold puts them after a first
#: chunk of their size; it must be given, as a trim threshold alone fixes it at 128 KiB.
#: ``MALLOC_TRIM_THRESHOLD_`` (8 MiB): free memory beyond it at the heap's top goes back to
#: the system when freed.  glibc's dynamic one is twice the mmap threshold, 32 MiB after a
#: 16 MiB chunk: the bytes Zarr read the chunk from stayed resident beside the coder's float64
#: grid, and the resident rise per worker was 3.8-4.2 bytes per chunk byte over 1-16 MiB
#: chunks; with 8 MiB it follows the allocations (about 3: the chunk and its float64 copy),
#: and chunks up to 1 MiB (a few MiB of arrays) are never trimmed (docs/scale.md).
WORKER_CONFIG: dict[str, Any] = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": str(8 << 20),
    "distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": str(32 << 20),
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

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        # LocalCluster takes 0 or fewer and waits for ever for a worker to take the tasks
        msg = f"workers must be a whole number of processes >= 1, not {workers!r}"
        raise InvalidParameter(msg)
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
