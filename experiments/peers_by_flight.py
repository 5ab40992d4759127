"""Open-loop AOE flight by flight and room by room, in the peers' own forms, beside what is left.

For each EuRoC test flight of configs/euroc_paper.toml (MH_04, V1_03, V2_02, V1_01; V1_01 against its
corrected 20 Hz ASL state, as the config says) and TUM-VI rooms 2 and 4 of configs/tumvi.toml:

* the AOE of score.peers: the gyro integrated open loop from the ground-truth attitude at the first
  sample, error angle e_j at every sample; **RMSE** (Brossard's and Debias_IMU's AOE) and **mean**
  (AirIMU's ``AOE``). EuRoC: per gap-free segment of the config (max_gap_s), pooled; TUM-VI:
  Brossard's protocol (the whole room integrated through motion-capture gaps of up to 3 s, counted
  where motion capture measured: score.peers.masked_aoe, as experiments/bridged_aoe.py);
* inputs: ``raw``; ``floor``: the shipped device profile (models/profiles/<device>: ``imu-learn calibrate
  --config CONFIG --select``, its training split only, the terms chosen on its recordings held out in
  turn; ``--refit`` fits it again under OUT/profiles); ``floor +
  still``: that floor and the recording's own gyro bias from its still stretches, with no ground
  truth (what ``imu-learn refine --profile P --bias still`` writes: the same library steps, run on
  the whole IMU file); ``floor + still + offset``: the still estimate plus the mean, over the
  TRAINING recordings, of their in-motion (oracle) bias minus their still estimate (the device's rest-to-
  flight shift; no ground truth of the test recording); ``floor + gravity``: the floor and the recording's
  bias from gravity consistency (``refine --profile P --bias gravity``: rates perpendicular to gravity
  only); ``floor + still∥g + gravity⊥g``: the two combined (``refine --profile P --bias still+gravity``): the
  still estimate along the mean gravity direction in the body frame (the axis gravity consistency
  cannot see), the gravity estimate across it; ``model``: the shipped model as it is (models/euroc_adis16448_openloop.pt,
  models/tumvi_bmi160.pt; on the whole IMU file, as refine runs it); ``oracle bias``: the floor and
  the recording's whole constant gyro bias fitted on its ground truth (score.metrics.fit_startup_bias
  over each gap-free segment: an upper bound for any constant-bias estimate); ``oracle 10 s``: the
  floor and a bias fitted on ground truth per 10 s block (what a bias that moves leaves); ``oracle
  affine``: the traditional calibration (scale, misalignment, bias) fitted on the recording itself;
* why (every recording): the floor's, the still and the gravity estimate's distance to the oracle bias, and the ground truth's
  orientation noise from the residual of its relative rotation against the oracle-debiased gyro over
  short windows (1 sample to 0.5 s): its mean square grows linearly with the window from an
  intercept that is twice the ground truth's per-sample noise (and the AOE compares against noisy
  ground truth at both ends).

    IMU_LEARN_DATA=<root> python experiments/peers_by_flight.py [--out reports/peers_by_flight] [--refit]

Prints one markdown table per dataset and writes OUT/results.json. Writes: docs/experiments/learning.md,
"Flight by flight against the peers". Data: the EuRoC and TUM-VI recordings of the two configs under
the data root. About 6 min on one shared core (EuRoC 3, TUM-VI 3); ``--refit`` adds about 30 s (EuRoC)
and 80 s (TUM-VI).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from imu_learn.calib.profile import Profile
from imu_learn.core.bias_gravity import gravity_bias
from imu_learn.core.integration import preintegrate
from imu_learn.core.quat import quat_conj, quat_mul, rotation_angle
from imu_learn.core.still import BIAS_SETTINGS, still_bias
from imu_learn.data.formats import read_imu_source
from imu_learn.data.loading import AlignOptions, load_sequence
from imu_learn.data.splits import data_root_dir, find_all, make_split, recording_name
from imu_learn.data.types import Segment
from imu_learn.infer.rewrite import still_along_gravity
from imu_learn.score.metrics import fit_startup_bias
from imu_learn.score.peers import attitude_errors, covered, masked_aoe
from imu_learn.train.config import load_config
from imu_learn.util.atomic import atomic_write_text

REPO = Path(__file__).resolve().parents[1]
BLOCK_S = 10.0  # the moving-bias oracle's blocks [s]
NOISE_WINDOWS_S = (0.0, 0.025, 0.05, 0.1, 0.25, 0.5)  # 0: one sample
NOISE_FIT_MAX_S = 0.1  # the intercept is fitted over windows up to this [s]

# The peers' published figures [deg]: AirIMU's released weights (third-party rerun,
# KwanWaiPang/AirIMU_comment; AOE as the mean error angle); Debias_IMU (RSS 2025, evo_evaluation/results.txt;
# AOE as RMSE, initial bias from ground truth; TUM-VI on the raw, uncalibrated IMU); Brossard et al. 2020
# (TUM-VI rooms 2, 4; AOE as RMSE).
PEERS = {
    "euroc": {"AirIMU (mean)": {"MH_04_difficult": 0.98, "V1_03_difficult": 1.20, "V2_02_medium": 4.96,
                                "V1_01_easy": 3.16},
              "Debias_IMU (RMSE)": {"MH_04_difficult": 1.06, "V1_03_difficult": 2.26, "V2_02_medium": 4.27,
                                    "V1_01_easy": 1.27}},
    "tumvi": {"Debias_IMU (RMSE)": {"dataset-room2_512_16": 1.69, "dataset-room4_512_16": 1.71},
              "Brossard (RMSE)": {"dataset-room2_512_16": 1.31, "dataset-room4_512_16": 1.48}},
}
DATASETS = {
    "euroc": {"config": "configs/euroc_paper.toml", "model": "models/euroc_adis16448_openloop.pt",
              "profile": "models/profiles/euroc_adis16448/profile.json"},
    "tumvi": {"config": "configs/tumvi.toml", "model": "models/tumvi_bmi160.pt",
              "profile": "models/profiles/tumvi_bmi160/profile.json"},
}
INPUTS = ("raw", "floor", "floor + still", "floor + still + offset", "floor + gravity", "floor + still∥g + gravity⊥g",
          "model", "oracle bias", "oracle 10 s", "oracle affine")
OURS = ("raw", "floor", "floor + still", "floor + still + offset", "floor + gravity", "floor + still∥g + gravity⊥g",
        "model")  # no ground truth of the recording


# -- the floor ---------------------------------------------------------------------------------------

def ensure_profile(spec: dict, out: Path, data_root: Path, refit: bool) -> Path:
    """The shipped profile (``imu-learn calibrate --config CONFIG --select``, its training split only, and
    its bias prior); with ``refit``, that command run again into ``out`` (no bias prior)."""
    if not refit:
        return REPO / spec["profile"]
    path = out / "profile.json"
    exe = Path(sys.executable).with_name("imu-learn")
    cmd = [str(exe), "calibrate", "--config", str(REPO / spec["config"]), "--data-root", str(data_root),
           "--out", str(out), "--select", "--no-plot"]
    print(f"fitting the floor: {' '.join(cmd)}", file=sys.stderr)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return path


# -- the inputs on the whole IMU file (as refine writes them) ---------------------------------------------

def model_gyro(checkpoint: Path, t_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """The shipped model's gyro as ``imu-learn refine --checkpoint`` gives it (a profile it carries
    but does not hold applied first)."""
    from imu_learn.infer.checkpoint import imu_record, load_checkpoint, model_from_checkpoint
    from imu_learn.infer.refiner import refine_arrays

    state = load_checkpoint(checkpoint)
    record = imu_record(state)
    if record["profile"] and not record["profile_in_model"]:
        gyro, acc = Profile.from_dict(record["profile"], str(checkpoint)).apply(t_ns, gyro, acc)
    g, _ = refine_arrays(model_from_checkpoint(state), gyro, acc)
    return g


def floor_and_still(path: Path, profile: Profile) -> Tuple[Any, np.ndarray, np.ndarray, Any]:
    """The recording's IMU file, its floor (gyro, acc) and the still-stretch bias estimate on the floor
    (refine --profile --bias still: the accelerometer norm checked against the profile's gravity)."""
    src = read_imu_source(path)
    t = np.asarray(src.t_ns, dtype=np.int64)
    fg, fa = profile.apply(t, src.gyro, src.acc)
    settings = replace(BIAS_SETTINGS, gravity=float(profile.gravity_mps2 or BIAS_SETTINGS.gravity))
    return src, fg, fa, still_bias(t, fg, fa, settings)


def whole_file_inputs(path: Path, profile: Profile, checkpoint: Path, offset: np.ndarray) -> Dict[str, Any]:
    """raw, floor, floor + still bias (and the training recordings' still-to-flight offset) and the
    model's gyro over the recording's whole IMU file."""
    src, fg, fa, est = floor_and_still(path, profile)
    t = np.asarray(src.t_ns, dtype=np.int64)
    sb = est.gyro_bias if est.gyro_bias is not None else np.zeros(3)
    grav = gravity_bias(t, fg, fa)  # refine --profile P --bias gravity
    gb = grav.gyro_bias if grav.gyro_bias is not None else np.zeros(3)
    both = still_along_gravity(est.gyro_bias, grav)  # refine --profile P --bias still+gravity
    both = np.zeros(3) if both is None else both
    return {"t_ns": t, "gyro": {"raw": np.asarray(src.gyro, dtype=np.float64), "floor": fg, "floor + still": fg - sb,
                                "floor + still + offset": fg - sb - offset, "floor + gravity": fg - gb,
                                "floor + still∥g + gravity⊥g": fg - both,
                                "model": model_gyro(checkpoint, t, src.gyro, src.acc)},
            "floor_acc": fa, "still": est, "gravity": grav, "combined": both}


def still_offset(train: Dict[str, Tuple[Path, List[Segment]]], profile: Profile, gravity: float) -> Dict[str, Any]:
    """The device's offset between the bias in motion and at rest, from the TRAINING recordings only:
    per recording, the oracle bias of its training segments (floor applied) minus the still estimate of
    its whole IMU file; their mean is what ``floor + still + offset`` adds to the still estimate."""
    per = {}
    for name, (path, segs) in train.items():
        src, fg, _, est = floor_and_still(path, profile)
        if est.gyro_bias is None:
            continue
        t = np.asarray(src.t_ns, dtype=np.int64)
        b = oracle_bias(segs, [fg[at(t, s.t_ns)] for s in segs], gravity)
        per[name] = [float(v) for v in b - est.gyro_bias]
    if not per:  # no training recording rests: nothing to learn the offset from
        return {"per_recording_rad_s": {}, "mean_rad_s": [0.0, 0.0, 0.0], "std_rad_s": None}
    d = np.array(list(per.values()))
    return {"per_recording_rad_s": per, "mean_rad_s": [float(v) for v in d.mean(0)],
            "std_rad_s": [float(v) for v in d.std(0, ddof=1)] if len(d) > 1 else None}


def at(t_src: np.ndarray, t_seg: np.ndarray) -> np.ndarray:
    """Indices of a segment's stamps in the IMU file's."""
    i = np.searchsorted(t_src, t_seg)
    if np.any(i >= len(t_src)) or np.any(t_src[np.minimum(i, len(t_src) - 1)] != t_seg):
        raise ValueError("a segment's stamps are not the IMU file's")
    return i


def sub(seg: Segment, a: int, b: int, gyro: Optional[np.ndarray] = None) -> Segment:
    g = seg.gyro if gyro is None else gyro
    return Segment(seg.name, seg.t_ns[a:b], g[a:b], seg.acc[a:b], seg.p[a:b], seg.v[a:b], seg.q_wxyz[a:b])


# -- the oracles (ground truth) -----------------------------------------------------------------------------

def oracle_bias(segs: List[Segment], floor_gyro: List[np.ndarray], gravity: float) -> np.ndarray:
    """One constant gyro bias over all of a recording's gap-free segments (each fitted on its own ground
    truth by fit_startup_bias over its whole span, averaged by samples)."""
    bs, ws = [], []
    for s, g in zip(segs, floor_gyro):
        s2 = sub(s, 0, len(s), g)
        bs.append(fit_startup_bias(s2, s2.duration_s + 1.0, gravity=gravity)[0])
        ws.append(len(s))
    return np.average(np.array(bs), axis=0, weights=np.array(ws, dtype=float))


def block_bias(t_src: np.ndarray, segs: List[Segment], floor_gyro: List[np.ndarray], constant: np.ndarray,
               gravity: float) -> np.ndarray:
    """(N,) x 3 bias over the IMU file: per BLOCK_S block, fitted on the longest ground-truth piece inside
    it (at least 2 s), else the constant oracle."""
    out = np.broadcast_to(constant, (len(t_src), 3)).copy()
    edges = np.arange(t_src[0], t_src[-1] + 1, int(BLOCK_S * 1e9))
    for lo in edges:
        hi = lo + int(BLOCK_S * 1e9)
        best = None
        for s, g in zip(segs, floor_gyro):
            a, b = np.searchsorted(s.t_ns, lo), np.searchsorted(s.t_ns, hi)
            if b - a > 1 and (best is None or b - a > best[2] - best[1]):
                best = (sub(s, 0, len(s), g), a, b)
        if best is None or (best[0].t_ns[best[2] - 1] - best[0].t_ns[best[1]]) < 2e9:
            continue
        piece = sub(best[0], best[1], best[2])
        bg = fit_startup_bias(piece, piece.duration_s + 1.0, gravity=gravity)[0]
        out[(t_src >= lo) & (t_src < hi)] = bg
    return out


def gt_noise(segs: List[Segment], gyro: List[np.ndarray]) -> Dict[str, Any]:
    """The residual of the ground truth's relative rotation against the (oracle-debiased) gyro over
    short windows: RMS angle [deg] per window, and the intercept of its mean square (linear in the
    window up to NOISE_FIT_MAX_S) halved: the ground truth's per-sample orientation noise (RMS angle)."""
    rows = []
    for w_s in NOISE_WINDOWS_S:
        sq = []
        for s, g in zip(segs, gyro):
            rate = (len(s) - 1) / max(s.duration_s, 1e-9)
            n = max(1, int(round(w_s * rate)))
            if len(s) <= n:
                continue
            inc = preintegrate(s.t_ns, g, np.zeros_like(g))  # cumulative: dq[j] = R_0^T R_j from the gyro
            dq = inc.dq_wxyz
            rel_imu = quat_mul(quat_conj(dq[:-n]), dq[n:])
            rel_gt = quat_mul(quat_conj(s.q_wxyz[:-n]), s.q_wxyz[n:])
            sq.append(rotation_angle(rel_gt, rel_imu) ** 2)
        x = np.concatenate(sq)
        rows.append({"window_s": w_s, "samples": n, "rms_deg": math.degrees(float(np.sqrt(np.mean(x)))),
                     "ms_rad2": float(np.mean(x))})
    fit = [(r["window_s"] if r["window_s"] > 0 else 1 / 200.0, r["ms_rad2"]) for r in rows
           if r["window_s"] <= NOISE_FIT_MAX_S]
    slope, icpt = np.polyfit([f[0] for f in fit], [f[1] for f in fit], 1)
    sigma = math.degrees(math.sqrt(max(icpt, 0.0) / 2.0))
    return {"windows": rows, "intercept_rad2": float(icpt), "slope_rad2_per_s": float(slope),
            "gt_noise_rms_deg": sigma}


# -- scoring -------------------------------------------------------------------------------------------------

def aoe_segments(segs: List[Segment], gyro: List[np.ndarray]) -> Dict[str, float]:
    """AOE RMSE and mean, yaw AOE [deg] pooled over gap-free segments (each from its own ground-truth start)."""
    errs = [attitude_errors(s, g) for s, g in zip(segs, gyro)]
    e = np.concatenate([x["angle_rad"] for x in errs])
    y = np.concatenate([x["yaw_rad"] for x in errs])
    return {"aoe_deg": math.degrees(float(np.sqrt(np.mean(e * e)))), "aoe_mean_deg": math.degrees(float(np.mean(e))),
            "yaw_aoe_deg": math.degrees(float(np.sqrt(np.mean(y * y))))}


def oracle_affine(t: np.ndarray, raw_gyro: np.ndarray, raw_acc: np.ndarray, segs: List[Segment],
                  gravity: float, window: int) -> np.ndarray:
    """The traditional calibration (scale, misalignment, g-sensitivity, bias, low-pass) fitted on the
    recording's OWN ground truth, applied to its whole IMU file: an upper bound for any constant linear
    calibration (as experiments/headroom.py's oracle calibration)."""
    from imu_learn.baselines.base import FitSettings
    from imu_learn.baselines.traditional import Traditional

    method = Traditional()
    method.fit(list(segs), list(segs), FitSettings(window=window, gravity=gravity))
    whole = Segment("whole", t, raw_gyro, raw_acc, np.zeros((len(t), 3)), np.zeros((len(t), 3)),
                    np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1)))
    return method.refine(whole)[0]


@dataclass
class Setting:
    """What every recording of a dataset is scored with."""

    profile: Profile
    checkpoint: Path
    gravity: float
    window: int
    offset: np.ndarray


def recording(name: str, path: Path, segs: List[Segment], bridged: Optional[Tuple[Segment, np.ndarray]],
              st: Setting) -> Dict[str, Any]:
    """Every input's AOE on one recording, and the why figures."""
    profile, gravity = st.profile, st.gravity
    w = whole_file_inputs(path, profile, st.checkpoint, st.offset)
    t = w["t_ns"]
    idx = [at(t, s.t_ns) for s in segs]
    floor_seg = [w["gyro"]["floor"][i] for i in idx]
    b_or = oracle_bias(segs, floor_seg, gravity)
    b_blk = block_bias(t, segs, floor_seg, b_or, gravity)
    w["gyro"]["oracle bias"] = w["gyro"]["floor"] - b_or
    w["gyro"]["oracle 10 s"] = w["gyro"]["floor"] - b_blk
    raw = w["gyro"]["raw"]
    w["gyro"]["oracle affine"] = oracle_affine(t, raw, read_imu_source(path).acc, segs, gravity, st.window)
    res: Dict[str, Any] = {"recording": name, "segments": len(segs), "samples": int(sum(len(s) for s in segs)),
                           "duration_s": float(sum(s.duration_s for s in segs)), "aoe": {}}
    for key in INPUTS:
        g = w["gyro"][key]
        if bridged is None:
            res["aoe"][key] = aoe_segments(segs, [g[i] for i in idx])
        else:
            seg, mask = bridged
            r = masked_aoe(seg, g[at(t, seg.t_ns)], mask)
            res["aoe"][key] = {k: r[k] for k in ("aoe_deg", "aoe_mean_deg", "yaw_aoe_deg")}
            res["bridged"] = {"samples": r["samples"], "bridged": r["bridged"]}
    est = w["still"]
    res["still"] = {k: v for k, v in est.to_dict().items() if k in ("gyro_bias_rad_s", "still_s", "samples")}
    res["still"]["stretches"] = len(est.stretches)
    res["still"]["first_t0_s"] = est.stretches[0]["t0_s"] if est.stretches else None
    res["oracle_bias_rad_s"] = [float(v) for v in b_or]
    res["still_minus_oracle_rad_s"] = None if est.gyro_bias is None else [float(v) for v in est.gyro_bias - b_or]
    res["still_minus_oracle_norm_rad_s"] = None if est.gyro_bias is None else float(np.linalg.norm(est.gyro_bias - b_or))
    g = w["gravity"].gyro_bias
    res["gravity_bias_rad_s"] = None if g is None else [float(v) for v in g]
    res["combined_bias_rad_s"] = [float(v) for v in w["combined"]]
    res["gravity_minus_oracle_norm_rad_s"] = None if g is None else float(np.linalg.norm(g - b_or))
    res["oracle_blocks_spread_rad_s"] = [float(v) for v in np.std(b_blk, axis=0)]
    res["gt_noise"] = gt_noise(segs, [w["gyro"]["oracle bias"][i] for i in idx])
    return res


def train_groups(split: Any, found: Dict[str, Any]) -> Dict[str, Tuple[Path, List[Segment]]]:
    names = dict.fromkeys(recording_name(s.name) for s in split.train)
    return {n: (found[n][0], [s for s in split.train if recording_name(s.name) == n]) for n in names}


def euroc_recordings(data_root: Path) -> Tuple[Any, Dict[str, Any], List[Tuple[str, Path, List[Segment], None]]]:
    cfg = load_config(REPO / DATASETS["euroc"]["config"], ["--data.data_root", str(data_root)])
    split = make_split(cfg.data)
    found = find_all(cfg.data.roots, data_root_dir(cfg.data))
    names = list(dict.fromkeys(recording_name(s.name) for s in split.test))
    return cfg.data, train_groups(split, found), [(n, found[n][0], [s for s in split.test
                                                                   if recording_name(s.name) == n], None) for n in names]


def tumvi_recordings(data_root: Path) -> Tuple[Any, Dict[str, Any], List[Tuple[str, Path, List[Segment],
                                                                               Tuple[Segment, np.ndarray]]]]:
    cfg = load_config(REPO / DATASETS["tumvi"]["config"], ["--data.data_root", str(data_root)])
    split = make_split(cfg.data)
    found = find_all(cfg.data.roots, data_root_dir(cfg.data))
    out = []
    for n in dict.fromkeys(recording_name(s.name) for s in split.test):
        path = found[n][0]
        seg = max(load_sequence(path, options=AlignOptions(max_gap_s=3.0)), key=len)
        gt = np.loadtxt(path / "mav0" / "mocap0" / "data.csv", delimiter=",", comments="#", usecols=0, dtype=np.float64)
        out.append((n, path, [s for s in split.test if recording_name(s.name) == n],
                    (seg, covered(seg.t_ns, gt.astype(np.int64), 0.05))))
    return cfg.data, train_groups(split, found), out


# -- the table -------------------------------------------------------------------------------------------------

def _fig(x: float, bold: bool) -> str:
    return f"**{x:.2f}**" if bold else f"{x:.2f}"


def _vec(est: Optional[List[float]], ref: List[float]) -> str:
    """est − ref per axis and its norm [rad/s] ("–": no estimate)."""
    if est is None:
        return "–"
    d = np.asarray(est) - np.asarray(ref)
    return "(" + ", ".join(f"{v:+.4f}" for v in d) + f") ({float(np.linalg.norm(d)):.4f})"


def table(ds: str, rows: List[Dict[str, Any]]) -> str:
    """Rows = recordings; the peers' columns, then ours as mean / RMSE, bold where one of ours (not the
    oracles) beats a peer in that peer's own form."""
    peers = PEERS[ds]
    head = ["recording", *peers, *[f"{k} mean / RMSE" for k in INPUTS]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        n = r["recording"]
        cells = [n, *[f"{peers[p][n]:.2f}" if n in peers[p] else "–" for p in peers]]
        for k in INPUTS:
            m, s = r["aoe"][k]["aoe_mean_deg"], r["aoe"][k]["aoe_deg"]
            oracle = k not in OURS
            beat_m = not oracle and any(p.endswith("(mean)") and m < peers[p].get(n, -1) for p in peers)
            beat_s = not oracle and any(p.endswith("(RMSE)") and s < peers[p].get(n, -1) for p in peers)
            cells.append(f"{_fig(m, beat_m)} / {_fig(s, beat_s)}")
        lines.append("| " + " | ".join(cells) + " |")
    why = ["", "| recording | floor − oracle bias [rad/s] (norm) | still: stretches, s, first at [s] | still − oracle bias [rad/s] (norm) | gravity − oracle bias [rad/s] (norm) | still∥g + gravity⊥g − oracle [rad/s] (norm) | "
               "10 s blocks' bias spread [rad/s] | ground-truth noise [deg] | residual RMS 1 sample / 0.05 / 0.5 s [deg] |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        st, gn = r["still"], r["gt_noise"]
        dd = _vec(st["gyro_bias_rad_s"], r["oracle_bias_rad_s"])
        win = {x["window_s"]: x["rms_deg"] for x in gn["windows"]}
        fd = _vec([0.0, 0.0, 0.0], r["oracle_bias_rad_s"])
        why.append(f"| {r['recording']} | {fd} | {st['stretches']}, {st['still_s']:.1f}, {st['first_t0_s']} | {dd} | "
                   + _vec(r["gravity_bias_rad_s"], r["oracle_bias_rad_s"]) + " | "
                   + _vec(r["combined_bias_rad_s"], r["oracle_bias_rad_s"])
                   + " | "
                   + ", ".join(f"{v:.4f}" for v in r["oracle_blocks_spread_rad_s"])
                   + f" | {gn['gt_noise_rms_deg']:.3f} | {win[0.0]:.3f} / {win[0.05]:.3f} / {win[0.5]:.3f} |")
    return "\n".join(lines + why)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path(os.environ.get("IMU_LEARN_DATA", REPO.parent / "shared" / "data")))
    ap.add_argument("--out", type=Path, default=REPO / "reports" / "peers_by_flight")
    ap.add_argument("--datasets", default="euroc,tumvi", help="comma-separated: euroc, tumvi")
    ap.add_argument("--refit", action="store_true", help="refit the profiles (calibrate --select) instead of using the shipped ones")
    a = ap.parse_args()
    t0 = time.time()
    result: Dict[str, Any] = {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "data_root": str(a.data_root),
                              "peers": PEERS, "datasets": {}}
    for ds in [d for d in a.datasets.split(",") if d]:
        spec = DATASETS[ds]
        prof_path = ensure_profile(spec, a.out / "profiles" / ds, a.data_root, a.refit)
        profile = Profile.load(prof_path)
        data, train, recs = euroc_recordings(a.data_root) if ds == "euroc" else tumvi_recordings(a.data_root)
        off = still_offset(train, profile, data.gravity)
        st = Setting(profile, REPO / spec["model"], data.gravity, data.window, np.array(off["mean_rad_s"]))
        rows = [recording(n, p, segs, br, st) for n, p, segs, br in recs]
        result["datasets"][ds] = {"config": spec["config"], "profile": str(prof_path), "model": spec["model"],
                                  "time_offset_s": profile.time_offset_s, "still_offset": off, "rows": rows}
        print(f"\n### {ds}\n\n{table(ds, rows)}\n")
    result["wall_s"] = round(time.time() - t0, 1)
    a.out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(a.out / "results.json", json.dumps(result, indent=1))
    print(f"written {a.out / 'results.json'} ({result['wall_s']} s)")


if __name__ == "__main__":
    main()
