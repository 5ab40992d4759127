"""A sensor's extrinsic calibration: ``T_BS`` of a Kalibr / EuRoC (ASL) ``sensor.yaml``.

``T_BS`` is the sensor frame S (a camera, a Leica prism) expressed in the body frame B, which in
EuRoC is the IMU frame: ``p_B = R_BS p_S + t_BS``. A camera pose ``T_C0_Ck`` (camera k in the first
camera's frame) therefore becomes the body pose ``T_C0_Ck T_BS^-1`` in that frame, and a relative
camera motion ``T_Ci_Cj`` the body motion ``T_BS T_Ci_Cj T_BS^-1``.

The file is OpenCV-flavoured YAML (``%YAML:1.0``, a ``T_BS:`` block with ``cols``, ``rows`` and
``data: [16 numbers, row-major]``, the list possibly spread over lines). It is read with the
small parser of :func:`imu_learn.data.formats.asl.read_sensor_yaml` (no YAML library needed).
A missing file is :class:`FileNotFoundError`; a missing ``T_BS``, a ``data`` list that is not 16
numbers, ``rows``/``cols`` other than 4, a last row other than ``0 0 0 1`` or a rotation block that
is not a rotation: :class:`imu_learn.errors.ExtrinsicsError` naming the file, the line and the field.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

import numpy as np

from imu_learn.data.formats.asl import read_sensor_yaml
from imu_learn.errors import ExtrinsicsError, ParseError

ROTATION_TOL = 1e-3  # |R^T R - I| and |det R - 1| above this: not a rotation (calibrations print ~1e-9)


def _line_of(lines: list, key: str) -> Optional[int]:
    for i, raw in enumerate(lines, start=1):
        text = raw.split("#", 1)[0]
        if text.strip().startswith(f"{key}:"):
            return i
    return None


def read_t_bs(path: Union[str, Path]) -> np.ndarray:
    """The 4x4 ``T_BS`` (sensor to body) of a Kalibr/ASL ``sensor.yaml`` (module docstring)."""
    path = Path(path)
    src = str(path)
    if path.is_dir():
        raise ExtrinsicsError(f"{src}: a folder, not a sensor.yaml (give the file holding T_BS, e.g. "
                              f"{path / 'sensor.yaml'})", src, None, None, None)
    if not path.is_file():
        raise FileNotFoundError(2, "No such file or directory", src)
    try:
        path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ExtrinsicsError(f"{src}: not a text YAML file (byte {e.start} is not UTF-8): give the sensor.yaml "
                              "holding T_BS", src, None, None, None) from None
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    at = _line_of(lines, "T_BS")
    try:
        y = read_sensor_yaml(path)
    except ParseError as e:  # T_BS's data is not 16 numbers
        raise ExtrinsicsError(str(e), src, e.line or at, None, "T_BS.data") from None
    if "T_BS" not in y or at is None:
        raise ExtrinsicsError(f"{src}: no T_BS entry (the sensor-to-body transform, a 4x4 'data: [...]' block)",
                              src, None, None, "T_BS")
    # rows / cols of the block, when given, must say 4x4
    for key in ("rows", "cols"):
        for i in range(at, min(at + 4, len(lines))):
            text = lines[i].split("#", 1)[0].strip()
            if text.startswith(f"{key}:"):
                val = text.partition(":")[2].strip()
                if val != "4":
                    raise ExtrinsicsError(f"{src}:{i + 1}: T_BS.{key}: {val!r}, expected 4", src, i + 1, None,
                                          f"T_BS.{key}")
    T = np.asarray(y["T_BS"], dtype=np.float64)
    if not np.all(np.isfinite(T)):
        raise ExtrinsicsError(f"{src}:{at}: T_BS.data holds a value that is not finite", src, at, None, "T_BS.data")
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ExtrinsicsError(f"{src}:{at}: T_BS.data: last row {T[3].tolist()}, expected [0, 0, 0, 1]",
                              src, at, None, "T_BS.data")
    R = T[:3, :3]
    orth = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if orth > ROTATION_TOL or abs(det - 1.0) > ROTATION_TOL:
        raise ExtrinsicsError(f"{src}:{at}: T_BS.data: the 3x3 block is not a rotation (|R^T R - I| = {orth:.2g}, "
                              f"det {det:.4g})", src, at, None, "T_BS.data")
    # re-orthonormalise the printed digits (SVD: the nearest rotation)
    u, _, vt = np.linalg.svd(R)
    T = T.copy()
    T[:3, :3] = u @ vt
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """The inverse of a 4x4 rigid transform."""
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out
