"""The guidance commands of one navigator update interval, asked for in one go.

Guidance flies an update interval on one estimate, dead-reckoned to each guidance tick (sim.py), so the
interval's commands depend on nothing its flight produces: they are asked for before it is flown, in the
order the ticks come. Asked for in the closed loop's second process (nav_stage.py) right after the estimate
they use, they cost the flight's process nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import trn_env.scenario.build as components


@dataclass
class IntervalPlan:
    """commands[j] = (autopilot targets, map height under the estimate (m, NaN off the map)) for guidance tick
    j of the interval, written after its first j guidance ticks' steps; the list stops where the time limit
    falls or the route is complete. complete: the route was complete once they were asked for."""

    commands: list[tuple[object, float]]
    complete: bool


class IntervalPlanner:
    """command(estimate, t_s) -> targets is the guidance (or an env's commander); complete() says whether it
    has flown its route; map_dem gives the height under the estimate for the autopilot's AGL hold."""

    def __init__(self, command: Callable[[object, float], object], complete: Callable[[], bool], map_dem,
                 steps_per_guidance_tick: int, guidance_ticks: int, dt_s: float, duration_s: float):
        self.command = command
        self.complete = complete
        self.map_dem = map_dem
        self.steps_per_guidance_tick = int(steps_per_guidance_tick)
        self.guidance_ticks = int(guidance_ticks)
        self.dt_s = float(dt_s)
        self.duration_s = float(duration_s)

    def command_at(self, est, t_s: float) -> tuple[object, float]:
        """(targets, map height) for `est` dead-reckoned to t_s (itself if it is for t_s)."""
        if est.t_s != t_s:
            est = est.extrapolated(t_s)
        return self.command(est, t_s), components.map_height(self.map_dem, est.lat_rad, est.lon_rad)

    def plan(self, est, steps0: int, first_tick: int = 0) -> IntervalPlan:
        """The commands of the interval starting at JSBSim step steps0, from guidance tick first_tick on (the
        first one is asked for unconditionally: the loop has judged the route incomplete at that time)."""
        commands = []
        n, dt = self.steps_per_guidance_tick, self.dt_s
        for j in range(first_tick, self.guidance_ticks):
            t_j = (steps0 + j * n) * dt
            if j > 0 and (t_j >= self.duration_s - 0.5 * dt or self.complete()):
                break
            commands.append(self.command_at(est, t_j))
        return IntervalPlan(commands, self.complete())
