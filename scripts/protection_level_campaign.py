"""Protection levels of the terrain navigators over recorded flights: misleading-information (MI) rate,
hazardous MI rate against an alert limit, availability, and a Stanford diagram per navigator.

    python scripts/protection_level_campaign.py --budget-s 4000 --workers 2 --out pl_campaign
    python scripts/protection_level_campaign.py --report-only --out pl_campaign

(Run it from the repository root with PYTHONPATH=. so the worktree's trn_env is the one imported.)

Each flight is recorded once (trn_env.logs.record, the INS flying the route, every sensor the navigators
read) and replayed open loop through every navigator (trn_env.logs.replay): the flight dynamics and the
sensors are paid once per flight instead of once per navigator. A flight is `--duration-s` long, GNSS lost
at 10 s, over a 66 km loop inside the area the Jacksboro DEM and the synthetic "rolling" terrain share
(the start leg rotates with the seed). Conditions (8): terrain (jacksboro: the real 3" DEM against a world
refined to 30 m; rolling: the synthetic preset, same refinement) x IMU grade (navigation, tactical) x map
class (as_published: the map is the DEM the world was refined from; dted1: that map plus the DTED-1
class's error model drawn per seed - bias, horizontal shift, spatially correlated vertical error).

Counted epochs: the replay's rows (navigator rate) after GNSS is lost where the navigator says it is healthy
and publishes a finite HPL. Per (navigator, condition) and pooled per navigator: MI epochs, rate and its
one-sided 95 % Clopper-Pearson bound (rows of one flight are correlated: the bound counts them as
independent), hazardous MI against the alert limit, availability; and the accuracy: each flight's horizontal
RMS error after GNSS is lost, its median and 90th percentile over the condition's flights. Jobs (condition,
seed) run round-robin in `--workers` processes until `--budget-s` is spent; each saves
OUT/epochs/<nav>/<condition>/s<seed>.npz, so a run resumes where it stopped and `--navigators` can add a
navigator to flights already recorded. Writes OUT/pl_campaign.json and OUT/stanford.png.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path

import numpy as np

from trn_env.output.run_folder import folder_problem

NAVIGATORS = {"ins_tercom": {"remove_bias": True}, "pmf": {"grid_size": 200}, "pf": {"n_particles": 10000},
              "acq_track": {"transect_samples": 25, "replica_model": "return", "aiding_source": "ins"},
              "rbpf": {}}
TERRAINS = {"jacksboro": "jacksboro", "rolling": "synthetic:rolling"}
GRADES = ("navigation", "tactical")
MAPS = ("as_published", "dted1")
CONDITIONS = [f"{t}-{g}-{m}" for t in TERRAINS for g in GRADES for m in MAPS]
# a loop inside both DEMs (jacksboro: lat 36.447-36.733, lon -84.413 to -84.078; rolling: 36.500-36.771,
# -84.300 to -83.965), ~3 km from the shared area's edges
LOOP = [(36.53, -84.27), (36.70, -84.27), (36.70, -84.11), (36.53, -84.11)]
GNSS_LOST_S = 10.0


def scenario_data(condition: str, seed: int, duration_s: float) -> dict:
    """The recording scenario of one flight (acq_track_short's sensors, the INS as navigator)."""
    from trn_env.scenario.loading import read_scenario_file
    terrain, grade, map_class = condition.split("-")
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    k = seed % len(LOOP)
    pts = LOOP[k:] + LOOP[:k] + LOOP[k:k + 1]
    (la0, lo0), (la1, lo1) = pts[0], pts[1]
    heading = float(np.degrees(np.arctan2((lo1 - lo0) * np.cos(np.radians(la0)), la1 - la0))) % 360.0
    data.update(name=f"pl_{condition}_{seed}", seed=seed, duration_s=duration_s)
    data["initial"].update(lat_deg=la0, lon_deg=lo0, h_agl_m=600.0, heading_deg=heading)
    data["route"]["waypoints"] = [{"lat_deg": a, "lon_deg": b, "h_agl_m": 600.0} for a, b in pts]
    data["terrain"]["world"]["dem"] = TERRAINS[terrain]
    data["terrain"]["map"] = {"dem": TERRAINS[terrain]}
    if map_class == "dted1":
        data["terrain"]["map"]["error_model"] = {"preset": "dted1"}
    data["sensors"]["imu"] = {"grade": grade}
    data["gnss"] = {"outages": [{"start_s": GNSS_LOST_S}]}
    data["navigator"] = {"name": "ins", "settings": {}}
    return data


def run_job(out: str, condition: str, seed: int, duration_s: float, navs: list[str],
            extra_settings: dict | None = None) -> list[str]:
    """Record one flight (unless recorded) and replay it through the navigators not yet saved, each with
    NAVIGATORS' settings updated by extra_settings[nav]."""
    from trn_env.logs.record import record
    from trn_env.logs.replay import replay
    from trn_env.scenario.loading import validate
    out_p = Path(out)
    log_dir = out_p / "logs" / condition / f"s{seed}"
    lines = []
    if not (log_dir / "metadata.json").exists():
        t0 = time.perf_counter()
        sc = validate(scenario_data(condition, seed, duration_s), source="protection_level_campaign")
        r, _ = record(sc, log_dir)
        lines.append(f"record {condition} s{seed}: {r.termination}, {time.perf_counter() - t0:.1f} s")
    for nav in navs:
        f = out_p / "epochs" / nav / condition / f"s{seed}.npz"
        if f.exists():
            continue
        t0 = time.perf_counter()
        rr = replay(log_dir, nav, settings=NAVIGATORS[nav] | (extra_settings or {}).get(nav, {}))
        a = rr.arrays
        e = np.hypot(a["err_ned_m"][:, 0], a["err_ned_m"][:, 1])
        h = np.asarray(a["est_hpl_m"], float)
        ok = np.asarray(a["nav_ok"], bool)
        denied = ~np.asarray(a["gnss_available"], bool)
        f.parent.mkdir(parents=True, exist_ok=True)
        np.savez(f, t=a["t_s"], e=e, h=h, ok=ok, denied=denied, status=a["nav_status_code"],
                 err_ned_m=np.asarray(a["err_ned_m"], np.float32))
        c = ok & denied & np.isfinite(h)
        lines.append(f"  {nav} {condition} s{seed}: {rr.termination}, {int(np.sum(c & (e > h)))} MI of "
                     f"{int(c.sum())}, {time.perf_counter() - t0:.1f} s")
    return lines


def load_epochs(out: Path, nav: str, condition: str):
    """(e, h, healthy) of the counted epochs (GNSS lost) of every saved flight, the flight count and the
    number of flights with a misleading epoch."""
    files = sorted((out / "epochs" / nav / condition).glob("s*.npz"))
    if not files:
        return None
    zs = [np.load(f) for f in files]
    d = [z["denied"] for z in zs]
    e, h, ok = ([z[k][m] for z, m in zip(zs, d, strict=True)] for k in ("e", "h", "ok"))
    st = [z["status"][m] if "status" in z else np.zeros(m.sum(), np.int8) for z, m in zip(zs, d, strict=True)]
    n_mi = sum(int(np.any(o & np.isfinite(hh) & (ee > hh))) for ee, hh, o in zip(e, h, ok, strict=True))
    return (np.concatenate(e), np.concatenate(h), np.concatenate(ok), len(files), n_mi,
            np.concatenate(st))


def accuracy_figures(out: Path, nav: str, condition: str) -> dict:
    """Each flight's horizontal RMS error over its epochs after GNSS is lost (healthy or not): the median
    and 90th percentile over the condition's flights, m."""
    rms = []
    for f in sorted((out / "epochs" / nav / condition).glob("s*.npz")):
        z = np.load(f)
        e = z["e"][z["denied"]]
        if e.size:
            rms.append(float(np.sqrt(np.mean(e * e))))
    if not rms:
        return {}
    return {"horizontal_rms_median_m": float(np.median(rms)),
            "horizontal_rms_p90_m": float(np.percentile(rms, 90))}


def flagged_figures(e, h, status) -> dict:
    """Epochs the run-time consistency check flagged ("inconsistent", navigators.integrity) and how many of
    them had the error above the HPL (misleading had the navigator stayed healthy)."""
    from trn_env.sim.log import NAV_STATUS_CODES
    flag = status == NAV_STATUS_CODES.index("inconsistent")
    return {"inconsistent_epochs": int(flag.sum()),
            "inconsistent_error_above_hpl": int(np.sum(flag & np.isfinite(h) & (e > h)))}


def report(out: Path, navs: list[str], al: float, risk: float) -> dict:
    """OUT/pl_campaign.json and OUT/stanford.png from the saved epochs."""
    import pandas as pd

    from trn_env.campaign.report import stanford_plot
    from trn_env.output.integrity_metrics import protection_level_metrics
    res: dict = {}
    rows = []
    for nav in navs:
        pooled = []
        for c in CONDITIONS:
            got = load_epochs(out, nav, c)
            if got is None:
                continue
            e, h, ok, nf, n_mi, st = got
            m = protection_level_metrics(e, h, ok, al) | flagged_figures(e, h, st)
            m |= accuracy_figures(out, nav, c)
            m |= {"flights": nf, "flights_with_mi": n_mi, "all_epochs": int(e.size)}
            m["meets_risk"] = bool(m["pl_misleading_rate_upper95"] <= risk)
            res[f"{nav}/{c}"] = m
            pooled.append((e, h, ok, st))
        if pooled:
            e, h, ok, st = (np.concatenate([p[i] for p in pooled]) for i in range(4))
            m = protection_level_metrics(e, h, ok, al) | flagged_figures(e, h, st)
            m["all_epochs"] = int(e.size)
            m["meets_risk"] = bool(m["pl_misleading_rate_upper95"] <= risk)
            res[f"{nav}/all"] = m
            rows.append({"navigator": nav, "series_err_h_m": e, "series_hpl_m": h,
                         "series_nav_ok": ok.astype(float)})
    doc = {"alert_limit_m": al, "integrity_risk": risk, "conditions": CONDITIONS, "results": res}
    (out / "pl_campaign.json").write_text(json.dumps(doc, indent=1, default=float) + "\n", encoding="utf-8")
    if rows:
        stanford_plot(out / "stanford.png", pd.DataFrame(rows), al)
    return doc


def accuracy_table(doc: dict) -> str:
    """Markdown: each condition's per-flight horizontal RMS after GNSS is lost, median / 90th percentile
    (m), one column per navigator (the report's navigators in its order)."""
    res = doc["results"]
    navs = list(dict.fromkeys(k.split("/")[0] for k in res))
    lines = ["| condition | " + " | ".join(f"`{n}`" for n in navs) + " |",
             "|---" * (len(navs) + 1) + "|"]
    for c in doc["conditions"]:
        cells = []
        for n in navs:
            m = res.get(f"{n}/{c}", {})
            cells.append(f"{m['horizontal_rms_median_m']:.0f} / {m['horizontal_rms_p90_m']:.0f}"
                         if "horizontal_rms_median_m" in m else "-")
        lines.append(f"| {c.replace('-', ', ')} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def settings_argument(text: str, navs: list[str], error) -> dict:
    """--settings parsed and checked against each navigator's declared settings (error(message) on a
    problem, before any work)."""
    from trn_env.navigators import registry
    try:
        extra = json.loads(text)
    except json.JSONDecodeError as exc:
        error(f"--settings: not JSON ({exc})")
    if not isinstance(extra, dict) or not all(isinstance(v, dict) for v in extra.values()):
        error("--settings: expected a JSON object of navigator name -> object of settings")
    for nav, kw in extra.items():
        if nav not in navs:
            error(f"--settings: {nav!r} is not among --navigators {navs}")
        try:
            registry.capabilities(nav).settings(**(NAVIGATORS[nav] | kw))
        except (TypeError, ValueError) as exc:
            error(f"--settings: {nav}: {exc}")
    return extra


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget-s", type=float, default=3600.0, help="wall-time budget for new jobs (s)")
    ap.add_argument("--duration-s", type=float, default=400.0, help="flight length (s)")
    ap.add_argument("--seeds", type=int, default=40, help="flights per condition")
    ap.add_argument("--seed0", type=int, default=1000, help="first scenario seed")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--alert-limit-m", type=float, default=185.2)
    ap.add_argument("--integrity-risk", type=float, default=1e-3)
    ap.add_argument("--navigators", default=",".join(NAVIGATORS))
    ap.add_argument("--conditions", default="", help="comma-separated parts of condition names (e.g. "
                    "'as_published'): only the jobs of the conditions that contain one (default: all)")
    ap.add_argument("--settings", default="{}", help="JSON object of navigator name -> settings that update "
                    "its campaign settings for the replays this run makes, e.g. "
                    "'{\"rbpf\": {\"map_error_in_height\": true}}'")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--replay-only", action="store_true", help="only flights already recorded")
    ap.add_argument("--out", default="pl_campaign")
    args = ap.parse_args(argv)
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    from trn_env.navigators.integrity.protection_level import check_alert_limit, check_integrity_risk
    al = check_alert_limit(args.alert_limit_m, "--alert-limit-m")
    risk = check_integrity_risk(args.integrity_risk, "--integrity-risk")
    navs = [n.strip() for n in args.navigators.split(",") if n.strip()]
    bad = [n for n in navs if n not in NAVIGATORS]
    if bad:
        ap.error(f"--navigators: unknown {bad}; choose from {sorted(NAVIGATORS)}")
    extra = settings_argument(args.settings, navs, ap.error)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")
        conds = [c for c in CONDITIONS if any(part in c for part in args.conditions.split(","))]
        jobs = [(c, args.seed0 + s) for s in range(args.seeds) for c in conds]
        if args.replay_only:
            jobs = [(c, s) for c, s in jobs if (out / "logs" / c / f"s{s}" / "metadata.json").exists()]
        t0 = time.perf_counter()
        with ProcessPoolExecutor(args.workers) as pool:
            running = set()
            while jobs or running:
                while jobs and len(running) < args.workers and time.perf_counter() - t0 < args.budget_s:
                    c, s = jobs.pop(0)
                    running.add(pool.submit(run_job, str(out), c, s, args.duration_s, navs, extra))
                if not running:
                    break
                done, running = wait(running, return_when=FIRST_COMPLETED)
                for fut in done:
                    print(f"{time.perf_counter() - t0:7.0f} s", *fut.result(), sep="\n", flush=True)
    doc = report(out, navs, al, risk)
    print("| navigator | condition | flights (with MI) | epochs counted / healthy with HPL | MI epochs | "
          "MI rate (upper 95 %) | HMI | availability | median HPL (m) | flagged inconsistent (error > HPL) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for k, m in doc["results"].items():
        nav, cond = k.split("/")
        fl = f"{m['flights']} ({m['flights_with_mi']})" if "flights" in m else "all"
        rate = m["pl_misleading_rate"]
        print(f"| {nav} | {cond} | {fl} | {m['all_epochs']} / {m['pl_epochs']} | "
              f"{m['pl_misleading_epochs']} | {rate:.2g} (≤ {m['pl_misleading_rate_upper95']:.2g}) | "
              f"{m['pl_hazardous_epochs']} | {m['pl_availability']:.3f} | {m['hpl_median_m']:.1f} | "
              f"{m['inconsistent_epochs']} ({m['inconsistent_error_above_hpl']}) |")
    print("\nHorizontal RMS after GNSS is lost, per flight: median / 90th percentile over the flights (m)\n")
    print(accuracy_table(doc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
