"""Throughput and memory of the terrain filters in the default closed loop, beside the EKF and bare JSBSim.

For each navigator - `pmf` (200 x 200 grid), `pf` (10,000 particles) and the reference `ins_tercom` (INS +
TERCOM + EKF) - the default scenario flies pipelined, as `trn-env fly --navigator NAME` runs it (sensors and
navigator in a second process beside the flight), after a warm-up; figures: simulated seconds per wall
second (`filters_<name>_sim_s_per_wall_s`) and that over the EKF loop's, measured in the same run
(`filters_<name>_vs_ins_tercom`); bare JSBSim's simulated seconds per wall second at the same initial
condition (`filters_bare_jsbsim_sim_s_per_wall_s`, a `run()` loop timed right after each navigator's loop).
Memory: the peak of Python/numpy allocations (tracemalloc) while the navigator runs 40 s of the loop's
frames inline (`filters_<name>_peak_mb`), and what it still holds after 20 and after 40 updates
(`filters_<name>_held_mb_after_20` / `_after_40`: equal when it keeps no per-step history).
"""

from __future__ import annotations

import copy
import dataclasses
import gc
import time
import tracemalloc

import numpy as np

NAVIGATORS = {"pmf": {"grid_size": 200}, "pf": {"n_particles": 10_000}, "ins_tercom": {"remove_bias": True}}


def _loop_rate(name: str, settings: dict, warm_s: float, sim_s: float,
               dems=None) -> tuple[float, float, tuple]:
    from trn_env.bench.runner import bare_jsbsim_steps_per_s
    from trn_env.scenario import build as components
    from trn_env.scenario.loading import load_scenario
    from trn_env.scenario.sections import NavigatorSection
    from trn_env.sim.closed_loop import ClosedLoop
    sc = load_scenario("default", navigator=name, duration_s=warm_s + sim_s + 10.0)
    nav = NavigatorSection.of(name, settings, rate_hz=sc.navigator.rate_hz,
                              latency_updates=sc.navigator.latency_updates)
    sc = dataclasses.replace(sc, sections=dataclasses.replace(sc.sections, navigator=nav))
    with ClosedLoop(sc, pipeline=True, log_sensors=False, dems=dems) as loop:
        dems = (loop.world_dem, loop.map_dem)
        while loop.t_s < warm_s and loop.termination is None:
            loop.tick()
        loop.sync()
        t_start = loop.t_s
        w0 = time.perf_counter()
        while loop.t_s < t_start + sim_s and loop.termination is None:
            loop.tick()
        loop.sync()
        rate = (loop.t_s - t_start) / (time.perf_counter() - w0)
        ref = components.build_flight(sc, loop.world_dem, np.random.default_rng(0))
        steps = int(round(sim_s / loop.dt_s))
        bare = bare_jsbsim_steps_per_s(ref.fdm, steps) * loop.dt_s
    return rate, bare, dems


def _memory(name: str, settings: dict, dems, n_frames: int = 40) -> dict:
    """Peak and held allocations (MB) of the navigator over n_frames of the default loop's frames."""
    from trn_env.navigators import registry
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario("default", navigator="ins", duration_s=n_frames + 5.0)
    frames = []
    with ClosedLoop(sc, pipeline=False, log_sensors=False, dems=dems) as loop:
        nav_ins = loop._stage.navigator
        real = nav_ins.update

        def spy(fr):
            frames.append(copy.deepcopy(fr))
            return real(fr)

        nav_ins.update = spy
        init = copy.deepcopy(loop.estimate)
        while len(frames) < n_frames and loop.termination is None:
            loop.tick()
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    # the rng reaches only a navigator whose capabilities say takes_rng
    nav = registry.create(name, dem=dems[1], rng=np.random.default_rng(0), **settings)
    nav.reset(init)
    held = []
    for k, fr in enumerate(frames):
        nav.update(fr)
        if k + 1 in (n_frames // 2, n_frames):
            gc.collect()
            held.append((tracemalloc.get_traced_memory()[0] - base) / 2**20)
    peak = (tracemalloc.get_traced_memory()[1] - base) / 2**20
    tracemalloc.stop()
    return {f"filters_{name}_peak_mb": peak, f"filters_{name}_held_mb_after_{n_frames // 2}": held[0],
            f"filters_{name}_held_mb_after_{n_frames}": held[1]}


def benchmark(quick: bool = False) -> dict:
    warm_s, sim_s = (10.0, 20.0) if quick else (20.0, 60.0)
    out: dict = {"filters_sim_seconds_timed": sim_s}
    dems = None
    bare = []
    for name, settings in NAVIGATORS.items():
        rate, b, dems = _loop_rate(name, settings, warm_s, sim_s, dems)
        out[f"filters_{name}_sim_s_per_wall_s"] = rate
        bare.append(b)
    out["filters_bare_jsbsim_sim_s_per_wall_s"] = float(max(bare))
    for name in ("pmf", "pf"):
        out[f"filters_{name}_vs_ins_tercom"] = (out[f"filters_{name}_sim_s_per_wall_s"]
                                                / out["filters_ins_tercom_sim_s_per_wall_s"])
    for name in ("pmf", "pf"):
        out.update(_memory(name, NAVIGATORS[name], dems, 20 if quick else 40))
    return out


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(benchmark(quick="--quick" in sys.argv), indent=1))
