"""On a CUDA GPU the operators, the solvers and the blind pipeline give what they give on the CPU.

Skipped where torch sees no GPU (as on CI); ``benchmarks/gpu_check.sh`` runs them on a machine with one.
The CPU results they are compared with are themselves checked against brute-force references in
``test_blur.py``, ``test_rotation.py`` and ``test_deconvolution.py``.
"""

import numpy as np
import pytest
import torch

from napari_lfdeblur import blind_deblur, deconvolve, random_path, simulate_blur
from napari_lfdeblur.blind import BlindParams
from napari_lfdeblur.blur import BlurOperator
from napari_lfdeblur.path import linear_path
from test_blind import FAST, _scene
from test_deconvolution import tv_case

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")

SHAPE = (5, 5, 24, 28, 3)


def _path(motion: str) -> np.ndarray:
    """A curved path with ``p_z != 0``; with ``'6dof'`` also a rotation of up to 0.02 rad."""
    cp = random_path(3, extent=2.0, z_extent=1.0, seed=4)
    if motion == "6dof":
        rot = np.random.default_rng(5).uniform(-0.02, 0.02, (3, 3))
        cp = np.concatenate([cp, rot - rot.mean(axis=0)], axis=1)
    return cp


def _pair(seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(SHAPE, generator=g), torch.rand(SHAPE, generator=g)


@pytest.mark.parametrize("motion", ["3dof", "6dof"])
@pytest.mark.parametrize("d_inf", [0.0, 1.0])
def test_operator_on_the_gpu_matches_the_cpu_and_is_adjoint(motion, d_inf):
    x, y = _pair()
    cpu = BlurOperator(SHAPE, _path(motion), n_times=8, infinity_disparity=d_inf, device="cpu")
    gpu = BlurOperator(SHAPE, _path(motion), n_times=8, infinity_disparity=d_inf, device="cuda")
    fx, aty = gpu.forward(x.cuda()), gpu.adjoint(y.cuda())
    assert fx.is_cuda and aty.is_cuda
    torch.testing.assert_close(fx.cpu(), cpu.forward(x), atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(aty.cpu(), cpu.adjoint(y), atol=1e-5, rtol=1e-5)
    lhs = float((fx.double() * y.cuda().double()).sum())
    rhs = float((x.cuda().double() * aty.double()).sum())
    assert abs(lhs - rhs) <= 1e-5 * abs(lhs)


@pytest.mark.parametrize("motion", ["3dof", "6dof"])
def test_path_gradient_on_the_gpu_matches_the_cpu(motion):
    x, target = _pair(1)
    grads = {}
    for dev in ("cpu", "cuda"):
        cp = torch.tensor(_path(motion), dtype=torch.float32, device=dev, requires_grad=True)
        op = BlurOperator(SHAPE, cp, n_times=8, infinity_disparity=0.5, device=dev)
        loss = 0.5 * (op.forward(x.to(dev)) - target.to(dev)).square().sum()
        loss.backward()
        grads[dev] = cp.grad.cpu()
    torch.testing.assert_close(grads["cuda"], grads["cpu"], atol=1e-3, rtol=1e-3)


@pytest.mark.parametrize("d_inf", [0.0, 1.0])
def test_tv_deconvolution_on_the_gpu_matches_the_cpu(d_inf):
    lf, cp, blurred = tv_case(d_inf)
    out = {dev: deconvolve(blurred, cp, n_times=8, infinity_disparity=d_inf, device=dev) for dev in ("cpu", "cuda")}
    assert out["cuda"].dtype == np.float32 and out["cuda"].shape == lf.shape
    # the same iterations up to rounding (the GPU sweeps the whole field as one block of rows)
    assert np.sqrt(np.mean((out["cuda"] - out["cpu"]) ** 2)) < 1e-3
    assert np.sqrt(np.mean((out["cuda"] - lf) ** 2)) < 0.7 * np.sqrt(np.mean((blurred - lf) ** 2))


def test_blind_deblurring_on_the_gpu_finds_the_blur_and_lowers_the_error():
    sharp = _scene()
    rng = np.random.default_rng(1)
    blurred = simulate_blur(sharp, linear_path(2.0, angle_deg=30.0), n_times=32)
    blurred = np.clip(blurred + rng.normal(0, 0.002, sharp.shape), 0, 1).astype(np.float32)
    res = blind_deblur(blurred, params=BlindParams().replace(n_control_points=2, **FAST), device="cuda", seed=0)
    assert res.info["device"].startswith("cuda")
    assert res.info["blur_found"] is True
    c = 6
    err_blurred = np.sqrt(np.mean((blurred - sharp)[:, :, c:-c, c:-c] ** 2))
    err_restored = np.sqrt(np.mean((res.lightfield - sharp)[:, :, c:-c, c:-c] ** 2))
    assert err_restored < 0.75 * err_blurred  # as on the CPU (test_blind.py)


def test_a_gpu_short_of_memory_restores_in_tiles_on_the_gpu(monkeypatch):
    # as test_blind.test_short_memory_runs_in_overlapping_tiles, with the GPU's plan
    from napari_lfdeblur import devices
    from napari_lfdeblur.blind import _memory

    sharp = _scene((5, 5, 72, 72), seed=6)
    cp = np.array([[-0.6, 0.2, -0.3], [0.5, -0.3, 0.3]])
    blurred = simulate_blur(sharp, cp, n_times=32)
    p = BlindParams().replace(n_control_points=2, path=dict(n_outer=2, steps=60, region=40),
                              final={"n_iter": 20, "tol": 0.0}, final_n_times=8)
    whole, path_stage = _memory._memory_of_stages(blurred.shape, p)
    assert path_stage < whole
    monkeypatch.setattr(devices, "free_memory", lambda device: (whole + path_stage) // 2)
    with pytest.warns(RuntimeWarning, match="overlapping tiles"):
        res = blind_deblur(blurred, params=p, device="cuda", seed=0)
    assert res.info["device"].startswith("cuda") and res.info["tile"][0] < 72
    # the tiles, with their overlap, give nearly what one full-frame solve with that path gives
    ref = deconvolve(blurred, res.control_points, n_times=8, method="tv", n_iter=20, tol=0.0, device="cuda")
    assert np.abs(res.lightfield - ref).max() < 2e-3
