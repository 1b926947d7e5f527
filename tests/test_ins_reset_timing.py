"""The INS state after a reset is at the reset time: the first IMU sample's step starts there.

The closed loop resets every navigator with the truth at t = 0 and its first IMU sample is the one at
t = dt (the mean over (0, dt] for an integrating IMU). Starting the INS clock at that first sample dropped
one IMU interval: a constant along-track lag of v dt (0.86 m at 80 m/s and 100 Hz), the same in every run,
which the terrain filters' Monte Carlo saw as an error common to all runs."""

import math

import numpy as np
import pytest
from _ins_truth import noise_free_ins_errors
from trn_env.navigators.inertial.strapdown import StrapdownIns

from trn_env.flight.kinematic import KinematicTruth, Segment

SPEED_MPS = 240.0


@pytest.mark.parametrize("sampling", ["interval", "instant"])
def test_first_imu_sample_after_the_reset_time_leaves_no_lag(sampling):
    k = KinematicTruth(math.radians(36.55), math.radians(-84.3), 2500.0, SPEED_MPS, math.radians(18.0),
                       [Segment("straight", 20.0)], rate_hz=100.0)
    t0 = k.advance(1)          # the reset state (t = 0), as the closed loop's truth at reset
    rest = k.advance(1999)     # what the sensors sample: t = 0.01 ... 19.99
    assert rest.t_s[0] > t0.t_s[0]
    dn, de, _, _, ins = noise_free_ins_errors(rest, sampling, start=t0)
    # one dropped interval would be 2.4 m here (240 m/s x 0.01 s); the figure: docs/validation/ins.md
    print(f"INS after a mid-flight reset ({sampling}): max horizontal error {np.hypot(dn, de).max():.2e} m")
    assert np.hypot(dn, de).max() < 0.05, np.hypot(dn, de).max()
    assert ins.t_s == pytest.approx(float(rest.t_s[-1]))


def test_first_sample_at_the_reset_time_is_the_left_end_of_the_next_step():
    """An "instant" first sample at the reset time itself does not move the state and is the trapezoid's
    left end for the step that follows (the tests that sample the reset row rely on this)."""
    ins = StrapdownIns("j2", tau_baro_s=None, imu_samples="instant")
    ins.reset(5.0, 0.6, -1.4, 1000.0, [80.0, 0.0, 0.0], 0.0, 0.0, 0.0)
    before = ins.state.copy()
    out = ins.propagate([5.0], np.array([[0.0, 0.0, -9.8]]), np.zeros((1, 3)))
    assert np.array_equal(out[0], before)
    assert ins.prev_imu[0] == 5.0 and ins.prev_imu[3] == -9.8
