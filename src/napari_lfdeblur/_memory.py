"""Free host memory, for checks before large allocations (no torch, no Qt)."""

from __future__ import annotations

__all__ = ["host_available_memory"]


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
