"""TerrainNavFast-v0: TerrainNav-v0's task for N point-mass aircraft per process, a gymnasium VectorEnv.

    envs = gymnasium.make_vec("trn_env/TerrainNavFast-v0", num_envs=256,
                              vectorization_mode="vector_entry_point", scenario="basin_route",
                              action_mode="pursuit", decision_interval_s=30.0)

Same observation space, action space (turn, bearing, pursuit), reward terms and episode ends as
TerrainNavEnv (trn_env.env.terrain_nav: its docstring holds the tables; both import trn_env.env.task), so a
policy trained on one runs unchanged on the other. What differs is the simulation under the task:
trn_env.env.fast.dynamics (3-DOF aircraft with the JSBSim King Air's measured envelope, its autopilot's laws,
wind layers and turbulence) and trn_env.env.fast.navigator (INS error process + batch TERCOM + Kalman filter,
the "ins_tercom" family, or "ins" alone), over the same terrain: the scenario's world DEM (truth: sensing
and collision) and its map DEM (navigator, guidance, observation), built exactly as TerrainNav-v0 builds
them. Every decision is one numba call over all aircraft (`dynamics.fly_decision`) and one for the
observations (`observation.observe`); resets are one call over the sub-envs being reset.

Threads: the two per-decision calls spread the aircraft over numba's threads (`numba.set_num_threads`;
default: one per core) in chunks of dynamics.CHUNK_AIRCRAFT taken in turn. Importing the package sets
OMP_WAIT_POLICY=PASSIVE unless the environment sets it: with OpenMP's default spinning, a thread waiting at
the end of a call burns its core, which on a machine shared with other processes costs more than the second
thread gains.

Vector API: `reset(seed=None | int | list, options=None)` seeds sub-env i with seed + i (or seeds[i]);
options `goal_deg` / `start_deg` ((lat, lon), or an (N, 2) array, NaN rows drawn as usual) and
`reset_mask` (reset only these sub-envs). `step(actions)` with actions of shape (N, 2). Autoreset per
sub-env, `AutoresetMode.NEXT_STEP`: the step after a sub-env's episode ended resets it (its action is
ignored, reward 0, returns the reset observation). `info` holds arrays (one element per sub-env) of the
keys TerrainNav-v0 reports (`t_s`, `true_error_ned_m`, `true_horizontal_error_m`,
`true_distance_to_goal_m`, `estimated_distance_to_goal_m`, `sigma_ned_m`, `nav_ok`, `nav_status`,
`goal_deg`, `start_deg`, `distance_flown_m`, `termination`, `reward_terms`), `true_miss_m` with its mask
`_true_miss_m`, and episode statistics `episode` = {"r": return, "l": decisions, "t": wall s} with
`_episode` where an episode ended (gymnasium's RecordEpisodeStatistics convention; `episode_statistics=False`
leaves them out, for code that wraps the env in that wrapper, which refuses an existing `episode` key).

Randomness: each sub-env owns a SplitMix64 stream (trn_env.env.fast.rng); a sub-env's seed fixes its
episodes bit for bit whatever N and whatever the other sub-envs do. The terrain (and the map's error draw)
comes from the scenario seed, as in TerrainNav-v0.

Arguments: TerrainNavEnv's (scenario, decision_interval_s, max_episode_s, navigator, goal_deg,
goal_radius_m, reward_mode, the reward weights, agl_min_m, agl_max_m, climb_rate_max_mps,
turn_rate_max_dps, info_offset_m, info_sigma_m, info_window_m, goal_region_deg, start_region_deg,
held_out_goals_deg, held_out_radius_m, min_goal_distance_m, shaping_gamma, action_mode,
bearing_offset_max_deg, sigma_shaping_weight, informative_crlb_m, action_change_weight: the previous
track action is kept per sub-env and set to 0 when the sub-env resets, autoreset included;
time_limit_failure: the time limit terminates, as a failure) plus num_envs and
episode_statistics;
render_mode must be None.
`navigator` must be one the fast tier models ("ins", "ins_tercom"; ValueError listing them otherwise).
"""

from __future__ import annotations

import math
import os
import time

import gymnasium as gym
import numba
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

import trn_env.scenario.build as components
from trn_env.env import task
from trn_env.env.env_settings import _check_number, check_point, check_region
from trn_env.env.fast import dynamics as dyn
from trn_env.env.fast import navigator as nv
from trn_env.env.fast import observation as ob
from trn_env.env.fast import reset as rs
from trn_env.env.fast import rng as frng
from trn_env.env.fast import state as S
from trn_env.env.fast.kernel_params import (  # noqa: F401 - re-exported
    BARO_SIGMA_M,
    DT_S,
    TURBULENCE_LENGTH_M,
    TURBULENCE_SIGMA_MPS,
    build_kernel_params,
)
from trn_env.scenario.loading import Scenario, load_scenario
from trn_env.sim.closed_loop import spawn_rngs

BYTES_PER_ENV_BASE = 8 * (S.N_STATE + 40 + 8)


class TerrainNavFastVectorEnv(gym.vector.VectorEnv):
    """N point-mass aircraft flying TerrainNav-v0's task (see the module docstring)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP, "render_fps": 1 / 30.0}

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | Scenario = "default",
        render_mode: str | None = None,
        decision_interval_s: float = 5.0,
        max_episode_s: float = 300.0,
        navigator: str | None = None,
        goal_deg=None,
        goal_radius_m: float = 1000.0,
        reward_mode: str = "arrival",
        error_weight: float = 1.0,
        goal_bonus: float = 10.0,
        collision_penalty: float = 100.0,
        failure_penalty: float = 100.0,
        miss_weight: float = 20.0,
        time_cost_per_s: float = 0.01,
        progress_weight: float = 1.0,
        agl_min_m: float = 300.0,
        agl_max_m: float = 3000.0,
        climb_rate_max_mps: float = 5.0,
        turn_rate_max_dps: float = 3.0,
        info_offset_m: float = 3000.0,
        info_sigma_m: float = 5.0,
        info_window_m: float = 2000.0,
        goal_region_deg=None,
        start_region_deg=None,
        held_out_goals_deg=None,
        held_out_radius_m: float = 2000.0,
        min_goal_distance_m: float = 5000.0,
        shaping_gamma: float = 1.0,
        action_mode: str = "turn",
        bearing_offset_max_deg: float = 90.0,
        sigma_shaping_weight: float = 0.0,
        informative_crlb_m: float = 5.0,
        episode_statistics: bool = True,
        action_change_weight: float = 0.0,
        time_limit_failure: bool = False,
    ):
        n = _check_num_envs(num_envs, decision_interval_s)
        if not isinstance(episode_statistics, bool):
            raise ValueError(f"episode_statistics must be a bool, got {episode_statistics!r}")
        self.episode_statistics = episode_statistics
        _check_memory(n, 42, 21)  # before any per-aircraft array (the default 40 s TERCOM profile)
        if render_mode is not None:
            raise ValueError(
                f"render_mode must be None (TerrainNavFast-v0 does not render), got {render_mode!r}"
            )
        if reward_mode not in task.REWARD_MODES:
            raise ValueError(f"reward_mode must be one of {task.REWARD_MODES}, got {reward_mode!r}")
        if action_mode not in task.ACTION_MODES:
            raise ValueError(f"action_mode must be one of {task.ACTION_MODES}, got {action_mode!r}")
        if navigator is not None and navigator not in nv.MODELLED_NAVIGATORS:
            raise ValueError(
                f"navigator {navigator!r} is not modelled by the fast tier; it models: "
                f"{', '.join(nv.MODELLED_NAVIGATORS)} (TerrainNav-v0 runs any registered navigator)"
            )
        for name, v in (
            ("decision_interval_s", decision_interval_s),
            ("max_episode_s", max_episode_s),
            ("goal_radius_m", goal_radius_m),
            ("climb_rate_max_mps", climb_rate_max_mps),
            ("turn_rate_max_dps", turn_rate_max_dps),
            ("info_offset_m", info_offset_m),
            ("info_sigma_m", info_sigma_m),
            ("info_window_m", info_window_m),
            ("agl_min_m", agl_min_m),
            ("agl_max_m", agl_max_m),
            ("held_out_radius_m", held_out_radius_m),
            ("min_goal_distance_m", min_goal_distance_m),
            ("informative_crlb_m", informative_crlb_m),
            ("bearing_offset_max_deg", bearing_offset_max_deg),
            ("shaping_gamma", shaping_gamma),
        ):
            _check_number(name, v, positive=True)
        for name, v in (
            ("error_weight", error_weight),
            ("goal_bonus", goal_bonus),
            ("collision_penalty", collision_penalty),
            ("failure_penalty", failure_penalty),
            ("miss_weight", miss_weight),
            ("time_cost_per_s", time_cost_per_s),
            ("progress_weight", progress_weight),
            ("sigma_shaping_weight", sigma_shaping_weight),
            ("action_change_weight", action_change_weight),
        ):
            _check_number(name, v, positive=False)
        if bearing_offset_max_deg > 180.0:
            raise ValueError(f"bearing_offset_max_deg must be in (0, 180], got {bearing_offset_max_deg!r}")
        if shaping_gamma > 1.0:
            raise ValueError(f"shaping_gamma must be in (0, 1], got {shaping_gamma!r}")
        if not 0 < agl_min_m < agl_max_m:
            raise ValueError(f"need 0 < agl_min_m < agl_max_m, got {agl_min_m}, {agl_max_m}")
        if not isinstance(scenario, (str, Scenario)):
            raise ValueError(
                f"scenario must be a built-in name, a TOML path or a Scenario, got {type(scenario).__name__}"
            )
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, navigator=navigator)
        if isinstance(scenario, Scenario) and navigator is not None:
            sc = sc.with_overrides(navigator=navigator)
        nav_name = sc.navigator_name
        if nav_name not in nv.MODELLED_NAVIGATORS:
            raise ValueError(
                f"navigator {nav_name!r} (scenario {sc.name!r}) is not modelled by the fast tier; it "
                f"models: {', '.join(nv.MODELLED_NAVIGATORS)}; pass navigator="
            )
        self.scenario = sc
        self.num_envs = n
        self.render_mode = None
        self.navigator = nav_name
        self.decision_interval_s = float(decision_interval_s)
        self.n_sub = max(1, int(round(self.decision_interval_s / DT_S)))
        self.decision_interval_s = self.n_sub * DT_S
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / self.decision_interval_s}
        self.max_episode_s = float(max_episode_s)
        self.reward_mode, self.action_mode = reward_mode, action_mode
        self._weights = dict(
            progress_weight=float(progress_weight),
            shaping_gamma=float(shaping_gamma),
            time_cost_per_s=float(time_cost_per_s),
            collision_penalty=float(collision_penalty),
            failure_penalty=float(failure_penalty),
            goal_bonus=float(goal_bonus),
            miss_weight=float(miss_weight),
            sigma_shaping_weight=float(sigma_shaping_weight),
        )
        self.error_weight = float(error_weight)
        self.action_change_weight = float(action_change_weight)
        task.episode_end_reasons(time_limit_failure)  # ValueError unless a bool
        self.time_limit_failure = time_limit_failure
        self.goal_radius_m = float(goal_radius_m)
        self.agl_min_m, self.agl_max_m = float(agl_min_m), float(agl_max_m)
        self.tas_mps = float(sc.route.tas_mps)
        self.bearing_offset_max_rad = math.radians(float(bearing_offset_max_deg))
        self.action_limits = task.action_limits(
            self.decision_interval_s, turn_rate_max_dps, climb_rate_max_mps
        )
        self.single_action_space = task.action_space()
        self.single_observation_space = task.observation_space()
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)

        # terrain exactly as TerrainNav-v0 builds it (world: truth; map: navigator, guidance, observations)
        self._world, self._map = components.build_terrain(sc, sc.extras, spawn_rngs(sc.seed)["map"])
        self._info_map = components.terrain_information_map(self._map, info_sigma_m, info_window_m)
        self.held_out_radius_m = float(held_out_radius_m)
        self.min_goal_distance_m = float(min_goal_distance_m)
        self.goal_region_deg = self._check_region("goal_region_deg", goal_region_deg)
        self.start_region_deg = self._check_region("start_region_deg", start_region_deg)
        if held_out_goals_deg is None and self.goal_region_deg is not None:
            la0, la1, lo0, lo1 = self.goal_region_deg
            held_out_goals_deg = [
                (la0 + fa * (la1 - la0), lo0 + fo * (lo1 - lo0))
                for fa, fo in ((0.25, 0.25), (0.25, 0.75), (0.5, 0.5), (0.75, 0.25), (0.75, 0.75))
            ]
        self.held_out_goals_deg = [
            self._check_point("held_out_goals_deg", g) for g in (held_out_goals_deg or [])
        ]
        wp_last = sc.route.waypoints[-1]
        g = goal_deg if goal_deg is not None else (wp_last.lat_deg, wp_last.lon_deg)
        self._fixed_goal_deg = self._check_point("goal_deg", g)
        init = sc.initial
        self._init_start_deg = (float(init.lat_deg), float(init.lon_deg))
        self._h_agl_init_m = float(0.0 if init.h_agl_m is None else init.h_agl_m)
        self._h_msl_init_m = float(init.h_msl_m) if init.h_agl_m is None else math.nan

        # the kernels' parameter arrays and records (kernel_params.py)
        kp = build_kernel_params(self, sc, float(info_offset_m), float(informative_crlb_m))
        self._wind, self._fp, self._nav = kp.wind, kp.fp, kp.nav
        self._init_params, self._op, self._route_offsets = kp.init_params, kp.op, kp.route_offsets

        # per-aircraft arrays
        n_prof = int(math.ceil(self._nav[nv.NP_FIX_PERIOD])) + 2
        _check_memory(n, n_prof, nv.tercom_table_rows(self._nav))
        self._X = np.zeros((n, S.N_STATE))
        self._X[:, S.END] = S.TIME_LIMIT
        self._rng = frng.seed_states(np.random.SeedSequence().generate_state(n, np.uint32))
        self._prof = np.zeros((3, n, n_prof))
        self._diff = np.zeros((n, 3, n_prof))
        self._tables = np.zeros((n, 4, nv.tercom_table_rows(self._nav), n_prof))
        self._obs = np.zeros((n, task.N_OBS), np.float32)
        self._autoreset = np.zeros(n, bool)
        self._needs_reset = True
        self._ep_return = np.zeros(n)
        self._ep_len = np.zeros(n, np.int64)
        self._ep_t0 = np.zeros(n)
        self._a0_before = np.zeros(n)  # each sub-env's previous track action (0 at its episode's start)

    # ---------------------------------------------------------------------------------------- checks
    def _check_point(self, name: str, p) -> tuple[float, float]:
        return check_point(name, p, (self._world, self._map))

    def _check_region(self, name: str, r):
        return check_region(name, r, (self._world, self._map))

    def _points_option(self, name: str, v) -> np.ndarray:
        """An option's (lat, lon) deg as an (N, 2) rad array (NaN rows: drawn)."""
        a = np.asarray(v, dtype=np.float64) if v is not None else np.full((self.num_envs, 2), np.nan)
        if a.shape == (2,):
            a = np.tile(a, (self.num_envs, 1))
        if a.shape != (self.num_envs, 2):
            raise ValueError(
                f"options[{name!r}] must be (lat_deg, lon_deg) or an array of shape "
                f"({self.num_envs}, 2), got shape {a.shape}"
            )
        for i in range(self.num_envs):
            if not np.all(np.isnan(a[i])):
                self._check_point(f"options[{name!r}][{i}]", a[i])
        return np.radians(a)

    # ---------------------------------------------------------------------------------------- state
    def _records(self):
        """The world DEM, the map DEM and the information map as kernel records (bilinear)."""
        return self._world.record(), self._map.record(), self._info_map.record()

    def _est_latlon(self):
        X = self._X
        rm, rn = _radii(X[:, S.LAT])
        return X[:, S.LAT] + X[:, S.EP_N] / (rm + X[:, S.H]), X[:, S.LON] + X[:, S.EP_E] / (
            (rn + X[:, S.H]) * np.cos(X[:, S.LAT])
        )

    def _goal_offset(self, lat, lon):
        rm, rn = _radii(lat)
        return (self._X[:, S.GOAL_LAT] - lat) * rm, (self._X[:, S.GOAL_LON] - lon) * rn * np.cos(lat)

    def _d_est(self):
        return np.hypot(*self._goal_offset(*self._est_latlon()))

    def _d_true(self):
        return np.hypot(*self._goal_offset(self._X[:, S.LAT], self._X[:, S.LON]))

    def _sigma_h(self):
        return np.sqrt(2.0 * np.maximum(self._X[:, S.P00], 0.0))

    def _observe(self, mask):
        _, map_rec, info_rec = self._records()
        with numba.parallel_chunksize(dyn.CHUNK_AIRCRAFT):
            ob.observe(
                self._X, mask, self._obs, map_rec, info_rec, self._op, self._route_offsets,
                ob.INFO_BEARINGS_RAD, (task.OBS_LOW, task.OBS_HIGH), self._wind,
            )

    def _reset_envs(self, mask, start_rad=None, goal_rad=None):
        n = self.num_envs
        start_rad = np.full((n, 2), np.nan) if start_rad is None else start_rad
        goal_rad = np.full((n, 2), np.nan) if goal_rad is None else goal_rad
        if self.start_region_deg is None:
            start_rad = np.where(np.isnan(start_rad), np.radians(self._init_start_deg), start_rad)
        if self.goal_region_deg is None:
            goal_rad = np.where(np.isnan(goal_rad), np.radians(self._fixed_goal_deg), goal_rad)
        regions = np.radians(
            np.array([self.start_region_deg or (np.nan,) * 4, self.goal_region_deg or (np.nan,) * 4], float)
        )
        held = np.radians(np.array(self.held_out_goals_deg, float).reshape(-1, 2))
        world_rec, map_rec, _ = self._records()
        status = rs.reset_aircraft(
            self._X, self._rng, mask, start_rad, goal_rad,
            (regions, held, self.held_out_radius_m, self.min_goal_distance_m),
            (self._h_agl_init_m, self._h_msl_init_m, self._init_params), world_rec, map_rec,
        )
        if np.any(status[mask] != 0):
            raise ValueError(
                "goal_region_deg: no goal found in 1000 draws at least min_goal_distance_m from the "
                "start and outside held_out_radius_m of the held-out goals"
            )
        d_est = self._d_est()
        self._X[mask, S.D_EST_START] = d_est[mask]
        self._X[mask, S.NEXT_SAMPLE_T] = 1.0
        self._ep_return[mask] = 0.0
        self._ep_len[mask] = 0
        self._ep_t0[mask] = time.perf_counter()
        self._a0_before[mask] = 0.0
        self._observe(mask)

    # ---------------------------------------------------------------------------------------- API
    def reset(self, *, seed=None, options=None):
        n = self.num_envs
        seeds = _seeds(seed, n) if seed is not None else None
        super().reset(seed=seeds[0] if seeds is not None else None)
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None, got {type(options).__name__}")
        options = dict(options or {})
        unknown = set(options) - {"goal_deg", "start_deg", "reset_mask"}
        if unknown:
            raise ValueError(
                f"reset options: unknown keys {sorted(unknown)}; known: goal_deg, start_deg, reset_mask"
            )
        mask = np.ones(n, bool)
        if "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.shape != (n,) or mask.dtype != bool:
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({n},), got {mask!r}")
        if seeds is not None:
            self._rng[mask] = frng.seed_states(seeds)[mask]
        start = self._points_option("start_deg", options.get("start_deg"))
        goal = self._points_option("goal_deg", options.get("goal_deg"))
        self._reset_envs(mask, start, goal)
        self._autoreset[mask] = False
        self._needs_reset = False
        return self._obs.copy(), self._info(None, mask)

    def step(self, actions):
        if self._needs_reset:
            raise gym.error.ResetNeeded("Cannot call step() before calling reset()")
        n = self.num_envs
        a = task.check_actions(
            actions,
            (n, 2),
            np.tile(self.single_action_space.low, (n, 1)),
            np.tile(self.single_action_space.high, (n, 1)),
        )
        X = self._X
        auto = self._autoreset.copy()
        live = ~auto
        change = task.action_change_terms(a[:, 0], self._a0_before,
                                          action_change_weight=self.action_change_weight)
        self._a0_before[live] = a[live, 0]
        self._apply_actions(a, live)
        d_est0, d_true0, sig0, t0 = self._d_est(), self._d_true(), self._sigma_h(), X[:, S.T].copy()
        X[live, S.END] = 0.0
        world_rec, map_rec, _ = self._records()
        with numba.parallel_chunksize(dyn.CHUNK_AIRCRAFT):
            dyn.fly_decision(
                X, self._rng, live, self.n_sub, (self._prof[0], self._prof[1], self._prof[2]), world_rec,
                map_rec, self._fp, self._nav, self._wind, (self._diff, self._tables),
            )
        end = np.where(live, X[:, S.END], 0.0).astype(int)
        reasons = np.array(S.END_NAMES, dtype=object)[end]
        reasons[end == 0] = None
        self._observe(live)
        if auto.any():
            self._reset_envs(auto)
        info = self._info(reasons, np.ones(n, bool))
        ended = end != 0
        err_h = info["true_horizontal_error_m"]
        if self.reward_mode == "progress":
            terms = task.progress_reward_terms(
                d_true0,
                info["true_distance_to_goal_m"],
                err_h,
                end == S.GOAL,
                end == S.COLLISION,
                error_weight=self.error_weight,
                goal_bonus=self._weights["goal_bonus"],
                collision_penalty=self._weights["collision_penalty"],
            )
        else:
            failed = (end == S.OFF_MAP) | (end == S.DIVERGED)
            if self.time_limit_failure:
                failed |= end == S.TIME_LIMIT
            terms = task.arrival_reward_terms(
                d_est0,
                info["estimated_distance_to_goal_m"],
                X[:, S.T] - t0,
                sig0,
                self._sigma_h(),
                ended,
                end == S.ARRIVED,
                end == S.COLLISION,
                failed,
                err_h,
                **self._weights,
            )
        terms.update(change)
        terms = {
            k: np.where(live, np.broadcast_to(v, (n,)), 0.0).astype(np.float64) for k, v in terms.items()
        }
        rewards = np.sum(list(terms.values()), axis=0)
        info["reward_terms"] = terms
        arrived = end == S.ARRIVED
        info["true_miss_m"] = np.where(arrived, err_h, np.nan)
        info["_true_miss_m"] = arrived
        terminated = live & np.isin(end, (S.ARRIVED, S.COLLISION, S.OFF_MAP, S.GOAL, S.DIVERGED))
        truncated = live & (end == S.TIME_LIMIT)
        if self.time_limit_failure:
            terminated, truncated = terminated | truncated, np.zeros(n, bool)
        self._ep_return[live] += rewards[live]
        self._ep_len[live] += 1
        done = terminated | truncated
        if done.any() and self.episode_statistics:
            now = time.perf_counter()
            info["episode"] = {
                "r": np.where(done, self._ep_return, 0.0),
                "l": np.where(done, self._ep_len, 0),
                "t": np.where(done, now - self._ep_t0, 0.0),
            }
            info["_episode"] = done
        self._autoreset = done
        return self._obs.copy(), rewards, terminated, truncated, info

    def _apply_actions(self, a, live):
        X = self._X
        dpsi, dagl = self.action_limits
        trk = X[:, S.TRK_CMD].copy()
        agl = X[:, S.AGL_CMD].copy()
        agl_want = self.agl_min_m + 0.5 * (a[:, 1] + 1.0) * (self.agl_max_m - self.agl_min_m)
        if self.action_mode == "turn":
            trk = trk + a[:, 0] * dpsi
            agl = agl + a[:, 1] * dagl
        elif self.action_mode == "pursuit":
            X[live, S.OFFSET_FRAC] = a[live, 0]
            agl = agl + np.clip(agl_want - agl, -dagl, dagl)
        else:
            dn, de = self._goal_offset(*self._est_latlon())
            omega = self.action_limits[0] / self.decision_interval_s
            lim = task.bearing_offset_limit_rad(
                np.hypot(dn, de), omega, self.tas_mps, self.bearing_offset_max_rad
            )
            want = np.arctan2(de, dn) + a[:, 0] * lim
            dd = np.arctan2(np.sin(want - trk), np.cos(want - trk))
            trk = trk + np.clip(dd, -dpsi, dpsi)
            agl = agl + np.clip(agl_want - agl, -dagl, dagl)
        X[live, S.TRK_CMD] = np.arctan2(np.sin(trk), np.cos(trk))[live]
        X[live, S.AGL_CMD] = np.clip(agl, self.agl_min_m, self.agl_max_m)[live]

    def _info(self, reasons, mask) -> dict:
        X = self._X
        lat_e, lon_e = self._est_latlon()
        rm, rn = _radii(X[:, S.LAT])
        err = np.stack([X[:, S.EP_N], X[:, S.EP_E], -X[:, S.BARO]], axis=1)
        sig_h = np.sqrt(np.maximum(X[:, S.P00], 0.0))
        ok = X[:, S.DEGRADED] < 0.5
        return {
            "t_s": X[:, S.T].copy(),
            "true_error_ned_m": err,
            "true_horizontal_error_m": np.hypot(X[:, S.EP_N], X[:, S.EP_E]),
            "true_distance_to_goal_m": self._d_true(),
            "estimated_distance_to_goal_m": self._d_est(),
            "sigma_ned_m": np.stack([sig_h, sig_h, np.full(self.num_envs, BARO_SIGMA_M)], axis=1),
            "nav_ok": ok,
            "nav_status": np.where(ok, "ok", "degraded"),
            "goal_deg": np.degrees(np.stack([X[:, S.GOAL_LAT], X[:, S.GOAL_LON]], axis=1)),
            "start_deg": np.degrees(np.stack([X[:, S.START_LAT], X[:, S.START_LON]], axis=1)),
            "distance_flown_m": X[:, S.DIST_FLOWN].copy(),
            "termination": reasons if reasons is not None else np.full(self.num_envs, None, dtype=object),
        }

    def close_extras(self, **kwargs):
        self._needs_reset = True


def single_env_refused(**kwargs):
    """The entry point gymnasium.make (and make_vec's sync/async modes) reach for TerrainNavFast-v0: the tier
    is a batch of aircraft in one process, with no single-env form; the message says how to make it."""
    raise TypeError(
        "trn_env/TerrainNavFast-v0 is a vector env (N aircraft in one process), not a single env: "
        "gymnasium.make_vec('trn_env/TerrainNavFast-v0', num_envs=N, vectorization_mode='vector_entry_point')"
        "; for one aircraft per env, trn_env/TerrainNav-v0 is the full-fidelity loop"
    )


def _radii(lat):
    s = np.sin(lat)
    w = 1.0 - dyn.WGS84_E2 * s * s
    return dyn.WGS84_A_M * (1.0 - dyn.WGS84_E2) / (w * np.sqrt(w)), dyn.WGS84_A_M / np.sqrt(w)


def _seeds(seed, n: int) -> list[int]:
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(n)]
    try:
        seeds = [int(s) for s in seed]
    except (TypeError, ValueError):
        raise ValueError(f"seed must be None, an int or a list of {n} ints, got {seed!r}") from None
    if len(seeds) != n:
        raise ValueError(f"seed: a list of {n} ints (one per sub-env), got {len(seeds)}")
    return seeds


def _check_num_envs(num_envs, decision_interval_s) -> int:
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
        raise ValueError(f"num_envs must be an int >= 1, got {num_envs!r}")
    if num_envs < 1:
        raise ValueError(f"num_envs must be >= 1, got {num_envs}")
    return int(num_envs)


def _available_memory_bytes() -> int:
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 1 << 62


def _check_memory(n: int, n_prof: int, table_rows: int) -> None:
    """ValueError when the per-aircraft arrays of n sub-envs would not fit in half the available memory."""
    need = n * (BYTES_PER_ENV_BASE + 8 * (6 + 4 * table_rows) * n_prof + 4 * task.N_OBS)
    avail = _available_memory_bytes()
    if need > avail // 2:
        raise ValueError(
            f"num_envs={n} needs {need / 1e9:.3g} GB for its per-aircraft arrays, more than half "
            f"of the {avail / 1e9:.3g} GB available; use fewer sub-envs"
        )


__all__ = ["TerrainNavFastVectorEnv"]
