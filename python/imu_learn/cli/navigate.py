"""``imu-learn navigate``: a user's recording navigated with its real aiding file, no ground truth at
run time (:mod:`imu_learn.fuse.navigate`)."""
from __future__ import annotations

import argparse
import logging
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from imu_learn.calib.profile import Profile
from imu_learn.cli.common import add_imu_input_options, csv_layout, run_command
from imu_learn.cli.common import parser as common_parser
from imu_learn.errors import ConfigError
from imu_learn.fuse.aiding.kinds import GEODETIC_KIND, kind_of
from imu_learn.fuse.navigate import (
    AIDING_FORMATS,
    KINDS,
    NavigateOptions,
    Sources,
    navigate,
    one_line,
    parse_gaps,
    parse_vector,
)
from imu_learn.infer.bias import choices as bias_choices
from imu_learn.infer.bias import help_text as bias_help
from imu_learn.util.extras import require
from imu_learn.util.staging import check_writable

logger = logging.getLogger(__name__)

DESCRIPTION = """Navigate one recording with its real aiding file (a camera trajectory as relative or absolute
poses, or position fixes), no ground truth needed: the first state comes from the data (attitude
levelled from the accelerometer, heading from the first pose or from the track, position and velocity
from the first aiding), under a loose prior, and the IMU is fused with the aiding in a GTSAM factor
graph. Writes causal.tum and smoothed.tum (t tx ty tz qx qy qz qw, body = IMU frame), plot.png and
summary.json to --out, all at once at the end (an error or a Ctrl-C, exit 130, before then leaves --out
as it was), and prints a one-line summary; --groundtruth only scores the result afterwards.
GNSS fixes (an RTKLIB .pos, known by its content; a bag's NavSatFix topic) also give the tracks as
latitude/longitude/height CSVs, KML and GeoJSON; a bag as input or aiding gets the trajectories back as
nav_msgs/Odometry bags. The IMU noise comes from --imu-noise, a device profile (--profile, which also
applies its floor), the recording's sensor.yaml, or the MEMS class default scaled to the aiding's
innovations (with a warning).
GNSS/IMU logs (the gnss-imu format) take --imu-rotation-rpy-deg, --imu-delay-s, --lever-arm and, on
wheels, --nhc; a --profile that calibrate fitted against positions carries the mounting, delay and lever
arm it used or estimated, taken where those options are not given (one line says so)."""

EPILOG = """examples:
  imu-learn navigate --input <data>/euroc/MH_04_difficult --aiding <ORB-SLAM2 trajectory>.txt \\
      --aiding-kind relative-pose --extrinsics <data>/euroc-vo/cam0_sensor.yaml \\
      --checkpoint models/euroc_adis16448.pt --out out/MH_04
      a recording navigated with camera poses, no ground truth
      -> out/MH_04/{causal.tum,smoothed.tum,plot.png,summary.json}
  imu-learn navigate --input <data>/gnss-imu/drive/imu.csv --aiding <data>/gnss-imu/drive/gnss.pos \\
      --imu-rotation-rpy-deg 180,-6.79,185.35 --nhc --profile calib/profile.json
      a car's IMU log with its RTKLIB solution (found by its content: positions), the non-holonomic
      constraint on, the noise of the device's profile; also writes causal_llh.csv, smoothed_llh.csv,
      track.kml and track.geojson
  imu-learn navigate --input run.bag --aiding run.bag --aiding-topic /gps/fix
      a bag's IMU with its NavSatFix topic; the trajectories also go into causal.bag and smoothed.bag
"""


MOUNTING_HELP = ("roll, pitch, yaw [deg] of the body frame relative to the IMU frame (Groves' convention, "
                 "rtklibexplorer/GNSS_IMU's imu_misalign): starting from the IMU's axes, turn by yaw about z, then"
                 " by pitch about the new y, then by roll about the new x (intrinsic z-y'-x'') to reach the body's"
                 " axes; gyro and acc are rotated into the body frame as body = (Rz(yaw) Ry(pitch) Rx(roll))^T "
                 "imu. Examples: 180,0,0 an IMU upside down (its z down, its y along the body's -y); -90,0,0 a "
                 "y-up IMU (its y along the body's z, its x forward); 0,0,90 a yaw of 90 deg (the IMU's y forward,"
                 " its x along the body's -y, i.e. to the right)")


def parse_delay(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"--imu-delay-s: seconds (e.g. -0.2) or 'auto', got {text!r}") from None


def add_arguments(ap: argparse.ArgumentParser) -> None:
    d = NavigateOptions()
    ap.add_argument("--input", type=Path, required=True, metavar="REC",
                    help="the recording (a folder or file the loaders read, e.g. an EuRoC ASL folder); only its IMU "
                         "is read, never its ground truth")
    ap.add_argument("--aiding", type=Path, default=None, metavar="FILE",
                    help="the aiding file, or a ROS bag with --aiding-topic (required)")
    ap.add_argument("--aiding-topic", default=None, metavar="TOPIC",
                    help="the aiding's topic when --aiding is a ROS bag: geometry_msgs PoseStamped / TransformStamped, "
                         "nav_msgs Odometry (poses), PointStamped (positions) or sensor_msgs NavSatFix (GNSS fixes "
                         "with their covariance; --aiding-kind position implied)")
    ap.add_argument("--aiding-kind", choices=KINDS, default=None,
                    help="relative-pose: between consecutive poses (any visual odometry; the aiding's world, where "
                         "it has no breaks or its breaks keep one map, is one more state estimated online, never given); pose: absolute poses in the aiding's own world, levelled at the start (a SLAM's "
                         "globally consistent trajectory: re-anchors after gaps); position: position fixes (heading "
                         "from the track). Required unless the aiding is GNSS fixes (an RTKLIB .pos, a NavSatFix "
                         "topic): those are positions")
    ap.add_argument("--out", type=Path, default=None, metavar="DIR", help="output folder (default out/<REC's name>)")
    ap.add_argument("--format", default=None, metavar="F",
                    help="the recording's layout (default auto: asl/euroc, tum-vi, blackbird, broad, kaist, fetch, "
                         "rosbag, gnss-imu: an IMU .csv with its RTKLIB .csv.tag)")
    ap.add_argument("--aiding-format", choices=AIDING_FORMATS, default=None,
                    help="auto (default: by the file's content), tum (t tx ty tz qx qy qz qw, seconds), csv (the same "
                         "with commas), asl (ns, p, q_wxyz), rtklib (.pos: GNSS positions), bag (a ROS bag topic)")
    ap.add_argument("--profile", type=Path, default=None, metavar="JSON",
                    help="a device profile (imu-learn calibrate's profile.json): the IMU noise the graph assumes, and "
                         "its floor (time offset, affine calibration) applied to the IMU unless --checkpoint or "
                         "--calibration refines it")
    ap.add_argument("--checkpoint", default=None, metavar="PT",
                    help="refine the IMU with this checkpoint before fusing (its device bias, if it carries one, is "
                         "the bias prior; with a covariance head its per-sample variances weight the IMU)")
    ap.add_argument("--displacement", type=Path, default=None, metavar="PT",
                    help="a tlio-style displacement model (imu-learn evaluate --methods tlio-style writes "
                         "<out>/methods/tlio-style.pt): its 1 s displacements of the raw IMU join the graph as "
                         "factors; with a --checkpoint that has a covariance head this is the 'learned' input; or its "
                         "floor <out>/methods/zero-displacement.json (the device stays put, with the fitted spread)")
    ap.add_argument("--variance-scale", default=None, metavar="G,A",
                    help="multiply the covariance head's per-sample gyro and acc variances by G and A (a --checkpoint "
                         "with a covariance head only; imu_learn.fuse.variance.calibrate_model calibrates them over "
                         "the keyframe interval)")
    ap.add_argument("--force", action="store_true",
                    help="apply a --profile or --checkpoint made for a rate more than 5 %% off the recording's "
                         "(a warning; without it: refused, as imu-learn refine); with --nhc, fuse a mounting whose "
                         "forward axis is more than 20 deg from the one the GNSS track shows (a warning)")
    ap.add_argument("--imu-name", metavar="NAME",
                    help="the recording's device, checked against the profile's or model's (default: the dataset "
                         "its format belongs to, else not checked)")
    ap.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                    help="apply a fit imu-learn evaluate saved (<out>/methods/timing.json, traditional+timing.json) "
                         "to the IMU instead of a checkpoint: the simple floor a learned input is judged against")
    ap.add_argument("--extrinsics", type=Path, default=None, metavar="YAML",
                    help="the aiding sensor's Kalibr/ASL sensor.yaml: T_BS, sensor to body (IMU); camera poses are "
                         "moved into the IMU frame with it (without: the aiding is taken as body poses, and refused when its rotations are not the gyro's)")
    ap.add_argument("--groundtruth", type=Path, default=None, metavar="FILE",
                    help="score the result afterwards (TUM or ASL): RMSE after SE(3) alignment for camera aiding, "
                         "without alignment for position fixes; the visual-only error beside it; with GNSS an "
                         "RTKLIB .pos (its RTK-fixed rows against the antenna, each --gaps window at the fixes "
                         "withheld there)")
    ap.add_argument("--keyframe-hz", type=float, default=None, metavar="HZ",
                    help=f"keyframe grid besides the aiding's own samples (default {d.keyframe_hz:g})")
    ap.add_argument("--gaps", default=None, metavar="START:DUR,...",
                    help="drop the aiding inside these windows (seconds from the first IMU sample), e.g. 30:10,70:10")
    ap.add_argument("--aiding-scale", type=float, default=None, metavar="S",
                    help="multiply the pose aiding's positions by S (a monocular VO's scale); without it they are "
                         "checked metric against the accelerometer, and refused with the S to pass when they are not")
    ap.add_argument("--aiding-hz", type=float, default=None, metavar="HZ",
                    help="thin the aiding to this rate (default: every row)")
    ap.add_argument("--sigma-rot-deg", type=float, default=None, metavar="DEG",
                    help=f"pose factors' rotation sigma (default relative {d.rel_sigma_rot_deg:g}, absolute "
                         f"{d.pose_sigma_rot_deg:g})")
    ap.add_argument("--sigma-m", type=float, default=None, metavar="M",
                    help=f"pose factors' translation / position fixes' sigma (default relative "
                         f"{d.rel_sigma_trans_m:g}, absolute {d.pose_sigma_m:g}, position {d.position_sigma_m:g})")
    ap.add_argument("--max-relative-gap-s", type=float, default=None, metavar="S",
                    help=f"consecutive poses further apart are not chained (default {d.max_relative_gap_s:g})")
    ap.add_argument("--keep-aiding-frame", action="store_true",
                    help="fuse the poses in the frame given (after --extrinsics) even where their rotation rates put "
                         "it clearly off the IMU's (by default turned onto the gyro's: at least 0.3 deg and 3 bootstrap "
                         "spreads, e.g. a stereo VO's rectified camera against the raw camera's T_BS)")
    ap.add_argument("--lag-s", type=float, default=None, metavar="S",
                    help="the causal estimate's fixed-lag window (default: the factor graph's)")
    ap.add_argument("--imu-rotation-rpy-deg", default=None, metavar="R,P,Y",
                    help="the IMU's mounting: " + MOUNTING_HELP + "; the body's x-axis is what the track heading "
                         "and --nhc take as forward")
    ap.add_argument("--imu-delay-s", default=None, metavar="S|auto",
                    help="added to every IMU stamp: a logging delay [s] (e.g. -0.2 on rtklibexplorer's drive); "
                         "'auto' (GNSS fixes): measured from the data, the accelerometer's specific-force norm "
                         "against the fixes' accelerations outside --gaps (the summary's imu_delay); without the "
                         "option GNSS fixes get that measurement where it fits clearly better than 0 (a warning "
                         "line), else 0")
    ap.add_argument("--lever-arm", default=None, metavar="X,Y,Z",
                    help="position aiding: the antenna from the IMU in the body frame [m] (instead of --extrinsics)")
    ap.add_argument("--nhc", action="store_true", default=None,
                    help="wheeled platforms: the non-holonomic constraint (no sideways or vertical velocity in the "
                         f"body frame; sigma {d.nhc_sigma_lat_mps:g} / {d.nhc_sigma_vert_mps:g} m/s) at every keyframe")
    ap.add_argument("--gnss-velocity-sigma", type=float, default=None, metavar="MPS",
                    help=f"GNSS fixes with velocities (an RTKLIB .pos): each epoch's velocity as a factor too, this "
                         f"sigma [m/s] (x2 for a float epoch; default {d.gnss_velocity_sigma_mps:g}), at the instant its "
                         "lag behind the positions puts it (measured from the file: the summary's gnss_velocities); "
                         "0: positions only")
    ap.add_argument("--imu-noise", default=None, metavar="GND,AND,GRW,ARW",
                    help="the IMU's gyro and acc noise densities and random walks (rad/s/sqrt(Hz), m/s^2/sqrt(Hz), "
                         "rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz)); default: --profile's, else the recording's sensor.yaml, "
                         "else the MEMS class default scaled to the aiding's innovations, each white noise raised to "
                         "the IMU's at a rest at the start where higher (with a warning)")
    ap.add_argument("--bias", choices=bias_choices(navigate=True), default="none", help=bias_help(navigate=True))
    ap.add_argument("--threads", type=int, default=None, metavar="N",
                    help="torch threads for the --checkpoint's model (default: torch's own)")
    add_imu_input_options(ap)


def require_gtsam(command: str) -> None:
    """A :class:`MissingExtraError` naming the ``fuse`` extra when GTSAM (the factor graph) is not
    installed (:func:`imu_learn.util.extras.require`, the one rule)."""
    require("gtsam", "fuse", f"imu-learn {command}")


def set_torch_threads(threads: Optional[int]) -> None:
    """``torch.set_num_threads(threads)`` (nothing when None; a :class:`ConfigError` below 1)."""
    if threads is None:
        return
    if threads < 1:
        raise ConfigError(f"--threads: must be >= 1, got {threads}")
    import torch

    torch.set_num_threads(threads)


def parser() -> argparse.ArgumentParser:
    """The full ``imu-learn navigate`` parser (common flags included)."""
    return common_parser("navigate")


def options(args: argparse.Namespace):
    """The :class:`~imu_learn.fuse.navigate.NavigateOptions` the command line asks for."""
    if args.aiding is None:
        raise ConfigError("--input needs --aiding FILE (and --aiding-kind {position,pose,relative-pose} unless it is "
                          "GNSS fixes)")
    # the kind None: found from the aiding by imu_learn.fuse.navigate.resolve_aiding (GNSS fixes are positions)
    o = NavigateOptions(aiding_kind=args.aiding_kind, aiding_format=args.aiding_format or "auto")
    if args.gnss_velocity_sigma is not None and not (args.gnss_velocity_sigma >= 0):
        raise ConfigError(f"--gnss-velocity-sigma: a sigma >= 0 m/s (0: positions only), got {args.gnss_velocity_sigma!r}")
    plain = {"keyframe_hz": args.keyframe_hz, "aiding_hz": args.aiding_hz, "aiding_scale": args.aiding_scale, "max_relative_gap_s": args.max_relative_gap_s,
             "lag_s": args.lag_s, "gnss_velocity_sigma_mps": args.gnss_velocity_sigma}
    o = replace(o, **{k: v for k, v in plain.items() if v is not None})
    if args.imu_delay_s is not None:
        o = replace(o, **({"imu_delay_from": "fixes"} if args.imu_delay_s.strip().lower() == "auto"
                          else {"imu_delay_s": parse_delay(args.imu_delay_s), "imu_delay_from": "option"}))
    if args.gaps is not None:
        o = replace(o, gaps=parse_gaps(args.gaps))
    for name, n in (("imu_rotation_rpy_deg", 3), ("lever_arm", 3), ("imu_noise", 4), ("variance_scale", 2)):
        text = getattr(args, name)
        if text is not None:
            o = replace(o, **{name: parse_vector(text, n, f"--{name.replace('_', '-')}")})
    o = profile_navigator(args, o)
    if args.nhc:
        o = replace(o, nhc=True)
    if args.keep_aiding_frame:
        o = replace(o, turn_aiding_frame=False)
    if args.bias != "none":
        o = replace(o, bias=args.bias)
    if args.sigma_rot_deg is not None:
        if o.aiding_kind is None:
            raise ConfigError("--sigma-rot-deg weighs poses: give --aiding-kind pose or relative-pose")
        o = replace(o, **{kind_of(o.aiding_kind).sigma_rot_option: args.sigma_rot_deg})
    if args.sigma_m is not None:
        o = replace(o, **{kind_of(o.aiding_kind or GEODETIC_KIND).sigma_m_option: args.sigma_m})
    return o


# profile.json's reference.navigator key, NavigateOptions' field, the option, its numbers (0: one, a delay)
PROFILE_NAVIGATOR = (("imu_rotation_rpy_deg", "imu_rotation_rpy_deg", "--imu-rotation-rpy-deg", 3),
                     ("imu_delay_s", "imu_delay_s", "--imu-delay-s", 0), ("lever_arm_m", "lever_arm", "--lever-arm", 3))


def profile_navigator(args: argparse.Namespace, o):
    """``o`` with the mounting, IMU delay and lever arm of ``--profile``'s ``reference.navigator`` (what
    calibrate used or estimated against positions) where the command line gives none; one line says which.
    A profile of another reference kind, or without them, leaves ``o`` as it is (the lever arm: position
    aiding only)."""
    if args.profile is None or not Path(args.profile).is_file():
        return o  # a missing profile is refused where it is read, with the others
    nav = (Profile.load(args.profile).reference or {}).get("navigator") or {}
    taken = []
    for key, field, option, n in PROFILE_NAVIGATOR:
        value = nav.get(key)
        if value is None or getattr(args, field) is not None:
            continue
        if field == "lever_arm" and (args.extrinsics is not None
                                     or not (o.aiding_kind is None or kind_of(o.aiding_kind).lever)):
            continue
        if n:
            o = replace(o, **{field: parse_vector(",".join(repr(float(x)) for x in value), n, option)})
            taken.append(f"{option} {','.join(f'{float(x):.4g}' for x in value)}")
        else:
            o = replace(o, imu_delay_s=float(value), imu_delay_from="profile")
            taken.append(f"{option} {float(value):+.4g}")
    if taken:
        logger.info("taken from %s (calibrate's reference.navigator; the options override): %s", args.profile,
                    "; ".join(taken))
    return o


def run(args: argparse.Namespace, rest: List[str], keep: Callable[[Any], None]) -> int:
    o = options(args)
    set_torch_threads(args.threads)
    require_gtsam("navigate")
    out = args.out or Path("out") / args.input.name
    check_writable(out)  # before the fusion: a file or a read-only folder is named now, not after minutes
    done: List[bool] = []  # the outputs go in all at once, at the end (imu_learn.util.staging)
    keep(lambda: f"{out} holds this run's complete outputs" if done else f"nothing of this run is written to {out}")
    src = Sources(args.input, args.aiding, fmt=args.format or "auto", aiding_topic=args.aiding_topic,
                  columns=csv_layout(args), profile=args.profile, extrinsics=args.extrinsics,
                  checkpoint=None if args.checkpoint is None else Path(args.checkpoint), groundtruth=args.groundtruth,
                  displacement=args.displacement, calibration=args.calibration, force=args.force,
                  imu_name=args.imu_name)
    print(one_line(navigate(src, out, o, progress=not args.quiet, written=lambda: done.append(True))))
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``imu-learn navigate ARGV``."""
    return run_command("navigate", argv)
