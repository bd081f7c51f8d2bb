"""The TV's angular differences along the scene's disparity (DeconvolutionParams.angular='disparity')."""

import numpy as np
import pytest
import torch

from napari_lfdeblur import DeconvolutionParams, deconvolve, linear_path, simulate_blur
from napari_lfdeblur._oriented import OrientedDifferences
from napari_lfdeblur._tv_solvers import TVProx, tv_value
from napari_lfdeblur.deconvolution import scene_disparity
from napari_lfdeblur.priors import gradient4d, project_tv_dual
from test_deconvolution import plane_lightfield, rmse


def brute_difference(x, d, axis):
    """``l(v + 1, u, y + d, x) - l`` (axis 0) or ``l(v, u + 1, y, x + d) - l`` (axis 1), sample by sample."""
    V, U, Y, X, _ = x.shape
    out = np.zeros_like(x)
    n = (Y, X)[axis]
    for v in range(V - (axis == 0)):
        for u in range(U - (axis == 1)):
            for y in range(Y):
                for xx in range(X):
                    p = min(max((y, xx)[axis] + d[y, xx], 0), n - 1)
                    k = min(int(np.floor(p)), n - 2)
                    w = p - k
                    if axis == 0:
                        s = (1 - w) * x[v + 1, u, k, xx] + w * x[v + 1, u, k + 1, xx]
                    else:
                        s = (1 - w) * x[v, u + 1, y, k] + w * x[v, u + 1, y, k + 1]
                    out[v, u, y, xx] = s - x[v, u, y, xx]
    return out


@pytest.mark.parametrize("axis", [0, 1])
def test_oriented_differences_match_brute_force_and_their_adjoint(axis, engine):
    rng = np.random.default_rng(0)
    shape = (3, 4, 7, 9, 2)
    d = rng.uniform(-3, 3, shape[2:4])  # reaching beyond the edges too: the replicate boundary
    od = OrientedDifferences(torch.as_tensor(d))
    x, g = (torch.as_tensor(rng.standard_normal(shape)) for _ in range(2))
    Dx = od.difference(x, axis)
    np.testing.assert_allclose(Dx.numpy(), brute_difference(x.numpy(), d, axis), atol=1e-12)
    DTg = od.add_adjoint(g, axis, torch.zeros_like(g))
    assert float((Dx * g).sum()) == pytest.approx(float((x * DTg).sum()), rel=1e-12)
    # the norm bound holds: power iteration on D^T D
    z = torch.as_tensor(rng.standard_normal(shape))
    for _ in range(100):
        z = od.add_adjoint(od.difference(z, axis), axis, torch.zeros_like(z))
        z /= z.norm()
    assert float(od.difference(z, axis).norm()) ** 2 <= od.norm_bound(axis) * (1 + 1e-9)
    # accumulating forms, into a non-zero field
    base = torch.as_tensor(rng.standard_normal(shape))
    np.testing.assert_allclose(od.add_difference(x, axis, base.clone(), alpha=-0.5).numpy(),
                               (base - 0.5 * Dx).numpy(), atol=1e-12)
    np.testing.assert_allclose(od.add_adjoint(g, axis, base.clone(), alpha=2.0).numpy(), (base + 2 * DTg).numpy(),
                               atol=1e-12)


def test_zero_disparity_gives_the_differences_along_the_view_axes(engine):
    x = torch.as_tensor(np.random.default_rng(1).random((3, 4, 5, 6, 1)))
    od = OrientedDifferences(torch.zeros(5, 6, dtype=torch.float64))
    gv, gu, _, _ = gradient4d(x)
    np.testing.assert_allclose(od.difference(x, 0).numpy(), gv.numpy(), atol=1e-15)
    np.testing.assert_allclose(od.difference(x, 1).numpy(), gu.numpy(), atol=1e-15)


def test_a_lambertian_plane_has_no_oriented_differences_at_its_disparity():
    lf = plane_lightfield((5, 5, 20, 24), 1.0)[..., None]  # integer disparity: the views are exact shifts
    x = torch.as_tensor(lf, dtype=torch.float64)
    inner = (slice(None), slice(None), slice(3, -3), slice(3, -3))
    at = OrientedDifferences(torch.ones(20, 24, dtype=torch.float64))
    views = OrientedDifferences(torch.zeros(20, 24, dtype=torch.float64))
    for axis in (0, 1):
        assert float(at.difference(x, axis)[inner].abs().max()) < 1e-6
        assert float(views.difference(x, axis)[inner].abs().max()) > 0.05


def test_scene_disparity_finds_a_plane():
    for d in (0.75, -1.5):
        lf = plane_lightfield((5, 5, 24, 24), d)
        est = scene_disparity(torch.as_tensor(lf)[..., None])
        assert np.median(est[4:-4, 4:-4]) == pytest.approx(d, abs=0.07)
    assert scene_disparity(torch.zeros(3, 3, 8, 8, 1), 2.0).shape == (8, 8)
    # with d_inf, the search reaches |d_inf| further: a plane at 3.5 px/view (beyond the reach alone) is found
    lf = plane_lightfield((5, 5, 32, 32), 3.5)
    # the search reaches DISPARITY_REACH + |d_inf|, for d_inf < 0 as well (the mirror image of the case above)
    for d, d_inf in ((3.5, 2.0), (-3.5, -2.0)):
        lf = plane_lightfield((5, 5, 32, 32), d)
        est = scene_disparity(torch.as_tensor(lf)[..., None], d_inf)
        assert np.median(est[6:-6, 6:-6]) == pytest.approx(d, abs=0.07)


def test_scene_disparity_reaches_its_documented_limit():
    # with d_inf = 0 the shears tried are |d| <= DISPARITY_REACH = 2.5 px/view (documented in _disparity) in steps
    # of 0.125: a plane at exactly +-2.5 is on the grid, and found there
    for d in (2.5, -2.5):
        lf = plane_lightfield((5, 5, 32, 32), d)
        est = scene_disparity(torch.as_tensor(lf)[..., None], 0.0)
        assert np.median(est[6:-6, 6:-6]) == pytest.approx(d, abs=0.01)


@pytest.mark.parametrize("isotropic, coupled", [(True, True), (True, False), (False, True), (False, False)])
@pytest.mark.parametrize("channels", [2, 3])  # three channels have loops of their own
def test_tv_prox_and_value_with_oriented_differences(isotropic, coupled, channels, engine):
    rng = np.random.default_rng(3)
    shape = (3, 4, 6, 5, channels)
    aw, mu, n_inner = (1.0, 0.5, 1.0, 2.0), 0.3, 4
    od = OrientedDifferences(torch.as_tensor(rng.uniform(-1.5, 1.5, shape[2:4])))

    def grad(x):
        _, _, gy, gx = gradient4d(x)
        return [aw[0] * od.difference(x, 0), aw[1] * od.difference(x, 1), aw[2] * gy, aw[3] * gx]

    def div(p):  # -grad^T p
        out = -gradient4d_adjoint_spatial(p[2:], aw)
        od.add_adjoint(p[0], 0, out, alpha=-aw[0])
        od.add_adjoint(p[1], 1, out, alpha=-aw[1])
        return out

    v = torch.as_tensor(rng.uniform(-0.5, 1.5, shape))
    prox = TVProx(v, n_inner, isotropic, aw, (0.0, 1.0), coupled=coupled, oriented=od)
    # the dual step 1 / (mu lip) converges only if lip bounds ||grad||^2 of these weighted oriented
    # differences: ||grad x||^2 at a unit x, power-iterated on -div(grad), is a lower estimate of it
    x = torch.as_tensor(np.random.default_rng(7).standard_normal(shape))
    for _ in range(100):
        x = -div(grad(x))
        x = x / torch.linalg.vector_norm(x)
    norm_sq = float(sum((g * g).sum() for g in grad(x)))
    assert norm_sq <= prox.lip
    assert norm_sq > 0.5 * prox.lip  # measured 20.4 against 27.5
    p = [torch.zeros(shape, dtype=torch.float64) for _ in range(4)]
    step = 1.0 / (mu * prox.lip)
    for _ in range(n_inner):
        g = grad((v + mu * div(p)).clamp(0, 1))
        p = [a + step * b for a, b in zip(p, g)]
        project_tv_dual(p, 1.0, isotropic, coupled_channels=coupled)
    out = torch.empty_like(v)
    prox(v, mu, out)
    np.testing.assert_allclose(out.numpy(), (v + mu * div(p)).clamp(0, 1).numpy(), atol=1e-12)
    sq = [q * q for q in grad(v)]
    if isotropic:
        want = (sum(sq).sum(-1) if coupled else sum(sq)).sqrt().sum()
    else:
        want = sum((q.sum(-1).sqrt() if coupled else q.sqrt()).sum() for q in sq)
    assert tv_value(v, isotropic, aw, coupled=coupled, oriented=od) == pytest.approx(float(want), rel=1e-12)


def gradient4d_adjoint_spatial(p, aw):
    """``sum_a D_a^T p_a`` over the spatial axes (y, x) of forward differences, written out."""
    out = torch.zeros_like(p[0])
    for axis, g in zip((2, 3), p):
        n = g.shape[axis]
        head = aw[axis] * g.narrow(axis, 0, n - 1)
        out.narrow(axis, 0, n - 1).sub_(head)
        out.narrow(axis, 1, n - 1).add_(head)
    return out


def test_disparity_tv_restores_a_noisy_blurred_plane_better_than_the_view_tv():
    # a plane off the zero-disparity plane: its texture's parallax is what the view-axis TV penalises
    sharp = plane_lightfield((5, 5, 32, 32), 1.0, seed=4)
    cp = linear_path(1.0, angle_deg=30)
    blurred = simulate_blur(sharp, cp, n_times=8)
    blurred = np.clip(blurred + np.random.default_rng(5).normal(0, 0.03, blurred.shape), 0, 1).astype(np.float32)
    inner = (slice(None), slice(None), slice(4, -4), slice(4, -4))
    errors = {a: rmse(deconvolve(blurred, cp, n_times=8, angular=a, n_iter=60)[inner], sharp[inner])
              for a in ("views", "disparity")}
    assert errors["views"] < rmse(blurred[inner], sharp[inner])
    assert errors["disparity"] < 0.9 * errors["views"]


def test_bad_angular_and_disparity_map():
    with pytest.raises(ValueError, match="unknown angular differences 'pixel'"):
        DeconvolutionParams(angular="pixel")
    with pytest.raises(ValueError, match="finite"):
        OrientedDifferences(torch.tensor([[0.0, float("nan")]]))
    od = OrientedDifferences(torch.zeros(4, 5))
    with pytest.raises(ValueError, match="views 5x5; the disparity map is 4x5"):
        od.difference(torch.zeros(2, 2, 5, 5, 1), 0)
    # the fused prox writes through numpy: a strided output would be a copy, its result lost
    from napari_lfdeblur import _fused

    if _fused.available("cpu"):
        v = torch.zeros(2, 2, 4, 5, 1)
        dual = [torch.zeros_like(v) for _ in range(4)]
        strided = torch.zeros(2, 2, 5, 4, 1).transpose(2, 3)
        with pytest.raises(ValueError, match="contiguous"):
            od.fused_prox(v, dual, [0.1] * 4, None, strided)
