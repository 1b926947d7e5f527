"""terrain.metrics.track_crlb against independent computations: a Kalman filter on a planar terrain (where
the posterior CRLB equals the KF covariance), the closed form without process noise, and a finite-difference
Monte Carlo Fisher information of the measurement on a rough map."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.terrain import geodesy, metrics
from trn_env.terrain.dem import Dem

from trn_env import terrain

LAT0 = math.radians(36.5)
LON0 = math.radians(-84.3)


def _plane(a_n: float, a_e: float, n: int = 121, spacing_m: float = 30.0) -> Dem:
    """A map h = a_n * north + a_e * east (m), north/east in metres from the grid origin at every post."""
    dlat = spacing_m / geodesy.meridian_radius_m(LAT0)
    dlon = spacing_m / (geodesy.prime_vertical_radius_m(LAT0) * math.cos(LAT0))
    lat = LAT0 + np.arange(n) * dlat
    north = (lat - LAT0) * geodesy.meridian_radius_m(LAT0)
    east = np.arange(n)[None, :] * dlon * (geodesy.prime_vertical_radius_m(lat) * np.cos(lat))[:, None]
    return Dem(500.0 + a_n * north[:, None] + a_e * east, LAT0, LON0, dlat, dlon, "plane")


def _track(dem: Dem, n: int, rng: np.random.Generator):
    la0, la1, lo0, lo1 = dem.bounds
    m = 0.2
    lat = rng.uniform(la0 + m * (la1 - la0), la1 - m * (la1 - la0), n)
    lon = rng.uniform(lo0 + m * (lo1 - lo0), lo1 - m * (lo1 - lo0), n)
    return lat, lon


def _kf_covariances(H: np.ndarray, r: np.ndarray, t: np.ndarray, p0: float, q: float) -> np.ndarray:
    """Covariance form of the Kalman filter (Joseph update) for x_k = x_(k-1) + w, z_k = H_k x_k + v."""
    P = np.eye(2) * p0**2
    out = []
    for k in range(H.shape[0]):
        if k > 0:
            P = P + np.eye(2) * q * (t[k] - t[k - 1])
        h = H[k][None, :]
        S = float((h @ P @ h.T)[0, 0]) + r[k]
        K = P @ h.T / S
        A = np.eye(2) - K @ h
        P = A @ P @ A.T + K @ K.T * r[k]
        out.append(P)
    return np.array(out)


@pytest.mark.parametrize("method", ["bicubic", "bilinear"])
def test_planar_terrain_bound_equals_kalman_filter(method):
    """On a plane the measurement is linear in position: the bound is the KF covariance (process noise,
    sensor noise varying per epoch, a map error, uneven epochs)."""
    rng = np.random.default_rng(3)
    dem = _plane(0.12, -0.05)
    n = 40
    lat, lon = _track(dem, n, rng)
    t = np.cumsum(rng.uniform(0.5, 2.0, n))
    sig = rng.uniform(2.0, 5.0, n)
    q, p0, s_map = 1.3, 150.0, 1.5
    b = metrics.track_crlb(dem, lat, lon, sig, t, prior_sigma_m=p0, process_noise_m2_per_s=q,
                           map_sigma_m=s_map, method=method)
    H = np.array([[0.12, -0.05]] * n)
    P_kf = _kf_covariances(H, sig**2 + s_map**2, t, p0, q)
    assert np.allclose(b.gradient, H, rtol=2e-3, atol=1e-5)
    assert np.allclose(b.covariance_m2, P_kf, rtol=2e-3, atol=1e-9)
    assert np.allclose(b.sigma_h_m, np.sqrt(np.trace(P_kf, axis1=1, axis2=2)), rtol=2e-3)
    assert b.sigma_z_m == pytest.approx(np.sqrt(sig**2 + s_map**2))
    # a plane leaves the direction along its contours to the prior and the process noise
    assert b.sigma_h_m[-1] > 100.0
    # without a prior, one gradient direction: (numerically almost) singular information, no useful bound
    nop = metrics.track_crlb(dem, lat, lon, sig, t, process_noise_m2_per_s=q, method=method)
    assert np.isinf(nop.sigma_h_m[0]) and np.all(nop.sigma_h_m > 1e5)
    assert b.rms_m(t[20]) == pytest.approx(math.sqrt(np.mean(np.trace(P_kf[t >= t[20]], axis1=1, axis2=2))),
                                           rel=2e-3)


def test_no_process_noise_is_the_summed_information():
    """q = 0: J_n = J_0 + sum_k g_k g_k^T / var_k, on a rough real map (gradients from the map)."""
    dem = terrain.load("jacksboro")
    rng = np.random.default_rng(5)
    lat, lon = _track(dem, 60, rng)
    sig = rng.uniform(2.0, 6.0, 60)
    b = metrics.track_crlb(dem, lat, lon, sig, prior_sigma_m=1000.0, map_sigma_m=2.0)
    gn, ge = dem.gradient(lat, lon, method="bicubic")
    J = np.eye(2) / 1000.0**2 + np.einsum("k,ki,kj->ij", 1.0 / (sig**2 + 4.0), np.c_[gn, ge], np.c_[gn, ge])
    assert np.allclose(b.information[-1], J, rtol=1e-10)
    assert b.covariance_m2[-1] == pytest.approx(np.linalg.inv(J), rel=1e-8)
    assert np.all(np.diff(b.sigma_h_m) <= 1e-12)           # information only accumulates


def test_fisher_information_matches_finite_difference_monte_carlo():
    """Each measurement's information g g^T / var equals E[s s^T] of the score s = d log p(z | x) / dx,
    the log-likelihood differentiated by central differences of the map's own heights (1 m steps north and
    east), z drawn from the model: a Monte Carlo estimate with a chi-square-free tolerance of 4 standard
    errors (relative SE of a mean of s^2 over n draws: sqrt(2 / n))."""
    dem = terrain.load("jacksboro")
    rng = np.random.default_rng(11)
    n_pts, n_mc = 25, 4000
    lat, lon = _track(dem, n_pts, rng)
    sigma = 3.0
    inc = np.empty((n_pts, 2, 2))
    for k in range(n_pts):
        one = metrics.track_crlb(dem, lat[k:k + 1], lon[k:k + 1], sigma, prior_sigma_m=1e6)
        inc[k] = one.information[0] - np.eye(2) / 1e12
    step = 1.0
    est = np.zeros((2, 2))
    for k in range(n_pts):
        h0 = dem.height(lat[k], lon[k], method="bicubic")
        z = h0 + sigma * rng.standard_normal(n_mc)
        score = np.empty((n_mc, 2))
        for a, (dn, de) in enumerate(((step, 0.0), (0.0, step))):
            la_p, lo_p = dem.offset_to_latlon(lat[k], lon[k], dn, de)
            la_m, lo_m = dem.offset_to_latlon(lat[k], lon[k], -dn, -de)
            hp = dem.height(la_p, lo_p, method="bicubic")
            hm = dem.height(la_m, lo_m, method="bicubic")
            score[:, a] = (-0.5 * (z - hp) ** 2 + 0.5 * (z - hm) ** 2) / sigma**2 / (2 * step)
        est += score.T @ score / n_mc
    total = inc.sum(axis=0)
    se = math.sqrt(2.0 / n_mc) / math.sqrt(n_pts)
    assert est[0, 0] == pytest.approx(total[0, 0], rel=4 * se + 0.01)
    assert est[1, 1] == pytest.approx(total[1, 1], rel=4 * se + 0.01)
    assert abs(est[0, 1] - total[0, 1]) < (4 * se + 0.01) * math.sqrt(total[0, 0] * total[1, 1])


@pytest.mark.parametrize("kw,match", [
    (dict(sigma_m=-1.0), "sigma_m"), (dict(sigma_m=np.nan), "sigma_m"), (dict(sigma_m=0.0), "map_sigma_m"),
    (dict(prior_sigma_m=0.0), "prior_sigma_m"), (dict(process_noise_m2_per_s=-1.0), "process_noise"),
    (dict(t_s=[1.0, 0.0, 2.0]), "t_s"), (dict(map_sigma_m=math.inf), "map_sigma_m")])
def test_bad_input(kw, match):
    dem = _plane(0.1, 0.1)
    lat, lon = _track(dem, 3, np.random.default_rng(0))
    args = dict(sigma_m=2.0) | kw
    with pytest.raises(ValueError, match=match):
        metrics.track_crlb(dem, lat, lon, **args)
