"""scripts/route_policy_benchmark.py: one real evaluation episode in its env; its summary statistics against
numpy."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "route_policy_benchmark.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("route_policy_benchmark", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_one_episode_and_the_summary(bench):
    # a goal 6-9 km north of the start region, on the hills west of the basin: a short arrival
    from trn_env.campaign.episodes import make_policy, run_episode

    env = bench.make_env("basin")
    assert env.action_mode == "pursuit" and env.failure_penalty == 20.0
    row = run_episode(env, make_policy({"kind": "straight", "agl_m": 600.0}, env), 7, (36.60, -84.14))
    env.close()
    row.update(policy="straight", terrain="basin")
    assert row["termination"] == "arrived" and row["arrived"]
    assert 0.0 <= row["true_miss_m"] < 300.0
    assert -0.05 < row["extra_distance_fraction"] < 0.1          # the straight line, minus the arrival radius
    rng = np.random.default_rng(0)
    rows = []
    for name in ("straight", "planner"):
        for k in range(20):
            arrived = bool(k % 5)
            rows.append(dict(row, policy=name, arrived=arrived,
                             termination="arrived" if arrived else "off_map",
                             true_miss_m=float(rng.uniform(0, 500)) if arrived else None,
                             extra_distance_fraction=float(rng.uniform(0, 0.3)), collision=int(k == 3),
                             **{"return": float(k)}))
    s = bench.summarise(rows)["basin"]
    for name in ("straight", "planner"):
        mine = [r for r in rows if r["policy"] == name]
        miss = np.array([r["true_miss_m"] for r in mine if r["arrived"]])
        assert s[name]["success_rate"] == pytest.approx(16 / 20)
        assert s[name]["mean_true_error_at_goal_m"] == pytest.approx(miss.mean())
        m = np.sort(miss)            # 16 values: the 95th percentile sits 0.25 of the way from m[14] to m[15]
        assert s[name]["p95_true_error_at_goal_m"] == pytest.approx(m[14] + 0.25 * (m[15] - m[14]))
        assert s[name]["collisions"] == 1 and s[name]["terminations"] == {"arrived": 16, "off_map": 4}
    red = 1 - s["planner"]["mean_true_error_at_goal_m"] / s["straight"]["mean_true_error_at_goal_m"]
    assert s["planner_vs_straight_mean_error_reduction"] == pytest.approx(red)
    assert "| basin | planner |" in bench.table({"basin": s})


def test_paired_comparison_against_a_hand_computation(bench):
    import math

    rng = np.random.default_rng(1)
    rows, diffs = [], []
    for k in range(12):
        base = float(rng.uniform(100, 500))
        d = float(rng.normal(-60.0, 80.0))
        diffs.append(d)
        for name, miss in (("ppo", base + d), ("straight", base)):
            rows.append(dict(policy=name, arrived=True, true_miss_m=miss, goal_lat_deg=36.7 + 0.01 * (k % 3),
                             goal_lon_deg=-84.1, seed=1000 + k // 3))
    rows.append(dict(policy="ppo", arrived=False, true_miss_m=None, goal_lat_deg=36.9, goal_lon_deg=-84.1,
                     seed=1))                                     # unpaired: left out
    c = bench.paired(rows, "ppo", "straight")
    d = np.array(diffs)
    assert c["pairs"] == 12 and c["mean_difference_m"] == pytest.approx(d.mean())
    t975_11 = 2.200985                                  # Student t, 11 degrees of freedom, 97.5 % (tables)
    half = t975_11 * d.std(ddof=1) / math.sqrt(12)
    assert c["ci95_m"] == pytest.approx([d.mean() - half, d.mean() + half], rel=1e-5)
    w = int((d < 0).sum())
    n = 12
    tail = sum(math.comb(n, i) for i in range(0, min(w, n - w) + 1)) / 2**n
    assert c["a_better"] == w and c["sign_test_p"] == pytest.approx(min(1.0, 2 * tail))


def test_bad_out_is_refused_before_any_work(bench, tmp_path, capsys):
    afile = tmp_path / "a.txt"
    afile.write_text("a file")
    for target, msg in ((afile, "exists and is not a folder"), (afile / "o", "is not a directory")):
        assert bench.main(["--out", str(target), "--terrains", "basin", "--train-steps", "0"]) == 2
        assert f"--out {target}: " in (err := capsys.readouterr().err) and msg in err
    (tmp_path / "eval" / "episodes_basin").mkdir(parents=True)
    (tmp_path / "eval" / "episodes_basin" / "mine.txt").write_text("mine")
    with pytest.raises(SystemExit, match="holds no earlier evaluation"):
        bench.evaluate("basin", None, [1000], tmp_path / "eval" / "episodes_basin", None)
    assert (tmp_path / "eval" / "episodes_basin" / "mine.txt").read_text() == "mine"


def test_what_the_evaluation_takes_is_refused_before_the_training(bench, tmp_path, capsys):
    """--workers, --envs and the planner's settings were first used after the training (minutes of PPO, then
    a traceback): each is now one line and exit 2 before anything is trained or written."""
    from trn_env.campaign.local import MAX_WORKERS_PER_CORE, default_workers

    many = str(MAX_WORKERS_PER_CORE * default_workers() + 1)
    out = tmp_path / "o"
    for args, msg in ((["--workers", many], f"--workers: {many} is more than"),
                      (["--envs", many], f"--envs: {many} is more than"),
                      (["--planner-weight", "nan"], "--planner-weight must be a finite number >= 0"),
                      (["--planner-informative-crlb", "-1"], "--planner-informative-crlb must be")):
        assert bench.main(["--out", str(out), "--terrains", "basin", *args]) == 2
        assert msg in capsys.readouterr().err
        assert not out.exists()
