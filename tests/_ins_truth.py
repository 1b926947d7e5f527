"""The strapdown INS fed a noise-free IMU of a truth: what is left is the integration's own error (the
truth tests' check that a truth is consistent with its own specific force and rates)."""

from __future__ import annotations

import numpy as np
from trn_env.navigators.inertial.strapdown import StrapdownIns
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env.sensors.imu import ImuConfig, sample_imu


def noise_free_ins_errors(tr, sampling: str = "instant", start=None):
    """(north, east, down position error m, velocity error m/s) at every sample of a noise-free IMU
    (`sampling`: "instant" or "interval") of the truth tr integrated by StrapdownIns (J2 gravity, no baro
    loop). The INS starts from start's first row at its time (a truth chunk before tr: a reset), else
    from tr's first row at t = 0."""
    imu, _ = sample_imu(tr, None, np.random.default_rng(0), ImuConfig.noise_free(sampling=sampling))
    s = tr if start is None else start
    ins = StrapdownIns("j2", tau_baro_s=None, imu_samples=sampling)
    ins.reset(0.0 if start is None else float(s.t_s[0]), s.lat_rad[0], s.lon_rad[0], s.h_msl_m[0],
              s.v_ned_mps[0], s.roll_rad[0], s.pitch_rad[0], s.yaw_rad[0])
    hist = ins.propagate(imu.t_s, imu.f_b_mps2, imu.omega_ib_b_rps)
    k = np.searchsorted(tr.t_s, imu.t_s)
    lat, h = tr.lat_rad[k], tr.h_msl_m[k]
    dn = (hist[:, 0] - lat) * (meridian_radius_m(lat) + h)
    de = (hist[:, 1] - tr.lon_rad[k]) * (prime_vertical_radius_m(lat) + h) * np.cos(lat)
    return dn, de, hist[:, 2] - h, np.linalg.norm(hist[:, 3:6] - tr.v_ned_mps[k], axis=1), ins
