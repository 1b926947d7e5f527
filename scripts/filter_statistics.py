"""Monte Carlo statistics of the point-mass (`pmf`) and particle (`pf`) filters on the default scenario.

One JSBSim flight of the default scenario is flown once (navigator "ins", so the truth follows the route);
its truth chunks are kept and every run regenerates the real sensor suite's noise (trn_env.sensors, a new
seed per run), the initial estimate's error and the world's fractal detail (the terrain the 3" map does not
hold: the scenario's [terrain.world] refinement drawn again with the run's seed; --world-detail fixed keeps
the recorded one), then runs the navigators, built as the scenario builds them (build_navigator: its IMU's
specification, its barometer's lag), open-loop on those frames (guidance does not react to the
estimate: the truth is the same flight for every run). GNSS is denied from t = 0.

    PYTHONPATH=$PWD python scripts/filter_statistics.py [--runs 100] [--duration 180] [--out DIR]

Experiments (each prints a JSON block; --only NAME runs one):
- "convergence": 1 km (1 sigma) initial position error; fraction of runs within 50 m at the end (3 min of
  flight) for pmf, pf and ins_tercom (INS + batch TERCOM + EKF), with a 95 % Clopper-Pearson interval.
- "nees": the horizontal position NEES e' P^-1 e averaged over the converged runs (ANEES) at every update
  after t_converged_s, against the 95 % chi-square interval for 2 x runs degrees of freedom (divided by
  runs); the fraction of epochs inside and its binomial least value (nees_figures); the runs' common error;
  the pooled ANEES (all epochs of all runs) with bounds as if the epochs were independent, thinned to
  decorrelated epochs (the lag where the measured NEES autocorrelation falls below 0.1) and the runs'
  t interval (pooled_nees_figures).
- "crlb": horizontal RMS over the converged runs and t >= t_converged_s against terrain.metrics.track_crlb
  of the IRA samples the filter takes (map gradients at their true closest points, prior 1 km, the filter's
  position random walk and velocity offset: initial sigma from the scenario, the filter's velocity random
  walk; for the pmf also its acceleration offset: g x the initial tilt and accel_bias_sigma_mps2), with
  the filter's measurement variance and with the actual one (the IRA's noise + the measured world-minus-map
  RMS); and terrain.metrics.terrain_information's window CRLB along the track.
- "crosswind": a 20 m/s crosswind flight (crosswind_5km: 5,600 m MSL, seed 000's case), map = world (the
  high-resolution 30 m truth, as the published comparison's map), PF with the proposed (seed 000 eqs
  14-36) vs the conventional (eqs 9-13) closest point: horizontal RMS of each and their ratio.
- "turning" (only with --only turning): the PMF's NEES on the whole default flight (468 s, its two 80-90
  degree turns), 30 m initial error, --turning-runs runs from seed 4000 (the INS error model's heading-
  dependent part: the accelerometer bias turning with the aircraft, the heading error).
- "rate": PMF with terrain samples at 1 Hz (the default) vs 2 Hz and 5 Hz: horizontal RMS (the accuracy
  cost of the lower rate the speed figures use).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy import stats
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

import trn_env.scenario.build as components
from trn_env.output.run_folder import file_target_problem
from trn_env.scenario.loading import load_scenario
from trn_env.scenario.sections import from_dict
from trn_env.sim.closed_loop import perturbed_estimate
from trn_env.sim.nav_stage import gate_gnss
from trn_env.testing import truth_chunks

CONVERGED_M = 50.0


def record_flight(scenario: str = "default", duration_s: float = 180.0, wind_mps: float | None = None,
                  seed: int = 0):
    """(scenario data, truth chunks, world DEM, map DEM, truth at t = 0) of one closed-loop flight flown on
    the free INS."""
    sc = load_scenario(scenario, navigator="ins", duration_s=duration_s + 2.0, seed=seed)
    if wind_mps is not None:
        sc = sc.with_fields({"wind.layers": [
            {"altitude_m": 0.0, "direction_from_deg": 270.0, "speed_mps": wind_mps},
            {"altitude_m": 6000.0, "direction_from_deg": 270.0, "speed_mps": wind_mps}],
            "wind.turbulence": {"model": "none"}})
    chunks, truth0, world, the_map = truth_chunks(sc, duration_s)
    return sc.to_dict(), chunks, world, the_map, truth0


def sensor_frames(d: dict, chunks, world, seed: int, outages=({"start_s": 0.0},)):
    """The real sensor suite's frames of every chunk, with a run's own noise seed; GNSS gated."""
    suite = components.build_sensors(from_dict(d), np.random.SeedSequence([seed, 17]))
    return [gate_gnss(suite.sample(c, world), list(outages)) for c in chunks]


def initial_estimate(d: dict, truth0, seed: int, sigma_h_m: float):
    sig = dict(d["initial_errors"])
    sig["position_ned_m"] = [sigma_h_m, sigma_h_m, sig["position_ned_m"][2]]
    return perturbed_estimate(truth0, 0, sig, np.random.default_rng([seed, 23]))


def error_ne(est, chunk) -> tuple[float, float]:
    """(north, east) m of the estimate minus the truth at the chunk's last row (local radii at the truth)."""
    i = len(chunk.t_s) - 1
    lat, lon = float(chunk.lat_rad[i]), float(chunk.lon_rad[i])
    r_n = meridian_radius_m(lat) + float(chunk.h_msl_m[i])
    r_e = (prime_vertical_radius_m(lat) + float(chunk.h_msl_m[i])) * math.cos(lat)
    return (est.lat_rad - lat) * r_n, (est.lon_rad - lon) * r_e


def build_navigator(d: dict, name: str, settings: dict, map_dem, rng: np.random.Generator | None = None):
    """The navigator `name` as the scenario `d` builds it with [navigator.settings] = settings
    (trn_env.scenario.build.build_navigator: the settings the scenario's sensors and map imply, e.g. the
    barometer's lag and the IMU's specification, unless `settings` gives them)."""
    dd = {**d, "navigator": {"name": name, "settings": dict(settings)}}
    return components.build_navigator(from_dict(dd), map_dem, rng)


def run_navigator(d: dict, name: str, settings: dict, initial, frames, chunks, map_dem, seed: int) -> dict:
    """Errors (estimate minus truth, N/E m), covariance diagonals and timing of one navigator run, the
    navigator built as the scenario `d` builds it (build_navigator)."""
    nav = build_navigator(d, name, settings, map_dem, np.random.default_rng([seed, 29]))
    nav.reset(initial)
    t, err, cov = [], [], []
    wall = 0.0
    for fr, ch in zip(frames, chunks, strict=True):
        w0 = time.perf_counter()
        est = nav.update(fr)
        wall += time.perf_counter() - w0
        t.append(est.t_s)
        err.append(error_ne(est, ch))
        cov.append(est.covariance[:2, :2].copy())
    return {"t": np.array(t), "err": np.array(err), "cov": np.array(cov), "wall_s": wall,
            "recoveries": int(getattr(nav, "recoveries", 0))}


def clopper_pearson(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    a = 1.0 - conf
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def run_world(d: dict, world, seed: int, world_detail: str):
    """The true terrain of one run: the recorded flight's world ("fixed"), or the scenario's raw world DEM
    refined again with the run's own fractal detail ("redraw": the detail the map does not hold is the
    map error the filters model as random, so the runs must not share one draw of it)."""
    refinement = d["terrain"]["world"].get("refinement")
    if world_detail == "fixed" or not refinement:
        return world
    from trn_env import terrain
    raw = terrain.load(d["terrain"]["world"]["dem"], fill_voids=bool(d["terrain"]["world"].get("fill_voids")))
    return components.refine_dem(raw, refinement, np.random.default_rng([seed, 31]))


def monte_carlo(runs: int, duration_s: float, sigma_h_m: float, names: dict, seed0: int = 1000,
                flight=None, map_world: bool = False, log=print, world_detail: str = "redraw") -> dict:
    """{label: [run results]} of `runs` runs of each navigator in names {label: (name, settings)}; the world
    detail per run as `run_world` says (with map_world the map is the recorded world, so it stays fixed)."""
    d, chunks, world, the_map, truth0 = flight or record_flight(duration_s=duration_s)
    the_map = world if map_world else the_map
    out = {k: [] for k in names}
    for r in range(runs):
        seed = seed0 + r
        w = world if map_world else run_world(d, world, seed, world_detail)
        frames = sensor_frames(d, chunks, w, seed)
        init = initial_estimate(d, truth0, seed, sigma_h_m)
        for label, (name, settings) in names.items():
            run = run_navigator(d, name, settings, init, frames, chunks, the_map, seed)
            run["name"], run["sigma0_m"] = name, sigma_h_m
            out[label].append(run)
        if log and (r + 1) % max(1, runs // 10) == 0:
            fin = {k: round(float(np.hypot(*v[-1]["err"][-1])), 1) for k, v in out.items()}
            log(f"  run {r + 1}/{runs}: final errors {fin}")
    return out


def convergence_figures(res: dict, duration_s: float) -> dict:
    out = {}
    for label, runs in res.items():
        fin = np.array([np.hypot(*r["err"][-1]) for r in runs])
        k, n = int(np.sum(fin < CONVERGED_M)), len(runs)
        t_conv = []
        for r in runs:
            e = np.hypot(r["err"][:, 0], r["err"][:, 1])
            # first time after which the error stays below 50 m
            above = np.nonzero(e >= CONVERGED_M)[0]
            t_conv.append(r["t"][above[-1] + 1] if above.size and above[-1] + 1 < e.size
                          else (r["t"][0] if not above.size else math.inf))
        out[label] = {"runs": n, "within_50m_at_end": k, "fraction": k / n,
                      "fraction_95ci": clopper_pearson(k, n),
                      "median_final_error_m": float(np.median(fin)),
                      "median_time_to_stay_within_50m_s": float(np.median(t_conv)),
                      "wall_s_per_run": float(np.mean([r["wall_s"] for r in runs])),
                      "sim_s_per_wall_s": duration_s / float(np.mean([r["wall_s"] for r in runs]))}
    return out


DECORRELATED_ACF = 0.1   # autocorrelation below which NEES epochs count as independent samples


def nees_autocorrelation(nees: np.ndarray) -> np.ndarray:
    """Autocorrelation over lags 0 .. epochs - 2 of the runs' NEES series (runs x epochs) about the per-epoch
    ANEES, pooled over the runs (lag k from runs x (epochs - k) pairs): what is left once the time profile
    all runs share is taken out, i.e. the correlation that sets how many independent samples the pooled
    ANEES averages."""
    x = nees - nees.mean(axis=0, keepdims=True)
    v = float(np.mean(x * x))
    n_ep = x.shape[1]
    return np.array([np.mean(x[:, :n_ep - k] * x[:, k:]) / v for k in range(n_ep - 1)])


def pooled_nees_figures(nees: np.ndarray, dof: int = 2) -> dict:
    """The pooled ANEES (all runs x epochs) and its 95 % bounds three ways: (a) chi2(dof R E) / (R E) as if
    all R x E samples were independent (too narrow: epochs 1 s apart are strongly correlated); (b) thinned to
    every k-th epoch, k the first lag at which the NEES autocorrelation (nees_autocorrelation) falls below
    DECORRELATED_ACF, chi2 bounds for the R x ceil(E / k) samples left; (c) a t interval of the runs' time
    averages (the runs are independent whatever the epochs' correlation). Also the integrated autocorrelation
    time tau = 1 + 2 sum rho (lags up to the first non-positive rho) and R E / tau."""
    runs, n_ep = nees.shape
    acf = nees_autocorrelation(nees)
    below = np.nonzero(acf < DECORRELATED_ACF)[0]
    k = int(below[0]) if below.size else n_ep
    thin = nees[:, ::k]
    n_thin = thin.size
    nonpos = np.nonzero(acf <= 0.0)[0]
    tau = 1.0 + 2.0 * float(np.sum(acf[1:nonpos[0] if nonpos.size else acf.size]))
    n_all = runs * n_ep
    ta = nees.mean(axis=1)
    half = float(stats.t.ppf(0.975, runs - 1) * ta.std(ddof=1) / math.sqrt(runs))
    return {"anees_pooled": float(nees.mean()),
            "bounds_95_independent_epochs": [float(x) for x in stats.chi2.ppf([0.025, 0.975], dof * n_all)
                                             / n_all],
            "autocorrelation_lags_0_10_20_30_40_60": [float(acf[i]) for i in (0, 10, 20, 30, 40, 60)
                                                      if i < acf.size],
            "thinning_epochs": k, "thinned_samples": int(n_thin), "anees_thinned": float(thin.mean()),
            "bounds_95_thinned": [float(x) for x in stats.chi2.ppf([0.025, 0.975], dof * n_thin) / n_thin],
            "integrated_autocorrelation_epochs": tau, "effective_samples": n_all / tau,
            "runs_time_average_t_interval_95": [float(ta.mean() - half), float(ta.mean() + half)]}


def nees_figures(res: dict, t_from_s: float) -> dict:
    """Per-epoch ANEES (the horizontal NEES e' P^-1 e averaged over the converged runs) after t_from_s
    against its 95 % chi-square interval chi2.ppf([0.025, 0.975], 2 n) / n, the fraction of epochs inside
    it, and the least fraction a consistent filter shows with 97.5 % probability: binom.ppf(0.025, E, 0.95)
    / E over the E epochs (as if independent; neighbouring epochs are correlated, so the spread is wider).
    "pooled": the ANEES over all epochs and runs with its bounds (pooled_nees_figures: as if independent,
    thinned to decorrelated epochs, and the runs' t interval).
    "common_error": RMS over the epochs of the runs' mean error, against sqrt(mean trace P / n), what it is
    when the runs' errors are independent (larger: the runs share an error - one world, one flight)."""
    out = {}
    for label, runs in res.items():
        good = [r for r in runs if np.hypot(*r["err"][-1]) < CONVERGED_M]
        n = len(good)
        if n < 2:
            out[label] = {"runs": n}
            continue
        t = good[0]["t"]
        sel = t >= t_from_s
        E = np.array([r["err"][sel] for r in good])
        P = np.array([r["cov"][sel] for r in good])
        nees = np.einsum("rti,rtij,rtj->rt", E, np.linalg.inv(P), E)
        anees = nees.mean(axis=0)
        lo, hi = stats.chi2.ppf([0.025, 0.975], 2 * n) / n
        n_ep = int(sel.sum())
        inside = (anees >= lo) & (anees <= hi)
        m = E.mean(axis=0)
        axis_nees = E ** 2 / np.diagonal(P, axis1=2, axis2=3)
        out[label] = {"runs": n, "t_from_s": t_from_s, "epochs": n_ep, "anees_mean": float(anees.mean()),
                      "bounds_95": [float(lo), float(hi)],
                      "fraction_of_epochs_inside": float(np.mean(inside)),
                      "fraction_below": float(np.mean(anees < lo)),
                      "fraction_above": float(np.mean(anees > hi)),
                      "binomial_least_fraction_inside": float(stats.binom.ppf(0.025, n_ep, 0.95) / n_ep),
                      "pooled": pooled_nees_figures(nees),
                      "nees_per_axis_north_east": [float(x) for x in axis_nees.mean(axis=(0, 1))],
                      "common_error_rms_m": float(np.sqrt(np.mean(np.sum(m * m, axis=1)))),
                      "common_error_if_independent_m": float(np.sqrt(np.mean(np.trace(P, axis1=2, axis2=3))
                                                                     / n)),
                      "horizontal_rms_m": float(np.sqrt(np.mean(np.sum(E * E, axis=2)))),
                      "recoveries_per_run": float(np.mean([r.get("recoveries", 0) for r in runs]))}
    return out


def ira_track(d: dict, chunks, world, rate_hz: float):
    """(t, aircraft lat, lon, h, true closest-point lat, lon, h) of the IRA samples a filter at rate_hz takes
    (the first of each 1/rate_hz s), closest points on the true terrain (terrain.queries.ira_return)."""
    from trn_env.terrain import queries
    cfg = d["sensors"]["ira"]
    half = math.radians(float(cfg.get("half_window_deg", 45.0)))
    dt_ira = 1.0 / float(cfg.get("rate_hz", 50.0))
    rows = []
    t_next = -np.inf
    t_ira = -np.inf
    for ch in chunks:
        for i in range(len(ch.t_s)):
            if ch.t_s[i] >= t_ira + dt_ira - 1e-9:
                t_ira = ch.t_s[i]
                if ch.t_s[i] >= t_next - 1e-9:
                    t_next = ch.t_s[i] + 1.0 / rate_hz
                    rows.append((ch, i))
    col = [np.array([getattr(c, f)[i] for c, i in rows]) for f in ("t_s", "lat_rad", "lon_rad", "h_msl_m",
                                                                   "v_ned_mps", "C_bn")]
    ret = queries.ira_return(world, col[1], col[2], col[3], col[4], col[5], half)
    return col[0], col[1], col[2], col[3], ret.lat_rad, ret.lon_rad, ret.h_m


def crlb_figures(res: dict, flight, t_from_s: float, settings: dict | None = None) -> dict:
    """Horizontal RMS of the converged runs after t_from_s against terrain.metrics.track_crlb of the IRA
    samples the filter takes, at their true closest points, with (a) the filter's own measurement variance
    (its sensor, map and terrain-model noise) and (b) the actual one: the sensor's noise plus the measured
    variance of world minus map at those points; both with the filter's prior (the initial 1 sigma) and its
    position random walk as the process noise. Also terrain.metrics.terrain_information's window CRLB (every
    post of a 2 km window measured) along the track, for comparison."""
    from trn_env.terrain import metrics
    d, chunks, world, the_map, _ = flight
    settings = settings or {}
    out = {"t_from_s": t_from_s}
    for label, runs in res.items():
        name = runs[0].get("name", label)
        nav = build_navigator(d, name, dict(settings.get(label) or {}), the_map, np.random.default_rng(0))
        t, lat, lon, h, plat, plon, ph = ira_track(d, chunks, world, nav.measurement_rate_hz)
        r_n = meridian_radius_m(lat) + h
        r_e = (prime_vertical_radius_m(lat) + h) * np.cos(lat)
        p_n, p_e, p_d = (plat - lat) * r_n, (plon - lon) * r_e, h - ph
        rng_m = np.sqrt(p_n**2 + p_e**2 + p_d**2)
        var_filter = nav.ira_variance(rng_m, p_d, np.hypot(p_n, p_e))
        var_sensor = (nav.ira_range_sigma_m * p_d / rng_m) ** 2 + (nav.ira_look_angle_sigma_rad
                                                                   * np.hypot(p_n, p_e)) ** 2
        map_err = world.height(plat, plon) - the_map.height(plat, plon, method=nav.map_interpolation)
        map_sigma = float(np.nanstd(map_err))
        q = (nav.position_noise if name == "pmf" else nav.s_pos) ** 2
        s_v = nav.velocity_noise if name == "pmf" else nav.s_vel
        p0 = float(runs[0].get("sigma0_m", 1000.0))
        # both filters carry the INS's velocity offset (its error is a ramp): the bound does too, with the
        # scenario's initial velocity sigma and the filter's velocity random walk
        sv0 = float(d["initial_errors"]["velocity_ned_mps"][0])
        # the pmf also carries the INS error's acceleration (initial tilt times g and the accelerometer bias,
        # constant in NED on this straight flight): its bound too
        s_a = 0.0
        if name == "pmf":
            tilt_rad = 1e-3 * float(d["initial_errors"]["attitude_mrad"][0])
            s_a = math.hypot(9.80665 * tilt_rad, nav.accel_bias_sigma)
        kw = dict(t_s=t, prior_sigma_m=p0, process_noise_m2_per_s=q, method=nav.map_interpolation,
                  velocity_prior_sigma_mps=sv0, velocity_noise_mps_per_sqrt_s=s_v,
                  acceleration_prior_sigma_mps2=s_a)
        b_filter = metrics.track_crlb(the_map, plat, plon, np.sqrt(var_filter), **kw).rms_m(t_from_s)
        b_actual = metrics.track_crlb(the_map, plat, plon, np.sqrt(var_sensor), map_sigma_m=map_sigma,
                                      **kw).rms_m(t_from_s)
        good = [r for r in runs if np.hypot(*r["err"][-1]) < CONVERGED_M]
        if not good:
            continue
        sel = good[0]["t"] >= t_from_s
        e2 = np.concatenate([np.sum(r["err"][sel] ** 2, axis=1) for r in good])
        rms = float(np.sqrt(np.mean(e2)))
        out[label] = {"runs": len(good), "horizontal_rms_m": rms, "process_noise_m2_per_s": q,
                      "filter_sigma_z_m_median": float(np.median(np.sqrt(var_filter))),
                      "world_minus_map_sigma_m": map_sigma,
                      "track_crlb_filter_noise_m": b_filter,
                      "ratio_to_track_crlb_filter_noise": rms / b_filter,
                      "track_crlb_actual_noise_m": b_actual,
                      "ratio_to_track_crlb_actual_noise": rms / b_actual}
        if "terrain_metrics_window_crlb_m_median_along_track" not in out:
            sz = float(np.median(np.sqrt(var_filter)))
            info = metrics.terrain_information(the_map, sz, 2000.0)
            crlb_map = the_map.with_heights(np.nan_to_num(np.asarray(info.crlb_sigma_h_m, float), nan=1e4,
                                                          posinf=1e4))
            out["terrain_metrics_window_crlb_m_median_along_track"] = float(
                np.median(crlb_map.height(lat, lon)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--duration", type=float, default=180.0)
    ap.add_argument("--sigma", type=float, default=1000.0,
                    help="initial horizontal error, 1 sigma per axis (m)")
    ap.add_argument("--ekf-runs", type=int, default=20)
    ap.add_argument("--crosswind-runs", type=int, default=10)
    ap.add_argument("--crosswind-scenario", default="crosswind_5km",
                    help="flight of the crosswind comparison (default: seed 000's 5,600 m MSL case)")
    ap.add_argument("--only", default=None, choices=["convergence", "crosswind", "rate", "turning"])
    ap.add_argument("--turning-runs", type=int, default=30)
    ap.add_argument("--world-detail", default="redraw", choices=["redraw", "fixed"],
                    help="the world's fractal detail drawn per run (default) or the recorded flight's")
    ap.add_argument("--out", default=None, help="write the figures as JSON here")
    args = ap.parse_args(argv)
    if args.out is not None and (problem := file_target_problem(args.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    figures = {}
    t0 = time.time()
    if args.only in (None, "convergence"):
        print(f"recording the default flight ({args.duration:.0f} s) ...", flush=True)
        flight = record_flight(duration_s=args.duration)
        names = {"pmf": ("pmf", {}), "pf": ("pf", {})}
        res = monte_carlo(args.runs, args.duration, args.sigma, names, flight=flight,
                          world_detail=args.world_detail)
        ekf = monte_carlo(args.ekf_runs, args.duration, args.sigma,
                          {"ins_tercom": ("ins_tercom", {"remove_bias": True})}, flight=flight,
                          world_detail=args.world_detail) \
            if args.ekf_runs else {}
        figures["convergence"] = convergence_figures({**res, **ekf}, args.duration)
        print(json.dumps({"convergence": figures["convergence"]}, indent=1), flush=True)
        figures["nees"] = nees_figures(res, 60.0)
        print(json.dumps({"nees": figures["nees"]}, indent=1), flush=True)
        figures["crlb"] = crlb_figures(res, flight, 60.0)
        print(json.dumps({"crlb": figures["crlb"]}, indent=1), flush=True)
    if args.only == "turning":
        flight = record_flight(duration_s=468.0)
        res = monte_carlo(args.turning_runs, 468.0, 30.0, {"pmf": ("pmf", {})}, flight=flight, seed0=4000,
                          world_detail=args.world_detail)
        figures["turning"] = nees_figures(res, 60.0)
        print(json.dumps({"turning": figures["turning"]}, indent=1), flush=True)
    if args.only in (None, "rate"):
        flight = record_flight(duration_s=120.0)
        names = {f"pmf_{r:g}hz": ("pmf", {"measurement_rate_hz": r}) for r in (1.0, 2.0, 5.0)}
        res = monte_carlo(args.crosswind_runs, 120.0, 30.0, names, flight=flight, seed0=3000)
        figures["rate"] = {k: {"horizontal_rms_m_t_ge_30s": float(np.sqrt(np.mean(np.concatenate(
            [np.sum(r["err"][r["t"] >= 30.0] ** 2, axis=1) for r in v])))),
            "sim_s_per_wall_s": 120.0 / float(np.mean([r["wall_s"] for r in v]))} for k, v in res.items()}
        print(json.dumps({"rate": figures["rate"]}, indent=1), flush=True)
    if args.only in (None, "crosswind"):
        flight = record_flight(args.crosswind_scenario, duration_s=120.0, wind_mps=20.0)
        names = {"pf_proposed": ("pf", {"ira_formula": "proposed", "terrain_model_sigma_m": 1.0}),
                 "pf_conventional": ("pf", {"ira_formula": "conventional", "terrain_model_sigma_m": 1.0})}
        res = monte_carlo(args.crosswind_runs, 120.0, 30.0, names, flight=flight, map_world=True, seed0=2000)
        cw = {}
        for k, v in res.items():
            e2 = np.concatenate([np.sum(r["err"][r["t"] >= 30.0] ** 2, axis=1) for r in v])
            cw[k] = {"runs": len(v), "horizontal_rms_m_t_ge_30s": float(np.sqrt(np.mean(e2)))}
        cw["ratio_conventional_over_proposed"] = (cw["pf_conventional"]["horizontal_rms_m_t_ge_30s"]
                                                  / cw["pf_proposed"]["horizontal_rms_m_t_ge_30s"])
        v = flight[1]
        crab = [math.degrees(math.atan2(c.v_ned_mps[-1, 1], c.v_ned_mps[-1, 0]) - c.yaw_rad[-1])
                for c in v[30:]]
        cw["median_crab_deg"] = float(np.median(np.abs(crab)))
        figures["crosswind"] = cw
        print(json.dumps({"crosswind": cw}, indent=1), flush=True)
    figures["wall_s"] = time.time() - t0
    if args.out:
        Path(args.out).write_text(json.dumps(figures, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
