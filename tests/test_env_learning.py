"""TerrainNav-v0's learning aids: the normalised goal observations (19-21), the "bearing" action mode, the
potential-based shaping option and the bounds-scaled sb3 features; each against a computation made here."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _ecef import ned_between

from trn_env.env.terrain_nav import N_OBS, OBS_HIGH, OBS_LOW, TerrainNavEnv
from trn_env.policies import StraightLinePolicy

SMALL = dict(scenario="basin_route", decision_interval_s=1.0, max_episode_s=12.0, navigator="ins")
NEAR_START, NEAR_GOAL = (36.55, -84.25), (36.577, -84.25)     # 3 km apart on the basin's western hills


def _goal_bearing_and_distance(env):
    est = env._loop.estimate
    d = ned_between(est.lat_rad, est.lon_rad, est.h_m, env.goal_lat_rad, env.goal_lon_rad, est.h_m)[0]
    return math.atan2(d[1], d[0]), math.hypot(d[0], d[1])


def test_normalised_goal_observations_match_the_estimate():
    env = TerrainNavEnv(**SMALL, goal_deg=(36.60, -84.20))
    obs, _ = env.reset(seed=1)
    bearing, d0 = _goal_bearing_and_distance(env)
    assert obs.shape == (N_OBS,) and OBS_LOW.size == OBS_HIGH.size == N_OBS == 32
    rel = bearing - env._track_cmd_rad
    assert obs[19] == pytest.approx(math.sin(rel), abs=1e-5)
    assert obs[20] == pytest.approx(math.cos(rel), abs=1e-5)
    assert obs[21] == pytest.approx(1.0, abs=1e-6)              # the distance at the reset is the reference
    for _ in range(3):
        obs, *_ = env.step(np.array([1.0, 0.0], np.float32))  # turn right: the goal moves to the left
    bearing, d = _goal_bearing_and_distance(env)
    rel = bearing - env._track_cmd_rad
    assert obs[19] == pytest.approx(math.sin(rel), abs=1e-5) and obs[19] < -0.1
    assert obs[21] == pytest.approx(d / d0, rel=1e-5)
    env.close()


def test_bearing_action_turns_and_climbs_toward_its_targets_at_the_aircrafts_limits():
    env = TerrainNavEnv(**SMALL, goal_deg=(36.60, -84.20), action_mode="bearing", bearing_offset_max_deg=90.0)
    env.reset(seed=2)
    dpsi, dagl = env.action_limits
    assert dpsi == pytest.approx(math.radians(3.0)) and dagl == pytest.approx(5.0)
    track0, agl0 = env._track_cmd_rad, env._agl_cmd_m
    bearing, d_goal = _goal_bearing_and_distance(env)
    env.step(np.array([0.5, -1.0], np.float32))       # 45 deg right of the goal, down to agl_min_m
    assert env._bearing_offset_limit_rad(d_goal) == pytest.approx(math.pi / 2)   # far: the full 90 deg
    want = bearing + math.radians(45.0)
    d = math.atan2(math.sin(want - track0), math.cos(want - track0))
    assert env._track_cmd_rad == pytest.approx(track0 + float(np.clip(d, -dpsi, dpsi)), abs=1e-9)
    assert env._agl_cmd_m == pytest.approx(max(agl0 - dagl, env.agl_min_m), abs=1e-9)
    # a target within one step's reach is taken exactly
    bearing, _ = _goal_bearing_and_distance(env)
    track1 = env._track_cmd_rad
    off = math.atan2(math.sin(track1 - bearing), math.cos(track1 - bearing)) / (math.pi / 2)
    env.step(np.array([off, -1.0], np.float32))
    assert env._track_cmd_rad == pytest.approx(track1, abs=1e-6)
    # near the goal the offset is what the turn rate can hold: the bearing's turn v sin(phi) / d and the
    # offset's own shrinking add up to omega (tests/test_pursuit_offset_limit.py flies it)
    omega = dpsi / env.decision_interval_s
    for d in (300.0, 500.0, 1000.0):
        phi = env._bearing_offset_limit_rad(d)
        assert 2.0 * env.tas_mps * math.sin(phi) / d == pytest.approx(omega, rel=1e-9)
    assert math.degrees(env._bearing_offset_limit_rad(500.0)) == pytest.approx(8.9, abs=0.5)
    with pytest.raises(ValueError, match="action_mode"):
        TerrainNavEnv(**SMALL, action_mode="heading")
    with pytest.raises(ValueError, match="bearing_offset_max_deg"):
        TerrainNavEnv(**SMALL, bearing_offset_max_deg=270.0)
    env.close()


def test_straight_line_policy_in_bearing_mode_flies_to_the_goal():
    env = TerrainNavEnv(**{**SMALL, "max_episode_s": 80.0}, action_mode="bearing", goal_radius_m=500.0)
    pol = StraightLinePolicy(env)
    obs, _ = env.reset(seed=3, options={"start_deg": NEAR_START, "goal_deg": NEAR_GOAL})
    a = pol(obs)
    assert abs(a[0]) < 1e-3                               # the straight line is action 0
    done, info = False, {}
    while not done:
        obs, r, term, trunc, info = env.step(pol(obs))
        done = term or trunc
    assert info["termination"] == "arrived" and info["true_miss_m"] < 100.0
    env.close()


@pytest.mark.parametrize("gamma", [1.0, 0.9])
def test_shaping_term_is_the_potential_difference(gamma):
    env = TerrainNavEnv(**SMALL, goal_deg=(36.60, -84.20), shaping_gamma=gamma, progress_weight=2.0)
    _, info = env.reset(seed=4)
    d_prev = info["estimated_distance_to_goal_m"]
    total, d0 = 0.0, d_prev
    for _ in range(5):
        _, r, *_, info = env.step(np.array([0.0, 0.0], np.float32))
        d = info["estimated_distance_to_goal_m"]
        expected = 2.0 * (d_prev - gamma * d) / 1000.0
        assert info["reward_terms"]["progress"] == pytest.approx(expected, rel=1e-9)
        total += info["reward_terms"]["progress"]
        d_prev = d
    if gamma == 1.0:                                     # telescopes: only the end points count
        assert total == pytest.approx(2.0 * (d0 - d_prev) / 1000.0, rel=1e-9)
    with pytest.raises(ValueError, match="shaping_gamma"):
        TerrainNavEnv(**SMALL, shaping_gamma=1.5)
    env.close()


def test_bounds_scaled_extractor_maps_the_bounds_to_plus_minus_one():
    pytest.importorskip("stable_baselines3")
    import torch

    from trn_env.env.sb3_features import BoundsScaledExtractor

    env = TerrainNavEnv(**SMALL)
    ext = BoundsScaledExtractor(env.observation_space)
    lo, hi = torch.as_tensor(OBS_LOW), torch.as_tensor(OBS_HIGH)
    assert torch.allclose(ext(lo[None]), -torch.ones(1, N_OBS), atol=1e-6)
    assert torch.allclose(ext(hi[None]), torch.ones(1, N_OBS), atol=1e-6)
    mid = (lo + hi) / 2
    assert torch.allclose(ext(mid[None]), torch.zeros(1, N_OBS), atol=1e-6)
    env.close()
