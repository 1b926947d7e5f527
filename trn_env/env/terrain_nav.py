"""Gymnasium environment: route decisions for terrain-referenced navigation, in closed loop.

The module is longer than the style's ~600 lines because about 250 of them are the env's documentation (the
class docstring: gymnasium's Description / spaces / rewards / arguments tables, which `help(env)` and the
docs' reference page show); the code is one concept, the env's episode and step. Its parts that are not
(the scenario from the constructor's arguments, the goal geometry) live in trn_env.env.env_settings; the
task's spaces, rewards and ends in trn_env.env.task; the route information in trn_env.env.route_info.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import EzPickle
from gymnasium.vector import AutoresetMode

import trn_env.scenario.build as components
from trn_env.env import task
from trn_env.env.env_settings import (  # noqa: F401 - _check_number: TerrainNavFast-v0's argument checks
    ALTITUDE_CMD_M,
    BANK_LIMIT_RAD,
    _check_number,
    check_point,
    check_region,
    goal_offset_ne,
    with_fields,
    with_rates,
)
from trn_env.env.route_info import route_information

# the task's constants, spaces, action check, rewards and episode ends (shared with TerrainNavFast-v0)
from trn_env.env.task import (  # noqa: F401 - re-exported under this module's names
    ACTION_MODES,
    FAILURE_REASONS,
    G0_MPS2,
    N_OBS,
    N_ROUTES,
    N_TERRAIN_FEATURES,
    OBS_HIGH,
    OBS_LOW,
    REWARD_MODES,
    ROUTE_FEATURELESS_MAX_KM,
    ROUTE_OFFSET_FRACTIONS,
    TERMINATING_REASONS,
    TRUNCATING_REASONS,
)
from trn_env.flight.core import AutopilotTargets, LateralMode, SpeedMode, VerticalMode
from trn_env.scenario.loading import Scenario, load_scenario
from trn_env.sim.closed_loop import ClosedLoop, spawn_rngs
from trn_env.terrain.geodesy import latlon_to_ned_offset

# pipelined env: within this distance (m) beyond the arrival circle (the last estimate dead-reckoned to now)
# the flight waits for each navigator update to judge arrival on it (TerrainNavEnv._arrival_needs_sync)
ARRIVAL_SYNC_MARGIN_M = 3000.0


class TerrainNavEnv(gym.Env, EzPickle):
    """Fly to a goal over real terrain while a terrain-referenced navigator keeps the position estimate.

    ## Description
    The aircraft (JSBSim King Air) starts at the scenario's initial state with GNSS lost (per the
    scenario) and must reach a goal; guidance flies the agent's track and height-above-ground commands on
    the navigator's *estimate* (the height-above-ground hold flies on the estimate and the map), so a route
    over featureless terrain lets the navigation error grow while a route over rough terrain keeps it
    small, and flying low over rough terrain helps the TRN but risks the terrain when the estimate is
    wrong. Every `step` flies `decision_interval_s` seconds of the full closed loop (flight 100 Hz,
    sensors, navigator updates at the scenario's `navigator.rate_hz`, 1 Hz by default, guidance targets
    at `guidance_rate_hz`, by default once per navigator update), rounded to whole navigator updates.
    Any registered navigator name works (`navigator=`).

    ## Action Space
    `Box(-1, 1, shape=(2,), dtype=float32)`, each a fraction of what the aircraft can do in one step:

    | index | action | scaled to |
    |-------|--------|-----------|
    | 0 | change of the commanded ground track (positive = clockwise / right) | `dpsi_max` rad |
    | 1 | change of the commanded height above ground (positive = up) | `dagl_max` m |

    That is `action_mode="turn"` (default). `action_mode="bearing"` (a coarser action, easier to learn):

    | index | action (target) | scaled to |
    |-------|-----------------|-----------|
    | 0 | desired ground track - goal's bearing from the ESTIMATE (+ = right) | `bearing_offset_max_deg` |
    | 1 | desired height above ground, `agl_min_m` (-1) .. `agl_max_m` (+1) | - |

    the commanded track and height then move toward these targets by at most `dpsi_max` and `dagl_max` in
    the step (0 flies the straight line to the goal from where the estimate is). Near the goal the offset
    is cut to what the aircraft can hold, asin(d omega / (2 v)) at estimated distance d, turn rate omega
    and airspeed v (at 3 deg/s and 85 m/s: 90 deg beyond 3.2 km, 8.9 deg at 500 m): holding it turns the
    ground track at omega (the goal's bearing turns at v sin(phi) / d and the offset shrinks as fast;
    trn_env.env.task.bearing_offset_limit_rad), so that the aircraft still captures the arrival circle
    instead of orbiting the goal.

    `action_mode="pursuit"` (the coarsest: a whole route family per action): the same two targets, but the
    offset is HELD relative to the goal's bearing from the estimate at every guidance tick (1 Hz), not
    only at the decision: the commanded track is `bearing(estimate -> goal) + a0 * limit(d)` (limit as
    above, from the estimate's distance d at that tick) all through the step, so a constant action flies a
    logarithmic spiral into the goal, d / cos(offset) long (+41 % at 45 deg), and the aircraft's autopilot
    turns to it at its bank limit; the height above ground moves toward its target by at most `dagl_max`
    per step as in "bearing". With a long `decision_interval_s` (30 s: ~8 decisions over a 20 km route) an
    episode is a few coarse choices of which way round, which makes the credit assignment easy. Action 0
    is the straight line.

    The limits are the aircraft's: `dpsi_max = min(turn_rate_max_dps * decision_interval_s, 60 deg)` (the
    rate-one turn, 3 deg/s, by default) and `dagl_max = climb_rate_max_mps * decision_interval_s`
    (`env.action_limits` holds both). The commanded height above ground is kept in
    `[agl_min_m, agl_max_m]`. An action of the wrong shape, not finite, or outside the space raises
    `ValueError` naming what it breaks.

    ## Observation Space
    `Box(OBS_LOW, OBS_HIGH, dtype=float32)` of shape `(32,)` (every observation is clipped to it),
    everything from what the aircraft knows (the navigator's estimate and its map), never truth:

    | index | observation | unit | min | max |
    |-------|-------------|------|-----|-----|
    | 0, 1 | goal minus estimated position, north and east | km | -300 | 300 |
    | 2 | estimated distance to the goal | km | 0 | 450 |
    | 3, 4 | sin and cos of the commanded ground track | - | -1 | 1 |
    | 5 | estimated ground speed / 100 | (100 m/s) | 0 | 5 |
    | 6 | estimated height above the map terrain | km | -10 | 20 |
    | 7 | commanded height above ground | km | 0 | 10 |
    | 8, 9, 10 | log10(1 + sigma) of the estimate, north, east, down (sigma in m) | - | 0 | 8 |
    | 11-16 | terrain information of the map around the estimate (below) | - | 0 | 4.1 |
    | 17 | fraction of the episode time used | - | 0 | 1 |
    | 18 | navigator health ok (1) or not (0) | - | 0 | 1 |
    | 19, 20 | sin, cos of (goal's bearing from the estimate - commanded track; + = right) | - | -1 | 1 |
    | 21 | estimated distance to the goal / the estimated distance at the reset | - | 0 | 2 |
    | 22-26 | mean log10(1 + CRLB) along 5 candidate routes to the goal (below) | - | 0 | 4.1 |
    | 27-31 | longest featureless stretch along the same 5 routes (below) | km | 0 | 50 |

    Elements 19-21 are the goal relative to the ESTIMATE in normalised form (what a policy steers by
    without having to combine 0, 1 and 3, 4 itself); `trn_env.env.sb3_features.BoundsScaledExtractor`
    maps every element to [-1, 1] by these bounds for a learner.

    Terrain information (11-16) is log10(1 + CRLB) of the horizontal position a TRN could reach from the
    navigator's MAP (`terrain.metrics.terrain_information`: Fisher information of altimeter heights with
    noise `info_sigma_m` over an `info_window_m` square; CRLB in m, 1e4 m where the terrain is flat or off
    the map), sampled at the estimate and `info_offset_m` away ahead, ahead-left, ahead-right, left and
    right of the commanded track: low values mark where a route would let the TRN fix well.

    Route information (22-31, `trn_env.env.route_info`, from the MAP only): the 5 candidate routes are the
    constant-offset pursuit paths from the estimate to the goal at offsets (-1, -0.5, 0, 0.5, 1) x
    `bearing_offset_max_deg` from the goal's bearing (the routes that the pursuit actions -1 .. 1 fly),
    each marched in ~24 steps; 22-26 is the mean of log10(1 + CRLB) over each path, 27-31 its longest run
    of points with CRLB > `informative_crlb_m` (the longest stretch the navigator would dead-reckon on it;
    clipped at 50 km). They tell a policy, for any goal, which way
    round keeps the TRN fixing, so it can generalise across goals instead of memorising routes.

    ## Rewards
    `reward_mode="arrival"` (default; the task of a GNSS-denied aircraft). Each step:
    `progress_weight * (d_est_before - shaping_gamma * d_est_after) / 1 km - time_cost_per_s * dt`, d_est
    the ESTIMATED distance to the goal. The progress term is potential-based shaping (Ng, Harada & Russell
    1999, F = gamma Phi(s') - Phi(s) with Phi = -progress_weight d_est / 1 km), on the aircraft's own
    estimate: with `shaping_gamma = 1` (default) it adds up, over an episode that arrives, to the same
    amount for every route, so it guides learning without favouring a route; set `shaping_gamma` to the
    learner's discount (e.g. 0.99) for the form whose optimal policy of the discounted task is exactly that
    of the unshaped one (the undiscounted return then grows by progress_weight (1 - gamma) d_est per step
    spent far away, so returns compared undiscounted stay route-neutral only with 1); `progress_weight = 0`
    switches shaping off. Navigation-quality shaping (`sigma_shaping_weight` w, default 0): a second
    potential Phi_sigma = -w * sigma_h / 1 km on the navigator's REPORTED horizontal position sigma
    (sigma_h = sqrt(sigma_n^2 + sigma_e^2), the square root of the trace of the horizontal covariance),
    term `sigma = shaping_gamma * Phi_sigma(s') - Phi_sigma(s)`, with Phi_sigma = 0 at every episode end
    (Ng et al.'s terminal condition): it charges the growth of the navigator's uncertainty at the step
    where it happens (over a featureless stretch) and pays back the last step's sigma at the end, so over
    any episode it adds up to w * sigma_h(start) / 1 km, the same for every route: a dense signal of
    navigation quality that leaves the undiscounted return, and (at shaping_gamma = the learner's
    discount) the optimal policy, unchanged. The time term is the fuel/time cost. On arrival:
    `+ goal_bonus - miss_weight * true_miss_km`. The true miss is where the aircraft ends up when it flies
    the last `goal_radius_m` on its estimate: the true position plus (goal - estimated position), whose
    distance from the goal is the TRUE horizontal navigation error
    at arrival. `- collision_penalty` on terrain collision, `- failure_penalty` off the map, when the
    navigator diverged or when an engine stopped.

    `reward_mode="progress"` (the v0 reward before arrival mode; kept for comparison): each step
    `progress_km - error_weight * true_horizontal_error_km`, progress the decrease of the TRUE distance to
    the goal; `+ goal_bonus` when the TRUE position reaches the goal, `- collision_penalty` on collision.

    Steering-change cost (`action_change_weight` w, default 0; either mode; a training choice, the route
    task scores with 0): term `action_change = -w * |a0_t - a0_{t-1}|` on the track component of the
    clipped action, a0_{-1} = 0 at each episode's start (trn_env.env.task.action_change_terms; absent from
    the terms with w = 0). It charges offset reversals (-1 -> +1 costs 2 w), which turn the aircraft across
    its route and back.

    Time-outs as failures (`time_limit_failure`, default False; a training choice, the route task scores
    with False): the time limit ends the episode terminated (not truncated), with `- failure_penalty`
    (trn_env.env.task.episode_end_reasons says why a bootstrapping learner needs it).

    The terms reach `info["reward_terms"]` (a dict whose values add up to the reward).

    ## Starting State
    The scenario's initial state, or a start drawn per episode uniformly (in latitude and longitude) from
    `start_region_deg`; the navigator starts from the truth plus the scenario's initial errors (seed 000
    Table 2), drawn from the episode seed. The goal: `goal_deg`, or drawn per episode from
    `goal_region_deg` at least `min_goal_distance_m` from the start and outside `held_out_radius_m` of every
    held-out goal. `reset(options={"goal_deg": (lat, lon), "start_deg": (lat, lon)})` sets either for one
    episode (evaluation on the held-out goals). The commanded track starts at the bearing to the goal and
    the commanded height above ground at the scenario's.

    Held-out goals (`env.held_out_goals_deg`): `held_out_goals_deg` if given; else, with a goal region
    `(lat_min, lat_max, lon_min, lon_max)`, the five points at fractions (0.25, 0.25), (0.25, 0.75),
    (0.5, 0.5), (0.75, 0.25), (0.75, 0.75) of its latitude and longitude spans. Training goals never fall
    within `held_out_radius_m` of them.

    ## Episode End
    Terminated: arrival (mode "arrival": the ESTIMATED position within `goal_radius_m` of the goal, judged at
    every navigator update on that update's estimate; `termination = "arrived"`; mode "progress": the TRUE
    position within `goal_radius_m`, "goal"), terrain
    collision (true height above the true terrain < 0), off the map, the navigator diverged, or an engine
    stopped (fuel exhausted or engine failure; the scenario's `aircraft.constant_fuel = true` keeps the tanks
    full for long episodes). Truncated: `max_episode_s` of flight (terminated, a failure, with
    `time_limit_failure=True`). `step` after the end without `reset`
    raises `gymnasium.error.ResetNeeded`.

    ## Info
    `t_s`, `true_error_ned_m` (estimate minus truth), `true_horizontal_error_m`, `true_distance_to_goal_m`,
    `estimated_distance_to_goal_m`, `sigma_ned_m`, `nav_ok`, `nav_status`, `goal_deg`, `start_deg`,
    `distance_flown_m` (true, since the reset), `termination` (None while running; else `arrived`, `goal`,
    `terrain_collision`, `off_map`, `diverged`, `fuel_exhausted`, `engine_failure` or `time_limit`),
    `reward_terms`; at arrival `true_miss_m`.

    ## Vector envs, pickling
    `metadata["autoreset_mode"]` is `AutoresetMode.NEXT_STEP` (the step after an episode's end returns the
    reset observation), `render_fps` the decision rate (1 / decision_interval_s). The env pickles by its
    constructor arguments (`gymnasium.utils.EzPickle`): an unpickled env is a new one that needs `reset`.
    `close()` may be called any number of times.

    ## Arguments
    `gymnasium.make("trn_env/TerrainNav-v0", scenario="default", render_mode=None, decision_interval_s=5.0,
    max_episode_s=300.0, navigator=None, goal_deg=None, goal_radius_m=1000.0, reward_mode="arrival",
    error_weight=1.0, goal_bonus=10.0, collision_penalty=100.0, failure_penalty=100.0, miss_weight=20.0,
    time_cost_per_s=0.01, progress_weight=1.0, agl_min_m=300.0, agl_max_m=3000.0, climb_rate_max_mps=5.0,
    turn_rate_max_dps=3.0, info_offset_m=3000.0, info_sigma_m=5.0, info_window_m=2000.0,
    log_sensors=False, goal_region_deg=None, start_region_deg=None, held_out_goals_deg=None,
    held_out_radius_m=2000.0, min_goal_distance_m=5000.0, shaping_gamma=1.0, action_mode="turn",
    bearing_offset_max_deg=90.0, sigma_shaping_weight=0.0, informative_crlb_m=5.0, guidance_rate_hz=None,
    pipeline=False, flight_dt_s=None, scenario_fields=None, action_change_weight=0.0,
    time_limit_failure=False)`.
    `scenario_fields`: scenario fields set for every episode by dotted path (`Scenario.with_fields`, as
    `trn-env fly --set`), e.g. `{"sensors.ira.rate_hz": 10.0, "navigator.rate_hz": 0.5}`; applied with
    `navigator` (validated together: the fields may add a sensor the navigator requires) and before
    `guidance_rate_hz` and `flight_dt_s`; anything the scenario's schema rejects is a ValueError naming
    `scenario_fields` and the field. The route task's rates (`TASK_RATES`, its default) and its opt-in
    `DECISION_RATES` use it (trn_env.env.route_task; what they cost in accuracy:
    docs/validation/env_speed.md).
    `flight_dt_s`: JSBSim's integration step (s, at most 0.05; None = the scenario's `[aircraft] dt_s`,
    0.01 in the built-in scenarios). The IMU's rate is lowered to the step rate when it was faster (an
    integrating IMU: each sample is the mean over its interval of the truth rows); any other sensor faster
    than the step, or a step that does not divide the guidance tick, is a ValueError naming `flight_dt_s`.
    The route task (`trn_env.env.route_task`) flies 0.02 s: half the JSBSim work of 0.01 s; JSBSim's step
    error is first order, so its trajectory departs about three times as far from a 0.005 s one as
    0.01 s's does (tens of metres in a climb's transient; docs/validation/route_task.md).
    `guidance_rate_hz`: how often guidance re-computes the autopilot targets from the (dead-reckoned)
    estimate; None = once per navigator update (the scenario's `[guidance] rate_hz` is replaced; it must be
    a whole multiple of the navigator's rate). The autopilot itself runs inside JSBSim at every step.
    `pipeline=True` runs the sensors and the navigator in a second process while the flight goes on
    (`ClosedLoop(pipeline=True)`: the same episode bit for bit, fewer wall seconds per step when a second
    core is free; a worker process is forked at each reset, so keep it off inside vectorised trainers).
    `scenario` is a built-in name, a TOML path or a `Scenario`; `goal_deg=(lat, lon)` defaults to the
    route's last waypoint. The terrain (and the map's error draw) is built once per env from the
    scenario seed; each episode's flight, sensor and navigator randomness comes from the reset seed.
    `render_mode="rgb_array"` returns the map with the true (black) and estimated (red) tracks, (480, 480, 3)
    uint8 frames (`gymnasium.wrappers.RecordVideo` writes them with moviepy, the `video` extra).

    ## Version History
    - v0 (a held offset that the aircraft can fly): the pursuit and bearing actions' offset limit near the
      goal is asin(d omega / (2 v)), was asin(d omega / v), which asked for twice the turn rate in the final
      approach (orbits of the goal and time-outs); `time_limit_failure`. Episodes that hold an offset
      within ~3 km of the goal differ from before.
    - v0 (arrival on time): arrival is judged on each navigator update's own estimate (before: on the
      previous update's, then confirmed on the current one, so arrival came up to one update late).
    - v0 (scenario fields): `scenario_fields`; the per-update goal geometry and the route information's
      pursuit paths are compiled kernels (the same episodes to rounding).
    - v0 (JSBSim's step): `flight_dt_s`.
    - v0 (rates matched to the decision): guidance re-computes the targets once per navigator update
      instead of at the scenario's 10 Hz (`guidance_rate_hz`); `pipeline`.
    - v0 (coarse decisions): `action_mode="pursuit"`; route-information observations 22-31 (the
      observation grows from 22 to 32 elements); `sigma_shaping_weight`.
    - v0 (normalised goal): observation elements 19-21 (goal bearing and distance relative to the
      estimate, normalised); `shaping_gamma`; `action_mode="bearing"`.
    - v0 (arrival mode): episodes end when the estimate arrives; the true miss at arrival counts; goal
      and start sampling per episode; per-element observation bounds; reward terms in info.
    - v0 (first): the "progress" reward and termination on the true position.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 0.2, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, scenario: str | Scenario = "default", render_mode: str | None = None,
                 decision_interval_s: float = 5.0, max_episode_s: float = 300.0, navigator: str | None = None,
                 goal_deg: tuple[float, float] | None = None, goal_radius_m: float = 1000.0,
                 reward_mode: str = "arrival", error_weight: float = 1.0, goal_bonus: float = 10.0,
                 collision_penalty: float = 100.0, failure_penalty: float = 100.0, miss_weight: float = 20.0,
                 time_cost_per_s: float = 0.01, progress_weight: float = 1.0,
                 agl_min_m: float = 300.0, agl_max_m: float = 3000.0, climb_rate_max_mps: float = 5.0,
                 turn_rate_max_dps: float = 3.0, info_offset_m: float = 3000.0, info_sigma_m: float = 5.0,
                 info_window_m: float = 2000.0, log_sensors: bool = False,
                 goal_region_deg: tuple[float, float, float, float] | None = None,
                 start_region_deg: tuple[float, float, float, float] | None = None,
                 held_out_goals_deg=None, held_out_radius_m: float = 2000.0,
                 min_goal_distance_m: float = 5000.0, shaping_gamma: float = 1.0,
                 action_mode: str = "turn", bearing_offset_max_deg: float = 90.0,
                 sigma_shaping_weight: float = 0.0, informative_crlb_m: float = 5.0,
                 guidance_rate_hz: float | None = None, pipeline: bool = False,
                 flight_dt_s: float | None = None, scenario_fields: dict | None = None,
                 action_change_weight: float = 0.0, time_limit_failure: bool = False):
        EzPickle.__init__(self, scenario, render_mode, decision_interval_s, max_episode_s, navigator,
                          goal_deg, goal_radius_m, reward_mode, error_weight, goal_bonus, collision_penalty,
                          failure_penalty, miss_weight, time_cost_per_s, progress_weight, agl_min_m,
                          agl_max_m,
                          climb_rate_max_mps, turn_rate_max_dps, info_offset_m, info_sigma_m, info_window_m,
                          log_sensors, goal_region_deg, start_region_deg, held_out_goals_deg,
                          held_out_radius_m, min_goal_distance_m, shaping_gamma, action_mode,
                          bearing_offset_max_deg, sigma_shaping_weight, informative_crlb_m,
                          guidance_rate_hz, pipeline, flight_dt_s, scenario_fields, action_change_weight,
                          time_limit_failure)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if reward_mode not in REWARD_MODES:
            raise ValueError(f"reward_mode must be one of {REWARD_MODES}, got {reward_mode!r}")
        if not isinstance(scenario, (str, Scenario)):
            raise ValueError(f"scenario must be a built-in name, a TOML path or a Scenario, got "
                             f"{type(scenario).__name__}")
        if navigator is not None and not isinstance(navigator, str):
            raise ValueError(f"navigator must be a registered navigator name (str) or None, "
                             f"got {navigator!r}")
        for name, v in (("decision_interval_s", decision_interval_s), ("max_episode_s", max_episode_s),
                        ("goal_radius_m", goal_radius_m), ("climb_rate_max_mps", climb_rate_max_mps),
                        ("turn_rate_max_dps", turn_rate_max_dps), ("info_offset_m", info_offset_m),
                        ("info_sigma_m", info_sigma_m), ("info_window_m", info_window_m),
                        ("agl_min_m", agl_min_m), ("agl_max_m", agl_max_m),
                        ("held_out_radius_m", held_out_radius_m),
                        ("min_goal_distance_m", min_goal_distance_m),
                        ("informative_crlb_m", informative_crlb_m)):
            _check_number(name, v, positive=True)
        for name, v in (("error_weight", error_weight), ("goal_bonus", goal_bonus),
                        ("collision_penalty", collision_penalty), ("failure_penalty", failure_penalty),
                        ("miss_weight", miss_weight), ("time_cost_per_s", time_cost_per_s),
                        ("progress_weight", progress_weight), ("sigma_shaping_weight", sigma_shaping_weight),
                        ("action_change_weight", action_change_weight)):
            _check_number(name, v, positive=False)
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode must be one of {ACTION_MODES}, got {action_mode!r}")
        _check_number("bearing_offset_max_deg", bearing_offset_max_deg, positive=True)
        if bearing_offset_max_deg > 180.0:
            raise ValueError(f"bearing_offset_max_deg must be in (0, 180], got {bearing_offset_max_deg!r}")
        _check_number("shaping_gamma", shaping_gamma, positive=True)
        if shaping_gamma > 1.0:
            raise ValueError(f"shaping_gamma must be in (0, 1], got {shaping_gamma!r}")
        if not isinstance(log_sensors, bool):
            raise ValueError(f"log_sensors must be a bool, got {log_sensors!r}")
        if not 0 < agl_min_m < agl_max_m:
            raise ValueError(f"need 0 < agl_min_m < agl_max_m, got {agl_min_m}, {agl_max_m}")
        if navigator is not None and scenario_fields:
            # one validation: the fields may fit what the navigator needs (a sensor it requires)
            base = (scenario if isinstance(scenario, Scenario)
                    else load_scenario(scenario, check_components=False))
            sc = with_fields(base, scenario_fields, navigator=navigator)
            sc = sc.with_overrides(duration_s=float(max_episode_s) + 1.0)
        else:
            sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, navigator=navigator)
            if isinstance(scenario, Scenario) and navigator is not None:
                sc = sc.with_overrides(navigator=navigator)
            sc = sc.with_overrides(duration_s=float(max_episode_s) + 1.0)
            sc = with_fields(sc, scenario_fields)
        sc = with_rates(sc, guidance_rate_hz, flight_dt_s)
        if not isinstance(pipeline, bool):
            raise ValueError(f"pipeline must be a bool, got {pipeline!r}")
        self.pipeline = pipeline
        self.scenario = sc
        rate_hz = float(sc.navigator.rate_hz)      # one loop tick = one navigator update
        self.ticks_per_decision = max(1, int(round(decision_interval_s * rate_hz)))
        self.decision_interval_s = self.ticks_per_decision / rate_hz
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / self.decision_interval_s}
        self.max_episode_s = float(max_episode_s)
        self.render_mode = render_mode
        self.reward_mode = reward_mode
        self.error_weight = float(error_weight)
        self.goal_bonus = float(goal_bonus)
        self.collision_penalty = float(collision_penalty)
        self.failure_penalty = float(failure_penalty)
        self.miss_weight = float(miss_weight)
        self.time_cost_per_s = float(time_cost_per_s)
        self.progress_weight = float(progress_weight)
        self.shaping_gamma = float(shaping_gamma)
        self.sigma_shaping_weight = float(sigma_shaping_weight)
        self.action_change_weight = float(action_change_weight)
        self._terminating, self._truncating, self._failures = task.episode_end_reasons(time_limit_failure)
        self.time_limit_failure = time_limit_failure
        self.informative_crlb_m = float(informative_crlb_m)
        self.action_mode = action_mode
        self.bearing_offset_max_rad = math.radians(float(bearing_offset_max_deg))
        self._route_offsets_rad = np.array(ROUTE_OFFSET_FRACTIONS) * self.bearing_offset_max_rad
        self.goal_radius_m = float(goal_radius_m)
        self.agl_min_m, self.agl_max_m = float(agl_min_m), float(agl_max_m)
        self.tas_mps = float(sc.route.tas_mps)
        self.info_offset_m = float(info_offset_m)
        self.log_sensors = bool(log_sensors)
        self.held_out_radius_m = float(held_out_radius_m)
        self.min_goal_distance_m = float(min_goal_distance_m)

        self.action_limits = task.action_limits(self.decision_interval_s, turn_rate_max_dps,
                                                climb_rate_max_mps)          # rad, m per decision step
        self.action_space = task.action_space()
        self.observation_space = task.observation_space()

        self._dems = components.build_terrain(sc, sc.extras, spawn_rngs(sc.seed)["map"])
        self._info_map = components.terrain_information_map(self._dems[1], info_sigma_m, info_window_m)
        self.goal_region_deg = self._check_region("goal_region_deg", goal_region_deg)
        self.start_region_deg = self._check_region("start_region_deg", start_region_deg)
        if held_out_goals_deg is None and self.goal_region_deg is not None:
            la0, la1, lo0, lo1 = self.goal_region_deg
            held_out_goals_deg = [(la0 + fa * (la1 - la0), lo0 + fo * (lo1 - lo0))
                                  for fa, fo in ((0.25, 0.25), (0.25, 0.75), (0.5, 0.5), (0.75, 0.25),
                                                 (0.75, 0.75))]
        self.held_out_goals_deg = [self._check_point("held_out_goals_deg", g)
                                   for g in (held_out_goals_deg or [])]
        wp_last = sc.route.waypoints[-1]
        g = goal_deg if goal_deg is not None else (wp_last.lat_deg, wp_last.lon_deg)
        g = self._check_point("goal_deg", g)
        self._fixed_goal_deg = g
        self.goal_lat_rad, self.goal_lon_rad = math.radians(g[0]), math.radians(g[1])
        self.start_deg = (float(sc.initial.lat_deg), float(sc.initial.lon_deg))
        self._loop: ClosedLoop | None = None
        self._needs_reset = True
        self._track_cmd_rad = 0.0
        self._agl_cmd_m = 0.0
        self._true_track: list[tuple[float, float]] = []
        self._est_track: list[tuple[float, float]] = []
        self._background = None
        self._distance_flown_m = 0.0
        self._d_est_start_m = 1.0
        self._offset_frac = 0.0          # pursuit mode: the held offset, a fraction of the offset limit

    # ---------------------------------------------------------------------------------------- checks
    def _check_point(self, name: str, p) -> tuple[float, float]:
        return check_point(name, p, self._dems)

    def _check_region(self, name: str, r):
        return check_region(name, r, self._dems)

    # ---------------------------------------------------------------------------------------- helpers
    @property
    def map_dem(self):
        """The navigator's map (what planners and policies may read; never the world)."""
        return self._dems[1]

    @property
    def goal_deg(self) -> tuple[float, float]:
        return math.degrees(self.goal_lat_rad), math.degrees(self.goal_lon_rad)

    def _commander(self, est, t_s):
        if self.action_mode == "pursuit":         # the offset held from the goal's bearing at every tick
            dn, de = self._offset_to_goal(est.lat_rad, est.lon_rad, est.h_m)
            limit = self._bearing_offset_limit_rad(math.hypot(dn, de))
            track = math.atan2(de, dn) + self._offset_frac * limit
            self._track_cmd_rad = math.atan2(math.sin(track), math.cos(track))
        track = self._track_cmd_rad
        if not math.isfinite(track):              # (the validating constructor names it)
            return components.track_agl_targets(track, self._agl_cmd_m, self.tas_mps)
        # the targets of components.track_agl_targets from values known to be valid (finite track, AGL
        # within [agl_min_m, agl_max_m], the route's TAS), without re-validating them at every tick
        return AutopilotTargets.trusted(LateralMode.TRACK, track, track, BANK_LIMIT_RAD,
                                        VerticalMode.HEIGHT_AGL, ALTITUDE_CMD_M, self._agl_cmd_m, 0.0,
                                        SpeedMode.TAS, self.tas_mps)

    def _offset_to_goal(self, lat, lon, h=0.0) -> tuple[float, float]:
        """North/east (m) of the goal in the local level frame at (lat, lon, h), exact through ECEF (the goal
        is tens of km away: no small-offset approximation), the goal taken at the same height."""
        return goal_offset_ne(float(lat), float(lon), float(h), self.goal_lat_rad, self.goal_lon_rad)

    def _arrival_needs_sync(self) -> bool:
        """Whether arrival is to be judged on the estimate for this time (the navigator's update of the
        interval just flown: `ClosedLoop.sync`). Inline, that update is already computed (sync costs nothing),
        so always: arrival is judged at every navigator update, on its own estimate. Pipelined (the update
        still in the worker), only when the last collected estimate, dead-reckoned to now, is within
        `goal_radius_m + ARRIVAL_SYNC_MARGIN_M` (or already inside the circle), so the flight waits for the
        worker only near the goal; the same decisions as inline unless one update moves the estimate by
        more than the margin."""
        loop = self._loop
        if not loop.pipelined:
            return True
        est = loop.estimate
        if self._estimated_distance_m() <= self.goal_radius_m:
            return True
        ahead = est.extrapolated(loop.t_s) if est.t_s != loop.t_s else est
        d = math.hypot(*self._offset_to_goal(ahead.lat_rad, ahead.lon_rad, ahead.h_m))
        return d <= self.goal_radius_m + ARRIVAL_SYNC_MARGIN_M

    def _estimated_distance_m(self) -> float:
        est = self._loop.estimate
        return math.hypot(*self._offset_to_goal(est.lat_rad, est.lon_rad, est.h_m))

    def _obs(self) -> np.ndarray:
        loop = self._loop
        est = loop.estimate
        dn, de = self._offset_to_goal(est.lat_rad, est.lon_rad, est.h_m)
        sig = est.sigma_ned_m
        h_ground = components.map_height(self._dems[1], est.lat_rad, est.lon_rad)
        agl_est = est.h_m - h_ground if math.isfinite(h_ground) else 0.0
        info = components.sample_information(self._info_map, self._dems[1], est.lat_rad, est.lon_rad,
                                             self._track_cmd_rad, self.info_offset_m)
        d_m = math.hypot(dn, de)
        rel = math.atan2(de, dn) - self._track_cmd_rad
        obs = np.array([
            dn / 1000.0, de / 1000.0, d_m / 1000.0,
            math.sin(self._track_cmd_rad), math.cos(self._track_cmd_rad),
            float(np.hypot(est.v_ned_mps[0], est.v_ned_mps[1])) / 100.0,
            agl_est / 1000.0, self._agl_cmd_m / 1000.0,
            *np.log10(1.0 + np.clip(sig, 0.0, 1e300)),
            *np.log10(1.0 + np.clip(info, 0.0, None)),
            loop.t_s / self.max_episode_s,
            1.0 if est.health.ok else 0.0,
            math.sin(rel), math.cos(rel), d_m / max(self._d_est_start_m, 1.0),
            *self._route_information(est, dn, de),
        ], dtype=np.float64)
        obs = np.nan_to_num(obs, nan=0.0, posinf=1e4, neginf=-1e4)
        return np.clip(obs, OBS_LOW, OBS_HIGH).astype(np.float32)

    def _route_information(self, est, dn: float, de: float) -> np.ndarray:
        """Observation elements 22-31 (see the class docstring): the map's information along the candidate
        pursuit routes from the estimate to the goal."""
        omega = self.action_limits[0] / self.decision_interval_s
        mean, featureless = route_information(
            self._info_map, est.lat_rad, est.lon_rad, dn, de, self._route_offsets_rad, self.goal_radius_m,
            omega, self.tas_mps, self.informative_crlb_m)
        return np.concatenate([mean, np.minimum(featureless, ROUTE_FEATURELESS_MAX_KM)])

    def _sigma_h_m(self) -> float:
        sig = self._loop.estimate.sigma_ned_m
        s = math.hypot(float(sig[0]), float(sig[1]))
        return s if math.isfinite(s) else 0.0

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
            "estimated_distance_to_goal_m": self._estimated_distance_m(),
            "sigma_ned_m": est.sigma_ned_m.copy(),
            "nav_ok": bool(est.health.ok),
            "nav_status": str(est.health.status),
            "goal_deg": self.goal_deg,
            "start_deg": self.start_deg,
            "distance_flown_m": float(self._distance_flown_m),
            "termination": termination,
        }

    def _draw_region(self, region) -> tuple[float, float]:
        la0, la1, lo0, lo1 = region
        return float(self.np_random.uniform(la0, la1)), float(self.np_random.uniform(lo0, lo1))

    def _far_from_held_out(self, p) -> bool:
        lat, lon = math.radians(p[0]), math.radians(p[1])
        for g in self.held_out_goals_deg:
            dn, de = latlon_to_ned_offset(lat, lon, 0.0, math.radians(g[0]), math.radians(g[1]))
            if math.hypot(dn, de) < self.held_out_radius_m:
                return False
        return True

    def _episode_endpoints(self, options: dict) -> tuple[tuple[float, float], tuple[float, float]]:
        init = self.scenario.initial
        if "start_deg" in options:
            start = self._check_point("options['start_deg']", options["start_deg"])
        elif self.start_region_deg is not None:
            start = self._draw_region(self.start_region_deg)
        else:
            start = (float(init.lat_deg), float(init.lon_deg))
        if "goal_deg" in options:
            return start, self._check_point("options['goal_deg']", options["goal_deg"])
        if self.goal_region_deg is None:
            return start, self._fixed_goal_deg
        s_lat, s_lon = math.radians(start[0]), math.radians(start[1])
        for _ in range(1000):
            g = self._draw_region(self.goal_region_deg)
            dn, de = latlon_to_ned_offset(s_lat, s_lon, 0.0, math.radians(g[0]), math.radians(g[1]))
            if math.hypot(dn, de) >= self.min_goal_distance_m and self._far_from_held_out(g):
                return start, g
        raise ValueError("goal_region_deg: no goal found in 1000 draws at least min_goal_distance_m from the "
                         "start and outside held_out_radius_m of the held-out goals")

    # ------------------------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None, got {type(options).__name__}")
        options = options or {}
        unknown = set(options) - {"goal_deg", "start_deg"}
        if unknown:
            raise ValueError(f"reset options: unknown keys {sorted(unknown)}; known: goal_deg, start_deg")
        if self._loop is not None:
            self._loop.close()
        start, goal = self._episode_endpoints(options)
        self.goal_lat_rad, self.goal_lon_rad = math.radians(goal[0]), math.radians(goal[1])
        self.start_deg = start
        ep_seed = int(self.np_random.integers(0, 2**31 - 1))
        sc = self.scenario
        sections = sc.sections
        lat0, lon0 = math.radians(start[0]), math.radians(start[1])
        gn, ge = self._offset_to_goal(lat0, lon0)
        self._track_cmd_rad = math.atan2(ge, gn)
        if start != (float(sections.initial.lat_deg), float(sections.initial.lon_deg)):
            initial = dataclasses.replace(sections.initial, lat_deg=start[0], lon_deg=start[1],
                                          heading_deg=math.degrees(self._track_cmd_rad) % 360.0)
            sections = dataclasses.replace(sections, initial=initial)
        sc = Scenario(name=sc.name, source=sc.source, sections=sections, description=sc.description,
                      seed=ep_seed, duration_s=sc.duration_s, extras=sc.extras)
        init = sections.initial
        if init.h_agl_m is not None:
            self._agl_cmd_m = float(init.h_agl_m)
        else:
            self._agl_cmd_m = float(init.h_msl_m) - components.map_height(self._dems[1], lat0, lon0)
        self._agl_cmd_m = float(np.clip(self._agl_cmd_m, self.agl_min_m, self.agl_max_m))
        self._offset_frac = 0.0
        self._a0_before = 0.0                    # the previous track action (0 at the episode's start)
        self._loop = ClosedLoop(sc, commander=self._commander, dems=self._dems, log_sensors=self.log_sensors,
                                pipeline=self.pipeline)
        self._needs_reset = False
        self._distance_flown_m = 0.0
        self._d_est_start_m = self._estimated_distance_m()
        lat, lon, _ = self._truth_now()
        self._true_track = [(lat, lon)]
        self._est_track = [(self._loop.estimate.lat_rad, self._loop.estimate.lon_rad)]
        return self._obs(), self._info(None)

    def _check_action(self, action) -> np.ndarray:
        return task.check_actions(action, self.action_space.shape, self.action_space.low,
                                  self.action_space.high)

    def _bearing_offset_limit_rad(self, d_m: float) -> float:
        """Largest offset from the goal's bearing that the aircraft can hold at distance d_m: flying at an
        offset phi turns the bearing at v sin(phi) / d, which the turn rate must keep up with."""
        omega = self.action_limits[0] / self.decision_interval_s
        return float(task.bearing_offset_limit_rad(d_m, omega, self.tas_mps, self.bearing_offset_max_rad))

    def _apply_action(self, a: np.ndarray) -> None:
        """The action (in [-1, 1]) -> new commanded track and height above ground (see Action Space)."""
        dpsi, dagl = self.action_limits
        if self.action_mode == "turn":
            track = self._track_cmd_rad + a[0] * dpsi
            agl = self._agl_cmd_m + a[1] * dagl
        elif self.action_mode == "pursuit":    # the commander holds the offset; height as in "bearing"
            self._offset_frac = float(a[0])
            track = self._track_cmd_rad
            agl_want = self.agl_min_m + 0.5 * (a[1] + 1.0) * (self.agl_max_m - self.agl_min_m)
            agl = self._agl_cmd_m + float(np.clip(agl_want - self._agl_cmd_m, -dagl, dagl))
        else:                                  # "bearing": toward targets, at the aircraft's limits
            est = self._loop.estimate
            dn, de = self._offset_to_goal(est.lat_rad, est.lon_rad, est.h_m)
            want = math.atan2(de, dn) + a[0] * self._bearing_offset_limit_rad(math.hypot(dn, de))
            d = math.atan2(math.sin(want - self._track_cmd_rad), math.cos(want - self._track_cmd_rad))
            track = self._track_cmd_rad + float(np.clip(d, -dpsi, dpsi))
            agl_want = self.agl_min_m + 0.5 * (a[1] + 1.0) * (self.agl_max_m - self.agl_min_m)
            agl = self._agl_cmd_m + float(np.clip(agl_want - self._agl_cmd_m, -dagl, dagl))
        self._track_cmd_rad = math.atan2(math.sin(track), math.cos(track))
        self._agl_cmd_m = float(np.clip(agl, self.agl_min_m, self.agl_max_m))

    def step(self, action):
        if self._loop is None or self._needs_reset:
            raise ResetNeeded("Cannot call env.step() before calling env.reset() (the episode has ended or "
                              "never started)")
        a = self._check_action(action)
        change = task.action_change_terms(a[0], self._a0_before,
                                          action_change_weight=self.action_change_weight)
        self._a0_before = float(a[0])
        self._apply_action(a)
        lat, lon, h = self._truth_now()
        d_before = math.hypot(*self._offset_to_goal(lat, lon, h))
        d_est_before = self._estimated_distance_m()
        sigma_before = self._sigma_h_m()
        t_before = self._loop.t_s
        self._loop.command_now()                         # new targets take effect now
        reason = None
        arrival = self.reward_mode == "arrival"
        for _ in range(self.ticks_per_decision):
            reason = self._loop.tick()
            lat1, lon1, h1 = self._truth_now()
            dn, de = latlon_to_ned_offset(lat, lon, h, lat1, lon1)
            self._distance_flown_m += math.hypot(dn, de)
            lat, lon, h = lat1, lon1, h1
            if reason is None:
                if arrival:
                    if self._arrival_needs_sync():
                        self._loop.sync()                # the estimate at this time decides
                        reason = self._loop.termination or (
                            "arrived" if self._estimated_distance_m() <= self.goal_radius_m else None)
                elif math.hypot(*self._offset_to_goal(lat, lon, h)) <= self.goal_radius_m:
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
        terms = self._reward_terms(info, reason, d_before, d_est_before, self._loop.t_s - t_before,
                                   sigma_before)
        terms.update({k: float(v) for k, v in change.items()})
        info["reward_terms"] = terms
        reward = float(sum(terms.values()))
        terminated = reason in self._terminating
        truncated = reason in self._truncating
        if terminated or truncated:
            self._needs_reset = True
        return self._obs(), reward, bool(terminated), bool(truncated), info

    def _reward_terms(self, info: dict, reason: str | None, d_before: float, d_est_before: float,
                      dt_s: float, sigma_before_m: float = 0.0) -> dict[str, float]:
        if self.reward_mode == "progress":
            terms = task.progress_reward_terms(
                d_before, info["true_distance_to_goal_m"], info["true_horizontal_error_m"], reason == "goal",
                reason == "terrain_collision", error_weight=self.error_weight, goal_bonus=self.goal_bonus,
                collision_penalty=self.collision_penalty)
            return {k: float(v) for k, v in terms.items()}
        if reason == "arrived":
            # flying the last goal_radius_m on the estimate ends at truth + (goal - estimate): its miss is
            # the true horizontal navigation error
            info["true_miss_m"] = info["true_horizontal_error_m"]
        terms = task.arrival_reward_terms(
            d_est_before, info["estimated_distance_to_goal_m"], dt_s, sigma_before_m,
            self._sigma_h_m() if self.sigma_shaping_weight > 0.0 else 0.0, reason is not None,
            reason == "arrived", reason == "terrain_collision", reason in self._failures,
            info["true_horizontal_error_m"], progress_weight=self.progress_weight,
            shaping_gamma=self.shaping_gamma, time_cost_per_s=self.time_cost_per_s,
            collision_penalty=self.collision_penalty, failure_penalty=self.failure_penalty,
            goal_bonus=self.goal_bonus, miss_weight=self.miss_weight,
            sigma_shaping_weight=self.sigma_shaping_weight)
        return {k: float(v) for k, v in terms.items()}

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        import trn_env.output.plots as plots
        return plots.render_tracks_rgb(self._dems[0], self._true_track, self._est_track,
                                       (self.goal_lat_rad, self.goal_lon_rad), cache=self)

    def close(self):
        """Release the episode's flight (safe to call any number of times)."""
        loop, self._loop = self._loop, None
        if loop is not None:
            loop.close()
        self._needs_reset = True
