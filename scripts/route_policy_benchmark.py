"""Route policies for TRN side by side: straight line, terrain-information planner, and a trained PPO policy.

    python scripts/route_policy_benchmark.py --out out/route_bench            # defaults (2 cores: < 1 h)
    python scripts/route_policy_benchmark.py --train-steps 60000 --seeds 10   # longer, more seeds
    python scripts/route_policy_benchmark.py --terrains basin --train-steps 0 # no PPO (straight vs planner)

For each terrain (the synthetic "basin" - rolling hills with a flat basin between the start region and the
goal region, scenario basin_route - and the bundled real DEM, scenario default):

1. trains PPO (stable-baselines3, the `rl` extra) in TerrainNav-v0's arrival task (the episode ends when the
   ESTIMATE says it has arrived; the TRUE miss counts) with the start and the goal drawn per episode from
   the terrain's regions (never within held_out_radius_m of a held-out goal), on a 2-env SubprocVecEnv;
   saves it to OUT/ppo_<terrain>.zip;
2. evaluates the straight-line policy, the planner policy (trn_env.policies.PlannerPolicy, replanning from
   the estimate at every decision step) and the trained policy on the same held-out goals (the env's
   documented set) and the same episode seeds, episodes spread over a local process pool
   (concurrent.futures; the campaign machinery is not on main yet);
3. writes OUT/episodes.json (one row per episode), OUT/summary.json and OUT/table.md (per terrain and
   policy: success rate, mean and 95th percentile TRUE horizontal error at the goal over the arrived
   episodes, mean extra distance flown against the straight line, collisions, mean return) and
   OUT/route_benchmark.png.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

TERRAINS = {
    # start south of the basin, goals just past its north rim (basin centre 36.635 N, radius ~6 km)
    "basin": dict(
        scenario="basin_route",
        agl_m=600.0,
        env=dict(
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
            start_region_deg=(36.47, 36.50, -84.39, -84.35),
            goal_region_deg=(36.64, 36.70, -84.22, -84.12),
            held_out_radius_m=1500.0,
        ),
    ),
}
ENV_COMMON = dict(decision_interval_s=5.0, max_episode_s=480.0, goal_radius_m=500.0)
POLICIES = ("straight", "planner", "ppo")
PLANNER = {"weight": 3.0, "informative_crlb_m": 5.0}     # set from the command line (run_episode's tasks)

_cache: dict = {}


def make_env(terrain_key: str):
    from trn_env.env.terrain_nav import TerrainNavEnv

    t = TERRAINS[terrain_key]
    return TerrainNavEnv(t["scenario"], **ENV_COMMON, **t["env"])


def train(terrain_key: str, steps: int, out: Path, seed: int = 0) -> Path:
    from functools import partial

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import SubprocVecEnv

    torch.set_num_threads(1)
    venv = SubprocVecEnv([partial(make_env, terrain_key)] * 2, start_method="forkserver")
    venv.seed(seed)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=256,
        batch_size=128,
        n_epochs=5,
        gamma=0.99,
        learning_rate=3e-4,
        seed=seed,
        device="cpu",
        policy_kwargs=dict(net_arch=[64, 64]),
        verbose=0,
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    venv.close()
    path = out / f"ppo_{terrain_key}.zip"
    model.save(path)
    print(f"[train] {terrain_key}: {steps} steps in {time.perf_counter() - t0:.0f} s -> {path}", flush=True)
    return path


def _policy(terrain_key: str, name: str, env, model_path: str | None):
    from trn_env.guidance.planner import PlannerConfig
    from trn_env.policies import PlannerPolicy, StraightLinePolicy

    agl = TERRAINS[terrain_key]["agl_m"]
    key = (terrain_key, name)
    if key in _cache:
        return _cache[key]
    if name == "straight":
        pol = StraightLinePolicy(env, agl_m=agl)
    elif name == "planner":
        pol = PlannerPolicy(env, PlannerConfig(weight=PLANNER["weight"], agl_m=agl, tas_mps=env.tas_mps,
                                               informative_crlb_m=PLANNER["informative_crlb_m"]))
    else:
        import torch
        from stable_baselines3 import PPO

        torch.set_num_threads(1)
        model = PPO.load(model_path, device="cpu")
        pol = model
    _cache[key] = pol
    return pol


def run_episode(task: tuple) -> dict:
    """One evaluation episode (runs in a pool worker; envs and policies cached per process)."""
    terrain_key, name, goal, seed, model_path, planner = task
    PLANNER.update(planner)
    env = _cache.get(terrain_key)
    if env is None:
        env = _cache[terrain_key] = make_env(terrain_key)
    pol = _policy(terrain_key, name, env, model_path)
    t0 = time.perf_counter()
    obs, info0 = env.reset(seed=seed, options={"goal_deg": goal})
    if hasattr(pol, "reset"):
        pol.reset()
    ret, done, info = 0.0, False, info0
    collisions = 0
    while not done:
        action, _ = pol.predict(obs, deterministic=True)
        obs, r, term, trunc, info = env.step(np.asarray(action, np.float32))
        ret += r
        done = term or trunc
    from terrain.geodesy import latlon_to_ned_offset

    s, g = info0["start_deg"], info0["goal_deg"]
    dn, de = latlon_to_ned_offset(
        math.radians(s[0]), math.radians(s[1]), 0.0, math.radians(g[0]), math.radians(g[1])
    )
    straight_m = math.hypot(dn, de)
    collisions = int(info["termination"] == "terrain_collision")
    return {
        "terrain": terrain_key,
        "policy": name,
        "goal_deg": list(goal),
        "seed": seed,
        "start_deg": list(s),
        "termination": info["termination"],
        "arrived": info["termination"] == "arrived",
        "true_miss_m": info.get("true_miss_m"),
        "final_true_error_m": info["true_horizontal_error_m"],
        "distance_flown_m": info["distance_flown_m"],
        "straight_distance_m": straight_m,
        "extra_distance_fraction": info["distance_flown_m"]
        / max(straight_m - ENV_COMMON["goal_radius_m"], 1.0)
        - 1.0,
        "collision": collisions,
        "return": ret,
        "t_s": info["t_s"],
        "wall_s": time.perf_counter() - t0,
    }


def summarise(rows: list[dict]) -> dict:
    out: dict = {}
    for r in rows:
        out.setdefault(r["terrain"], {}).setdefault(r["policy"], []).append(r)
    summary: dict = {}
    for terrain_key, per in out.items():
        summary[terrain_key] = {}
        for name, rs in per.items():
            miss = np.array([r["true_miss_m"] for r in rs if r["arrived"]], float)
            extra = np.array([r["extra_distance_fraction"] for r in rs if r["arrived"]], float)
            summary[terrain_key][name] = {
                "episodes": len(rs),
                "success_rate": float(np.mean([r["arrived"] for r in rs])),
                "mean_true_error_at_goal_m": float(miss.mean()) if miss.size else math.nan,
                "p95_true_error_at_goal_m": float(np.percentile(miss, 95)) if miss.size else math.nan,
                "mean_extra_distance_fraction": float(extra.mean()) if extra.size else math.nan,
                "collisions": int(sum(r["collision"] for r in rs)),
                "mean_return": float(np.mean([r["return"] for r in rs])),
                "terminations": {
                    k: sum(r["termination"] == k for r in rs) for k in {r["termination"] for r in rs}
                },
            }
        s, p = summary[terrain_key].get("straight"), summary[terrain_key].get("planner")
        if s and p and s["mean_true_error_at_goal_m"] > 0:
            summary[terrain_key]["planner_vs_straight_mean_error_reduction"] = (
                1.0 - p["mean_true_error_at_goal_m"] / s["mean_true_error_at_goal_m"]
            )
    return summary


def table(summary: dict) -> str:
    lines = [
        "| terrain | policy | episodes | success | mean error at goal (m) | p95 (m) | extra distance | "
        "collisions | mean return |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for terrain_key, per in summary.items():
        for name in POLICIES:
            if name not in per:
                continue
            v = per[name]
            lines.append(
                f"| {terrain_key} | {name} | {v['episodes']} | {100 * v['success_rate']:.0f} % | "
                f"{v['mean_true_error_at_goal_m']:.1f} | {v['p95_true_error_at_goal_m']:.1f} | "
                f"{100 * v['mean_extra_distance_fraction']:+.1f} % | {v['collisions']} | "
                f"{v['mean_return']:.2f} |"
            )
        red = per.get("planner_vs_straight_mean_error_reduction")
        if red is not None:
            lines.append(
                f"| {terrain_key} | planner vs straight | | | {100 * red:.0f} % less mean error | | | | |"
            )
    return "\n".join(lines) + "\n"


def plot(path: Path, rows: list[dict], summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    terrains = list(summary)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    colours = {"straight": "tab:gray", "planner": "tab:green", "ppo": "tab:blue"}
    width = 0.25
    for k, name in enumerate(POLICIES):
        means = [summary[t].get(name, {}).get("mean_true_error_at_goal_m", math.nan) for t in terrains]
        p95 = [summary[t].get(name, {}).get("p95_true_error_at_goal_m", math.nan) for t in terrains]
        x = np.arange(len(terrains)) + (k - 1) * width
        axes[0].bar(x, means, width, color=colours[name], label=f"{name} mean")
        axes[0].plot(x, p95, "v", color="black", ms=7, label="p95" if k == 0 else None)
    axes[0].set_xticks(np.arange(len(terrains)), terrains)
    axes[0].set_ylabel("true horizontal error at the goal (m)")
    axes[0].legend(fontsize=8)
    axes[0].set_title("navigation error when the estimate arrives")
    for r in rows:
        if r["arrived"]:
            axes[1].plot(
                100 * r["extra_distance_fraction"],
                r["true_miss_m"],
                "o" if r["terrain"] == terrains[0] else "s",
                color=colours[r["policy"]],
                alpha=0.6,
                ms=5,
            )
    for name, c in colours.items():
        axes[1].plot([], [], "o", color=c, label=name)
    axes[1].set_xlabel("extra distance flown vs the straight line (%)")
    axes[1].set_ylabel("true error at the goal (m)")
    axes[1].set_title(f"per episode (o {terrains[0]}" + (f", s {terrains[1]})" if len(terrains) > 1 else ")"))
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--terrains", nargs="+", default=list(TERRAINS), choices=list(TERRAINS))
    p.add_argument(
        "--train-steps",
        type=int,
        default=12288,
        help="PPO env steps per terrain (0: no PPO); default 12288 (~15 min per terrain on 2 cores)",
    )
    p.add_argument("--seeds", type=int, default=4, help="episode seeds per held-out goal (default 4)")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument("--planner-weight", type=float, default=PLANNER["weight"],
                   help="the planner's weight (extra cost of a featureless metre)")
    p.add_argument("--planner-informative-crlb", type=float, default=PLANNER["informative_crlb_m"],
                   help="CRLB (m) at or below which the planner counts terrain as informative")
    p.add_argument("--out", type=Path, default=Path("out/route_bench"))
    a = p.parse_args(argv)
    PLANNER.update(weight=a.planner_weight, informative_crlb_m=a.planner_informative_crlb)
    if a.train_steps < 0 or a.seeds < 1 or a.workers < 1:
        print("error: --train-steps >= 0, --seeds >= 1, --workers >= 1", file=sys.stderr)
        return 2
    a.out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    rows: list[dict] = []
    for t in a.terrains:                 # train, evaluate and write one terrain at a time
        model = str(train(t, a.train_steps, a.out)) if a.train_steps > 0 else None
        tasks = []
        for g in make_env(t).held_out_goals_deg:
            for seed in range(1000, 1000 + a.seeds):
                for name in POLICIES:
                    if name == "ppo" and model is None:
                        continue
                    tasks.append((t, name, tuple(g), seed, model, dict(PLANNER)))
        print(f"[eval] {t}: {len(tasks)} episodes on {a.workers} workers", flush=True)
        t0 = time.perf_counter()
        with ProcessPoolExecutor(a.workers, mp_context=get_context("forkserver")) as pool:
            rows += list(pool.map(run_episode, tasks, chunksize=1))
        print(f"[eval] {t}: {time.perf_counter() - t0:.0f} s", flush=True)
        summary = summarise(rows)
        summary["_run"] = {"planner": dict(PLANNER), "train_steps": a.train_steps, "seeds_per_goal": a.seeds,
                           "workers": a.workers,
                           "wall_s": time.perf_counter() - t_start, "env": ENV_COMMON,
                           "terrains": {k: TERRAINS[k] for k in a.terrains},
                           "held_out_goals_deg": {k: make_env(k).held_out_goals_deg for k in a.terrains}}
        (a.out / "episodes.json").write_text(json.dumps(rows, indent=1))
        (a.out / "summary.json").write_text(json.dumps(summary, indent=2))
        per = {k: v for k, v in summary.items() if not k.startswith("_")}
        tab = table(per)
        (a.out / "table.md").write_text(tab)
        plot(a.out / "route_benchmark.png", rows, per)
    print(tab)
    print(f"total {time.perf_counter() - t_start:.0f} s; {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
