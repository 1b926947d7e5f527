"""The true horizontal error at each 30 s decision of a reference route, fast tier against the full loop's
recorded `errors_by_decision_m` (scripts/calibrate_fast_tier.py --tier full --out DIR): mean, 90th
percentile and the episodes still flying, per decision; where along a route the tiers part.

    python scripts/fast_tier_by_decision.py --out DIR --route jacksboro_sw_ne [--fix-noise batch]

Prints a markdown table. Exit 2 on an unknown route, a missing or malformed DIR/full_<route>.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def fast_by_decision(name: str, n: int, fix_noise: str = "fixed") -> list[list[float]]:
    """The fast tier's true horizontal error (m) at every decision of route `name`, seeds 0..n-1, with the
    navigator's fix_noise (calibration.env_kwargs)."""
    from trn_env.env.fast import calibration as cal
    from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv

    r = cal.route_by_name(name)
    env = TerrainNavFastVectorEnv(num_envs=n, **cal.env_kwargs(r, fix_noise))
    env.reset(seed=list(range(n)), options={"start_deg": r.start_deg})
    a = np.tile(np.asarray(r.action, np.float32), (n, 1))
    by: list[list[float]] = [[] for _ in range(n)]
    done = np.zeros(n, bool)
    while not done.all():
        _, _, term, trunc, info = env.step(a)
        for i in np.flatnonzero(~done):
            by[i].append(float(info["true_horizontal_error_m"][i]))
        done |= term | trunc
    env.close()
    return by


def main(argv=None) -> int:
    from trn_env.env.fast.calibration import REFERENCE_ROUTES

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="directory of the full loop's full_<route>.json")
    p.add_argument("--route", required=True)
    p.add_argument("--fast-seeds", type=int, default=256)
    p.add_argument("--fix-noise", choices=("fixed", "batch"), default="fixed",
                   help="the fast tier's TERCOM fix noise (as the full loop's in DIR was flown)")
    args = p.parse_args(argv)
    known = [r.name for r in REFERENCE_ROUTES]
    if args.route not in known:
        print(f"--route: unknown {args.route!r}; known: {known}", file=sys.stderr)
        return 2
    if args.fast_seeds < 1:
        print("--fast-seeds must be >= 1", file=sys.stderr)
        return 2
    path = args.out / f"full_{args.route}.json"
    try:
        full = json.loads(path.read_text())["errors_by_decision_m"]
    except (OSError, ValueError, KeyError) as exc:
        print(f"{path}: no full-loop errors_by_decision_m ({exc})", file=sys.stderr)
        return 2
    fast = fast_by_decision(args.route, args.fast_seeds, args.fix_noise)
    print("| decision | fast mean / p90 (m) | fast episodes | full mean / p90 (m) | full episodes |")
    print("|---|---|---|---|---|")
    for k in range(max(max(map(len, fast)), max(map(len, full)))):
        f = [b[k] for b in fast if len(b) > k]
        g = [b[k] for b in full if len(b) > k]
        cell = [f"{np.mean(x):.1f} / {np.percentile(x, 90):.1f} | {len(x)}" if x else "- | 0" for x in (f, g)]
        print(f"| {k} | {cell[0]} | {cell[1]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
