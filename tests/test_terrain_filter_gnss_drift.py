"""The terrain filters' GNSS receiver drift (gnss_drift_sigma_m, navigators.filters.terrain_filter): fixes
that share one drift cannot narrow the belief below it. Checked by the normalised estimation error squared
over independent runs whose fixes carry a drawn drift plus white noise (a chi-square bound computed here),
with the old white-fix model (drift 0) as the case that fails it, for pmf, pf and the rbpf's floor
(gnss_pos_bias_sigma_m); and the scenario builder filling the settings from the GNSS sensor."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2
from test_terrain_filter_linear import COMMON, H_ANT, LAT0, LON0, initial, ins_state, planar_dem
from trn_env.navigators.filters.pf import ParticleFilter
from trn_env.navigators.filters.pmf import PointMassFilter
from trn_env.navigators.measurements.terrain_models import radii_m

SIGMA_D, SIGMA_W, FIXES, RUNS = 1.5, 1.0, 20, 40


def _horizontal_nees(kind: str, drift_sigma_m: float, seed: int) -> float:
    """Sum over RUNS independent runs of e' P^-1 e (north/east, m) after FIXES GNSS fixes, each run's fixes
    the truth plus one drift N(0, SIGMA_D^2) per axis plus white N(0, SIGMA_W^2); the filter assumes 2 m
    white noise (its default gnss_sigma_m) and the given drift."""
    dem = planar_dem()
    rng = np.random.default_rng(seed)
    r_lat, r_lon = radii_m(LAT0, H_ANT)
    total = 0.0
    for k in range(RUNS):
        kw = dict(COMMON, gnss_drift_sigma_m=drift_sigma_m, position_noise_m_per_sqrt_s=0.01)
        if kind == "pmf":
            nav = PointMassFilter(dem, grid_size=81, **kw)
        else:
            nav = ParticleFilter(dem, rng=np.random.default_rng(seed * 100 + k), n_particles=4000, **kw)
        nav.reset(initial(10.0))
        true_ne = rng.normal(0.0, 10.0, 2)           # the truth about the INS, drawn from the prior
        drift = rng.normal(0.0, SIGMA_D, 2)
        st = ins_state()
        for i in range(FIXES):
            t = 1.0 + i
            nav._predict_to(t, st)
            fix = true_ne + drift + rng.normal(0.0, SIGMA_W, 2)
            nav._gnss_update(t, st, (LAT0 + fix[0] / r_lat, LON0 + fix[1] / r_lon, H_ANT,
                                     np.array([80.0, 0.0, 0.0])))
        est = nav.estimate()
        e = np.array([(est.lat_rad - LAT0) * r_lat - true_ne[0], (est.lon_rad - LON0) * r_lon - true_ne[1]])
        total += float(e @ np.linalg.solve(est.covariance[:2, :2], e))
    return total


@pytest.mark.parametrize("kind", ["pmf", "pf"])
def test_gnss_drift_keeps_the_belief_consistent(kind):
    # 40 runs x 2 dof: with the drift modelled the NEES sum lies below the 99.9 % chi-square(80) quantile
    # (the floor max(sigma_d^2, white posterior) is below the exact sigma_d^2 + sigma_w^2 / N by at most
    # sigma_w^2 / N: the bound at 1.03 x the quantile covers it); with fixes taken as white (drift 0) the
    # belief shrinks to ~2 / sqrt(20) m and the NEES sum exceeds the quantile: the cause of the misleading
    # epochs at GNSS loss (docs/validation/integrity.md section 6)
    q = chi2.isf(0.001, 2 * RUNS)
    assert _horizontal_nees(kind, SIGMA_D, seed=5) <= 1.03 * q
    assert _horizontal_nees(kind, 0.0, seed=5) > q


def _rbpf_horizontal_nees(bias_sigma_m: float, seed: int) -> float:
    """As _horizontal_nees for the rbpf's GNSS position update (rbpf_cloud._gnss_cloud_update, the cloud moved
    onto the Kalman posterior of its moments): RUNS independent runs, each a cloud drawn from the prior
    N(0, 10^2) per axis, a true offset drawn from it, FIXES fixes of it plus one drift N(0, SIGMA_D^2) per
    axis plus white N(0, SIGMA_W^2); the filter assumes SIGMA_W white (gnss_pos_sigma_m) and the given drift
    (gnss_pos_bias_sigma_m). NEES of the cloud's weighted mean against its weighted covariance."""
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
    dem = planar_dem()
    rng = np.random.default_rng(seed)
    total = 0.0
    for k in range(RUNS):
        nav = RaoBlackwellizedPF(dem, rng=np.random.default_rng(seed * 100 + k), n_particles=4000,
                                 acquisition_particles=0, gnss_pos_sigma_m=(SIGMA_W, 2.0),
                                 gnss_pos_bias_sigma_m=(bias_sigma_m, 3.0),
                                 init_pos_sigma_m=(10.0, 10.0, 5.0), prior_from_initial=False)
        nav.reset(initial(10.0))
        true_ne = rng.normal(0.0, 10.0, 2)
        drift = rng.normal(0.0, SIGMA_D, 2)
        for _ in range(FIXES):
            fix = true_ne + drift + rng.normal(0.0, SIGMA_W, 2)
            nav._gnss_cloud_update(np.array([fix[0], fix[1], 0.0]))
        w = nav._weights()
        m = w @ nav.xn[:, :2]
        d = nav.xn[:, :2] - m
        P = (d * w[:, None]).T @ d
        e = m - true_ne
        total += float(e @ np.linalg.solve(P, e))
    return total


def test_rbpf_gnss_drift_floor_keeps_the_cloud_consistent():
    # the same bound as the pmf / pf test: with the receiver's drift as the floor the NEES sum over 40 runs
    # (2 dof each) lies below the 99.9 % chi-square(80) quantile (x 1.03, the floor against the exact
    # sigma_d^2 + sigma_w^2 / N); without it (fixes white) it exceeds the quantile
    q = chi2.isf(0.001, 2 * RUNS)
    assert _rbpf_horizontal_nees(SIGMA_D, seed=5) <= 1.03 * q
    assert _rbpf_horizontal_nees(0.0, seed=5) > q


def test_builder_fills_gnss_drift_from_the_sensor():
    from trn_env.scenario.build import navigator_settings
    from trn_env.scenario.loading import read_scenario_file, validate
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    data["sensors"]["gnss"] = {"horizontal_drift_m": 2.5}
    for name, expect in (("pmf", 2.5), ("pf", 2.5)):
        data["navigator"] = {"name": name, "settings": {}}
        sc = validate(data, source="test")
        assert navigator_settings(sc, None)["gnss_drift_sigma_m"] == pytest.approx(expect)
    data["navigator"] = {"name": "pmf", "settings": {"gnss_drift_sigma_m": 0.5}}
    assert navigator_settings(validate(data, source="test"), None)["gnss_drift_sigma_m"] == 0.5
    data["sensors"]["gnss"] = {"horizontal_drift_m": 2.5, "vertical_drift_m": 4.5}
    data["navigator"] = {"name": "rbpf", "settings": {}}
    got = navigator_settings(validate(data, source="test"), None)["gnss_pos_bias_sigma_m"]
    assert tuple(got) == pytest.approx((2.5, 4.5))
    data["navigator"] = {"name": "acq_track", "settings": {}}
    assert "gnss_drift_sigma_m" not in navigator_settings(validate(data, source="test"), None)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "x"])
def test_bad_gnss_drift_named(bad):
    with pytest.raises(ValueError, match="gnss_drift_sigma_m"):
        PointMassFilter(planar_dem(), grid_size=41, gnss_drift_sigma_m=bad)
    assert math.isfinite(SIGMA_D)
