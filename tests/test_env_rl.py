"""TerrainNav-v0 as RL users expect it: make_vec, metadata, RecordVideo, stable-baselines3's check_env and a
PPO smoke run over a 2-env SubprocVecEnv, pickling, close(), memory over resets, the arrival task and its
reward, goal sampling with held-out goals, the route policies, bad options."""

from __future__ import annotations

import math
import os
import pickle
import warnings
from functools import partial

import gymnasium as gym
import numpy as np
import pytest
from _ecef import ned_between

import trn_env  # noqa: F401 - registers the env id
from trn_env.env.terrain_nav import TerrainNavEnv
from trn_env.policies import PlannerPolicy, StraightLinePolicy

# cheap episodes: 1 s decisions, 12 s of flight, INS-only navigator, the basin terrain (no refinement)
SMALL = dict(scenario="basin_route", decision_interval_s=1.0, max_episode_s=12.0, navigator="ins")
# the basin's south-west hills: a start and a goal 3 km apart (an arrival in ~40 s)
NEAR_START, NEAR_GOAL = (36.55, -84.25), (36.577, -84.25)


def test_make_vec_sync_and_async_and_metadata():
    for mode in ("sync", "async"):
        venv = gym.make_vec("trn_env/TerrainNav-v0", num_envs=2, vectorization_mode=mode, **SMALL)
        obs, _ = venv.reset(seed=3)
        assert obs.shape == (2, 32) and obs.dtype == np.float32
        obs, r, term, trunc, _ = venv.step(np.zeros((2, 2), np.float32))
        assert np.all(np.isfinite(r)) and venv.observation_space.contains(obs)
        assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        venv.close()
    e = TerrainNavEnv(**SMALL)
    assert e.metadata["render_fps"] == pytest.approx(1.0 / e.decision_interval_s)
    e2 = TerrainNavEnv(**{**SMALL, "decision_interval_s": 5.0})
    assert e2.metadata["render_fps"] == pytest.approx(0.2)
    e.close()
    e2.close()


def test_sb3_check_env_without_warnings():
    pytest.importorskip("stable_baselines3", reason="the rl extra is installed in CI")
    from stable_baselines3.common.env_checker import check_env

    e = TerrainNavEnv(**SMALL)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning of sb3's checker fails the test
        check_env(e, warn=True, skip_render_check=True)
    e.close()


def test_record_video_writes_frames(tmp_path):
    pytest.importorskip("moviepy", reason="the video extra (moviepy) is not installed")
    e = gym.wrappers.RecordVideo(
        gym.make("trn_env/TerrainNav-v0", render_mode="rgb_array", **{**SMALL, "max_episode_s": 6.0}),
        video_folder=str(tmp_path / "videos"),
        episode_trigger=lambda k: True,
        disable_logger=True,
    )
    e.reset(seed=0)
    done = False
    while not done:
        _, _, term, trunc, _ = e.step(np.array([1.0, 0.0], np.float32))
        done = term or trunc
    e.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


def test_ppo_trains_over_a_two_env_subproc_vec_env(tmp_path):
    pytest.importorskip("stable_baselines3", reason="the rl extra is installed in CI")
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import SubprocVecEnv

    torch.set_num_threads(1)  # the two env workers have the cores
    make = partial(TerrainNavEnv, **{**SMALL, "max_episode_s": 30.0})
    venv = SubprocVecEnv([make, make], start_method="forkserver")  # workers re-create the env
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=256,
        batch_size=256,
        n_epochs=2,
        seed=0,
        device="cpu",
        policy_kwargs=dict(net_arch=[16]),
    )
    model.set_logger(configure(str(tmp_path), []))   # SB3's own would leave a folder in the system tmp
    before = torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach().clone()
    model.learn(total_timesteps=1536)
    after = torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach()
    venv.close()
    assert model.num_timesteps == 1536
    assert model._n_updates == 3 * 2  # 3 rollouts of 2 x 256 steps, 2 epochs each
    assert not torch.allclose(before, after)


def test_pickles_and_closes_twice():
    e = gym.make("trn_env/TerrainNav-v0", **SMALL)
    e.reset(seed=4)
    a = [e.step(np.array([0.3, 0.1], np.float32))[0] for _ in range(2)]
    e2 = pickle.loads(pickle.dumps(e))
    e2.reset(seed=4)
    b = [e2.step(np.array([0.3, 0.1], np.float32))[0] for _ in range(2)]
    assert np.array_equal(a, b)  # the re-created env flies the same episode
    for env in (e, e2):
        env.close()
        env.close()


def _rss_mb() -> float:
    with open(f"/proc/{os.getpid()}/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="needs /proc (Linux) to read the RSS")
def test_memory_flat_over_resets():
    """200 resets here (1,000 for the figure in docs/guide/planning.md, the same check): the RSS after a
    warm-up stays flat (keeping every reset's flight alive would show as tens of MB; the per-reset figure:
    docs/validation/route_task.md, regression tests' bounds)."""
    e = TerrainNavEnv(**SMALL)
    for k in range(40):  # warm-up: allocator pools, numba dispatch
        e.reset(seed=k)
    rss0 = _rss_mb()
    for k in range(160):
        e.reset(seed=k)
        if k % 40 == 0:
            e.step(np.zeros(2, np.float32))
    growth = _rss_mb() - rss0
    e.close()
    assert growth < 10.0, f"RSS grew {growth:.1f} MB over 160 resets"


def test_arrival_task_counts_the_true_miss():
    e = TerrainNavEnv(
        scenario="basin_route",
        navigator="ins",
        decision_interval_s=5.0,
        max_episode_s=120.0,
        goal_radius_m=500.0,
    )
    pol = StraightLinePolicy(e, agl_m=600.0)
    obs, info0 = e.reset(seed=1, options={"start_deg": NEAR_START, "goal_deg": NEAR_GOAL})
    assert info0["start_deg"] == NEAR_START and info0["goal_deg"] == pytest.approx(NEAR_GOAL)
    totals: dict[str, float] = {}
    done, info = False, {}
    while not done:
        obs, r, term, trunc, info = e.step(pol(obs))
        done = term or trunc
        assert sum(info["reward_terms"].values()) == pytest.approx(r, rel=1e-12, abs=1e-12)
        for k, v in info["reward_terms"].items():
            totals[k] = totals.get(k, 0.0) + v
    assert term and info["termination"] == "arrived"
    assert info["estimated_distance_to_goal_m"] <= 500.0
    # the true miss: truth + (goal - estimate) -> its distance from the goal, computed here through ECEF
    est = e._loop.estimate
    lat, lon, h = e._truth_now()
    err = ned_between(lat, lon, h, est.lat_rad, est.lon_rad, h)[0]
    assert info["true_miss_m"] == pytest.approx(math.hypot(err[0], err[1]), abs=0.1)
    t = info["reward_terms"]
    assert t["arrival"] == e.goal_bonus
    assert t["miss"] == pytest.approx(-e.miss_weight * info["true_miss_m"] / 1000.0)
    # over the episode: the time cost is the flight time, the progress term telescopes on the estimate
    assert totals["time"] == pytest.approx(-e.time_cost_per_s * info["t_s"], rel=1e-9)
    assert totals["progress"] == pytest.approx(
        e.progress_weight
        * (info0["estimated_distance_to_goal_m"] - info["estimated_distance_to_goal_m"])
        / 1e3,
        rel=1e-9,
    )
    assert totals["collision"] == totals["failure"] == 0.0
    assert 2_000.0 < info["distance_flown_m"] < 4_500.0
    e.close()


def test_goal_sampling_avoids_held_out_goals():
    region = (36.55, 36.74, -84.27, -84.0)
    e = TerrainNavEnv(**SMALL, goal_region_deg=region, held_out_radius_m=2500.0)
    assert len(e.held_out_goals_deg) == 5
    goals = []
    for k in range(25):
        _, info = e.reset(seed=k)
        goals.append(info["goal_deg"])
    g = np.array(goals)
    assert np.all(
        (g[:, 0] >= region[0]) & (g[:, 0] <= region[1]) & (g[:, 1] >= region[2]) & (g[:, 1] <= region[3])
    )
    assert len({tuple(x) for x in goals}) == 25
    for lat, lon in goals:
        for hl, ho in e.held_out_goals_deg:
            dn, de, _ = ned_between(
                math.radians(lat), math.radians(lon), 0.0, math.radians(hl), math.radians(ho), 0.0
            )[0]
            assert math.hypot(dn, de) >= 2500.0
    _, info = e.reset(seed=0, options={"goal_deg": e.held_out_goals_deg[2]})
    assert info["goal_deg"] == pytest.approx(e.held_out_goals_deg[2])
    e.close()


def test_planner_policy_goes_round_the_basin():
    e = TerrainNavEnv(scenario="basin_route", navigator="ins", decision_interval_s=5.0, max_episode_s=60.0)
    straight, planner = StraightLinePolicy(e), PlannerPolicy(e)
    obs, _ = e.reset(seed=0)
    assert abs(straight(obs)[0]) < 0.05  # the goal is dead ahead
    a = planner(obs)
    assert a[0] < -0.5  # turns left, to the basin's west rim
    assert planner.route.featureless_m < 500.0 and planner.n_plans == 1
    obs, *_ = e.step(a)
    planner(obs)
    assert planner.n_plans == 2  # replans at each decision step
    a, _ = planner.predict(np.stack([obs, obs]))
    assert a.shape == (2, 2) and a.dtype == np.float32
    e.close()


def test_bad_options_name_the_option():
    for kw, name in (
        (dict(max_episode_s="60"), "max_episode_s"),
        (dict(goal_radius_m=-1.0), "goal_radius_m"),
        (dict(reward_mode="fast"), "reward_mode"),
        (dict(miss_weight=float("nan")), "miss_weight"),
        (dict(goal_region_deg=(1, 2)), "goal_region_deg"),
        (dict(log_sensors=1), "log_sensors"),
        (dict(goal_deg=(10.0, 10.0)), "goal_deg"),
        (dict(navigator=3), "navigator"),
    ):
        with pytest.raises(ValueError, match=name):
            TerrainNavEnv(**{**SMALL, **kw})
    e = TerrainNavEnv(**SMALL)
    with pytest.raises(ValueError, match="unknown keys"):
        e.reset(options={"goal": (36.6, -84.1)})
    with pytest.raises(ValueError, match="goal_deg"):
        e.reset(options={"goal_deg": "north"})
    e.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        e.step(np.zeros((2, 1), np.float32))
    with pytest.raises(ValueError, match=r"array of numbers of shape \(2,\)"):
        e.step(["left", "up"])
    e.close()


def test_arrival_is_judged_on_each_updates_own_estimate_inline_and_pipelined():
    """1 s decisions = one navigator update each: the episode ends at the first update whose estimate is
    inside the circle (the step before it reported an estimate outside), and the pipelined env (navigator in a
    second process, waiting for it only near the goal) ends the same episode at the same time with the same
    miss."""
    kw = dict(scenario="basin_route", navigator="ins", decision_interval_s=1.0, max_episode_s=90.0,
              goal_radius_m=500.0)
    runs = {}
    for pipeline in (False, True):
        e = TerrainNavEnv(**kw, pipeline=pipeline)
        pol = StraightLinePolicy(e, agl_m=600.0)
        obs, info = e.reset(seed=2, options={"start_deg": NEAR_START, "goal_deg": NEAR_GOAL})
        d_est = [info["estimated_distance_to_goal_m"]]
        while True:
            obs, _, term, trunc, info = e.step(pol(obs))
            d_est.append(info["estimated_distance_to_goal_m"])
            if term or trunc:
                break
        e.close()
        assert info["termination"] == "arrived"
        assert d_est[-1] <= 500.0 < min(d_est[:-1])      # on time: never inside the circle before
        runs[pipeline] = (info["t_s"], info["true_miss_m"], d_est)
    assert runs[True] == runs[False]
