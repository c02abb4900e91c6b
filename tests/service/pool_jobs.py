"""Module-level jobs for the work-pool tests (the worker processes import them by name)."""

from __future__ import annotations

import os
import time
from pathlib import Path


def spin(pid_file: str, seconds: float) -> int:
    """Write this worker's process id, then burn CPU for ``seconds``."""
    Path(pid_file).write_text(str(os.getpid()))
    end = time.monotonic() + seconds
    count = 0
    while time.monotonic() < end:
        count += 1
    return count


def run_out_of_memory() -> None:
    raise MemoryError


def die() -> None:
    os._exit(3)


def worker_pid() -> int:
    return os.getpid()


class TwoArgumentError(Exception):
    """An exception whose ``__init__`` needs two arguments: it cannot be unpickled as is."""

    def __init__(self, value: int, reason: str) -> None:
        super().__init__(f"{value}: {reason}")


def raise_unpicklable() -> None:
    raise TwoArgumentError(7, "seven is not accepted")


def allocate(pid_file: str, nbytes: int) -> int:
    """Write this worker's process id, then fill ``nbytes`` of memory in 64 MiB pieces."""
    import numpy as np

    Path(pid_file).write_text(str(os.getpid()))
    pieces = [np.ones(64 << 20, dtype=np.uint8) for _ in range(nbytes >> 26)]
    return len(pieces)


def library_threads() -> str:
    """The library's thread count as the worker's environment sets it."""
    return os.environ.get("WAVECORE_THREADS", "")


def encode_faults() -> int:
    """The page faults of one 512² encode in this worker (the heap it finds decides them)."""
    import resource

    from skimage import data

    import wavecore

    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    wavecore.encode_image(data.camera())
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


def encode_large() -> int:
    """A 1024² RGB encode at 1 bpp: its freed heap is fragmented (glibc still counts some
    85 MiB of it as free after a trim)."""
    import numpy as np
    from skimage import data

    import wavecore

    return len(wavecore.encode_image(np.tile(data.astronaut(), (2, 2, 1)), bpp=1.0))
