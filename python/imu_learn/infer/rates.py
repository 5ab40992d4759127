"""Is a model or a device profile made for this recording? Its sample rate and its device.

A model (:func:`imu_learn.infer.checkpoint.imu_record`) and a device profile record the IMU they
were made from: its sample rate and its device. Applied to a recording whose rate (the one
sample-rate rule, :func:`imu_learn.data.types.sample_rate_hz`) is more than :data:`TOLERANCE` off,
:func:`check` stops with one line naming both rates (an :class:`InvalidInputError`: exit 2 from
the CLI); ``force`` turns that into a warning line. A profile in which nothing depends on the rate
(``MadeFor.rate_terms`` empty: biases, matrices and noise densities, no time offset it observed and no
low-pass) applies at any rate, with a warning line. A recording of another device is a warning
line. An unknown rate or device on either side is not checked (the caller says so in an info line).

The recording's device is the name the user gives it (``--imu-name``), else the dataset its format
belongs to (blackbird, broad, fetch, kaist; ``--format euroc`` / ``tum-vi``), else unknown.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Sequence

from imu_learn.errors import InvalidInputError

TOLERANCE = 0.05  # the largest relative difference of two rates taken as the same rate
# Formats that only one device writes: their name is the device's (the dataset's) name.
DEVICE_FORMATS = ("euroc", "tum-vi", "blackbird", "broad", "kaist", "fetch")


@dataclass(frozen=True)
class MadeFor:
    """What a model or profile was made from: ``what`` names it in messages ("model
    models/euroc_adis16448.pt"); ``sample_rate_hz`` / ``device`` None where unknown."""

    what: str
    sample_rate_hz: Optional[float]
    device: Optional[str]
    # what of it depends on the rate, in words (:meth:`imu_learn.calib.profile.Profile.rate_terms`); "": nothing
    # (a profile of biases and matrices applies at any rate); None: all of it (a model)
    rate_terms: Optional[str] = None


def hz(rate: float) -> str:
    """A rate as the messages print it: ``200 Hz``, ``285.7 Hz``, ``99.98 Hz``."""
    return f"{rate:.4g} Hz"


def recording_device(fmt: str, given_format: str = "auto", name: Optional[str] = None) -> Optional[str]:
    """The device of a recording read as ``fmt`` (its layout) with ``--format given_format``:
    ``name`` when given, else the dataset name of a one-device format, else None (unknown)."""
    if name:
        return name
    for f in (given_format, fmt):
        if f in DEVICE_FORMATS:
            return f
    return None


def _key(name: str) -> str:
    return "".join(c for c in name.lower() if c.isalnum())


def same_device(recording: str, made_for: str) -> bool:
    """Whether a recording of device ``recording`` is one ``made_for`` (devices joined by "+") was made for:
    the same name, or a profile named ``DATASET_SENSOR`` (the shipped ones: ``fetch_debias``,
    ``tumvi_bmi160``) for a recording of that dataset's format; case and punctuation aside."""
    names = [d.strip() for d in made_for.split("+")]
    return _key(recording) in {_key(n) for n in names} | {_key(n.split("_")[0]) for n in names}


def check(recording: str, rate_hz: Optional[float], device: Optional[str], made_for: Sequence[MadeFor],
          force: bool = False, forceable: bool = True) -> List[str]:
    """The warning lines for applying each of ``made_for`` to a recording (``recording`` names it)
    of rate ``rate_hz`` and ``device``; raises :class:`InvalidInputError` (one line, both rates)
    for a rate more than :data:`TOLERANCE` off unless ``force`` (``forceable``: the command has a
    ``--force``, which the line then offers)."""
    warnings: List[str] = []
    for m in made_for:
        if rate_hz and m.sample_rate_hz and abs(rate_hz - m.sample_rate_hz) > TOLERANCE * m.sample_rate_hz:
            line = (f"{recording} is sampled at {hz(rate_hz)} but {m.what} is for {hz(m.sample_rate_hz)} "
                    f"(more than {TOLERANCE * 100:.0f} % off)")
            if m.rate_terms == "":
                warnings.append(f"{line}; applied: nothing in it depends on the rate (biases, matrices, noise "
                                "densities; no time offset it observed, no low-pass)")
            elif not force:
                raise InvalidInputError(f"{line}" + (f": its {m.rate_terms} depend on the rate" if m.rate_terms else "")
                                        + "; use a model or profile made at this rate"
                                        + (", or --force to apply it anyway" if forceable else ""))
            else:
                warnings.append(f"{line}; applied anyway (--force)")
        if device and m.device and not same_device(device, m.device):
            warnings.append(f"{recording} is from device {device!r} but {m.what} was made for {m.device!r}; check it "
                            "on your recording first (docs/refine.md)")
    return warnings


def other_devices(added: MadeFor, made_for: Sequence[MadeFor]) -> List[str]:
    """The warning lines for applying ``added`` (a bias estimator) together with each of ``made_for`` made
    for another device (the recording's own device is :func:`check`'s)."""
    return [f"{added.what} was trained on device {added.device!r} but {m.what} is for {m.device!r}: a bias "
            "estimator learns its own device's bias; use one trained on this device"
            for m in made_for if added.device and m.device and not same_device(added.device, m.device)]


def unchecked(rate_hz: Optional[float], made_for: Sequence[MadeFor]) -> List[str]:
    """Info lines for what :func:`check` could not check (a rate unknown on either side)."""
    lines = [f"{m.what} records no sample rate: the recording's rate is not checked"
             for m in made_for if not m.sample_rate_hz]
    if not rate_hz and made_for:
        lines.append("the recording has no stamps of its own: its rate is not checked")
    return lines
