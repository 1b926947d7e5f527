"""Shared synthetic truth for the sensor tests, and tests of the sampling grid and error recursions."""

from __future__ import annotations

import numpy as np
import pytest
from trn_env.terrain.geodesy import OMEGA_EARTH_RPS, euler_to_C_bn, meridian_radius_m, prime_vertical_radius_m

from trn_env.flight.truth import TruthChunk
from trn_env.sensors.common import sample_steps

G_ISA = 9.80665


def normal_gravity_mps2(lat_rad: float, h_m: float) -> float:
    """Somigliana normal gravity with the free-air correction (independent of the sensor code)."""
    s2 = np.sin(lat_rad) ** 2
    g0 = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
    return g0 - 3.086e-6 * h_m


def straight_truth(n: int, dt_s: float = 0.01, t0_s: float = 0.0, lat0_deg: float = 33.2,
                   lon0_deg: float = -98.2, h_m: float = 1500.0, speed_mps: float = 100.0,
                   track_deg: float = 30.0, yaw_deg: float | None = None, roll_deg: float = 0.0,
                   pitch_deg: float = 2.0, turn_rate_dps: float = 0.0, wind_ned_mps=(0.0, 0.0, 0.0),
                   temp_offset_K: float = 0.0) -> TruthChunk:
    """Analytic level flight (optionally a steady turn), every TruthChunk field filled, SI."""
    c = TruthChunk.empty(n)
    t = t0_s + dt_s * np.arange(n)
    c.t_s[:] = t
    track = np.deg2rad(track_deg) + np.deg2rad(turn_rate_dps) * (t - t0_s)
    v = np.stack([speed_mps * np.cos(track), speed_mps * np.sin(track), np.zeros(n)], axis=1)
    c.v_ned_mps[:] = v
    lat0 = np.deg2rad(lat0_deg)
    r_n = meridian_radius_m(lat0) + h_m
    r_e = prime_vertical_radius_m(lat0) + h_m
    c.lat_rad[:] = lat0 + np.cumsum(np.r_[0.0, v[:-1, 0]]) * dt_s / r_n
    c.lon_rad[:] = np.deg2rad(lon0_deg) + np.cumsum(np.r_[0.0, v[:-1, 1]]) * dt_s / (r_e * np.cos(lat0))
    c.h_msl_m[:] = h_m
    yaw = track if yaw_deg is None else np.deg2rad(yaw_deg) + (track - np.deg2rad(track_deg))
    c.roll_rad[:] = np.deg2rad(roll_deg)
    c.pitch_rad[:] = np.deg2rad(pitch_deg)
    c.yaw_rad[:] = np.mod(yaw + np.pi, 2 * np.pi) - np.pi
    c.C_bn[:] = euler_to_C_bn(c.roll_rad, c.pitch_rad, c.yaw_rad)
    g = normal_gravity_mps2(lat0, h_m)
    c.f_b_mps2[:] = np.einsum("nji,j->ni", c.C_bn, np.array([0.0, 0.0, -g]))
    w_ie_n = OMEGA_EARTH_RPS * np.array([np.cos(lat0), 0.0, -np.sin(lat0)])
    w_eb_n = np.stack([np.zeros(n), np.zeros(n), np.full(n, np.deg2rad(turn_rate_dps))], axis=1)
    c.omega_eb_b_rps[:] = np.einsum("nji,nj->ni", c.C_bn, w_eb_n)
    c.omega_ib_b_rps[:] = c.omega_eb_b_rps + np.einsum("nji,j->ni", c.C_bn, w_ie_n)
    air = v - np.asarray(wind_ned_mps, float)
    c.tas_mps[:] = np.linalg.norm(air, axis=1)
    c.alpha_rad[:] = np.deg2rad(pitch_deg)
    c.beta_rad[:] = 0.0
    # ISA-shaped pressure with a temperature offset (hydrostatic, troposphere): a non-standard day
    T = 288.15 + temp_offset_K - 0.0065 * h_m
    c.T_static_K[:] = T
    c.p_static_pa[:] = 101325.0 * (T / (288.15 + temp_offset_K)) ** (G_ISA / (287.05287 * 0.0065))
    c.wind_ned_mps[:] = np.asarray(wind_ned_mps, float)
    c.h_agl_m[:] = np.nan
    return c


def chunks_of(truth: TruthChunk, sizes):
    out, i = [], 0
    for s in sizes:
        out.append(truth.slice(i, min(i + s, len(truth))))
        i += s
    if i < len(truth):
        out.append(truth.slice(i, len(truth)))
    return out


# ------------------------------------------------------------------------------------------------ tests
@pytest.mark.parametrize("rate_hz, expected_period", [(50.0, 2), (20.0, 5), (100.0, 1), (1.0, 100)])
def test_sampling_grid_independent_of_chunking(rate_hz, expected_period):
    t = np.round(0.01 * np.arange(1000), 10) + 0.0
    one, _ = sample_steps(t, rate_hz, None)
    np.testing.assert_array_equal(one, np.arange(0, 1000, expected_period))
    got, last, start = [], None, 0
    for size in (7, 1, 33, 0, 159, 300, 500):
        idx, last = sample_steps(t[start:start + size], rate_hz, last)
        got.append(idx + start)
        start += size
    np.testing.assert_array_equal(np.concatenate(got), one)


def test_sampling_off_grid_start_and_non_dividing_rate():
    t = 0.005 + 0.01 * np.arange(100)           # steps between grid points
    idx, _ = sample_steps(t, 50.0, None)
    # first step at or after each 0.02 s grid instant: 0.025 (grid 0.02), 0.045 (0.04), ...
    np.testing.assert_allclose(t[idx][:3], [0.025, 0.045, 0.065])
    t = 0.01 * np.arange(300)
    idx, _ = sample_steps(t, 30.0, None)         # 30 Hz on a 100 Hz truth: 90 samples in 3 s
    assert idx.shape[0] == 90
    grid = np.arange(90) / 30.0
    assert np.all(t[idx] >= grid - 1e-9) and np.all(t[idx] < grid + 0.01)


def test_rate_above_truth_rate_is_refused():
    t = 0.01 * np.arange(10)
    with pytest.raises(ValueError, match="rate_hz"):
        sample_steps(t, 200.0, None)
    _, last = sample_steps(t[:5], 100.0, None)
    with pytest.raises(ValueError, match="rate_hz"):
        sample_steps(t[5:], 300.0, last * 3)
