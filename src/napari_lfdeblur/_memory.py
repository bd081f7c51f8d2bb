"""Host memory: how much is free, for checks before large allocations, and handing freed memory back.

No torch, no Qt.
"""

from __future__ import annotations

import ctypes
import sys

__all__ = ["host_available_memory", "release_host_memory"]


def host_available_memory() -> int | None:
    """Bytes of host memory available now, or None when unknown.

    ``psutil`` when installed, else ``MemAvailable`` of ``/proc/meminfo``.
    """
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 - psutil missing or failing
        pass
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def release_host_memory() -> None:
    """Hand freed heap memory back to the operating system, where the C library can (glibc's ``malloc_trim``).

    glibc keeps freed blocks below its mmap threshold in the process's heap, and raises that threshold
    (up to 32 MiB) each time a larger block is freed. A run that allocates and frees many blocks of
    tens of MiB, such as a final stage restored tile by tile, then holds far more resident memory than
    it uses. A no-op off Linux and where ``malloc_trim`` is missing.
    """
    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass
