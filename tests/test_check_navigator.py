"""trn_env.testing.check_navigator: every built-in navigator and monitor and the SITAN template plug-in pass
it; navigators broken on purpose fail it, each with the check that names the fault.

All checks share one recorded flight per process (the default route, 30 s, every sensor fitted)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators.builtin import ins as _ins
from trn_env.navigators.frames import copy_frames

from trn_env.testing import NavigatorCheckError, check_navigator, recorded_flight


@pytest.fixture(scope="module")
def sitan_installed():
    from sitan_support import ensure_sitan_installed
    ensure_sitan_installed()


@pytest.mark.parametrize("name, settings", [
    ("ins", {}),
    ("ins_tercom", {"remove_bias": True}),
    ("pmf", {"grid_size": 60}),
    ("pf", {"n_particles": 2000}),
    ("acq_track", {}),
    ("dem_integrity", {}),
])
def test_builtin_passes(name, settings):
    report = check_navigator(name, settings, verbose=False)
    assert report.ok, str(report)
    assert "determinism" in report.checks and any(c.startswith("bad settings refused") for c in report.checks)
    if report.kind == "navigator":
        assert report.info["speed_sim_s_per_wall_s"] > 0
        assert math.isfinite(report.info["position_nees_mean (3 = consistent)"])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pmf", "pf", "rbpf"])
def test_builtin_passes_with_default_settings(name):
    report = check_navigator(name, verbose=False)
    assert report.ok, str(report)


def test_sitan_plugin_passes(sitan_installed):
    report = check_navigator("sitan", verbose=False)
    assert report.ok, str(report)
    assert {"radar_altimeter", "imu"} <= set(report.info["sensors_used"])
    assert "robust off the map" in report.checks
    assert "declared sensors enforced (2 required)" in report.checks


# ------------------------------------------------------------------------------------------ the checker fails

class Faulty:
    """The built-in INS with one fault injected (`fault`), to show the checker catches it."""

    name = "faulty"

    def __init__(self, fault: str = "none", gain: float = 1.0, rng=None, **settings):
        self.fault = fault
        self.gain = gain
        self.rng = rng if rng is not None else np.random.default_rng()
        self.nav = _ins(**settings)
        self.kept = None
        self.P = np.zeros((9, 9))

    def reset(self, initial):
        self.nav.reset(initial)
        self.kept = None

    def update(self, frames):
        if self.fault == "raise_on_nan" and frames.imu is not None and np.isnan(frames.imu.f_b_mps2).any():
            raise ValueError("NaN in the IMU")
        if self.fault == "frames_in_place" and frames.baro is not None:
            frames.baro.h_baro_m += 100.0                       # a bias correction made on the input
        est = self.nav.update(frames)
        if self.fault == "asymmetric":
            est.covariance = est.covariance.copy()
            est.covariance[0, 1] += 1.0
        elif self.fault == "negative":
            est.covariance = est.covariance.copy()
            est.covariance[0, 0] = -1.0
        elif self.fault == "nan" and frames.t_start_s > 12:
            est.lat_rad = math.nan
        elif self.fault == "stale":
            est.t_s = frames.t_start_s
        elif self.fault == "random":
            est.lat_rad += 1e-9 * self.rng.standard_normal()
        elif self.fault == "reuse_estimate":                    # one Estimate object, overwritten
            if self.kept is None:
                self.kept = est
            else:
                vars(self.kept).update(vars(est))
            est = self.kept
        elif self.fault == "shared_covariance":                 # the filter's own P handed out
            self.P[:] = est.covariance
            est.covariance = self.P
        return est


@pytest.mark.parametrize("fault, check", [
    ("asymmetric", "covariance"), ("negative", "covariance"), ("nan", "finite"), ("stale", "contract"),
    ("raise_on_nan", "robustness"),
])
def test_checker_catches_faults(fault, check):
    report = check_navigator(Faulty, {"fault": fault}, check_settings=False, verbose=False)
    assert not report.ok
    assert check in {p.check for p in report.problems}, str(report)
    assert all(p.fix for p in report.problems)


@pytest.mark.parametrize("fault, words", [
    ("frames_in_place",
     "update(frames) changed its input frames in place (first at the update ending 1.01 s: baro.h_baro_m)"),
    ("reuse_estimate",
     "the estimate returned by update 0 changed afterwards: the same object is returned again"),
    ("shared_covariance", "the estimate returned by update 0 changed afterwards: it shares arrays"),
])
def test_checker_names_inputs_changed_in_place_and_outputs_changed_afterwards(fault, words):
    """Each was reported under a wrong diagnosis (frames and a shared covariance as 'determinism: draw random
    numbers only from the rng=', a reused Estimate as 'estimate time 30.0 s is neither the interval's end')
    and a navigator writing into its frames wrote into the process's recorded flight, which every later
    check reads. Now: one contract problem naming what changed, and the recording as it was."""
    rec = recorded_flight()
    before = [copy_frames(fr) for fr in rec.frames]
    report = check_navigator(Faulty, {"fault": fault}, check_settings=False, verbose=False)
    assert [(p.check, words in p.message) for p in report.problems] == [("contract", True)], str(report)
    for fr, was in zip(rec.frames, before, strict=True):
        assert np.array_equal(fr.baro.h_baro_m, was.baro.h_baro_m)
        assert np.array_equal(fr.imu.f_b_mps2, was.imu.f_b_mps2)


class _EstimateChangingMonitor:
    """The DEM monitor, moving the estimate it is given."""

    def __init__(self, **settings):
        from trn_env.navigators import registry
        self.inner = registry.create_monitor("dem_integrity", **settings)

    def reset(self):
        self.inner.reset()

    def update(self, frames, estimate):
        estimate.lat_rad += 1e-6
        return self.inner.update(frames, estimate)


def test_checker_names_a_monitor_changing_the_estimate_it_is_given():
    report = check_navigator(_EstimateChangingMonitor, kind="monitor", check_settings=False, verbose=False)
    assert [p.check for p in report.problems] == ["contract"], str(report)
    assert "update(frames, estimate) changed the navigator's estimate in place" in report.problems[0].message


def test_checker_catches_nondeterminism():
    """A navigator drawing from its own unseeded generator instead of the rng= it is given."""
    def factory(**settings):
        return Faulty(**{**settings, "rng": None})

    report = check_navigator(factory, {"fault": "random"}, check_settings=False, verbose=False)
    assert "determinism" in {p.check for p in report.problems}, str(report)


def test_checker_catches_unvalidated_settings():
    """Faulty accepts NaN and strings for `gain`: the checker names the setting."""
    report = check_navigator(Faulty, verbose=False)
    bad = [p for p in report.problems if p.check == "settings"]
    assert bad and "gain=nan: accepted" in bad[0].message
    assert "gain='not a number': accepted" in bad[0].message
    with pytest.raises(NavigatorCheckError, match="gain=nan"):
        check_navigator(Faulty, raise_on_failure=True, verbose=False)


class _NoUpdate:
    name = "no_update"

    def reset(self, initial):
        pass


def test_a_broken_or_missing_navigator_is_named_as_a_navigator():
    """A navigator reference that does not resolve is reported as a navigator with its own error (it was
    reported as a monitor: 'is not a monitor: ... lacks update(frames, estimate)'); a non-callable object is
    a protocol problem (it was 'construction failed: int object is not callable')."""
    for ref, words in ((f"{__name__}:_NoUpdate", "is not a navigator: class _NoUpdate lacks update(frames"),
                       ("no_such_module_xyz:Nav", "cannot import module 'no_such_module_xyz'"),
                       (42, "42 (int) is neither a name nor a class or factory")):
        report = check_navigator(ref, check_settings=False, verbose=False)
        assert report.kind == "navigator" and not report.ok
        assert [p.check for p in report.problems] == ["protocol"] and words in report.problems[0].message
    assert check_navigator("dem_integrity", check_settings=False, verbose=False).kind == "monitor"


def test_checker_passes_a_correct_wrapper():
    """The same wrapper without a fault passes everything but the settings check (gain unvalidated)."""
    report = check_navigator(Faulty, check_settings=False, verbose=False)
    assert report.ok, str(report)


def test_recorded_flight_has_every_sensor_and_gnss_denial():
    rec = recorded_flight()
    assert len(rec.frames) == 30
    f = rec.frames[0]
    for s in ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading"):
        assert getattr(f, s) is not None, s
    late = rec.frames[-1].gnss
    assert late is None or not np.any(late.valid)                  # denied from 10 s
    assert recorded_flight() is rec                                # recorded once per process
