"""IMU model: static readings, Allan deviation levels, chunking, presets, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensors_common import chunks_of, normal_gravity_mps2, straight_truth
from trn_env.terrain.geodesy import OMEGA_EARTH_RPS, euler_to_C_bn

from trn_env.sensors.imu import IMU_GRADES, ImuConfig, sample_imu


def allan_deviation(y: np.ndarray, dt_s: float, m_list) -> np.ndarray:
    """Overlapping Allan deviation of rate samples y (n,) at cluster sizes m (independent helper)."""
    theta = np.r_[0.0, np.cumsum(y)] * dt_s
    out = []
    for m in m_list:
        tau = m * dt_s
        d = theta[2 * m:] - 2 * theta[m:-m] + theta[:-2 * m]
        out.append(np.sqrt(np.sum(d * d) / (2 * tau * tau * d.shape[0])))
    return np.array(out)


def expected_avar_gm_plus_white(m: int, sigma_gm: float, phi: float, white_var: float) -> float:
    """Exact Allan variance of discrete samples of (AR(1) with std sigma_gm, coefficient phi) + white."""
    k = np.arange(-(m - 1), m)
    wts = (m - np.abs(k)) / m**2
    var_mean = np.sum(wts * sigma_gm**2 * phi ** np.abs(k)) + white_var / m
    cov_adj = np.sum(wts * sigma_gm**2 * phi ** np.abs(m + k))
    return var_mean - cov_adj


def static_truth(n, dt_s=0.01, lat_deg=45.0, h_m=300.0, roll=-2.0, pitch=3.0, yaw=30.0):
    return straight_truth(n, dt_s=dt_s, lat0_deg=lat_deg, h_m=h_m, speed_mps=0.0, track_deg=yaw,
                          roll_deg=roll, pitch_deg=pitch)


def test_static_imu_reports_gravity_and_earth_rate():
    lat, h = np.deg2rad(45.0), 300.0
    truth = static_truth(6000, lat_deg=45.0, h_m=h)
    # independent expected readings: f_b = -C_nb g_n (Somigliana gravity), omega = C_nb omega_ie_n
    C_nb = euler_to_C_bn(np.deg2rad(-2.0), np.deg2rad(3.0), np.deg2rad(30.0)).T
    f_exp = C_nb @ np.array([0.0, 0.0, -normal_gravity_mps2(lat, h)])
    w_exp = C_nb @ (OMEGA_EARTH_RPS * np.array([np.cos(lat), 0.0, -np.sin(lat)]))
    cfg = ImuConfig.grade("navigation")
    frame, _ = sample_imu(truth, None, np.random.default_rng(3), cfg)
    assert frame.valid.all() and frame.t_s.shape[0] == 6000
    n_s = 60.0
    sig_f = np.hypot(cfg.accel_bias_mps2, cfg.accel_noise_density_mps2_rthz / np.sqrt(n_s))
    sig_w = np.hypot(cfg.gyro_bias_rps, cfg.gyro_noise_density_rps_rthz / np.sqrt(n_s))
    assert np.all(np.abs(frame.f_b_mps2.mean(axis=0) - f_exp) < 4 * sig_f)
    assert np.all(np.abs(frame.omega_ib_b_rps.mean(axis=0) - w_exp) < 4 * sig_w)
    # the Earth rate (~5e-5 rad/s) is resolved: a nav-grade gyro error is far smaller
    assert np.linalg.norm(frame.omega_ib_b_rps.mean(axis=0) - w_exp) < 0.02 * OMEGA_EARTH_RPS
    nf, _ = sample_imu(truth, None, np.random.default_rng(3), ImuConfig.noise_free())
    np.testing.assert_allclose(nf.f_b_mps2, np.tile(f_exp, (6000, 1)), atol=1e-12)
    np.testing.assert_allclose(nf.omega_ib_b_rps, np.tile(w_exp, (6000, 1)), atol=1e-15)


def test_allan_white_noise_level_at_one_second():
    cfg = ImuConfig.grade("navigation")
    truth = static_truth(60000)          # 600 s at 100 Hz
    frame, _ = sample_imu(truth, None, np.random.default_rng(4), cfg)
    for axis in range(3):
        ad_f = allan_deviation(frame.f_b_mps2[:, axis], 0.01, [100])[0]
        ad_w = allan_deviation(frame.omega_ib_b_rps[:, axis], 0.01, [100])[0]
        assert abs(ad_f / cfg.accel_noise_density_mps2_rthz - 1) < 0.10
        assert abs(ad_w / cfg.gyro_noise_density_rps_rthz - 1) < 0.10
    # slope -1/2 between 0.1 s and 1 s
    ad = allan_deviation(frame.f_b_mps2[:, 0], 0.01, [10, 100])
    assert abs(np.log10(ad[1] / ad[0]) + 0.5) < 0.05


def test_allan_bias_instability_levels():
    rate, tau_c = 10.0, 5.0
    cfg = ImuConfig.noise_free(rate_hz=rate, accel_bias_instability_mps2=2e-3, accel_bias_tau_s=tau_c,
                               accel_noise_density_mps2_rthz=1e-3, gyro_bias_instability_rps=1e-4,
                               gyro_bias_tau_s=tau_c, gyro_noise_density_rps_rthz=2e-5)
    truth = static_truth(300000, dt_s=0.1)     # 30000 s = 6000 correlation times
    frame, _ = sample_imu(truth, None, np.random.default_rng(5), cfg)
    phi = np.exp(-0.1 / tau_c)
    ms = [10, 50, 100, 200]
    for y, s_gm, dens in ((frame.f_b_mps2[:, 0] - truth.f_b_mps2[0, 0], 2e-3, 1e-3),
                          (frame.omega_ib_b_rps[:, 1] - truth.omega_ib_b_rps[0, 1], 1e-4, 2e-5)):
        got = allan_deviation(y, 0.1, ms)
        exp = np.sqrt([expected_avar_gm_plus_white(m, s_gm, phi, dens**2 / 0.1) for m in ms])
        np.testing.assert_allclose(got, exp, rtol=0.10)
        # the bias-instability hump: ADEV peaks near 1.9 tau_c well above the white-noise line
        assert got[2] > 1.5 * dens / np.sqrt(10.0)


def test_chunked_equals_one_shot_and_seed_determinism():
    cfg = ImuConfig.grade("tactical")
    truth = straight_truth(1000, turn_rate_dps=3.0, roll_deg=20.0)
    one, s_one = sample_imu(truth, None, np.random.default_rng(7), cfg)
    rng, state, parts = np.random.default_rng(7), None, []
    for c in chunks_of(truth, [1, 10, 37, 200, 3, 400]):
        f, state = sample_imu(c, None, rng, cfg, state)
        parts.append(f)
    for name in ("t_s", "f_b_mps2", "omega_ib_b_rps", "valid"):
        np.testing.assert_allclose(np.concatenate([getattr(p, name) for p in parts]), getattr(one, name),
                                   rtol=0, atol=1e-15)
    again, _ = sample_imu(truth, None, np.random.default_rng(7), cfg)
    np.testing.assert_array_equal(again.f_b_mps2, one.f_b_mps2)
    other, _ = sample_imu(truth, None, np.random.default_rng(8), cfg)
    assert not np.array_equal(other.f_b_mps2, one.f_b_mps2)


def test_rate_and_quantisation():
    cfg = ImuConfig.grade("tactical", rate_hz=50.0)
    truth = straight_truth(500)
    frame, _ = sample_imu(truth, None, np.random.default_rng(0), cfg)
    np.testing.assert_allclose(np.diff(frame.t_s), 0.02)
    dv = frame.f_b_mps2 * 0.02 / cfg.accel_quantum_mps
    np.testing.assert_allclose(dv, np.round(dv), atol=1e-6)


def test_quantiser_carries_the_remainder():
    # coarse quanta, nothing else: each sample is a whole number of quanta and the integrated output
    # (velocity / angle) stays within half a quantum of the integrated truth
    cfg = ImuConfig.noise_free(accel_quantum_mps=0.05, gyro_quantum_rad=1e-3)
    truth = straight_truth(2000, turn_rate_dps=5.0, roll_deg=15.0)
    frame, _ = sample_imu(truth, None, np.random.default_rng(0), cfg)
    pairs = ((frame.f_b_mps2, truth.f_b_mps2, 0.05), (frame.omega_ib_b_rps, truth.omega_ib_b_rps, 1e-3))
    for meas, true, q in pairs:
        inc = meas * 0.01 / q
        np.testing.assert_allclose(inc, np.round(inc), atol=1e-6)
        err = np.cumsum(meas - true, axis=0) * 0.01
        assert np.abs(err).max() <= 0.5 * q + 1e-12
        assert np.abs(meas - true).max() > 0.3 * q / 0.01      # individual samples are visibly quantised


def test_scale_factor_and_misalignment_draws():
    cfg = ImuConfig.noise_free(accel_scale_factor_ppm=1000.0, accel_misalignment_rad=2e-3, sampling="instant")
    truth = straight_truth(60)
    rng_f = np.random.default_rng(11)
    truth.f_b_mps2[:] = rng_f.normal(0, 10, (60, 3))     # excite all axes
    diag, off = [], []
    for seed in range(200):
        frame, _ = sample_imu(truth, None, np.random.default_rng(seed), cfg)
        M, *_ = np.linalg.lstsq(truth.f_b_mps2, frame.f_b_mps2, rcond=None)
        M = M.T
        diag.extend(np.diag(M) - 1)
        off.extend(M[~np.eye(3, dtype=bool)])
    assert abs(np.std(diag) / 1e-3 - 1) < 0.15
    assert abs(np.std(off) / 2e-3 - 1) < 0.15


def test_grades_ordered_and_seed_values():
    nav, tac, con = (IMU_GRADES[k] for k in ("navigation", "tactical", "consumer"))
    g = 9.80665
    assert nav.accel_bias_mps2 == pytest.approx(50e-6 * g)
    assert nav.accel_noise_density_mps2_rthz == pytest.approx(10e-6 * g)
    assert nav.gyro_bias_rps == pytest.approx(np.deg2rad(0.005) / 3600)
    assert nav.gyro_noise_density_rps_rthz == pytest.approx(np.deg2rad(0.005) / 60)
    for a, b in ((nav, tac), (tac, con)):
        assert a.accel_bias_mps2 < b.accel_bias_mps2 and a.gyro_bias_rps < b.gyro_bias_rps
        assert a.gyro_noise_density_rps_rthz < b.gyro_noise_density_rps_rthz


@pytest.mark.parametrize("field, value", [("rate_hz", 0.0), ("rate_hz", -100.0), ("accel_bias_mps2", -1e-4),
                                          ("gyro_noise_density_rps_rthz", -1.0), ("gyro_bias_tau_s", 0.0),
                                          ("accel_quantum_mps", float("nan"))])
def test_bad_config_names_field(field, value):
    with pytest.raises(ValueError, match=field):
        ImuConfig(**{field: value})


def test_from_mapping_rejects_unknown_keys_and_grades():
    with pytest.raises(ValueError, match="accel_bias_ug"):
        ImuConfig.from_mapping({"accel_bias_ug": 3})
    with pytest.raises(ValueError, match="grade"):
        ImuConfig.from_mapping({"grade": "military"})
    assert ImuConfig.from_mapping({"grade": "tactical", "rate_hz": 200}).rate_hz == 200


def test_interval_sampling_is_the_mean_over_each_interval_across_chunks():
    """sampling="interval": each sample is the trapezoid mean of f and the step-start mean of omega (scaled to
    the rotation of JSBSim's Euler quaternion step) over (t_{k-1}, t_k], computed here independently;
    chunking does not change it."""
    truth = straight_truth(400)
    rng = np.random.default_rng(3)
    truth.f_b_mps2[:] = rng.normal(0, 3, (400, 3))
    truth.omega_ib_b_rps[:] = rng.normal(0, 0.1, (400, 3))
    for rate_hz, step in ((100.0, 1), (50.0, 2), (20.0, 5)):
        cfg = ImuConfig.noise_free(rate_hz=rate_hz)
        whole, _ = sample_imu(truth, None, np.random.default_rng(0), cfg)
        parts, state = [], None
        for a, b in ((0, 7), (7, 130), (130, 131), (131, 400)):
            fr, state = sample_imu(truth.slice(a, b), None, np.random.default_rng(0), cfg, state)
            parts.append(fr)
        chunked_f = np.concatenate([p.f_b_mps2 for p in parts])
        np.testing.assert_allclose(chunked_f, whole.f_b_mps2, rtol=0, atol=1e-12)
        rows = np.flatnonzero(np.isin(truth.t_s, whole.t_s))
        for i in range(1, len(rows)):
            j0, j1 = rows[i - 1], rows[i]
            assert j1 - j0 == step
            f = truth.f_b_mps2
            want_f = np.mean([(f[m - 1] + f[m]) / 2 for m in range(j0 + 1, j1 + 1)], axis=0)
            w = truth.omega_ib_b_rps[j0:j1]
            wdt = np.linalg.norm(w, axis=1) * (truth.t_s[1] - truth.t_s[0])
            want_w = (w * (2 * np.arctan(wdt / 2) / wdt)[:, None]).mean(axis=0)
            np.testing.assert_allclose(whole.f_b_mps2[i], want_f, atol=1e-12)
            np.testing.assert_allclose(whole.omega_ib_b_rps[i], want_w, atol=1e-12)


def test_unknown_sampling_is_rejected():
    with pytest.raises(ValueError, match="sampling: must be one of"):
        ImuConfig(sampling="sometimes")
