"""Env episodes as campaign runs: a policy flies `TerrainNav-v0` episodes over goals and seeds, one
campaign row per episode, on the campaign backends (local process pool, Ray) and into a campaign folder
(manifest, one Parquet row per run, `resume`).

    campaign = episode_campaign({
        "name": "route_bench_basin",
        "env": {"scenario": "basin_route", "decision_interval_s": 5.0, "max_episode_s": 480.0, ...},
        "policies": [{"label": "straight", "kind": "straight", "agl_m": 600.0},
                     {"label": "planner", "kind": "planner", "agl_m": 600.0, "config": {"weight": 3.0}},
                     {"label": "ppo", "kind": "sb3", "model": "out/ppo_basin.zip"},
                     {"label": "random", "kind": "random"}],
        "goals_deg": "held_out",            # the env's documented held-out goals, or [[lat, lon], ...]
        "seeds": [1000, 1001, 1002, 1003],  # episode (reset) seeds; or a count drawn from root_seed
    })
    run_campaign(campaign, "out/episodes", backend=make_backend("local"))
    rows = read_rows("out/episodes")         # pandas, one row per episode

A variant is one (policy, goal); every variant flies every seed, and seed s is the same `env.reset(seed=s)`
in every variant (common random numbers: the policies meet the same sensor noise, turbulence and initial
navigation error). The env is built once per worker process from its arguments (its terrain and map error
come from the scenario seed), and each episode's randomness from the reset seed, so an episode's row is the
same bits whichever worker flies it and in whatever order (`fly_episode` on a fresh process gives it too).
Policy kinds: "straight" (`StraightLinePolicy`), "planner" (`PlannerPolicy` with a `PlannerConfig` from
"config"), "sb3" (a saved stable-baselines3 model, deterministic actions, or with `"deterministic": false`
samples of its action distribution from torch's generator seeded by the episode seed; the `rl` extra),
"random" (uniform actions drawn from a generator seeded by the episode seed). The campaign hash covers the
spec and the bytes of every model file, so `resume` refuses a folder made with another model.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trn_env.campaign.spec import MAX_RUNS, CampaignError, RunKey, SeedMajorRuns, draw_seeds

POLICY_KINDS = ("straight", "planner", "sb3", "random")
# columns of an episode row (besides the run bookkeeping ones); floats are NaN where they do not apply
EPISODE_FLOAT_KEYS = ("goal_lat_deg", "goal_lon_deg", "start_lat_deg", "start_lon_deg", "true_miss_m",
                      "final_true_error_m", "distance_flown_m", "straight_distance_m",
                      "extra_distance_fraction", "return", "sim_time_s", "wall_time_s")


@dataclass(frozen=True)
class PolicyVariant:
    """One (policy, goal) of an episode campaign; `navigator` gives the label for the driver's manifest."""

    index: int
    label: str
    policy: dict
    goal_deg: tuple[float, float]

    @property
    def navigator(self):              # the driver lists the campaign's labels by `variant.navigator.label`
        return self


@dataclass(frozen=True)
class EpisodeTask(RunKey):
    """Everything a worker needs to fly one episode (picklable, small)."""

    policy_label: str
    policy: dict
    env: dict
    goal_deg: tuple[float, float]
    attempt: int = 1
    kind: str = "episode"


@dataclass
class EpisodeCampaign(SeedMajorRuns):
    """A validated episode campaign; runs through `trn_env.campaign.driver.run_campaign` as a Campaign."""

    env: dict
    variants: list[PolicyVariant]
    sweep_paths: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    def tasks(self, skip: set[str]):
        """The campaign's episodes not in `skip`, seed-major, made lazily."""
        for index, si, seed, v, run_id in self.pending_runs(skip):
            yield EpisodeTask(campaign=self.name, campaign_hash=self.hash, run_id=run_id, run_index=index,
                              variant_index=v.index, seed_index=si, seed=int(seed), policy_label=v.label,
                              policy=v.policy, env=self.env, goal_deg=v.goal_deg)


def _check_policy(i: int, p: Any) -> dict:
    at = f"policies[{i}]"
    if not isinstance(p, dict):
        raise CampaignError("episode campaign", [f"{at}: must be a table with label and kind, got {p!r}"])
    problems = []
    unknown = set(p) - {"label", "kind", "agl_m", "config", "model", "replan_every", "lookahead_m",
                        "deterministic"}
    if unknown:
        problems.append(f"{at}: unknown keys {sorted(unknown)}")
    if not isinstance(p.get("label"), str) or not p.get("label"):
        problems.append(f"{at}.label: a non-empty string is required")
    if p.get("kind") not in POLICY_KINDS:
        problems.append(f"{at}.kind: must be one of {POLICY_KINDS}, got {p.get('kind')!r}")
    if p.get("kind") == "sb3":
        model = p.get("model")
        if not isinstance(model, str) or not Path(model).is_file():
            problems.append(f"{at}.model: a saved stable-baselines3 model file is required, got {model!r}")
    if not isinstance(p.get("deterministic", True), bool):
        problems.append(f"{at}.deterministic: true or false, got {p.get('deterministic')!r}")
    if problems:
        raise CampaignError("episode campaign", problems)
    out = copy.deepcopy(p)
    if out.get("kind") == "sb3":
        out["model"] = str(Path(out["model"]).resolve())
    return out


def episode_campaign(spec: dict, source: str = "episode campaign") -> EpisodeCampaign:
    """Validate an episode campaign spec (see the module docstring); CampaignError naming each problem."""
    from trn_env.env.terrain_nav import TerrainNavEnv

    if not isinstance(spec, dict):
        raise CampaignError(source, [f"spec: must be a dict, got {type(spec).__name__}"])
    unknown = set(spec) - {"name", "description", "env", "policies", "goals_deg", "seeds", "root_seed"}
    if unknown:
        raise CampaignError(source, [f"{k}: unknown key (allowed: name, description, env, policies, "
                                     "goals_deg, seeds, root_seed)" for k in sorted(unknown)])
    problems = []
    name = spec.get("name", "episodes")
    if not isinstance(name, str) or not name:
        problems.append("name: a non-empty string is required")
    env_spec = spec.get("env")
    if not isinstance(env_spec, dict) or not isinstance(env_spec.get("scenario"), str):
        problems.append("env: a table of TerrainNavEnv arguments with `scenario` (a built-in name or a path) "
                        "is required")
    policies = spec.get("policies")
    if not isinstance(policies, list) or not policies:
        problems.append("policies: a non-empty list of policy tables is required")
    seeds = spec.get("seeds")
    if isinstance(seeds, bool) or not (
            (isinstance(seeds, int) and seeds >= 1)
            or (isinstance(seeds, list) and seeds and len(set(seeds)) == len(seeds)
                and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds))):
        problems.append(f"seeds: a count >= 1 or a list of distinct seeds >= 0, got {seeds!r}")
    if problems:
        raise CampaignError(source, problems)
    pols = [_check_policy(i, p) for i, p in enumerate(policies)]
    labels = [p["label"] for p in pols]
    dup = sorted({lab for lab in labels if labels.count(lab) > 1})
    if dup:
        raise CampaignError(source, [f"policies: label(s) {dup} used twice"])
    env_spec = json.loads(json.dumps(env_spec))      # plain JSON types: tuples become lists
    try:
        env = TerrainNavEnv(**env_spec)
    except (TypeError, ValueError) as exc:
        raise CampaignError(source, [f"env: {exc}"]) from None
    goals = spec.get("goals_deg", "held_out")
    try:
        if goals == "held_out":
            goals = [tuple(g) for g in env.held_out_goals_deg]
            if not goals:
                raise ValueError("the env has no held-out goals (give goal_region_deg or held_out_goals_deg)")
        else:
            goals = [env._check_point(f"goals_deg[{k}]", g) for k, g in enumerate(goals)]
        for p in pols:
            if p["kind"] == "planner":
                from trn_env.guidance.planner import PlannerConfig
                PlannerConfig(**{"tas_mps": env.tas_mps, **p.get("config", {})})
    except (TypeError, ValueError) as exc:
        raise CampaignError(source, [f"goals_deg / policies: {exc}"]) from None
    finally:
        env.close()
    n_runs = (len(seeds) if isinstance(seeds, list) else seeds) * len(pols) * len(goals)
    if n_runs > MAX_RUNS:           # counted before the seeds are drawn (spec.MAX_RUNS)
        raise CampaignError(source, [f"seeds: the campaign asks for {n_runs:,} episodes "
                                     f"({len(seeds) if isinstance(seeds, list) else seeds:,} seeds x "
                                     f"{len(pols)} policies x {len(goals)} goals), more than {MAX_RUNS:,}: "
                                     "split it into campaigns of fewer episodes"])
    seed_list = list(seeds) if isinstance(seeds, list) else draw_seeds(spec.get("root_seed", 0), seeds)
    variants = [PolicyVariant(index=k, label=p["label"], policy=p, goal_deg=(float(g[0]), float(g[1])))
                for k, (p, g) in enumerate((p, g) for p in pols for g in goals)]
    text = json.dumps({"name": name, "env": env_spec, "policies": pols, "goals_deg": goals,
                       "seeds": seed_list}, sort_keys=True, indent=1)
    h = hashlib.sha256(text.encode())
    for p in pols:
        if p["kind"] == "sb3":
            h.update(Path(p["model"]).read_bytes())
    return EpisodeCampaign(name=name, source=source, description=str(spec.get("description", "")),
                           hash=h.hexdigest(), text=text, seeds=seed_list, env=env_spec, variants=variants)


# ------------------------------------------------------------------------------------------ worker side
_ENVS: dict[str, Any] = {}
_POLICIES: dict[str, Any] = {}


def _env(env_spec: dict):
    from trn_env.env.terrain_nav import TerrainNavEnv

    key = json.dumps(env_spec, sort_keys=True)
    env = _ENVS.get(key)
    if env is None:
        env = _ENVS[key] = TerrainNavEnv(**env_spec)
    return key, env


class RandomPolicy:
    """Uniform actions over the env's action space, from a generator seeded per episode."""

    def __init__(self, env):
        self.space = env.action_space
        self.rng = np.random.default_rng(0)

    def seed(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        lo, hi = self.space.low, self.space.high
        return self.rng.uniform(lo, hi).astype(np.float32), None


class SampledPolicy:
    """A stable-baselines3 model acting by samples of its action distribution (as during training), from
    torch's generator seeded per episode."""

    def __init__(self, model):
        self.model = model

    def seed(self, seed: int) -> None:
        import torch
        torch.manual_seed(int(seed))
        self._steps = 0

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = False):
        # gSDE (use_sde): draw the exploration matrix at the episode's start and every sde_sample_freq
        # steps, as PPO's rollouts do, from the generator seeded above
        if getattr(self.model, "use_sde", False):
            freq = int(getattr(self.model, "sde_sample_freq", -1))
            if getattr(self, "_steps", 0) == 0 or (freq > 0 and self._steps % freq == 0):
                self.model.policy.reset_noise()
            self._steps = getattr(self, "_steps", 0) + 1
        return self.model.predict(obs, deterministic=False)


def make_policy(spec: dict, env):
    """A policy object with `predict(obs, deterministic=True) -> (action, state)` from a policy table."""
    kind = spec["kind"]
    if kind == "straight":
        from trn_env.env.policies import StraightLinePolicy
        return StraightLinePolicy(env, agl_m=spec.get("agl_m"))
    if kind == "planner":
        from trn_env.env.policies import PlannerPolicy
        from trn_env.guidance.planner import PlannerConfig
        cfg = {"tas_mps": env.tas_mps, **({"agl_m": spec["agl_m"]} if spec.get("agl_m") else {}),
               **spec.get("config", {})}
        return PlannerPolicy(env, PlannerConfig(**cfg), replan_every=int(spec.get("replan_every", 1)),
                             lookahead_m=float(spec.get("lookahead_m", 2500.0)))
    if kind == "sb3":
        import torch
        from stable_baselines3 import PPO
        torch.set_num_threads(1)         # the pool has a process per core already
        model = PPO.load(spec["model"], device="cpu")
        return model if spec.get("deterministic", True) else SampledPolicy(model)
    if kind == "random":
        return RandomPolicy(env)
    raise ValueError(f"policy kind must be one of {POLICY_KINDS}, got {kind!r}")


def _policy(env_key: str, spec: dict, env):
    key = env_key + json.dumps(spec, sort_keys=True)
    pol = _POLICIES.get(key)
    if pol is None:
        pol = _POLICIES[key] = make_policy(spec, env)
    return pol


def _base_row(task: EpisodeTask) -> dict:
    from trn_env.campaign.runs import versions

    row = {
        "campaign": task.campaign, "campaign_hash": task.campaign_hash, "run_id": task.run_id,
        "run_index": task.run_index, "variant_index": task.variant_index, "seed_index": task.seed_index,
        "seed": task.seed, "scenario": str(task.env.get("scenario")), "policy": task.policy_label,
        "policy_kind": task.policy["kind"], "navigator": task.policy_label,
        "termination": "error", "error": None, "attempts": task.attempt, "arrived": False,
        "collision": False, "steps": 0, "host": socket.gethostname(), "pid": os.getpid(),
    }
    row.update(versions())
    for k in EPISODE_FLOAT_KEYS:
        row[k] = float("nan")
    row["goal_lat_deg"], row["goal_lon_deg"] = float(task.goal_deg[0]), float(task.goal_deg[1])
    return row


def run_episode(env, policy, seed: int, goal_deg) -> dict:
    """Fly one episode of `policy` on `env` from `reset(seed=seed, options={"goal_deg": goal_deg})`; its
    figures (the campaign row's episode columns)."""
    from trn_env.terrain.geodesy import latlon_to_ned_offset

    obs, info0 = env.reset(seed=int(seed), options={"goal_deg": tuple(goal_deg)})
    if hasattr(policy, "reset"):
        policy.reset()
    if isinstance(policy, (RandomPolicy, SampledPolicy)):   # (an sb3 model's `seed` is its int seed)
        policy.seed(int(seed))
    ret, done, info, steps = 0.0, False, info0, 0
    while not done:
        action, _ = policy.predict(obs, deterministic=True)
        obs, r, term, trunc, info = env.step(np.asarray(action, np.float32))
        ret += float(r)
        steps += 1
        done = term or trunc
    s, g = info0["start_deg"], info0["goal_deg"]
    dn, de = latlon_to_ned_offset(math.radians(s[0]), math.radians(s[1]), 0.0, math.radians(g[0]),
                                  math.radians(g[1]))
    straight_m = math.hypot(dn, de)
    arrived = info["termination"] == "arrived"
    # the route flown to arrival against the straight line to the arrival circle
    extra = info["distance_flown_m"] / max(straight_m - env.goal_radius_m, 1.0) - 1.0
    return {
        "start_lat_deg": float(s[0]), "start_lon_deg": float(s[1]),
        "termination": str(info["termination"]), "arrived": bool(arrived),
        "true_miss_m": float(info["true_miss_m"]) if arrived else float("nan"),
        "final_true_error_m": float(info["true_horizontal_error_m"]),
        "distance_flown_m": float(info["distance_flown_m"]), "straight_distance_m": float(straight_m),
        "extra_distance_fraction": float(extra) if arrived else float("nan"),
        "collision": info["termination"] == "terrain_collision", "return": ret, "steps": steps,
        "sim_time_s": float(info["t_s"]),
    }


def fly_episode(task: EpisodeTask, dems: dict | None = None) -> tuple[dict, None]:
    """One episode into its row (runs in a backend worker; env and policy cached per process). Never raises
    on the episode's own failure: the row carries termination 'error' and the message."""
    row = _base_row(task)
    t0 = time.perf_counter()
    try:
        key, env = _env(task.env)
        pol = _policy(key, task.policy, env)
        row.update(run_episode(env, pol, task.seed, task.goal_deg))
        row["error"] = None
    except Exception as exc:  # noqa: BLE001 - an episode's failure is its row, not the campaign's end
        row["termination"] = "error"
        row["error"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=6)}"
    row["wall_time_s"] = time.perf_counter() - t0
    return row, None


def died_episode_row(task: EpisodeTask, why: str) -> dict:
    row = _base_row(task)
    row["error"] = why
    return row


__all__ = ["EpisodeCampaign", "EpisodeTask", "PolicyVariant", "RandomPolicy", "SampledPolicy",
           "episode_campaign", "fly_episode", "make_policy", "run_episode"]
