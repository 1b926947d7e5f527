"""The route task shared by both env tiers: spaces, action limits and checks, rewards and episode ends.

TerrainNav-v0 (trn_env.env.terrain_nav, the full JSBSim loop) and TerrainNavFast-v0 (trn_env.env.fast, N
point-mass aircraft per process) import their observation and action spaces, the action limits, the
action check, the reward terms and the sets of episode-end reasons from here, so a policy trained on one
runs unchanged on the other. The tables (what each observation element and action means) are in
TerrainNavEnv's docstring.

The reward function is written over numpy arrays (one element per aircraft) so that the vector tier computes
every sub-env's terms in one call; the single env passes 0-d values.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

G0_MPS2 = 9.80665
N_TERRAIN_FEATURES = 6
REWARD_MODES = ("arrival", "progress")
ACTION_MODES = ("turn", "bearing", "pursuit")
# candidate routes of the route-information observation: constant offsets from the goal's bearing, as
# fractions of bearing_offset_max_deg (the pursuit action that flies each)
ROUTE_OFFSET_FRACTIONS = (-1.0, -0.5, 0.0, 0.5, 1.0)
N_ROUTES = len(ROUTE_OFFSET_FRACTIONS)
ROUTE_FEATURELESS_MAX_KM = 50.0

# Observation bounds per element (the clip applied to every observation), see TerrainNavEnv's table.
OBS_LOW = np.array([-300.0, -300.0, 0.0, -1.0, -1.0, 0.0, -10.0, 0.0, 0.0, 0.0, 0.0,
                    0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, -1.0, 0.0]
                   + [0.0] * (2 * N_ROUTES), np.float32)
OBS_HIGH = np.array([300.0, 300.0, 450.0, 1.0, 1.0, 5.0, 20.0, 10.0, 8.0, 8.0, 8.0,
                     4.1, 4.1, 4.1, 4.1, 4.1, 4.1, 1.0, 1.0, 1.0, 1.0, 2.0]
                    + [4.1] * N_ROUTES + [ROUTE_FEATURELESS_MAX_KM] * N_ROUTES, np.float32)
N_OBS = OBS_LOW.size

# Episode-end reasons (info["termination"]): which terminate the episode, which are failures (penalised
# with failure_penalty in the arrival reward); "time_limit" truncates.
TERMINATING_REASONS = ("arrived", "goal", "terrain_collision", "off_map", "diverged", "fuel_exhausted",
                       "engine_failure")
FAILURE_REASONS = ("off_map", "diverged", "fuel_exhausted", "engine_failure")
TRUNCATING_REASONS = ("time_limit",)


def episode_end_reasons(time_limit_failure: bool = False) -> tuple[tuple, tuple, tuple]:
    """(terminating, truncating, failure) episode-end reasons. By default the time limit truncates (the
    gymnasium convention: a learner bootstraps the value of the last observation). With
    `time_limit_failure=True` (a training choice) it ends the episode as a failure instead: terminated, with
    `failure_penalty` in the arrival reward. The route task scores a time-out as not arrived, and the
    observation carries the fraction of the episode time used (element 17), so the limit is part of the
    task's state; truncated, a time-out costs a bootstrapping learner (RLlib's GAE, SB3's PPO) only the
    extrapolated value of a state it never sees continue, and a policy learns detours that just fit the
    limit."""
    if not isinstance(time_limit_failure, bool):
        raise ValueError(f"time_limit_failure must be a bool, got {time_limit_failure!r}")
    if not time_limit_failure:
        return TERMINATING_REASONS, TRUNCATING_REASONS, FAILURE_REASONS
    return (TERMINATING_REASONS + TRUNCATING_REASONS, (), FAILURE_REASONS + TRUNCATING_REASONS)

ACTION_NAMES = ("track change (fraction of the turn limit)", "AGL change (fraction of the climb limit)")


def action_space() -> spaces.Box:
    """`Box(-1, 1, shape=(2,), float32)`: (track, height above ground) as fractions of the step's limits."""
    return spaces.Box(low=-1.0, high=1.0, shape=(2,), dtype=np.float32)


def observation_space() -> spaces.Box:
    """`Box(OBS_LOW, OBS_HIGH, float32)` of shape (N_OBS,) = (32,)."""
    return spaces.Box(low=OBS_LOW, high=OBS_HIGH, dtype=np.float32)


def action_limits(decision_interval_s: float, turn_rate_max_dps: float,
                  climb_rate_max_mps: float) -> np.ndarray:
    """(dpsi_max rad, dagl_max m) per decision: min(turn rate x interval, 60 deg), climb rate x interval."""
    dpsi = min(math.radians(turn_rate_max_dps) * decision_interval_s, math.pi / 3)
    return np.array([dpsi, climb_rate_max_mps * decision_interval_s])


def bearing_offset_limit_rad(d_m, omega_rps: float, tas_mps: float, offset_max_rad: float):
    """Largest offset (rad) from the goal's bearing the aircraft can hold at distance d_m (m; scalar or
    array) turning at no more than omega: min(offset_max, asin(min(1, d omega / (2 v)))).

    Holding phi(d) = asin(k d) takes two turns at once: flying at the offset turns the goal's bearing at
    v sin(phi) / d = v k, and the offset itself shrinks as d does, at |dphi/dt| = k v cos(phi) / cos(phi)
    = v k; the ground track turns at their sum 2 v k, so k = omega / (2 v). (With k = omega / v, the law
    before, the final approach asked for twice omega: 4 deg/s at the route task's omega of 2 deg/s, past the
    King Air's ~3.1 deg/s at its bank limit, and a held offset turned into an orbit of the goal that the
    aircraft could not leave in time.)"""
    return np.minimum(offset_max_rad,
                      np.arcsin(np.minimum(1.0, np.asarray(d_m) * omega_rps / (2.0 * tas_mps))))


def check_actions(action, shape: tuple[int, ...], low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """`action` as float64 of `shape`, clipped to [low, high]; ValueError naming what it breaks (not an
    array of numbers, wrong shape, not finite, outside the space by more than 1e-6 relative). The last axis
    is (track change, AGL change)."""
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action must be an array of numbers of shape {shape} (track change, AGL change), "
                         f"got {action!r}") from None
    if a.shape != tuple(shape):
        raise ValueError(f"action must have shape {tuple(shape)} (track change, AGL change), "
                         f"got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0].tolist()
        raise ValueError(f"action must be finite, got {a[tuple(bad)]} at index {bad}")
    lo = np.asarray(low, np.float64)
    hi = np.asarray(high, np.float64)
    tol = 1e-6 * np.maximum(1.0, np.abs(hi))
    out = (a < lo - tol) | (a > hi + tol)
    if np.any(out):
        idx = tuple(np.argwhere(out)[0].tolist())
        k = idx[-1]
        where = f"action{list(idx)}" if len(idx) > 1 else f"action[{k}]"
        lo_i, hi_i = np.broadcast_to(lo, a.shape)[idx], np.broadcast_to(hi, a.shape)[idx]
        raise ValueError(f"{where} {ACTION_NAMES[k]} = {a[idx]:.6g} is outside the action space "
                         f"[{lo_i:.6g}, {hi_i:.6g}]")
    return np.clip(a, lo, hi)


def arrival_reward_terms(d_est_before_m, d_est_after_m, dt_s, sigma_before_m, sigma_after_m, ended, arrived,
                         collided, failed, true_error_h_m, *, progress_weight: float, shaping_gamma: float,
                         time_cost_per_s: float, collision_penalty: float, failure_penalty: float,
                         goal_bonus: float, miss_weight: float, sigma_shaping_weight: float) -> dict:
    """Reward terms of the "arrival" mode (TerrainNavEnv's Rewards section), element-wise over arrays.

    progress: potential-based shaping (Ng, Harada & Russell 1999, F = gamma Phi(s') - Phi(s)) with
    Phi = -progress_weight * estimated distance to the goal (km); time: -time_cost_per_s * dt_s; arrival:
    goal_bonus when arrived; miss: -miss_weight * true horizontal error (km) when arrived (the true miss of
    flying the last goal radius on the estimate); collision, failure: the penalties; sigma (only with
    sigma_shaping_weight > 0): shaping on the reported horizontal sigma with Phi = 0 at any episode end.
    Distances in m, dt_s in s; the flags are booleans. Returns {name: array} whose values add up to the
    reward.
    """
    arrived = np.asarray(arrived, bool)
    terms = {"progress": progress_weight * (np.asarray(d_est_before_m) - shaping_gamma
                                            * np.asarray(d_est_after_m)) / 1000.0,
             "time": -time_cost_per_s * np.asarray(dt_s, float),
             "arrival": np.where(arrived, goal_bonus, 0.0),
             "miss": np.where(arrived, -miss_weight * np.asarray(true_error_h_m) / 1000.0, 0.0),
             "collision": np.where(collided, -collision_penalty, 0.0),
             "failure": np.where(failed, -failure_penalty, 0.0)}
    if sigma_shaping_weight > 0.0:
        w = sigma_shaping_weight / 1000.0
        phi_after = np.where(ended, 0.0, -w * np.asarray(sigma_after_m))
        terms["sigma"] = shaping_gamma * phi_after + w * np.asarray(sigma_before_m)
    return terms


def action_change_terms(offset, offset_before, *, action_change_weight: float) -> dict:
    """The steering-change term (both reward modes): `action_change = -action_change_weight *
    |a0_t - a0_{t-1}|` on the track component a0 of the (clipped) action, a0_{-1} = 0 at each episode's
    start; element-wise over arrays. Only the track component: a reversal of the pursuit offset (-1 -> +1)
    turns the aircraft across its route and back, while the height component is already rate-limited by the
    climb limit and chooses the terrain the navigator sees. Returns {} with action_change_weight = 0 (the
    reward and its terms exactly as without the term), else {"action_change": array}."""
    if action_change_weight == 0.0:
        return {}
    return {"action_change": -action_change_weight * np.abs(np.asarray(offset, float)
                                                            - np.asarray(offset_before, float))}


def progress_reward_terms(d_true_before_m, d_true_after_m, true_error_h_m, reached_goal, collided, *,
                          error_weight: float, goal_bonus: float, collision_penalty: float) -> dict:
    """Reward terms of the "progress" mode: decrease of the TRUE distance to the goal (km), minus
    error_weight x true horizontal error (km), goal_bonus at the goal, -collision_penalty on collision."""
    return {"progress": (np.asarray(d_true_before_m) - np.asarray(d_true_after_m)) / 1000.0,
            "error": -error_weight * np.asarray(true_error_h_m) / 1000.0,
            "goal": np.where(reached_goal, goal_bonus, 0.0),
            "collision": np.where(collided, -collision_penalty, 0.0)}


__all__ = ["ACTION_MODES", "FAILURE_REASONS", "G0_MPS2", "N_OBS", "N_ROUTES", "N_TERRAIN_FEATURES",
           "OBS_HIGH", "OBS_LOW", "REWARD_MODES", "ROUTE_FEATURELESS_MAX_KM", "ROUTE_OFFSET_FRACTIONS",
           "TERMINATING_REASONS", "TRUNCATING_REASONS", "action_change_terms", "action_limits",
           "episode_end_reasons",
           "action_space", "arrival_reward_terms", "bearing_offset_limit_rad", "check_actions",
           "observation_space", "progress_reward_terms"]
