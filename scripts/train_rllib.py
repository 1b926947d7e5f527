"""Train PPO on Ray RLlib in the reference route task, locally or on a Ray cluster, then evaluate it on the
held-out goals in the full-fidelity loop.

    python scripts/train_rllib.py --out out/rllib                          # local Ray, fast tier if present
    python scripts/train_rllib.py --tier full --iterations 20 --out out/rllib_full
    python scripts/train_rllib.py --address auto --env-runners 30 --out /shared/rllib   # on a cluster
    python scripts/train_rllib.py --evaluate-only out/rllib/checkpoints/final --out out/rllib_eval

Needs the `rllib` extra (`pip install 'trn-env[rllib]'`). The task is trn_env.env.route_task's (terrain
`--terrain`, start and goal regions, held-out goals, evaluation seeds); the policy trains on `--tier` (fast:
TerrainNavFast-v0, N aircraft per EnvRunner; full: TerrainNav-v0) and is always evaluated in the full
JSBSim loop on the env's five held-out goals x `--eval-seeds` seeds (its mean action). Writes OUT/history.json
(the learning curve: env steps, episodes, mean return per iteration), OUT/checkpoints/iter_N and
OUT/checkpoints/final (RLlib checkpoints: `Algorithm.from_checkpoint`), OUT/evaluation.json (one row per
episode) and prints a one-line summary. docs/guide/rllib.md covers multi-node training and its scaling.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--tier", choices=("auto", "fast", "full"), default="auto",
                   help="env tier to train on (auto: fast when registered, else full)")
    p.add_argument("--terrain", default="basin", help="route_task terrain (basin, jacksboro)")
    p.add_argument("--iterations", type=int, default=10, help="training iterations")
    p.add_argument("--address", default=None,
                   help="Ray cluster address (e.g. auto, or ray://head:10001); default: a local Ray instance")
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of the local Ray instance (no --address)")
    p.add_argument("--env-runners", type=int, default=1, help="EnvRunner actors (one CPU each)")
    p.add_argument("--envs-per-runner", type=int, default=1,
                   help="sub-envs per EnvRunner (the fast tier: aircraft per runner)")
    p.add_argument("--train-batch-size", type=int, default=256, help="env steps per iteration")
    p.add_argument("--minibatch-size", type=int, default=64)
    p.add_argument("--epochs", type=int, default=10, help="SGD passes per iteration")
    p.add_argument("--hidden", default="64,64", help="hidden layer widths, comma separated")
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--checkpoint-every", type=int, default=10, help="iterations between checkpoints")
    p.add_argument("--eval-seeds", type=int, default=2, help="evaluation episode seeds per held-out goal")
    p.add_argument("--max-episode-s", type=float, default=None, help="override the task's episode length")
    p.add_argument("--evaluate-only", type=Path, default=None, help="checkpoint to evaluate (no training)")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    from trn_env.env.rllib import RLlibNotInstalled, require_rllib

    try:
        require_rllib()
    except RLlibNotInstalled as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    import gymnasium as gym

    from trn_env.env import route_task
    from trn_env.env.rllib import FAST_ID
    from trn_env.env.rllib_train import evaluate_module, module_from_checkpoint, ppo_config, train

    try:
        kw = route_task.env_kwargs(args.terrain)
        try:
            hidden = tuple(int(h) for h in args.hidden.split(","))
        except ValueError:
            hidden = ()
        if not hidden or min(hidden) < 1:
            raise ValueError(f"--hidden must be layer widths >= 1 separated by commas (e.g. 64,64), got "
                             f"{args.hidden!r}")
        if args.max_episode_s is not None:
            kw["max_episode_s"] = float(args.max_episode_s)
        for name in ("iterations", "eval_seeds", "checkpoint_every", "envs_per_runner", "train_batch_size",
                     "minibatch_size", "epochs"):
            if getattr(args, name) < 1:
                raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
        if args.env_runners < 0:
            raise ValueError(f"--env-runners must be >= 0 (0: sample in the driver), got {args.env_runners}")
        if args.num_cpus is not None and (args.address or args.num_cpus < 1):
            raise ValueError(f"--num-cpus must be >= 1 and only without --address, got {args.num_cpus}")
        if not (math.isfinite(args.lr) and args.lr > 0):
            raise ValueError(f"--lr must be a finite number > 0, got {args.lr}")
        from trn_env.output.run_folder import folder_problem
        problem = folder_problem(args.out, "--out")
        if problem is not None:
            raise ValueError(problem)
        if args.eval_seeds > len(route_task.EVAL_SEEDS):
            raise ValueError(f"--eval-seeds must be at most the task's {len(route_task.EVAL_SEEDS)}, "
                             f"got {args.eval_seeds}")
        if args.evaluate_only is not None and not args.evaluate_only.is_dir():
            raise ValueError(f"--evaluate-only {args.evaluate_only}: no such checkpoint folder")
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    tier = args.tier if args.tier != "auto" else ("fast" if FAST_ID in gym.registry else "full")
    import ray

    from trn_env.campaign.ray_backend import connect_for_env_runners
    try:
        connect_for_env_runners(ray, args.address, args.num_cpus, args.env_runners)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    try:
        if args.evaluate_only is not None:
            module, history = module_from_checkpoint(args.evaluate_only), []
        else:
            try:
                cfg = ppo_config(tier, kw, seed=args.seed, num_env_runners=args.env_runners,
                                 num_envs_per_env_runner=args.envs_per_runner, hidden=hidden,
                                 train_batch_size=args.train_batch_size, minibatch_size=args.minibatch_size,
                                 num_epochs=args.epochs, lr=args.lr)
            except ValueError as err:
                print(f"error: {err}", file=sys.stderr)
                return 2

            def show(row):
                print(f"[iter {row['iteration']}] env steps {row['env_steps']:.0f}, episodes "
                      f"{row['episodes']:.0f}, mean return {row['episode_return_mean']:.2f}, "
                      f"{row['wall_s']:.0f} s", flush=True)

            algo, history = train(cfg, args.iterations, args.out / "checkpoints", args.checkpoint_every, show)
            module = algo.get_module()
            (args.out / "history.json").write_text(json.dumps(
                {"tier": tier, "terrain": args.terrain, "env": kw, "args": {k: str(v) for k, v in
                                                                             vars(args).items()},
                 "history": history}, indent=1))
        env = gym.make("trn_env/TerrainNav-v0", **kw)
        goals = env.unwrapped.held_out_goals_deg
        env.close()
        seeds = list(route_task.EVAL_SEEDS[:args.eval_seeds])
        rows = evaluate_module(module, kw, goals, seeds)
        (args.out / "evaluation.json").write_text(json.dumps(rows, indent=1))
        miss = [r["true_miss_m"] for r in rows if r["arrived"]]
        mean = sum(miss) / len(miss) if miss else math.nan
        print(f"evaluation ({tier}-trained, full loop): {len(miss)}/{len(rows)} arrived, mean true miss "
              f"{mean:.0f} m -> {args.out}")
    finally:
        ray.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
