"""The device's bias prior for ``--bias auto`` (docs/refine.md, "The recording's own bias"), and the
held-out table of every ``--bias`` option against the profile alone.

``fit``: on the recordings a profile was fitted on (CONFIG's train and val splits, whole recordings,
the profile's floor applied to the whole IMU file), per recording: the bias *while moving* (one
constant gyro bias fitted on its ground truth, ``score.metrics.fit_startup_bias`` over each gap-free
segment, averaged by samples), the still estimate and the gravity-consistency estimate of
``--bias still`` / ``--bias gravity`` (no ground truth) and their errors against it. Their spreads
go into the profile's ``bias_prior`` (``moving_std_rad_s``: the recording-to-recording spread of the
moving bias after the floor; ``still_error_std_rad_s``: how far a still stretch's (resting) bias lies
from the moving one, per axis; ``gravity_error_std_rad_s``: gravity consistency's error along the
directions it observed, beyond its own uncertainty). ``rms_rad_s``: per estimator its RMS error
against the moving bias and the profile alone's, ``still`` and ``gravity`` (auto's gate), then, with
the prior those figures make (as the profile will run), ``moving``'s time average and ``auto`` as it
runs (still and gravity, its gate), both along the directions ``moving`` observed (moving's gate
compares it with the profile alone, the still estimate and auto; a profile fitted before ``auto`` was
measured has no ``auto`` figure, and its moving gate says so). ``imu_learn.infer.bias`` reads them.

``score``: on CONFIG's test recordings, the profile's floor and each ``--bias`` option exactly as
``imu-learn refine --profile P --bias METHOD`` runs it (``imu_learn.infer.bias.bias_step`` on the
whole IMU file, the prior from the profile), open-loop AOE (``imu_learn.score.peers.attitude_errors``,
RMS pooled over the recording's gap-free ground-truth segments, each integrated from its own start;
its mean beside, AirIMU's form) and RO_RMSE / RP_RMSE over 1 s windows
(``imu_learn.score.peers.segment_errors``); beside them oracles fitted on the recording's own ground
truth (:data:`ORACLES`: bounds, not estimators); per recording whether ``moving`` gave its own estimate
or auto's (its gate), and the training figures the gate judged.

    IMU_LEARN_DATA=<root> python experiments/bias_prior.py fit --config configs/euroc_paper.toml \\
        --profile models/profiles/euroc_adis16448/profile.json [--write]
    IMU_LEARN_DATA=<root> python experiments/bias_prior.py score --config configs/euroc_paper.toml \\
        --profile models/profiles/euroc_adis16448/profile.json [--json OUT.json] [--splits train,val]
    IMU_LEARN_DATA=<root> python experiments/bias_prior.py still-check --config configs/broad.toml \\
        --profile models/profiles/broad_handheld/profile.json [--splits train,val,test]

``still-check``: per recording (the profile's floor applied), how far gravity consistency's estimate
lies from the still stretches' (``imu_learn.infer.bias.disagreement``, in combined sigmas; ``-``
where either has none), and the largest.

Writes: with ``fit --write``, the profile's ``bias_prior`` field (the profile file itself); with
``score --json``, the table's figures. Prints a markdown table.
Data: the recordings of CONFIG under the data root (EuRoC, TUM-VI, Fetch, Blackbird, BROAD).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any, Dict, List, Tuple

import numpy as np

from imu_learn.calib.correction import _prior  # the prior refine gives --bias (the profile's)
from imu_learn.calib.profile import Profile
from imu_learn.core.quat import quat_conj, quat_log, quat_mul
from imu_learn.core.still import BiasPrior
from imu_learn.data.formats import read_imu_source
from imu_learn.data.splits import data_root_dir, find_all, make_split, recording_name
from imu_learn.data.types import Segment
from imu_learn.infer.bias import REGISTRY, Context, bias_step, disagreement, gravity_alone, measure_prior
from imu_learn.score.metrics import fit_startup_bias
from imu_learn.score.peers import attitude_errors, open_loop_attitude, segment_errors
from imu_learn.train.config import load_config
from imu_learn.util.atomic import atomic_write_text

REPO = Path(__file__).resolve().parents[1]
METHODS = ("none", "still", "gravity", "still+gravity", "auto", "moving")
# fitted on the recording's own ground truth: bounds, not estimators. oracle: one constant bias;
# oracle_20s: one per 20 s; auto+oracle_vertical: auto's estimate with its component along the body's
# mean gravity direction (what only a still stretch sees) replaced by the constant oracle's
ORACLES = ("oracle", "oracle_20s", "auto+oracle_vertical")


def recordings(config: str, data_root: Path, splits: Tuple[str, ...]) -> Tuple[Any, List[Tuple[str, Path, List[Segment]]]]:
    """(the data config, [(recording, its IMU file's path, its segments of ``splits``)])."""
    cfg = load_config(REPO / config if not Path(config).is_absolute() else Path(config),
                      ["--data.data_root", str(data_root)])
    split = make_split(cfg.data)
    found = find_all(cfg.data.roots, data_root_dir(cfg.data))
    segs = [s for name in splits for s in getattr(split, name)]
    names = list(dict.fromkeys(recording_name(s.name) for s in segs))
    return cfg.data, [(n, found[n][0], [s for s in segs if recording_name(s.name) == n]) for n in names]


def at(t_src: np.ndarray, t_seg: np.ndarray) -> np.ndarray:
    i = np.searchsorted(t_src, t_seg)
    if np.any(i >= len(t_src)) or np.any(t_src[np.minimum(i, len(t_src) - 1)] != t_seg):
        raise ValueError("a segment's stamps are not the IMU file's")
    return i


def with_gyro(s: Segment, g: np.ndarray) -> Segment:
    return Segment(s.name, s.t_ns, g, s.acc, s.p, s.v, s.q_wxyz)


def moving_bias(segs: List[Segment], gyro: List[np.ndarray], gravity: float) -> np.ndarray:
    """One constant gyro bias over a recording's segments, fitted on ground truth (by samples)."""
    bs = [fit_startup_bias(with_gyro(s, g), s.duration_s + 1.0, gravity=gravity)[0] for s, g in zip(segs, gyro)]
    return np.average(np.array(bs), axis=0, weights=np.array([len(s) for s in segs], dtype=float))


def floor_file(path: Path, profile: Profile, segs: List[Segment]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floor on the recording's whole IMU file (as refine runs), or, where the file cannot be read
    alone or its stamps are not the segments' (BROAD's trials, Blackbird's flights), on its
    ground-truth segments joined (a gap in the stamps between them)."""
    try:
        src = read_imu_source(path)
        t = np.asarray(src.t_ns, dtype=np.int64)
        for s in segs:
            at(t, s.t_ns)
        gyro, acc = src.gyro, src.acc
    except (TypeError, ValueError, OSError):
        t = np.concatenate([s.t_ns for s in segs]).astype(np.int64)
        gyro, acc = np.concatenate([s.gyro for s in segs]), np.concatenate([s.acc for s in segs])
    g, a = profile.apply(t, gyro, acc)
    return t, g, a


def gravity_of(profile: Profile, data: Any) -> float:
    g = profile.gravity_mps2
    return float(g) if g is not None and g == g and g > 0 else float(data.gravity)


# -- fit ------------------------------------------------------------------------------------------------

def fit(config: str, profile_path: Path, data_root: Path) -> Dict[str, Any]:
    """The profile's ``bias_prior`` (module doc) from CONFIG's train and val recordings."""
    profile = Profile.load(profile_path)
    data, recs = recordings(config, data_root, ("train", "val"))
    grav = gravity_of(profile, data)
    term = profile.noise.get("gyroscope_random_walk")  # rad/s^2/sqrt(Hz) = rad/s/sqrt(s)
    # how far the bias may move between `moving`'s knots: the data's upper bound where no fit observed the
    # random walk (the loosest the recordings allow; the class default would hold the bias nearly constant)
    rw = None if term is None else float(term.bound if term.bounded_only else term.value)
    rw = rw if rw is not None and math.isfinite(rw) else None
    std, how = profile.gyro_bias_prior_std()  # the spread refine's --bias prior is given (calib.correction)
    prior = BiasPrior.from_bias_std(std, f"the profile's bias spread ({how})",
                                    measured={"random_walk_rad_s_sqrt_s": rw})
    measured = []
    for name, path, segs in recs:
        t, g, a = floor_file(path, profile, segs)
        b = moving_bias(segs, [g[at(t, s.t_ns)] for s in segs], data.gravity)
        measured.append((name, t, g, a, b))
        print(f"{name}: moving bias {np.round(b * 1e3, 2)} mrad/s", file=sys.stderr, flush=True)
    out = measure_prior(measured, Context(grav, prior))
    for r in out["recordings"]:
        print(f"{r['recording']}: still - moving {r['still_minus_moving_rad_s']}, gravity's error "
              f"{r['gravity_error_along_observed_rad_s']}", file=sys.stderr)
    return {"method": "experiments/bias_prior.py fit (docs/refine.md, \"The recording's own bias\")",
            "config": config, **out, "random_walk_rad_s_sqrt_s": prior.random_walk}


# -- score ----------------------------------------------------------------------------------------------

def peer(row: Dict[str, Any], m: str, segs: List[Segment], gyro: List[np.ndarray], gravity: float) -> None:
    """``row``'s open-loop AOE [deg] (RMSE, Debias_IMU's form, and mean, AirIMU's) and RO_RMSE [deg] /
    RP_RMSE [m] over 1 s (AirIMU's) for method ``m``."""
    e, ro, rp = [], [], []
    for s, g in zip(segs, gyro):
        e.append(attitude_errors(with_gyro(s, g))["angle_rad"])
        w = segment_errors(s, g, s.acc, gravity=gravity)
        ro.append(w["rot_rad"])
        rp.append(w["trans_m"])
    r = {k: float(np.sqrt(np.mean(np.square(np.concatenate(v))))) for k, v in (("a", e), ("o", ro), ("p", rp))}
    row["aoe_deg"][m] = math.degrees(r["a"])
    row.setdefault("aoe_mean_deg", {})[m] = math.degrees(float(np.mean(np.concatenate(e))))  # AirIMU's form
    row.setdefault("ro_rmse_deg", {})[m] = math.degrees(r["o"])
    row.setdefault("rp_rmse_m", {})[m] = r["p"]


def oracle_gyro(segs: List[Segment], gyro: List[np.ndarray], piece_s: Any = None) -> Tuple[List[np.ndarray], np.ndarray]:
    """The gyro less the bias that minimises the open-loop attitude error on the recording's own ground
    truth (least squares on the rotation error every 10th sample, scipy): one constant per recording
    (``piece_s`` None), or one per ``piece_s`` of each segment (the last piece at least half as long);
    and the biases (pieces, 3) [rad/s]."""
    from scipy.optimize import least_squares

    ks = []
    for s in segs:
        tt = (s.t_ns - s.t_ns[0]) * 1e-9
        k = np.zeros(len(s), dtype=int) if piece_s is None else np.floor(tt / piece_s).astype(int)
        if k.max() > 0 and tt[-1] - k.max() * piece_s < piece_s / 2:
            k[k == k.max()] -= 1
        ks.append(k)
    offs = np.cumsum([0] + [int(k.max()) + 1 for k in ks]) if piece_s is not None else np.zeros(len(ks) + 1, int)

    def biased(x: np.ndarray) -> List[np.ndarray]:
        b = x.reshape(-1, 3)
        return [g - b[o + k] for g, o, k in zip(gyro, offs[:-1], ks)]

    def res(x: np.ndarray) -> np.ndarray:
        return np.concatenate([quat_log(quat_mul(quat_conj(s.q_wxyz[::10]), open_loop_attitude(s, g)[::10])).ravel()
                               for s, g in zip(segs, biased(x))])

    n = 3 * (int(offs[-1]) if piece_s is not None else 1)
    x = least_squares(res, np.zeros(n), diff_step=1e-3, x_scale=1e-3).x
    return biased(x), x.reshape(-1, 3)


# -- score (the table) ----------------------------------------------------------------------------------------------

def score(config: str, profile_path: Path, data_root: Path, splits: Tuple[str, ...] = ("test",)) -> List[Dict[str, Any]]:
    """Every ``--bias`` option's open-loop AOE on CONFIG's test recordings (module doc)."""
    profile = Profile.load(profile_path)
    data, recs = recordings(config, data_root, splits)
    grav = gravity_of(profile, data)
    prior = _prior(profile, str(profile_path))
    out = []
    for name, path, segs in recs:
        t, g, a = floor_file(path, profile, segs)
        idx = [at(t, s.t_ns) for s in segs]
        row: Dict[str, Any] = {"recording": name, "aoe_deg": {}, "decision": {}, "subtracted_rad_s": {}}
        for m in METHODS:
            gm = g
            if m != "none":
                sink: Dict[str, Any] = {}
                gm, _, _ = bias_step(m, grav, sink, prior=prior)(t, g, a)
                v = sink["bound"]
                row["decision"][m] = v.decision
                row["subtracted_rad_s"][m] = None if v.gyro_bias is None else [float(x) for x in v.gyro_bias]
                if m == "auto":
                    row["auto_used"] = sink[m].detail.get("used")
                if m == "moving":  # its gate: its own estimate, or auto's (imu_learn.infer.bias.moving_admitted)
                    row["moving_own"] = sink[m].method == "moving"
                    gate = sink[m].detail.get("gate") or sink[m].detail.get("moving_gate")
                    row["moving_gate_rms_rad_s"] = None if gate is None else gate["training_rms_rad_s"]
            peer(row, m, segs, [gm[i] for i in idx], data.gravity)
        fixed, b_or = oracle_gyro(segs, [g[i] for i in idx])
        peer(row, "oracle", segs, fixed, data.gravity)
        peer(row, "oracle_20s", segs, oracle_gyro(segs, [g[i] for i in idx], 20.0)[0], data.gravity)
        b_auto = np.asarray(row["subtracted_rad_s"]["auto"] or np.zeros(3))
        u = a.mean(0) / np.linalg.norm(a.mean(0))  # the body's mean gravity direction
        b_mix = b_auto + u * float(u @ (b_or[0] - b_auto))
        peer(row, "auto+oracle_vertical", segs, [g[i] - b_mix for i in idx], data.gravity)
        row["oracle_rad_s"] = b_or[0].tolist()
        row["moving_bias_rad_s"] = moving_bias(segs, [g[i] for i in idx], data.gravity).tolist()
        out.append(row)
        print(f"{name}: " + "  ".join(f"{m} {row['aoe_deg'][m]:.2f}" for m in METHODS + ORACLES) + f"  (auto used {row.get('auto_used')})",
              file=sys.stderr, flush=True)
    return out


def still_check(config: str, profile_path: Path, data_root: Path, splits: Tuple[str, ...]) -> List[Tuple[str, Any]]:
    """(recording, gravity consistency's distance from the still stretches in combined sigmas or None)."""
    profile = Profile.load(profile_path)
    data, recs = recordings(config, data_root, splits)
    ctx = Context(gravity_of(profile, data), _prior(profile, str(profile_path)))
    out = []
    for name, path, segs in recs:
        t, g, a = floor_file(path, profile, segs)
        out.append((name, disagreement(gravity_alone(ctx, t, g, a), REGISTRY["still"].run(ctx, t, g, a))))
    return out


def table(rows: List[Dict[str, Any]]) -> str:
    cols = METHODS + ORACLES
    head = ("| recording | " + " | ".join(f"{m}" for m in cols)
            + " | auto / none | moving / none | auto used | moving gives |")
    lines = [head, "|" + "---|" * (len(cols) + 5)]
    for r in rows:
        a = r["aoe_deg"]
        gives = "its own" if r.get("moving_own") else "auto's"
        lines.append(f"| {r['recording']} | " + " | ".join(f"{a[m]:.2f}" for m in cols)
                     + f" | {a['auto'] / a['none']:.3f} | {a['moving'] / a['none']:.3f} | "
                     f"{', '.join(r.get('auto_used') or []) or '–'} | {gives} |")
    gates = {json.dumps(r.get("moving_gate_rms_rad_s"), sort_keys=True) for r in rows}
    for g in gates:  # the same profile for every row: one line
        lines.append("")
        lines.append("moving's gate, training RMS [mrad/s]: " + ("none measured (it enters)" if g == "null" else
                     ", ".join(f"{k} {v * 1e3:.3f}" for k, v in json.loads(g).items())))
    lines.append("")
    lines.append("AOE mean [deg] (AirIMU's form) / RO_RMSE 1 s [deg] / RP_RMSE 1 s [m]:")
    for r in rows:
        lines.append(f"- {r['recording']}: " + ", ".join(
            f"{m} {r['aoe_mean_deg'][m]:.2f} / {r['ro_rmse_deg'][m]:.3f} / {r['rp_rmse_m'][m]:.4f}" for m in cols))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("fit", "score", "still-check"))
    ap.add_argument("--config", required=True)
    ap.add_argument("--profile", type=Path, required=True)
    ap.add_argument("--data-root", type=Path, default=Path(os.environ.get("IMU_LEARN_DATA", "data")))
    ap.add_argument("--write", action="store_true", help="fit: write bias_prior into the profile")
    ap.add_argument("--json", type=Path, help="score: write the figures here")
    ap.add_argument("--splits", default="test", help="score: CONFIG's splits to score, comma-separated (default "
                    "test; train,val: the recordings fit measures, a check of the gate's figures, not held out)")
    a = ap.parse_args()
    if a.what == "fit":
        bp = fit(a.config, a.profile, a.data_root)
        print(json.dumps({k: v for k, v in bp.items() if k != "recordings"}, indent=1))
        if a.write:
            d = json.loads(a.profile.read_text())
            d["bias_prior"] = bp
            atomic_write_text(a.profile, json.dumps(d, indent=2, allow_nan=False) + "\n")
            print(f"written {a.profile}'s bias_prior")
    elif a.what == "still-check":
        rows = still_check(a.config, a.profile, a.data_root, tuple(x for x in a.splits.split(",") if x))
        for name, z in rows:
            print(f"{name}: {'-' if z is None else f'{z:.2f}'}")
        zs = [z for _, z in rows if z is not None]
        print(f"{len(zs)} of {len(rows)} recordings with both; largest {max(zs):.2f}" if zs else "none with both")
    else:
        rows = score(a.config, a.profile, a.data_root, tuple(x for x in a.splits.split(",") if x))
        print(table(rows))
        if a.json:
            atomic_write_text(a.json, json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
