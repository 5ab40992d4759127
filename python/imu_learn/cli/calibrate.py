"""``imu-learn calibrate``: a device profile from recordings with a reference trajectory (or a still
recording alone), written as profile.json, Kalibr's imu.yaml and calibration.png. The command picks
the reference source (:mod:`imu_learn.calib.sources`) from its options; :mod:`imu_learn.calib.run`
does the work."""
from __future__ import annotations

import argparse
import logging
import math
import sys
from contextlib import nullcontext
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence

from imu_learn.baselines.base import FitSettings
from imu_learn.calib.odometry import OdometrySource, is_odometry_reference
from imu_learn.calib.profile import unobserved_value
from imu_learn.calib.run import SELECT_BY_DEFAULT_FOR, CalibInputs, CalibOptions, calibrate
from imu_learn.calib.sources import (
    NAVIGATOR_OPTIONS,
    TRAIN,
    VAL,
    PosesSource,
    Progress,
    Source,
    StillSource,
    blocks,
    device_name,
    under_root,
)
from imu_learn.cli.common import add_data_root, add_imu_input_options, csv_layout, run_command
from imu_learn.data.formats import FORMATS, USER_CSV, detect_format
from imu_learn.data.splits import data_root_dir, make_split, recording_name
from imu_learn.errors import ConfigError
from imu_learn.eval.run import load_eval_config
from imu_learn.settings import read_toml
from imu_learn.train.config import build_config, load_config
from imu_learn.util.helper import shared_helper
from imu_learn.util.staging import check_writable

logger = logging.getLogger(__name__)

DESCRIPTION = """Calibrate an IMU against a reference trajectory (ground truth, motion capture, a VIO/SLAM trajectory
in its camera's frame, RTK positions via --groundtruth; or a config's training split via --config).
The reference is checked against the IMU first: its rotation to the IMU (from rotation rates, or
--extrinsics), its lag, gravity in its world and its scale; what cannot be resolved is refused (exit 2,
one line), and only what the reference observes is fitted (a 20-30 Hz VO: no acc scale or low-pass;
positions: the biases). A profile outside what a MEMS IMU can be (scale 0.8-1.25, misalignment < 5°,
|gyro bias| < 0.1 rad/s, |acc bias| < 1 m/s^2, gravity within 5 %) or one that makes the held-back block
worse is not written (--force writes it with a warning). Fitted: the time offset and the
gyroscope/accelerometer affine calibration (scale, misalignment, bias; evaluate's traditional+timing
floor, with the same settings), gravity, and the noise: white-noise densities and bias random walks
from the residuals against the reference and from the Allan deviation of still stretches. A still
recording without a reference (--imu-only) gives the noise alone. Writes OUT/profile.json (every
parameter with its uncertainty, the recordings and spans used, what could not be observed),
OUT/imu.yaml (Kalibr's noise file, read by Kalibr, OpenVINS, VINS-Fusion, ORB-SLAM3) and
OUT/calibration.png; `imu-learn refine --profile OUT/profile.json` applies the floor.
--learned then trains a refiner on top of the profile on the same recordings (the validation split
selects and judges it): OUT/model.pt when it beats the floor on validation, else OUT/model.not_shipped.pt
and the profile stays the result (one line says which; OUT/learned.json the figures, OUT/fit the run).
The method: the module docs of imu_learn.calib.noise and imu_learn.calib.fit."""
EPILOG = """examples:
  imu-learn calibrate --config configs/eval_euroc_paper.toml --data-root DATA --out calib/euroc
  imu-learn calibrate --input datasets/euroc/MH_01_easy --out calib/mh01
  imu-learn calibrate --input datasets/euroc/MH_01_easy --out calib/mh01 --learned --learned-epochs 3
  imu-learn calibrate --input robot/run1 --groundtruth robot/run1_vio.tum --device my-imu --out calib/robot
  imu-learn calibrate --imu-only --input DATA/broad/04_undisturbed_slow_rotation_with_breaks_A.mat --out calib/broad"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--input", type=Path, action="append", metavar="REC",
                   help="a recording (folder, file or bag) with its reference; repeat for several")
    p.add_argument("--groundtruth", type=Path, action="append", metavar="FILE",
                   help="the reference of the --input of the same position (TUM 't x y z qx qy qz qw' or ASL; "
                        "default: the format's own ground truth)")
    p.add_argument("--config", type=Path, metavar="TOML",
                   help="a fit or evaluate config: its training split (validation for the floor's selection), "
                        "with evaluate's settings")
    p.add_argument("--format", default="auto", choices=("auto", *FORMATS, USER_CSV),
                   help="the recordings' layout (default: detected)")
    p.add_argument("--max-gap-s", type=float, default=None, metavar="S",
                   help="with --input: split at reference gaps longer than S (default 0.05, or 1.5 periods of a "
                        "sparse reference such as a 20 Hz VIO trajectory)")
    p.add_argument("--extrinsics", type=Path, metavar="YAML",
                   help="the reference sensor's known extrinsic (Kalibr / EuRoC sensor.yaml T_BS: the reference's "
                        "frame in the IMU's); default: estimated from the rotation rates and written to profile.json")
    p.add_argument("--imu-topic", help="ROS bags: the sensor_msgs/msg/Imu topic (default: the bag's only one)")
    p.add_argument("--groundtruth-topic", help="ROS bags: the pose topic of the reference (default: the bag's only one)")
    p.add_argument("--force", action="store_true",
                   help="write a profile that fails a plausibility check (scale, misalignment, bias, gravity, the "
                        "held-back block), or with --imu-only one that measured nothing (the class defaults), with a "
                        "warning, instead of stopping")
    p.add_argument("--select", action=argparse.BooleanOptionalAction, default=None,
                   help="choose each sensor's terms (offset, bias, scale, affine, g-sensitivity, low-pass): the simplest "
                        "that no simpler one beats on a recording held out in turn (imu_learn.calib.select; "
                        "profile.json's selection); --no-select: every term (faster; on recordings it did not see such "
                        "a profile can lose to raw). Default: chosen for a poses reference (motion capture, VIO/SLAM); "
                        "positions and odometry fit the terms they observe")
    p.add_argument("--imu-only", action="store_true",
                   help="read each --input's IMU alone (no reference): the noise from its still stretches only")
    p.add_argument("--device", metavar="NAME", help="the device's name in the profile (default: the dataset a "
                                                    "one-device format belongs to, else the first recording's name)")
    p.add_argument("--val-fraction", type=float, default=0.15, metavar="F",
                   help="with --input: the last F of each recording selects the floor's filter and offset, as the "
                        "configs' splits do, and judges the profile (default 0.15; a last block that does not move: "
                        "the latest one that does; 0: the training windows select)")
    p.add_argument("--min-still-s", type=float, default=10.0, metavar="S",
                   help="total still time the Allan noise needs (default 10)")
    p.add_argument("--no-plot", action="store_true", help="no calibration.png")
    p.add_argument("--learned", action="store_true",
                   help="then train a refiner on top of the profile (imu-learn fit --model.start OUT/profile.json) on "
                        "the same recordings; OUT/model.pt only when it beats the floor on validation "
                        "(imu_learn.train.on_profile)")
    p.add_argument("--learned-epochs", type=int, metavar="N",
                   help="with --learned: epochs of training (default: the config's optim.epochs, 24 by default)")
    p.add_argument("--seed", type=int, metavar="S", help="with --learned: the run's seed (default: the config's, 0)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    nav = "with a positions-only --groundtruth (GNSS), as imu-learn navigate's option of the same name: "
    p.add_argument("--imu-rotation-rpy-deg", default=None, metavar="R,P,Y",
                   help=nav + "the IMU's mounting, "
                              "roll, pitch, yaw [deg] of the body frame relative to the IMU frame (Groves' convention, "
                              "rtklibexplorer/GNSS_IMU's imu_misalign): starting from the IMU's axes, turn by yaw about z, then"
                              " by pitch about the new y, then by roll about the new x (intrinsic z-y'-x'') to reach the body's"
                              " axes; gyro and acc are rotated into the body frame as body = (Rz(yaw) Ry(pitch) Rx(roll))^T "
                              "imu. Examples: 180,0,0 an IMU upside down (its z down, its y along the body's -y); -90,0,0 a "
                              "y-up IMU (its y along the body's z, its x forward); 0,0,90 a yaw of 90 deg (the IMU's y forward,"
                              " its x along the body's -y, i.e. to the right)"
                              " (default: estimated from the track)")
    p.add_argument("--imu-delay-s", type=float, default=None, metavar="S",
                   help=nav + "added to every IMU stamp, a logging delay (e.g. -0.125 on rtklibexplorer's drive; "
                              "default: estimated from the track, recorded in profile.json's reference)")
    p.add_argument("--lever-arm", default=None, metavar="X,Y,Z",
                   help=nav + "the antenna from the IMU in the body frame [m] (instead of --extrinsics)")
    add_data_root(p, "the config's recordings")
    add_imu_input_options(p)


class ConfigSource(Source):
    """A fit or evaluate config's train/val split (its recordings' ground truth), with evaluate's
    FitSettings for it; ``data_root`` overrides the config's."""

    kind = "poses"

    def __init__(self, config: Path, data_root: Optional[Any] = None, device: Optional[str] = None) -> None:
        self.config, self.data_root, self.device = Path(config), data_root, device

    def read(self, progress: Progress = lambda s: None) -> CalibInputs:
        overrides = ["--data.data_root", self.data_root] if self.data_root else []
        if "base" in read_toml(self.config):  # an evaluate config: its base holds the data
            res = load_eval_config(self.config, overrides)
            data, settings = res.run.data, res.fit_settings()
        else:
            run = load_config(self.config, overrides)
            data = run.data
            settings = FitSettings(window=data.window, seed=run.seed, gravity=data.gravity)
        split = make_split(data)
        root = data_root_dir(data)
        sources = [{**row, **{k: under_root(row.get(k), root) for k in ("path", "groundtruth", "groundtruth_path")},
                    "role": role}
                   for role in ("train", "val") for row in split.record[role]]
        device = self.device or device_name(data.roots[0].format if data.roots else "auto", split.train[0].name)
        recordings = (blocks(split.train, [recording_name(s.name) for s in split.train], TRAIN)
                      + blocks(split.val, [recording_name(s.name) for s in split.val], VAL))
        return CalibInputs(recordings=recordings, settings=settings, device=device, sources=sources, source=self)




def positions() -> Any:
    """The positions reference's module (:mod:`imu_learn.fuse.calibrate_positions`), imported where a
    --groundtruth file or its options are given: it brings the navigator (GTSAM's graph, scipy's
    rotations), about 1 s of start-up a config's, still or ASL recording's calibration does not need."""
    from imu_learn.fuse import calibrate_positions

    return calibrate_positions


def source_of(args: argparse.Namespace) -> Source:
    """The reference source the options name: --config's split, --imu-only's still recordings, a
    positions-only --groundtruth (GNSS), a planar odometry one (the yaw rate), else poses (any frame)."""
    if args.config:
        return ConfigSource(args.config, args.data_root, args.device)
    if args.imu_only:
        return StillSource(args.input, args.format, csv_layout(args), args.device)
    if args.groundtruth and any(positions().is_positions_reference(g) for g in args.groundtruth):
        return positions().source_from_cli(args, csv_layout(args))  # positions only: the navigator's smoother's attitude
    if any(is_odometry_reference(g) for g in args.groundtruth or []):  # planar odometry: the yaw rate only
        return OdometrySource(args.input, args.groundtruth, args.format, csv_layout(args), args.max_gap_s,
                              args.val_fraction, args.device)
    return PosesSource(args.input, args.groundtruth or [], args.format, csv_layout(args), args.extrinsics,
                       args.max_gap_s, args.val_fraction, args.device,
                       {"imu_topic": args.imu_topic, "groundtruth_topic": args.groundtruth_topic})


HELPER_STEPS = ("imu_learn.calib.fit", "imu_learn.calib.select")  # where the helper process's steps live


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    if bool(args.input) == bool(args.config):
        raise ConfigError("give --input REC (repeatable) or --config TOML, not both and not neither")
    if args.config and args.imu_only:
        raise ConfigError("--imu-only reads --input recordings, not a config's split")
    check_learned(args)
    check_writable(args.out)  # before any work: a file or a read-only folder is named now, not after the fit
    say = (lambda s: None) if args.quiet else (lambda s: logger.info("%s", s))
    say("reading the recordings")
    source = source_of(args)
    if any(getattr(args, k, None) is not None for k in NAVIGATOR_OPTIONS):  # the positions kind's options only
        positions().refuse_navigator_options(args, source.kind)
    writes = source.kind == "positions"  # its reading runs the smoother, which writes into --out

    def kept() -> str:
        work = "; the smoother's work in it may be new" if writes else ""
        return (f"{args.out}'s profile files are as they were (replaced together, at the end{work})"
                if Path(args.out).exists()
                else f"nothing written ({args.out} not created)")

    if writes:
        keep(kept)
    # a poses reference's floor, refits and held-out folds are split with a helper process, started
    # now so that its imports overlap the reading
    with shared_helper(HELPER_STEPS) if source.kind == "poses" else nullcontext():
        inp = source.read(say)
        if not writes:
            keep(kept)
        res = calibrate(inp, args.out, CalibOptions(min_still_s=args.min_still_s, plot=not args.no_plot,
                                                     force=args.force, select=args.select), say)
    p = res.profile
    for line in summary(p):
        print(line)
    for name, path in res.files.items():
        print(f"{name}: {path}")
    print(f"calibrate took {res.seconds:.1f} s")
    sys.stdout.flush()
    if args.learned:
        learned(args, inp, res.files["profile"], say, keep)
    return 0


def check_learned(args: argparse.Namespace) -> None:
    """--learned's refusals, before any work."""
    if not args.learned:
        if args.learned_epochs is not None or args.seed is not None:
            raise ConfigError("--learned-epochs and --seed set the --learned refiner's run; add --learned")
        return
    if args.imu_only:
        raise ConfigError("--learned needs a reference trajectory; --imu-only gives the noise alone")
    if args.learned_epochs is not None and args.learned_epochs < 1:
        raise ConfigError(f"--learned-epochs: must be at least 1, got {args.learned_epochs}")
    if (args.out / "fit" / "last.pt").exists():
        raise ConfigError(f"{args.out / 'fit'}: already holds a refiner's run; remove it or choose another --out")


def learned(args: argparse.Namespace, inp: CalibInputs, profile: Path, say: Callable[[str], None],
            keep: Callable[[Any], None]) -> None:
    """--learned: the refiner on top of ``profile``, its one line (imu_learn.train.on_profile)."""
    from imu_learn.train.on_profile import config_on_profile, train_on_profile  # torch

    base = learned_base(args, inp)
    cfg = config_on_profile(base, profile, args.learned_epochs or base.optim.epochs,
                            base.seed if args.seed is None else args.seed)
    keep(f"{profile} is the result so far; the refiner's unfinished run is in {args.out / 'fit'}: remove that "
         "folder and run the same calibrate --learned command again to train it (it starts over)")
    res = train_on_profile(cfg, inp.train, inp.val, args.out, say, bar=not args.quiet)
    print(res.line())
    print(f"learned refiner took {res.seconds:.1f} s")


def learned_base(args: argparse.Namespace, inp: CalibInputs) -> Any:
    """The run config the refiner starts from: the --config's (a fit config, or an evaluate config's
    base), else the defaults with data.roots and data.split naming the --input recordings, the gap
    rule and the blocks calibrate cut (what the run's config.toml then says it trained on)."""
    overrides = ["--data.data_root", str(args.data_root)] if args.data_root else []
    if args.config:
        if "base" in read_toml(args.config):
            return load_eval_config(args.config, overrides).run
        return load_config(args.config, overrides)
    gts = list(args.groundtruth or []) + [None] * len(args.input)
    f = args.val_fraction
    roots, train, val = [], [], []
    for path, gt, source in zip(args.input, gts, inp.sources):
        name = path.stem if path.is_file() else path.name
        fmt = args.format if args.format != "auto" else detect_format(path)
        # the run config names a dataset (`imu-learn fit --resume` reads it back): the ASL layout is EuRoC's reader
        roots.append({"path": str(path), "format": {"asl": "euroc"}.get(fmt, fmt),
                      "groundtruth": str(gt) if gt else "", "max_gap_s": source["max_gap_s"]})
        train.append(name if f <= 0 else f"{name}[0:{1 - f:g}]")
        val += [] if f <= 0 else [f"{name}[{1 - f:g}:1]"]
    return build_config({}, {"data.roots": roots, "data.split.train": train, "data.split.val": val or train,
                             "data.split.test": []})


def summary(p: Any) -> List[str]:
    lines = [f"device {p.device}: {p.sample_rate_hz:.4g} Hz"]
    if p.has_floor:
        spread = (f"+-{p.time_offset_s_std * 1e3:.3f}" if math.isfinite(p.time_offset_s_std)
                  else "not observed: held at its prior")
        lines.append(f"time offset {p.time_offset_s * 1e3:+.3f} ms ({spread}); "
                     f"gyro bias {_vec(p.gyro.bias)} rad/s; acc bias {_vec(p.acc.bias)} m/s^2; "
                     f"gravity {p.gravity_mps2:.4f} m/s^2")
        lines.append(_terms_line(p.selection, p.reference.get("kind", "poses"),
                                 bool(p.observed.get("time_offset", {}).get("observed", True))))
    for k, t in p.noise.items():
        if p.unobserved_noise(k):
            lines.append(f"{k}: {p.kalibr()[k]:.3e} {t.unit} (not observed: {unobserved_value(k, t.bound)[1]}; the data "
                         f"bound it above by {t.bound:.3e})")
            continue
        lines.append(f"{k}: {t.value:.3e} {t.unit} ({t.source}, {t.detail.get('kind', 'fit')})")
    if p.reference and not all(v is False for v in p.reference.get("applied", {}).values()):
        r = p.reference
        lines.append(f"reference moved into the IMU frame: rotation {r['rotation_deg']:.2f}° ({r['rotation_from']}), "
                     f"applied: {', '.join(k for k, v in r['applied'].items() if v)}")
    for k, o in p.observed.items():
        if o.get("observed", True) and o.get("partly"):
            lines.append(f"partly observed: {k}: {o['partly']}")
        if not o.get("observed", True):
            why = str(o.get("why", ""))
            if why.startswith("not selected: "):  # observed, but it did not pay on held-out data
                lines.append(f"not selected: {k}: {why[len('not selected: '):]}")
            else:
                lines.append(f"not observed: {k} (kept at its prior): {why}")
    for u in p.unobservable:
        lines.append(f"not observed: {u['what']}: {u['why']}")
    return lines


def _terms_line(selection: Dict[str, Any], kind: str, offset_observed: bool = True) -> str:
    """Which of the floor's terms the profile holds and how they were chosen (the level ``offset`` is the
    time offset alone: no term at all where the time offset is held at its prior)."""
    if kind != "poses":
        return f"terms: those a {kind} reference observes (the others at their prior)"
    if "gyro" in selection:
        def level(x: Any) -> str:
            return (("offset (the time offset alone)" if offset_observed else "none (the time offset held at its prior)")
                    if x == "offset" else str(x))

        return (f"terms chosen on held-out recordings ({selection['held_out']}): gyroscope {level(selection['gyro'])}, "
                f"accelerometer {level(selection['acc'])}" + ("; by default for " + SELECT_BY_DEFAULT_FOR
                                                             + " (--no-select: every term)" if "by_default" in selection else ""))
    if "skipped" in selection:
        return f"terms: the reference's own ({selection['skipped']})"
    return ("terms: every term of the floor (--no-select), none chosen on held-out recordings (on recordings it did not "
            "see a richer floor can lose to a simpler one)")


def _vec(v: Any) -> str:
    return "[" + ", ".join(f"{x:+.4f}" for x in v) + "]"


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn calibrate ARGV``."""
    return run_command("calibrate", argv)


__all__ = ["add_arguments", "run", "main", "source_of", "under_root"]  # under_root: where older code imports it
