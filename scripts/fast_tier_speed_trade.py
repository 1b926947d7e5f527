"""Measure the King Air's true-airspeed trade against vertical speed in the full JSBSim loop on the fast
tier's reference routes (trn_env.env.fast.calibration.REFERENCE_ROUTES, at the route task's full-tier
settings): the figures `tas_per_vs` and `tas_tau_s` of trn_env.env.fast.envelope.KINGAIR_ENVELOPE.

    python scripts/fast_tier_speed_trade.py --seeds 2 [--routes jacksboro_sw_ne basin_west] [--out F.json]

Per route and seed the episode's truth (JSBSim at 50 Hz: true airspeed and vertical speed) is recorded and
the least-squares fit TAS - tas_mps = -tas_per_vs x VS (lagged by tas_tau_s) is made over all of it
(envelope.fit_speed_trade); prints the fit per route and pooled, and the mean true airspeed binned by
vertical speed. Exit 2 on an unknown route or --seeds < 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def fly_truth(route_name: str, seeds) -> list[np.ndarray]:
    """Per seed the full loop's truth along the route: rows (t s, true airspeed m/s, vertical speed m/s
    up)."""
    from trn_env.env.fast import calibration as cal
    from trn_env.env.terrain_nav import TerrainNavEnv

    r = cal.route_by_name(route_name)
    env = TerrainNavEnv(**{**cal.env_kwargs(r), **cal.full_tier_settings(), "pipeline": False})
    a = np.asarray(r.action, np.float32)
    out = []
    for s in seeds:
        env.reset(seed=int(s), options={"start_deg": r.start_deg})
        loop = env._loop
        rows = []
        tick = loop.tick

        def recording_tick(loop=loop, tick=tick, rows=rows):
            reason = tick()
            tr = loop.last_truth       # the JSBSim steps this tick flew
            rows.append(np.column_stack([tr.t_s, tr.tas_mps, -tr.v_ned_mps[:, 2]]))
            return reason

        loop.tick = recording_tick
        while True:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                break
        out.append(np.concatenate(rows))
    env.close()
    return out


def main(argv=None) -> int:
    from trn_env.env.fast.calibration import REFERENCE_ROUTES
    from trn_env.env.fast.envelope import KINGAIR_ENVELOPE, fit_speed_trade

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 per route (default 2)")
    p.add_argument("--routes", nargs="*", default=None, help="route names (default: all)")
    p.add_argument("--out", type=Path, default=None, help="write the fits (JSON) here")
    args = p.parse_args(argv)
    known = [r.name for r in REFERENCE_ROUTES]
    names = args.routes or known
    bad = [n for n in names if n not in known]
    if bad or args.seeds < 1:
        print(f"--routes: each one of {known} (got {bad}); --seeds >= 1", file=sys.stderr)
        return 2
    tas0 = KINGAIR_ENVELOPE.tas_mps
    fits, pooled = {}, []
    for name in names:
        runs = fly_truth(name, range(args.seeds))
        pooled += runs
        k, tau = fit_speed_trade(runs, tas0)
        fits[name] = {"tas_per_vs": k, "tas_tau_s": tau, "rows": int(sum(len(x) for x in runs))}
        print(f"{name}: tas_per_vs {k:.3f}, tas_tau_s {tau:.1f} s", flush=True)
    k, tau = fit_speed_trade(pooled, tas0)
    fits["pooled"] = {"tas_per_vs": k, "tas_tau_s": tau}
    print(f"pooled: tas_per_vs {k:.3f}, tas_tau_s {tau:.1f} s (stated {KINGAIR_ENVELOPE.tas_per_vs}, "
          f"{KINGAIR_ENVELOPE.tas_tau_s} s)")
    x = np.concatenate(pooled)
    print("| vertical speed (m/s) | samples | mean true airspeed (m/s) |\n|---|---|---|")
    for lo in range(-8, 8, 2):
        m = (x[:, 2] >= lo) & (x[:, 2] < lo + 2)
        if m.any():
            print(f"| {lo} to {lo + 2} | {int(m.sum())} | {x[m, 1].mean():.1f} |")
    if args.out is not None:
        args.out.write_text(json.dumps(fits, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
