"""The reference route task (docs/guide/route_task.md): train PPO, then evaluate straight, planner, random and
PPO in both env tiers on the same held-out goals and seeds.

    python scripts/route_task.py all --out out/route_task           # train (3,600 CPU s), select, evaluate
    python scripts/route_task.py train --out out/route_task --cpu-minutes 60  # RLlib PPO, fast tier if there
    python scripts/route_task.py train --out out/route_task --minutes 30     # a wall-time budget instead
    python scripts/route_task.py evaluate --out out/route_task               # needs OUT/checkpoints/final
    python scripts/route_task.py evaluate --out out/route_task --seeds 10    # a quick look (50 episodes)
    python scripts/route_task.py evaluate --out out/b --policies straight,planner,random   # no checkpoint
    python scripts/route_task.py evaluate --out out/route_task --policies ppo --merge-rows out/b/rows.json
    python scripts/route_task.py all --out /tmp/rt --iterations 1 --seeds 1 --max-episode-s 60   # tiny
    python scripts/route_task.py select --out out/route_task                 # model selection (no held-out)
    python scripts/route_task.py select --out out/rt --every 10 --rule success --validation-seeds 2000

train: RLlib PPO (the `rllib` extra) on the task (trn_env.env.route_task: terrain `--terrain`, start and
goal regions, training goals outside the held-out radius) on TerrainNavFast-v0 when it is registered, else on
TerrainNav-v0 (`--tier`); stops after `--iterations`, at the last iteration that keeps the run within
`--cpu-minutes` of CPU time (the driver's and every EnvRunner process's, summed; default: the task's budget,
30 minutes x 2 cores = 60 CPU minutes, route_task.TRAIN_BUDGET), or after `--minutes` of wall time (no wall
limit unless given), whichever comes first; writes OUT/checkpoints/ (iter_N, final), OUT/history.json and
OUT/learning_curve.png.
evaluate: the trained policy (OUT/checkpoints/final, or `--checkpoint`) and the baselines on the env's five
held-out goals x `--seeds` evaluation seeds (route_task.EVAL_SEEDS) in each tier of `--tiers` (the fast
tier only when registered); writes OUT/rows.json (one row per episode), OUT/summary.json (the table's
figures, the paired comparisons, the transfer gap and the issue's target check) and OUT/table.md, and prints
the table. Bad arguments: a message and exit 2, nothing written.
select: model selection without the held-out goals: every `--every`-th (default 50) checkpoint of
OUT/checkpoints (iter_N with N a multiple of it, and final) flies `--validation-seeds` (default all 20,000)
fast-tier episodes (seeds route_task.VALIDATION_SEEDS, goals drawn by the env from the training distribution,
never a held-out goal); `--rule fix_loss` (default): the lowest fix-loss rate (episodes not arrived or missing
by more than 100 m), then the lowest mean true miss, is the pick; `--rule success`: the highest success rate,
then the lowest mean true miss; writes OUT/selection.json (every checkpoint's figures, the pick, the CPU
seconds it took) and OUT/selection.png (the figures against the iteration), and prints them. Evaluate the pick
with `evaluate --checkpoint`.
all: train, select, then evaluate the pick (or `--checkpoint`, without the selection).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

POLICIES = ("straight", "planner", "random", "ppo")
VALIDATION_SEEDS = range(100_000, 120_000)      # = route_task.VALIDATION_SEEDS (checked in _check)
EVAL_SEEDS = range(1000, 1200)                  # = route_task.EVAL_SEEDS (checked in _check)


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("command", choices=("train", "evaluate", "all", "select"))
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--terrain", default="basin")
    p.add_argument("--tier", choices=("auto", "fast", "full"), default="auto", help="tier to train on")
    p.add_argument("--iterations", type=int, default=1000, help="training iterations at most")
    p.add_argument("--minutes", type=float, default=None, help="training wall-time budget (default: none)")
    p.add_argument("--cpu-minutes", type=float, default=None,
                   help="training CPU-time budget: the driver's and every EnvRunner's CPU minutes, summed "
                        "(default: the task's, 60 = 30 minutes on 2 cores)")
    p.add_argument("--address", default=None, help="Ray cluster address (default: local Ray)")
    p.add_argument("--num-cpus", type=int, default=2, help="CPUs of the local Ray instance")
    p.add_argument("--env-runners", type=int, default=1)
    p.add_argument("--envs-per-runner", type=int, default=None,
                   help="sub-envs per EnvRunner (default: 64 on the fast tier, 1 on the full tier)")
    p.add_argument("--train-batch-size", type=int, default=None,
                   help="env steps per iteration (default: 2048 fast tier, 64 full tier)")
    p.add_argument("--minibatch-size", type=int, default=None)
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--hidden", default="64,64")
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--lr-end", type=float, default=None,
                   help="learning rate at the end of a linear decay over --lr-decay-steps env steps")
    p.add_argument("--lr-decay-steps", type=int, default=None)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--lambda", dest="lambda_", type=float, default=0.95, help="GAE lambda")
    p.add_argument("--entropy", type=float, default=0.0, help="entropy coefficient")
    p.add_argument("--vf-clip", type=float, default=10.0, help="RLlib's value-loss clip")
    p.add_argument("--activation", default="tanh", choices=("tanh", "relu"))
    p.add_argument("--log-std-clip", type=float, default=20.0,
                   help="bound of the policy's log standard deviation (RLlib's log_std_clip_param; "
                        "default 20)")
    p.add_argument("--miss-weight", type=float, default=None,
                   help="TRAINING reward only: reward per km of true miss at arrival (default: the task's, "
                        "20); evaluation always scores the true miss with the task's reward")
    p.add_argument("--action-change-weight", type=float, default=None,
                   help="TRAINING reward only: cost per unit change of the track (offset) action between "
                        "decisions, -w |a0_t - a0_(t-1)| (default: the task's, 0); evaluation always uses "
                        "the task's reward")
    p.add_argument("--time-limit-failure", action="store_true",
                   help="TRAINING only: the time limit ends an episode as a failure (terminated, with the "
                        "failure penalty) instead of truncating it, so the learner does not bootstrap past "
                        "a time-out; evaluation always uses the task's episode ends")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--checkpoint", type=Path, default=None, help="checkpoint to evaluate")
    p.add_argument("--seeds", type=int, default=len(EVAL_SEEDS),
                   help=f"evaluation seeds per held-out goal (default the task's {len(EVAL_SEEDS)}; fewer "
                        f"for a quick look, whose means a single lost track can decide)")
    p.add_argument("--tiers", default="full,fast", help="tiers to evaluate in (comma separated)")
    p.add_argument("--max-episode-s", type=float, default=None, help="override the task's episode length")
    p.add_argument("--torch-threads", type=int, default=None,
                   help="torch/OpenMP threads per process (default: torch's own; 1 on a shared machine: "
                        "the learner's SGD then does not spin on busy cores)")
    p.add_argument("--policies", default="straight,planner,random,ppo",
                   help="policies to evaluate (comma separated, of straight, planner, random, ppo)")
    p.add_argument("--every", type=int, default=50,
                   help="select: consider the checkpoints iter_N with N a multiple of this (and final)")
    p.add_argument("--validation-seeds", type=int, default=len(VALIDATION_SEEDS),
                   help=f"select: validation episodes per checkpoint (default and at most "
                        f"{len(VALIDATION_SEEDS)})")
    p.add_argument("--rule", choices=("success", "fix_loss"), default="fix_loss",
                   help="select: the pick's rule: the lowest fix-loss rate (not arrived, or a miss above "
                        "100 m), then the lowest mean miss (fix_loss, default), or the highest success "
                        "rate, then the lowest mean miss (success)")
    p.add_argument("--merge-rows", type=Path, nargs="*", default=[],
                   help="rows.json files of earlier evaluations (same terrain and seeds) to summarise with "
                        "this one's; this run's rows replace theirs for the same tier, policy, goal and seed")
    return p.parse_args(argv)


def _check(args) -> dict:
    from trn_env.env import route_task

    kw = route_task.env_kwargs(args.terrain)            # ValueError naming the terrain
    if args.max_episode_s is not None:
        if not args.max_episode_s > 0:
            raise ValueError(f"--max-episode-s must be > 0, got {args.max_episode_s}")
        kw["max_episode_s"] = float(args.max_episode_s)
    for name in ("iterations", "seeds", "epochs", "env_runners"):
        least = 0 if name == "env_runners" else 1
        if getattr(args, name) < least:
            raise ValueError(f"--{name.replace('_', '-')} must be >= {least}, got {getattr(args, name)}")
    if args.num_cpus < 1:
        raise ValueError(f"--num-cpus must be >= 1, got {args.num_cpus}")
    from trn_env.output.run_folder import folder_problem
    problem = folder_problem(args.out, "--out")
    if problem is not None:
        raise ValueError(problem)
    for name, lo, hi in (("lr", 0.0, 1.0), ("gamma", 0.0, 1.0), ("lambda_", 0.0, 1.0),
                         ("vf_clip", 0.0, math.inf)):
        v = getattr(args, name)
        if not (lo < v <= hi and math.isfinite(v)):
            raise ValueError(f"--{name.rstrip('_').replace('_', '-')} must be in ({lo}, {hi}], got {v}")
    if not (0.0 <= args.log_std_clip < math.inf):
        raise ValueError(f"--log-std-clip must be a finite number >= 0, got {args.log_std_clip}")
    if args.miss_weight is not None and not (0.0 <= args.miss_weight < math.inf):
        raise ValueError(f"--miss-weight must be a finite number >= 0, got {args.miss_weight}")
    if args.action_change_weight is not None and not (0.0 <= args.action_change_weight < math.inf):
        raise ValueError(f"--action-change-weight must be a finite number >= 0, "
                         f"got {args.action_change_weight}")
    if not (0.0 <= args.entropy < math.inf):
        raise ValueError(f"--entropy must be a finite number >= 0, got {args.entropy}")
    if (args.lr_end is None) != (args.lr_decay_steps is None):
        raise ValueError("--lr-end and --lr-decay-steps go together (both or neither)")
    if args.lr_end is not None and not 0.0 < args.lr_end <= 1.0:
        raise ValueError(f"--lr-end must be in (0, 1], got {args.lr_end}")
    if args.lr_decay_steps is not None and args.lr_decay_steps < 1:
        raise ValueError(f"--lr-decay-steps must be >= 1, got {args.lr_decay_steps}")
    for name in ("minutes", "cpu_minutes"):
        v = getattr(args, name)
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise ValueError(f"--{name.replace('_', '-')} must be a finite number > 0, got {v}")
    for t in args.tiers.split(","):
        if t not in ("full", "fast"):
            raise ValueError(f"--tiers: each must be full or fast, got {t!r}")
    try:
        args.hidden_t = tuple(int(h) for h in args.hidden.split(","))
    except ValueError:
        raise ValueError(f"--hidden must be comma-separated widths, got {args.hidden!r}") from None
    if args.torch_threads is not None and args.torch_threads < 1:
        raise ValueError(f"--torch-threads must be >= 1, got {args.torch_threads}")
    args.policies_t = tuple(x.strip() for x in args.policies.split(",") if x.strip())
    bad = [x for x in args.policies_t if x not in POLICIES]
    if bad or not args.policies_t:
        raise ValueError(f"--policies: each must be one of {', '.join(POLICIES)}, got {args.policies!r}")
    for f in args.merge_rows:
        if not f.is_file():
            raise ValueError(f"--merge-rows: no file {f}")
        try:
            rows = json.loads(f.read_text())
            keys = {"tier", "policy", "goal_index", "seed"}
            ok = isinstance(rows, list) and all(keys <= set(r) for r in rows)
        except (json.JSONDecodeError, TypeError):
            ok = False
        if not ok:
            raise ValueError(f"--merge-rows: {f} is not a rows.json written by `evaluate`")
    if tuple(VALIDATION_SEEDS) != route_task.VALIDATION_SEEDS:
        raise ValueError("scripts/route_task.py's VALIDATION_SEEDS differ from the task's")
    if tuple(EVAL_SEEDS) != route_task.EVAL_SEEDS:
        raise ValueError("scripts/route_task.py's EVAL_SEEDS differ from the task's")
    if args.every < 1:
        raise ValueError(f"--every must be >= 1, got {args.every}")
    if not 1 <= args.validation_seeds <= len(VALIDATION_SEEDS):
        raise ValueError(f"--validation-seeds must be in [1, {len(VALIDATION_SEEDS)}], "
                         f"got {args.validation_seeds}")
    if args.command == "select":
        args.select_t = checkpoints_to_select(args.out / "checkpoints", args.every)
        if not args.select_t:
            raise ValueError(f"no checkpoints to select from in {args.out / 'checkpoints'} "
                             "(run `train` first)")
    if args.command == "evaluate" and "ppo" in args.policies_t:
        ck = args.checkpoint or args.out / "checkpoints" / "final"
        if not ck.is_dir():
            raise ValueError(f"no checkpoint at {ck} (run `train` first, or give --checkpoint)")
    return kw


def checkpoints_to_select(folder: Path, every: int) -> list[Path]:
    """iter_N (N a multiple of `every`) in iteration order, then final, of those in `folder`."""
    if not folder.is_dir():
        return []
    its = sorted((int(d.name[5:]), d) for d in folder.iterdir()
                 if d.is_dir() and d.name.startswith("iter_") and d.name[5:].isdigit())
    out = [d for n, d in its if n % every == 0]
    return out + ([folder / "final"] if (folder / "final").is_dir() else [])


def select(args, kw: dict) -> dict:
    import time

    from trn_env.campaign import route_task as rt
    from trn_env.env import route_task

    cpu0, wall0 = time.process_time(), time.time()
    seeds = list(route_task.VALIDATION_SEEDS[:args.validation_seeds])
    res = rt.select_checkpoint(args.select_t, args.terrain, seeds, {"max_episode_s": kw["max_episode_s"]},
                               rule=args.rule)
    res.update(terrain=args.terrain, seeds=[seeds[0], seeds[-1]], n_seeds=len(seeds),
               cpu_s=time.process_time() - cpu0, wall_s=time.time() - wall0)
    lines = ["| checkpoint | success | fix-loss rate | miss mean (m) | median (m) | p90 (m) |",
             "|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {Path(r['checkpoint']).name} | {r['success']:.3f} | {r['fix_loss_rate']:.4f} | "
                     f"{r['miss_mean_m']:.1f} | {r['miss_median_m']:.1f} | {r['miss_p90_m']:.1f} |")
    text = "\n".join(lines) + (f"\n\npick ({args.rule}): {res['best']['checkpoint']} "
                               f"({res['cpu_s']:.0f} CPU s)\n")
    (args.out / "selection.json").write_text(json.dumps(res, indent=1))
    rt.plot_selection(args.out / "selection.png", res, f"{args.out.name}: validation, {len(seeds)} fast-tier "
                      f"episodes per checkpoint; pick ({args.rule}) {Path(res['best']['checkpoint']).name}")
    print(text)
    return res


def training_env_kwargs(args, kw: dict) -> dict:
    """The env's keyword arguments for training: the task's (`kw`) with the training-only choices (reward
    weights, time-outs as failures) the command line sets; evaluation always flies `kw`."""
    train_kw = dict(kw)
    if args.miss_weight is not None:
        train_kw["miss_weight"] = float(args.miss_weight)
    if args.action_change_weight is not None:
        train_kw["action_change_weight"] = float(args.action_change_weight)
    if args.time_limit_failure:
        train_kw["time_limit_failure"] = True
    return train_kw


def train(args, kw: dict) -> None:
    import gymnasium as gym

    from trn_env.campaign.route_task import plot_learning_curve
    from trn_env.env import route_task
    from trn_env.env.rllib import FAST_ID
    from trn_env.env.rllib_train import ppo_config, train

    tier = args.tier if args.tier != "auto" else ("fast" if FAST_ID in gym.registry else "full")
    envs = args.envs_per_runner or (64 if tier == "fast" else 1)
    batch = args.train_batch_size or (2048 if tier == "fast" else 64)
    mini = args.minibatch_size or min(256 if tier == "fast" else 32, batch)
    recipe = dict(hidden=args.hidden_t, train_batch_size=batch, minibatch_size=mini, num_epochs=args.epochs,
                  lr=args.lr, lr_end=args.lr_end, lr_decay_steps=args.lr_decay_steps, gamma=args.gamma,
                  lambda_=args.lambda_, entropy_coeff=args.entropy, vf_clip_param=args.vf_clip,
                  activation=args.activation, log_std_clip=args.log_std_clip)
    train_kw = training_env_kwargs(args, kw)
    cfg = ppo_config(tier, train_kw, seed=args.seed, num_env_runners=args.env_runners,
                     num_envs_per_env_runner=envs, **recipe)
    cpu_s = 60.0 * args.cpu_minutes if args.cpu_minutes is not None else route_task.TRAIN_BUDGET["cpu_s"]
    wall_s = 60.0 * args.minutes if args.minutes is not None else None

    def show(row):
        print(f"[train {tier}] iter {row['iteration']}: {row['env_steps']:.0f} steps, {row['episodes']:.0f} "
              f"episodes, return {row['episode_return_mean']:.2f}, {row['wall_s']:.0f} s wall, "
              f"{row['cpu_s']:.0f} s CPU", flush=True)

    algo, history = train(cfg, args.iterations, args.out / "checkpoints", 10, show, wall_s, cpu_s)
    algo.stop()
    (args.out / "history.json").write_text(json.dumps(
        {"tier": tier, "terrain": args.terrain, "env": train_kw, "envs_per_runner": envs, "env_runners":
         args.env_runners, "seed": args.seed, "budget": {"cpu_s": cpu_s, "wall_s": wall_s},
         **{k: (list(v) if isinstance(v, tuple) else v) for k, v in recipe.items()},
         "epochs": args.epochs, "history": history}, indent=1))
    last = history[-1]
    plot_learning_curve(args.out / "learning_curve.png", history,
                        f"PPO on {tier} tier, {args.terrain} ({last['cpu_s']:.0f} CPU s, "
                        f"{last['wall_s'] / 60:.1f} min wall)")


def evaluate(args, kw: dict) -> dict:
    import gymnasium as gym

    from trn_env.campaign import route_task as rt
    from trn_env.env import route_task
    from trn_env.env.rllib import FAST_ID

    ck = (args.checkpoint or args.out / "checkpoints" / "final").resolve()
    specs = {"straight": {"label": "straight", "kind": "straight"},
             "planner": {"label": "planner", "kind": "planner", "config": {"weight": 3.0}},
             "random": {"label": "random", "kind": "random"},
             "ppo": {"label": "ppo", "kind": "rllib", "checkpoint": str(ck)}}
    policies = [specs[p] for p in args.policies_t]
    tiers = [t for t in args.tiers.split(",") if t == "full" or FAST_ID in gym.registry]
    seeds = list(route_task.EVAL_SEEDS[:args.seeds]) if args.seeds <= len(route_task.EVAL_SEEDS) else \
        [route_task.EVAL_SEEDS[0] + k for k in range(args.seeds)]
    overrides = {"max_episode_s": kw["max_episode_s"]}
    rows = rt.evaluate(policies, args.terrain, seeds, tiers, overrides)
    mine = {(r["tier"], r["policy"], r["goal_index"], r["seed"]) for r in rows}
    for f in args.merge_rows:
        rows += [r for r in json.loads(f.read_text())
                 if (r["tier"], r["policy"], r["goal_index"], r["seed"]) not in mine]
    summary = rt.summarise(rows)
    summary["target"] = rt.target_check(summary)
    summary["tiers_evaluated"] = tiers
    summary["seeds"] = seeds
    text = rt.table(summary)
    (args.out / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    (args.out / "table.md").write_text(text)
    print(text)
    print("target (full tier):", json.dumps(summary["target"]))
    return summary


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    from trn_env.env.rllib import RLlibNotInstalled, require_rllib

    try:
        require_rllib()
        kw = _check(args)
    except (RLlibNotInstalled, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.torch_threads is not None:      # before Ray starts: its workers inherit the environment
        import os

        import torch
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = str(args.torch_threads)
        torch.set_num_threads(args.torch_threads)
    import ray

    from trn_env.campaign.ray_backend import connect_for_env_runners
    if args.command in ("train", "all"):             # (evaluation needs no Ray: it loads the module alone)
        try:
            connect_for_env_runners(ray, args.address, None if args.address else args.num_cpus,
                                    args.env_runners, log_to_driver=False)
        except ValueError as err:
            print(f"error: {err}", file=sys.stderr)
            return 2
    args.out.mkdir(parents=True, exist_ok=True)
    if args.command in ("train", "all"):
        try:
            train(args, kw)
        finally:
            ray.shutdown()
    if args.command == "all" and "ppo" in args.policies_t and args.checkpoint is None:
        # the recipe: the checkpoint model selection picks (never on the held-out goals) is the one evaluated
        args.select_t = checkpoints_to_select(args.out / "checkpoints", args.every)
        args.checkpoint = Path(select(args, kw)["best"]["checkpoint"])
    if args.command in ("evaluate", "all"):
        evaluate(args, kw)
    if args.command == "select":
        select(args, kw)
    return 0


if __name__ == "__main__":
    sys.exit(main())
