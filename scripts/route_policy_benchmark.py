"""Route policies for TRN side by side: straight line, terrain-information planner, and a trained PPO policy.

    python scripts/route_policy_benchmark.py --out out/route_bench            # defaults (2 cores: < 1 h)
    python scripts/route_policy_benchmark.py --train-steps 100000 --seeds 10  # longer, more seeds
    python scripts/route_policy_benchmark.py --terrains basin --train-steps 0 # no PPO (straight vs planner)
    python scripts/route_policy_benchmark.py --backend ray                    # evaluation on Ray

For each terrain (the synthetic "basin" - rolling hills with a flat basin between the start region and the
goal region, scenario basin_route - and the bundled real DEM, scenario default):

1. trains PPO (stable-baselines3, the `rl` extra) in TerrainNav-v0's arrival task (the episode ends when the
   ESTIMATE says it has arrived; the TRUE miss counts) with the start and the goal drawn per episode from
   the terrain's regions (never within held_out_radius_m of a held-out goal), on an `--envs`-env
   SubprocVecEnv (default 2); saves the trained model to OUT/ppo_<terrain>.zip, the same network before
   training to OUT/ppo_<terrain>_untrained.zip, and the training episodes to OUT/train_<terrain>.json;
2. evaluates the straight-line policy, the planner policy (trn_env.policies.PlannerPolicy, replanning from
   the estimate at every decision step), the trained policy (deterministic: the mean action), the
   untrained network acting as at the start of training (samples of its action distribution; its mean
   action, 0, is the straight line) and uniformly random actions on the same held-out goals (the env's
   documented set) and the same episode seeds, as an episode
   campaign (trn_env.campaign.episodes: one Parquet row per episode in OUT/episodes_<terrain>/, on the
   campaign backends - the local pool on every core, or Ray);
3. writes OUT/summary.json and OUT/table.md (per terrain and policy: success rate, mean and 95th
   percentile TRUE horizontal error at the goal over the arrived episodes, mean extra distance flown against
   the straight line, collisions, mean return) and OUT/route_benchmark.png (errors, error against extra
   distance, and the training curve).

The learning setup (documented in TerrainNavEnv's docstring; measured in docs/guide/planning.md's benchmark
section). Coarse decisions: `action_mode="pursuit"` with `decision_interval_s` 30 (an action is an offset
from the goal's bearing, HELD from the estimate at every guidance tick, so a constant action flies a log
spiral into the goal; +-45 deg, `bearing_offset_max_deg`, at most +41 % distance; and a height above ground
in [agl_min_m, agl_max_m], whose middle is the straight line's height): an episode is ~8-12 decisions of
which way round, so the credit for the miss at the goal reaches the decisions that caused it. Observations
the choice needs: the route information (observation 22-31: the map's CRLB along the 5 constant-offset
routes from the estimate to the goal, MAP only), which lets one network generalise over goals drawn per
episode instead of memorising routes; every element mapped to [-1, 1] by its bounds
(trn_env.env.sb3_features.BoundsScaledExtractor). Rewards: the arrival task's (progress potential with
`shaping_gamma` 1, time cost, +10 at arrival - 20 per km of TRUE miss, failure penalty 20);
`sigma_shaping_weight` (the potential on the navigator's reported sigma) is available and 0 here (see
docs/guide/planning.md for the comparison). PPO: n_steps 128 per env x 2 envs (~28 episodes per update),
batch 64, 10 epochs, gamma 0.99, GAE lambda 0.95, learning rate 3e-4, ent_coef 0, log_std_init -0.7 (an
action std of 0.5: +-22 deg about the straight line, which explores both ways round the basin), net 64-64.
Untrained and trained networks share the same initial weights (seed 0).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from trn_env.env.route_task import TERRAINS  # the terrains' scenarios, heights and regions

GAMMA = 0.99
# the route task's settings (trn_env.env.route_task.ENV_COMMON) at JSBSim's default step
ENV_COMMON = dict(decision_interval_s=30.0, max_episode_s=480.0, goal_radius_m=500.0, action_mode="pursuit",
                  bearing_offset_max_deg=45.0, failure_penalty=20.0, sigma_shaping_weight=0.0)
PPO_SETTINGS = dict(n_steps=128, batch_size=64, n_epochs=10, gamma=GAMMA, gae_lambda=0.95,
                    learning_rate=1e-3, ent_coef=0.0, clip_range=0.2, use_sde=True, sde_sample_freq=8)
POLICY_NET = dict(net_arch=[64, 64], log_std_init=-2.0)
POLICIES = ("straight", "planner", "ppo", "ppo_untrained", "random")
PLANNER_DEFAULTS = {"weight": 3.0, "informative_crlb_m": 5.0}
PLANNER = dict(PLANNER_DEFAULTS)     # set from the command line (each main() from its own arguments)


def env_spec(terrain_key: str) -> dict:
    """TerrainNavEnv arguments of a terrain (JSON types: what the episode campaign carries)."""
    t = TERRAINS[terrain_key]
    return json.loads(json.dumps({"scenario": t["scenario"], **ENV_COMMON, **t["env"]}))


def make_env(terrain_key: str, spec: dict | None = None):
    """The terrain's env; `spec` (env_spec's, made in the parent) so that worker processes, which import this
    module afresh, build exactly the parent's env."""
    from trn_env.env.terrain_nav import TerrainNavEnv

    return TerrainNavEnv(**(spec if spec is not None else env_spec(terrain_key)))


def cpu_s() -> float:
    """CPU seconds of this process and its waited-for descendants (the evaluation's forked pool)."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def proc_cpu_s(pid: int) -> float:
    """CPU seconds of a live process and its waited-for children (Linux /proc; NaN elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return sum(int(x) for x in fields[11:15]) / os.sysconf("SC_CLK_TCK")     # utime stime cutime cstime
    except (OSError, ValueError, IndexError):
        return math.nan


def train(terrain_key: str, steps: int, out: Path, seed: int = 0, n_envs: int = 2) -> tuple[Path, Path]:
    """Train PPO; returns (trained model, untrained model) paths. Training episodes -> OUT/train_<t>.json."""
    from functools import partial

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecMonitor

    from trn_env.env.sb3_features import BoundsScaledExtractor

    class Episodes(BaseCallback):
        def __init__(self):
            super().__init__()
            self.rows: list[dict] = []

        def _on_step(self) -> bool:
            for inf in self.locals["infos"]:
                if "episode" in inf:
                    ep = inf["episode"]
                    self.rows.append({"timesteps": int(self.num_timesteps), "return": float(ep["r"]),
                                      "length": int(ep["l"]), "termination": inf.get("termination")})
            return True

    torch.set_num_threads(1)
    fns = [partial(make_env, terrain_key, env_spec(terrain_key))] * n_envs
    venv = VecMonitor(SubprocVecEnv(fns, start_method="forkserver"), info_keywords=("termination",))
    venv.seed(seed)
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **PPO_SETTINGS,
                policy_kwargs=dict(features_extractor_class=BoundsScaledExtractor, **POLICY_NET))
    model.set_logger(configure(str(out), []))   # SB3's own would leave a folder in the system tmp
    untrained = out / f"ppo_{terrain_key}_untrained.zip"
    model.save(untrained)
    cb = Episodes()
    t0, c0 = time.perf_counter(), cpu_s()
    workers = [proc.pid for proc in venv.venv.processes]
    w0 = sum(proc_cpu_s(pid) for pid in workers)
    model.learn(total_timesteps=steps, callback=cb)
    wall = time.perf_counter() - t0
    train_cpu = cpu_s() - c0 + sum(proc_cpu_s(pid) for pid in workers) - w0      # learner + env workers
    venv.close()
    path = out / f"ppo_{terrain_key}.zip"
    model.save(path)
    (out / f"train_{terrain_key}.json").write_text(json.dumps(
        {"steps": steps, "n_envs": n_envs, "wall_s": wall, "cpu_s": train_cpu, "env": env_spec(terrain_key),
         "ppo": PPO_SETTINGS, "policy": POLICY_NET,
         "episodes": cb.rows}, indent=1))
    print(f"[train] {terrain_key}: {steps} steps in {wall:.0f} s wall, {train_cpu:.0f} s CPU "
          f"({steps / wall:.1f} steps/s) -> {path}", flush=True)
    return path, untrained


def policy_specs(terrain_key: str, models: tuple[Path, Path] | None) -> list[dict]:
    agl = TERRAINS[terrain_key]["agl_m"]
    out = [{"label": "straight", "kind": "straight", "agl_m": agl},
           {"label": "planner", "kind": "planner", "agl_m": agl, "config": dict(PLANNER)}]
    if models is not None:
        out += [{"label": "ppo", "kind": "sb3", "model": str(models[0])},
                {"label": "ppo_untrained", "kind": "sb3", "model": str(models[1]), "deterministic": False}]
    out.append({"label": "random", "kind": "random"})
    return out


def evaluate(terrain_key: str, models, seeds: list[int], out_dir: Path, backend) -> list[dict]:
    """The evaluation episodes as an episode campaign; its rows (dicts), one per episode."""
    from trn_env.campaign import run_campaign
    from trn_env.campaign.episodes import episode_campaign
    from trn_env.campaign.rows import read_rows

    campaign = episode_campaign({"name": f"route_bench_{terrain_key}", "env": env_spec(terrain_key),
                                 "policies": policy_specs(terrain_key, models), "goals_deg": "held_out",
                                 "seeds": seeds})
    if out_dir.exists():                       # an earlier evaluation's campaign folder, never anything else
        if not (out_dir / "campaign.json").is_file():
            raise SystemExit(f"error: {out_dir} exists and holds no earlier evaluation (no campaign.json); "
                             "remove it or give another --out")
        shutil.rmtree(out_dir)
    stats = run_campaign(campaign, out_dir, backend=backend, progress=False)
    rows = read_rows(out_dir).to_dict("records")
    for r in rows:
        r["terrain"] = terrain_key
        if isinstance(r.get("true_miss_m"), float) and math.isnan(r["true_miss_m"]):
            r["true_miss_m"] = None
    errors = [r for r in rows if r["termination"] == "error"]
    if errors:
        raise RuntimeError(f"{len(errors)} evaluation episode(s) failed, e.g. {errors[0]['error']}")
    print(f"[eval] {terrain_key}: {stats['flown']} episodes in {stats['wall_time_s']:.0f} s "
          f"({stats['backend']}) -> {out_dir}", flush=True)
    return rows


PAIRS = (("ppo", "straight"), ("ppo", "ppo_untrained"), ("planner", "straight"))


def paired(rows: list[dict], a: str, b: str) -> dict | None:
    """Paired comparison of policies a and b over the episodes both flew to arrival with the same goal and
    seed (common random numbers): the mean of (miss_a - miss_b) with its 95 % confidence interval
    (Student t over the pairs) and the two-sided sign test's p-value (binomial, ties dropped)."""
    from scipy import stats

    key = lambda r: (round(r["goal_lat_deg"], 9), round(r["goal_lon_deg"], 9), int(r["seed"]))   # noqa: E731
    rows = [r for r in rows if all(k in r for k in ("goal_lat_deg", "goal_lon_deg", "seed"))]
    ra = {key(r): r for r in rows if r["policy"] == a and r["arrived"]}
    rb = {key(r): r for r in rows if r["policy"] == b and r["arrived"]}
    both = sorted(set(ra) & set(rb))
    if len(both) < 2:
        return None
    d = np.array([ra[k]["true_miss_m"] - rb[k]["true_miss_m"] for k in both], float)
    half = float(stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size))
    wins, losses = int(np.sum(d < 0)), int(np.sum(d > 0))
    p_sign = float(stats.binomtest(wins, wins + losses, 0.5).pvalue) if wins + losses else 1.0
    return {"pairs": int(d.size), "mean_difference_m": float(d.mean()),
            "ci95_m": [float(d.mean() - half), float(d.mean() + half)], "a_better": wins, "b_better": losses,
            "sign_test_p": p_sign}


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
        for a, b in PAIRS:
            cmp = paired(per_rows := [r for r in rows if r["terrain"] == terrain_key], a, b)
            if cmp is not None:
                summary[terrain_key][f"{a}_vs_{b}"] = cmp
        arrived = [r for r in per_rows if r["arrived"]]
        if len(arrived) > 2:             # do returns rank episodes by their navigation quality?
            from scipy import stats
            rho = stats.spearmanr([r["return"] for r in arrived], [r["true_miss_m"] for r in arrived])
            summary[terrain_key]["return_vs_miss_spearman"] = float(rho.statistic)
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
                f"| {terrain_key} | planner vs straight | | | {100 * abs(red):.0f} % "
                f"{'less' if red >= 0 else 'more'} mean error | | | | |"
            )
    lines += ["", "| terrain | paired (same goal and seed) | pairs | mean difference of the error (m) | "
              "95 % CI (m) | first better / second better | sign test p |", "|---|---|---|---|---|---|---|"]
    for terrain_key, per in summary.items():
        for a, b in PAIRS:
            c = per.get(f"{a}_vs_{b}")
            if c:
                lo, hi = c["ci95_m"]
                lines.append(f"| {terrain_key} | {a} - {b} | {c['pairs']} | {c['mean_difference_m']:+.1f} | "
                             f"[{lo:+.1f}, {hi:+.1f}] | {c['a_better']} / {c['b_better']} | "
                             f"{c['sign_test_p']:.2g} |")
    for terrain_key, per in summary.items():
        if "return_vs_miss_spearman" in per:
            lines.append(f"\n{terrain_key}: Spearman correlation of the episode return and the true error at "
                         f"the goal (arrived episodes): {per['return_vs_miss_spearman']:+.2f}")
    return "\n".join(lines) + "\n"


def plot(path: Path, rows: list[dict], summary: dict, training: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    terrains = list(summary)
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.8))
    colours = {"straight": "tab:gray", "planner": "tab:green", "ppo": "tab:blue",
               "ppo_untrained": "tab:purple", "random": "tab:red"}
    names = [n for n in POLICIES if any(n in summary[t] for t in terrains)]
    width = 0.8 / max(1, len(names))
    for k, name in enumerate(names):
        means = [summary[t].get(name, {}).get("mean_true_error_at_goal_m", math.nan) for t in terrains]
        p95 = [summary[t].get(name, {}).get("p95_true_error_at_goal_m", math.nan) for t in terrains]
        x = np.arange(len(terrains)) + (k - (len(names) - 1) / 2) * width
        axes[0].bar(x, means, width, color=colours[name], label=f"{name} mean")
        axes[0].plot(x, p95, "v", color="black", ms=7, label="p95" if k == 0 else None)
    axes[0].set_xticks(np.arange(len(terrains)), terrains)
    axes[0].set_ylabel("true horizontal error at the goal (m)")
    axes[0].legend(fontsize=8)
    axes[0].set_title("navigation error when the estimate arrives")
    for r in rows:
        if r["arrived"]:
            axes[1].plot(100 * r["extra_distance_fraction"], r["true_miss_m"],
                         "o" if r["terrain"] == terrains[0] else "s", color=colours[r["policy"]],
                         alpha=0.6, ms=5)
    for name in names:
        axes[1].plot([], [], "o", color=colours[name], label=name)
    axes[1].set_xlabel("extra distance flown vs the straight line (%)")
    axes[1].set_ylabel("true error at the goal (m)")
    axes[1].set_title(f"per episode (o {terrains[0]}" + (f", s {terrains[1]})" if len(terrains) > 1 else ")"))
    axes[1].legend(fontsize=8)
    for t, tr in training.items():
        eps = tr["episodes"]
        if not eps:
            continue
        x = np.array([e["timesteps"] for e in eps])
        arrived = np.array([e["termination"] == "arrived" for e in eps], float)
        k = max(1, min(20, len(eps) // 5))
        kern = np.ones(k) / k
        axes[2].plot(x[k - 1:], 100 * np.convolve(arrived, kern, "valid"), label=f"{t}: arrived (%)")
        axes[2].plot(x[k - 1:], np.convolve([e["return"] for e in eps], kern, "valid"), "--",
                     label=f"{t}: return")
    axes[2].set_xlabel("PPO env steps")
    axes[2].set_title("training episodes (running mean of 20; stochastic policy)")
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    from trn_env.campaign import make_backend

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--terrains", nargs="+", default=list(TERRAINS), choices=list(TERRAINS))
    p.add_argument("--train-steps", type=int, default=12288,
                   help="PPO env steps (30 s decisions) per terrain (0: no PPO); default 12288 (~1,200 "
                        "episodes); longer: e.g. 20000 (see the README for the CPU time per step)")
    p.add_argument("--envs", type=int, default=2, help="training envs (SubprocVecEnv workers; default 2)")
    p.add_argument("--seeds", type=int, default=4, help="episode seeds per held-out goal (default 4)")
    p.add_argument("--workers", type=int, default=None, help="evaluation workers (default: every core)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="campaign backend of the evaluation (default local)")
    p.add_argument("--planner-weight", type=float, default=PLANNER_DEFAULTS["weight"],
                   help="the planner's weight (extra cost of a featureless metre)")
    p.add_argument("--planner-informative-crlb", type=float, default=PLANNER_DEFAULTS["informative_crlb_m"],
                   help="CRLB (m) at or below which the planner counts terrain as informative")
    p.add_argument("--out", type=Path, default=Path("out/route_bench"))
    p.add_argument("--reuse-models", action="store_true",
                   help="evaluate the models already in OUT (ppo_<terrain>.zip, ppo_<terrain>_untrained.zip, "
                        "train_<terrain>.json from an earlier run of this script) instead of training")
    a = p.parse_args(argv)
    PLANNER.update(weight=a.planner_weight, informative_crlb_m=a.planner_informative_crlb)
    if a.train_steps < 0 or a.seeds < 1 or (a.workers is not None and a.workers < 1) or a.envs < 1:
        print("error: --train-steps >= 0, --seeds >= 1, --workers >= 1, --envs >= 1", file=sys.stderr)
        return 2
    # what the evaluation takes is checked before the training, which it would otherwise follow by minutes
    from trn_env.campaign.local import check_local_workers
    from trn_env.guidance.planner import PlannerConfig
    try:
        check_local_workers(a.envs, "--envs")              # SubprocVecEnv: one process per env
        make_backend(a.backend, a.workers)
        PlannerConfig(**PLANNER)
    except ValueError as err:
        msg = str(err).replace("PlannerConfig.weight", "--planner-weight").replace(
            "PlannerConfig.informative_crlb_m", "--planner-informative-crlb")
        print(f"error: {msg}", file=sys.stderr)
        return 2
    from trn_env.output.run_folder import folder_problem
    problem = folder_problem(a.out, "--out")
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    a.out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    rows: list[dict] = []
    training: dict = {}
    seeds = list(range(1000, 1000 + a.seeds))
    timing: dict = {}
    for t in a.terrains:                 # train, evaluate and write one terrain at a time
        t0 = time.perf_counter()
        saved = (a.out / f"ppo_{t}.zip", a.out / f"ppo_{t}_untrained.zip")
        if a.reuse_models and a.train_steps > 0:
            if not all(f.exists() for f in (*saved, a.out / f"train_{t}.json")):
                print(f"error: --reuse-models: no trained models for {t} in {a.out}", file=sys.stderr)
                return 2
            models = saved
            print(f"[train] {t}: reusing {saved[0]}", flush=True)
        else:
            models = train(t, a.train_steps, a.out, n_envs=a.envs) if a.train_steps > 0 else None
        if models is not None:
            training[t] = json.loads((a.out / f"train_{t}.json").read_text())
            timing[f"{t}_train_s"] = training[t]["wall_s"]
            timing[f"{t}_train_cpu_s"] = training[t].get("cpu_s")
        t0, c0 = time.perf_counter(), cpu_s()
        rows += evaluate(t, models, seeds, a.out / f"episodes_{t}", make_backend(a.backend, a.workers))
        timing[f"{t}_eval_s"] = time.perf_counter() - t0
        timing[f"{t}_eval_cpu_s"] = cpu_s() - c0
        summary = summarise(rows)
        summary["_run"] = {"planner": dict(PLANNER), "train_steps": a.train_steps, "seeds": seeds,
                           "envs": a.envs, "backend": a.backend, "workers": a.workers or os.cpu_count(),
                           "wall_s": time.perf_counter() - t_start, "timing_s": timing, "env": ENV_COMMON,
                           "ppo": PPO_SETTINGS, "policy_net": POLICY_NET,
                           "terrains": {k: TERRAINS[k] for k in a.terrains},
                           "held_out_goals_deg": {k: make_env(k).held_out_goals_deg for k in a.terrains}}
        (a.out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
        per = {k: v for k, v in summary.items() if not k.startswith("_")}
        tab = table(per)
        (a.out / "table.md").write_text(tab)
        plot(a.out / "route_benchmark.png", rows, per, training)
    print(tab)
    print(f"total {time.perf_counter() - t_start:.0f} s; {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
