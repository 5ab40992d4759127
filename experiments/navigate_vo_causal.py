"""Where the causal track's excess over the VO comes from (navigate, relative poses, EuRoC's ORB-SLAM2
stereo trajectories, the shipped EuRoC profile). Three diagnostics, none of which changes the package:

* ``world``: each causal pose taken back into the aiding's world through the world as the causal solver
  estimated it at that pose's update, then all mapped by the final world estimate (one rigid map, as the
  score's alignment is), against the causal track as written; the world's estimate over time; the
  causal pose's deviation from the aiding's own pose (in its world) split at 1 s.
* ``frame``: the residual rotation between the aiding's body frame and the IMU's (the frame check's
  Kabsch fit on rotation rates) applied to the poses before fusion, against the poses as given.
* ``errors``: the aiding's own position error against the ground truth (rigidly aligned), its spread
  over spans of 1-64 frames, and the noise estimate's residual tails (RMS over the robust sigma, share
  beyond 3 robust sigmas).

    IMU_LEARN_DATA=DIR python experiments/navigate_vo_causal.py world  --flight V1_03_difficult:V103
    IMU_LEARN_DATA=DIR python experiments/navigate_vo_causal.py frame  --flight V1_03_difficult:V103
    IMU_LEARN_DATA=DIR python experiments/navigate_vo_causal.py errors --flight V1_03_difficult:V103

Writes: tables on stdout (docs/experiments/navigate-vo.md, "What the causal excess is not"); the navigate
runs. folders under ``--out`` (default reports/navigate_vo_causal). Data: ``euroc/<flight>`` (IMU and
``state_groundtruth_estimate0``, the latter for scoring only) and ``euroc-vo/orbslam2_stereo/trial0/<VO>.txt``
with ``euroc-vo/cam0_sensor.yaml`` under the data root.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import imu_learn.fuse.aiding.noise as noise_mod
import imu_learn.fuse.graph as graph_mod
import imu_learn.fuse.navigate as nav
from imu_learn.calib.frames import kabsch
from imu_learn.data.config import resolve_data_root
from imu_learn.data.formats.extrinsics import read_t_bs
from imu_learn.fuse import score as sc
from imu_learn.fuse.aiding.frame import check_frame, paired_rates
from imu_learn.fuse.aiding.tum import read_tum

PROFILE = Path("models/profiles/euroc_adis16448/profile.json")


def sources(root: Path, flight: str, vo: str) -> nav.Sources:
    return nav.Sources(input=root / "euroc" / flight, aiding=root / f"euroc-vo/orbslam2_stereo/trial0/{vo}.txt",
                       extrinsics=root / "euroc-vo/cam0_sensor.yaml", profile=PROFILE,
                       groundtruth=root / "euroc" / flight / "mav0/state_groundtruth_estimate0/data.csv")


def ratios(summary) -> str:
    s = summary["scores"]
    c, m, v = (s[k]["pos_rmse_m"] for k in ("causal_at_aiding_stamps", "smoothed_at_aiding_stamps", "aiding_only"))
    return f"causal {c:.4f} m, smoothed {m:.4f} m, VO alone {v:.4f} m (causal / VO {c / v:.3f})"


def moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    c = np.cumsum(np.r_[np.zeros((1, x.shape[1])), x], axis=0)
    out = (c[n:] - c[:-n]) / n
    return np.r_[np.repeat(out[:1], n // 2, 0), out, np.repeat(out[-1:], n - n // 2 - 1, 0)]


def world(src: nav.Sources, out: Path) -> None:
    worlds, seen = {}, {}
    update = graph_mod.IncrementalFusion._update

    def recorded(self, t_ns, **kw):  # the world's estimate after each update of the causal solver
        update(self, t_ns, **kw)
        if self._world is not None:
            worlds[self._k] = self._isam.calculateEstimatePose3(self._world).matrix()

    summary_of = nav.run_summary

    def kept(src_, out_, inp, run, res):
        seen.update(inp=inp, run=run, res=res)
        return summary_of(src_, out_, inp, run, res)

    graph_mod.IncrementalFusion._update, nav.run_summary = recorded, kept
    summary = nav.navigate(src, out, nav.NavigateOptions(aiding_kind="relative-pose"))
    print("as written:", ratios(summary))
    inp, res = seen["inp"], seen["res"]
    kf_t = inp.imu.t_ns[seen["run"].st.start:][res.kf_idx]
    W = np.full((len(kf_t), 4, 4), np.nan)
    last = None
    for k in range(len(kf_t)):
        last = worlds.get(k, last)
        if last is not None:
            W[k] = last
    ok = ~np.isnan(W[:, 0, 0])
    final = W[np.where(ok)[0][-1]]
    mapped = res.causal_p.copy()
    for k in np.where(ok)[0]:
        M = final @ np.linalg.inv(W[k])
        mapped[k] = M[:3, :3] @ res.causal_p[k] + M[:3, 3]
    rows = inp.rows
    pos = {int(t): k for k, t in enumerate(kf_t)}
    pairs = np.array([(r, pos[int(t)]) for r, t in enumerate(rows.imu_t_ns) if int(t) in pos and ok[pos[int(t)]]])
    ri, ki = pairs[:, 0], pairs[:, 1]
    gt = sc.read_groundtruth(src.groundtruth)
    gi, gp, gR = sc.interpolate_groundtruth(gt, kf_t[ki])
    for name, p in (("causal as written", res.causal_p), ("causal through the final world", mapped)):
        print(f"{name}: {sc._errors(p[ki][gi], None, gp, gR, True)[0]['pos_rmse_m']:.4f} m")
    t = (kf_t - kf_t[0]) * 1e-9
    print("the world's causal estimate against its final one (rotation vector [deg], translation [mm]):")
    for q in (0, 5, 7, 8, 9, 10, 12, 15, 20, 30, 60):
        k = int(np.searchsorted(t, q))
        if k < len(t) and ok[k]:
            rv = np.degrees(Rotation.from_matrix(final[:3, :3].T @ W[k][:3, :3]).as_rotvec())
            print(f"  {q:>3} s: {np.round(rv, 2)}  {1000 * np.linalg.norm(final[:3, 3] - W[k][:3, 3]):.1f}")
    in_a = np.array([(np.linalg.inv(W[k]) @ np.r_[res.causal_p[k], 1.0])[:3] for k in ki])
    d = in_a - rows.p[ri]
    low = moving_mean(d, 20)
    rms = lambda x: 1000 * np.sqrt(np.mean(np.sum(x ** 2, axis=1)))  # noqa: E731
    print(f"causal minus the aiding's pose, in its world: RMS {rms(d):.1f} mm, below 1 Hz {rms(low):.1f} mm, "
          f"above {rms(d - low):.1f} mm")


def frame(src: nav.Sources, out: Path) -> None:
    checked = nav.checked_frame

    def turned(src_, rows, imu, max_gap_s):  # the poses turned onto the gyro's frame
        chk = checked(src_, rows, imu, max_gap_s)
        R = kabsch(*paired_rates(imu.t_ns, imu.gyro, rows, max_gap_s))[0]
        rows.R = np.einsum("nij,kj->nik", rows.R, R)
        after = check_frame(imu.t_ns, imu.gyro, rows, max_gap_s).rotation_deg
        print(f"  residual rotation applied: {np.round(np.degrees(Rotation.from_matrix(R).as_rotvec()), 3)} deg "
              f"(afterwards {after:.2g} deg)")
        return chk

    print("as given:", ratios(nav.navigate(src, out / "as_given", nav.NavigateOptions(aiding_kind="relative-pose"))))
    nav.checked_frame = turned
    print("turned:  ", ratios(nav.navigate(src, out / "turned", nav.NavigateOptions(aiding_kind="relative-pose"))))


def errors(src: nav.Sources, out: Path) -> None:
    traj = read_tum(src.aiding)
    _, p = nav.body_poses(traj, read_t_bs(src.extrinsics))  # the IMU's positions in the VO's world
    inside, pg, _ = sc.interpolate_groundtruth(sc.read_groundtruth(src.groundtruth), np.asarray(traj.t_ns))
    Ra, ta = sc.umeyama(p[inside], pg)
    e = p[inside] @ Ra.T + ta - pg
    spans = "  ".join(f"{m}: {1000 * np.sqrt(np.mean(np.sum((e[m:] - e[:-m]) ** 2, axis=1)) / 6):.1f}"
                      for m in (1, 2, 4, 8, 16, 32, 64))
    print(f"VO error RMS {1000 * np.sqrt(np.mean(np.sum(e ** 2, axis=1))):.1f} mm; per axis and pose, "
          f"sqrt(var(e[k+m] - e[k]) / 2) [mm] over m frames: {spans}")
    robust = noise_mod.robust_sigma

    def told(r):
        s = robust(r)
        c = r - np.median(r, axis=0)
        print(f"  noise estimate's residuals: RMS / robust sigma {np.round(np.sqrt(np.mean(c ** 2, 0)) / s, 2)}, "
              f"beyond 3 robust sigmas {np.round(np.mean(np.abs(c) > 3 * s, 0), 3)} (Gaussian 0.003)")
        return s

    noise_mod.robust_sigma = told
    print("rotation, then translation:")
    nav.read_inputs(src, nav.NavigateOptions(aiding_kind="relative-pose"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("world", "frame", "errors"))
    ap.add_argument("--flight", default="V1_03_difficult:V103", help="EuRoC folder:ORB-SLAM2 file stem")
    ap.add_argument("--out", type=Path, default=Path("reports/navigate_vo_causal"))
    ap.add_argument("--data-root", help="the data root (else $IMU_LEARN_DATA)")
    args = ap.parse_args()
    flight, vo = args.flight.split(":")
    root = resolve_data_root(args.data_root)
    if not root:
        ap.error("no data root: pass --data-root or set IMU_LEARN_DATA")
    src = sources(Path(root), flight, vo)
    {"world": world, "frame": frame, "errors": errors}[args.what](src, args.out / flight / args.what)


if __name__ == "__main__":
    main()
