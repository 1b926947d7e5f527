"""Gymnasium environment: route decisions for terrain-referenced navigation, in closed loop."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

import trn_env.scenario.build as components
from terrain.geodesy import C_en, latlon_to_ned_offset, lla_to_ecef
from trn_env.scenario.loading import Scenario, load_scenario
from trn_env.sim.closed_loop import ClosedLoop, spawn_rngs

G0_MPS2 = 9.80665
N_TERRAIN_FEATURES = 6


class TerrainNavEnv(gym.Env):
    """Fly to a goal over real terrain while a terrain-referenced navigator keeps the position estimate.

    ## Description
    The aircraft (JSBSim King Air) starts at the scenario's initial state with GNSS lost (per the
    scenario) and must reach a goal; guidance flies the agent's heading and height-above-ground
    commands on the navigator's *estimate*, so a route over featureless terrain lets the navigation
    error grow while a route over rough terrain keeps it small. Every `step` flies `decision_interval_s`
    seconds of the full closed loop (flight 100 Hz, sensors, navigator updates at the scenario's
    `navigator.rate_hz`, 1 Hz by default, guidance targets at 10 Hz), rounded to whole navigator updates.

    ## Action Space
    `Box(-1, 1, shape=(2,), dtype=float32)`, each a fraction of what the aircraft can do in one step:

    | index | action | scaled to |
    |-------|--------|-----------|
    | 0 | change of the commanded ground track (positive = clockwise / right) | `dpsi_max` rad |
    | 1 | change of the commanded height above ground (positive = up) | `dagl_max` m |

    The limits are the aircraft's: `dpsi_max = min(turn_rate_max_dps * decision_interval_s, 60 deg)` (the
    rate-one turn, 3 deg/s, by default) and `dagl_max = climb_rate_max_mps * decision_interval_s`
    (`env.action_limits` holds both). The commanded height above ground is kept in
    `[agl_min_m, agl_max_m]`. An action outside the space (or not finite) raises `ValueError` naming the
    bound it breaks.

    ## Observation Space
    `Box(float32)` of shape `(19,)`, everything from what the aircraft knows (the navigator's estimate
    and its map), never truth:

    | index | observation | unit |
    |-------|-------------|------|
    | 0, 1 | goal minus estimated position, north and east | km |
    | 2 | estimated distance to the goal | km |
    | 3, 4 | sin and cos of the commanded ground track | - |
    | 5 | estimated ground speed / 100 | (100 m/s) |
    | 6 | estimated height above the map terrain | km |
    | 7 | commanded height above ground | km |
    | 8, 9, 10 | log10(1 + sigma) of the estimate, north, east, down (sigma in m) | - |
    | 11-16 | terrain information of the map around the estimate (below) | - |
    | 17 | fraction of the episode time used | - |
    | 18 | navigator health ok (1) or not (0) | - |

    Terrain information (11-16) is log10(1 + CRLB) of the horizontal position a TRN could reach from the
    navigator's MAP (`terrain.metrics.terrain_information`: Fisher information of altimeter heights with
    noise `info_sigma_m` over an `info_window_m` square; CRLB in m, 1e4 m where the terrain is flat or off
    the map), sampled at the estimate and `info_offset_m` away ahead, ahead-left, ahead-right, left and
    right of the commanded track: low values mark where a route would let the TRN fix well.

    ## Rewards
    Each step: `progress_km - error_weight * true_horizontal_error_km`, where progress is the decrease
    of the TRUE distance to the goal; `+ goal_bonus` on reaching the goal, `- collision_penalty` on
    terrain collision.

    ## Starting State
    The scenario's initial state; the navigator starts from the truth plus the scenario's initial errors
    (seed 000 Table 2), drawn from the episode seed. The commanded track starts at the bearing to the goal
    and the commanded height above ground at the scenario's.

    ## Episode End
    Terminated: the true position within `goal_radius_m` of the goal, terrain collision (true height above
    the true terrain < 0), off the map, the navigator diverged, or an engine stopped (fuel exhausted or
    engine failure; the scenario's `aircraft.constant_fuel = true` keeps the tanks full for long episodes).
    Truncated: `max_episode_s` of flight.
    `step` after the end without `reset` raises `gymnasium.error.ResetNeeded`.

    ## Info
    `t_s`, `true_error_ned_m` (estimate minus truth), `true_horizontal_error_m`, `true_distance_to_goal_m`,
    `sigma_ned_m`, `nav_ok`, `nav_status`, `termination` (None while running; else `goal`,
    `terrain_collision`, `off_map`, `diverged`, `fuel_exhausted`, `engine_failure` or `time_limit`).

    ## Arguments
    `gymnasium.make("trn_env/TerrainNav-v0", scenario="default", render_mode=None, decision_interval_s=5.0,
    max_episode_s=300.0, navigator=None, goal_deg=None, goal_radius_m=1000.0, error_weight=1.0,
    goal_bonus=10.0, collision_penalty=100.0, agl_min_m=300.0, agl_max_m=3000.0, climb_rate_max_mps=5.0,
    turn_rate_max_dps=3.0, info_offset_m=3000.0, info_sigma_m=5.0, info_window_m=2000.0,
    log_sensors=False)`.
    `scenario` is a built-in name, a TOML path or a `Scenario`; `goal_deg=(lat, lon)` defaults to the
    route's last waypoint. The terrain (and the map's error draw) is built once per env from the
    scenario seed; each episode's flight, sensor and navigator randomness comes from the reset seed.
    `render_mode="rgb_array"` returns the map with the true (black) and estimated (red) tracks.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, scenario: str | Scenario = "default", render_mode: str | None = None,
                 decision_interval_s: float = 5.0, max_episode_s: float = 300.0, navigator: str | None = None,
                 goal_deg: tuple[float, float] | None = None, goal_radius_m: float = 1000.0,
                 error_weight: float = 1.0, goal_bonus: float = 10.0, collision_penalty: float = 100.0,
                 agl_min_m: float = 300.0, agl_max_m: float = 3000.0, climb_rate_max_mps: float = 5.0,
                 turn_rate_max_dps: float = 3.0, info_offset_m: float = 3000.0, info_sigma_m: float = 5.0,
                 info_window_m: float = 2000.0, log_sensors: bool = False):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        for name, v in (("decision_interval_s", decision_interval_s), ("max_episode_s", max_episode_s),
                        ("goal_radius_m", goal_radius_m), ("climb_rate_max_mps", climb_rate_max_mps),
                        ("turn_rate_max_dps", turn_rate_max_dps)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if not 0 < agl_min_m < agl_max_m:
            raise ValueError(f"need 0 < agl_min_m < agl_max_m, got {agl_min_m}, {agl_max_m}")
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, navigator=navigator)
        if isinstance(scenario, Scenario) and navigator is not None:
            sc = sc.with_overrides(navigator=navigator)
        sc = sc.with_overrides(duration_s=float(max_episode_s) + 1.0)
        self.scenario = sc
        d = sc.data
        rate_hz = float(d["navigator"]["rate_hz"])      # one loop tick = one navigator update
        self.ticks_per_decision = max(1, int(round(decision_interval_s * rate_hz)))
        self.decision_interval_s = self.ticks_per_decision / rate_hz
        self.max_episode_s = float(max_episode_s)
        self.render_mode = render_mode
        self.error_weight = float(error_weight)
        self.goal_bonus = float(goal_bonus)
        self.collision_penalty = float(collision_penalty)
        self.goal_radius_m = float(goal_radius_m)
        self.agl_min_m, self.agl_max_m = float(agl_min_m), float(agl_max_m)
        self.tas_mps = float(d["route"]["tas_mps"])
        self.info_offset_m = float(info_offset_m)
        self.log_sensors = bool(log_sensors)
        wp_last = d["route"]["waypoints"][-1]
        g = goal_deg if goal_deg is not None else (wp_last["lat_deg"], wp_last["lon_deg"])
        self.goal_lat_rad, self.goal_lon_rad = math.radians(g[0]), math.radians(g[1])

        dpsi = min(math.radians(turn_rate_max_dps) * self.decision_interval_s, math.pi / 3)
        dagl = climb_rate_max_mps * self.decision_interval_s
        self.action_limits = np.array([dpsi, dagl])          # rad, m per decision step
        self.action_space = spaces.Box(low=-1.0, high=1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(low=-1e4, high=1e4, shape=(19,), dtype=np.float32)

        self._dems = components.build_terrain(d, sc.extras, spawn_rngs(sc.seed)["map"])
        self._info_map = components.terrain_information_map(self._dems[1], info_sigma_m, info_window_m)
        if not self._dems[0].contains(self.goal_lat_rad, self.goal_lon_rad):
            raise ValueError(f"goal_deg {g} is outside the terrain")
        self._loop: ClosedLoop | None = None
        self._needs_reset = True
        self._track_cmd_rad = 0.0
        self._agl_cmd_m = 0.0
        self._true_track: list[tuple[float, float]] = []
        self._est_track: list[tuple[float, float]] = []
        self._background = None

    # ---------------------------------------------------------------------------------------- helpers
    def _commander(self, est, t_s):
        return components.track_agl_targets(self._track_cmd_rad, self._agl_cmd_m, self.tas_mps)

    def _offset_to_goal(self, lat, lon, h=0.0) -> tuple[float, float]:
        """North/east (m) of the goal in the local level frame at (lat, lon, h), exact through ECEF (the goal
        is tens of km away: no small-offset approximation), the goal taken at the same height."""
        r0 = np.array(lla_to_ecef(lat, lon, h))
        r1 = np.array(lla_to_ecef(self.goal_lat_rad, self.goal_lon_rad, h))
        d_ned = C_en(lat, lon).T @ (r1 - r0)
        return float(d_ned[0]), float(d_ned[1])

    def _obs(self) -> np.ndarray:
        loop = self._loop
        est = loop.estimate
        dn, de = self._offset_to_goal(est.lat_rad, est.lon_rad, est.h_m)
        sig = est.sigma_ned_m
        h_ground = components.map_height(self._dems[1], est.lat_rad, est.lon_rad)
        agl_est = est.h_m - h_ground if math.isfinite(h_ground) else 0.0
        info = components.sample_information(self._info_map, self._dems[1], est.lat_rad, est.lon_rad,
                                             self._track_cmd_rad, self.info_offset_m)
        obs = np.array([
            dn / 1000.0, de / 1000.0, math.hypot(dn, de) / 1000.0,
            math.sin(self._track_cmd_rad), math.cos(self._track_cmd_rad),
            float(np.hypot(est.v_ned_mps[0], est.v_ned_mps[1])) / 100.0,
            agl_est / 1000.0, self._agl_cmd_m / 1000.0,
            *np.log10(1.0 + sig),
            *np.log10(1.0 + np.clip(info, 0.0, None)),
            loop.t_s / self.max_episode_s,
            1.0 if est.health.ok else 0.0,
        ], dtype=np.float64)
        obs = np.nan_to_num(obs, nan=0.0, posinf=1e4, neginf=-1e4)
        return np.clip(obs, -1e4, 1e4).astype(np.float32)

    def _truth_now(self):
        tr = self._loop.last_truth
        return float(tr.lat_rad[-1]), float(tr.lon_rad[-1]), float(tr.h_msl_m[-1])

    def _info(self, termination: str | None) -> dict[str, Any]:
        est = self._loop.estimate
        lat, lon, h = self._truth_now()
        dn, de = latlon_to_ned_offset(lat, lon, h, est.lat_rad, est.lon_rad)
        err = np.array([dn, de, -(est.h_m - h)])
        gn, ge = self._offset_to_goal(lat, lon, h)
        return {
            "t_s": float(self._loop.t_s),
            "true_error_ned_m": err,
            "true_horizontal_error_m": float(math.hypot(dn, de)),
            "true_distance_to_goal_m": float(math.hypot(gn, ge)),
            "sigma_ned_m": est.sigma_ned_m.copy(),
            "nav_ok": bool(est.health.ok),
            "nav_status": str(est.health.status),
            "termination": termination,
        }

    # ------------------------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        ep_seed = int(self.np_random.integers(0, 2**31 - 1))
        sc = self.scenario
        sc = Scenario(name=sc.name, source=sc.source, data=sc.data, description=sc.description, seed=ep_seed,
                      duration_s=sc.duration_s, extras=sc.extras)
        d = sc.data
        init = d["initial"]
        lat0, lon0 = math.radians(init["lat_deg"]), math.radians(init["lon_deg"])
        gn, ge = self._offset_to_goal(lat0, lon0)
        self._track_cmd_rad = math.atan2(ge, gn)
        if "h_agl_m" in init:
            self._agl_cmd_m = float(init["h_agl_m"])
        else:
            self._agl_cmd_m = float(init["h_msl_m"]) - components.map_height(self._dems[1], lat0, lon0)
        self._agl_cmd_m = float(np.clip(self._agl_cmd_m, self.agl_min_m, self.agl_max_m))
        self._loop = ClosedLoop(sc, commander=self._commander, dems=self._dems, log_sensors=self.log_sensors)
        self._needs_reset = False
        lat, lon, _ = self._truth_now()
        self._true_track = [(lat, lon)]
        self._est_track = [(self._loop.estimate.lat_rad, self._loop.estimate.lon_rad)]
        return self._obs(), self._info(None)

    def _check_action(self, action) -> np.ndarray:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape} (track change, AGL change), "
                             f"got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a.tolist()}")
        lo = self.action_space.low.astype(np.float64)
        hi = self.action_space.high.astype(np.float64)
        tol = 1e-6 * np.maximum(1.0, np.abs(hi))
        names = ("track change (fraction of the turn limit)", "AGL change (fraction of the climb limit)")
        for i in range(2):
            if a[i] < lo[i] - tol[i] or a[i] > hi[i] + tol[i]:
                raise ValueError(f"action[{i}] {names[i]} = {a[i]:.6g} is outside the action space "
                                 f"[{lo[i]:.6g}, {hi[i]:.6g}]")
        return np.clip(a, lo, hi) * self.action_limits

    def step(self, action):
        if self._loop is None or self._needs_reset:
            raise ResetNeeded("Cannot call env.step() before calling env.reset() (the episode has ended or "
                              "never started)")
        a = self._check_action(action)
        track = self._track_cmd_rad + a[0]
        self._track_cmd_rad = math.atan2(math.sin(track), math.cos(track))
        self._agl_cmd_m = float(np.clip(self._agl_cmd_m + a[1], self.agl_min_m, self.agl_max_m))
        lat, lon, h = self._truth_now()
        d_before = math.hypot(*self._offset_to_goal(lat, lon, h))
        self._loop.command_now()                         # new targets take effect now
        reason = None
        for _ in range(self.ticks_per_decision):
            reason = self._loop.tick()
            lat, lon, h = self._truth_now()
            if reason is None and math.hypot(*self._offset_to_goal(lat, lon, h)) <= self.goal_radius_m:
                reason = "goal"
            if reason is None and self._loop.t_s >= self.max_episode_s - 1e-6:
                reason = "time_limit"
            if reason is not None:
                break
        if self._loop.termination is None and self._loop.sync() is not None:
            reason = self._loop.termination           # the estimate at the decision time diverged
        self._true_track.append((lat, lon))
        self._est_track.append((self._loop.estimate.lat_rad, self._loop.estimate.lon_rad))
        info = self._info(reason)
        d_after = info["true_distance_to_goal_m"]
        reward = (d_before - d_after) / 1000.0 - self.error_weight * info["true_horizontal_error_m"] / 1000.0
        if reason == "goal":
            reward += self.goal_bonus
        if reason == "terrain_collision":
            reward -= self.collision_penalty
        terminated = reason in ("goal", "terrain_collision", "off_map", "diverged", "fuel_exhausted",
                                "engine_failure")
        truncated = reason == "time_limit"
        if terminated or truncated:
            self._needs_reset = True
        return self._obs(), float(reward), bool(terminated), bool(truncated), info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        import trn_env.output.plots as plots
        return plots.render_tracks_rgb(self._dems[0], self._true_track, self._est_track,
                                       (self.goal_lat_rad, self.goal_lon_rad), cache=self)

    def close(self):
        self._loop = None
