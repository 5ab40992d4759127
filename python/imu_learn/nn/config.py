"""The model's and the loss's settings as plain dataclasses (no torch), so that configs, checkpoint
cards and the fusion code can read and validate them without importing torch."""
from __future__ import annotations

from dataclasses import dataclass

REFINE_CHANNELS = {"imu": [1.0] * 6, "gyro": [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]}
# Where training starts (ModelConfig.start); "calibrate" (a run's default): the device profile that
# `imu-learn calibrate` fits on the run's own training split; "profile": a device profile's floor as the fixed
# calibration and FIR shift. A run config may also name the profile's file (PATH.json), which
# `imu-learn fit` reads and replaces by "profile".
MODEL_STARTS = ("calibrate", "raw", "timing", "traditional+timing", "profile")

# What a checkpoint written before these model args existed was trained with (its missing args).
ARGS_BEFORE = {"start": "raw", "fir_init_tau": 0.0, "calib": False}


@dataclass
class ModelConfig:
    hidden: int = 64  # LSTM hidden size per direction
    layers: int = 2  # stacked LSTM blocks, each followed by a fully connected layer
    fc: int = 64  # width of the fully connected layers between LSTM blocks
    causal: bool = False  # unidirectional (online) variant
    output_scale: float = 0.1  # correction = output_scale * input std * head output
    dropout: float = 0.0
    # Which channels the model corrects: "imu" (all six, the paper) or "gyro" (the accelerometer
    # passes through unchanged, as in denoise-imu-gyro). On data where the accelerometer's
    # corrections do not transfer, "gyro" still improves translation through better attitude.
    refine: str = "imu"
    # Taps of an optional learned linear FIR filter over the normalised raw input, added to the
    # LSTM's correction (0 = off; odd, centred, edges padded by repetition; bidirectional only;
    # one filter per channel on its own input, with zero DC gain).
    # It holds what a linear filter says best and an LSTM learns slowly: low-pass smoothing and
    # the half-sample shift between the integration's zero-order hold (sample k held over
    # [t_k, t_k+1]) and when a sample was taken, which taps of [0, -1/2, 1/2] undo exactly.
    fir_taps: int = 0
    # Where training starts (`imu-learn fit` fills the fields below from the train split):
    # "calibrate" (a run's default): calibrate's device profile of the training split (written to
    # RUN/profile/), then as "profile" below, so an untrained or unhelpful model is that profile;
    # "raw" (the identity map, the paper); "timing": the FIR starts as a time shift by
    # fir_init_tau samples (linear interpolation between the two nearest taps,
    # |tau| <= fir_taps // 2), so the untrained model is the `timing` floor; "traditional+timing": that
    # shift plus a fixed affine calibration (calib = true: scale, misalignment, bias and g-sensitivity as
    # `traditional+timing` fits them, without its low-pass filter), so the untrained model is that floor
    # and the network learns only what the floor leaves; "profile": the same with a device profile's floor
    # (`imu-learn fit --model.start PATH/profile.json`, `imu-learn calibrate --learned`) instead of a fit,
    # so the model holds that floor itself: the checkpoint carries the profile, and refine does not
    # apply it again before the model.
    start: str = "raw"  # a run's default is "calibrate" (train.config.RunConfig)
    fir_init_tau: float = 0.0
    calib: bool = False  # a fixed affine calibration (buffers calib_A (6, 6), calib_c (6,)) before the network
    # Learned uncertainty: a second head predicting each refined sample's noise variances (six
    # channels, discrete-time: the variance of one sample in (rad/s)^2 and (m/s^2)^2; a filter that
    # wants a noise density takes sigma * sqrt(dt), see imu_learn.nn.covariance). Bounded by
    # construction: log sigma^2 = log min^2 + (log max^2 - log min^2) * sigmoid(z).
    covariance: bool = False
    sigma_gyro_min: float = 1e-4  # [rad/s]
    sigma_gyro_max: float = 1.0
    sigma_acc_min: float = 1e-3  # [m/s^2]
    sigma_acc_max: float = 10.0



@dataclass(frozen=True)
class LossConfig:
    w_q: float = 1.0  # weight of the rotation term
    w_v: float = 1.0  # weight of the velocity (Δβ) term
    w_p: float = 1.0  # weight of the position (Δγ) term
    huber_q: float = 0.005  # Huber delta on |Log(Δq_s Δq̂⁻¹)| [rad]
    huber_v: float = 0.05  # Huber delta on |Δβ_s − Δβ̂| [m/s]
    huber_p: float = 0.01  # Huber delta on |Δγ_s − Δγ̂| [m]
    w_reg: float = 1.0  # weight of the regulariser
    reg_gyro: float = 0.05  # λ for the gyro channels [rad/s]
    reg_acc: float = 0.5  # λ for the accelerometer channels [m/s²]
    bias_aware: bool = True  # the paper's bias-augmented loss: integrate (û − b)
    # Residual scaling per horizon: "none" (the paper: every horizon's residual as it is, so the
    # longest horizons, whose residuals are largest, dominate) or "inverse" (each residual divided
    # by its horizon's fraction of the longest one, so a 10-sample horizon pulls as hard as the
    # full window: for models scored over short horizons, e.g. the paper's Table II, n = 10).
    horizon_scale: str = "none"
    # Gaussian negative log-likelihood of the 9-vector residual (δθ, δβ, δγ) under the covariance
    # propagated from the model's per-sample variances (imu_learn.nn.covariance), summed over the
    # label horizons like the other terms; needs a model with model.covariance = true. 0 = off.
    w_nll: float = 0.0
