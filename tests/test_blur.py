"""The forward model against MODEL.md: brute force, special cases, ambiguities, gradients, adjoint."""

import numpy as np
import pytest
import torch

from _reference import blur_reference
from napari_lfdeblur import _fused, random_path, simulate_blur
from napari_lfdeblur.blur import BlurOperator, to_tensor
from napari_lfdeblur.path import bezier_positions, center_path


@pytest.mark.parametrize("shape", [(5, 4, 7, 9), (3, 5, 7, 6, 3)], ids=["gray", "colour"])
@pytest.mark.parametrize("d_inf", [0.0, 0.7, -1.3])
@pytest.mark.parametrize("seed", [0, 1])
def test_simulate_blur_matches_brute_force(shape, d_inf, seed, engine):
    rng = np.random.default_rng(seed)
    lf = rng.random(shape).astype(np.float32)
    cp = random_path(n_points=int(rng.integers(2, 5)), extent=3.0, z_extent=2.0, seed=seed + 10)
    got = simulate_blur(lf, cp, n_times=7, infinity_disparity=d_inf, device="cpu")
    want = blur_reference(lf, cp, 7, d_inf)
    assert got.dtype == np.float32 and got.shape == lf.shape
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_small_blocks_give_the_same_result(monkeypatch):
    monkeypatch.setattr(_fused, "available", lambda *args: False)  # blocks are the torch version's
    rng = np.random.default_rng(3)
    lf = torch.rand(4, 5, 11, 6, 2, dtype=torch.float64)
    cp = random_path(3, extent=2.0, z_extent=1.0, seed=2)
    big = BlurOperator(lf.shape, cp, n_times=5, device="cpu", dtype=torch.float64)
    tiny = BlurOperator(lf.shape, cp, n_times=5, device="cpu", dtype=torch.float64, block_elements=1)
    torch.testing.assert_close(big.forward(lf), tiny.forward(lf))
    y = torch.from_numpy(rng.random(lf.shape))
    torch.testing.assert_close(big.adjoint(y), tiny.adjoint(y))


def test_taps_left_out_where_they_weigh_nothing_change_nothing(engine):
    # a large p_z moves the (v, y) and (u, x) offsets across the image: in blocks of one row, many of the 4D
    # kernel's taps weigh nothing, or only in some columns, and are left out there
    rng = np.random.default_rng(4)
    lf = rng.random((4, 5, 12, 14, 1))
    cp = np.array([[-0.3, 0.2, -2.5], [0.4, -0.1, 2.5]])
    op = BlurOperator(lf.shape, cp, n_times=6, infinity_disparity=1.5, device="cpu", dtype=torch.float64,
                      block_elements=1)
    taps = op._taps()
    X = lf.shape[3]
    if engine == "torch":
        assert any(len(spans) < len(taps.taps) or any(b - a < X for _, a, b in spans) for spans in taps.spans)
    else:  # the fused loops' column spans, per tap and row
        x0, x1 = taps.spans
        assert (x0 >= x1).any() and ((x1 - x0) < X).any()
    x = torch.from_numpy(lf)
    np.testing.assert_allclose(op.forward(x).numpy(), blur_reference(lf, cp, 6, 1.5), atol=1e-12)
    y = torch.from_numpy(rng.random(lf.shape))
    assert abs(float((op.forward(x) * y).sum() - (x * op.adjoint(y)).sum())) < 1e-10


def test_zero_path_is_identity():
    lf = np.random.default_rng(0).random((5, 5, 8, 9, 3)).astype(np.float32)
    for d_inf in (0.0, 1.5):
        out = simulate_blur(lf, np.zeros((3, 3)), n_times=4, infinity_disparity=d_inf)
        np.testing.assert_array_equal(out, lf)


def test_constant_integer_path_is_an_exact_view_shift():
    lf = np.random.default_rng(1).random((5, 6, 8, 8)).astype(np.float32)
    out = simulate_blur(lf, [[2, -1, 0], [2, -1, 0]], n_times=3)
    # f[v, u] = l[clamp(v - 1), clamp(u + 2)]
    v = np.clip(np.arange(5) - 1, 0, 4)
    u = np.clip(np.arange(6) + 2, 0, 5)
    np.testing.assert_allclose(out, lf[v][:, u], rtol=0, atol=1e-6)  # float32 mean of equal terms


def test_time_reversal_and_reordering_give_the_same_blur():
    lf = np.random.default_rng(2).random((5, 5, 10, 10)).astype(np.float32)
    cp = random_path(4, extent=3.0, z_extent=1.0, seed=5)
    fwd = simulate_blur(lf, cp, n_times=9, infinity_disparity=0.4)
    rev = simulate_blur(lf, cp[::-1], n_times=9, infinity_disparity=0.4)
    np.testing.assert_allclose(fwd, rev, atol=1e-6)
    # any reordering of the visited positions: compare a sum of constant-path blurs
    pos = bezier_positions(cp, 9)
    acc = sum(simulate_blur(lf, [p, p], n_times=2, infinity_disparity=0.4) for p in pos[::-1])
    np.testing.assert_allclose(fwd, acc / 9, atol=1e-5)


def test_constant_offset_ambiguity():
    """blur(l, p + c) == blur(view of l from c, p) away from the aperture border.

    With an integer in-plane offset c, viewing from c is an exact view shift,
    so the identity holds wherever no sample was clamped.
    """
    lf = np.random.default_rng(3).random((9, 9, 8, 8)).astype(np.float32)
    cp = random_path(3, extent=1.0, seed=4)  # positions within about +-0.5 views
    c = np.array([1.0, -1.0, 0.0])
    shifted = simulate_blur(lf, cp + c, n_times=8)
    moved = simulate_blur(lf, [c, c], n_times=2)
    other = simulate_blur(moved, cp, n_times=8)
    inner = (slice(2, -2), slice(2, -2))
    np.testing.assert_allclose(shifted[inner], other[inner], atol=1e-6)


def test_center_path_zero_mean():
    cp = random_path(4, extent=3.0, z_extent=1.0, seed=1) + 5.0
    centred = center_path(cp, n_times=11)
    np.testing.assert_allclose(bezier_positions(centred, 11).mean(axis=0), 0.0, atol=1e-12)


@pytest.mark.parametrize("d_inf", [0.0, 0.6])
def test_gradcheck_lightfield_and_path(d_inf, engine):
    torch.manual_seed(0)
    lf = torch.rand(3, 4, 5, 4, 1, dtype=torch.float64, requires_grad=True)
    # keep away from integer sample positions, where bilinear weights have kinks
    cp = torch.tensor(random_path(3, extent=1.3, z_extent=0.7, seed=7) + 0.137,
                      dtype=torch.float64, requires_grad=True)

    def f(lf, cp):
        return BlurOperator(lf.shape, cp, n_times=4, infinity_disparity=d_inf, dtype=torch.float64).forward(lf)

    assert torch.autograd.gradcheck(f, (lf, cp), eps=1e-6, atol=1e-6)


@pytest.mark.parametrize("d_inf", [0.0, 0.6])
def test_path_gradient_on_the_views_is_the_right_sided_derivative(d_inf, engine):
    # an in-plane path along x: p_y is 0 at every instant, so every lookup along v falls exactly on a view,
    # where the weight of the next view is zero but its difference from this view is the derivative
    torch.manual_seed(0)
    lf = torch.rand(4, 5, 6, 7, 1, dtype=torch.float64)
    target = torch.rand(4, 5, 6, 7, 1, dtype=torch.float64)
    cp0 = torch.tensor([[-1.1, 0.0, 0.0], [0.3, 0.0, 0.0], [0.9, 0.0, 0.0]], dtype=torch.float64)

    def loss(cp):
        op = BlurOperator(lf.shape, cp, n_times=5, infinity_disparity=d_inf, dtype=torch.float64)
        return 0.5 * ((op.forward(lf) - target) ** 2).sum()

    cp = cp0.clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(loss(cp), cp)
    h = 1e-7
    for i in range(3):
        step = torch.zeros_like(cp0)
        step[i, 1] = h
        right = (loss(cp0 + step) - loss(cp0)) / h
        assert float(grad[i, 1]) == pytest.approx(float(right), rel=1e-4, abs=1e-6), i
        left = (loss(cp0) - loss(cp0 - step)) / h
        assert abs(float(right - left)) > 1e-2  # a kink: the two sides differ


@pytest.mark.parametrize("d_inf", [0.0, 0.8])
def test_adjoint(d_inf, engine):
    gen = torch.Generator().manual_seed(1)
    shape = (4, 5, 7, 6, 3)
    x = torch.rand(shape, generator=gen, dtype=torch.float64)
    y = torch.rand(shape, generator=gen, dtype=torch.float64)
    op = BlurOperator(shape, random_path(4, 3.0, 2.0, seed=2), n_times=6,
                      infinity_disparity=d_inf, device="cpu", dtype=torch.float64)
    lhs = torch.sum(op.forward(x) * y)
    rhs = torch.sum(x * op.adjoint(y))
    assert abs(float(lhs - rhs)) < 1e-10 * float(abs(lhs))


@pytest.mark.parametrize("d_inf", [0.0, -0.9])
def test_adjoint_equals_autograd_vjp(d_inf, engine):
    shape = (3, 4, 5, 6, 1)
    x = torch.rand(shape, dtype=torch.float64, requires_grad=True)
    y = torch.rand(shape, dtype=torch.float64)
    op = BlurOperator(shape, random_path(3, 2.0, 1.0, seed=0), n_times=5, infinity_disparity=d_inf, device="cpu",
                      dtype=torch.float64)
    (g,) = torch.autograd.grad(op.forward(x), x, y)
    torch.testing.assert_close(op.adjoint(y), g)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(lf=np.zeros((4, 4, 4))), "4D"),
        (dict(lf=np.full((3, 3, 4, 4), np.nan)), "NaN"),
        (dict(control_points=[[0, 0, 0]]), "at least 2"),
        (dict(control_points=[[0, 0], [1, 1]]), r"\(n, 3\)"),
        (dict(control_points=[[0, 0, np.nan], [1, 1, 0]]), "NaN"),
        (dict(n_times=1), "n_times"),
        (dict(n_times=2.5), "n_times"),
        (dict(infinity_disparity=np.inf), "infinity_disparity must be finite"),
        (dict(infinity_disparity=-2.5), "must be at most 2"),  # 3x3 views of 4x4 px: the outer ones move 2.5 px
        (dict(lf=(np.zeros((3, 3, 4, 4)), np.zeros((4, 4)))), "pass the first"),  # a scene's (lf, disparity)
        (dict(lf=[np.zeros((3, 3, 4, 4))] * 2), "list of 2 arrays"),  # not read as one (2, 3, 3, 4, 4) array
    ],
)
def test_bad_input_gives_clear_errors(kwargs, message):
    args = dict(lf=np.zeros((3, 3, 4, 4)), control_points=[[0, 0, 0], [1, 0, 0]], n_times=4)
    args.update(kwargs)
    lf = args.pop("lf")
    cp = args.pop("control_points")
    with pytest.raises(ValueError, match=message):
        simulate_blur(lf, cp, **args)


def test_a_list_of_rows_of_views_is_one_light_field():
    lf = np.random.default_rng(0).random((3, 3, 4, 4))
    cp = [[0, 0, 0], [1, 0, 0]]
    np.testing.assert_array_equal(simulate_blur(list(lf), cp, n_times=4), simulate_blur(lf, cp, n_times=4))


def test_wrong_types_are_type_errors():
    lf, cp = np.zeros((3, 3, 4, 4)), [[0, 0, 0], [1, 0, 0]]
    with pytest.raises(TypeError, match="infinity_disparity"):
        simulate_blur(lf, cp, n_times=4, infinity_disparity="far")


def test_operator_rejects_wrong_shape():
    op = BlurOperator((3, 3, 4, 4), [[0, 0, 0], [1, 0, 0]], n_times=3, device="cpu")
    with pytest.raises(ValueError, match="shape"):
        op.forward(torch.zeros(3, 3, 4, 5, 1))
    assert to_tensor(np.zeros((3, 3, 4, 4))).shape == (3, 3, 4, 4, 1)
    with pytest.raises(ValueError, match="whole numbers"):  # not truncated to (3, 3, 4, 4)
        BlurOperator((3.7, 3, 4, 4), [[0, 0, 0], [1, 0, 0]], n_times=3, device="cpu")
    for bad in (0, -5, 2.5, True):  # taken as it was, a block of no memory
        with pytest.raises(ValueError, match="block_elements must be a whole number >= 1"):
            BlurOperator((3, 3, 4, 4), [[0, 0, 0], [1, 0, 0]], n_times=3, device="cpu", block_elements=bad)


def test_in_plane_blur_is_one_angular_matrix_per_pixel():
    """In-plane motion: every pixel's (V*U) angular vector sees M = mean_k B_k (x) A_k."""
    from napari_lfdeblur.blur import interpolation_matrices

    rng = np.random.default_rng(4)
    lf = rng.random((4, 5, 6, 7)).astype(np.float32)
    cp = random_path(3, extent=3.0, seed=9)  # p_z = 0
    T = 6
    pos = torch.tensor(bezier_positions(cp, T))
    A, B, _, _ = interpolation_matrices(pos, lf.shape)
    M = sum(np.kron(B[k, 0].numpy(), A[k, 0].numpy()) for k in range(T)) / T
    want = (M @ lf.reshape(20, -1)).reshape(lf.shape)
    np.testing.assert_allclose(simulate_blur(lf, cp, n_times=T), want, atol=1e-5)
    # rows sum to one: the blur preserves constants
    np.testing.assert_allclose(M.sum(axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("d_inf", [0.0, 0.8])
def test_a_tile_with_its_frame_blurs_like_the_full_light_field(d_inf):
    rng = np.random.default_rng(5)
    lf = rng.random((5, 5, 30, 40)).astype(np.float32)
    cp = np.array([[-0.7, 0.3, -0.8], [0.4, -0.5, 0.2], [0.6, 0.4, 0.9]])  # strong p_z: shifts vary with x, y
    full = simulate_blur(lf, cp, n_times=12, infinity_disparity=d_inf, device="cpu")
    y0, x0, h, w = 7, 11, 16, 20
    op = BlurOperator((5, 5, h, w), cp, n_times=12, infinity_disparity=d_inf, device="cpu", frame=(y0, x0, 30, 40))
    tile = op.forward(torch.as_tensor(lf[:, :, y0 : y0 + h, x0 : x0 + w])[..., None])[..., 0].numpy()
    m = 0 if d_inf == 0 else 3  # d_inf shifts pixels across the tile's edge: compare inside a margin
    np.testing.assert_allclose(tile[:, :, m : h - m, m : w - m], full[:, :, y0 + m : y0 + h - m, x0 + m : x0 + w - m],
                               atol=1e-5)
    with pytest.raises(ValueError, match="does not fit"):
        BlurOperator((5, 5, h, w), cp, device="cpu", frame=(20, 0, 30, 40))
    with pytest.raises(ValueError, match="whole numbers"):  # was truncated to (1, 0, 30, 40)
        BlurOperator((5, 5, h, w), cp, device="cpu", frame=(1.7, 0.9, 30, 40))


@pytest.mark.parametrize("d_inf", [0.0, 4.0])
def test_fused_loops_agree_with_the_torch_version_far_past_the_edges(d_inf, monkeypatch):
    # at 4 px/view and p_z = 3 most taps of the outer views read beyond every edge of a 6 x 5 view
    if not _fused.available("cpu"):
        pytest.skip("numba is not installed")
    gen = torch.Generator().manual_seed(6)
    shape = (4, 3, 6, 5, 2)
    lf = torch.rand(shape, generator=gen, dtype=torch.float64, requires_grad=True)
    y = torch.rand(shape, generator=gen, dtype=torch.float64)
    cp = torch.tensor([[-1.6, 0.9, -3.0], [2.1, -1.2, 3.0], [0.3, 1.7, 1.0]], dtype=torch.float64, requires_grad=True)
    results = []
    for use_fused in (True, False):
        monkeypatch.setattr(_fused, "available", lambda *args, use=use_fused: use)
        op = BlurOperator(shape, cp, n_times=9, infinity_disparity=d_inf, device="cpu", dtype=torch.float64)
        assert isinstance(op._taps(), _fused.FusedTaps) == use_fused
        out = op.forward(lf)
        results.append([out, op.adjoint(y), *torch.autograd.grad((out * y).sum(), (lf, cp))])
    for got, want in zip(*results):
        torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-12)


def test_the_fused_loops_can_be_turned_off(monkeypatch):
    monkeypatch.setenv("NAPARI_LFDEBLUR_NUMBA", "0")
    _fused._loops.cache_clear()
    try:
        assert not _fused.available("cpu")
        op = BlurOperator((3, 3, 4, 5), [[0, 0, 0.5], [1, 0, -0.5]], n_times=3, infinity_disparity=0.5, device="cpu")
        assert not isinstance(op._taps(), _fused.FusedTaps)
    finally:
        _fused._loops.cache_clear()
    assert not _fused.available("cuda") and not _fused.available("cpu", torch.float16)


def test_a_numba_that_fails_to_load_falls_back_with_a_warning(monkeypatch):
    import sys

    import napari_lfdeblur

    monkeypatch.delattr(napari_lfdeblur, "_fused_loops", raising=False)
    monkeypatch.setitem(sys.modules, "napari_lfdeblur._fused_loops", None)  # its import now raises ImportError
    _fused._loops.cache_clear()
    try:
        with pytest.warns(RuntimeWarning, match="numba could not be loaded.*torch version"):
            assert not _fused.available("cpu")
        lf = np.random.default_rng(8).random((3, 3, 5, 6)).astype(np.float32)
        cp = [[-0.4, 0.3, 0.5], [0.6, -0.2, -0.5]]
        np.testing.assert_allclose(simulate_blur(lf, cp, n_times=5, infinity_disparity=0.5, device="cpu"),
                                   blur_reference(lf, cp, 5, 0.5), atol=1e-5)
    finally:
        _fused._loops.cache_clear()


def test_a_read_only_light_field_is_blurred_without_a_warning():
    import warnings

    lf = np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32)
    frozen = lf.copy()
    frozen.setflags(write=False)  # as np.load(..., mmap_mode='r') gives
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # torch warned that the array is not writable
        out = simulate_blur(frozen, [[-1.0, 0.0, 0.0], [1.0, 0.5, 0.0]], n_times=8)
    np.testing.assert_array_equal(out, simulate_blur(lf, [[-1.0, 0.0, 0.0], [1.0, 0.5, 0.0]], n_times=8))


def test_arrays_of_any_byte_order_or_float_width_and_tensors_with_grad_are_blurred_as_their_values():
    lf = np.random.default_rng(0).random((3, 3, 8, 8))
    cp = [[-1.0, 0.0, 0.2], [1.0, 0.5, 0.0]]
    want = simulate_blur(lf.astype(np.float32), cp, n_times=8)
    # big-endian data (FITS, MATLAB, HDF5 files), numpy's long double, a tensor that requires grad
    for other in (lf.astype(">f4"), lf.astype(">f8"), lf.astype(np.longdouble), torch.tensor(lf, requires_grad=True)):
        np.testing.assert_allclose(simulate_blur(other, cp, n_times=8), want, atol=1e-6)
    # control points in a tensor that requires grad, as an optimiser holds them
    np.testing.assert_array_equal(simulate_blur(lf, torch.tensor(cp, requires_grad=True), n_times=8),
                                  simulate_blur(lf, cp, n_times=8))


def test_the_first_fused_loop_leaves_torchs_thread_count_as_the_caller_set_it():
    """numba's OpenMP pool, started by the process's first loop, sets the thread's OpenMP count (torch's) to
    every core; the caller's torch.set_num_threads(1) stands (a fresh process: the first loop is the test)."""
    import os
    import subprocess
    import sys

    pytest.importorskip("numba")
    if (os.cpu_count() or 1) < 2:
        pytest.skip("one core: every count is 1")
    code = ("import numpy as np, torch\n"
            "torch.set_num_threads(1)\n"
            "from napari_lfdeblur import _fused, simulate_blur\n"
            "assert _fused.available('cpu'), 'the fused loops are off'\n"
            "simulate_blur(np.zeros((3, 3, 8, 8), np.float32), [[-1, 0, 0], [1, 0, 0]], n_times=4)\n"
            "print(torch.get_num_threads())\n")
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "NAPARI_LFDEBLUR_NUMBA")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    if "the fused loops are off" in out.stderr:
        pytest.skip("the fused loops are off")
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["1"]


def test_the_fused_loops_leave_numbas_thread_count_as_it_was():
    numba = pytest.importorskip("numba")
    from napari_lfdeblur import _fused

    if not _fused.available("cpu"):
        pytest.skip("the fused loops are off")
    before_numba, before_torch = numba.get_num_threads(), torch.get_num_threads()
    try:
        numba.set_num_threads(1)
        torch.set_num_threads(2)
        lf = np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32)
        simulate_blur(lf, [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], n_times=4)
        assert numba.get_num_threads() == 1  # put back after the loops
        seen = []  # and a loop runs with torch's 2 threads (where numba has them)
        _fused.call(lambda: seen.append(numba.get_num_threads()))
        assert seen == [min(2, numba.config.NUMBA_NUM_THREADS)] and numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(before_numba)
        torch.set_num_threads(before_torch)
