"""Statistics of the seed 003 DEM integrity monitor and of the navigator's own integrity flag.

    python scripts/integrity_statistics.py                  # everything (vectorised + closed-loop flights)
    python scripts/integrity_statistics.py --vectorised-only --tests 1000000
    python scripts/integrity_statistics.py --seeds 5 --json out.json

1. False alarms on fault-free data, N = 50, threshold 96 (design 1e-4): >= 1e6 independent tests drawn from
   the error models (map: the DTED-1 class of terrain.map_error, 18.24 m, against the monitor's 18.9 m of
   seed 003; radar altimeter 0.6 m + 2 % of the range at 300-1,500 m above ground; GNSS vertical 2 m white +
   3 m slowly drifting), for the plain statistic (eq 4) and the Kalman-filtered one (eq 5) at 96 and at its
   own 1e-4 threshold; plus the same with the map error correlated along the track (500 m correlation
   length, 85 m between epochs) to show what the independence assumption is worth.
2. Detection: missed-detection probability within 50 samples and mean samples to alarm against a map bias
   of 20-100 m, plain and Kalman, on the same draws.
3. Closed loop (King Air, 600 m above the real Jacksboro DEM refined to 30 m, radar altimeter, GNSS,
   INS + TERCOM): fault-free flights (alarms), flights over a bias patch (20-100 m) and a ramp (to 60 / 100
   m): probability of detection and time to alarm after entering the fault; the Kalman-filtered statistic
   replayed on the same flights' logs (navigators.integrity.dem_monitor.replay_log).
4. A navigator meeting a stale patch (GNSS denied, the map's region along the route taken from 5 km away):
   how often its own integrity flag (Health.status "degraded", navigators.integrity.innovation_monitor)
   rises before its true error leaves its 3 sigma, and its misleading-information time.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from scipy.stats import beta, chi2
from trn_env.navigators.integrity import dem_monitor as dm

N_WIN = 50
THRESHOLD = 96.0
PROCESS_RATIO = 0.01


def _upper95(k: int, n: int) -> float:
    """One-sided 95 % Clopper-Pearson upper bound of a binomial proportion."""
    return 1.0 if k >= n else float(beta.ppf(0.95, k + 1, n - k))


def _map_sigma_m() -> float:
    """The DTED-1 class's vertical sigma in terrain.map_error (LE90 30 m / 1.6449 = 18.24 m): the map error
    drawn here, while the monitor assumes seed 003's measured disparity sigma of 18.9 m."""
    from trn_env.terrain.map_error import ACCURACY_CLASSES
    return float(ACCURACY_CLASSES["dted1"].sigma_v_m)


def _draw(rng, n: int, k: int, agl_m: np.ndarray, corr_len_m: float | None = None, spacing_m: float = 85.0,
          gnss_drift_m: float = 3.0):
    """(disparities, the monitor's variances) of n sequences of k fault-free epochs from the error models."""
    ra_sig = 0.6 + 0.02 * agl_m[:, None]
    s_map = _map_sigma_m()
    if corr_len_m is None:
        map_err = s_map * rng.standard_normal((n, k))
    else:          # Gauss-Markov along track: the exp(-d/L) correlation at the epoch spacing
        a = math.exp(-spacing_m / corr_len_m)
        w = rng.standard_normal((n, k))
        map_err = np.empty((n, k))
        map_err[:, 0] = w[:, 0]
        for j in range(1, k):
            map_err[:, j] = a * map_err[:, j - 1] + math.sqrt(1 - a * a) * w[:, j]
        map_err *= s_map
    p = map_err + ra_sig * rng.standard_normal((n, k)) + 2.0 * rng.standard_normal((n, k)) \
        + gnss_drift_m * rng.standard_normal((n, 1))
    var = np.broadcast_to(18.9**2 + ra_sig**2 + 13.0, (n, k))
    return p, np.ascontiguousarray(var)


def vectorised(n_tests: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    thr_kf = dm.kalman_threshold(1e-4, N_WIN, PROCESS_RATIO)
    burn = 100           # the eq 5 filter reaches its steady state before the tested window
    chunk = 100_000
    counts = {"plain": 0, "kalman_96": 0, "kalman_own": 0, "plain_correlated": 0, "kalman_96_correlated": 0,
              "kalman_own_no_drift": 0}
    n_done = 0
    t0 = time.perf_counter()
    while n_done < n_tests:
        n = min(chunk, n_tests - n_done)
        agl = rng.uniform(300.0, 1500.0, n)
        p, var = _draw(rng, n, burn + N_WIN, agl)
        T = dm.window_statistics(p[:, burn:] ** 2 / var[:, burn:], N_WIN)[:, 0]
        Tk = dm.window_statistics(dm.kalman_terms(p, var, PROCESS_RATIO)[:, burn:], N_WIN)[:, 0]
        counts["plain"] += int(np.count_nonzero(T > THRESHOLD))
        counts["kalman_96"] += int(np.count_nonzero(Tk > THRESHOLD))
        counts["kalman_own"] += int(np.count_nonzero(Tk > thr_kf))
        if n_done < n_tests // 10 + 1:    # eq 5 at its own threshold without the (constant) GNSS drift
            pw, varw = _draw(rng, n, burn + N_WIN, agl, gnss_drift_m=0.0)
            Tkw = dm.window_statistics(dm.kalman_terms(pw, varw, PROCESS_RATIO)[:, burn:], N_WIN)[:, 0]
            counts["kalman_own_no_drift"] += int(np.count_nonzero(Tkw > thr_kf))
        if n_done < n_tests // 10 + 1:    # the correlated case on a tenth of the tests (it is far off anyway)
            pc, varc = _draw(rng, n, burn + N_WIN, agl, corr_len_m=500.0)
            Tc = dm.window_statistics(pc[:, burn:] ** 2 / varc[:, burn:], N_WIN)[:, 0]
            Tkc = dm.window_statistics(dm.kalman_terms(pc, varc, PROCESS_RATIO)[:, burn:], N_WIN)[:, 0]
            counts["plain_correlated"] += int(np.count_nonzero(Tc > THRESHOLD))
            counts["kalman_96_correlated"] += int(np.count_nonzero(Tkc > THRESHOLD))
            counts.setdefault("n_correlated", 0)
            counts["n_correlated"] += n
        n_done += n
    out = {"tests": n_tests, "design_pfa": float(chi2.sf(THRESHOLD, N_WIN)), "kalman_threshold_1e-4": thr_kf,
           "seconds": time.perf_counter() - t0}
    for k in ("plain", "kalman_96", "kalman_own"):
        out[f"pfa_{k}"] = counts[k] / n_tests
        out[f"pfa_{k}_upper95"] = _upper95(counts[k], n_tests)
    nc = counts["n_correlated"]
    out["pfa_plain_correlated_500m"] = counts["plain_correlated"] / nc
    out["pfa_kalman_96_correlated_500m"] = counts["kalman_96_correlated"] / nc
    out["pfa_kalman_own_no_gnss_drift"] = counts["kalman_own_no_drift"] / nc
    out["tests_correlated"] = nc
    # detection: a bias under all 50 samples (missed detection), and samples to alarm after onset
    det = {}
    n_det = max(20_000, n_tests // 20)
    for agl_m in (600.0, 1500.0):
        for b in (20.0, 40.0, 60.0, 80.0, 100.0):
            p, var = _draw(rng, n_det, burn + 2 * N_WIN, np.full(n_det, agl_m))
            p[:, burn + N_WIN:] -= b
            # window k of these holds the last k samples of the fault (k = 0 .. N)
            T = dm.window_statistics(p ** 2 / var, N_WIN)[:, burn:]
            Tk = dm.window_statistics(dm.kalman_terms(p, var, PROCESS_RATIO), N_WIN)[:, burn:]
            row = {}
            variants = (("plain", T, THRESHOLD), ("kalman", Tk, THRESHOLD), ("kalman_own", Tk, thr_kf))
            for name, S, thr in variants:
                missed = int(np.count_nonzero(S[:, N_WIN] <= thr))
                hit = S[:, 1:] > thr
                first = np.where(hit.any(axis=1), np.argmax(hit, axis=1) + 1, np.nan)
                row[name] = {"p_md_50": missed / n_det, "p_md_50_upper95": _upper95(missed, n_det),
                             "mean_samples_to_alarm": float(np.nanmean(first)),
                             "p95_samples_to_alarm": float(np.nanpercentile(first, 95))}
            det[f"agl{int(agl_m)}_bias{int(b)}"] = row
    out["detection"] = det
    out["detection_windows"] = n_det
    return out


# ------------------------------------------------------------------------------------------ closed loop

BASE = "tests/scenarios/integrity_short.toml"
# a patch entered about 70 s after the start (past the 50-epoch warm-up), left about 47 s later
PATCH = {"center_lat_deg": 36.5650, "center_lon_deg": -84.3555, "size_n_m": 4000.0, "size_e_m": 3000.0}
DURATION_S = 140.0


DEFAULT_ROUTE = [(36.490, -84.370), (36.640, -84.340), (36.640, -84.200), (36.520, -84.160)]


def _scenario(seed: int, faults: list[dict], refine: bool = True, monitor: dict | None = None,
              outage: bool = False, duration_s: float = DURATION_S, navigator: dict | None = None,
              route: list | None = None):
    from trn_env.scenario.loading import read_scenario_file, validate
    data, _ = read_scenario_file(BASE)
    data["seed"] = seed
    data["duration_s"] = duration_s
    data["terrain"]["map"]["faults"] = faults
    if refine:
        data["terrain"]["world"]["refinement"] = {"spacing_m": 30.0}
    data["monitors"]["dem_integrity"] = monitor or {"n_window": N_WIN, "threshold": THRESHOLD}
    if outage:
        data["gnss"] = {"outages": [{"start_s": 10.0}]}
    if navigator:
        data["navigator"]["settings"].update(navigator)
    if route:
        data["route"]["waypoints"] = [{"lat_deg": a, "lon_deg": b, "h_agl_m": 600.0} for a, b in route]
    return validate(data, source="integrity_statistics")


def _entry_time(arrays, fault: dict) -> float | None:
    from trn_env.terrain.geodesy import latlon_to_ned_offset
    lat_c, lon_c = math.radians(fault["center_lat_deg"]), math.radians(fault["center_lon_deg"])
    for t, lat, lon in zip(arrays["t_s"], arrays["true_lat_rad"], arrays["true_lon_rad"], strict=True):
        dn, de = latlon_to_ned_offset(lat_c, lon_c, 0.0, lat, lon)
        if abs(dn) <= fault["size_n_m"] / 2 and abs(de) <= fault["size_e_m"] / 2:
            return float(t)
    return None


def _fly(sc):
    from trn_env.sim.closed_loop import ClosedLoop
    loop = ClosedLoop(sc, pipeline=True)
    return loop, loop.run()


def closed_loop(seeds: int) -> dict:
    from trn_env.navigators.registry import create_monitor

    from trn_env.scenario.build import monitor_settings
    out: dict = {"seeds": seeds}
    t0 = time.perf_counter()
    # fault-free
    alarms = []
    stat_max = []
    for s in range(seeds * 2):
        _, r = _fly(_scenario(100 + s, []))
        m = r.summary["monitors"]["dem_integrity"]
        alarms.append(m["alarm_count"])
        stat_max.append(m["statistic_max"])
    out["fault_free"] = {"flights": len(alarms), "flights_with_alarm": int(np.count_nonzero(alarms)),
                         "statistic_max": float(max(stat_max)), "epochs_per_flight": int(DURATION_S) + 1}
    rows = {}
    cases = [("bias", b) for b in (20.0, 40.0, 60.0, 80.0, 100.0)] + [("ramp", 60.0), ("ramp", 100.0)]
    for kind, size in cases:
        fault = dict(PATCH, kind=kind, bias_m=size)
        if kind == "ramp":
            fault["direction_deg"] = 0.0        # rising along the (northbound) track
        det, tta, det_kf, tta_kf = [], [], [], []
        for s in range(seeds):
            loop, r = _fly(_scenario(200 + s, [fault]))
            t_in = _entry_time(r.arrays, fault)
            m = r.summary["monitors"]["dem_integrity"]
            a_t = r.arrays["monitor_dem_integrity_t_s"]
            a_al = r.arrays["monitor_dem_integrity_alarm"]
            hit = a_al & (a_t >= t_in)
            det.append(bool(hit.any()) and not bool((a_al & (a_t < t_in)).any()))
            if hit.any():
                tta.append(float(a_t[np.argmax(hit)] - t_in))
            # the Kalman-filtered statistic on the same flight's log (the map here is the faulted one: static)
            kf = create_monitor("dem_integrity", dem=loop.map_dem,
                                **{**monitor_settings(r.scenario, "dem_integrity"), "variant": "kalman"})
            rep = dm.replay_log(kf, r.arrays)
            hk = rep["alarm"] & (rep["t_s"] >= t_in)
            det_kf.append(bool(hk.any()))
            if hk.any():
                tta_kf.append(float(rep["t_s"][np.argmax(hk)] - t_in))
            _ = m
        rows[f"{kind}_{int(size)}m"] = {
            "flights": seeds, "p_detect": float(np.mean(det)), "p_md": 1.0 - float(np.mean(det)),
            "time_to_alarm_s_mean": float(np.mean(tta)) if tta else None,
            "time_to_alarm_s_max": float(np.max(tta)) if tta else None,
            "kalman_p_detect": float(np.mean(det_kf)),
            "kalman_time_to_alarm_s_mean": float(np.mean(tta_kf)) if tta_kf else None}
    out["faults"] = rows
    out["seconds"] = time.perf_counter() - t0
    return out


def stale_patch(seeds: int) -> dict:
    """GNSS denied from 10 s; the default scenario's route (600 m above ground), the map along its second
    (eastbound) leg taken from 5 km south: entered after about 210 s of flight (five TERCOM fixes after the
    start: the navigator is "ok" by then), left about 120 s later (three fixes inside)."""
    from trn_env.output.integrity_metrics import flag_before_error
    fault = {"kind": "stale", "center_lat_deg": 36.6400, "center_lon_deg": -84.2750, "size_n_m": 3000.0,
             "size_e_m": 10000.0, "source_offset_n_m": -5000.0, "source_offset_e_m": 0.0}
    res = []
    t0 = time.perf_counter()
    for s in range(seeds):
        sc = _scenario(300 + s, [fault], outage=True, duration_s=360.0, route=DEFAULT_ROUTE)
        _, r = _fly(sc)
        a = r.arrays
        t_in = _entry_time(a, fault) or 0.0
        f = flag_before_error(a["t_s"], a["err_ned_m"], a["est_cov_diag"], a["nav_status_code"],
                              t_from_s=t_in)
        healthy_at_entry = bool(a["nav_status_code"][np.searchsorted(a["t_s"], t_in)] == 0)
        f.update(t_entry_s=t_in, mi_time_s=r.summary["misleading_information_time_s"],
                 healthy_at_entry=healthy_at_entry,
                 t_dem_alarm_s=r.summary["monitors"]["dem_integrity"]["first_alarm_t_s"],
                 fraction_healthy=r.summary["fraction_healthy"], termination=r.termination,
                 h_err_max_m=r.summary["horizontal_error_max_m"],
                 recoveries=sum("recovery:" in msg for _, _, msg in r.events))
        res.append(f)
    first = [x["flag_first"] for x in res]
    flagged = [x["t_flag_s"] is not None for x in res]
    left = [x["t_error_outside_s"] is not None for x in res]
    dem_first = [x["t_dem_alarm_s"] is not None
                 and (x["t_error_outside_s"] is None or x["t_dem_alarm_s"] <= x["t_error_outside_s"])
                 for x in res]
    return {"flights": seeds, "fraction_flag_first": float(np.mean(first)),
            "fraction_dem_alarm_before_error": float(np.mean(dem_first)),
            "fraction_flagged": float(np.mean(flagged)), "fraction_error_left_3sigma": float(np.mean(left)),
            "misleading_information_time_s_mean": float(np.mean([x["mi_time_s"] for x in res])),
            "misleading_information_time_s_max": float(np.max([x["mi_time_s"] for x in res])),
            "runs": res, "seconds": time.perf_counter() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tests", type=int, default=1_000_000, help="vectorised fault-free tests (default 1e6)")
    ap.add_argument("--seeds", type=int, default=5, help="closed-loop flights per fault case")
    ap.add_argument("--vectorised-only", action="store_true")
    ap.add_argument("--stale-only", action="store_true", help="only part 4 (the navigator's own flag)")
    ap.add_argument("--skip-vectorised", action="store_true", help="parts 3 and 4 only")
    ap.add_argument("--json", default=None, help="write the figures to this file")
    args = ap.parse_args(argv)
    out = {}
    if args.stale_only:
        out["stale_patch"] = stale_patch(max(args.seeds * 2, 6))
        print(json.dumps(out["stale_patch"], indent=1), flush=True)
        args.vectorised_only = True
    elif not args.skip_vectorised:
        out["vectorised"] = vectorised(args.tests)
        print(json.dumps(out["vectorised"], indent=1), flush=True)
    if not args.vectorised_only:
        out["closed_loop"] = closed_loop(args.seeds)
        print(json.dumps(out["closed_loop"], indent=1), flush=True)
        out["stale_patch"] = stale_patch(max(args.seeds * 2, 6))
        print(json.dumps({k: v for k, v in out["stale_patch"].items() if k != "runs"}, indent=1), flush=True)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
