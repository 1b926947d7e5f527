"""The bench's bare JSBSim reference loop is a fair stand-in for gymnasium-jsbsim: its JSBSim rate (60 Hz for
every aircraft, jsbgym `JsbSimEnv.JSBSIM_DT_HZ`), agent step (5 Hz) and per-step property traffic of its
HeadingControlTask (`FlightTask.task_step`: 3 controls written; run() 12 times; custom properties: v-north,
v-east, target track, altitude, steps left read, track error, altitude error, steps left written; 17 state
properties read; the terminal test reads steps left, the assessment reward and the altitude error; 2
reward properties written), counted through a proxy around the real FGFDMExec."""

from __future__ import annotations

import numpy as np
import pytest
from _scripts import load_script

from trn_env.bench import env as bench_env


class _Counting:
    """Delegates to a JSBSim FGFDMExec, counting reads, writes and run() calls."""

    def __init__(self, fdm):
        self.fdm, self.reads, self.writes, self.runs = fdm, 0, 0, 0

    def __getitem__(self, name):
        self.reads += 1
        return self.fdm[name]

    def __setitem__(self, name, value):
        self.writes += 1
        self.fdm[name] = value

    def run(self):
        self.runs += 1
        return self.fdm.run()

    def reset_to_initial_conditions(self, mode):
        return self.fdm.reset_to_initial_conditions(mode)


def test_king_air_reference_flies_at_gymnasium_jsbsims_rate_with_its_property_traffic():
    fdm, dt = bench_env.gym_reference_fdm("kingair")
    assert dt == 1.0 / 60.0 and abs(fdm.get_delta_t() - 1.0 / 60.0) < 1e-12
    proxy = _Counting(fdm)
    env = bench_env.GymJsbsimReference(proxy, dt)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (17,) and np.isfinite(obs).all()
    t0 = fdm["simulation/sim-time-sec"]
    steps = 5
    proxy.reads = proxy.writes = proxy.runs = 0
    for _ in range(steps):
        obs, reward, term, trunc, _ = env.step(np.zeros(3))
        assert np.isfinite(obs).all() and 0.0 <= reward <= 1.0 and not trunc
    assert proxy.runs == 12 * steps
    assert abs(fdm["simulation/sim-time-sec"] - t0 - 0.2 * steps) < 1e-9
    assert proxy.reads == (5 + 17 + 3) * steps
    assert proxy.writes == (3 + 3 + 2) * steps
    # the state it returns is the aircraft's: altitude in ft, the altitude error against the start
    assert abs(obs[0] - fdm["position/h-sl-ft"]) < 1e-9
    assert abs(obs[13] - (fdm["position/h-sl-ft"] - env.target_alt_ft)) < 1e-9


def test_reference_episode_ends_after_60_simulated_seconds():
    fdm, dt = bench_env.gym_reference_fdm("c172p")
    env = bench_env.GymJsbsimReference(fdm, dt)
    env.reset(seed=0)
    n = 0
    term = False
    while not term and n < 1000:
        *_, term, _, _ = env.step(np.zeros(3))
        n += 1
    assert term and n <= 300                     # 60 s of 0.2 s steps, or earlier on an altitude excursion


def test_reference_rejects_an_unknown_aircraft():
    with pytest.raises(ValueError, match="aircraft"):
        bench_env.gym_reference_fdm("f16")


def test_ratio_check_script_bad_arguments_exit_2(capsys):
    """scripts/env_ratio_check.py: a bad --repeats or --ref-s is a one-line error and exit 2."""
    mod = load_script("env_ratio_check")
    for argv, words in ((["--repeats", "0"], "--repeats"), (["--ref-s", "0"], "--ref-s"),
                        (["--ref-s", "nan"], "--ref-s")):
        assert mod.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and words in err, err
