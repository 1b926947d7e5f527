"""The `trn-env` command line: fly (outputs, atomic writes, bad input), scenarios, validate, bench."""

from __future__ import annotations

import json
import multiprocessing
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _child_processes import NEUTRAL_CWD
from _ecef import ned_between as ned_vector_between

from trn_env import cli
from trn_env.output import run_folder as output
from trn_env.scenario.loading import builtin_names
from trn_env.sim.closed_loop import ClosedLoop
from trn_env.sim.nav_stage import fork_available

SCEN = Path(__file__).parent / "scenarios"
DESIGN_FIELDS = ("scenario", "seed", "navigator", "sim_time_s", "wall_time_s", "realtime_factor",
                 "horizontal_error_rms_m", "horizontal_error_final_m", "vertical_error_rms_m", "termination")
TERMINATIONS = {"completed", "terrain_collision", "off_map", "diverged", "fuel_exhausted", "engine_failure",
                "time_limit"}


def _fly(tmp_path, *extra) -> tuple[int, Path]:
    out = tmp_path / "run"
    code = cli.main(["fly", str(SCEN / "default_short.toml"), "--out", str(out), "--quiet",
                     "--duration", "15", *extra])
    return code, out


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fly")
    code, out = _fly(tmp, "--seed", "3")
    return code, out


def test_fly_writes_summary_log_and_plots(flown):
    code, out = flown
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in DESIGN_FIELDS:
        assert key in summary, key
    assert summary["seed"] == 3 and summary["termination"] in TERMINATIONS
    assert summary["sim_time_s"] == pytest.approx(15.0)
    assert summary["realtime_factor"] == pytest.approx(summary["sim_time_s"] / summary["wall_time_s"])
    assert set(summary["files"]) >= {"summary.json", "log.npz", "timeline.csv", "track.png", "errors.png"}
    # the log is loadable by numpy and pandas and agrees with the summary (errors recomputed via ECEF)
    log = np.load(out / "log.npz")
    d = ned_vector_between(log["true_lat_rad"], log["true_lon_rad"], log["true_h_msl_m"], log["est_lat_rad"],
                           log["est_lon_rad"], log["est_h_m"])
    e_h = np.hypot(d[:, 0], d[:, 1])
    assert summary["horizontal_error_rms_m"] == pytest.approx(np.sqrt(np.mean(e_h ** 2)), rel=1e-3)
    assert summary["horizontal_error_final_m"] == pytest.approx(e_h[-1], rel=1e-3)
    assert summary["vertical_error_rms_m"] == pytest.approx(np.sqrt(np.mean(d[:, 2] ** 2)), rel=1e-3)
    table = pd.read_csv(out / "timeline.csv")
    assert list(table.columns) == output.TIMELINE_COLUMNS
    assert len(table) == log["t_s"].shape[0] == 16           # t = 0 and each 1 s navigator update
    assert np.allclose(table["err_horizontal_m"], e_h, atol=0.05)
    assert np.allclose(table["true_lat_deg"], np.degrees(log["true_lat_rad"]))
    for png in ("track.png", "errors.png"):
        data = (out / png).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert not list(out.parent.glob(".run.partial-*"))


def test_fly_rerun_into_existing_dir_refused_or_replaced_whole(flown, tmp_path, capsys, monkeypatch):
    """A run folder holds one run: a non-empty --out is refused before flying; --overwrite replaces the
    previous run's folder as a whole (its plots do not survive beside a --no-plots run's summary)."""
    _, out = flown
    target = tmp_path / "run"
    shutil.copytree(out, target)
    (target / "stale.txt").write_text("x")
    args = ["fly", str(SCEN / "default_short.toml"), "--out", str(target), "--quiet", "--duration", "5",
            "--seed", "4", "--no-plots"]
    before = sorted(p.name for p in target.iterdir())
    assert cli.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not empty" in err and "--overwrite" in err
    assert sorted(p.name for p in target.iterdir()) == before
    assert cli.main([*args, "--overwrite"]) == 0
    summary = json.loads((target / "summary.json").read_text())
    assert summary["seed"] == 4 and summary["sim_time_s"] == pytest.approx(5.0)
    assert len(pd.read_csv(target / "timeline.csv")) == 6
    assert sorted(p.name for p in target.iterdir()) == sorted(summary["files"])
    assert not (target / "track.png").exists() and not (target / "stale.txt").exists()
    assert not list(tmp_path.glob(".run.partial-*"))
    # a non-empty folder that holds no run is refused even with --overwrite
    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("keep")
    assert cli.main(["fly", "--out", str(other), "--overwrite", "--quiet", "--duration", "5"]) == 2
    assert "no previous run" in capsys.readouterr().err and (other / "mine.txt").read_text() == "keep"
    # nor the current folder (or one holding it), whatever it holds
    monkeypatch.chdir(target)
    assert cli.main(["fly", "--out", ".", "--overwrite", "--quiet", "--duration", "5"]) == 2
    assert "current folder" in capsys.readouterr().err and (target / "summary.json").exists()


def test_fly_without_out_keeps_a_run_already_in_its_default_folder(tmp_path, monkeypatch, capsys):
    """`trn-env fly` with no --out writes runs/<scenario>-<UTC second>: when another run already holds
    that name (two started in the same second), this one goes to NAME-2 and says so; the other is kept."""
    taken = tmp_path / "runs" / "default-20261206T120000Z"
    monkeypatch.setattr(output, "default_out_dir", lambda name, now=None: taken)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["fly", "--quiet", "--no-plots", "--duration", "5", "--seed", "1"]) == 0
    assert cli.main(["fly", "--quiet", "--no-plots", "--duration", "5", "--seed", "2"]) == 0
    second = taken.with_name(taken.name + "-2")
    assert second.name in "".join(capsys.readouterr().out.split())         # the table's title (wrapped)
    seeds = [json.loads((d / "summary.json").read_text())["seed"] for d in (taken, second)]
    assert seeds == [1, 2]


def test_bad_scenario_exits_nonzero_lists_problems_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    text = (SCEN / "default_short.toml").read_text()
    text = text.replace('name = "ins_tercom"', 'name = "warp_drive"')
    text = text.replace("duration_s = ", "extra_key = 1\nduration_s = ")
    bad.write_text(text)
    out = tmp_path / "never"
    code = cli.main(["fly", str(bad), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "extra_key: unknown key" in err
    assert "navigator.name: unknown navigator 'warp_drive'" in err
    assert not out.exists()
    assert not list(tmp_path.glob(".never*"))


def test_interrupted_flight_writes_nothing(tmp_path, monkeypatch, capsys):
    real_tick = ClosedLoop.tick
    count = {"n": 0}

    def tick_then_interrupt(self):
        count["n"] += 1
        if count["n"] == 8:
            raise KeyboardInterrupt
        return real_tick(self)

    monkeypatch.setattr(ClosedLoop, "tick", tick_then_interrupt)
    code, out = _fly(tmp_path)
    assert code == 130 and count["n"] == 8
    assert not out.exists() and not list(tmp_path.glob(".run.partial-*"))
    assert "interrupted" in capsys.readouterr().err
    assert not multiprocessing.active_children()          # the pipelined stage's worker was stopped


def test_fly_without_the_pipeline_gives_the_same_summary(flown, tmp_path):
    code, out = _fly(tmp_path, "--seed", "3", "--no-pipeline")
    assert code == 0
    a = json.loads((flown[1] / "summary.json").read_text())
    b = json.loads((out / "summary.json").read_text())
    assert b["pipelined"] is False and a["pipelined"] is fork_available()
    for k in ("horizontal_error_rms_m", "horizontal_error_final_m", "vertical_error_rms_m", "termination",
              "jsbsim_steps"):
        assert a[k] == b[k], k


def test_interrupted_while_writing_leaves_no_summary(tmp_path, monkeypatch):
    """Ctrl-C after log.npz and timeline.csv are written (inside the plots) leaves no run directory."""
    from trn_env.output import plots

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "plot_errors", boom)
    code, out = _fly(tmp_path)
    assert code == 130
    assert not out.exists() and not list(tmp_path.glob(".run.partial-*"))
    # into an existing run directory: its old summary is not left vouching for new files
    out.mkdir()
    (out / "summary.json").write_text("{}")
    monkeypatch.setattr(output, "write_timeline_csv", boom)
    code, _ = _fly(tmp_path, "--overwrite")
    assert code == 130
    assert (out / "summary.json").read_text() == "{}"          # untouched: nothing was moved in
    assert not (out / "log.npz").exists()


def test_scenarios_command_console_script():
    exe = shutil.which("trn-env")
    cmd = [exe, "scenarios"] if exe else [sys.executable, "-m", "trn_env.cli", "scenarios"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=NEUTRAL_CWD)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.strip().splitlines()
    assert [ln.split()[0] for ln in lines] == builtin_names()
    assert all(len(ln.split(None, 1)) == 2 for ln in lines)


def test_a_reader_that_closes_the_output_early_stops_nothing(tmp_path):
    """`trn-env ... | head -1`: with the pipe's reading end closed before the command writes a byte, the
    command finishes, writes its files and exits 0, with no traceback and no 'Exception ignored' (Python's
    own behaviour was a BrokenPipeError traceback from `plan`, and exit 120 with a message at shutdown)."""
    route = tmp_path / "route.toml"
    for args in (["scenarios"], ["plan", "basin_route", "--goal", "36.716", "-84.1325", "--out", str(route)]):
        child = subprocess.Popen([sys.executable, "-m", "trn_env.cli", *args], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, cwd=NEUTRAL_CWD)
        child.stdout.close()
        err = child.stderr.read().decode()
        assert child.wait(timeout=120) == 0, err
        assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err
    assert route.stat().st_size > 0 and route.with_suffix(".png").stat().st_size > 0


def test_validate_command(capsys, tmp_path):
    assert cli.main(["validate", "default"]) == 0
    assert "ok" in capsys.readouterr().out
    bad = tmp_path / "b.toml"
    bad.write_text('name = "x"\n[initial]\nlat_deg = 100\n')
    assert cli.main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "initial.lat_deg:" in err and "route: required key is missing" in err


def test_validate_takes_fly_overrides(capsys):
    """validate checks the scenario fly would build from the same options, every problem at once."""
    assert cli.main(["validate", "default", "--navigator", "pmf", "--seed", "7", "--duration", "30",
                     "--set", "navigator.settings.grid_size=65"]) == 0
    out = capsys.readouterr().out
    assert "navigator pmf, seed 7, time limit 30 s" in out
    assert cli.main(["validate", "default", "--navigator", "pmff", "--set", "terrain.world.dem=nodem",
                     "--set", "wind.layers.0.speed_mps=-3"]) == 2
    err = capsys.readouterr().err
    assert "3 problem(s)" in err and "navigator.name: unknown navigator 'pmff'" in err
    assert "wind.layers[0].speed_mps" in err
    assert "terrain.world.dem" in err and "neither a bundled terrain ('jacksboro'" in err and "basin" in err
    assert cli.main(["validate", "default", "--set", "x"]) == 2
    assert "--set 'x': expected PATH=VALUE" in capsys.readouterr().err


def test_bench_closed_loop_and_env_figures():
    from trn_env.bench import runner as bench
    cl = bench.closed_loop_benchmark(sim_s=3.0)
    assert cl["closed_loop_steps_per_s"] > 0 and cl["closed_loop_jsbsim_reference_steps_per_s"] > 0
    segments = cl["closed_loop_ratio_by_segment"]
    assert len(segments) == 3 and cl["closed_loop_ratio"] == pytest.approx(sorted(segments)[1], abs=1e-3)
    overall = cl["closed_loop_steps_per_s"] / cl["closed_loop_jsbsim_reference_steps_per_s"]
    assert min(segments) - 1e-3 <= overall <= max(segments) + 1e-3     # per-segment ratios of the same run
    assert cl["closed_loop_sim_seconds"] == pytest.approx(3.0)
    assert cl["closed_loop_pipelined"] is fork_available() and cl["closed_loop_ratio_inline"] > 0
    from trn_env.bench import env as env_bench
    env = env_bench.env_figures(n_steps=3, decision_interval_s=1.0)
    assert env["env_sim_seconds_measured"] == pytest.approx(3.0)
    assert env["env_sim_seconds_per_wall_second"] > 0


def test_bench_collects_components_and_survives_a_failing_one(monkeypatch, capsys):
    import types

    from trn_env.bench import runner as bench
    good = types.ModuleType("fake_good")
    good.benchmark = lambda quick=False: {"jsbsim_steps_per_s": 1.0, "quick_seen": quick}
    bad = types.ModuleType("fake_bad")

    def explode():
        raise RuntimeError("broken component")

    bad.benchmark = explode
    monkeypatch.setitem(sys.modules, "trn_env.bench.flight", good)
    monkeypatch.setitem(sys.modules, "trn_env.terrain.bench", bad)
    monkeypatch.setitem(sys.modules, "trn_env.bench.sensors", types.ModuleType("fake_none"))
    monkeypatch.setitem(sys.modules, "trn_env.bench.rbpf", good)   # its real flights cost ~20 s
    monkeypatch.setattr(bench, "closed_loop_benchmark", lambda quick: {"closed_loop_ratio": 0.25})
    env_mod = types.ModuleType("fake_env")
    env_mod.benchmark = lambda quick=False: {"env_sim_seconds_per_wall_second": 9.0}
    monkeypatch.setitem(sys.modules, "trn_env.bench.env", env_mod)
    monkeypatch.setitem(sys.modules, "trn_env.bench.fast_env", good)     # its real run costs ~1 min
    assert cli.main(["bench", "--quick", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["jsbsim_steps_per_s"] == 1.0 and out["quick_seen"] is True
    assert "broken component" in out["trn_env.terrain.bench.error"]
    assert out["trn_env.bench.sensors.error"] == "no benchmark() function"
    assert out["closed_loop_ratio"] == 0.25 and out["env_sim_seconds_per_wall_second"] == 9.0
    # without --json: the table, figure beside its reference and their ratio
    monkeypatch.setattr(bench, "run_all", lambda quick: {
        "flight_steps_per_s": 30000.0, "jsbsim_steps_per_s": 60000.0, "x.error": "broken component"})
    assert cli.main(["bench", "--quick"]) == 0
    text = capsys.readouterr().out
    row = next(line for line in text.splitlines() if "flight_steps_per_s" in line)
    assert "30,000" in row and "60,000" in row and "0.5" in row and "bare JSBSim" in row
    assert "broken component" in text


def test_bench_rows_pair_figures_with_references():
    from trn_env.bench.table import bench_rows
    rows = bench_rows({"closed_loop_steps_per_s": 20000.0,
                       "closed_loop_jsbsim_reference_steps_per_s": 50000.0,
                       "closed_loop_ratio": 0.41, "bilinear_lookups_per_s": 3.0e7,
                       "numpy_bilinear_lookups_per_s": 1.0e7, "sensor_time_fraction": 0.12,
                       "closed_loop_ratio_by_segment": [0.4, 0.41, 0.42], "x.error": "boom"})
    by = {r[0]: r for r in rows}
    assert by["closed_loop_steps_per_s"][4] == "0.41"          # the benchmark's own ratio (segment median)
    assert by["bilinear_lookups_per_s"][4] == "3"               # computed: figure / reference
    assert by["sensor_time_fraction"][1:] == ("0.12", "", "", "")
    assert "closed_loop_jsbsim_reference_steps_per_s" not in by and "closed_loop_ratio_by_segment" not in by
    assert by["x.error"][1] == "boom"
