"""The C heap: keep freed working memory mapped between codings (glibc only).

glibc hands the free memory at the top of its heap back to the system once more than its trim
threshold lies there, and takes it back page by page, each page a fault, on the next growth;
arrays above its mmap threshold (at most 32 MiB) are mapped and unmapped afresh each time.  An
encode frees its working arrays and the next one faults them in again: a 512² grey
``encode_image(camera)`` faulted 1 200 pages (about 2.5 ms of system time, a tenth of its CPU),
and a 2048² RGB encode at 1 bpp, whose float planes are 32 MiB each, 2 700 pages an encode and
1 000 a decode even with the pad and threshold below.  Page faults are also where two threads
lose most against one: the kernel serialises them on the process's address space.  Three
settings keep that memory mapped:

* ``M_MMAP_MAX`` 0: no array gets a mapping of its own; every one comes from the heap, whose
  freed memory is reused by the next coding (the 2048² RGB encode then faults about 10 pages).
* ``M_TRIM_THRESHOLD``, 256 MiB: the heap gives back the free memory at its top only beyond
  that much, so a process holds at most about 256 MiB more than its arrays need between
  codings (``malloc_trim`` gives it back at once: the service's workers call it after each job).
* ``M_TOP_PAD``, 16 MiB: the heap grows by at least that much, so a small coding's growth
  costs few system calls.

The settings are the process's, so they are made once, only on glibc, and never over the
user's own tuning of glibc's allocator (``MALLOC_*`` environment variables or
``GLIBC_TUNABLES``), which takes precedence.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import platform

#: glibc's ``mallopt`` parameter numbers (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_MAX = -4
TRIM_THRESHOLD_BYTES = 256 << 20
TOP_PAD_BYTES = 16 << 20


def keep_freed_memory() -> bool:
    """Make glibc keep freed memory mapped (see the module docstring); whether it was set.

    Nothing happens off glibc, or when the environment already tunes glibc's allocator.
    """
    if platform.libc_ver()[0] != "glibc":
        return False
    if any(name.startswith("MALLOC_") for name in os.environ) or "GLIBC_TUNABLES" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        settings = (
            (_M_MMAP_MAX, 0),
            (_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES),
            (_M_TOP_PAD, TOP_PAD_BYTES),
        )
        return all([libc.mallopt(parameter, value) for parameter, value in settings])
    except (OSError, AttributeError):  # pragma: no cover - a libc without mallopt
        return False
