"""TerrainNav-v0's rates and the task's miss: the calibration routes flown under several env settings, paired.

    python scripts/env_rates_check.py --config base='{"flight_dt_s": 0.02}' \
        --config task='{"flight_dt_s": 0.02, "scenario_fields": {"sensors.ira.rate_hz": 10.0}}' \
        --seeds 16 [--first-seed 0] [--routes basin_west ...] [--out DIR]

Each `--config NAME=JSON` is a set of TerrainNav-v0 keyword arguments added to the fast tier's calibration
routes' own (trn_env.env.fast.calibration.REFERENCE_ROUTES: informative, featureless and mixed routes on both
terrains, a constant action each); every configuration flies the same routes with the same episode seeds
first_seed .. first_seed + seeds - 1 (`--routes`: only the routes named). Prints, per route, the first
configuration's mean / 90th percentile of the true miss (the true horizontal navigation error at arrival, else
at the episode's end) and, for every other one, its mean / p90, the paired difference of the misses with its
95 % t interval, the paired t and Wilcoxon p values, the arrivals, the CPU seconds per decision, and the
mean paired difference of the true horizontal error after each decision. With
`--out DIR` each configuration's per-seed results are written to DIR/rates_<NAME>.json and read back from
there by a later call with the same name, seeds and settings (so a configuration can be added without flying
the others again).

    python scripts/env_rates_check.py --cpu-repeats 6 --config default='{}' --config avg5='{"scenario_fields":
        {"navigator.settings.ira_average": 5}}'

instead measures the CPU per 30 s decision of each configuration over the route task's own basin env
(`route_task.env_kwargs("basin")` plus the configuration): the configurations interleaved in one process,
each repeat 8 random pursuit decisions from a reset (seed 100 + repeat, the same actions for every
configuration); prints the median and the repeats (ms), and each one's ratio to the first's median.
Bad arguments: a message and exit 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from trn_env.output.run_folder import folder_problem


def fly(settings: dict, seeds: int, routes: list[str] | None = None, first_seed: int = 0) -> dict:
    """Per route (all, or those named): the true miss per seed (m), the terminations, the error at each
    decision, CPU seconds per decision (trn_env.env.fast.calibration.fly_full)."""
    from trn_env.env.fast.calibration import REFERENCE_ROUTES, fly_full

    return {route.name: fly_full(route, range(first_seed, first_seed + seeds), settings)
            for route in REFERENCE_ROUTES if routes is None or route.name in routes}


def compare(configs: dict[str, dict], seeds: int, out: Path | None, routes: list[str] | None = None,
            first_seed: int = 0) -> None:
    from scipy import stats

    res: dict[str, dict] = {}
    key = {"seeds": seeds, "first_seed": first_seed, "only_routes": routes}
    for name, settings in configs.items():
        path = None if out is None else out / f"rates_{name}.json"
        if path is not None and path.exists():
            old = json.loads(path.read_text())
            if old.get("settings") == settings and all(old.get(k, 0 if k == "first_seed" else None) == v
                                                      for k, v in key.items()):
                res[name] = old["routes"]
                continue
        res[name] = fly(settings, seeds, routes, first_seed)
        if path is not None:
            out.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"settings": settings, **key, "routes": res[name]}, indent=1))
    names = list(configs)
    base = names[0]
    for route in res[base]:
        x = np.array(res[base][route]["errors_m"])
        b = res[base][route]
        print(f"{route:22s} {base}: {x.mean():7.1f} / {np.percentile(x, 90):7.1f} m, arrived "
              f"{b['terminations'].count('arrived')}/{seeds}, {1e3 * b['cpu_s_per_decision']:.0f} ms "
              "CPU/decision")
        for name in names[1:]:
            r = res[name][route]
            y = np.array(r["errors_m"])
            d = y - x
            half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d))
            same = bool(np.all(d == 0.0))
            p_t = 1.0 if same else stats.ttest_rel(y, x).pvalue
            p_w = 1.0 if same else stats.wilcoxon(y, x).pvalue
            print(f"{'':22s} {name}: {y.mean():7.1f} / {np.percentile(y, 90):7.1f} m, ratio "
                  f"{y.mean() / x.mean():.2f}, diff {d.mean():+.1f} [{d.mean() - half:+.1f}, "
                  f"{d.mean() + half:+.1f}], p {p_t:.2f} (t) / {p_w:.2f} (Wilcoxon), arrived "
                  f"{r['terminations'].count('arrived')}/{seeds}, {1e3 * r['cpu_s_per_decision']:.0f} ms "
                  "CPU/decision")
            if "errors_by_decision_m" in r and "errors_by_decision_m" in b:
                print(f"{'':22s} {name} - {base}, mean true horizontal error after decision 1, 2, ...: "
                      + " ".join(f"{v:+.1f}" for v in _by_decision_difference(b, r)))


def cpu_interleaved(configs: dict[str, dict], repeats: int, decisions: int = 8) -> dict[str, list[float]]:
    """CPU ms per 30 s decision of each configuration (TerrainNav-v0 arguments over the route task's basin
    env), measured interleaved: per repeat, every configuration flies the same random pursuit actions from
    a reset with seed 100 + repeat (episodes restarted when they end)."""
    import time

    from trn_env.env.route_task import env_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv

    envs = {k: TerrainNavEnv(**{**env_kwargs("basin"), **v}) for k, v in configs.items()}
    for e in envs.values():                       # first use (numba caches, map tables) outside the timing
        e.reset(seed=0)
        e.step(np.zeros(2, np.float32))
    out: dict[str, list[float]] = {k: [] for k in envs}
    rng = np.random.default_rng(0)
    for rep in range(repeats):
        actions = rng.uniform(-1.0, 1.0, (decisions, 2)).astype(np.float32)
        for k, e in envs.items():
            e.reset(seed=100 + rep)
            c0 = time.process_time()
            sim_s = 0.0
            for a in actions:
                t0 = e._loop.t_s
                _, _, term, trunc, _ = e.step(a)
                sim_s += e._loop.t_s - t0
                if term or trunc:
                    e.reset()
            out[k].append(1e3 * (time.process_time() - c0) / sim_s * 30.0)
    for e in envs.values():
        e.close()
    return out


def _by_decision_difference(base: dict, other: dict, n_max: int = 16) -> list[float]:
    """Mean over seeds of the paired difference of the true horizontal error after each decision (seeds
    whose episodes both reached that decision)."""
    out = []
    for k in range(n_max):
        pairs = zip(base["errors_by_decision_m"], other["errors_by_decision_m"], strict=True)
        d = [o[k] - b[k] for b, o in pairs if len(b) > k and len(o) > k]
        if not d:
            break
        out.append(float(np.mean(d)))
    return out


def _config(text: str) -> tuple[str, dict]:
    name, sep, js = text.partition("=")
    if not sep or not name.isidentifier():
        raise ValueError(f"--config must be NAME=JSON with NAME an identifier, got {text!r}")
    try:
        settings = json.loads(js)
    except json.JSONDecodeError as err:
        raise ValueError(f"--config {name}: not JSON ({err})") from None
    if not isinstance(settings, dict):
        raise ValueError(f"--config {name}: must be a JSON object of TerrainNav-v0 arguments, got {js!r}")
    return name, settings


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--config", action="append", default=[], metavar="NAME=JSON")
    p.add_argument("--cpu-repeats", type=int, default=0,
                   help="measure CPU per decision, interleaved, this many repeats (no routes flown)")
    p.add_argument("--seeds", type=int, default=16)
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--routes", nargs="+", default=None, metavar="ROUTE")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        p.error(problem)       # checked before the work, not after it
    try:
        configs = dict(_config(c) for c in args.config)
        if len(configs) < 2 or len(configs) != len(args.config):
            raise ValueError(f"give two or more --config with distinct names, got {args.config}")
        if args.cpu_repeats < 0:
            raise ValueError(f"--cpu-repeats must be >= 0, got {args.cpu_repeats}")
        if args.seeds < 2:
            raise ValueError(f"--seeds must be >= 2 (paired statistics), got {args.seeds}")
        if args.first_seed < 0:
            raise ValueError(f"--first-seed must be >= 0, got {args.first_seed}")
        from trn_env.env.fast.calibration import REFERENCE_ROUTES, env_kwargs
        from trn_env.env.terrain_nav import TerrainNavEnv
        known = [r.name for r in REFERENCE_ROUTES]
        unknown = sorted(set(args.routes or []) - set(known))
        if unknown:
            raise ValueError(f"--routes: unknown {unknown}; known: {known}")
        for name, settings in configs.items():     # every configuration builds before anything flies
            try:
                TerrainNavEnv(**{**env_kwargs(REFERENCE_ROUTES[0]), **settings}).close()
            except (TypeError, ValueError) as err:
                raise ValueError(f"--config {name}: {err}") from None
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.cpu_repeats:
        res = cpu_interleaved(configs, args.cpu_repeats)
        ref = float(np.median(res[next(iter(res))]))
        for name, v in res.items():
            print(f"{name:16s} median {np.median(v):6.1f} ms CPU per 30 s decision, ratio to the first "
                  f"{ref / np.median(v):.2f}, repeats {[round(x, 1) for x in v]}")
        return 0
    compare(configs, args.seeds, args.out, args.routes, args.first_seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
