"""Throughput of the Rust core against a vectorised numpy reference, GTSAM and polars.

    python bench/bench_core.py [--quick] [--data ../shared/data/euroc] [--only-reference]

Everything printed is measured on this machine now: each figure is the median of several
repeats timed with time.perf_counter, on the same inputs for every implementation. Data: the
EuRoC crops shipped in datasets/euroc (or the full files with --data). ``--only-reference``
times only numpy/GTSAM/polars and needs no compiled module.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Callable, Dict, List, Optional

# numpy's reference is elementwise and single-threaded; an idle OpenBLAS/OpenMP pool would only
# spin on the cores rayon needs. Set before numpy is imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parent

from imu_learn.core import numpy_reference as nr  # noqa: E402
from imu_learn.util.machine import cpu_name  # noqa: E402

SEQUENCES = ("MH_01_easy", "V1_01_easy")
WINDOW, STRIDE, BATCH = 200, 1, 256
FRACTIONS = (0.2, 0.4, 0.6, 0.8, 1.0)
GRAVITY = 9.81
# Augmentation of the size the paper trains with (EuRoC ADIS16448 datasheet-like figures).
AUGMENT = dict(gyro_noise_density=1.7e-4, acc_noise_density=2.0e-3, gyro_bias_max=0.02, acc_bias_max=0.2)
SCAN_NOTES = {
    "doubling": "Hillis–Steele quaternion scan, O(N log N) work",
    "blocked": "two-level scan (16-wide blocks), O(N) work",
}
TARGETS = {"integration": 20.0, "labels": 5.0, "batches": 5.0, "csv": 1.0}


# ------------------------------------------------------------------------------------------------
# timing and machine
# ------------------------------------------------------------------------------------------------


def measure(fn: Callable[[], object], repeats: int, warmup: int = 1) -> Dict[str, float]:
    """Median / min / max wall time [s] of ``fn()`` over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "n": repeats}


def _version(pkg: str) -> str:
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return "not installed"


def _numpy_blas() -> str:
    try:
        import threadpoolctl  # type: ignore[import-not-found]

        infos = threadpoolctl.threadpool_info()
        return "; ".join(
            f"{i.get('internal_api')} {i.get('version')} ({i.get('num_threads')} threads)" for i in infos
        ) or "none found by threadpoolctl"
    except ImportError:
        pass
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return f"{blas.get('name')} {blas.get('version')} (build config; threadpoolctl not installed)"
    except Exception:  # noqa: BLE001 - older numpy: no dict mode
        return "unknown (threadpoolctl not installed)"


def machine_lines(have_core: bool) -> List[str]:
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = os.cpu_count() or 0
    lines = [
        f"- CPU: {cpu_name()}; os.cpu_count() = {os.cpu_count()}, usable by this process = {affinity}",
        f"- RAYON_NUM_THREADS = {os.environ.get('RAYON_NUM_THREADS', '(unset: one thread per usable core)')}",
        f"- Python {platform.python_version()} on {platform.system()} {platform.release()}",
        f"- numpy {np.__version__}; BLAS: {_numpy_blas()}",
        f"- polars {_version('polars')}, gtsam {_version('gtsam')}",
    ]
    try:
        import polars as pl

        lines[-1] += f" (polars thread pool: {pl.thread_pool_size()})"
    except ImportError:
        pass
    if have_core:
        import imu_learn

        lines.append(f"- imu_learn {imu_learn.__version__} (core: {Path(imu_learn._imu_core.__file__).name})")
    else:
        lines.append("- imu_learn core: not timed (--only-reference or module not importable)")
    return lines


# ------------------------------------------------------------------------------------------------
# data
# ------------------------------------------------------------------------------------------------


def imu_csv(data: Path, name: str) -> Path:
    return data / name / "mav0" / "imu0" / "data.csv"


def load_imu(path: Path, have_core: bool):
    if have_core:
        from imu_learn import _imu_core as core
        return core.read_asl_imu(str(path))
    return nr.read_asl_imu_numpy(path)


def load_sequences(data: Path, have_core: bool) -> List[tuple]:
    """(t_ns, gyro, acc, p, v, q_wxyz) per aligned segment; the core's alignment when available."""
    out: List[tuple] = []
    for name in SEQUENCES:
        root = data / name
        if not root.exists():
            continue
        if have_core:
            import imu_learn

            out += [(s.t_ns, s.gyro, s.acc, s.p, s.v, s.q_wxyz) for s in imu_learn.load_sequence(root)]
        else:
            t, g, a = nr.read_asl_imu_numpy(imu_csv(data, name))
            out.append(nr.align_tum_numpy(t, g, a, root / "groundtruth_pose.tum"))
    if not out:
        raise SystemExit(f"no EuRoC sequences ({', '.join(SEQUENCES)}) under {data}")
    return out


# ------------------------------------------------------------------------------------------------
# benchmarks: each returns rows {task, impl, seconds(median), items, unit, note}
# ------------------------------------------------------------------------------------------------

Row = Dict[str, object]


def _row(task: str, impl: str, m: Dict[str, float], items: float, unit: str, note: str = "") -> Row:
    return {"task": task, "impl": impl, "m": m, "items": items, "unit": unit, "note": note}


def bench_integration(t, gyro, acc, have_core: bool, repeats: int, gtsam_repeats: int) -> List[Row]:
    n = len(t)
    rows: List[Row] = []
    ref = nr.preintegrate(t, gyro, acc)
    if have_core:
        import imu_learn

        inc = imu_learn.preintegrate(t, gyro, acc)
        err = max(float(np.abs(a - b).max()) for a, b in zip((inc.dq_wxyz, inc.dv, inc.dp, inc.dt), ref))
        scale = max(float(np.abs(x).max()) for x in ref)
        m = measure(lambda: imu_learn.preintegrate(t, gyro, acc), repeats)
        note = f"max \\|core − numpy\\| = {err:.1e} (largest entry {scale:.1e})"
        rows.append(_row("integration", "imu_learn.preintegrate", m, n, "samples", note))
    for scan in ("doubling", "blocked"):
        m = measure(lambda scan=scan: nr.preintegrate(t, gyro, acc, scan), repeats)
        rows.append(_row("integration", f"numpy ({scan} scan)", m, n, "samples", SCAN_NOTES[scan]))
    try:
        import gtsam
    except ImportError:
        return rows
    params = gtsam.PreintegrationParams.MakeSharedU(GRAVITY)
    params.setGyroscopeCovariance(np.eye(3) * 1e-6)
    params.setAccelerometerCovariance(np.eye(3) * 1e-4)
    params.setIntegrationCovariance(np.eye(3) * 1e-8)
    bias = gtsam.imuBias.ConstantBias()
    hold = (np.diff(t) * 1e-9).tolist()
    # Rows of numpy arrays, built outside the timed loop: the loop is the per-sample call users make.
    gyro_rows, acc_rows = list(gyro[:-1]), list(acc[:-1])

    def run_gtsam():
        pim = gtsam.PreintegratedImuMeasurementsManifold(params, bias)
        for a, w, h in zip(acc_rows, gyro_rows, hold):
            pim.integrateMeasurement(a, w, h)
        return pim

    pim = run_gtsam()
    err = max(float(np.abs(pim.deltaVij() - ref[1][-1]).max()), float(np.abs(pim.deltaPij() - ref[2][-1]).max()))
    m = measure(run_gtsam, gtsam_repeats)
    rows.append(
        _row(
            "integration", "GTSAM Manifold, Python loop", m, n, "samples",
            f"integrateMeasurement per sample (also propagates the 9x9 covariance); final \\|gtsam − numpy\\| = {err:.1e}",
        )
    )
    return rows


def bench_labels(seqs: List[tuple], have_core: bool, repeats: int) -> List[Row]:
    n_windows = sum(max(len(s[0]) - WINDOW, 0) for s in seqs)
    rows: List[Row] = []

    def run_numpy():
        return [nr.window_labels(s[0], s[3], s[4], s[5], WINDOW, STRIDE, FRACTIONS, GRAVITY) for s in seqs]

    if have_core:
        from imu_learn import _imu_core as core
        def run_core():
            return [core.window_labels(s[0], s[3], s[4], s[5], WINDOW, STRIDE, list(FRACTIONS), GRAVITY) for s in seqs]

        err = max(
            float(np.abs(c[k] - r[k]).max())
            for c, r in zip(run_core(), run_numpy())
            for k in ("dq_wxyz", "dv", "dp", "dt")
        )
        m = measure(run_core, repeats)
        note = f"max \\|core − numpy\\| = {err:.1e}"
        rows.append(_row("labels", "imu_learn.window_labels", m, n_windows, "windows", note))
    m = measure(run_numpy, repeats)
    rows.append(_row("labels", "numpy (fancy indexing)", m, n_windows, "windows"))
    return rows


def bench_batches(seqs: List[tuple], have_core: bool, repeats: int, per_repeat: int) -> List[Row]:
    rows: List[Row] = []
    n = BATCH * per_repeat
    note = f"{per_repeat} batches of {BATCH} x {WINDOW} per repeat, noise + bias"
    if have_core:
        import imu_learn
        from imu_learn import AugmentConfig, BatchConfig, BatchSampler
        parts = [imu_learn.Segment(f"s{i}", *s) for i, s in enumerate(seqs)]
        sampler = BatchSampler(parts, BatchConfig(window=WINDOW, batch_size=BATCH, augment=AugmentConfig(**AUGMENT)))
        seed = iter(range(10**9))
        m = measure(lambda: [sampler.sample(next(seed)) for _ in range(per_repeat)], repeats)
        rows.append(_row("batches", "imu_learn.BatchSampler.sample", m, n, "windows", note))
    ss = nr.SequenceSet(seqs)
    seed2 = iter(range(10**9))
    m = measure(
        lambda: [ss.make_batch(WINDOW, BATCH, FRACTIONS, GRAVITY, next(seed2), **AUGMENT) for _ in range(per_repeat)],
        repeats,
    )
    rows.append(_row("batches", "numpy make_batch", m, n, "windows", note))
    return rows


def bench_csv(path: Path, have_core: bool, repeats: int) -> List[Row]:
    rows: List[Row] = []
    size_mb = path.stat().st_size / 1e6
    with open(path, "rb") as f:
        n_rows = sum(1 for line in f if line.strip() and not line.startswith(b"#"))
    note = f"{path.parent.parent.parent.name} imu0/data.csv, {size_mb:.2f} MB"

    if have_core:
        from imu_learn import _imu_core as core
        m = measure(lambda: core.read_asl_imu(str(path)), repeats)
        rows.append(_row("csv", "imu_learn._imu_core.read_asl_imu", m, n_rows, "rows", note))
    try:
        import polars as pl
    except ImportError:
        return rows

    def run_polars():
        df = pl.read_csv(path)
        t = df[:, 0].to_numpy()
        x = df[:, 1:7].to_numpy()
        return t, np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:])

    t_pl = run_polars()[0]
    assert t_pl.dtype == np.int64 and len(t_pl) == n_rows, (t_pl.dtype, len(t_pl), n_rows)
    m = measure(run_polars, repeats)
    rows.append(_row("csv", "polars.read_csv -> numpy", m, n_rows, "rows", note))
    for r in rows:
        r["mb"] = size_mb
    return rows


# ------------------------------------------------------------------------------------------------
# report
# ------------------------------------------------------------------------------------------------


def _rate(x: float) -> str:
    for div, suf in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if x >= div:
            return f"{x / div:.2f} {suf}"
    return f"{x:.1f} "


def _ms(s: float) -> str:
    return f"{s * 1e3:.2f} ms" if s < 10 else f"{s:.2f} s"


def print_table(rows: List[Row]) -> None:
    print("| task | implementation | items | median (min–max, n) | throughput | note |")
    print("|---|---|---:|---|---:|---|")
    for r in rows:
        m = r["m"]
        rate = r["items"] / m["median"]
        thr = f"{_rate(rate)}{r['unit']}/s"
        if "mb" in r:
            thr += f", {r['mb'] / m['median']:.1f} MB/s"
        span = f"{_ms(m['median'])} ({_ms(m['min'])}–{_ms(m['max'])}, {m['n']})"
        print(f"| {r['task']} | {r['impl']} | {r['items']:,} | {span} | {thr} | {r['note']} |")


def speedups(rows: List[Row]) -> None:
    by: Dict[str, Dict[str, float]] = {}
    for r in rows:
        by.setdefault(str(r["task"]), {})[str(r["impl"])] = r["m"]["median"]
    # The fairest numpy figure for integration is the faster of its two scans, measured now.
    integ = by.get("integration", {})
    scans = [k for k in integ if k.startswith("numpy (")]
    best = min(scans, key=lambda k: integ[k]) if scans else "numpy (doubling scan)"
    pairs = [
        ("integration", "imu_learn.preintegrate", best, f"core / {best}"),
        ("integration", "imu_learn.preintegrate", "GTSAM Manifold, Python loop", "core / GTSAM loop"),
        ("integration", best, "GTSAM Manifold, Python loop", f"{best} / GTSAM loop"),
        ("labels", "imu_learn.window_labels", "numpy (fancy indexing)", "core / numpy"),
        ("batches", "imu_learn.BatchSampler.sample", "numpy make_batch", "core / numpy"),
        ("csv", "imu_learn._imu_core.read_asl_imu", "polars.read_csv -> numpy", "core / polars"),
    ]
    print("\n| task | ratio | speed-up (median time of the slower / the faster named first) | target | met |")
    print("|---|---|---:|---:|---|")
    for task, fast, slow, label in pairs:
        t = by.get(task, {})
        if fast not in t or slow not in t:
            continue
        s = t[slow] / t[fast]
        target = TARGETS.get(task) if label.startswith("core /") and "GTSAM" not in label else None
        if task == "integration" and fast != "imu_learn.preintegrate":
            target = None
        tgt = f"≥ {target:g}×" if target else "—"
        met = ("yes" if s >= target else "NO") if target else "—"
        print(f"| {task} | {label} | {s:.1f}× | {tgt} | {met} |")


def main(argv: Optional[List[str]] = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repeats (a smoke run; figures are noisier)")
    ap.add_argument(
        "--data", type=Path, default=REPO / "datasets" / "euroc", help="folder holding MH_01_easy, V1_01_easy"
    )
    ap.add_argument("--only-reference", action="store_true", help="time numpy / GTSAM / polars only (no compiled core)")
    ap.add_argument("--repeats", type=int, default=None, help="repeats per figure (default 7, --quick 3)")
    args = ap.parse_args(argv)

    have_core = False
    if not args.only_reference:
        try:
            import imu_learn  # noqa: F401

            have_core = True
        except ImportError as e:
            print(f"imu_learn not importable ({e}); timing the references only.", file=sys.stderr)
    repeats = args.repeats or (3 if args.quick else 7)
    gtsam_repeats = max(1, min(repeats, 2 if args.quick else 3))
    per_repeat = 2 if args.quick else 8

    data = args.data.resolve()
    t, gyro, acc = load_imu(imu_csv(data, SEQUENCES[0]), have_core)
    seqs = load_sequences(data, have_core)

    print(f"# imu_core benchmark ({'quick' if args.quick else 'full'} run, data: {data})\n")
    print("\n".join(machine_lines(have_core)))
    print(
        f"- inputs: integration on {SEQUENCES[0]} IMU ({len(t):,} samples, one call); labels on "
        f"{len(seqs)} aligned sequence(s) ({sum(len(s[0]) for s in seqs):,} samples; window {WINDOW}, "
        f"stride {STRIDE}, {len(FRACTIONS)} horizons); batches B={BATCH}, W={WINDOW}, augment {AUGMENT}"
    )
    print(f"- numpy is single-threaded here (elementwise ufuncs; OPENBLAS/OMP threads pinned to 1 so BLAS "
          f"helpers do not steal a core); the core uses rayon on {os.environ.get('RAYON_NUM_THREADS') or os.cpu_count()} "
          "threads for integration (a chunked scan), labels, batches and parsing.\n")

    rows: List[Row] = []
    rows += bench_integration(t, gyro, acc, have_core, repeats, gtsam_repeats)
    rows += bench_labels(seqs, have_core, repeats)
    rows += bench_batches(seqs, have_core, repeats, per_repeat)
    rows += bench_csv(imu_csv(data, SEQUENCES[0]), have_core, repeats)
    print_table(rows)
    speedups(rows)
    if not have_core:
        print("\n(core not timed: no core/numpy ratios or targets; run without --only-reference after `just dev`.)")


if __name__ == "__main__":
    main()
