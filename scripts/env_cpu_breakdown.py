"""Where TerrainNav-v0's CPU goes at the route task's settings: CPU ms per 30 s decision by component.

    python scripts/env_cpu_breakdown.py [--decisions 60] [--config '{"scenario_fields": {}}']

The route task's basin env (`route_task.env_kwargs("basin")` plus `--config`, TerrainNav-v0 keyword
arguments as JSON), 4 warm-up decisions, then `--decisions` random pursuit decisions from reset(seed=5)
(episodes restarted when they end). Each component is timed by a wrapper around its entry point: thread CPU
time (`time.thread_time`) for the flight core's record and conversion, the sensors, the IRA's terrain
search, the MAD accumulation and the INS + covariance kernel; process CPU time for the env's step, the
navigator's update and the MAD surface at a fix (its second thread counted); each sensor's sampling
("sensor: imu", ...), the loop's guidance commands, interval plans, estimate collection and truth checks,
the env's observation (thread CPU). Then JSBSim alone on the same aircraft: `run()` per step, run + the
recorded property reads, the reads alone (µs per step). Then the bench's gym reference loops
(`trn_env.bench.env._gym_jsbsim_rates`, `--ref-s` wall seconds each): CPU ms per simulated 30 s of the King
Air in gymnasium-jsbsim's shape at its 60 Hz (the target's reference) and at the scenario's 100 Hz, beside
the env's. Bad arguments: a message and exit 2.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time

import numpy as np


def breakdown(settings: dict, decisions: int, ref_s: float = 3.0) -> dict[str, float]:
    from trn_env.navigators.filters import ins_trn_ekf, ins_trn_propagation
    from trn_env.navigators.tercom import mad

    from trn_env.bench.env import _gym_jsbsim_rates
    from trn_env.env import terrain_nav
    from trn_env.env.route_task import env_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv
    from trn_env.flight import core as fcore
    from trn_env.sensors import ira as sira
    from trn_env.sensors import suite
    from trn_env.sim import closed_loop

    tot: dict[str, float] = {}
    undo = []

    def wrap(owner, name, key, clock=time.thread_time):
        f = getattr(owner, name)
        undo.append((owner, name, f))

        @functools.wraps(f)
        def g(*a, **k):
            t0 = clock()
            try:
                return f(*a, **k)
            finally:
                tot[key] = tot.get(key, 0.0) + clock() - t0
        setattr(owner, name, g)

    wrap(TerrainNavEnv, "step", "env step (all)", time.process_time)
    wrap(fcore.Flight, "record", "flight: JSBSim run + record")
    wrap(fcore.Flight, "take", "flight: conversion to truth")
    wrap(suite.SensorSuite, "sample", "sensors (all)")
    wrap(sira.queries, "ira_return", "sensors: IRA terrain search")
    wrap(ins_trn_ekf.InsTrnNavigator, "update", "navigator (all, both threads)", time.process_time)
    wrap(mad.MadAccumulator, "add", "navigator: MAD accumulation")
    wrap(mad.MadAccumulator, "surface", "navigator: MAD surface at fixes (both threads)", time.process_time)
    wrap(ins_trn_propagation.kern, "fused_segment", "navigator: INS + covariance kernel")
    wrap(closed_loop.ClosedLoop, "command_now", "loop: guidance commands")
    wrap(closed_loop.ClosedLoop, "_plan_guidance", "loop: interval plans")
    wrap(closed_loop.ClosedLoop, "_collect", "loop: estimate collection")
    wrap(closed_loop.ClosedLoop, "_truth_reason", "loop: truth checks")
    wrap(terrain_nav.TerrainNavEnv, "_obs", "env: observation")
    models = dict(suite.SENSOR_MODELS)       # the suite binds each model's sample function when it is built
    for name, m in models.items():
        holder = type("_Holder", (), {"sample": staticmethod(m.sample)})
        wrap(holder, "sample", f"sensor: {name}")
        suite.SENSOR_MODELS[name] = suite.SensorModel(m.config_cls, holder.sample, m.needs_terrain)
    try:
        env = TerrainNavEnv(**{**env_kwargs("basin"), **settings})
        env.reset(seed=0)
        for _ in range(4):
            *_, term, trunc, _ = env.step(np.zeros(2, np.float32))
            if term or trunc:
                env.reset()
        tot.clear()
        rng = np.random.default_rng(0)
        env.reset(seed=5)
        sim_s = 0.0
        for _ in range(decisions):
            t0 = env._loop.t_s
            _, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            sim_s += env._loop.t_s - t0
            if term or trunc:
                env.reset()
        fl = env._loop.flight
        fdm, getters = fl.fdm, fl._getters
        n = 3000
        buf = np.empty(n * len(getters))
        c0 = time.process_time()
        for _ in range(n):
            fdm.run()
        c1 = time.process_time()
        fl._recorder(n, fdm.run, buf, 0, getters)
        c2 = time.process_time()
        for _ in range(n):
            for g in getters:
                g()
        c3 = time.process_time()
        env.close()
    finally:
        for owner, name, f in undo:
            setattr(owner, name, f)
        suite.SENSOR_MODELS.update(models)
    out = {k: 1e3 * v / sim_s * 30.0 for k, v in sorted(tot.items())}
    refs = {"gym loop: King Air 60 Hz (reference)": {}, "gym loop: King Air 100 Hz": {"dt_s": 0.01}}
    for key, kw in refs.items():
        out[key] = 30e3 / max(_gym_jsbsim_rates(ref_s, **kw)[1], _gym_jsbsim_rates(ref_s, **kw)[1])
    out["simulated_s"] = sim_s
    out["jsbsim_run_us_per_step"] = 1e6 * (c1 - c0) / n
    out["jsbsim_run_and_record_us_per_step"] = 1e6 * (c2 - c1) / n
    out["jsbsim_property_reads_us_per_step"] = 1e6 * (c3 - c2) / n
    out["load_average_1min"] = os.getloadavg()[0]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--decisions", type=int, default=60, help="timed decisions (default 60)")
    p.add_argument("--config", default="{}", help="TerrainNav-v0 keyword arguments over the task's (JSON)")
    p.add_argument("--ref-s", type=float, default=3.0, help="wall seconds per gym reference run (default 3)")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        if args.decisions < 1:
            raise ValueError(f"--decisions must be >= 1, got {args.decisions}")
        if not args.ref_s > 0.0:
            raise ValueError(f"--ref-s must be > 0, got {args.ref_s}")
        try:
            settings = json.loads(args.config)
        except json.JSONDecodeError as err:
            raise ValueError(f"--config is not JSON: {err}") from None
        if not isinstance(settings, dict):
            raise ValueError(f"--config must be a JSON object, got {args.config!r}")
        out = breakdown(settings, args.decisions, args.ref_s)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"{out.pop('simulated_s'):.0f} simulated s, load {out.pop('load_average_1min'):.1f}")
    for k, v in out.items():
        unit = "us" if k.startswith("jsbsim") else "ms CPU per 30 s decision"
        print(f"  {k:50s} {v:7.2f} {unit}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
