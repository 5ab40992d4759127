"""The core's ``filtfilt_section`` (the floor's order-2 low-pass, baselines/affine.py's ``filtfilt2``):
scipy's ``sosfiltfilt`` is its oracle on real-looking signals (tests/test_floor_numpy.py); here the
binding's refusals, each a typed error, never a panic."""
import numpy as np
import pytest

from imu_learn import _imu_core as core
from imu_learn.baselines.affine import butter2
from imu_learn.errors import InvalidInputError

SOS = butter2(5.0, 200.0)[0]


def test_a_signal_too_short_for_the_padding_is_refused():
    with pytest.raises(InvalidInputError, match="needs more than 9"):
        core.filtfilt_section(np.ones((9, 3)), SOS)


@pytest.mark.parametrize("sos,what", [(SOS[:5], "expected 6"), (np.r_[SOS[:5], np.nan], "not finite"),
                                      (np.r_[SOS[:3], 0.0, SOS[4:]], "a0"),
                                      (np.array([1.0, 0.0, 0.0, 1.0, -2.0, 1.0]), "pole at z = 1")])
def test_a_bad_section_is_refused(sos, what):
    with pytest.raises(InvalidInputError, match=what):
        core.filtfilt_section(np.ones((50, 3)), np.ascontiguousarray(sos))


def test_a_strided_signal_is_refused_not_copied_silently():
    x = np.ones((100, 6))[:, ::2]
    with pytest.raises(InvalidInputError, match="C-contiguous"):
        core.filtfilt_section(x, SOS)


def test_each_column_alone_and_a_constant_unchanged():
    rng = np.random.default_rng(3)
    x = np.column_stack([np.full(400, 9.81), rng.normal(size=400)])
    y = core.filtfilt_section(x, SOS)
    np.testing.assert_allclose(y[:, 0], 9.81, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(y[:, 1], core.filtfilt_section(np.ascontiguousarray(x[:, 1:]), SOS)[:, 0])
