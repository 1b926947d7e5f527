"""The INS + TERCOM EKF's turn term in the angle turn_angle = "excursion" names, against the attitude error
the real strapdown INS (navigators.inertial.strapdown) builds through a turn with the gyro's scale factor
and misalignment.

The motion: a straight leg whose heading wanders (2 deg, period 2 s, as turbulence and the autopilot move
it), a coordinated 90 deg turn at 24 deg of bank over 30 s, then the wandering straight leg again; perfect
IMU samples of it (tests/nav_reference_trajectory.py, computed in ECEF). The truth: the strapdown INS flown
on the gyro samples (I + E) w_ib with each of the 9 scale-factor / misalignment entries E set to its 1-sigma
value alone, minus the INS flown on the perfect samples; the attitude error is linear in E, so its
covariance is the sum of the 9 responses' outer products (the entries are independent). The navigator's
term: the attitude variance the `ins` EKF adds with the specification's scale factor and misalignment
(and no other error) over the one without. The excursion's attitude variance must bound the strapdown's
on every axis, within 2 x (the walk's sigma^2 TURN_REFERENCE per rad matches a 90 deg turn's
sigma^2 dpsi^2; the tilt reaches 2 sigma^2 (1 - cos dpsi) of it): the heading's includes the misalignment's
share in the bank (k = cos^4 + sin^4 of the bank; with the level-flight scale factor alone it was 0.29 x the
strapdown's here);
"total" (the integral of |yaw rate|) counts the wander's back-and-forth, which the INS undoes (the gyro
error of an oscillating yaw integrates to an oscillating tilt of the oscillation's amplitude), and must
exceed the truth by more than 2 x here.
"""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.core.error_states import PSID, PSIE, PSIN
from trn_env.navigators.core.imu_spec import ImuSpec
from trn_env.navigators.filters.ins_trn_ekf import initial_covariance
from trn_env.navigators.frames import BaroFrame, ImuFrame, SensorFrames
from trn_env.navigators.inertial.strapdown import StrapdownIns, quat_to_dcm
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

sys.path.insert(0, str(Path(__file__).parent))
from nav_reference_trajectory import imu_and_truth  # noqa: E402

LAT0, LON0, H = np.radians(33.2), np.radians(-98.2), 2500.0
V, G = 83.0, 9.80665
T0, T_TURN, T_END = 20.0, 30.0, 80.0
TURN_RAD = np.radians(90.0)
RATE = TURN_RAD / T_TURN
HEADING0 = np.radians(40.0)
WANDER_RAD = np.radians(2.0)
BANK_RAD = math.atan(V * RATE / G)
SCALE_PPM, MISALIGN_RAD = 150.0, 5e-4   # the tactical preset's gyro (trn_env.sensors.imu)


def _track(t):
    """Track angle: straight, a constant-rate turn between T0 and T0 + T_TURN, straight."""
    return HEADING0 + RATE * np.clip(t - T0, 0.0, T_TURN)


def _lla(t):
    a = np.clip(t, None, T0)
    b = np.clip(t, T0, T0 + T_TURN) - T0
    c = np.clip(t - T0 - T_TURN, 0.0, None)
    th1 = HEADING0 + TURN_RAD
    n = V * (a * np.cos(HEADING0) + (np.sin(HEADING0 + RATE * b) - np.sin(HEADING0)) / RATE + c * np.cos(th1))
    e = V * (a * np.sin(HEADING0) + (np.cos(HEADING0) - np.cos(HEADING0 + RATE * b)) / RATE + c * np.sin(th1))
    r_n, r_e = meridian_radius_m(LAT0) + H, (prime_vertical_radius_m(LAT0) + H) * np.cos(LAT0)
    return LAT0 + n / r_n, LON0 + e / r_e, np.full_like(t, H)


def _wander(t):
    """The heading's wander about the track on the straight legs (none in the turn)."""
    straight = (t < T0) | (t > T0 + T_TURN)
    return np.where(straight, WANDER_RAD * np.sin(np.pi * t), 0.0)


def _euler(t):
    ramp = np.clip(np.minimum(t - T0, T0 + T_TURN - t) / 2.0, 0.0, 1.0)    # bank in and out over 2 s
    return BANK_RAD * ramp, np.full_like(t, 0.02), _track(t) + _wander(t)


@pytest.fixture(scope="module")
def motion():
    t = np.arange(0.0, T_END + 1e-9, 0.01)
    f_b, w_ib, (lat, lon, h, v, eu) = imu_and_truth(t, _lla, _euler)
    return dict(t=t, f_b=f_b, w=w_ib, lat=lat, lon=lon, h=h, v=v, eu=eu)


def _strapdown_attitude(m, w_ib) -> np.ndarray:
    ins = StrapdownIns("j2", None, "instant")
    ins.reset(0.0, m["lat"][0], m["lon"][0], m["h"][0], m["v"][0], m["eu"][0][0], m["eu"][1][0],
              m["eu"][2][0])
    return quat_to_dcm(ins.propagate(m["t"][1:], m["f_b"][1:], w_ib[1:])[-1, 6:10])


def _strapdown_covariance(m) -> np.ndarray:
    """Covariance (3, 3) of the strapdown INS's attitude error psi (NED) at the end of the motion."""
    C_ref = _strapdown_attitude(m, m["w"])
    cov = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            E = np.zeros((3, 3))
            E[i, j] = SCALE_PPM * 1e-6 if i == j else MISALIGN_RAD
            S = C_ref @ _strapdown_attitude(m, m["w"] + m["w"] @ E.T).T - np.eye(3)  # = [psi x]
            psi = np.array([S[2, 1], S[0, 2], S[1, 0]])
            cov += np.outer(psi, psi)
    return cov


def _navigator_added(m, turn_angle: str) -> np.ndarray:
    """Attitude variance (psi N, E, D) the `ins` EKF adds with the gyro's scale factor and misalignment."""
    P = {}
    for key, spec in (("on", ImuSpec(gyro_scale_factor_ppm=SCALE_PPM, gyro_misalignment_rad=MISALIGN_RAD)),
                      ("off", ImuSpec())):
        nav = registry.create("ins", turn_angle=turn_angle)
        nav.apply_imu_spec(spec)
        nav.reset(Estimate(0.0, m["lat"][0], m["lon"][0], m["h"][0], m["v"][0].copy(), m["eu"][0][0],
                           m["eu"][1][0], m["eu"][2][0], initial_covariance()))
        t = m["t"]
        for a in range(1, t.size, 100):
            b = min(a + 100, t.size)
            ones = np.ones(b - a, bool)
            imu = ImuFrame(t[a:b], m["f_b"][a:b], m["w"][a:b], ones)
            baro = BaroFrame(t[a:b:5], m["h"][a:b:5], ones[::5])
            nav.update(SensorFrames(t[a - 1], t[b - 1], imu=imu, baro=baro))
        P[key] = np.diag(nav.kf.P)[[PSIN, PSIE, PSID]].copy()
    return P["on"] - P["off"]


def test_excursion_turn_term_bounds_the_strapdown_tilt_and_total_overcounts_the_wander(motion):
    truth = np.diag(_strapdown_covariance(motion))
    excursion = _navigator_added(motion, "excursion")
    total = _navigator_added(motion, "total")
    summed = float(np.abs(np.diff(np.unwrap(motion["eu"][2]))).sum())
    print(f"\nturn 90 deg, summed heading changes {np.degrees(summed):.0f} deg; strapdown var {truth}; "
          f"excursion {excursion}; total {total}; excursion / truth {excursion / truth}")
    # the strapdown's tilt is the turn's, not the wander's: the same order as the misalignment's over 90 deg
    assert 1.0 * MISALIGN_RAD**2 < truth[0] < 3.0 * MISALIGN_RAD**2
    assert 1.0 * MISALIGN_RAD**2 < truth[1] < 3.0 * MISALIGN_RAD**2
    # the excursion's attitude variance bounds the strapdown's, within 2 x, the heading's included
    assert np.all(excursion >= truth) and np.all(excursion <= 2.0 * truth), (excursion, truth)
    # "total" counts the summed back-and-forth (here > 2.5 x the net turn) as turning
    assert summed > 2.5 * float(TURN_RAD)
    assert np.all(total[:2] > 2.0 * truth[:2]), (total, truth)


def test_tilt_walk_is_matched_at_the_fix_period_and_the_defaults():
    """The x / y gyro biases' tilt walk: q = sigma_bg^2 T with T the fix period for the aided filter with the
    batch fix covariance (at most EKF_MEMORY_S), EKF_MEMORY_S for the free INS and the fixed fix noise;
    ins_tercom's defaults are the batch fix covariance and the excursion, the free INS keeps the summed angle
    (its settings are shared)."""
    from synthetic_terrain import wave_map
    from trn_env.navigators.filters.ins_trn_propagation import EKF_MEMORY_S

    spec = ImuSpec(gyro_bias_rps=5e-6, gyro_bias_instability_rps=1.5e-6)
    sig2 = 5e-6**2 + 1.5e-6**2
    cases = (("ins_tercom", {}, 40.0), ("ins_tercom", {"fix_period_s": 25.0}, 25.0),
             ("ins_tercom", {"fix_period_s": 500.0}, EKF_MEMORY_S), ("ins", {}, EKF_MEMORY_S),
             ("ins_tercom", {"fix_noise": "fixed"}, EKF_MEMORY_S))
    for name, settings, memory_s in cases:
        nav = registry.create(name, **({"dem": wave_map(0)} if name == "ins_tercom" else {}), **settings)
        nav.apply_imu_spec(spec)
        assert nav._q_tilt == pytest.approx(sig2 * memory_s, rel=1e-12), (name, settings)
    tercom, ins = registry.create("ins_tercom", dem=wave_map(0)), registry.create("ins")
    assert (tercom.fix_noise, tercom.turn_angle) == ("batch", "excursion")
    assert (ins.fix_noise, ins.turn_angle) == ("fixed", "total")
    with pytest.raises(ValueError, match="turn_angle"):
        registry.create("ins", turn_angle="net")
