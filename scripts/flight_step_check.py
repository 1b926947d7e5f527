"""JSBSim's step in the route task: the King Air's trajectory and the task's miss at two steps.

    python scripts/flight_step_check.py trajectory [--duration-s 480]
    python scripts/flight_step_check.py routes --dt 0.01 0.02 --seeds 16 [--out DIR]

trajectory: the flight core alone (calm air, the same autopilot schedule: +-45 deg track changes every 60 s,
200 m climbs and descents every 90 s) at 200, 100, 60 and 50 Hz; prints each step's largest horizontal and
height departure from the 100 Hz and the 200 Hz flights. routes: TerrainNav-v0 at each `--dt` on the fast
tier's calibration routes (trn_env.env.fast.calibration.REFERENCE_ROUTES), the same seeds at every step;
prints mean / 90th percentile of the true miss per route and step, the paired difference with its 95 %
interval and the paired t and Wilcoxon p values; writes DIR/routes_<dt>.json when `--out` is given.
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

R_EARTH_M = 6.371e6


def fly(dt_s: float, duration_s: int) -> np.ndarray:
    """(lat, lon, h) once a second of the scheduled calm-air flight at JSBSim step dt_s."""
    from trn_env.flight.core import (
        AutopilotTargets,
        Flight,
        InitialCondition,
        LateralMode,
        SpeedMode,
        VerticalMode,
    )

    lat0, lon0 = math.radians(36.527), math.radians(-84.1325)
    fl = Flight(InitialCondition(lat0, lon0, 900.0, 85.0, 0.0), dt_s=dt_s, seed=1, terrain_elevation_m=300.0)
    out = []
    for k in range(duration_s):
        fl.set_targets(AutopilotTargets(
            lateral_mode=LateralMode.TRACK, track_cmd_rad=math.radians(45.0 * ((k // 60) % 3 - 1)),
            vertical_mode=VerticalMode.ALTITUDE_MSL, altitude_cmd_m=900.0 + 200.0 * ((k // 90) % 2),
            speed_mode=SpeedMode.TAS, tas_cmd_mps=85.0))
        c = fl.advance(int(round(1.0 / dt_s)))
        out.append((c.lat_rad[-1], c.lon_rad[-1], c.h_msl_m[-1]))
    return np.array(out)


def departure(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Largest horizontal and height distance (m) between two flights sampled at the same times."""
    dn = (a[:, 0] - b[:, 0]) * R_EARTH_M
    de = (a[:, 1] - b[:, 1]) * R_EARTH_M * np.cos(b[:, 0])
    return float(np.max(np.hypot(dn, de))), float(np.max(np.abs(a[:, 2] - b[:, 2])))


def trajectory(duration_s: int) -> None:
    flights = {hz: fly(1.0 / hz, duration_s) for hz in (200, 100, 60, 50)}
    for hz, x in flights.items():
        for ref in (100, 200):
            if ref != hz:
                h, v = departure(x, flights[ref])
                print(f"{hz:3d} Hz vs {ref} Hz over {duration_s} s: horizontal {h:6.1f} m, height {v:5.1f} m")


def routes(dts: list[float], seeds: int, out: Path | None) -> None:
    from scipy import stats

    from trn_env.env.fast.calibration import REFERENCE_ROUTES, fly_full

    res: dict[float, dict] = {}
    for dt in dts:
        res[dt] = {route.name: fly_full(route, range(seeds), {"flight_dt_s": dt})
                   for route in REFERENCE_ROUTES}
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / f"routes_{dt}.json").write_text(json.dumps(res[dt], indent=1))
    base = dts[0]
    for name in res[base]:
        x = np.array(res[base][name]["errors_m"])
        line = f"{name:22s} {base} s: {x.mean():7.1f} / {np.percentile(x, 90):7.1f}"
        for dt in dts[1:]:
            y = np.array(res[dt][name]["errors_m"])
            d = y - x
            half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d))
            line += (f" | {dt} s: {y.mean():7.1f} / {np.percentile(y, 90):7.1f}, "
                     f"ratio {y.mean() / x.mean():.2f}, diff {d.mean():+.1f} "
                     f"[{d.mean() - half:+.1f}, {d.mean() + half:+.1f}], "
                     f"p {stats.ttest_rel(y, x).pvalue:.2f} / {stats.wilcoxon(y, x).pvalue:.2f}, arrived "
                     f"{res[dt][name]['terminations'].count('arrived')} vs "
                     f"{res[base][name]['terminations'].count('arrived')}")
        print(line)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("command", choices=("trajectory", "routes"))
    p.add_argument("--duration-s", type=int, default=480)
    p.add_argument("--dt", type=float, nargs="+", default=[0.01, 0.02])
    p.add_argument("--seeds", type=int, default=16)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        p.error(problem)       # checked before the work, not after it
    bad = None
    if args.duration_s < 1:
        bad = f"--duration-s must be >= 1, got {args.duration_s}"
    elif args.seeds < 2:
        bad = f"--seeds must be >= 2 (paired statistics), got {args.seeds}"
    elif any(not (math.isfinite(d) and 0.0 < d <= 0.05) for d in args.dt) or len(args.dt) < 2:
        bad = f"--dt needs two or more steps within (0, 0.05] s, got {args.dt}"
    if bad:
        print(f"error: {bad}", file=sys.stderr)
        return 2
    if args.command == "trajectory":
        trajectory(args.duration_s)
    else:
        routes(args.dt, args.seeds, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
