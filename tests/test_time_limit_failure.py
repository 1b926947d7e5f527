"""Time-outs as failures (`time_limit_failure`, a training choice; trn_env.env.task.episode_end_reasons): the
time limit terminates the episode instead of truncating it and charges the failure penalty, identically in
both tiers; everything else (flights, observations, the other reward terms) bit for bit as without it; the
default keeps gymnasium's truncation; bad values refused naming the field; the training command passes it to
the env and evaluation never sees it."""

from __future__ import annotations

import importlib.util
import pickle
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from trn_env.env import route_task, task

ROOT = Path(__file__).resolve().parents[1]
PENALTY = 20.0


def _kw(fast: bool) -> dict:
    kw = route_task.env_kwargs("basin")
    kw.update(max_episode_s=60.0, failure_penalty=PENALTY)    # 2 decisions, then the time limit
    return route_task.fast_tier_kwargs(kw) if fast else kw


def _fast(n: int, **kw):
    return gymnasium.make_vec("trn_env/TerrainNavFast-v0", num_envs=n,
                              vectorization_mode="vector_entry_point", **{**_kw(True), **kw})


def test_reasons():
    assert task.episode_end_reasons() == (task.TERMINATING_REASONS, task.TRUNCATING_REASONS,
                                          task.FAILURE_REASONS)
    term, trunc, fail = task.episode_end_reasons(True)
    assert "time_limit" in term and "time_limit" in fail and trunc == ()
    assert set(term) - {"time_limit"} == set(task.TERMINATING_REASONS)
    assert set(fail) - {"time_limit"} == set(task.FAILURE_REASONS)


def test_fast_tier_terminates_with_the_penalty_and_changes_nothing_else():
    n = 3
    acts = np.random.default_rng(5).uniform(-1.0, 1.0, (5, n, 2)).astype(np.float32)
    out = {}
    for flag in (False, True):
        e = _fast(n, time_limit_failure=flag)
        e.reset(seed=[11, 12, 13])
        out[flag] = [e.step(a) for a in acts]
        e.close()
    ended = 0
    for (o0, r0, te0, tr0, i0), (o1, r1, te1, tr1, i1) in zip(out[False], out[True], strict=True):
        assert np.array_equal(o0, o1)                         # same flights, same autoresets
        timed_out = i0["termination"] == "time_limit"
        ended += int(timed_out.sum())
        assert np.array_equal(te1, te0 | tr0) and not tr1.any()
        assert np.array_equal(tr0, timed_out)
        assert np.array_equal(r1 - r0, np.where(timed_out, -PENALTY, 0.0))
        assert np.array_equal(i1["reward_terms"]["failure"], np.where(timed_out, -PENALTY, 0.0))
        for k, v in i0["reward_terms"].items():
            if k != "failure":
                assert np.array_equal(v, i1["reward_terms"][k])
    assert ended == 2 * n          # decisions 2 and 5 (3 is the autoreset step): each sub-env twice


def test_full_tier_terminates_with_the_penalty():
    res = {}
    for flag in (False, True):
        env = gymnasium.make("trn_env/TerrainNav-v0", **_kw(False), time_limit_failure=flag)
        env.reset(seed=3)
        steps = [env.step(np.zeros(2, np.float32)) for _ in range(2)]
        res[flag] = steps
        if flag:
            again = pickle.loads(pickle.dumps(env))
            assert again.unwrapped.time_limit_failure is True
        env.close()
    (_, r0, te0, tr0, i0), (_, r1, te1, tr1, i1) = res[False][-1], res[True][-1]
    assert i0["termination"] == i1["termination"] == "time_limit"
    assert (te0, tr0, te1, tr1) == (False, True, True, False)
    assert r1 - r0 == pytest.approx(-PENALTY, abs=1e-12)
    assert i1["reward_terms"]["failure"] == -PENALTY and i0["reward_terms"]["failure"] == 0.0
    assert res[False][0][1] == res[True][0][1]                 # before the limit: the same reward


@pytest.mark.parametrize("bad", ["yes", 1, None])
def test_bad_value_named(bad):
    with pytest.raises(ValueError, match="time_limit_failure"):
        _fast(1, time_limit_failure=bad)
    with pytest.raises(ValueError, match="time_limit_failure"):
        gymnasium.make("trn_env/TerrainNav-v0", **_kw(False), time_limit_failure=bad)


def test_training_command_sets_it_for_training_only():
    spec = importlib.util.spec_from_file_location("route_task_cli", ROOT / "scripts" / "route_task.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    kw = route_task.env_kwargs("basin")
    on = mod.training_env_kwargs(mod.parse(["train", "--out", "x", "--time-limit-failure"]), kw)
    off = mod.training_env_kwargs(mod.parse(["train", "--out", "x"]), kw)
    assert on == {**kw, "time_limit_failure": True}
    assert off == kw and "time_limit_failure" not in kw       # evaluation flies kw
