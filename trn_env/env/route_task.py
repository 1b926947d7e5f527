"""The reference route task: the settings that every tier, trainer and baseline of the route benchmark share.

    from trn_env.env.route_task import env_kwargs, EVAL_SEEDS
    env = gymnasium.make("trn_env/TerrainNav-v0", **env_kwargs("basin"))

A GNSS-denied King Air flies from a start drawn in the terrain's start region to a goal drawn in its goal
region (at least `min_goal_distance_m` apart, never within `held_out_radius_m` of a held-out goal) with the
route benchmark's coarse decisions (`action_mode="pursuit"`, 30 s decisions, +-45 deg offsets from the goal's
bearing, height above ground in [agl_min_m, agl_max_m]); the episode ends when the navigator's ESTIMATE is
within `goal_radius_m` of the goal, and the TRUE miss there (the true horizontal navigation error) is what the
task scores. Evaluation: the env's five held-out goals of the goal region (`env.held_out_goals_deg`) times
`EVAL_SEEDS` (episode seeds disjoint from every training seed: training seeds are `TRAIN_SEED_BASE + k`).
The terrains (docs/guide/route_task.md):

- `basin`: synthetic rolling hills (rms 60 m) with a flat basin of 6 km radius between the start region
  (south) and the goal region (north); the straight route dead-reckons ~12 km over the basin.
- `jacksboro`: the bundled real DEM (rough almost everywhere), south-west to north-east.

The full-fidelity tier flies JSBSim at 50 Hz (`flight_dt_s = 0.02`; the IMU samples at the step rate): the
King Air's trajectory departs from the 100 Hz one by as much as the 100 Hz one departs from 200 Hz
(docs/validation/route_task.md), at half the cost. Its sensor, filter and navigator rates (TASK_RATES, in
ENV_COMMON): the IRA at its 50 Hz with each 3 consecutive samples entered into the navigator's TERCOM
batch as their mean (`ira_average`), the navigator's covariance steps at 10 Hz, an estimate every 2 s
(arrival judged on each), guidance re-aiming at 1 Hz on it dead-reckoned: 1.3-1.5x the agent steps per CPU
second of the scenario's own rates, with no significant change of the true miss on any calibration route
(32 paired seeds each, the informative basin route 96; docs/validation/env_speed.md).
`env_kwargs(terrain, decision_rates=True)` replaces them with `DECISION_RATES`: the IRA at 10 Hz (samples
8.5 m apart at 85 m/s instead of 1.7 m, none averaged): cheaper still, but the informative routes' true
miss grows by ~3-4 m (15-19 %, significant over 48 paired seeds), so it is opt-in (to train or screen on
the full tier, score on the default).
"""

from __future__ import annotations

import copy

TERRAINS: dict[str, dict] = {
    # start south of the basin, goals just past its north rim (basin centre 36.635 N, radius ~6 km)
    "basin": dict(
        scenario="basin_route",
        agl_m=600.0,
        env=dict(
            agl_min_m=300.0, agl_max_m=900.0,      # action 0 holds 600 m, the straight line's height
            start_region_deg=(36.515, 36.54, -84.16, -84.105),
            goal_region_deg=(36.70, 36.735, -84.20, -84.065),
            held_out_radius_m=1500.0,
        ),
    ),
    # the real DEM (rough almost everywhere): south-west to north-east
    "jacksboro": dict(
        scenario="default",
        agl_m=1000.0,
        env=dict(
            agl_min_m=500.0, agl_max_m=1500.0,
            start_region_deg=(36.47, 36.50, -84.39, -84.35),
            goal_region_deg=(36.64, 36.70, -84.22, -84.12),
            held_out_radius_m=1500.0,
        ),
    ),
}
# the full tier's navigator keeps ins_tercom's "fixed" TERCOM fix noise (the fast tier's default model and the
# mode its calibration holds in, docs/validation/fast_tier.md; ins_tercom's own default is "batch");
# the full tier's rates at 30 s decisions (see above): the IRA's 50 Hz samples averaged by 3 into the TERCOM
# batch, covariance steps at 10 Hz, an estimate every 2 s (logged at each), guidance at 1 Hz
TASK_RATES: dict = dict(guidance_rate_hz=1.0, scenario_fields={
    "navigator.settings.fix_noise": "fixed", "navigator.settings.ira_average": 3,
    "navigator.settings.ekf_rate_hz": 10.0, "navigator.rate_hz": 0.5,
    "guidance.log_rate_hz": 0.5})
ENV_COMMON: dict = dict(decision_interval_s=30.0, max_episode_s=480.0, goal_radius_m=500.0,
                        action_mode="pursuit", bearing_offset_max_deg=45.0, failure_penalty=20.0,
                        sigma_shaping_weight=0.0, flight_dt_s=0.02, **TASK_RATES)
# opt-in (env_kwargs(..., decision_rates=True)), replacing TASK_RATES: the IRA itself at 10 Hz - cheaper, at
# a measured cost in the informative routes' miss (docs/validation/env_speed.md): not the task's default
DECISION_RATES: dict = dict(guidance_rate_hz=1.0, scenario_fields={
    "navigator.settings.fix_noise": "fixed", "sensors.ira.rate_hz": 10.0,
    "navigator.settings.ekf_rate_hz": 10.0, "navigator.rate_hz": 0.5,
    "guidance.log_rate_hz": 0.5})
# settings only the full-fidelity tier has (JSBSim's step, the guidance rate, the pipelined nav stage, the
# scenario's sensor and filter rates): a fast-tier env is built from the same keyword arguments without them
FULL_TIER_ONLY: tuple[str, ...] = ("flight_dt_s", "guidance_rate_hz", "pipeline", "scenario_fields")
# episode seeds of the evaluation (held-out goals x these seeds: 1,000 episodes per policy and tier; a policy
# loses the track in ~0.1-2 % of episodes, and over ten seeds per goal whether one of 50 episodes did decides
# the mean: docs/validation/route_task.md); training seeds start at TRAIN_SEED_BASE
EVAL_SEEDS: tuple[int, ...] = tuple(range(1000, 1200))
TRAIN_SEED_BASE = 0
# episode seeds of model selection (the fast tier, goals drawn from the training distribution, never a
# held-out goal): disjoint from EVAL_SEEDS and from the trainer's reset seeds. 20,000 of them: a policy's
# lost fixes are ~1 % of episodes, and over 2,000 episodes a rate's standard error (~0.2 %) is as large as
# the differences between late checkpoints (docs/validation/route_task.md, "Tenth session")
VALIDATION_SEEDS: tuple[int, ...] = tuple(range(100_000, 120_000))
# the training budget: 30 minutes on 2 cores, held as CPU seconds (what 30 minutes on 2 idle cores give at
# most), so that a run on a shared machine is held to the same amount of computation as one on an idle machine
TRAIN_BUDGET = {"wall_s": 1800.0, "cores": 2, "cpu_s": 3600.0}
GYM_IDS = {"full": "trn_env/TerrainNav-v0", "fast": "trn_env/TerrainNavFast-v0"}


def env_kwargs(terrain: str, decision_rates: bool = False) -> dict:
    """TerrainNav-v0 keyword arguments of the task on a terrain (plain JSON types: a worker process or a
    Ray actor can rebuild exactly this env from them; `fast_tier_kwargs` of them build TerrainNavFast-v0);
    `decision_rates` replaces the task's rates (TASK_RATES) with DECISION_RATES (see above). ValueError
    naming the terrain if unknown."""
    if terrain not in TERRAINS:
        raise ValueError(f"terrain must be one of {sorted(TERRAINS)}, got {terrain!r}")
    if not isinstance(decision_rates, bool):
        raise ValueError(f"decision_rates must be True or False, got {decision_rates!r}")
    t = TERRAINS[terrain]
    kw = {"scenario": t["scenario"], **copy.deepcopy(ENV_COMMON), **copy.deepcopy(t["env"])}
    if decision_rates:
        kw.update(copy.deepcopy(DECISION_RATES))
    for k in ("start_region_deg", "goal_region_deg"):
        kw[k] = list(kw[k])
    return kw


def straight_agl_m(terrain: str) -> float:
    """The height above ground (m) that the straight-line and planner baselines fly on a terrain."""
    if terrain not in TERRAINS:
        raise ValueError(f"terrain must be one of {sorted(TERRAINS)}, got {terrain!r}")
    return float(TERRAINS[terrain]["agl_m"])


def fast_tier_kwargs(kw: dict) -> dict:
    """The task's keyword arguments without the full tier's own settings (FULL_TIER_ONLY): what
    TerrainNavFast-v0 takes."""
    return {k: v for k, v in kw.items() if k not in FULL_TIER_ONLY}
