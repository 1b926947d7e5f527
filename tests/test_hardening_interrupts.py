"""Interrupts and kills (issue 21 section 4), with real processes and signals.

Ctrl-C is sent as a terminal sends it: SIGINT to the whole process group (the command and its
estimation worker)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from trn_env.output import run_folder

SCEN = Path(__file__).parent / "scenarios"
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}   # run in tmp_path: the children import the installed trn_env

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX signals and fork")


# `trn-env ARGS` as a terminal user starts it: Ctrl-C raises KeyboardInterrupt. A test runner started in
# the background of a shell without job control (`pytest &` in a script) ignores SIGINT, and its children
# inherit the ignore, Python's included; the command is then started with Python's own handler restored.
_CLI_AT_A_TERMINAL = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
                      "from trn_env.cli import main; sys.exit(main(sys.argv[1:]))")


def _start(args, tmp_path):
    return subprocess.Popen([sys.executable, "-c", _CLI_AT_A_TERMINAL, *args], cwd=tmp_path, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def _ctrl_c(proc) -> tuple[int, str]:
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


def test_ctrl_c_during_start_up(tmp_path):
    """SIGINT while the command imports and loads the scenario: one line, exit 130, no traceback."""
    proc = _start(["fly", str(SCEN / "default_short.toml"), "--out", str(tmp_path / "run")], tmp_path)
    # wait for the start-up phase (terrain, then the kernels' compile or cache load) rather than a fixed
    # time: on a cold install a fixed delay can land before the interpreter has installed its handlers
    err_head = proc.stderr.readline()
    assert err_head.startswith("preparing"), err_head
    code, err = _ctrl_c(proc)
    err = err_head + err
    assert code == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert "interrupted" in err and len(err.strip().splitlines()) <= 4, err
    assert not (tmp_path / "run").exists()


def test_ctrl_c_mid_flight_no_worker_traceback(tmp_path):
    """SIGINT while the pipelined flight runs: exit 130, 'nothing written', and no BrokenPipeError from
    the estimation worker (it used to send on the closed pipe, and again from its error handler)."""
    # the point-mass filter's flight lasts ~5 s (ins_tercom's now ends within a second of 'ready after')
    proc = _start(["fly", "default", "--navigator", "pmf", "--out", str(tmp_path / "run")], tmp_path)
    err_head = ""
    t0 = time.time()
    while time.time() - t0 < 120:          # until the flight has started
        line = proc.stderr.readline()
        err_head += line
        if line.startswith("ready after") or not line:
            break
    time.sleep(0.5)
    code, err = _ctrl_c(proc)
    err = err_head + err
    assert code == 130, err
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert "nothing written" in err
    assert not (tmp_path / "run").exists()


_CLOSE_WHILE_BUSY = """
import sys, time
from trn_env.scenario.loading import load_scenario
from trn_env.sim.closed_loop import ClosedLoop
import dataclasses
sc = load_scenario(sys.argv[1], duration_s=30.0)
world = dataclasses.replace(sc.terrain.world, refinement=None)
sc = dataclasses.replace(sc, sections=dataclasses.replace(
    sc.sections, terrain=dataclasses.replace(sc.terrain, world=world)))
for _ in range(2):
    loop = ClosedLoop(sc, pipeline=True)
    assert loop.pipelined
    for _ in range(3):
        loop.tick()                 # the last interval's chunk is with the worker now
    loop.close()                    # as Ctrl-C does: the worker's reply meets a closed pipe
    time.sleep(0.3)
print("closed", flush=True)
"""


def test_worker_quiet_when_the_loop_closes_while_it_works(tmp_path):
    r = subprocess.run([sys.executable, "-c", _CLOSE_WHILE_BUSY, str(SCEN / "default_short.toml")], env=ENV,
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "closed" in r.stdout, r.stderr
    assert "Traceback" not in r.stderr and "BrokenPipeError" not in r.stderr, r.stderr


_ARRAYS = """
import numpy as np
n = 2
ARRAYS = {k: np.zeros(n) for k in ("t_s", "true_lat_rad", "true_lon_rad", "true_h_msl_m", "true_h_agl_m",
                                   "true_yaw_rad", "true_tas_mps", "est_lat_rad", "est_lon_rad", "est_h_m",
                                   "est_yaw_rad", "gnss_available", "nav_ok")}
ARRAYS["err_ned_m"] = np.zeros((n, 3))
ARRAYS["est_cov_diag"] = np.ones((n, 9))
"""
_KILL_WHILE_WRITING = _ARRAYS + """
import sys, time
from trn_env.output.run_folder import write_run
def plot(tmp):
    print("writing", flush=True)
    time.sleep(60)
    return []
write_run(sys.argv[1], {"a": 1}, ARRAYS, [], plot=plot)
"""


def test_kill_while_writing_leftover_cleaned_by_next_run(tmp_path):
    runs = tmp_path / "runs"
    proc = subprocess.Popen([sys.executable, "-c", _KILL_WHILE_WRITING, str(runs / "r1")], env=ENV,
                            cwd=tmp_path, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing"
    proc.kill()
    proc.wait(timeout=30)
    left = list(runs.glob(".r1.partial-*"))
    assert len(left) == 1 and not (runs / "r1").exists()         # what a kill leaves behind
    live = runs / f".r0.partial-{os.getpid()}-abcd"              # a run still writing: kept
    live.mkdir()
    old = runs / ".r2.partial-xyz"                                # older layout, no pid: removed once stale
    old.mkdir()
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    ns: dict = {}
    exec(_ARRAYS, ns)
    run_folder.write_run(runs / "r3", {"a": 1}, ns["ARRAYS"], [])    # the next run, any name
    assert (runs / "r3" / "summary.json").exists()
    assert not left[0].exists() and not old.exists() and live.exists()
    assert sorted(p.name for p in runs.iterdir()) == sorted([live.name, "r3"])


def test_ctrl_c_inside_a_numba_dispatcher_is_an_interrupt(monkeypatch, capsys):
    """Ctrl-C while numba unpickles a cached kernel reaches Python as a SystemError caused by the
    KeyboardInterrupt (seen on CI in test_ctrl_c_during_start_up): still exit 130 and one line."""
    import trn_env.cli as cli

    def interrupted_in_numba(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher(<function bicubic_batch>) returned a result with an exception "
                              "set") from exc

    monkeypatch.setattr(cli, "cmd_scenarios", lambda: interrupted_in_numba(None))
    assert cli.main(["scenarios"]) == 130
    assert capsys.readouterr().err.strip() == "interrupted: nothing written"

    def other_system_error():
        raise SystemError("a real bug")

    monkeypatch.setattr(cli, "cmd_scenarios", other_system_error)
    with pytest.raises(SystemError, match="a real bug"):
        cli.main(["scenarios"])


def test_a_run_written_meanwhile_is_never_replaced(tmp_path):
    """Two runs finishing into one folder (two `trn-env fly` started in the same second share
    default_out_dir's name): the other run lands while this one is being written (its plot step here).
    Without overwrite this run refuses and leaves the other whole; with `unique` it takes NAME-2 (then
    NAME-3); with overwrite it replaces it, as asked. The old commit replaced the other run in every case."""
    ns: dict = {}
    exec(_ARRAYS, ns)
    arrays = ns["ARRAYS"]
    out = tmp_path / "runs" / "default-20261206T120000Z"

    def other_run_lands(tmp):
        if not out.exists():
            run_folder.write_run(out, {"who": "other"}, arrays, [])
        return []

    def who(folder):
        return json.loads((folder / "summary.json").read_text())["who"]

    with pytest.raises(FileExistsError, match="another run was written there"):
        run_folder.write_run(out, {"who": "this"}, arrays, [], plot=other_run_lands)
    assert who(out) == "other"
    second, third = out.with_name(out.name + "-2"), out.with_name(out.name + "-3")
    assert run_folder.write_run(out, {"who": "this"}, arrays, [], plot=other_run_lands, unique=True) == second
    assert run_folder.write_run(out, {"who": "third"}, arrays, [], unique=True) == third
    assert [who(out), who(second), who(third)] == ["other", "this", "third"]
    assert run_folder.write_run(out, {"who": "this"}, arrays, [], overwrite=True) == out
    assert who(out) == "this"
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".")] == []
