"""Real recording: raw IMU, seed-0 aiding of configs/fuse_euroc.toml's scenarios, each ISAM2 setting.

python docs/probes/fuse_isam2/real.py REC SCENARIOS MODES [DATA_ROOT]; the data root (holding euroc/)
is the fourth argument, else $IMU_LEARN_DATA; results are appended to $PROBE_OUT/real.jsonl
(default: probe_out/ in the working directory)."""
import json, os, sys, time
from pathlib import Path
import numpy as np
import gtsam
from scipy.spatial.transform import Rotation
from imu_learn.fuse.config import load
from imu_learn.fuse import run as R
from imu_learn.fuse.graph import fuse
from imu_learn.fuse.score import score
from imu_learn.core.quat import wxyz_to_xyzw

rec_name, scen_names, modes = sys.argv[1], sys.argv[2].split(","), sys.argv[3].split(",")
HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]  # docs/probes/fuse_isam2 -> repository root
data_root = sys.argv[4] if len(sys.argv) > 4 else os.environ.get("IMU_LEARN_DATA", "")
if not data_root:
    sys.exit("set the data root: 4th argument or IMU_LEARN_DATA")
OUT = Path(os.environ.get("PROBE_OUT", "probe_out"))
OUT.mkdir(parents=True, exist_ok=True)
cfg = load(REPO / "configs" / "fuse_euroc.toml", data_root)
spec = next(s for s in cfg.recordings if Path(s.path).name == rec_name)
seq, noise, leica = R.load_recording_for_fusion(cfg, spec)
R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
_ISAM2 = gtsam.ISAM2
sys.path.insert(0, str(HERE))  # fls.py
import fls
for sn in scen_names:
    scn = next(s for s in cfg.scenarios if s.name == sn)
    aiding = R.make_aiding(scn, seq, leica, R.aiding_rng(0, rec_name, scn))
    bias0 = R.bias_prior_mean(scn, seq, seq.gyro, seq.acc, cfg.gravity)
    for mode in modes:
        def patched(params, mode=mode):
            if "skip10" in mode:
                params.relinearizeSkip = 10
            return (fls.FixedLag if 'fls' in mode else _ISAM2)(params)
        gtsam.ISAM2 = patched
        t0 = time.perf_counter()
        res = fuse(seq.t_ns, seq.gyro, seq.acc, (R0, seq.p[0], seq.v[0]), [aiding], noise, cfg.gravity,
                   cfg.keyframe_hz, bias0=bias0, partial_relinearization="partial" in mode)
        wall = time.perf_counter() - t0
        s = score(res, seq.t_ns, seq.p, seq.q_wxyz, scn.outage_windows())
        out = dict(rec=rec_name, scenario=sn, mode=mode, wall=wall, causal=s["causal"]["pos_rmse_m"],
                   smoothed=s["smoothed"]["pos_rmse_m"], causal_rot=s["causal"]["rot_rmse_deg"],
                   max_dcausal=float(np.abs(res.causal_p).max()))
        print(json.dumps(out), flush=True)
        open(OUT / "real.jsonl", "a").write(json.dumps(out) + "\n")
