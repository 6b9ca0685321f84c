"""Keep freed memory in the process: the simulator's step reuses the same large temporaries.

A batched step allocates and frees the same few hundred kilobyte-to-megabyte arrays every time.
glibc serves blocks above its mmap threshold (128 KiB at first) with fresh mappings and returns
them, and trims the top of the heap, on every free: the next step faults the same pages in
again — about 700 page faults and 1.5 ms of system time per step at 5u1o × 1,024, 15% of it.
`keep_freed_memory` raises both thresholds so that freed blocks stay for the next step.

Called explicitly by the entry points that step the simulator for long (``remarl-fc``'s
commands, the benchmark tools); importing this module changes nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util

M_TRIM_THRESHOLD = -1
"""glibc mallopt parameter: free memory at the top of the heap kept before trimming (bytes)."""

M_MMAP_THRESHOLD = -3
"""glibc mallopt parameter: requests at least this large are served by mmap (bytes)."""

MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
"""Blocks below 32 MiB come from the heap: glibc's largest allowed mmap threshold on 64-bit
(DEFAULT_MMAP_THRESHOLD_MAX); a step's temporaries are far smaller (a 50u8o × 1,024 sub-step
grid is 2.4 MB)."""

TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024
"""Up to 256 MiB of freed heap is kept for reuse instead of being returned to the system."""


def keep_freed_memory() -> bool:
    """Ask the C allocator to keep freed memory for reuse; False where it is not glibc."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    kept = mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
    trimmed = mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    return bool(trimmed and kept)
