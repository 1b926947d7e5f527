"""Kinematic truth (trn_env.flight.kinematic): a noise-free IMU of it drives the INS along it to centimetres,
and it is self-consistent (velocity integrates to position, chunked = whole)."""

import math

import numpy as np
import pytest
from _ins_truth import noise_free_ins_errors

from trn_env.flight.kinematic import KinematicTruth, Segment

SEGMENTS = [
    Segment("straight", 20.0),
    Segment("turn", 40.0, bank_deg=25.0, transition_s=5.0),
    Segment("climb", 30.0, flight_path_deg=4.0, transition_s=5.0),
    Segment("straight", 30.0, transition_s=5.0),
    Segment("turn", 30.0, bank_deg=-20.0, flight_path_deg=-3.0, transition_s=5.0),
]


def _truth():
    k = KinematicTruth(math.radians(36.55), math.radians(-84.3), 2500.0, 240.0, math.radians(18.1575),
                       SEGMENTS, rate_hz=100.0)
    return k, k.truth()


def test_ins_follows_kinematic_truth_to_centimetres():
    _, tr = _truth()
    dn, de, dd, dv, _ = noise_free_ins_errors(tr)
    err = np.sqrt(dn**2 + de**2 + dd**2)
    assert tr.t_s[-1] >= 149.0
    # a noise-free IMU of a consistent truth leaves only the integration's error (the figures behind these
    # margins: docs/validation/ins.md)
    print(f"INS vs kinematic truth over {tr.t_s[-1]:.0f} s: max position error {err.max():.3f} m, "
          f"max velocity error {1e3 * dv.max():.2f} mm/s")
    assert err.max() < 0.2, err.max()
    assert dv.max() < 4e-3, dv.max()
    # the profile really manoeuvres: heading changes by tens of degrees, height by > 100 m
    assert np.ptp(np.unwrap(tr.yaw_rad)) > math.radians(35) and np.ptp(tr.h_msl_m) > 100.0


def test_chunked_equals_whole_and_velocity_integrates_to_position():
    k, whole = _truth()
    k2 = KinematicTruth(math.radians(36.55), math.radians(-84.3), 2500.0, 240.0, math.radians(18.1575),
                        SEGMENTS, rate_hz=100.0)
    parts = [k2.advance(1), k2.advance(999), k2.advance(7000), k2.advance(len(whole) - 8000)]
    cat = np.concatenate([p.lat_rad for p in parts])
    assert np.allclose(cat, whole.lat_rad, rtol=0, atol=1e-12)
    assert np.allclose(np.concatenate([p.t_s for p in parts]), whole.t_s)
    # specific force in a 25-deg coordinated turn: sqrt(g^2 + (g0 tan 25)^2), less the Eotvos and v^2/R
    # terms (~0.03 m/s^2 at 240 m/s)
    i = np.searchsorted(whole.t_s, 45.0)
    g = 9.792  # normal gravity at 36.6 deg, 2.5 km
    assert abs(np.linalg.norm(whole.f_b_mps2[i]) - math.hypot(g, 9.80665 * math.tan(math.radians(25)))) < 0.06
    assert abs(whole.f_b_mps2[i, 1]) < 0.01   # coordinated: no side force


def test_bad_segments_raise_naming_the_field():
    with pytest.raises(ValueError, match="duration_s"):
        Segment("straight", -1.0)
    with pytest.raises(ValueError, match="bank_deg"):
        Segment("turn", 10.0)
    with pytest.raises(ValueError, match="kind"):
        Segment("loop", 10.0)
    with pytest.raises(ValueError, match="speed_mps"):
        KinematicTruth(0.6, -1.4, 2500.0, float("nan"), 0.0, [Segment("straight", 10.0)])
