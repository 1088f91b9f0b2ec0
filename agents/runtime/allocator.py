"""The C allocator's settings for torch's CPU tensors: freed memory kept for reuse (training sets it once)."""

from __future__ import annotations

import platform
import sys

# glibc's mallopt parameters (malloc.h) and their values here: blocks up to 32 MiB (the largest mmap threshold glibc
# accepts) come from the heap, and the heap keeps up to 1 GiB of freed memory instead of returning it to the system.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD_BYTES, _TRIM_THRESHOLD_BYTES = 32 << 20, 1 << 30


def keep_freed_memory() -> bool:
    """Let the C allocator reuse freed memory for torch's CPU tensors instead of handing it back to the system.

    torch allocates each minibatch's activations and gradients anew (megabytes each). glibc serves such blocks with
    fresh mmap pages and unmaps them when freed, so every minibatch pays for tens of thousands of page faults and
    cold pages (measured: ~45k faults per update of the MortarMayhemB-Grid benchmark; ~25k with this). Returns
    whether the setting took effect (glibc only; elsewhere nothing changes).
    """
    if sys.platform != "linux" or platform.libc_ver()[0] != "glibc":
        return False
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return False
    return bool(
        libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)
        and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD_BYTES)
    )
