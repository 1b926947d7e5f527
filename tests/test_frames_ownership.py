"""The loop's log and monitors get the sensor frames as measured, whatever a navigator or a monitor changes
in them in place (trn_env.sim.nav_stage: each reader gets arrays of its own while others read the frames).

Before, a navigator correcting its barometer in place (`frames.baro.h_baro_m += bias`) wrote the correction
into the recorded log (a replay then applied it twice) and into what the monitors saw."""

from __future__ import annotations

import numpy as np
from trn_env.navigators import registry
from trn_env.navigators.builtin import ins as _ins

SEEN: dict[str, list[np.ndarray]] = {"navigator": [], "monitor": []}


class BaroCorrectingIns:
    """The built-in INS, adding 100 m to the barometer's heights in the frames it is given."""

    name = "baro_correcting_ins"

    def __init__(self, **settings):
        self.nav = _ins(**settings)

    def reset(self, initial):
        self.nav.reset(initial)

    def update(self, frames):
        if frames.baro is not None:
            SEEN["navigator"].append(frames.baro.h_baro_m.copy())
            frames.baro.h_baro_m += 100.0
        return self.nav.update(frames)


class BaroCorrectingMonitor:
    """The DEM monitor, adding 50 m to the barometer's heights in the frames it is given."""

    def __init__(self, **settings):
        self.inner = registry.create_monitor("dem_integrity", **settings)

    def reset(self):
        self.inner.reset()

    def update(self, frames, estimate):
        if frames.baro is not None:
            SEEN["monitor"].append(frames.baro.h_baro_m.copy())
            frames.baro.h_baro_m += 50.0
        return self.inner.update(frames, estimate)


def test_log_and_monitors_get_the_frames_as_measured():
    from trn_env.scenario.overrides import load_scenario_with
    from trn_env.sim.closed_loop import ClosedLoop

    for seen in SEEN.values():
        seen.clear()
    sc = load_scenario_with("default", [("monitors", {f"{__name__}:BaroCorrectingMonitor": {}})], seed=3,
                            duration_s=6.0, navigator=f"{__name__}:BaroCorrectingIns")
    loop = ClosedLoop(sc, log_sensors=True, pipeline=False)
    try:
        while loop.termination is None:
            loop.tick()
    finally:
        loop.close()
    logged = [fr.baro.h_baro_m for fr in loop.log.frames if fr.baro is not None]
    assert len(logged) == len(SEEN["navigator"]) == len(SEEN["monitor"]) >= 5
    for log_h, nav_h, mon_h in zip(logged, SEEN["navigator"], SEEN["monitor"], strict=True):
        assert np.array_equal(log_h, nav_h) and np.array_equal(log_h, mon_h)


def test_replay_gives_the_monitors_the_frames_as_logged(tmp_path):
    from trn_env.cli import main
    from trn_env.logs import read_log
    from trn_env.logs.replay import replay

    log_path = tmp_path / "flight.trnlog"
    assert main(["record", "default", "--out", str(log_path), "--duration", "6", "--quiet"]) == 0
    for seen in SEEN.values():
        seen.clear()
    replay(log_path, f"{__name__}:BaroCorrectingIns", monitors=[f"{__name__}:BaroCorrectingMonitor"])
    logged = [fr.baro.h_baro_m for fr in read_log(log_path).frames() if fr.baro is not None]
    assert len(logged) == len(SEEN["navigator"]) == len(SEEN["monitor"]) >= 5
    for log_h, nav_h, mon_h in zip(logged, SEEN["navigator"], SEEN["monitor"], strict=True):
        assert np.array_equal(log_h, nav_h) and np.array_equal(log_h, mon_h)


class ReturnsNothing(BaroCorrectingIns):
    """A navigator whose update forgot its `return`."""

    def update(self, frames):
        self.nav.update(frames)


def test_an_update_returning_no_estimate_is_one_line_naming_the_navigator(tmp_path, capsys):
    """It was an AttributeError traceback from inside the loop ('NoneType' object has no attribute
    'lat_rad'), exit 1, in fly (both stages), record and replay."""
    from trn_env.cli import main

    log_path = tmp_path / "flight.trnlog"
    assert main(["record", "default", "--out", str(log_path), "--duration", "3", "--quiet"]) == 0
    ref = f"{__name__}:ReturnsNothing"
    for argv in (["fly", "default", "--out", str(tmp_path / "run")],
                 ["fly", "default", "--no-pipeline", "--out", str(tmp_path / "run")],
                 ["record", "default", "--out", str(tmp_path / "again.trnlog")],
                 ["replay", str(log_path), "--out", str(tmp_path / "replayed")]):
        argv = [*argv, "--navigator", ref] + (["--duration", "3", "--quiet"] if argv[0] != "replay" else [])
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1] == ("error: navigator 'baro_correcting_ins': update() returned NoneType, not a "
                           "trn_env.navigators.protocol.Estimate (the update ending 1.01 s): return the "
                           "estimate from every update; trn_env.testing.check_navigator checks the whole "
                           "contract (nothing written)"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.trnlog"]


class ThreeColumnMonitor(BaroCorrectingMonitor):
    """The DEM monitor, handing back only three of its seven columns."""

    def update(self, frames, estimate):
        from trn_env.navigators.integrity.dem_monitor import MonitorOutput
        out = self.inner.update(frames, estimate)
        return MonitorOutput(out.rows[:, :3], out.threshold, out.events)


def test_a_monitor_output_the_run_cannot_concatenate_stops_at_its_first_update(tmp_path, capsys):
    """The flight was flown to its end and then lost to an IndexError traceback on concatenating the
    monitor's rows; now the first update stops it, one line, exit 2, and check_navigator names it."""
    from trn_env.cli import main
    from trn_env.testing import check_navigator

    argv = ["fly", "default", "--duration", "20", "--quiet", "--out", str(tmp_path / "run"),
            "--set", f'monitors={{"{__name__}:ThreeColumnMonitor"={{}}}}']
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith(f"error: monitor '{__name__}:ThreeColumnMonitor': update() returned MonitorOutput "
                          "(rows of shape (0, 3), events list), not a MonitorOutput with rows (m, 7)"), err
    assert "(the update ending 1.01 s)" in err and not (tmp_path / "run").exists()
    report = check_navigator(ThreeColumnMonitor, kind="monitor", check_settings=False, verbose=False)
    assert [p.check for p in report.problems] == ["contract"] and "rows (m, 7)" in report.problems[0].message


class ThreeByThree(BaroCorrectingIns):
    """A navigator reporting only its position covariance."""

    def update(self, frames):
        est = self.nav.update(frames)
        est.covariance = est.covariance[:3, :3].copy()
        return est


def test_an_estimate_without_the_9_by_9_covariance_is_one_line_naming_the_navigator(tmp_path, capsys):
    """It was 'error: scenario built-in 'default': setting an array element with a sequence. The requested
    array has an inhomogeneous shape ...': blamed on the scenario, naming neither the navigator nor the
    covariance."""
    from trn_env.cli import main

    argv = ["fly", "default", "--duration", "3", "--quiet", "--out", str(tmp_path / "run"),
            "--navigator", f"{__name__}:ThreeByThree"]
    assert main(argv) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "error: navigator 'baro_correcting_ins': its estimate's covariance has shape (3, 3), not the 9 x 9 "
        "block over [north, east, down, v_n, v_e, v_d, roll, pitch, yaw] (the update ending 1.01 s): return "
        "the estimate from every update; trn_env.testing.check_navigator checks the whole contract (nothing "
        "written)")
