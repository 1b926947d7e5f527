"""IRA closest-point models inside the particle filter in a crosswind: seed 000's proposed formula (eqs 14-36)
against its conventional one (eq 13), as in issue 17.

Both models put the closest point in the zero-Doppler plane of the INS velocity (seed 000 eqs 9-12); they
differ only in the angle inside that plane. The IRA's look angle theta is interferometric - measured from the
plane perpendicular to the antenna baseline, i.e. the body y axis - so in a crosswind, where the body is
crabbed against the track, theta - roll (eq 13's substitution) is not the angle of the point in the
zero-Doppler plane; the effective look angle xi of eqs 30-35 is. Level, with crab angle c:
sin(theta) = cos(c) sin(xi), so eq 13 puts the point at R (xi - theta) ~ R theta (1/cos c - 1) from where it
is: 3 % of the across-track offset at c = 14 deg (seed 000 eq 40).

Conditions (a kinematic truth, [truth] source = "kinematic", so the geometry is exactly what is stated;
`--truth jsbsim` flies the King Air at 85 m/s instead, crab 13.6 deg): level flight at `--height` MSL
(default 5,600 m, seed 000's 5 km case, ~5 km above the terrain), 80 m/s true airspeed, a 20 m/s wind from
the west crossing the northbound track (crab asin(20/80) = 14.5 deg), 120 s over the Jacksboro DEM refined
to `--spacing` m posts with fractal detail (terrain.refine), map = world (a high-resolution map with no map
error, as the published comparison's; stated, not the bundled 3" map; `--map jacksboro` flies against the
3" map instead).
Sensors: navigation-grade IMU, barometer, IRA at 50 Hz with sigma_R `--range-sigma`, sigma_theta
`--look-sigma`; no GNSS. Navigator: `pf` (10,000 particles), terrain samples at `--rate` Hz, its noise
model told the IRA's sigmas, terrain_model_sigma_m `--model-sigma` (map = world: no unresolved terrain).
Each run draws new sensor noise and initial errors; both models run on the same frames and the same filter
seed, so the difference is the model alone.

Output: per model the horizontal RMS over t >= 30 s and all runs, the ratio conventional / proposed, and
the closest-point geometry (look angles, the two models' horizontal separation |dp|, the height residual
each gives at the true position with noise-free samples).

    PYTHONPATH=$PWD python scripts/ira_model_comparison.py [--runs 10] [--range-sigma 1.0] [--look-sigma 0.02]
        [--rate 5] [--spacing 30] [--height 5600] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from trn_env.navigators import registry
from trn_env.navigators.measurements.ira_closest_point import closest_point_ned
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

import trn_env.scenario.build as components
from trn_env.flight.kinematic import heading_for_track, wind_ned_from
from trn_env.output.run_folder import file_target_problem
from trn_env.scenario.loading import validate
from trn_env.sensors.ira import IraConfig, sample_ira
from trn_env.sim.closed_loop import perturbed_estimate
from trn_env.testing import truth_chunks

T_FROM_S = 30.0
LAT0_DEG, LON0_DEG = 36.475, -84.30   # flying north across the Jacksboro DEM
AIRSPEED_MPS, WIND_MPS, WIND_FROM_DEG = 80.0, 20.0, 270.0
JSBSIM_AIRSPEED_MPS = 85.0            # the King Air's, as in the built-in crosswind_5km


def scenario(height_m: float = 5600.0, spacing_m: float = 30.0, range_sigma_m: float = 1.0,
             look_sigma_deg: float = 0.02, rate_hz: float = 5.0, model_sigma_m: float = 0.5,
             duration_s: float = 120.0, formula: str = "proposed", seed: int = 0,
             n_particles: int = 10_000, ira_rate_hz: float = 50.0, map_dem: str = "world",
             truth: str = "kinematic") -> dict:
    """The comparison's scenario (data, validated by the caller): crosswind flight north, map = world.
    truth "kinematic" (default): the prescribed profile at 80 m/s; "jsbsim": the King Air at 85 m/s (as the
    built-in crosswind_5km; it flies the route on its autopilot, crabbing into the wind)."""
    kinematic = truth == "kinematic"
    airspeed = AIRSPEED_MPS if kinematic else JSBSIM_AIRSPEED_MPS
    wind = wind_ned_from(WIND_MPS, WIND_FROM_DEG)
    heading = math.degrees(heading_for_track(0.0, airspeed, wind))
    end_lat = LAT0_DEG + duration_s * 1.05 * airspeed / 111_000.0
    truth_table = {"source": "kinematic", "speed_mps": airspeed,
                   "segments": [{"kind": "straight", "duration_s": duration_s}]} if kinematic else {
                       "source": "jsbsim"}
    samples = "instant" if kinematic else "interval"
    return {
        "name": "ira_crosswind",
        "description": "IRA models in a 20 m/s crosswind (scripts/ira_model_comparison.py)",
        "seed": seed, "duration_s": duration_s, "truth": truth_table,
        "initial": {"lat_deg": LAT0_DEG, "lon_deg": LON0_DEG, "h_msl_m": height_m, "tas_mps": airspeed,
                    "heading_deg": heading},
        "route": {"tas_mps": airspeed,
                  "waypoints": [{"lat_deg": LAT0_DEG, "lon_deg": LON0_DEG, "h_msl_m": height_m},
                                {"lat_deg": end_lat, "lon_deg": LON0_DEG, "h_msl_m": height_m}]},
        "wind": {"layers": [{"altitude_m": 0.0, "direction_from_deg": WIND_FROM_DEG, "speed_mps": WIND_MPS}]},
        "terrain": {"world": {"dem": "jacksboro", "refinement": {"spacing_m": spacing_m}},
                    "map": {"dem": map_dem}},
        "sensors": {"imu": {"grade": "navigation", "sampling": samples}, "baro": {},
                    "ira": {"range_noise_m": range_sigma_m, "look_angle_noise_deg": look_sigma_deg,
                            "rate_hz": ira_rate_hz}},
        "navigator": {"name": "pf", "settings": {
            "ira_formula": formula, "measurement_rate_hz": rate_hz, "imu_samples": samples,
            "n_particles": n_particles,
            "ira_range_sigma_m": range_sigma_m, "ira_look_angle_sigma_deg": look_sigma_deg,
            "terrain_model_sigma_m": model_sigma_m}},
    }


def record(d: dict):
    """(scenario, world DEM, map DEM, truth chunks of 1 s, first truth row) of the scenario's flight, flown
    by the closed loop on the free INS (with a JSBSim truth guidance then follows the route; a kinematic
    truth does not care)."""
    sc = validate(d, source="ira_crosswind")
    rec = sc.to_dict()
    rec["navigator"] = {"name": "ins"}
    rec_sc = validate(rec, source="ira_crosswind_recording")
    chunks, truth0, world, the_map = truth_chunks(rec_sc, sc.duration_s - 1e-6)
    return sc, world, the_map, chunks, truth0


def geometry(world, chunks, ira_cfg: IraConfig) -> dict:
    """Noise-free IRA samples on the truth: look angles, |dp| between the two models and the height
    residual (measured minus map at the true position) of each."""
    from trn_env.flight.truth import TruthChunk
    tr = TruthChunk.concatenate(chunks)
    cfg = IraConfig.noise_free(rate_hz=5.0, half_window_deg=ira_cfg.half_window_deg)
    ira, _ = sample_ira(tr, world, np.random.default_rng(0), cfg)
    k = np.searchsorted(tr.t_s, ira.t_s - 1e-9)[ira.valid]
    R, th = ira.range_m[ira.valid], ira.look_angle_rad[ira.valid]
    C, v = tr.C_bn[k], tr.v_ned_mps[k]
    lat, lon, h = tr.lat_rad[k], tr.lon_rad[k], tr.h_msl_m[k]
    rn = meridian_radius_m(lat) + h
    re = (prime_vertical_radius_m(lat) + h) * np.cos(lat)
    out = {"samples": int(R.shape[0]), "range_median_m": float(np.median(R)),
           "look_angle_abs_deg_p10_p50_p90": [float(x) for x in np.percentile(np.degrees(np.abs(th)),
                                                                              [10, 50, 90])],
           "crab_deg": float(np.degrees(np.median(np.arctan2(v[:, 1], v[:, 0]) - tr.yaw_rad[k])))}
    p = {}
    for f in ("conventional", "proposed"):
        p[f] = closest_point_ned(R, th, None, None, None, v, f, C)
        resid = (h - p[f][:, 2]) - world.height(lat + p[f][:, 0] / rn, lon + p[f][:, 1] / re)
        out[f"height_residual_rms_m_{f}"] = float(np.sqrt(np.nanmean(resid ** 2)))
    dp = np.hypot(*(p["conventional"] - p["proposed"])[:, :2].T)
    out["dp_m_p50_p90"] = [float(np.median(dp)), float(np.percentile(dp, 90))]
    return out


def run_pf(sc, the_map, frames, chunks, initial, seed: int) -> np.ndarray:
    """Horizontal errors (m, one per second) of the scenario's navigator on the given frames."""
    nav = registry.create(sc.navigator.name, dem=the_map, rng=np.random.default_rng([seed, 29]),
                          **sc.navigator.table.to_dict())
    nav.reset(initial)
    err = []
    for fr, ch in zip(frames, chunks, strict=True):
        est = nav.update(fr)
        i = len(ch.t_s) - 1
        lat, h = float(ch.lat_rad[i]), float(ch.h_msl_m[i])
        dn = (est.lat_rad - lat) * (meridian_radius_m(lat) + h)
        de = (est.lon_rad - float(ch.lon_rad[i])) * (prime_vertical_radius_m(lat) + h) * math.cos(lat)
        err.append((dn, de))
    return np.array(err)


def compare(runs: int = 10, seed0: int = 500, log=print, t_from_s: float = T_FROM_S, **conditions) -> dict:
    """Horizontal RMS (t >= t_from_s, all runs) of the PF with each model on the same frames, their ratio,
    and the closest-point geometry (`geometry`). conditions: `scenario`'s keywords."""
    base = scenario(**conditions)
    sc, world, the_map, chunks, truth0 = record(base)
    t = np.array([float(c.t_s[-1]) for c in chunks])
    sel = t >= t_from_s
    scs = {f: validate(scenario(**conditions, formula=f), source=f"ira_crosswind_{f}")
           for f in ("proposed", "conventional")}
    e2 = {f: [] for f in scs}
    per_run = {f: [] for f in scs}
    wall = time.time()
    for r in range(runs):
        seed = seed0 + r
        suite = components.build_sensors(sc, np.random.SeedSequence([seed, 17]))
        frames = [suite.sample(c, world) for c in chunks]
        init = perturbed_estimate(truth0, 0, sc.initial_errors, np.random.default_rng([seed, 23]))
        for f, s in scs.items():
            err = run_pf(s, the_map, frames, chunks, init, seed)
            sq = np.sum(err[sel] ** 2, axis=1)
            e2[f].append(sq)
            per_run[f].append(float(np.sqrt(np.mean(sq))))
        if log:
            log(f"  run {r + 1}/{runs}: proposed {per_run['proposed'][-1]:.2f} m, "
                f"conventional {per_run['conventional'][-1]:.2f} m")
    out = {"conditions": {**{k: v for k, v in conditions.items()}, "runs": runs,
                          "airspeed_mps": float(sc.initial.tas_mps), "crosswind_mps": WIND_MPS,
                          "t_from_s": t_from_s},
           "geometry": geometry(world, chunks, sc.sensors.ira),
           "wall_s": time.time() - wall}
    for f in scs:
        out[f] = {"horizontal_rms_m": float(np.sqrt(np.mean(np.concatenate(e2[f])))),
                  "per_run_rms_m": per_run[f]}
    out["ratio_conventional_over_proposed"] = (out["conventional"]["horizontal_rms_m"]
                                               / out["proposed"]["horizontal_rms_m"])
    out["runs_conventional_worse"] = int(sum(c > p for c, p in zip(per_run["conventional"],
                                                                     per_run["proposed"], strict=True)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--range-sigma", type=float, default=1.0, help="IRA sigma_R (m)")
    ap.add_argument("--look-sigma", type=float, default=0.02, help="IRA sigma_theta (deg)")
    ap.add_argument("--rate", type=float, default=5.0, help="PF terrain samples per second")
    ap.add_argument("--spacing", type=float, default=30.0, help="world = map post spacing (m)")
    ap.add_argument("--height", type=float, default=5600.0, help="flight height (m MSL)")
    ap.add_argument("--model-sigma", type=float, default=0.5, help="PF terrain_model_sigma_m (m)")
    ap.add_argument("--map", default="world",
                    help='the navigator\'s map: "world" (default) or a DEM name, e.g. "jacksboro" '
                         '(the 3" DEM without the world\'s fractal detail)')
    ap.add_argument("--truth", choices=["kinematic", "jsbsim"], default="kinematic",
                    help="kinematic profile at 80 m/s (default) or the JSBSim King Air at 85 m/s")
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--seed", type=int, default=500)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    if a.out is not None and (problem := file_target_problem(a.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    res = compare(a.runs, a.seed, height_m=a.height, spacing_m=a.spacing, range_sigma_m=a.range_sigma,
                  look_sigma_deg=a.look_sigma, rate_hz=a.rate, model_sigma_m=a.model_sigma,
                  duration_s=a.duration, map_dem=a.map, truth=a.truth)
    print(json.dumps(res, indent=1))
    print(f"PF horizontal RMS (t >= {T_FROM_S:.0f} s, {a.runs} runs): proposed "
          f"{res['proposed']['horizontal_rms_m']:.2f} m, conventional "
          f"{res['conventional']['horizontal_rms_m']:.2f} m, ratio "
          f"{res['ratio_conventional_over_proposed']:.2f} (conventional worse in "
          f"{res['runs_conventional_worse']}/{a.runs} runs)")
    if a.out:
        a.out.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
