"""Compile (or load from numba's cache) the kernels a scenario uses before its flight starts.

The numba kernels compile on their first call and are cached beside the package, so the first run after
an install spends its first seconds compiling; later runs load the cache in well under a second. Flown
as it is, that compile sits inside the flight: the progress bar stalls at the first simulated second and
the real-time factor counts it. `warm_up` flies a copy of the scenario for three navigator updates first
(one process, the same terrain objects, its own aircraft trim and random streams): GNSS (if fitted) in the
first update, none after it, a TERCOM fix (if the navigator has one) due at the third. Every kernel the
flight will call - sensors, terrain queries, mechanisation, covariance propagation on the GNSS-aided and
the fused GNSS-denied paths, the fix's correlation - is compiled or loaded then, and only those: a kernel
the scenario does not use is never compiled. The flight itself is untouched (its objects and random
streams are separate), so its results are the same bit for bit.
"""

from __future__ import annotations

import copy
import time

from trn_env.scenario.loading import Scenario


def warm_up_scenario(scenario: Scenario) -> Scenario:
    """The three-update copy of `scenario` that warm_up flies (module docstring)."""
    d = copy.deepcopy(scenario.data)
    rate = float(d["navigator"]["rate_hz"])
    d["duration_s"] = 3.0 / rate
    settings = d["navigator"].setdefault("settings", {})
    if d["navigator"]["name"] in ("ins_tercom",):
        settings["fix_period_s"] = 2.0 / rate    # after the last GNSS fix (first update): due at the third
        settings["min_samples"] = 1
    d["gnss"]["outages"] = [{"start_s": 1.5 / rate}]
    return Scenario(name=f"{scenario.name}[warm-up]", source=scenario.source, data=d,
                    description=scenario.description, seed=scenario.seed, duration_s=d["duration_s"],
                    extras=scenario.extras)


def warm_up(scenario: Scenario, dems) -> float:
    """Fly warm_up_scenario(scenario) over `dems` (world, map) in this process; returns the wall seconds."""
    from trn_env.sim.closed_loop import ClosedLoop
    t0 = time.perf_counter()
    loop = ClosedLoop(warm_up_scenario(scenario), dems=dems, log_sensors=False, pipeline=False)
    try:
        loop.run()
    finally:
        loop.close()
    return time.perf_counter() - t0
