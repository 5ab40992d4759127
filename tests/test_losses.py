"""The paper's losses: zero at the truth, Huber and dead-zone shapes, and the bias-augmented form
rewarding a network that passes an added bias through (and the plain form the opposite)."""
import numpy as np
import pytest
import torch

import imu_learn as il
from imu_learn.nn.losses import LossConfig, dead_zone, huber_norm, imu_loss
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)


def closed_form_window(W=200, rate=200.0):
    """A smooth motion: gyro and specific force as closed-form functions of time."""
    t = np.arange(W + 1) / rate
    t_ns = np.round(t * 1e9).astype(np.int64)
    gyro = np.stack([0.4 * np.sin(2 * t), 0.3 * np.cos(t), -0.2 + 0.1 * t], -1)
    acc = np.stack([np.cos(3 * t), 0.5 * np.sin(t), 9.81 + 0.2 * t], -1)
    return t_ns, gyro, acc


def test_zero_loss_at_the_true_signal_with_core_labels():
    W = 200
    hs = np.array([40, 80, 120, 160, 200])
    t_ns, gyro, acc = closed_form_window(W)
    inc = il.preintegrate(t_ns, gyro, acc)  # labels from the Rust core, row h = after h samples
    dq, dv, dp = (x[hs][None] for x in (inc.dq_wxyz, inc.dv, inc.dp))
    true = torch.from_numpy(np.concatenate([gyro[:W], acc[:W]], -1))[None]
    dt = torch.from_numpy(np.diff(t_ns) * 1e-9)[None]
    rng = np.random.default_rng(0)
    raw = true + torch.from_numpy(rng.uniform(-0.01, 0.01, (1, W, 6)))  # noise inside λ
    total, terms = imu_loss(true, raw, dt, dq, dv, dp, hs, None, LossConfig(bias_aware=False))
    assert float(total) < 1e-20
    assert set(terms) == {"q", "v", "p", "reg", "total"} and all(not v.requires_grad for v in terms.values())
    # with a known added bias, the bias-aware loss is zero for the pass-through output
    b = torch.tensor([0.02, -0.03, 0.01, 0.3, -0.2, 0.1], dtype=torch.float64).expand(1, W, 6)
    total_b, _ = imu_loss(true + b, raw + b, dt, dq, dv, dp, hs, b, LossConfig())
    assert float(total_b) < 1e-20
    # float32 works and is near zero
    total32, _ = imu_loss(true.float(), raw.float(), dt, dq, dv, dp, hs, None, LossConfig(bias_aware=False))
    assert total32.dtype == torch.float32 and float(total32) < 1e-9


def test_huber_quadratic_small_linear_large():
    d = 0.1
    r = torch.tensor([[0.0, 0.0, 0.0], [0.03, 0.04, 0.0], [3.0, 4.0, 0.0], [0.0, 0.0, -10.0]], dtype=torch.float64)
    h = huber_norm(r, d)
    torch.testing.assert_close(h, torch.tensor([0.0, 0.5 * 0.05 ** 2, d * (5.0 - d / 2), d * (10.0 - d / 2)], dtype=torch.float64))
    # matches torch's HuberLoss applied to the norm, and is continuous with slope δ beyond δ
    n = r.norm(dim=-1)
    torch.testing.assert_close(h, torch.nn.functional.huber_loss(n, torch.zeros_like(n), reduction="none", delta=d))
    x = torch.tensor([[2.0, 0.0, 0.0]], dtype=torch.float64, requires_grad=True)
    huber_norm(x, d).sum().backward()
    torch.testing.assert_close(x.grad, torch.tensor([[d, 0.0, 0.0]], dtype=torch.float64))
    z = torch.zeros(1, 3, requires_grad=True)
    huber_norm(z, d).sum().backward()
    assert torch.equal(z.grad, torch.zeros(1, 3))


def test_regulariser_zero_inside_lambda_linear_outside():
    W = 10
    t_ns, gyro, acc = closed_form_window(W)
    inc = il.preintegrate(t_ns, gyro, acc)
    hs = [W]
    labels = [x[hs][None] for x in (inc.dq_wxyz, inc.dv, inc.dp)]
    dt = np.diff(t_ns)[None] * 1e-9
    refined = torch.from_numpy(np.concatenate([gyro[:W], acc[:W]], -1))[None]
    cfg = LossConfig(bias_aware=False, reg_gyro=0.05, reg_acc=0.5)
    lam = torch.tensor([0.05] * 3 + [0.5] * 3, dtype=torch.float64)
    for scale, expect in [(0.0, 0.0), (0.99, 0.0), (1.5, 0.5), (3.0, 2.0)]:
        raw = refined + scale * lam  # every channel off by scale·λ
        _, terms = imu_loss(refined, raw, dt, *labels, hs, None, cfg)
        torch.testing.assert_close(terms["reg"], torch.tensor(expect * float(lam.sum()), dtype=torch.float64))
    torch.testing.assert_close(dead_zone(torch.tensor([-2.0, -0.5, 0.5, 2.0]), torch.tensor(1.0)), torch.tensor([1.0, 0, 0, 1.0]))


@pytest.fixture(scope="module")
def real_windows(shipped):
    """Eight 1 s windows of V1_01 with GT labels and no augmentation."""
    seqs = il.load_sequence(shipped / "euroc" / "V1_01_easy")
    b = il.BatchSampler(seqs, il.BatchConfig(window=200, batch_size=8)).eval_windows(stride=1400)
    return b


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_bias_aware_rewards_passing_the_bias_through(real_windows, dtype, sign):
    """THE key property. The recorded IMU has its own bias (V1_01's gyro z is off by ~0.08 rad/s), so
    the added b is chosen well above twice that on every axis, and tried with both signs: then the
    comparison does not depend on how b happens to line up with the device's bias. λ is set above |b|
    so that the regulariser is neutral and the integrated terms alone decide."""
    b = real_windows
    clean = torch.from_numpy(b.imu).to(dtype)
    bias = sign * torch.tensor([0.25, -0.25, 0.25, 2.0, -2.0, 2.0], dtype=dtype).expand_as(clean)
    net_in = clean + bias  # what the network sees
    labels = (b.dt, b.dq_wxyz, b.dv, b.dp, b.horizons)  # ground truth, from the poses
    passthrough, removing = net_in, clean
    neutral = dict(reg_gyro=0.3, reg_acc=3.0)

    aware = LossConfig(bias_aware=True, **neutral)
    l_pass, t_pass = imu_loss(passthrough, net_in, *labels, bias, aware)
    l_rem, t_rem = imu_loss(removing, net_in, *labels, bias, aware)
    assert float(l_pass) < float(l_rem)
    for k in ("q", "v", "p"):
        assert float(t_pass[k]) < float(t_rem[k])

    plain = LossConfig(bias_aware=False, **neutral)
    l_pass, t_pass = imu_loss(passthrough, net_in, *labels, bias, plain)
    l_rem, t_rem = imu_loss(removing, net_in, *labels, bias, plain)
    assert float(l_rem) < float(l_pass)
    for k in ("q", "v", "p"):
        assert float(t_rem[k]) < float(t_pass[k])
    assert t_pass["reg"] == 0 and t_rem["reg"] == 0

    # with the default λ the regulariser agrees with the bias-aware form: passing through is free
    _, t_pass = imu_loss(passthrough, net_in, *labels, bias, LossConfig())
    _, t_rem = imu_loss(removing, net_in, *labels, bias, LossConfig())
    assert t_pass["reg"] == 0 and t_rem["reg"] > 0


def test_loss_gradient_wrt_model_params_is_finite(real_windows, shipped):
    torch.manual_seed(0)
    seqs = il.load_sequence(shipped / "euroc" / "V1_01_easy")
    aug = il.AugmentConfig(gyro_noise_density=1.7e-4, acc_noise_density=2e-3, gyro_bias_max=0.02, acc_bias_max=0.1)
    b = il.BatchSampler(seqs, il.BatchConfig(window=100, batch_size=4, augment=aug)).sample(5)
    imu = torch.from_numpy(b.imu).float()
    model = ImuRefiner(ModelConfig(hidden=8, layers=1, fc=8), mean=imu.mean((0, 1)), std=imu.std((0, 1)))
    torch.nn.init.normal_(model.head.weight, std=0.1)  # away from the identity start
    refined = model(imu)
    total, terms = imu_loss(refined, imu, b.dt, b.dq_wxyz, b.dv, b.dp, b.horizons, b.bias, LossConfig())
    total.backward()
    assert torch.isfinite(total)
    grads = [p.grad for p in model.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert model.head.weight.grad.abs().sum() > 0
    # also at the identity start (zero head), where the refined output equals the raw input
    model.zero_grad()
    torch.nn.init.zeros_(model.head.weight)
    total, _ = imu_loss(model(imu), imu, b.dt, b.dq_wxyz, b.dv, b.dp, b.horizons, b.bias, LossConfig())
    total.backward()
    assert all(torch.isfinite(p.grad).all() for p in model.parameters())
    assert model.head.weight.grad.abs().sum() > 0


def test_inverse_horizon_scale_weighs_a_short_horizon_like_the_full_window():
    """With horizon_scale = "inverse" a residual at a fifth of the window costs what a five times
    larger residual at the full window does (quadratic branch); with "none" it costs 25x less."""
    W = 200
    t_ns, gyro, acc = closed_form_window(W)
    inc = il.preintegrate(t_ns, gyro, acc)
    dt = torch.from_numpy(np.diff(t_ns) * 1e-9)[None]
    true = torch.from_numpy(np.concatenate([gyro[:W], acc[:W]], -1))[None]
    off = {"w_q": 0.0, "w_v": 0.0, "w_reg": 0.0, "huber_p": 1e3}  # position term only, quadratic branch

    def p_loss(h, scale, dp_err):
        hs = np.array([h])
        dp = inc.dp[hs][None] + dp_err
        total, _ = imu_loss(true, true, dt, inc.dq_wxyz[hs][None], inc.dv[hs][None], dp, hs, None,
                            LossConfig(bias_aware=False, horizon_scale=scale, **off))
        return float(total)

    e = np.array([[[1e-3, 0.0, 0.0]]])
    # a single horizon is its own longest: scale 1
    assert p_loss(40, "inverse", e) == pytest.approx(p_loss(40, "none", e), rel=1e-9)

    def two(scale):
        hs = np.array([40, 200])
        dp = inc.dp[hs][None] + np.array([[[1e-3, 0, 0], [0, 0, 0]]])
        total, _ = imu_loss(true, true, dt, inc.dq_wxyz[hs][None], inc.dv[hs][None], dp, hs, None,
                            LossConfig(bias_aware=False, horizon_scale=scale, **off))
        return float(total)

    assert two("inverse") == pytest.approx(25.0 * two("none"), rel=1e-9)
    with pytest.raises(ValueError, match="horizon_scale"):
        two("sqrt")


def test_gaussian_nll_is_the_closed_form_density():
    from scipy.stats import multivariate_normal

    from imu_learn.nn.losses import gaussian_nll
    rng = np.random.default_rng(3)
    A = rng.normal(size=(9, 9))
    cov = A @ A.T + np.diag(np.logspace(-8, 0, 9))  # blocks on very different scales, like rad² against m²
    r = rng.multivariate_normal(np.zeros(9), cov)
    got = float(gaussian_nll(torch.tensor(r), torch.tensor(cov)))
    want = -multivariate_normal(np.zeros(9), cov).logpdf(r) - 4.5 * np.log(2 * np.pi)
    assert got == pytest.approx(want, rel=1e-6, abs=1e-6)


def test_nll_term_trains_the_variances_toward_the_residuals():
    """On a window whose refined samples are off by a fixed error, the NLL's gradient on the
    per-sample variances points up when they are far too small and down when far too large."""
    W = 200
    hs = [40, 200]
    t_ns, gyro, acc = closed_form_window(W)
    labels = il.integrate_windows(il.Segment("w", t_ns, gyro, acc, np.zeros((W + 1, 3)), np.zeros((W + 1, 3)),
                                              np.tile([1.0, 0, 0, 0], (W + 1, 1))),
                                  np.array([0], dtype=np.uint64), np.array(hs, dtype=np.uint64))
    u = torch.tensor(np.concatenate([gyro, acc], 1)[None, :W], dtype=torch.float64)
    u_off = u + torch.tensor([1e-3] * 3 + [1e-2] * 3, dtype=torch.float64)
    dt = torch.tensor(np.diff(t_ns)[None] * 1e-9)
    cfg = LossConfig(w_q=0, w_v=0, w_p=0, w_reg=0, w_nll=1.0, bias_aware=False)
    grads = []
    for scale in (1e-12, 1e2):
        var = torch.full((1, W, 6), scale, dtype=torch.float64, requires_grad=True)
        loss, terms = imu_loss(u_off, u_off, dt, labels.dq_wxyz, labels.dv, labels.dp, hs, None, cfg, var)
        assert "nll" in terms and torch.isfinite(loss)
        loss.backward()
        grads.append(float(var.grad.sum()))
    assert grads[0] < 0 < grads[1]


def test_nll_without_variances_is_an_error():
    cfg = LossConfig(w_nll=1.0)
    x = torch.zeros(1, 10, 6)
    with pytest.raises(ValueError, match="w_nll"):
        imu_loss(x, x, np.full((1, 10), 0.005), np.tile([1.0, 0, 0, 0], (1, 1, 1)), np.zeros((1, 1, 3)),
                 np.zeros((1, 1, 3)), [10], None, cfg)
