"""The steering-change reward term (trn_env.env.task.action_change_terms): -w |a0_t - a0_(t-1)| on the track
action, a0_(-1) = 0 at every episode start, identical in both tiers; absent (the reward unchanged bit for
bit) with w = 0; bad weights refused naming the field."""

from __future__ import annotations

import math
import pickle

import gymnasium
import numpy as np
import pytest

from trn_env.env import route_task, task

W = 0.25


def _fast(n: int, **kw):
    base = route_task.fast_tier_kwargs(route_task.env_kwargs("basin"))
    base["max_episode_s"] = 60.0                      # 2 decisions, then time_limit and an autoreset step
    return gymnasium.make_vec("trn_env/TerrainNavFast-v0", num_envs=n,
                              vectorization_mode="vector_entry_point", **{**base, **kw})


def test_helper_by_hand():
    assert task.action_change_terms(np.array([1.0, -1.0]), np.array([-1.0, -1.0]),
                                    action_change_weight=0.0) == {}
    t = task.action_change_terms(np.array([1.0, -1.0, 0.3]), np.array([-1.0, -1.0, -0.2]),
                                 action_change_weight=W)
    assert np.allclose(t["action_change"], [-0.5, 0.0, -0.125], rtol=0, atol=1e-15)


def test_fast_tier_term_by_hand_with_autoreset_and_unchanged_at_weight_0():
    n = 3
    rng = np.random.default_rng(7)
    acts = rng.uniform(-1.0, 1.0, (6, n, 2))
    acts[:, 1, 0] = [1.0, -1.0, 1.0, -1.0, 1.0, -1.0]   # a bang-bang sub-env
    plain, zero, charged = _fast(n), _fast(n, action_change_weight=0.0), _fast(n, action_change_weight=W)
    out = {}
    for name, e in (("plain", plain), ("zero", zero), ("charged", charged)):
        e.reset(seed=123)
        out[name] = [e.step(a) for a in acts]
        e.close()
    prev = np.zeros(n)
    live = np.ones(n, bool)
    n_auto = 0
    for k, a in enumerate(acts):
        r_plain, r_zero, r_w = out["plain"][k][1], out["zero"][k][1], out["charged"][k][1]
        assert np.array_equal(r_plain, r_zero)           # bit for bit
        assert "action_change" not in out["zero"][k][4]["reward_terms"]
        assert np.array_equal(out["plain"][k][0], out["charged"][k][0])   # same flights
        want = np.where(live, -W * np.abs(a[:, 0] - prev), 0.0)
        assert np.allclose(out["charged"][k][4]["reward_terms"]["action_change"], want, rtol=0, atol=1e-12)
        assert np.allclose(r_w - r_plain, want, rtol=0, atol=1e-9)
        prev = np.where(live, a[:, 0], 0.0)              # an autoreset step starts the episode at 0
        n_auto += int(np.sum(~live))
        done = out["plain"][k][2] | out["plain"][k][3]
        live = ~done
    assert n_auto >= n                                   # every sub-env went through an autoreset


def test_fast_tier_reset_mask_restarts_the_previous_action():
    e = _fast(2, action_change_weight=W)
    e.reset(seed=5)
    e.step(np.array([[1.0, 0.0], [1.0, 0.0]]))
    e.reset(options={"reset_mask": np.array([True, False])})
    _, _, _, _, info = e.step(np.array([[-1.0, 0.0], [-1.0, 0.0]]))
    assert np.allclose(info["reward_terms"]["action_change"], [-W * 1.0, -W * 2.0], rtol=0, atol=1e-12)
    e.close()


def test_full_tier_term_and_reset():
    kw = route_task.env_kwargs("basin")
    kw["max_episode_s"] = 60.0
    env = gymnasium.make("trn_env/TerrainNav-v0", **kw, action_change_weight=W)
    for seed in (1, 2):
        env.reset(seed=seed)
        prev = 0.0
        for a0 in (1.0, -1.0):
            _, r, term, trunc, info = env.step(np.array([a0, 0.0], np.float32))
            assert info["reward_terms"]["action_change"] == pytest.approx(-W * abs(a0 - prev), abs=1e-12)
            assert r == pytest.approx(sum(info["reward_terms"].values()), abs=1e-9)
            prev = a0
            if term or trunc:
                break
    env2 = pickle.loads(pickle.dumps(env))             # EzPickle keeps the weight
    assert env2.unwrapped.action_change_weight == W
    env.close()
    env2.close()


@pytest.mark.parametrize("bad", [-0.1, math.nan, math.inf, "x"])
def test_bad_weights_refused_in_both_tiers(bad):
    with pytest.raises(ValueError, match="action_change_weight"):
        _fast(1, action_change_weight=bad)
    with pytest.raises(ValueError, match="action_change_weight"):
        gymnasium.make("trn_env/TerrainNav-v0", **route_task.env_kwargs("basin"), action_change_weight=bad)


def test_trace_steering_summary_by_hand():
    from _scripts import load_script

    mod = load_script("route_task_trace")

    def ep(offsets):
        return {"decisions": [{"offset": o} for o in offsets]}

    # reversals: sides of |a0| >= 0.5 only (0.2 skipped): +,-,+ -> 2 ; -,- -> 0
    st = mod.steering_summary([ep([1.0, -1.0, 0.2, 1.0]), ep([-0.6, -1.0])])
    assert st["episodes"] == 2 and st["reversals_per_episode"] == pytest.approx(1.0)
    assert st["saturated_share"] == pytest.approx(4 / 6)
    # total change from a0_(-1) = 0: (1 + 2 + 1.2 + 0.8) and (0.6 + 0.4)
    assert st["offset_change_per_episode"] == pytest.approx((5.0 + 1.0) / 2)
