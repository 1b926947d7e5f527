"""`trn-env bench`: throughput figures from one run, each beside its reference measured in the same run.

Collects the component benchmarks (trn_env.bench.flight, trn_env.terrain.bench, trn_env.bench.sensors,
trn_env.bench.navigators, trn_env.bench.env - the env, a 2-env SubprocVecEnv and the route planner -,
trn_env.bench.fast_env - TerrainNavFast-v0 at N = 256 beside TerrainNav-v0 and bare JSBSim: each a
`benchmark(...) -> dict`) and adds the closed-loop figures measured here:

- closed_loop_steps_per_s: JSBSim steps per wall second of the full default-scenario loop (flight,
  sensors, navigator, guidance, termination checks, logging);
- closed_loop_jsbsim_reference_steps_per_s: a bare `fdm.run()` loop of the same aircraft, trimmed at the
  same initial condition, timed just before and just after the closed loop (the faster is kept);
- closed_loop_ratio: their ratio (target >= 0.5);
- closed_loop_ms_per_tick_by_stage: where a loop tick's wall time goes - one navigator update, with
  closed_loop_guidance_ticks_per_tick guidance ticks inside it - (flight core, sensors, navigator - TERCOM
  fixes amortised, closed_loop_tercom_fixes of them fall in the timed window - guidance between updates,
  the rest of the loop: termination checks, logging, guidance after the update), beside
  closed_loop_ms_per_tick and the bare JSBSim time for the same steps (closed_loop_bare_jsbsim_ms_per_tick).
  Everything runs single-threaded.
"""

from __future__ import annotations

import importlib
import inspect
import math
import time
import traceback

import numpy as np


def _component(module: str, quick: bool) -> dict:
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        return {f"{module}.error": f"not available: {exc}"}
    fn = getattr(mod, "benchmark", None)
    if fn is None:
        return {f"{module}.error": "no benchmark() function"}
    kwargs = {"quick": quick} if "quick" in inspect.signature(fn).parameters else {}
    try:
        out = fn(**kwargs)
    except Exception as exc:  # noqa: BLE001 - a failing component must not hide the others' figures
        return {f"{module}.error": f"{type(exc).__name__}: {exc}",
                f"{module}.traceback": traceback.format_exc()}
    return dict(out)


def bare_jsbsim_steps_per_s(fdm, n_steps: int) -> float:
    """Steps per second of a bare `run()` loop on an already initialised FGFDMExec."""
    run = fdm.run
    t0 = time.perf_counter()
    for _ in range(n_steps):
        run()
    return n_steps / (time.perf_counter() - t0)


def closed_loop_benchmark(quick: bool = False, scenario: str = "default", sim_s: float | None = None) -> dict:
    """Full closed loop of `scenario` (sim_s seconds after a 45 s warm-up) vs a bare JSBSim loop at the same
    initial condition: pipelined as `trn-env fly` runs it (the closed_loop_* keys), then inline in one
    process (closed_loop_*_inline), both in this run."""
    out = _closed_loop_figures(quick, scenario, sim_s, pipeline=True)
    inline = _closed_loop_figures(quick, scenario, sim_s, pipeline=False)
    for key in ("closed_loop_steps_per_s", "closed_loop_ratio", "closed_loop_ratio_by_segment",
                "closed_loop_ms_per_tick", "closed_loop_ms_per_tick_by_stage"):
        out[key + "_inline"] = inline[key]
    return out


def _closed_loop_figures(quick: bool, scenario: str, sim_s: float | None, pipeline: bool,
                         segments: int = 3) -> dict:
    """sim_s seconds of the loop in `segments` equal segments, each right after a bare JSBSim run of the same
    number of steps: the ratio is the median of the segments' ratios, so a slow spell of the machine (other
    processes) spoils one segment, not the figure. With the default 120 s, each 40 s segment holds one
    TERCOM fix of the default scenario."""
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import ClosedLoop

    sim_s = sim_s or (40.0 if quick else 120.0)
    warm_s = 45.0       # past the first TERCOM fix (40 s), whose first call loads its kernels
    sc = load_scenario(scenario, duration_s=warm_s + sim_s + 20.0)
    with ClosedLoop(sc, log_sensors=True, pipeline=pipeline) as loop:
        # bare reference: a second flight at the same (trimmed) initial condition, run() only
        import trn_env.scenario.build as components
        ref_flight = components.build_flight(sc, loop.world_dem, np.random.default_rng(0))
        # warm-up (numba dispatch, first sensor, navigator and fix calls), not timed
        for _ in range(int(round(warm_s / (loop.steps_per_tick * loop.dt_s)))):
            loop.tick()
        loop.sync()
        seg_steps = int(round(sim_s / segments / loop.dt_s))
        steps0 = loop.jsbsim_steps
        fixes0 = loop.navigator_fixes
        stage0 = dict(loop.stage_s)
        wall = bare_wall = 0.0
        ratios = []
        for _ in range(segments):
            bare_s = seg_steps / bare_jsbsim_steps_per_s(ref_flight.fdm, seg_steps)
            s0 = loop.jsbsim_steps
            t0 = time.perf_counter()
            while loop.termination is None and (loop.jsbsim_steps - s0) < seg_steps:
                loop.tick()
            loop.sync()
            loop_s = time.perf_counter() - t0
            ratios.append(bare_s / loop_s * (loop.jsbsim_steps - s0) / seg_steps)
            wall += loop_s
            bare_wall += bare_s
        bare = segments * seg_steps / bare_wall
        steps = loop.jsbsim_steps - steps0
        n_fixes = loop.navigator_fixes - fixes0
        ticks = steps // loop.steps_per_tick
        cl = steps / wall if wall > 0 else math.nan
        return {
            "closed_loop_steps_per_s": cl,
            "closed_loop_jsbsim_reference_steps_per_s": bare,
            "closed_loop_ratio": float(np.median(ratios)),
            "closed_loop_ratio_by_segment": [round(r, 3) for r in ratios],
            "closed_loop_realtime_factor": steps * loop.dt_s / wall if wall > 0 else math.nan,
            "closed_loop_pipelined": loop.pipelined,
            "closed_loop_scenario": scenario,
            "closed_loop_navigator": sc.navigator_name,
            "closed_loop_sim_seconds": steps * loop.dt_s,
            "closed_loop_steps_per_tick": loop.steps_per_tick,
            "closed_loop_guidance_ticks_per_tick": loop.guidance_ticks_per_tick,
            "closed_loop_ms_per_tick": 1e3 * wall / max(ticks, 1),
            "closed_loop_bare_jsbsim_ms_per_tick": 1e3 * loop.steps_per_tick / bare if bare > 0 else math.nan,
            "closed_loop_ms_per_tick_by_stage": {k: round(1e3 * (v - stage0[k]) / max(ticks, 1), 4)
                                                 for k, v in loop.stage_s.items()},
            "closed_loop_tercom_fixes": n_fixes,
        }


def run_all(quick: bool = False) -> dict:
    """Every figure, as one flat dict (the JSON `trn-env bench` prints)."""
    out: dict = {}
    for module in ("trn_env.bench.flight", "trn_env.terrain.bench", "trn_env.bench.sensors",
                   "trn_env.bench.navigators", "trn_env.bench.campaign", "trn_env.bench.acq_track",
                   "trn_env.bench.rbpf", "trn_env.bench.filters", "trn_env.bench.integrity",
                   "trn_env.bench.env", "trn_env.bench.fast_env"):
        out.update(_component(module, quick))
    for name, fn in (("closed_loop", closed_loop_benchmark),):
        try:
            out.update(fn(quick))
        except Exception as exc:  # noqa: BLE001
            out[f"{name}.error"] = f"{type(exc).__name__}: {exc}"
            out[f"{name}.traceback"] = traceback.format_exc()
    out["quick"] = bool(quick)
    return out
