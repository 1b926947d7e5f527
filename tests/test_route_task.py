"""The reference route task (trn_env.env.route_task, trn_env.campaign.route_task, scripts/route_task.py):
the paired statistics against independent computations, the evaluation rows of the baselines, and the whole
command (train + evaluate) at a tiny size."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from _child_processes import NEUTRAL_CWD
from scipy.stats import binomtest

from trn_env.campaign import route_task as rt
from trn_env.env import route_task

ROOT = Path(__file__).resolve().parents[1]


def test_sign_test_matches_scipy_binomial():
    for wins, losses in ((0, 0), (5, 0), (7, 3), (12, 12), (2, 9), (20, 5)):
        p = rt.sign_test_p(wins, losses)
        if wins + losses == 0:
            assert math.isnan(p)
            continue
        ref = binomtest(wins, wins + losses, 0.5, alternative="greater").pvalue
        assert p == pytest.approx(ref, rel=1e-12)


def _rows(miss_a, miss_b, tier="full"):
    rows = []
    for k, (a, b) in enumerate(zip(miss_a, miss_b, strict=True)):
        for lab, m in (("ppo", a), ("straight", b)):
            rows.append({"tier": tier, "policy": lab, "goal_index": k % 5, "seed": k,
                         "arrived": math.isfinite(m), "true_miss_m": m, "extra_distance_fraction": 0.1,
                         "collision": False, "return": 1.0})
    return rows


def test_paired_comparison_uses_only_pairs_where_both_arrived_and_its_interval_covers():
    rng = np.random.default_rng(5)
    b = rng.uniform(200.0, 400.0, 40)
    a = 0.6 * b + rng.normal(0.0, 10.0, 40)              # 40 % better, paired
    a[3] = math.nan                                        # a did not arrive: the pair is dropped
    c = rt.paired(_rows(a, b), "full", "ppo", "straight")
    keep = np.isfinite(a)
    assert c["n_pairs"] == 39 and c["n_compared"] == 40
    assert c["mean_a_m"] == pytest.approx(a[keep].mean()) and c["mean_b_m"] == pytest.approx(b[keep].mean())
    assert c["improvement"] == pytest.approx(1.0 - a[keep].mean() / b[keep].mean())
    lo, hi = c["improvement_ci95"]
    assert lo < c["improvement"] < hi and hi - lo < 0.1
    assert c["wins"] == int(np.sum(a[keep] < b[keep])) and c["sign_test_p"] < 1e-6
    s = rt.summarise(_rows(a, b))
    assert s["policies"]["full/ppo"]["success"] == pytest.approx(39 / 40)
    assert s["policies"]["full/ppo"]["miss_p90_m"] == pytest.approx(np.percentile(a[keep], 90))
    t = rt.target_check(s)
    assert t["beats_straight_by_30pct"] and t["sign_test_p_below_0_01"]
    assert not t["within_20pct_of_planner"]                # no planner evaluated
    assert "ppo vs straight" in rt.table(s)
    # within 20 % of the planner needs the planner's success rate too (misses are over arrived episodes)
    rows = _rows(a, b) + [{**r, "policy": "planner", "true_miss_m": 1.1 * r["true_miss_m"]}
                          for r in _rows(a, b) if r["policy"] == "ppo"]
    for r in rows:
        if r["policy"] == "planner" and not r["arrived"]:
            r["arrived"], r["true_miss_m"] = True, 30.0
    t = rt.target_check(rt.summarise(rows))
    assert not t["success_not_below_planner"] and not t["within_20pct_of_planner"]
    assert t["ratio_to_planner"] < 1.2


def test_route_task_script_refuses_bad_policies_threads_and_rows(tmp_path, capsys):
    pytest.importorskip("ray.rllib")
    spec = importlib.util.spec_from_file_location("route_task_script", ROOT / "scripts" / "route_task.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "o"
    base = ["evaluate", "--out", str(out), "--policies", "straight"]
    assert mod.main([*base[:3], "--policies", "straight,teleport"]) == 2
    assert "--policies" in capsys.readouterr().err
    assert mod.main([*base, "--torch-threads", "0"]) == 2
    assert "--torch-threads" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{}")
    assert mod.main([*base, "--merge-rows", str(tmp_path / "bad.json")]) == 2
    assert "--merge-rows" in capsys.readouterr().err
    assert mod.main([*base, "--merge-rows", str(tmp_path / "missing.json")]) == 2
    train = ["train", "--out", str(out)]
    for bad, name in ((["--cpu-minutes", "0"], "--cpu-minutes"), (["--cpu-minutes", "nan"], "--cpu-minutes"),
                      (["--minutes", "-1"], "--minutes"), (["--gamma", "1.5"], "--gamma"),
                      (["--lambda", "0"], "--lambda"), (["--entropy", "-0.1"], "--entropy"),
                      (["--lr-end", "1e-5"], "--lr-decay-steps"), (["--miss-weight", "-1"], "--miss-weight"),
                      (["--log-std-clip", "-1"], "--log-std-clip"),
                      (["--log-std-clip", "inf"], "--log-std-clip"),
                      (["--miss-weight", "inf"], "--miss-weight"),
                      (["--action-change-weight", "-0.1"], "--action-change-weight"),
                      (["--action-change-weight", "nan"], "--action-change-weight"),
                      (["--num-cpus", "0"], "--num-cpus must be >= 1"),
                      (["--env-runners", "-1"], "--env-runners must be >= 0")):
        assert mod.main([*train, *bad]) == 2
        assert name in capsys.readouterr().err
    # Ray's waits (trn_env.campaign.ray_backend.connect_for_env_runners): more EnvRunners than CPUs, an
    # address where nothing listens
    import socket
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    for bad, name in ((["--env-runners", "3", "--num-cpus", "2"], "--env-runners 3 needs 3 CPUs"),
                      (["--address", f"127.0.0.1:{port}"], f"no Ray cluster reachable at 127.0.0.1:{port}")):
        assert mod.main([*train, *bad]) == 2
        assert name in capsys.readouterr().err
    assert not out.exists()                                  # nothing written
    afile = tmp_path / "a.txt"
    afile.write_text("a file")
    for target, msg in ((afile, "exists and is not a folder"), (afile / "o", "is not a directory")):
        assert mod.main(["evaluate", "--out", str(target), "--policies", "straight"]) == 2
        assert f"--out {target}: " in (err := capsys.readouterr().err) and msg in err
    sel = ["select", "--out", str(out)]
    for bad, name in ((["--every", "0"], "--every"), (["--validation-seeds", "0"], "--validation-seeds"),
                      (["--validation-seeds", "20001"], "--validation-seeds"), ([], "no checkpoints")):
        assert mod.main([*sel, *bad]) == 2
        assert name in capsys.readouterr().err
    assert not out.exists()
    ck = tmp_path / "ck"
    for d in ("iter_10", "iter_20", "iter_30", "iter_100", "final", "iter_x"):
        (ck / d).mkdir(parents=True)
    assert [d.name for d in mod.checkpoints_to_select(ck, 20)] == ["iter_20", "iter_100", "final"]
    every10 = ["iter_10", "iter_20", "iter_30", "iter_100", "final"]
    assert [d.name for d in mod.checkpoints_to_select(ck, 10)] == every10


def test_checkpoint_pick_prefers_success_then_the_lower_mean_miss():
    rows = [{"checkpoint": "a", "success": 0.98, "miss_mean_m": 10.0},
            {"checkpoint": "b", "success": 1.0, "miss_mean_m": 30.0},
            {"checkpoint": "c", "success": 1.0, "miss_mean_m": 20.0},
            {"checkpoint": "d", "success": 1.0, "miss_mean_m": 20.0},
            {"checkpoint": "e", "success": 0.0, "miss_mean_m": math.nan}]
    assert rt.best_checkpoint(rows)["checkpoint"] == "c"
    assert rt.best_checkpoint(rows[-1:] + rows[:1])["checkpoint"] == "a"


def test_fix_loss_pick_prefers_the_fewer_lost_fixes_then_the_lower_mean_miss():
    rows = [{"checkpoint": "a", "success": 1.0, "fix_loss_rate": 0.03, "miss_mean_m": 15.0},
            {"checkpoint": "b", "success": 0.99, "fix_loss_rate": 0.02, "miss_mean_m": 30.0},
            {"checkpoint": "c", "success": 0.99, "fix_loss_rate": 0.02, "miss_mean_m": 25.0},
            {"checkpoint": "d", "success": 0.0, "fix_loss_rate": 1.0, "miss_mean_m": math.nan}]
    assert rt.best_checkpoint(rows, "fix_loss")["checkpoint"] == "c"
    assert rt.best_checkpoint(rows, "success")["checkpoint"] == "a"
    with pytest.raises(ValueError, match="rule"):
        rt.best_checkpoint(rows, "luck")
    with pytest.raises(ValueError, match="rule"):
        rt.select_checkpoint(["x"], "basin", [100_000], rule="luck")
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="max_envs"):
            rt.select_checkpoint(["x"], "basin", [100_000], max_envs=bad)


def test_task_settings_and_bad_terrain():
    kw = route_task.env_kwargs("basin")
    assert kw["action_mode"] == "pursuit" and kw["decision_interval_s"] == 30.0
    assert json.loads(json.dumps(kw)) == kw                # plain JSON types
    assert not set(route_task.EVAL_SEEDS) & set(range(route_task.TRAIN_SEED_BASE, 1000))
    # model selection's seeds: neither evaluation seeds nor the trainer's reset seeds (base + sub-env index)
    assert not set(route_task.VALIDATION_SEEDS) & (set(route_task.EVAL_SEEDS) | set(range(10_000)))
    with pytest.raises(ValueError, match="terrain"):
        route_task.env_kwargs("moon")


def test_baselines_fly_the_held_out_goals_in_the_full_tier():
    pols = [{"label": "straight", "kind": "straight"}, {"label": "random", "kind": "random"}]
    rows = rt.evaluate_full(pols, "basin", [1000], env_overrides={"max_episode_s": 60.0})
    assert len(rows) == 2 * 5                               # 2 policies x 5 held-out goals x 1 seed
    assert {r["goal_index"] for r in rows} == set(range(5))
    for r in rows:
        assert r["termination"] in ("time_limit", "arrived", "terrain_collision", "off_map", "diverged")
        assert r["distance_flown_m"] > 1000.0               # 60 s at ~85 m/s
    with pytest.raises(ValueError, match="kind"):
        rt.evaluate_full([{"kind": "teleport"}], "basin", [1000])


def test_baselines_fly_the_same_goals_and_seeds_in_the_fast_tier():
    import gymnasium as gym

    if "trn_env/TerrainNavFast-v0" not in gym.registry:
        pytest.skip("the fast tier is not installed")
    pols = [{"label": "straight", "kind": "straight"}, {"label": "planner", "kind": "planner"},
            {"label": "random", "kind": "random"}]
    rows = rt.evaluate_fast(pols, "basin", [1000, 1001])
    assert len(rows) == 3 * 5 * 2
    assert {(r["goal_index"], r["seed"]) for r in rows if r["policy"] == "planner"} == \
        {(g, s) for g in range(5) for s in (1000, 1001)}
    s = rt.summarise(rows)
    for lab in ("straight", "planner", "random"):
        assert s["policies"][f"fast/{lab}"]["success"] > 0.5          # full-length episodes arrive
    # the straight line flies (nearly) the straight distance; the random policy wanders further
    assert abs(s["policies"]["fast/straight"]["extra_distance_mean"]) < 0.05
    again = rt.evaluate_fast(pols[:1], "basin", [1000, 1001])             # one seed, one episode
    assert [r["true_miss_m"] for r in again] == [r["true_miss_m"] for r in rows if r["policy"] == "straight"]


def test_validation_episodes_draw_training_goals_never_a_held_out_one():
    import gymnasium as gym

    from trn_env.env.terrain_nav import TerrainNavEnv

    if "trn_env/TerrainNavFast-v0" not in gym.registry:
        pytest.skip("the fast tier is not installed")
    seeds = list(route_task.VALIDATION_SEEDS[:16])
    pols = [{"label": "straight", "kind": "straight"}]
    rows = rt.evaluate_fast(pols, "basin", seeds, drawn_goals=True)
    assert [r["seed"] for r in rows] == seeds and {r["goal_index"] for r in rows} == {-1}
    kw = route_task.env_kwargs("basin")
    la0, la1, lo0, lo1 = kw["goal_region_deg"]
    env = TerrainNavEnv(**kw)
    held = np.radians(np.array(env.held_out_goals_deg))
    env.close()
    goals = np.radians(np.array([r["goal_deg"] for r in rows]))
    assert np.all((np.degrees(goals[:, 0]) >= la0) & (np.degrees(goals[:, 0]) <= la1))
    assert np.all((np.degrees(goals[:, 1]) >= lo0) & (np.degrees(goals[:, 1]) <= lo1))
    # haversine distance (sphere of 6,371 km) from each drawn goal to each held-out goal
    dlat = goals[:, None, 0] - held[None, :, 0]
    dlon = goals[:, None, 1] - held[None, :, 1]
    h = np.sin(dlat / 2) ** 2 + np.cos(goals[:, None, 0]) * np.cos(held[None, :, 0]) * np.sin(dlon / 2) ** 2
    d_m = 2 * 6_371_000.0 * np.arcsin(np.sqrt(h))
    assert d_m.min() > 0.99 * kw["held_out_radius_m"]
    assert len({tuple(r["goal_deg"]) for r in rows}) == len(rows)        # a goal per seed
    again = rt.evaluate_fast(pols, "basin", seeds[:4], drawn_goals=True)   # a seed fixes goal and episode
    assert [(r["goal_deg"], r["true_miss_m"]) for r in again] == \
        [(r["goal_deg"], r["true_miss_m"]) for r in rows[:4]]


@pytest.mark.slow
def test_route_task_command_trains_and_evaluates_at_a_tiny_size(tmp_path, monkeypatch):
    pytest.importorskip("ray.rllib")
    monkeypatch.chdir(NEUTRAL_CWD)      # the Ray it starts: workers import trn_env from where the tests do
    spec = importlib.util.spec_from_file_location("route_task_script", ROOT / "scripts" / "route_task.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "rt"
    assert mod.main(["all", "--out", str(out), "--iterations", "1", "--seeds", "1", "--max-episode-s", "60",
                     "--train-batch-size", "8", "--minibatch-size", "4", "--epochs", "1",
                     "--hidden", "8", "--envs-per-runner", "2", "--validation-seeds", "2"]) == 0
    for f in ("history.json", "learning_curve.png", "selection.json", "rows.json", "summary.json",
              "table.md"):
        assert (out / f).is_file(), f
    assert json.loads((out / "selection.json").read_text())["rows"][0]["episodes"] == 2   # `all` selects
    rows = json.loads((out / "rows.json").read_text())
    full = [r for r in rows if r["tier"] == "full"]
    assert {r["policy"] for r in full} == {"straight", "planner", "random", "ppo"}
    assert len(full) == 4 * 5
    fast = [r for r in rows if r["tier"] == "fast"]
    assert len(fast) == 4 * 5 and {r["policy"] for r in fast} == {r["policy"] for r in full}
    summary = json.loads((out / "summary.json").read_text())
    assert "target" in summary and "full/ppo" in summary["policies"]
    assert mod.main(["evaluate", "--out", str(tmp_path / "none")]) == 2          # no checkpoint: exit 2
    assert mod.main(["select", "--out", str(out), "--every", "1", "--validation-seeds", "3",
                     "--max-episode-s", "60"]) == 0
    sel = json.loads((out / "selection.json").read_text())
    assert [Path(r["checkpoint"]).name for r in sel["rows"]] == ["final"]   # one iteration: final only
    assert all(r["episodes"] == 3 for r in sel["rows"]) and sel["best"] in sel["rows"]
    assert mod.main(["select", "--out", str(out), "--every", "1", "--validation-seeds", "4",
                     "--max-episode-s", "60", "--rule", "fix_loss"]) == 0
    sel = json.loads((out / "selection.json").read_text())
    assert sel["rule"] == "fix_loss" and sel["rows"][0]["episodes"] == 4
    assert (out / "selection.png").is_file()
    assert sel["rows"][0]["fix_loss_rate"] >= 1.0 - sel["rows"][0]["success"]   # not arrived = lost
    # the validation episodes flown in vector envs of 2 sub-envs give the figures of one vector env
    seeds, final = list(route_task.VALIDATION_SEEDS[:5]), [out / "checkpoints" / "final"]
    one, split = (rt.select_checkpoint(final, "basin", seeds, {"max_episode_s": 60.0}, "fix_loss", max_envs=m)
                  for m in (5, 2))
    assert split["rows"] == one["rows"] and one["rows"][0]["episodes"] == 5


@pytest.mark.parametrize("bad, name", [(["--goals", "9"], "--goals"), (["--goals", "x"], "--goals"),
                                       (["--seeds", "1,a"], "--seeds"), (["--elite", "1.5"], "--elite"),
                                       (["--population", "0"], "--population")])
def test_action_search_script_refuses_bad_arguments(tmp_path, capsys, bad, name):
    """scripts/route_action_search.py: exit 2 naming the argument, nothing written."""
    path = ROOT / "scripts" / "route_action_search.py"
    spec = importlib.util.spec_from_file_location("route_action_search", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "search.json"
    assert mod.main([*bad, "--out", str(out)]) == 2
    assert name in capsys.readouterr().err
    assert not out.exists()


def test_trace_script_matches_the_evaluation_and_refuses_bad_arguments(tmp_path, capsys):
    import gymnasium as gym

    if "trn_env/TerrainNavFast-v0" not in gym.registry:
        pytest.skip("the fast tier is not installed")
    path = ROOT / "scripts" / "route_task_trace.py"
    spec = importlib.util.spec_from_file_location("route_task_trace", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for bad, name in ((["--goal", "5"], "--goal"), (["--seeds", "a-b"], "--seeds"),
                      (["--sigma-scale", "0"], "--sigma-scale"), (["--sigma-scale", "nan"], "--sigma-scale"),
                      (["--policy", "ppo", "--checkpoint", str(tmp_path / "none")], "--checkpoint")):
        args = ["--policy", "straight", "--goal", "2", "--tier", "fast", "--out", str(tmp_path / "t.json")]
        assert mod.main([*args, *bad]) == 2
        assert name in capsys.readouterr().err
    assert not (tmp_path / "t.json").exists()
    pol = {"label": "straight", "kind": "straight"}
    eps = mod.trace_fast(pol, "basin", 2, [1000, 1001])
    rows = [r for r in rt.evaluate_fast([pol], "basin", [1000, 1001]) if r["goal_index"] == 2]
    for e, r in zip(eps, rows, strict=True):          # the same episode as the evaluation's (seed, goal)
        assert e["seed"] == r["seed"] and e["termination"] == r["termination"]
        assert len(e["decisions"]) == r["steps"]
        if r["arrived"]:
            assert e["true_miss_m"] == pytest.approx(r["true_miss_m"], rel=1e-9)
            assert e["decisions"][-1]["true_err_m"] == pytest.approx(r["true_miss_m"], rel=1e-9)
        t = [d["t_s"] for d in e["decisions"]]
        assert all(b > a for a, b in zip(t, t[1:], strict=False)) and all(d["offset"] == 0.0
                                                                          for d in e["decisions"])
    # losses by the largest terrain information: counted by hand on three made-up episodes
    def ep(term, miss, infos):
        return {"termination": term, "true_miss_m": miss, "decisions": [{"info_here": x} for x in infos]}
    made = [ep("arrived", 20.0, [0.5, 0.9]), ep("arrived", 300.0, [0.6, 2.5]),
            ep("time_limit", math.nan, [1.2])]
    assert mod.losses_by_info(made) == [(0, 1), (1, 1), (0, 0), (1, 1)]

    class Echo:
        def predict(self, obs, *a, **k):
            return obs, None
    o = np.zeros(32, np.float32)
    o[8:11] = np.log10(1.0 + np.array([9.0, 99.0, 4.0]))
    seen = mod.SigmaScaled(Echo(), 2.0).predict(o)[0]
    assert np.allclose(10.0 ** seen[8:10] - 1.0, [18.0, 198.0], rtol=1e-5) and seen[10] == o[10]
