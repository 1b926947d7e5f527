"""Protection levels of the terrain navigators in closed loop: misleading-information (MI) rate, hazardous
MI rate against an alert limit, availability, and a Stanford diagram per navigator.

    python scripts/protection_level_campaign.py --budget-s 3000 --out pl_campaign   # round-robin flights

Each navigator flies its regression scenario (tests/scenarios/<nav>_short.toml; ins_tercom: default_short)
along the default scenario's route (~45 km, 600 m above ground; --duration-s at most), under two map
conditions: "as_published" (the scenario's own map: the real 3"
DEM against a world refined to 30 m) and "dted1_correlated" (that map plus the DTED-1 class's error model
drawn per seed: bias, horizontal shift, correlated random vertical error). Flights go round-robin over
navigators x conditions x seeds until the wall-time budget is spent; every epoch (logged row, 1 Hz) where
the navigator is healthy and publishes an HPL counts. Writes OUT/pl_campaign.json (pooled figures with
one-sided 95 % Clopper-Pearson bounds) and OUT/stanford.png.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

SCENARIOS = {"ins_tercom": "default_short", "pmf": "pmf_short", "pf": "pf_short", "rbpf": "rbpf_short",
             "acq_track": "acq_track_short"}
CONDITIONS = ("as_published", "dted1_correlated")
# the default scenario's route (600 m above ground, ~45 km): longer flights than the short scenarios' own
ROUTE = [(36.490, -84.370), (36.640, -84.340), (36.640, -84.200), (36.520, -84.160)]


def fly(nav: str, condition: str, seed: int, duration_s: float):
    from trn_env.scenario.loading import read_scenario_file, validate
    from trn_env.sim.closed_loop import ClosedLoop
    data, _ = read_scenario_file(f"tests/scenarios/{SCENARIOS[nav]}.toml")
    data["seed"] = seed
    data["duration_s"] = duration_s
    data["route"]["waypoints"] = [{"lat_deg": a, "lon_deg": b, "h_agl_m": 600.0} for a, b in ROUTE]
    if condition == "dted1_correlated":
        data["terrain"]["map"]["dem"] = "jacksboro"
        data["terrain"]["map"]["error_model"] = {"preset": "dted1"}
    sc = validate(data, source="protection_level_campaign")
    r = ClosedLoop(sc, pipeline=True).run()
    a = r.arrays
    e = np.hypot(a["err_ned_m"][:, 0], a["err_ned_m"][:, 1])
    return e, np.asarray(a["est_hpl_m"], float), np.asarray(a["nav_ok"], bool), r.termination


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget-s", type=float, default=3000.0, help="wall-time budget (s)")
    ap.add_argument("--duration-s", type=float, default=600.0, help="flight length limit (s)")
    ap.add_argument("--alert-limit-m", type=float, default=185.2)
    ap.add_argument("--navigators", default=",".join(SCENARIOS))
    ap.add_argument("--out", default="pl_campaign")
    ap.add_argument("--seed0", type=int, default=1000, help="first scenario seed")
    args = ap.parse_args(argv)
    from trn_env.navigators.integrity.protection_level import check_alert_limit

    from trn_env.output.integrity_metrics import clopper_pearson_upper, protection_level_metrics
    al = check_alert_limit(args.alert_limit_m, "--alert-limit-m")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    navs = [n.strip() for n in args.navigators.split(",") if n.strip()]
    data = {(n, c): {"e": [], "h": [], "ok": [], "flights": 0, "terminations": []} for n in navs
            for c in CONDITIONS}
    t0 = time.perf_counter()
    seed = 0
    while time.perf_counter() - t0 < args.budget_s:
        for n in navs:
            for c in CONDITIONS:
                if time.perf_counter() - t0 >= args.budget_s:
                    break
                e, h, ok, term = fly(n, c, args.seed0 + seed, args.duration_s)
                d = data[(n, c)]
                d["e"].append(e)
                d["h"].append(h)
                d["ok"].append(ok)
                d["flights"] += 1
                d["terminations"].append(term)
                print(f"{time.perf_counter() - t0:7.0f} s {n} {c} seed {args.seed0 + seed}: {term}, "
                      f"{int(np.sum(ok & (e > h)))} MI of {int(np.sum(ok & np.isfinite(h)))}", flush=True)
                res = {}
                for (nn, cc), dd in data.items():
                    if not dd["flights"]:
                        continue
                    E, H, OK = (np.concatenate(dd[k]) for k in ("e", "h", "ok"))
                    m = protection_level_metrics(E, H, OK, al)
                    m.update(flights=dd["flights"], terminations=dd["terminations"],
                             pl_misleading_rate_upper95=clopper_pearson_upper(m["pl_misleading_epochs"],
                                                                               m["pl_epochs"]))
                    res[f"{nn}/{cc}"] = m
                    np.savez(out / f"{nn}_{cc}.npz", e=E, h=H, ok=OK)
                (out / "pl_campaign.json").write_text(json.dumps(
                    {"alert_limit_m": al, "duration_s": args.duration_s, "results": res,
                     "wall_s": time.perf_counter() - t0}, indent=1, default=float) + "\n", encoding="utf-8")
        seed += 1
    stanford(out, navs, al)
    return 0


def stanford(out: Path, navs: list[str], al: float) -> None:
    """OUT/stanford.png from the saved epochs (both conditions pooled per navigator)."""
    import pandas as pd

    from trn_env.campaign.report import stanford_plot
    rows = []
    for n in navs:
        for c in CONDITIONS:
            p = out / f"{n}_{c}.npz"
            if p.exists():
                z = np.load(p)
                rows.append({"navigator": n, "series_err_h_m": z["e"], "series_hpl_m": z["h"],
                             "series_nav_ok": z["ok"].astype(float)})
    if rows:
        stanford_plot(out / "stanford.png", pd.DataFrame(rows), al)


if __name__ == "__main__":
    raise SystemExit(main())
