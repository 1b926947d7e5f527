"""The fast tier's airspeed model (trn_env.env.fast.envelope): the fits that measure it, against synthetic
series with known parameters, and the aircraft flying it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trn_env.env.fast.envelope import KINGAIR_ENVELOPE, fit_speed_trade, seed_spread, wander_from_spread


def _lag(x, dt, tau):
    a = 1.0 - math.exp(-dt / tau)
    out, acc = np.empty_like(x), 0.0
    for k in range(x.size):
        acc += a * (x[k] - acc)
        out[k] = acc
    return out


def test_fit_speed_trade_recovers_gain_and_lag():
    """A vertical-speed history of climbs and descents, TAS = 85 - 0.6 x VS lagged 3 s + white noise: the
    fit finds the gain within 3 % and the lag on its grid."""
    rng = np.random.default_rng(1)
    dt = 0.1
    t = np.arange(0.0, 600.0, dt)
    vs = 7.0 * np.sign(np.sin(2 * np.pi * t / 90.0))
    tas = 85.0 - 0.6 * _lag(vs, dt, 3.0) + rng.normal(0.0, 1.0, t.size)
    gain, tau = fit_speed_trade([np.column_stack([t, tas, vs])], 85.0)
    assert gain == pytest.approx(0.6, rel=0.03)
    assert tau == pytest.approx(3.0, abs=0.5)


def test_seed_spread_of_a_gauss_markov_process():
    """64 seeds of a first-order Gauss-Markov process (sigma 2 m/s, tau 20 s, 1 Hz, 600 s) plus a common
    signal: the spread over the seeds removes the common part; variance within 15 % of 4, the integral time
    scale within 30 % of 20 s (its sampling spread at 64 x 600 s is ~10 %)."""
    rng = np.random.default_rng(2)
    a = math.exp(-1.0 / 20.0)
    x = np.zeros((64, 600))
    for k in range(1, 600):
        x[:, k] = a * x[:, k - 1] + 2.0 * math.sqrt(1 - a * a) * rng.normal(size=64)
    common = 5.0 * np.sin(np.arange(600) / 30.0)
    var, t_int = seed_spread(x + common)
    assert var == pytest.approx(4.0, rel=0.15)
    assert t_int == pytest.approx(20.0, rel=0.3)


def test_wander_from_spread_adds_what_the_gust_lacks():
    w, tau = wander_from_spread(4.0, 20.0, 1.5, 6.0)
    assert w**2 == pytest.approx(4.0 - 2.25)
    assert w**2 * tau == pytest.approx(80.0 - 2.25 * 6.0)
    assert wander_from_spread(2.0, 5.0, 1.5, 6.0) == (0.0, 0.0)


def test_fast_aircraft_speeds_up_descending():
    """One fast-tier aircraft told to descend 600 m: its ground speed (calm air, no turbulence) exceeds the
    held airspeed by about tas_per_vs x the descent rate, and it is back near the held one once level."""
    from trn_env.env.fast import state as S
    from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv
    from trn_env.scenario.overrides import load_scenario_with

    sc = load_scenario_with("basin_route", [("wind.layers", []), ("wind.turbulence.model", "none")])
    env = TerrainNavFastVectorEnv(num_envs=1, scenario=sc, action_mode="turn", decision_interval_s=30.0,
                                  agl_min_m=300.0, agl_max_m=900.0, max_episode_s=480.0)
    env.reset(seed=0)
    env._X[:, S.AGL_CMD] = 300.0
    speeds = []
    for _ in range(6):
        d0 = env._X[0, S.DIST_FLOWN]
        env.step(np.zeros((1, 2), np.float32))
        speeds.append((env._X[0, S.DIST_FLOWN] - d0) / 30.0)
    e = KINGAIR_ENVELOPE
    descending = e.tas_mps + e.tas_per_vs * e.descent_rate_max_mps
    assert max(speeds) == pytest.approx(descending, abs=2.5)
    assert speeds[-1] < max(speeds) - 2.0


def test_speed_trade_script_bad_arguments_exit_2(capsys):
    """scripts/fast_tier_speed_trade.py: an unknown route or fewer than 2 seeds is a one-line error naming the
    argument and exit 2, before anything flies."""
    from _scripts import load_script

    mod = load_script("fast_tier_speed_trade")
    for argv, words in ((["--routes", "nowhere"], "--routes"), (["--seeds", "1"], "--seeds")):
        assert mod.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and words in err, err
