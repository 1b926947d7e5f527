"""The paper-reproduction scripts run end to end (short settings) and produce their tables and plots."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest
from _child_processes import NEUTRAL_CWD

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "gallery"


def _load(name: str):
    path = SCRIPTS / f"{name}.py"
    if not path.is_file():
        path = EXAMPLES / f"{name}.py"
    if not path.is_file():
        pytest.skip(f"{path} is not in this checkout")
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_reproduce_seed000_short_run_writes_table4_for_both_formulas(tmp_path, capsys):
    mod = _load("reproduce_seed000")
    mod.main(["--runs", "2", "--duration", "100", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert "Table 4" in out and "Position Error" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    table = summary["table4"]
    assert set(table) == {"conventional", "proposed"}
    for formula in table.values():
        assert set(formula) == {"1", "2", "3", "4"}
        for case in formula.values():
            assert case["n_fixes"] >= 2
            # TRN keeps the 30 m (1 sigma) initial error bounded at 5.6 km with a navigation-grade IMU
            assert 0.0 < case["pos_rms_m"] < 40.0
    # the crosswind makes the two formulas disagree about the closest points (seed 000 Figure 16)
    assert summary["geometry"]["dp_m_median"] > 3.0
    assert any(p.suffix == ".png" for p in tmp_path.iterdir())


def test_gnss_denied_demo_ins_drifts_and_trn_stays_bounded(tmp_path):
    mod = _load("gnss_denied_demo")
    mod.main(["--minutes", "8", "--out", str(tmp_path)])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (tmp_path / "gnss_denied.png").is_file()
    ins, trn = summary["ins"], summary["ins_tercom"]
    # a tactical-grade INS alone drifts in 8 min without GNSS; INS + TRN stays bounded on the same flight
    assert ins["horizontal_error_final_m"] > 500.0
    assert trn["horizontal_error_final_m"] < 0.2 * ins["horizontal_error_final_m"]



def test_gallery_fly_route_completes_its_route_on_the_legs(capsys):
    """The gallery's flight-core example (shown as code, not run by the docs build) flies its route in wind
    and light turbulence: completed, on the legs but for the turns."""
    import re

    mod = _load("fly_route")
    mod.main(["--turbulence", "light", "--seed", "2"])
    out = capsys.readouterr().out
    assert "completed in" in out and "NOT completed" not in out, out
    assert float(re.search(r"median ([\d.]+) m", out).group(1)) < 5.0, out


# Scripts that say "RLlib is not installed" (exit 2) before anything else when the rllib extra is missing.
_NEED_RLLIB = ("route_task", "train_rllib")

# Each script that writes --out, with what else its parser requires.
_OUT_SCRIPTS = {
    "calibrate_fast_tier": [], "env_rates_check": [], "fast_tier_speed_trade": [], "filter_statistics": [],
    "flight_step_check": ["routes"], "grade_consistency": [], "ira_model_comparison": [],
    "log_memory": ["--hours", "0.01"], "protection_level_campaign": [], "reproduce_seed000": [],
    "reproduce_seed001": [], "reproduce_seed002": [], "route_action_search": [],
    "route_task_trace": ["--policy", "straight", "--goal", "0", "--tier", "fast"],
    "route_task": ["train"], "train_rllib": [], "route_policy_benchmark": [],
}

_RUN_WITH_ARGV = """
import contextlib, io, json, runpy, sys
results = {}
scripts, commands = json.loads(sys.stdin.read())
for name, argv in commands.items():
    sys.argv = [name + ".py"] + argv
    err = io.StringIO()
    code = None
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            runpy.run_path(f"{scripts}/{name}.py", run_name="__main__")
        except SystemExit as exc:
            code = exc.code
    results[name] = [code, err.getvalue().strip().splitlines()[-1:] or [""]]
print(json.dumps(results))
"""


def test_scripts_refuse_an_unwritable_out_before_their_work(tmp_path):
    """A script whose --out cannot be written stops at once with exit code 2 and a line naming --out,
    instead of failing after its flights (one child process runs them all)."""
    import subprocess
    import sys
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    bad = str(blocker / "out")               # under a file: no folder or file can be made there
    import importlib.util
    rllib = importlib.util.find_spec("ray") is not None and importlib.util.find_spec("ray.rllib") is not None
    payload = {name: argv + ["--out", bad] for name, argv in _OUT_SCRIPTS.items()
               if (SCRIPTS / f"{name}.py").is_file() and (rllib or name not in _NEED_RLLIB)}
    child = subprocess.run([sys.executable, "-c", _RUN_WITH_ARGV], input=json.dumps([str(SCRIPTS), payload]),
                           text=True, capture_output=True, timeout=300, cwd=NEUTRAL_CWD)  # _child_processes
    assert child.returncode == 0, child.stderr[-2000:]
    results = json.loads(child.stdout.strip().splitlines()[-1])
    wrong = {name: r for name, r in results.items() if r[0] != 2 or "--out" not in r[1][0]}
    assert not wrong, wrong
    assert len(results) == len(payload) >= 15 - (0 if rllib else len(_NEED_RLLIB))


@pytest.mark.parametrize("option, value", [("--shift-share", "0"), ("--shift-share", "nan"),
                                           ("--shift-share", "inf"), ("--shift-share", "north"),
                                           ("--grade", "military")])
def test_axis_consistency_refuses_bad_options(option, value, capsys):
    mod = _load("axis_consistency")
    with pytest.raises(SystemExit) as exc:
        mod.parse([option, value])
    assert exc.value.code == 2 and option in capsys.readouterr().err
    assert mod.parse(["--grade", "tactical"]).grade == "tactical"


@pytest.mark.parametrize("argv, option", [
    (["--denied", "-1"], "--denied"), (["--faulted", "-2"], "--faulted"),
    (["--navigator", "acq_track"], "--navigator"), (["--json", "."], "--json"),
    (["--json", "out.txt"], "--json")])
def test_integrity_closed_loop_refuses_bad_options_before_flying(argv, option, capsys):
    mod = _load("integrity_closed_loop")
    with pytest.raises(SystemExit) as exc:
        mod.main(["--fault-free", "0", "--denied", "0", "--faulted", "0"] + argv)
    assert exc.value.code == 2 and option in capsys.readouterr().err
