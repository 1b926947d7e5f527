"""The strapdown INS with perfect IMU data follows a 10-minute manoeuvring JSBSim flight within 1 m.

Needs the flight core (trn_env.flight.core); navigators themselves never import trn_env."""

import math

import numpy as np
import pytest
from trn_env.navigators.inertial.strapdown import StrapdownIns
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

flight_mod = pytest.importorskip("trn_env.flight.core")

FT = 0.3048
PLAN = [
    (0, 60, 3000),
    (60, 150, 3200),
    (150, -30, 3200),
    (240, 100, 2900),
    (330, 200, 3100),
    (420, 20, 3100),
    (510, -80, 3000),
]  # (start s, heading deg, altitude m)
PROPS = (
    "position/lat-geod-rad",
    "position/long-gc-rad",
    "position/geod-alt-ft",
    "velocities/v-north-fps",
    "velocities/v-east-fps",
    "velocities/v-down-fps",
    "attitude/phi-rad",
    "attitude/theta-rad",
    "attitude/psi-rad",
    "velocities/pi-rad_sec",
    "velocities/qi-rad_sec",
    "velocities/ri-rad_sec",
    "forces/fbx-total-lbs",
    "forces/fby-total-lbs",
    "forces/fbz-total-lbs",
    "inertia/mass-slugs",
)


def _flight():
    ic = flight_mod.InitialCondition(
        math.radians(36.85), math.radians(-84.25), 3000.0, 90.0, math.radians(60)
    )
    try:
        return flight_mod.Flight(ic)
    except flight_mod.TrimError as exc:  # the aircraft model is still being tuned
        pytest.skip(f"flight core cannot trim: {exc}")


def _targets(hd, alt):
    return flight_mod.AutopilotTargets(
        lateral_mode=flight_mod.LateralMode.HEADING,
        heading_cmd_rad=math.radians(hd),
        altitude_cmd_m=alt,
        tas_cmd_mps=90.0,
        bank_limit_rad=math.radians(30),
    )


def _gyro_rotation_rate(w_ib, dt_s):
    """The rotation the JSBSim body actually makes per step, as a mean rate (what a perfect integrating gyro
    reports). JSBSim 1.3 integrates its ECI attitude quaternion with a rectangular Euler step and then
    normalises it (FGPropagate, simulation/integrator/position/rotational = 1): q + dt/2 q*(0, w), which is a
    rotation by 2 atan(|w| dt / 2) about w, not by |w| dt. The shortfall, (|w| dt)^3 / 12 per step, is a tilt
    of ~5e-7 rad per roll manoeuvre at 100 Hz (~0.5 micro-g of horizontal specific force): fed the raw rates,
    the exact rotation-vector INS drifts about a metre from the truth in 10 min, fed this a few centimetres
    (the figures: docs/validation/ins.md)."""
    n = np.linalg.norm(w_ib, axis=1, keepdims=True)
    a = n * dt_s
    return w_ib * np.where(a > 0.0, 2.0 * np.arctan(0.5 * a) / np.where(a > 0.0, a, 1.0), 1.0)


def _assert_rectangular_attitude_integrator(fdm):
    assert fdm["simulation/integrator/position/rotational"] == 1.0  # eRectEuler: _gyro_rotation_rate holds


def _ins_error(t, lat, lon, h, v, eu, f_b, w_ib, mode):
    ins = StrapdownIns("j2", tau_baro_s=30.0, imu_samples=mode)
    ins.reset(t[0], lat[0], lon[0], h[0], v[0], eu[0][0], eu[1][0], eu[2][0])
    out = ins.propagate(t, f_b, w_ib, None, t, h)  # baro = true height (perfect)
    dn = (out[:, 0] - lat) * (meridian_radius_m(lat[0]) + h)
    de = (out[:, 1] - lon) * (prime_vertical_radius_m(lat[0]) + h) * np.cos(lat)
    return np.hypot(dn, de), np.abs(out[:, 2] - h)


def test_ins_follows_jsbsim_with_specific_force_from_total_forces():
    """Perfect IMU = JSBSim's inertial body rates and (total non-gravitational force) / mass, read each step,
    as interval samples consistent with JSBSim's own integration: the attitude step ending at row k uses the
    rate of row k-1 (JSBSim's rectangular rotational integrator), the velocity step the mean of the specific
    forces of rows k-1 and k (found by comparing alignments; other alignments leave 12-40 m after 10 min)."""
    fl = _flight()
    fdm = fl.fdm
    nodes = [fdm.get_property_manager().get_node(p, False) for p in PROPS]
    rows = [[n.get_double_value() for n in nodes]]
    for i, (ts, hd, alt) in enumerate(PLAN):
        fl.set_targets(_targets(hd, alt))
        te = PLAN[i + 1][0] if i + 1 < len(PLAN) else 600
        for _ in range(int(round((te - ts) / fl.dt_s))):
            fdm.run()
            rows.append([n.get_double_value() for n in nodes])
    r = np.array(rows)
    t = np.arange(r.shape[0]) * fl.dt_s
    f_b = r[:, 12:15] / r[:, 15:16] * FT
    f_b = 0.5 * (f_b + np.concatenate([f_b[:1], f_b[:-1]]))
    w_ib = _gyro_rotation_rate(np.concatenate([r[:1, 9:12], r[:-1, 9:12]]), fl.dt_s)
    _assert_rectangular_attitude_integrator(fdm)
    assert np.ptp(np.degrees(r[:, 6])) > 40.0  # it manoeuvred (banks both ways)
    hor, ver = _ins_error(
        t, r[:, 0], r[:, 1], r[:, 2] * FT, r[:, 3:6] * FT, (r[:, 6], r[:, 7], r[:, 8]), f_b, w_ib, "interval"
    )
    # the rotation-rate conversion and the timing alignment above are what keep this far under the bound
    # (the figures with and without them: docs/validation/ins.md)
    print(f"INS vs JSBSim over {t[-1] - t[0]:.0f} s: max horizontal error {hor.max():.3f} m, "
          f"vertical {ver.max():.3f} m")
    assert hor.max() < 1.0, hor.max()
    assert ver.max() < 1.0, ver.max()


def _planned_truth():
    """(flight, its truth chunks of PLAN's legs concatenated, from the start)."""
    fl = _flight()
    chunks = [fl.snapshot()]
    for i, (ts, hd, alt) in enumerate(PLAN):
        fl.set_targets(_targets(hd, alt))
        te = PLAN[i + 1][0] if i + 1 < len(PLAN) else 600
        chunks.append(fl.advance(int(round((te - ts) / fl.dt_s))))
    return fl, type(chunks[0]).concatenate(chunks)


def test_ins_follows_flight_core_truth_chunk():
    fl, tr = _planned_truth()
    f_b = 0.5 * (tr.f_b_mps2 + np.concatenate([tr.f_b_mps2[:1], tr.f_b_mps2[:-1]]))
    w_ib = _gyro_rotation_rate(np.concatenate([tr.omega_ib_b_rps[:1], tr.omega_ib_b_rps[:-1]]), fl.dt_s)
    _assert_rectangular_attitude_integrator(fl.fdm)
    hor, ver = _ins_error(
        tr.t_s,
        tr.lat_rad,
        tr.lon_rad,
        tr.h_msl_m,
        tr.v_ned_mps,
        (tr.roll_rad, tr.pitch_rad, tr.yaw_rad),
        f_b,
        w_ib,
        "interval",
    )
    # the flight core's truth chunk gives the same as the raw node reads above
    assert hor.max() < 1.0 and ver.max() < 1.0, (hor.max(), ver.max())


def test_ins_on_the_noise_free_sensor_imu_follows_the_flight():
    """The closed loop's path: the flight core's truth -> trn_env.sensors' noise-free integrating IMU
    ("interval" samples, rates scaled to JSBSim's quaternion step) -> the INS. Same bound as above."""
    from trn_env.sensors.imu import ImuConfig, sample_imu

    fl, tr = _planned_truth()
    frame, _ = sample_imu(tr, None, np.random.default_rng(0), ImuConfig.noise_free())
    assert np.array_equal(frame.t_s, tr.t_s)
    hor, ver = _ins_error(
        tr.t_s, tr.lat_rad, tr.lon_rad, tr.h_msl_m, tr.v_ned_mps, (tr.roll_rad, tr.pitch_rad, tr.yaw_rad),
        frame.f_b_mps2, frame.omega_ib_b_rps, "interval",
    )
    assert hor.max() < 1.0, hor.max()
    assert ver.max() < 1.0, ver.max()
