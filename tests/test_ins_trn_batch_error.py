"""The batch TERCOM fix's H (navigators.filters.ins_trn_batch_error, tercom.fix_noise.slope_weighted_mean).

1. sample_error_rows against the closed forms of a constant specific force and attitude: the attitude and
   accelerometer-bias columns tau^2 / 2 times the acceleration error's rows, the z-gyro bias's tau^3 / 6.
2. slope_weighted_mean against real MAD fixes (tercom.mad.correlate) of a batch whose INS error is not one
   rigid shift: a synthetic map whose relief fades along the batch (the informative terrain at its start),
   the INS error d0 - u tau_k (a velocity error u), Gaussian height noise. The trials' mean fix must match
   the slope-weighted average of the samples' errors within the 99 % band of the mean computed from the
   trials' own scatter, and the mean-lag model (the rigid shift at the batch's mean time) must lie outside
   that band (the test fails without the slope weights).
"""

import math

import numpy as np
from scipy import stats
from synthetic_terrain import LAT0, LON0, POST_M, wave_map
from trn_env.navigators.core.error_states import BAX, BGZ, DRE, DRN, DVE, DVN, N_EKF13, PSIN
from trn_env.navigators.filters.ins_trn_batch_error import BatchKinematics, sample_error_rows
from trn_env.navigators.tercom.fix_noise import slope_weighted_mean
from trn_env.navigators.tercom.mad import correlate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m


def _log(t_s, f_n, C):
    """A kinematics log with the INS flying constant f^n (NED) and attitude C over times t_s."""
    k = BatchKinematics()
    q = np.zeros((t_s.shape[0], 10))
    # C from a quaternion: a yaw of 30 deg (the log recomputes C from hist's quaternion)
    q[:, 6:10] = C
    f_b = np.tile(f_n, (t_s.shape[0], 1))
    k.add(t_s, f_b, q, np.zeros(3))
    return k.since(-math.inf)


def test_sample_error_rows_closed_forms():
    yaw = math.radians(30.0)
    quat = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    C = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    f_b = np.array([0.4, -1.5, -9.8])
    t = np.linspace(0.0, 40.0, 4001)                      # 100 Hz IMU, logged every LOG_DECIMATION-th
    log = _log(t, f_b, quat)
    t_k = np.array([0.0, 7.5, 20.0, 33.3, 40.0])
    M = sample_error_rows(t_k, 40.0, log)
    tau = 40.0 - t_k
    f = C @ f_b
    rows = np.zeros((2, N_EKF13))
    rows[0, PSIN + 1], rows[0, PSIN + 2] = -f[2], f[1]
    rows[1, PSIN], rows[1, PSIN + 2] = f[2], -f[0]
    rows[:, BAX:BAX + 3] = C[:2, :]
    fxc = np.cross(f, C[:, 2])
    for k in range(t_k.shape[0]):
        want = np.zeros((2, N_EKF13))
        want[0, DRN] = want[1, DRE] = 1.0
        want[0, DVN] = want[1, DVE] = -tau[k]
        want += 0.5 * tau[k] ** 2 * rows
        want[:, BGZ] = fxc[:2] * tau[k] ** 3 / 6.0
        np.testing.assert_allclose(M[k], want, rtol=1e-3, atol=1e-6 * (1.0 + tau[k] ** 3))


def _fading_map() -> Dem:
    """wave_map(4)'s relief times a ramp that fades from 1 at the batch's start to 0.05 near its end (the
    batch flies north-east)."""
    base = wave_map(4)
    h = np.asarray(base.heights_m, float)
    n = h.shape[0]
    y, x = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ramp = np.clip(1.0 - (x + y - 100.0) / 150.0, 0.05, 1.0)
    h = 400.0 + (h - 400.0) * ramp
    r_n = meridian_radius_m(LAT0)
    r_e = prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    return Dem(h, LAT0, LON0, POST_M / r_n, POST_M / r_e, "synthetic-fading")


def test_slope_weighted_mean_predicts_mad_fixes_of_a_deformed_batch():
    dem = _fading_map()
    r_n = meridian_radius_m(LAT0)
    r_e = prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    m, dt_s = 600, 0.05                                   # 30 s, 5 m apart
    s = np.arange(m) * 5.0
    n_true, e_true = 1500.0 + 0.6 * s, 1500.0 + 0.8 * s
    t_k = np.arange(m) * dt_s
    tau = t_k[-1] - t_k
    d0, u = np.array([12.0, -8.0]), np.array([1.2, -0.9])  # INS error at the fix (m), velocity error (m/s)
    err_k = d0[None, :] - tau[:, None] * u[None, :]
    lat_ins = LAT0 + (n_true + err_k[:, 0]) / r_n
    lon_ins = LON0 + (e_true + err_k[:, 1]) / r_e
    h_true = dem.height(LAT0 + n_true / r_n, LON0 + e_true / r_e)
    zeros = np.zeros(m)
    rng = np.random.default_rng(5)
    trials, noise_m = 30, 4.0
    z = []
    for _ in range(trials):
        h_meas = h_true + rng.normal(0.0, noise_m, m)
        fix = correlate(dem, 0.0, lat_ins, lon_ins, h_meas, zeros, zeros, half=40, cell_m=1.0,
                        remove_bias=False)
        assert fix.valid
        z.append(-np.array([fix.dn_m, fix.de_m]))         # INS minus matched position
    z = np.array(z)
    mean, sem = z.mean(axis=0), z.std(axis=0, ddof=1) / math.sqrt(trials)
    band = stats.t.ppf(0.995, trials - 1) * np.hypot(sem, 1.0 / math.sqrt(12.0 * trials))
    want = slope_weighted_mean(dem, lat_ins, lon_ins, h_true, zeros, zeros, -mean[0], -mean[1],
                               err_k[:, :, None])[:, 0]
    rigid = d0 - tau.mean() * u
    print(f"\nmean fix {mean.round(2)} +- {band.round(2)}; slope-weighted {want.round(2)}; mean lag "
          f"{rigid.round(2)}")
    assert np.all(np.abs(mean - want) < band + 0.5)       # + half a cell: the search grid's rounding
    assert np.any(np.abs(mean - rigid) > band + 0.5 + 2.0)
