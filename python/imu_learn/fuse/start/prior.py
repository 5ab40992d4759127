"""The first state's bias prior from a device profile (:func:`profile_bias_sigmas`).

Once a profile's floor has been applied, what is left of the IMU's bias on a new recording is that
recording's own departure from the device's mean: the spread of the bias *between recordings*. The
profile's ``bias_std`` is not that spread but the standard error of the floor's mean over its groups
(:mod:`imu_learn.calib.fit`: the spread of the per-group values over sqrt(groups)), so the
per-recording spread is ``bias_std × sqrt(groups)``, ``groups`` the profile's
``fit_log["groups"]`` (one entry per recording refitted alone;
:meth:`imu_learn.calib.profile.Profile.recording_groups`, the ``--bias`` prior's rule too). A
profile fitted on one recording has time blocks of it as groups (``block1`` ..): their spread is not between recordings, and the
defaults (:class:`~imu_learn.fuse.settings.PriorSigmas`) are kept.

Per axis (the profile's axes are the body's when the IMU is not rotated into another body frame;
with a mounting, ``isotropic``: the largest axis' spread on every axis, as the gyro's ``--bias``
prior does), each floored at :data:`GYRO_SPREAD_FLOOR` / :data:`ACC_SPREAD_FLOOR` (a spread from a
handful of recordings may come out small by chance) and never looser than the defaults.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple

import numpy as np

from imu_learn.core.still import BIAS_SPREAD_FLOOR

from ..settings import PriorSigmas

# rad/s: the least gyro bias spread a profile's prior is given (the still rule's floor for a profile
# fitted on few recordings, imu_learn.core.still.BIAS_SPREAD_FLOOR)
GYRO_SPREAD_FLOOR = BIAS_SPREAD_FLOOR
# m/s^2: the least accelerometer bias spread (about 1 mg, the order of an ADIS16448-class MEMS
# accelerometer's bias repeatability; EuRoC's profile spreads 0.05-0.11 m/s^2 by axis, above it)
ACC_SPREAD_FLOOR = 0.01


def profile_bias_sigmas(profile, defaults: PriorSigmas = PriorSigmas(), isotropic: bool = False
                        ) -> Tuple[Optional[Tuple[Tuple[float, ...], Tuple[float, ...]]], Dict[str, object]]:
    """((gyro sigmas [rad/s], acc sigmas [m/s^2]), each per axis) or None, the summary's entry): the
    first state's bias prior from ``profile`` (an :class:`imu_learn.calib.profile.Profile`; module
    docstring; ``isotropic``: the largest axis on every axis). None, with the reason in the entry, where
    the profile does not give a per-recording spread (fewer than two recordings, time blocks of one,
    or no ``bias_std``): the defaults then."""
    n, _ = profile.recording_groups()
    entry: Dict[str, object] = {"groups": n}
    (gyro, why_g), (acc, why_a) = profile.bias_spread("gyro"), profile.bias_spread("acc")
    if gyro is None or acc is None:
        entry["source"] = (f"defaults (gyro {defaults.bias_gyro} rad/s, acc {defaults.bias_acc} m/s^2): "
                           + (why_g if gyro is None else why_a))
        return None, entry

    def sigmas(spread: np.ndarray, floor: float, default) -> Tuple[float, ...]:
        s = np.full(3, spread.max()) if isotropic else spread
        return tuple(float(v) for v in np.minimum(np.maximum(s, floor), np.broadcast_to(default, (3,))))

    sg = sigmas(gyro, GYRO_SPREAD_FLOOR, defaults.bias_gyro)
    sa = sigmas(acc, ACC_SPREAD_FLOOR, defaults.bias_acc)
    entry.update({
        "source": (f"the profile's per-recording bias spread: bias_std x sqrt({n} groups), "
                   + ("its largest axis on every axis (the IMU rotated into the body frame), " if isotropic
                      else "per axis, ")
                   + f"floored at {GYRO_SPREAD_FLOOR:g} rad/s / {ACC_SPREAD_FLOOR:g} m/s^2"),
        "gyro_per_recording_rad_s": [round(float(v), 6) for v in gyro],
        "acc_per_recording_mps2": [round(float(v), 6) for v in acc],
        "bias_gyro_rad_s": [round(v, 6) for v in sg], "bias_acc_mps2": [round(v, 6) for v in sa]})
    return (sg, sa), entry
