"""Imported by the work pool's fork server (multiprocessing's preload list): warms it.

Imported there, it warms every kernel once (:func:`service.work.warm_up`), so each worker
forked from the fork server starts warm, and a worker that replaces a killed one takes jobs
at once instead of spending seconds of CPU loading numba's cache.  The warm-up's inputs are
too small for the library's thread pool, so the fork server stays single-threaded, safe to
fork.  Imported anywhere else (a test collecting doctests), it does nothing.
"""

from __future__ import annotations

import contextlib
import inspect

from . import work


def _imported_by_the_fork_server() -> bool:
    return any(
        frame.frame.f_globals.get("__name__") == "multiprocessing.forkserver"
        for frame in inspect.stack(0)
    )


if _imported_by_the_fork_server():
    # A failed warm-up must not take the fork server down: the workers then warm themselves.
    with contextlib.suppress(Exception):
        work.warm_up()
