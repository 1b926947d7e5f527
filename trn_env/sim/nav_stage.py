"""The closed loop's estimation stage: sensors, then the navigator, over one update interval of truth.

The loop submits each interval's truth chunk and later collects the navigator's estimate for its end:

    stage.submit(chunk, steps0)  the sensors sample the chunk, GNSS is gated, the navigator updates, and
                                 (given a planner) guidance plans the interval starting at step steps0
    out = stage.collect()        NavOutput: the estimate, the plan, the stage's timings

`InlineNavStage` does the work inside `submit`. `ProcessNavStage` does it in a second process forked from the
loop's, so it runs while the loop flies the next interval; the loop collects before it submits again. The
worker is a fork of the same objects (sensor generators, navigator state, DEMs) and they are used in the
same order, so both stages give the same estimates bit for bit; which one runs is a matter of speed only.
The worker ignores Ctrl-C (the loop's process handles it and closes the stage), exits when the loop's end
of the pipe closes, and sends back any exception it meets, to be raised by `collect`.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
import sys
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from trn_env.flight.truth import TruthChunk, chunk_from_buffer, chunk_to_buffer
from trn_env.navigators.frames import SensorFrames, copy_frames
from trn_env.navigators.protocol import Estimate, NavigatorContractError
from trn_env.sim.interval_plan import IntervalPlan, IntervalPlanner


def outage_windows(outages) -> list[tuple[float, float]]:
    """[(start_s, end_s)] of GNSS outages given as the scenario's `gnss.outages` sections
    (trn_env.scenario.sections.Outage) or as {start_s, end_s} mappings (a log's metadata); an outage
    without end_s lasts for the rest of the flight (end_s = inf)."""
    out = []
    for o in outages:
        if isinstance(o, Mapping):
            out.append((o["start_s"], o.get("end_s", math.inf)))
        else:
            out.append((o.start_s, math.inf if o.end_s is None else o.end_s))
    return out


def gnss_available_mask(t_s: np.ndarray, outages) -> np.ndarray:
    """True where GNSS fixes reach the navigator: outside every [start_s, end_s) outage (`outages` as
    outage_windows takes them)."""
    ok = np.ones(np.shape(t_s), bool)
    for start, end in outage_windows(outages):
        ok &= ~((t_s >= start) & (t_s < end))
    return ok


def gate_gnss(frames: SensorFrames, outages) -> SensorFrames:
    """The frames with the GNSS fixes inside an outage removed (frames.gnss None if none is left)."""
    g = frames.gnss
    if g is None or not outages or g.t_s.shape[0] == 0:
        return frames
    windows = outage_windows(outages)
    t_first, t_last = float(g.t_s[0]), float(g.t_s[-1])
    if all(t_last < start or t_first >= end for start, end in windows):
        return frames                                   # no outage touches this frame
    if any(t_first >= start and t_last < end for start, end in windows):
        frames.gnss = None                              # the whole frame is inside one outage
        return frames
    keep = gnss_available_mask(g.t_s, outages)
    if keep.all():
        return frames
    if not keep.any():
        frames.gnss = None
        return frames
    frames.gnss = type(g)(**{k: (v[keep] if isinstance(v, np.ndarray) else v) for k, v in vars(g).items()})
    return frames


def navigator_update(navigator, frames: SensorFrames) -> Estimate:
    """navigator.update(frames), refused with NavigatorContractError unless it is an Estimate with a square
    covariance of at least the 9 x 9 block and three velocity components (a plug-in's missing `return` or
    its position-only covariance otherwise fails far from its cause: on an attribute of None, or when the
    log stacks the covariances)."""
    est = navigator.update(frames)
    problem = None
    cov_shape = np.shape(getattr(est, "covariance", None))
    if not isinstance(est, Estimate):
        problem = f"update() returned {type(est).__name__}, not a trn_env.navigators.protocol.Estimate"
    elif not (len(cov_shape) == 2 and cov_shape[0] == cov_shape[1] and cov_shape[0] >= 9):
        problem = (f"its estimate's covariance has shape {cov_shape}, not the 9 x 9 block over [north, "
                   "east, down, v_n, v_e, v_d, roll, pitch, yaw]")
    elif np.shape(est.v_ned_mps) != (3,):
        problem = f"its estimate's v_ned_mps has shape {np.shape(est.v_ned_mps)}, not (3,)"
    if problem is not None:
        name = getattr(navigator, "name", type(navigator).__name__)
        raise NavigatorContractError(
            f"navigator {name!r}: {problem} (the update ending {frames.t_end_s:g} s): return the estimate "
            "from every update; trn_env.testing.check_navigator checks the whole contract")
    return est


def monitor_update(monitor, name: str, frames: SensorFrames, estimate: Estimate):
    """monitor.update(frames, estimate), refused with NavigatorContractError unless it has a MonitorOutput's
    shape (otherwise the run fails at its end, on concatenating the rows, with the whole flight lost)."""
    from trn_env.navigators.integrity.dem_monitor import output_problem
    out = monitor.update(frames, estimate)
    problem = output_problem(out)
    if problem is not None:
        raise NavigatorContractError(
            f"monitor {name!r}: {problem} (the update ending {frames.t_end_s:g} s): return "
            "trn_env.navigators.integrity.dem_monitor.MonitorOutput; trn_env.testing.check_navigator "
            "checks the whole contract")
    return out


def _fix_count(navigator) -> int:
    """The navigator's TERCOM fixes so far (`n_fixes`, else the length of its `fixes`)."""
    n = getattr(navigator, "n_fixes", None)
    return int(n) if n is not None else len(getattr(navigator, "fixes", ()))


@dataclass
class NavOutput:
    """One update's result: the estimate at the interval's end, the guidance plan made on it (None without a
    planner), wall seconds spent in the sensors, the navigator and the planning, and the navigator's TERCOM
    fix count so far."""

    estimate: Estimate
    plan: IntervalPlan | None
    sensors_s: float
    navigator_s: float
    guidance_s: float
    navigator_fixes: int
    monitors: dict | None = None       # monitor name -> its output for this interval
    events: list | None = None         # (t_s, source, message) of the stage: monitor alarms, map changes
    monitor_s: float = 0.0             # wall seconds in the monitors


class InlineNavStage:
    """The stage run in the caller's process: `submit` does the work, `collect` hands it over. With
    log_sensors the frames are kept here until `logged_frames()` (pipelined, that spares the loop their
    transfer every update)."""

    pipelined = False

    def __init__(self, sensors, navigator, world_dem, outages: list[dict], log_sensors: bool,
                 planner: IntervalPlanner | None = None, monitors: dict | None = None, map_dem=None,
                 map_schedule: list | None = None, frame_sink=None, lever_arms: dict | None = None):
        """lever_arms: {sensor: body-FRD offset from the IMU, m}: the navigator gets the ranging sensors'
        measurements transferred to the IMU's point (navigators.measurements.lever_arm; the monitors and
        the log get them as measured); frame_sink: an object whose `write_frames(frames)` takes each
        interval's frames instead of the in-memory list (a trn_env.logs LogWriter; `finish_frames` closes
        it); monitors: {name: monitor} run after the navigator on the same frames and its estimate. While
        the log or a monitor reads the frames, the navigator and each monitor get a copy of their own
        (navigators.frames.copy_frames): what one changes in place reaches no other reader.
        map_schedule: [(t_from_s, heights)] of a time-dependent navigator's map `map_dem`: the heights are
        swapped in (terrain.map_error.set_heights) before the first update interval that reaches t_from_s,
        in this process, so the navigator, the monitors and the route's guidance all meet them."""
        self.monitors = dict(monitors or {})
        self.map_dem = map_dem
        self.map_schedule = list(map_schedule or [])
        self.sensors = sensors
        self.navigator = navigator
        self.planner = planner
        self.world_dem = world_dem
        self.outages = list(outages)
        self.log_sensors = bool(log_sensors)
        self._out: NavOutput | None = None
        self._frames: list[SensorFrames] = []
        self.frame_sink = frame_sink
        from trn_env.navigators.measurements.lever_arm import has_lever_arms
        self.lever_arms = dict(lever_arms) if has_lever_arms(lever_arms) else None

    def process(self, chunk: TruthChunk, plan_steps0: int | None = None) -> NavOutput:
        clock = time.perf_counter
        events = []
        while self.map_schedule and self.map_schedule[0][0] <= float(chunk.t_s[-1]):
            from trn_env.terrain.map_error import set_heights
            t_fault, heights = self.map_schedule.pop(0)
            set_heights(self.map_dem, heights)
            events.append((float(t_fault), "map",
                           f"map fault appears in the navigator's map at {t_fault:g} s"))
        t0 = clock()
        frames = gate_gnss(self.sensors.sample(chunk, self.world_dem), self.outages)
        t1 = clock()
        # The log and the monitors get the frames as measured: when anyone reads them after the navigator,
        # each reader gets arrays of its own, so a change one makes in place stays with it.
        shared = bool(self.monitors) or self.frame_sink is not None or self.log_sensors
        nav_frames = copy_frames(frames) if shared else frames
        if self.lever_arms is not None:
            from trn_env.navigators.measurements.lever_arm import compensate_frames
            nav_frames = compensate_frames(nav_frames, self.lever_arms)
        est = navigator_update(self.navigator, nav_frames)
        t2 = clock()
        mon_out = None
        if self.monitors:
            mon_out = {}
            for name, mon in self.monitors.items():
                out = monitor_update(mon, name, copy_frames(frames), est)
                mon_out[name] = out
                events += [(t_ev, name, msg) for t_ev, msg in out.events]
        t_mon = clock() - t2
        t2 = clock()
        if self.frame_sink is not None:
            self.frame_sink.write_frames(frames)
        elif self.log_sensors:
            self._frames.append(frames)
        plan = None
        finite = math.isfinite(est.lat_rad) and math.isfinite(est.lon_rad) and math.isfinite(est.h_m)
        if self.planner is not None and plan_steps0 is not None and finite:   # (else the run ends on it)
            plan = self.planner.plan(est, plan_steps0)
        return NavOutput(est, plan, t1 - t0, t2 - t1, clock() - t2, _fix_count(self.navigator),
                         mon_out, events, t_mon)

    def logged_frames(self) -> list[SensorFrames]:
        """The frames of every update so far not yet handed over, in order (empty unless log_sensors)."""
        frames, self._frames = self._frames, []
        return frames

    def finish_frames(self) -> dict:
        """Close the frame sink's tables (rows per table; {} without a sink)."""
        return self.frame_sink.close_frames() if self.frame_sink is not None else {}

    @property
    def busy(self) -> bool:
        """True between a submit and its collect."""
        return self._out is not None

    def submit(self, chunk: TruthChunk, plan_steps0: int | None = None) -> None:
        if self._out is not None:
            raise RuntimeError("InlineNavStage.submit: the previous output was not collected")
        self._out = self.process(chunk, plan_steps0)

    def collect(self) -> NavOutput:
        if self._out is None:
            raise RuntimeError("InlineNavStage.collect: nothing submitted")
        out, self._out = self._out, None
        return out

    def close(self) -> None:
        self._out = None


def fork_available() -> bool:
    """A worker process can be forked here: Linux (macOS has fork, but its system libraries are not safe to
    use after it) and a process that may have children (gymnasium's AsyncVectorEnv runs environments in
    daemonic processes, which may not)."""
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


_QUIT, _FRAMES, _FINISH = b"Q", b"F", b"E"   # the worker's one-byte requests; longer: a truth chunk


def _serve(conn, parent_end, stage: InlineNavStage) -> None:
    """The worker's loop: a chunk in (truth.chunk_to_buffer, tagged with the plan's first step or -1), a
    NavOutput (or the exception met) out; _QUIT or EOF ends it, _FRAMES asks for the logged frames."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent_end.close()
    while True:
        try:
            msg = conn.recv_bytes()
        except (EOFError, OSError):
            return
        if msg == _QUIT:
            return
        try:
            if msg == _FRAMES:                    # requested once at the end
                reply = ("ok", stage.logged_frames())
            elif msg == _FINISH:                  # the frame sink's tables closed, once at the end
                reply = ("ok", stage.finish_frames())
            else:
                chunk, plan_steps0 = chunk_from_buffer(bytearray(msg))   # (a private, writable copy)
                reply = ("ok", stage.process(chunk, plan_steps0 if plan_steps0 >= 0 else None))
        except BaseException as exc:          # sent back whole; raised again by collect()
            reply = ("error", exc, traceback.format_exc())
        try:
            conn.send(reply)
        except (BrokenPipeError, ConnectionError, EOFError, OSError):
            return                            # the loop stopped (Ctrl-C, a closed run): nobody to tell
        except Exception as exc:              # an exception or output that does not pickle
            try:
                conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}"), traceback.format_exc()))
            except (BrokenPipeError, ConnectionError, EOFError, OSError):
                return


class ProcessNavStage:
    """The stage in a forked worker process (see the module docstring). Close it when done (the loop does)."""

    pipelined = True

    def __init__(self, inline: InlineNavStage):
        if not fork_available():
            raise RuntimeError("ProcessNavStage needs the fork start method in a non-daemonic process")
        ctx = multiprocessing.get_context("fork")
        self._conn, child_end = ctx.Pipe(duplex=True)
        self._process = ctx.Process(target=_serve, args=(child_end, self._conn, inline), daemon=True,
                                    name="trn-env-nav-stage")
        self._process.start()
        child_end.close()
        self._busy = False

    @property
    def busy(self) -> bool:
        return self._busy

    def submit(self, chunk: TruthChunk, plan_steps0: int | None = None) -> None:
        self._send(chunk_to_buffer(chunk, -1 if plan_steps0 is None else int(plan_steps0)))

    def _send(self, msg) -> None:
        if self._busy:
            raise RuntimeError("ProcessNavStage.submit: the previous output was not collected")
        self._conn.send_bytes(msg)
        self._busy = True

    def collect(self) -> NavOutput:
        if not self._busy:
            raise RuntimeError("ProcessNavStage.collect: nothing submitted")
        try:
            reply = self._conn.recv()
        except (EOFError, OSError):
            self._process.join(1.0)
            raise RuntimeError(f"the navigator's worker process ended unexpectedly (exit code "
                               f"{self._process.exitcode})") from None
        self._busy = False
        if reply[0] == "ok":
            return reply[1]
        exc, tb = reply[1], reply[2]
        raise exc from RuntimeError(f"raised in the navigator's worker process:\n{tb}")

    def logged_frames(self) -> list[SensorFrames]:
        """The worker's logged frames not yet handed over (collect first; none once closed)."""
        if self._process is None:
            return []
        self._send(_FRAMES)
        return self.collect()

    def finish_frames(self) -> dict:
        """Close the worker's frame sink (collect first); {} once closed."""
        if self._process is None:
            return {}
        self._send(_FINISH)
        return self.collect()

    def close(self) -> None:
        """Stop the worker (idempotent)."""
        if self._process is None:
            return
        try:
            self._conn.send_bytes(_QUIT)
        except (OSError, ValueError):
            pass
        self._conn.close()
        self._process.join(2.0)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(2.0)
        self._process = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
