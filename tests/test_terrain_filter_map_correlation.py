"""The terrain filters' model of a map error correlated along the ground (map_correlation_length_m,
navigators.filters.terrain_filter): the random walk's rate against the structure function computed here,
the PMF against a Kalman filter carrying the same walk in the vertical offset, consistency (NEES against a
chi-square bound computed here) over runs whose map error is drawn as the exponential Gauss-Markov field it
is, with the white model as the case that fails it; a GNSS height leaves the map's part of the offset; the
scenario builder fills the settings from the map error model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2
from test_terrain_filter_linear import G_E, G_N, H0, H_ANT, LAT0, LON0, SIGMA_R, ins_state, planar_dem
from trn_env.navigators.filters.pf import ParticleFilter
from trn_env.navigators.filters.pmf import PointMassFilter
from trn_env.navigators.filters.terrain_filter import map_walk_variance_per_m
from trn_env.navigators.measurements.terrain_models import radii_m
from trn_env.navigators.protocol import Estimate

SIGMA_MAP, L_MAP, SIGMA_BARO, SPEED = 10.0, 1070.0, 3.0, 80.0   # ins_state() flies north at 80 m/s
COMMON = dict(outlier_prob=0.0, terrain_model_sigma_m=0.0, ira_range_sigma_m=SIGMA_R,
              ira_look_angle_sigma_deg=0.1, baro_bias_sigma_m=SIGMA_BARO, vertical_noise_m_per_sqrt_s=0.0,
              position_noise_m_per_sqrt_s=0.01, map_sigma_m=SIGMA_MAP)


def _initial(sig_h: float) -> Estimate:
    cov = np.diag([sig_h**2, sig_h**2, 1.0, 1e-6, 1e-6, 1e-6, 1e-10, 1e-10, 1e-8])
    return Estimate(0.0, LAT0, LON0, H_ANT, np.array([SPEED, 0.0, 0.0]), 0.0, 0.0, 0.0, cov)


@pytest.mark.parametrize("function", ["exponential", "gaussian"])
def test_walk_rate_covers_the_structure_function(function):
    # q d >= 2 sigma^2 (1 - rho(d / L)) at every distance, and touches it (the smallest such rate)
    d = np.linspace(1.0, 20.0 * L_MAP, 200_000)
    x = d / L_MAP
    rho = np.exp(-x) if function == "exponential" else np.exp(-0.5 * x * x)
    q = map_walk_variance_per_m(SIGMA_MAP, L_MAP, function)
    ratio = 2.0 * SIGMA_MAP**2 * (1.0 - rho) / (q * d)
    assert ratio.max() <= 1.0 + 1e-9
    assert ratio.max() >= 0.999
    assert map_walk_variance_per_m(SIGMA_MAP, 0.0) == 0.0 and map_walk_variance_per_m(0.0, L_MAP) == 0.0


def test_pmf_carries_the_correlated_map_error_as_the_kalman_filter_does():
    # planar terrain, IRA straight down (linear in dn, de, b); the PMF with the correlated map model against a
    # 3-state Kalman filter whose b walks by q_map * speed * dt and starts at baro^2 + map^2, samples' noise
    # the sensor's only
    dem = planar_dem()
    nav = PointMassFilter(dem, grid_size=241, spacing_min_m=0.2, span_sigmas=4.5,
                          map_correlation_length_m=L_MAP, velocity_noise_mps_per_sqrt_s=1e-6,
                          accel_bias_sigma_mps2=1e-7, **COMMON)
    nav.reset(_initial(40.0))
    q_b = map_walk_variance_per_m(SIGMA_MAP, L_MAP) * SPEED * 1.0
    k = KalmanFilter(dim_x=3, dim_z=1)
    k.x = np.zeros((3, 1))
    k.P = np.diag([40.0**2, 40.0**2, SIGMA_BARO**2 + SIGMA_MAP**2])
    k.Q = np.diag([0.01**2, 0.01**2, q_b])
    k.R = np.array([[SIGMA_R**2]])
    k.H = np.array([[G_N, G_E, 1.0]])
    rng = np.random.default_rng(3)
    st = ins_state()
    nav._predict_to(0.0, st)
    for i in range(25):
        t = 1.0 + i
        nav._predict_to(t, st)
        k.predict()
        z = H0 + G_N * 20.0 - G_E * 10.0 + rng.normal(0.0, 6.0)
        nav._terrain_update(t, "ira", float(H_ANT - z), 0.0, st, None)
        k.update(np.array([[z - H0]]))
    mean, cov = nav._moments()
    xk, Pk = k.x.ravel(), k.P
    sig = np.sqrt(np.diag(Pk))
    assert np.all(np.abs(mean[:3] - xk) < 0.02 * sig), (mean[:3], xk, sig)
    np.testing.assert_allclose(np.diag(cov)[:3], np.diag(Pk), rtol=0.02)


def _nees(kind: str, correlation_length_m: float, seed: int, runs: int, samples: int) -> float:
    """Sum over `runs` independent runs of the horizontal NEES after `samples` 1 Hz IRA samples over planar
    terrain whose map error along the flown line is the exponential Gauss-Markov field of sigma SIGMA_MAP,
    correlation length L_MAP (AR(1) over the 80 m between samples, stationary start), the baro bias drawn
    from its prior and the true offset from the filter's; the filter assumes the given correlation length
    (0: the map error white per sample)."""
    dem = planar_dem()
    rng = np.random.default_rng(seed)
    rho = math.exp(-SPEED / L_MAP)
    total = 0.0
    for r in range(runs):
        kw = dict(COMMON, map_correlation_length_m=correlation_length_m)
        if kind == "pmf":
            nav = PointMassFilter(dem, grid_size=121, spacing_min_m=0.5, velocity_noise_mps_per_sqrt_s=1e-6,
                                  accel_bias_sigma_mps2=1e-7, **kw)
        else:
            nav = ParticleFilter(dem, n_particles=4000, rng=np.random.default_rng(seed * 100 + r),
                                 velocity_noise_mps_per_sqrt_s=1e-6, heading_noise_rad_per_sqrt_s=0.0, **kw)
        nav.reset(_initial(40.0))
        x_true = rng.normal(0.0, 40.0, 2)
        b = rng.normal(0.0, SIGMA_BARO)
        e = rng.normal(0.0, SIGMA_MAP)
        st = ins_state()
        nav._predict_to(0.0, st)
        for i in range(samples):
            t = 1.0 + i
            nav._predict_to(t, st)
            # measured terrain height h_INS - R = truth's terrain + b; the map reads its terrain + e
            z = H0 + G_N * x_true[0] + G_E * x_true[1] + b - e + rng.normal(0.0, SIGMA_R)
            nav._terrain_update(t, "ira", float(H_ANT - z), 0.0, st, None)
            e = rho * e + math.sqrt(1.0 - rho * rho) * SIGMA_MAP * rng.standard_normal()
        est = nav.estimate()
        r_lat, r_lon = radii_m(LAT0, H_ANT)
        err = np.array([(est.lat_rad - LAT0) * r_lat - x_true[0], (est.lon_rad - LON0) * r_lon - x_true[1]])
        total += float(err @ np.linalg.solve(est.covariance[:2, :2], err))
    return total


@pytest.mark.parametrize("kind", ["pmf", "pf"])
def test_correlated_map_model_keeps_the_position_consistent(kind):
    # 30 runs x 2 dof: with the correlation modelled the NEES sum lies below the 99.9 % chi-square(60)
    # quantile (the walk covers the Gauss-Markov error: conservative); with the map error taken as white per
    # sample the 25 samples average it down by 5 where the correlated error's mean hardly shrinks, and the
    # NEES sum exceeds the quantile
    runs = 30
    q = chi2.isf(0.001, 2 * runs)
    assert _nees(kind, L_MAP, seed=11, runs=runs, samples=25) <= q
    assert _nees(kind, 0.0, seed=11, runs=runs, samples=25) > q


def _vertical_nees(kind: str, seed: int, runs: int, samples: int, gnss_samples: int, bias_m: float) -> float:
    """Sum over runs of the published height's NEES after `gnss_samples` GNSS fixes (4 m vertical) then
    `samples` 1 Hz IRA samples over planar terrain; the map's vertical error is a bias drawn from
    N(0, bias_m^2) plus the exponential Gauss-Markov field of _nees, the INS height's error drawn from the
    baro prior. The height's error is b_ins - b_hat (the estimate's height minus the truth's)."""
    dem = planar_dem()
    rng = np.random.default_rng(seed)
    rho = math.exp(-SPEED / L_MAP)
    total = 0.0
    for r in range(runs):
        kw = dict(COMMON, map_correlation_length_m=L_MAP, map_bias_sigma_m=bias_m)
        nav = (PointMassFilter(dem, grid_size=121, spacing_min_m=0.5, velocity_noise_mps_per_sqrt_s=1e-6,
                               accel_bias_sigma_mps2=1e-7, **kw) if kind == "pmf"
               else ParticleFilter(dem, n_particles=4000, rng=np.random.default_rng(seed * 100 + r),
                                   velocity_noise_mps_per_sqrt_s=1e-6, heading_noise_rad_per_sqrt_s=0.0,
                                   **kw))
        nav.reset(_initial(10.0))
        x_true = rng.normal(0.0, 10.0, 2)
        b_ins = rng.normal(0.0, SIGMA_BARO)
        m = rng.normal(0.0, bias_m) + rng.normal(0.0, SIGMA_MAP)      # the map's bias + correlated error
        m_corr = m
        st = ins_state()
        r_lat, r_lon = radii_m(LAT0, H_ANT)
        nav._predict_to(0.0, st)
        t = 0.0
        for i in range(gnss_samples + samples):
            t = 1.0 + i
            nav._predict_to(t, st)
            if i < gnss_samples:
                fix = (LAT0 + (x_true[0] + rng.normal(0.0, 2.0)) / r_lat,
                       LON0 + (x_true[1] + rng.normal(0.0, 2.0)) / r_lon,
                       H_ANT - b_ins + rng.normal(0.0, 4.0))
                nav._gnss_update(t, st, (*fix, np.array([SPEED, 0.0, 0.0])))
            else:
                z = H0 + G_N * x_true[0] + G_E * x_true[1] + b_ins - m + rng.normal(0.0, SIGMA_R)
                nav._terrain_update(t, "ira", float(H_ANT - z), 0.0, st, None)
            step = rho * m_corr + math.sqrt(1.0 - rho * rho) * SIGMA_MAP * rng.standard_normal()
            m, m_corr = m - m_corr + step, step
        est = nav.estimate()
        err = est.h_m - (H_ANT - b_ins)
        total += err * err / float(est.covariance[2, 2])
    return total


@pytest.mark.parametrize("kind", ["pmf", "pf"])
def test_published_height_carries_the_maps_vertical_error(kind):
    # 40 runs x 1 dof: terrain samples pin the offset b = INS error + map error, so the height keeps the
    # map's bias and correlated error; the published variance covers them (height_error): the NEES sum lies
    # between the chi-square(40) 0.1 % and 99.9 % quantiles, after GNSS fixes and without them (P_b alone,
    # a few m^2 after 25 samples, put it at ~10 x the upper quantile)
    runs = 40
    lo, hi = chi2.ppf(0.001, runs), chi2.isf(0.001, runs)
    for gnss_samples in (0, 5):
        nees = _vertical_nees(kind, seed=5 + gnss_samples, runs=runs, samples=25, gnss_samples=gnss_samples,
                              bias_m=7.0)
        assert lo <= nees <= hi, (gnss_samples, nees, lo, hi)


@pytest.mark.parametrize("kind", ["pmf", "pf"])
def test_gnss_height_leaves_the_maps_part_of_the_offset(kind):
    # b = INS height error + map error; 20 GNSS heights (4 m) see the first only: the exact two-state
    # posterior variance is P_h' + P_m >= P_m = map bias^2 + correlated map sigma^2
    dem = planar_dem()
    r_lat, r_lon = radii_m(LAT0, H_ANT)
    for bias, corr in ((7.0, 0.0), (7.0, L_MAP), (0.0, 0.0)):
        kw = dict(COMMON, map_bias_sigma_m=bias, map_correlation_length_m=corr)
        nav = (PointMassFilter(dem, grid_size=61, **kw) if kind == "pmf"
               else ParticleFilter(dem, n_particles=2000, rng=np.random.default_rng(1), **kw))
        nav.reset(_initial(10.0))
        st = ins_state()
        for i in range(20):
            nav._predict_to(1.0 + i, st)
            nav._gnss_update(1.0 + i, st, (LAT0, LON0, H_ANT, np.array([SPEED, 0.0, 0.0])))
        p_m = bias**2 + (SIGMA_MAP**2 if corr > 0.0 else 0.0)
        # the INS part through 20 fixes of 4 m: a scalar Kalman recursion; the correlated map's walk over
        # each second (w) is counted to the part the fix sees (conservative: the map's own part stays at its
        # stationary variance), so with it the INS part settles where P = (P + w) r / (P + w + r)
        w = map_walk_variance_per_m(SIGMA_MAP, corr) * SPEED * 1.0
        p_h = SIGMA_BARO**2
        for _ in range(20):
            p_h = (p_h + w) * 16.0 / (p_h + w + 16.0)
        assert nav.P_b == pytest.approx(p_m + p_h, rel=1e-6), (bias, corr)
        assert math.isfinite(r_lat + r_lon)


def test_builder_fills_the_map_correlation():
    from trn_env.scenario.build import navigator_settings
    from trn_env.scenario.loading import read_scenario_file, validate
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    data["terrain"]["map"] = {"dem": "jacksboro", "error_model": {"preset": "dted1"}}
    for name in ("pmf", "pf"):
        data["navigator"] = {"name": name, "settings": {}}
        s = navigator_settings(validate(data, source="test"), None)
        assert s["map_correlation_length_m"] == pytest.approx(1070.0)
        assert s["map_correlation_function"] == "exponential"
    data["terrain"]["map"] = {"dem": "jacksboro", "error_model": {"preset": "dted1", "bias_fraction": 1.0}}
    assert "map_correlation_length_m" not in navigator_settings(validate(data, source="test"), None)
    data["terrain"]["map"] = {"dem": "jacksboro"}
    assert "map_correlation_length_m" not in navigator_settings(validate(data, source="test"), None)
    data["navigator"] = {"name": "rbpf", "settings": {}}      # for its published height's error
    data["terrain"]["map"] = {"dem": "jacksboro", "error_model": {"preset": "dted1"}}
    assert navigator_settings(validate(data, source="test"), None)["map_correlation_length_m"] == 1070.0


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_bad_map_correlation_named(bad):
    with pytest.raises(ValueError, match="map_correlation_length_m"):
        PointMassFilter(planar_dem(), grid_size=41, map_correlation_length_m=bad)
    with pytest.raises(ValueError, match="map_correlation_function"):
        PointMassFilter(planar_dem(), grid_size=41, map_correlation_function="spherical")


@pytest.mark.slow
def test_rbpf_published_height_carries_the_maps_vertical_error():
    # 8 flights of the default route over a DTED-1 map (each seed its own map error), GNSS lost at 10 s: the
    # final height's NEES summed over the flights lies inside the chi-square(8) 0.1 % .. 99.9 % band; the
    # cloud's own height spread (2.9 m against a 13 m error, the map's) put the sum near 160. The final
    # horizontal NEES likewise inside the chi-square(16) band with the map shift's share in the published
    # covariance (map_shift.particle_mean_response): a share taken from the cloud's narrowing instead put
    # the sum at 2.6, below it (docs/validation/integrity.md, section 7.1)
    from trn_env.sim import run_scenario
    total, total_h = 0.0, 0.0
    for seed in range(8):
        r = run_scenario("default", seed=seed, navigator="rbpf", duration_s=60.0,
                         sets={"terrain.map.error_model": {"preset": "dted1"}})
        e_down, var_down = r.arrays["err_ned_m"][-1, 2], r.arrays["est_cov_diag"][-1, 2]
        total += float(e_down * e_down / var_down)
        e_h, cov_h = r.arrays["err_ned_m"][-1, :2], r.arrays["est_cov"][-1, :2, :2]
        total_h += float(e_h @ np.linalg.solve(cov_h, e_h))
    assert chi2.ppf(0.001, 8) <= total <= chi2.isf(0.001, 8), total
    assert chi2.ppf(0.001, 16) <= total_h <= chi2.isf(0.001, 16), total_h
