"""Replay: run a navigator (and monitors) open loop over a log's frames (`trn-env replay`).

The navigator is built as the closed loop builds it (trn_env.scenario.build.build_navigator: the settings
the scenario builder fills from the sensors and the map come from the log's sensor configs and map), on
the log's map, with the log's seed's `navigator` random stream, reset to the log's initial estimate, and
fed the frames in order. For a log made by `trn-env record` with its own navigator and settings that is
exactly the closed loop's sequence of calls, so the estimates equal the flight's bit for bit.

The ranging sensors' measurements reach the navigator transferred from their antennas to the IMU's point
with the log's lever arms (navigators.measurements.lever_arm), as in the closed loop; monitors get them
as logged.

The run's arrays (the keys of trn_env.sim.SimLog.arrays) pair each estimate with the truth at its time:
exactly at the logged truth rows when the truth has a row at every estimate time (a recorded log: the
closed loop's log rate), else the truth linearly interpolated to the estimate times inside its span.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trn_env.logs.format import LogError
from trn_env.logs.reader import SensorLog, read_log
from trn_env.navigators.frames import copy_frames
from trn_env.navigators.integrity.protection_level import EXTRA_PROTECTION_LEVEL
from trn_env.navigators.protocol import Estimate, Health
from trn_env.scenario.loading import Scenario
from trn_env.scenario.sections import ScenarioSections, SectionsError
from trn_env.scenario.sections import from_dict as from_sections_dict
from trn_env.sim.closed_loop import perturbed_estimate, spawn_rngs, summarise
from trn_env.sim.log import NAV_STATUS_CODES, error_ned_m
from trn_env.sim.nav_stage import gnss_available_mask, monitor_update, navigator_update

DEFAULT_INITIAL_ERRORS = {"position_ned_m": [30.0, 30.0, 15.0], "velocity_ned_mps": [0.1, 0.1, 0.1],
                          "attitude_mrad": [0.05, 0.05, 1.0]}


@dataclass
class ReplayResult:
    """A replay's outcome: arrays as SimLog.arrays (estimates paired with truth when the log has it),
    the summary (summary.json; metrics only with truth), the estimates at every frame, events."""

    scenario: Scenario
    termination: str
    arrays: dict
    summary: dict
    estimates: list
    events: list
    world_dem: object
    has_truth: bool


def _load_dem(value: str):
    from trn_env.scenario.build import _load_dem as load
    try:
        return load(str(value), False)
    except Exception as exc:     # rasterio, numpy and file errors: say which map
        raise LogError(f"map {value}: cannot be loaded ({type(exc).__name__}: {exc})") from exc


def scenario_of(log: SensorLog, navigator: str | None, settings: dict | None,
                monitors: list[str] | None) -> ScenarioSections:
    """The scenario sections the builders need (terrain, sensors, navigator, monitors, gnss, initial
    errors; trn_env.scenario.sections.from_dict with partial=True), from the log's resolved scenario
    (recorded) or its metadata (built), with the replay's navigator, settings and monitors. LogError for
    settings or sensor tables their components refuse."""
    meta = log.metadata
    if "scenario" in meta:
        base = copy.deepcopy(meta["scenario"])
    else:
        base = {"name": log.path.name, "seed": int(meta.get("seed", 0)), "duration_s": 0.0,
                "terrain": {"world": {"dem": meta["map"]["dem"]}, "map": {"dem": "world"}},
                "sensors": {k: dict(v) for k, v in meta.get("sensors", {}).items()},
                "navigator": copy.deepcopy(meta.get("navigator") or {"name": "ins", "settings": {}}),
                "monitors": {}, "gnss": {"outages": []}, "initial_errors": DEFAULT_INITIAL_ERRORS}
    nav_table = dict(base.get("navigator") or {"name": "ins"})
    nav_settings = dict(nav_table.get("settings") or {})
    if navigator is not None and navigator != nav_table.get("name"):
        nav_table["name"], nav_settings = navigator, {}
    nav_table["settings"] = {**nav_settings, **(settings or {})}
    base["navigator"] = nav_table
    base["monitors"] = {**(base.get("monitors") or {}),
                        **{name: {} for name in monitors or [] if name not in (base.get("monitors") or {})}}
    # the sensors the log holds are the ones fitted (a builder's log may carry more configs than tables)
    tables = base.get("sensors") or {}
    base["sensors"] = {s: cfg for s, cfg in tables.items() if s in log.sensors} | {
        s: {} for s in log.sensors if s not in tables}
    try:
        return from_sections_dict(base, partial=True)
    except SectionsError as exc:
        raise LogError(f"log {log.path}: {'; '.join(exc.problems)}") from None


# the last fault-free (world, map) built, keyed by the log's terrain: replaying several navigators over one
# log pays the world's refinement and the map's error draw once (maps with a fault schedule are never kept:
# the replay changes their heights)
_LAST_MAPS: dict = {}


def build_maps(log: SensorLog, d: ScenarioSections, map_path: str | None):
    """(world DEM for the truth's height above ground, navigator's map)."""
    if map_path is not None:
        the_map = _load_dem(map_path)
        return the_map, the_map, []
    if "scenario" in log.metadata:
        from trn_env.scenario.build import build_terrain
        key = (str(log.path), int(d.seed), repr(d.terrain))
        if key in _LAST_MAPS:
            world, the_map = _LAST_MAPS[key]
            return world, the_map, []
        extras: dict = {}
        world, the_map = build_terrain(d, extras, spawn_rngs(int(d.seed))["map"])
        schedule = extras.get("map_fault_schedule") or []
        if schedule:
            from trn_env.terrain.map_error import set_heights
            set_heights(the_map, extras["map_fault_heights0"])
        else:
            _LAST_MAPS.clear()
            _LAST_MAPS[key] = (world, the_map)
        return world, the_map, list(schedule)
    the_map = _load_dem(d.terrain.world.dem)
    return the_map, the_map, []


def _initial(log: SensorLog, d: ScenarioSections) -> Estimate:
    est = log.initial_estimate()
    if est is not None:
        return est
    truth = log.truth()
    if truth is None:
        raise LogError(f"log {log.path}: states neither an initial_estimate nor truth to start from")
    t0 = float(log.column("frames", "t_start_s")[0])
    # the last truth row before the first frame (the first IMU sample covers the interval ending at its
    # time, so the estimate starts at or before it: the closed loop's t = 0 before samples from 0.01)
    i = int(np.clip(np.searchsorted(truth["t_s"].to_numpy(), t0, side="left") - 1, 0, len(truth) - 1))
    row = truth.iloc[i]

    class _Row:   # the attributes perturbed_estimate reads, one row
        t_s = np.array([row["t_s"]])
        lat_rad, lon_rad = np.array([row["lat_rad"]]), np.array([row["lon_rad"]])
        h_msl_m = np.array([row["h_m"]])
        v_ned_mps = np.array([[row["v_n_mps"], row["v_e_mps"], row["v_d_mps"]]])
        roll_rad, pitch_rad, yaw_rad = np.array([row["roll_rad"]]), np.array([row["pitch_rad"]]), np.array(
            [row["yaw_rad"]])
    return perturbed_estimate(_Row, 0, d.initial_errors, spawn_rngs(int(d.seed))["initial_errors"])


def check_sensors(navigator, name: str, log: SensorLog, d: ScenarioSections | None = None) -> None:
    """Refuse a log that lacks a sensor the navigator or a monitor of the scenario `d` (its sections)
    requires (their declared capabilities, navigators.registry.sensor_needs; a navigator the registry does
    not know is asked its `required_sensors()` if it has one). Without `d`: the navigator's default
    settings and no monitors."""
    from trn_env.navigators import registry
    users = []
    try:
        needs = registry.sensor_needs(name, {} if d is None else d.navigator.table.to_dict())
        users.append((f"navigator {name!r}", list(needs.required.items())))
    except ValueError:
        need = getattr(navigator, "required_sensors", None)
        users.append((f"navigator {name!r}", list(need()) if need is not None else []))
    for mon in () if d is None else d.monitors:
        try:
            needs = registry.monitor_sensor_needs(mon.name, mon.settings.to_dict())
        except ValueError:
            continue
        users.append((f"monitor {mon.name!r}", list(needs.required.items())))
    for who, need in users:
        missing = [(s, why) for s, why in need if s not in log.sensors]
        if missing:
            raise LogError(f"log {log.path}: {who} needs sensor(s) the log does not hold: "
                           + "; ".join(f"{s} ({why})" for s, why in missing)
                           + f" (the log holds: {', '.join(log.sensors) or 'none'})")


def unused_in_log(d: ScenarioSections, sensors) -> list[str]:
    """The log's sensors that neither the navigator nor a monitor of the scenario `d` (its sections) reads
    (by their declared sensor needs); empty when a component's needs cannot be read."""
    from trn_env.navigators import registry
    try:
        used = set(registry.sensor_needs(d.navigator.name, d.navigator.table.to_dict()).used)
        for mon in d.monitors:
            used |= set(registry.monitor_sensor_needs(mon.name, mon.settings.to_dict()).used)
    except ValueError:
        return []
    return sorted(set(sensors) - used)


def replay(log: SensorLog | Path | str, navigator: str | None = None, *, settings: dict | None = None,
           monitors: list[str] | None = None, map_path: str | None = None, seed: int | None = None,
           progress=None) -> ReplayResult:
    """Run `navigator` (default: the log's) over the log; LogError/ValueError on bad input, before
    anything runs. `settings` update the navigator's; `seed` replaces the log's seed for the navigator's
    random stream (the map errors and the initial estimate keep the log's)."""
    from trn_env.scenario.build import build_monitors, build_navigator
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                             or not 0 <= int(seed) <= 2**63 - 1):
        raise LogError(f"seed: {seed!r} is not a seed from 0 to {2**63 - 1} (64-bit, as the scenario's)")
    seed_override = seed
    if not isinstance(log, SensorLog):
        log = read_log(log)
    d = scenario_of(log, navigator, settings, monitors)
    world, the_map, schedule = build_maps(log, d, map_path)
    seed = int(d.seed if d.seed is not None else log.metadata.get("seed", 0))
    nav_seed = seed if seed_override is None else int(seed_override)
    try:
        nav = build_navigator(d, the_map, spawn_rngs(nav_seed)["navigator"])
        mons = build_monitors(d, the_map)
    except (ValueError, TypeError, KeyError) as exc:
        raise LogError(f"navigator {d.navigator.name!r}: {exc}") from exc
    check_sensors(nav, d.navigator.name, log, d)
    initial = _initial(log, d)
    if not the_map.contains(initial.lat_rad, initial.lon_rad):
        la0, la1, lo0, lo1 = (math.degrees(x) for x in the_map.bounds)
        lat, lon = math.degrees(initial.lat_rad), math.degrees(initial.lon_rad)
        raise LogError(f"map {the_map.name!r} does not cover the log's start ({lat:.5f}, {lon:.5f} deg): it "
                       f"spans latitude {la0:.4f} to {la1:.4f} deg, longitude {lo0:.4f} to {lo1:.4f} deg; "
                       "give the map of the flown area")
    nav.reset(initial)
    ests: list[Estimate] = [initial]
    events: list = []
    mon_outs: dict[str, list] = {n: [] for n in mons}
    termination = "completed"
    wall0 = time.perf_counter()
    n = log.n_frames
    from trn_env.navigators.measurements.lever_arm import compensate_frames, has_lever_arms
    arms = log.metadata.get("lever_arms_m") or {}
    arms = arms if has_lever_arms(arms) else None
    for k, frames in enumerate(log.frames()):
        while schedule and schedule[0][0] <= frames.t_end_s:
            from trn_env.terrain.map_error import set_heights
            t_fault, heights = schedule.pop(0)
            set_heights(the_map, heights)
            events.append((float(t_fault), "map",
                           f"map fault appears in the navigator's map at {t_fault:g} s"))
        # as in the loop: while monitors read the frames too, each reader gets arrays of its own
        nav_frames = copy_frames(frames) if mons else frames
        est = navigator_update(nav, compensate_frames(nav_frames, arms) if arms is not None else nav_frames)
        for t_ev, msg in est.health.events:
            events.append((t_ev, "navigator", msg))
        for name, mon in mons.items():
            out = monitor_update(mon, name, copy_frames(frames), est)
            mon_outs[name].append(out)
            events += [(t_ev, name, msg) for t_ev, msg in out.events]
        ests.append(_snapshot(est))
        if not (math.isfinite(est.lat_rad) and math.isfinite(est.lon_rad) and math.isfinite(est.h_m)):
            termination = "diverged"
            break
        if progress is not None:
            progress(k + 1, n)
    wall = time.perf_counter() - wall0
    sc = Scenario(name=str(log.metadata.get("scenario_name", log.path.name)), source=str(log.path),
                  sections=d, seed=nav_seed,
                  duration_s=float(log.column("frames", "t_end_s")[-1]) if n else 0.0)
    arrays, has_truth = replay_arrays(log, ests, world, d)
    summary = {"scenario": sc.name, "seed": seed, "navigator": sc.navigator_name, "replay_of": str(log.path),
               "frames": n, "termination": termination, "wall_time_s": wall}
    if has_truth and arrays["t_s"].size:
        summary = summarise(sc, termination, arrays, wall, 0, ests[-1]) | {"replay_of": str(log.path),
                                                                            "frames": n}
    summary["truth_in_log"] = has_truth
    summary["sensors_in_log"] = list(log.sensors)
    summary["unused_sensors"] = unused_in_log(d, log.sensors)
    if mons:
        from trn_env.navigators.integrity.dem_monitor import alarm_summary, concatenate
        summary["monitors"] = {}
        for name, outs in mon_outs.items():
            mon = concatenate(outs)
            arrays.update({f"monitor_{name}_{k}": v for k, v in mon.items()})
            summary["monitors"][name] = alarm_summary(mon)
    events.append((float(ests[-1].t_s), "replay", f"termination: {termination}"))
    events.sort(key=lambda ev: ev[0])
    return ReplayResult(sc, termination, arrays, summary, ests, events, world, has_truth)


def _snapshot(est: Estimate) -> Estimate:
    """The numbers of an estimate (a navigator may reuse its arrays between updates), with its protection
    level."""
    return Estimate(float(est.t_s), float(est.lat_rad), float(est.lon_rad), float(est.h_m),
                    np.array(est.v_ned_mps, float), float(est.roll_rad), float(est.pitch_rad),
                    float(est.yaw_rad), np.array(est.covariance[:9, :9], float),
                    Health(bool(est.health.ok), str(est.health.status), dict(est.health.skipped)),
                    extra={k: float(v) for k, v in est.extra.items() if k == EXTRA_PROTECTION_LEVEL})


def estimate_columns(ests: list[Estimate]) -> dict[str, np.ndarray]:
    """est_* arrays as SimLog.arrays names them."""
    return {
        "est_t_s": np.array([e.t_s for e in ests]),
        "est_lat_rad": np.array([e.lat_rad for e in ests]),
        "est_lon_rad": np.array([e.lon_rad for e in ests]),
        "est_h_m": np.array([e.h_m for e in ests]),
        "est_v_ned_mps": np.array([e.v_ned_mps for e in ests], float).reshape(-1, 3),
        "est_roll_rad": np.array([e.roll_rad for e in ests]),
        "est_pitch_rad": np.array([e.pitch_rad for e in ests]),
        "est_yaw_rad": np.array([e.yaw_rad for e in ests]),
        "est_cov": np.array([e.covariance for e in ests], float).reshape(-1, 9, 9),
        "est_hpl_m": np.array([float(e.extra.get(EXTRA_PROTECTION_LEVEL, np.nan)) for e in ests]),
        "nav_ok": np.array([e.health.ok for e in ests], bool),
        "nav_status_code": np.array([NAV_STATUS_CODES.index(e.health.status) if e.health.status in
                                     NAV_STATUS_CODES else len(NAV_STATUS_CODES) for e in ests], np.int8),
    }


def replay_arrays(log: SensorLog, ests: list[Estimate], world, d: ScenarioSections) -> tuple[dict, bool]:
    est = estimate_columns(ests)
    truth = log.truth()
    t_est = est["est_t_s"]
    if truth is None or not len(truth):
        return est | {"t_s": t_est}, False
    tt = truth["t_s"].to_numpy()
    exact = np.isin(tt, t_est)
    if exact.all():
        keep = np.isin(t_est, tt)
        rows = np.searchsorted(tt, t_est[keep])
        tr = {c: truth[c].to_numpy()[rows] for c in truth.columns}
    else:
        keep = (t_est >= tt[0]) & (t_est <= tt[-1])
        tq = t_est[keep]
        tr = {"t_s": tq}
        for c in truth.columns:
            if c == "t_s":
                continue
            v = truth[c].to_numpy()
            tr[c] = (np.unwrap(v) if c in ("yaw_rad", "roll_rad") else v)
            tr[c] = np.interp(tq, tt, tr[c])
            if c in ("yaw_rad", "roll_rad"):
                tr[c] = np.angle(np.exp(1j * tr[c]))
    out = {k: v[keep] for k, v in est.items()}
    out["t_s"] = tr["t_s"]
    out["true_lat_rad"], out["true_lon_rad"], out["true_h_msl_m"] = tr["lat_rad"], tr["lon_rad"], tr["h_m"]
    out["true_v_ned_mps"] = np.column_stack([tr["v_n_mps"], tr["v_e_mps"], tr["v_d_mps"]])
    for c in ("roll_rad", "pitch_rad", "yaw_rad", "tas_mps", "alpha_rad", "beta_rad"):
        out[f"true_{c}"] = tr.get(c, np.full(out["t_s"].shape, np.nan))
    if "wind_n_mps" in tr:
        out["true_wind_ned_mps"] = np.column_stack([tr["wind_n_mps"], tr["wind_e_mps"], tr["wind_d_mps"]])
    from trn_env.scenario.build import world_height
    out["true_h_agl_m"] = out["true_h_msl_m"] - world_height(world, out["true_lat_rad"], out["true_lon_rad"])
    out["est_cov_diag"] = np.diagonal(out["est_cov"], axis1=1, axis2=2).copy()
    out["err_ned_m"] = error_ned_m(out["true_lat_rad"], out["true_lon_rad"], out["true_h_msl_m"],
                                   out["est_lat_rad"], out["est_lon_rad"], out["est_h_m"])
    if "gnss_outages" in log.metadata:
        out["gnss_available"] = gnss_available_mask(out["t_s"], log.metadata["gnss_outages"])
    else:   # a built log: GNSS available where the log holds a valid fix up to the estimate's time
        out["gnss_available"] = _gnss_mask(log, out["t_s"])
    return out, True


def _gnss_mask(log: SensorLog, t_s: np.ndarray) -> np.ndarray:
    if "gnss" not in log.sensors:
        return np.zeros(t_s.shape, bool)
    tg = log.column("gnss", "t_s")[log.column("gnss", "valid").astype(bool)]
    if not tg.size:
        return np.zeros(t_s.shape, bool)
    gap = float(np.median(np.diff(tg))) * 1.5 + 1e-9 if tg.size > 1 else 1.0
    i = np.searchsorted(tg, t_s, side="right") - 1
    return (i >= 0) & (t_s - tg[np.clip(i, 0, None)] <= max(gap, 1.0 + 1e-9))


def write_result_log(writer, res: ReplayResult) -> Path:
    """A replay's estimates (and the truth paired with them) as a log's estimates/truth/events tables
    (no frames: the sensor data stay in the replayed log, named in the metadata); returns the committed
    folder."""
    a = res.arrays
    n = a["est_t_s"].shape[0]
    nan = np.full(n, np.nan)

    def col(key, i=None):
        v = a.get(key)
        if v is None:
            return nan
        return v[:, i] if i is not None else v

    truth = np.column_stack([a.get("t_s", a["est_t_s"]), col("true_lat_rad"), col("true_lon_rad"),
                             col("true_h_msl_m"), col("true_v_ned_mps", 0), col("true_v_ned_mps", 1),
                             col("true_v_ned_mps", 2), col("true_roll_rad"), col("true_pitch_rad"),
                             col("true_yaw_rad"), col("true_tas_mps"), col("true_alpha_rad"),
                             col("true_beta_rad"), col("true_wind_ned_mps", 0), col("true_wind_ned_mps", 1),
                             col("true_wind_ned_mps", 2)])
    v = a["est_v_ned_mps"]
    est = {"t_s": a["est_t_s"], "lat_rad": a["est_lat_rad"], "lon_rad": a["est_lon_rad"], "h_m": a["est_h_m"],
           "v_n_mps": v[:, 0].copy(), "v_e_mps": v[:, 1].copy(), "v_d_mps": v[:, 2].copy(),
           "roll_rad": a["est_roll_rad"], "pitch_rad": a["est_pitch_rad"], "yaw_rad": a["est_yaw_rad"]}
    est |= {f"cov_{i}_{j}": a["est_cov"][:, i, j].copy() for i in range(9) for j in range(9)}
    est |= {"hpl_m": np.asarray(a.get("est_hpl_m", np.full(len(a["est_t_s"]), np.nan)), float),
            "nav_ok": a["nav_ok"], "nav_status_code": a["nav_status_code"]}
    if not res.has_truth:
        truth[:, 0] = a["est_t_s"]
    writer.write_ticks(truth, est)
    writer.write_events(res.events)
    import trn_env
    return writer.commit({"source": "trn-env replay", "trn_env_version": trn_env.__version__,
                          "replay_of": str(res.summary.get("replay_of")), "navigator": {
                              "name": res.scenario.navigator_name,
                              "settings": res.scenario.navigator.table.to_dict()},
                          "height_datum": {"reference": "msl"}, "truth_in_log": res.has_truth,
                          "termination": res.termination})
