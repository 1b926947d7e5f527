"""Per-axis consistency (north, east, down NEES) of navigators on the default route, by terrain condition.

    python scripts/axis_consistency.py                                  # pmf, pf, rbpf, ins_tercom; 4 seeds
    python scripts/axis_consistency.py --navigators pmf --seeds 8 --duration 300
    python scripts/axis_consistency.py --conditions dted1 --seeds 16 --statistic mean
    python scripts/axis_consistency.py --detail-correlation     # the world's sub-post detail along the route
    python scripts/axis_consistency.py --return-bias            # the IRA return's height against the map
    python scripts/axis_consistency.py --shift-share 30 --navigators pmf,pf,rbpf   # a map shifted 30 m north
    python scripts/axis_consistency.py --conditions dted1 --grade tactical      # another IMU grade

Conditions: "refined" (the default scenario: the world is the 3" DEM with 30 m fractal detail, the
navigator's map the DEM itself), "world=map" (the refinement removed: the map is the world) and "dted1"
(the refined world, the map with the DTED-1 error model). For each navigator, condition and seed it flies
the route closed loop (GNSS lost at 10 s) and prints, over the epochs after 12 s, the mean of e_i^2 / P_ii
for each axis (1 for a consistent filter), the down error's RMS, the mean height error (estimate minus
truth), the median published down sigma and the run's position ANEES (3-dof; 3 for a consistent filter).
Where a figure is measured for the docs, the validation page quotes this command. `--detail-correlation`
prints instead the standard deviation of the refined world minus the navigator's map (bicubic) along the
default route's legs, sampled every 10 m, and its correlation at lags of 10-400 m (mean over the legs).
`--return-bias` flies the route (seeds as given) and queries the IRA (the scenario's settings, noise free)
from the true state every 0.5 s after 12 s, once against the refined world and once against the world
without its refinement, and prints the returned point's height minus the navigator's map there, read
bicubically (the terrain filters' default) and bilinearly (what a terrain update sees with exact position
and noise-free ranges): mean, sigma, and the world minus the bicubic map below the aircraft for reference;
then, from the same states, a 17 deg radar altimeter's closest range over the map minus over the world.
`--shift-share S` flies the route (seeds as given, navigator in this process) over a map shifted S m north
and nothing else (terrain.map_error's shift_n_m; the navigator told map_horizontal_sigma_m = S) and prints,
at 20-s marks, the north error over S (the share of the shift the estimate has taken on: what the map shift
share recursion of navigators.filters.map_shift should follow) beside that recursion's north share, as the
filter publishes it (pmf, pf; "-" for a navigator without one), means over the seeds.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

CONDITIONS = ("refined", "world=map", "dted1")
RA_BEAM_DEG = 17.0      # the radar altimeter's full beam (trn_env.sensors.radar_altimeter's default)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not np.isfinite(value) or value <= 12.0:
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 12, got {text}")
    return value


def _grades() -> list[str]:
    from trn_env.sensors.imu import IMU_GRADES
    return sorted(IMU_GRADES)


def _shift_m(text: str) -> float:
    value = float(text)
    if not np.isfinite(value) or value == 0.0:
        raise argparse.ArgumentTypeError(f"must be a finite shift in m other than 0, got {text}")
    return value


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--navigators", default="pmf,pf,rbpf,ins_tercom", help="comma-separated navigator names")
    p.add_argument("--conditions", default=",".join(CONDITIONS), help=f"comma-separated, of {CONDITIONS}")
    p.add_argument("--seeds", type=_positive_int, default=4, help="seeds 0 .. N-1")
    p.add_argument("--duration", type=_positive_float, default=120.0, help="flight time, s (> 12)")
    p.add_argument("--grade", choices=_grades(), default=None,
                   help="the IMU grade flown by the per-axis figures and --shift-share (default: the "
                        "scenario's, navigation)")
    p.add_argument("--statistic", choices=("median", "mean"), default="median",
                   help="how the seeds' figures are combined")
    p.add_argument("--detail-correlation", action="store_true",
                   help="print the world-minus-map detail's spread and correlation along the route instead")
    p.add_argument("--return-bias", action="store_true",
                   help="print the IRA return's height minus the map's there (noise free, true state)")
    p.add_argument("--shift-share", type=_shift_m, default=None, metavar="S_M",
                   help="fly over a map shifted S_M m north: the share of it in the estimate against the "
                        "filters' recursion")
    args = p.parse_args(argv)
    args.conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    bad = [c for c in args.conditions if c not in CONDITIONS]
    if bad or not args.conditions:
        p.error(f"--conditions: {bad or 'none given'}; choose from {', '.join(CONDITIONS)}")
    args.navigators = [n.strip() for n in args.navigators.split(",") if n.strip()]
    if not args.navigators:
        p.error("--navigators: none given")
    return args


def scenario_dict(navigator: str, condition: str, seed: int, duration_s: float,
                  grade: str | None = None) -> dict:
    from trn_env.scenario.loading import load_scenario
    d = load_scenario("default", seed=seed, navigator=navigator, duration_s=duration_s).to_dict()
    if grade is not None:
        d["sensors"]["imu"]["grade"] = grade
    if condition == "world=map":
        d["terrain"]["world"].pop("refinement", None)
    elif condition == "dted1":
        d["terrain"]["map"]["error_model"] = {"preset": "dted1"}
    return d


def axis_figures(arrays: dict, summary: dict, after_s: float = 12.0) -> list[float]:
    """[NEES north, east, down, down error RMS (m), mean height error est - true (m), median down sigma (m),
    ANEES] over t > after_s."""
    e, c = arrays["err_ned_m"], arrays["est_cov_diag"]
    m = arrays["t_s"] > after_s
    nees = [float(np.mean(e[m, k] ** 2 / c[m, k])) for k in range(3)]
    return nees + [float(np.sqrt(np.mean(e[m, 2] ** 2))), float(np.mean(-e[m, 2])),
                   float(np.median(np.sqrt(c[m, 2]))), float(summary["anees"])]


def detail_correlation(lags_m=(10, 20, 40, 60, 80, 120, 160, 240, 400), step_m: float = 10.0) -> None:
    """World minus map (both bicubic) along the default route's legs: its spread and correlation by lag."""
    import math

    from trn_env.navigators.core.maps import map_height, map_record

    from trn_env.scenario.loading import load_scenario
    from trn_env.scenario.maps import build_terrain
    from trn_env.sim.closed_loop import spawn_rngs
    sc = load_scenario("default")
    world, the_map = build_terrain(sc, {}, spawn_rngs(int(sc.seed))["map"])
    rec_w, rec_m = map_record(world, True), map_record(the_map, True)
    legs = []
    wp = sc.route.waypoints
    for a, b in zip(wp[:-1], wp[1:], strict=True):
        la0, lo0, la1, lo1 = map(math.radians, (a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg))
        dist = math.hypot((la1 - la0) * 6.371e6, (lo1 - lo0) * 6.371e6 * math.cos(la0))
        f = np.linspace(0.0, 1.0, int(dist / step_m))
        d = np.array([map_height(rec_w, la0 + x * (la1 - la0), lo0 + x * (lo1 - lo0))
                      - map_height(rec_m, la0 + x * (la1 - la0), lo0 + x * (lo1 - lo0)) for x in f])
        legs.append(d[np.isfinite(d)])
    print(f"world minus map along the route: sigma {np.concatenate(legs).std():.2f} m")
    for lag in lags_m:
        k = int(round(lag / step_m))
        r = np.mean([np.corrcoef(x[:-k], x[k:])[0, 1] for x in legs if x.size > k + 10])
        print(f"  correlation at {lag:4d} m: {r:+.3f}")


def return_bias(seeds: int, duration_s: float, every_s: float = 0.5, after_s: float = 12.0) -> None:
    """The IRA's returned point's height minus the navigator's map at that point, from the true state."""
    from trn_env.navigators.core.maps import map_height, map_record
    from trn_env.terrain.geodesy import euler_to_C_bn
    from trn_env.terrain.queries import ira_return, radar_altimeter_return

    from trn_env.scenario.loading import load_scenario
    from trn_env.scenario.maps import build_terrain
    from trn_env.sim import run_scenario
    from trn_env.sim.closed_loop import spawn_rngs

    labels = ("refined world", "world=map")
    rows = {(w, m): [] for w in labels for m in ("bicubic", "bilinear")}
    nadir = {w: [] for w in labels}
    ra_rows = {w: [] for w in labels}
    for seed in range(seeds):
        sc = load_scenario("default", seed=seed, duration_s=duration_s)
        a = run_scenario(sc).arrays
        world, the_map = build_terrain(sc, {}, spawn_rngs(int(sc.seed))["map"])
        d = sc.to_dict()
        d["terrain"]["world"].pop("refinement", None)
        plain_world, _ = build_terrain(load_scenario(d), {}, spawn_rngs(int(sc.seed))["map"])
        ira = sc.sensors.ira
        step = max(1, int(round(every_s / float(np.median(np.diff(a["t_s"]))))))
        k = np.flatnonzero(a["t_s"] > after_s)[::step]
        C = np.stack([euler_to_C_bn(a["true_roll_rad"][i], a["true_pitch_rad"][i], a["true_yaw_rad"][i])
                      for i in k])
        maps = {"bicubic": map_record(the_map, True), "bilinear": map_record(the_map, False)}
        lat, lon, h = a["true_lat_rad"][k], a["true_lon_rad"][k], a["true_h_msl_m"][k]
        ra_map = radar_altimeter_return(the_map, lat, lon, h, C, np.deg2rad(0.5 * RA_BEAM_DEG))
        for label, dem in zip(labels, (world, plain_world), strict=True):
            ret = ira_return(dem, a["true_lat_rad"][k], a["true_lon_rad"][k], a["true_h_msl_m"][k],
                             a["true_v_ned_mps"][k], C, np.deg2rad(ira.half_window_deg), ira.max_range_m)
            ok = ret.valid
            for name, rec_m in maps.items():
                points = zip(ret.lat_rad[ok], ret.lon_rad[ok], strict=True)
                h_map = [map_height(rec_m, la, lo) for la, lo in points]
                rows[label, name].append(ret.h_m[ok] - np.array(h_map))
            ra = radar_altimeter_return(dem, lat, lon, h, C, np.deg2rad(0.5 * RA_BEAM_DEG))
            both = ra.valid & ra_map.valid
            ra_rows[label].append(ra_map.range_m[both] - ra.range_m[both])
            rec_w = map_record(dem, False)       # the sensors' world surface is bilinear
            nadir[label].append(np.array([map_height(rec_w, la, lo) - map_height(maps["bicubic"], la, lo)
                                          for la, lo in zip(a["true_lat_rad"][k], a["true_lon_rad"][k],
                                                            strict=True)]))
    print(f"IRA return height minus map (noise free, true state, every {every_s:g} s after {after_s:g} s, "
          f"{seeds} seeds x {duration_s:g} s; nadir: the world below the aircraft minus the bicubic map)")
    print(f"{'world':<15}{'samples':>8}{'bicubic mean':>13}{'sigma':>7}{'bilinear mean':>14}{'sigma':>7}"
          f"{'nadir mean':>11}{'sigma':>7}")
    for label in labels:
        x, y = np.concatenate(rows[label, "bicubic"]), np.concatenate(rows[label, "bilinear"])
        z = np.concatenate(nadir[label])
        print(f"{label:<15}{x.size:8d}{x.mean():+13.2f}{x.std():7.2f}{y.mean():+14.2f}{y.std():7.2f}"
              f"{np.nanmean(z):+11.2f}{np.nanstd(z):7.2f}")
    print(f"radar altimeter ({RA_BEAM_DEG:g} deg beam, same states): closest range over the map (bilinear, "
          "as the terrain filters predict it) minus over the world")
    print(f"{'world':<15}{'samples':>8}{'mean m':>9}{'sigma m':>9}")
    for label in labels:
        x = np.concatenate(ra_rows[label])
        print(f"{label:<15}{x.size:8d}{x.mean():+9.2f}{x.std():9.2f}")


def shift_share(navigators: list[str], seeds: int, duration_s: float, shift_m: float,
                grade: str | None = None) -> int:
    """--shift-share: the share of a pure north map shift in each navigator's estimate, flown and
    recursed (module docstring)."""
    from trn_env.scenario.loading import ScenarioError, validate
    from trn_env.sim.closed_loop import ClosedLoop

    marks = np.arange(20.0, duration_s + 1e-9, 20.0)
    print(f"share of a {shift_m:g} m north map shift, means over {seeds} seeds; at t = "
          + ", ".join(f"{t:g}" for t in marks) + " s")
    for nav in navigators:
        flown, recursed = [], []
        for seed in range(seeds):
            d = scenario_dict(nav, "refined", seed, duration_s, grade)
            d["terrain"]["map"]["error_model"] = {"shift_n_m": shift_m, "shift_e_m": 0.0}
            d["navigator"].setdefault("settings", {})["map_horizontal_sigma_m"] = abs(shift_m)
            try:
                loop = ClosedLoop(validate(d, source=f"{nav} seed {seed}"), pipeline=False)
            except (ScenarioError, ValueError) as err:
                print(f"error: {nav}: {err}", file=sys.stderr)
                return 2
            shares: list[tuple[float, float]] = []
            update = loop.navigator.update

            def recorded(frames, update=update, shares=shares, navigator=loop.navigator):
                est = update(frames)
                share = getattr(navigator, "_map_shift", None)
                shares.append((est.t_s, np.nan if share is None else float(share.share[0])))
                return est

            loop.navigator.update = recorded
            arrays = loop.run().arrays
            t_share, a_n = np.array(shares).T
            idx = [int(np.argmin(np.abs(arrays["t_s"] - t))) for t in marks]
            flown.append(arrays["err_ned_m"][idx, 0] / shift_m)
            recursed.append([a_n[int(np.argmin(np.abs(t_share - t)))] for t in marks])
        fl, rc = np.mean(flown, axis=0), np.mean(recursed, axis=0)
        print(f"{nav:<12}flown     " + "".join(f"{x:7.2f}" for x in fl))
        print(f"{'':<12}recursion " + "".join("      -" if not np.isfinite(x) else f"{x:7.2f}" for x in rc))
    return 0


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    if args.detail_correlation:
        detail_correlation()
        return 0
    if args.return_bias:
        return_bias(args.seeds, args.duration)
        return 0
    if args.shift_share is not None:
        return shift_share(args.navigators, args.seeds, args.duration, args.shift_share, args.grade)
    from trn_env.scenario.loading import ScenarioError
    from trn_env.sim import run_scenario
    print(f"{'navigator':<12}{'condition':<11}{'NEES N':>8}{'NEES E':>8}{'NEES D':>8}{'D rms m':>9}"
          f"{'h mean m':>9}{'sigma D m':>10}{'ANEES':>8}   ({args.statistic}s over {args.seeds} seeds, "
          f"{args.duration:g} s; h mean: height est - true)")
    for nav in args.navigators:
        for cond in args.conditions:
            rows = []
            for seed in range(args.seeds):
                try:
                    result = run_scenario(scenario_dict(nav, cond, seed, args.duration, args.grade))
                except ScenarioError as err:
                    print(f"error: {nav} / {cond}: {err}", file=sys.stderr)
                    return 2
                rows.append(axis_figures(result.arrays, result.summary))
            med = (np.median if args.statistic == "median" else np.mean)(np.array(rows), axis=0)
            print(f"{nav:<12}{cond:<11}{med[0]:8.2f}{med[1]:8.2f}{med[2]:8.2f}{med[3]:9.1f}{med[4]:+9.1f}"
                  f"{med[5]:10.1f}{med[6]:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
