"""What ``imu-learn navigate --nhc`` costs against the same run without it, per pass (causal: the
sample loop with its fixed-lag updates; smoothed: the batch pass), measured now on this machine and
printed as a markdown table.

The recording stands in for a ground robot's log (IMU at 30 Hz, GNSS at 2.5 Hz, ~400 s): the car
drive of rtklibexplorer/GNSS_IMU (``gnss-imu/drive_0708`` under the data root), its 100 Hz IMU
averaged into 30 Hz bins and cut after ``--seconds`` (written to a temporary folder with its time
tag), its RTKLIB fixes thinned to ``--aiding-hz``; each run with the built-in noise and with the
profile ``imu-learn calibrate --imu-only`` writes for that 30 Hz IMU (``--profile``: one already
written, else it is calibrated here first). The fixes are thinned here (a ``.pos`` written beside the
IMU): navigate's ``--aiding-hz`` does not thin geodetic fixes. ``--fix-sigma-m`` sets every fix's
sigma (a receiver without RTK, as a robot's NavSatFix is).

    RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python bench/bench_nhc.py [--data-root DIR] [--seconds 410] [--aiding-hz 2.5] [--fix-sigma-m M] [--profile JSON]
                                  [--variants plain,nhc,profile,profile+nhc] [--cprofile OUT.prof]

Each run is the CLI's ``navigate`` (``--quiet``); the fusion is timed by wrapping
:func:`imu_learn.fuse.navigate.fuse_run`, the smoothing pass by wrapping
:meth:`imu_learn.fuse.graph.IncrementalFusion.smooth`; the causal pass is the fusion less the smoothing
pass. CPU seconds (``time.process_time``, all threads) beside wall seconds: on a shared machine the
CPU figure is the one to compare.
``--cprofile`` writes the last variant's profile (``python -m pstats``).
"""
from __future__ import annotations

import argparse
import cProfile
import json
import os
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROT = "180,-6.79,185.35"  # the drive's mounting (docs/navigate.md)
DELAY = "-0.125"


def write_30hz(src: Path, folder: Path, seconds: float, rate_hz: float = 30.0) -> Path:
    """``src`` (a gnss-imu CSV at ~100 Hz) averaged into ``rate_hz`` bins over its first ``seconds``
    (each bin stamped at the mean counter of its samples), with its tag's end moved to the new last
    sample. The first line (cut as logged, never trusted by the reader) is kept as it is."""
    lines = src.read_text().splitlines()
    rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:-1] if ln.count(",") == 6])
    c0 = rows[0, 6]
    rows = rows[rows[:, 6] - c0 <= seconds * 1e3]
    b = np.floor((rows[:, 6] - c0) * rate_hz / 1e3).astype(np.int64)
    n = np.bincount(b)
    keep = n > 0
    avg = np.stack([np.bincount(b, rows[:, j])[keep] / n[keep] for j in range(7)], axis=1)
    avg[:, 6] += c0 - avg[0, 6]  # the first kept stamp stays the tag's start
    out = folder / src.name
    body = "".join(f"{r[0]:.6f},{r[1]:.6f},{r[2]:.6f},{r[3]:.5f},{r[4]:.5f},{r[5]:.5f},{r[6]:.3f}\n" for r in avg)
    out.write_text(lines[0] + "\n" + body)
    tag = src.with_name(src.name + ".tag").read_bytes()
    end_ms = int(round(avg[-1, 6] - c0))
    out.with_name(out.name + ".tag").write_bytes(tag[:76] + struct.pack("<II", end_ms, 0))
    return out


def write_pos(src: Path, folder: Path, rate_hz: float, sigma_m: float = 0.0) -> Path:
    """``src`` (an RTKLIB ``.pos``) thinned to the first fix of each ``1/rate_hz`` bin; ``sigma_m`` > 0:
    every fix's sdn, sde, sdu set to it (a receiver without RTK, as a robot's NavSatFix reports)."""
    out, t0 = [], None
    last_bin = -1
    for ln in src.read_text().splitlines():
        f = ln.split()
        if ln.startswith("%") or len(f) < 10:
            out.append(ln)
            continue
        hh, mm, ss = f[1].split(":")
        t = int(hh) * 3600 + int(mm) * 60 + float(ss)
        t0 = t if t0 is None else t0
        b = int((t - t0) * rate_hz + 1e-6)
        if b == last_bin:
            continue
        last_bin = b
        if sigma_m > 0:
            f[7:10] = [f"{sigma_m:.4f}"] * 3
        out.append(" ".join(f))
    path = folder / src.name
    path.write_text("\n".join(out) + "\n")
    return path


def calibrate_profile(imu: Path, folder: Path) -> Path:
    from imu_learn.cli import main

    rc = main(["calibrate", "--imu-only", "--input", str(imu), "--format", "gnss-imu", "--no-plot", "--quiet",
               "--out", str(folder / "calib")])
    if rc != 0:
        raise SystemExit(f"calibrate --imu-only failed ({rc})")
    return folder / "calib" / "profile.json"


def navigate_timed(imu: Path, pos: Path, out: Path, extra: list, prof=None) -> dict:
    """One navigate run: CPU and wall seconds of the causal pass (the fusion less the smoothing pass)
    and of the smoothing pass, the keyframes and NHC factors."""
    from imu_learn.cli import main
    from imu_learn.fuse import graph
    from imu_learn.fuse import navigate as nav

    spent = {}

    def timer(name, fn):
        def run(*args, **kw):
            c, w = time.process_time(), time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                spent[name] = (time.process_time() - c, time.perf_counter() - w)
        return run

    real_smooth, real_fuse = graph.IncrementalFusion.smooth, nav.fuse_run
    graph.IncrementalFusion.smooth = timer("smooth", real_smooth)
    nav.fuse_run = timer("fuse", real_fuse)
    argv = ["navigate", "--quiet", "--input", str(imu), "--format", "gnss-imu", "--aiding", str(pos),
            "--imu-rotation-rpy-deg", ROT, "--imu-delay-s", DELAY, "--out", str(out), *extra]
    try:
        rc = prof.runcall(main, argv) if prof is not None else main(argv)
    finally:
        graph.IncrementalFusion.smooth, nav.fuse_run = real_smooth, real_fuse
    if rc != 0:
        raise SystemExit(f"navigate {' '.join(extra)} failed ({rc})")
    s = json.loads((out / "summary.json").read_text())
    (fc, fw), (sc, sw) = spent["fuse"], spent["smooth"]
    return {"causal": (fc - sc, fw - sw), "smoothed": (sc, sw), "keyframes": s["keyframes"],
            "extra_factors": s["counts"].get("extra_factors", 0)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", default=os.environ.get("IMU_LEARN_DATA", ""))
    ap.add_argument("--seconds", type=float, default=410.0)
    ap.add_argument("--aiding-hz", type=float, default=2.5, help="the fixes thinned to this rate")
    ap.add_argument("--fix-sigma-m", type=float, default=0.0,
                    help="every fix's sigma [m] (0: RTKLIB's own, cm where fixed); e.g. 2 for a receiver without RTK")
    ap.add_argument("--profile", default=None)
    ap.add_argument("--variants", default="plain,nhc,profile,profile+nhc")
    ap.add_argument("--cprofile", default=None)
    a = ap.parse_args()
    drive = Path(a.data_root) / "gnss-imu" / "drive_0708"
    if not (drive / "imu_1934.csv").is_file():
        raise SystemExit(f"{drive}: the gnss-imu drive is not there (--data-root)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        imu = write_30hz(drive / "imu_1934.csv", folder, a.seconds)
        variants = a.variants.split(",")
        profile = a.profile
        if profile is None and any("profile" in v for v in variants):
            profile = str(calibrate_profile(imu, folder))
        pos = write_pos(drive / "gnss_1934_sf.pos", folder, a.aiding_hz, a.fix_sigma_m)
        print(f"30 Hz IMU of {a.seconds:g} s, fixes at {a.aiding_hz:g} Hz, sigma "
              f"{a.fix_sigma_m or 'RTKLIB'}; profile {profile}", file=sys.stderr)
        print("| variant | keyframes | NHC factors | causal CPU [s] | smoothed CPU [s] | causal wall [s] | smoothed wall [s] |")
        print("|---|---|---|---|---|---|---|")
        for i, v in enumerate(variants):
            extra = (["--nhc"] if "nhc" in v else []) + (["--profile", profile] if "profile" in v else [])
            prof = cProfile.Profile(time.process_time) if a.cprofile and i == len(variants) - 1 else None
            r = navigate_timed(imu, pos, folder / v, extra, prof)
            if prof is not None:
                prof.dump_stats(a.cprofile)
            (cc, cw), (sc, sw) = r["causal"], r["smoothed"]
            print(f"| {v} | {r['keyframes']} | {r['extra_factors']} | {cc:.1f} | {sc:.1f} | {cw:.1f} | {sw:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()
