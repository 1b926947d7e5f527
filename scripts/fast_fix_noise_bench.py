"""Same-run cost of the fast tier's batch TERCOM fix covariance: TerrainNavFast-v0 at the fast-env bench's
settings (trn_env.bench.fast_env.SETTINGS, numba's default threads) with the navigator's fix_noise "fixed"
(fix_sigma_m) and "batch" (trn_env.env.fast.fix_noise), interleaved rounds of vector steps; agent steps per
wall and per CPU second (median over rounds) and their ratios, as JSON.

    python scripts/fast_fix_noise_bench.py [--rounds 8] [--num-envs 256] [--steps 20]

Exit 2 on a count below 1.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--num-envs", type=int, default=256)
    p.add_argument("--steps", type=int, default=20, help="vector steps per round")
    args = p.parse_args(argv)
    for name in ("rounds", "num_envs", "steps"):
        if getattr(args, name) < 1:
            print(f"--{name.replace('_', '-')} must be >= 1", file=sys.stderr)
            return 2
    from trn_env.bench.fast_env import SETTINGS
    from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv
    from trn_env.scenario.overrides import load_scenario_with

    n = args.num_envs
    envs = {}
    for mode in ("fixed", "batch"):
        sc = load_scenario_with(SETTINGS["scenario"], [("navigator.settings.fix_noise", mode)])
        e = TerrainNavFastVectorEnv(num_envs=n, **{**SETTINGS, "scenario": sc})
        e.reset(seed=0)
        e.step(np.random.default_rng(0).uniform(-1, 1, (n, 2)).astype(np.float32))  # warm-up
        envs[mode] = e
    res: dict = {m: {"wall": [], "cpu": []} for m in envs}
    rng = np.random.default_rng(1)
    for r in range(args.rounds):
        for mode in ("fixed", "batch") if r % 2 == 0 else ("batch", "fixed"):
            acts = rng.uniform(-1, 1, (args.steps, n, 2)).astype(np.float32)
            t0, c0 = time.perf_counter(), time.process_time()
            for k in range(args.steps):
                envs[mode].step(acts[k])
            res[mode]["wall"].append(n * args.steps / (time.perf_counter() - t0))
            res[mode]["cpu"].append(n * args.steps / (time.process_time() - c0))
    for e in envs.values():
        e.close()
    out = {f"{m}_agent_steps_per_{k}_s": float(np.median(v)) for m, d in res.items() for k, v in d.items()}
    for k in ("wall", "cpu"):
        out[f"ratio_batch_over_fixed_{k}"] = (out[f"batch_agent_steps_per_{k}_s"]
                                              / out[f"fixed_agent_steps_per_{k}_s"])
    out["load_average_1min"] = os.getloadavg()[0]
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
