"""Fast-tier throughput: TerrainNavFast-v0 agent steps per second beside TerrainNav-v0's in the same run.

    python -m trn_env.bench.fast_env [--quick]     # prints one JSON object

At the route benchmark's settings (scenario basin_route, action_mode "pursuit", 30 s decisions, +-45 deg
offsets, 500 m arrival radius, 480 s episodes, the scenario's INS + TERCOM navigator; uniformly random
actions from a fixed seed, autoresets included):

- fast_env_agent_steps_per_s: sub-env steps per wall second of TerrainNavFast-v0 with
  fast_env_num_envs = 256 sub-envs in one process (the median of fast_env_runs timed runs of
  fast_env_steps_per_run vector steps each, after a warm-up step; numba compiled beforehand), on numba's
  default threads (fast_env_threads, one per core; fast_env_threading_layer);
- fast_env_full_tier_agent_steps_per_s: TerrainNav-v0 (the full JSBSim loop) at the same settings, one env,
  episode resets included, env construction excluded; fast_env_ratio_to_full_tier their ratio;
- fast_env_bare_jsbsim_agent_steps_per_s: a bare JSBSim `fdm.run()` loop of the same aircraft (one
  aircraft, nothing else), in 30 s decisions per wall second: the most the full tier could give per core;
- fast_env_agent_steps_per_cpu_s: the same steps per CPU second of the process (all threads), which on a
  machine shared with other work tells what the tier costs; fast_env_load_average_1min the machine's load
  when measured (a 2-core machine is saturated at 2), fast_env_threads numba's thread count; the same
  two figures with numba limited to one thread (fast_env_agent_steps_per_s_one_thread,
  fast_env_agent_steps_per_cpu_s_one_thread): on an idle machine the threads' wall figure approaches
  fast_env_threads times the one-thread figure, while the CPU figures stay alike (what the threads cost);
- fast_env_sim_seconds_per_wall_second: simulated aircraft-seconds per wall second of the fast tier;
- fast_env_ms_per_vector_step: wall time of one step of all sub-envs (median run);
- fast_env_build_s: constructing the vector env (terrain, information map) and its first reset.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

SETTINGS = dict(
    scenario="basin_route",
    decision_interval_s=30.0,
    max_episode_s=480.0,
    goal_radius_m=500.0,
    action_mode="pursuit",
    bearing_offset_max_deg=45.0,
    agl_min_m=300.0,
    agl_max_m=900.0,
    failure_penalty=20.0,
)


def fast_figures(num_envs: int = 256, runs: int = 5, steps_per_run: int = 20) -> dict:
    from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv

    t0 = time.perf_counter()
    env = TerrainNavFastVectorEnv(num_envs=num_envs, **SETTINGS)
    env.reset(seed=0)
    build = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    env.step(rng.uniform(-1, 1, (num_envs, 2)).astype(np.float32))  # warm-up
    rates, sim_rates, ms, cpu_rates = [], [], [], []
    for _ in range(runs):
        acts = rng.uniform(-1, 1, (steps_per_run, num_envs, 2)).astype(np.float32)
        t0 = time.perf_counter()
        c0 = time.process_time()
        for k in range(steps_per_run):
            env.step(acts[k])
        wall = time.perf_counter() - t0
        cpu_rates.append(num_envs * steps_per_run / (time.process_time() - c0))
        rates.append(num_envs * steps_per_run / wall)
        sim_rates.append(num_envs * steps_per_run * env.decision_interval_s / wall)
        ms.append(1e3 * wall / steps_per_run)
    env.close()
    k = int(np.argsort(rates)[len(rates) // 2])
    import numba

    return {
        "fast_env_agent_steps_per_s": float(rates[k]),
        "fast_env_agent_steps_per_cpu_s": float(np.median(cpu_rates)),
        "fast_env_load_average_1min": float(os.getloadavg()[0]),
        "fast_env_threads": numba.get_num_threads(),
        "fast_env_threading_layer": _threading_layer(),
        "fast_env_agent_steps_per_s_by_run": [round(r, 1) for r in rates],
        "fast_env_sim_seconds_per_wall_second": float(sim_rates[k]),
        "fast_env_ms_per_vector_step": float(ms[k]),
        "fast_env_num_envs": num_envs,
        "fast_env_runs": runs,
        "fast_env_steps_per_run": steps_per_run,
        "fast_env_build_s": build,
        "fast_env_decision_interval_s": env.decision_interval_s,
    }


def _threading_layer() -> str:
    import numba

    try:
        return str(numba.threading_layer())
    except ValueError:  # no parallel kernel has run
        return ""


def full_figures(n_steps: int) -> dict:
    from trn_env.env.terrain_nav import TerrainNavEnv

    env = TerrainNavEnv(**SETTINGS)
    env.action_space.seed(0)
    env.reset(seed=0)
    env.step(env.action_space.sample())  # warm-up (numba dispatch)
    t0 = time.perf_counter()
    for _ in range(n_steps):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()
    wall = time.perf_counter() - t0
    env.close()
    return {
        "fast_env_full_tier_agent_steps_per_s": n_steps / wall,
        "fast_env_full_tier_steps_measured": n_steps,
    }


def benchmark(quick: bool = False) -> dict:
    import numba

    from trn_env.bench.env import _bare_jsbsim_sim_s_per_wall_s

    runs, steps = (3, 10) if quick else (5, 20)
    out = fast_figures(num_envs=256, runs=runs, steps_per_run=steps)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        one = fast_figures(num_envs=256, runs=runs, steps_per_run=steps)
    finally:
        numba.set_num_threads(threads)
    out["fast_env_agent_steps_per_s_one_thread"] = one["fast_env_agent_steps_per_s"]
    out["fast_env_agent_steps_per_cpu_s_one_thread"] = one["fast_env_agent_steps_per_cpu_s"]
    out.update(full_figures(6 if quick else 20))
    bare = _bare_jsbsim_sim_s_per_wall_s(5000 if quick else 20000)
    out["fast_env_bare_jsbsim_agent_steps_per_s"] = bare / SETTINGS["decision_interval_s"]
    out["fast_env_ratio_to_full_tier"] = (
        out["fast_env_agent_steps_per_s"] / out["fast_env_full_tier_agent_steps_per_s"]
    )
    return out


if __name__ == "__main__":  # pragma: no cover
    print(json.dumps(benchmark(quick="--quick" in sys.argv[1:]), indent=1))
