"""``imu-learn evaluate``'s ``profile:PATH`` method: a device profile's floor as it ships, scored beside
the floors fitted on the training split (nothing is fitted: the profile is what it is).

The floor is the profile's ``floor`` entry (``traditional+timing``'s saved dict, whichever terms
calibrate chose for it), applied as :meth:`imu_learn.calib.profile.Profile.apply` applies it (both are
:meth:`imu_learn.baselines.affine.Floor.apply`). A profile without a floor (noise only) leaves the IMU as
recorded. The file is read when the method is made: a missing one is FileNotFoundError, a malformed
one a :class:`imu_learn.errors.ProfileError` naming the file and the field. Note that the profile may
have been fitted on recordings that are test recordings here: choose the split accordingly."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from imu_learn.baselines.affine import Floor
from imu_learn.baselines.base import FitSettings, Method
from imu_learn.data.types import Segment
from imu_learn.errors import ProfileError


def read_floor(path: Path) -> Optional[Floor]:
    """The floor of the profile at ``path`` (None: a noise-only profile)."""
    where = str(path)
    try:
        d: Any = json.loads(Path(path).read_text())
    except json.JSONDecodeError as e:
        raise ProfileError(f"{where}:{e.lineno}: not JSON ({e.msg})", where, e.lineno, e.colno) from None
    floor = d.get("floor") if isinstance(d, dict) else None
    if not isinstance(floor, dict):
        raise ProfileError(f"{where}: field 'floor': missing (not an imu-learn device profile?)", where, field="floor")
    if not floor:
        return None
    Floor.check_dict(floor, lambda k, what: ProfileError(f"{where}: field 'floor.{k}': {what}", where,
                                                          field=f"floor.{k}"))
    return Floor.from_dict(floor)


class ProfileFloor(Method):
    """The floor of a device profile (``profile.json``), fitted on nothing here."""

    name = "profile"
    rotation_only = False

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.floor = read_floor(self.path)

    def fit(self, train: List[Segment], val: List[Segment], settings: FitSettings = FitSettings()) -> Dict[str, list]:
        return {"profile": [str(self.path)]}

    def refine(self, seq: Segment) -> Tuple[np.ndarray, np.ndarray]:
        if self.floor is None:
            return np.array(seq.gyro, dtype=np.float64), np.array(seq.acc, dtype=np.float64)
        return self.floor.apply(np.asarray(seq.t_ns, dtype=np.int64), seq.gyro, seq.acc)
