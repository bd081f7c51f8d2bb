"""4D finite differences, divergence (exact negative adjoint), TV and its dual projection."""

import math

import numpy as np
import pytest
import torch

from napari_lfdeblur.priors import (
    divergence4d,
    gradient4d,
    gradient_norm_bound,
    project_tv_dual,
    prox_l1,
    tv4d,
)


def _np_forward_diff(a, axis):
    out = np.zeros_like(a)
    n = a.shape[axis]
    sl_hi = [slice(None)] * a.ndim
    sl_lo = [slice(None)] * a.ndim
    sl_hi[axis] = slice(1, n)
    sl_lo[axis] = slice(0, n - 1)
    out[tuple(sl_lo)] = a[tuple(sl_hi)] - a[tuple(sl_lo)]
    return out


@pytest.mark.parametrize("shape", [(3, 4, 5, 6), (2, 3, 4, 5, 3), (1, 4, 1, 5)])
def test_gradient_matches_numpy_forward_differences(shape):
    a = np.random.default_rng(0).random(shape)
    g = gradient4d(torch.from_numpy(a))
    assert len(g) == 4
    for axis in range(4):
        np.testing.assert_allclose(g[axis].numpy(), _np_forward_diff(a, axis), atol=1e-12)
        # Neumann boundary: zero at the last sample of the differenced axis
        assert np.all(g[axis].numpy().take(-1, axis=axis) == 0)


def test_gradient_of_a_ramp_is_one_inside_zero_at_the_end():
    v, u, y, x = np.meshgrid(*(np.arange(n, dtype=float) for n in (3, 4, 5, 6)), indexing="ij")
    ramp = torch.from_numpy(2 * v - u + 0.5 * y + 3 * x)
    want = (2.0, -1.0, 0.5, 3.0)
    for axis, g in enumerate(gradient4d(ramp)):
        inner = g.numpy().take(range(ramp.shape[axis] - 1), axis=axis)
        np.testing.assert_allclose(inner, want[axis])


@pytest.mark.parametrize("shape", [(3, 4, 5, 6), (2, 3, 4, 5, 3), (1, 2, 7, 1)])
@pytest.mark.parametrize("weights", [None, (0.5, 2.0, 1.0, 3.0)])
def test_divergence_is_exact_negative_adjoint(shape, weights):
    rng = np.random.default_rng(1)
    L = torch.from_numpy(rng.standard_normal(shape))
    G = [torch.from_numpy(rng.standard_normal(shape)) for _ in range(4)]
    lhs = sum((g * h).sum() for g, h in zip(gradient4d(L, weights), G))
    rhs = -(L * divergence4d(G, weights)).sum()
    assert abs(float(lhs - rhs)) < 1e-10 * max(1.0, abs(float(lhs)))
    # into a given tensor (whatever it held): the same values, in that tensor
    buf = torch.full(shape, 7.0, dtype=torch.float64)
    assert divergence4d(G, weights, out=buf) is buf
    torch.testing.assert_close(buf, divergence4d(G, weights), rtol=0, atol=0)
    # scaled and added onto what the tensor held
    base = torch.from_numpy(rng.standard_normal(shape))
    acc = divergence4d(G, weights, out=base.clone(), scale=-0.3, accumulate=True)
    torch.testing.assert_close(acc, base - 0.3 * divergence4d(G, weights))
    with pytest.raises(ValueError, match="needs out"):
        divergence4d(G, weights, accumulate=True)


def test_divergence_matches_autograd_vjp():
    rng = np.random.default_rng(2)
    L = torch.from_numpy(rng.standard_normal((3, 3, 4, 4))).requires_grad_(True)
    G = [torch.from_numpy(rng.standard_normal((3, 3, 4, 4))) for _ in range(4)]
    s = sum((g * h).sum() for g, h in zip(gradient4d(L), G))
    (vjp,) = torch.autograd.grad(s, L)
    torch.testing.assert_close(vjp, -divergence4d(G))


def test_tv_values_against_brute_force():
    a = np.random.default_rng(3).random((2, 3, 4, 5))
    grads = [_np_forward_diff(a, ax) for ax in range(4)]
    iso = np.sqrt(sum(g**2 for g in grads)).sum()
    aniso = sum(np.abs(g).sum() for g in grads)
    t = torch.from_numpy(a)
    assert float(tv4d(t)) == pytest.approx(iso, rel=1e-12)
    assert float(tv4d(t, isotropic=False)) == pytest.approx(aniso, rel=1e-12)
    assert float(tv4d(t, reduction="mean")) == pytest.approx(iso / a.size, rel=1e-12)
    # smoothing: 0 <= TV - TV_eps and -> 0 as eps -> 0
    assert 0 <= iso - float(tv4d(t, eps=1e-2)) < iso
    assert float(tv4d(t, eps=1e-8)) == pytest.approx(iso, rel=1e-6)
    assert float(tv4d(torch.ones(2, 2, 3, 3))) == 0.0


def test_colour_tv_against_brute_force():
    a = np.random.default_rng(5).random((2, 3, 4, 5, 3))
    grads = [_np_forward_diff(a, ax) for ax in range(4)]
    t = torch.from_numpy(a)
    # the norm per sample over axes and channels (isotropic), over channels per axis (anisotropic)
    iso = np.sqrt(sum((g**2).sum(-1) for g in grads)).sum()
    aniso = sum(np.sqrt((g**2).sum(-1)).sum() for g in grads)
    assert float(tv4d(t, coupled_channels=True)) == pytest.approx(iso, rel=1e-12)
    assert float(tv4d(t, isotropic=False, coupled_channels=True)) == pytest.approx(aniso, rel=1e-12)
    # grey (equal channels): sqrt(C) times the grey TV, where separate channels give C times
    grey = t[..., :1].expand(-1, -1, -1, -1, 3)
    assert float(tv4d(grey, coupled_channels=True)) == pytest.approx(np.sqrt(3) * float(tv4d(t[..., 0])), rel=1e-12)
    with pytest.raises(ValueError, match="channel axis"):
        tv4d(t[..., 0], coupled_channels=True)


@pytest.mark.parametrize("isotropic", [True, False])
def test_colour_dual_projection_is_the_dual_ball_of_colour_tv(isotropic):
    rng = np.random.default_rng(6)
    x = torch.from_numpy(rng.random((2, 3, 4, 5, 3)))
    G = gradient4d(x)
    # TV(x) = max over the dual ball of <grad x, p>, reached at the projection of t grad x for large t
    P = project_tv_dual([g * 1e6 for g in G], 1.0, isotropic, coupled_channels=True)
    assert sum(float((g * p).sum()) for g, p in zip(G, P)) == pytest.approx(
        float(tv4d(x, isotropic=isotropic, coupled_channels=True)), rel=1e-9)
    # a projection: points inside the ball stay, those outside land on its boundary along their direction
    Q = [torch.from_numpy(rng.standard_normal((2, 2, 5, 5, 3))) for _ in range(4)]
    orig = [q.clone() for q in Q]
    project_tv_dual(Q, 0.5, isotropic, coupled_channels=True)
    if isotropic:
        on = torch.sqrt(sum((o * o).sum(-1, keepdim=True) for o in orig))
        expected = [o * torch.clamp(0.5 / on, max=1.0) for o in orig]
    else:
        expected = [o * torch.clamp(0.5 / torch.sqrt((o * o).sum(-1, keepdim=True)), max=1.0) for o in orig]
    for q, e in zip(Q, expected):
        torch.testing.assert_close(q, e)


def test_dual_projection_and_soft_threshold():
    rng = np.random.default_rng(4)
    P = [torch.from_numpy(rng.standard_normal((2, 2, 5, 5))) for _ in range(4)]
    orig = [p.clone() for p in P]
    project_tv_dual(P, 0.5, isotropic=True)
    norm = torch.sqrt(sum(p * p for p in P))
    onorm = torch.sqrt(sum(p * p for p in orig))
    assert float(norm.max()) <= 0.5 + 1e-12
    inside = onorm <= 0.5
    for p, o in zip(P, orig):
        torch.testing.assert_close(p[inside], o[inside])  # unchanged inside the ball
        # outside: same direction, radius 0.5
        torch.testing.assert_close(p[~inside], (o / onorm * 0.5)[~inside])
    Q = [o.clone() for o in orig]
    project_tv_dual(Q, 0.3, isotropic=False)
    for q, o in zip(Q, orig):
        torch.testing.assert_close(q, o.clamp(-0.3, 0.3))
    x = torch.tensor([-2.0, -0.1, 0.0, 0.2, 3.0])
    torch.testing.assert_close(prox_l1(x, 0.5), torch.tensor([-1.5, 0.0, 0.0, 0.0, 2.5]))


def _exact_gradient_norm_sq(shape, weights):
    # The forward difference with a zero last row on n samples has ||D||^2 = 4 sin^2(pi (n - 1) / (2 n)) (its
    # D^T D is the Neumann Laplacian, eigenvalues 4 sin^2(pi k / (2 n)), k < n). The weighted 4D gradient stacks
    # commuting Kronecker factors, so ||grad_w||^2 = sum_a w_a^2 ||D_{n_a}||^2.
    return sum(w * w * 4.0 * math.sin(math.pi * (n - 1) / (2 * n)) ** 2 for w, n in zip(weights, shape))


@pytest.mark.parametrize("weights", [None, (1, 1, 2, 2), (0.5, 1, 2, 3)])
def test_gradient_norm_bound_holds(weights):
    w = (1.0, 1.0, 1.0, 1.0) if weights is None else weights
    shape = (4, 4, 6, 6)
    # power iteration on -div_w(grad_w) estimates ||grad_w||^2 from below and reaches the analytic value
    x = torch.from_numpy(np.random.default_rng(5).standard_normal(shape))
    for _ in range(200):
        x = -divergence4d(gradient4d(x, weights), weights)
        x = x / torch.linalg.vector_norm(x)
    est = float((x * -divergence4d(gradient4d(x, weights), weights)).sum())
    exact = _exact_gradient_norm_sq(shape, w)
    assert 0.99 * exact <= est <= exact * (1 + 1e-9)
    bound = gradient_norm_bound(weights)
    assert exact <= bound + 1e-9
    assert est > 0.5 * bound
    # the bound holds for every field size, including a large one whose exact norm nears 4 sum_a w_a^2
    assert _exact_gradient_norm_sq((64, 64, 256, 256), w) <= bound + 1e-9


def test_bad_input():
    with pytest.raises(ValueError, match="4 axes"):
        gradient4d(torch.zeros(3, 3, 3))
    with pytest.raises(ValueError, match="axis_weights"):
        gradient4d(torch.zeros(2, 2, 2, 2), axis_weights=(1, 1))
    with pytest.raises(ValueError, match="4 components"):
        divergence4d([torch.zeros(2, 2, 2, 2)] * 3)
    with pytest.raises(ValueError, match="reduction"):
        tv4d(torch.zeros(2, 2, 2, 2), reduction="max")


def test_spatial_gradient_is_the_yx_part_of_gradient4d_and_its_divergence_the_adjoint():
    from napari_lfdeblur.priors import divergence_yx, gradient_yx

    torch.manual_seed(5)
    L = torch.rand(3, 4, 5, 6, 2, dtype=torch.float64)
    gy, gx = gradient_yx(L)
    g4 = gradient4d(L)
    assert torch.equal(gy, g4[2]) and torch.equal(gx, g4[3])
    G = (torch.rand_like(L), torch.rand_like(L))
    lhs = float((gy * G[0]).sum() + (gx * G[1]).sum())
    assert lhs == pytest.approx(-float((L * divergence_yx(*G)).sum()), rel=1e-12)
    zero = torch.zeros_like(L)
    assert torch.equal(divergence_yx(*G), divergence4d((zero, zero) + G))
    with pytest.raises(TypeError):
        gradient_yx(np.zeros((2, 2, 3, 3)))


@pytest.mark.parametrize("shape", [(3, 4, 6, 5, 2), (2, 3, 4, 5), (1, 3, 1, 4, 3)])
@pytest.mark.parametrize("weights", [(1.0, 1.0, 1.0, 1.0), (0.5, 0.25, 1.0, 2.0), (0.0, 0.0, 1.0, 1.0)])
def test_fused_laplacian_step_is_a_plus_scaled_minus_div_grad(shape, weights):
    from napari_lfdeblur import _fused

    if not _fused.available("cpu"):
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(6)
    a, z = (torch.as_tensor(rng.random(shape)) for _ in range(2))
    ref = a - 0.7 * divergence4d(gradient4d(z, weights), weights)
    got = _fused.add_laplacian(a, z, weights, 0.7)
    np.testing.assert_allclose(got.numpy(), ref.numpy(), atol=1e-12)


def test_sparse_gradient_prior_rejects_a_non_positive_eps():
    from napari_lfdeblur.priors import sparse_gradient_prior

    with pytest.raises(ValueError, match="eps"):
        sparse_gradient_prior(torch.zeros(2, 2, 3, 3), 0.0)


@pytest.mark.parametrize("weights", [None, (0.5, 0.25, 1.0, 2.0), (0.0, 0.0, 1.0, 1.0)])
def test_laplacian_is_minus_the_divergence_of_the_gradient(weights):
    from napari_lfdeblur.priors import laplacian4d

    L = torch.as_tensor(np.random.default_rng(4).random((3, 4, 6, 5, 2)))
    ref = -divergence4d(gradient4d(L, weights), weights)
    np.testing.assert_allclose(laplacian4d(L, weights).numpy(), ref.numpy(), atol=1e-12)
    out = torch.full_like(L, 7.0)  # overwritten, not added to
    assert laplacian4d(L, weights, out=out) is out
    np.testing.assert_allclose(out.numpy(), ref.numpy(), atol=1e-12)
    # positive semi-definite: <L, lap L> = ||grad L||^2
    np.testing.assert_allclose(float((L * ref).sum()), sum(float((g * g).sum()) for g in gradient4d(L, weights)))


@pytest.mark.parametrize("weights", [(1, 1, 1, float("nan")), (1, 1, float("inf"), 1), (1, 1, -1, 1), (1, 1, 1)])
def test_axis_weights_are_four_finite_non_negative_numbers(weights):
    """A NaN weight would make every TV value and prox NaN; an infinite one, every difference along its axis."""
    from napari_lfdeblur.priors import tv4d

    with pytest.raises(ValueError, match="axis_weights must be 4 non-negative numbers"):
        tv4d(torch.zeros(2, 2, 3, 3, 1), axis_weights=weights)


def test_smoothed_tv_and_the_sparse_gradient_prior_of_one_step_are_their_formulas():
    """One step of height h along x: tv4d's smoothing is sqrt(h^2 + eps^2) - eps per step (0 where flat), the
    sparse-gradient prior min(h^2 / eps^2, 1) per step, averaged over the field (its differences are the field's
    shape, the last one 0)."""
    from napari_lfdeblur.priors import sparse_gradient_prior, tv4d

    L = torch.zeros(2, 2, 3, 4, 1, dtype=torch.float64)
    L[..., 2:, :] = 0.3  # a step between x = 1 and x = 2 in every row: 2 * 2 * 3 steps of height 0.3
    eps, h, steps = 0.1, 0.3, 12
    assert float(tv4d(torch.zeros_like(L), eps=eps)) == 0.0  # flat: no cost, not eps per difference
    assert float(tv4d(L, eps=eps, isotropic=False)) == pytest.approx(steps * (math.sqrt(h * h + eps * eps) - eps))
    n = L.numel()
    assert float(sparse_gradient_prior(L, eps=0.6)) == pytest.approx(steps * (h * h / 0.36) / n)
    assert float(sparse_gradient_prior(L, eps=0.1)) == pytest.approx(steps / n)  # each step costs 1
