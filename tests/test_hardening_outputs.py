"""Issue 39: what a run folder holds and how the command line refuses what it cannot do.

The resolved scenario.toml of a run replays the run from the folder alone; summary.json names the package
version and the command; --out that cannot be created, a start the flight cannot trim, and overlapping GNSS
outages are refused before any flight; SIGTERM is handled as Ctrl-C is (exit 143, one line, nothing left).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from trn_env import __version__, cli
from trn_env.scenario.loading import ScenarioError, load_scenario, read_scenario_file, validate
from trn_env.sim.closed_loop import ClosedLoop

SCEN = Path(__file__).parent / "scenarios"
SAME = ("horizontal_error_rms_m", "horizontal_error_final_m", "vertical_error_rms_m", "termination",
        "jsbsim_steps", "seed", "navigator", "sim_time_s", "distance_flown_m")


def _no_flight(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("flew although the input should have been refused first")
    monkeypatch.setattr(ClosedLoop, "__init__", refuse)


def test_run_folder_holds_the_resolved_scenario_and_replays_from_it(tmp_path, capsys):
    """--seed, --navigator, --duration and --set land in RUN/scenario.toml; flying that file alone gives
    the same summary figures; summary.json names the package version and the command line."""
    run = tmp_path / "run"
    args = ["fly", str(SCEN / "default_short.toml"), "--out", str(run), "--quiet", "--no-plots",
            "--seed", "5", "--navigator", "ins", "--duration", "8", "--set", "wind.layers.0.speed_mps=7.5"]
    assert cli.main(args) == 0
    summary = json.loads((run / "summary.json").read_text())
    assert summary["trn_env_version"] == __version__
    assert summary["command_line"].startswith("trn-env fly ") and "--set wind.layers.0.speed_mps=7.5" in \
        summary["command_line"]
    assert "scenario.toml" in summary["files"]
    data, _ = read_scenario_file(run / "scenario.toml")
    assert data["seed"] == 5 and data["navigator"]["name"] == "ins" and data["duration_s"] == 8.0
    assert data["wind"]["layers"][0]["speed_mps"] == 7.5
    assert load_scenario(run / "scenario.toml").to_dict() == load_scenario(
        SCEN / "default_short.toml", seed=5, navigator="ins", duration_s=8.0).to_dict() | {
        "wind": data["wind"]}
    replay = tmp_path / "replay"
    capsys.readouterr()
    assert cli.main(["fly", str(run / "scenario.toml"), "--out", str(replay), "--quiet", "--no-plots"]) == 0
    again = json.loads((replay / "summary.json").read_text())
    for key in SAME:
        assert again[key] == summary[key], key


def test_version_and_fly_help_lists_the_navigators(capsys):
    with pytest.raises(SystemExit) as ex:
        cli.main(["--version"])
    assert ex.value.code == 0 and capsys.readouterr().out.strip() == f"trn-env {__version__}"
    with pytest.raises(SystemExit):
        cli.main(["fly", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    from trn_env.navigators import registry
    for name in registry.available():
        assert name in text, name
    assert "navigators (--navigator NAME):" in text


@pytest.mark.parametrize("out, why", [("/proc/trn-env-x/y", "cannot create"),
                                      ("{tmp}/file.txt/run", "is not a directory")])
def test_out_that_cannot_be_created_is_refused_before_flying(tmp_path, capsys, monkeypatch, out, why):
    (tmp_path / "file.txt").write_text("x")
    _no_flight(monkeypatch)
    code = cli.main(["fly", str(SCEN / "default_short.toml"), "--out", out.format(tmp=tmp_path), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and why in err and "Traceback" not in err, err


def _short_data() -> dict:
    data, _ = read_scenario_file(SCEN / "default_short.toml")
    return data


def test_validate_refuses_a_start_the_flight_cannot_trim(tmp_path, capsys, monkeypatch):
    text = (SCEN / "default_short.toml").read_text()
    text = text.replace("tas_mps = 85.0\nheading", "tas_mps = 30.0\nheading")
    bad = tmp_path / "slow.toml"
    bad.write_text(text)
    assert cli.main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "initial: JSBSim cannot trim" in err and "initial.tas_mps" in err
    _no_flight(monkeypatch)
    assert cli.main(["fly", str(bad), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("outages, where, what", [
    ([{"start_s": 10.0, "end_s": 100.0}, {"start_s": 50.0, "end_s": 120.0}], "gnss.outages[1]:", "overlaps"),
    ([{"start_s": 50.0, "end_s": 60.0}, {"start_s": 10.0, "end_s": 20.0}], "gnss.outages[1].start_s:",
     "time order"),
    ([{"start_s": 10.0}, {"start_s": 50.0, "end_s": 60.0}], "gnss.outages[1]:", "inside the open outage"),
])
def test_gnss_outages_that_overlap_or_disorder_are_refused(outages, where, what):
    data = _short_data()
    data["gnss"] = {"outages": outages}
    with pytest.raises(ScenarioError) as err:
        validate(data, source="t")
    assert any(p.startswith(where) and what in p for p in err.value.problems), err.value.problems
    data["gnss"] = {"outages": [{"start_s": 10.0, "end_s": 50.0}, {"start_s": 50.0, "end_s": 60.0},
                                {"start_s": 70.0}]}          # touching and an open last window: fine
    validate(data, source="t")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX signals")
def test_sigterm_mid_flight_is_handled_like_ctrl_c(tmp_path):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}     # in tmp_path: the child imports the installed trn_env
    # the point-mass filter's flight lasts ~5 s (ins_tercom's can end within a second of 'ready after')
    proc = subprocess.Popen([sys.executable, "-m", "trn_env.cli", "fly", "default", "--navigator", "pmf",
                             "--out", str(tmp_path / "run")], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    head = ""
    while True:                        # until the flight has started
        line = proc.stderr.readline()
        head += line
        if line.startswith("ready after") or not line:
            break
    proc.send_signal(signal.SIGTERM)   # the command only, as `kill PID` or a job scheduler sends it
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, head + err
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "terminated: nothing written", err
    # besides the progress bar (it may have drawn before the signal landed), the one line
    messages = [ln for ln in err.strip().splitlines() if not ln.startswith("fly default:")]
    assert len(messages) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == []     # no run folder, no .run.partial-* left


def test_goal_error_model_terms():
    """Each term of the short-term INS error growth alone, against its closed form (per axis, x sqrt 2)."""
    import math

    from trn_env.guidance.goal_error import G_MPS2, expected_goal_error_m
    t = 100.0
    assert expected_goal_error_m(8500.0, 85.0, 1e-3, 0.0, 0.0, 0.0) == pytest.approx(math.sqrt(2) * 5.0)
    assert expected_goal_error_m(8500.0, 85.0, 0.0, 1e-6, 0.0, 0.0) == pytest.approx(
        math.sqrt(2) * G_MPS2 * 1e-6 * t ** 3 / 6)
    assert expected_goal_error_m(0.0, 85.0, 1e-3, 1e-6, 5.0, 0.1) == pytest.approx(math.sqrt(2) * 5.0)
    assert expected_goal_error_m(8500.0, 85.0, 1e-3, 1e-6) > expected_goal_error_m(4250.0, 85.0, 1e-3, 1e-6)


# ------------------------------------------------------------------------------------- a full disk

def _no_space(*_args, **_kw):
    import errno
    raise OSError(errno.ENOSPC, "Error writing bytes to file. Detail: [errno 28] No space left on device")


@pytest.mark.parametrize("how", ["fly", "fly --no-pipeline", "record"])
def test_a_full_disk_during_the_flight_is_one_line_and_nothing_is_left(tmp_path, capsys, monkeypatch, how):
    """The log streamed during a flight hits a full disk (as pyarrow reports it; the navigator's worker
    process raises it in the pipelined loop): one line, exit 2, no partial folder (a traceback, exit 1,
    before)."""
    from trn_env.logs import writer
    monkeypatch.setattr(writer._Table, "flush", _no_space)       # (inherited by the forked worker)
    command, *opts = how.split()
    out = tmp_path / "out"
    args = [command, "default", "--duration", "5", "--quiet", "--out", str(out), *opts]
    assert cli.main(args + (["--no-plots"] if command == "fly" else [])) == 2
    err = capsys.readouterr().err.strip().splitlines()
    what = "the log" if command == "record" else "the run's log beside"
    assert err == [f"error: cannot write {what} {out}: No space left on device (nothing written)"], err
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_when_writing_a_run_folder_a_report_or_a_campaigns_rows(tmp_path, capsys, monkeypatch):
    from trn_env.campaign import driver
    from trn_env.output import run_folder

    out = tmp_path / "run"
    with monkeypatch.context() as m:
        m.setattr(run_folder, "write_run", _no_space)
        assert cli.main(["fly", "default", "--duration", "5", "--quiet", "--no-plots",
                         "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == (f"error: cannot write the run folder {out}: No space left on "
                                               "device (nothing written)")
    assert list(tmp_path.iterdir()) == []
    camp = tmp_path / "camp"
    real = driver.write_row
    calls = []

    def second_row_fails(out_dir, row):
        calls.append(row)
        return _no_space() if len(calls) > 1 else real(out_dir, row)

    with monkeypatch.context() as m:
        m.setattr(driver, "write_row", second_row_fails)
        assert cli.main(["campaign", str(Path(__file__).parent / "campaigns" / "ci_small.toml"), "--out",
                         str(camp), "--workers", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"error: cannot write the campaign {camp}: No space left on device (the finished runs' "
                   f"rows are in {camp / 'runs'}: continue with --resume once it can be written)"), err
    assert len(list((camp / "runs").glob("*.parquet"))) == 1
    assert cli.main(["campaign", str(Path(__file__).parent / "campaigns" / "ci_small.toml"), "--out",
                     str(camp), "--workers", "1", "--quiet", "--resume"]) == 0
    assert "1 already done" in capsys.readouterr().out
    from trn_env.campaign import report
    with monkeypatch.context() as m:
        m.setattr(report, "cdf_plot", _no_space)
        assert cli.main(["report", str(camp)]) == 2
    assert capsys.readouterr().err.strip() == (f"error: cannot write the report {camp / 'report'}: No space "
                                               "left on device (nothing written)")
    assert not (camp / "report").exists() and not list(camp.glob(".report*"))


@pytest.mark.parametrize("args, names", [
    (["fly", "default", "--duration", "5", "--no-plots", "--quiet", "--out", "{L}"], "--out {L}"),
    (["record", "default", "--duration", "5", "--quiet", "--out", "{L}"], "--out {L}"),
    (["replay", "{L}", "--navigator", "pmf", "--out", "{tmp}/out"], "log {L}"),
    (["replay", "{L}", "--navigator", "pmf"], "log {L}"),
    (["plan", "default", "--goal", "36.66", "-84.18", "--out", "{L}.toml"], "--out {L}.toml"),
    (["campaign", str(Path(__file__).parent / "campaigns" / "ci_small.toml"), "--quiet", "--out", "{L}"],
     "--out {L}"),
    (["campaign", "{L}.toml"], "{L}.toml"),
    (["validate", "{L}.toml"], "{L}.toml"),
    (["report", "{L}"], "report: {L}"),
    (["report", "{L}", "--out", "{tmp}/report"], "report: {L}"),
])
def test_a_name_longer_than_the_file_system_takes_is_one_line(tmp_path, capsys, monkeypatch, args, names):
    """A 300-character name (NAME_MAX is 255 on Linux's file systems) as an output or an input: one line
    naming that path in its role and exit 2 (the lookups raised ENAMETOOLONG: a traceback, exit 1; an
    input's name was blamed on the output derived from it)."""
    monkeypatch.chdir(tmp_path)
    long_name = str(tmp_path / ("x" * 300))
    argv = [a.replace("{L}", long_name).replace("{tmp}", str(tmp_path)) for a in args]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "File name too long" in err and "Traceback" not in err, err
    assert names.replace("{L}", long_name) + ": File name too long" in err, err
    assert list(tmp_path.iterdir()) == []
