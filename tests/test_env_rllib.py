"""RLlib glue (trn_env.env.rllib, trn_env.env.rllib_train, scripts/train_rllib.py): registration of the env
tiers, the one-line error without the extra, and a few PPO iterations on a local 2-CPU Ray instance."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from _child_processes import init_local_ray

import trn_env  # noqa: F401  (registers the gymnasium ids)
from trn_env.env import rllib as glue
from trn_env.env.route_task import env_kwargs

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("train_rllib", ROOT / "scripts" / "train_rllib.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_without_the_extra_the_error_is_one_line_with_the_install_command(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray.rllib", None)        # import ray.rllib -> ImportError
    with pytest.raises(glue.RLlibNotInstalled) as exc:
        glue.require_rllib()
    assert "pip install 'trn-env[rllib]'" in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(glue.RLlibNotInstalled):
        glue.register_rllib_envs()
    assert _script().main(["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "pip install 'trn-env[rllib]'" in err
    assert not (tmp_path / "o").exists()                         # nothing written


def test_bad_arguments_exit_2_naming_them(tmp_path, capsys):
    pytest.importorskip("ray.rllib")
    s = _script()
    assert s.main(["--out", str(tmp_path / "o"), "--terrain", "moon"]) == 2
    assert "terrain" in capsys.readouterr().err
    assert s.main(["--out", str(tmp_path / "o"), "--iterations", "0"]) == 2
    assert "--iterations" in capsys.readouterr().err
    assert s.main(["--out", str(tmp_path / "o"), "--eval-seeds", "201"]) == 2
    assert "--eval-seeds" in capsys.readouterr().err
    # refused before Ray starts (--num-cpus 0 crashed Ray's raylet and hung; a file as --out, a traceback
    # after the local instance had started)
    afile = tmp_path / "a.txt"
    afile.write_text("a file")
    for args, msg in ((["--num-cpus", "0"], "--num-cpus must be >= 1"), (["--hidden", "64,,64"], "--hidden"),
                      (["--lr", "nan"], "--lr"), (["--env-runners", "-1"], "--env-runners"),
                      (["--epochs", "0"], "--epochs"), (["--out", str(afile)], "exists and is not a folder"),
                      (["--out", str(afile / "o")], "is not a directory")):
        assert s.main(["--out", str(tmp_path / "o"), *args]) == 2
        assert msg in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    # Ray's own waits, each for minutes or for ever, are refused in one line: an address where nothing
    # listens (ray.init retried it for 5 minutes and more) and more EnvRunners than the instance has CPUs
    # (RLlib waited for the missing actors for ever); --num-cpus as a campaign's --workers
    import socket

    import ray
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]             # closed again: nothing listens there
    before = ray.is_initialized()
    for args, msg in ((["--address", f"127.0.0.1:{port}"], f"no Ray cluster reachable at 127.0.0.1:{port}"),
                      (["--env-runners", "3", "--num-cpus", "2"],
                       "--env-runners 3 needs 3 CPUs, one per EnvRunner; the local Ray instance (--num-cpus) "
                       "has 2"),
                      (["--num-cpus", "100000"], "--num-cpus: 100000 is more than 4 per usable core")):
        assert s.main(["--out", str(tmp_path / "o"), *args]) == 2
        err = capsys.readouterr().err
        assert msg in err, err
        assert ray.is_initialized() == before and not (tmp_path / "o").exists()
    from trn_env.env.rllib_train import ppo_config

    for bad in (-1.0, math.inf, True):
        with pytest.raises(ValueError, match="log_std_clip"):
            ppo_config("fast", env_kwargs("basin"), log_std_clip=bad)
    cfg = ppo_config("fast", env_kwargs("basin"), log_std_clip=0.5)
    assert cfg.model_config["log_std_clip_param"] == 0.5


def test_both_tiers_registered_and_observations_scaled():
    pytest.importorskip("ray.rllib")
    from ray.tune.registry import ENV_CREATOR, _global_registry

    names = glue.register_rllib_envs()
    assert names["full"] == "trn_env/TerrainNav-v0"
    assert ("fast" in names) == ("trn_env/TerrainNavFast-v0" in gym.registry)
    for name in names.values():
        assert _global_registry.contains(ENV_CREATOR, name)
    kw = env_kwargs("basin")
    env = _global_registry.get(ENV_CREATOR, names["full"])({**kw, "worker_index": 1, "num_workers": 1})
    obs, _ = env.reset(seed=3)
    raw = env.unwrapped._obs()
    lo, hi = env.unwrapped.observation_space.low, env.unwrapped.observation_space.high
    assert np.all(np.abs(obs) <= 1.0 + 1e-6)
    np.testing.assert_allclose(obs, -1.0 + 2.0 * (raw - lo) / (hi - lo), atol=1e-5)   # by the bounds
    env.close()
    if "fast" in names:
        venv = glue.make_fast_env({**kw, "num_envs": 3})
        o, _ = venv.reset(seed=0)
        assert o.shape[0] == 3 and np.all(np.abs(o) <= 1.0 + 1e-6)
        venv.close()
    with pytest.raises(ValueError, match="tier"):
        glue.rllib_env_settings("medium")


@pytest.mark.slow
def test_ppo_trains_a_few_iterations_on_a_local_two_cpu_ray(tmp_path):
    pytest.importorskip("ray.rllib")
    import ray
    import torch

    from trn_env.env.rllib_train import evaluate_module, module_from_checkpoint, ppo_config, train

    kw = env_kwargs("basin")
    kw["max_episode_s"] = 90.0          # 3 decisions of 30 s: episodes end (time limit) within an iteration
    init_local_ray()
    try:
        cfg = ppo_config("full", kw, num_env_runners=1, hidden=(8,), train_batch_size=12, minibatch_size=6,
                         num_epochs=2, lr=1e-3)
        algo = cfg.build_algo()
        before = [p.detach().clone() for p in algo.get_module().parameters()]
        algo, history = train(algo, 2, tmp_path / "ckpt", checkpoint_every=1)
        module = algo.get_module()
        after = [p.detach().clone() for p in module.parameters()]
        assert len(history) == 2 and history[-1]["env_steps"] >= 24
        assert history[-1]["episodes"] >= 4                   # 24 steps of 3-step episodes: >= 4 finished
        assert math.isfinite(history[-1]["episode_return_mean"])
        changed = max(float((a - b).abs().max()) for a, b in zip(after, before, strict=True))
        assert changed > 1e-6                                  # the policy's weights moved
        assert (tmp_path / "ckpt" / "iter_1").is_dir() and (tmp_path / "ckpt" / "final").is_dir()
        restored = module_from_checkpoint(tmp_path / "ckpt" / "final").state_dict()
        trained = module.state_dict()
        assert trained and set(trained) <= set(restored)   # the acting part (restored: + value function)
        for k, v in trained.items():
            assert torch.equal(restored[k], v), k
        # a checkpoint named relative to the working directory loads too (scripts take --out as typed)
        with pytest.MonkeyPatch.context() as mp:
            mp.chdir(tmp_path)
            relative = module_from_checkpoint(Path("ckpt") / "final").state_dict()
        for k, v in trained.items():
            assert torch.equal(relative[k], v), k
        goal = tuple(env_kwargs("basin")["goal_region_deg"][::2])
        rows = evaluate_module(module, kw, [goal], [1000])
        assert len(rows) == 1 and rows[0]["termination"] is not None and rows[0]["steps"] >= 1
        algo.stop()
    finally:
        ray.shutdown()


@pytest.mark.slow
def test_cpu_budget_stops_within_it_and_counts_every_process(tmp_path):
    pytest.importorskip("ray.rllib")
    if glue.FAST_ID not in gym.registry:
        pytest.skip("the fast tier is not installed")
    import ray

    from trn_env.env.rllib_train import ppo_config, train

    kw = env_kwargs("basin")
    init_local_ray()
    try:
        cfg = ppo_config("fast", kw, num_env_runners=1, num_envs_per_env_runner=8, hidden=(8,),
                         train_batch_size=64, minibatch_size=32, num_epochs=1)
        with pytest.raises(ValueError, match="max_cpu_s"):
            train(cfg, 2, max_cpu_s=-1.0)
        algo = cfg.build_algo()
        # the EnvRunner's construction alone (its own process, counted) takes more than 0.5 CPU s, so the
        # budget ends the run after its first iteration, well before the 50 asked for
        algo, history = train(algo, 50, tmp_path / "ckpt", checkpoint_every=10, max_cpu_s=0.5)
        assert len(history) == 1 and (tmp_path / "ckpt" / "final").is_dir()
        row = history[0]
        assert row["env_runner_cpu_s"] > 0.5 and row["driver_cpu_s"] > 0.0
        assert row["cpu_s"] == pytest.approx(row["driver_cpu_s"] + row["env_runner_cpu_s"])
        # a generous budget: every iteration asked for runs, and the CPU count only grows
        algo, more = train(algo, 2, max_cpu_s=1e6)
        assert len(more) == 2 and more[1]["cpu_s"] >= more[0]["cpu_s"] > 0.0
        algo.stop()
    finally:
        ray.shutdown()
