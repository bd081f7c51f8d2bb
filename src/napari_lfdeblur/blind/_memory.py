"""Memory of blind deblurring: a peak estimate, the tile plan when it does not fit, the tiles."""

from __future__ import annotations

import math
import numbers

import torch

from ._params import BlindParams
from ._region import region_grid

__all__ = ["estimate_blind_memory", "plan_tiles", "plan_run", "tiled_peak", "check_max_memory", "within", "tiles",
           "tile_for_margin", "TILE_MARGIN", "MIN_TILE", "FINAL_TENSORS"]

#: overlap (px) of neighbouring tiles in the final stage, on top of what ``d_inf`` shifts
TILE_MARGIN = 12
#: smallest tile side (px) worth working on
MIN_TILE = 32
#: one-channel float32 tensors alive at once in the final stage, besides the result (see estimate_blind_memory)
FINAL_TENSORS = 15


def estimate_blind_memory(shape, params: BlindParams | None = None) -> int:
    """An estimate of the peak memory of blind deblurring, in bytes.

    Counts the light-field-sized float32 tensors alive at once in the final
    (colour) TV stage and in the grayscale path stage (on its window of
    ``params.path.region`` px), plus the blur operator's blocks and
    interpolation tables.

    Parameters
    ----------
    shape : tuple, (V, U, Y, X[, C])
    params : BlindParams, optional

    Returns
    -------
    int
    """
    return _memory_of_stages(shape, params)[0]


def _memory_of_stages(shape, params):
    """``(whole run, path stage alone)``: the peak memory estimates of :func:`estimate_blind_memory`."""
    p = params or BlindParams()
    shape = tuple(int(s) for s in shape)
    V, U, Y, X = shape[:4]
    C = shape[4] if len(shape) == 5 else 1
    n = V * U * Y * X
    # the final stage solves one colour channel at a time (all at once with the colour TV); float32
    # tensors of one group's size: the group's data (1; it is also the start), FISTA's iterates x,
    # x_new, y and two scratch buffers, K x, K y, K x_new, the residual and the gradient (10), the
    # TV prox's dual field (4; its primal and dual norm use FISTA's scratch); and the result, all channels
    group = C if p.final is not None and p.final.couple_channels else 1
    final = n * 4 * (FINAL_TENSORS * group + C) if p.final is not None else n * 4 * C  # else: the input's copy
    r = p.path.region
    ny, nx = (min(Y, r), min(X, r)) if r else (Y, X)
    rows, cols = region_grid(Y, X, r, p.path_windows()) if r and (ny, nx) != (Y, X) else (1, 1)
    # the full-size input and its grayscale and refocused copies (with the refocus's buffers for one row of
    # views: the mirrored extension, its spectrum and the shifted extension, 12 floats a pixel), then the
    # windows' path stage: each window's f and latent, and one window's CG vectors, gradients and autograd
    # buffers (grayscale)
    path = n * C * 4 + n * 4 * 2 + U * Y * X * 4 * 12 + V * U * ny * nx * 4 * (2 * rows * cols + 14)
    tables = 4 * max(p.n_times, p.final_n_times) * (X * U * U + Y * V * V) * 2
    blocks = 4 * (1 << 22) * 3
    return int(max(final, path) + tables + blocks), int(path + tables + blocks)


def plan_tiles(shape, params: BlindParams | None, free: int | None, result_in_free: bool = True):
    """The tile size ``(ty, tx)`` to work in when the whole light field does not fit, else None.

    The largest square-ish tiles (plus :data:`TILE_MARGIN` on each side) whose
    :func:`estimate_blind_memory` fits in ``free`` bytes, after the full-size
    result is set aside (when ``result_in_free``: on the CPU, where the result
    lives; a GPU sends each tile's result to the host). None when ``free`` is
    unknown or enough. The tiles are :data:`MIN_TILE` px when even those do
    not fit.

    Parameters
    ----------
    shape : tuple, (V, U, Y, X[, C])
    params : BlindParams, optional
    free : int or None
        Bytes available.
    result_in_free : bool, default True

    Returns
    -------
    tuple of 2 int, or None
    """
    p = params or BlindParams()
    shape = tuple(int(v) for v in shape)
    if free is None or estimate_blind_memory(shape, p) <= free:
        return None
    V, U, Y, X = shape[:4]
    C = shape[4] if len(shape) == 5 else 1
    budget = free - (4 * V * U * Y * X * C if result_in_free else 0)  # the result, full size
    side = max(Y, X)
    while side > MIN_TILE and _tile_memory(shape, p, (side, side)) > budget:
        side = max(MIN_TILE, int(side * 0.8))
    return min(Y, side), min(X, side)


def tiled_peak(shape, params: BlindParams | None, tile) -> int:
    """The peak memory estimate (bytes) of a run restored in ``tile`` px tiles: its path stage's (the whole
    input and the work on the windows), or the full-size result and one tile's work, whichever is larger."""
    p = params or BlindParams()
    result = 4 * math.prod(int(v) for v in shape)  # float32, all channels
    return max(_memory_of_stages(shape, p)[1], result + _tile_memory(shape, p, tile))


def _tile_memory(shape, p: BlindParams, tile) -> int:
    """:func:`estimate_blind_memory` of one tile of ``tile`` px with its overlap."""
    V, U, Y, X = shape[:4]
    ty, tx = min(Y, tile[0] + 2 * TILE_MARGIN), min(X, tile[1] + 2 * TILE_MARGIN)
    return estimate_blind_memory((V, U, ty, tx) + tuple(shape[4:]), p)


def plan_run(shape, params: BlindParams | None, device, free_memory):
    """Where a blind run goes: ``(device, tile)``, the device to run on and the tile plan (or None).

    On the CPU, a light field that does not fit is restored in tiles
    (:func:`plan_tiles`). On a GPU, too, when the path stage fits on it
    whole (it works on windows of the full frame) and the final stage fits
    in tiles (their results go to the host as they are done); otherwise the
    run goes to the CPU.

    Parameters
    ----------
    shape : tuple, (V, U, Y, X[, C])
    params : BlindParams, optional
    device : torch.device
    free_memory : callable
        ``free_memory(device)``: bytes free on a device, or None when
        unknown (:func:`napari_lfdeblur.devices.free_memory`).

    Returns
    -------
    device : torch.device
    tile : tuple of 2 int, or None
    """
    p = params or BlindParams()
    if device.type == "cuda":
        free = free_memory(device)
        tile = plan_tiles(shape, p, free, result_in_free=False)
        if tile is None:
            return device, None
        if _memory_of_stages(shape, p)[1] <= free and _tile_memory(shape, p, tile) <= free:
            return device, tile
        device = torch.device("cpu")
    return device, plan_tiles(shape, p, free_memory(device))


def check_max_memory(max_memory) -> int | None:
    """``max_memory`` as whole bytes (None stays None); a finite number of at least 1 byte, else an error."""
    if max_memory is None:
        return None
    if isinstance(max_memory, bool) or not isinstance(max_memory, numbers.Real):
        raise TypeError(f"max_memory must be a number of bytes or None; got {max_memory!r}")
    if not math.isfinite(max_memory) or max_memory < 1:  # a fraction of a byte would be a cap of 0
        raise ValueError(f"max_memory must be at least 1 byte; got {max_memory!r}")
    return int(max_memory)


def within(free_memory, cap: int | None):
    """``free_memory`` (a function of the device) limited to ``cap`` bytes; ``cap`` where it is unknown."""
    if cap is None:
        return free_memory

    def available(device):
        free = free_memory(device)
        return cap if free is None else min(free, cap)

    return available


def tile_for_margin(tile, margin: int, Y: int, X: int) -> tuple[int, int]:
    """The tile to cut a Y x X image into with ``margin``, so that no tile with it is larger than the plan's.

    :func:`plan_tiles` budgets for ``tile`` plus :data:`TILE_MARGIN` on each
    side; a wider ``margin`` (the final stage's at ``d_inf != 0``, known once
    the path is) takes its extra width from the tile, along each axis the
    tiles split (down to :data:`MIN_TILE`, never up).
    """
    extra = max(0, margin - TILE_MARGIN)
    return tuple(t if t >= n else max(min(t, MIN_TILE), t - 2 * extra) for t, n in zip(tile, (Y, X)))


def tiles(Y: int, X: int, tile, margin: int):
    """``(core, padded)`` slices (y, x) covering a Y x X image with tiles of ``tile`` and ``margin``.

    Yields
    ------
    core, padded : tuple of 2 slice
        The tile itself (the tiles cover the image exactly once) and the
        tile grown by ``margin`` on each side, clipped to the image.
    """
    ty, tx = tile
    for y0 in range(0, Y, ty):
        for x0 in range(0, X, tx):
            y1, x1 = min(Y, y0 + ty), min(X, x0 + tx)
            py0, px0 = max(0, y0 - margin), max(0, x0 - margin)
            py1, px1 = min(Y, y1 + margin), min(X, x1 + margin)
            yield (slice(y0, y1), slice(x0, x1)), (slice(py0, py1), slice(px0, px1))
