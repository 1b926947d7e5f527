"""Compile every numba kernel the built-in scenarios, navigators and env tiers use, once, on all cores.

    trn-env precompile          # after `pip install`, on every node of a cluster, or as a CI job's first step

The kernels compile on their first call and are cached beside the package (numba `cache=True`). A first
`trn-env fly` compiles only what its scenario uses (`trn_env.sim.warm_up`); this compiles what every
built-in navigator, the DEM integrity monitor, both env tiers at the route task's settings and the task's
route planner use, so that later flights, local campaigns, env episodes (TerrainNav-v0 and
TerrainNavFast-v0, RLlib's env runners included) and test runs load them from the cache.

Jobs, each in its own process:
- a scenario job is `warm_up` of one (scenario, navigator, overrides) (SCENARIO_JOBS; the overrides are
  `trn-env fly --set` assignments: the INS job also flies the DEM integrity monitor, with the radar
  altimeter it needs). The first (the default scenario with INS + TERCOM: flight core, sensors, the exact
  terrain queries, the EKF and TERCOM kernels) runs in this process, with warm_up's own forked child
  compiling its navigator beside it; the other scenario jobs share its kernels, so they start when it is
  done (no kernel is compiled twice at once).
- the env jobs: `warm_fast_tier` builds the route task's TerrainNavFast-v0 and steps it (its kernels' types
  do not depend on the terrain, the fast tier's navigator, the number of aircraft or the task's settings);
  it shares no kernel with the scenario jobs, so it starts at once (EARLY_JOBS), on the pool's cores the
  first job leaves idle. `warm_full_tier` does the same with TerrainNav-v0, whose flight, sensors and
  navigator are the first job's, flying the route planner's route: it compiles the env's own kernels and
  the planner's after it (LATER_JOBS).
Longest first: the pool takes the jobs in order.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import partial

ScenarioJob = tuple[str, str, tuple[str, ...]]
_DEM_MONITOR = ("sensors.radar_altimeter={}", "monitors.dem_integrity={}")
# (built-in scenario, navigator, overrides): the first runs before the others, then longest first (module
# docstring)
SCENARIO_JOBS: tuple[ScenarioJob, ...] = (
    ("default", "ins_tercom", ()),
    ("acq_track", "acq_track", ()),
    ("default", "rbpf", ()),
    ("default", "pmf", ()),
    ("default", "ins", _DEM_MONITOR),
    ("default", "pf", ()),
)


def warm_job(job: ScenarioJob, parallel: bool = False) -> tuple[str, float]:
    """warm_up one (scenario, navigator, overrides) in this process; returns (label, wall s)."""
    from trn_env.scenario.build import build_terrain, quiet_stdout
    from trn_env.scenario.overrides import load_scenario_with, parse_assignment
    from trn_env.sim.closed_loop import spawn_rngs
    from trn_env.sim.warm_up import warm_up

    name, navigator, overrides = job
    t0 = time.perf_counter()
    scenario = load_scenario_with(name, [parse_assignment(a) for a in overrides], navigator=navigator)
    dems = build_terrain(scenario, scenario.extras, spawn_rngs(scenario.seed)["map"])
    with quiet_stdout():
        warm_up(scenario, dems, parallel=parallel)
    monitors = "".join(f" + {m.name}" for m in scenario.sections.monitors)
    return f"{name} / {navigator}{monitors}", time.perf_counter() - t0


def warm_fast_tier() -> tuple[str, float]:
    """Build the route task's TerrainNavFast-v0 (two aircraft) on the basin terrain, reset it and fly two
    decisions: every kernel of the tier compiles (dynamics.fly_decision, observation.observe,
    reset.reset_aircraft and their callees); returns (label, wall s)."""
    import gymnasium as gym
    import numpy as np

    from trn_env.env import route_task
    from trn_env.scenario.build import quiet_stdout

    t0 = time.perf_counter()
    kw = route_task.fast_tier_kwargs(route_task.env_kwargs("basin"))
    with quiet_stdout():
        envs = gym.make_vec("trn_env/TerrainNavFast-v0", num_envs=2, vectorization_mode="vector_entry_point",
                            **kw)
        try:
            envs.reset(seed=0)
            for _ in range(2):
                envs.step(np.zeros(envs.action_space.shape, envs.action_space.dtype))
        finally:
            envs.close()
    return "TerrainNavFast-v0 (route task)", time.perf_counter() - t0


def warm_full_tier() -> tuple[str, float]:
    """Build the route task's TerrainNav-v0 on the basin terrain, reset it and fly one decision on the
    terrain-information planner's route (the env's own kernels: goal sampling, pursuit paths, observations;
    the planner's cost map and A* search, which the task's planner baseline flies in both tiers); returns
    (label, wall s)."""
    import gymnasium as gym

    from trn_env.env import route_task
    from trn_env.env.policies import PlannerPolicy
    from trn_env.scenario.build import quiet_stdout

    t0 = time.perf_counter()
    with quiet_stdout():
        env = gym.make("trn_env/TerrainNav-v0", **route_task.env_kwargs("basin"))
        try:
            obs, _ = env.reset(seed=0)
            env.step(PlannerPolicy(env)(obs))
        finally:
            env.close()
    return "TerrainNav-v0 (route task) and the planner", time.perf_counter() - t0


Job = Callable[[], tuple[str, float]]
EARLY_JOBS: tuple[Job, ...] = (warm_fast_tier,)
LATER_JOBS: tuple[Job, ...] = (warm_full_tier,)


def precompile(scenario_jobs: tuple[ScenarioJob, ...] = SCENARIO_JOBS,
               early_jobs: tuple[Job, ...] = EARLY_JOBS, later_jobs: tuple[Job, ...] = LATER_JOBS,
               workers: int | None = None, report=print) -> float:
    """Run the jobs (module docstring); returns the wall seconds. `report(line)` gets one line per job."""
    t0 = time.perf_counter()
    first = scenario_jobs[0]
    later = [partial(warm_job, job) for job in scenario_jobs[1:]] + list(later_jobs)
    n = max(1, min(len(early_jobs) + len(later), workers or os.cpu_count() or 1))
    with ProcessPoolExecutor(max_workers=n) as pool:
        futures = [pool.submit(job) for job in early_jobs]
        label, dt = warm_job(first, parallel=True)
        report(f"compiled {label} in {dt:.1f} s")
        futures += [pool.submit(job) for job in later]
        for future in futures:
            label, dt = future.result()
            report(f"compiled {label} in {dt:.1f} s")
    return time.perf_counter() - t0
