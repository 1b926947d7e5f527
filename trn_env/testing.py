"""`check_navigator`: the conformance checker every navigator and monitor passes (what gymnasium's
`check_env` is for environments).

    from trn_env.testing import check_navigator
    report = check_navigator("sitan")                 # a name, a module:Name reference, or a factory
    report = check_navigator(MyNavigator, {"n_particles": 500})
    assert report.ok, report                          # or check_navigator(..., raise_on_failure=True)

It flies a short recorded flight once per process (the default route, JSBSim, 30 s: GNSS until 10 s, then
denied; every sensor fitted: IMU, barometer, radar altimeter, IRA, GNSS, air data, heading; `recorded_flight`)
and runs the navigator on its sensor frames open loop, then on adversarial frames. Each failure is reported
with what to fix:

- protocol: `name`, `reset(initial)`, `update(frames) -> Estimate` (navigators.protocol);
- the reset/update contract: an Estimate per update, at the interval's end (or its last sample), a Health;
- finite estimates; a 9 x 9 symmetric positive semi-definite covariance; times that move forward;
- adversarial frames (NaN samples marked valid, radar/IRA no-returns, an initial estimate off the map, an
  empty frame, a frame with a gap in its samples): no exception, a finite estimate, each counted in
  `Health` (`Health.skip`) - the no-return and off-map cases for navigators that use the altimeters;
- determinism: the same settings and seed give the same estimates, bit for bit;
- settings: an unknown setting, and NaN or a string for each numeric setting, raise ValueError naming it;
- declared sensors: a scenario without a sensor the navigator declares it requires (its Capabilities,
  navigators.core.capabilities) is refused before it flies, naming the sensor; sensors that change its
  estimate but are not declared are listed in the info.

As information it reports the navigator's speed (simulated seconds per wall second on the flight) and its
position NEES on the flight (3 for a consistent filter; Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4).
Monitors (`kind="monitor"`) run beside the INS navigator's estimates and get the same frame checks; their
`update(frames, estimate)` must return an object with `rows` and `events` (navigators.integrity
MonitorOutput).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np

from trn_env.navigators import registry
from trn_env.navigators.frames import SensorFrames, copy_frames
from trn_env.navigators.protocol import Estimate, Health
from trn_env.scenario.sections import ScenarioSections

SENSORS = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")
_FLIGHTS: dict[tuple, FlightRecord] = {}
_CHECK_NAME = "__check_navigator__"
_TRACE: dict[int, tuple[int, int]] = {}     # id(estimate) -> (skips so far, events of that update)
_MISUSE: dict[str, tuple] = {}              # what a check's reader changed that it must not (_run)


@dataclass
class FlightRecord:
    """A recorded flight: its frames (one per navigator update), the initial estimate, the truth at the end
    of each update (t_s, lat_rad, lon_rad, h_m arrays), the scenario's typed sections and the navigator's
    map."""

    frames: list[SensorFrames]
    initial: Estimate
    truth: dict[str, np.ndarray]
    scenario: ScenarioSections
    map_dem: object
    wall_s: float


@dataclass
class Problem:
    """One failed check: which check, what happened, what to fix."""

    check: str
    message: str
    fix: str

    def __str__(self) -> str:
        return f"[{self.check}] {self.message}\n    fix: {self.fix}"


@dataclass
class CheckReport:
    """check_navigator's result: `ok`, every `problem`, `info` (speed, NEES, sensors used, ...)."""

    name: str
    kind: str
    problems: list[Problem] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    checks: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def fail(self, check: str, message: str, fix: str) -> None:
        self.problems.append(Problem(check, message, fix))

    def __str__(self) -> str:
        head = f"check_navigator({self.name!r}, kind={self.kind}): " + (
            f"passed {len(self.checks)} checks" if self.ok else f"{len(self.problems)} problem(s)")
        info = "".join(f"\n  {k}: {v}" for k, v in self.info.items())
        return head + info + "".join(f"\n- {p}" for p in self.problems)


class NavigatorCheckError(AssertionError):
    """Raised by check_navigator(..., raise_on_failure=True); its message lists every problem."""


def recorded_flight(duration_s: float = 30.0, seed: int = 0, scenario: str = "default") -> FlightRecord:
    """A short closed-loop flight of `scenario` with every sensor fitted, recorded once per process:
    the frames of each 1 s update, the initial estimate, the truth at each update's end."""
    key = (float(duration_s), int(seed), scenario)
    if key in _FLIGHTS:
        return _FLIGHTS[key]
    from trn_env.scenario.overrides import load_scenario_with
    from trn_env.sim.closed_loop import ClosedLoop
    sets = [("sensors.radar_altimeter", {}), ("sensors.heading", {}), ("sensors.ira", {}),
            ("sensors.air_data", {}), ("navigator.settings", {}), ("monitors", {})]
    sc = load_scenario_with(scenario, sets, seed=seed, duration_s=duration_s, navigator="ins")
    wall0 = time.perf_counter()
    loop = ClosedLoop(sc, log_sensors=True, pipeline=False)
    initial = copy.deepcopy(loop.estimate)
    try:
        while loop.termination is None:
            loop.tick()
        loop.result(0.0)
    finally:
        loop.close()
    rows = np.array(loop.log.truth_rows, float)
    truth = {"t_s": rows[1:, 0], "lat_rad": rows[1:, 1], "lon_rad": rows[1:, 2], "h_m": rows[1:, 3]}
    rec = FlightRecord(list(loop.log.frames), initial, truth, sc.sections, loop.map_dem,
                       time.perf_counter() - wall0)
    _FLIGHTS[key] = rec
    return rec


def truth_chunks(sc, until_s: float):
    """Fly the validated scenario sc's closed loop (no pipeline, no sensor log) until its time reaches
    until_s (s) or it ends; returns (deep copies of the truth chunks its sensors sampled, the truth before
    the first, world DEM, map DEM): a flight to sample again with other sensor noise or to feed other
    navigators (the statistics scripts)."""
    from trn_env.sim.closed_loop import ClosedLoop
    chunks = []
    with ClosedLoop(sc, pipeline=False, log_sensors=False) as loop:
        truth0 = copy.deepcopy(loop.last_truth)
        real = loop.sensors.sample

        def spy(chunk, dem):
            chunks.append(copy.deepcopy(chunk))
            return real(chunk, dem)

        loop.sensors.sample = spy
        while loop.termination is None and loop.t_s < until_s:
            loop.tick()
        loop.sync()
        return chunks, truth0, loop.world_dem, loop.map_dem


# ------------------------------------------------------------------------------------------------ frames

def _corrupt(frames: SensorFrames, how: str) -> SensorFrames:
    """A copy of `frames` made adversarial: "nan" (values NaN, still marked valid), "no_return" (radar
    altimeter and IRA ranges NaN, invalid), "empty" (no sensor data), "gap" (the interval's middle half
    missing from every sensor)."""
    if how == "empty":
        return SensorFrames(frames.t_start_s, frames.t_end_s)
    out = replace(frames, extra=dict(frames.extra))
    for name in SENSORS:
        fr = getattr(frames, name)
        if fr is None:
            continue
        arrays = {k: np.array(v, copy=True) for k, v in vars(fr).items() if isinstance(v, np.ndarray)}
        n = arrays["t_s"].shape[0]
        if how == "nan" and n:
            rows = slice(n // 3, max(n // 3 + 1, n // 2))
            for k, v in arrays.items():
                if k not in ("t_s", "valid") and v.dtype.kind == "f":
                    v[rows] = np.nan
        elif how == "no_return" and name in ("radar_altimeter", "ira"):
            arrays["range_m"][:] = np.nan
            arrays["valid"][:] = False
            if name == "ira":
                arrays["look_angle_rad"][:] = np.nan
        elif how == "gap" and n:
            t = arrays["t_s"]
            span = frames.t_end_s - frames.t_start_s
            keep = (t < frames.t_start_s + 0.25 * span) | (t >= frames.t_start_s + 0.75 * span)
            arrays = {k: v[keep] for k, v in arrays.items()}
        setattr(out, name, type(fr)(**arrays))
    return out


def _drop(frames: SensorFrames, sensor: str) -> SensorFrames:
    out = replace(frames, extra=dict(frames.extra))
    setattr(out, sensor, None)
    return out


# ------------------------------------------------------------------------------------------------ checks

def _skips(h: Health) -> int:
    return int(sum(h.skipped.values())) if isinstance(getattr(h, "skipped", None), dict) else 0


def _estimate_problems(est, frames: SensorFrames, prev_t: float | None) -> list[tuple[str, str, str]]:
    """(check, message, fix) of one update's estimate against the contract."""
    if not isinstance(est, Estimate):
        return [("contract", f"update returned {type(est).__name__}, not an Estimate",
                 "return navigators.protocol.Estimate from update(frames)")]
    out = []
    vals = [est.t_s, est.lat_rad, est.lon_rad, est.h_m, est.roll_rad, est.pitch_rad, est.yaw_rad,
            *np.asarray(est.v_ned_mps, float).ravel()]
    if not all(math.isfinite(float(v)) for v in vals):
        out.append(("finite", f"estimate at t = {est.t_s} s is not finite",
                    "skip bad samples (count them with Health.skip) instead of letting NaN into the state"))
    cov = np.asarray(est.covariance, float)
    if cov.shape != (9, 9):
        out.append(("covariance", f"covariance has shape {cov.shape}, not (9, 9)",
                    "report the 9 x 9 block over [n, e, d, vn, ve, vd, roll, pitch, yaw] "
                    "(Estimate docstring)"))
    elif not np.all(np.isfinite(cov)):
        out.append(("covariance", f"covariance at t = {est.t_s} s is not finite",
                    "guard the covariance update (Joseph form, symmetrise) and skip bad measurements"))
    else:
        scale = max(float(np.max(np.abs(cov))), 1e-300)
        if np.max(np.abs(cov - cov.T)) > 1e-9 * scale:
            out.append(("covariance", f"covariance at t = {est.t_s} s is not symmetric "
                        f"(max |P - P'| = {np.max(np.abs(cov - cov.T)):.3g})",
                        "symmetrise: P = (P + P') / 2"))
        elif np.min(np.linalg.eigvalsh(cov)) < -1e-9 * scale:
            out.append(("covariance", f"covariance at t = {est.t_s} s is not positive semi-definite (min "
                        f"eigenvalue {np.min(np.linalg.eigvalsh(cov)):.3g})",
                        "use the Joseph form of the update, or compute the covariance from particles' "
                        "moments"))
    last = [float(fr.t_s[-1]) for fr in (getattr(frames, s) for s in SENSORS)
            if fr is not None and fr.t_s.size]
    t_ok = {float(frames.t_end_s)} | ({max(last)} if last else set())
    if math.isfinite(est.t_s) and not any(abs(est.t_s - t) <= 1e-6 for t in t_ok):
        out.append(("contract", f"estimate time {est.t_s} s is neither the interval's end {frames.t_end_s} s "
                    "nor its last sample's time",
                    "return the estimate at frames.t_end_s (or the last sample)"))
    if prev_t is not None and not est.t_s > prev_t:
        out.append(("time", f"estimate time {est.t_s} s does not move forward (previous {prev_t} s)",
                    "advance the estimate to each interval's end, even when it holds no samples"))
    if not isinstance(getattr(est, "health", None), Health):
        out.append(("contract", "estimate.health is not a navigators.protocol.Health",
                    "keep a Health and count skipped measurements with Health.skip"))
    return out


def _build(factory_name: str, settings: dict, rec: FlightRecord, seed: int, kind: str):
    from trn_env.scenario import build
    if kind == "monitor":
        return registry.create_monitor(factory_name, **{"dem": rec.map_dem, **settings})
    return build.build_navigator(_with_navigator(rec.scenario, factory_name, settings), rec.map_dem,
                                 np.random.default_rng(seed))


def _with_navigator(sc: ScenarioSections, name: str, settings: dict) -> ScenarioSections:
    """The recorded flight's scenario flown by navigator `name` with `settings` (refused settings are kept
    as written: building the navigator reports them)."""
    from trn_env.scenario.sections import NavigatorSection
    nav = NavigatorSection.of(name, settings, rate_hz=sc.navigator.rate_hz,
                              latency_updates=sc.navigator.latency_updates, strict=False)
    return replace(sc, navigator=nav)


def _run(nav, rec: FlightRecord, frames: list[SensorFrames], initial: Estimate | None = None,
         kind="navigator", beside: list | None = None, update_wall_s: list | None = None) -> list:
    """The navigator's (or monitor's) outputs over `frames` after a reset to `initial`, each as it was when
    returned. The reader gets copies of the frames (and a monitor of the estimate), so the recording stays
    as measured whatever it does; a change it makes to them in place, or to an output after returning it,
    is noted in _MISUSE for _check to report once. `update_wall_s[0]` (if given) accumulates the wall
    seconds spent in its update calls alone."""
    clock = time.perf_counter
    spent = 0.0
    outs, live = [], []
    if kind == "monitor":
        if hasattr(nav, "reset"):
            nav.reset()
        for fr, est in zip(frames, beside, strict=False):
            given, est_given = copy_frames(fr), copy.deepcopy(est)
            t0 = clock()
            out = nav.update(given, est_given)
            spent += clock() - t0
            _note_frames_changed(given, fr, "update(frames, estimate)")
            if not np.array_equal(_estimate_key(est_given), _estimate_key(est), equal_nan=True):
                _MISUSE.setdefault("estimate", float(fr.t_end_s))
            outs.append(_snapshot(out))
            live.append(out)
        _note_outputs_changed(outs, live, kind)
        if update_wall_s is not None:
            update_wall_s[0] += spent
        return outs
    nav.reset(copy.deepcopy(initial or rec.initial))
    for fr in frames:
        given = copy_frames(fr)
        t0 = clock()
        est = nav.update(given)
        spent += clock() - t0
        _note_frames_changed(given, fr, "update(frames)")
        # the Health a navigator returns is often its own live object: snapshot what it counted so far
        h = getattr(est, "health", None)
        est_trace = (_skips(h), len(getattr(h, "events", None) or ()))
        kept = _snapshot(est)
        outs.append(kept)
        live.append(est)
        _TRACE[id(kept)] = est_trace
    _note_outputs_changed(outs, live, kind)
    if update_wall_s is not None:
        update_wall_s[0] += spent
    return outs


def _snapshot(out):
    try:
        return copy.deepcopy(out)
    except Exception:  # noqa: BLE001 - an output that cannot be copied is checked as it is
        return out


def _estimate_key(o) -> np.ndarray:
    """An Estimate's values (health aside), or a monitor output's rows, as one float array."""
    if isinstance(o, Estimate):
        try:
            return np.array([o.t_s, o.lat_rad, o.lon_rad, o.h_m, *np.ravel(o.v_ned_mps), o.roll_rad,
                             o.pitch_rad, o.yaw_rad, *np.ravel(o.covariance)], float)
        except (TypeError, ValueError):
            return np.array([np.nan])
    rows = getattr(o, "rows", None)
    try:
        return np.asarray(rows, float).ravel()
    except (TypeError, ValueError):
        return np.array([np.nan])


def _note_frames_changed(given: SensorFrames, original: SensorFrames, call: str) -> None:
    """Note (once) which of the frames' arrays the reader changed in place (or replaced)."""
    if "frames" in _MISUSE:
        return
    changed = []
    for name in SENSORS:
        a, b = getattr(given, name, None), getattr(original, name)
        if (a is None) != (b is None):
            changed.append(name)
        elif b is not None:
            for f in fields(b):
                x, y = np.asarray(getattr(a, f.name, None)), getattr(b, f.name)
                if x.shape != y.shape or not np.array_equal(x, y, equal_nan=y.dtype.kind == "f"):
                    changed.append(f"{name}.{f.name}")
    if changed:
        _MISUSE["frames"] = (call, float(original.t_end_s), changed)


def _note_outputs_changed(outs: list, live: list, kind: str) -> None:
    """Note (once) an output that differs, after the run, from what update() returned: the same object
    returned again, or arrays the reader keeps overwriting (its covariance held as a state it updates)."""
    if "outputs" in _MISUSE:
        return
    for i, (kept, out) in enumerate(zip(outs, live, strict=True)):
        if kept is out:
            continue
        if not np.array_equal(_estimate_key(kept), _estimate_key(out), equal_nan=True):
            again = any(out is other for other in live[i + 1:])
            _MISUSE["outputs"] = (kind, i, again)
            return


def _report_misuse(report: CheckReport) -> None:
    if "frames" in _MISUSE:
        call, t_s, changed = _MISUSE["frames"]
        report.fail("contract", f"{call} changed its input frames in place (first at the update ending "
                    f"{t_s:g} s: {', '.join(changed)})",
                    "leave the frames as given: copy an array before changing it "
                    "(np.array(frames.baro.h_baro_m)); the same frames may be given to other navigators, "
                    "monitors and the log")
    if "estimate" in _MISUSE:
        report.fail("contract", "update(frames, estimate) changed the navigator's estimate in place (first "
                    f"at the update ending {_MISUSE['estimate']:g} s)",
                    "copy the estimate before changing it: the loop's guidance and log use it")
    if "outputs" in _MISUSE:
        kind, i, again = _MISUSE["outputs"]
        what = "estimate" if kind == "navigator" else "output"
        how = ("the same object is returned again by a later update" if again else
               "it shares arrays the " + kind + " keeps changing (e.g. its covariance is the filter's own P)")
        report.fail("contract", f"the {what} returned by update {i} changed afterwards: {how}",
                    f"return a new {'Estimate' if kind == 'navigator' else 'output'} with arrays of its own "
                    "from every update (np.array(self.P), not self.P): the loop keeps earlier estimates")


def check_navigator(name_or_factory: str | Callable[..., object], settings: dict | None = None, *,
                    kind: str | None = None, seed: int = 0, duration_s: float = 30.0,
                    check_settings: bool = True, verbose: bool = True,
                    raise_on_failure: bool = False) -> CheckReport:
    """Run every conformance check on a navigator or monitor (see the module docstring).

    Parameters
    ----------
    name_or_factory : str or callable
        a navigator or monitor name (built-in or installed), a `package.module:Name` reference, or a factory
        (a class or a callable taking the settings as keyword arguments).
    settings : dict, optional
        its settings; `dem` (the flight's map) and the scenario-derived ones are filled as in a scenario.
    kind : "navigator" or "monitor", optional
        default: what the name resolves to (a navigator first).
    seed : int
        the navigator's random stream seed (particle filters).
    duration_s : float
        length of the recorded flight, s (GNSS is denied from 10 s).
    check_settings : bool
        also try bad values of every numeric setting (one construction each).
    verbose : bool
        print the report.
    raise_on_failure : bool
        raise NavigatorCheckError listing every problem instead of returning a failed report.

    Returns
    -------
    CheckReport
    """
    _TRACE.clear()
    _MISUSE.clear()
    try:
        return _check(name_or_factory, dict(settings or {}), kind, seed, duration_s, check_settings, verbose,
                      raise_on_failure)
    finally:
        registry.unregister(_CHECK_NAME)
        registry.unregister(_CHECK_NAME, "monitor")


def _check(name_or_factory, settings: dict, kind: str | None, seed: int, duration_s: float,
           check_settings: bool, verbose: bool, raise_on_failure: bool) -> CheckReport:
    label = name_or_factory if isinstance(name_or_factory, str) else getattr(name_or_factory, "__name__",
                                                                             repr(name_or_factory))
    name = name_or_factory
    if not isinstance(name_or_factory, str) and not callable(name_or_factory):
        report = CheckReport(str(label), kind or "navigator")
        report.fail("protocol", f"{name_or_factory!r} ({type(name_or_factory).__name__}) is neither a name "
                    "nor a class or factory", "give a navigator's name, a module:Name reference or a factory")
        return _finish(report, verbose, raise_on_failure)
    if not isinstance(name_or_factory, str):
        registry.register(_CHECK_NAME, name_or_factory, takes_rng=registry._takes_rng(name_or_factory))
        registry.register_monitor(_CHECK_NAME, name_or_factory)
        name = _CHECK_NAME
    if kind is None:
        kind = "navigator"
        if isinstance(name_or_factory, str):
            try:
                registry.resolve(name, "navigator")
            except ValueError:     # a monitor's name, or a broken navigator (then its own error is reported)
                try:
                    registry.resolve(name, "monitor")
                    kind = "monitor"
                except ValueError:
                    pass
        elif _update_takes_estimate(name_or_factory):
            kind = "monitor"
    report = CheckReport(str(label), kind)
    try:
        plugin = registry.resolve(name, kind)
    except ValueError as exc:
        report.fail("protocol", str(exc), "give a navigator's name, a module:Name reference or a factory")
        return _finish(report, verbose, raise_on_failure)
    rec = recorded_flight(duration_s, 0)
    try:
        nav = _build(name, settings, rec, seed, kind)
    except Exception as exc:  # noqa: BLE001 - reported, with what to fix
        report.fail("settings", f"construction with {sorted(settings)} failed: {type(exc).__name__}: {exc}",
                    "fix the settings or the constructor; it must accept its documented defaults")
        return _finish(report, verbose, raise_on_failure)
    report.checks.append("construct")
    missing = registry.lacks(nav, kind)
    if kind == "navigator" and not isinstance(getattr(nav, "name", None), str):
        missing.append("name (a str attribute)")
    if missing:
        report.fail("protocol", f"the {kind} lacks {', '.join(missing)}",
                    "implement navigators.protocol.Navigator")
        return _finish(report, verbose, raise_on_failure)
    report.checks.append("protocol")
    beside = _ins_estimates(rec) if kind == "monitor" else None
    frames = rec.frames
    update_wall_s = [0.0]
    try:
        outs = _run(nav, rec, frames, kind=kind, beside=beside, update_wall_s=update_wall_s)
    except Exception as exc:  # noqa: BLE001
        report.fail("contract", f"raised on the recorded flight: {type(exc).__name__}: {exc}",
                    "a navigator never raises on data; skip and count bad samples in Health")
        return _finish(report, verbose, raise_on_failure)
    wall = update_wall_s[0]
    sim_s = float(frames[-1].t_end_s - frames[0].t_start_s)
    report.info["speed_sim_s_per_wall_s"] = round(sim_s / max(wall, 1e-9), 1)
    if kind == "navigator":
        _check_outputs(report, outs, frames, "recorded flight")
        report.info.update(_nees(outs, rec))
        _check_sensors(report, nav, rec, name, settings)
        _check_adversarial(report, lambda: _build(name, settings, rec, seed, kind), rec, kind, beside)
        _check_determinism(report, lambda: _build(name, settings, rec, seed, kind), rec, outs, kind, beside)
    else:
        _check_monitor_outputs(report, outs)
        _check_adversarial(report, lambda: _build(name, settings, rec, seed, kind), rec, kind, beside)
        _check_determinism(report, lambda: _build(name, settings, rec, seed, kind), rec, outs, kind, beside)
    if check_settings:
        _check_bad_settings(report, plugin, name, settings, rec, seed, kind)
    if not _MISUSE:
        report.checks.append("frames and estimates left as given")
    return _finish(report, verbose, raise_on_failure)


def _update_takes_estimate(factory) -> bool:
    """A class whose update() takes (frames, estimate): a monitor's signature."""
    import inspect
    update = getattr(factory, "update", None) if inspect.isclass(factory) else None
    try:
        params = [p for p in inspect.signature(update).parameters.values() if p.name != "self"]
    except (TypeError, ValueError):
        return False
    return len(params) >= 2


def _finish(report: CheckReport, verbose: bool, raise_on_failure: bool) -> CheckReport:
    _report_misuse(report)
    if verbose:
        print(report)
    if raise_on_failure and not report.ok:
        raise NavigatorCheckError(str(report))
    return report


def _check_outputs(report: CheckReport, outs: list, frames: list[SensorFrames], where: str) -> bool:
    prev = None
    for est, fr in zip(outs, frames, strict=True):
        for check, msg, fix in _estimate_problems(est, fr, prev):
            report.fail(check, f"{where}: {msg}", fix)
            return False
        prev = est.t_s
    report.checks.append(f"outputs on {where}")
    return True


def _nees(outs: list[Estimate], rec: FlightRecord) -> dict:
    from trn_env.sim.log import error_ned_m
    t = rec.truth
    est = np.array([[e.lat_rad, e.lon_rad, e.h_m] for e in outs])
    err = error_ned_m(t["lat_rad"][:len(outs)], t["lon_rad"][:len(outs)], t["h_m"][:len(outs)],
                      est[:, 0], est[:, 1], est[:, 2])
    nees = []
    for e, x in zip(outs, err, strict=True):
        try:
            nees.append(float(x @ np.linalg.solve(np.asarray(e.covariance)[:3, :3], x)))
        except np.linalg.LinAlgError:
            nees.append(math.nan)
    h = np.hypot(err[:, 0], err[:, 1])
    return {"position_nees_mean (3 = consistent)": round(float(np.nanmean(nees)), 2),
            "horizontal_error_rms_m": round(float(np.sqrt(np.mean(h ** 2))), 2)}


def _ins_estimates(rec: FlightRecord) -> list[Estimate]:
    nav = registry.create("ins")
    return _run(nav, rec, rec.frames)


def _check_monitor_outputs(report: CheckReport, outs: list) -> None:
    from trn_env.navigators.integrity.dem_monitor import output_problem
    for out in outs:
        problem = output_problem(out)
        if problem is not None:
            report.fail("contract", f"monitor {problem}",
                        "return navigators.integrity.dem_monitor.MonitorOutput")
            return
    report.checks.append("monitor outputs")


def _check_adversarial(report: CheckReport, make, rec: FlightRecord, kind: str, beside) -> None:
    """Clean frames, one adversarial frame at 15 s (GNSS denied), clean frames again."""
    k = min(15, len(rec.frames) - 3)
    uses = report.info.get("sensors_used") or []
    cases = [("nan", "NaN samples marked valid", True), ("empty", "an empty frame", True),
             ("gap", "a frame with a gap in its samples", True),
             ("no_return", "radar-altimeter / IRA no-returns", bool({"radar_altimeter", "ira"} & set(uses)))]
    for how, what, must_count in cases:
        frames = list(rec.frames)
        frames[k] = _corrupt(frames[k], how)
        nav = make()
        try:
            outs = _run(nav, rec, frames[:k + 3], kind=kind, beside=beside)
        except Exception as exc:  # noqa: BLE001
            report.fail("robustness", f"raised on {what}: {type(exc).__name__}: {exc}",
                        "never raise on data: skip the bad samples and count them with Health.skip")
            continue
        if kind == "navigator":
            if not _check_outputs(report, outs, frames[:k + 3], what):
                continue
            before = _TRACE[id(outs[k - 1])][0] if k else 0
            counted = _TRACE[id(outs[k])][0] > before or _TRACE[id(outs[k])][1] > 0
            if must_count and not counted:
                report.fail("health", f"{what} at {frames[k].t_start_s:g}-{frames[k].t_end_s:g} s left no "
                            "trace in Health (skipped counts and events unchanged)",
                            "count each skipped or missing sample with Health.skip(t_s, reason)")
                continue
        report.checks.append(f"robust to {what}")
    if kind == "navigator" and {"radar_altimeter", "ira"} & set(uses):
        _check_off_map(report, make, rec)


def _check_off_map(report: CheckReport, make, rec: FlightRecord) -> None:
    """An initial estimate 2 km outside the map's edge: hypotheses off the map must be skipped, counted."""
    dem = rec.map_dem
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    init = copy.deepcopy(rec.initial)
    init.lat_rad = lat_max + 2000.0 / 6.371e6
    frames = [fr for fr in rec.frames if fr.t_start_s >= 10.0][:5]     # GNSS denied: only the map to go by
    nav = make()
    try:
        nav.reset(init)
        outs = [nav.update(fr) for fr in frames]
    except Exception as exc:  # noqa: BLE001
        report.fail("robustness", f"raised with its hypotheses off the map: {type(exc).__name__}: {exc}",
                    "look the map up with NaN outside it and skip those measurements (Health.skip)")
        return
    if not (_skips(outs[-1].health) or any(e.health.events for e in outs) or not outs[-1].health.ok):
        report.fail("health", "with the estimate 2 km off the map no terrain measurement was counted as "
                    "skipped", "count off-map measurements with Health.skip(t_s, 'off_map')")
        return
    report.checks.append("robust off the map")


def _check_determinism(report: CheckReport, make, rec: FlightRecord, outs: list, kind: str, beside) -> None:
    again = _run(make(), rec, rec.frames, kind=kind, beside=beside)
    for i, (a, b) in enumerate(zip(outs, again, strict=True)):
        if not np.array_equal(_estimate_key(a), _estimate_key(b), equal_nan=True):
            report.fail("determinism", f"a second run with the same settings and seed differs at update {i}",
                        "draw random numbers only from the rng= Generator the factory is given")
            return
    report.checks.append("determinism")


def _check_sensors(report: CheckReport, nav, rec: FlightRecord, name: str, settings: dict) -> None:
    """Which sensors change the estimate (info), and declared required sensors refused when absent."""
    k = min(15, len(rec.frames))
    base = _run(nav, rec, rec.frames[:k])
    used = []
    for s in SENSORS:
        if getattr(rec.frames[0], s, None) is None:
            continue
        try:
            outs = _run(nav, rec, [_drop(fr, s) for fr in rec.frames[:k]])
        except Exception as exc:  # noqa: BLE001
            report.fail("robustness", f"raised without {s} frames: {type(exc).__name__}: {exc}",
                        "treat an absent sensor (None) as no samples")
            continue
        if any(a.lat_rad != b.lat_rad or a.h_m != b.h_m for a, b in zip(base, outs, strict=True)):
            used.append(s)
    report.info["sensors_used"] = used
    from trn_env.scenario.loading import _sensor_need_problems
    try:
        required = registry.sensor_needs(name, settings).required
    except ValueError as exc:
        report.fail("sensors", f"its declared sensor needs cannot be read: {exc}",
                    "declare Capabilities(required_sensors=..., optional_sensors=...) on the class")
        return
    for sensor in required:
        sc = _with_navigator(rec.scenario, name, settings)
        sc = replace(sc, sensors=sc.sensors.without(sensor))
        if not any(p.startswith(f"sensors.{sensor}:") for p in _sensor_need_problems(sc.to_dict())):
            report.fail("sensors", f"a scenario without {sensor} (declared required) is not refused",
                        "declare it in Capabilities.required_sensors (navigators.core.capabilities)")
            return
    undeclared = [s for s in used if s not in registry.sensor_needs(name, settings).used]
    if undeclared:
        report.info["used_but_not_declared"] = undeclared
    report.checks.append(f"declared sensors enforced ({len(required)} required)")


def _check_bad_settings(report: CheckReport, plugin, name: str, settings: dict, rec: FlightRecord, seed: int,
                        kind: str) -> None:
    from trn_env.navigators.catalogue import settings_of
    trials = [("no_such_setting_xyz", 1.0)]
    for s in settings_of(plugin.factory):
        if s.name in settings or s.name == "dem":
            continue
        try:
            default = eval(s.default, {"__builtins__": {}}, {"inf": math.inf, "nan": math.nan})  # noqa: S307
        except Exception:  # noqa: BLE001 - not a literal: no numeric trial
            continue
        if isinstance(default, float) and not isinstance(default, bool):
            trials += [(s.name, math.nan), (s.name, "not a number")]
        elif isinstance(default, int) and not isinstance(default, bool):
            trials += [(s.name, "not a number")]
    bad = []
    for key, value in trials:
        try:
            _build(name, {**settings, key: value}, rec, seed, kind)
        except ValueError as exc:
            if key not in str(exc):
                bad.append(f"{key}={value!r}: ValueError does not name the setting ({exc})")
            continue
        except Exception as exc:  # noqa: BLE001
            bad.append(f"{key}={value!r}: {type(exc).__name__} instead of ValueError ({exc})")
            continue
        bad.append(f"{key}={value!r}: accepted")
    if bad:
        report.fail("settings", f"{len(bad)} bad setting(s) not refused with a ValueError naming them: "
                    + "; ".join(bad[:8]) + (" ..." if len(bad) > 8 else ""),
                    "validate every setting in the constructor: raise ValueError(f'{name}: ...')")
    else:
        report.checks.append(f"bad settings refused ({len(trials)} tried)")
