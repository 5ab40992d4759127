"""Each recording's own gyro bias without ground truth, measured against the bias fitted on its ground
truth (docs/experiments/learning.md, "Each recording's own bias").

For every device (Fetch, TUM-VI, EuRoC, BROAD; imu_learn.train.bias_data) and every recording: the
floor's input (the raw gyro minus the training recordings' mean ground-truth bias), then each estimate
of what is left: none (the training mean), still stretches (imu_learn.core.still), gravity consistency
(imu_learn.core.bias_gravity) and, with --model DEVICE=PT, the learned estimator (imu_learn.nn.bias_net).
Printed and written (JSON): the bias error |estimate - ground-truth fit| [rad/s] and the open-loop AOE
(imu_learn.score.peers: RMS and mean over the segment) of the raw gyro minus each estimate, and of the
ground-truth fit (the oracle).

Writes: the table of "Each recording's own bias" to stdout and every figure to --out (JSON).
Data: the training and test recordings of Fetch, TUM-VI, EuRoC and BROAD under the data root.

    IMU_LEARN_DATA=<root> python experiments/bias_estimates.py --out reports/bias/estimates.json \
        [--devices fetch,tumvi,euroc,broad] [--splits test,train] [--model euroc=reports/bias/euroc.pt]
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Callable, Dict, Optional

import numpy as np

from imu_learn.core.bias_gravity import gravity_bias
from imu_learn.core.still import BIAS_SETTINGS, still_bias
from imu_learn.score.peers import PeerErrors, add_segment, segment_errors, summarise
from imu_learn.train.bias_data import DEVICES, Recording, load_device, training_mean

Estimator = Callable[[Recording, np.ndarray], Optional[np.ndarray]]


def still(r: Recording, g0: np.ndarray) -> Optional[np.ndarray]:
    from dataclasses import replace
    return still_bias(r.seg.t_ns, g0, r.seg.acc, replace(BIAS_SETTINGS, gravity=r.gravity)).gyro_bias


def gravity(r: Recording, g0: np.ndarray) -> Optional[np.ndarray]:
    return gravity_bias(r.seg.t_ns, g0, r.seg.acc).gyro_bias


def learned(path: str) -> Estimator:
    from imu_learn.nn.bias_net import load_bias_net, predict_bias

    net = load_bias_net(path)
    return lambda r, g0: predict_bias(net, r.seg.t_ns, g0, r.seg.acc)


def aoe(r: Recording, bias: np.ndarray) -> Dict[str, float]:
    e = PeerErrors()
    add_segment(e, segment_errors(r.seg, r.seg.gyro - bias[None], r.seg.acc, r.gravity))
    s = summarise(e)
    return {"aoe_deg": round(s["aoe_deg"], 3), "aoe_mean_deg": round(s["aoe_mean_deg"], 3)}


def tilts(r: Recording) -> Dict[str, float]:
    """What the accelerometer says about gravity, against ground truth (median over windows, deg):
    the 1 s mean accelerometer against gravity's direction in the body frame (tilt read from the
    body-frame samples), and the 10 s mean specific force in the world frame against the vertical
    (what gravity consistency relies on)."""
    from imu_learn.core.quat import quat_conj, quat_rotate
    from imu_learn.data.types import sample_rate_hz

    n = int(round(sample_rate_hz(r.seg.t_ns)))
    up_body = quat_rotate(quat_conj(r.seg.q_wxyz), np.tile([0.0, 0.0, 1.0], (len(r.seg.t_ns), 1)))
    f_world = quat_rotate(r.seg.q_wxyz, r.seg.acc)

    def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        c = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        return np.degrees(np.arccos(np.clip(c, -1, 1)))

    def means(x: np.ndarray, k: int) -> np.ndarray:
        m = len(x) // k
        return x[: m * k].reshape(m, k, 3).mean(1)

    out = {"tilt_1s_body_deg": float(np.median(angle(means(r.seg.acc, n), means(up_body, n))))}
    w = means(f_world, 10 * n)
    out["tilt_10s_world_deg"] = float(np.median(angle(w, np.tile([0.0, 0.0, 1.0], (len(w), 1))))) if len(w) else None
    return out


def measure(r: Recording, mean: np.ndarray, estimators: Dict[str, Estimator]) -> Dict[str, object]:
    g0 = r.seg.gyro - mean[None]
    row: Dict[str, object] = {"recording": r.seg.name, "duration_s": round(r.seg.duration_s, 1),
                              "gt_bias_rad_s": [round(float(x), 6) for x in r.gyro_bias],
                              "oracle": aoe(r, r.gyro_bias), **tilts(r)}
    for name, est in estimators.items():
        inc = est(r, g0)
        bias = mean + (np.zeros(3) if inc is None else inc)
        err = bias - r.gyro_bias
        row[name] = {"found": inc is not None, "bias_rad_s": [round(float(x), 6) for x in bias],
                     "error_rad_s": round(float(np.linalg.norm(err)), 6),
                     "error_axes_rad_s": [round(float(x), 6) for x in err], **aoe(r, bias)}
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--devices", default=",".join(DEVICES))
    ap.add_argument("--splits", default="test")
    ap.add_argument("--model", action="append", default=[], metavar="DEVICE=PT")
    args = ap.parse_args()
    models = dict(m.split("=", 1) for m in args.model)
    root = os.environ.get("IMU_LEARN_DATA", "data")
    result = {}
    for dev in args.devices.split(","):
        t0 = time.time()
        recs = load_device(dev, root)
        mean = training_mean(recs["train"])
        ests: Dict[str, Estimator] = {"mean": lambda r, g0: None, "still": still, "gravity": gravity}
        if dev in models:
            ests["learned"] = learned(models[dev])
        result[dev] = {"training_mean_rad_s": [float(x) for x in mean]}
        for split in args.splits.split(","):
            rows = [measure(r, mean, ests) for r in recs[split]]
            result[dev][split] = rows
            for row in rows:
                cells = " | ".join(f"{k} {row[k]['error_rad_s']:.4f} {row[k]['aoe_deg']:.2f}/{row[k]['aoe_mean_deg']:.2f}°"
                                   for k in ests)
                print(f"{dev} {split} {row['recording']} ({row['duration_s']} s): {cells} | oracle "
                      f"{row['oracle']['aoe_deg']:.2f}/{row['oracle']['aoe_mean_deg']:.2f}°", flush=True)
        print(f"{dev}: {time.time() - t0:.0f} s", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
