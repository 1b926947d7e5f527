"""Barometric altimeter: ISA table, non-standard day, lag, noise, chunking, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensors_common import chunks_of, straight_truth

from trn_env.sensors.baro import BaroConfig, isa_pressure_altitude_m, isa_pressure_pa, sample_baro

# ICAO / ISO 2533 standard atmosphere table, geopotential altitude (m) -> pressure (Pa)
ISA_TABLE = [(0.0, 101325.0), (1500.0, 84556.0), (5000.0, 54020.0), (11000.0, 22632.0), (15000.0, 12045.0),
             (20000.0, 5474.9), (25000.0, 2511.0)]


@pytest.mark.parametrize("h_m, p_pa", ISA_TABLE)
def test_isa_matches_published_table(h_m, p_pa):
    assert isa_pressure_pa(h_m) == pytest.approx(p_pa, rel=2e-4)
    assert isa_pressure_altitude_m(p_pa) == pytest.approx(h_m, abs=2.0)


def test_isa_tables_by_geometric_height():
    # tables by geometric height (US 1976): 5000 m -> 54.05 kPa, 1500 m -> 84.56 kPa
    # (geopotential H = r Z / (r + Z))
    r0 = 6356766.0
    for z, p in ((1500.0, 84560.0), (5000.0, 54048.0)):
        assert isa_pressure_pa(r0 * z / (r0 + z)) == pytest.approx(p, rel=3e-4)


def test_noise_free_standard_and_non_standard_day():
    std = straight_truth(200, h_m=3000.0)
    frame, _ = sample_baro(std, None, np.random.default_rng(0), BaroConfig.noise_free())
    np.testing.assert_allclose(frame.h_baro_m, 3000.0, atol=0.5)      # ISA day: reads the altitude
    hot = straight_truth(200, h_m=3000.0, temp_offset_K=15.0)
    frame, _ = sample_baro(hot, None, np.random.default_rng(0), BaroConfig.noise_free())
    # ISA+15: the air column is warmer and taller; hydrostatics say the altimeter under-reads by ~ h dT/T
    expected = 3000.0 * 288.15 / (288.15 + 15.0)
    np.testing.assert_allclose(frame.h_baro_m, expected, atol=1.0)
    assert frame.h_baro_m.mean() < 3000.0 - 100.0


def test_rate_bias_noise_statistics():
    truth = straight_truth(20000, h_m=1000.0)
    cfg = BaroConfig(rate_hz=10.0, bias_m=0.0, noise_m=2.0, lag_tau_s=0.0)
    frame, _ = sample_baro(truth, None, np.random.default_rng(1), cfg)
    assert frame.t_s.shape[0] == 2000 and np.allclose(np.diff(frame.t_s), 0.1)
    err = frame.h_baro_m - isa_pressure_altitude_m(truth.p_static_pa[::10])
    assert abs(err.std() / 2.0 - 1) < 0.06 and abs(err.mean()) < 0.2
    biases = [sample_baro(truth.slice(0, 10), None, np.random.default_rng(s), BaroConfig(bias_m=20.0,
              noise_m=0.0, lag_tau_s=0.0))[0].h_baro_m[0] - 1000.0 for s in range(300)]
    assert abs(np.std(biases) / 20.0 - 1) < 0.15


def test_lag_follows_a_climb_and_chunking_is_seamless():
    truth = straight_truth(3000, h_m=1000.0)
    h = 1000.0 + 5.0 * (truth.t_s - 10.0).clip(0)        # 5 m/s climb from t = 10 s
    truth.p_static_pa[:] = isa_pressure_pa(h)
    cfg = BaroConfig(rate_hz=50.0, bias_m=0.0, noise_m=0.0, lag_tau_s=1.0)
    one, _ = sample_baro(truth, None, np.random.default_rng(2), cfg)
    # steady ramp through a first-order lag lags by rate * tau = 5 m
    late = one.t_s > 20.0
    np.testing.assert_allclose(one.h_baro_m[late], (1000.0 + 5.0 * (one.t_s - 10.0) - 5.0)[late], atol=0.05)
    rng, state, parts = np.random.default_rng(2), None, []
    for c in chunks_of(truth, [3, 250, 1, 999]):
        f, state = sample_baro(c, None, rng, cfg, state)
        parts.append(f.h_baro_m)
    np.testing.assert_allclose(np.concatenate(parts), one.h_baro_m, atol=1e-9)


@pytest.mark.parametrize("field, value", [("rate_hz", -1.0), ("noise_m", -0.1), ("bias_m", -3.0),
                                          ("lag_tau_s", -0.5)])
def test_bad_config_names_field(field, value):
    with pytest.raises(ValueError, match=field):
        BaroConfig(**{field: value})
