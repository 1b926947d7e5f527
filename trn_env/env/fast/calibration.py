"""Calibration of the fast tier against the full JSBSim loop on fixed reference routes.

A reference route is a terrain (scenario), a start, a goal and a scripted pursuit policy (the benchmark's
settings: pursuit actions, 30 s decisions, +-45 deg offsets, 500 m arrival radius): a constant action, or
a fixed cycle of actions, one per decision (the weaving route: the offset saturated and reversed every
second decision, the bang-bang steering of a PPO policy trained on the fast tier). Both tiers fly it with
the same navigator family (the scenario's INS + batch TERCOM); the figure compared
is the TRUE horizontal navigation error at the goal (`true_miss_m` on arrival; the true horizontal error at
the episode's end otherwise), its mean and 90th percentile over the seeds, FAST_SEEDS (256) in both tiers:
the 90th percentile of the turning routes hangs on a few episodes, which tens of seeds sample too coarsely
(docs/validation/fast_tier.md, "The full loop over 256 seeds").

Routes (labels from the map's terrain information along them, observation 27-31's featureless stretch):
informative (rough terrain all the way), featureless (a long flat stretch before the goal), mixed; weaving
(informative terrain, reversed offsets). Besides the true error the flights record the navigator's
horizontal sigma (the hypot of its north and east sigmas) and the episode's end, so that the tiers'
covariances and arrival (time-out) rates can be compared too.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ReferenceRoute:
    """One reference route: scenario, start and goal (deg), the pursuit action and AGL range (m); `cycle`
    (optional) the actions of decisions 0, 1, 2, ..., repeated, or, when `after` is given, flown once and
    then `after` held (`action` is the cycle's first)."""

    name: str
    kind: str
    scenario: str
    start_deg: tuple[float, float]
    goal_deg: tuple[float, float]
    action: tuple[float, float]
    agl_min_m: float
    agl_max_m: float
    cycle: tuple[tuple[float, float], ...] = ()
    after: tuple[float, float] | None = None

    def action_at(self, k: int) -> np.ndarray:
        """The action of decision k (0-based)."""
        if not self.cycle:
            a = self.action
        elif self.after is not None and k >= len(self.cycle):
            a = self.after
        else:
            a = self.cycle[k % len(self.cycle)]
        return np.asarray(a, np.float32)


_BASIN = dict(scenario="basin_route", agl_min_m=300.0, agl_max_m=900.0)
_JACKS = dict(scenario="default", agl_min_m=500.0, agl_max_m=1500.0)
REFERENCE_ROUTES = (
    ReferenceRoute(
        "basin_straight",
        "featureless",
        start_deg=(36.527, -84.1325),
        goal_deg=(36.716, -84.1325),
        action=(0.0, 0.0),
        **_BASIN,
    ),
    ReferenceRoute(
        "basin_round",
        "mixed",
        start_deg=(36.527, -84.1325),
        goal_deg=(36.716, -84.1325),
        action=(1.0, 0.0),
        **_BASIN,
    ),
    ReferenceRoute(
        "basin_west",
        "informative",
        start_deg=(36.527, -84.245),
        goal_deg=(36.716, -84.245),
        action=(0.0, 0.0),
        **_BASIN,
    ),
    ReferenceRoute(
        "jacksboro_sw_ne",
        "informative",
        start_deg=(36.49, -84.37),
        goal_deg=(36.67, -84.25),
        action=(0.0, 0.0),
        **_JACKS,
    ),
    ReferenceRoute(
        "jacksboro_flat_patch",
        "mixed",
        start_deg=(36.52, -84.24),
        goal_deg=(36.70, -84.13),
        action=(0.0, 0.0),
        **_JACKS,
    ),
    # basin_west's start and goal, the offset saturated and reversed every second decision (west first):
    # ~4-5 reversals of 90 deg in the ~11 decisions to the goal, over informative terrain
    ReferenceRoute(
        "basin_weave",
        "weaving",
        start_deg=(36.527, -84.245),
        goal_deg=(36.716, -84.245),
        action=(-1.0, 0.0),
        cycle=((-1.0, 0.0), (-1.0, 0.0), (1.0, 0.0), (1.0, 0.0)),
        **_BASIN,
    ),
    # the same weave for ten decisions (4 reversals, to ~1.3 km from the goal), then straight in (offset 0)
    ReferenceRoute(
        "basin_weave_in",
        "weaving",
        start_deg=(36.527, -84.245),
        goal_deg=(36.716, -84.245),
        action=(-1.0, 0.0),
        cycle=((-1.0, 0.0), (-1.0, 0.0), (1.0, 0.0), (1.0, 0.0)) * 2 + ((-1.0, 0.0), (-1.0, 0.0)),
        after=(0.0, 0.0),
        **_BASIN,
    ),
)
# The full JSBSim loop's true error at the goal on every reference route, seeds 0..n-1, at the route task's
# full-tier settings (full_tier_settings(): JSBSim at 50 Hz, the task's TASK_RATES; ins_tercom taking the
# barometer's lag out of its terrain heights, its baro_lag_s from the scenario), per TERCOM fix noise of
# the navigator (FIX_NOISE_MODES: "fixed", fix_sigma_m per axis, the route task's; "batch", ins_tercom's
# default, the batch's own covariance, which the fast tier models in fix_noise.py), recorded with
# `python scripts/calibrate_fast_tier.py --tier full --seeds 256 [--fix-noise batch] --out DIR`
# (docs/validation/fast_tier.md): the default test compares the fast tier, flown now, with these; "first_8"
# holds the figures of seeds 0..RECHECKED_SEEDS-1 alone (the same 256-seed record's flights), which the
# slow test flies again, so that a change to the full loop that would leave these references stale fails
# there (the full loop gives the same episodes on every machine of ours: its 64-seed figures of an earlier
# session came back to the centimetre; any change to the loop moves every flight's error, so eight flights
# per route and fix-noise mode detect it as well as the whole record would). RECHECKED_ROUTES leaves out a
# route whose full-loop flights are another's: basin_weave_in's actions are basin_weave's until decision 11
# and the full loop arrives before it on every recorded seed (identical records, which a test checks).
RECHECKED_SEEDS = 8
RECHECKED_ROUTES = ("basin_straight", "basin_round", "basin_west", "jacksboro_sw_ne",
                    "jacksboro_flat_patch", "basin_weave")
FIX_NOISE_MODES = ("fixed", "batch")
FULL_LOOP_REFERENCE = {
    "basin_straight": {"mean_m": 448.09, "p90_m": 766.97, "n": 256,
     "first_8": {"mean_m": 334.21, "p90_m": 626.90}},
    "basin_round": {"mean_m": 13.29, "p90_m": 22.38, "n": 256,
     "first_8": {"mean_m": 8.33, "p90_m": 15.12}},
    "basin_west": {"mean_m": 27.33, "p90_m": 46.65, "n": 256,
     "first_8": {"mean_m": 23.03, "p90_m": 38.24}},
    "jacksboro_sw_ne": {"mean_m": 7.18, "p90_m": 13.76, "n": 256,
     "first_8": {"mean_m": 6.06, "p90_m": 10.80}},
    "jacksboro_flat_patch": {"mean_m": 8.18, "p90_m": 14.40, "n": 256,
     "first_8": {"mean_m": 10.20, "p90_m": 15.41}},
    "basin_weave": {"mean_m": 18.15, "p90_m": 32.18, "n": 256,
     "first_8": {"mean_m": 18.95, "p90_m": 30.38}},
    "basin_weave_in": {"mean_m": 18.15, "p90_m": 32.18, "n": 256,
     "first_8": {"mean_m": 18.95, "p90_m": 30.38}},
}
FULL_LOOP_REFERENCE_BATCH = {
    "basin_straight": {"mean_m": 176.65, "p90_m": 303.88, "n": 256,
     "first_8": {"mean_m": 191.60, "p90_m": 375.84}},
    "basin_round": {"mean_m": 10.97, "p90_m": 15.12, "n": 256,
     "first_8": {"mean_m": 7.10, "p90_m": 12.08}},
    "basin_west": {"mean_m": 16.71, "p90_m": 27.93, "n": 256,
     "first_8": {"mean_m": 14.00, "p90_m": 26.86}},
    "jacksboro_sw_ne": {"mean_m": 4.71, "p90_m": 9.55, "n": 256,
     "first_8": {"mean_m": 3.64, "p90_m": 5.97}},
    "jacksboro_flat_patch": {"mean_m": 5.17, "p90_m": 9.12, "n": 256,
     "first_8": {"mean_m": 5.73, "p90_m": 8.20}},
    "basin_weave": {"mean_m": 19.02, "p90_m": 25.64, "n": 256,
     "first_8": {"mean_m": 13.59, "p90_m": 20.59}},
    "basin_weave_in": {"mean_m": 19.02, "p90_m": 25.64, "n": 256,
     "first_8": {"mean_m": 13.59, "p90_m": 20.59}},
}
# Figures (route, "mean_m" or "p90_m") the fast tier does not hold within 25 % of FULL_LOOP_REFERENCE (and
# of FULL_LOOP_REFERENCE_BATCH), with the measured gap (docs/validation/fast_tier.md); the tests expect them
# to fail, so one that comes back into calibration is reported.
OUT_OF_CALIBRATION: dict[tuple[str, str], str] = {}
OUT_OF_CALIBRATION_BATCH = {
    ("jacksboro_flat_patch", "mean_m"): "+60 %: full 5.2 m, fast 8.2 (the full batch's dense IRA points: "
                                        "the full loop at 1 Hz flies 7.2 on seeds 0-127)",
    ("jacksboro_flat_patch", "p90_m"): "+61 %: full 9.1 m, fast 14.6 (as the mean)",
    ("basin_weave", "mean_m"): "-27 %: full 19.0 m, fast 13.9 (a few lost tracks decide it: +15 % on seeds "
                               "0-127)",
    ("basin_weave_in", "mean_m"): "-27 %: full 19.0 m, fast 13.9 (basin_weave's flights)",
}
# seeds per route in the fast tier, and in the recorded full loop
FAST_SEEDS = 256

ENV_SETTINGS = dict(
    decision_interval_s=30.0,
    max_episode_s=480.0,
    goal_radius_m=500.0,
    action_mode="pursuit",
    bearing_offset_max_deg=45.0,
    failure_penalty=20.0,
)


def full_tier_settings() -> dict:
    """The route task's full-tier-only settings (trn_env.env.route_task: ENV_COMMON's keys that are in
    FULL_TIER_ONLY: JSBSim's step `flight_dt_s`, the guidance rate and the scenario's sensor and navigator
    rates): the full loop is calibrated against as the task flies it."""
    from trn_env.env.route_task import ENV_COMMON, FULL_TIER_ONLY

    return {k: v for k, v in ENV_COMMON.items() if k in FULL_TIER_ONLY}


def route_by_name(name: str) -> ReferenceRoute:
    for r in REFERENCE_ROUTES:
        if r.name == name:
            return r
    raise ValueError(f"unknown reference route {name!r}; known: {[r.name for r in REFERENCE_ROUTES]}")


def env_kwargs(route: ReferenceRoute, fix_noise: str = "fixed") -> dict:
    """Constructor arguments (both tiers) of a route's env; fix_noise ("fixed", the route task's, or "batch",
    ins_tercom's own default): the navigator's TERCOM fix noise set in the route's scenario."""
    if fix_noise not in FIX_NOISE_MODES:
        raise ValueError(f"fix_noise: one of {FIX_NOISE_MODES}, got {fix_noise!r}")
    from trn_env.scenario.overrides import load_scenario_with

    scenario = load_scenario_with(route.scenario, [("navigator.settings.fix_noise", fix_noise)])
    return dict(
        scenario=scenario,
        agl_min_m=route.agl_min_m,
        agl_max_m=route.agl_max_m,
        goal_deg=route.goal_deg,
        **ENV_SETTINGS,
    )


def _sigma_h(sigma_ned_m) -> float:
    """The horizontal sigma (m): the hypot of the north and east sigmas."""
    return float(math.hypot(float(sigma_ned_m[0]), float(sigma_ned_m[1])))


def _end_error(info: dict) -> float:
    return float(info.get("true_miss_m", info["true_horizontal_error_m"]))


def fly_full(
    route: ReferenceRoute, seeds, settings: dict | None = None, fix_noise: str = "fixed"
) -> dict:
    """The route in TerrainNav-v0 (full JSBSim loop) once per seed, at the route task's full-tier settings
    (full_tier_settings()) with `settings` (constructor arguments) over them and the route's own: per-seed
    true error at the goal (m), terminations, the true horizontal error at each decision (m), wall time
    (construction included) and CPU seconds per decision."""
    from trn_env.env.terrain_nav import TerrainNavEnv

    t0 = time.perf_counter()
    tier = full_tier_settings()             # the task's scenario fields, with this run's fix noise
    tier["scenario_fields"] = {**tier["scenario_fields"], "navigator.settings.fix_noise": fix_noise}
    env = TerrainNavEnv(**{**env_kwargs(route, fix_noise), **tier, **(settings or {})})
    c0 = time.process_time()                  # per decision: the episodes' CPU, not the env's construction
    errors, ends, by_decision, sig_by_decision, n = [], [], [], [], 0
    for s in seeds:
        env.reset(seed=int(s), options={"start_deg": route.start_deg})
        by_decision.append([])
        sig_by_decision.append([])
        k = 0
        while True:
            _, _, term, trunc, info = env.step(route.action_at(k))
            by_decision[-1].append(float(info["true_horizontal_error_m"]))
            sig_by_decision[-1].append(_sigma_h(info["sigma_ned_m"]))
            n += 1
            k += 1
            if term or trunc:
                break
        errors.append(_end_error(info))
        ends.append(info["termination"])
    env.close()
    return {"errors_m": errors, "terminations": ends, "errors_by_decision_m": by_decision,
            "sigma_by_decision_m": sig_by_decision, "sigma_m": [r[-1] for r in sig_by_decision],
            "wall_s": time.perf_counter() - t0, "cpu_s_per_decision": (time.process_time() - c0) / max(n, 1)}


def fly_fast(route: ReferenceRoute, seeds, fix_noise: str = "fixed") -> dict:
    """The route in TerrainNavFast-v0, one sub-env per seed, all in one vector env (fix_noise: as
    env_kwargs')."""
    from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv

    t0 = time.perf_counter()
    seeds = [int(s) for s in seeds]
    env = TerrainNavFastVectorEnv(num_envs=len(seeds), **env_kwargs(route, fix_noise))
    env.reset(seed=seeds, options={"start_deg": route.start_deg})
    errors = [math.nan] * len(seeds)
    sigmas = [math.nan] * len(seeds)
    ends: list = [None] * len(seeds)
    by_decision: list = [[] for _ in seeds]
    sig_by_decision: list = [[] for _ in seeds]
    done = np.zeros(len(seeds), bool)
    k = 0
    while not done.all():
        _, _, term, trunc, info = env.step(np.tile(route.action_at(k), (len(seeds), 1)))
        k += 1
        for i in np.flatnonzero(~done):
            by_decision[i].append(float(info["true_horizontal_error_m"][i]))
            sig_by_decision[i].append(_sigma_h(info["sigma_ned_m"][i]))
        new = (term | trunc) & ~done
        for i in np.flatnonzero(new):
            errors[i] = (
                float(info["true_miss_m"][i])
                if info["termination"][i] == "arrived"
                else float(info["true_horizontal_error_m"][i])
            )
            sigmas[i] = sig_by_decision[i][-1]
            ends[i] = str(info["termination"][i])
        done |= new
    env.close()
    return {"errors_m": errors, "terminations": ends, "sigma_m": sigmas, "errors_by_decision_m": by_decision,
            "sigma_by_decision_m": sig_by_decision, "wall_s": time.perf_counter() - t0}


def summary(errors) -> dict:
    e = np.asarray(errors, float)
    return {"mean_m": float(np.mean(e)), "p90_m": float(np.percentile(e, 90)), "n": int(e.size)}


def compare(full: dict, fast: dict) -> dict:
    """Relative differences (fast / full - 1) of the mean and the 90th percentile."""
    f, q = summary(full["errors_m"]), summary(fast["errors_m"])
    return {
        "full": f,
        "fast": q,
        "mean_rel": q["mean_m"] / f["mean_m"] - 1.0,
        "p90_rel": q["p90_m"] / f["p90_m"] - 1.0,
    }


__all__ = [
    "ENV_SETTINGS",
    "FAST_SEEDS",
    "FIX_NOISE_MODES",
    "FULL_LOOP_REFERENCE_BATCH",
    "OUT_OF_CALIBRATION",
    "OUT_OF_CALIBRATION_BATCH",
    "FULL_LOOP_REFERENCE",
    "REFERENCE_ROUTES",
    "ReferenceRoute",
    "compare",
    "env_kwargs",
    "fly_fast",
    "full_tier_settings",
    "fly_full",
    "route_by_name",
    "summary",
]
