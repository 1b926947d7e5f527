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
