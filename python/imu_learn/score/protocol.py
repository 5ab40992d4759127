"""The evaluation protocol, as every report states it (``imu_learn.eval.run`` follows it)."""

PROTOCOL = """\
* Data and split: the eval config names a fit config (``base``: data roots, by-sequence
  train / val / test split, window, gravity); its ``[data]`` table may override any of it. Test
  sequences are never seen in training or in model selection: every method is fitted on the
  train split only, and uses the val split only for its own model selection. A ``--checkpoint``
  whose training or validation split names a test recording is refused.
  Relative data paths are taken from the data root (``--data-root DIR``, else the environment
  variable ``IMU_LEARN_DATA``, else the configs' ``data.data_root``; see :mod:`imu_learn.data.splits`).
* Fitting: each method gets the same budget (``[fit]``: a ``FitSettings`` with window, batch size,
  steps, learning rate, device, threads; seed = the config's ``seed``, gravity = ``data.gravity``;
  horizons = ``eval.horizons``, for which the end-to-end regressor trains one net each, so its row
  at n comes from a net trained on n-sample windows).
  Fitted methods are saved in ``<report>/methods/<name>.*`` with a record of the settings and the
  split (``<name>.record.json``); ``--reuse`` loads them instead of refitting when both match.
* Prediction: every window starts from the ground-truth state (p, v, R) at its first sample k and
  the method sees only the IMU samples k, k+1, ... from then on, never ground-truth biases or
  later ground truth. Refiners (methods that correct IMU samples) have their corrected samples
  integrated by the core's zero-order-hold integration (``integrate_windows``) to the state at
  k + n; regressors (methods that predict poses directly) return the end pose themselves.
* Two variants, side by side:
  - open loop: the method's output as it is;
  - start-up bias removed: a constant per-sequence gyro and accelerometer bias, fitted against
    ground truth on the first ``startup_bias_s`` (10) seconds of that sequence
    (``metrics.fit_startup_bias``), is subtracted — fitted on the method's own refined output for
    refiners, on the raw input (which the regressor then sees) for regressors. This is the
    initialisation an estimator would give; no ground truth after those seconds is used.
  In both variants windows start from ``startup_bias_s`` seconds on (every ``stride`` samples, the
  window's end inside the sequence), so no window is scored on data a bias was fitted on.
* Errors, per window, at the end sample j = k + n: rotation = angle of R_jᵀ R̂ [rad, deg];
  translation = |p̂ − p_j| [m]; velocity = |v̂ − v_j| [m/s] (only where the method predicts a
  velocity; refiners always do). Each metric is the RMSE over the windows of a test recording
  (the windows of all its gap-free segments pooled); "average" is the mean of the per-recording
  RMSEs (as the paper's "Average" row).
* Metrics: relative pose RMSE over n IMU samples for each n in ``eval.horizons`` (default 10, 50,
  200; the paper's Table II uses n = 10); AirIMU's figures: rotation and position RMSE over 1 s,
  position RMSE over 0.5, 1, 2, 3 s; integration error against horizon (``eval.curve_count``
  log-spaced horizons from ``curve_min_s`` to ``curve_max_s``, default 12 from 0.05 s to 5 s):
  RMSE of position, rotation and velocity (the paper's integration-error figure). Seconds are
  turned into samples with the recording's median sample period.
* The peers' protocols, open loop (:mod:`imu_learn.score.peers`; every method's samples as they are,
  no bias removed, scored from the start of each gap-free test segment, not from ``startup_bias_s``):
  AOE (Brossard et al. 2020) = RMSE over every sample of the angle between the ground-truth
  orientation and the gyro integrated from the ground-truth orientation at the segment's first
  sample; "AOE mean" = the mean of that angle (what AirIMU's evaluation code reports as AOE); yaw AOE =
  the RMSE of the yaw (about world z, z-y-x Euler) of the world-frame error R̂ Rᵀ. AirIMU's ROE / RTE
  (means) and RO_RMSE / RP_RMSE (RMSEs) over non-overlapping consecutive windows of 1 s
  (round(rate) samples) starting at sample 0, each from the ground-truth state (p, v, R) at its first
  sample: orientation angle and position error at the window's end. Segments of a recording are
  pooled (samples for AOE, windows for the rest). Regressors get the window metrics from ``predict``
  on the raw input and no AOE; methods without a position no RTE ("-").
* Noise floor: where the test ground truth is pose-only (velocity derived from positions), a row
  "ground truth (noise floor)" gives the same metrics for an IMU synthesised from the ground truth
  itself (:mod:`imu_learn.baselines.noise_floor`), which integrates to exactly the ground truth for a
  perfect label; what remains is label noise (``eval.noise_floor = "always"`` adds it for every
  ground truth, ``"never"`` drops it).
"""

# The two variants above, as every table, CSV and report names them: key, label, short label.
VARIANTS = ("open_loop", "bias_removed")
VARIANT_LABELS = {"open_loop": "open loop", "bias_removed": "start-up bias removed"}
VARIANT_SHORT = {"open_loop": "open loop", "bias_removed": "bias removed"}

# The simple floor every learned method is judged against (the best of these per cell), and the
# reference rows that are neither floor nor learned.
FLOOR_METHODS = ("raw", "timing", "traditional", "traditional+timing", "zero-displacement")
REFERENCE_METHODS = ("ground truth (noise floor)",)
