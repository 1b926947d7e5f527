"""The planner's climb constraint (on by default): over a steep ridge with a gap, the planned route keeps to
the King Air's climb gradient, checked on the terrain profile sampled along the route from the DEM here;
without the constraint the same planner flies straight over the ridge."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import latlon_to_ned_offset, ned_offset_to_latlon

from trn_env.guidance.planner import PlannerConfig, TerrainInformationPlanner

LAT0, LON0 = math.radians(36.4), math.radians(-84.3)
SPACING_M = 100.0
N = 201                                   # 20 x 20 km
R_E = 6_371_000.0


def _ridge_dem() -> Dem:
    """Rolling hills (informative everywhere) and an east-west ridge 900 m high, 1.5 km e-folding half-width,
    at 10 km north, that tapers to nothing between 13 and 17 km east: a gap at the east end."""
    n = np.arange(N) * SPACING_M
    e = np.arange(N) * SPACING_M
    nn, ee = np.meshgrid(n, e, indexing="ij")
    rng = np.random.default_rng(5)
    hills = np.zeros((N, N))
    for _ in range(40):      # smooth bumps of 30 m, so the map is informative but gentle (slopes < 0.03)
        cn, ce = rng.uniform(0, 20000, 2)
        hills += 30.0 * np.exp(-((nn - cn) ** 2 + (ee - ce) ** 2) / (2 * 1200.0**2))
    height = np.clip((17000.0 - ee) / 4000.0, 0.0, 1.0) * 900.0
    ridge = height * np.exp(-(((nn - 10000.0) / 1500.0) ** 2))
    dlat = SPACING_M / R_E
    dlon = SPACING_M / (R_E * math.cos(LAT0))
    return Dem(300.0 + hills + ridge, LAT0, LON0, dlat, dlon, name="ridge")


def _profile_gradient(dem: Dem, waypoints_deg, window_m: float) -> float:
    """Largest rise / distance of the ground under the route between two points `window_m` apart (ground
    sampled every 20 m along the legs from the DEM)."""
    w = np.radians(np.array([(a, b) for a, b, _ in waypoints_deg]))
    hs = []
    for (a0, b0), (a1, b1) in zip(w[:-1], w[1:], strict=True):
        dn, de = latlon_to_ned_offset(a0, b0, 0.0, a1, b1)
        k = max(2, int(math.hypot(dn, de) / 20.0))
        f = np.arange(k) / k
        la, lo = ned_offset_to_latlon(a0, b0, 0.0, f * dn, f * de)
        hs.append(dem.height(la, lo))
    h = np.concatenate(hs)
    step = int(window_m / 20.0)
    return float(np.max((h[step:] - h[:-step]) / window_m))


@pytest.fixture(scope="module")
def dem():
    return _ridge_dem()


def _endpoints():
    s = ned_offset_to_latlon(LAT0, LON0, 0.0, 3000.0, 8000.0)
    g = ned_offset_to_latlon(LAT0, LON0, 0.0, 17000.0, 8000.0)
    return (*s, *g)


def test_default_config_limits_the_climb_to_the_king_airs_gradient():
    c = PlannerConfig()
    # 5 m/s at 85 m/s: below the King Air's 7.5 m/s autopilot climb limit and its 9.9 m/s POH sea-level rate
    assert c.climb_gradient == pytest.approx(5.0 / 85.0)
    assert c.climb_gradient < 7.5 / c.tas_mps < 9.9 / c.tas_mps
    assert PlannerConfig(climb_rate_mps=None).climb_gradient is None
    assert PlannerConfig(climb_gradient_max=0.1).climb_gradient == 0.1
    with pytest.raises(ValueError, match="climb_rate_mps"):
        PlannerConfig(climb_rate_mps=-1.0)


def test_route_over_a_steep_ridge_keeps_the_climb_gradient(dem):
    on = TerrainInformationPlanner(dem, PlannerConfig(weight=1.0, agl_m=600.0))
    off = TerrainInformationPlanner(dem, PlannerConfig(weight=1.0, agl_m=600.0, climb_rate_mps=None))
    r_on, r_off = on.plan(*_endpoints()), off.plan(*_endpoints())
    gamma = PlannerConfig().climb_gradient
    # the terrain needs the constraint: without it the route crosses the ridge (slopes ~0.5)
    assert _profile_gradient(dem, r_off.waypoints_deg, 1000.0) > 5 * gamma
    assert r_off.extra_distance_fraction < 0.05
    # with it the route goes round through the gap; over any km of it the ground rises by at most the
    # climb gradient plus a quarter (the search holds 500 m cell means to it; the DEM is sampled here)
    for window_m in (1000.0, 2000.0, 4000.0):
        assert _profile_gradient(dem, r_on.waypoints_deg, window_m) <= 1.25 * gamma, window_m
    # the gap is at >= 13 km east: the route must pass there (north 10 km +- 2 km)
    w = np.radians(np.array([(a, b) for a, b, _ in r_on.waypoints_deg]))
    east_km = [latlon_to_ned_offset(LAT0, LON0, 0.0, a, b)[1] / 1000.0 for a, b in w]
    assert max(east_km) > 13.0
    assert 0.2 < r_on.extra_distance_fraction < 0.8
