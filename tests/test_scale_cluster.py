"""wavecore.scale.local_cluster: worker processes spawned without Dask's malloc trim setting."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("zarr", reason="the Zarr tests need the zarr extra (pip install '.[zarr]')")
distributed = pytest.importorskip("dask.distributed", reason="the zarr extra installs it")

from wavecore.scale import WORKER_CONFIG, local_cluster  # noqa: E402


def _worker_environ() -> tuple[str | None, int]:
    return os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.getpid()


@pytest.mark.skipif(
    "MALLOC_TRIM_THRESHOLD_" in os.environ,
    reason="the variable set in this shell reaches the workers whatever the configuration",
)
def test_local_cluster_workers_keep_glibc_thresholds() -> None:
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in every worker by default, which fixes
    # glibc's mmap threshold and made the codec ~2x slower per CPU-second (docs/scale.md).
    with local_cluster(1) as cluster, distributed.Client(cluster) as client:
        seen = list(client.run(_worker_environ).values())
        info = client.scheduler_info()
    assert len(seen) == 1
    value, pid = seen[0]
    assert value is None
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
    assert seen == [("on", None, "1")]
    assert "WAVECORE_PROBE_WORKER_ENV" not in os.environ
    assert "MALLOC_ARENA_MAX" not in os.environ
