"""ImuRefiner: identity at start, dtype follows the input, causal streaming equals the full window,
state only for the causal variant, normalisation saved with the weights."""
import pytest
import torch

from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

SMALL = dict(hidden=8, layers=2, fc=8)


def imu_batch(B=2, W=30, dtype=torch.float32, seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(B, W, 6, generator=g, dtype=dtype)
    x[..., :3] *= 0.5
    x[..., 3:] = x[..., 3:] * 2 + torch.tensor([9.0, 0.2, -3.7], dtype=dtype)
    return x


def randomise_head(model, seed=1):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        model.head.weight.copy_(torch.randn(model.head.weight.shape, generator=g))
        model.head.bias.copy_(torch.randn(model.head.bias.shape, generator=g))


@pytest.mark.parametrize("causal", [False, True])
def test_starts_as_identity(causal):
    torch.manual_seed(0)
    x = imu_batch()
    model = ImuRefiner(ModelConfig(causal=causal, **SMALL), mean=x.mean((0, 1)), std=x.std((0, 1)))
    assert torch.count_nonzero(model.head.weight) == 0 and torch.count_nonzero(model.head.bias) == 0
    assert torch.equal(model(x), x)


@pytest.mark.parametrize("causal", [False, True])
def test_output_dtype_follows_input(causal):
    torch.manual_seed(0)
    model = ImuRefiner(ModelConfig(causal=causal, **SMALL))
    randomise_head(model)
    x32 = imu_batch()
    out32 = model(x32)
    assert out32.dtype == torch.float32 and out32.shape == x32.shape
    model64 = model.double()
    x64 = x32.double()
    out64 = model64(x64)
    assert out64.dtype == torch.float64
    assert model64.mean.dtype == torch.float64 and model64.std.dtype == torch.float64
    torch.testing.assert_close(out64.float(), out32, rtol=1e-4, atol=1e-4)
    assert not torch.equal(out64, x64)  # the randomised head does change the signal


def test_causal_step_by_step_equals_full_window():
    torch.manual_seed(0)
    x = imu_batch(B=3, W=25, dtype=torch.float64)
    model = ImuRefiner(ModelConfig(causal=True, **SMALL), mean=x.mean((0, 1)), std=x.std((0, 1))).double()
    randomise_head(model)
    model.eval()
    with torch.no_grad():
        full = model(x)
        state = None
        steps = []
        for i in range(x.shape[1]):
            y, state = model.step(x[:, i], state)
            steps.append(y)
        torch.testing.assert_close(torch.stack(steps, 1), full, rtol=0, atol=1e-12)
        # and in chunks with carried state
        a, s = model.forward_with_state(x[:, :11])
        b, _ = model.forward_with_state(x[:, 11:], s)
        torch.testing.assert_close(torch.cat((a, b), 1), full, rtol=0, atol=1e-12)
    # causal: the output at t does not depend on inputs after t
    y = x.clone()
    y[:, 15:] += 1.0
    with torch.no_grad():
        torch.testing.assert_close(model(y)[:, :15], full[:, :15], rtol=0, atol=0)


def test_bidirectional_refuses_state():
    model = ImuRefiner(ModelConfig(causal=False, **SMALL))
    x = imu_batch()
    _, state = model.forward_with_state(x)
    with pytest.raises(ValueError):
        model(x, state)
    with pytest.raises(ValueError):
        model.forward_with_state(x, state)
    with pytest.raises(ValueError):
        model.step(x[:, 0])


def test_normalisation_buffers_in_state_dict():
    mean = torch.tensor([0.01, -0.02, 0.03, 9.0, 0.2, -3.7])
    std = torch.tensor([0.3, 0.2, 0.1, 1.0, 0.5, 0.7])
    model = ImuRefiner(ModelConfig(**SMALL), mean=mean, std=std)
    sd = model.state_dict()
    assert torch.equal(sd["mean"], mean) and torch.equal(sd["std"], std)
    # a fresh model picks them up from the state dict alone
    fresh = ImuRefiner(ModelConfig(**SMALL))
    fresh.load_state_dict(sd)
    assert torch.equal(fresh.mean, mean) and torch.equal(fresh.std, std)
    randomise_head(model)
    fresh.load_state_dict(model.state_dict())
    x = imu_batch()
    torch.testing.assert_close(fresh(x), model(x), rtol=0, atol=0)


def test_gyro_only_refines_gyro_and_passes_acc_bit_for_bit():
    """model.refine = "gyro": the accelerometer channels leave the model exactly as they came in,
    the gyro channels are corrected; the choice is not saved as weights (older checkpoints load)."""
    torch.manual_seed(0)
    m = ImuRefiner(ModelConfig(refine="gyro", **SMALL))
    randomise_head(m)
    x = imu_batch()
    y = m(x)
    assert torch.equal(y[..., 3:], x[..., 3:])
    assert (y[..., :3] - x[..., :3]).abs().max() > 1e-3
    assert "channels" not in m.state_dict()
    full = ImuRefiner(ModelConfig(**SMALL))
    full.load_state_dict(m.state_dict())
    assert not torch.equal(full(x)[..., 3:], x[..., 3:])
    with pytest.raises(ValueError, match="model.refine"):
        ImuRefiner(ModelConfig(refine="acc", **SMALL))


def test_fir_branch_starts_at_zero_and_can_hold_the_half_sample_shift():
    """model.fir_taps: a linear filter on the normalised input, zero at start (identity model);
    taps [0, -1/2, 1/2] on each channel's own input make every sample the mean of it and the next
    (the zero-order hold's half-sample shift), with the last sample unchanged (edge repeated)."""
    torch.manual_seed(0)
    x = imu_batch(dtype=torch.float64)
    mean, std = x.mean((0, 1)), x.std((0, 1))
    model = ImuRefiner(ModelConfig(fir_taps=3, **SMALL), mean=mean, std=std).double()
    assert torch.equal(model(x), x)
    from imu_learn.nn.model import FIR_GAIN

    with torch.no_grad():
        # one filter per channel (depthwise); a constant added to the taps is ignored (zero DC gain)
        w = torch.zeros(6, 1, 3, dtype=torch.float64)
        w[:, 0, 1], w[:, 0, 2] = -0.5 / FIR_GAIN, 0.5 / FIR_GAIN
        model.fir.weight.copy_(w + 0.3)
    out = model(x)
    want = x.clone()
    want[:, :-1] = 0.5 * (x[:, :-1] + x[:, 1:])
    assert torch.allclose(out, want, atol=1e-12)
    # gyro only: the accelerometer passes through even with the FIR on
    g = ImuRefiner(ModelConfig(fir_taps=3, refine="gyro", **SMALL), mean=mean, std=std).double()
    g.fir.weight.data.copy_(w)
    out_g = g(x)
    assert torch.equal(out_g[..., 3:], x[..., 3:])
    assert torch.allclose(out_g[..., :3], want[..., :3], atol=1e-12)


@pytest.mark.parametrize("kw", [dict(fir_taps=4), dict(fir_taps=-3), dict(fir_taps=3, causal=True)])
def test_fir_taps_must_be_odd_and_bidirectional(kw):
    with pytest.raises(ValueError, match="model.fir_taps"):
        ImuRefiner(ModelConfig(**{**SMALL, **kw}))


@pytest.mark.parametrize("causal", [False, True])
def test_covariance_head_is_bounded_positive_and_leaves_the_refined_samples_alone(causal):
    torch.manual_seed(0)
    cfg = ModelConfig(**SMALL, causal=causal, covariance=True)
    m = ImuRefiner(cfg).eval()
    x = imu_batch()
    with torch.no_grad():
        for p in m.cov_head.parameters():
            p.mul_(1000.0)  # drive the sigmoid into both saturations
        refined, var = m.forward_with_variance(x)
        plain = ImuRefiner(ModelConfig(**SMALL, causal=causal))
        plain.load_refiner({k: v for k, v in m.state_dict().items() if not k.startswith("cov_head.")})
        assert torch.equal(plain.eval()(x), refined)
    assert var.shape == x.shape and bool((var > 0).all())
    sd = var.sqrt()
    assert bool((sd[..., :3] >= cfg.sigma_gyro_min * (1 - 1e-5)).all() and (sd[..., :3] <= cfg.sigma_gyro_max * (1 + 1e-5)).all())
    assert bool((sd[..., 3:] >= cfg.sigma_acc_min * (1 - 1e-5)).all() and (sd[..., 3:] <= cfg.sigma_acc_max * (1 + 1e-5)).all())


def test_a_model_without_the_head_says_so():
    with pytest.raises(ValueError, match="no covariance head"):
        ImuRefiner(ModelConfig(**SMALL)).forward_with_variance(imu_batch())


def test_freeze_refiner_leaves_only_the_head_trainable():
    m = ImuRefiner(ModelConfig(**SMALL, covariance=True))
    m.freeze_refiner()
    trainable = {n for n, p in m.named_parameters() if p.requires_grad}
    assert trainable and all(n.startswith("cov_head.") for n in trainable)


def test_load_refiner_refuses_weights_of_another_shape():
    big = ImuRefiner(ModelConfig(hidden=16, layers=2, fc=8))
    with pytest.raises((ValueError, RuntimeError)):
        ImuRefiner(ModelConfig(**SMALL, covariance=True)).load_refiner(big.state_dict())


@pytest.mark.parametrize("tau,taps", [(0.54, 3), (-0.3, 3), (1.68, 5), (-2.0, 5)])
def test_fir_init_timing_equals_the_timing_floor(tau, taps):
    """An untrained model with model.fir_init_tau = tau is the `timing` floor: raw IMU resampled at
    t + tau samples (baselines.timing.resample, an independent numpy interpolation), away from the
    window's ends (padded by repetition there, held ends in resample)."""
    import numpy as np

    from imu_learn.baselines.timing import resample

    model = ImuRefiner(ModelConfig(fir_taps=taps, fir_init_tau=tau, **SMALL),
                       mean=torch.tensor([0.1, -0.2, 0.3, 9.0, 0.1, -3.0]), std=torch.tensor([0.5, 0.4, 0.3, 2.0, 1.5, 1.0]))
    x = imu_batch(B=1, W=60, dtype=torch.float64)
    with torch.no_grad():
        out = model.double()(x)[0].numpy()
    period = 5_000_000
    t = np.arange(60, dtype=np.int64) * period
    ref = resample(t, x[0].numpy(), tau, period)
    k = taps // 2
    np.testing.assert_allclose(out[k:-k], ref[k:-k], rtol=0, atol=1e-6)  # float32 taps
    assert np.abs(out[k:-k] - x[0].numpy()[k:-k]).max() > 1e-3  # it does shift


def test_fir_init_tau_out_of_reach():
    with pytest.raises(ValueError, match="fir_taps >= 5"):
        ImuRefiner(ModelConfig(fir_taps=3, fir_init_tau=1.7, **SMALL))
    with pytest.raises(ValueError, match="needs the FIR branch"):
        ImuRefiner(ModelConfig(fir_init_tau=0.5, **SMALL))


def test_start_traditional_timing_equals_the_calibration_floor():
    """model.calib with the fixed affine calibration and the FIR shift of a TraditionalParams is, untrained,
    exactly baselines.traditional's numpy refine with those parameters (no low-pass filter)."""
    import numpy as np

    from imu_learn.baselines.traditional import Traditional, TraditionalParams
    from imu_learn.data.types import Segment

    rng = np.random.default_rng(3)
    p = TraditionalParams(M_g=np.eye(3) + 0.02 * rng.standard_normal((3, 3)), b_g=0.01 * rng.standard_normal(3),
                          G=0.001 * rng.standard_normal((3, 3)), M_a=np.eye(3) + 0.01 * rng.standard_normal((3, 3)),
                          b_a=0.1 * rng.standard_normal(3), time_offset=0.6)
    A = np.zeros((6, 6))
    A[:3, :3], A[:3, 3:], A[3:, 3:] = p.M_g, -p.G, p.M_a
    c = np.concatenate([-p.M_g @ p.b_g, -p.M_a @ p.b_a])
    model = ImuRefiner(ModelConfig(fir_taps=3, fir_init_tau=p.time_offset, calib=True, start="traditional+timing", **SMALL))
    model.set_calibration(torch.as_tensor(A), torch.as_tensor(c))
    x = imu_batch(B=1, W=80, dtype=torch.float64)
    with torch.no_grad():
        out = model.double()(x)[0].numpy()
    n = 80
    t = np.arange(n, dtype=np.int64) * 5_000_000 + 10**12
    z = np.zeros((n, 3))
    seq = Segment("s", t, x[0, :, :3].numpy(), x[0, :, 3:].numpy(), z, z, np.tile([1.0, 0, 0, 0], (n, 1)))
    trad = Traditional(cutoffs_hz=(None,))
    trad.params = p
    g, a = trad.refine(seq)
    np.testing.assert_allclose(out[1:-1], np.concatenate([g, a], 1)[1:-1], rtol=0, atol=2e-5)  # float32 buffers
    gyro_only = ImuRefiner(ModelConfig(calib=True, refine="gyro", **SMALL))
    gyro_only.set_calibration(torch.as_tensor(A), torch.as_tensor(c))
    with torch.no_grad():
        o2 = gyro_only.double()(x)[0].numpy()
    # a gyro-only model on a floor passes the accelerometer through that floor (it passed it raw, dropping a
    # profile's accelerometer calibration under "on top of the floor of its profile")
    np.testing.assert_allclose(o2[:, 3:], x[0, :, 3:].numpy() @ p.M_a.T - p.M_a @ p.b_a, rtol=0, atol=1e-5)
