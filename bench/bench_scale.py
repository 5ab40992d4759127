"""Cost against recording length: time and peak memory of each stage on synthetic 200 Hz recordings.

    python bench/bench_scale.py [--hours 1/6,1,10] [--fuse-hours 1/4,1/2,1,2] [--fuse-lag S] [--fuse-smoothing batch|window]
                                [--stages parse,align,...]
                                [--quick] [--cache DIR] [--max-rss-gib 12]

A synthetic EuRoC ASL recording (``mav0/imu0/data.csv`` with the EuRoC header, the 17-column
``mav0/state_groundtruth_estimate0/data.csv``) of each length is written once into the cache folder
(default ``$TMPDIR/imu_learn_bench_scale``) and reused by later runs. Each stage of each length then
runs in a FRESH subprocess, so its peak resident memory (``os.wait4``'s ``ru_maxrss``) is that
stage's alone; the parent also watches the child's resident memory and stops it above
``--max-rss-gib`` (reported as such, not as a figure). Stages:

- ``write``   generating and writing the recording (only when it is not cached yet);
- ``parse``   ``imu_learn.read_imu`` + the ground-truth reader (``read_groundtruth``);
- ``align``   ``imu_learn.align`` (ground truth onto the IMU stamps) of the parsed files;
  ``load_sequence`` is parse + align;
- ``window_labels``  ``imu_learn.window_labels(seq, 200, 10)`` on the aligned sequence (the label
  computation alone);
- ``labels_cli``  ``imu-learn labels euroc --root ... --rebuild``: parse, align, labels and
  the ``.npz`` cache, as the CLI runs them;
- ``refine``  ``imu-learn refine`` with ``models/euroc_adis16448.pt`` on the CPU, writing a
  refined copy of the IMU file;
- ``fuse``    ``imu_learn.fuse.fuse`` on the raw IMU with simulated 1 Hz position fixes (sigma 0.1 m,
  10 Hz keyframes, the EuRoC ADIS16448 noise model: the ``gnss_1hz`` scenario of
  configs/fuse_euroc.toml), the causal estimate (the fixed-lag smoother, window ``--fuse-lag`` s;
  ``inf``: iSAM2 over the whole graph) then the batch smoothing pass; run on ``--fuse-hours``.

"wall s" is timed inside the child around the stage's own call (imports and the inputs a stage needs
are prepared before, untimed). "peak RSS MiB" is the resident high-water mark DURING the stage (the
child resets it just before: ``/proc/self/clear_refs``), "before MiB" the resident memory when the
stage started (interpreter, imports, inputs), "process peak MiB" the child's whole peak from
``wait4``. The growth exponent is the log-log slope of wall time (and of the stage's peak minus
"before") against samples between consecutive lengths: 1 is linear.

Thread counts are set explicitly and printed: torch 1 (``--torch-threads``), rayon from
``RAYON_NUM_THREADS`` (default 1). The trajectory is closed-form and bounded (a Lissajous path with
a wobbling yaw, built from imu_learn.data.synthetic's quaternion helpers), the IMU its exact specific force
and body rate plus seeded white noise and a constant bias.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from datetime import date
from fractions import Fraction
from pathlib import Path
from typing import Dict, List, Optional

HERE = Path(__file__).resolve().parent
REPO = HERE.parent

from imu_learn.util.machine import cpu_name  # noqa: E402

STAGES = ("parse", "align", "window_labels", "labels_cli", "refine", "fuse")
DEFAULT_HOURS = "1/6,1,10"
DEFAULT_FUSE_HOURS = "1/4,1/2,1,2"  # the fixed-lag causal estimate is linear (docs/experiments/scale.md)
QUICK_HOURS = "1/60,1/12"
CHECKPOINT = REPO / "models" / "euroc_adis16448.pt"
GENERATOR_VERSION = 1  # bump when the synthetic recording changes: cached ones are rewritten
CHUNK = 360_000  # samples generated and written at a time (30 min at 200 Hz)
WINDOW, STRIDE = 200, 10  # the labels CLI's defaults
FIX_RATE_HZ, FIX_SIGMA_M = 1.0, 0.1

STATE_HEADER = (
    "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
    "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
    "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]"
)
# Sensor errors of EuRoC's ADIS16448 size: white noise (discrete sigma at 200 Hz) and a constant bias.
GYRO_SIGMA, ACC_SIGMA = 1.7e-4 * math.sqrt(200.0), 2.0e-3 * math.sqrt(200.0)
GYRO_BIAS, ACC_BIAS = (0.004, -0.003, 0.002), (0.05, -0.04, 0.03)


# ------------------------------------------------------------------------------------------------
# the synthetic recording
# ------------------------------------------------------------------------------------------------


def trajectory(t):
    """Closed-form bounded motion at times ``t`` [s]: (q_wxyz, p, v, gyro, acc), noise-free.

    Rotation: yaw psi(t) about world z, then a tilt phi(t) about the body axis TILT; the body rate
    of R = Rz(psi) Ra(phi) is Ra^T (psi' z) + phi' a. Position: a Lissajous curve (about 1 m/s).
    Specific force: R^T (a_world + g z)."""
    import numpy as np

    from imu_learn.data.synthetic import G, axis_angle, qconj, qmul, rotate

    tilt = np.array([1.0, -1.0, 0.0]) / math.sqrt(2.0)
    psi, dpsi = 0.3 * t + 0.4 * np.sin(0.7 * t), 0.3 + 0.28 * np.cos(0.7 * t)
    phi, dphi = 0.2 * np.sin(1.1 * t), 0.22 * np.cos(1.1 * t)
    q_tilt = axis_angle(tilt, phi)
    q = qmul(axis_angle([0.0, 0.0, 1.0], psi), q_tilt)
    zero = np.zeros_like(t)
    gyro = rotate(qconj(q_tilt), np.stack([zero, zero, dpsi], -1)) + dphi[:, None] * tilt
    amp, w = np.array([20.0, 15.0, 2.0]), np.array([0.05, 0.1, 0.07])
    tt = t[:, None]
    p = amp * np.sin(w * tt)
    v = amp * w * np.cos(w * tt)
    a_world = -amp * w**2 * np.sin(w * tt) + np.array([0.0, 0.0, G])
    acc = rotate(qconj(q), a_world)
    return q, p, v, gyro, acc


def recording_dir(cache: Path, seconds: int) -> Path:
    """Each recording alone under its own root, so ``labels euroc --root`` finds exactly it."""
    return cache / f"v{GENERATOR_VERSION}_{seconds}s" / "synthetic" / "rec"


def is_cached(rec: Path) -> bool:
    return (rec / "complete.json").exists()


def write_recording(rec: Path, seconds: int, seed: int = 0) -> Dict[str, float]:
    """Write the recording in chunks: the IMU file by imu_core's writer, ground truth by polars."""
    import numpy as np
    import polars as pl

    from imu_learn import _imu_core as core
    from imu_learn.data.synthetic import stamps
    from imu_learn.util.atomic import atomic_write_bytes, atomic_write_path, atomic_write_text

    t_ns = stamps(seconds)
    n = len(t_ns)
    rng = np.random.default_rng(seed)
    gyro, acc = np.empty((n, 3)), np.empty((n, 3))
    bias = np.r_[GYRO_BIAS, ACC_BIAS]
    t0 = time.perf_counter()

    def write_groundtruth(f) -> None:
        f.write((STATE_HEADER + "\n").encode())
        for a in range(0, n, CHUNK):
            b = min(n, a + CHUNK)
            q, p, v, g, ac = trajectory((t_ns[a:b] - t_ns[0]) * 1e-9)
            gyro[a:b] = g + rng.normal(0.0, GYRO_SIGMA, g.shape)
            acc[a:b] = ac + rng.normal(0.0, ACC_SIGMA, ac.shape)
            cols = {"t": t_ns[a:b]}
            for name, arr in (("p", p), ("q", q), ("v", v), ("b", np.broadcast_to(bias, (b - a, 6)))):
                cols.update({f"{name}{i}": arr[:, i] for i in range(arr.shape[1])})
            pl.DataFrame(cols).write_csv(f, include_header=False, float_precision=9)

    atomic_write_bytes(rec / "mav0" / "state_groundtruth_estimate0" / "data.csv", write_groundtruth)
    t_gt = time.perf_counter() - t0
    atomic_write_path(rec / "mav0" / "imu0" / "data.csv",
                      lambda tmp: core.write_asl_imu(str(tmp), t_ns, gyro, acc))
    t_imu = time.perf_counter() - t0 - t_gt
    atomic_write_text(rec / "complete.json", json.dumps({"version": GENERATOR_VERSION, "seconds": seconds,
                                                          "samples": n, "seed": seed}))
    return {"groundtruth_s": t_gt, "imu_s": t_imu}


# ------------------------------------------------------------------------------------------------
# one stage, run inside a fresh child process
# ------------------------------------------------------------------------------------------------


def imu_csv(rec: Path) -> Path:
    return rec / "mav0" / "imu0" / "data.csv"


def gt_csv(rec: Path) -> Path:
    return rec / "mav0" / "state_groundtruth_estimate0" / "data.csv"


def prepare_and_run(stage: str, rec: Path, scratch: Path, lag_s: float = float("inf"),
                    smoothing: str = "batch") -> Dict[str, object]:
    """Prepare the stage's inputs (untimed), then time the stage. Returns seconds and extras."""
    import imu_learn as il
    from imu_learn.data.formats.groundtruth import read_groundtruth

    extra: Dict[str, object] = {}
    if stage == "write":
        return {"seconds": None, **write_recording(rec, seconds_of(rec))}
    if stage == "parse":
        def run() -> None:
            t0 = time.perf_counter()
            imu = il.read_imu(imu_csv(rec))
            extra["imu_s"] = time.perf_counter() - t0
            read_groundtruth(gt_csv(rec))
            extra["samples"] = len(imu)
    elif stage in ("align", "window_labels", "fuse"):
        imu, gt = il.read_imu(imu_csv(rec)), read_groundtruth(gt_csv(rec))
        if stage == "align":
            def run() -> None:
                extra["segments"] = len(il.align(imu, gt).segments)
        else:
            seq = max(il.align(imu, gt).segments, key=len)
            del imu, gt
            if stage == "window_labels":
                def run() -> None:
                    extra["windows"] = len(il.window_labels(seq, WINDOW, STRIDE).starts)
            else:
                run = fuse_runner(seq, extra, lag_s, smoothing)
    elif stage == "labels_cli":
        from imu_learn.cli.labels import main as labels_main

        def run() -> None:
            argv = ["euroc", "--dataset-dir", str(rec.parent), "--out", str(scratch / "labels"), "--rebuild", "--quiet"]
            if labels_main(argv) != 0:
                raise RuntimeError("python -m imu_learn.labels failed")
    elif stage == "refine":
        from imu_learn.cli.refine import main as refine_main

        def run() -> None:
            argv = ["--checkpoint", str(CHECKPOINT), "--input", str(rec), "--out", str(scratch / "refined"),
                    "--device", "cpu", "--quiet"]
            if refine_main(argv) != 0:
                raise RuntimeError("python -m imu_learn.refine failed")
    else:
        raise ValueError(f"unknown stage {stage}")
    extra["rss_before_mib"] = reset_peak_rss()
    t0 = time.perf_counter()
    run()
    return {"seconds": time.perf_counter() - t0, "stage_peak_mib": status_mib("VmHWM"), **extra}


def fuse_runner(seq, extra: Dict[str, object], lag_s: float, smoothing: str):
    """fuse() on the raw IMU with simulated 1 Hz fixes; the smoothing pass timed on its own."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    from imu_learn.fuse import ImuNoise, fuse, graph, simulate_position

    fixes = simulate_position(seq.t_ns, seq.p, FIX_RATE_HZ, FIX_SIGMA_M, np.random.default_rng(0))
    R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
    smooth = graph.IncrementalFusion.smooth

    def timed_smooth(self):  # instrumentation only: the same method, its time recorded
        # the causal pass's own peak and what it leaves resident (the graph kept for smoothing)
        extra["causal_peak_mib"], extra["rss_before_smooth_mib"] = status_mib("VmHWM"), status_mib("VmRSS")
        t0 = time.perf_counter()
        try:
            return smooth(self)
        finally:
            extra["smooth_s"] = time.perf_counter() - t0

    graph.IncrementalFusion.smooth = timed_smooth
    update = graph.IncrementalFusion._update
    update_s: List[float] = []

    def timed_update(self, t_ns):  # instrumentation only: how one iSAM2 update's cost grows
        t0 = time.perf_counter()
        update(self, t_ns)
        update_s.append(time.perf_counter() - t0)

    graph.IncrementalFusion._update = timed_update

    def run() -> None:
        res = fuse(seq.t_ns, seq.gyro, seq.acc, (R0, seq.p[0], seq.v[0]), [fixes],
                   graph.FusionSettings(ImuNoise(), lag_s=lag_s, smoothing=smoothing))
        err = res.smoothed_p - seq.p[res.kf_idx]
        err_c = res.causal_p - seq.p[res.kf_idx]
        extra.update(keyframes=len(res.kf_idx), fixes=len(fixes), counts=res.counts, lag_s=lag_s, smoothing=smoothing,
                     smoothed_pos_rmse_m=float(np.sqrt((err**2).sum(1).mean())),
                     causal_pos_rmse_m=float(np.sqrt((err_c**2).sum(1).mean())),
                     updates_s=float(sum(update_s)), **update_growth(update_s))

    return run


def update_growth(update_s: List[float]) -> Dict[str, float]:
    """Mean iSAM2 update time [ms] over the first and the last tenth of the updates."""
    tenth = max(1, len(update_s) // 10)
    return {"update_ms_first_tenth": 1e3 * sum(update_s[:tenth]) / tenth,
            "update_ms_last_tenth": 1e3 * sum(update_s[-tenth:]) / tenth}


def seconds_of(rec: Path) -> int:
    return int(rec.parent.parent.name.split("_")[1].rstrip("s"))


def status_mib(field: str) -> float:
    """A memory figure of this process from /proc/self/status (VmRSS now, VmHWM its peak)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024.0
    raise OSError(f"/proc/self/status has no {field}")


def reset_peak_rss() -> float:
    """Reset this process's peak RSS (Linux >= 4.0: writing 5 to clear_refs) so that VmHWM after the
    stage is the stage's own peak, not the input preparation's; returns the RSS now."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    return status_mib("VmRSS")


def peak_rss_self_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def child_main(stage: str, rec: Path, scratch: Path, result: Path, torch_threads: int, lag_s: float,
               smoothing: str) -> int:
    """Run one stage and write its result. Only ``refine`` imports torch (540 MiB resident on its
    own), so the other stages' peaks are theirs. The peak is read right after the stage and the
    child leaves by ``os._exit``: an interpreter that imported torch grows by ~125 MiB while it
    finalises, which is no stage's cost."""
    if stage == "refine":
        import torch

        torch.set_num_threads(torch_threads)
    from imu_learn.util.atomic import atomic_write_text

    out = prepare_and_run(stage, rec, scratch, lag_s, smoothing)
    out["peak_self_mib"] = peak_rss_self_mib()
    out["torch_threads"] = torch_threads if "torch" in sys.modules else None
    if "torch" in sys.modules:
        import torch

        out["torch_threads"] = torch.get_num_threads()
    atomic_write_text(result, json.dumps(out))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


# ------------------------------------------------------------------------------------------------
# the parent: children, memory watch, table
# ------------------------------------------------------------------------------------------------


def rss_mib(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


def run_child(stage: str, rec: Path, scratch: Path, args) -> Dict[str, object]:
    """One stage in a fresh interpreter; its own peak RSS from wait4, stopped above the limit."""
    result = scratch / f"{stage}.json"
    cmd = [sys.executable, __file__, "--child", stage, "--rec", str(rec), "--scratch", str(scratch),
           "--result", str(result), "--torch-threads", str(args.torch_threads), "--fuse-lag", str(args.fuse_lag),
           "--fuse-smoothing", args.fuse_smoothing]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd)
    limit = args.max_rss_gib * 1024.0
    stopped = None
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if rss_mib(proc.pid) > limit:
            stopped = f"stopped: resident memory over {args.max_rss_gib:g} GiB"
            proc.kill()
        time.sleep(0.2)
    proc.returncode = os.waitstatus_to_exitcode(status)
    out: Dict[str, object] = {"peak_mib": usage.ru_maxrss / 1024.0, "process_s": time.perf_counter() - t0}
    if stopped or proc.returncode != 0:
        out["failed"] = stopped or f"exit status {proc.returncode}"
        return out
    out.update(json.loads(result.read_text()))
    return out


def parse_hours(text: str) -> List[Fraction]:
    try:
        hours = [Fraction(x.strip()) for x in text.split(",") if x.strip()]
    except (ValueError, ZeroDivisionError) as e:
        raise argparse.ArgumentTypeError(f"lengths in hours, e.g. 1/6,1,10: {e}") from None
    if not hours or any(h <= 0 for h in hours):
        raise argparse.ArgumentTypeError(f"lengths must be positive hours, got {text!r}")
    return sorted(set(hours))


def length_label(seconds: int) -> str:
    if seconds % 3600 == 0:
        return f"{seconds // 3600} h"
    if seconds % 60 == 0:
        return f"{seconds // 60} min"
    return f"{seconds} s"


def slope(x0: float, y0: float, x1: float, y1: float) -> Optional[float]:
    if min(x0, y0, x1, y1) <= 0 or x0 == x1:
        return None
    return math.log(y1 / y0) / math.log(x1 / x0)


def format_table(rows: List[dict]) -> str:
    lines = ["| stage | length | samples | wall s | peak RSS MiB | before MiB | process peak MiB | µs/sample | "
             "time exponent | memory exponent |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    prev: Dict[str, dict] = {}
    for r in rows:
        n = r["samples"]
        if "failed" in r:
            lines.append(f"| {r['stage']} | {length_label(r['seconds_rec'])} | {n:,} | {r['failed']} | "
                         f" | | {r['peak_mib']:.0f} | | | |")
            continue
        p = prev.get(r["stage"])
        te = slope(p["samples"], p["seconds"], n, r["seconds"]) if p else None
        me = slope(p["samples"], p["stage_peak_mib"] - p["base_mib"], n, r["stage_peak_mib"] - r["base_mib"]) if p else None
        lines.append(
            f"| {r['stage']} | {length_label(r['seconds_rec'])} | {n:,} | {r['seconds']:.2f} | {r['stage_peak_mib']:.0f} | "
            f"{r['base_mib']:.0f} | {r['peak_mib']:.0f} | {r['seconds'] / n * 1e6:.2f} | {'' if te is None else f'{te:.2f}'} | "
            f"{'' if me is None else f'{me:.2f}'} |")
        prev[r["stage"]] = r
    return "\n".join(lines)


def machine() -> str:
    cpu = cpu_name()
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{cpu}, {os.cpu_count()} cores, {mem:.0f} GiB RAM, Python {platform.python_version()}"


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=parse_hours, default=None, help=f"recording lengths in hours (default {DEFAULT_HOURS})")
    ap.add_argument("--fuse-hours", type=parse_hours, default=None,
                    help=f"lengths for the fuse stage (default {DEFAULT_FUSE_HOURS}; fusion is the slow one)")
    ap.add_argument("--stages", default=",".join(STAGES), help=f"comma list of {','.join(STAGES)}")
    ap.add_argument("--quick", action="store_true", help=f"short lengths ({QUICK_HOURS} h) to try it")
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "imu_learn_bench_scale",
                    help="folder for the synthetic recordings and stage outputs")
    ap.add_argument("--max-rss-gib", type=float, default=12.0, help="stop a stage whose resident memory exceeds this")
    ap.add_argument("--torch-threads", type=int, default=1)
    ap.add_argument("--fuse-lag", type=float, default=None,
                    help="the fuse stage's fixed-lag window [s] (default: the estimator's; inf: iSAM2 over the whole graph)")
    ap.add_argument("--fuse-smoothing", choices=("batch", "window"), default="batch",
                    help="the fuse stage's smoothed estimate: batch LM over the whole graph, or the fixed-lag window's")
    ap.add_argument("--json", type=Path, default=None, help="also write every measurement here")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--rec", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--scratch", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    if args.fuse_lag is None:
        from imu_learn.fuse.settings import DEFAULT_LAG_S

        args.fuse_lag = DEFAULT_LAG_S
    if args.child:
        return child_main(args.child, args.rec, args.scratch, args.result, args.torch_threads, args.fuse_lag,
                          args.fuse_smoothing)
    stages = [s.strip() for s in args.stages.split(",") if s.strip()]
    if set(stages) - set(STAGES):
        ap.error(f"--stages: unknown {sorted(set(stages) - set(STAGES))}; known: {','.join(STAGES)}")
    hours = args.hours or parse_hours(QUICK_HOURS if args.quick else DEFAULT_HOURS)
    fuse_hours = args.fuse_hours or (hours if args.quick else parse_hours(DEFAULT_FUSE_HOURS))
    print(f"# bench_scale: {machine()}; torch threads {args.torch_threads}, "
          f"RAYON_NUM_THREADS={os.environ['RAYON_NUM_THREADS']}; fuse lag {args.fuse_lag:g} s, smoothing {args.fuse_smoothing}; {date.today().isoformat()}")
    print(f"# command: python bench/bench_scale.py {' '.join(argv if argv is not None else sys.argv[1:])}".rstrip())
    lengths = sorted({int(h * 3600) for h in hours} | ({int(h * 3600) for h in fuse_hours} if "fuse" in stages else set()))
    rows: List[dict] = []
    writes: List[dict] = []
    for seconds in lengths:
        rec = recording_dir(args.cache, seconds)
        scratch = rec.parent.parent / "scratch"
        scratch.mkdir(parents=True, exist_ok=True)
        if not is_cached(rec):
            print(f"# writing the {length_label(seconds)} recording to {rec} ...", flush=True)
            w = run_child("write", rec, scratch, args)
            if "failed" in w:
                print(f"# writing failed: {w['failed']}")
                return 1
            writes.append({"seconds_rec": seconds, **w})
        n = 1 + seconds * 200
        for stage in stages:
            todo = fuse_hours if stage == "fuse" else hours
            if not any(int(h * 3600) == seconds for h in todo):
                continue
            print(f"# {stage}, {length_label(seconds)} ...", flush=True)
            r = run_child(stage, rec, scratch, args)
            r.update(stage=stage, seconds_rec=seconds, samples=n)
            r["base_mib"] = r.get("rss_before_mib", 0.0)
            r["stage_peak_mib"] = r.get("stage_peak_mib", r["peak_mib"])
            rows.append(r)
            print("#   " + json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}), flush=True)
    for w in writes:
        print(f"# wrote {length_label(w['seconds_rec'])}: ground truth {w['groundtruth_s']:.1f} s, IMU {w['imu_s']:.1f} s, "
              f"peak {w['peak_mib']:.0f} MiB")
    order = {s: i for i, s in enumerate(STAGES)}
    rows.sort(key=lambda r: (order[r["stage"]], r["samples"]))
    print(format_table(rows))
    if args.json:
        from imu_learn.util.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps({"rows": rows, "writes": writes, "machine": machine()}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
