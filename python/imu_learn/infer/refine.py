"""Apply a trained refiner to a recording and write the refined IMU in the input's own format.

    python -m imu_learn.refine --checkpoint CKPT --input IN --output OUT
        [--format auto|asl|euroc|tum-vi|blackbird|broad|kaist|rosbag] [--imu-topic TOPIC]
        [--window 1000 --overlap 200] [--device auto|cpu|cuda] [--batch 16] [--copy-folder]
        [--fill-covariance] [--quiet]

Only the IMU is read (no ground truth needed); timestamps and everything but gyro/acc are kept:

- ASL (EuRoC, TUM-VI): IN is a sequence folder, its ``mav0`` or an IMU ``.csv``. OUT is a folder
  (``OUT/mav0/imu0/data.csv`` is written) or a ``.csv`` path. The ORIGINAL header line and the
  original integer-ns stamps are kept; values are written with the shortest text that reads back
  to the same float64. ``--copy-folder`` first copies the whole input sequence folder to OUT.
- KAIST: IN is the folder holding ``sensor_data/xsens_imu.csv`` (or that file). Same 17 columns,
  only gyro (cols 8-10) and acc (cols 11-13, 0-based) replaced; OUT is a folder
  (``OUT/sensor_data/xsens_imu.csv``) or a ``.csv`` path.
- Blackbird: IN is the folder holding ``data.hdf5`` (or that file). OUT gets a copy of the file
  with ``gyro_raw`` / ``accel_raw`` replaced (datasets keep their dtype, chunking, attributes).
- BROAD: IN is a ``.mat`` trial. OUT (a ``.mat`` path, or a folder that gets the input's name)
  gets every variable of the input with ``imu_gyr`` / ``imu_acc`` replaced.
- ROS bags: IN is a ROS 1 ``.bag`` or a ROS 2 bag folder (sqlite3 or mcap); ``--imu-topic`` names
  the sensor_msgs/msg/Imu topic (not needed when the bag has one). OUT is a new bag of the same kind
  (ROS 2 keeps its storage plugin and compression) in which only that topic's angular_velocity and
  linear_acceleration change; every other message, connection and stamp, and the IMU messages'
  headers and covariance fields, are copied unchanged. A ROS 2 OUT folder that exists is refused
  (a folder cannot be replaced in one step); ``--copy-folder`` does not apply.
  ``--fill-covariance`` (a checkpoint with a covariance head) also writes each IMU message's
  angular_velocity_covariance and linear_acceleration_covariance: the diagonal 3x3 (row-major,
  off-diagonals 0) of that sample's predicted discrete-time variances, (rad/s)^2 and (m/s^2)^2
  (:func:`refine_with_variance`); orientation_covariance is kept.

Each layout's module in :mod:`imu_learn.data.formats` reads and writes it; every file is written to a
temporary file beside its target and renamed into place (:mod:`imu_learn.util.atomic`). The input is
never written: an OUT that resolves to the input file (or, with ``--copy-folder``, the input
folder) is refused. Errors print one line and exit with status 2.

Stitching rule (bidirectional model). A sequence of N samples is cut into windows of W samples
starting every S = W - O samples (O the overlap); the last window is moved back to end at N so that
every window is full length (N <= W: one window of N). Consecutive windows k, k+1 overlap on
[s_{k+1}, e_k); sample i of the overlap is taken from window k if i < b = (s_{k+1} + e_k) // 2 and
from window k+1 otherwise: each sample comes from the window in which it lies farthest from a
window edge (a centre crop keeping ~O/2 samples of context on each side), and the first and last
windows keep their outer edges, which are the sequence's own. The result therefore approximates
running the model over the whole sequence at once; the difference is bounded by how much the LSTM
remembers beyond O/2 samples (measured in tests/test_refine.py). For W >= N it is exact.

Causal model: windows of W samples run one after the other with the LSTM state carried over, which
is the whole-sequence causal forward exactly (no overlap, no stitching; ``overlap`` is unused).

Precision: the network runs in float32; its correction (model output minus its float32 input) is
added to the float64 raw samples, so a model whose correction is zero returns the input bit for bit.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np
import torch

from imu_learn.data import formats
from imu_learn.data.formats import ImuSource
from imu_learn.errors import InvalidInputError
from imu_learn.nn.model import ImuRefiner

FORMATS = ("auto", *formats.FORMATS)


# --------------------------------------------------------------------------------------------
# Windowing and the model
# --------------------------------------------------------------------------------------------


def window_plan(n: int, window: int, overlap: int) -> List[Tuple[int, int, int, int]]:
    """The windows of the stitching rule: (start, end, keep_from, keep_to) per window, where the
    window covers samples [start, end) and contributes samples [keep_from, keep_to) to the output.
    The kept ranges tile [0, n) in order."""
    if window < 1:
        raise InvalidInputError(f"window must be >= 1, got {window}")
    if not 0 <= overlap < window:
        raise InvalidInputError(f"overlap must be in [0, window), got overlap {overlap} for window {window}")
    if n <= window:
        return [(0, n, 0, n)] if n > 0 else []
    stride = window - overlap
    starts = list(range(0, n - window + 1, stride))
    if starts[-1] + window < n:
        starts.append(n - window)
    plan = []
    for k, s in enumerate(starts):
        e = s + window
        keep_from = 0 if k == 0 else (s + starts[k - 1] + window) // 2
        keep_to = n if k == len(starts) - 1 else (starts[k + 1] + e) // 2
        plan.append((s, e, keep_from, keep_to))
    return plan


def _device_of(model: ImuRefiner) -> torch.device:
    return next(iter(model.parameters())).device


def _progress(total: int, enabled: bool, desc: str):
    from tqdm import tqdm

    return tqdm(total=total, disable=not enabled, desc=desc, unit="sample", unit_scale=True, file=sys.stderr)


def refine_corrections(
    model: ImuRefiner,
    imu32: np.ndarray,
    window: int = 1000,
    overlap: int = 200,
    batch: int = 16,
    progress: bool = False,
) -> np.ndarray:
    """Corrections (N, 6) float32 = model output - input, by the module's windowing rule."""
    return _windowed(model, imu32, window, overlap, batch, progress, False)[0]


@torch.no_grad()
def _windowed(model: ImuRefiner, imu32: np.ndarray, window: int, overlap: int, batch: int, progress: bool,
              variance: bool) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Corrections (N, 6) and, with ``variance``, the covariance head's variances (N, 6), both
    float32, stitched by the same windowing rule."""
    n = len(imu32)
    out = np.zeros((n, 6), dtype=np.float32)
    var_out = np.zeros((n, 6), dtype=np.float32) if variance else None
    if variance and getattr(model, "cov_head", None) is None:
        raise InvalidInputError("this model has no covariance head (trained with model.covariance = false)")
    if n == 0:
        return out, var_out
    device = _device_of(model)
    x_all = torch.from_numpy(np.ascontiguousarray(imu32, dtype=np.float32)).to(device)
    was_training = model.training
    model.eval()
    try:
        if model.cfg.causal:
            state = None
            with _progress(n, progress, "refine (causal)") as bar:
                for s in range(0, n, window):
                    x = x_all[None, s : s + window]
                    if var_out is not None:
                        y, v, state = model.forward_full(x, state)
                        var_out[s : s + window] = v[0].float().cpu().numpy()
                    else:  # any model with forward_with_state (the baselines' nets too)
                        y, state = model.forward_with_state(x, state)
                    out[s : s + window] = (y - x)[0].float().cpu().numpy()
                    bar.update(x.shape[1])
            return out, var_out
        plan = window_plan(n, window, overlap)
        with _progress(n, progress, "refine") as bar:
            for b0 in range(0, len(plan), max(1, batch)):
                chunk = plan[b0 : b0 + max(1, batch)]
                x = torch.stack([x_all[s:e] for s, e, _, _ in chunk])
                if var_out is not None:
                    y, v = model(x, with_variance=True)
                    vv = v.float().cpu().numpy()
                else:  # any model mapping (B, W, 6) to (B, W, 6) (the baselines' nets too)
                    y, vv = model(x), None
                corr = (y - x).float().cpu().numpy()
                for j, (s, _e, kf, kt) in enumerate(chunk):
                    out[kf:kt] = corr[j, kf - s : kt - s]
                    if var_out is not None and vv is not None:
                        var_out[kf:kt] = vv[j, kf - s : kt - s]
                bar.update(chunk[-1][3] - chunk[0][2])
    finally:
        model.train(was_training)
    return out, var_out


def refine_arrays(
    model: ImuRefiner,
    gyro: np.ndarray,
    acc: np.ndarray,
    window: int = 1000,
    overlap: int = 200,
    batch: int = 16,
    progress: bool = False,
) -> Tuple[np.ndarray, np.ndarray]:
    """Refine raw gyro [rad/s] and acc [m/s^2] (N, 3) with ``model`` -> (gyro, acc) float64 (N, 3).

    Bidirectional model: overlapping windows stitched by centre crop (see the module docstring);
    causal model: sequential windows with carried state (exact). ``batch`` windows run at once.
    """
    g, a, _ = _refine(model, gyro, acc, window, overlap, batch, progress, False)
    return g, a


def refine_with_variance(
    model: ImuRefiner,
    gyro: np.ndarray,
    acc: np.ndarray,
    window: int = 1000,
    overlap: int = 200,
    batch: int = 16,
    progress: bool = False,
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`refine_arrays` plus the covariance head's per-sample noise variances (N, 6) float64,
    gyro then acc, discrete-time ((rad/s)^2, (m/s^2)^2: the variance of one sample; a noise density
    is sigma * sqrt(dt), see :mod:`imu_learn.nn.covariance`)."""
    g, a, v = _refine(model, gyro, acc, window, overlap, batch, progress, True)
    assert v is not None
    return g, a, v


def _refine(model: ImuRefiner, gyro: np.ndarray, acc: np.ndarray, window: int, overlap: int, batch: int,
            progress: bool, variance: bool) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    gyro = np.asarray(gyro, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or acc.shape != gyro.shape:
        raise InvalidInputError(f"gyro and acc must both be (N, 3); got {gyro.shape} and {acc.shape}")
    raw = np.concatenate([gyro, acc], axis=1)
    if not np.isfinite(raw).all():
        raise InvalidInputError(f"IMU row {int(np.flatnonzero(~np.isfinite(raw).all(1))[0])} is not finite")
    x32 = raw.astype(np.float32)
    corr, var = _windowed(model, x32, window, overlap, batch, progress, variance)
    refined = raw + corr.astype(np.float64)
    return (np.ascontiguousarray(refined[:, :3]), np.ascontiguousarray(refined[:, 3:]),
            None if var is None else var.astype(np.float64))


# --------------------------------------------------------------------------------------------
# Where the refined IMU goes (reading and writing each layout is imu_learn.data.formats' job)
# --------------------------------------------------------------------------------------------


def output_file(src: ImuSource, out: Path) -> Path:
    """The file to write for OUT: OUT itself when it names a file of the input's kind, else the
    input's relative path under the folder OUT."""
    if out.suffix.lower() == src.imu_file.suffix.lower() and not out.is_dir():
        return out
    return out / src.rel


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _inside(child: Path, parent: Path) -> bool:
    try:
        child.resolve().relative_to(parent.resolve())
        return True
    except ValueError:
        return False


def refine_recording(
    model: ImuRefiner,
    input: Path,
    output: Path,
    fmt: str = "auto",
    window: int = 1000,
    overlap: int = 200,
    copy_folder: bool = False,
    batch: int = 16,
    progress: bool = False,
    imu_topic: Optional[str] = None,
    fill_covariance: bool = False,
) -> Path:
    """Refine one recording; returns the file (or ROS 2 bag folder) written. ``imu_topic``: the
    IMU topic of a ROS bag; ``fill_covariance``: a bag's IMU covariance fields get the model's
    per-sample variances (the model needs a covariance head)."""
    input, output = Path(input), Path(output)
    src = formats.read_imu_source(input, fmt, imu_topic)
    if fill_covariance and src.fmt != formats.rosbag.NAME:
        raise InvalidInputError(f"--fill-covariance writes the covariance fields of a ROS bag's IMU messages; "
                                f"{input} is {src.fmt}, not a bag")
    if copy_folder and src.fmt == formats.rosbag.NAME:
        raise InvalidInputError("--copy-folder does not apply to ROS bags: the output bag holds every topic already")
    if copy_folder:
        if output.suffix.lower() == src.imu_file.suffix.lower() and not output.is_dir():
            raise InvalidInputError(f"--copy-folder needs OUT to be a folder, got {output}")
        if _same(output, src.root) or _inside(output, src.root) or _inside(src.root, output):
            raise InvalidInputError(f"--copy-folder: OUT {output} and the input folder {src.root} overlap")
        if output.exists() and (not output.is_dir() or any(output.iterdir())):
            raise InvalidInputError(f"--copy-folder: {output} exists and is not an empty folder")
    target = output_file(src, output)
    if _same(target, src.imu_file) or _same(output, input):
        raise InvalidInputError(f"refusing to overwrite the input: OUT {output} is the input {input}")
    if fill_covariance:
        gyro, acc, var = refine_with_variance(model, src.gyro, src.acc, window, overlap, batch, progress)
        formats.rosbag.write_imu(src, target, gyro, acc, variances=var)
        return target
    gyro, acc = refine_arrays(model, src.gyro, src.acc, window, overlap, batch, progress)
    if copy_folder:
        shutil.copytree(src.root, output, dirs_exist_ok=True)
    formats.write_imu(src, target, gyro, acc)
    return target


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def require_covariance_head(model: ImuRefiner, checkpoint: Path) -> None:
    """Before any input is read: ``--fill-covariance`` needs variances, which only a model with a
    covariance head predicts."""
    if getattr(model, "cov_head", None) is None:
        raise InvalidInputError(f"{checkpoint}: no covariance head (trained with model.covariance = false); "
                                f"--fill-covariance needs one, e.g. models/euroc_adis16448_cov.pt")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m imu_learn.refine",
        description="Write a recording's IMU refined by a trained model, in the input's own format.",
    )
    p.add_argument("--checkpoint", required=True, type=Path, help="imu_learn checkpoint (.pt)")
    p.add_argument("--input", required=True, type=Path, help="recording folder, IMU file or ROS bag (never written)")
    p.add_argument("--output", required=True, type=Path, help="folder, or a file (or bag) of the input's kind")
    p.add_argument("--format", default="auto", choices=FORMATS)
    p.add_argument("--imu-topic", help="ROS bags: the sensor_msgs/msg/Imu topic (default: the bag's only one)")
    p.add_argument("--window", type=int, default=1000, help="samples per window (default 1000)")
    p.add_argument("--overlap", type=int, default=200, help="overlap of consecutive windows (default 200)")
    p.add_argument("--batch", type=int, default=16, help="windows run at once (default 16)")
    p.add_argument("--device", default="auto", help="auto (cuda if available), cpu, cuda, cuda:1 ...")
    p.add_argument("--copy-folder", action="store_true", help="copy the whole input folder to OUT first")
    p.add_argument("--fill-covariance", action="store_true",
                   help="ROS bags, a checkpoint with a covariance head: write each IMU message's angular_velocity / "
                        "linear_acceleration covariance as the diagonal of its predicted per-sample variances")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    return p


def main(argv: Optional[List[str]] = None) -> int:
    args = _parser().parse_args(argv)
    try:
        from imu_learn.train.checkpoint import load_model

        device = pick_device(args.device)
        model = load_model(args.checkpoint).to(device)
        if args.fill_covariance:
            require_covariance_head(model, args.checkpoint)
        target = refine_recording(
            model, args.input, args.output, args.format, args.window, args.overlap, args.copy_folder,
            args.batch, progress=not args.quiet, imu_topic=args.imu_topic, fill_covariance=args.fill_covariance,
        )
    except Exception as e:  # every failure is one line and status 2
        msg = " ".join(str(e).split()) or type(e).__name__
        print(f"error: {type(e).__name__}: {msg}", file=sys.stderr)
        return 2
    if not args.quiet:
        kind = "causal" if model.cfg.causal else f"window {args.window}, overlap {args.overlap}"
        cov = "; covariance fields: learned per-sample variances" if args.fill_covariance else ""
        print(f"refined IMU ({kind}, {device}{cov}) written to {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
