"""GNSS velocities as factors: a velocity prior at each fix's keyframe (the epoch's ENU velocity from
an RTKLIB solution), as rtklibexplorer/GNSS_IMU's EKF uses them; the antenna's rotation-induced
velocity (omega x lever, ~cm/s with car lever arms) is neglected."""
from __future__ import annotations

from typing import Callable

from imu_learn.errors import InvalidInputError

from ..aiding.rtklib import RtkSolution
from ..aiding.types import GnssFixes


def velocity_callback(fixes: GnssFixes, sol: RtkSolution, sigma: float, float_gain: float) -> Callable:
    """An ``extra_factors`` callback adding a velocity prior at each fix's keyframe (the epoch's
    ENU velocity; sigma times ``float_gain`` for float epochs)."""
    import gtsam
    from gtsam.symbol_shorthand import V

    if sol.vel_enu is None:
        raise InvalidInputError(f"{sol.path}: velocity_sigma_mps > 0 but the file has no velocity columns")
    at = {int(s): (sol.vel_enu[e], sigma * (1.0 if q == 1 else float_gain))
          for s, e, q in zip(fixes.idx, fixes.epoch, fixes.q)}

    def extra(inc, k: int, s: int) -> list:
        if s not in at:
            return []
        v, sg = at[s]
        return [gtsam.PriorFactorVector(V(k), v, gtsam.noiseModel.Isotropic.Sigma(3, sg))]

    return extra
