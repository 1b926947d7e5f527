"""Fingerprint of TerrainNav-v0's and the closed loop's outputs, to check that a speed-up kept the bits.

    python scripts/env_bits_check.py            # envs and two closed-loop scenarios (~10-30 s of CPU)
    python scripts/env_bits_check.py --quick    # the basin envs only

Prints one sha256 (first 16 hex digits) per item: every observation, reward, termination flag and info of
TerrainNav-v0 at the route task's settings (`route_task.env_kwargs`: basin seeds 3 and 11, jacksboro seed 5,
basin with the opt-in decision rates seed 7; 16 random pursuit decisions, actions from a fixed generator),
and the log arrays and summary (wall-clock keys left out) of `run_scenario("default", duration_s=300)` and
`run_scenario("basin_route", duration_s=240)`, seed 3, not pipelined. Run it before and after a change:
the same lines mean the same bits.
"""

from __future__ import annotations

import argparse
import hashlib
import sys

import numpy as np

WALL_KEYS = ("wall_time_s", "realtime_factor", "closed_loop_steps_per_s", "wall_time_by_stage_s")


def _feed(h, x) -> None:
    if isinstance(x, dict):
        for k in sorted(x, key=str):
            h.update(str(k).encode())
            _feed(h, x[k])
    elif isinstance(x, (list, tuple)):
        for v in x:
            _feed(h, v)
    elif isinstance(x, np.ndarray):
        h.update(str(x.dtype).encode())
        h.update(np.ascontiguousarray(x).tobytes())
    elif isinstance(x, (float, np.floating)):
        h.update(np.float64(x).tobytes())
    else:
        h.update(repr(x).encode())


def fingerprints(quick: bool = False) -> dict[str, str]:
    from trn_env.env.route_task import env_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv

    out = {}
    cases = (("basin", False, (3, 11)), ("jacksboro", False, (5,)), ("basin", True, (7,)))
    for terrain, rates, seeds in cases:
        if quick and terrain != "basin":
            continue
        env = TerrainNavEnv(**env_kwargs(terrain, decision_rates=rates))
        h = hashlib.sha256()
        rng = np.random.default_rng(42)
        for s in seeds:
            obs, info = env.reset(seed=s)
            _feed(h, (obs, info))
            for _ in range(16):
                obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
                _feed(h, (obs, r, info, term, trunc))
                if term or trunc:
                    break
        env.close()
        out[f"env {terrain}{' decision_rates' if rates else ''} seeds {list(seeds)}"] = h.hexdigest()[:16]
    if not quick:
        from trn_env.sim.closed_loop import run_scenario

        for name, duration_s in (("default", 300.0), ("basin_route", 240.0)):
            res = run_scenario(name, duration_s=duration_s, pipeline=False, seed=3)
            h = hashlib.sha256()
            _feed(h, res.arrays)
            _feed(h, {k: v for k, v in res.summary.items() if k not in WALL_KEYS})
            out[f"scenario {name} {duration_s:.0f} s seed 3"] = h.hexdigest()[:16]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="the basin envs only")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    for k, v in fingerprints(args.quick).items():
        print(f"{v}  {k}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
