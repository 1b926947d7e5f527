"""Reproduce seed 000 sections 4.3-4.4: IRA-aided batch TERCOM in crosswind, conventional vs proposed
closest-point formula, Monte Carlo over the four cases of Table 3, printed like Table 4.

    python scripts/reproduce_seed000.py --runs 50 --out out/seed000

Set-up (Table 2 where it says; our choices marked): the King Air flown by JSBSim (trn_env.flight) at about
5600 m MSL and 83 m/s (falls back to the nearest speed the current aircraft model trims at), S-turns along a
north-east track over the jacksboro DEM resampled to 10 m (bicubic) plus a small fractal detail (ours:
--detail-rms, to give the 10 m grid sub-post texture), a steady crosswind (ours: --wind, from the left of
the track), navigation-grade IMU (Table 2), baro, IRA 50 Hz (sigma_R 3.5 m, sigma_theta 0.1 deg), initial
errors of Table 2, TERCOM 101 x 101 x 5 m every 40 s, filter noise (10 m)^2. The truth is flown once; each
Monte Carlo run draws new sensor noise and initial errors (the same draws for every case and formula).
Table 4's figure: RMS over runs of the error at each fix time, averaged over the fix times.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from trn_env.navigators import registry
from trn_env.navigators.filters.ins_trn_ekf import initial_covariance
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.measurements.ira_closest_point import closest_point_ned, effective_look_angle
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain
from trn_env.flight.core import (
    AutopilotTargets,
    Flight,
    InitialCondition,
    LateralMode,
    TrimError,
    VerticalMode,
)
from trn_env.flight.truth import TruthChunk
from trn_env.flight.wind import WindConfig
from trn_env.output.run_folder import folder_problem
from trn_env.sensors.suite import SensorSuite

CASES = {1: 0.0, 2: 5.0, 3: 10.0, 4: 15.0}  # Table 3: all data, dp > 5, 10, 15 m


def refined_dem(
    base: Dem, lat_c: float, lon_c: float, half_m: float, spacing_m: float, detail_rms_m: float, seed: int
) -> Dem:
    """The base DEM resampled (bicubic) to spacing_m over a square of +-half_m around (lat_c, lon_c), plus a
    zero-mean fractal detail of detail_rms_m (terrain.synthetic.psd_field, correlation length 200 m)."""
    from trn_env.terrain.synthetic import psd_field

    r_n = meridian_radius_m(lat_c)
    r_e = prime_vertical_radius_m(lat_c) * math.cos(lat_c)
    n = int(2 * half_m / spacing_m) + 1
    dlat, dlon = spacing_m / r_n, spacing_m / r_e
    lat0, lon0 = lat_c - half_m / r_n, lon_c - half_m / r_e
    la = lat0 + np.arange(n) * dlat
    lo = lon0 + np.arange(n) * dlon
    h = base.height(la[:, None], lo[None, :], method="bicubic")
    if detail_rms_m > 0:
        h = h + detail_rms_m * psd_field((n, n), spacing_m, 200.0, 0.8, np.random.default_rng(seed))
    return Dem(h, lat0, lon0, dlat, dlon, f"{base.name}-{spacing_m:g}m")


def fly(args, dem: Dem) -> tuple[TruthChunk, float]:
    lat_c, lon_c = dem.center_rad
    track = math.radians(args.track_deg)
    r_n = meridian_radius_m(lat_c)
    r_e = prime_vertical_radius_m(lat_c) * math.cos(lat_c)
    half = 0.5 * args.tas * args.duration
    lat0 = lat_c - half * math.cos(track) / r_n
    lon0 = lon_c - half * math.sin(track) / r_e
    wind = WindConfig.constant((args.track_deg - 90.0) % 360.0, args.wind)  # from the left of the track
    for tas in [args.tas] + [args.tas + d for d in (2, 5, 8, 12, 17, 22)]:
        try:
            fl = Flight(
                InitialCondition(lat0, lon0, args.h, tas, track),
                wind=wind,
                terrain_elevation_m=float(np.nanmax(dem.heights_m)),
            )
            break
        except TrimError as exc:
            print(f"  trim failed at {tas:.0f} m/s: {exc}")
    else:
        raise SystemExit("the aircraft does not trim near the requested condition")
    chunks = [fl.snapshot()]
    steps_per_s = int(round(1.0 / fl.dt_s))
    for k in range(int(args.duration)):
        if k % 30 == 0:  # S-turns: +-turn_deg about the mean track every 30 s
            sign = 1 if (k // 30) % 2 == 0 else -1
            fl.set_targets(
                AutopilotTargets(
                    lateral_mode=LateralMode.TRACK,
                    track_cmd_rad=track + sign * math.radians(args.turn_deg),
                    vertical_mode=VerticalMode.ALTITUDE_MSL,
                    altitude_cmd_m=args.h,
                    tas_cmd_mps=tas,
                    bank_limit_rad=math.radians(25),
                )
            )
        chunks.append(fl.advance(steps_per_s))
    return TruthChunk.concatenate(chunks), tas


def slice_frames(fr: SensorFrames, t0: float, t1: float) -> SensorFrames:
    out = SensorFrames(t0, t1)
    for name in ("imu", "baro", "ira"):
        f = getattr(fr, name)
        if f is None:
            continue
        sel = (f.t_s >= t0) & (f.t_s < t1)
        setattr(out, name, replace(f, **{k: v[sel] for k, v in vars(f).items() if isinstance(v, np.ndarray)}))
    return out


def geometry_stats(truth: TruthChunk, frames: SensorFrames) -> dict:
    """(theta - roll) - xi and dp between the formulas on noise-free truth attitude/velocity (Figs 15-16)."""
    ira = frames.ira
    k = np.clip(np.searchsorted(truth.t_s, ira.t_s), 0, len(truth) - 1)
    ok = ira.valid
    C = truth.C_bn[k][ok]
    v = truth.v_ned_mps[k][ok]
    R, th = ira.range_m[ok], ira.look_angle_rad[ok]
    xi, _ = effective_look_angle(th, C, v)
    dang = (th - truth.roll_rad[k][ok]) - xi
    pp = closest_point_ned(R, th, None, None, None, v, "proposed", C)
    pc = closest_point_ned(R, th, None, None, None, v, "conventional", C)
    dp = np.hypot(pp[:, 0] - pc[:, 0], pp[:, 1] - pc[:, 1])
    return {
        "angle_diff_deg_max": float(np.degrees(np.nanmax(np.abs(dang)))),
        "angle_diff_deg_rms": float(np.degrees(np.sqrt(np.nanmean(dang**2)))),
        "dp_m_median": float(np.nanmedian(dp)),
        "dp_m_max": float(np.nanmax(dp)),
        "dp_frac_below_5m": float(np.mean(dp < 5)),
        "dp_frac_below_10m": float(np.mean(dp < 10)),
        "dp_frac_above_15m": float(np.mean(dp > 15)),
        "ira_valid_fraction": float(ok.mean()),
    }


def run_one(nav, truth: TruthChunk, frames: SensorFrames, init: Estimate, chunk_s: float):
    nav.reset(init)
    t_end = float(truth.t_s[-1])
    errs = []
    t = float(truth.t_s[0])
    n_fix_seen = 0
    while t < t_end:
        est = nav.update(slice_frames(frames, t, t + chunk_s))
        t += chunk_s
        if len(nav.fixes) > n_fix_seen:
            n_fix_seen = len(nav.fixes)
            k = min(int(np.searchsorted(truth.t_s, est.t_s)), len(truth) - 1)
            r_n = meridian_radius_m(truth.lat_rad[k]) + truth.h_msl_m[k]
            r_e = (prime_vertical_radius_m(truth.lat_rad[k]) + truth.h_msl_m[k]) * math.cos(truth.lat_rad[k])
            errs.append(
                (
                    (est.lat_rad - truth.lat_rad[k]) * r_n,
                    (est.lon_rad - truth.lon_rad[k]) * r_e,
                    est.t_s,
                    nav.fixes[-1].valid,
                )
            )
    return np.array(errs)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/seed000")
    ap.add_argument("--h", type=float, default=5600.0, help="flight altitude MSL, m")
    ap.add_argument("--tas", type=float, default=83.0)
    ap.add_argument("--wind", type=float, default=15.0, help="crosswind speed, m/s (from the left)")
    ap.add_argument("--track-deg", type=float, default=45.0)
    ap.add_argument("--turn-deg", type=float, default=10.0, help="S-turn amplitude about the mean track")
    ap.add_argument("--duration", type=float, default=255.0, help="s (Table 1: 255 s at 5 km)")
    ap.add_argument("--detail-rms", type=float, default=3.0)
    ap.add_argument("--ira-decimation", type=int, default=1, help="use every n-th IRA sample (1 = 50 Hz)")
    ap.add_argument("--cases", default="1,2,3,4")
    ap.add_argument("--formulas", default="conventional,proposed")
    args = ap.parse_args(argv)
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_wall = time.time()

    base = terrain.load("jacksboro")
    lat_c, lon_c = base.center_rad
    dem = refined_dem(
        base, lat_c, lon_c, 0.5 * args.tas * args.duration + 3000.0, 10.0, args.detail_rms, args.seed
    )
    print(
        f"terrain: {dem.name} {dem.heights_m.shape}, {np.nanmin(dem.heights_m):.0f}-"
        f"{np.nanmax(dem.heights_m):.0f} m"
    )
    truth, tas = fly(args, dem)
    crab = np.degrees(
        np.angle(np.exp(1j * (np.arctan2(truth.v_ned_mps[:, 1], truth.v_ned_mps[:, 0]) - truth.yaw_rad)))
    )
    print(
        f"flight: {len(truth)} steps, TAS {tas:.0f} m/s, h {truth.h_msl_m.mean():.0f} m, crab "
        f"{crab.min():.1f}..{crab.max():.1f} deg, roll {np.degrees(truth.roll_rad.min()):.1f}.."
        f"{np.degrees(truth.roll_rad.max()):.1f} deg"
    )

    # baro without bias: the paper's INS altitude was GPS-corrected (section 4.1); noise 0.5 m, lag 0.2 s
    sensors = {"imu": {}, "baro": {"bias_m": 0.0}, "ira": {}}
    geo = geometry_stats(truth, SensorSuite.from_config({"ira": {"noise_free": True}}, 0).sample(truth, dem))
    print("geometry (noise-free IRA on the truth):", json.dumps({k: round(v, 3) for k, v in geo.items()}))

    cases = [int(c) for c in args.cases.split(",")]
    formulas = args.formulas.split(",")
    ss = np.random.SeedSequence(args.seed)
    run_seeds = ss.spawn(args.runs)
    init_sig = np.array([30.0, 30.0, 15.0, 0.1, 0.1, 0.1, 0.05e-3, 0.05e-3, 1e-3])  # Table 2
    results = {f: {c: [] for c in cases} for f in formulas}
    for r in range(args.runs):
        rng = np.random.default_rng(run_seeds[r])
        frames = SensorFrames(float(truth.t_s[0]), float(truth.t_s[-1]) + 0.01)
        fr = SensorSuite.from_config(sensors, run_seeds[r].spawn(1)[0]).sample(truth, dem)
        frames.imu, frames.baro, frames.ira = fr.imu, fr.baro, fr.ira
        e = init_sig * rng.standard_normal(9)
        r_n = meridian_radius_m(truth.lat_rad[0]) + truth.h_msl_m[0]
        r_e = (prime_vertical_radius_m(truth.lat_rad[0]) + truth.h_msl_m[0]) * math.cos(truth.lat_rad[0])
        init = Estimate(
            float(truth.t_s[0]),
            truth.lat_rad[0] + e[0] / r_n,
            truth.lon_rad[0] + e[1] / r_e,
            truth.h_msl_m[0] - e[2],
            truth.v_ned_mps[0] + e[3:6],
            truth.roll_rad[0] + e[6],
            truth.pitch_rad[0] + e[7],
            truth.yaw_rad[0] + e[8],
            initial_covariance(),
        )
        for f in formulas:
            for c in cases:
                nav = registry.create(
                    "ins_tercom", dem=dem, formula=f, dp_min_m=CASES[c], ira_decimation=args.ira_decimation
                )
                results[f][c].append(run_one(nav, truth, frames, init, 1.0))
        print(f"  run {r + 1}/{args.runs} done ({time.time() - t_wall:.0f} s)", flush=True)

    table = {}
    print("\nTable 4 (average over fix times of the RMS over runs of the error at each fix), metres")
    print(f"{'method':<14}{'error':<18}" + "".join(f"{'case #' + str(c):>10}" for c in cases))
    for f in formulas:
        rows = {"Latitude Error": [], "Longitude Error": [], "Position Error": []}
        for c in cases:
            errs = results[f][c]
            n_fix = min(len(x) for x in errs)
            if n_fix == 0:
                for v in rows.values():
                    v.append(float("nan"))
                continue
            a = np.stack([x[:n_fix] for x in errs])  # runs x fixes x (dn, de, t, valid)
            rms_n = np.sqrt(np.mean(a[:, :, 0] ** 2, axis=0))
            rms_e = np.sqrt(np.mean(a[:, :, 1] ** 2, axis=0))
            rows["Latitude Error"].append(float(rms_n.mean()))
            rows["Longitude Error"].append(float(rms_e.mean()))
            rows["Position Error"].append(float(np.sqrt(rms_n**2 + rms_e**2).mean()))
            table.setdefault(f, {})[c] = {
                "lat_rms_m": rows["Latitude Error"][-1],
                "lon_rms_m": rows["Longitude Error"][-1],
                "pos_rms_m": rows["Position Error"][-1],
                "n_fixes": n_fix,
                "valid_fix_fraction": float(a[:, :, 3].mean()),
            }
        for i, (name, vals) in enumerate(rows.items()):
            print(f"{f if i == 0 else '':<14}{name:<18}" + "".join(f"{v:>10.2f}" for v in vals))
    summary = {
        "args": vars(args),
        "tas_mps": tas,
        "geometry": geo,
        "table4": table,
        "wall_time_s": time.time() - t_wall,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(2, len(formulas), figsize=(6 * len(formulas), 7), squeeze=False)
        for j, f in enumerate(formulas):
            for c in cases:
                errs = results[f][c]
                n_fix = min(len(x) for x in errs)
                if n_fix == 0:
                    continue
                a = np.stack([x[:n_fix] for x in errs])
                tt = a[0, :, 2]
                axs[0, j].plot(tt, np.sqrt(np.mean(a[:, :, 0] ** 2, axis=0)), "o-", label=f"case #{c}")
                axs[1, j].plot(tt, np.sqrt(np.mean(a[:, :, 1] ** 2, axis=0)), "o-", label=f"case #{c}")
            axs[0, j].set_title(f"{f}: latitude RMS error (m)")
            axs[1, j].set_title(f"{f}: longitude RMS error (m)")
            for ax in axs[:, j]:
                ax.set_xlabel("t (s)")
                ax.legend()
                ax.grid(True)
        fig.tight_layout()
        fig.savefig(out / "fig19_mc_rms.png", dpi=110)
        print(f"wrote {out / 'summary.json'} and {out / 'fig19_mc_rms.png'}")
    except Exception as exc:  # plotting is optional
        print(f"plot skipped: {exc}")
    return summary


if __name__ == "__main__":
    main()
