"""Compile every numba kernel the built-in scenarios and navigators use, once, on all cores.

    trn-env precompile          # after `pip install`, or as the first step of a CI job

The kernels compile on their first call and are cached beside the package (numba `cache=True`). A first
`trn-env fly` compiles only what its scenario uses (`trn_env.sim.warm_up`); this compiles what every
built-in navigator uses, so that later flights, campaigns, env episodes and test runs of any navigator load
them from the cache. Each job is `warm_up` of one (scenario, navigator) pair in its own process. The first
job (the default scenario with INS + TERCOM: flight core, sensors, the exact terrain queries, the EKF and
TERCOM kernels, most of the compile time) runs alone, with warm_up's own second process compiling its
navigator beside it; the others share its kernels and run side by side on the remaining work, so no kernel
is compiled twice at the same time.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor

# (built-in scenario, navigator); the first job runs alone (module docstring)
JOBS: tuple[tuple[str, str], ...] = (
    ("default", "ins_tercom"),
    ("default", "pmf"),
    ("default", "pf"),
    ("default", "rbpf"),
    ("acq_track", "acq_track"),
    ("default", "ins"),
)


def warm_job(job: tuple[str, str], parallel: bool = False) -> tuple[str, str, float]:
    """warm_up one (scenario, navigator) pair in this process; returns (scenario, navigator, wall s)."""
    from trn_env.scenario.build import build_terrain, quiet_stdout
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import spawn_rngs
    from trn_env.sim.warm_up import warm_up

    name, navigator = job
    t0 = time.perf_counter()
    scenario = load_scenario(name, navigator=navigator)
    dems = build_terrain(scenario, scenario.extras, spawn_rngs(scenario.seed)["map"])
    with quiet_stdout():
        warm_up(scenario, dems, parallel=parallel)
    return name, navigator, time.perf_counter() - t0


def precompile(jobs: tuple[tuple[str, str], ...] = JOBS, workers: int | None = None,
               report=print) -> float:
    """Run the jobs (module docstring); returns the wall seconds. `report(line)` gets one line per job."""
    t0 = time.perf_counter()
    first, rest = jobs[0], jobs[1:]
    _, _, dt = warm_job(first, parallel=True)
    report(f"compiled {first[0]} / {first[1]} in {dt:.1f} s")
    n = max(1, min(len(rest), workers or os.cpu_count() or 1))
    with ProcessPoolExecutor(max_workers=n) as pool:
        for name, navigator, dt in pool.map(warm_job, rest):
            report(f"compiled {name} / {navigator} in {dt:.1f} s")
    return time.perf_counter() - t0
