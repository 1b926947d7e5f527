"""PPO on Ray RLlib over either env tier: configuration, the training loop with checkpoints, evaluation.

    config = ppo_config("full", env_kwargs("basin"), num_env_runners=2)
    algo, history = train(config, iterations=50, checkpoint_dir="out/ckpt")
    rows = evaluate_module(algo.get_module(), env_kwargs("basin"), goals_deg, seeds=[1000, 1001])

The training loop is RLlib's (`Algorithm.train()`, one iteration = sampling `train_batch_size` env steps on
the EnvRunners, then `num_epochs` passes of minibatch SGD on the Learner); on a cluster the EnvRunners spread
over its nodes (`ray.init(address=...)` before building, scripts/train_rllib.py `--address`). The history
rows carry what a learning curve needs: iteration, env steps and episodes so far, the mean episode return of
the iteration's finished episodes, wall seconds. Evaluation flies the module's mean action (deterministic)
in a local full-fidelity env on given goals and episode seeds; one row per episode with the termination,
the true miss at arrival and the distance flown.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from trn_env.env.rllib import (
    FAST_ID,
    FULL_ID,
    deterministic_action,
    make_full_env,
    register_rllib_envs,
    require_rllib,
    rllib_env_settings,
)

# how long an iteration waits for its EnvRunners' samples (s): a JSBSim runner on a loaded machine can take
# minutes for a batch, and RLlib's default (60 s) would train on whatever arrived
SAMPLE_TIMEOUT_S = 3600.0


def ppo_config(tier: str, env_config: dict, *, seed: int = 0, num_env_runners: int = 1,
               num_envs_per_env_runner: int = 1, hidden: tuple[int, ...] = (64, 64),
               train_batch_size: int = 256, minibatch_size: int = 64, num_epochs: int = 10,
               lr: float = 3e-4, gamma: float = 0.99, lambda_: float = 0.95, entropy_coeff: float = 0.0,
               lr_end: float | None = None, lr_decay_steps: int | None = None, vf_clip_param: float = 10.0,
               log_std_clip: float = 20.0,
               activation: str = "tanh"):
    """An RLlib PPOConfig (new API stack, torch) for an env tier ("full" or "fast") with env_config (the env's
    keyword arguments). `lr_end` with `lr_decay_steps`: the learning rate falls linearly from `lr` to
    `lr_end` over that many env steps, then stays (RLlib's piecewise schedule). `vf_clip_param`: RLlib's
    clip of the value loss (in squared return units). ValueError naming the argument on bad input;
    RLlibNotInstalled without the extra."""
    require_rllib()
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    names = register_rllib_envs()
    if tier not in ("full", "fast"):
        raise ValueError(f"tier must be 'full' or 'fast', got {tier!r}")
    if tier not in names:
        raise ValueError(f"tier 'fast': {FAST_ID} is not registered in this installation")
    for name, v in (("num_env_runners", num_env_runners),
                    ("num_envs_per_env_runner", num_envs_per_env_runner),
                    ("train_batch_size", train_batch_size), ("minibatch_size", minibatch_size),
                    ("num_epochs", num_epochs)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < (0 if name == "num_env_runners"
                                                                               else 1):
            raise ValueError(f"{name} must be a whole number >= {0 if name == 'num_env_runners' else 1}, "
                             f"got {v!r}")
    if minibatch_size > train_batch_size:
        raise ValueError(f"minibatch_size ({minibatch_size}) must not exceed train_batch_size "
                         f"({train_batch_size})")
    if not hidden or any(not isinstance(h, (int, np.integer)) or h < 1 for h in hidden):
        raise ValueError(f"hidden must be layer widths >= 1, got {hidden!r}")
    for name, v, lo, hi in (("lr", lr, 0.0, 1.0), ("gamma", gamma, 0.0, 1.0), ("lambda_", lambda_, 0.0, 1.0),
                            ("vf_clip_param", vf_clip_param, 0.0, math.inf)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo < v <= hi:
            raise ValueError(f"{name} must be a number in ({lo}, {hi}], got {v!r}")
    if isinstance(entropy_coeff, bool) or not isinstance(entropy_coeff, (int, float)) or not (
            0.0 <= entropy_coeff < math.inf):
        raise ValueError(f"entropy_coeff must be a finite number >= 0, got {entropy_coeff!r}")
    if isinstance(log_std_clip, bool) or not isinstance(log_std_clip, (int, float)) or not (
            0.0 <= log_std_clip < math.inf):
        raise ValueError(f"log_std_clip must be a finite number >= 0, got {log_std_clip!r}")
    if (lr_end is None) != (lr_decay_steps is None):
        raise ValueError("lr_end and lr_decay_steps go together (both or neither)")
    if lr_end is not None and (isinstance(lr_end, bool) or not isinstance(lr_end, (int, float))
                               or not 0.0 < lr_end <= 1.0):
        raise ValueError(f"lr_end must be a number in (0, 1], got {lr_end!r}")
    if lr_decay_steps is not None and (isinstance(lr_decay_steps, bool) or not isinstance(
            lr_decay_steps, (int, np.integer)) or lr_decay_steps < 1):
        raise ValueError(f"lr_decay_steps must be a whole number >= 1, got {lr_decay_steps!r}")
    if activation not in ("tanh", "relu"):
        raise ValueError(f"activation must be 'tanh' or 'relu', got {activation!r}")
    lr_arg = float(lr) if lr_end is None else [[0, float(lr)], [int(lr_decay_steps), float(lr_end)]]
    return (
        PPOConfig()
        .environment(names[tier], env_config=dict(env_config))
        .env_runners(num_env_runners=int(num_env_runners),
                     num_envs_per_env_runner=int(num_envs_per_env_runner), num_cpus_per_env_runner=1,
                     create_local_env_runner=int(num_env_runners) == 0, sample_timeout_s=SAMPLE_TIMEOUT_S,
                     **rllib_env_settings(tier))
        .learners(num_learners=0)
        .training(train_batch_size_per_learner=int(train_batch_size), minibatch_size=int(minibatch_size),
                  num_epochs=int(num_epochs), lr=lr_arg, gamma=float(gamma), lambda_=float(lambda_),
                  entropy_coeff=float(entropy_coeff), vf_clip_param=float(vf_clip_param))
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=[int(h) for h in hidden],
                                                   fcnet_activation=activation, vf_share_layers=False,
                                                   log_std_clip_param=float(log_std_clip)))
        .debugging(seed=int(seed))
        .reporting(metrics_num_episodes_for_smoothing=20)
    )


def _metric(result: dict, key: str, default=math.nan):
    v = result.get("env_runners", {}).get(key, default)
    try:
        return float(v)
    except (TypeError, ValueError):
        return default


def train(config, iterations: int, checkpoint_dir: str | Path | None = None, checkpoint_every: int = 10,
          progress=None, max_wall_s: float | None = None,
          max_cpu_s: float | None = None) -> tuple[Any, list[dict]]:
    """Build the algorithm from `config` (or take an Algorithm already built) and run `iterations` training
    iterations; a checkpoint (`Algorithm.save_to_path`) every `checkpoint_every` iterations and at the end
    into checkpoint_dir/iter_N (checkpoint_dir/final at the end).

    The end is the first of: `iterations`; the first iteration that ends after `max_wall_s` of wall time;
    the last iteration that keeps the run within `max_cpu_s` CPU seconds, i.e. the iteration after which
    one more iteration costing what the last one did would exceed it (`cpu_s`, below). The CPU budget is
    the one that means the same on an idle and on a shared machine: 30 minutes on 2 idle cores are at most
    3,600 CPU seconds, and a run that stops at 3,600 CPU seconds got no more than that whatever the load.

    Returns (algorithm, history rows: iteration, env steps, episodes, mean return and length, wall_s,
    driver_cpu_s (this process since the call, the build included: the local learner, and sampling when
    there are no remote EnvRunners), env_runner_cpu_s (the remote EnvRunner processes' CPU in total,
    construction included) and cpu_s, their sum: the CPU seconds the run got). progress(row) is called
    per row. The learner is local (`ppo_config` sets no remote learners), so these are every process that
    trains."""
    if not isinstance(iterations, int) or iterations < 1:
        raise ValueError(f"iterations must be a whole number >= 1, got {iterations!r}")
    for name, v in (("max_wall_s", max_wall_s), ("max_cpu_s", max_cpu_s)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0
                              or not math.isfinite(v)):
            raise ValueError(f"{name} must be a finite number > 0 or None, got {v!r}")
    t0 = time.perf_counter()
    c0 = time.process_time()            # (before building: the driver's share of the build counts too)
    algo = config if hasattr(config, "train") else config.build_algo()
    history = []
    ckpt = Path(checkpoint_dir) if checkpoint_dir is not None else None
    for it in range(1, iterations + 1):
        res = algo.train()
        row = {"iteration": it, "env_steps": _metric(res, "num_env_steps_sampled_lifetime"),
               "episodes": _metric(res, "num_episodes_lifetime", 0.0),
               "episode_return_mean": _metric(res, "episode_return_mean"),
               "episode_len_mean": _metric(res, "episode_len_mean"),
               "wall_s": time.perf_counter() - t0,
               "driver_cpu_s": time.process_time() - c0,        # this process: learner (+ local sampling)
               "env_runner_cpu_s": _env_runner_cpu_s(algo)}     # remote EnvRunners' processes, in total
        row["cpu_s"] = row["driver_cpu_s"] + row["env_runner_cpu_s"]
        history.append(row)
        if progress is not None:
            progress(row)
        last = it == iterations or (max_wall_s is not None and row["wall_s"] >= max_wall_s)
        if max_cpu_s is not None:
            if not math.isfinite(row["cpu_s"]):
                raise RuntimeError("max_cpu_s: the EnvRunners' CPU time cannot be read (a runner died?)")
            step = row["cpu_s"] - (history[-2]["cpu_s"] if len(history) > 1 else 0.0)
            last = last or row["cpu_s"] + step > max_cpu_s
        if ckpt is not None and (it % max(1, checkpoint_every) == 0 or last):
            algo.save_to_path(str((ckpt / ("final" if last else f"iter_{it}")).resolve()))
        if last:
            break
    return algo, history


def _env_runner_cpu_s(algo) -> float:
    """CPU seconds used so far by the algorithm's remote EnvRunner processes (0 without remote runners; NaN
    if they cannot be asked): on a shared machine the wall budget buys less CPU, and this says how much."""
    group = getattr(algo, "env_runner_group", None)
    if group is None or group.num_remote_env_runners() == 0:
        return 0.0
    try:
        return float(sum(group.foreach_env_runner(lambda r: time.process_time(), local_env_runner=False)))
    except Exception:               # a runner that died or a group API that changed: unknown, not zero
        return math.nan


def module_from_checkpoint(path: str | Path):
    """The trained RLModule (default policy) of a checkpoint written by `train`."""
    require_rllib()
    from ray.rllib.core.rl_module.rl_module import RLModule

    # absolute: RLlib reads the folder through pyarrow's filesystem, which takes a relative path for a URI
    # without a scheme and fails
    p = Path(path).resolve() / "learner_group" / "learner" / "rl_module" / "default_policy"
    if not p.is_dir():
        raise ValueError(f"checkpoint {path}: no RLModule at {p} (not a checkpoint written by train())")
    return RLModule.from_checkpoint(str(p))


def evaluate_module(module, env_config: dict, goals_deg, seeds,
                    scale_observations: bool = True) -> list[dict]:
    """Fly the module's mean action on every (goal, seed) pair in a local TerrainNav-v0 built from
    env_config; one row per episode: goal_index, goal_deg, seed, termination, arrived, true_miss_m (NaN if it
    did not arrive), distance_flown_m, return, steps."""
    env = make_full_env({**env_config, "scale_observations": scale_observations})
    rows = []
    try:
        for gi, g in enumerate(goals_deg):
            for s in seeds:
                obs, _ = env.reset(seed=int(s), options={"goal_deg": tuple(g)})
                ret, n, done, info = 0.0, 0, False, {}
                while not done:
                    obs, r, term, trunc, info = env.step(deterministic_action(module, obs))
                    ret += float(r)
                    n += 1
                    done = term or trunc
                rows.append({"goal_index": gi, "goal_deg": list(g), "seed": int(s),
                             "termination": info.get("termination"),
                             "arrived": info.get("termination") == "arrived",
                             "true_miss_m": float(info.get("true_miss_m", math.nan)),
                             "distance_flown_m": float(info.get("distance_flown_m", math.nan)),
                             "return": ret, "steps": n})
    finally:
        env.close()
    return rows


__all__ = ["FULL_ID", "FAST_ID", "ppo_config", "train", "module_from_checkpoint", "evaluate_module"]
