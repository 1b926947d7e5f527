"""The RBPF's map errors once GNSS no longer pins its height (RaoBlackwellizedPF._map_release, the opt-in
map_error_in_height): the map's bias and correlated vertical error leave the IRA's measurement noise and
enter the cloud's up coordinate, widened once by their variances and then walking with the correlated
error's rate over the ground flown (the rate computed here from the exponential structure function); a
white map error stays noise; without a map error model, or without the opt-in, nothing changes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
from trn_env.navigators.measurements import ira_seed002 as ira_model
from trn_env.navigators.protocol import Estimate

from trn_env import terrain

SIGMA_MAP, BIAS, L_MAP, SPEED = 12.9, 6.0, 1070.0, 100.0


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _nav(dem, **kw) -> RaoBlackwellizedPF:
    kw.setdefault("map_error_in_height", True)
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(1), n_particles=100, acquisition_particles=0,
                             **kw)
    lat, lon = dem.center_rad
    cov = np.diag([25.0, 25.0, 4.0, 0.01, 0.01, 0.01, 1e-6, 1e-6, 1e-6])
    nav.reset(Estimate(0.0, lat, lon, 2500.0, np.array([SPEED, 0.0, 0.0]), 0.0, 0.0, 0.0, cov))
    return nav


def _fix(t: float):
    return (t, 0.0, 0.0, 0.0, np.zeros(3))


def _range_var(nav: RaoBlackwellizedPF, sigma_m: float) -> float:
    """The IRA range variance with the map's error sigma_m (m) as noise, computed from the model."""
    return float(nav.r_var[0] + ira_model.map_noise_variances(sigma_m, nav.terrain_model_sigma_m, 2000.0,
                                                              nav.terrain_factors(2000.0))[0])


def test_release_after_gnss_then_walk(dem):
    nav = _nav(dem, map_sigma_m=SIGMA_MAP, map_bias_sigma_m=BIAS, map_correlation_length_m=L_MAP)
    both = math.hypot(SIGMA_MAP, BIAS)
    for k in range(5):                                   # fixes at 1 Hz: the map's errors are noise
        assert nav._map_release(1.0 + k, _fix(1.0 + k)) == 0.0
        assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, both))
    assert nav._map_release(6.0, None) == 0.0            # one epoch without a fix: still held (1.5 s)
    assert not nav._map_released
    q = nav._map_release(7.0, None)                      # 2 s since the last fix: released
    assert q == pytest.approx(SIGMA_MAP**2 + BIAS**2)
    assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, 0.0))
    # then a walk: exponential structure function 2 sigma^2 (1 - exp(-d / L)) <= q d, q = 2 sigma^2 / L
    speed = math.hypot(*nav.ins.state[3:5])
    assert nav._map_release(9.0, None) == pytest.approx(2.0 * SIGMA_MAP**2 / L_MAP * speed * 2.0)
    assert nav._map_release(10.0, _fix(10.0)) == 0.0     # a fix pins the height again
    assert not nav._map_released
    assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, both))


def test_hold_follows_the_fix_interval(dem):
    # fixes every 4 s: once two have set the interval, the epochs between them keep the map's errors as noise
    nav = _nav(dem, map_sigma_m=SIGMA_MAP, map_correlation_length_m=L_MAP)
    assert nav._map_release(-3.0, _fix(-3.0)) == 0.0
    for t in (1.0, 5.0, 9.0):
        assert nav._map_release(t, _fix(t)) == 0.0
        for dt in (1.0, 2.0, 3.0):
            assert nav._map_release(t + dt, None) == 0.0
    assert nav._map_release(16.0, None) == pytest.approx(SIGMA_MAP**2)     # 7 s > 1.5 x 4 s


def test_white_map_error_stays_noise(dem):
    # no correlation length: the random error averages over samples, only the bias moves into the cloud
    nav = _nav(dem, map_sigma_m=SIGMA_MAP, map_bias_sigma_m=BIAS)
    assert nav._map_release(0.0, None) == pytest.approx(BIAS**2)          # no fix since the start
    assert nav._map_release(1.0, None) == 0.0                             # a white error does not walk
    assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, SIGMA_MAP))


def test_no_map_error_model_changes_nothing(dem):
    nav = _nav(dem)
    assert [nav._map_release(t, None) for t in (0.0, 1.0, 5.0)] == [0.0, 0.0, 0.0]
    assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, 0.0))


def test_default_keeps_the_maps_errors_as_noise(dem):
    # without the opt-in: the random error is noise throughout, the bias only at an epoch with a fix
    nav = _nav(dem, map_sigma_m=SIGMA_MAP, map_bias_sigma_m=BIAS, map_correlation_length_m=L_MAP,
               map_error_in_height=False)
    assert [nav._map_release(t, None) for t in (0.0, 1.0, 5.0)] == [0.0, 0.0, 0.0]
    nav._gnss_now = False
    assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, SIGMA_MAP))
    nav._gnss_now = True
    assert nav._r_var_now(2000.0)[0] == pytest.approx(_range_var(nav, math.hypot(SIGMA_MAP, BIAS)))
