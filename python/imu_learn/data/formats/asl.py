"""EuRoC / TUM-VI ASL folders (``mav0/imu0/data.csv`` + a ground-truth file): detect, read, write
the refined IMU, and the aiding files beside it (``sensor.yaml``, the Leica positions)."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from imu_learn import _imu_core as core
from imu_learn.data.types import GroundTruth, ImuData
from imu_learn.errors import ColumnCountError, FloatTimestampError, HeaderError, InvalidInputError, ParseError
from imu_learn.util.atomic import atomic_write_path

from .csv_columns import data_line_ends
from .groundtruth import read_groundtruth
from .input_checks import check_fixed_units
from .source import ImuSource

NAME = "asl"

# Searched in order when no ground truth is named: the ASL layout's own files first, then the
# pose-only TUM file that open_vins ships beside a sequence.
GROUNDTRUTH_CANDIDATES = (
    "mav0/state_groundtruth_estimate0/data.csv",
    "mav0/mocap0/data.csv",
    "groundtruth_state.csv",
    "groundtruth_pose.tum",
    "groundtruth.tum",
    "groundtruth.txt",
)


def detect(path: Path) -> bool:
    """A sequence folder (holding ``mav0``), its ``mav0`` folder, or a ``.csv`` IMU file. KAIST's
    ``xsens_imu.csv`` is a ``.csv`` too: :func:`imu_learn.data.formats.detect_format` asks KAIST first."""
    return path.suffix.lower() == ".csv" or path.name == "mav0" or (path / "mav0").is_dir()


def find_recordings(root: Path) -> List[Path]:
    """Every sequence folder (one holding ``mav0``) under ``root``."""
    return [p.parent for p in root.rglob("mav0") if p.is_dir()]


def imu_file(path: Path) -> Path:
    """The IMU CSV of an ASL sequence folder, its ``mav0`` folder, or the CSV itself."""
    if path.is_file():
        return path
    for cand in (path / "mav0" / "imu0" / "data.csv", path / "imu0" / "data.csv"):
        if cand.exists():
            return cand
    raise FileNotFoundError(2, "No such file or directory", str(path / "mav0" / "imu0" / "data.csv"))


def sequence_root(path: Path) -> Path:
    """The folder that holds ``mav0`` for any path inside an ASL sequence."""
    p = path if path.is_dir() else path.parent
    for cand in (p, *p.parents):
        if (cand / "mav0").is_dir():
            return cand
    return p


def find_groundtruth(root: Path) -> Path:
    for rel in GROUNDTRUTH_CANDIDATES:
        if (root / rel).exists():
            return root / rel
    raise InvalidInputError(
        f"{root}: no ground truth found (looked for {', '.join(GROUNDTRUTH_CANDIDATES)}); "
        "give a TUM or ASL ground-truth file (--groundtruth FILE; groundtruth = \"FILE\" in a config)"
    )


def _read_imu_csv(path: Path, f: Path, allow_float_timestamps: bool = False):
    """The core's reading of IMU CSV ``f`` (of ``path``); a header that is not EuRoC's on a file given as
    such gets a note naming the options of a CSV of the user's own."""
    try:
        t_ns, gyro, acc = core.read_asl_imu(str(f), allow_float_timestamps)
        check_fixed_units(f, t_ns, gyro, acc, "an ASL (EuRoC) IMU file")
        return t_ns, gyro, acc
    except HeaderError as e:
        if Path(path).is_file():  # a CSV of the user's own, read as EuRoC's layout for want of a column map
            e.add_note("a CSV of your own: name its columns with --columns (e.g. t,gx,gy,gz,ax,ay,az) and its units "
                       "with --time-unit, --gyro-unit, --acc-unit (docs/your-device.md)")
        raise
    except ColumnCountError as e:
        if e.line is not None and e.line == data_line_ends(f)[1]:
            e.add_note(f"the last line, cut by the logger? delete it, or read {f} as a CSV of your own with "
                       "--columns t,gx,gy,gz,ax,ay,az --time-unit ns --skip-bad-lines")
        raise
    except FloatTimestampError as e:
        e.add_note(f"from the command line: read {f} as a CSV of your own, --columns t,gx,gy,gz,ax,ay,az --time-unit ns "
                   "(the stamps rounded as the file holds them), with --skip-bad-lines where lines that are not samples "
                   "(a spreadsheet's notes, empty rows) follow")
        raise


def read_imu(path: Path, allow_float_timestamps: bool = False) -> ImuData:
    t_ns, gyro, acc = _read_imu_csv(path, imu_file(Path(path)), allow_float_timestamps)
    return ImuData(t_ns=t_ns, gyro=gyro, acc=acc)


def read_recording(
    path: Path, groundtruth: Optional[Path] = None, allow_float_timestamps: bool = False
) -> Tuple[ImuData, GroundTruth]:
    imu = read_imu(path, allow_float_timestamps)
    gt_path = Path(groundtruth) if groundtruth is not None else find_groundtruth(sequence_root(Path(path)))
    return imu, read_groundtruth(gt_path, allow_float_timestamps)


def read_imu_source(path: Path) -> ImuSource:
    """The IMU of a sequence folder, its ``mav0`` or the IMU CSV itself, strictly parsed (integer
    ns stamps only: the refined copy keeps them as they are)."""
    f = imu_file(path)
    t_ns, gyro, acc = _read_imu_csv(path, f)
    root = sequence_root(f) if path.is_file() else (path.parent if path.name == "mav0" else path)
    try:
        rel = f.resolve().relative_to(root.resolve())
    except ValueError:  # a CSV outside any sequence folder stands alone
        root, rel = f.parent, Path(f.name)
    return ImuSource(NAME, f, root, rel, t_ns, gyro, acc)


def write_imu(src: ImuSource, out: Path, gyro: np.ndarray, acc: np.ndarray) -> None:
    """``out``: ``src``'s IMU CSV with gyro and acc replaced. The original header line, its line ends
    (the EuRoC zips' CRLF or LF) and integer ns stamps are kept; values are the shortest text that reads
    back to the same float64."""
    header = core.read_asl_imu_header(str(src.imu_file)).rstrip("\r\n")
    with open(src.imu_file, "rb") as fh:
        crlf = fh.readline().endswith(b"\r\n")
    g, a = np.ascontiguousarray(gyro), np.ascontiguousarray(acc)
    atomic_write_path(out, lambda tmp: core.write_asl_imu(str(tmp), src.t_ns, g, a, header, crlf))


# --------------------------------------------------------------------------------------------
# Sensor calibration files and the Leica laser tracker (aiding for imu_learn.fuse)
# --------------------------------------------------------------------------------------------

LEICA_FILE = Path("mav0") / "leica0" / "data.csv"
IMU_SENSOR_YAML = Path("mav0") / "imu0" / "sensor.yaml"


def imu_sensor_yaml(path: Path) -> Optional[Path]:
    """The IMU's ``sensor.yaml`` of an ASL sequence folder (its noise densities), or None."""
    yaml = Path(path) / IMU_SENSOR_YAML
    return yaml if yaml.exists() else None


def leica_file(path: Path) -> Optional[Path]:
    """The Leica position CSV of an ASL sequence folder (EuRoC's machine hall), or None."""
    csv = Path(path) / LEICA_FILE
    return csv if csv.exists() else None


def read_sensor_yaml(path: Path) -> dict:
    """An ASL ``sensor.yaml``: its scalar ``key: value`` entries (numbers as float, the rest as
    str) and ``T_BS`` as a 4x4 list of rows. Only the subset of YAML these files use (no YAML
    library needed); a malformed ``T_BS`` is a :class:`ParseError` naming the file and line."""
    path = Path(path)
    lines = path.read_text().splitlines()
    out: dict = {}
    i = 0
    while i < len(lines):
        raw = lines[i].split("#", 1)[0].rstrip()
        i += 1
        if not raw.strip() or raw.startswith((" ", "\t")) or ":" not in raw:
            continue
        key, _, value = raw.partition(":")
        key, value = key.strip(), value.strip()
        if key == "T_BS":
            start = i
            while i < len(lines) and "data:" not in lines[i]:
                i += 1
            text = ""
            while i < len(lines):
                text += lines[i].split("#", 1)[0]
                i += 1
                if "]" in text:
                    break
            body = text.partition("[")[2].partition("]")[0]
            try:
                vals = [float(x) for x in body.split(",") if x.strip()]
            except ValueError:
                vals = []
            if len(vals) != 16:
                raise ParseError(f"{path}:{start}: T_BS: expected 16 numbers in data: [...], got {body.strip()!r}",
                                 str(path), start, None, "T_BS")
            out["T_BS"] = [vals[r * 4:(r + 1) * 4] for r in range(4)]
            continue
        try:
            out[key] = float(value)
        except ValueError:
            out[key] = value
    return out


def read_leica(path: Path):
    """EuRoC's Leica MS50 positions (``mav0/leica0/data.csv`` of a sequence folder, or the CSV
    itself) -> ``(t_ns (N,), p (N, 3), lever_arm (3,))``: ``p`` is the tracked prism in the world
    frame, ``lever_arm`` the prism's position in the body frame (``T_BS`` translation of
    ``leica0/sensor.yaml``; zeros when the file is absent). Strict parsing in the Rust core."""
    path = Path(path)
    csv = path if path.is_file() else path / LEICA_FILE
    if not csv.exists():
        raise FileNotFoundError(2, "No such file or directory", str(csv))
    t_ns, p = core.read_asl_position(str(csv))
    yaml = csv.parent / "sensor.yaml"
    lever = np.zeros(3)
    if yaml.exists():
        T = read_sensor_yaml(yaml).get("T_BS")
        if T is not None:
            lever = np.array([T[0][3], T[1][3], T[2][3]], dtype=np.float64)
    return t_ns, p, lever
