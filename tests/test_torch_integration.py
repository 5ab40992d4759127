"""Differentiable torch integration against the Rust core on real EuRoC windows, gradients by
finite differences, and the parallel scan against a plain loop."""
import numpy as np
import pytest
import torch

import imu_learn as il
from imu_learn.nn.integration import integrate, prefix_quat_product
from imu_learn.nn.so3 import quat_conj, quat_mul, quat_rotate, so3_exp, so3_log

torch.set_num_threads(1)

STARTS = np.array([0, 777, 3001, 5555, 9000])


@pytest.fixture(scope="module")
def seq(shipped):
    return il.load_sequence(shipped / "euroc" / "V1_01_easy")[0]


def windows(seq, starts, W):
    g = np.stack([seq.gyro[k:k + W] for k in starts])
    a = np.stack([seq.acc[k:k + W] for k in starts])
    dt = np.stack([np.diff(seq.t_ns[k:k + W + 1]) * 1e-9 for k in starts])
    return g, a, dt


def max_diffs(inc, ref):
    dq = inc.dq_wxyz.double().numpy()
    sign = np.sign((dq * ref.dq_wxyz).sum(-1, keepdims=True))  # q and -q are the same rotation
    return (
        np.abs(dq * sign - ref.dq_wxyz).max(),
        np.abs(inc.dv.double().numpy() - ref.dv).max(),
        np.abs(inc.dp.double().numpy() - ref.dp).max(),
    )


@pytest.mark.parametrize("W", [200, 1000])
def test_matches_core_float64(seq, W):
    hs = np.array([W // 5 * k for k in range(1, 6)])
    ref = il.integrate_windows(seq, STARTS, hs)
    g, a, dt = windows(seq, STARTS, W)
    inc = integrate(torch.from_numpy(g), torch.from_numpy(a), torch.from_numpy(dt), hs)
    assert inc.dq_wxyz.dtype == torch.float64 and inc.dq_wxyz.shape == (len(STARTS), 5, 4)
    assert max(max_diffs(inc, ref)) < 1e-10


@pytest.mark.parametrize("W", [200, 1000])
def test_matches_core_float32_loosely(seq, W):
    hs = np.array([W // 5 * k for k in range(1, 6)])
    ref = il.integrate_windows(seq, STARTS, hs)
    g, a, dt = windows(seq, STARTS, W)
    f = lambda x: torch.from_numpy(x).float()  # noqa: E731
    inc = integrate(f(g), f(a), f(dt), hs)
    assert inc.dv.dtype == torch.float32
    e_q, e_v, e_p = max_diffs(inc, ref)
    # relative to |Δγ| ~ ½ g T² (≈ 120 m at 5 s), these are ~1e-6
    assert e_q < 1e-4 and e_v < 2e-3 and e_p < 2e-3


def test_arbitrary_horizons_index_the_same_scan(seq):
    W = 64
    g, a, dt = (torch.from_numpy(x) for x in windows(seq, STARTS[:3], W))
    full = integrate(g, a, dt, range(1, W + 1))
    hs = [1, 7, 64, 33, 7]
    part = integrate(g, a, dt, np.array(hs))
    idx = [h - 1 for h in hs]
    torch.testing.assert_close(part.dq_wxyz, full.dq_wxyz[:, idx], rtol=0, atol=0)
    torch.testing.assert_close(part.dv, full.dv[:, idx], rtol=0, atol=0)
    torch.testing.assert_close(part.dp, full.dp[:, idx], rtol=0, atol=0)
    # one sample: Exp(w0 dt0), a0 dt0, ½ a0 dt0²
    d0 = dt[:, :1]
    torch.testing.assert_close(full.dq_wxyz[:, 0], so3_exp(g[:, 0] * d0))
    torch.testing.assert_close(full.dv[:, 0], a[:, 0] * d0)
    torch.testing.assert_close(full.dp[:, 0], 0.5 * a[:, 0] * d0 ** 2)
    with pytest.raises(ValueError):
        integrate(g, a, dt, [0])
    with pytest.raises(ValueError):
        integrate(g, a, dt, [W + 1])
    # torch tensor horizons work too
    t = integrate(g, a, dt, torch.tensor([1, 7, 64, 33, 7]))
    torch.testing.assert_close(t.dp, part.dp, rtol=0, atol=0)


def sequential(gyro, acc, dt):
    """Plain loop over samples, the equations as written."""
    B, W, _ = gyro.shape
    R = torch.zeros(B, 4, dtype=gyro.dtype)
    R[:, 0] = 1
    v = torch.zeros(B, 3, dtype=gyro.dtype)
    p = torch.zeros(B, 3, dtype=gyro.dtype)
    Rs, vs, ps = [], [], []
    for i in range(W):
        d = dt[:, i:i + 1]
        ra = quat_rotate(R, acc[:, i])
        p = p + v * d + 0.5 * ra * d * d
        v = v + ra * d
        R = quat_mul(R, so3_exp(gyro[:, i] * d))
        Rs.append(R), vs.append(v), ps.append(p)
    return torch.stack(Rs, 1), torch.stack(vs, 1), torch.stack(ps, 1)


@pytest.mark.parametrize("W", [1, 2, 5, 37, 64])
def test_scan_equals_sequential_loop(W):
    gen = torch.Generator().manual_seed(W)
    gyro = torch.randn(3, W, 3, generator=gen, dtype=torch.float64) * 2
    acc = torch.randn(3, W, 3, generator=gen, dtype=torch.float64) * 5
    dt = 0.005 + 0.01 * torch.rand(3, W, generator=gen, dtype=torch.float64)
    R, v, p = sequential(gyro, acc, dt)
    inc = integrate(gyro, acc, dt, range(1, W + 1))
    torch.testing.assert_close(inc.dq_wxyz, R, rtol=0, atol=1e-13)
    torch.testing.assert_close(inc.dv, v, rtol=0, atol=1e-13)
    torch.testing.assert_close(inc.dp, p, rtol=0, atol=1e-13)
    torch.testing.assert_close(prefix_quat_product(so3_exp(gyro * dt[..., None])), R, rtol=0, atol=1e-13)


def test_gradcheck_integrate():
    gen = torch.Generator().manual_seed(0)
    B, W = 2, 16
    gyro = (torch.randn(B, W, 3, generator=gen, dtype=torch.float64) * 3).requires_grad_()
    acc = (torch.randn(B, W, 3, generator=gen, dtype=torch.float64) * 5).requires_grad_()
    dt = (0.02 + 0.03 * torch.rand(B, W, generator=gen, dtype=torch.float64)).requires_grad_()

    def f(g, a, d):
        inc = integrate(g, a, d, [3, 8, 16])
        return inc.dq_wxyz, inc.dv, inc.dp

    assert torch.autograd.gradcheck(f, (gyro, acc, dt))
    # a window that does not rotate at all: gradients at the identity
    assert torch.autograd.gradcheck(f, (torch.zeros_like(gyro).requires_grad_(), acc, dt))


def test_gradcheck_so3_exp_log_at_and_near_zero():
    gen = torch.Generator().manual_seed(1)
    cases = [
        torch.zeros(1, 3, dtype=torch.float64),
        torch.randn(4, 3, generator=gen, dtype=torch.float64) * 1e-9,
        torch.randn(4, 3, generator=gen, dtype=torch.float64) * 1e-4,  # at the Taylor switch
        torch.randn(4, 3, generator=gen, dtype=torch.float64),
        torch.randn(4, 3, generator=gen, dtype=torch.float64) * 0.9,
    ]
    for phi in cases:
        phi = phi.requires_grad_()
        assert torch.autograd.gradcheck(so3_exp, (phi,))
        q = so3_exp(phi.detach()).requires_grad_()
        assert torch.autograd.gradcheck(so3_log, (q,))
        assert torch.autograd.gradcheck(lambda x: so3_log(so3_exp(x)), (phi,))
        torch.testing.assert_close(so3_log(so3_exp(phi)), phi, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_gradients_finite_at_zero_rotation(dtype):
    phi = torch.zeros(2, 3, dtype=dtype, requires_grad=True)
    q = so3_exp(phi)
    r = so3_log(quat_mul(q, quat_conj(q)))
    (so3_exp(phi).sum() + r.sum() + so3_log(q).pow(2).sum()).backward()
    assert torch.isfinite(phi.grad).all()
    torch.testing.assert_close(so3_exp(phi), torch.tensor([[1.0, 0, 0, 0]] * 2, dtype=dtype))
    # and through the integrator, in both precisions
    g = torch.zeros(1, 8, 3, dtype=dtype, requires_grad=True)
    a = torch.ones(1, 8, 3, dtype=dtype, requires_grad=True)
    inc = integrate(g, a, torch.full((1, 8), 0.01, dtype=dtype), [4, 8])
    (so3_log(inc.dq_wxyz).sum() + inc.dp.sum()).backward()
    assert torch.isfinite(g.grad).all() and torch.isfinite(a.grad).all()


def test_so3_log_takes_the_short_way_and_ignores_sign():
    phi = torch.tensor([[0.3, -1.2, 2.0]], dtype=torch.float64)
    q = so3_exp(phi)
    torch.testing.assert_close(so3_log(-q), phi)
    big = torch.tensor([[0.0, 0.0, 3.5]], dtype=torch.float64)  # > pi wraps to the other side
    torch.testing.assert_close(so3_log(so3_exp(big)), torch.tensor([[0.0, 0.0, 3.5 - 2 * np.pi]], dtype=torch.float64))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_runs_on_cuda(seq):
    g, a, dt = windows(seq, STARTS, 200)
    cpu = integrate(*(torch.from_numpy(x) for x in (g, a, dt)), [40, 200])
    gpu = integrate(*(torch.from_numpy(x).cuda() for x in (g, a, dt)), [40, 200])
    torch.testing.assert_close(gpu.dp.cpu(), cpu.dp, rtol=0, atol=1e-10)
