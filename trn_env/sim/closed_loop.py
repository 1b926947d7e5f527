"""The multi-rate closed loop: flight -> sensors -> navigator -> guidance -> flight.

One loop tick is one navigator update interval (1 Hz by default, scenario `[navigator] rate_hz`), made of
guidance ticks (10 Hz by default, `[guidance] rate_hz`):

    for each guidance tick of the update interval:
        flight.record(steps_per_guidance_tick)          JSBSim at 100 Hz, raw truth kept unconverted
        targets = guidance.command(g.extrapolated(t))   guidance flies on the navigator's ESTIMATE g,
                                                        dead-reckoned with its own velocity
                                                        (asked for at the interval's start: _plan_guidance)
    chunk = flight.take()                               truth of the whole interval, converted once
    stage.submit(chunk)                                 sensors sample it (each at its own rate), GNSS is
                                                        gated by the scenario's outages, the navigator
                                                        updates - it never sees truth (nav_stage.py)
    est = stage.collect()                               the estimate for the interval's end

With `[navigator] latency_updates = 1` (default) g for interval k is the estimate for the end of interval
k - 1, so the stage's work on interval k - 1 can run in a second process while interval k is flown
(`ClosedLoop(..., pipeline=True)`: the estimate is collected after the flight, inside the next tick); with
0 it is the estimate of the interval just flown. Sensors and the navigator work on the interval's chunk in
one call each, so their fixed per-call costs are paid once per update, not once per guidance tick (`trn-env
bench` shows the split). Every sample keeps its own timestamp: an IMU sample at 100 Hz is processed at its
time whatever the update rate.

A run ends with `completed` (route flown, the aircraft at the last waypoint's height), `route_not_followed`
(the route's guidance is done but the aircraft is not at the last waypoint's height: summary.json says
what happened), `terrain_collision` (true height above the true terrain < 0 at
any JSBSim step), `off_map` (truth outside the true DEM), `diverged` (estimate not finite, horizontal
sigma above the scenario limit, or navigator health 'diverged'), `fuel_exhausted` (an engine stopped with
its fuel tank empty: JSBSim starves it), `engine_failure` (an engine stopped with fuel on board, e.g. cut
off), or `time_limit`. Termination is judged on every step of an update interval at its end (the truth
first - collision, map, engines - then that interval's estimate); route completion and the time limit end
the interval early. An engine stop ends the run at once rather than gliding on to a `terrain_collision`
that would hide its cause (`aircraft.constant_fuel = true` keeps the tanks full for long flights).

Randomness: the scenario seed -> numpy SeedSequence -> one Generator per component (flight/turbulence,
sensors, map errors, initial estimate errors, navigator), so one seed gives the same run bit for bit,
pipelined or not.
"""

from __future__ import annotations

import math
import time
import warnings
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

import trn_env.scenario.build as components
from trn_env.flight.core import FlightDiverged
from trn_env.flight.truth import TruthChunk
from trn_env.navigators.protocol import Estimate, Health
from trn_env.scenario.loading import Scenario, load_scenario
from trn_env.sim.interval_plan import IntervalPlan, IntervalPlanner
from trn_env.sim.log import SimLog
from trn_env.sim.nav_stage import InlineNavStage, ProcessNavStage, fork_available
from trn_env.sim.summary import summarise  # noqa: F401 - the run's summary, re-exported here
from trn_env.terrain.geodesy import latlon_to_ned_offset, meridian_radius_m, prime_vertical_radius_m

TERMINATIONS = ("completed", "terrain_collision", "off_map", "diverged", "fuel_exhausted", "engine_failure",
                "time_limit", "route_not_followed")
# `completed` needs the aircraft at the last waypoint's height within this (m; MSL or above the true terrain,
# as the waypoint gives it): a height-above-ground hold over the map meets the true terrain's detail and the
# autopilot's lag (the default flight: 1,250-1,700 m true AGL for 1,500 m commanded)
ROUTE_ALTITUDE_TOLERANCE_M = 300.0

# Order of the child seeds spawned from the scenario seed; append only (changing it changes every run).
RNG_STREAMS = ("flight", "sensors", "map", "initial_errors", "navigator")


def spawn_seeds(seed: int) -> dict[str, np.random.SeedSequence]:
    """One independent child SeedSequence per component from one scenario seed."""
    children = np.random.SeedSequence(int(seed)).spawn(len(RNG_STREAMS))
    return dict(zip(RNG_STREAMS, children, strict=True))


def spawn_rngs(seed: int) -> dict[str, np.random.Generator]:
    """One independent Generator per component from one scenario seed."""
    return {name: np.random.default_rng(s) for name, s in spawn_seeds(seed).items()}


def perturbed_estimate(truth: TruthChunk, i: int, sigmas, rng: np.random.Generator) -> Estimate:
    """Initial estimate = truth at row i + Gaussian errors with the scenario's 1-sigma values (`sigmas`: the
    scenario's `initial_errors` section, trn_env.scenario.sections.InitialErrorsSection, or a mapping with
    the same keys).

    Covariance = diag(sigma^2) over [n, e, d, vn, ve, vd, roll, pitch, yaw] (seed 000 Table 2 defaults).
    """
    if isinstance(sigmas, Mapping):
        from trn_env.scenario.sections import InitialErrorsSection
        sigmas = InitialErrorsSection(**sigmas)
    s_pos = np.asarray(sigmas.position_ned_m, float)
    s_vel = np.asarray(sigmas.velocity_ned_mps, float)
    s_att = 1e-3 * np.asarray(sigmas.attitude_mrad, float)
    e = rng.standard_normal(9) * np.concatenate([s_pos, s_vel, s_att])
    lat, lon, h = float(truth.lat_rad[i]), float(truth.lon_rad[i]), float(truth.h_msl_m[i])
    r_n = meridian_radius_m(lat) + h
    r_e = prime_vertical_radius_m(lat) + h
    cov = np.diag(np.concatenate([s_pos, s_vel, s_att]) ** 2)
    yaw = float(truth.yaw_rad[i]) + e[8]
    return Estimate(
        t_s=float(truth.t_s[i]),
        lat_rad=lat + e[0] / r_n,                      # seed 000 eq 2
        lon_rad=lon + e[1] / (r_e * math.cos(lat)),
        h_m=h - e[2],
        v_ned_mps=np.asarray(truth.v_ned_mps[i], float) + e[3:6],
        roll_rad=float(truth.roll_rad[i]) + e[6],
        pitch_rad=float(truth.pitch_rad[i]) + e[7],
        yaw_rad=math.atan2(math.sin(yaw), math.cos(yaw)),
        covariance=cov,
        health=Health(),
    )


@dataclass
class RunResult:
    scenario: Scenario
    termination: str
    sim_time_s: float
    wall_time_s: float
    jsbsim_steps: int
    arrays: dict[str, np.ndarray]
    events: list[tuple[float, str, str]]
    summary: dict
    world_dem: object = None


Commander = Callable[[Estimate, float], object]


class ClosedLoop:
    """One closed-loop flight of a validated scenario, advanced one navigator update interval at a time.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario (``load_scenario``).
    commander : callable, optional
        ``commander(estimate, t_s) -> AutopilotTargets`` replaces the scenario's route guidance.
    dems : tuple of Dem, optional
        ``(world, map)`` already built, to reuse terrain between flights.
    log_sensors : bool
        Keep the full-rate sensor frames in the log.
    progress : callable, optional
        Called as ``progress(t_s, total_s)``.
    pipeline : bool
        Run sensors and navigator in a second process (same bits; see below).

    Notes
    -----

    `commander(estimate, t_s) -> AutopilotTargets` replaces the scenario's route guidance (the gymnasium
    env uses this); `dems=(world, map)` reuses already-built terrain. `pipeline=True` runs the sensors and
    the navigator in a second process while the loop flies the next interval (nav_stage.ProcessNavStage);
    it needs `navigator.latency_updates = 1` and a platform with fork (else the loop runs inline:
    `self.pipelined` says which). The results are the same bit for bit either way. Close a pipelined loop
    when done with it (`run()` does; `close()` or `with ClosedLoop(...) as loop:` otherwise).

    `log_sink` (a trn_env.logs.writer.LogWriter) streams the log to disk as the flight goes (SimLog):
    the frames from the estimation stage, the ticks from here; the caller commits it after `result()`.

    Latency (scenario `[navigator] latency_updates`): guidance flies interval k on the estimate at the end
    of interval k - 1 - latency, dead-reckoned (with latency 1 the estimate of interval k - 1 is still being
    computed while interval k is flown). `self.estimate` is the newest estimate collected; `sync()` waits
    for the one in progress so that it matches `self.t_s`.
    """

    def __init__(self, scenario: Scenario, *, commander: Commander | None = None, dems=None,
                 log_sensors: bool = True, progress: Callable[[float, float], None] | None = None,
                 pipeline: bool = False, log_sink=None):
        self.scenario = sc = scenario
        self.seeds = spawn_seeds(scenario.seed)
        self.rngs = {name: np.random.default_rng(s) for name, s in self.seeds.items()}
        if dems is None:
            dems = components.build_terrain(sc, scenario.extras, self.rngs["map"])
        self.world_dem, self.map_dem = dems
        self.dt_s = float(sc.aircraft.dt_s)
        nav_rate_hz = float(sc.navigator.rate_hz)
        self.latency_updates = int(sc.navigator.latency_updates)
        # JSBSim steps per guidance tick, guidance ticks per navigator update (validated whole numbers)
        self.steps_per_guidance_tick = int(round(1.0 / (sc.guidance.rate_hz * self.dt_s)))
        self.guidance_ticks_per_tick = int(round(sc.guidance.rate_hz / nav_rate_hz))
        self.steps_per_tick = self.steps_per_guidance_tick * self.guidance_ticks_per_tick
        self.log_every = max(1, int(round(nav_rate_hz / sc.guidance.log_rate_hz)))
        self.duration_s = float(scenario.duration_s)
        self.outages = list(sc.gnss.outages)
        self.max_sigma_h_m = float(sc.limits.max_horizontal_sigma_m)
        self.max_err_h_m = sc.limits.max_horizontal_error_m
        self.log_sensors = log_sensors
        self.progress = progress

        self.flight = components.build_flight(sc, self.world_dem, self.rngs["flight"])
        sensors = components.build_sensors(sc, self.seeds["sensors"])
        navigator = components.build_navigator(sc, self.map_dem, self.rngs["navigator"])
        monitors = components.build_monitors(sc, self.map_dem)
        self.monitor_outputs: dict[str, list] = {name: [] for name in monitors}
        self.commander = commander
        if commander is None:
            guidance = components.build_guidance(sc, self.map_dem)
            command, complete = guidance.command, (lambda: components.guidance_complete(guidance))
        else:
            guidance, command, complete = None, commander, (lambda: False)
        self.guidance = guidance
        self.planner = IntervalPlanner(command, complete, self.map_dem, self.steps_per_guidance_tick,
                                       self.guidance_ticks_per_tick, self.dt_s, self.duration_s)
        # The route's guidance plans each interval right after the estimate it flies on, in the estimation
        # stage (so, pipelined, in the second process); a commander (the env, whose actions change between
        # ticks) is asked at each interval's start.
        self._plans: deque[IntervalPlan] | None = deque() if commander is None else None
        self._complete = False          # the route was complete after the commands of the interval flown

        truth0 = self.flight.snapshot()
        self.estimate = perturbed_estimate(truth0, 0, sc.initial_errors, self.rngs["initial_errors"])
        navigator.reset(self.estimate)
        self.guidance_estimate = self.estimate       # the estimate guidance flies on (dead-reckoned)
        self.t_s = float(truth0.t_s[0])
        self.last_truth = truth0
        self.jsbsim_steps = 0
        self.n_ticks = 0
        self.navigator_fixes = 0
        self.termination: str | None = None
        self.route_miss: str | None = None      # why the route was not followed (route_not_followed)
        self.log_sink = log_sink
        self.log = SimLog(sink=log_sink)
        # wall time per stage: flight core (recording and conversion), sensors, navigator, guidance between
        # navigator updates, waiting for a pipelined stage's output, the rest (termination checks, logging,
        # guidance after an update). Pipelined, the sensors and navigator times are the worker's.
        self.stage_s = {"flight": 0.0, "sensors": 0.0, "navigator": 0.0, "guidance": 0.0, "wait": 0.0,
                        "loop": 0.0, "monitors": 0.0}
        self._last_targets = None
        self._inflight: tuple[TruthChunk, int] | None = None   # submitted, not yet collected
        self._log_tick(truth0, 0, self.estimate)
        if self._plans is not None:
            # the first 1 + latency intervals fly on the initial estimate
            for k in range(1 + self.latency_updates):
                self._plans.append(self.planner.plan(self.estimate, k * self.steps_per_tick))
            self._apply(*self._plans[0].commands[0])
        else:
            self.command_now()

        inline = InlineNavStage(sensors, navigator, self.world_dem, self.outages, log_sensors,
                                self.planner if self._plans is not None else None, monitors=monitors,
                                map_dem=self.map_dem,
                                map_schedule=self._map_schedule(scenario), frame_sink=log_sink,
                                lever_arms=components.sensor_lever_arms(sc))
        self.pipelined = bool(pipeline and self.latency_updates >= 1 and fork_available())
        self._stage = inline
        if self.pipelined:
            try:        # forked last, so the worker starts from exactly this state
                self._stage = ProcessNavStage(inline)
            except OSError as err:              # no process to be had: the same run, in this one
                warnings.warn(f"ClosedLoop: running inline, the worker process failed to start ({err})",
                              RuntimeWarning, stacklevel=2)
                self.pipelined = False
        # the sensors, navigator and guidance objects in use (None when they live in the worker process)
        self.sensors = None if self.pipelined else sensors
        self.navigator = None if self.pipelined else navigator
        if self.pipelined:
            self.guidance = None

    def _map_schedule(self, scenario: Scenario) -> list:
        """The time-dependent map's changes, when the map is the one built for this scenario (its
        faults-from-start heights restored first: the env reuses the map from episode to episode)."""
        schedule = scenario.extras.get("map_fault_schedule") or []
        if not schedule or self.map_dem is not scenario.extras.get("map_dem"):
            return []
        from trn_env.terrain.map_error import set_heights
        set_heights(self.map_dem, scenario.extras["map_fault_heights0"])
        return schedule

    def close(self) -> None:
        """Stop the pipelined stage's worker process (idempotent; a no-op inline). An ended run has its
        sensor frames in the log by then; a run closed midway keeps only those already fetched."""
        self._stage.close()

    def _fetch_frames(self) -> None:
        """Move the stage's logged sensor frames into the log (nothing in progress may be pending)."""
        if self._stage.busy:
            return
        for frames in self._stage.logged_frames():
            self.log.add_frames(frames)
        if self.log_sink is not None:
            self._stage.finish_frames()

    def __enter__(self) -> ClosedLoop:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------------------------------ loop
    def command_now(self, est: Estimate | None = None) -> None:
        """Targets from the commander written to the flight now, for `est` or by default the guidance
        estimate dead-reckoned to now, with the map height under it for the autopilot's height-above-ground
        hold (the env calls this when its action changes). A loop flying the scenario's route takes its
        targets from the interval plans instead."""
        if self._plans is not None:
            raise RuntimeError("command_now: this loop flies its route's interval plans (no commander)")
        self._apply(*self.planner.command_at(self.guidance_estimate if est is None else est, self.t_s))

    def _apply(self, targets, h_ground: float) -> None:
        if targets != self._last_targets:        # unchanged targets need no property writes
            self.flight.set_targets(targets)
            self._last_targets = targets
        if math.isfinite(h_ground):
            self.flight.set_terrain_elevation(h_ground)

    def _plan_guidance(self) -> list[tuple[object, float]]:
        """The commands of the guidance ticks inside the coming update interval after its first (written
        when the previous interval ended), in order: after each guidance tick's steps, the targets for the
        guidance estimate dead-reckoned to that time. They depend on nothing the interval's flight produces,
        so they are asked for before it (interval_plan.py): for the route, by the estimation stage when the
        estimate was made; for a commander, here."""
        if self._plans is not None:
            plan = self._plans.popleft()
        else:
            plan = self.planner.plan(self.guidance_estimate, self.flight.steps, first_tick=1)
        self._complete = plan.complete
        return plan.commands[1:] if self._plans is not None else plan.commands

    def route_complete(self) -> bool:
        """The route's guidance was done after the commands of the interval last flown."""
        return self._complete

    def tick(self) -> str | None:
        """Advance one navigator update interval (its guidance ticks included); returns the termination
        reason once the run has ended.

        The interval's truth goes to the estimation stage; with latency 1 its estimate is collected during
        the next tick, after that interval is flown (pipelined, the worker computes it meanwhile). Should
        that estimate have diverged, the run ends at its time and the interval flown since is dropped
        (never logged or counted), so a pipelined and an inline run end the same way."""
        if self.termination is not None:
            raise RuntimeError(f"the run has already ended ({self.termination})")
        clock = time.perf_counter
        flight = self.flight
        record, n_steps, apply = flight.record, self.steps_per_guidance_tick, self._apply
        t0 = clock()
        plan = self._plan_guidance()
        t1 = clock()
        try:
            for targets, h_ground in plan:
                record(n_steps)
                apply(targets, h_ground)
            record(n_steps)
            chunk = flight.take()
        except FlightDiverged:
            if self._inflight is not None and self._collect(final=False) is not None:
                return self._end("diverged")      # the estimate had ended the run before this interval
            raise
        t2 = clock()
        self.stage_s["guidance"] += t1 - t0
        self.stage_s["flight"] += t2 - t1
        if self._inflight is not None and self._collect(final=False) is not None:
            return self._end("diverged")
        t3 = clock()
        self.t_s = flight.t_s
        self.jsbsim_steps += len(chunk)
        self.last_truth = chunk
        self.n_ticks += 1
        t4 = clock()
        plan_steps0 = self.flight.steps + self.latency_updates * self.steps_per_tick
        self._stage.submit(chunk, plan_steps0)    # inline, the work is done here: counted by _collect
        if not self._stage.pipelined:
            t3 += clock() - t4
        self._inflight = (chunk, self.n_ticks)
        reason = self._truth_reason(chunk)
        if reason is not None or self.route_complete() or self._time_up() or self.latency_updates == 0:
            final = reason is not None or self.route_complete() or self._time_up()
            t4 = clock()
            diverged = self._collect(final=final)
            t3 += clock() - t4                    # counted as wait, sensors and navigator by _collect
            if reason is None:
                reason = diverged or (self._completion(chunk) if self.route_complete() else
                                      "time_limit" if self._time_up() else None)
        if reason is None:
            self.guidance_estimate = self.estimate
            if self._plans is not None:
                self._apply(*self._plans[0].commands[0])
            else:
                self.command_now()
        else:
            self._end(reason)
        self.stage_s["loop"] += clock() - t3
        if self.progress is not None:
            self.progress(self.t_s, self.duration_s)
        return reason

    def sync(self) -> str | None:
        """Wait for the estimate in progress, if any, so that `self.estimate` is the estimate at `self.t_s`;
        returns the termination reason if it ended the run (diverged)."""
        if self.termination is None and self._inflight is not None and self._collect(final=False):
            self._end("diverged")
        return self.termination

    def _collect(self, final: bool) -> str | None:
        """Take the submitted interval's estimate from the stage: becomes self.estimate, its frames and
        health events are logged, its row too (on the log's rate, or when `final` or diverged); returns
        'diverged' if it ended the run."""
        chunk, tick_no = self._inflight
        t0 = time.perf_counter()
        out = self._stage.collect()
        st = self.stage_s
        st["wait"] += time.perf_counter() - t0
        st["sensors"] += out.sensors_s
        st["navigator"] += out.navigator_s
        st["guidance"] += out.guidance_s
        if out.plan is not None:
            self._plans.append(out.plan)
        self._inflight = None
        est = out.estimate
        self.estimate = est
        self.navigator_fixes = out.navigator_fixes
        self._log_gnss_outages(chunk)
        for t_ev, msg in est.health.events:
            self.log.events.append((t_ev, "navigator", msg))
        st["monitors"] += out.monitor_s
        if out.events:
            self.log.events.extend(out.events)
        if out.monitors:
            for name, mo in out.monitors.items():
                self.monitor_outputs[name].append(mo)
        diverged = self._diverged(chunk, est)
        if final or diverged or tick_no % self.log_every == 0:
            self._log_tick(chunk, len(chunk) - 1, est)
        return "diverged" if diverged else None

    def _log_gnss_outages(self, chunk: TruthChunk) -> None:
        """Events for the scenario's GNSS outage edges (gnss.outages) that fall inside the chunk's time."""
        if not self.outages or not len(chunk):
            return
        t0, t1 = float(chunk.t_s[0]) - 0.5 * self.dt_s, float(chunk.t_s[-1]) + 0.5 * self.dt_s
        for i, o in enumerate(self.outages):
            if t0 <= o.start_s < t1:
                self.log.events.append((float(o.start_s), "gnss",
                                        f"GNSS outage begins (gnss.outages[{i}]): no fixes reach the "
                                        "navigator"))
            if o.end_s is not None and t0 <= o.end_s < t1:
                self.log.events.append((float(o.end_s), "gnss", f"GNSS outage ends (gnss.outages[{i}]):"
                                        " fixes reach the navigator again"))

    def _end(self, reason: str) -> str:
        if self._inflight is not None:          # (not reached: every ending collects first)
            self._collect(final=True)
        if self.last_truth is not None and len(self.last_truth):
            self.t_s = float(self.last_truth.t_s[-1])
        self.termination = reason
        self.log.events.append((self.t_s, "sim", f"termination: {reason}"))
        self._fetch_frames()
        self.close()
        return reason

    def _completion(self, chunk: TruthChunk) -> str:
        """`completed`, or `route_not_followed` (with an event saying why) when the guidance has flown the
        route but the aircraft is not at the last waypoint's height (it could not climb or descend to it)."""
        if self.commander is not None:
            return "completed"
        wp = self.scenario.route.waypoints[-1]
        lat, lon, h = float(chunk.lat_rad[-1]), float(chunk.lon_rad[-1]), float(chunk.h_msl_m[-1])
        if wp.h_agl_m is not None:
            ground = float(self.world_dem.height(lat, lon))
            have, want, ref = h - ground, float(wp.h_agl_m), "above ground"
        else:
            have, want, ref = h, float(wp.h_msl_m), "MSL"
        if math.isfinite(have) and abs(have - want) > ROUTE_ALTITUDE_TOLERANCE_M:
            n = len(self.scenario.route.waypoints)
            self.route_miss = (f"the route ended with the aircraft at {have:.0f} m {ref}, the last waypoint "
                               f"(route.waypoints[{n - 1}]) asks for {want:.0f} m: it could not follow the "
                               f"route's heights (tolerance {ROUTE_ALTITUDE_TOLERANCE_M:.0f} m)")
            self.log.events.append((float(chunk.t_s[-1]), "sim", self.route_miss))
            return "route_not_followed"
        return "completed"

    def _time_up(self) -> bool:
        return self.t_s >= self.duration_s - 0.5 * self.dt_s

    def _truth_reason(self, chunk: TruthChunk) -> str | None:
        """off_map or terrain_collision if any step of the chunk was; else fuel_exhausted or engine_failure
        if an engine is stopped at its end (the stop is logged as an event)."""
        agl_min, n_nan = components.min_height_above_terrain(self.world_dem, chunk.lat_rad, chunk.lon_rad,
                                                             chunk.h_msl_m)
        if n_nan:   # a step off the grid or over a void (then the other steps are judged)
            inside = components.world_contains(self.world_dem, chunk.lat_rad, chunk.lon_rad)
            if not np.all(inside):
                k = int(np.argmin(inside))
                lat, lon = chunk.lat_rad[k:k + 1], chunk.lon_rad[k:k + 1]
                if any(components.world_contains(self.world_dem, lat, lon + turn)[0]
                       for turn in (-2.0 * math.pi, 2.0 * math.pi)):
                    self.log.events.append((float(chunk.t_s[k]), "sim", "the aircraft crossed the "
                                            "antimeridian (180 deg), which trn-env does not fly across: "
                                            "keep the flight on one side of it"))
                return "off_map"
        if agl_min < 0.0:
            return "terrain_collision"
        stop = self.flight.engine_stop()
        if stop is not None:
            self.log.events.append((float(chunk.t_s[-1]), "flight", stop[1]))
            return stop[0]
        return None

    def _diverged(self, chunk: TruthChunk, est: Estimate) -> bool:
        if not (math.isfinite(est.lat_rad) and math.isfinite(est.lon_rad) and math.isfinite(est.h_m)):
            return True
        c = est.covariance
        if not math.isfinite(float(c[:3, :3].sum())):   # a NaN or inf anywhere in the position block
            return True
        if est.health.status == "diverged":
            return True
        sig_h = math.sqrt(max(c[0, 0], 0.0) + max(c[1, 1], 0.0))
        if sig_h > self.max_sigma_h_m:
            return True
        if self.max_err_h_m is not None:
            e = self._err_ned(chunk, len(chunk) - 1, est)
            if math.hypot(e[0], e[1]) > self.max_err_h_m:
                return True
        return False

    @staticmethod
    def _err_ned(truth: TruthChunk, i: int, est: Estimate) -> np.ndarray:
        """Estimate minus truth in NED metres (at the true position)."""
        lat, lon, h = float(truth.lat_rad[i]), float(truth.lon_rad[i]), float(truth.h_msl_m[i])
        dn, de = latlon_to_ned_offset(lat, lon, h, est.lat_rad, est.lon_rad)
        return np.array([dn, de, -(est.h_m - h)])

    def _log_tick(self, truth: TruthChunk, i: int, est: Estimate) -> None:
        self.log.add_tick(truth, i, est)

    def run(self) -> RunResult:
        """Fly until a termination; returns the result with its log and summary (closes the loop)."""
        wall0 = time.perf_counter()
        try:
            while self.termination is None:
                self.tick()
        finally:
            self.close()
        wall = time.perf_counter() - wall0
        return self.result(wall)

    def result(self, wall_time_s: float) -> RunResult:
        self.sync()
        if self.termination is None:
            self._fetch_frames()
        arrays = self.log.arrays(self.world_dem, self.outages)
        summary = summarise(self.scenario, self.termination or "time_limit", arrays, wall_time_s,
                            self.jsbsim_steps, self.estimate)
        from trn_env.navigators.integrity.dem_monitor import alarm_summary, concatenate
        if self.monitor_outputs:
            summary["monitors"] = {}
            for name, outs in self.monitor_outputs.items():
                mon = concatenate(outs)
                arrays.update({f"monitor_{name}_{k}": v for k, v in mon.items()})
                summary["monitors"][name] = alarm_summary(mon)
        summary["map_faults"] = list(self.scenario.extras.get("map_faults", []))
        summary["wall_time_by_stage_s"] = {k: round(v, 4) for k, v in self.stage_s.items()}
        summary["pipelined"] = self.pipelined
        if self.route_miss is not None:
            summary["route_not_followed"] = self.route_miss
        summary["navigator_latency_updates"] = self.latency_updates
        summary["fuel_remaining_kg"] = round(self.flight.fuel_kg, 3)
        summary["constant_fuel"] = self.flight.constant_fuel
        summary["truth_source"] = self.scenario.truth.source
        from trn_env.navigators.integrity.protection_level import EXTRA_PL_NOT_VALIDATED
        if EXTRA_PL_NOT_VALIDATED in self.estimate.extra:    # the navigator's word on its HPL's validity
            summary["pl_not_validated"] = str(self.estimate.extra[EXTRA_PL_NOT_VALIDATED])
        # fitted sensors that neither the navigator nor a monitor reads (their declared sensor needs)
        summary["unused_sensors"] = components.unused_sensors(self.scenario)
        events = sorted(self.log.events, key=lambda ev: ev[0])   # (stable: same-time events keep their order)
        return RunResult(self.scenario, summary["termination"], summary["sim_time_s"], wall_time_s,
                         self.jsbsim_steps, arrays, events, summary, self.world_dem)


def run_scenario(name_or_path="default", *, sets: Mapping[str, object] | None = None, progress=None,
                 pipeline: bool = True, **overrides) -> RunResult:
    """Load, validate and fly a scenario in closed loop.

    Parameters
    ----------
    name_or_path : str, Path, Scenario or dict
        A built-in scenario name, a TOML file's path, a loaded Scenario or a scenario dict.
    sets : mapping, optional
        Scenario fields by dotted path (``{"wind.layers.0.speed_mps": 12.0}``), applied after the overrides,
        as ``trn-env fly --set`` applies them.
    progress : callable, optional
        Called as ``progress(t_s, total_s)`` as the flight goes.
    pipeline : bool
        Run the sensors and the navigator in a second process one update behind the flight where the
        scenario allows it; the results are the same bits either way.
    **overrides
        ``seed=``, ``duration_s=`` (s) and ``navigator=``, as ``load_scenario`` takes them (TypeError for
        any other name).

    Returns
    -------
    RunResult
        ``.summary`` (the ``summary.json`` fields) and ``.arrays`` (the time-series log).

    Raises
    ------
    ScenarioError
        When the scenario is invalid (every problem, by field path), before anything flies.
    """
    from trn_env.scenario.overrides import load_scenario_with

    if sets is not None and not isinstance(sets, Mapping):
        raise TypeError(f"sets must be a mapping of dotted paths to values, got {type(sets).__name__}")
    if isinstance(name_or_path, Scenario) and not sets and not overrides:
        scenario = name_or_path
    elif not sets:
        scenario = load_scenario(name_or_path, **overrides)
    else:
        scenario = load_scenario_with(name_or_path, list(sets.items()), **overrides)
    return ClosedLoop(scenario, progress=progress, pipeline=pipeline).run()
