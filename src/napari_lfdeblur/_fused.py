"""The tap blur, its adjoint and its kernel gradient as fused CPU loops (numba).

A tap kernel is ``S`` weight maps ``K[s]`` of shape ``(Y, X)`` with integer
offsets ``(a, b, c, e)`` of ``(v, y, u, x)``::

    f[v, u, y, x] = sum_s K[s, y, x] l[clamp(v + a), clamp(u + c), clamp(y + b), clamp(x + e)]

(:mod:`~napari_lfdeblur._taps` at ``d_inf = 0``, where ``b = e = 0``, and
:mod:`~napari_lfdeblur._taps4d` otherwise). The torch versions make one
multiply-add pass over a block of the light field per tap, through padded
copies. These loops instead make one pass over the output, row by row in
parallel: the rows a tap reads stay in cache, nothing is padded or copied,
and the ``x`` loop is contiguous in ``(x, channel)``. Sums run over the taps
in the same order, so the forward agrees with the torch version to rounding.

The adjoint is written as a gather over the output rows of the adjoint (each
thread owns the rows it writes), so it needs no atomic adds. Clamped indices
make edge rows and columns collect the terms of every sample read beyond
the edge, as the model's replicate boundary does.

Used on the CPU when numba imports; ``NAPARI_LFDEBLUR_NUMBA=0`` turns it off
(then the torch versions run). The kernels are compiled on first use and
cached on disk by numba.
"""

from __future__ import annotations

import functools
import os
import threading

import numpy as np
import torch

__all__ = ["available", "FusedTaps"]

_LOCK = threading.Lock()  # numba's default thread pool runs one parallel loop at a time


@functools.lru_cache(maxsize=1)
def _loops():
    """The module of compiled loops, or None when numba is missing, broken or turned off."""
    if os.environ.get("NAPARI_LFDEBLUR_NUMBA", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    try:
        from . import _fused_loops
    except Exception:  # noqa: BLE001 - numba not installed, or built for another numpy
        return None
    return _fused_loops


def available(device) -> bool:
    """True when the fused loops can run on ``device`` (the CPU, with numba)."""
    return torch.device(device).type == "cpu" and _loops() is not None


def _run(name, *args):
    import numba

    with _LOCK:
        numba.set_num_threads(max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS)))
        getattr(_loops(), name)(*args)


class FusedTaps:
    """A tap kernel applied by the fused loops: the interface of :class:`~napari_lfdeblur._taps.Taps`.

    Parameters
    ----------
    shape : tuple
        ``(V, U, Y, X, C)`` of the light fields.
    K : torch.Tensor, shape (S, Y, X), on the CPU
        The taps' weight maps (detached here).
    offsets : torch.Tensor or sequence, int, shape (S, 4)
        The ``(a, b, c, e)`` offsets of ``(v, y, u, x)`` of each tap.
    to_kernel : callable, optional
        Maps the gradient for ``K`` (S, Y, X) to the shape the caller's
        kernel has (see :meth:`angular`).
    """

    def __init__(self, shape, K, offsets, to_kernel=None):
        self.shape = tuple(shape)
        self.to_kernel = to_kernel
        V, U, Y, X, C = self.shape
        self.K = K.detach().contiguous()
        self.offsets = np.ascontiguousarray(np.asarray(offsets, dtype=np.int64).reshape(-1, 4))
        used = self.K != 0  # (S, Y, X): the columns each tap weighs something in, per row
        any_x = used.any(dim=2)
        first = used.to(torch.uint8).argmax(dim=2)
        past = X - used.flip(2).to(torch.uint8).argmax(dim=2)
        self.x0 = torch.where(any_x, first, 0).numpy().astype(np.int64)
        self.x1 = torch.where(any_x, past, 0).numpy().astype(np.int64)

    @classmethod
    def angular(cls, shape, K, ov, ou):
        """The ``d_inf = 0`` kernel of :func:`~napari_lfdeblur._taps.tap_kernel`, ``K`` (Y, X, Dv, Du).

        Only offsets that carry weight somewhere become taps; the kernel
        gradient comes back as ``(Y, X, Dv, Du)``, zero at the others.
        """
        Kd = K.detach()
        active = (Kd.abs().amax(dim=(0, 1)) > 0).nonzero().tolist()
        stack = torch.stack([Kd[:, :, i, j] for i, j in active])

        def to_kernel(g):
            out = g.new_zeros(K.shape)
            for s, (i, j) in enumerate(active):
                out[:, :, i, j] = g[s]
            return out

        return cls(shape, stack, [(ov + i, 0, ou + j, 0) for i, j in active], to_kernel)

    def _rows(self, t):
        """``t`` (V, U, Y, X, C) as a numpy view of rows (V, U, Y, X * C)."""
        V, U, Y, X, C = self.shape
        return t.detach().contiguous().numpy().reshape(V, U, Y, X * C)

    def _weights(self, dtype):
        return self.K.to(dtype).numpy()

    def forward(self, L):
        out = torch.empty(self.shape, dtype=L.dtype)
        _run("forward", self._rows(L), self._weights(L.dtype), self.offsets, self.x0, self.x1, self._rows(out))
        return out

    def backward(self, L, G, need_L=True, need_K=False):
        """``(adjoint(G), d<G, forward(L)>/dK)``, each None when not needed."""
        gL = gK = None
        if need_L:
            gL = torch.empty(self.shape, dtype=G.dtype)
            _run("adjoint", self._rows(G), self._weights(G.dtype), self.offsets, self.x0, self.x1, self._rows(gL))
        if need_K:
            gK = torch.empty(self.K.shape, dtype=G.dtype)
            _run("kernel_grad", self._rows(L.to(G.dtype)), self._rows(G), self.offsets, gK.numpy())
            gK = gK.to(self.K.dtype)
            if self.to_kernel is not None:
                gK = self.to_kernel(gK)
        return gL, gK

    def adjoint(self, G):
        return self.backward(None, G, need_L=True, need_K=False)[0]
