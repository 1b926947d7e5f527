"""Env episodes as campaign runs (trn_env.campaign.episodes): a 2-worker local campaign of two policies
over one goal and two seeds gives, row for row, the same bits as the same episodes flown here by hand in
this process; `resume` flies nothing more; bad specs name their field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trn_env.campaign import CampaignError, make_backend, run_campaign
from trn_env.campaign.episodes import RandomPolicy, episode_campaign
from trn_env.campaign.rows import read_rows
from trn_env.env.terrain_nav import TerrainNavEnv
from trn_env.policies import StraightLinePolicy

GOAL = (36.577, -84.25)                      # 3 km north of the start, on the basin's western hills
ENV = dict(scenario="basin_route", decision_interval_s=2.0, max_episode_s=60.0, navigator="ins",
           goal_radius_m=500.0, start_region_deg=[36.5495, 36.5505, -84.2505, -84.2495])
SPEC = {"name": "episodes_small", "env": ENV, "goals_deg": [list(GOAL)], "seeds": [3, 4],
        "policies": [{"label": "straight", "kind": "straight"}, {"label": "random", "kind": "random"}]}


def _by_hand(env, policy_kind: str, seed: int) -> dict:
    """The episode flown directly on an env of this process, without the campaign code."""
    pol = StraightLinePolicy(env) if policy_kind == "straight" else None
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed, options={"goal_deg": GOAL})
    ret, done = 0.0, False
    while not done:
        a = pol(obs) if pol is not None else rng.uniform(env.action_space.low, env.action_space.high)
        obs, r, term, trunc, info = env.step(np.asarray(a, np.float32))
        ret += r
        done = term or trunc
    return {"return": ret, "termination": info["termination"], "distance_flown_m": info["distance_flown_m"],
            "true_miss_m": info.get("true_miss_m", math.nan), "sim_time_s": info["t_s"]}


def test_episode_campaign_rows_are_the_episodes_bit_for_bit(tmp_path):
    campaign = episode_campaign(SPEC)
    assert campaign.n_runs == 4 and [v.label for v in campaign.variants] == ["straight", "random"]
    stats = run_campaign(campaign, tmp_path / "c", backend=make_backend("local", workers=2), progress=False)
    assert stats["flown"] == 4 and stats["failed"] == 0
    rows = read_rows(tmp_path / "c")
    assert len(rows) == 4 and set(rows["error"].fillna("")) == {""}
    env = TerrainNavEnv(**ENV)
    for _, row in rows.iterrows():
        ref = _by_hand(env, row["policy_kind"], int(row["seed"]))
        assert row["termination"] == ref["termination"]
        assert row["return"] == ref["return"]                       # bit for bit, per seed
        assert row["distance_flown_m"] == ref["distance_flown_m"]
        assert row["sim_time_s"] == ref["sim_time_s"]
        if ref["termination"] == "arrived":
            assert row["true_miss_m"] == ref["true_miss_m"] and row["arrived"]
        else:
            assert math.isnan(row["true_miss_m"]) and not row["arrived"]
    env.close()
    straight = rows[rows["policy"] == "straight"]
    assert straight["arrived"].all()                               # 3 km on the straight line: arrives
    again = run_campaign(campaign, tmp_path / "c", backend=make_backend("local", workers=2), resume=True,
                         progress=False)
    assert again["flown"] == 0 and again["already_done"] == 4


def test_random_policy_is_seeded_per_episode():
    env = TerrainNavEnv(**ENV)
    p = RandomPolicy(env)
    p.seed(7)
    a = [p.predict(None)[0] for _ in range(3)]
    p.seed(7)
    assert all(np.array_equal(x, p.predict(None)[0]) for x in a)
    assert all(env.action_space.contains(x) for x in a)
    env.close()


@pytest.mark.parametrize(("patch", "field"), [
    ({"seeds": 0}, "seeds"),
    ({"policies": [{"label": "x", "kind": "teleport"}]}, "policies[0].kind"),
    ({"policies": [{"label": "x", "kind": "sb3", "model": "/no/such.zip"}]}, "policies[0].model"),
    ({"policies": [{"label": "a", "kind": "straight"}, {"label": "a", "kind": "random"}]}, "used twice"),
    ({"env": {"scenario": "basin_route", "goal_radius_m": -1.0}}, "goal_radius_m"),
    ({"goals_deg": [[10.0, 10.0]]}, "goals_deg[0]"),
    ({"colour": "red"}, "colour"),
    ({"seeds": 1_000_000_000}, "seeds: the campaign asks for 2,000,000,000 episodes"),   # not drawn first
])
def test_bad_episode_campaign_specs_name_the_field(patch, field):
    with pytest.raises(CampaignError, match=field.replace("[", r"\[").replace("]", r"\]")):
        episode_campaign({**SPEC, **patch})
