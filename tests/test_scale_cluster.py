"""wavecore.scale.local_cluster: worker processes spawned with the codec's malloc settings, not
Dask's trim threshold."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("zarr", reason="the Zarr tests need the zarr extra (pip install '.[zarr]')")
distributed = pytest.importorskip("dask.distributed", reason="the zarr extra installs it")

from wavecore.scale import WORKER_CONFIG, local_cluster  # noqa: E402

_MALLOC_NAMES = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_ARENA_MAX")


def _worker_environ() -> tuple[tuple[str | None, ...], int]:
    return tuple(os.environ.get(name) for name in _MALLOC_NAMES), os.getpid()


@pytest.mark.skipif(
    any(name in os.environ for name in _MALLOC_NAMES),
    reason="variables set in this shell reach the workers whatever the configuration",
)
def test_local_cluster_workers_get_the_codecs_malloc_settings() -> None:
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in every worker by default, which fixes
    # glibc's mmap threshold at 128 KiB and made the codec ~2x slower per CPU-second; the
    # workers get an mmap threshold of 32 MiB beside a trim threshold of 8 MiB (docs/scale.md).
    with local_cluster(1) as cluster, distributed.Client(cluster) as client:
        seen = list(client.run(_worker_environ).values())
        info = client.scheduler_info()
    assert len(seen) == 1
    values, pid = seen[0]
    assert values == (str(8 << 20), str(32 << 20), "1")
    assert int(values[0]) > 65536  # not Dask's default
    assert pid != os.getpid()  # a worker process, not a thread of this one
    assert all(w["nthreads"] == 1 for w in info["workers"].values())
    # The setting applies only while the cluster is made: the caller's configuration is intact.
    import dask

    key = next(iter(WORKER_CONFIG))
    assert dask.config.get(key) is not None


def _probe_environ() -> tuple[str | None, ...]:
    names = ("WAVECORE_PROBE_WORKER_ENV", "MALLOC_TRIM_THRESHOLD_", "MALLOC_ARENA_MAX")
    return tuple(os.environ.get(name) for name in names)


@pytest.mark.skipif(
    any(
        name in os.environ
        for name in ("WAVECORE_PROBE_WORKER_ENV", "MALLOC_TRIM_THRESHOLD_", "MALLOC_ARENA_MAX")
    ),
    reason="variables set in this shell reach the workers whatever the configuration",
)
def test_local_cluster_environ_reaches_only_the_workers() -> None:
    # environ= adds variables to the worker processes (a memory setting for a tight cluster),
    # on top of WORKER_CONFIG (one malloc arena: the resident rise per chunk byte, docs/scale.md),
    # and neither reaches this process.
    with (
        local_cluster(1, environ={"WAVECORE_PROBE_WORKER_ENV": "on"}) as cluster,
        distributed.Client(cluster) as client,
    ):
        seen = list(client.run(_probe_environ).values())
    assert seen == [("on", str(8 << 20), "1")]
    assert "WAVECORE_PROBE_WORKER_ENV" not in os.environ
    assert "MALLOC_ARENA_MAX" not in os.environ
