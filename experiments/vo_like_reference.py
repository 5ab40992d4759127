"""calibrate on Blackbird from a VO-like reference (its motion capture as a camera's 20 Hz poses in an
unknown frame and world: experiments/vo_like_breaks.py's files) against its motion capture, both on the
`train` recording, scored on the unseen `val` by ``imu-learn evaluate`` beside the simpler floors it fits
on `train` against the motion capture (timing, traditional, traditional+timing); and the VO profile with the
motion-capture gyro's misalignment rotation put back (its M_g and M_a premultiplied by the rotation of
the motion-capture M_g's antisymmetric part), which the estimated frame took (profile.json's ``observed``).

    IMU_LEARN_DATA=DIR python experiments/vo_like_reference.py [--out reports/vo_like_reference]

Writes: OUT/vo/ (the VO-like files), OUT/mocap/, OUT/vo_profile/, OUT/vo_profile_rotated/ (profiles),
OUT/evaluate/ (evaluate's report); the evaluate table and the rotations on stdout (docs/experiments/
references.md, "Another device: Blackbird from a VO-like reference"). Data: ``blackbird/clover_yawForward_maxSpeed5p0``
(`train` and `val`) under the data root; configs/eval_blackbird.toml.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from vo_like_breaks import R_BC, REPO, make_vo  # noqa: E402

RECORDING = Path("blackbird") / "clover_yawForward_maxSpeed5p0"


def imu_learn(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "imu_learn.cli", *args], check=True)


def skew_rotation(M: np.ndarray) -> Rotation:
    k = (M - M.T) / 2
    return Rotation.from_rotvec([k[2, 1], k[0, 2], k[1, 0]])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("IMU_LEARN_DATA", str(REPO.parent / "shared" / "data")))
    ap.add_argument("--out", type=Path, default=Path("reports/vo_like_reference"))
    a = ap.parse_args()
    rec = Path(a.data) / RECORDING
    vo, _, _ = make_vo(rec / "train" / "stamped_groundtruth_imu.txt", a.out / "vo")
    imu_learn("calibrate", "--input", str(rec / "train"), "--no-plot", "--quiet", "--out", str(a.out / "mocap"))
    imu_learn("calibrate", "--input", str(rec / "train"), "--groundtruth", str(vo), "--no-plot", "--quiet",
              "--out", str(a.out / "vo_profile"))
    mocap = json.loads((a.out / "mocap" / "profile.json").read_text())
    p = json.loads((a.out / "vo_profile" / "profile.json").read_text())
    turn = skew_rotation(np.asarray(mocap["floor"]["M_g"], dtype=np.float64))
    est = Rotation.from_matrix(np.asarray(p["reference"]["rotation_imu_from_reference"], dtype=np.float64))
    print("the estimated frame against the true one [deg]:", np.round(np.degrees((est * Rotation.from_matrix(R_BC).inv())
                                                                                  .as_rotvec()), 3))
    print("the motion-capture gyro's misalignment rotation [deg]:", np.round(np.degrees(turn.as_rotvec()), 3))
    for key, sensor in (("M_g", "gyroscope"), ("M_a", "accelerometer")):
        M = turn.as_matrix() @ np.asarray(p["floor"][key], dtype=np.float64)
        p["floor"][key] = p[sensor]["matrix"] = M.tolist()
    (a.out / "vo_profile_rotated").mkdir(parents=True, exist_ok=True)
    (a.out / "vo_profile_rotated" / "profile.json").write_text(json.dumps(p, indent=1))
    profiles = [f"profile:{a.out / d / 'profile.json'}" for d in ("mocap", "vo_profile", "vo_profile_rotated")]
    methods = ",".join(["raw", "timing", "traditional", "traditional+timing"] + profiles)
    imu_learn("evaluate", "--config", str(REPO / "configs" / "eval_blackbird.toml"), "--methods", methods,
              "--out", str(a.out / "evaluate"))


if __name__ == "__main__":
    main()
