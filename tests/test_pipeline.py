"""The pipelined closed loop: sensors and navigator in a forked worker process, same results as inline."""

from __future__ import annotations

import copy
import multiprocessing

import pytest
from _runs import assert_same_run

import trn_env.scenario.build as components
from trn_env.scenario.loading import read_scenario_file, validate
from trn_env.sim.closed_loop import ClosedLoop
from trn_env.sim.nav_stage import fork_available

pytestmark = pytest.mark.skipif(not fork_available(), reason="needs the fork start method")


def _scenario(duration_s: float, navigator: str = "ins_tercom", gnss_denied_from_s: float | None = None,
              **limits):
    data, _ = read_scenario_file("default")
    data = copy.deepcopy(data)
    if gnss_denied_from_s is not None:
        data["gnss"] = {"outages": [{"start_s": gnss_denied_from_s}]}
    data["duration_s"] = duration_s
    data["navigator"]["name"] = navigator
    if navigator != "ins_tercom":
        data["navigator"]["settings"] = {}
    data.setdefault("limits", {}).update(limits)
    return validate(data, source="test")


def _fly(sc, pipeline: bool):
    loop = ClosedLoop(sc, pipeline=pipeline)
    assert loop.pipelined is pipeline
    return loop.run()


def test_pipelined_run_equals_the_inline_run_bit_for_bit():
    """55 s of the default scenario (GNSS fused for 10 s, a TERCOM fix at 49 s): every logged array, event and
    summary figure."""
    sc = _scenario(55.0)
    inline, piped = _fly(sc, False), _fly(sc, True)
    assert piped.summary["pipelined"] and not inline.summary["pipelined"]
    assert any("TERCOM fix" in msg for _, _, msg in piped.events)
    assert piped.arrays["sensor_ira_range_m"].shape[0] == 55 * 50      # the worker's frames reach the log
    assert_same_run(inline, piped)
    assert not multiprocessing.active_children()                     # run() stopped the worker


def test_divergence_found_a_tick_late_ends_the_run_at_the_estimate_time():
    """A pipelined loop learns of a diverged estimate after it has flown the next interval; it ends at the
    estimate's time and drops that interval, exactly as the inline loop does."""
    sc = _scenario(30.0, navigator="ins", max_horizontal_sigma_m=14.0,   # free-inertial sigma grows past it
                   gnss_denied_from_s=0.0)
    inline, piped = _fly(sc, False), _fly(sc, True)
    assert inline.termination == "diverged"
    t_end = inline.arrays["t_s"][-1]
    assert t_end < 29.0 and inline.jsbsim_steps == round(t_end / 0.01)
    assert inline.events[-1] == (pytest.approx(t_end), "sim", "termination: diverged")
    assert_same_run(inline, piped)


def test_a_worker_exception_is_raised_by_tick_and_the_worker_stops(monkeypatch):
    real = components.build_navigator

    class Failing:
        def __init__(self, nav):
            self.nav = nav
            self.name = nav.name

        def reset(self, initial):
            self.nav.reset(initial)

        def update(self, frames):
            if frames.t_end_s > 3.0:
                raise ValueError("navigator failed at t > 3 s")
            return self.nav.update(frames)

    monkeypatch.setattr(components, "build_navigator", lambda *a, **k: Failing(real(*a, **k)))
    loop = ClosedLoop(_scenario(10.0, navigator="ins"), pipeline=True)
    assert loop.pipelined
    with pytest.raises(ValueError, match="navigator failed at t > 3 s"):
        while loop.tick() is None:
            pass
    loop.close()
    assert not multiprocessing.active_children()


def test_a_killed_worker_gives_a_clear_error():
    loop = ClosedLoop(_scenario(10.0, navigator="ins"), pipeline=True)
    loop.tick()
    loop._stage._process.kill()
    with pytest.raises(RuntimeError, match="worker process ended unexpectedly"):
        for _ in range(3):
            loop.tick()
    loop.close()


def test_without_latency_the_loop_runs_inline():
    sc = _scenario(3.0, navigator="ins").with_fields({"navigator.latency_updates": 0})
    with ClosedLoop(sc, pipeline=True) as loop:
        assert not loop.pipelined and loop.navigator is not None


def test_a_nan_estimate_ends_both_runs_at_its_time(monkeypatch):
    """The stage makes no guidance plan on a NaN estimate (the run ends on it): inline and pipelined end at
    the fifth update with the same log."""
    from trn_env.navigators.protocol import Estimate

    real = components.build_navigator

    class NanAfter5:
        def __init__(self, nav):
            self.nav, self.name = nav, nav.name

        def reset(self, initial):
            self.nav.reset(initial)

        def update(self, frames):
            est = self.nav.update(frames)
            if frames.t_end_s > 4.5:
                return Estimate(est.t_s, float("nan"), est.lon_rad, est.h_m, est.v_ned_mps, est.roll_rad,
                                est.pitch_rad, est.yaw_rad, est.covariance, est.health)
            return est

    monkeypatch.setattr(components, "build_navigator", lambda *a, **k: NanAfter5(real(*a, **k)))
    sc = _scenario(20.0, navigator="ins")
    inline, piped = _fly(sc, False), _fly(sc, True)
    assert inline.termination == "diverged" and inline.sim_time_s == pytest.approx(5.0)
    assert_same_run(inline, piped)


def test_a_worker_that_cannot_start_leaves_the_loop_inline(monkeypatch):
    import trn_env.sim.closed_loop as sim

    def no_process(inline):
        raise OSError("fork: resource temporarily unavailable")

    monkeypatch.setattr(sim, "ProcessNavStage", no_process)
    with pytest.warns(RuntimeWarning, match="running inline"):
        loop = ClosedLoop(_scenario(3.0, navigator="ins"), pipeline=True)
    assert not loop.pipelined and loop.navigator is not None
    assert loop.run().termination == "time_limit"
