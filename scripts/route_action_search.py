"""How well can the route task's pursuit action family do at all? A cross-entropy search over open-loop
action sequences in the fast tier, against the planner on the same starts, goals and noise.

    PYTHONPATH=. python scripts/route_action_search.py --goals 0,2,4 --seeds 1000,1001 --out /tmp/search.json

For each held-out goal g (`--goals`, indices into the env's five) and task seed s (`--seeds`: the start that
`reset(seed=s)` draws for that goal), the start is held fixed and the episode's randomness (turbulence, INS
and sensor errors, initial navigation error) is drawn from `--noise` noise seeds. The search: a Gaussian
over sequences of `--decisions` pursuit actions (offset from the goal's bearing, and height above ground,
each in [-1, 1]; with `--fixed-height` only the offsets, the height held at the straight route's 600 m),
`--population` sequences per generation, each flown on the same `--noise` noise seeds (population x noise
sub-envs of one TerrainNavFast-v0), scored by the mean true miss at arrival (an episode that does not
arrive counts `NO_ARRIVAL_M`); the best `--elite` fraction re-fits the Gaussian (`--generations` times).
The best sequence found is then flown on `--noise` FRESH noise seeds, with the planner and the straight
route on the same fresh seeds: the search picked it on the first noise set, so the fresh set is its fair
score. A sequence is open loop (it does not see the estimate), so its score is a lower bound on what a
policy in the family can reach; if it cannot reach the planner's miss, the action family is the limit.
Writes --out (JSON: per pair, the scores and the best sequence) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from trn_env.output.run_folder import file_target_problem

NO_ARRIVAL_M = 2000.0


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--terrain", default="basin")
    p.add_argument("--goals", default="0,1,2,3,4")
    p.add_argument("--seeds", default="1000")
    p.add_argument("--noise", type=int, default=8, help="noise seeds per evaluation")
    p.add_argument("--population", type=int, default=48)
    p.add_argument("--generations", type=int, default=15)
    p.add_argument("--elite", type=float, default=0.2)
    p.add_argument("--decisions", type=int, default=16)
    p.add_argument("--fixed-height", action="store_true")
    p.add_argument("--search-seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.out is not None and (problem := file_target_problem(args.out, "--out")):
        p.error(problem)       # checked before the work, not after it
    return args


def _fly(kw, start, goal, noise_seeds, actions_fn, n):
    """Fly n sub-envs from start to goal, sub-env i with noise seed noise_seeds[i]; actions_fn(t, obs, done)
    -> (n, 2) actions. Returns (miss with NO_ARRIVAL_M where not arrived, arrived, flown)."""
    import gymnasium as gym

    from trn_env.env.rllib import FAST_ID
    from trn_env.env.route_task import fast_tier_kwargs

    venv = gym.make_vec(FAST_ID, num_envs=n, vectorization_mode="vector_entry_point", **fast_tier_kwargs(kw))
    obs, _ = venv.reset(seed=[int(s) for s in noise_seeds],
                        options={"goal_deg": np.tile(goal, (n, 1)), "start_deg": np.tile(start, (n, 1))})
    done = np.zeros(n, bool)
    miss = np.full(n, NO_ARRIVAL_M)
    flown = np.full(n, math.nan)
    arrived = np.zeros(n, bool)
    t = 0
    while not done.all():
        obs, _, term, trunc, info = venv.step(actions_fn(t, obs, done))
        ended = (term | trunc) & ~done
        for i in np.flatnonzero(ended):
            arrived[i] = str(info["termination"][i]) == "arrived"
            if arrived[i]:
                miss[i] = float(info["true_miss_m"][i])
            flown[i] = float(info["distance_flown_m"][i])
        done |= ended
        t += 1
    venv.close()
    return miss, arrived, flown


def _sequence_actions(seqs, noise):
    """actions_fn flying sequence k on sub-envs k * noise .. (k + 1) * noise - 1 (the last action held)."""
    def fn(t, obs, done):
        a = seqs[:, min(t, seqs.shape[1] - 1), :]
        return np.repeat(a, noise, axis=0).astype(np.float32)
    return fn


def _policy_actions(kind, full, goal, n):
    from trn_env.campaign.episodes import make_policy
    from trn_env.campaign.route_task import goal_view
    from trn_env.env import route_task

    view = goal_view(full, goal)
    spec = {"kind": kind, "agl_m": route_task.straight_agl_m("basin")}
    if kind == "planner":
        spec["config"] = {"weight": 3.0}
    first = make_policy(spec, view)
    pols = [first] + [make_policy(spec, view) for _ in range(n - 1)]
    if kind == "planner":
        for p in pols[1:]:
            p.planner = first.planner

    def fn(t, obs, done):
        return np.stack([np.asarray(pols[i].predict(obs[i])[0], np.float32) if not done[i]
                         else np.zeros(2, np.float32) for i in range(n)])
    return fn


def search_pair(kw, full, goal, start, args, rng, search_noise, fresh_noise):
    T, P, K = args.decisions, args.population, args.noise
    dims = 1 if args.fixed_height else 2
    mu = np.zeros((T, dims))
    sd = np.full((T, dims), 0.6)
    best = (math.inf, None)
    n_elite = max(2, int(round(args.elite * P)))
    history = []
    for _ in range(args.generations):
        x = np.clip(mu + sd * rng.standard_normal((P, T, dims)), -1.0, 1.0)
        x[0] = np.clip(mu, -1, 1)
        if best[1] is not None:
            x[1] = best[1]
        seqs = x if dims == 2 else np.concatenate([x, np.zeros_like(x)], axis=2)
        miss, _, _ = _fly(kw, start, goal, np.tile(search_noise, P), _sequence_actions(seqs, K), P * K)
        score = miss.reshape(P, K).mean(axis=1)
        order = np.argsort(score)
        if score[order[0]] < best[0]:
            best = (float(score[order[0]]), x[order[0]].copy())
        el = x[order[:n_elite]]
        mu = el.mean(axis=0)
        sd = np.maximum(el.std(axis=0), 0.05)
        history.append(float(score[order[0]]))
    seq = best[1] if dims == 2 else np.concatenate([best[1], np.zeros_like(best[1])], axis=1)
    res = {"search_best_mean_m": best[0], "search_history_m": history, "sequence": seq.tolist()}
    miss, arr, flown = _fly(kw, start, goal, fresh_noise, _sequence_actions(seq[None], K), K)
    res["cem_fresh"] = {"miss_mean_m": float(miss.mean()), "arrived": int(arr.sum()),
                        "flown_m": float(np.nanmean(flown))}
    for kind in ("planner", "straight"):
        miss, arr, flown = _fly(kw, start, goal, fresh_noise, _policy_actions(kind, full, goal, K), K)
        res[kind] = {"miss_mean_m": float(miss.mean()), "arrived": int(arr.sum()),
                     "flown_m": float(np.nanmean(flown)), "misses_m": miss.tolist()}
    return res


def _int_list(name: str, text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"--{name} must be comma-separated integers, got {text!r}") from None


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    import gymnasium as gym

    import trn_env  # noqa: F401
    from trn_env.env import route_task
    from trn_env.env.rllib import FAST_ID
    from trn_env.env.route_task import fast_tier_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv

    try:
        kw = route_task.env_kwargs(args.terrain)
        goals_i, seeds = _int_list("goals", args.goals), _int_list("seeds", args.seeds)
        for name in ("noise", "population", "generations", "decisions"):
            if getattr(args, name) < 1:
                raise ValueError(f"--{name} must be >= 1, got {getattr(args, name)}")
        if not 0 < args.elite < 1:
            raise ValueError(f"--elite must be in (0, 1), got {args.elite}")
        if FAST_ID not in gym.registry:
            raise ValueError(f"{FAST_ID} is not registered")
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    full = TerrainNavEnv(**kw)
    n_goals = len(full.held_out_goals_deg)
    bad = [i for i in goals_i if not 0 <= i < n_goals]
    if bad:
        full.close()
        print(f"error: --goals {bad} out of range: the env has {n_goals} held-out goals (0-{n_goals - 1})",
              file=sys.stderr)
        return 2
    goals = [tuple(full.held_out_goals_deg[i]) for i in goals_i]
    rng = np.random.default_rng(args.search_seed)
    search_noise = np.arange(50_000, 50_000 + args.noise)
    fresh_noise = np.arange(60_000, 60_000 + args.noise)
    out = []
    for gi, goal in zip(goals_i, goals, strict=True):
        for s in seeds:
            v = gym.make_vec(FAST_ID, num_envs=1, vectorization_mode="vector_entry_point",
                             **fast_tier_kwargs(kw))
            _, info = v.reset(seed=[s], options={"goal_deg": np.array([goal])})
            start = np.asarray(info["start_deg"][0], float)
            v.close()
            r = search_pair(kw, full, np.asarray(goal), start, args, rng, search_noise, fresh_noise)
            r.update(goal_index=gi, seed=s, start_deg=start.tolist(), goal_deg=list(goal))
            out.append(r)
            print(f"goal {gi} seed {s}: search best {r['search_best_mean_m']:.1f} m; fresh noise: CEM "
                  f"{r['cem_fresh']['miss_mean_m']:.1f} m ({r['cem_fresh']['flown_m'] / 1e3:.1f} km), "
                  f"planner "
                  f"{r['planner']['miss_mean_m']:.1f} m ({r['planner']['flown_m'] / 1e3:.1f} km), straight "
                  f"{r['straight']['miss_mean_m']:.1f} m", flush=True)
            args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "pairs": out},
                                           indent=1))
    full.close()
    c = np.mean([r["cem_fresh"]["miss_mean_m"] for r in out])
    p = np.mean([r["planner"]["miss_mean_m"] for r in out])
    s_ = np.mean([r["straight"]["miss_mean_m"] for r in out])
    print(f"mean over {len(out)} pairs (fresh noise): CEM {c:.1f} m, planner {p:.1f} m, straight {s_:.1f} m; "
          f"CEM / planner {c / p:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
