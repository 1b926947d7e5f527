"""Route policies for `TerrainNavEnv`: the straight line to the goal, and the terrain-information planner.

    policy = PlannerPolicy(env, PlannerConfig(weight=2.0))
    obs, info = env.reset(seed=0); policy.reset()
    action = policy(obs)              # or policy.predict(obs) -> (action, None), as stable-baselines3

Both act on the observation only (the estimate's offset from the goal, the commanded track and height
above ground) plus what the aircraft carries: the goal, the navigator's MAP (`env.map_dem`, never the
world) and the aircraft's action limits. The estimated position is the goal moved back by the observed
goal offset (obs 0, 1; north/east in the estimate's level frame, taken at the goal: a few metres over tens
of km, well inside what the policies steer by).

A policy turns a desired ground track into the action: the track change, as a fraction of the turn limit
of one step (clipped to [-1, 1]), and the height-above-ground change toward its height, as a fraction of
the climb limit (the env's `action_mode="turn"`); or, with `action_mode="bearing"`, the desired track
relative to the goal's bearing and the desired height above ground, each scaled to [-1, 1] (the same action
with `action_mode="pursuit"`, where the env holds that offset from the goal's bearing through the step).
"""

from __future__ import annotations

import math

import numpy as np

from trn_env.guidance.planner import PlannedRoute, PlannerConfig, TerrainInformationPlanner
from trn_env.terrain.geodesy import latlon_to_ned_offset, ned_offset_to_latlon


def _unwrapped(env):
    return getattr(env, "unwrapped", env)


class _Policy:
    """Shared: from a desired track and height above ground to the env's action."""

    def __init__(self, env, agl_m: float | None):
        self.env = _unwrapped(env)
        if agl_m is not None and (
            not isinstance(agl_m, (int, float)) or not math.isfinite(agl_m) or agl_m <= 0
        ):
            raise ValueError(f"agl_m must be a finite number > 0 or None, got {agl_m!r}")
        self.agl_m = None if agl_m is None else float(agl_m)

    def reset(self) -> None:
        """Forget the episode (call after env.reset)."""

    def estimated_position(self, obs) -> tuple[float, float]:
        """(lat, lon) rad of the estimate: the goal moved back by the observed goal offset."""
        e = self.env
        dn, de = float(obs[0]) * 1000.0, float(obs[1]) * 1000.0
        return ned_offset_to_latlon(e.goal_lat_rad, e.goal_lon_rad, 0.0, -dn, -de)

    def action_for(self, obs, track_rad: float, agl_m: float | None) -> np.ndarray:
        e = self.env
        if getattr(e, "action_mode", "turn") in ("bearing", "pursuit"):
            bearing = math.atan2(float(obs[1]), float(obs[0]))
            d = math.atan2(math.sin(track_rad - bearing), math.cos(track_rad - bearing))
            a0 = float(np.clip(d / e.bearing_offset_max_rad, -1.0, 1.0))
            h = float(obs[7]) * 1000.0 if agl_m is None else agl_m
            a1 = float(np.clip(2.0 * (h - e.agl_min_m) / (e.agl_max_m - e.agl_min_m) - 1.0, -1.0, 1.0))
            return np.array([a0, a1], np.float32)
        lim = e.action_limits
        track_now = math.atan2(float(obs[3]), float(obs[4]))
        d = math.atan2(math.sin(track_rad - track_now), math.cos(track_rad - track_now))
        a0 = float(np.clip(d / lim[0], -1.0, 1.0))
        a1 = 0.0 if agl_m is None else float(np.clip((agl_m - float(obs[7]) * 1000.0) / lim[1], -1.0, 1.0))
        return np.array([a0, a1], np.float32)

    def __call__(self, obs) -> np.ndarray:
        raise NotImplementedError

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        """stable-baselines3's call: one observation or a batch -> (action(s), None)."""
        o = np.asarray(obs, np.float32)
        if o.ndim == 2:
            return np.stack([self(row) for row in o]), None
        return self(o), None


class StraightLinePolicy(_Policy):
    """Steer to the bearing of the goal from the estimate; hold `agl_m` (None: keep the commanded height)."""

    def __init__(self, env, agl_m: float | None = None):
        super().__init__(env, agl_m)

    def __call__(self, obs) -> np.ndarray:
        return self.action_for(obs, math.atan2(float(obs[1]), float(obs[0])), self.agl_m)


class PlannerPolicy(_Policy):
    """Fly the terrain-information planner's route, replanned from the estimate every `replan_every` steps
    (1: each decision step). The desired track points at the route `lookahead_m` ahead (along the route)
    of the estimate; the height above ground is the planner's `agl_m`. Falls back to the straight line
    when no route is found from where the estimate is (e.g. near the map's edge)."""

    def __init__(
        self,
        env,
        config: PlannerConfig | None = None,
        replan_every: int = 1,
        lookahead_m: float = 2500.0,
        planner: TerrainInformationPlanner | None = None,
    ):
        e = _unwrapped(env)
        self.config = config if config is not None else PlannerConfig(tas_mps=e.tas_mps)
        super().__init__(env, self.config.agl_m)
        if isinstance(replan_every, bool) or not isinstance(replan_every, int) or replan_every < 1:
            raise ValueError(f"replan_every must be an integer >= 1, got {replan_every!r}")
        if not isinstance(lookahead_m, (int, float)) or not math.isfinite(lookahead_m) or lookahead_m <= 0:
            raise ValueError(f"lookahead_m must be a finite number > 0, got {lookahead_m!r}")
        self.replan_every = replan_every
        self.lookahead_m = float(lookahead_m)
        self.planner = planner if planner is not None else TerrainInformationPlanner(e.map_dem, self.config)
        self.route: PlannedRoute | None = None
        self.n_plans = 0
        self._steps = 0
        self._goal = None

    def reset(self) -> None:
        self.route = None
        self._steps = 0
        self._goal = None

    def _replan(self, lat: float, lon: float) -> None:
        e = self.env
        try:
            self.route = self.planner.plan(lat, lon, e.goal_lat_rad, e.goal_lon_rad)
            self.n_plans += 1
        except ValueError:  # off the planning grid / no route from here: fly straight
            self.route = None

    def _carrot(self, lat: float, lon: float) -> tuple[float, float] | None:
        """(north, east) m from the estimate of the route point lookahead_m along the route past the point
        nearest the estimate."""
        w = np.radians(np.array([(a, b) for a, b, _ in self.route.waypoints_deg]))
        ne = np.array([latlon_to_ned_offset(lat, lon, 0.0, a, b) for a, b in w])
        best = (np.inf, 0, 0.0)
        for k in range(len(ne) - 1):
            p, q = ne[k], ne[k + 1]
            d = q - p
            L2 = float(d @ d)
            t = 0.0 if L2 == 0 else float(np.clip(-(p @ d) / L2, 0.0, 1.0))
            dist = float(np.hypot(*(p + t * d)))
            if dist < best[0]:
                best = (dist, k, t)
        _, k, t = best
        remaining = self.lookahead_m
        pos = ne[k] + t * (ne[k + 1] - ne[k])
        while True:
            seg = ne[k + 1] - pos
            L = float(np.hypot(*seg))
            if L >= remaining or k + 1 == len(ne) - 1:
                return tuple(pos + seg * min(1.0, remaining / L)) if L > 0 else tuple(pos)
            remaining -= L
            pos = ne[k + 1]
            k += 1

    def __call__(self, obs) -> np.ndarray:
        e = self.env
        lat, lon = self.estimated_position(obs)
        goal = (e.goal_lat_rad, e.goal_lon_rad)
        if self._goal != goal:
            self.reset()
            self._goal = goal
        if self.route is None or self._steps % self.replan_every == 0:
            self._replan(lat, lon)
        self._steps += 1
        if self.route is None:
            return self.action_for(obs, math.atan2(float(obs[1]), float(obs[0])), self.agl_m)
        cn, ce = self._carrot(lat, lon)
        if math.hypot(cn, ce) < 1.0:
            cn, ce = float(obs[0]) * 1000.0, float(obs[1]) * 1000.0
        return self.action_for(obs, math.atan2(ce, cn), self.agl_m)


__all__ = ["PlannerPolicy", "StraightLinePolicy"]
