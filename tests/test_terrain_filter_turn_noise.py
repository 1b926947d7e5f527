"""The point-mass filter's and the RBPF's turn noise (pmf apply_imu_spec: per rad turned the gyro
misalignment on the tilt acceleration and the scale factor on the heading error; rbpf likewise on its Kalman
parts' attitude process noise) does not depend on the measurement rate: the variance a motion adds is the same
with a fix or epoch every 1 s and every 2 s, and equals the specification's density times the integral of
|yaw rate| computed here from the reference trajectory (independent of the navigator). The motion (as
tests/test_ins_trn_turn_noise.py's) is a heading oscillation of period 2 s on top of a 45 deg turn: a yaw
change measured once per prediction (at each fix) sees the oscillation fully with 1 s fixes and
not at all with 2 s fixes, which the test checks too, so the per-update form of the term fails it.

The pmf's predictions are driven by GNSS fixes of the truth with 10 km position and velocity noise (the
updates change the tilt and heading variances by less than 1e-6 of the term checked), on a flat map; the
RBPF's epochs by GNSS fixes at its trn_rate_hz (1 or 0.5 Hz), its attitude process noise per epoch summed."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators.core.imu_spec import G0_MPS2, ImuSpec
from trn_env.navigators.filters.pmf import TURN_REFERENCE_RAD, PointMassFilter
from trn_env.navigators.frames import BaroFrame, GnssFrame, ImuFrame, SensorFrames
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.dem import Dem

sys.path.insert(0, str(Path(__file__).parent))
from nav_reference_trajectory import imu_and_truth  # noqa: E402
from test_ins_trn_turn_noise import (  # noqa: E402
    MISALIGN_RAD,
    SCALE_PPM,
    T_END,
    _euler,
    _lla,
    _per_frame_turn,
    _yaw,
)

TILT, HEADING = 2, 6    # the pmf's u indexes: tilt acceleration north, heading error


@pytest.fixture(scope="module")
def motion():
    t = np.arange(0.0, T_END + 1e-9, 0.01)
    f_b, w_ib, (lat, lon, h, v, eu) = imu_and_truth(t, _lla, _euler)
    return dict(t=t, f_b=f_b, w=w_ib, lat=lat, lon=lon, h=h, v=v, eu=eu)


def _flat_map(m) -> Dem:
    d = math.radians(10.0 / 3600.0)
    lat0, lon0 = m["lat"].min() - 0.01, m["lon"].min() - 0.01
    n = int(max(m["lat"].max() - lat0, m["lon"].max() - lon0) / d) + 80
    return Dem(np.full((n, n), 300.0), lat0, lon0, d, d, "flat")


def _frames(m, fix_every_s: float):
    t = m["t"]
    k_fix = set(np.round(np.arange(fix_every_s, T_END + 1e-9, fix_every_s) / 0.01).astype(int).tolist())
    for a in range(1, t.size, 100):            # 1 s frames
        b = min(a + 100, t.size)
        ones = np.ones(b - a, bool)
        k = np.array([i for i in range(a, b) if i in k_fix], int)
        gnss = GnssFrame(t[k], m["lat"][k], m["lon"][k], m["h"][k], m["v"][k], np.ones(k.size, bool))
        yield SensorFrames(t[a - 1], t[b - 1], imu=ImuFrame(t[a:b], m["f_b"][a:b], m["w"][a:b], ones),
                           baro=BaroFrame(t[a:b:5], m["h"][a:b:5], ones[::5]), gnss=gnss)


def _initial(m) -> Estimate:
    cov = np.diag([100.0, 100.0, 4.0, 0.01, 0.01, 0.01, 1e-6, 1e-6, 1e-6])
    return Estimate(0.0, m["lat"][0], m["lon"][0], m["h"][0], m["v"][0].copy(), m["eu"][0][0], m["eu"][1][0],
                    m["eu"][2][0], cov)


def _turned() -> float:
    """The integral of |yaw rate| of the reference trajectory on a 1 ms grid (independent of the filters)."""
    tf = np.arange(0.0, T_END + 1e-9, 0.001)
    return float(np.abs(np.diff(_yaw(tf))).sum())


def _forms_differ(m) -> None:
    """The motion separates the forms: per fix, 1 s fixes count the oscillation, 2 s fixes miss it."""
    yaw = _yaw(m["t"])
    one, two = _per_frame_turn(m["t"], yaw, 1.0), _per_frame_turn(m["t"], yaw, 2.0)
    assert one > 2.0 * two and two < 0.5 * _turned(), (one, two)


def _run(m, fix_every_s: float, spec: ImuSpec) -> np.ndarray:
    nav = PointMassFilter(_flat_map(m), grid_size=21, gnss_sigma_m=1e4, gnss_velocity_sigma_mps=1e4,
                          gnss_vertical_sigma_m=1e4)
    nav.apply_imu_spec(spec)
    nav.reset(_initial(m))
    for fr in _frames(m, fix_every_s):
        nav.update(fr)
    return np.diag(nav.C_uu)[[TILT, HEADING]].copy()


def test_pmf_turn_variance_does_not_depend_on_the_measurement_rate(motion):
    on = ImuSpec(gyro_scale_factor_ppm=SCALE_PPM, gyro_misalignment_rad=MISALIGN_RAD)
    off = ImuSpec()
    added = {s: _run(motion, s, on) - _run(motion, s, off) for s in (1.0, 2.0)}
    turned = _turned()
    want = np.array([(G0_MPS2 * MISALIGN_RAD) ** 2, (SCALE_PPM * 1e-6) ** 2]) * TURN_REFERENCE_RAD * turned
    print(f"\nturned {np.degrees(turned):.0f} deg; added 1 s {added[1.0]}, 2 s {added[2.0]}, expected {want}")
    # the same with fixes every 1 s and 2 s (1 %) ...
    np.testing.assert_allclose(added[2.0], added[1.0], rtol=0.01)
    # ... and what the specification gives for the angle turned (2 %: the INS's attitude from the perfect IMU
    # at its 10 ms sampling of the oscillation)
    np.testing.assert_allclose(added[1.0], want, rtol=0.02)
    _forms_differ(motion)


def _rbpf_turn_variance(m, rate_hz: float, spec: ImuSpec) -> np.ndarray:
    """Sum over the RBPF's epochs of the attitude process noise beyond its floor (rad^2, n e d)."""
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
    nav = RaoBlackwellizedPF(_flat_map(m), rng=np.random.default_rng(3), n_particles=50,
                             acquisition_particles=0, turn_angle="total",
                             trn_rate_hz=rate_hz)
    nav.apply_imu_spec(spec)
    added = np.zeros(3)
    orig = nav._epoch_ql_var

    def recorded():
        ql = orig()
        added[:] += ql[3:6] - nav.ql_var[3:6]
        return ql

    nav._epoch_ql_var = recorded
    nav.reset(_initial(m))
    for fr in _frames(m, 1.0):
        nav.update(fr)
    return added


def test_rbpf_turn_variance_does_not_depend_on_the_epoch_rate(motion):
    on = ImuSpec(gyro_scale_factor_ppm=SCALE_PPM, gyro_misalignment_rad=MISALIGN_RAD)
    added = {r: _rbpf_turn_variance(motion, r, on) for r in (1.0, 0.5)}
    turned = _turned()
    want = np.array([MISALIGN_RAD**2, MISALIGN_RAD**2, (SCALE_PPM * 1e-6) ** 2]) * TURN_REFERENCE_RAD * turned
    print(f"\nturned {np.degrees(turned):.0f} deg; added 1 Hz {added[1.0]}, 0.5 Hz {added[0.5]}, "
          f"expected {want}")
    np.testing.assert_allclose(added[0.5], added[1.0], rtol=0.01)
    np.testing.assert_allclose(added[1.0], want, rtol=0.02)
    _forms_differ(motion)
