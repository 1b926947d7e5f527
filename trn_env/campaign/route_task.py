"""The reference route task's evaluation: baselines and a trained policy in both env tiers on the same
held-out goals and seeds, paired statistics, a table and a learning-curve plot.

    rows = evaluate(policies, "basin", seeds, tiers=("full", "fast"))
    summary = summarise(rows)                # per (tier, policy): success, miss mean / p90, extra distance...
    text = table(summary)

Policies (dicts): {"label", "kind": "straight" | "planner" | "random" | "rllib", "checkpoint": path (rllib)}.
"straight" flies the pursuit action 0 (the straight line to the goal from the estimate) at the terrain's
height; "planner" the terrain-information planner's route from the navigator's map, replanned at every
decision (trn_env.env.policies.PlannerPolicy); "random" uniform actions from a generator seeded by the
episode seed; "rllib" the mean action of a PPO RLModule (trn_env.env.rllib_train). Every policy flies every
(held-out goal, seed) pair, and seed s is the same `reset(seed=s)` for every policy (common random numbers),
so the comparisons are paired. Full tier: TerrainNav-v0 episodes one after another (trn_env.campaign.episodes'
`run_episode`); fast tier: one TerrainNavFast-v0 vector env with a sub-env per (goal, seed), each sub-env's
first episode kept.

Statistics (`paired`): over the (goal, seed) pairs where both policies arrived, the mean true miss of each,
the relative improvement 1 - mean(a) / mean(b) with a percentile-bootstrap 95 % interval (resampling pairs,
`N_BOOTSTRAP` resamples, generator seeded 0), and the one-sided sign test of "a misses less than b" (ties
dropped; p = P(X >= wins) for X ~ Binomial(n, 1/2)).
"""

from __future__ import annotations

import math
import types
from pathlib import Path

import numpy as np

from trn_env.env import route_task

N_BOOTSTRAP = 2000
POLICY_KINDS = ("straight", "planner", "random", "rllib")


class RLlibPolicy:
    """The mean action of an RLlib PPO module trained on observations rescaled to [-1, 1] by the observation
    space's bounds (trn_env.env.rllib); `predict(obs)` takes the env's raw observation (one or a batch)."""

    def __init__(self, checkpoint: str | Path, observation_space):
        from trn_env.env.rllib_train import module_from_checkpoint

        self.module = module_from_checkpoint(checkpoint)
        self.low = observation_space.low.astype(np.float64)
        self.span = (observation_space.high - observation_space.low).astype(np.float64)

    def scale(self, obs: np.ndarray) -> np.ndarray:
        return (-1.0 + 2.0 * (np.asarray(obs, np.float64) - self.low) / self.span).astype(np.float32)

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        import torch
        from ray.rllib.core.columns import Columns

        x = self.scale(obs)
        single = x.ndim == 1
        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: torch.as_tensor(np.atleast_2d(x))})
        a = out[Columns.ACTION_DIST_INPUTS].numpy()
        a = np.clip(a[:, : a.shape[1] // 2], -1.0, 1.0).astype(np.float32)
        return (a[0] if single else a), None


def goal_view(full, goal_deg) -> types.SimpleNamespace:
    """What a baseline policy reads of a TerrainNav-v0 `full` (its map, action limits and spaces) with the
    goal at goal_deg (lat, lon in degrees): the fast tier's sub-envs and open-loop searches build their
    policies on it."""
    return types.SimpleNamespace(
        action_mode=full.action_mode, bearing_offset_max_rad=full.bearing_offset_max_rad,
        agl_min_m=full.agl_min_m, agl_max_m=full.agl_max_m, action_limits=full.action_limits,
        map_dem=full.map_dem, tas_mps=full.tas_mps, goal_radius_m=full.goal_radius_m,
        goal_lat_rad=math.radians(goal_deg[0]), goal_lon_rad=math.radians(goal_deg[1]),
        observation_space=full.observation_space, action_space=full.action_space)


def _check_policies(policies: list[dict]) -> list[dict]:
    labels = []
    for i, p in enumerate(policies):
        if not isinstance(p, dict) or p.get("kind") not in POLICY_KINDS:
            raise ValueError(f"policies[{i}]: kind must be one of {POLICY_KINDS}, got {p!r}")
        if p["kind"] == "rllib" and not Path(str(p.get("checkpoint", ""))).is_dir():
            raise ValueError(f"policies[{i}]: rllib checkpoint {p.get('checkpoint')!r} is not a folder")
        labels.append(str(p.get("label", p["kind"])))
    if len(set(labels)) != len(labels):
        raise ValueError(f"policies: labels must differ, got {labels}")
    return [{**p, "label": lab} for p, lab in zip(policies, labels, strict=True)]


def _make(spec: dict, env, agl_m: float):
    """A policy object for one env (the full env, or a per-sub-env view of the fast tier)."""
    from trn_env.campaign.episodes import make_policy

    if spec["kind"] == "rllib":
        return RLlibPolicy(spec["checkpoint"], env.observation_space)
    if spec["kind"] in ("straight", "planner"):
        return make_policy({**spec, "agl_m": agl_m}, env)
    return make_policy(spec, env)


def evaluate_full(policies: list[dict], terrain: str, seeds, env_overrides: dict | None = None) -> list[dict]:
    """Every policy on every (held-out goal, seed) in TerrainNav-v0; one row per episode."""
    from trn_env.campaign.episodes import RandomPolicy, run_episode
    from trn_env.env.terrain_nav import TerrainNavEnv

    pols = _check_policies(policies)
    kw = {**route_task.env_kwargs(terrain), **(env_overrides or {})}
    env = TerrainNavEnv(**kw)
    agl = route_task.straight_agl_m(terrain)
    rows = []
    try:
        goals = [tuple(g) for g in env.held_out_goals_deg]
        for p in pols:
            pol = _make(p, env, agl)
            for gi, g in enumerate(goals):
                for s in seeds:
                    if isinstance(pol, RandomPolicy):
                        pol.seed(int(s))
                    r = run_episode(env, pol, int(s), g)
                    rows.append({"tier": "full", "policy": p["label"], "goal_index": gi, "seed": int(s), **r})
    finally:
        env.close()
    return rows


def evaluate_fast(policies: list[dict], terrain: str, seeds, env_overrides: dict | None = None,
                  drawn_goals: bool = False) -> list[dict]:
    """Every policy on every (held-out goal, seed) in TerrainNavFast-v0: one vector env with a sub-env per
    (goal, seed), stepped until every sub-env's first episode has ended; one row per episode. With
    `drawn_goals` the held-out goals are not flown: one sub-env per seed, its goal drawn by the env from the
    training distribution (the goal region outside the held-out radius; rows' `goal_index` -1, `goal_deg`
    the drawn goal) - the validation episodes of `select_checkpoint`. ValueError if the fast tier is not
    registered."""
    import gymnasium as gym

    from trn_env.env.rllib import FAST_ID
    from trn_env.env.terrain_nav import TerrainNavEnv
    from trn_env.terrain.geodesy import latlon_to_ned_offset

    if FAST_ID not in gym.registry:
        raise ValueError(f"{FAST_ID} is not registered: the fast tier is not installed")
    pols = _check_policies(policies)
    kw = {**route_task.env_kwargs(terrain), **(env_overrides or {})}
    full = TerrainNavEnv(**kw)                     # the map, limits and held-out goals the policies read
    goals = [tuple(g) for g in full.held_out_goals_deg]
    pairs = ([(-1, None, int(s)) for s in seeds] if drawn_goals else
             [(gi, g, int(s)) for gi, g in enumerate(goals) for s in seeds])
    n = len(pairs)
    agl = route_task.straight_agl_m(terrain)
    rows = []
    for p in pols:
        venv = gym.make_vec(FAST_ID, num_envs=n, vectorization_mode="vector_entry_point",
                            **route_task.fast_tier_kwargs(kw))
        obs, info0 = venv.reset(seed=[s for _, _, s in pairs], options=None if drawn_goals else
                                {"goal_deg": np.array([g for _, g, _ in pairs])})
        if drawn_goals:
            pairs = [(-1, tuple(float(x) for x in info0["goal_deg"][i]), s)
                     for i, (_, _, s) in enumerate(pairs)]
        views, pol_objs = [], []
        shared = None
        for _gi, g, s in pairs:
            view = goal_view(full, g)
            views.append(view)
            if p["kind"] == "rllib":
                shared = shared or _make(p, full, agl)
                pol_objs.append(shared)
                continue
            pol = _make(p, view, agl)
            if p["kind"] == "planner":
                shared = shared or pol.planner
                pol.planner = shared
            if hasattr(pol, "seed"):
                pol.seed(s)
            pol_objs.append(pol)
        done = np.zeros(n, bool)
        ret = np.zeros(n)
        last = [None] * n
        steps = np.zeros(n, int)
        while not done.all():
            if p["kind"] == "rllib":
                act = shared.predict(obs)[0]
            else:
                act = np.stack([np.asarray(pol_objs[i].predict(obs[i])[0], np.float32) if not done[i]
                                else np.zeros(2, np.float32) for i in range(n)])
            obs, r, term, trunc, info = venv.step(act)
            ended = (term | trunc) & ~done
            ret[~done] += r[~done]
            steps[~done] += 1
            for i in np.flatnonzero(ended):
                last[i] = {k: (v[i] if isinstance(v, np.ndarray) and v.shape[:1] == (n,) else v)
                           for k, v in info.items() if not k.startswith("_")}
            done |= ended
        venv.close()
        for i, (gi, g, s) in enumerate(pairs):
            inf = last[i]
            st = info0["start_deg"][i]
            dn, de = latlon_to_ned_offset(math.radians(st[0]), math.radians(st[1]), 0.0, math.radians(g[0]),
                                          math.radians(g[1]))
            straight_m = math.hypot(dn, de)
            why = str(inf["termination"])
            arrived = why == "arrived"
            flown = float(inf["distance_flown_m"])
            rows.append({"tier": "fast", "policy": p["label"], "goal_index": gi, "seed": s,
                         **({"goal_deg": list(g)} if drawn_goals else {}), "termination": why,
                         "arrived": arrived,
                         "true_miss_m": float(inf["true_miss_m"]) if arrived else math.nan,
                         "distance_flown_m": flown, "straight_distance_m": straight_m,
                         "extra_distance_fraction": (flown / max(straight_m - full.goal_radius_m, 1.0) - 1.0
                                                     if arrived else math.nan),
                         "collision": why == "terrain_collision", "return": float(ret[i]),
                         "steps": int(steps[i])})
    full.close()
    return rows


def evaluate(policies: list[dict], terrain: str, seeds, tiers=("full", "fast"),
             env_overrides: dict | None = None) -> list[dict]:
    """evaluate_full and evaluate_fast for the tiers asked for; rows of both."""
    rows = []
    for t in tiers:
        if t not in ("full", "fast"):
            raise ValueError(f"tiers: each must be 'full' or 'fast', got {t!r}")
        fn = evaluate_full if t == "full" else evaluate_fast
        rows += fn(policies, terrain, seeds, env_overrides)
    return rows


# a validation episode "loses the fix" when it does not arrive or its true miss exceeds this (m): a kept
# TERCOM fix ends within tens of metres, a lost one (a false fix after a featureless stretch) hundreds
FIX_LOSS_MISS_M = 100.0
SELECTION_RULES = ("success", "fix_loss")


def select_checkpoint(checkpoints, terrain: str, seeds, env_overrides: dict | None = None,
                      rule: str = "success", max_envs: int = 2000) -> dict:
    """Model selection without the held-out goals: every checkpoint (RLlib checkpoint folders) flies the fast
    tier's validation episodes (`evaluate_fast(..., drawn_goals=True)` over `seeds`, which should be
    `route_task.VALIDATION_SEEDS`: goals drawn from the training distribution, never a held-out goal, seeds
    disjoint from the evaluation's); per checkpoint the success rate, the fix-loss rate (episodes not arrived
    or missing by more than FIX_LOSS_MISS_M) and the mean, median and 90th-percentile true miss over the
    arrived episodes. The best by `rule` (`best_checkpoint`). The episodes fly in vector envs of at most
    `max_envs` sub-envs (a seed fixes its episode whatever the vector's size). Returns {"rows": [...] per
    checkpoint, "best": its row, "rule": rule}. ValueError on no checkpoints, an unknown rule or `max_envs`
    below 1."""
    checkpoints = [str(c) for c in checkpoints]
    seeds = [int(s) for s in seeds]
    if not checkpoints:
        raise ValueError("checkpoints: none given")
    if rule not in SELECTION_RULES:
        raise ValueError(f"rule must be one of {SELECTION_RULES}, got {rule!r}")
    if isinstance(max_envs, bool) or not isinstance(max_envs, int) or max_envs < 1:
        raise ValueError(f"max_envs must be a positive integer, got {max_envs!r}")
    out = []
    for c in checkpoints:
        rs = []
        for k in range(0, len(seeds), max_envs):
            rs += evaluate_fast([{"label": "ppo", "kind": "rllib", "checkpoint": c}], terrain,
                                seeds[k:k + max_envs], env_overrides, drawn_goals=True)
        miss = np.array([r["true_miss_m"] for r in rs if r["arrived"]])
        lost = sum((not r["arrived"]) or r["true_miss_m"] > FIX_LOSS_MISS_M for r in rs)
        out.append({"checkpoint": c, "episodes": len(rs),
                    "success": float(np.mean([r["arrived"] for r in rs])),
                    "fix_loss_rate": lost / len(rs),
                    "miss_mean_m": float(miss.mean()) if miss.size else math.nan,
                    "miss_median_m": float(np.median(miss)) if miss.size else math.nan,
                    "miss_p90_m": float(np.percentile(miss, 90)) if miss.size else math.nan})
    return {"rows": out, "best": best_checkpoint(out, rule), "rule": rule}


def best_checkpoint(rows: list[dict], rule: str = "success") -> dict:
    """The pick (the first of equals). Rule "success": the highest "success", then the lowest finite
    "miss_mean_m". Rule "fix_loss": the lowest "fix_loss_rate" (not arrived, or a miss above
    FIX_LOSS_MISS_M: the rare lost fixes that decide a mean over tens of episodes), then the lowest finite
    "miss_mean_m"."""
    if rule not in SELECTION_RULES:
        raise ValueError(f"rule must be one of {SELECTION_RULES}, got {rule!r}")

    def mean(r):
        return r["miss_mean_m"] if math.isfinite(r["miss_mean_m"]) else math.inf

    if rule == "fix_loss":
        return min(rows, key=lambda r: (r["fix_loss_rate"], mean(r)))
    return min(rows, key=lambda r: (-r["success"], mean(r)))


# ------------------------------------------------------------------------------------------ statistics
def sign_test_p(wins: int, losses: int) -> float:
    """One-sided sign test: P(X >= wins) for X ~ Binomial(wins + losses, 1/2) (ties already dropped)."""
    n = wins + losses
    if n == 0:
        return math.nan
    return float(sum(math.comb(n, k) for k in range(wins, n + 1)) / 2.0 ** n)


def paired(rows: list[dict], tier: str, a: str, b: str) -> dict | None:
    """Policy a against b in one tier over the (goal, seed) pairs where both arrived (module docstring)."""
    by = {(r["policy"], r["goal_index"], r["seed"]): r for r in rows if r["tier"] == tier}
    keys = sorted({(g, s) for (p, g, s) in by if p == a} & {(g, s) for (p, g, s) in by if p == b})
    both = [(by[(a, *k)]["true_miss_m"], by[(b, *k)]["true_miss_m"]) for k in keys
            if by[(a, *k)]["arrived"] and by[(b, *k)]["arrived"]]
    if not both:
        return None
    x = np.array(both)
    ma, mb = float(x[:, 0].mean()), float(x[:, 1].mean())
    rng = np.random.default_rng(0)
    idx = rng.integers(0, len(x), (N_BOOTSTRAP, len(x)))
    boot = 1.0 - x[idx, 0].mean(axis=1) / np.maximum(x[idx, 1].mean(axis=1), 1e-9)
    wins, losses = int(np.sum(x[:, 0] < x[:, 1])), int(np.sum(x[:, 0] > x[:, 1]))
    return {"tier": tier, "a": a, "b": b, "n_pairs": len(x), "n_compared": len(keys), "mean_a_m": ma,
            "mean_b_m": mb, "improvement": 1.0 - ma / mb if mb > 0 else math.nan,
            "improvement_ci95": [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))],
            "wins": wins, "losses": losses, "sign_test_p": sign_test_p(wins, losses)}


def summarise(rows: list[dict]) -> dict:
    """Per (tier, policy): episodes, success rate, mean and 90th-percentile true miss over the arrived
    episodes, mean extra distance, collisions, mean return; the paired comparisons of every policy against
    "straight" and "planner"; the transfer gap (a policy's mean miss in the full tier minus the fast tier)."""
    out: dict = {"policies": {}, "paired": [], "transfer": {}}
    for tier in sorted({r["tier"] for r in rows}):
        labels = list(dict.fromkeys(r["policy"] for r in rows if r["tier"] == tier))
        for lab in labels:
            rs = [r for r in rows if r["tier"] == tier and r["policy"] == lab]
            miss = np.array([r["true_miss_m"] for r in rs if r["arrived"]])
            extra = np.array([r["extra_distance_fraction"] for r in rs if r["arrived"]])
            out["policies"][f"{tier}/{lab}"] = {
                "tier": tier, "policy": lab, "episodes": len(rs),
                "success": float(np.mean([r["arrived"] for r in rs])),
                "miss_mean_m": float(miss.mean()) if miss.size else math.nan,
                "miss_p90_m": float(np.percentile(miss, 90)) if miss.size else math.nan,
                "extra_distance_mean": float(extra.mean()) if extra.size else math.nan,
                "collisions": int(sum(bool(r["collision"]) for r in rs)),
                "return_mean": float(np.mean([r["return"] for r in rs]))}
            for ref in ("straight", "planner"):
                if lab != ref and ref in labels:
                    c = paired(rows, tier, lab, ref)
                    if c is not None:
                        out["paired"].append(c)
    out["per_goal"] = per_goal(rows)
    pol = out["policies"]
    for v in pol.values():
        if v["tier"] == "full" and f"fast/{v['policy']}" in pol:
            out["transfer"][v["policy"]] = v["miss_mean_m"] - pol[f"fast/{v['policy']}"]["miss_mean_m"]
    return out


def per_goal(rows: list[dict]) -> list[dict]:
    """Per (tier, held-out goal, policy): episodes, arrived, mean and median true miss over the arrived
    episodes, mean extra distance (where a policy wins or loses, goal by goal)."""
    out = []
    for tier, gi, lab in sorted({(r["tier"], r["goal_index"], r["policy"]) for r in rows}):
        rs = [r for r in rows if (r["tier"], r["goal_index"], r["policy"]) == (tier, gi, lab)]
        arr = [r for r in rs if r["arrived"]]
        miss = np.array([r["true_miss_m"] for r in arr])
        out.append({"tier": tier, "goal_index": int(gi), "policy": lab, "episodes": len(rs),
                    "arrived": len(arr),
                    "miss_mean_m": float(miss.mean()) if miss.size else math.nan,
                    "miss_median_m": float(np.median(miss)) if miss.size else math.nan,
                    "extra_distance_mean": float(np.mean([r["extra_distance_fraction"] for r in arr]))
                    if arr else math.nan})
    return out


def target_check(summary: dict, policy: str = "ppo") -> dict:
    """The issue's target in the full tier: `policy` beats straight by >= 30 % mean true miss (paired, sign
    test p < 0.01) and its mean miss is within 20 % of the planner's with a success rate (arrived) not below
    the planner's (the miss is over the arrived episodes: a policy that arrives less often is not within 20 %
    however small its miss on the few it finishes)."""
    c = next((c for c in summary["paired"]
              if c["tier"] == "full" and c["a"] == policy and c["b"] == "straight"), None)
    pol = summary["policies"]
    planner = pol.get("full/planner", {}).get("miss_mean_m", math.nan)
    mine = pol.get(f"full/{policy}", {}).get("miss_mean_m", math.nan)
    success_ok = pol.get(f"full/{policy}", {}).get("success", 0.0) >= pol.get("full/planner", {}).get(
        "success", math.inf)
    return {"beats_straight_by_30pct": bool(c is not None and c["improvement"] >= 0.30),
            "sign_test_p_below_0_01": bool(c is not None and c["sign_test_p"] < 0.01),
            "within_20pct_of_planner": bool(math.isfinite(mine) and math.isfinite(planner)
                                            and mine <= 1.2 * planner and success_ok),
            "success_not_below_planner": bool(success_ok),
            "improvement": None if c is None else c["improvement"],
            "sign_test_p": None if c is None else c["sign_test_p"],
            "ratio_to_planner": mine / planner if planner and math.isfinite(planner) else math.nan}


def table(summary: dict) -> str:
    """Markdown: the per-policy table, then the paired comparisons."""
    lines = ["| tier | policy | episodes | success | miss mean (m) | miss p90 (m) | extra distance | "
             "collisions | return |", "|---|---|---|---|---|---|---|---|---|"]
    for v in summary["policies"].values():
        lines.append(f"| {v['tier']} | {v['policy']} | {v['episodes']} | {v['success']:.2f} | "
                     f"{v['miss_mean_m']:.0f} | {v['miss_p90_m']:.0f} | "
                     f"{100 * v['extra_distance_mean']:+.1f} % | "
                     f"{v['collisions']} | {v['return_mean']:.2f} |")
    lines += ["", "| tier | a vs b | pairs | mean a (m) | mean b (m) | improvement [95 % CI] | wins-losses | "
              "sign test p |", "|---|---|---|---|---|---|---|---|"]
    for c in summary["paired"]:
        lo, hi = c["improvement_ci95"]
        lines.append(f"| {c['tier']} | {c['a']} vs {c['b']} | {c['n_pairs']} | {c['mean_a_m']:.0f} | "
                     f"{c['mean_b_m']:.0f} | {100 * c['improvement']:+.0f} % "
                     f"[{100 * lo:+.0f}, {100 * hi:+.0f}] | "
                     f"{c['wins']}-{c['losses']} | {c['sign_test_p']:.3g} |")
    goals = summary.get("per_goal", [])
    if goals:
        labels = list(dict.fromkeys(g["policy"] for g in goals))
        lines += ["", "Per held-out goal: mean / median true miss (m) over the arrived episodes, arrived of "
                  "flown, mean extra distance", "", "| tier | goal | " + " | ".join(labels) + " |",
                  "|---|---|" + "---|" * len(labels)]
        by = {(g["tier"], g["goal_index"], g["policy"]): g for g in goals}
        for tier, gi in sorted({(g["tier"], g["goal_index"]) for g in goals}):
            cells = []
            for lab in labels:
                g = by.get((tier, gi, lab))
                cells.append("" if g is None else f"{g['miss_mean_m']:.0f} / {g['miss_median_m']:.0f}, "
                             f"{g['arrived']}/{g['episodes']}, {100 * g['extra_distance_mean']:+.0f} %")
            lines.append(f"| {tier} | {gi} | " + " | ".join(cells) + " |")
    if summary["transfer"]:
        lines += ["", "Transfer gap (mean miss, full tier minus fast tier): " + ", ".join(
            f"{k} {v:+.0f} m" for k, v in summary["transfer"].items())]
    return "\n".join(lines) + "\n"


def plot_learning_curve(path: str | Path, history: list[dict], title: str = "") -> None:
    """Mean episode return against env steps and against the CPU seconds the run got (one point per
    training iteration) into a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [h["env_steps"] for h in history]
    y = [h["episode_return_mean"] for h in history]
    cpu = [h.get("cpu_s", h.get("driver_cpu_s", math.nan) + h.get("env_runner_cpu_s", math.nan))
           for h in history]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.5), dpi=100, sharey=True)
    ax.plot(x, y, ".-")
    ax.set_xlabel("env steps (decisions)")
    ax.set_ylabel("mean episode return")
    ax2.plot(cpu, y, ".-")
    ax2.set_xlabel("CPU s (driver + EnvRunners)")
    for a in (ax, ax2):
        a.grid(alpha=0.3)
    fig.suptitle(title or "PPO learning curve")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_selection(path: str | Path, selection: dict, title: str = "") -> None:
    """The validation figures of `select_checkpoint`'s rows against the checkpoint's iteration (`iter_N`;
    `final` after the last): fix-loss rate and success rate (left), mean and median true miss (right), the
    pick marked; into a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = selection["rows"]
    names = [Path(r["checkpoint"]).name for r in rows]
    its = [int(n[5:]) if n.startswith("iter_") and n[5:].isdigit() else None for n in names]
    last = max([i for i in its if i is not None], default=0)
    x = [i if i is not None else last + 10 for i in its]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.5), dpi=100, sharex=True)
    ax.plot(x, [100 * r["fix_loss_rate"] for r in rows], ".-", label="fix lost (not arrived or > 100 m)")
    ax.plot(x, [100 * (1 - r["success"]) for r in rows], ".-", label="not arrived")
    ax.set_ylabel("% of validation episodes")
    ax2.plot(x, [r["miss_mean_m"] for r in rows], ".-", label="mean")
    ax2.plot(x, [r["miss_median_m"] for r in rows], ".-", label="median")
    ax2.set_ylabel("true miss over the arrived (m)")
    k = rows.index(selection["best"])
    for a in (ax, ax2):
        a.axvline(x[k], color="k", lw=0.8, ls=":")
        a.set_xlabel("training iteration (final at the right)")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(title or f"validation ({rows[0]['episodes']} episodes per checkpoint), pick {names[k]}")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
