"""Calibrate the fast tier (TerrainNavFast-v0) against the full JSBSim loop (TerrainNav-v0) on the reference
routes of trn_env.env.fast.calibration: the true horizontal error at the goal, mean and 90th percentile over
seeds, per route, in both tiers, with the same navigator family (the scenario's INS + batch TERCOM); the
full loop at the route task's full-tier settings (calibration.full_tier_settings(): JSBSim at 50 Hz).

    python scripts/calibrate_fast_tier.py --out out/fast_calibration                  # both tiers
    python scripts/calibrate_fast_tier.py --tier full --out DIR                       # only the full loop
    python scripts/calibrate_fast_tier.py --tier fast --out DIR                       # fast vs saved full
    python scripts/calibrate_fast_tier.py --fix-noise batch ...     # both tiers with the batch fix covariance

The full loop flies seeds 0..--seeds-1, the fast tier 0..--fast-seeds-1 (both default 256,
calibration.FAST_SEEDS, as the recorded references: the turning routes' 90th percentiles hang on a few
episodes; the full loop takes ~1.5-3 min per route on an idle 2-core machine).

Writes DIR/full_<route>.json, DIR/fast_<route>.json (per-seed errors, terminations, the navigator's
horizontal sigma per decision and at the end) and DIR/table.md (mean and p90 true miss, the time-out share
and the mean sigma at the end per tier); prints the table.
The full-loop results are reused from DIR when present (--tier fast), so the fast tier can be re-run alone.

    python scripts/calibrate_fast_tier.py --policies planner,straight --policy-seeds 10 --tier fast --out DIR

flies the route task's baselines instead (trn_env.campaign.route_task: basin terrain, its 5 held-out goals x
seeds 1000..1000+N-1) in the tier(s) asked for: DIR/policies_<tier>.json (per-episode rows) and
DIR/policies.md (mean, median, p90 and max true miss per policy and tier).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from trn_env.output.run_folder import folder_problem


def main(argv=None) -> int:
    from trn_env.env.fast.calibration import REFERENCE_ROUTES, compare, fly_fast, fly_full

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=None,
                   help="full-loop seeds 0..N-1 per route (default: calibration.FAST_SEEDS, 256)")
    p.add_argument(
        "--fast-seeds",
        type=int,
        default=None,
        help="fast-tier seeds 0..N-1 per route (default: calibration.FAST_SEEDS, 256)",
    )
    p.add_argument("--routes", nargs="*", default=None, help="route names (default: all)")
    p.add_argument("--tier", choices=("both", "full", "fast"), default="both")
    p.add_argument("--fix-noise", choices=("fixed", "batch"), default="fixed",
                   help="the navigator's TERCOM fix noise in both tiers (default: fixed, the route task's; "
                        "batch: ins_tercom's own default)")
    p.add_argument("--out", type=Path, default=Path("out/fast_calibration"))
    p.add_argument("--policies", default=None,
                   help="comma-separated route-task baselines (straight, planner) to fly, not the routes")
    p.add_argument("--policy-seeds", type=int, default=10, help="seeds per held-out goal with --policies")
    args = p.parse_args(argv)
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        p.error(problem)       # checked before the work, not after it
    if args.policies is not None:
        return _policies(args)
    from trn_env.env.fast.calibration import FAST_SEEDS

    fast_n = FAST_SEEDS if args.fast_seeds is None else args.fast_seeds
    full_n = FAST_SEEDS if args.seeds is None else args.seeds
    if full_n < 1 or fast_n < 1:
        print("--seeds and --fast-seeds must be >= 1", file=sys.stderr)
        return 2
    known = {r.name: r for r in REFERENCE_ROUTES}
    names = args.routes or list(known)
    bad = [n for n in names if n not in known]
    if bad:
        print(f"--routes: unknown {bad}; known: {sorted(known)}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    seeds = {"full": list(range(full_n)), "fast": list(range(fast_n))}
    rows = []
    for name in names:
        r = known[name]
        for tier, fn in (("full", fly_full), ("fast", fly_fast)):
            path = args.out / f"{tier}_{name}.json"
            if args.tier in (tier, "both") and not (tier == "full" and args.tier == "fast" and path.exists()):
                res = fn(r, seeds[tier], fix_noise=args.fix_noise)
                path.write_text(json.dumps({"route": name, "seeds": seeds[tier], **res}, indent=1))
                print(f"{tier} {name}: {res['wall_s']:.1f} s", file=sys.stderr, flush=True)
        fp, qp = args.out / f"full_{name}.json", args.out / f"fast_{name}.json"
        if fp.exists() and qp.exists():
            full, fast = json.loads(fp.read_text()), json.loads(qp.read_text())
            rows.append((r, compare(full, fast), _ends(full), _ends(fast)))
    lines = [
        "| route | kind | terrain | seeds full / fast | full mean / p90 (m) | fast mean / p90 (m) "
        "| mean diff | p90 diff | time-outs full / fast | sigma at the end full / fast (m) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r, c, ef, eq in rows:
        lines.append(
            f"| {r.name} | {r.kind} | {r.scenario} | {c['full']['n']} / {c['fast']['n']} | "
            f"{c['full']['mean_m']:.1f} / "
            f"{c['full']['p90_m']:.1f} | {c['fast']['mean_m']:.1f} / {c['fast']['p90_m']:.1f} | "
            f"{100 * c['mean_rel']:+.0f} % | {100 * c['p90_rel']:+.0f} % | {ef[0]} / {eq[0]} | "
            f"{ef[1]} / {eq[1]} |"
        )
    table = "\n".join(lines)
    (args.out / "table.md").write_text(table + "\n")
    print(table)
    return 0


def _ends(res: dict) -> tuple[str, str]:
    """(time-out share, mean horizontal sigma at the end) of a tier's flights, as text ("-" when the record
    holds no sigma)."""
    ends = res.get("terminations") or []
    timeouts = f"{100.0 * sum(e == 'time_limit' for e in ends) / max(len(ends), 1):.1f} %"
    sig = res.get("sigma_m")
    return timeouts, (f"{sum(sig) / len(sig):.1f}" if sig else "-")


def _policies(args) -> int:
    import numpy as np

    from trn_env.campaign import route_task as rt

    known = {"straight": {"label": "straight", "kind": "straight"},
             "planner": {"label": "planner", "kind": "planner", "config": {"weight": 3.0}}}
    names = [n for n in args.policies.split(",") if n]
    bad = [n for n in names if n not in known]
    if bad or not names or args.policy_seeds < 1:
        print(f"--policies: each one of {sorted(known)}, --policy-seeds >= 1; got {args.policies!r}, "
              f"{args.policy_seeds}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    tiers = ("full", "fast") if args.tier == "both" else (args.tier,)
    seeds = list(range(1000, 1000 + args.policy_seeds))
    lines = ["| policy | tier | episodes | arrived | mean (m) | median (m) | p90 (m) | max (m) |",
             "|---|---|---|---|---|---|---|---|"]
    for tier in tiers:
        rows = rt.evaluate([known[n] for n in names], "basin", seeds, (tier,))
        (args.out / f"policies_{tier}.json").write_text(json.dumps(rows, indent=1, default=str))
        for n in names:
            m = np.array([r["true_miss_m"] for r in rows if r["policy"] == n], float)
            a = m[np.isfinite(m)]
            lines.append(f"| {n} | {tier} | {m.size} | {a.size} | {a.mean():.1f} | {np.median(a):.1f} | "
                         f"{np.percentile(a, 90):.1f} | {a.max():.0f} |")
    table = "\n".join(lines)
    (args.out / "policies.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
