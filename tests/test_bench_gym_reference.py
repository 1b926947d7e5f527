"""The bench's bare JSBSim reference loop is a fair stand-in for gymnasium-jsbsim: its JSBSim rate (60 Hz for
every aircraft, jsbgym `JsbSimEnv.JSBSIM_DT_HZ`), agent step (5 Hz) and per-step property traffic of its
HeadingControlTask (`FlightTask.task_step`: 3 controls written; run() 12 times; custom properties: v-north,
v-east, target track, altitude, steps left read, track error, altitude error, steps left written; 17 state
properties read; the terminal test reads steps left, the assessment reward and the altitude error; 2
reward properties written), counted through a proxy around the real FGFDMExec, and the same traffic
counted in the gymnasium-jsbsim package itself (the `bench` extra)."""

from __future__ import annotations

import collections
import math

import numpy as np
import pytest
from _scripts import load_script

from trn_env.bench import env as bench_env


class _Counting:
    """Delegates to a JSBSim FGFDMExec, counting reads, writes and run() calls (and the property names)."""

    def __init__(self, fdm):
        self.fdm, self.reads, self.writes, self.runs = fdm, 0, 0, 0
        self.read_names, self.written_names = collections.Counter(), collections.Counter()

    def __getitem__(self, name):
        self.reads += 1
        self.read_names[name] += 1
        return self.fdm[name]

    def __setitem__(self, name, value):
        self.writes += 1
        self.written_names[name] += 1
        self.fdm[name] = value

    def __getattr__(self, name):             # the rest of FGFDMExec's interface, uncounted
        return getattr(self.fdm, name)

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


def _count_steps(env, proxy, steps: int, n_act: int) -> None:
    proxy.reads = proxy.writes = proxy.runs = 0
    proxy.read_names.clear()
    proxy.written_names.clear()
    for _ in range(steps):
        env.step(np.zeros(n_act, np.float32))


def test_gymnasium_jsbsim_package_has_the_stand_ins_traffic_per_step():
    """The package's own env, made as its users make it, counted through the same proxy: the same run()
    calls, and the same properties read and written, name by name, as GymJsbsimReference's."""
    pytest.importorskip("gymnasium_jsbsim")
    import gymnasium as gym

    from trn_env.scenario.build import quiet_stdout

    with quiet_stdout():
        pkg = gym.make(bench_env.GYMNASIUM_JSBSIM_ENV_ID)
        pkg.reset(seed=0)
    sim = pkg.unwrapped.sim
    assert abs(sim.sim_dt - 1.0 / bench_env.GYM_JSBSIM_DT_HZ) < 1e-12
    pkg_proxy = _Counting(sim.jsbsim)
    sim.jsbsim = pkg_proxy
    steps = 5
    _count_steps(pkg, pkg_proxy, steps, 3)

    fdm, dt = bench_env.gym_reference_fdm("c172p")
    ours_proxy = _Counting(fdm)
    ours = bench_env.GymJsbsimReference(ours_proxy, dt)
    ours.reset(seed=0)
    _count_steps(ours, ours_proxy, steps, 3)
    assert pkg_proxy.runs == ours_proxy.runs == 12 * steps
    assert pkg_proxy.read_names == ours_proxy.read_names
    assert pkg_proxy.written_names == ours_proxy.written_names
    pkg.close()


def test_gymnasium_jsbsim_package_rates_are_measured_quietly(capfd):
    """The bench's figure for the package: positive, finite, and JSBSim's banner kept off stdout (the bench
    prints its JSON there)."""
    pytest.importorskip("gymnasium_jsbsim")
    rates = bench_env.gymnasium_jsbsim_package_rates(0.3)
    assert rates is not None and all(math.isfinite(r) and r > 0 for r in rates)
    assert "JSBSim" not in capfd.readouterr().out


def test_jsbsim_alone_ceiling_only_runs_the_task_envs_own_flight():
    """The ceiling of the env's figure: bare run() calls on the route task env's own JSBSim flight (its King
    Air at the task's 50 Hz), no property read or written, simulated time = run() calls x the flight's
    step."""
    import types

    from trn_env.env.route_task import env_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv

    env = TerrainNavEnv(**env_kwargs("basin"))
    try:
        env.reset(seed=0)
        flight = env._loop.flight
        assert flight.dt_s == 0.02 and abs(flight.fdm.get_delta_t() - 0.02) < 1e-12
        proxy = _Counting(flight.fdm)
        t0 = flight.fdm["simulation/sim-time-sec"]
        proxy.reads = 0
        wall, cpu = bench_env._jsbsim_alone_rates(types.SimpleNamespace(fdm=proxy, dt_s=flight.dt_s), 0.05)
        assert proxy.runs >= 100 and proxy.runs % 100 == 0
        assert proxy.reads == 0 and proxy.writes == 0
        assert abs(flight.fdm["simulation/sim-time-sec"] - t0 - proxy.runs * 0.02) < 1e-6
        assert all(math.isfinite(r) and r > 0 for r in (wall, cpu))
        # the rate is the simulated seconds run over at least the 0.05 s asked for
        assert wall <= proxy.runs * 0.02 / 0.05
    finally:
        env.close()
