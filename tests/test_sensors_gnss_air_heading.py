"""GNSS, air data and compass: noise statistics, outage windows, chunking, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensors_common import chunks_of, straight_truth
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env.sensors.air_data import AirDataConfig, sample_air_data
from trn_env.sensors.gnss import GnssConfig, sample_gnss
from trn_env.sensors.heading import HeadingConfig, sample_heading


def gnss_errors_ned(frame, truth, idx):
    lat0 = truth.lat_rad[idx]
    h = truth.h_msl_m[idx]
    r_n = np.array([meridian_radius_m(x) for x in lat0]) + h
    r_e = np.array([prime_vertical_radius_m(x) for x in lat0]) + h
    dn = (frame.lat_rad - lat0) * r_n
    de = (frame.lon_rad - truth.lon_rad[idx]) * r_e * np.cos(lat0)
    return np.stack([dn, de, -(frame.h_m - h)], axis=1)


def test_gnss_rate_noise_and_outages():
    truth = straight_truth(100000, speed_mps=120.0)           # 1000 s
    cfg = GnssConfig(horizontal_noise_m=2.0, vertical_noise_m=4.0, horizontal_drift_m=0.0,
                     vertical_drift_m=0.0,
                     velocity_noise_mps=0.1, outages=[(100.0, 250.5), (600.0, 700.0)])
    frame, _ = sample_gnss(truth, None, np.random.default_rng(0), cfg)
    assert frame.t_s.shape[0] == 1000 and np.allclose(np.diff(frame.t_s), 1.0)
    out = ((frame.t_s >= 100.0) & (frame.t_s < 250.5)) | ((frame.t_s >= 600.0) & (frame.t_s < 700.0))
    np.testing.assert_array_equal(frame.valid, ~out)
    assert np.isnan(frame.lat_rad[out]).all() and np.isnan(frame.v_ned_mps[out]).all()
    idx = np.arange(1000) * 100
    e = gnss_errors_ned(frame, truth, idx)[frame.valid]
    np.testing.assert_allclose(e.std(axis=0), [2.0, 2.0, 4.0], rtol=0.08)
    ev = frame.v_ned_mps[frame.valid] - truth.v_ned_mps[idx][frame.valid]
    np.testing.assert_allclose(ev.std(axis=0), 0.1, rtol=0.08)


def test_gnss_drift_is_correlated_and_chunking_is_seamless():
    truth = straight_truth(200000, dt_s=0.1, speed_mps=0.0)       # 20000 s = 1000 correlation times
    cfg = GnssConfig(horizontal_noise_m=0.0, vertical_noise_m=0.0, horizontal_drift_m=3.0,
                     vertical_drift_m=3.0,
                     drift_tau_s=20.0, rate_hz=1.0)
    one, _ = sample_gnss(truth, None, np.random.default_rng(1), cfg)
    e = gnss_errors_ned(one, truth, np.arange(0, 200000, 10))
    for axis in range(3):
        rho = np.corrcoef(e[:-20, axis], e[20:, axis])[0, 1]     # lag 20 s = one correlation time
        assert abs(rho - np.exp(-1.0)) < 0.08
        assert abs(e[:, axis].std() / 3.0 - 1) < 0.1
    rng, state, parts = np.random.default_rng(1), None, []
    for c in chunks_of(truth, [5, 1234, 7, 30000]):
        f, state = sample_gnss(c, None, rng, cfg, state)
        parts.append(f.lat_rad)
    np.testing.assert_array_equal(np.concatenate(parts), one.lat_rad)


@pytest.mark.parametrize("outages, msg", [
    ([(10.0, 5.0)], "backwards"), ([(0.0, 10.0), (5.0, 20.0)], "overlaps"),
    ([(20.0, 30.0), (0.0, 10.0)], "overlaps"), ([(1.0, 1.0)], "backwards"), ([(1.0,)], "outages")])
def test_gnss_bad_outages(outages, msg):
    with pytest.raises(ValueError, match=msg) as err:
        GnssConfig(outages=outages)
    assert "outages" in str(err.value)


@pytest.mark.parametrize("field", ["rate_hz", "horizontal_noise_m", "velocity_noise_mps", "drift_tau_s"])
def test_gnss_bad_numbers(field):
    with pytest.raises(ValueError, match=field):
        GnssConfig(**{field: -1.0})


def test_air_data_bias_and_noise():
    truth = straight_truth(100000, speed_mps=110.0, wind_ned_mps=(10.0, -5.0, 0.0))
    cfg = AirDataConfig(tas_bias_mps=0.0, tas_noise_mps=0.8, alpha_bias_deg=0.0, alpha_noise_deg=0.3,
                        beta_bias_deg=0.0, beta_noise_deg=0.1)
    frame, _ = sample_air_data(truth, None, np.random.default_rng(2), cfg)
    assert frame.t_s.shape[0] == 10000
    idx = np.arange(0, 100000, 10)
    assert abs((frame.tas_mps - truth.tas_mps[idx]).std() / 0.8 - 1) < 0.05
    assert abs(np.rad2deg(frame.alpha_rad - truth.alpha_rad[idx]).std() / 0.3 - 1) < 0.05
    assert abs(np.rad2deg(frame.beta_rad - truth.beta_rad[idx]).std() / 0.1 - 1) < 0.05
    biases = [sample_air_data(truth.slice(0, 1), None, np.random.default_rng(s), AirDataConfig.noise_free(
        tas_bias_mps=1.5))[0].tas_mps[0] - truth.tas_mps[0] for s in range(400)]
    assert abs(np.std(biases) / 1.5 - 1) < 0.12
    nf, _ = sample_air_data(truth, None, np.random.default_rng(2), AirDataConfig.noise_free())
    np.testing.assert_array_equal(nf.tas_mps, truth.tas_mps[idx])


def test_heading_error_class_and_wrap():
    # full circle of headings (a turn), default compass: total error below 0.7 deg at ~1.4 sigma
    truth = straight_truth(36000, turn_rate_dps=1.0, track_deg=170.0)
    errs = []
    for seed in range(20):
        frame, _ = sample_heading(truth, None, np.random.default_rng(seed), HeadingConfig())
        d = np.angle(np.exp(1j * (frame.heading_rad - truth.yaw_rad[::10])))
        errs.append(d)
        assert np.all(frame.heading_rad <= np.pi) and np.all(frame.heading_rad > -np.pi)
    rms = np.rad2deg(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    assert 0.2 < rms < 0.7
    # deviation depends on heading: with only the B-E terms the error averages to zero over the circle
    cfg = HeadingConfig.noise_free(deviation_deg=1.0)
    frame, _ = sample_heading(truth, None, np.random.default_rng(3), cfg)
    d = np.angle(np.exp(1j * (frame.heading_rad - truth.yaw_rad[::10])))
    assert np.ptp(d) > np.deg2rad(0.3) and abs(d.mean()) < np.deg2rad(0.05)


@pytest.mark.parametrize("cls, field", [(AirDataConfig, "tas_noise_mps"), (AirDataConfig, "rate_hz"),
                                        (HeadingConfig, "noise_deg"), (HeadingConfig, "bias_deg")])
def test_air_heading_bad_numbers(cls, field):
    with pytest.raises(ValueError, match=field):
        cls(**{field: -2.0})
