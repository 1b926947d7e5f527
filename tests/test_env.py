"""TerrainNav-v0: gymnasium API conformance, determinism, action checks, rewards, vector env."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from _ecef import ned_between as ned_vector_between
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env

import trn_env  # noqa: F401 - registers the env id
from trn_env.env.terrain_nav import TerrainNavEnv

# cheap episodes: 1 s decisions, 12 s of flight, INS-only navigator
SMALL = dict(decision_interval_s=1.0, max_episode_s=12.0, navigator="ins")


@pytest.fixture(scope="module")
def env():
    e = TerrainNavEnv("default", **SMALL)
    yield e
    e.close()


def test_registered_and_make_works():
    assert "trn_env/TerrainNav-v0" in gym.registry
    e = gym.make("trn_env/TerrainNav-v0", **SMALL)
    obs, info = e.reset(seed=0)
    assert e.observation_space.contains(obs)
    e.close()


def test_check_env_passes():
    e = gym.make("trn_env/TerrainNav-v0", render_mode="rgb_array", **SMALL)
    check_env(e.unwrapped, skip_render_check=False)
    e.close()


def test_spaces_and_aircraft_limits(env):
    a = env.action_space
    assert a.shape == (2,) and a.dtype == np.float32
    assert np.all(a.low == -1.0) and np.all(a.high == 1.0)
    # 1 s decisions: rate-one turn (3 deg/s) and 5 m/s climb
    assert np.allclose(env.action_limits, [math.radians(3.0), 5.0])
    env.reset(seed=0)
    track0, agl0 = env._track_cmd_rad, env._agl_cmd_m
    env.step(np.array([0.5, -1.0], np.float32))
    assert env._track_cmd_rad - track0 == pytest.approx(math.radians(1.5))
    assert env._agl_cmd_m - agl0 == pytest.approx(-5.0)
    assert env.observation_space.shape == (32,)


def test_identical_seeds_identical_episodes():
    def episode(seed):
        e = TerrainNavEnv("default", **SMALL)
        e.action_space.seed(seed)
        obs, _ = e.reset(seed=seed)
        out = [obs]
        rewards = []
        for _ in range(4):
            o, r, term, trunc, info = e.step(e.action_space.sample())
            out.append(o)
            rewards.append(r)
        e.close()
        return np.array(out), np.array(rewards)

    o1, r1 = episode(11)
    o2, r2 = episode(11)
    o3, _ = episode(12)
    assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
    assert not np.array_equal(o1, o3)


def test_action_outside_space_raises(env):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action\[0\].*outside the action space"):
        env.step(np.array([1.5, 0.0], np.float32))
    with pytest.raises(ValueError, match=r"action\[1\].*outside"):
        env.step(np.array([0.0, -1.01], np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0], np.float32))


def test_step_before_reset_and_after_end_raise():
    e = gym.make("trn_env/TerrainNav-v0", **SMALL)
    with pytest.raises(ResetNeeded):
        e.step(np.zeros(2, np.float32))
    e.reset(seed=1)
    done = False
    n = 0
    while not done:
        _, _, term, trunc, info = e.step(np.zeros(2, np.float32))
        done = term or trunc
        n += 1
    assert trunc and info["termination"] == "time_limit" and n == 12
    with pytest.raises(ResetNeeded):
        e.step(np.zeros(2, np.float32))
    e.reset(seed=2)
    e.step(np.zeros(2, np.float32))          # usable again after reset
    e.close()


def test_observation_and_reward_match_independent_computation():
    env = TerrainNavEnv("default", reward_mode="progress", **SMALL)     # the v0 reward, kept as an option
    obs0, info0 = env.reset(seed=5)
    est = env._loop.estimate
    goal = ned_vector_between(est.lat_rad, est.lon_rad, est.h_m, env.goal_lat_rad, env.goal_lon_rad,
                              est.h_m)[0]
    assert np.allclose(obs0[:2], goal[:2] / 1000.0, atol=1e-5)       # km (float32)
    assert np.allclose(obs0[8:11], np.log10(1.0 + est.sigma_ned_m), rtol=1e-5)
    # terrain information at the estimate: the CRLB of terrain.metrics on the navigator's map
    from trn_env.terrain import metrics
    the_map = env._dems[1]
    crlb = metrics.terrain_information(the_map, 5.0, 2000.0).crlb_sigma_h_m
    here = the_map.with_heights(np.minimum(np.nan_to_num(crlb, nan=1e4, posinf=1e4), 1e4)).height(
        est.lat_rad, est.lon_rad)
    assert obs0[11] == pytest.approx(np.log10(1.0 + here), rel=1e-5)
    assert np.all(obs0[11:17] > 0.0)
    obs1, r, term, trunc, info1 = env.step(np.array([0.5, 0.6], np.float32))
    expected = ((info0["true_distance_to_goal_m"] - info1["true_distance_to_goal_m"]) / 1000.0
                - env.error_weight * info1["true_horizontal_error_m"] / 1000.0)
    assert r == pytest.approx(expected, rel=1e-9)
    lat, lon, h = env._truth_now()
    e_true = ned_vector_between(lat, lon, h, env._loop.estimate.lat_rad, env._loop.estimate.lon_rad, h)[0]
    assert info1["true_horizontal_error_m"] == pytest.approx(math.hypot(e_true[0], e_true[1]), abs=0.05)
    assert info1["termination"] is None and not term and not trunc
    assert info1["t_s"] == pytest.approx(1.0)
    assert sum(info1["reward_terms"].values()) == pytest.approx(r, rel=1e-12)
    env.close()


def test_collision_penalty_and_termination():
    """Level at 800 m MSL toward a 996 m summit 2.8 km north: terminated with the collision penalty."""

    from trn_env.flight.core import AutopilotTargets, LateralMode, VerticalMode
    from trn_env.scenario.loading import load_scenario, validate

    sc = load_scenario("default", navigator="ins")
    data = sc.to_dict()
    data["initial"] = {"lat_deg": 36.5408, "lon_deg": -84.2725, "h_msl_m": 800.0, "tas_mps": 85.0,
                       "heading_deg": 0.0}
    data["route"]["waypoints"] = [{"lat_deg": 36.5408, "lon_deg": -84.2725, "h_msl_m": 800.0},
                                  {"lat_deg": 36.6200, "lon_deg": -84.2725, "h_msl_m": 1500.0}]
    e = TerrainNavEnv(validate(data, source="test"), decision_interval_s=5.0, max_episode_s=90.0,
                      collision_penalty=100.0)
    # a pilot who ignores the terrain: the autopilot holds 800 m MSL due north whatever the action
    e._commander = lambda est, t: AutopilotTargets(lateral_mode=LateralMode.TRACK, track_cmd_rad=0.0,
                                                   vertical_mode=VerticalMode.ALTITUDE_MSL,
                                                   altitude_cmd_m=800.0, tas_cmd_mps=85.0)
    e.reset(seed=0)
    term = trunc = False
    rewards, info = [], {}
    while not (term or trunc):
        _, r, term, trunc, info = e.step(np.zeros(2, np.float32))
        rewards.append(r)
    assert term and not trunc and info["termination"] == "terrain_collision"
    assert rewards[-1] < -90.0 and all(r > -10.0 for r in rewards[:-1])
    assert 20.0 < info["t_s"] < 60.0
    e.close()


def test_render_rgb_array_shows_tracks():
    e = TerrainNavEnv("default", render_mode="rgb_array", **SMALL)
    e.reset(seed=0)
    first = e.render()
    for _ in range(6):
        e.step(np.array([1.0, 0.0], np.float32))
    later = e.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3
    assert first.shape == later.shape
    # the track grows: more pixels differ from the background hillshade
    assert np.count_nonzero(np.any(first != later, axis=2)) > 20
    e.close()


def test_random_policy_through_async_vector_env():
    """A stable-baselines3-style loop (VecEnv API: reset -> obs; step -> obs, rewards, dones, infos)."""
    n_envs = 2
    venv = gym.vector.AsyncVectorEnv([lambda: gym.make("trn_env/TerrainNav-v0", **SMALL)] * n_envs)
    rng = np.random.default_rng(0)
    obs, _ = venv.reset(seed=[0, 1])
    assert obs.shape == (n_envs, 32)
    low, high = venv.single_action_space.low, venv.single_action_space.high
    assert np.all(low == -1.0) and np.all(high == 1.0)
    episodes = 0
    total_steps = 200
    for _ in range(total_steps):
        actions = rng.uniform(low, high, size=(n_envs, 2)).astype(np.float32)     # the random policy
        obs, rewards, terms, truncs, infos = venv.step(actions)
        dones = terms | truncs
        episodes += int(dones.sum())
        assert obs.shape == (n_envs, 32) and np.all(np.isfinite(obs)) and np.all(np.isfinite(rewards))
    venv.close()
    # 12-step episodes plus the autoreset step: about 200 / 13 episodes per env
    assert episodes >= 2 * (total_steps // 13) - 2
