"""Train the paper's IMU refiner: ``python -m imu_learn.fit``.

Usage::

    python -m imu_learn.fit                                  # default run: the shipped EuRoC crops
    python -m imu_learn.fit --config configs/euroc.toml      # a config file
    python -m imu_learn.fit --optim.lr 3e-4 --data.window 100 --name try1   # dotted overrides
    python -m imu_learn.fit --resume runs/try1               # continue a run (``--optim.epochs N`` to extend)
    python -m imu_learn.fit --print-config                   # the resolved config as TOML
    torchrun --nproc_per_node 4 -m imu_learn.fit --config configs/euroc.toml   # several GPUs

What a run does:

* config: defaults (= ``configs/default.toml``), then ``--config FILE``, then ``--key.sub value``
  overrides, each checked against the field's type (:mod:`imu_learn.train.config`).
* split by sequence (:mod:`imu_learn.data.splits`), written to ``RUN/split.json``; the config to
  ``RUN/config.toml``. Run folder: ``<runs_dir>/<name>``, name defaulting to a timestamp.
* model normalisation (per-channel mean/std) from the training split's raw IMU.
* Adam (paper: lr 1e-4). An epoch is ``optim.steps_per_epoch`` augmented batches, built by the Rust
  ``BatchSampler`` in the main process (no forked DataLoader workers: rayon does not survive a
  fork). Batch ``step`` is drawn with a seed derived from (seed, rank, step), and torch's RNG is
  re-seeded from the same triple before the step (dropout), so a resumed run draws exactly the
  batches the uninterrupted one would have.
* after every epoch: loss on fixed, non-augmented validation windows (``BatchSampler.eval_windows``,
  stride ``data.val_stride``); ``best.pt`` when it improves, then ``last.pt`` (both atomic, via
  :mod:`imu_learn.infer.checkpoint`: model args and weights incl. normalisation, optimiser, full config,
  epoch, step, best metric, code version, and the metrics history); ``RUN/metrics.csv`` rewritten
  (atomically) with one row per epoch so far; TensorBoard scalars in ``RUN/tb`` when the ``tensorboard`` package is
  installed (it is optional; without it nothing is written there).
* ``--resume RUN``: everything is rebuilt from ``RUN/last.pt`` (config, split check, model,
  optimiser, step, history; metrics.csv is rewritten from the checkpoint's history so a kill
  between two writes cannot duplicate or lose a row). A checkpoint taken mid-epoch (Ctrl-C)
  continues mid-epoch. The data must be what the run started with (split.json is compared). A
  truncated or modified ``last.pt`` (its content digest does not match) is refused with one line,
  never silently replaced by a fresh start.
* Ctrl-C: ``last.pt`` is saved with the state after the last finished step, one line says how to
  resume, exit status 130. Known errors (config, data, checkpoint, missing files, a full disk or a
  read-only run folder) print one line and exit with status 2; every file of the run folder is
  written atomically (:mod:`imu_learn.util.atomic`), so what is there after any failure is complete.
* at the end: relative pose error on the held-out test split (:mod:`imu_learn.score.metrics`) for the
  raw IMU, for the timing floor (the raw IMU resampled at the one time offset fitted on the training
  split, :mod:`imu_learn.baselines.timing`) and for the best-validation model, judged against the
  better of raw and timing in each cell ("model/floor"), over ``data.eval_horizons`` IMU samples (default 10
  and 200), pooled and per test recording, open loop and with a
  start-up bias (fitted on each input's first ``data.startup_bias_s`` seconds against ground truth,
  raw and refined separately) subtracted; windows start after those seconds so no cell is scored on
  data its bias was fitted on. Printed and written to ``RUN/results.json``.

Devices: ``device = "auto"`` uses CUDA when present, else the CPU with ``threads`` torch threads.
Several GPUs: start with ``torchrun --nproc_per_node K -m imu_learn.fit ...``; when ``WORLD_SIZE``
is above 1 each process joins a process group (NCCL on CUDA, Gloo on CPU), wraps the model in
DistributedDataParallel, draws its own batch stream (the rank enters the seed) so the effective
batch is K × batch_size, and only rank 0 writes files and evaluates; validation runs on every rank
(it is small), so all ranks agree on the best epoch without communication.
"""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import logging
import math
import os
import signal
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple
from typing import Sequence as Seq

import numpy as np
import torch
from tqdm import tqdm

from imu_learn.baselines import affine
from imu_learn.baselines.affine import TraditionalParams
from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.timing import Timing, resample
from imu_learn.baselines.traditional import TraditionalTiming
from imu_learn.calib.profile import Profile
from imu_learn.core.batches import Batch, BatchSampler, batch_seed
from imu_learn.data.splits import Split, make_split, split_signature, write_split
from imu_learn.data.types import Segment
from imu_learn.infer import guard, windowing
from imu_learn.infer.checkpoint import (
    load_checkpoint,
    load_model,
    measured_record,
    model_from_checkpoint,
    save_checkpoint,
    training_record,
)
from imu_learn.infer.rates import recording_device
from imu_learn.nn.config import ARGS_BEFORE
from imu_learn.nn.device import pick_device
from imu_learn.nn.losses import imu_loss
from imu_learn.nn.model import ImuRefiner, ModelConfig
from imu_learn.score.metrics import floor_ratios, index_at, relative_pose_rmse_many, variant_table, without_fitted_bias
from imu_learn.score.peers import open_loop_aoe_deg
from imu_learn.score.protocol import VARIANT_LABELS, VARIANTS
from imu_learn.settings import toml_of_text
from imu_learn.train.config import ConfigError, RunConfig, build_config, read_toml, to_toml
from imu_learn.train.split_profile import PROFILE_DIR, calibrate_split
from imu_learn.util.atomic import atomic_write_text

RESUME_OVERRIDABLE = ("optim.epochs", "device", "threads")
# what a run's start (floor_start, profile_start) writes into its config after config.toml: no edit of the user's
SET_BY_THE_START = ("model.start", "model.fir_taps", "model.fir_init_tau", "model.calib")
logger = logging.getLogger(__name__)

StepHook = Callable[[int, float], None]


# ---------------------------------------------------------------------------------------------
# small helpers


def norm_stats(seqs: Seq[Segment]) -> tuple:
    x = np.concatenate([np.concatenate([s.gyro, s.acc], axis=1) for s in seqs], axis=0)
    mean = x.mean(axis=0)
    std = np.maximum(x.std(axis=0), 1e-6)
    return torch.as_tensor(mean, dtype=torch.float32), torch.as_tensor(std, dtype=torch.float32)


@contextlib.contextmanager
def deferred_interrupt():
    """Hold a Ctrl-C until the block is done (a checkpoint write is never cut short)."""
    if not hasattr(signal, "SIGINT") or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    got: List[Any] = []
    try:
        old = signal.signal(signal.SIGINT, lambda *a: got.append(a))
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if got:
            raise KeyboardInterrupt


def write_csv(path: Path, rows: List[Dict[str, Any]]) -> None:
    """All ``rows`` to ``path``, atomically (rewritten whole each epoch rather than appended to,
    so a kill or a full disk never leaves half a row)."""
    buf = io.StringIO()
    if rows:
        # Every key of every row (an epoch-0 row from optim.validate_start has no training terms).
        names = list(dict.fromkeys(k for r in rows for k in r))
        w = csv.DictWriter(buf, fieldnames=names, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    atomic_write_text(path, buf.getvalue())


def _tb_writer(run_dir: Path):
    try:
        from torch.utils.tensorboard import SummaryWriter  # needs the tensorboard package
    except Exception:
        return None
    return SummaryWriter(str(run_dir / "tb"))


# ---------------------------------------------------------------------------------------------
# distributed


class Dist:
    def __init__(self) -> None:
        self.world = int(os.environ.get("WORLD_SIZE", "1"))
        self.rank = int(os.environ.get("RANK", "0"))
        self.local_rank = int(os.environ.get("LOCAL_RANK", "0"))
        self.on = self.world > 1

    @property
    def main(self) -> bool:
        return self.rank == 0

    def init(self, device: torch.device) -> None:
        if self.on and not torch.distributed.is_initialized():
            backend = "nccl" if device.type == "cuda" else "gloo"
            if device.type == "cuda":
                torch.cuda.set_device(device)
            torch.distributed.init_process_group(backend)

    def barrier(self) -> None:
        if self.on and torch.distributed.is_initialized():
            torch.distributed.barrier()

    def close(self) -> None:
        if self.on and torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()


# ---------------------------------------------------------------------------------------------
# evaluation pieces


@torch.no_grad()
def validation_loss(model: ImuRefiner, batch: Batch, cfg: RunConfig, device: torch.device, chunk: int = 256) -> Dict[str, float]:
    """Loss terms over all fixed validation windows (window-weighted means)."""
    was = model.training
    model.eval()
    sums: Dict[str, float] = {}
    n_total = batch.imu.shape[0]
    horizons = [int(h) for h in batch.horizons]
    for a in range(0, n_total, chunk):
        b = min(n_total, a + chunk)
        imu = torch.from_numpy(np.ascontiguousarray(batch.imu[a:b], dtype=np.float32)).to(device)
        with torch.no_grad():
            refined, var = model(imu, with_variance=True)
            _, terms = imu_loss(refined, reg_reference(model, imu), batch.dt[a:b], batch.dq_wxyz[a:b], batch.dv[a:b],
                                batch.dp[a:b], horizons, batch.bias[a:b], cfg.loss, var)
        for k, v in terms.items():
            sums[k] = sums.get(k, 0.0) + float(v) * (b - a)
    model.train(was)
    return {k: v / n_total for k, v in sums.items()}


def reg_reference(model: ImuRefiner, imu: torch.Tensor) -> torch.Tensor:
    """What the loss's regulariser measures the refined samples against: the input, or, for a model on
    top of a device profile (model.start = "profile"), the profile's floor the model holds, so only
    the network's residual is regularised (the floor's own correction is not pulled back to raw)."""
    return model.floor(imu) if model.cfg.start == "profile" else imu


# The model args that may differ between optim.init's checkpoint and the model it initialises.
COVARIANCE_ARGS = ("covariance", "sigma_gyro_min", "sigma_gyro_max", "sigma_acc_min", "sigma_acc_max")


def init_from(model: ImuRefiner, path: Path) -> None:
    """optim.init: the weights of a trained checkpoint (normalisation included) into ``model``."""
    state = load_checkpoint(path)
    # a checkpoint written before a model arg existed has that arg's default
    theirs = {k: v for k, v in {**asdict(ModelConfig()), **ARGS_BEFORE, **state["model_args"]}.items() if k not in COVARIANCE_ARGS}
    ours = {k: v for k, v in model.model_args().items() if k not in COVARIANCE_ARGS}
    diff = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
    if diff:
        raise ConfigError(f"optim.init: {path} was trained with other model args: "
                          + ", ".join(f"model.{k} = {theirs.get(k)!r} there, {ours.get(k)!r} here" for k in diff))
    try:
        model.load_refiner(state["model"])
    except ValueError as e:
        raise ConfigError(f"optim.init: {path}: {e}") from None


def without_startup_bias(seqs: Seq[Segment], cfg: RunConfig) -> Tuple[List[Segment], Dict[str, Any]]:
    """Each sequence with its own start-up bias (fitted on its first ``data.startup_bias_s``
    seconds against ground truth) subtracted, and the biases by sequence name."""
    return without_fitted_bias(seqs, cfg.data.startup_bias_s, cfg.data.gravity)


def without_device_bias(split: Split, cfg: RunConfig) -> Split:
    """``data.train_bias = "remove"``: the training and validation segments, each with one constant
    gyro and accelerometer bias fitted against its ground truth over the whole segment subtracted
    (test segments unchanged)."""
    g = cfg.data.gravity
    return Split(without_fitted_bias(split.train, None, g)[0], without_fitted_bias(split.val, None, g)[0],
                 split.test, split.record)


def bias_removed_pose(seqs: Seq[Segment], n: int, cfg: RunConfig) -> Dict[str, float]:
    """Relative pose RMSE over ``n`` samples with each sequence's start-up bias removed (the
    final table's second protocol); windows from ``data.startup_bias_s`` on when the sequence is
    long enough for that, else from its start (short validation blocks still get a score)."""
    d = cfg.data
    fixed, _ = without_startup_bias(seqs, cfg)
    long_enough = all(len(s) - index_at(s, d.startup_bias_s) > n for s in seqs)
    first = d.startup_bias_s if long_enough else 0.0
    return relative_pose_rmse_many(fixed, n, d.val_stride, d.gravity, first_s=first)


class ValidationPose:
    """The ``optim.select = "val_pose"`` metric: relative pose RMSE on the validation sequences,
    start-up bias removed (as in the final table), at the horizons ``optim.select_horizons``
    (default: ``data.window`` samples), scored as the largest model/raw ratio over those horizons
    and the terms ``optim.select_terms`` (rotation and translation, or rotation only), combined by
    ``optim.select_combine``: "max" is below 1 only when the model beats raw IMU on every one, so a
    model that trades one for another is not picked; "mean" is their geometric mean.
    Selecting on the reported protocol matters because the validation loss also scores the
    device's own constant bias, which the bias-aware model passes through by design."""

    def __init__(self, seqs: Seq[Segment], cfg: RunConfig) -> None:
        self.seqs, self.cfg = list(seqs), cfg
        self.horizons = list(cfg.optim.select_horizons) or [cfg.data.window]
        self.keys = ("rot_rad",) if cfg.optim.select_terms == "rot" else ("rot_rad", "trans_m")
        # "recordings": each validation recording's ratio counts alike (geometric mean), so one
        # recording with noisy ground truth cannot decide the pooled RMSE alone.
        groups: Dict[str, List[int]] = {}
        for i, s in enumerate(self.seqs):
            groups.setdefault(recording_of(s.name) if cfg.optim.select_average == "recordings" else "all", []).append(i)
        self.groups = list(groups.values())
        self.raw = {n: self._scores(self.seqs, n) for n in self.horizons}
        # on top of a floor (select_reference "start") the open-loop AOE is one more cell: an epoch that
        # loses it to the floor is not picked (the verdict covers every cell the final table reports)
        self.aoe = cfg.optim.select_reference == "start"
        self.raw_aoe = [open_loop_aoe_deg([self.seqs[i] for i in g]) for g in self.groups] if self.aoe else []
        # optim.select_reference = "start": the untrained model's ratios (set by its first call, epoch
        # 0, and carried in the checkpoint so a resumed run scores the same way)
        self.reference: Optional[List[float]] = None

    def _scores(self, seqs: List[Segment], n: int) -> List[Dict[str, float]]:
        return [bias_removed_pose([seqs[i] for i in g], n, self.cfg) for g in self.groups]

    @torch.no_grad()
    def __call__(self, model: ImuRefiner, device: torch.device) -> Dict[str, float]:
        refined = [refine_sequence(model, s, self.cfg) for s in self.seqs]  # keeps model.training
        out: Dict[str, float] = {}
        ratios = []
        for n in self.horizons:
            got = self._scores(refined, n)
            for k in self.keys:
                logs = [math.log(max(m[k], 1e-15) / max(r[k], 1e-15)) for m, r in zip(got, self.raw[n])]
                ratios.append(math.exp(sum(logs) / len(logs)))
            pooled = bias_removed_pose(refined, n, self.cfg) if len(self.groups) > 1 else got[0]
            out[f"pose_rot_deg_n{n}"], out[f"pose_trans_m_n{n}"] = pooled["rot_deg"], pooled["trans_m"]
        # the longest horizon's figures also under the short names (metrics.csv columns kept)
        out["pose_rot_deg"], out["pose_trans_m"] = pooled["rot_deg"], pooled["trans_m"]
        if self.aoe:
            got_aoe = [open_loop_aoe_deg([refined[i] for i in g]) for g in self.groups]
            logs = [math.log(max(m, 1e-15) / max(r, 1e-15)) for m, r in zip(got_aoe, self.raw_aoe)]
            ratios.append(math.exp(sum(logs) / len(logs)))
            out["pose_aoe_deg"] = open_loop_aoe_deg(refined)
        if self.cfg.optim.select_reference == "start":
            if self.reference is None:
                self.reference = list(ratios)
            ratios = [r / ref for r, ref in zip(ratios, self.reference)]
        if self.cfg.optim.select_combine == "mean":
            out["pose_score"] = math.exp(sum(math.log(r) for r in ratios) / len(ratios))
        else:
            out["pose_score"] = max(ratios)
        return out


def refine_sequence(model: ImuRefiner, seq: Segment, cfg: RunConfig) -> Segment:
    """The model applied to a whole sequence by the one windowing rule
    (:mod:`imu_learn.infer.windowing`) for a model trained on ``cfg.data.window``: the same rule
    ``imu-learn refine``, evaluate, fuse and model_check apply to the saved checkpoint."""
    return windowing.refine_sequence(model, seq, windowing.Windowing.for_training_window(cfg.data.window))


def recording_of(segment_name: str) -> str:
    """``V1_01_easy#2`` -> ``V1_01_easy`` (segments of one recording are scored together)."""
    return segment_name.split("#")[0]


def _cells(seqs: List[Segment], fixed: List[Segment], cfg: RunConfig) -> Dict[str, Any]:
    d = cfg.data
    return variant_table(seqs, fixed, d.eval_horizons, d.eval_stride, d.startup_bias_s, d.gravity)


Calibration = Tuple[np.ndarray, np.ndarray]  # A (6, 6), c (6,) for ImuRefiner.set_calibration


def affine_calibration(p: TraditionalParams) -> Calibration:
    """The fixed calibration of an affine floor: [gyro, acc] -> A @ [gyro, acc] + c."""
    A = np.zeros((6, 6))
    A[:3, :3], A[:3, 3:], A[3:, 3:] = p.M_g, -p.G, p.M_a
    return A, np.concatenate([-p.M_g @ p.b_g, -p.M_a @ p.b_a])


def floor_start(cfg: RunConfig, split: Split, run_dir: Path) -> Tuple[RunConfig, Start]:
    """``model.start`` = "calibrate": calibrate's device profile of the split's training segments
    (:mod:`imu_learn.train.split_profile`, written to ``run_dir/profile/``), then as a profile's path.
    ``model.start`` = "timing" or "traditional+timing": fit that floor on the split's training
    recordings (validation keeps its offset or not) and return ``cfg`` with ``model.fir_init_tau`` (and
    ``model.calib``) set, plus the calibration (A (6, 6), c (6,)) for :meth:`ImuRefiner.set_calibration`
    (None for "timing"): the untrained model is then that floor (without traditional's low-pass filter).
    ``model.start`` = a device profile's path: :func:`profile_start` (no fit)."""
    settings = FitSettings(window=cfg.data.window, gravity=cfg.data.gravity, seed=cfg.seed)
    if cfg.model.start == "calibrate":
        device = (recording_device(cfg.data.roots[0].format) if cfg.data.roots else None) or "device"
        logger.info("model.start = calibrate: fitting the device profile of the training split")
        path = calibrate_split(split, run_dir, settings, device, progress=logger.info)
        cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, start=str(path)))
    if cfg.model.start not in ("timing", "traditional+timing"):
        given = cfg.model.start
        cfg, start = profile_start(cfg)
        check_start_profile(given, start.profile, split)
        return cfg, start
    max_shift = float(cfg.model.fir_taps // 2)
    calib = None
    if cfg.model.start == "timing":
        m = Timing(max_shift=max_shift)
        m.fit(list(split.train), list(split.val), settings)
        tau = m.tau
    else:
        t = TraditionalTiming(cutoffs_hz=(None,), max_shift=max_shift)
        t.fit(list(split.train), list(split.val), settings)
        calib = affine_calibration(t.params)
        tau = t.params.time_offset
    logger.info("model.start = %s: fitted on the train split, the FIR starts as a shift of %+.3f samples%s",
                cfg.model.start, tau, "" if calib is None else " after the fixed affine calibration")
    model = dataclasses.replace(cfg.model, fir_init_tau=float(tau), calib=calib is not None)
    return dataclasses.replace(cfg, model=model), Start(calib)


# The FIR of a profile's start holds its low-pass to this much of the filter's absolute response
# left outside the taps (the truncated filter is rescaled to unit DC, so the bias is kept exactly).
FIR_TAIL = 1e-5


@dataclass(frozen=True)
class Start:
    """What ``model.start`` sets in a new model: the fixed calibration (A (6, 6), c (6,)), the FIR
    branch's filters (6, taps) and the device profile's dict (each None where not used)."""

    calib: Optional[Calibration] = None
    fir: Optional[np.ndarray] = None
    profile: Optional[Dict[str, Any]] = None


def floor_filters(p: TraditionalParams, rate_hz: float, most: int) -> Tuple[np.ndarray, float]:
    """A floor's time shift and low-pass as one centred FIR per channel (gyro: ``cutoff_gyro``, acc:
    ``cutoff_acc``): (6, 2K + 1) filters of unit sum and the absolute response they leave out, K the
    fewest taps each side (at least the shift's, at most ``most``) leaving out below :data:`FIR_TAIL`.
    From the response of :func:`imu_learn.baselines.affine.apply`'s own shift and filter to a unit
    impulse on uniform stamps."""
    c = 4 * max(most, 8)
    t = np.arange(2 * c + 1, dtype=np.int64) * int(round(1e9 / rate_hz))
    delta = np.zeros((len(t), 1))
    delta[c] = 1.0
    shifted = resample(t, delta, p.time_offset, float(t[1] - t[0]))
    resp = [affine.lowpass(shifted, rate_hz, cut)[:, 0] for cut in (p.cutoff_gyro, p.cutoff_acc)]
    shift = math.ceil(abs(p.time_offset))
    k, tail = shift, math.inf
    for k in range(shift, max(most, shift) + 1):
        tail = max(float(np.abs(y).sum() - np.abs(y[c - k:c + k + 1]).sum()) for y in resp)
        if tail < FIR_TAIL:
            break
    # out[j] = sum_m g_m x[j + m] with g_m = y[c - m]; the taps run m = -k .. k
    taps = [y[c - k:c + k + 1][::-1] / y[c - k:c + k + 1].sum() for y in resp]
    return np.stack([taps[0]] * 3 + [taps[1]] * 3), tail


def check_start_profile(where: str, profile: Dict[str, Any], split: Split) -> None:
    """One warning where a start profile's raw IMU (its ``inputs``) looks unlike the run's training
    segments (refine's guard, the locations alone: another device or mounting), so a profile of another
    device is named before the run trains on top of it."""
    inputs = profile.get("inputs") if isinstance(profile, dict) else None
    if not inputs or not inputs.get("recordings"):
        return
    unlike = {}
    for s in split.train:
        out = guard.compare(inputs, guard.input_stats(s.t_ns, s.gyro, s.acc), device_only=True)
        if out:
            unlike[s.name] = out[0]
    if unlike:
        name, d = next(iter(unlike.items()))
        logger.warning("model.start: %s was fitted on an IMU unlike %d of the %d training segments (%s: %s %.4g, the "
                       "profile's %.4g..%.4g): another device or mounting? its floor may make this device's data worse; "
                       "calibrate this device's (model.start = calibrate)", where, len(unlike), len(split.train), name,
                       d["statistic"], d["value"], d["training"][0], d["training"][1])


def profile_start(cfg: RunConfig) -> Tuple[RunConfig, Start]:
    """``model.start`` = PATH to a device profile (``imu-learn calibrate``'s profile.json): its floor
    (``traditional+timing``'s parameters) becomes the model's fixed calibration and its FIR filters
    (the time shift, then the low-pass where the profile has one: :func:`floor_filters`), so the
    untrained model is that floor. No fit. ``model.start`` becomes "profile"; ``model.fir_taps``, when
    0, the fewest taps that hold the floor (at most a quarter of ``data.window`` each side, so the
    windows refine keeps see no edge; beyond that a warning says how much of the filter is left out).
    The profile's dict goes into the checkpoint (:func:`imu_learn.infer.checkpoint.training_record`);
    since the model holds its floor, ``imu-learn refine`` does not apply it again."""
    where = cfg.model.start
    if where == "profile":
        raise ConfigError("model.start = profile: name the device profile's file (PATH/profile.json)")
    prof = Profile.load(where)
    if not prof.has_floor:
        raise ConfigError(f"model.start: {where} has no floor (a profile of the noise alone, from a recording "
                          "without a reference)")
    p = prof.floor.params
    tau = float(p.time_offset)
    need = math.ceil(abs(tau))
    if cfg.model.fir_taps and cfg.model.fir_taps // 2 < need:
        raise ConfigError(f"model.start: the time offset of {where} ({tau:+.3f} samples) needs model.fir_taps >= "
                          f"{2 * need + 1}, got {cfg.model.fir_taps}")
    most = cfg.model.fir_taps // 2 if cfg.model.fir_taps else max(cfg.data.window // 4, need)
    fir, tail = floor_filters(p, prof.sample_rate_hz, most)
    if cfg.model.fir_taps:  # the user's taps: the filters padded with zeros
        pad = cfg.model.fir_taps // 2 - fir.shape[1] // 2
        fir = np.pad(fir, ((0, 0), (pad, pad)))
    if tail >= FIR_TAIL:
        logger.warning("model.start: the low-pass filter of %s needs more than %d FIR taps; the untrained model "
                       "leaves out %.2g of its response", where, fir.shape[1], tail)
    taps = fir.shape[1] if fir.shape[1] > 1 else 0
    logger.info("model.start = %s (device %s): the FIR (%d taps) starts as the floor's shift of %+.3f samples%s, "
                "after its fixed affine calibration", where, prof.device, taps, tau,
                "" if p.cutoff_gyro is None and p.cutoff_acc is None else " and its low-pass")
    model = dataclasses.replace(cfg.model, start="profile", fir_taps=taps, fir_init_tau=tau, calib=True)
    return dataclasses.replace(cfg, model=model), Start(affine_calibration(p), fir if taps else None, prof.to_dict())


def timing_floor(split: Split, cfg: RunConfig) -> Tuple[List[Segment], float]:
    """The ``timing`` floor of the final table: the raw test IMU resampled at the one time offset
    [samples] fitted on the run's training split (validation only keeps it or not), as
    :mod:`imu_learn.baselines.timing` does; returns the shifted test sequences and the offset."""
    m = Timing()
    m.fit(list(split.train), list(split.val), FitSettings(window=cfg.data.window, gravity=cfg.data.gravity))
    test = [Segment(s.name, s.t_ns, *m.refine(s), s.p, s.v, s.q_wxyz) for s in split.test]
    return test, m.tau


def evaluate_table(raw_seqs: List[Segment], model_seqs: List[Segment], cfg: RunConfig,
                   timing_seqs: Optional[List[Segment]] = None,
                   profile_seqs: Optional[List[Segment]] = None) -> Dict[str, Any]:
    """Relative pose RMSE (rot deg, trans m) at ``data.eval_horizons``, raw (and, given
    ``timing_seqs``, the timing floor) vs model, open loop vs bias removed: pooled over every window
    of the test split (``rows``) and per test recording (``per_recording``, as the paper's Table II
    lists sequences). ``profile_seqs``: the test split through the device profile the model starts
    from (its floor, low-pass included). ``vs_floor``: the model's ratio to the best of the floor rows
    (raw, timing, profile) per cell (:func:`imu_learn.score.metrics.floor_ratios`)."""
    out: Dict[str, Any] = {"rows": {}, "per_recording": {}, "startup_bias": {}}
    floors = [("timing", timing_seqs), ("profile", profile_seqs)]
    rows = [("raw", raw_seqs)] + [(k, v) for k, v in floors if v is not None] + [("model", model_seqs)]
    for row, seqs in rows:
        fixed, out["startup_bias"][row] = without_startup_bias(seqs, cfg)
        out["rows"][row] = _cells(seqs, fixed, cfg)
        for rec in dict.fromkeys(recording_of(s.name) for s in seqs):
            idx = [i for i, s in enumerate(seqs) if recording_of(s.name) == rec]
            out["per_recording"].setdefault(rec, {})[row] = _cells([seqs[i] for i in idx], [fixed[i] for i in idx], cfg)
    floors = [r for r, _ in rows if r != "model"]
    out["vs_floor"] = floor_ratios(out["rows"], floors, "model")
    out["aoe_deg"] = {row: open_loop_aoe_deg(list(seqs)) for row, seqs in rows}
    return out


def format_table(res: Dict[str, Any], names: List[str], cfg: RunConfig) -> str:
    d = cfg.data
    hs = list(d.eval_horizons)
    recs = sorted({n.split("#")[0] for n in names})
    what = ", ".join(names) if len(names) <= 3 else f"{len(names)} segments of {len(recs)} recordings"
    head = (f"Held-out test ({what}): relative pose RMSE over n IMU samples, windows every "
            f"{d.eval_stride} samples from {d.startup_bias_s:g} s on")
    k = len(hs)
    cols = [(c, n) for c in VARIANTS for n in hs]
    width = 14 * k - 1
    lines = [head,
             f"{'':24}|" + "|".join(f"{VARIANT_LABELS[v]:^{width}}" for v in VARIANTS),
             f"{'':24}|" + "|".join(f"{'n=' + str(n):^13}" for _, n in cols[:k]) + "|"
             + "|".join(f"{'n=' + str(n):^13}" for _, n in cols[k:])]
    tau = res.get("timing_offset_samples")
    labels = {"raw": "raw IMU", "timing": "timing" if tau is None else f"timing {tau:+.2f}",
              "profile": "device profile", "model": "trained model"}
    for row in [r for r in ("raw", "timing", "profile", "model") if r in res["rows"]]:
        for key, unit, fmt in (("rot_deg", "rot [deg]", "{:.4f}"), ("trans_m", "trans [m]", "{:.5f}")):
            first = labels[row] if key == "rot_deg" else ""
            cells = [fmt.format(res["rows"][row][c][str(n)][key]) for c, n in cols]
            lines.append(f"{first:14}{unit:>10}|" + "|".join(f"{x:^13}" for x in cells[:k]) + "|"
                         + "|".join(f"{x:^13}" for x in cells[k:]))
    aoe = res.get("aoe_deg")
    if aoe:
        lines.append("open-loop AOE [deg]: " + ", ".join(f"{labels[r]} {aoe[r]:.3f}" for r in labels if r in aoe)
                     + " (each test segment from its first ground-truth attitude)")
    vs = res.get("vs_floor")
    if vs:
        for key, unit in (("rot", "rot"), ("trans", "trans")):
            first = "model/floor" if key == "rot" else ""
            cells = [f"{vs[c][str(n)][key]:.2f} {vs[c][str(n)][key + '_floor']}" for c, n in cols]
            lines.append(f"{first:14}{unit:>10}|" + "|".join(f"{x:^13}" for x in cells[:k]) + "|"
                         + "|".join(f"{x:^13}" for x in cells[k:]))
        lines.append("model/floor: the trained model's error over the lower floor row (named) of each cell; below 1 beats it")
        if "timing" in res["rows"]:
            lines.append("timing: raw IMU resampled at the time offset [samples] fitted on the training split")
        if "profile" in res["rows"]:
            lines.append("device profile: the floor the model starts from (calibrate's, fitted on the training split)")
    if res.get("ships"):
        lines.append(res["ships"])
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# the run


@dataclass
class Validation:
    """The fixed validation windows and, with ``optim.select = "val_pose"``, the pose score."""

    batch: Batch
    pose: Optional[ValidationPose]

    @property
    def select_key(self) -> str:
        return "pose_score" if self.pose is not None else "total"

    def __call__(self, model: ImuRefiner, cfg: RunConfig, device: torch.device) -> Dict[str, float]:
        val = validation_loss(model, self.batch, cfg, device)
        if self.pose is not None:
            val.update(self.pose(model, device))
        return val


@dataclass
class TrainState:
    """What a run carries from step to step and saves in its checkpoints."""

    model: ImuRefiner
    opt: torch.optim.Optimizer
    step: int = 0
    epochs_done: int = 0
    best: Optional[float] = None
    best_epoch: Optional[int] = None
    history: List[Dict[str, Any]] = field(default_factory=list)
    partial: Dict[str, float] = field(default_factory=dict)  # summed loss terms of the epoch so far
    elapsed0: float = 0.0  # seconds run before a resume
    t_start: float = field(default_factory=time.time)
    validation: Optional[Validation] = None  # its pose score's reference is saved with the state
    record: Dict[str, Any] = field(default_factory=dict)  # the training IMU's rate and device (checkpoint.training_record)
    measured: Optional[Tuple[int, Dict[str, Any]]] = None  # (step, record with the model's residual at that step)

    def elapsed(self) -> float:
        return self.elapsed0 + time.time() - self.t_start


def setup_device(cfg: RunConfig) -> Tuple[Dist, torch.device]:
    """The process group (when ``WORLD_SIZE`` > 1) and this process's device."""
    dist = Dist()
    device = pick_device(cfg.device, dist.local_rank)
    if device.type == "cpu":
        torch.set_num_threads(cfg.threads)
    dist.init(device)
    return dist, device


def prepare_data(cfg: RunConfig, split: Optional[Split]) -> Tuple[Split, BatchSampler, Validation]:
    """The split (made from ``cfg.data`` when not given; device bias removed with
    ``data.train_bias = "remove"``), the training batch sampler and the validation set."""
    if split is None:
        split = make_split(cfg.data)
    if cfg.data.train_bias == "remove":
        split = without_device_bias(split, cfg)
    bc = cfg.data.batch_config()
    sampler = BatchSampler(split.train, bc)
    val_batch = BatchSampler(split.val, bc).eval_windows(cfg.data.val_stride)
    val_pose = ValidationPose(split.val, cfg) if cfg.optim.select == "val_pose" else None
    return split, sampler, Validation(val_batch, val_pose)


def _optimizer(model: ImuRefiner, cfg: RunConfig) -> torch.optim.Optimizer:
    return torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=cfg.optim.lr)


def new_state(cfg: RunConfig, train_seqs: Seq[Segment], device: torch.device, start: Start = Start()) -> TrainState:
    """A fresh model (seeded by ``cfg.seed``, normalised on ``train_seqs``, ``optim.init``'s weights
    when set) and its optimiser."""
    torch.manual_seed(cfg.seed)
    mean, std = norm_stats(train_seqs)
    model = ImuRefiner(cfg.model, mean, std)
    if start.calib is not None:
        model.set_calibration(torch.as_tensor(start.calib[0]), torch.as_tensor(start.calib[1]))
    if start.fir is not None:
        model.set_fir_filter(torch.as_tensor(start.fir))
    if cfg.optim.init:
        init_from(model, Path(cfg.optim.init))
    if cfg.optim.trainable == "covariance":
        model.freeze_refiner()
    model.to(device)
    return TrainState(model, _optimizer(model, cfg))


def resumed_state(cfg: RunConfig, state: Dict[str, Any], device: torch.device) -> TrainState:
    """Model, optimiser, step, best metric and history of checkpoint ``state``."""
    model = model_from_checkpoint(state)
    if cfg.optim.trainable == "covariance":
        model.freeze_refiner()
    model.to(device)
    opt = _optimizer(model, cfg)
    opt.load_state_dict(state["optimizer"])
    extra = state.get("extra") or {}
    return TrainState(
        model, opt, step=int(state["step"]), epochs_done=int(state["epoch"]), best=state["best_metric"],
        best_epoch=extra.get("best_epoch"), history=list(extra.get("history", [])),
        partial=dict(extra.get("partial", {})), elapsed0=float(extra.get("elapsed_s", 0.0)),
    )


def save_state(path: Path, ts: TrainState, cfg_dict: Dict[str, Any], dist: Dist) -> None:
    """Checkpoint ``ts`` to ``path`` (rank 0 only; a Ctrl-C waits until the file is written)."""
    if not dist.main:
        return
    pose = ts.validation.pose if ts.validation is not None else None
    extra = {"history": ts.history, "partial": ts.partial, "best_epoch": ts.best_epoch, "elapsed_s": ts.elapsed(),
             "select_reference": None if pose is None else pose.reference,
             "world_size": dist.world}
    if ts.measured is None or ts.measured[0] != ts.step:  # best.pt and last.pt of one step: measured once
        ts.measured = (ts.step, measured_record(ts.record, ts.model, cfg_dict))
    with deferred_interrupt():
        save_checkpoint(path, ts.model, cfg_dict, ts.epochs_done, ts.step, ts.best, ts.opt, extra, ts.measured[1])


def train_step(net: torch.nn.Module, ts: TrainState, sampler: BatchSampler, cfg: RunConfig, rank: int,
               device: torch.device) -> float:
    """One optimiser step on batch ``ts.step`` (batch and torch RNG seeded from (seed, rank, step));
    adds the loss terms to ``ts.partial`` and returns the total loss."""
    s = batch_seed(cfg.seed, rank, ts.step)
    torch.manual_seed(s)
    b = sampler.sample(s)
    horizons = [int(h) for h in b.horizons]
    imu = torch.from_numpy(np.ascontiguousarray(b.imu, dtype=np.float32)).to(device)
    refined, var = net(imu, with_variance=True)
    loss, terms = imu_loss(refined, reg_reference(ts.model, imu), b.dt, b.dq_wxyz, b.dv, b.dp, horizons, b.bias,
                           cfg.loss, var)
    ts.opt.zero_grad(set_to_none=True)
    loss.backward()
    if cfg.optim.grad_clip > 0:
        torch.nn.utils.clip_grad_norm_(ts.model.parameters(), cfg.optim.grad_clip)
    ts.opt.step()
    ts.step += 1
    for k, v in terms.items():
        ts.partial[k] = ts.partial.get(k, 0.0) + float(v)
    ts.partial["n"] = ts.partial.get("n", 0.0) + 1.0
    return float(terms["total"])


def select_epoch(ts: TrainState, val: Dict[str, float], cfg: RunConfig, select_key: str) -> Tuple[Dict[str, Any], bool]:
    """Close the epoch that just ended in ``ts``: its metrics row (appended to the history) and
    whether it is the best so far by ``select_key`` (then ``ts.best``/``best_epoch`` move to it)."""
    epoch = ts.step // cfg.optim.steps_per_epoch
    n = max(1.0, ts.partial.get("n", 0.0))
    row: Dict[str, Any] = {"epoch": epoch, "step": ts.step, "lr": cfg.optim.lr}
    for k in sorted(k for k in ts.partial if k != "n"):
        row[f"train_{k}"] = ts.partial[k] / n
    for k in sorted(val):
        row[f"val_{k}"] = val[k]
    improved = ts.best is None or val[select_key] < ts.best
    if improved:
        ts.best, ts.best_epoch = val[select_key], epoch
    row["best_epoch"] = ts.best_epoch
    row["elapsed_s"] = round(ts.elapsed(), 2)
    ts.history.append(row)
    ts.epochs_done = epoch
    ts.partial = {}
    return row, improved


def record_epoch(run_dir: Path, ts: TrainState, row: Dict[str, Any], improved: bool, cfg_dict: Dict[str, Any],
                 dist: Dist, tb: Any) -> None:
    """Rank 0: best.pt (when ``improved``), last.pt, metrics.csv and the TensorBoard scalars."""
    if not dist.main:
        return
    if improved:
        save_state(run_dir / "best.pt", ts, cfg_dict, dist)
    save_state(run_dir / "last.pt", ts, cfg_dict, dist)
    write_csv(run_dir / "metrics.csv", ts.history)
    if tb is not None:
        for k, v in row.items():
            if k.startswith(("train_", "val_")):
                tb.add_scalar(k.replace("_", "/", 1), v, ts.step)
        tb.flush()


def epoch_line(row: Dict[str, Any], val: Dict[str, float], cfg: RunConfig, improved: bool) -> str:
    return (f"epoch {row['epoch']}/{cfg.optim.epochs}  train {row.get('train_total', float('nan')):.5f}  "
            f"val {val['total']:.5f}"
            + (f"  pose {val['pose_score']:.4f}" if "pose_score" in val else "")
            + ("  *best*" if improved else ""))


def train(
    cfg: RunConfig,
    run_dir: Path,
    state: Optional[Dict[str, Any]] = None,
    split: Optional[Split] = None,
    on_step: Optional[StepHook] = None,
    progress: bool = True,
) -> Dict[str, Any]:
    """Train (or continue from checkpoint ``state``) and evaluate; returns the results dict.

    ``on_step(step, loss)`` is called after every finished optimiser step (tests use it to
    interrupt at a chosen step). KeyboardInterrupt propagates after ``last.pt`` is saved.
    """
    dist, device = setup_device(cfg)
    run_dir = Path(run_dir)
    split, sampler, validation = prepare_data(cfg, split)
    start = Start(profile=None if state is None else state.get("profile"))  # a profile the model holds
    if state is None and cfg.model.start != "raw":
        cfg, start = floor_start(cfg, split, run_dir)
    ts = new_state(cfg, split.train, device, start) if state is None else resumed_state(cfg, state, device)
    if validation.pose is not None and state is not None:
        validation.pose.reference = (state.get("extra") or {}).get("select_reference")
    ts.validation = validation
    ts.model.train()
    net: torch.nn.Module = ts.model
    if dist.on:
        net = torch.nn.parallel.DistributedDataParallel(ts.model, device_ids=[device.index] if device.type == "cuda" else None)

    spe = cfg.optim.steps_per_epoch
    total = cfg.optim.epochs * spe
    cfg_dict = cfg.to_dict()
    ts.record = training_record(split.train, cfg_dict, profile=start.profile, inputs=True)  # inputs: refine's guard
    if start.profile is not None:  # a model on top of a device profile is that device's
        ts.record["device"] = start.profile.get("device") or ts.record["device"]
    tb = _tb_writer(run_dir) if dist.main else None
    bar = tqdm(total=total, initial=ts.step, desc="fit", unit="step", disable=not (progress and dist.main),
               dynamic_ncols=True, mininterval=1.0)
    try:
        while True:
            if ts.step == 0 and not ts.history and cfg.optim.validate_start:
                val = validation(ts.model, cfg, device)
                row, improved = select_epoch(ts, val, cfg, validation.select_key)
                record_epoch(run_dir, ts, row, improved, cfg_dict, dist, tb)
                if dist.main:
                    bar.write(epoch_line(row, val, cfg, improved))
            if ts.step > 0 and ts.step % spe == 0 and ts.epochs_done < ts.step // spe:
                val = validation(ts.model, cfg, device)
                row, improved = select_epoch(ts, val, cfg, validation.select_key)
                record_epoch(run_dir, ts, row, improved, cfg_dict, dist, tb)
                if dist.main:
                    bar.write(epoch_line(row, val, cfg, improved))
            if ts.step >= total:
                break
            lv = train_step(net, ts, sampler, cfg, dist.rank, device)
            bar.update(1)
            bar.set_postfix(epoch=f"{ts.step // spe + (ts.step % spe > 0)}/{cfg.optim.epochs}", loss=f"{lv:.4g}", refresh=False)
            if on_step is not None:
                on_step(ts.step, lv)
    except KeyboardInterrupt:
        bar.close()
        save_state(run_dir / "last.pt", ts, cfg_dict, dist)
        if tb is not None:
            tb.close()
        raise
    bar.close()
    if tb is not None:
        tb.close()

    results: Dict[str, Any] = {}
    if dist.main and validation.pose is not None and ts.best is not None and ts.best >= 1.0:
        than = "raw IMU" if cfg.optim.select_reference == "raw" else f"the untrained start ({cfg.model.start})"
        logger.warning("no epoch beat %s on the validation sequences with the start-up bias removed "
                       "(best score %.4f at epoch %s; below 1 means better in every scored cell)",
                       than, ts.best, ts.best_epoch)
    if dist.main:
        results = final_evaluation(cfg, run_dir, split, device, ts.best_epoch, ts.best)
    dist.barrier()
    dist.close()
    return results


def ships_line(run_dir: Path, best_epoch: Optional[int]) -> str:
    """What a run on top of a device profile ships, from the selection on validation (never the test)."""
    if best_epoch:
        return (f"ships: the trained model (best.pt, epoch {best_epoch}): it beat the device profile in every "
                "scored cell on validation")
    return ("ships: the device profile (no trained epoch beat it on validation; best.pt is the profile's floor, "
            f"epoch 0): refine with --profile {run_dir / PROFILE_DIR / 'profile.json'}")


def final_evaluation(cfg: RunConfig, run_dir: Path, split: Split, device: torch.device,
                     best_epoch: Optional[int], best: Optional[float]) -> Dict[str, Any]:
    if not split.test:
        logger.info("no test sequences in data.split.test; no final table")
        return {}
    state = load_checkpoint(run_dir / "best.pt")
    model = load_model(run_dir / "best.pt", map_location=str(device)).to(device)
    refined = [refine_sequence(model, s, cfg) for s in split.test]
    timing_seqs, tau = timing_floor(split, cfg)
    profile = Profile.from_dict(state["profile"], str(run_dir / "best.pt")) if state.get("profile") else None
    profile_seqs = None if profile is None else [
        Segment(s.name, s.t_ns, *profile.apply(s.t_ns, s.gyro, s.acc), s.p, s.v, s.q_wxyz) for s in split.test]
    res = evaluate_table(list(split.test), refined, cfg, timing_seqs, profile_seqs)
    res["timing_offset_samples"] = tau
    if profile is not None:
        shipped = run_dir / PROFILE_DIR / "profile.json"
        if not shipped.exists():  # a model.start = PATH run: the profile it trained on, beside it (the ships line)
            shipped.parent.mkdir(parents=True, exist_ok=True)
            profile.save(shipped)
        res["ships"] = ships_line(run_dir, best_epoch)
    names = [s.name for s in split.test]
    table = format_table(res, names, cfg)  # the command prints it (results["text"])
    out = {
        "test_sequences": names,
        "checkpoint": "best.pt",
        "best_epoch": best_epoch,
        "selected_on": cfg.optim.select,
        "best_metric": best,
        "horizons_samples": list(cfg.data.eval_horizons),
        "eval_stride": cfg.data.eval_stride,
        "windows_from_s": cfg.data.startup_bias_s,
        "startup_bias_s": cfg.data.startup_bias_s,
        "units": {"rot_deg": "deg", "rot_rad": "rad", "trans_m": "m"},
        "table": res["rows"],
        "timing_offset_samples": tau,
        "vs_floor": res["vs_floor"],
        "open_loop_aoe_deg": res["aoe_deg"],
        "per_recording": res["per_recording"],
        "startup_bias": res["startup_bias"],
        "ships": None if profile is None else ("model" if best_epoch else "profile"),
        "text": table,
    }
    atomic_write_text(run_dir / "results.json", json.dumps(out, indent=2))
    return out


# ---------------------------------------------------------------------------------------------
# starting a run (the command line is imu_learn.cli.fit)


def resolve_config(config: Optional[Path], resume: Optional[Path],
                   overrides: Dict[str, Any]) -> Tuple[RunConfig, Optional[Dict[str, Any]]]:
    """The run config: defaults, ``config`` (a TOML) and ``overrides``; or, with ``resume`` (a run
    folder), the config of its ``last.pt`` with only :data:`RESUME_OVERRIDABLE` overrides. Returns
    (config, the resumed checkpoint or None); nothing is written."""
    if resume is None:
        return build_config(read_toml(config) if config else {}, overrides), None
    if config is not None:
        raise ConfigError("--config: not with --resume (the run's config is in its checkpoint)")
    bad = [k for k in overrides if k not in RESUME_OVERRIDABLE]
    if bad:
        raise ConfigError(f"--{bad[0]}: cannot be changed when resuming (only {', '.join(RESUME_OVERRIDABLE)})")
    if not resume.is_dir():
        raise FileNotFoundError(2, "No such run folder", str(resume))
    if not (resume / "last.pt").exists() and (resume / "config.toml").is_file():
        # stopped before its first save (while its profile was fitted): the run starts again from its config
        logger.info("%s: no last.pt (the run stopped before its first epoch): started again from its config.toml", resume)
        return build_config(read_toml(resume / "config.toml"), overrides), None
    state = load_checkpoint(resume / "last.pt")  # before anything is written
    cfg = build_config(state["config"], overrides)
    edited = config_edits(resume / "config.toml", cfg)
    if edited:
        raise ConfigError(f"{resume / 'config.toml'}: {', '.join(edited[:5])} differ from the run's last.pt (a resumed run "
                          "continues with its checkpoint's config): restore the file, or start a new run with the new "
                          "config (--config FILE --name NEW)")
    if cfg.optim.epochs * cfg.optim.steps_per_epoch < int(state["step"]):
        raise ConfigError(f"--optim.epochs: {cfg.optim.epochs} is fewer than the {state['epoch']} epochs already run")
    return cfg, state


def config_edits(path: Path, cfg: RunConfig) -> List[str]:
    """The keys whose values in a run's ``config.toml`` (``path``; absent: none) differ from ``cfg`` (the
    config its checkpoint holds), dotted; only the options a resume may change aside."""
    if not path.is_file():
        return []

    def flat(d: Any, prefix: str = "") -> Dict[str, Any]:
        if isinstance(d, list) and d and all(isinstance(x, dict) for x in d):  # data.roots: entry by entry, key by key
            return {f"{prefix[:-1]}#": len(d), **{k: v for i, x in enumerate(d) for k, v in flat(x, f"{prefix}{i}.").items()}}
        if not isinstance(d, dict):
            return {prefix[:-1]: d}
        return {k: v for key, val in d.items() for k, v in flat(val, f"{prefix}{key}.").items()}

    on_disk, held = flat(read_toml(path)), flat(toml_of_text(to_toml(cfg)))
    free = {k.split(".")[-1] for k in RESUME_OVERRIDABLE} | {"data_root"}
    return [k for k in sorted(set(on_disk) & set(held))  # keys of both: a newer version's defaults are no edit
            if on_disk[k] != held[k] and k.split(".")[-1] not in free and k not in SET_BY_THE_START]


def open_run(cfg: RunConfig, state: Optional[Dict[str, Any]], run_dir: Optional[Path]) -> Tuple[Path, Split]:
    """The split and the run folder: for a resumed run (``state`` given, ``run_dir`` its folder) the
    data are checked against its split.json; a new run's folder (``run_dir``, default
    ``<runs_dir>/<name or timestamp>``) is created with config.toml and split.json."""
    split = make_split(cfg.data)
    dist = Dist()
    if state is not None:
        assert run_dir is not None
        saved = json.loads((run_dir / "split.json").read_text()) if (run_dir / "split.json").exists() else None
        if saved is not None and split_signature(saved) != split_signature(json.loads(json.dumps(split.record))):
            raise ConfigError(f"{run_dir}/split.json: the data differ from what the run started with")
        if dist.main:
            write_csv(run_dir / "metrics.csv", list((state.get("extra") or {}).get("history", [])))
        logger.info("resuming %s at epoch %s, step %s", run_dir, state["epoch"], state["step"])
        return run_dir, split
    if run_dir is None:
        run_dir = Path(cfg.runs_dir) / (cfg.name or datetime.now().strftime("%Y%m%d-%H%M%S"))
    if (run_dir / "last.pt").exists():
        raise ConfigError(f"{run_dir}: already holds a run; continue it with --resume {run_dir} or pick another --name")
    if dist.main:
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / "config.toml", to_toml(cfg))
        write_split(split, run_dir / "split.json")
        logger.info("run folder %s", run_dir)
    return run_dir, split
