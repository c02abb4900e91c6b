"""The C heap: keep freed working memory mapped between codings (glibc only).

glibc hands the free memory at the top of its heap back to the system once more than its trim
threshold lies there, and takes it back page by page, each page a fault, on the next growth;
arrays above its mmap threshold are mapped and unmapped afresh each time.  An encode frees its
working arrays (a 512² grey picture: a few MB of float bands, integers and reconstructions) and
the next one faults them in again: 1 200 page faults and about 2.5 ms of system time per
``encode_image(camera)``, a tenth of its CPU time (measured with ``getrusage``).  Two settings
keep them mapped:

* ``M_TOP_PAD``, 16 MiB: that much free memory past the top stays mapped when the heap
  shrinks.  The 512² grey encode then faults about 40 times (4 MiB left 1 100 faults).
* ``M_MMAP_THRESHOLD``, 32 MiB, glibc's own ceiling for the threshold it adapts: setting the
  pad stops that adaptation, so the threshold is set to where it would end up.  Without it a
  2048² RGB encode faulted twice as often; with it, fewer times than with glibc's defaults
  (5 700 against 8 900 faults per encode, about 0 against 5 200 per decode).

At most the pad stays resident beyond what the arrays need (the largest resident size of a
2048² RGB encode and decode grew by about 4 MB, 0.7 %).  The settings are the process's, so
they are made once, only on glibc, and never over the user's own tuning of glibc's allocator
(``MALLOC_*`` environment variables or ``GLIBC_TUNABLES``), which takes precedence.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import platform

#: glibc's ``mallopt`` parameter numbers (malloc.h).
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3
TOP_PAD_BYTES = 16 << 20
MMAP_THRESHOLD_BYTES = 32 << 20


def keep_freed_memory() -> bool:
    """Set glibc's top pad and mmap threshold (see the module docstring); whether they were.

    Nothing happens off glibc, or when the environment already tunes glibc's allocator.
    """
    if platform.libc_ver()[0] != "glibc":
        return False
    if any(name.startswith("MALLOC_") for name in os.environ) or "GLIBC_TUNABLES" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        threshold = libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        return bool(threshold and libc.mallopt(_M_TOP_PAD, TOP_PAD_BYTES))
    except (OSError, AttributeError):  # pragma: no cover - a libc without mallopt
        return False
