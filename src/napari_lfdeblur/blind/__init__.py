"""Blind motion deblurring of light fields: the camera path and the sharp light field.

:func:`blind_deblur` (and its generator form :func:`iter_blind_deblur`) takes a
motion-blurred light field and returns both the sharp light field and the 3D
camera path (docs/model.md units, zero-mean gauge), with no depth estimation.
Parameters are a :class:`BlindParams`, nested by stage
(:class:`LatentParams`, :class:`PathFitParams`, :class:`RotationFitParams`, :class:`JointParams` and the
final stage's :class:`~napari_lfdeblur.deconvolution.DeconvolutionParams`);
:data:`PRESETS` names two of them.

Two algorithms, chosen by :attr:`BlindParams.method`:

``'alternating'`` (the ``default`` preset)
    The plain joint MAP estimate is drawn to "no blur": the blurred light
    field itself has a lower sparse-gradient prior than the sharp one (Levin
    et al., 2009; docs/model.md). This method avoids that by design, in the
    manner of Xu et al. (2013) and Pan et al. (2014):

    1. the path is estimated on the grayscale light field, coarse to fine
       over a spatial pyramid (views untouched; ``p_x, p_y`` are in views and
       ``p_z`` in views per normalised ``x~``, so the path means the same at
       every level);
    2. at each level the estimate alternates between
       (a) a strongly sparsified, salient-edge latent light field: the L0
       gradient-regularised solve ``min ||K_p l - f||^2 + lambda ||grad l||_0``
       by half-quadratic splitting (conjugate gradients for the quadratic
       step), whose piecewise-constant result has step edges whatever the
       current path, and
       (b) the path fitted to that latent in the gradient domain,
       ``min_p ||grad_yx(K_p l_s) - grad_yx f||^2``, by Adam, on pixels drawn
       with a preference for strong gradients and large disparity (read off
       the blurred input), where the latent's over-sharp edges mislead the
       fit least; from the ``latent.edge_sigma_from``-th alternation the
       latent is modelled as sharper than the scene by a spatial Gaussian
       (``K_p G_sigma``), so that the path need not absorb the edge profile;
    3. the fit has many local minima, so every alternation fits a wide batch
       of paths at once (the fit is a small quadratic form in the blur
       kernel) and keeps the best: at first short lines in spread directions
       and random paths (never the zero path, where the gradient vanishes in
       the zero-mean gauge), later the current path, its mirror, perturbed
       copies and fresh random paths; with a pyramid, the degree is raised
       (exactly, by Bezier degree elevation) from a line to the requested
       number of control points on the way up;
    4. the zero-mean gauge holds throughout (the control points are
       re-centred inside every step) and the path is kept in a box of the
       aperture;
    5. with ``path.estimate_z``, a last stage frees ``p_z``, starting from
       the in-plane path;
    6. with ``d_inf != 0`` the path is estimated on the light field refocused
       by ``d_inf`` (which turns the model into the one with ``d_inf = 0``);
    7. with ``motion='6dof'`` a rotation stage follows: the translation
       found, with zero rotation, starts an alternation of the salient-edge
       latent and Adam on all six coordinates through the exact operator
       (:class:`RotationFitParams`; docs/blind.md, "Camera rotation").

``'joint'`` (the ``paper`` preset)
    The paper's blind stage as published: Adam on the control points and
    the grayscale light field jointly, on ``mean((K_p l - f)^2) + w R_eps(l)``
    with the 4D sparse-gradient prior ``R_eps = mean(min(|grad l|^2 / eps^2, 1))``
    and ``w``, ``eps`` annealed.

The path found, the data decide whether its blur is significant: the
salient-edge objective with the path's blur must beat the one with no blur
(the identity) by more than the noise floor and by a clear fraction, and the
blur must move the image by a good part of a pixel. If not,
``info['blur_found']`` is False and the path is estimated again on two
disjoint parts of the data: where they agree, the result is a light
restoration with the path scaled by ``params.light_restoration``, else the
input itself with a zero path (docs/blind.md, "What makes it robust"). If so, every colour channel is
restored by the non-blind
:func:`~napari_lfdeblur.deconvolution.deconvolve` with ``params.final``
(4D TV in both presets), tile by tile when memory is short. A restoration
that, blurred again by its path, misses the data by more than the noise
allows is not returned: the input is (the discrepancy principle). Both methods
return the path time-canonicalised
(:func:`~napari_lfdeblur.path.canonical_time_direction`), since the blur
does not depend on the order of the positions.

References
----------
.. [1] P. P. Srinivasan, R. Ng and R. Ramamoorthi, "Light Field Blind Motion
       Deblurring", CVPR 2017.
.. [2] L. Xu, S. Zheng and J. Jia, "Unnatural L0 Sparse Representation for
       Natural Image Deblurring", CVPR 2013.
.. [3] J. Pan, Z. Hu, Z. Su and M.-H. Yang, "Deblurring Text Images via
       L0-Regularized Intensity and Gradient Prior", CVPR 2014.
.. [4] A. Levin, Y. Weiss, F. Durand and W. T. Freeman, "Understanding and
       Evaluating Blind Deconvolution Algorithms", CVPR 2009.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from .. import devices
from .._lightfield import BRIGHT_LIMIT, brightest, caller_stacklevel, check_number, check_seed
from .._lightfield import check_infinity_disparity as _check_infinity_disparity
from .._memory import release_host_memory
from ..blur import validate_lightfield
from ..epi import warn_if_transposed
from ..path import bezier_positions, canonical_time_direction, center_path, path_in_frame
from ..progress import Progress, run_to_completion
from ._alternating import iter_alternating, relay
from ._disparity import shear_spectral
from ._evidence import discrepancy_check, evidence_message, iter_verdict
from ._joint import iter_joint
from ._memory import (TILE_MARGIN, check_max_memory, estimate_blind_memory, plan_run, tile_for_margin, tiled_peak,
                      tiles, within)
from ._rotation import iter_rotation_fit
from ._params import (MAX_EDGE_WIDTH, PRESETS, BlindParams, BlindResult, JointParams, LatentParams, PathFitParams,
                      RotationFitParams)
from ._windows import check_windows, path_windows, stage_preview

#: why ``infinity_disparity='auto'`` is refused (docs/blind.md, "Where d_inf comes from")
AUTO_MESSAGE = (
    "infinity_disparity='auto' is not available: d_inf cannot be estimated from a blurred light field alone "
    "(not at all on a single plane, where a longer path at another d_inf blurs it the same). Pass the disparity "
    "of the farthest scene content (the sky, a far wall) in px/view, or the value your decoder states; "
    "see docs/blind.md")

__all__ = [
    "BlindParams",
    "LatentParams",
    "PathFitParams",
    "RotationFitParams",
    "JointParams",
    "BlindResult",
    "PRESETS",
    "blind_deblur",
    "iter_blind_deblur",
    "estimate_blind_memory",
    "check_infinity_disparity",
    "AUTO_MESSAGE",
    "MAX_EDGE_WIDTH",
]


def blind_deblur(
    blurred,
    *,
    params: BlindParams | dict | str | None = None,
    infinity_disparity: float = 0.0,
    device="auto",
    seed: int = 0,
    callback=None,
    max_memory: float | None = None,
    windows=None,
    check_view_order: bool = True,
    **overrides,
) -> BlindResult:
    """Estimate the camera path and the sharp light field of a motion-blurred light field.

    Parameters
    ----------
    blurred : ndarray, shape (V, U, Y, X) or (V, U, Y, X, C)
        The blurred light field (docs/model.md layout), computed in float32.
    params : BlindParams, dict or str, optional
        Parameters, a dict of them (nested fields as sub-dicts), or a preset
        name (``'default'``, ``'paper'``). Default: the ``default`` preset.
    infinity_disparity : float, default 0.0
        ``d_inf`` in px/view of the blur model: the disparity of points at
        infinity (0 for a camera focused at infinity; with zero disparity
        on the focal plane, about the disparity of the farthest content).
        Finite, with ``|d_inf| (max(V, U) - 1) / 2 <= min(Y, X) / 2``
        (:func:`check_infinity_disparity`). ``'auto'`` is refused: it cannot
        be estimated from the blurred light field (docs/blind.md).
    device : {'auto', 'cpu', 'cuda'}, default 'auto'
        Where memory is short the final stage runs in tiles; a GPU that
        cannot hold the path stage falls back to the CPU, with a warning
        (docs/blind.md, *Memory*).
    seed : int, default 0
        Seed of the random parts (initial paths); equal seeds give equal results. The solver draws
        from its own generator: the global ones of numpy and torch are left as they were.
    callback : callable, optional
        Called with each :class:`~napari_lfdeblur.progress.Progress` record.
    max_memory : float, optional
        Bytes of memory the run may use on its device (the GPU's memory, or
        the host's on the CPU), at most; the final stage runs in tiles to
        stay within it (by :func:`estimate_blind_memory`). Default: what the
        device has free.
    windows : list of (y0, x0, height, width), optional
        Where in the view the path is estimated (pixels; each window at
        least 16 px a side, disjoint; one window for ``motion='6dof'`` and
        ``method='joint'``). Default:
        chosen from the data where the views are larger than
        ``params.path.region`` px, else the whole view. Name them to keep
        the estimate off a subject that moved by itself (its blur is not
        the camera's); the whole light field is restored with the path
        found there.
    check_view_order : bool, default True
        Measure how the image moves from view to view and warn
        (:class:`~napari_lfdeblur.epi.ViewOrderWarning`) when the angular
        axes look swapped against the spatial ones (the model has ``u``
        move ``x``; :func:`~napari_lfdeblur.views_transposed`). The readers
        check files already: pass False for a light field just read.
    **overrides
        Fields of :class:`BlindParams` to change, as in
        :meth:`BlindParams.replace` (e.g. ``n_control_points=3``,
        ``latent={"edge_anisotropy": 0.6}``).

    Returns
    -------
    BlindResult
        ``.lightfield`` (input shape, float32), ``.control_points`` ((n, 3),
        or (n, 6) with ``motion='6dof'``; zero-mean gauge), ``.loss_history``, ``.params``, ``.timings``,
        ``.info`` (with ``'blur_found'``, ``'evidence'``, ``'message'``).

    Raises
    ------
    ValueError
        On a malformed light field (wrong ndim, NaN, values reaching 2: not
        on the [0, 1] scale), invalid parameter values, an
        ``infinity_disparity`` that is not finite, beyond the views or
        ``'auto'``, or ``windows`` that are malformed, too small, reach
        outside the views, overlap or are more than one where only one is
        taken; a ``params`` dict with keys that are not fields (as
        :meth:`BlindParams.from_dict`).
    TypeError
        On an unknown keyword argument (a field override, as
        :meth:`BlindParams.replace`) or a parameter of the wrong type.
    """
    gen = iter_blind_deblur(blurred, params=params, infinity_disparity=infinity_disparity, device=device,
                            seed=seed, max_memory=max_memory, windows=windows,
                            check_view_order=check_view_order, **overrides)
    return run_to_completion(gen, callback)


def iter_blind_deblur(
    blurred,
    *,
    params: BlindParams | dict | str | None = None,
    infinity_disparity: float = 0.0,
    device="auto",
    seed: int = 0,
    max_memory: float | None = None,
    windows=None,
    check_view_order: bool = True,
    **overrides,
):
    """Blind deblurring as a generator: yields progress, returns a :class:`BlindResult`.

    Takes the arguments of :func:`blind_deblur`. Arguments are checked when
    the generator is created; closing it stops the work at the next yield:
    records come after every conjugate-gradient iteration of the latent
    (one forward and one adjoint blur), every few Adam steps of the path
    fit, every alternation and every iteration of the final solve. Inside
    :func:`napari_lfdeblur.progress.cancellable`, the final solve also stops
    within its iterations once the event is set
    (:class:`~napari_lfdeblur.progress.Cancelled` is raised).

    Yields
    ------
    Progress
        ``stage`` names the stage (``'path (level i/n, YxX)'`` for a pyramid
        level, ``'path (p_z i/n, ...)'`` for the stage that frees ``p_z``:
        ``n`` counts them and, with ``motion='6dof'``, the ``'rotation
        (YxX)'`` stage after them; ``'path (joint)'`` with ``method='joint'``;
        ``'evidence'``; ``'final'``, or ``'final (tile i/n)'`` when the final
        stage is tiled), ``control_points`` the current path (in every
        record). ``estimate()`` computes the current light-field estimate
        (input shape, float32; in the path stage the grayscale latent,
        upsampled, placed in the full frame and repeated over the channels);
        the rotation and evidence records have none (``estimate`` is None).
        Wrap the generator in
        :func:`~napari_lfdeblur.progress.with_previews` to get ``preview``
        arrays. In the path stage ``iteration`` counts the records of the
        level out of ``n_iterations`` (an alternation ending early jumps to
        its end); ``loss`` is the path fit at the end of an alternation
        (``info['phase'] == 'done'``) and NaN on the records inside one
        (``info['phase']`` ``'latent'`` or ``'path fit'``, with the current
        best fit in ``info['fit']``). Then records of stage ``'evidence'``
        (one per conjugate-gradient iteration of the evidence test; in the
        agreement check, ``'evidence (agreement check, part i of 2)'``, those
        of its two estimates, ``iteration`` counting thousandths of the
        stage) and, when the light field is restored, of the final stage.

    Returns
    -------
    BlindResult
    """
    arr, d_inf = _validate_input(blurred, infinity_disparity)
    p = _make_params(params, overrides)
    if not isinstance(check_view_order, (bool, np.bool_)):
        raise TypeError(f"check_view_order must be True or False; got {check_view_order!r}")
    in_plane = d_inf == 0 and p.method == "alternating" and p.motion == "3dof" and not p.path.estimate_z
    if p.final is not None and p.final.method == "inplane" and not in_plane:  # it would fail after the path stage
        raise ValueError("final.method='inplane' restores in-plane paths at infinity_disparity 0 only, and this run "
                         "may estimate p_z, a rotation or d_inf != 0 (path.estimate_z, motion, method); use 'tv'")
    seed = check_seed(seed)
    windows = check_windows(windows, arr.shape, p)
    cap = check_max_memory(max_memory)
    level = caller_stacklevel()  # warnings name the user's line, through blind_deblur or not
    if check_view_order:
        warn_if_transposed(arr, "the blurred light field", stacklevel=level)
    asked = devices.select_device(device)
    need = estimate_blind_memory(arr.shape, p)
    available = within(devices.free_memory, cap)
    dev, tile = plan_run(arr.shape, p, asked, available)
    if dev != asked:
        warnings.warn(f"blind deblurring needs about {need / 2**30:.2f} GiB, more than {asked} has free, even "
                      "in tiles: running on the CPU instead", RuntimeWarning, stacklevel=level)
    if tile is not None:
        Y, X, region = *arr.shape[2:4], p.path.region
        where = ("the windows given" if windows else f"{region}x{region} windows" if region and max(Y, X) > region
                 else "the whole view")
        have = "max_memory" if cap is not None and available(dev) == cap else f"what {dev} has free"
        how = (f"overlapping tiles of {tile[0]}x{tile[1]}" if tile[0] < Y or tile[1] < X
               else "one piece all the same (a tile would be no smaller than its views)")
        peak, room = tiled_peak(arr.shape, p, tile), available(dev)
        over = (f"; even so it needs about {peak / 2**30:.2f} GiB (the path stage, or the result and a tile), and "
                f"will exceed {have}") if room is not None and peak > room else ""
        warnings.warn(f"blind deblurring needs about {need / 2**30:.2f} GiB, more than {have}: restoring the light "
                      f"field in {how} (the path is estimated as usual, on {where}){over}", RuntimeWarning,
                      stacklevel=level)
    return devices.run_with_cpu_fallback(lambda d: _run(arr, d_inf, p, d, int(seed), tile, windows), dev)


def _validate_input(blurred, infinity_disparity):
    arr = validate_lightfield(blurred, "blurred light field")
    V, U, Y, X = arr.shape[:4]
    if V < 2 or U < 2:
        raise ValueError(f"blind deblurring needs at least 2 x 2 views; got {V} x {U}")
    if Y < 4 or X < 4:
        raise ValueError(f"blind deblurring needs views of at least 4 x 4 pixels; got {Y} x {X}")
    if arr.dtype == bool:
        arr = arr.astype(np.float32)
    if (top := float(arr.max())) >= BRIGHT_LIMIT:
        white = f"{np.iinfo(arr.dtype).max} for {arr.dtype}" if arr.dtype.kind in "iu" else "255 for 8-bit values"
        raise ValueError(f"the blurred light field reaches {top:.4g}: blind deblurring takes values in [0, 1] (its "
                         f"edge weights are on that scale); divide it by its white level ({white})")
    d_inf = check_infinity_disparity(infinity_disparity, arr.shape)
    return arr, d_inf


def check_infinity_disparity(infinity_disparity, shape) -> float:
    """``infinity_disparity`` as a float, checked against the light field's ``shape`` (V, U, Y, X[, C]).

    :func:`~napari_lfdeblur._lightfield.check_infinity_disparity` (finite,
    and within what the views' size allows), which ``simulate_blur`` and
    ``deconvolve`` apply too; ``'auto'`` gets a ValueError that says why it
    is not offered.

    Raises
    ------
    TypeError
        If it is not a real number (``'auto'`` gets a ValueError).
    ValueError
        If it is ``'auto'``, not finite or beyond the bound.
    """
    if isinstance(infinity_disparity, str) and infinity_disparity.strip().lower() == "auto":
        raise ValueError(AUTO_MESSAGE)
    return _check_infinity_disparity(infinity_disparity, shape)


def _make_params(params, overrides) -> BlindParams:
    if params is None:
        params = PRESETS["default"]
    elif isinstance(params, str):
        params = BlindParams.preset(params)
    elif isinstance(params, dict):
        params = BlindParams.from_dict(params)
    elif not isinstance(params, BlindParams):
        raise TypeError(f"params must be a BlindParams, a dict or a preset name; got {type(params).__name__}")
    if overrides:
        params = params.replace(**overrides)
    return params


def _run(arr, d_inf, p: BlindParams, dev, seed, tile=None, windows=None):
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)  # every draw of the solver (torch's global generator is the caller's)
    V, U, Y, X = arr.shape[:4]
    box = p.path_box(V, U)
    sheared = p.method == "alternating" and d_inf != 0.0
    gs, windows = path_windows(arr, d_inf, p, dev, sheared, windows)  # the path is the same everywhere
    g, window = gs[0], windows[0]
    # several windows: the path stage works in the frame's coordinates from the start
    frames = [(y0, x0, Y, X) for y0, x0, _, _ in windows] if len(windows) > 1 else None

    def preview(latent, fac):  # one latent, or one per window
        return stage_preview(latent if isinstance(latent, list) else [latent], fac, arr.shape,
                        d_inf if sheared else 0.0, [w[:2] for w in windows])

    if p.method == "alternating":
        est = yield from iter_alternating(gs, p, dev, rng, box, preview, frames)
        if p.motion == "6dof":  # its path is in the frame's coordinates
            est = yield from iter_rotation_fit(g, est, p, dev, window, (Y, X), box)
    else:
        est = yield from iter_joint(g, d_inf, p, dev, rng, box, preview)
    info = {"device": str(dev), "box": box, "window": window, "windows": windows, **est.info}
    info["levels"] = [(g.shape[2] // k, g.shape[3] // k) for k in est.factors]
    frame = (window[0], window[1], Y, X) if p.motion == "6dof" or frames else None
    if sheared or not d_inf:  # the windows of the agreement check, in the d_inf = 0 model
        split = (gs, windows, (Y, X), rng, box)
    else:
        split = ([shear_spectral(t, d_inf) for t in gs], windows, (Y, X), rng, box)
    evidence, light = yield from iter_verdict(split, est, p, dev, frame)
    restore, bright = evidence["blur_found"] or not p.require_evidence, brightest(arr)
    info.update(blur_found=evidence["blur_found"], evidence=evidence, brightest=bright,
                message=evidence_message(evidence, p.require_evidence, light, bright),
                restoration="full" if restore else "light" if light else "none")
    cp = est.control_points if frame else path_in_frame(est.control_points, window, (Y, X))  # window -> frame
    if not restore:  # the path estimated, kept; a light restoration uses it scaled, else the result has no blur
        info["rejected_path"] = canonical_time_direction(center_path(cp, p.n_times))
        cp = info["rejected_path"] * light if light else np.zeros_like(cp)
    if tile is not None:
        info["tile"] = tuple(tile)
    cp = canonical_time_direction(center_path(cp, p.n_times))
    t1 = time.perf_counter()
    del g, gs
    if p.final is not None and (restore or light):
        out = yield from _iter_final(arr, cp, d_inf, p, dev, tile, est.n_stages, info)
        if p.require_evidence:  # tiled: the device is short of memory, and one channel at a time fits the host
            out, cp = discrepancy_check(arr, out, cp, d_inf, p, dev if tile is None else "cpu", info)
    else:
        out = np.asarray(arr, dtype=np.float32).copy()
    if p.final is None and (restore or light):  # the path stands, but nothing restored with it
        info.update(restoration="none", message=info["message"] + "; final=None: the input is returned, unrestored")
    t2 = time.perf_counter()
    return BlindResult(lightfield=np.asarray(out, dtype=np.float32), control_points=cp, loss_history=est.loss_history,
                       params=p, timings={"path": t1 - t0, "final": t2 - t1, "total": t2 - t0}, info=info)


def _iter_final(arr, cp, d_inf, p: BlindParams, dev, tile, n_path, info):
    """The final non-blind stage over the whole light field (tile by tile when memory is short); its weight
    goes to ``info['final_weight']``."""
    from ..deconvolution import estimate_noise_sigma, iter_deconvolve

    Y, X = arr.shape[2:4]
    final = p.final
    info["noise_sigma"] = sigma = estimate_noise_sigma(arr)  # for the weight, and the discrepancy check after
    release_host_memory()  # the noise estimate's work, before the final stage allocates its own
    if final.weight is None:  # one weight for the whole light field, so that tiles agree
        n_channels = arr.shape[4] if arr.ndim == 5 else 1
        final = final.replace(weight=final.effective_weight(final.method, sigma, n_channels))
    info["final_weight"] = final.weight
    if tile is None:
        parts = [((slice(None), slice(None)), (slice(None), slice(None)))]
        out = None
    else:
        # d_inf moves the samples up to r px: near a tile's edge the blur reads clamped pixels over a band of
        # r px that the solve must explain, and its normal operator carries that band 2r px further in
        reach = float(np.abs(bezier_positions(cp, p.final_n_times)).sum(axis=1).max())  # |p_x| + |p_y| + |p_z|
        margin = TILE_MARGIN + 3 * int(math.ceil(abs(d_inf) * reach))
        tile = info["tile"] = tile_for_margin(tile, margin, Y, X)  # each tile with its margin as the plan's
        parts = list(tiles(Y, X, tile, margin))
        out = np.array(arr, dtype=np.float32)  # restored tile by tile; the rest shows as blurred meanwhile
    for i, (core, pad) in enumerate(parts):
        y0, x0 = pad[0].start or 0, pad[1].start or 0
        gen = iter_deconvolve(arr[:, :, pad[0], pad[1]], cp, n_times=p.final_n_times, infinity_disparity=d_inf,
                              device=dev, params=final, frame=None if tile is None else (y0, x0, Y, X))
        inner = None
        if tile is not None:
            inner = (slice(core[0].start - y0, core[0].stop - y0), slice(core[1].start - x0, core[1].stop - x0))

        def relabel(rec, i=i, core=core, inner=inner):
            return Progress(stage="final" if tile is None else f"final (tile {i + 1}/{len(parts)})",
                            iteration=i * rec.n_iterations + rec.iteration, n_iterations=rec.n_iterations * len(parts),
                            loss=rec.loss,
                            control_points=cp,
                            estimate=_tile_estimate(rec, out, core, inner), stage_index=n_path + 1,
                            n_stages=n_path + 2, info=rec.info)  # after the path and the evidence stages

        res = yield from relay(gen, relabel)
        if tile is None:
            out = res
        else:
            out[:, :, core[0], core[1]] = res[:, :, inner[0], inner[1]]
            del res, gen
            release_host_memory()  # the tile's freed work, before the next tile allocates its own
    return out


def _tile_estimate(rec: Progress, out, core, inner):
    """The estimate of a final-stage record: the tile's estimate placed in the full frame (when tiled)."""
    if rec.estimate is None or out is None:
        return rec.estimate

    def estimate():
        full = out.copy()
        full[:, :, core[0], core[1]] = rec.estimate()[:, :, inner[0], inner[1]]
        return full

    return estimate

