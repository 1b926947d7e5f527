"""Measure the King Air's true-airspeed trade against vertical speed in the full JSBSim loop on the fast
tier's reference routes (trn_env.env.fast.calibration.REFERENCE_ROUTES, at the route task's full-tier
settings): the figures `tas_per_vs` and `tas_tau_s` of trn_env.env.fast.envelope.KINGAIR_ENVELOPE.

    python scripts/fast_tier_speed_trade.py --seeds 4 [--routes jacksboro_sw_ne basin_west] [--out F.json]

Per route and seed the episode's truth (JSBSim at 50 Hz: true airspeed and vertical speed) is recorded and
the least-squares fit TAS - tas_mps = -tas_per_vs x VS (lagged by tas_tau_s) is made over all of it
(envelope.fit_speed_trade); prints the fit per route and pooled, the mean true airspeed binned by
vertical speed, and the seed-to-seed spread of the ground speed less the fit (envelope.seed_spread) with
the wander it implies beyond the fast tier's gusts (envelope.wander_from_spread: tas_wander_mps,
tas_wander_tau_s). Exit 2 on an unknown route or --seeds < 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from trn_env.output.run_folder import file_target_problem


def fly_truth(route_name: str, seeds) -> list[np.ndarray]:
    """Per seed the full loop's truth along the route: rows (t s, true airspeed m/s, vertical speed m/s
    up, horizontal ground speed m/s)."""
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
            rows.append(np.column_stack([tr.t_s, tr.tas_mps, -tr.v_ned_mps[:, 2],
                                         np.hypot(tr.v_ned_mps[:, 0], tr.v_ned_mps[:, 1])]))
            return reason

        loop.tick = recording_tick
        while True:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                break
        out.append(np.concatenate(rows))
    env.close()
    return out


def _lagged(vs: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    a = 1.0 - np.exp(-dt_s / tau_s)
    out = np.empty_like(vs)
    acc = 0.0
    for k in range(vs.size):
        acc += a * (vs[k] - acc)
        out[k] = acc
    return out


def main(argv=None) -> int:
    from trn_env.env.fast.calibration import REFERENCE_ROUTES
    from trn_env.env.fast.envelope import (
        KINGAIR_ENVELOPE,
        fit_speed_trade,
        seed_spread,
        wander_from_spread,
    )
    from trn_env.env.fast.kernel_params import TURBULENCE_LENGTH_M, TURBULENCE_SIGMA_MPS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 per route (default 2)")
    p.add_argument("--routes", nargs="*", default=None, help="route names (default: all)")
    p.add_argument("--out", type=Path, default=None, help="write the fits (JSON) here")
    args = p.parse_args(argv)
    if args.out is not None and (problem := file_target_problem(args.out, "--out")):
        p.error(problem)       # checked before the work, not after it
    known = [r.name for r in REFERENCE_ROUTES]
    names = args.routes or known
    bad = [n for n in names if n not in known]
    if bad:
        print(f"error: --routes: unknown {bad}; known: {known}", file=sys.stderr)
        return 2
    if args.seeds < 2:
        print(f"error: --seeds: at least 2 (the spread is over seeds), got {args.seeds}", file=sys.stderr)
        return 2
    tas0 = KINGAIR_ENVELOPE.tas_mps
    fits, pooled, by_route = {}, [], {}
    for name in names:
        runs = fly_truth(name, range(args.seeds))
        pooled += runs
        by_route[name] = runs
        k, tau = fit_speed_trade(runs, tas0)
        fits[name] = {"tas_per_vs": k, "tas_tau_s": tau, "rows": int(sum(len(x) for x in runs))}
        print(f"{name}: tas_per_vs {k:.3f}, tas_tau_s {tau:.1f} s", flush=True)
    k, tau = fit_speed_trade(pooled, tas0)
    fits["pooled"] = {"tas_per_vs": k, "tas_tau_s": tau}
    print(f"pooled: tas_per_vs {k:.3f}, tas_tau_s {tau:.1f} s (stated {KINGAIR_ENVELOPE.tas_per_vs}, "
          f"{KINGAIR_ENVELOPE.tas_tau_s} s)")
    # the seed-to-seed spread of the horizontal ground speed less the fitted trade, per route, pooled
    var_sum = vt_sum = 0.0
    for name, runs in by_route.items():
        res = []
        for x in runs:
            step = max(1, int(round(1.0 / (x[1, 0] - x[0, 0]))))
            lagged = _lagged(x[:, 2], x[1, 0] - x[0, 0], tau)
            res.append((x[:, 3] - (tas0 - k * lagged))[::step])
        n = min(len(r) for r in res)
        var, t_int = seed_spread([r[:n] for r in res])
        fits[name].update(ground_speed_spread_var=var, ground_speed_spread_t_int_s=t_int)
        print(f"{name}: ground-speed spread over the seeds {var ** 0.5:.2f} m/s, time scale {t_int:.1f} s")
        var_sum += var
        vt_sum += var * t_int
    var, t_int = var_sum / len(by_route), vt_sum / var_sum
    gust = TURBULENCE_SIGMA_MPS["light"]
    w, w_tau = wander_from_spread(var, t_int, gust, TURBULENCE_LENGTH_M / tas0)
    fits["pooled"].update(tas_wander_mps=w, tas_wander_tau_s=w_tau)
    print(f"pooled spread {var ** 0.5:.2f} m/s, {t_int:.1f} s; beyond the fast tier's light gust: "
          f"tas_wander_mps {w:.2f}, tas_wander_tau_s {w_tau:.0f} s (stated "
          f"{KINGAIR_ENVELOPE.tas_wander_mps}, {KINGAIR_ENVELOPE.tas_wander_tau_s} s)")
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
