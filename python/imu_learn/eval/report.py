"""The evaluation report: CSV tables (polars), PNG plots (matplotlib), ``report.md``, a terminal summary,
and the quoted (published, NOT measured here) figures the results are compared against.

Everything here formats the result dict that :func:`imu_learn.evaluate.run_evaluation` builds;
nothing is computed from data. The report's files go into the output folder together (:func:`write_report`).
"""
from __future__ import annotations

import json
import math
from datetime import datetime
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

from imu_learn.score.peers import PEER_KEYS
from imu_learn.score.protocol import (
    FLOOR_METHODS,
    PROTOCOL,
    REFERENCE_METHODS,
    VARIANT_LABELS,
    VARIANT_SHORT,
    VARIANTS,
)
from imu_learn.util.atomic import atomic_write_bytes, atomic_write_text
from imu_learn.util.extras import require
from imu_learn.util.outputs import check_replaceable
from imu_learn.util.staging import staged_dir

# ---------------------------------------------------------------------------------------------
# quoted figures (copied from publications; never our measurements)

# Named by its public citation (README, "Citation"), never by where a copy lies on some machine.
PAPER_SOURCE = ("the reproduced paper (M. Zhang, M. Zhang, Y. Chen and M. Li, *IMU Data Processing for "
                "Inertial Aided Navigation: A Recurrent Neural Network Based Approach*), Table II "
                "(label table:delta_pose_error): RMSE in relative translation (m) / orientation (rad) "
                "over ten IMU frames, EuRoC")
PAPER_TABLE2_SEQUENCES = ["MH_02_easy", "MH_04_difficult", "V1_03_difficult", "V2_02_medium", "V1_01_easy", "Average"]
PAPER_TABLE2_METHODS = ["Tr.", "Gyro-Denoising", "TLIO", "End-to-End learning", "Pr."]
# (translation m, rotation rad); None where the paper prints "-" (Gyro-Denoising predicts no position).
PAPER_TABLE2: Dict[str, Dict[str, Tuple[Optional[float], float]]] = {
    "MH_02_easy": {"Tr.": (0.0108, 0.0093), "Gyro-Denoising": (None, 0.0060), "TLIO": (0.0053, 0.0045),
                   "End-to-End learning": (0.0077, 0.0072), "Pr.": (0.0028, 0.0025)},
    "MH_04_difficult": {"Tr.": (0.0237, 0.0103), "Gyro-Denoising": (None, 0.0061), "TLIO": (0.0078, 0.0058),
                        "End-to-End learning": (0.0092, 0.0078), "Pr.": (0.0058, 0.0037)},
    "V1_03_difficult": {"Tr.": (0.0189, 0.0168), "Gyro-Denoising": (None, 0.0051), "TLIO": (0.0151, 0.0099),
                        "End-to-End learning": (0.0130, 0.0107), "Pr.": (0.0053, 0.0067)},
    "V2_02_medium": {"Tr.": (0.0191, 0.0130), "Gyro-Denoising": (None, 0.0118), "TLIO": (0.0127, 0.0083),
                     "End-to-End learning": (0.0131, 0.0122), "Pr.": (0.0083, 0.0068)},
    "V1_01_easy": {"Tr.": (0.0118, 0.0234), "Gyro-Denoising": (None, 0.0168), "TLIO": (0.0053, 0.0181),
                   "End-to-End learning": (0.0075, 0.0219), "Pr.": (0.0030, 0.0162)},
    "Average": {"Tr.": (0.0169, 0.0146), "Gyro-Denoising": (None, 0.0092), "TLIO": (0.0092, 0.0093),
                "End-to-End learning": (0.0101, 0.0120), "Pr.": (0.0050, 0.0072)},
}

AIRIMU_NOTE = (
    "AirIMU (Qiu et al., arXiv:2310.04874, https://airimu.github.io/) publishes EuRoC figures (1 s "
    "rotation / position RMSE, position RMSE over 0.5-3 s), but their numbers could NOT be retrieved "
    "with the search tools available when this report module was written (only the papers' opening "
    "sections were reachable: ar5iv.labs.arxiv.org/html/2310.04874, arxiv.org/html/2310.04874v4, "
    "airimu.github.io, github.com/haleqiu/AirIMU README). No AirIMU number is quoted here; our "
    "AirIMU-style columns are our own measurements with AirIMU's definitions, not theirs."
)


def quotes_euroc(result: Optional[Dict[str, Any]]) -> bool:
    """Whether the run's recordings are EuRoC's (the paper's Table II quotes EuRoC flights only); a result
    without its roots (older ones) is taken as EuRoC's, as before."""
    formats = {str(r.get("format", "")).lower() for r in (result or {}).get("roots") or []}
    return not formats or formats <= {"euroc", "asl"}


def quoted_rows(result: Optional[Dict[str, Any]] = None) -> List[Dict[str, Any]]:
    """The paper's Table II as rows, each marked as quoted (none for a run on another dataset)."""
    if not quotes_euroc(result):
        return []
    out = []
    for seq in PAPER_TABLE2_SEQUENCES:
        for m in PAPER_TABLE2_METHODS:
            t, r = PAPER_TABLE2[seq][m]
            out.append({"source": "quoted: paper Table II (not measured here)", "dataset": "EuRoC", "sequence": seq,
                        "method": m, "n_imu_samples": 10, "trans_m": t, "rot_rad": r})
    return out


def quoted_section(result: Optional[Dict[str, Any]] = None) -> str:
    if not quotes_euroc(result):
        formats = sorted({str(r.get("format", "")) for r in result["roots"]})
        return "\n".join(["## Quoted figures (published; NOT measured here)", "",
                          f"The paper's Table II quotes EuRoC flights; this run's recordings are {', '.join(formats)}: "
                          "nothing to quote beside them.", "", f"**AirIMU:** {AIRIMU_NOTE}", ""])
    head = "| Sequence (paper's test set) | " + " | ".join(PAPER_TABLE2_METHODS) + " |"
    lines = [
        "## Quoted figures (published; NOT measured here)",
        "",
        f"**Quoted** from {PAPER_SOURCE}. The paper's test sequences are the five below (its own "
        "train/test split of EuRoC, \"randomly chose half of the sequences\"); they are not our test "
        "split, so these numbers are for orientation only and are not comparable cell by cell. "
        "Format: translation [m] / rotation [rad]; \"-\": the method gives no position.",
        "",
        head,
        "|" + "---|" * (len(PAPER_TABLE2_METHODS) + 1),
    ]
    for seq in PAPER_TABLE2_SEQUENCES:
        cells = []
        for m in PAPER_TABLE2_METHODS:
            t, r = PAPER_TABLE2[seq][m]
            cells.append(f"{'-' if t is None else f'{t:.4f}'} / {r:.4f}")
        lines.append(f"| {seq.replace('_', chr(92) + '_')} (quoted) | " + " | ".join(cells) + " |")
    lines += ["", f"**AirIMU:** {AIRIMU_NOTE}", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# tables from the result


def _mean(xs: List[float]) -> float:
    xs = [x for x in xs if x is not None and not (isinstance(x, float) and math.isnan(x))]
    return sum(xs) / len(xs) if xs else float("nan")


def _index(result: Dict[str, Any]) -> Dict[Tuple[str, str, str, int], Dict[str, Any]]:
    return {(r["method"], r["variant"], r["sequence"], int(r["n"])): r for r in result["rows"]}


def relative_pose_table(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    """Rows (method, variant, sequence incl. "average", n) for the configured horizons."""
    idx = _index(result)
    out = []
    for m in result["methods"]:
        for v in VARIANTS:
            for n in result["eval"]["horizons"]:
                per = [idx[(m, v, s, int(n))] for s in result["test_sequences"] if (m, v, s, int(n)) in idx]
                for r in per:
                    out.append({k: r[k] for k in ("method", "variant", "sequence", "n", "horizon_s", "trans_m", "rot_rad",
                                                  "rot_deg", "vel_mps", "windows")})
                if per:
                    out.append({"method": m, "variant": v, "sequence": "average", "n": int(n),
                                "horizon_s": _mean([r["horizon_s"] for r in per]),
                                **{k: _mean([r[k] for r in per]) for k in ("trans_m", "rot_rad", "rot_deg", "vel_mps")},
                                "windows": sum(r["windows"] for r in per)})
    return out


def _at_seconds(result: Dict[str, Any], idx, m: str, v: str, seq: str, s: float) -> Optional[Dict[str, Any]]:
    by_s = result["horizons_by_s"].get(seq, {})
    n = by_s.get(float(s), by_s.get(str(float(s))))
    return None if n is None else idx.get((m, v, seq, int(n)))


def airimu_table(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    idx = _index(result)
    secs = sorted(set(float(x) for x in result["eval"]["airimu_s"]) | {1.0})
    out = []
    for m in result["methods"]:
        for v in VARIANTS:
            per = []
            for seq in result["test_sequences"]:
                r1 = _at_seconds(result, idx, m, v, seq, 1.0)
                if r1 is None:
                    continue
                row = {"method": m, "variant": v, "sequence": seq, "rot_1s_deg": r1["rot_deg"], "rot_1s_rad": r1["rot_rad"]}
                for s in secs:
                    r = _at_seconds(result, idx, m, v, seq, s)
                    row[f"pos_{s:g}s_m"] = float("nan") if r is None else r["trans_m"]
                per.append(row)
            out += per
            if per:
                avg = {"method": m, "variant": v, "sequence": "average"}
                for k in per[0]:
                    if k not in avg:
                        avg[k] = _mean([p[k] for p in per])
                out.append(avg)
    return out


def curve_table(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    idx = _index(result)
    out = []
    for m in result["methods"]:
        for v in VARIANTS:
            for s in result["curve_s"]:
                per = []
                for seq in result["test_sequences"]:
                    r = _at_seconds(result, idx, m, v, seq, s)
                    if r is not None:
                        per.append({"method": m, "variant": v, "sequence": seq, "horizon_s": s, "n": r["n"],
                                    "pos_m": r["trans_m"], "rot_rad": r["rot_rad"], "rot_deg": r["rot_deg"],
                                    "vel_mps": r["vel_mps"], "windows": r["windows"]})
                out += per
                if per:
                    out.append({"method": m, "variant": v, "sequence": "average", "horizon_s": s,
                                "n": per[0]["n"] if len({p["n"] for p in per}) == 1 else -1,
                                **{k: _mean([p[k] for p in per]) for k in ("pos_m", "rot_rad", "rot_deg", "vel_mps")},
                                "windows": sum(p["windows"] for p in per)})
    return out


def _write_csv(path: Path, rows: List[Dict[str, Any]]) -> None:
    pl = require("polars", "eval", "the report's tables")
    if not rows:
        atomic_write_text(path, "")
        return
    cols: List[str] = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    data = {c: [r.get(c) for r in rows] for c in cols}
    frame = pl.DataFrame(data, strict=False)
    atomic_write_bytes(path, frame.write_csv)


# ---------------------------------------------------------------------------------------------
# plots


def write_png(path: Path, fig: Any, dpi: int) -> None:
    atomic_write_bytes(path, lambda f: fig.savefig(f, format="png", dpi=dpi))


def plot_curves(result: Dict[str, Any], curves: List[Dict[str, Any]], out_dir: Path) -> List[str]:
    """One PNG per variant: position / rotation / velocity RMSE against horizon, log-log, a curve per method."""
    matplotlib = require("matplotlib", "eval", "the report's plots")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    avg = [c for c in curves if c["sequence"] == "average"]
    seqs = ", ".join(result["test_sequences"])
    for v in VARIANTS:
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
        for ax, (key, label) in zip(axes, (("pos_m", "position RMSE [m]"), ("rot_rad", "rotation RMSE [rad]"),
                                           ("vel_mps", "velocity RMSE [m/s]"))):
            for m in result["methods"]:
                pts = [(c["horizon_s"], c[key]) for c in avg if c["method"] == m and c["variant"] == v]
                pts = [(x, y) for x, y in pts if y is not None and not math.isnan(y) and y > 1e-10]
                if not pts:
                    continue
                style = "--" if m.startswith("ground truth") else "-"
                ax.plot([p[0] for p in pts], [p[1] for p in pts], style, marker="o", ms=3, label=m)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("integration horizon [s]")
            ax.set_ylabel(label)
            ax.grid(True, which="both", alpha=0.3)
        handles, labels = axes[0].get_legend_handles_labels()
        for ax in axes[1:]:
            for h, lab in zip(*ax.get_legend_handles_labels()):
                if lab not in labels:
                    handles.append(h)
                    labels.append(lab)
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=9, frameon=False)
        fig.suptitle(f"{result['config_name']}: integration error vs horizon, {VARIANT_LABELS[v]} "
                     f"(test: {seqs}; mean over sequences)", fontsize=10)
        fig.tight_layout(rect=(0, 0.1, 1, 0.95))
        name = f"integration_error_{v}.png"
        write_png(out_dir / name, fig, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


# ---------------------------------------------------------------------------------------------
# markdown


def _f(x: Any, fmt: str = "{:.4f}") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if isinstance(x, float) and x != 0 and (abs(x) < 1e-4 or abs(x) >= 1e4):
        return f"{x:.2e}"
    return fmt.format(x)


def _md_table(head: List[str], rows: List[List[str]]) -> List[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def _esc(s: str) -> str:
    return s.replace("_", "\\_").replace("|", "\\|")


def protocol_text() -> str:
    return PROTOCOL.strip()


def _md_head(r: Dict[str, Any]) -> List[str]:
    return [f"# Evaluation report: {r['config_name']}", "",
            f"Written {datetime.now().strftime('%Y-%m-%d %H:%M:%S')} by `imu-learn evaluate`"
            f"{' --config ' + r['config_path'] if r.get('config_path') else ''}; "
            f"wall time **{r['wall_s']:.1f} s** (from the start of the command to writing this report; "
            "fitting included, imports not).", "",
            "All numbers in the tables below are **our measurements** unless marked *quoted*.", "",
            "## Protocol", "", protocol_text(), ""]


def _md_data(r: Dict[str, Any]) -> List[str]:
    L = ["## Data and split", "",
         f"Fit config: `{r.get('base_path') or 'built-in defaults'}`; gravity {r['gravity']} m/s²; "
         f"windows every {r['stride']} samples from {r['startup_bias_s']:g} s on; start-up bias fitted on the "
         f"first {r['startup_bias_s']:g} s.", "",
         f"Data roots (relative paths from the data root `{r['data_root']}`):" if r.get("data_root")
         else "Data roots:", ""]
    for root in r["roots"]:
        L.append(f"- `{root['path']}` ({root['format']}{', ground truth ' + root['groundtruth'] if root.get('groundtruth') else ''})")
    L.append("")
    rows = []
    for split in ("train", "val", "test"):
        for e in r["split"].get(split, []):
            segs = e.get("segments", [])
            used = [s for s in segs if s.get("used", True)]
            rows.append([split, _esc(e["entry"]), str(len(used)), f"{sum(s['duration_s'] for s in used):.1f}",
                         _esc(r["ground_truth"].get(e["recording"], "")) if split == "test" else ""])
    L += _md_table(["split", "entry", "segments", "duration [s]", "ground truth"], rows) + [""]
    L += ["Test sampling rate: " + ", ".join(f"{_esc(k)} {v:.1f} Hz" for k, v in r["rates_hz"].items()), ""]
    return L


def _md_versions(r: Dict[str, Any]) -> List[str]:
    return ["## Versions, seeds, fit budget", "",
            "Versions: " + ", ".join(f"{k} {v}" for k, v in r["versions"].items()) + ".", "",
            f"Seed: {r['seed']} (numpy, torch and `FitSettings.seed`; set before each method's fit).", "",
            "FitSettings (the same for every method): " + ", ".join(f"{k}={v}" for k, v in r["fit_settings"].items()) + ".", ""]


def _md_methods(r: Dict[str, Any]) -> List[str]:
    rows = []
    for m in r["methods"]:
        rec = r["records"].get(m, {})
        rows.append([_esc(m), rec.get("status", ""), _f(rec.get("fit_s"), "{:.1f}"), _f(rec.get("eval_s"), "{:.1f}"),
                     f"`{rec['file']}`" if rec.get("file") else "-"])
    L = ["## Methods", ""] + _md_table(["method", "status", "fit [s]", "evaluation [s]", "saved / loaded from"], rows) + [""]
    if r["skipped"]:
        L += [f"Skipped (module not available): {', '.join(r['skipped'])}.", ""]
    if any(m.startswith("ground truth") for m in r["methods"]):
        L += ["\"ground truth (noise floor)\" is not a method: the IMU synthesised from the test ground truth "
              "itself (`imu_learn.baselines.noise_floor`). Its rotation and velocity errors are zero by construction; its "
              "position error is the disagreement between the ground-truth positions and the (derived) "
              "ground-truth velocities, i.e. label noise that no method can beat.", ""]
    return L


def _md_relative_pose(r: Dict[str, Any], rel: List[Dict[str, Any]]) -> List[str]:
    """The paper's Table II analogue at the first horizon, then every horizon's average."""
    n0 = int(r["eval"]["horizons"][0])
    seqs = r["test_sequences"] + ["average"]
    idx = {(x["method"], x["variant"], x["sequence"], x["n"]): x for x in rel}
    L = ["## Relative pose RMSE over n IMU samples (paper Table II analogue)", ""]
    for v in VARIANTS:
        L += [f"**{VARIANT_LABELS[v]}**, n = {n0} samples, translation [m] / rotation [rad]:", ""]
        rows = []
        for s in seqs:
            cells = []
            for m in r["methods"]:
                x = idx.get((m, v, s, n0))
                cells.append("-" if x is None else f"{_f(x['trans_m'])} / {_f(x['rot_rad'])}")
            rows.append([_esc(s)] + cells)
        L += _md_table(["sequence"] + [_esc(m) for m in r["methods"]], rows) + [""]
    L += ["All horizons, mean over test recordings (translation [m] / rotation [rad] / rotation [deg]):", ""]
    head = ["method", "variant"] + [f"n={n}" for n in r["eval"]["horizons"]]
    rows = []
    for m in r["methods"]:
        for v in VARIANTS:
            cells = []
            for n in r["eval"]["horizons"]:
                x = idx.get((m, v, "average", int(n)))
                cells.append("-" if x is None else f"{_f(x['trans_m'])} / {_f(x['rot_rad'])} / {_f(x['rot_deg'], '{:.3f}')}")
            rows.append([_esc(m), VARIANT_LABELS[v]] + cells)
    return L + _md_table(head, rows) + [""]


def _md_airimu(r: Dict[str, Any], air: List[Dict[str, Any]]) -> List[str]:
    secs = sorted(set(float(x) for x in r["eval"]["airimu_s"]) | {1.0})
    L = ["## AirIMU-style figures (our measurements, AirIMU's definitions)", "",
         "Mean over test recordings: rotation RMSE over 1 s [deg] and [rad], position RMSE over "
         + ", ".join(f"{s:g}" for s in secs) + " s [m] (per recording: `airimu_figures.csv`):", ""]
    head = ["method", "variant", "rot 1 s [deg]", "rot 1 s [rad]"] + [f"pos {s:g} s [m]" for s in secs]
    rows = []
    for a in air:
        if a["sequence"] != "average":
            continue
        rows.append([_esc(a["method"]), VARIANT_LABELS[a["variant"]], _f(a["rot_1s_deg"], "{:.3f}"), _f(a["rot_1s_rad"])]
                    + [_f(a.get(f"pos_{s:g}s_m")) for s in secs])
    return L + _md_table(head, rows) + [""]


def _md_curves(r: Dict[str, Any], pngs: List[str]) -> List[str]:
    L = ["## Integration error against horizon (paper's integration-error figure)", "",
         f"{len(r['curve_s'])} log-spaced horizons from {r['curve_s'][0]:g} s to {r['curve_s'][-1]:g} s; "
         "RMSE of position, rotation and velocity, mean over test recordings (values at or below 1e-10, "
         "e.g. the noise floor's rotation and velocity, are not drawn). Numbers: `integration_error.csv`.", ""]
    for p in pngs:
        L += [f"![{p}]({p})", ""]
    return L


def _md_calibration(r: Dict[str, Any]) -> List[str]:
    if not r.get("calibration"):
        return []
    from imu_learn.eval.calibration import format_table as calibration_table

    return ["## Calibration of the increments' covariance", "",
            "Residual (δθ, δβ, δγ) of the increments over n samples against ground truth (start-up bias "
            "removed), normalised by the covariance propagated from per-sample noise: the datasheet's white "
            f"noise ({r['eval'].get('gyro_noise_density')} rad/s/√Hz, {r['eval'].get('acc_noise_density')} "
            "m/s²/√Hz) or the checkpoint's learned variances. A calibrated covariance has mean NEES = dof and "
            "the χ² fractions inside its 1σ/2σ/3σ ellipsoids (in brackets); above dof is overconfident, "
            "below underconfident.", ""] + calibration_table(r["calibration"]) + [""]


def peers_table(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    """The peers' open-loop rows per (method, recording), then each method's mean over recordings."""
    rows = list(result.get("peers") or [])
    out: List[Dict[str, Any]] = []
    for m in result["methods"]:
        per = [x for x in rows if x["method"] == m]
        out += per
        if len(per) > 1:
            out.append({"method": m, "sequence": "average", **{k: _mean([p[k] for p in per]) for k in PEER_KEYS},
                        "window_samples": per[0]["window_samples"] if len({p["window_samples"] for p in per}) == 1 else -1,
                        "segments": sum(p["segments"] for p in per), "samples": sum(p["samples"] for p in per),
                        "windows": sum(p["windows"] for p in per)})
    return out


def _md_peers(r: Dict[str, Any], peers: List[Dict[str, Any]]) -> List[str]:
    if not peers:
        return []
    L = ["## The peers' protocols, open loop (AOE; AirIMU's 1 s ROE / RTE)", "",
         "Open loop: each method's samples as they are (no bias removed), integrated from the ground-truth "
         "initial state (`imu_learn.score.peers`). AOE / yaw AOE: RMSE over every sample of the recording of "
         "the orientation (yaw) error of the gyro integrated from the ground-truth orientation at the "
         "first sample (Brossard et al. 2020); \"AOE mean\": the mean of that angle instead, which is what "
         "AirIMU's evaluation code reports as AOE; a recording with gaps is scored per gap-free segment, each "
         "from its own ground-truth start, samples pooled. ROE / RO_RMSE, RTE / RP_RMSE: mean / RMSE over "
         "non-overlapping consecutive 1 s windows (round(rate) samples) from sample 0, each from the "
         "ground-truth state (p, v, R) at its first sample (AirIMU's protocol). \"-\": the method gives no such "
         "output (regressors: no whole-recording attitude; rotation-only methods: no position). Numbers: "
         "`peers.csv`.", ""]
    rows = [[_esc(x["method"]), _esc(x["sequence"]), _f(x["aoe_deg"], "{:.2f}"), _f(x["aoe_mean_deg"], "{:.2f}"),
             _f(x["yaw_aoe_deg"], "{:.2f}"),
             _f(x["roe_deg"], "{:.3f}"), _f(x["ro_rmse_deg"], "{:.3f}"), _f(x["rte_m"], "{:.3f}"),
             _f(x["rp_rmse_m"], "{:.3f}"), str(x["windows"])] for x in peers]
    head = ["method", "recording", "AOE [deg]", "AOE mean [deg]", "yaw AOE [deg]", "ROE 1 s [deg]", "RO_RMSE 1 s [deg]",
            "RTE 1 s [m]", "RP_RMSE 1 s [m]", "windows"]
    return L + _md_table(head, rows) + [""]


def _md_floor(r: Dict[str, Any]) -> List[str]:
    floor = floor_table(r)
    if not floor:
        return []
    L = ["## Learned methods (and shipped profiles) against the floor", "",
         "Each learned method's (and each `profile:` method's) error over the best of the simple methods in this run (" +
         ", ".join(f"`{m}`" for m in r["methods"] if m in FLOOR_METHODS) + ": raw IMU, a fitted time offset, "
         "an affine calibration, both; `zero-displacement`: the device stays put), per cell, mean over the test recordings; below 1 the learning pays.", ""]
    rows = [[_esc(x["method"]), VARIANT_SHORT[x["variant"]], str(x["n"]), "rot" if x["term"] == "rot_rad" else "trans",
             _f(x["ratio"], "{:.3f}"), _esc(x["floor"])] for x in floor]
    return L + _md_table(["method", "variant", "n", "term", "method / best floor", "best floor"], rows) + [""]


def _md_biases(r: Dict[str, Any]) -> List[str]:
    rows = []
    for b in r["biases"]:
        rows.append([_esc(b["method"]), _esc(b["segment"]), b["fitted_on"],
                     ", ".join(_f(b[f"gyro_bias_{a}"], "{:.5f}") for a in "xyz"),
                     ", ".join(_f(b[f"acc_bias_{a}"], "{:.4f}") for a in "xyz")])
    L = ["## Start-up biases (first seconds of each test segment, against ground truth)", ""]
    return L + _md_table(["method", "segment", "fitted on", "gyro [rad/s]", "acc [m/s²]"], rows) + [""]


def markdown(result: Dict[str, Any], rel: List[Dict[str, Any]], air: List[Dict[str, Any]],
             pngs: List[str], csvs: List[str]) -> str:
    """``report.md``: one section after another, each built from ``result`` by its own function."""
    r = result
    L = (_md_head(r) + _md_data(r) + _md_versions(r) + _md_methods(r) + _md_relative_pose(r, rel)
         + _md_floor(r) + _md_airimu(r, air) + _md_peers(r, peers_table(r)) + _md_curves(r, pngs) + _md_calibration(r) + _md_biases(r) + [quoted_section(r)])
    L += ["## Files", ""] + [f"- `{c}`" for c in csvs + pngs] + ["- `methods/`: fitted methods and their fit records", ""]
    return "\n".join(L)


CSV_NAMES = ("relative_pose.csv", "airimu_figures.csv", "integration_error.csv", "errors_all_horizons.csv",
             "startup_bias.csv", "peers.csv", "quoted_paper_table2.csv")
# every file a report holds (methods/, the fitted methods' cache that --reuse reads, is not the report's)
REPORT_NAMES = CSV_NAMES + ("result.json", "report.md") + tuple(f"integration_error_{v}.png" for v in VARIANTS)


def is_result(path: Path) -> bool:
    """Whether the file ``path`` is an evaluation's ``result.json`` (a JSON object with the result's
    ``config_name``, ``methods`` and ``eval``, which every report has written)."""
    try:
        saved = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return (isinstance(saved, dict) and "config_name" in saved and isinstance(saved.get("methods"), list)
            and isinstance(saved.get("eval"), dict))


def check_out(out_dir: Path) -> None:
    """Before any work: each file of :data:`REPORT_NAMES` already in ``out_dir`` belongs to an earlier
    report (an evaluation's ``result.json`` is beside it), else the InvalidInputError naming it
    (:func:`imu_learn.util.outputs.check_replaceable`): a user's report.md or CSV is never replaced."""
    out_dir = Path(out_dir)
    own = is_result(out_dir / "result.json")

    def not_own(path: Path) -> Optional[str]:
        if own:
            return None
        return "not an evaluation's result" if path.name == "result.json" else "no evaluation result.json beside it"

    names = ["result.json"] + [n for n in REPORT_NAMES if n != "result.json"]  # the marker first
    check_replaceable([out_dir / name for name in names], not_own, "evaluate", "remove it or give --out a new folder")


def write_report(out_dir: Path, result: Dict[str, Any]) -> None:
    """Every file of the report into a staging folder, put in ``out_dir`` together at the end
    (:func:`imu_learn.util.staging.staged_dir`): an interrupted or failed rerun leaves the previous
    report whole (its CSVs never beside another run's report.md); methods/ is kept. A file of the
    report's names that an earlier report did not write is refused (:func:`check_out`; the command
    checks first, before fitting)."""
    check_out(out_dir)
    rel = relative_pose_table(result)
    air = airimu_table(result)
    curves = curve_table(result)
    csvs = dict(zip(CSV_NAMES, (rel, air, curves, result["rows"], result["biases"], peers_table(result), quoted_rows(result))))
    with staged_dir(Path(out_dir), REPORT_NAMES) as stage:
        for name, rows in csvs.items():
            _write_csv(stage / name, rows)
        pngs = plot_curves(result, curves, stage)
        atomic_write_text(stage / "result.json",
                          json.dumps({k: v for k, v in result.items() if k != "rows"}, indent=2, default=str))
        atomic_write_text(stage / "report.md", markdown(result, rel, air, pngs, list(csvs) + ["result.json"]))


def floor_table(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    """Each learned method against the best floor method (:data:`FLOOR_METHODS` present in the run, and for a
    learned model every ``profile:PATH`` in it: the profile it sits on) per variant, horizon and term, on the
    mean over test recordings: ``ratio`` = method / best floor (below 1: learning pays), ``floor`` names the
    best floor method. Empty without a floor method."""
    rel = {(x["method"], x["variant"], x["n"]): x for x in relative_pose_table(result) if x["sequence"] == "average"}
    floors = [m for m in result["methods"] if m in FLOOR_METHODS]
    # a profile:PATH method is a floor that ships, judged against the run's floors as a learned method is; a
    # learned model is judged against those floors and against every profile in the run (the one it sits on)
    profiles = [m for m in result["methods"] if str(m).startswith("profile:")]
    learned = [m for m in result["methods"] if m not in FLOOR_METHODS and m not in REFERENCE_METHODS]
    out: List[Dict[str, Any]] = []
    for m in learned:
        floors_m = floors if m in profiles else floors + profiles
        for v in VARIANTS:
            for n in [int(h) for h in result["eval"]["horizons"]]:
                for key in ("rot_rad", "trans_m"):
                    mine = rel.get((m, v, n), {}).get(key, float("nan"))
                    cands = [(rel[(f, v, n)][key], f) for f in floors_m
                             if (f, v, n) in rel and math.isfinite(rel[(f, v, n)][key])]
                    if not cands or not math.isfinite(mine):
                        continue
                    best, name = min(cands)
                    out.append({"method": m, "variant": v, "n": n, "term": key, "value": mine, "floor": name,
                                "floor_value": best, "ratio": mine / best if best > 0 else float("nan")})
    return out


def summary_text(result: Dict[str, Any]) -> str:
    """A short table for the terminal: mean over test recordings."""
    rel = {(x["method"], x["variant"], x["n"]): x for x in relative_pose_table(result) if x["sequence"] == "average"}
    air = {(a["method"], a["variant"]): a for a in airimu_table(result) if a["sequence"] == "average"}
    hs = [int(n) for n in result["eval"]["horizons"]]
    n0, nl = hs[0], hs[-1]
    w = max([len(m) for m in result["methods"]] + [6])
    head = (f"{'method':<{w}}  {'variant':<12}  {f'n={n0} t[m]':>11}  {f'n={n0} r[deg]':>12}  "
            f"{f'n={nl} t[m]':>11}  {f'n={nl} r[deg]':>12}  {'1s rot[deg]':>11}  {'1s pos[m]':>10}")
    lines = [f"{result['config_name']}: test {', '.join(result['test_sequences'])}; mean over test recordings; "
             f"windows every {result['stride']} samples from {result['startup_bias_s']:g} s",
             head, "-" * len(head)]
    for m in result["methods"]:
        for v in VARIANTS:
            a, b, c = rel.get((m, v, n0)), rel.get((m, v, nl)), air.get((m, v))
            g = lambda d, k: _f(d[k]) if d else "-"  # noqa: E731
            lines.append(f"{m:<{w}}  {VARIANT_SHORT[v]:<12}  "
                         f"{g(a, 'trans_m'):>11}  {g(a, 'rot_deg'):>12}  {g(b, 'trans_m'):>11}  "
                         f"{(_f(b['rot_deg'], '{:.3f}') if b else '-'):>12}  "
                         f"{(_f(c['rot_1s_deg'], '{:.3f}') if c else '-'):>11}  {g(c, 'pos_1s_m'):>10}")
    peers = {x["method"]: x for x in peers_table(result) if x["sequence"] == "average"
             or len(result["test_sequences"]) == 1}
    if peers:
        lines.append("open loop, peers' protocols (mean over test recordings): AOE [deg] / RO_RMSE 1 s [deg] / "
                     "RP_RMSE 1 s [m]")
        for m in result["methods"]:
            x = peers.get(m)
            if x is not None:
                lines.append(f"{m:<{w}}  {_f(x['aoe_deg'], '{:.2f}'):>8} / {_f(x['ro_rmse_deg'], '{:.3f}'):>7} / "
                             f"{_f(x['rp_rmse_m'], '{:.3f}'):>6}")
    floor = floor_table(result)
    if floor:
        lines.append("learned (and profile:) / best floor (" + ", ".join(m for m in result["methods"] if m in FLOOR_METHODS)
                     + "), mean over test recordings; below 1 the learning (the profile) pays:")
        for m in dict.fromkeys(x["method"] for x in floor):
            for v in VARIANTS:
                cells = [f"{'rot' if x['term'] == 'rot_rad' else 'trans'} n={x['n']} {x['ratio']:.2f} ({x['floor']})"
                         for x in floor if x["method"] == m and x["variant"] == v]
                if cells:
                    lines.append(f"  {m:<{w}}  {VARIANT_SHORT[v]:<12}  " + ", ".join(cells))
    if result["skipped"]:
        lines.append(f"skipped (module not available): {', '.join(result['skipped'])}")
    lines.append(f"quoted for reference (paper Table II, EuRoC, its own test sequences, not ours): Pr. average "
                 f"{PAPER_TABLE2['Average']['Pr.'][0]} m / {PAPER_TABLE2['Average']['Pr.'][1]} rad over 10 samples")
    return "\n".join(lines)
