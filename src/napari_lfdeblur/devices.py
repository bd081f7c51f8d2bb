"""Choice of the torch device the solvers run on, its free memory, and the fall-back to the CPU."""

from __future__ import annotations

import warnings

import torch

from ._memory import host_available_memory

__all__ = ["select_device", "free_memory", "empty_cache", "run_with_cpu_fallback"]

_CHOICES = ("auto", "cpu", "cuda")


def select_device(device: str | torch.device | None = "auto") -> torch.device:
    """Return the torch device to compute on.

    Parameters
    ----------
    device : {'auto', 'cpu', 'cuda'}, torch.device or None
        ``'auto'`` (or None) picks CUDA when it is available and the CPU
        otherwise. ``'cuda'`` may carry an index (``'cuda:1'``).

    Returns
    -------
    torch.device

    Raises
    ------
    ValueError
        If the name (or the ``torch.device``'s type) is not known, or CUDA is
        asked for and not available, or its index is not one of the GPUs present.
    """
    if device is None or (isinstance(device, str) and device == "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if isinstance(device, torch.device):
        dev = device
    else:
        try:
            dev = torch.device(str(device))
        except RuntimeError:
            dev = None
    if dev is None or dev.type not in _CHOICES:
        raise ValueError(
            f"unknown device {device!r}: choose one of 'auto', 'cpu', 'cuda'"
        )
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            "device 'cuda' was asked for, but no CUDA GPU is available to torch; "
            "use device='auto' or 'cpu'"
        )
    if dev.type == "cpu" and dev.index not in (None, 0):  # torch has one CPU device; 'cpu:1' fails later
        raise ValueError(f"device {str(dev)!r}: the CPU is 'cpu' (it has no index)")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ValueError(f"device {str(dev)!r} was asked for, but torch sees {torch.cuda.device_count()} CUDA GPU(s), "
                         f"numbered from 0")
    return dev


def free_memory(device: str | torch.device | None = "auto") -> int | None:
    """Bytes of memory free on ``device``, or None when unknown.

    CUDA: ``torch.cuda.mem_get_info``; CPU: the host's available memory
    (``psutil`` or ``/proc/meminfo``).
    """
    dev = select_device(device)
    if dev.type == "cuda":  # pragma: no cover - needs a GPU
        free, _ = torch.cuda.mem_get_info(dev)
        return int(free)
    return host_available_memory()


def empty_cache(device: str | torch.device) -> None:
    """Release cached GPU memory and cuBLAS workspaces (a no-op on the CPU); ``device``: a name or torch.device."""
    device = torch.device(device)
    if device.type == "cuda" and torch.cuda.is_available():  # pragma: no cover - needs a GPU
        torch.cuda.synchronize(device)
        clear = getattr(torch._C, "_cuda_clearCublasWorkspaces", None)  # held by the caching allocator
        if clear is not None:
            clear()
        torch.cuda.empty_cache()


def run_with_cpu_fallback(run, device: torch.device):
    """Run the solver generator ``run(device)``; if a CUDA run runs out of memory, run it again on the CPU.

    A generator: yields the records of the run(s) and returns the result.
    The GPU's cache is released after the run (by :func:`empty_cache`), and
    before the CPU run starts the failed run's frames (and with them its GPU
    tensors) are gone. The fall-back is announced by a
    :class:`RuntimeWarning`.

    Parameters
    ----------
    run : callable
        ``run(device)`` returns a solver generator.
    device : str or torch.device
    """
    device = torch.device(device)
    try:
        result = yield from run(device)
        return result
    except torch.cuda.OutOfMemoryError as exc:
        if device.type != "cuda":
            raise
        # leave the except block before going on: its traceback holds the failed run's frames,
        # and with them its GPU tensors
        message = str(exc).splitlines()[0] if str(exc) else "out of memory"
    finally:
        empty_cache(device)
    warnings.warn(f"the GPU ran out of memory ({message}); starting again on the CPU", RuntimeWarning, stacklevel=2)
    result = yield from run(torch.device("cpu"))
    return result
