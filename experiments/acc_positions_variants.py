"""How the accelerometer fitted from a VO's positions (calib.acc_positions) depends on its options: the
ORB-SLAM2 profile of experiments/reference_kinds.py calibrated with other ``AccOptions`` (the baseline T,
the world tilt left out), then refined and scored on the unseen flights exactly as that script does.

    IMU_LEARN_DATA=<root> python experiments/acc_positions_variants.py [--variants notilt,T0.25,T1.0]
        [--trials 0,1,2] [--out reports/acc_positions_variants]

Data: under the data root, euroc/<flight>, euroc-vo/orbslam2_stereo/trial<k>/<code>.txt.
Writes: OUT/<variant>_t<k>/ (profile and refined flights), OUT/results.json; prints one markdown row per
variant and trial (AOE / RO_RMSE 1 s / RP_RMSE 1 s per unseen flight); docs/experiments/references.md
("6-DoF poses in another frame", the sensitivity).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from imu_learn.calib.acc_positions import AccOptions
from imu_learn.calib.run import CalibOptions, calibrate
from imu_learn.calib.sources import PosesSource

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reference_kinds import TEST, TRAIN, score  # noqa: E402

VARIANTS = {
    "default": AccOptions(fit_tilt=True),  # what imu-learn calibrate uses (PosesSource's default)
    "notilt": AccOptions(fit_tilt=False),
    "T0.25": AccOptions(baseline_s=0.25, fit_tilt=True),
    "T1.0": AccOptions(baseline_s=1.0, fit_tilt=True),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", default="notilt,T0.25,T1.0")
    ap.add_argument("--trials", default="0,1,2")
    ap.add_argument("--out", type=Path, default=Path("reports/acc_positions_variants"))
    args = ap.parse_args()
    root = Path(os.environ.get("IMU_LEARN_DATA", "datasets"))
    results: dict = {}
    for name in args.variants.split(","):
        for trial in args.trials.split(","):
            out = args.out / f"{name}_t{trial}"
            vo = root / "euroc-vo" / "orbslam2_stereo" / f"trial{trial}"
            src = PosesSource([root / "euroc" / f for f in TRAIN], [vo / f"{c}.txt" for c in TRAIN.values()],
                              device="euroc-adis16448", acc_options=VARIANTS[name])
            calibrate(src.read(), out, CalibOptions(plot=False))
            row = {}
            for flight in TEST:
                f = root / "euroc" / flight
                r = subprocess.run([sys.executable, "-m", "imu_learn.cli", "refine", "--profile", str(out / "profile.json"),
                                    "--input", str(f), "--out", str(out / flight), "--bias", "still+gravity", "--force"],
                                   capture_output=True, text=True)
                row[flight] = score(f, out / flight) if r.returncode == 0 else {"refine_exit": r.returncode}
            results[f"{name}_t{trial}"] = row
            (args.out / "results.json").write_text(json.dumps(results, indent=2, default=float))
            cells = [f"{s['aoe_deg']:.2f}° / {s['ro_rmse_deg']:.3f}° / {100 * s['rp_rmse_m']:.2f} cm" if "aoe_deg" in s
                     else "-" for s in row.values()]
            print(f"| {name}, trial {trial} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
