"""Fast-tier throughput: TerrainNavFast-v0 agent steps per second beside TerrainNav-v0's in the same run.

    python -m trn_env.bench.fast_env [--quick]     # prints one JSON object

At the route benchmark's settings (scenario basin_route, action_mode "pursuit", 30 s decisions, +-45 deg
offsets, 500 m arrival radius, 480 s episodes, the scenario's INS + TERCOM navigator; uniformly random
actions from a fixed seed, autoresets included):

- fast_env_agent_steps_per_s: sub-env steps per wall second of TerrainNavFast-v0 with
  fast_env_num_envs = 256 sub-envs in one process (the median of fast_env_runs timed runs of
  fast_env_steps_per_run vector steps each, after a warm-up step; numba compiled beforehand), single thread;
- fast_env_full_tier_agent_steps_per_s: TerrainNav-v0 (the full JSBSim loop) at the same settings, one env,
  episode resets included, env construction excluded; fast_env_ratio_to_full_tier their ratio;
- fast_env_sim_seconds_per_wall_second: simulated aircraft-seconds per wall second of the fast tier;
- fast_env_ms_per_vector_step: wall time of one step of all sub-envs (median run);
- fast_env_build_s: constructing the vector env (terrain, information map) and its first reset.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

SETTINGS = dict(scenario="basin_route", decision_interval_s=30.0, max_episode_s=480.0, goal_radius_m=500.0,
                action_mode="pursuit", bearing_offset_max_deg=45.0, agl_min_m=300.0, agl_max_m=900.0,
                failure_penalty=20.0)


def fast_figures(num_envs: int = 256, runs: int = 5, steps_per_run: int = 20) -> dict:
    from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv

    t0 = time.perf_counter()
    env = TerrainNavFastVectorEnv(num_envs=num_envs, **SETTINGS)
    env.reset(seed=0)
    build = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    env.step(rng.uniform(-1, 1, (num_envs, 2)).astype(np.float32))        # warm-up
    rates, sim_rates, ms = [], [], []
    for _ in range(runs):
        acts = rng.uniform(-1, 1, (steps_per_run, num_envs, 2)).astype(np.float32)
        sim0 = 0.0
        t0 = time.perf_counter()
        for k in range(steps_per_run):
            _, _, _, _, info = env.step(acts[k])
            sim0 += float(np.sum(info["t_s"]))          # not exact per step; recomputed below
        wall = time.perf_counter() - t0
        rates.append(num_envs * steps_per_run / wall)
        sim_rates.append(num_envs * steps_per_run * env.decision_interval_s / wall)
        ms.append(1e3 * wall / steps_per_run)
    env.close()
    k = int(np.argsort(rates)[len(rates) // 2])
    return {"fast_env_agent_steps_per_s": float(rates[k]),
            "fast_env_agent_steps_per_s_by_run": [round(r, 1) for r in rates],
            "fast_env_sim_seconds_per_wall_second": float(sim_rates[k]),
            "fast_env_ms_per_vector_step": float(ms[k]), "fast_env_num_envs": num_envs,
            "fast_env_runs": runs, "fast_env_steps_per_run": steps_per_run, "fast_env_build_s": build,
            "fast_env_decision_interval_s": env.decision_interval_s}


def full_figures(n_steps: int) -> dict:
    from trn_env.env.terrain_nav import TerrainNavEnv

    env = TerrainNavEnv(**SETTINGS)
    env.action_space.seed(0)
    env.reset(seed=0)
    env.step(env.action_space.sample())           # warm-up (numba dispatch)
    t0 = time.perf_counter()
    for _ in range(n_steps):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()
    wall = time.perf_counter() - t0
    env.close()
    return {"fast_env_full_tier_agent_steps_per_s": n_steps / wall, "fast_env_full_tier_steps_measured": n_steps}


def benchmark(quick: bool = False) -> dict:
    out = fast_figures(num_envs=256, runs=3 if quick else 5, steps_per_run=10 if quick else 20)
    out.update(full_figures(6 if quick else 20))
    out["fast_env_ratio_to_full_tier"] = out["fast_env_agent_steps_per_s"] / out[
        "fast_env_full_tier_agent_steps_per_s"]
    return out


if __name__ == "__main__":  # pragma: no cover
    print(json.dumps(benchmark(quick="--quick" in sys.argv[1:]), indent=1))
