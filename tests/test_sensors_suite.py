"""SensorSuite: config mapping, per-sensor random streams, chunking, and a real flight over the real DEM."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_sensors_common import chunks_of, straight_truth

from trn_env import terrain
from trn_env.sensors.baro import isa_pressure_altitude_m
from trn_env.sensors.imu import ImuConfig
from trn_env.sensors.suite import SENSOR_NAMES, SensorSuite

ALL = {"imu": {"grade": "tactical"}, "baro": True, "radar_altimeter": {"beamwidth_deg": 35.0}, "ira": True,
       "gnss": {"outages": [[2.0, 3.0]]}, "air_data": True, "heading": True}


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


@pytest.fixture(scope="module")
def truth(dem):
    lat, lon = dem.center_rad
    return straight_truth(500, lat0_deg=math.degrees(lat), lon0_deg=math.degrees(lon), h_m=2000.0,
                          roll_deg=8.0, turn_rate_dps=2.0)


def frames_equal(a, b):
    for name in SENSOR_NAMES:
        fa, fb = getattr(a, name), getattr(b, name)
        assert (fa is None) == (fb is None)
        if fa is None:
            continue
        for key, va in vars(fa).items():
            np.testing.assert_array_equal(va, getattr(fb, key), err_msg=f"{name}.{key}")


def test_suite_all_sensors_rates_and_interval(dem, truth):
    suite = SensorSuite.from_config(ALL, 42)
    frames = suite.sample(truth, dem)
    assert frames.t_start_s == 0.0 and frames.t_end_s == pytest.approx(5.0)
    counts = {n: getattr(frames, n).t_s.shape[0] for n in SENSOR_NAMES}
    assert counts == {"imu": 500, "baro": 50, "radar_altimeter": 100, "ira": 250, "gnss": 5, "air_data": 50,
                      "heading": 50}
    assert frames.radar_altimeter.valid.all() and frames.ira.valid.all()
    np.testing.assert_array_equal(frames.gnss.valid, [True, True, False, True, True])


def test_absent_sensors_are_none(dem, truth):
    frames = SensorSuite.from_config({"imu": True, "baro": None, "gnss": False}, 1).sample(truth, dem)
    assert frames.imu is not None
    for name in ("baro", "radar_altimeter", "ira", "gnss", "air_data", "heading"):
        assert getattr(frames, name) is None


def test_seeded_streams_deterministic_and_independent(dem, truth):
    a = SensorSuite.from_config(ALL, 7).sample(truth, dem)
    b = SensorSuite.from_config(ALL, np.random.SeedSequence(7)).sample(truth, dem)
    frames_equal(a, b)
    c = SensorSuite.from_config(ALL, 8).sample(truth, dem)
    assert not np.array_equal(a.imu.f_b_mps2, c.imu.f_b_mps2)
    # each sensor's stream is spawned by name: removing other sensors leaves the baro untouched
    only = SensorSuite.from_config({"baro": True}, 7).sample(truth, dem)
    np.testing.assert_array_equal(only.baro.h_baro_m, a.baro.h_baro_m)


def test_chunked_suite_equals_one_shot(dem, truth):
    one = SensorSuite.from_config(ALL, 3).sample(truth, dem)
    suite = SensorSuite.from_config(ALL, 3)
    parts = [suite.sample(c, dem) for c in chunks_of(truth, [10, 1, 49, 7, 133, 100])]
    assert parts[1].t_start_s == pytest.approx(0.10) and parts[1].t_end_s == pytest.approx(0.11)
    for name in SENSOR_NAMES:
        for key in vars(getattr(one, name)):
            joined = np.concatenate([getattr(getattr(p, name), key) for p in parts])
            np.testing.assert_allclose(joined, getattr(getattr(one, name), key), rtol=0, atol=1e-12,
                                       err_msg=f"{name}.{key}")


def test_bad_suite_config(dem, truth):
    with pytest.raises(ValueError, match="lidar"):
        SensorSuite.from_config({"lidar": True}, 0)
    with pytest.raises(ValueError, match="beamwidth_deg"):
        SensorSuite.from_config({"radar_altimeter": {"beamwidth_deg": 120.0}}, 0)
    with pytest.raises(ValueError, match="baseline_left_m"):
        SensorSuite.from_config({"ira": {"baseline_left_m": 0.0}}, 0)
    with pytest.raises(ValueError, match="outages"):
        SensorSuite.from_config({"gnss": {"outages": [[5.0, 1.0]]}}, 0)
    with pytest.raises(ValueError, match="bogus"):
        SensorSuite.from_config({"baro": {"bogus": 1}}, 0)
    with pytest.raises(ValueError, match="terrain"):
        SensorSuite.from_config({"ira": True}, 0).sample(truth, None)
    suite = SensorSuite.from_config({"imu": ImuConfig.noise_free()}, 0)
    assert suite.configs["imu"] == ImuConfig.noise_free()


def test_real_flight_over_real_dem(dem):
    """A short JSBSim flight (trn_env.flight) sampled noise-free: readings match the truth they came from."""
    flight_mod = pytest.importorskip("trn_env.flight.core")
    lat, lon = dem.center_rad
    h0 = float(np.nanmax(dem.heights_m)) + 800.0
    ic = flight_mod.InitialCondition(lat_rad=lat, lon_rad=lon, h_msl_m=h0, tas_mps=100.0,
                                     heading_rad=math.radians(60.0))
    try:
        fl = flight_mod.Flight(ic, terrain_elevation_m=float(dem.height(lat, lon)))
    except flight_mod.TrimError as exc:     # the flight core's business, not the sensors'
        pytest.skip(f"flight core could not trim: {exc}")
    cfg = {"imu": {"grade": "noise_free", "sampling": "instant"}, "baro": {"noise_free": True},
           "gnss": {"noise_free": True},
           "radar_altimeter": {"noise_free": True, "beamwidth_deg": 17.0}, "ira": {"noise_free": True},
           "air_data": {"noise_free": True}, "heading": {"noise_free": True}}
    suite = SensorSuite.from_config(cfg, 0)
    chunks = [fl.advance(10) for _ in range(30)]
    frames = [suite.sample(c, dem) for c in chunks]
    truth = chunks[0].concatenate(chunks)

    def rows(name):
        t = np.concatenate([getattr(f, name).t_s for f in frames])
        j = np.searchsorted(truth.t_s, t - 1e-9)
        np.testing.assert_allclose(truth.t_s[j], t)
        return j, t

    imu = np.concatenate([f.imu.f_b_mps2 for f in frames])
    np.testing.assert_allclose(imu, truth.f_b_mps2, atol=1e-12)
    j, t = rows("baro")
    np.testing.assert_allclose(np.diff(t), 0.1)
    assert np.allclose(np.mod(t + 1e-9, 0.1), 0.0, atol=1e-6)           # on the absolute 10 Hz grid
    baro = np.concatenate([f.baro.h_baro_m for f in frames])
    np.testing.assert_allclose(baro, isa_pressure_altitude_m(truth.p_static_pa[j]), atol=1e-6)
    j, _ = rows("radar_altimeter")
    ra = np.concatenate([f.radar_altimeter.range_m for f in frames])
    plumb = truth.h_msl_m[j] - dem.height(truth.lat_rad[j], truth.lon_rad[j])
    assert np.all(ra <= plumb + 0.5) and np.all(ra > 0.6 * plumb)
    j, t = rows("ira")
    assert t.shape[0] == 150
    ira = np.concatenate([f.ira.range_m for f in frames])
    plumb = truth.h_msl_m[j] - dem.height(truth.lat_rad[j], truth.lon_rad[j])
    assert np.all(np.isfinite(ira)) and np.all(ira <= plumb + 0.5)
    j, t = rows("gnss")
    np.testing.assert_allclose(t, [1.0, 2.0, 3.0])
    lat = np.concatenate([f.gnss.lat_rad for f in frames])
    np.testing.assert_allclose(lat, truth.lat_rad[j], atol=1e-12)
