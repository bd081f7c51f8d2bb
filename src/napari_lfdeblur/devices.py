"""Choice of the torch device the solvers run on."""

from __future__ import annotations

import torch

__all__ = ["select_device"]

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
