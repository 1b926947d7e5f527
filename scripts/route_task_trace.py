"""Per-decision traces of a route-task policy on one held-out goal, in the full loop and the fast tier: the
true horizontal error, the navigator's horizontal sigma, the action, the estimated height above the map
and the terrain information under the estimate at every 30 s decision (where a route loses the fix, and
whether the fast tier loses it there too).

    PYTHONPATH=. python scripts/route_task_trace.py --policy ppo --checkpoint J/checkpoints/iter_50 \
        --goal 2 --tier full --seeds 1000-1009 --out trace_full.json
    PYTHONPATH=. python scripts/route_task_trace.py --policy ppo --checkpoint J/checkpoints/iter_50 \
        --goal 2 --tier fast --seeds 1000-1255 --out trace_fast.json

Writes OUT (one record per episode: seed, termination, true miss, and the per-decision lists) and prints
per episode its termination, miss and the decision at which the true error first exceeded 100 m, then the
fix losses (not arrived, or a miss above 100 m) by the worst terrain information met along the route,
and the steering: the share of saturated offsets (|a0| >= 0.99), offset reversals per episode (a change of
side between decisions with |a0| >= 0.5, those in between skipped) and the mean total offset change per
episode (sum of |a0_t - a0_(t-1)| from a0_(-1) = 0: what `action_change_weight` charges).
`--sigma-scale k` (a probe of the policy, not of the env): a PPO policy sees the navigator's horizontal
sigma (observations 8, 9) multiplied by k. Exit 2 on bad arguments (unknown policy, goal index out of
range, missing checkpoint, malformed seeds, a sigma scale not > 0).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from trn_env.output.run_folder import file_target_problem


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    if not out:
        raise ValueError("no seeds")
    return out


def _record(obs, act, info, i=None) -> dict:
    def g(k):
        v = info[k]
        return v if i is None else v[i]

    sig = np.asarray(g("sigma_ned_m"), float)
    o = obs if i is None else obs[i]
    a = act if i is None else act[i]
    return {"t_s": float(g("t_s")), "true_err_m": float(g("true_horizontal_error_m")),
            "sigma_h_m": float(math.hypot(sig[0], sig[1])) if i is None else float(sig[0]),
            "offset": float(a[0]), "agl_action": float(a[1]), "est_agl_km": float(o[6]),
            "info_here": float(o[11]), "d_true_km": float(g("true_distance_to_goal_m")) / 1e3,
            "nav_ok": bool(g("nav_ok"))}


INFO_BINS = ((0.0, 1.0), (1.0, 1.5), (1.5, 2.0), (2.0, math.inf))


class SigmaScaled:
    """A policy whose observed horizontal sigma (observations 8, 9: log10(1 + sigma m)) is multiplied by
    `k` before it acts (how much its route depends on the tier's sigma)."""

    def __init__(self, policy, k: float):
        self.policy, self.k = policy, float(k)

    def predict(self, obs, *args, **kwargs):
        o = np.array(obs, np.float64, copy=True)
        o[..., 8:10] = np.log10(1.0 + self.k * (10.0 ** o[..., 8:10] - 1.0))
        return self.policy.predict(o.astype(np.float32), *args, **kwargs)


def losses_by_info(episodes: list[dict], miss_m: float = 100.0) -> list[tuple[int, int]]:
    """(lost, episodes) per INFO_BINS bin of the largest terrain information under the estimate over an
    episode's decisions; lost = not arrived or a true miss above miss_m."""
    out = []
    for lo, hi in INFO_BINS:
        sel = [e for e in episodes if lo <= max(d["info_here"] for d in e["decisions"]) < hi]
        out.append((sum(e["termination"] != "arrived" or e["true_miss_m"] > miss_m for e in sel), len(sel)))
    return out


def trace_full(policy_spec: dict, terrain: str, goal: int, seeds: list[int], sigma_scale: float = 1.0
               ) -> list[dict]:
    """Per-decision records of the policy on held-out goal `goal` in TerrainNav-v0, one episode per seed."""
    from trn_env.campaign.route_task import _make
    from trn_env.env import route_task
    from trn_env.env.terrain_nav import TerrainNavEnv

    env = TerrainNavEnv(**route_task.env_kwargs(terrain))
    pol = _make(policy_spec, env, route_task.straight_agl_m(terrain))
    if sigma_scale != 1.0:
        pol = SigmaScaled(pol, sigma_scale)
    g = tuple(env.held_out_goals_deg[goal])
    out = []
    try:
        for s in seeds:
            obs, info = env.reset(seed=int(s), options={"goal_deg": g})
            if hasattr(pol, "reset"):
                pol.reset()
            if hasattr(pol, "seed"):
                pol.seed(int(s))
            recs, done = [], False
            while not done:
                act = np.asarray(pol.predict(obs, deterministic=True)[0], np.float32)
                o_before = obs
                obs, _, term, trunc, info = env.step(act)
                recs.append(_record(o_before, act, info))
                done = term or trunc
            out.append({"seed": int(s), "termination": str(info["termination"]),
                        "true_miss_m": float(info.get("true_miss_m", math.nan)), "decisions": recs})
    finally:
        env.close()
    return out


def trace_fast(policy_spec: dict, terrain: str, goal: int, seeds: list[int], sigma_scale: float = 1.0
               ) -> list[dict]:
    """The same in TerrainNavFast-v0: one vector env, a sub-env per seed, each first episode kept."""
    import gymnasium as gym

    from trn_env.campaign.route_task import _make, goal_view
    from trn_env.env import route_task
    from trn_env.env.rllib import FAST_ID
    from trn_env.env.terrain_nav import TerrainNavEnv

    kw = route_task.env_kwargs(terrain)
    full = TerrainNavEnv(**kw)
    g = tuple(full.held_out_goals_deg[goal])
    n = len(seeds)
    agl = route_task.straight_agl_m(terrain)
    venv = gym.make_vec(FAST_ID, num_envs=n, vectorization_mode="vector_entry_point",
                        **route_task.fast_tier_kwargs(kw))
    obs, _ = venv.reset(seed=seeds, options={"goal_deg": np.array([g] * n)})
    if policy_spec["kind"] == "rllib":
        shared = _make(policy_spec, full, agl)
        shared = SigmaScaled(shared, sigma_scale) if sigma_scale != 1.0 else shared
        pols = None
    else:
        pols = [_make(policy_spec, goal_view(full, g), agl) for _ in seeds]
        for p, s in zip(pols, seeds, strict=True):
            if hasattr(p, "seed"):
                p.seed(int(s))
    recs: list[list[dict]] = [[] for _ in range(n)]
    end = [None] * n
    done = np.zeros(n, bool)
    while not done.all():
        if pols is None:
            act = shared.predict(obs)[0]
        else:
            act = np.stack([np.asarray(pols[i].predict(obs[i])[0], np.float32) if not done[i]
                            else np.zeros(2, np.float32) for i in range(n)])
        o_before = obs
        obs, _, term, trunc, info = venv.step(act)
        for i in np.flatnonzero(~done):
            recs[i].append(_record(o_before, act, info, i))
            if term[i] or trunc[i]:
                end[i] = (str(info["termination"][i]), float(info["true_miss_m"][i]))
        done |= term | trunc
    venv.close()
    full.close()
    return [{"seed": int(s), "termination": end[i][0], "true_miss_m": end[i][1], "decisions": recs[i]}
            for i, s in enumerate(seeds)]


def steering_summary(episodes: list[dict], side_min: float = 0.5, saturated_min: float = 0.99) -> dict:
    """The offsets' saturated share (|a0| >= saturated_min over all decisions), reversals per episode (sign
    changes between successive decisions with |a0| >= side_min; smaller offsets skipped) and the mean total
    change sum_t |a0_t - a0_(t-1)| per episode with a0_(-1) = 0."""
    offs = [np.array([d["offset"] for d in e["decisions"]], float) for e in episodes]
    rev, tv = [], []
    for o in offs:
        side = np.sign(o[np.abs(o) >= side_min])
        rev.append(int(np.sum(side[1:] != side[:-1])))
        tv.append(float(np.sum(np.abs(np.diff(o, prepend=0.0)))))
    allo = np.concatenate(offs) if offs else np.zeros(0)
    return {"episodes": len(offs), "saturated_share": float(np.mean(np.abs(allo) >= saturated_min)),
            "reversals_per_episode": float(np.mean(rev)), "offset_change_per_episode": float(np.mean(tv))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", choices=("straight", "planner", "ppo"), required=True)
    p.add_argument("--checkpoint", type=Path, default=None)
    p.add_argument("--terrain", default="basin")
    p.add_argument("--goal", type=int, required=True, help="held-out goal index (0-4)")
    p.add_argument("--tier", choices=("full", "fast"), required=True)
    p.add_argument("--seeds", default="1000-1009", help="e.g. 1000-1009 or 1000,1006")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--sigma-scale", type=float, default=1.0,
                   help="a ppo policy sees the navigator's horizontal sigma times this (a probe)")
    args = p.parse_args(argv)
    if args.out is not None and (problem := file_target_problem(args.out, "--out")):
        p.error(problem)       # checked before the work, not after it
    try:
        seeds = _seeds(args.seeds)
    except ValueError:
        print(f"--seeds: malformed {args.seeds!r}", file=sys.stderr)
        return 2
    if not 0 <= args.goal <= 4:
        print(f"--goal must be in 0..4, got {args.goal}", file=sys.stderr)
        return 2
    if not (args.sigma_scale > 0 and math.isfinite(args.sigma_scale)):
        print(f"--sigma-scale must be a finite number > 0, got {args.sigma_scale}", file=sys.stderr)
        return 2
    if args.policy == "ppo" and (args.checkpoint is None or not args.checkpoint.is_dir()):
        print(f"--checkpoint: no checkpoint folder {args.checkpoint}", file=sys.stderr)
        return 2
    spec = {"straight": {"label": "straight", "kind": "straight"},
            "planner": {"label": "planner", "kind": "planner", "config": {"weight": 3.0}},
            "ppo": {"label": "ppo", "kind": "rllib", "checkpoint": str(args.checkpoint)}}[args.policy]
    fn = trace_full if args.tier == "full" else trace_fast
    eps = fn(spec, args.terrain, args.goal, seeds, args.sigma_scale if args.policy == "ppo" else 1.0)
    args.out.write_text(json.dumps({"policy": args.policy, "checkpoint": str(args.checkpoint),
                                    "goal": args.goal, "tier": args.tier, "sigma_scale": args.sigma_scale,
                                    "episodes": eps}, indent=0))
    for e in eps:
        errs = [d["true_err_m"] for d in e["decisions"]]
        first = next((k for k, x in enumerate(errs) if x > 100.0), None)
        print(f"seed {e['seed']}: {e['termination']}, miss {e['true_miss_m']:.1f} m, {len(errs)} decisions, "
              f"first > 100 m at decision {first}, max {max(errs):.0f} m")
    bins = losses_by_info(eps)
    lost = sum(x for x, _ in bins)
    print(f"lost (not arrived or miss > 100 m): {lost} of {len(eps)} ({100 * lost / len(eps):.1f} %); by the "
          "largest terrain information along the route " + ", ".join(
              f"[{lo:g}, {hi:g}): {x}/{n}" for (lo, hi), (x, n) in zip(INFO_BINS, bins, strict=True)))
    st = steering_summary(eps)
    print(f"steering: {100 * st['saturated_share']:.1f} % of offsets saturated, "
          f"{st['reversals_per_episode']:.2f} reversals and {st['offset_change_per_episode']:.2f} total "
          "offset change per episode")
    return 0


if __name__ == "__main__":
    sys.exit(main())
