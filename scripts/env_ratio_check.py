"""TerrainNav-v0's simulated seconds per CPU second at the route task's settings beside the bench's gym
reference loops, for comparing two versions of the env in the same session.

    PYTHONPATH=. python scripts/env_ratio_check.py [--repeats 4] [--ref-s 3]
    PYTHONPATH=/path/to/other/tree python scripts/env_ratio_check.py     # that tree's env, this reference

The env is whichever `trn_env` is imported (PYTHONPATH decides); the reference loops always come from this
script's own tree (`trn_env/bench/env.py` beside it, loaded by path), so two trees are compared against the
same reference. The route task's basin env (`route_task.env_kwargs("basin")`), 3 warm-up decisions, then
`--repeats` x 10 random pursuit decisions from reset(seed=100 + repeat), in CPU time; the King Air gym loop
at 60 Hz (gymnasium-jsbsim's rate) and at 100 Hz, `--ref-s` wall seconds each, before and after the env (the
faster kept). Prints one JSON line: the env's CPU ms per simulated 30 s, the loops' simulated s per CPU s,
the ratios, the load. Bad arguments: a message and exit 2.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


def _reference_module():
    path = Path(__file__).resolve().parents[1] / "trn_env" / "bench" / "env.py"
    spec = importlib.util.spec_from_file_location("_env_ratio_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def measure(repeats: int, ref_s: float) -> dict:
    ref = _reference_module()
    import trn_env
    from trn_env.env.route_task import env_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv

    env = TerrainNavEnv(**env_kwargs("basin"))
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, np.float32))
    rng = np.random.default_rng(0)
    kinds = ({}, {"dt_s": 0.01})
    refs = [ref._gym_jsbsim_rates(ref_s, **k)[1] for k in kinds]
    sim = cpu = 0.0
    for rep in range(repeats):
        c0 = time.process_time()
        env.reset(seed=100 + rep)
        for _ in range(10):
            tb = env._loop.t_s
            *_, term, trunc, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            sim += env._loop.t_s - tb
            if term or trunc:
                env.reset()
        cpu += time.process_time() - c0
    env.close()
    refs = [max(a, ref._gym_jsbsim_rates(ref_s, **k)[1]) for a, k in zip(refs, kinds, strict=True)]
    rate = sim / cpu
    return {"env_code": str(Path(trn_env.__file__).resolve().parents[1]), "env_cpu_ms_per_30s": 30e3 / rate,
            "env_sim_s_per_cpu_s": rate, "king_air_60hz_sim_s_per_cpu_s": refs[0],
            "king_air_100hz_sim_s_per_cpu_s": refs[1], "ratio_60hz": rate / refs[0],
            "ratio_100hz": rate / refs[1], "load_average_1min": os.getloadavg()[0]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=4, help="rounds of 10 decisions (default 4)")
    p.add_argument("--ref-s", type=float, default=3.0, help="wall seconds per reference run (default 3)")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    if args.repeats < 1:
        print(f"error: --repeats must be >= 1, got {args.repeats}", file=sys.stderr)
        return 2
    if not args.ref_s > 0.0:
        print(f"error: --ref-s must be > 0, got {args.ref_s}", file=sys.stderr)
        return 2
    print(json.dumps(measure(args.repeats, args.ref_s)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
