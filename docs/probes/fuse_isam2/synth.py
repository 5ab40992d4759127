"""Fusion time and RMSE on a bench_scale synthetic recording with one ISAM2 setting.

python docs/probes/fuse_isam2/synth.py MODE SECONDS [CACHE]; CACHE is bench_scale's recording cache
(default: its own default, $TMPDIR/imu_learn_bench_scale); results go to $PROBE_OUT (default:
probe_out/ in the working directory)."""
import json, os, sys, tempfile, time
from pathlib import Path
HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]  # docs/probes/fuse_isam2 -> repository root
sys.path.insert(0, str(REPO / "bench")); sys.path.insert(0, str(REPO / "tests"))
import numpy as np
import gtsam
from scipy.spatial.transform import Rotation
import imu_learn as il
from imu_learn.data.formats.groundtruth import read_groundtruth
from imu_learn.fuse import ImuNoise, fuse, simulate_position
from imu_learn.fuse import graph
from imu_learn.core.quat import wxyz_to_xyzw
import bench_scale as bs

mode, seconds = sys.argv[1], int(sys.argv[2])
_ISAM2 = gtsam.ISAM2
sys.path.insert(0, str(HERE))  # fls.py
import fls
def patched(params):
    if "skip10" in mode:
        params.relinearizeSkip = 10
    return (fls.FixedLag if 'fls' in mode else _ISAM2)(params)
gtsam.ISAM2 = patched
cache = Path(sys.argv[3]) if len(sys.argv) > 3 else Path(tempfile.gettempdir()) / "imu_learn_bench_scale"
OUT = Path(os.environ.get("PROBE_OUT", "probe_out"))
OUT.mkdir(parents=True, exist_ok=True)
rec = bs.recording_dir(cache, seconds)
imu, gt = il.read_imu(bs.imu_csv(rec)), read_groundtruth(bs.gt_csv(rec))
seq = max(il.align(imu, gt).segments, key=len)
fixes = simulate_position(seq.t_ns, seq.p, 1.0, 0.1, np.random.default_rng(0))
R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
upd = []
orig = graph.IncrementalFusion._update
def timed(self, t):
    t0 = time.perf_counter(); orig(self, t); upd.append(time.perf_counter() - t0)
graph.IncrementalFusion._update = timed
t0 = time.perf_counter()
res = fuse(seq.t_ns, seq.gyro, seq.acc, (R0, seq.p[0], seq.v[0]), [fixes], ImuNoise(),
           partial_relinearization="partial" in mode)
wall = time.perf_counter() - t0
gtp = seq.p[res.kf_idx]
rm = lambda p: float(np.sqrt(((p - gtp) ** 2).sum(1).mean()))
tenth = max(1, len(upd) // 10)
out = dict(mode=mode, seconds=seconds, wall=wall, updates_s=sum(upd), upd_first_ms=1e3*np.mean(upd[:tenth]),
           upd_last_ms=1e3*np.mean(upd[-tenth:]), causal=rm(res.causal_p), smoothed=rm(res.smoothed_p))
np.savez(OUT / f"synth_{mode}_{seconds}.npz", cp=res.causal_p, sp=res.smoothed_p)
print(json.dumps(out)); open(OUT / "results.jsonl", "a").write(json.dumps(out) + "\n")
