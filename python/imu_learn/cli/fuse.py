"""``imu-learn fuse``: IMU fused with aiding in a GTSAM factor graph (:mod:`imu_learn.fuse.run`), or
streamed sample by sample with ``--online`` (:mod:`imu_learn.fuse.online`); with ``--input`` a user's
recording navigated with its real aiding file, no ground truth (:mod:`imu_learn.fuse.navigate`)."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.cli.common import add_data_root, run_command
from imu_learn.errors import ConfigError

DESCRIPTION = """Fuse IMU inputs (raw, a calibration, a trained model's refinement) with aiding in a GTSAM
factor graph and score the trajectories against ground truth: every recording x input x aiding
scenario of a config, causal (iSAM2) and smoothed (batch LM). With --online, each recording is
streamed sample by sample instead (the causal model's step, preintegration, iSAM2 at keyframes)
and the per-sample latency and real-time factor are measured. Prints the file written.

With --input instead of --config: navigate one recording with its real aiding file (a camera
trajectory as relative or absolute poses, or position fixes), no ground truth needed: the first
state comes from the data (attitude levelled from the accelerometer, heading from the first pose,
position and velocity from the first aiding), under a loose prior. Writes causal.tum and
smoothed.tum (t tx ty tz qx qy qz qw, body = IMU frame), plot.png and summary.json to --out and
prints a one-line summary; --groundtruth only scores the result afterwards. GNSS/IMU logs (the
gnss-imu format) take --imu-rotation-rpy-deg, --imu-delay-s, --lever-arm and, on wheels, --nhc.

A config with kind = "gnss-outages" (configs/fuse_gnss_*.toml) runs the GNSS/IMU experiment with
simulated outages instead (imu_learn.fuse.gnss_run; --set KEY=JSON and --variants apply to it only)."""

EPILOG = """examples:
  imu-learn fuse --input <data>/euroc/MH_04_difficult --aiding <ORB-SLAM2 trajectory>.txt \
      --aiding-kind relative-pose --extrinsics <data>/euroc-vo/cam0_sensor.yaml \
      --checkpoint models/euroc_adis16448.pt --out out/MH_04
      a recording navigated with camera poses, no ground truth
      -> out/MH_04/{causal.tum,smoothed.tum,plot.png,summary.json}
  imu-learn fuse --config configs/fuse_euroc.toml --data-root <data root>
      every recording x input x aiding scenario of the config, causal and smoothed
      -> reports/fuse_euroc/{results.json,table.md,trajectories/,plots/}
  imu-learn fuse --config configs/fuse_gnss_drive.toml --data-root <data root> [--set nhc.sigma_lat=0.05] \\
      [--variants raw]
      a kind = "gnss-outages" config: the car drive (or the walk) with the peer's simulated 15 s GNSS
      outages, live and smoothed error against the withheld RTK fixes, one line per variant
      -> reports/fuse_gnss_drive/{results.json,table.md}
  imu-learn fit --config configs/euroc_paper.toml --data-root <data root> --name euroc_causal_s0 \\
      --model.causal true --model.fir_taps 0
      a causal checkpoint (runs/euroc_causal_s0/best.pt; about 3 min on one CPU core)
  imu-learn fuse --config configs/fuse_euroc.toml --data-root <data root> --online \\
      --checkpoint runs/euroc_causal_s0/best.pt --recordings V1_01_easy --scenarios gnss_1hz
      the recording as a stream (raw and the causal model's refinement), one line per run with the
      causal position RMSE, per-sample latency (median, p99) and real-time factor
      -> reports/fuse_euroc/online.json
"""

ONLINE_ONLY = ("checkpoint", "recordings", "scenarios")


def _names(text: str) -> List[str]:
    return [n.strip() for n in text.split(",") if n.strip()]


NAVIGATE_ONLY = ("format", "aiding", "aiding_kind", "aiding_format", "extrinsics", "groundtruth", "keyframe_hz",
                 "gaps", "aiding_hz", "sigma_rot_deg", "sigma_m", "max_relative_gap_s", "lag_s", "imu_rotation_rpy_deg",
                 "imu_delay_s", "lever_arm", "nhc", "imu_noise", "displacement", "calibration", "variance_scale")


def add_arguments(ap: argparse.ArgumentParser) -> None:
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--config", type=Path, metavar="TOML",
                      help="fusion config: recordings, IMU inputs, aiding scenarios (configs/fuse_*.toml)")
    mode.add_argument("--input", type=Path, metavar="REC",
                      help="navigate this recording (a folder or file the loaders read, e.g. an EuRoC ASL folder) "
                           "with --aiding; only its IMU is read, never its ground truth")
    add_navigate_arguments(ap)
    add_data_root(ap, "the config's recording paths")
    ap.add_argument("--out", type=Path, default=None, metavar="DIR",
                    help="report folder (default <out_dir>/<name> of the config; with --input: out/<REC's name>)")
    ap.add_argument("--online", action="store_true",
                    help="stream each recording sample by sample (causal model step, preintegration, iSAM2 at "
                         "keyframes), measure per-sample latency and the real-time factor, write <out>/online.json; "
                         "no smoothing; simulated aiding from the config's first noise seed")
    ap.add_argument("--checkpoint", default=None, metavar="PT",
                    help="with --input: refine the IMU with this checkpoint before fusing (its device bias, if it "
                         "carries one, is the bias prior); with --online: the CAUSAL checkpoint (trained with --model.causal true) for the "
                         "'proposed' input, for every recording (default: the config's checkpoint, which must "
                         "then be causal)")
    ap.add_argument("--recordings", type=_names, default=None, metavar="NAME,...",
                    help="with --online: only these recordings (folder names, e.g. V1_01_easy; default all)")
    ap.add_argument("--scenarios", type=_names, default=None, metavar="NAME,...",
                    help="with --online: only these aiding scenarios (their names in the config, e.g. gnss_1hz; "
                         "default all)")
    ap.add_argument("--inputs", type=_names, default=None, metavar="NAME,...",
                    help="with --online: IMU inputs to stream, of raw, proposed and learned (default raw,proposed; "
                         "learned: the config's covariance_checkpoint run once per window, its variances fused); "
                         "without: run only these of the config's inputs (e.g. tlio-style), the results of "
                         "the others in results.json are left as they are")
    ap.add_argument("--init", choices=("data", "groundtruth"), default=None,
                    help="the runs' first state, instead of the config's init: from the data alone (the default), or "
                         "a prior from ground truth (the controlled setting; tables say which)")
    ap.add_argument("--jobs", type=int, default=1, metavar="N", help="runs fused at a time, in worker processes (one thread each); results.json is the same")
    g = ap.add_argument_group("the GNSS outage experiment (a --config with kind = \"gnss-outages\")")
    g.add_argument("--set", action="append", default=None, metavar="KEY=JSON", dest="set_values",
                   help="override a config value, e.g. --set velocity_sigma_mps=0 --set nhc.sigma_lat=0.05 "
                        "(repeatable)")
    g.add_argument("--variants", type=_names, default=None, metavar="NAME,...",
                   help="run only these of the config's variants (raw, raw+nhc)")
    ap.add_argument("--threads", type=int, default=None, metavar="N",
                    help="torch threads for the models (default: 1 with --online, where one sample at a time "
                         "gains nothing from more; torch's own otherwise)")


def add_navigate_arguments(ap: argparse.ArgumentParser) -> None:
    from imu_learn.fuse.navigate import AIDING_FORMATS, KINDS, NavigateOptions

    d = NavigateOptions()
    g = ap.add_argument_group("navigating a recording (--input)")
    g.add_argument("--format", default=None, metavar="F",
                   help="the recording's layout (default auto: asl/euroc, tum-vi, blackbird, broad, kaist, fetch, rosbag, "
                        "gnss-imu: an IMU .csv with its RTKLIB .csv.tag)")
    g.add_argument("--aiding", type=Path, default=None, metavar="FILE", help="the aiding file (required with --input)")
    g.add_argument("--aiding-kind", choices=KINDS, default=None,
                   help="relative-pose: between consecutive poses (any visual odometry; no world frame needed); pose: "
                        "absolute poses in the aiding's own world, levelled at the start (a SLAM's globally consistent "
                        "trajectory: re-anchors after gaps); position: position fixes (heading from the track)")
    g.add_argument("--aiding-format", choices=AIDING_FORMATS, default=None,
                   help="tum (t tx ty tz qx qy qz qw, seconds; default), csv (the same with commas), asl (ns, p, q_wxyz), "
                        "rtklib (.pos; with --aiding-kind position)")
    g.add_argument("--displacement", type=Path, default=None, metavar="PT",
                   help="a tlio-style displacement model (imu-learn evaluate --methods tlio-style writes "
                        "<out>/methods/tlio-style.pt): its 1 s displacements of the raw IMU join the graph as factors; "
                        "with a --checkpoint that has a covariance head this is the 'learned' input; or its floor "
                        "<out>/methods/zero-displacement.json (the device stays put, with the fitted spread)")
    g.add_argument("--variance-scale", default=None, metavar="G,A",
                   help="multiply the covariance head's per-sample gyro and acc variances by G and A (a "
                        "--checkpoint with a covariance head only; bench/variance_scale.py calibrates them over "
                        "the keyframe interval)")
    g.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                   help="apply a fit imu-learn evaluate saved (<out>/methods/timing.json, traditional+timing.json) "
                        "to the IMU instead of a checkpoint: the simple floor a learned input is judged against")
    g.add_argument("--extrinsics", type=Path, default=None, metavar="YAML",
                   help="the aiding sensor's Kalibr/ASL sensor.yaml: T_BS, sensor to body (IMU); camera poses are moved "
                        "into the IMU frame with it (without: the aiding is taken as body poses)")
    g.add_argument("--groundtruth", type=Path, default=None, metavar="FILE",
                   help="score the result afterwards (TUM or ASL): RMSE after SE(3) alignment for camera aiding, "
                        "without alignment for position fixes; the visual-only error beside it")
    g.add_argument("--keyframe-hz", type=float, default=None, metavar="HZ",
                   help=f"keyframe grid besides the aiding's own samples (default {d.keyframe_hz:g})")
    g.add_argument("--gaps", default=None, metavar="START:DUR,...",
                   help="drop the aiding inside these windows (seconds from the first IMU sample), e.g. 30:10,70:10")
    g.add_argument("--aiding-hz", type=float, default=None, metavar="HZ", help="thin the aiding to this rate (default: every row)")
    g.add_argument("--sigma-rot-deg", type=float, default=None, metavar="DEG",
                   help=f"pose factors' rotation sigma (default relative {d.rel_sigma_rot_deg:g}, absolute "
                        f"{d.pose_sigma_rot_deg:g})")
    g.add_argument("--sigma-m", type=float, default=None, metavar="M",
                   help=f"pose factors' translation / position fixes' sigma (default relative {d.rel_sigma_trans_m:g}, "
                        f"absolute {d.pose_sigma_m:g}, position {d.position_sigma_m:g})")
    g.add_argument("--max-relative-gap-s", type=float, default=None, metavar="S",
                   help=f"consecutive poses further apart are not chained (default {d.max_relative_gap_s:g})")
    g.add_argument("--lag-s", type=float, default=None, metavar="S",
                   help="the causal estimate's fixed-lag window (default: the factor graph's)")
    g.add_argument("--imu-rotation-rpy-deg", default=None, metavar="R,P,Y",
                   help="the IMU's mounting: roll, pitch, yaw [deg] of the body frame relative to the IMU frame "
                        "(Groves' convention, rtklibexplorer/GNSS_IMU's imu_misalign); gyro and acc are rotated into "
                        "the body frame, whose x-axis the track heading and --nhc take as forward")
    g.add_argument("--imu-delay-s", type=float, default=None, metavar="S",
                   help="added to every IMU stamp: a logging delay (e.g. -0.125 on rtklibexplorer's drive)")
    g.add_argument("--lever-arm", default=None, metavar="X,Y,Z",
                   help="position aiding: the antenna from the IMU in the body frame [m] (instead of --extrinsics)")
    g.add_argument("--nhc", action="store_true", default=None,
                   help="wheeled platforms: the non-holonomic constraint (no sideways or vertical velocity in the "
                        f"body frame; sigma {d.nhc_sigma_lat_mps:g} / {d.nhc_sigma_vert_mps:g} m/s) at every keyframe")
    g.add_argument("--imu-noise", default=None, metavar="GND,AND,GRW,ARW",
                   help="the IMU's gyro and acc noise densities and random walks (rad/s/sqrt(Hz), m/s^2/sqrt(Hz), "
                        "rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz)); default: the recording's sensor.yaml, else built in "
                        "(EuRoC's ADIS16448)")


def parser() -> argparse.ArgumentParser:
    """The full ``imu-learn fuse`` parser (common flags included)."""
    from imu_learn.cli.common import parser as common_parser

    return common_parser("fuse")


def navigate(args: argparse.Namespace, keep: Callable[[Any], None]) -> int:
    """``--input``: one recording navigated with its aiding file (:mod:`imu_learn.fuse.navigate`)."""
    from dataclasses import replace

    from imu_learn.fuse.navigate import NavigateOptions, one_line, parse_gaps, parse_vector
    from imu_learn.fuse.navigate import navigate as run_navigation

    wrong = [f"--{o.replace('_', '-')}" for o in ("recordings", "scenarios", "inputs", "data_root", "variants", "init")
             if getattr(args, o) is not None] + (["--online"] if args.online else []) \
        + (["--set"] if args.set_values is not None else [])
    if wrong:
        raise ConfigError(f"{', '.join(wrong)}: only with --config")
    if args.threads is not None:
        if args.threads < 1:
            raise ConfigError(f"--threads: must be >= 1, got {args.threads}")
        import torch

        torch.set_num_threads(args.threads)
    if args.aiding is None or args.aiding_kind is None:
        raise ConfigError("--input needs --aiding FILE and --aiding-kind {position,pose,relative-pose}")
    o = NavigateOptions(aiding_kind=args.aiding_kind, aiding_format=args.aiding_format or "tum")
    if args.keyframe_hz is not None:
        o = replace(o, keyframe_hz=args.keyframe_hz)
    if args.gaps is not None:
        o = replace(o, gaps=parse_gaps(args.gaps))
    if args.aiding_hz is not None:
        o = replace(o, aiding_hz=args.aiding_hz)
    if args.max_relative_gap_s is not None:
        o = replace(o, max_relative_gap_s=args.max_relative_gap_s)
    if args.lag_s is not None:
        o = replace(o, lag_s=args.lag_s)
    if args.imu_rotation_rpy_deg is not None:
        o = replace(o, imu_rotation_rpy_deg=parse_vector(args.imu_rotation_rpy_deg, 3, "--imu-rotation-rpy-deg"))
    if args.imu_delay_s is not None:
        o = replace(o, imu_delay_s=args.imu_delay_s)
    if args.lever_arm is not None:
        o = replace(o, lever_arm=parse_vector(args.lever_arm, 3, "--lever-arm"))
    if args.nhc:
        o = replace(o, nhc=True)
    if args.imu_noise is not None:
        o = replace(o, imu_noise=parse_vector(args.imu_noise, 4, "--imu-noise"))
    if args.variance_scale is not None:
        o = replace(o, variance_scale=parse_vector(args.variance_scale, 2, "--variance-scale"))
    if args.sigma_rot_deg is not None:
        o = replace(o, **{"rel_sigma_rot_deg" if o.aiding_kind == "relative-pose" else "pose_sigma_rot_deg":
                          args.sigma_rot_deg})
    if args.sigma_m is not None:
        key = {"relative-pose": "rel_sigma_trans_m", "pose": "pose_sigma_m", "position": "position_sigma_m"}
        o = replace(o, **{key[o.aiding_kind]: args.sigma_m})
    out = args.out or Path("out") / args.input.name
    keep(f"nothing is written to {out} before the fusion ends")
    summary = run_navigation(args.input, args.aiding, out, o, fmt=args.format or "auto", extrinsics=args.extrinsics,
                             checkpoint=None if args.checkpoint is None else Path(args.checkpoint),
                             groundtruth=args.groundtruth, displacement=args.displacement,
                             calibration=args.calibration)
    print(one_line(summary))
    return 0


GNSS_KIND = "gnss-outages"
NOT_GNSS = ("online", "checkpoint", "recordings", "scenarios", "inputs", "threads", "init")


def config_kind(path: Path) -> Optional[str]:
    """The config's ``kind`` (None for the fusion experiment's configs, which have none)."""
    from imu_learn.settings import read_toml

    kind = read_toml(Path(path)).get("kind")
    if kind is not None and kind != GNSS_KIND:
        raise ConfigError(f"{path}: kind: {GNSS_KIND!r} or none (the fusion experiment), got {kind!r}")
    return kind


def gnss_outages(args: argparse.Namespace, keep: Callable[[Any], None]) -> int:
    """A ``kind = "gnss-outages"`` config: the GNSS/IMU experiment with simulated outages
    (:mod:`imu_learn.fuse.gnss_run`); prints one line per variant and the files written."""
    from imu_learn.fuse import gnss_run

    wrong = [f"--{o}" for o in NOT_GNSS if getattr(args, o) not in (None, False)]
    if wrong:
        raise ConfigError(f"{', '.join(wrong)}: not with a kind = \"{GNSS_KIND}\" config")
    cfg = gnss_run.load_config(args.config, args.data_root)
    for item in args.set_values or []:
        gnss_run.apply_override(cfg, item)
    if args.variants is not None:
        cfg.variants = list(args.variants)
    gnss_run.check(cfg, f"{args.config} (after --set/--variants)")
    out = Path(args.out or cfg.out_dir)
    keep(f"nothing is written to {out} before the last variant ends")
    res = gnss_run.experiment(cfg)
    files = gnss_run.write_results(res, cfg, out)
    for line in gnss_run.summary_lines(res, cfg):
        print(line)
    print(f"wrote {files[0]} and {files[1]}")
    return 0


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    if args.input is not None:
        return navigate(args, keep)
    given = [f"--{o.replace('_', '-')}" for o in NAVIGATE_ONLY if getattr(args, o) is not None]
    if given:
        raise ConfigError(f"{', '.join(given)}: only with --input")
    if not args.online:  # options checked before any file is read
        given = [f"--{o}" for o in ONLINE_ONLY if getattr(args, o) is not None]
        if given:
            raise ConfigError(f"{', '.join(given)}: only with --online")
    kind = config_kind(args.config)
    gnss_given = [f"--{o}" for o, a in (("set", "set_values"), ("variants", "variants")) if getattr(args, a) is not None]
    if kind == GNSS_KIND:
        return gnss_outages(args, keep)
    if gnss_given:
        raise ConfigError(f"{', '.join(gnss_given)}: only with a kind = \"{GNSS_KIND}\" config")
    if args.threads is not None and args.threads < 1:
        raise ConfigError(f"--threads: must be >= 1, got {args.threads}")
    from imu_learn.fuse.config import load

    cfg = load(args.config, args.data_root)
    if args.init is not None:
        cfg.init = args.init
    out = args.out or Path(cfg.out_dir) / cfg.name
    if args.threads is not None or args.online:
        import torch

        torch.set_num_threads(args.threads or 1)
    if args.online:
        from imu_learn.fuse.online import ONLINE_INPUTS, run_online

        keep(f"the runs so far are in {out / 'online.json'}")
        run_online(cfg, out, args.checkpoint, args.recordings, args.scenarios, args.inputs or ONLINE_INPUTS,
                   log=lambda m: print(m, flush=True))
        print(f"wrote {out / 'online.json'}")
    else:
        from imu_learn.fuse.run import run_experiment

        keep(f"results so far are in {out / 'results.json'} (rerun to resume)")
        run_experiment(cfg, out, only_inputs=args.inputs, jobs=args.jobs)
        print(f"wrote {out / 'table.md'}")
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn fuse ARGV``."""
    return run_command("fuse", argv)
