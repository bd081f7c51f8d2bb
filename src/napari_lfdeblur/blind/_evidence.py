"""Is the blur significant? The evidence for the estimated path against the "no blur" explanation.

After the path estimate, the grayscale light field is explained twice by a
salient-edge latent of the same kind (:func:`~napari_lfdeblur.blind._latent.l0_latent`,
same weight): once through the estimated blur ``K_p``, once through the
identity (no blur). The blur is significant when the blur model explains
the data better than the identity (misfit plus edge count) by more than noise
alone would allow and by a clear fraction, and when the blur it describes
moves the image by a good part of a pixel (docs/blind.md, "What makes it
robust").

Where that evidence is weak, a light restoration (``BlindParams.light_restoration``)
still needs the blur to be the camera's: one motion for the whole view. The
path is then estimated again, independently, on two disjoint parts of the
data, and the two estimates must agree (:func:`iter_disagreement`).

Whatever path is restored with, the restoration must then reproduce the
data to the noise level (:func:`restoration_discrepancy`, the discrepancy
principle): the right path leaves at most about one noise variance per
sample, a path that does not explain the data leaves more.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .._lightfield import DARK_LEVEL, white_level
from .._noise import estimate_noise_sigma
from ..blur import BlurOperator, image_shifts
from ..path import bezier_positions, center_path
from ..priors import gradient_yx
from ..progress import Progress
from ._alternating import iter_alternating, relay
from ._disparity import DISPARITY_PIXELS, disparity_map, downsample
from ._latent import difference_pair, l0_latent, n_hqs_steps
from ._params import BlindParams

__all__ = ["noise_sigma", "blur_reach", "evidence_weight", "blur_evidence", "evidence_message", "Identity",
           "EVIDENCE_MARGIN", "RELATIVE_MARGIN", "MIN_REACH", "AGREEMENT_MARGIN", "MIN_PART", "split_parts",
           "path_disagreement", "iter_disagreement", "iter_verdict", "DISCREPANCY_MARGIN",
           "restoration_discrepancy", "discrepancy_check"]

#: the blur model must lower the salient-edge objective by more than this many noise variances per sample
EVIDENCE_MARGIN = 1.0
#: ... and by more than this fraction of the objective of the "no blur" explanation
RELATIVE_MARGIN = 0.06
#: a blur whose largest image motion is below this (px) counts as no blur
MIN_REACH = 0.25
#: two estimates of one camera motion agree when their blurs differ by at most this fraction of the larger one
AGREEMENT_MARGIN = 0.5
#: a restoration whose blurred result misses the data by more than this many noise variances per sample is
#: not returned: the path it used does not explain the data
DISCREPANCY_MARGIN = 1.25
#: the smallest side (px) of a part of the view that the agreement check estimates a path on
MIN_PART = 16


class Identity:
    """The "no blur" operator, with the interface of :class:`~napari_lfdeblur.blur.BlurOperator`."""

    def forward(self, z):
        return z

    def adjoint(self, r):
        return r


def noise_sigma(g: torch.Tensor) -> float:
    """Robust estimate of the noise standard deviation of (V, U, Y, X, C).

    :func:`~napari_lfdeblur.deconvolution.estimate_noise_sigma` (the
    smallest principal component of the least detailed patches), the
    estimate the non-blind weight rule uses too.
    """
    return estimate_noise_sigma(g.detach().cpu().numpy())


def blur_reach(cp, n_times: int, g: torch.Tensor, frame=None) -> float:
    """Largest image motion (px) of the blur of path ``cp`` in ``g`` (V, U, Y, X, 1), ``d_inf = 0`` model.

    A point at disparity ``d`` moves by ``(d - d_inf) s`` px when the camera
    moves by ``s`` views (docs/model.md): the path's in-plane extent (views)
    times the 95th percentile of ``|d|`` (``g`` is refocused by ``d_inf``)
    over the pixels with the stronger half of the gradients, where the
    disparity is measured (a flat region has none; 0 when the whole centre
    view is flat, since no motion shows there). A rotation (``cp`` of 6
    columns) adds the largest range of its image displacement over the
    exposure at any pixel of ``g`` (placed in ``frame``, as in
    :class:`~napari_lfdeblur.blur.BlurOperator`).
    """
    pos = bezier_positions(np.asarray(cp, dtype=np.float64), n_times)
    extent = float(np.linalg.norm(pos[:, :2].max(axis=0) - pos[:, :2].min(axis=0)))
    Y, X = g.shape[2:4]
    k = max(1, int(math.sqrt(Y * X / DISPARITY_PIXELS)))
    small = downsample(g, k)
    d = np.abs(disparity_map(small))
    gy, gx = gradient_yx(small.mean(dim=(0, 1))[None, None])
    mag = (gy * gy + gx * gx)[0, 0, ..., 0].cpu().numpy()
    if not mag.max() > 0:
        return 0.0  # a flat light field: no motion shows
    textured = mag >= np.median(mag)
    reach = extent * k * float(np.percentile(d[textured], 95))  # disparities of the k-times smaller image
    if pos.shape[1] == 6:
        t_y, t_x = image_shifts(torch.as_tensor(pos), tuple(g.shape), frame)
        span = torch.sqrt((t_y.amax(0) - t_y.amin(0)) ** 2 + (t_x.amax(0) - t_x.amin(0)) ** 2)
        reach += float(span.max())
    return reach


def evidence_weight(p: BlindParams) -> float:
    """The latent weight ``lambda`` of the evidence test: the floor of the alternation's, ``l0_weight * l0_floor``."""
    return p.latent.l0_weight * p.latent.l0_floor


def evidence_message(evidence: dict, required: bool = True, light: float = 0.0, brightest: float = 1.0) -> str:
    """A one-line description of the evidence for the blur, for people.

    ``required``: whether the result depends on it (else the light field was
    restored with the path whatever the evidence). ``light``: the scale of
    the path of a light restoration when little blur is found (0: the
    input is returned). ``brightest``: the input's
    :func:`~napari_lfdeblur._lightfield.brightest`; below
    :data:`~napari_lfdeblur._lightfield.DARK_LEVEL`, a message of little
    blur says that the input is dark and how to stretch it.
    """
    e = evidence
    if e["blur_found"]:
        return (f"blur found: the blur model explains {e['gain']:.2f} noise variances per sample more than no "
                f"blur; it moves the image by up to {e['reach']:.2f} px")
    why = []
    if not e["gain"] > EVIDENCE_MARGIN:
        why.append(f"the blur model explains {e['gain']:.2f} noise variances per sample more than no blur "
                   f"(needs > {EVIDENCE_MARGIN:g})")
    if not e["relative"] > RELATIVE_MARGIN:
        why.append(f"it lowers the salient-edge objective of no blur by {100 * e['relative']:.1f} % "
                   f"(needs > {100 * RELATIVE_MARGIN:g} %)")
    if not e["reach"] >= MIN_REACH:
        why.append(f"it moves the image by {e['reach']:.2f} px at most (needs >= {MIN_REACH:g})")
    d = e.get("disagreement", float("nan"))
    if required and not math.isnan(d):
        verb = "agree" if d <= AGREEMENT_MARGIN else "disagree"
        why.append(f"two parts of the data, estimated apart, {verb} on the path (their blurs differ by {d:.2f} of "
                   f"the larger; agreement needs <= {AGREEMENT_MARGIN:g})")
    if not required:
        verdict = "restored anyway (require_evidence=False)"
    elif light:
        verdict = f"a light restoration, with the estimated path at {100 * light:g} % of its length"
    else:
        verdict = "the input is returned unchanged"
    dark = ""
    if brightest <= 0:
        dark = ". The light field is black"
    elif brightest < DARK_LEVEL:
        dark = (f". The light field is dark (99.9 % of its centre view is below {brightest:.3g}) and the salient "
                "edges are found on an absolute scale: stretched to [0, 1] first (value_range='auto' when reading, "
                "lfdeblur --value-range auto), its blur may show")
    return f"little blur found, {verdict}: " + "; ".join(why) + dark


def _objective(op, g, lam, p: BlindParams):
    """The salient-edge latent ``l`` under ``op``: ``(|K l - g|^2 / N, edges / N)``.

    ``edges`` counts the pixels whose (weighted 4D) gradient the last
    splitting step keeps, the ``||grad l||_0`` of the latent's objective.
    """
    latent = yield from l0_latent(op, g, lam, p.latent, g.clone())
    r = op.forward(latent) - g
    grad, _ = difference_pair(p.latent.angular_weight)
    edges = float((sum(c * c for c in grad(latent)) >= lam / p.latent.hqs_beta_max).sum())
    n = g.numel()
    return float((r * r).sum()) / n, edges / n


def blur_evidence(g: torch.Tensor, cp, p: BlindParams, device, frame=None):
    """Evidence for the blur of path ``cp`` in the grayscale (V, U, Y, X, 1) ``g`` (``d_inf = 0`` model).

    ``frame`` places ``g`` in a larger view, as in
    :class:`~napari_lfdeblur.blur.BlurOperator` (it matters for rotation).

    ``E = |K l - g|^2 / N + lam * edges / N`` of the salient-edge latent
    (``lam``: :func:`evidence_weight`) is computed with
    ``K = K_p`` (``E_blur``) and with ``K = I`` (``E_none``). The blur is
    found when ``E_none - E_blur > EVIDENCE_MARGIN sigma^2`` (``sigma``:
    :func:`noise_sigma`), ``(E_none - E_blur) / E_none > RELATIVE_MARGIN``
    and :func:`blur_reach` ``>= MIN_REACH``.

    A generator (yields the latents' conjugate-gradient iterates, where the
    caller may report or stop); returns a dict of floats: ``sigma``,
    ``misfit_blur``, ``misfit_none`` (mean squared residuals),
    ``edges_blur``, ``edges_none`` (edges per sample), ``gain``
    (``(E_none - E_blur) / sigma^2``), ``relative`` (0 when ``E_none`` is
    below a thousandth of ``sigma^2``: a flat light field), ``reach`` (px),
    and ``blur_found`` (bool).
    """
    sigma = max(noise_sigma(g), 1e-4)
    lam = evidence_weight(p)
    op = BlurOperator(tuple(g.shape), cp, n_times=p.n_times, infinity_disparity=0.0, device=device, frame=frame)
    m_blur, e_blur = yield from _objective(op, g, lam, p)
    m_none, e_none = yield from _objective(Identity(), g, lam, p)
    e0, e1 = m_none + lam * e_none, m_blur + lam * e_blur
    gain = (e0 - e1) / sigma**2
    # a flat light field leaves "no blur" nothing to pay: no ratio to speak of (one over ~0 is rounding noise)
    relative = (e0 - e1) / e0 if e0 > 1e-3 * sigma**2 else 0.0
    reach = blur_reach(cp, p.n_times, g, frame)
    found = bool(gain > EVIDENCE_MARGIN and relative > RELATIVE_MARGIN and reach >= MIN_REACH)
    return {"sigma": sigma, "misfit_blur": m_blur, "misfit_none": m_none, "edges_blur": e_blur,
            "edges_none": e_none, "gain": gain, "relative": relative, "reach": reach,
            "blur_found": found}


def split_parts(gs, windows, frame_shape):
    """Two disjoint parts of the path stage's data, each ``(list of windows, list of frames)``.

    ``gs`` are the path stage's windows (``(V, U, h, w, 1)`` each), ``windows``
    their ``(y0, x0, h, w)`` in the view of ``frame_shape`` ``(Y, X)``. Several
    windows are dealt out alternately (the first, third, ... and the second,
    fourth, ...); one window is cut in two halves across its longer side.
    Frames are ``(y0, x0, Y, X)``, as :func:`~napari_lfdeblur.blind._alternating.iter_alternating`
    takes them. Returns None when a half would be narrower than :data:`MIN_PART` px.
    """
    Y, X = frame_shape
    if len(gs) >= 2:
        return [([gs[i] for i in idx], [(windows[i][0], windows[i][1], Y, X) for i in idx])
                for idx in (range(0, len(gs), 2), range(1, len(gs), 2))]
    g, (y0, x0, h, w) = gs[0], windows[0]
    axis, n = (3, w) if w >= h else (2, h)
    k = n // 2
    if k < MIN_PART or min(h, w) < MIN_PART:
        return None
    low, high = g.narrow(axis, 0, k).contiguous(), g.narrow(axis, k, n - k).contiguous()
    second = (y0, x0 + k) if axis == 3 else (y0 + k, x0)
    return [([low], [(y0, x0, Y, X)]), ([high], [(*second, Y, X)])]


def path_disagreement(g: torch.Tensor, cp_a, cp_b, n_times: int, frame=None) -> float:
    """How much the blurs of two paths differ on ``g`` (V, U, h, w, 1), ``d_inf = 0`` model.

    ``||K_a g - K_b g|| / max(||K_a g - g||, ||K_b g - g||)``: 0 when they blur
    alike, about 1 when they differ as much as the larger blur from no blur
    (symmetric in the two paths; inf when neither blurs ``g``). ``frame``
    places ``g`` in the view, as in :class:`~napari_lfdeblur.blur.BlurOperator`.
    """
    with torch.no_grad():
        a, b = (BlurOperator(tuple(g.shape), cp, n_times=n_times, infinity_disparity=0.0, device=g.device,
                             frame=frame).forward(g) for cp in (cp_a, cp_b))
        den = max(float(torch.linalg.vector_norm(a - g)), float(torch.linalg.vector_norm(b - g)))
        return float(torch.linalg.vector_norm(a - b)) / den if den > 0 else float("inf")


def iter_disagreement(gs, windows, frame_shape, p: BlindParams, device, rng, box: float):
    """Estimate the path on two disjoint parts of the data, independently; how much the two differ.

    The parts are :func:`split_parts`'; each gets the whole alternating
    estimate (:func:`~napari_lfdeblur.blind._alternating.iter_alternating`,
    in the view's coordinates, so that the two compare), and
    :func:`path_disagreement` compares them on the first window. A camera
    motion blurs every part of the view by one path, so two parts find the
    same one; what a path fit makes of the scene's own edges or texture
    differs from part to part where the content does (edges equally soft
    everywhere read as one blur too).

    A generator: yields ``(part, record)``, the part (0 or 1) and each
    progress record of its estimate; returns ``(disagreement, [path_a,
    path_b])``, or ``(nan, [])`` when the data are too small to split.
    """
    parts = split_parts(gs, windows, frame_shape)
    if parts is None:
        return float("nan"), []
    cps = []
    for i, (part, frames) in enumerate(parts):
        est = yield from relay(iter_alternating(part, p, device, rng, box, None, frames), lambda rec, i=i: (i, rec))
        cps.append(center_path(est.control_points, p.n_times))
    frame = (windows[0][0], windows[0][1], *frame_shape)
    return path_disagreement(gs[0], cps[0], cps[1], p.n_times, frame), cps


def iter_verdict(split, est, p: BlindParams, device, frame=None):
    """The evidence stage: is the estimated blur significant, and if not, is a light restoration warranted?

    ``split`` is ``(gs, windows, frame_shape, rng, box)``: the path stage's
    grayscale windows in the ``d_inf = 0`` model (refocused by ``d_inf``),
    their places in the view and what :func:`iter_disagreement` needs; the
    evidence test reads the first window, which ``frame`` places in the view.
    ``est`` is the path stage's :class:`~napari_lfdeblur.blind._params.PathEstimate`.
    :func:`iter_disagreement` runs when the test finds little blur, ``p.require_evidence`` holds
    and the light restoration's path would move the image by at least
    :data:`MIN_REACH` px. The light restoration is made when the two parts
    agree within :data:`AGREEMENT_MARGIN`.

    A generator of :class:`~napari_lfdeblur.progress.Progress` records (stage
    ``'evidence'``); returns ``(evidence, light)``: :func:`blur_evidence`'s
    dict, with ``disagreement`` (nan when not checked) and ``agreement_paths``
    added, and the scale of the light restoration's path (0: none).
    """
    cp = center_path(est.control_points, p.n_times)

    def report(_, stage="evidence", loss=float("nan"), path=cp, done=0.0):
        # a stage of its own, before the final one: the test takes the first tenth of it, the agreement
        # check's two estimates the rest (when it runs; else the stage ends there)
        return Progress(stage=stage, iteration=max(1, round(1000 * done)), n_iterations=1000, loss=loss,
                        control_points=path, stage_index=est.n_stages, n_stages=est.n_stages + 2)

    def report_part(item):  # the agreement check's estimates, with their own path, fit and progress
        i, rec = item
        path_share = max(1, rec.n_stages - 2) / rec.n_stages  # its records count an evidence and a final stage
        return report(None, f"evidence (agreement check, part {i + 1} of 2)", rec.loss, rec.control_points,
                      0.1 + 0.45 * (i + min(1.0, rec.fraction / path_share)))

    n_test, tick = 2 * n_hqs_steps(evidence_weight(p), p.latent) * (p.latent.n_cg + 1), [0]  # its latents' steps

    def report_test(_):
        tick[0] += 1
        return report(None, done=0.1 * min(1.0, tick[0] / n_test))

    evidence = yield from relay(blur_evidence(split[0][0], cp, p, device, frame), report_test)
    evidence.update(disagreement=float("nan"), agreement_paths=[])
    light = p.light_restoration
    if evidence["blur_found"] or not p.require_evidence or light * evidence["reach"] < MIN_REACH:
        return evidence, 0.0
    disagreement, paths = yield from relay(iter_disagreement(*split[:3], p, device, *split[3:]), report_part)
    evidence.update(disagreement=disagreement, agreement_paths=[c.tolist() for c in paths])
    return evidence, light if disagreement <= AGREEMENT_MARGIN else 0.0


def restoration_discrepancy(blurred: np.ndarray, restored: np.ndarray, control_points, n_times: int,
                            infinity_disparity: float, sigma: float, device) -> float:
    """How far the restoration, blurred again by its path, is from the data, in noise variances per sample.

    ``mean((K_p x - f)^2) / sigma^2`` over the samples of ``f`` below its
    white level (those at it may be clipped by the sensor, and the final
    stage fits them as censored). ``blurred`` ``f`` and ``restored`` ``x`` are
    (V, U, Y, X[, C]), ``K_p`` the exact blur (``infinity_disparity``), one
    channel at a time (so the memory is one channel's). The discrepancy
    principle (Morozov): a restoration through the right path is at least as
    close to the data as the sharp light field, which leaves exactly the
    noise, less what the prior takes; about one noise variance per sample
    or less. A path that cannot explain the data leaves more, whatever the
    restoration. Returns 0.0 when no sample is below the white level.

    Raises
    ------
    ValueError
        If ``sigma`` is not positive: without noise the principle has no scale.
    """
    if not sigma > 0:
        raise ValueError(f"the discrepancy needs a positive noise level; got sigma={sigma!r}")
    f, x = np.asarray(blurred), np.asarray(restored, dtype=np.float32)
    white = white_level(f.dtype)
    if f.ndim == 4:
        f, x = f[..., None], x[..., None]
    total, count = 0.0, 0
    op = BlurOperator(f.shape[:4], control_points, n_times=n_times, infinity_disparity=infinity_disparity,
                      device=device)
    with torch.no_grad():
        for c in range(f.shape[4]):  # in place: about one channel's worth of memory on top of the inputs
            fc = torch.as_tensor(np.ascontiguousarray(f[..., c], dtype=np.float32), device=op.device)
            r = op.forward(torch.as_tensor(np.ascontiguousarray(x[..., c]), device=op.device)[..., None])[..., 0]
            clipped = fc >= white
            r.sub_(fc).masked_fill_(clipped, 0.0)
            total += float(torch.sum(r.square_(), dtype=torch.float64))
            count += r.numel() - int(clipped.sum())
            del fc, r, clipped
    return total / count / sigma**2 if count else 0.0


def discrepancy_check(arr, out, cp, d_inf: float, p: BlindParams, device, info: dict):
    """The restoration ``out`` and its path ``cp``, or the input ``arr`` and a zero path.

    The input (float32, a copy) is returned where the restoration does not
    reproduce the data to the noise level: :func:`restoration_discrepancy`
    above :data:`DISCREPANCY_MARGIN`, with ``info['noise_sigma']`` (the
    final stage's noise estimate). With no measurable noise (an estimate
    of 0) there is no scale to judge by, and no test. Records
    ``info['discrepancy']`` (nan without a test); on a refusal sets
    ``info['restoration']`` to ``'none'``, keeps the path of a full
    restoration as ``info['rejected_path']`` and says why in
    ``info['message']``.
    """
    if not info["noise_sigma"] > 0:
        info["discrepancy"] = float("nan")
        return out, cp
    d = info["discrepancy"] = restoration_discrepancy(arr, out, cp, p.final_n_times, d_inf, info["noise_sigma"],
                                                   device)
    if d <= DISCREPANCY_MARGIN:
        return out, cp
    if info["restoration"] == "full":
        info["rejected_path"] = cp
    info.update(restoration="none", message=info["message"] + (
        f"; but the restoration with that path, blurred again, misses the data by {d:.2f} noise variances per "
        f"sample (the right path leaves about 1 or less; the limit is {DISCREPANCY_MARGIN:g}): the path does "
        "not explain the data, and the input is returned unchanged"))
    return np.asarray(arr, dtype=np.float32).copy(), np.zeros_like(cp)
