"""The pursuit action's offset limit near the goal (trn_env.env.task.bearing_offset_limit_rad) flown by an
independent kinematic integration: a point that holds its ground track at the limited offset from the goal's
bearing never has to turn faster than omega, and reaches the goal; the law before it (asin(d omega / v))
needed twice omega. The route-information paths step along the same limit, and the fast tier's guidance
kernel (its own copy) flies a held offset into the arrival circle, which it does not with the law before;
the full env's limit is checked in tests/test_env_learning.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trn_env.env import task
from trn_env.env.route_info import pursuit_step

V_MPS = 85.0
OMEGA_RPS = math.radians(2.0)          # the route task's: 60 deg per 30 s decision


def _fly(limit, offset_max_rad: float, d0_m: float = 6000.0, dt_s: float = 0.02):
    """Integrate a point at V_MPS holding track = bearing + limit(d) (offset to the right) from d0_m south of
    the goal until 200 m from it (inside any arrival circle); returns (largest track rate rad/s, time s,
    closest distance m)."""
    x, y = 0.0, -d0_m                  # east, north; goal at the origin
    prev, rate_max, t = None, 0.0, 0.0
    while True:
        d = math.hypot(x, y)
        if d < 200.0 or t > 600.0:
            return rate_max, t, d
        track = math.atan2(-x, -y) + limit(d, offset_max_rad)
        if prev is not None:
            rate_max = max(rate_max, abs(math.remainder(track - prev, 2.0 * math.pi)) / dt_s)
        prev = track
        x += V_MPS * math.sin(track) * dt_s
        y += V_MPS * math.cos(track) * dt_s
        t += dt_s


def _law(d, offset_max):
    return float(task.bearing_offset_limit_rad(d, OMEGA_RPS, V_MPS, offset_max))


def _law_before(d, offset_max):
    return min(offset_max, math.asin(min(1.0, d * OMEGA_RPS / V_MPS)))


@pytest.mark.parametrize("offset_max_deg", [45.0, 60.0])
def test_held_offset_needs_no_more_than_omega_and_arrives(offset_max_deg):
    rate, t, d_end = _fly(_law, math.radians(offset_max_deg))
    assert d_end < 200.0 and t < 200.0
    assert rate <= OMEGA_RPS * 1.01
    rate_before, _, _ = _fly(_law_before, math.radians(offset_max_deg))
    assert rate_before == pytest.approx(2.0 * OMEGA_RPS, rel=0.03)


def test_limit_values_and_the_route_paths_use_it():
    d = np.array([0.0, 500.0, 2000.0, 3000.0, 1e5])
    lim = task.bearing_offset_limit_rad(d, OMEGA_RPS, V_MPS, math.radians(45.0))
    want = np.minimum(math.radians(45.0), np.arcsin(np.minimum(1.0, d * OMEGA_RPS / (2 * V_MPS))))
    assert np.array_equal(lim, want)
    # the route-information march steps along the same limited offset
    phi0 = math.radians(45.0)
    turn = (phi0, abs(math.sin(phi0)), math.cos(phi0), math.sin(phi0))
    for dist in (800.0, 2500.0, 6000.0):
        pn, pe, seg = pursuit_step(0.0, 0.0, dist, 0.0, turn, (100.0, OMEGA_RPS, V_MPS, 10.0))
        phi = math.atan2(pe, pn)
        assert seg == 10.0
        assert phi == pytest.approx(_law(dist, phi0), abs=1e-12)


def test_fast_tier_flies_a_held_offset_into_the_arrival_circle():
    """The fast tier's guidance kernel (its own copy of the limit) with the offset held at +1 from ~4 km
    south of the goal: every aircraft arrives within two decisions. With the law before, the final
    approach asks 4 deg/s of an aircraft that turns 3.2: it overshoots and circles the goal."""
    import gymnasium

    from trn_env.env.fast import calibration as cal

    route = cal.route_by_name("basin_round")
    kw = {**cal.env_kwargs(route), "max_episode_s": 150.0}
    env = gymnasium.make_vec("trn_env/TerrainNavFast-v0", num_envs=16,
                             vectorization_mode="vector_entry_point", **kw)
    start = (route.goal_deg[0] - 0.036, route.goal_deg[1])          # ~4.0 km south
    env.reset(seed=list(range(16)), options={"start_deg": start})
    ends = np.full(16, None, dtype=object)
    steps = np.zeros(16, int)
    for k in range(5):
        _, _, term, trunc, info = env.step(np.tile(np.array([1.0, 0.0], np.float32), (16, 1)))
        new = (term | trunc) & (ends == None)  # noqa: E711 - element-wise over an object array
        ends[new] = info["termination"][new]
        steps[new] = k + 1
    env.close()
    assert list(ends) == ["arrived"] * 16, ends
    assert steps.max() <= 2
