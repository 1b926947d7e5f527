"""The DEM integrity monitor in closed loop over a map with realistic correlated error (not map = world).

    python scripts/integrity_closed_loop.py --fault-free 20 --denied 6 --faulted 3 --json out.json

King Air 600 m above the real Jacksboro DEM refined to 30 m (the world); the navigator's map is the 3"
DEM with the DTED-1 class's error model drawn per seed (terrain.map_error: vertical bias + exponentially
correlated random error at 1,070 m, 18.24 m together, and a horizontal shift of 23 m sigma per axis); INS +
TERCOM (`--navigator`: another terrain navigator); the monitor (N = 50, threshold 96) takes its map model
from the scenario (sigma, bias share, correlation: trn_env.scenario.build.monitor_map_settings) and its
navigator's declared error time constants, and whitens. For comparison every flight's log is
replayed through the monitor without the correlation model (eq 4 as seed 003 has it, "today"). Fault-free
flights with GNSS and GNSS-denied (from 10 s: the monitor then runs on the navigator's position and
covariance); faulted flights over a patch entered ~70 s after the start: bias 40 / 100 m, ramp to 100 m,
horizontal shift 300 m, stale (the region from 5 km away). Reports alarms per flight and per window, and for
the faults the detection and time to alarm after entering the patch.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import integrity_statistics as ist  # noqa: E402  (the closed-loop helpers of the seed 003 study)

FAULTS = [("bias", {"bias_m": 40.0}), ("bias", {"bias_m": 100.0}),
          ("ramp", {"bias_m": 100.0, "direction_deg": 0.0}), ("shift", {"shift_n_m": 300.0}),
          ("stale", {"source_offset_n_m": -5000.0})]


def _scenario(seed: int, faults: list[dict], outage: bool, navigator: str = "ins_tercom"):
    from trn_env.scenario.loading import read_scenario_file, validate
    data, _ = read_scenario_file(ist.BASE)
    if navigator != data["navigator"]["name"]:
        data["navigator"] = {"name": navigator, "settings": {}}
    data["seed"] = seed
    data["duration_s"] = ist.DURATION_S
    data["terrain"]["map"]["faults"] = faults
    data["terrain"]["map"]["error_model"] = {"preset": "dted1"}
    data["terrain"]["world"]["refinement"] = {"spacing_m": 30.0}
    data["monitors"]["dem_integrity"] = {"n_window": ist.N_WIN, "threshold": ist.THRESHOLD}
    if outage:
        data["gnss"] = {"outages": [{"start_s": 10.0}]}
    return validate(data, source="integrity_closed_loop")


def _fly(seed: int, faults: list[dict], outage: bool = False, navigator: str = "ins_tercom") -> dict:
    from trn_env.navigators.integrity import dem_monitor as dm
    from trn_env.navigators.registry import create_monitor

    from trn_env.scenario.build import monitor_settings
    from trn_env.sim.closed_loop import ClosedLoop
    sc = _scenario(seed, faults, outage, navigator)
    loop = ClosedLoop(sc, pipeline=True)
    r = loop.run()
    a = r.arrays
    settings = monitor_settings(r.scenario, "dem_integrity")
    white = {k: v for k, v in settings.items()
             if k not in ("correlation_length_m", "correlation_function", "map_bias_fraction", "sigma_m")}
    today = None
    if not faults:      # the same flight through eq 4 without the correlation model
        today = dm.replay_log(create_monitor("dem_integrity", dem=loop.map_dem, **white), a)
    return {"t": a["monitor_dem_integrity_t_s"], "alarm": a["monitor_dem_integrity_alarm"],
            "stat": a["monitor_dem_integrity_statistic"], "source": a["monitor_dem_integrity_source"],
            "today_alarm": None if today is None else today["alarm"], "arrays": a,
            "settings": {k: settings[k] for k in ("sigma_m", "correlation_length_m", "map_bias_fraction")
                         if k in settings}}


def fault_free(n: int, outage: bool, seed0: int, navigator: str = "ins_tercom") -> dict:
    flights, alarm_flights, windows, alarm_windows, today_flights, today_windows = 0, 0, 0, 0, 0, 0
    stat_max = []
    nav_src = []
    for s in range(n):
        f = _fly(seed0 + s, [], outage, navigator)
        ok = np.isfinite(f["stat"])
        flights += 1
        windows += int(ok.sum())
        alarm_windows += int(np.count_nonzero(f["alarm"]))
        alarm_flights += int(bool(np.any(f["alarm"])))
        today_windows += int(np.count_nonzero(f["today_alarm"]))
        today_flights += int(bool(np.any(f["today_alarm"])))
        stat_max.append(float(np.nanmax(f["stat"])) if ok.any() else float("nan"))
        nav_src.append(float(np.mean(f["source"] == 1)) if f["source"].size else float("nan"))
        n_al = int(np.count_nonzero(f["alarm"]))
        n_today = int(np.count_nonzero(f["today_alarm"]))
        print(f"fault-free{' denied' if outage else ''} seed {seed0 + s}: {n_al} alarm windows "
              f"(today {n_today}), T max {stat_max[-1]:.1f}, monitor model {f['settings']}", flush=True)
    return {"flights": flights, "flights_with_alarm": alarm_flights, "windows": windows,
            "alarm_windows": alarm_windows, "today_flights_with_alarm": today_flights,
            "today_alarm_windows": today_windows, "statistic_max": stat_max,
            "fraction_navigator_source": nav_src}


def faulted(n: int, seed0: int, navigator: str = "ins_tercom") -> dict:
    out = {}
    for kind, extra in FAULTS:
        fault = dict(ist.PATCH, kind=kind, **extra)
        det, tta, early = [], [], 0
        for s in range(n):
            f = _fly(seed0 + s, [fault], navigator=navigator)
            t_in = ist._entry_time(f["arrays"], fault)
            hit = f["alarm"] & (f["t"] >= t_in)
            early += int(bool(np.any(f["alarm"] & (f["t"] < t_in))))
            det.append(bool(hit.any()))
            if hit.any():
                tta.append(float(f["t"][np.argmax(hit)] - t_in))
        key = f"{kind}_{'_'.join(f'{k}{v:g}' for k, v in extra.items())}"
        out[key] = {"flights": n, "detected": int(np.sum(det)), "alarm_before_entry": early,
                    "time_to_alarm_s": tta}
        print(f"faulted {key}: {json.dumps(out[key])}", flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fault-free", type=int, default=20)
    ap.add_argument("--denied", type=int, default=6)
    ap.add_argument("--faulted", type=int, default=3)
    ap.add_argument("--navigator", default="ins_tercom", choices=("ins_tercom", "pmf", "pf", "rbpf"),
                    help="the navigator beside the monitor (its declared error time constants reach the "
                    "monitor's GNSS-denied path)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    for name in ("fault_free", "denied", "faulted"):
        if getattr(args, name) < 0:
            ap.error(f"--{name.replace('_', '-')}: must be >= 0, got {getattr(args, name)}")
    if args.json is not None:
        from trn_env.output.run_folder import file_target_problem
        if problem := file_target_problem(args.json, "--json", (".json",)):
            ap.error(problem)       # checked before the flights, not after them
    t0 = time.perf_counter()
    out = {"navigator": args.navigator,
           "fault_free": fault_free(args.fault_free, False, 500, args.navigator)}
    out["fault_free_gnss_denied"] = fault_free(args.denied, True, 600, args.navigator)
    out["faulted"] = faulted(args.faulted, 700, args.navigator)
    out["seconds"] = time.perf_counter() - t0
    print(json.dumps({k: v for k, v in out.items() if k != "faulted"}, default=float), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1, default=float) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
