"""terrain.metrics.track_crlb with a velocity offset (x_k = x_(k-1) + v dt + w, v a random walk), and with a
constant acceleration offset, equals a Kalman filter's covariance on a plane (filterpy, the exact answer
there), and adds to the bound."""

import math

import numpy as np
from filterpy.kalman import KalmanFilter
from test_terrain_filter_linear import G_E, G_N, LAT0, LON0, planar_dem
from trn_env.terrain import metrics


def test_velocity_bound_equals_the_kalman_filter_on_a_plane():
    dem = planar_dem()
    n, dt, sig, p0, sv0, s_v, q = 40, 1.0, 4.0, 30.0, 0.1, 0.01, 0.05
    lat = np.full(n, LAT0)
    lon = np.full(n, LON0)
    t = np.arange(n) * dt
    b = metrics.track_crlb(dem, lat, lon, sig, t, prior_sigma_m=p0, process_noise_m2_per_s=q,
                           velocity_prior_sigma_mps=sv0, velocity_noise_mps_per_sqrt_s=s_v)
    k = KalmanFilter(dim_x=4, dim_z=1)
    k.P = np.diag([p0**2, p0**2, sv0**2, sv0**2])
    k.F = np.eye(4)
    k.F[0, 2] = k.F[1, 3] = dt
    k.Q = np.diag([q * dt, q * dt, s_v**2 * dt, s_v**2 * dt])
    k.R = np.array([[sig**2]])
    gn, ge = (float(np.atleast_1d(x)[0]) for x in dem.gradient(lat[:1], lon[:1], method="bicubic"))
    assert abs(gn - G_N) < 0.01 and abs(ge - G_E) < 0.01     # the plane's slope (radii at the map's datum)
    k.H = np.array([[gn, ge, 0.0, 0.0]])
    for i in range(n):
        if i:
            k.predict()
        k.update(np.zeros((1, 1)))
        np.testing.assert_allclose(b.covariance_m2[i], k.P[:2, :2], rtol=1e-6, atol=1e-9)
    plain = metrics.track_crlb(dem, lat, lon, sig, t, prior_sigma_m=p0, process_noise_m2_per_s=q)
    assert b.sigma_h_m[-1] > plain.sigma_h_m[-1] * 1.01      # an unknown ramp only loses information
    assert math.isfinite(b.sigma_h_m[-1])


def test_acceleration_bound_equals_the_kalman_filter_on_a_plane():
    dem = planar_dem()
    n, dt, sig, p0, sv0, s_v, q, sa0 = 60, 1.0, 4.0, 30.0, 0.1, 0.001, 0.01, 0.01
    lat = np.full(n, LAT0)
    lon = np.full(n, LON0)
    t = np.arange(n) * dt
    kw = dict(prior_sigma_m=p0, process_noise_m2_per_s=q, velocity_prior_sigma_mps=sv0,
              velocity_noise_mps_per_sqrt_s=s_v)
    b = metrics.track_crlb(dem, lat, lon, sig, t, acceleration_prior_sigma_mps2=sa0, **kw)
    k = KalmanFilter(dim_x=6, dim_z=1)
    k.P = np.diag([p0**2, p0**2, sv0**2, sv0**2, sa0**2, sa0**2])
    k.F = np.eye(6)
    k.F[0, 2] = k.F[1, 3] = k.F[2, 4] = k.F[3, 5] = dt
    k.F[0, 4] = k.F[1, 5] = 0.5 * dt**2
    k.Q = np.diag([q * dt, q * dt, s_v**2 * dt, s_v**2 * dt, 0.0, 0.0])
    k.R = np.array([[sig**2]])
    gn, ge = (float(np.atleast_1d(x)[0]) for x in dem.gradient(lat[:1], lon[:1], method="bicubic"))
    k.H = np.array([[gn, ge, 0.0, 0.0, 0.0, 0.0]])
    for i in range(n):
        if i:
            k.predict()
        k.update(np.zeros((1, 1)))
        np.testing.assert_allclose(b.covariance_m2[i], k.P[:2, :2], rtol=1e-6, atol=1e-9)
    without = metrics.track_crlb(dem, lat, lon, sig, t, **kw)
    assert b.sigma_h_m[-1] > without.sigma_h_m[-1] * 1.01    # an unknown acceleration only loses information
