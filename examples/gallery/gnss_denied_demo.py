"""GNSS denied: INS alone against INS + TERCOM
===========================================

GNSS-denied demonstration: INS alone drifts, INS + IRA TERCOM stays bounded, on the same flight.

Run it as::

    python examples/gallery/gnss_denied_demo.py --minutes 20 --grade tactical --out out/gnss_denied

The King Air (trn_env.flight.core) flies a square circuit over the jacksboro DEM; GNSS is lost at t = 0 (the
navigators start from a GNSS-quality estimate, 3 m / 0.05 m/s, and never see GNSS again). The same sensor
frames (IMU of the chosen grade, baro, IRA) feed the "ins" and "ins_tercom" navigators; the horizontal
errors against the truth go into one plot and a summary.json.
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
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain
from trn_env.flight.core import AutopilotTargets, Flight, InitialCondition, LateralMode, VerticalMode
from trn_env.flight.truth import TruthChunk
from trn_env.flight.wind import WindConfig
from trn_env.sensors.imu import ImuConfig
from trn_env.sensors.suite import SensorSuite


def slice_frames(fr: SensorFrames, t0: float, t1: float) -> SensorFrames:
    out = SensorFrames(t0, t1)
    for name in ("imu", "baro", "ira"):
        f = getattr(fr, name)
        sel = (f.t_s >= t0) & (f.t_s < t1)
        setattr(out, name, replace(f, **{k: v[sel] for k, v in vars(f).items() if isinstance(v, np.ndarray)}))
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--grade", default="tactical", help="IMU grade: navigation | tactical | consumer")
    ap.add_argument("--h", type=float, default=3000.0)
    ap.add_argument("--tas", type=float, default=90.0)
    ap.add_argument("--leg-s", type=float, default=120.0, help="length of each side of the square, s")
    ap.add_argument("--wind", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="out/gnss_denied")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_wall = time.time()

    dem = terrain.load("jacksboro")
    lat_c, lon_c = dem.center_rad
    half = 0.5 * args.tas * args.leg_s
    r_n, r_e = meridian_radius_m(lat_c), prime_vertical_radius_m(lat_c) * math.cos(lat_c)
    lat0, lon0 = lat_c - half / r_n, lon_c - half / r_e
    fl = Flight(
        InitialCondition(lat0, lon0, args.h, args.tas, 0.0),
        wind=WindConfig.constant(270.0, args.wind),
        terrain_elevation_m=float(np.nanmax(dem.heights_m)),
    )
    chunks = [fl.snapshot()]
    n_s = int(args.minutes * 60)
    for k in range(n_s):
        if k % int(args.leg_s) == 0:
            leg = (k // int(args.leg_s)) % 4
            fl.set_targets(
                AutopilotTargets(
                    lateral_mode=LateralMode.TRACK,
                    track_cmd_rad=leg * math.pi / 2,
                    vertical_mode=VerticalMode.ALTITUDE_MSL,
                    altitude_cmd_m=args.h,
                    tas_cmd_mps=args.tas,
                    bank_limit_rad=math.radians(25),
                )
            )
        chunks.append(fl.advance(int(round(1.0 / fl.dt_s))))
    truth = TruthChunk.concatenate(chunks)
    print(f"flown {len(truth)} steps ({time.time() - t_wall:.0f} s wall)")

    imu_cfg = ImuConfig.grade(args.grade)
    frames = SensorSuite.from_config({"imu": imu_cfg, "baro": {"bias_m": 0.0}, "ira": {}}, args.seed).sample(
        truth, dem
    )
    nav_settings = dict(
        accel_bias_mps2=imu_cfg.accel_bias_mps2 + imu_cfg.accel_bias_instability_mps2,
        accel_noise_mps2_rthz=max(imu_cfg.accel_noise_density_mps2_rthz, 1e-9),
        gyro_bias_rps=imu_cfg.gyro_bias_rps + imu_cfg.gyro_bias_instability_rps,
        gyro_noise_rps_rthz=max(imu_cfg.gyro_noise_density_rps_rthz, 1e-12),
    )
    rng = np.random.default_rng(args.seed)
    e = np.array([3.0, 3.0, 5.0, 0.05, 0.05, 0.05, 0.2e-3, 0.2e-3, 1e-3]) * rng.standard_normal(9)
    rn0 = meridian_radius_m(truth.lat_rad[0]) + truth.h_msl_m[0]
    re0 = (prime_vertical_radius_m(truth.lat_rad[0]) + truth.h_msl_m[0]) * math.cos(truth.lat_rad[0])
    init = Estimate(
        0.0,
        truth.lat_rad[0] + e[0] / rn0,
        truth.lon_rad[0] + e[1] / re0,
        truth.h_msl_m[0] - e[2],
        truth.v_ned_mps[0] + e[3:6],
        truth.roll_rad[0] + e[6],
        truth.pitch_rad[0] + e[7],
        truth.yaw_rad[0] + e[8],
        initial_covariance(3.0, 5.0, 0.05, 0.2e-3, 1e-3),
    )
    curves = {}
    summary = {"args": vars(args)}
    for name in ("ins", "ins_tercom"):
        nav = registry.create(name, **nav_settings, **({"dem": dem} if name == "ins_tercom" else {}))
        nav.reset(init)
        ts, err, sig = [], [], []
        for k in range(n_s):
            est = nav.update(slice_frames(frames, float(k), float(k + 1)))
            j = min(int(np.searchsorted(truth.t_s, est.t_s)), len(truth) - 1)
            rn = meridian_radius_m(truth.lat_rad[j]) + truth.h_msl_m[j]
            re = (prime_vertical_radius_m(truth.lat_rad[j]) + truth.h_msl_m[j]) * math.cos(truth.lat_rad[j])
            ts.append(est.t_s)
            err.append(
                math.hypot((est.lat_rad - truth.lat_rad[j]) * rn, (est.lon_rad - truth.lon_rad[j]) * re)
            )
            sig.append(float(np.hypot(*est.sigma_ned_m[:2])))
        curves[name] = (np.array(ts), np.array(err), np.array(sig))
        summary[name] = {
            "horizontal_error_final_m": err[-1],
            "horizontal_error_max_m": max(err),
            "horizontal_error_rms_m": float(np.sqrt(np.mean(np.square(err)))),
            "skipped": est.health.skipped,
            "status": est.health.status,
        }
        print(
            f"{name:<11} final {err[-1]:8.1f} m  max {max(err):8.1f} m  rms "
            f"{summary[name]['horizontal_error_rms_m']:8.1f} m  ({est.health.status})"
        )
    summary["wall_time_s"] = time.time() - t_wall
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5))
    for name, (t, e_m, s_m) in curves.items():
        (line,) = ax.plot(t / 60, e_m, label=f"{name}: horizontal error")
        ax.plot(t / 60, s_m, "--", color=line.get_color(), alpha=0.6, label=f"{name}: filter 1-sigma")
    ax.set_xlabel("time since GNSS loss (min)")
    ax.set_ylabel("horizontal position error (m)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.4)
    ax.legend()
    ax.set_title(f"GNSS denied: {args.grade}-grade INS vs INS + IRA TERCOM")
    fig.tight_layout()
    fig.savefig(out / "gnss_denied.png", dpi=110)
    print(f"wrote {out / 'summary.json'} and {out / 'gnss_denied.png'}")
    return summary


if __name__ == "__main__":
    main()
