"""The IRA's range and look-angle residuals at the TRUE state of recorded flights, on the world and on the
`rbpf`'s map, against the filter's map-noise model (docs/validation/integrity.md, section 6.8):

    PYTHONPATH=. python scripts/ira_look_angle_residuals.py LOG [LOG ...] [--calibration-height-m 1500]
        [--json out.json]

LOG: a sensor log folder with the flight's truth (`trn-env record`, or the protection-level campaign's
OUT/logs/<condition>/s<seed>). For every 1 Hz epoch after the first, the IRA sample the `rbpf` takes there
(the one at the epoch's time: navigators.measurements.sampling.ira_epochs) is compared with eqs 23 and 26
(ira_seed002.predict_ira, with the filter's look window and search step) evaluated at the truth's position,
velocity and attitude, on the world the log was flown over and on the navigator's map (both rebuilt as
`trn-env replay` rebuilds them). The model is the filter's measurement variance without tempering: the
sensor's plus ira_seed002.map_noise_variances with the filter's calibration at each sample's range
(`RaoBlackwellizedPF.terrain_factors`), or, with --calibration-height-m, the calibration at that one height
for every sample (1500: the filter before it calibrated at the flight's height).

Per flight (epochs where both searches return): the look angle's robust sigma (1.4826 x the median absolute
deviation) on the world and on the map, the model's RMS sigma, the mean and median of z^2 = residual^2 /
model variance on the map (a Gaussian with the model's variance: 1 and 0.455), the share beyond 3 model
sigmas (0.27 %), the lag-1..3 autocorrelations of z, and the range's mean z^2. A log with lever arms is
compensated to the IMU as a replay does.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy.stats import median_abs_deviation

Z_AT = ("z2_mean", "z2_median", "beyond_3_sigma", "lag1", "lag2", "lag3")


def _autocorrelation(z: np.ndarray, lag: int) -> float:
    x = z - z.mean()
    return float(np.sum(x[:-lag] * x[lag:]) / np.sum(x * x))


def residuals(path: str | Path, calibration_height_m: float | None = None) -> dict:
    """Per-epoch residuals of one log and their figures (see the module doc); LogError on a bad log."""
    from trn_env.navigators.measurements import ira_seed002 as im
    from trn_env.navigators.measurements.lever_arm import compensate_frames, has_lever_arms
    from trn_env.terrain.geodesy import euler_to_C_bn

    from trn_env.logs import read_log
    from trn_env.logs.replay import build_maps, scenario_of
    from trn_env.scenario.build import build_navigator
    from trn_env.sim.closed_loop import spawn_rngs

    log = read_log(path)
    d = scenario_of(log, "rbpf", {}, None)
    world, the_map, _ = build_maps(log, d, None)
    nav = build_navigator(d, the_map, spawn_rngs(0)["navigator"])
    truth = log.truth()
    if truth is None or not len(truth):
        raise ValueError(f"log {log.path}: no truth table (a recorded flight is needed)")
    arms = log.metadata.get("lever_arms_m") or {}
    frames = [compensate_frames(f, arms) if has_lever_arms(arms) else f for f in log.frames()]
    frames = [f for f in frames if f.ira is not None]
    if not frames:
        raise ValueError(f"log {log.path}: no IRA samples")
    t_ira = np.concatenate([f.ira.t_s for f in frames])
    r_ira = np.concatenate([f.ira.range_m for f in frames])
    th_ira = np.concatenate([f.ira.look_angle_rad for f in frames])
    ok_ira = np.concatenate([np.asarray(f.ira.valid, bool) for f in frames])
    rows = []
    for k in range(1, len(truth)):
        row = truth.iloc[k]
        j = int(np.searchsorted(t_ira, float(row.t_s) - 1e-9))
        if j >= t_ira.size or abs(t_ira[j] - float(row.t_s)) > 1e-6 or not ok_ira[j]:
            continue
        lat, lon, h = np.array([row.lat_rad]), np.array([row.lon_rad]), np.array([row.h_m])
        v = np.array([row.v_n_mps, row.v_e_mps, row.v_d_mps], float)
        C = euler_to_C_bn(float(row.roll_rad), float(row.pitch_rad), float(row.yaw_rad))
        on_map, on_world = (im.predict_ira(dem, lat, lon, h, v, C, nav.half_window_rad, nav.max_range_m,
                                           ds_m=nav.search_step_m)[0] for dem in (the_map, world))
        if not (on_map[im.OUT_VALID] > 0.5 and on_world[im.OUT_VALID] > 0.5):
            continue
        r_cal = r_ira[j] if calibration_height_m is None else calibration_height_m
        var = nav.r_var + im.map_noise_variances(nav.map_sigma_m, nav.terrain_model_sigma_m, r_ira[j],
                                                 nav.terrain_factors(r_cal))
        rows.append((th_ira[j] - on_map[im.OUT_THETA], th_ira[j] - on_world[im.OUT_THETA],
                     r_ira[j] - on_map[im.OUT_R], var[0], var[1]))
    if len(rows) < 10:
        raise ValueError(f"log {log.path}: {len(rows)} epochs with a return on both world and map (need 10)")
    a = np.array(rows)
    z = a[:, 0] / np.sqrt(a[:, 4])
    z2 = z ** 2
    return {"log": str(log.path), "epochs": int(a.shape[0]),
            "terrain_model_sigma_m": float(nav.terrain_model_sigma_m),
            "theta_robust_sigma_world_deg": math.degrees(median_abs_deviation(a[:, 1], scale="normal")),
            "theta_robust_sigma_map_deg": math.degrees(median_abs_deviation(a[:, 0], scale="normal")),
            "theta_model_sigma_deg": math.degrees(math.sqrt(float(np.mean(a[:, 4])))),
            "z2_mean": float(np.mean(z2)), "z2_median": float(np.median(z2)),
            "beyond_3_sigma": float(np.mean(np.abs(z) > 3.0)),
            "lag1": _autocorrelation(z, 1), "lag2": _autocorrelation(z, 2), "lag3": _autocorrelation(z, 3),
            "range_z2_mean": float(np.mean(a[:, 2] ** 2 / a[:, 3]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="sensor log folders with truth")
    ap.add_argument("--calibration-height-m", type=float, default=None,
                    help="calibrate the map noise at this height for every sample (default: the filter's, "
                         "at each sample's range)")
    ap.add_argument("--json", default=None, help="write the figures here (.json)")
    args = ap.parse_args(argv)
    h = args.calibration_height_m
    if h is not None and not (math.isfinite(h) and h > 0.0):
        ap.error(f"--calibration-height-m: must be a positive height in m, got {h}")
    for p in args.logs:
        if not Path(p).is_dir():
            ap.error(f"log {p}: no such folder")
    if args.json is not None:
        from trn_env.output.run_folder import file_target_problem
        problem = file_target_problem(args.json, "--json", (".json",))
        if problem:
            ap.error(problem)
    from trn_env.logs.format import LogError
    out = []
    for p in args.logs:
        try:
            m = residuals(p, h)
        except (LogError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        out.append(m)
        print(f"{m['log']}: {m['epochs']} epochs; look angle robust sigma world "
              f"{m['theta_robust_sigma_world_deg']:.3f} deg, map {m['theta_robust_sigma_map_deg']:.2f} deg, "
              f"model {m['theta_model_sigma_deg']:.2f} deg; z^2 mean {m['z2_mean']:.2f}, median "
              f"{m['z2_median']:.2f}, beyond 3 sigma {100 * m['beyond_3_sigma']:.1f} %; lags 1-3 "
              f"{m['lag1']:+.2f} {m['lag2']:+.2f} {m['lag3']:+.2f}; range z^2 mean {m['range_z2_mean']:.2f}")
    if args.json is not None:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
