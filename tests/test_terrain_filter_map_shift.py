"""The map's horizontal shift in the terrain filters' published position (navigators/filters/map_shift.py).

A map shifted by s moves every terrain fix by s, so the estimate takes s on while the belief describes only
the error relative to the map. Checked two ways: the share recursion against a Monte Carlo of a scalar
Kalman filter fed terrain fixes x + s + v and GNSS fixes x + w (the exact answer for the linear case), and
the point-mass and particle filters over curved terrain with the map shifted by a drawn s: the published
horizontal NEES summed over runs within the chi-square bounds, after terrain samples and after GNSS fixes that
follow them, far above them without the shift's share.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2
from test_terrain_filter_linear import H_ANT, LAT0, LON0, SIGMA_R
from trn_env.navigators.filters.map_shift import MapShiftShare
from trn_env.navigators.filters.pf import ParticleFilter
from trn_env.navigators.filters.pmf import PointMassFilter
from trn_env.navigators.inertial.strapdown import quat_from_C_bn
from trn_env.navigators.integrity.protection_level import configure
from trn_env.navigators.measurements.terrain_models import radii_m
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import euler_to_C_bn

from trn_env.scenario.navigation import imu_spec

SIGMA_H = 50.0 / 2.146        # the DTED-1 class's shift per axis (CE90 50 m)
SIGMA_X0 = 30.0               # the INS's horizontal error at the start, per axis
SPEED = 80.0                  # m/s north


def test_share_recursion_matches_a_monte_carlo_kalman_filter():
    # scalar Kalman filter on x (prior var p0): GNSS fixes y = x + w, then terrain fixes z = x + s + v; the
    # error e = x_hat - x over 200,000 draws has var P + a^2 sigma_s^2, P the filter's own variance
    rng = np.random.default_rng(3)
    n, p0, r_gnss, r_terrain, sig_s, q = 200_000, 40.0**2, 3.0**2, 15.0**2, 20.0, 0.5
    x = rng.normal(0.0, math.sqrt(p0), n)
    s = rng.normal(0.0, sig_s, n)
    x_hat, P = np.zeros(n), p0
    share = MapShiftShare()
    for k in range(12):
        x = x + rng.normal(0.0, math.sqrt(q), n)       # the INS walk: truth moves, the estimate does not
        P += q
        gnss = k < 3
        r = r_gnss if gnss else r_terrain
        y = x + rng.normal(0.0, math.sqrt(r), n) + (0.0 if gnss else s)
        K = P / (P + r)
        x_hat = x_hat + K * (y - x_hat)
        P_post = (1.0 - K) * P
        update = share.gnss if gnss else share.terrain
        update(np.eye(2) * P, np.eye(2) * P_post)
        P = P_post
        e = x_hat - x
        predicted = P + float(share.covariance(sig_s)[0, 0])
        # the sample variance of 200,000 Gaussian draws: within 1.5 % (5 sigma of its 0.3 % spread)
        assert np.var(e) == pytest.approx(predicted, rel=0.015), (k, np.var(e), predicted)
        assert np.cov(e, s)[0, 1] == pytest.approx(share.share[0] * sig_s**2, rel=0.05, abs=0.5)
    assert 0.0 < share.share[0] < 1.0 and share.share[0] == share.share[1]


def test_carried_share_matches_a_monte_carlo_kalman_filter_with_velocity():
    # a position-velocity Kalman filter (x' = x + v dt, v a random walk) fed terrain fixes z = x + s + w
    # only: part of each fix's correction goes into v and reaches x at the next predictions. The recursion
    # with the carried state (U: v's share, moved by the filter's regression G = P_vx / P_xx at an update,
    # into x by B = dt at a prediction) gives the error's variance and its covariances with s; the
    # position-only rule does not (checked: it misses var(e_x) by more than 1.5 % once v carries a share)
    rng = np.random.default_rng(5)
    n, dt, r, sig_s, qv = 200_000, 1.0, 12.0**2, 20.0, 0.05
    P = np.diag([15.0**2, 0.5**2])
    X = np.stack([rng.normal(0.0, 15.0, n), rng.normal(0.0, 0.5, n)])  # true (x, v) minus the INS's
    s = rng.normal(0.0, sig_s, n)
    X_hat = np.zeros((2, n))
    F = np.array([[1.0, dt], [0.0, 1.0]])
    share = MapShiftShare(n_carried=1)
    scalar = MapShiftShare()
    missed = 0
    for k in range(25):
        X = F @ X
        X[1] += rng.normal(0.0, math.sqrt(qv * dt), n)
        X_hat = F @ X_hat
        P = F @ P @ F.T + np.diag([0.0, qv * dt])
        share.predict(np.array([[dt], [0.0]]), np.eye(1))     # v is the north velocity: B = (dt, 0)'
        z = X[0] + s + rng.normal(0.0, math.sqrt(r), n)
        K = P[:, 0] / (P[0, 0] + r)
        X_hat = X_hat + K[:, None] * (z - X_hat[0])
        P_post = P - np.outer(K, P[0])
        G = P[1, 0] / P[0, 0]
        share.terrain(np.eye(2) * P[0, 0], np.eye(2) * P_post[0, 0], np.array([[G, 0.0]]))
        scalar.terrain(np.eye(2) * P[0, 0], np.eye(2) * P_post[0, 0])
        P = P_post
        e = X_hat - X
        a, u = share.A[0, 0], share.U[0, 0]
        assert np.var(e[0]) == pytest.approx(P[0, 0] + a * a * sig_s**2, rel=0.015), (k, np.var(e[0]))
        assert np.var(e[1]) == pytest.approx(P[1, 1] + u * u * sig_s**2, rel=0.015), (k, np.var(e[1]))
        for j, share_j in ((0, a), (1, u)):        # within 5 sigma of the sample covariance's spread
            spread = math.sqrt(np.var(e[j]) * sig_s**2 / n)
            assert np.cov(e[j], s)[0, 1] == pytest.approx(share_j * sig_s**2, abs=5.0 * spread), (k, j)
        missed += abs(np.var(e[0]) / (P[0, 0] + scalar.covariance(sig_s)[0, 0]) - 1.0) > 0.015
    # the velocity's share carries the position past the map's shift (a > 1), which the position-only rule
    # cannot; that rule misses the error's variance at most steps
    assert a > 1.0 and scalar.share[0] < 1.0 and missed >= 15, (a, scalar.share[0], missed)


def test_particle_mean_response_is_the_kalman_gain_on_a_linear_gaussian_update():
    # 400,000 particles from N(0, P0), a scalar measurement y = h.x + w (variance r) reweighting them: the
    # mean's response M = (dm/dy) H equals K h' of the Kalman update (K = P0 h' / (h P0 h' + r)) within the
    # sample's spread; the cloud's own variance ratio gives the same on this linear case
    from trn_env.navigators.filters.map_shift import particle_mean_response
    rng = np.random.default_rng(8)
    P0 = np.array([[90.0, 30.0], [30.0, 40.0]])
    x = rng.multivariate_normal([0.0, 0.0], P0, 400_000)
    h, r, y = np.array([0.8, -0.5]), 25.0, 12.0
    y_hat = x @ h
    w1 = np.exp(-0.5 * (y - y_hat) ** 2 / r)
    score = (-(y - y_hat) / r)[:, None]                  # d log N(y; y_hat, r) / dy
    M = particle_mean_response(x, np.ones(len(x)), w1, score, y_hat[:, None])
    K = P0 @ h / (h @ P0 @ h + r)
    assert M == pytest.approx(np.outer(K, h), abs=0.01)


def test_particle_mean_response_ignores_a_narrowing_that_does_not_move_the_mean():
    # a cloud centred on the floor of a valley (y = x_n^2 / 100, symmetric) measured at the floor: the
    # reweighting narrows the cloud by ~90 % (the variance rule would take that as the gain), but neither
    # moves a shift the predicted measurements there (the floor is flat) nor does a measurement offset there
    # move the mean, so the share does not grow
    from trn_env.navigators.filters.map_shift import particle_mean_response
    rng = np.random.default_rng(9)
    x = rng.normal(0.0, 10.0, (200_000, 2))
    y_hat = x[:, 0] ** 2 / 100.0
    r, y = 0.05, 0.0
    w1 = np.exp(-0.5 * (y - y_hat) ** 2 / r)
    narrowing = 1.0 - np.average(x[:, 0] ** 2, weights=w1) / np.mean(x[:, 0] ** 2)
    M = particle_mean_response(x, np.ones(len(x)), w1, (-(y - y_hat) / r)[:, None], y_hat[:, None])
    assert narrowing > 0.8 and np.abs(M).max() < 1e-3, (narrowing, M)
    share = MapShiftShare()
    share.respond(M)
    assert np.abs(share.A).max() < 1e-3
    assert particle_mean_response(x[:1], [1.0], [1.0], [[0.0]], [[0.0]]) is None     # no spread: None


def test_share_gain_is_clipped_where_a_posterior_widens():
    share = MapShiftShare(np.array([0.5, 0.5]))
    share.terrain(np.diag([100.0, 100.0]), np.diag([150.0, 25.0]))     # north widened: k = 0, east: 0.75
    assert share.share[0] == 0.5 and share.share[1] == pytest.approx(0.875)
    share.gnss(np.diag([np.nan, 100.0]), np.diag([10.0, 0.0]))         # not finite: kept; k = 1: none left
    assert share.share[0] == 0.5 and share.share[1] == 0.0


def _terrain_m(n_m, e_m):
    """Curved terrain (m) at north/east metres from (LAT0, LON0): informative along both axes."""
    return (400.0 + 60.0 * np.sin(2 * np.pi * n_m / 1500.0) + 60.0 * np.sin(2 * np.pi * e_m / 1700.0 + 0.7)
            + 30.0 * np.sin(2 * np.pi * (n_m + e_m) / 900.0))


def _dem(shift_n_m: float, shift_e_m: float) -> Dem:
    """1" posts of the terrain, shifted: a feature at p appears at p + shift (terrain.map_error)."""
    d = math.radians(1.0 / 3600.0)
    n = 600
    lat = LAT0 + (np.arange(n) - n / 3) * d
    lon = LON0 + (np.arange(n) - n / 2) * d
    r_lat, r_lon = radii_m(LAT0, H_ANT)
    dn = (lat[:, None] - LAT0) * r_lat - shift_n_m
    de = (lon[None, :] - LON0) * r_lon - shift_e_m
    return Dem(_terrain_m(dn, de), lat[0], lon[0], d, d, "waves")


def _ins(t_s: float) -> np.ndarray:
    r_lat, _ = radii_m(LAT0, H_ANT)
    st = np.empty(10)
    st[:3] = (LAT0 + SPEED * t_s / r_lat, LON0, H_ANT)
    st[3:6] = (SPEED, 0.0, 0.0)
    st[6:] = quat_from_C_bn(euler_to_C_bn(0.0, 0.0, 0.0))
    return st


def _horizontal_nees(kind: str, seed: int, runs: int, gnss_fixes: int, modelled: bool) -> float:
    """Sum over runs of the published horizontal NEES after 25 1 Hz IRA samples looking straight down
    (3.5 m) and then `gnss_fixes` 1 Hz GNSS fixes (2 m), the map shifted by s ~ N(0, SIGMA_H^2) per axis,
    the INS's error x ~ N(0, SIGMA_X0^2) per axis; `modelled`: the filter told the map's SIGMA_H."""
    rng = np.random.default_rng(seed)
    r_lat, r_lon = radii_m(LAT0, H_ANT)
    total = 0.0
    for r in range(runs):
        s = rng.normal(0.0, SIGMA_H, 2)
        x = rng.normal(0.0, SIGMA_X0, 2)                 # true position minus INS position (constant)
        the_map = _dem(*s)
        common = dict(outlier_prob=0.0, terrain_model_sigma_m=0.0, map_sigma_m=0.0, baro_bias_sigma_m=1.0,
                      ira_range_sigma_m=SIGMA_R, ira_look_angle_sigma_deg=0.1,
                      vertical_noise_m_per_sqrt_s=0.0, position_noise_m_per_sqrt_s=0.01,
                      velocity_noise_mps_per_sqrt_s=1e-6)
        nav = (PointMassFilter(the_map, grid_size=121, spacing_min_m=1.0, accel_bias_sigma_mps2=1e-7,
                               **common)
               if kind == "pmf" else
               ParticleFilter(the_map, n_particles=4000, rng=np.random.default_rng(seed * 100 + r),
                              heading_noise_rad_per_sqrt_s=0.0, **common))
        if kind == "pf":      # GNSS by its ensemble update, as in a scenario (its likelihood path keeps a
            nav.apply_imu_spec(imu_spec({"grade": "navigation"}))    # handful of particles from a wide cloud)
        configure(nav, map_horizontal_sigma_m=SIGMA_H if modelled else 0.0)
        cov = np.diag([SIGMA_X0**2, SIGMA_X0**2, 1.0, 1e-6, 1e-6, 1e-6, 1e-10, 1e-10, 1e-8])
        nav.reset(Estimate(0.0, LAT0, LON0, H_ANT, np.array([SPEED, 0.0, 0.0]), 0.0, 0.0, 0.0, cov))
        nav._predict_to(0.0, _ins(0.0))
        for i in range(25 + gnss_fixes):
            t = 1.0 + i
            st = _ins(t)
            nav._predict_to(t, st)
            if i >= 25:
                fix = (st[0] + (x[0] + rng.normal(0.0, 2.0)) / r_lat,      # the filters' gnss_sigma_m
                       st[1] + (x[1] + rng.normal(0.0, 2.0)) / r_lon, H_ANT + rng.normal(0.0, 4.0))
                nav._gnss_update(t, st, (*fix, np.array([SPEED, 0.0, 0.0])))
            else:
                n_true = SPEED * t + x[0]
                z = float(_terrain_m(n_true, x[1])) + rng.normal(0.0, SIGMA_R)
                nav._terrain_update(t, "ira", float(H_ANT - z), 0.0, st, None)
        est = nav.estimate()
        st = nav.ins.state        # the filter's own INS (these steps hand it the moving state, not the IMU)
        err = np.array([(est.lat_rad - st[0]) * r_lat - x[0], (est.lon_rad - st[1]) * r_lon - x[1]])
        total += float(err @ np.linalg.solve(est.covariance[:2, :2], err))
    return total


@pytest.mark.parametrize("kind", ["pmf", "pf"])
def test_published_position_carries_the_maps_horizontal_shift(kind):
    # 20 runs x 2 dof, with and without 5 GNSS fixes after the terrain samples: the NEES sum between the
    # chi-square(40) 0.1 % and 99.9 % quantiles with the shift's share published (after the fixes the
    # estimate is the GNSS's again, and a share kept from the terrain would put the sum far below); without
    # the share (the belief's covariance alone, a few m against the shift's 23 m) far above the upper one
    # (10 runs: chi-square(20))
    runs = 20
    lo, hi = chi2.ppf(0.001, 2 * runs), chi2.isf(0.001, 2 * runs)
    for gnss_fixes in (0, 5):
        nees = _horizontal_nees(kind, seed=11 + gnss_fixes, runs=runs, gnss_fixes=gnss_fixes, modelled=True)
        assert lo <= nees <= hi, (gnss_fixes, nees, lo, hi)
    unmodelled = _horizontal_nees(kind, seed=11, runs=10, gnss_fixes=0, modelled=False)
    assert unmodelled > 3.0 * chi2.isf(0.001, 20), unmodelled


def test_pmf_carries_the_share_in_its_velocity_model_and_publishes_it():
    # wiring of pmf's carried share: with a velocity prior wide enough for the regression to move u, terrain
    # samples give u a share (U), a prediction without samples moves the position's share by B U, and the
    # published covariance carries sigma_h^2 [A; U_v][A; U_v]' in its position and velocity blocks
    the_map = _dem(20.0, -10.0)
    nav = PointMassFilter(the_map, grid_size=121, spacing_min_m=1.0, outlier_prob=0.0,
                          terrain_model_sigma_m=0.0, map_sigma_m=0.0, baro_bias_sigma_m=1.0,
                          ira_range_sigma_m=SIGMA_R, ira_look_angle_sigma_deg=0.1,
                          vertical_noise_m_per_sqrt_s=0.0)
    configure(nav, map_horizontal_sigma_m=SIGMA_H)
    cov = np.diag([SIGMA_X0**2, SIGMA_X0**2, 1.0, 0.5**2, 0.5**2, 1e-6, 1e-10, 1e-10, 1e-8])
    nav.reset(Estimate(0.0, LAT0, LON0, H_ANT, np.array([SPEED, 0.0, 0.0]), 0.0, 0.0, 0.0, cov))
    nav._predict_to(0.0, _ins(0.0))
    for i in range(15):
        t = 1.0 + i
        st = _ins(t)
        nav._predict_to(t, st)
        z = float(_terrain_m(SPEED * t, 0.0))
        nav._terrain_update(t, "ira", float(H_ANT - z), 0.0, st, None)
    share = nav._map_shift
    assert np.abs(share.U[:2]).max() > 0.003, share.U          # the velocity offset took part of the shift
    A0, U0 = share.A.copy(), share.U.copy()
    nav._predict_to(25.0, _ins(25.0))                          # 9 s without samples: x += v dt ...
    assert np.abs(share.A - A0).max() > 0.03 and np.abs(share.A - A0 - 9.0 * U0[:2]).max() < 0.2 * np.abs(
        9.0 * U0[:2]).max() + 1e-9, (share.A - A0, U0[:2])
    est = nav.estimate()
    c_ux, c_uu = share.carried_covariances(SIGMA_H)
    belief = nav._moments()[1]
    assert est.covariance[3:5, 3:5] - belief[3:5, 3:5] == pytest.approx(c_uu[:2, :2], rel=1e-6, abs=1e-9)
    assert est.covariance[3:5, :2] - belief[3:5, :2] == pytest.approx(c_ux[:2], rel=1e-6, abs=1e-9)


def test_rbpf_publishes_the_share_its_mean_took_on():
    # wiring of rbpf's share: over a DTED-1 map (map_horizontal_sigma_m from the class) its IRA updates give
    # the mean a share of the shift, and the published horizontal covariance is the cloud's plus
    # sigma_h^2 A A'; the GNSS fixes before 10 s restarted it each time
    from trn_env.navigators.filters import rbpf as rbpf_module

    from trn_env.scenario.loading import load_scenario, validate
    from trn_env.sim.closed_loop import ClosedLoop
    seen = []
    original = rbpf_module.RaoBlackwellizedPF._gnss_cloud_update

    def spy(self, y):
        seen.append(self._map_shift.share.copy())
        original(self, y)
        assert not self._map_shift.any()
    d = load_scenario("default", seed=1, navigator="rbpf", duration_s=30.0).to_dict()
    d["terrain"]["map"]["error_model"] = {"preset": "dted1"}
    loop = ClosedLoop(validate(d, source="test"), pipeline=False)
    rbpf_module.RaoBlackwellizedPF._gnss_cloud_update = spy
    try:
        loop.run()
    finally:
        rbpf_module.RaoBlackwellizedPF._gnss_cloud_update = original
    nav = loop.navigator
    sigma = nav.map_horizontal_sigma_m
    assert sigma == pytest.approx(SIGMA_H, rel=0.01)
    assert any(np.any(s > 0.0) for s in seen)                  # terrain between fixes took a share
    assert np.max(nav._map_shift.share) > 0.02, nav._map_shift.share
    est = nav.estimate()
    assert est.covariance[:2, :2] - nav._cov9[:2, :2] == pytest.approx(nav._map_shift.covariance(sigma),
                                                                       rel=1e-9, abs=1e-9)
