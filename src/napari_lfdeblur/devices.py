"""Choice of the torch device the solvers run on."""

from __future__ import annotations

import torch

from ._memory import host_available_memory

__all__ = ["select_device", "free_memory"]

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
        If the name is not known, or CUDA is asked for and not available.
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
