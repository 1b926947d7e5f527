"""Campaigns: the project's regression gate (tests/campaigns/ci_small.toml, real short flights on the local
pool), replay of a run alone, --resume, rows, report, Ray giving the same per-run results, bad input."""

from __future__ import annotations

import base64
import json
import re
import shlex
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _child_processes import init_local_ray

from trn_env import cli
from trn_env.campaign import load_campaign
from trn_env.campaign.rows import read_rows
from trn_env.output.metrics import METRIC_KEYS

HERE = Path(__file__).resolve().parent
CI = HERE / "campaigns" / "ci_small.toml"
BASELINE = HERE / "campaigns" / "ci_small_baseline.json"


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """ci_small flown once on the local pool (2 workers): its folder."""
    out = tmp_path_factory.mktemp("ci") / "ci_small"
    assert cli.main(["campaign", str(CI), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    return out


def test_rows_one_per_run_with_seeds_shared_across_navigators(flown):
    df = read_rows(flown)
    assert len(df) == 4 and sorted(df["run_id"]) == ["v000-s0000", "v000-s0001", "v001-s0000", "v001-s0001"]
    assert (df["termination"] == "time_limit").all() and df["error"].isna().all()
    assert set(df["navigator"]) == {"ins", "ins_tercom"}
    # seeds from the root seed through SeedSequence, computed here independently
    expect = [int(c.generate_state(1, np.uint64)[0] >> np.uint64(1))
              for c in np.random.SeedSequence(16).spawn(2)]
    for si in (0, 1):
        assert set(df.loc[df["seed_index"] == si, "seed"]) == {expect[si]}
    for k in METRIC_KEYS + ("scenario_hash", "jsbsim_version", "trn_env_version", "wall_time_s"):
        assert k in df
    assert df["sim_time_s"].between(44.0, 46.0).all()
    # one Parquet file per run, no temporary files left
    names = sorted(p.name for p in (flown / "runs").iterdir())
    assert names == [f"{r}.parquet" for r in sorted(df["run_id"])]
    # the TERCOM fix at 40 s pulls the final error below the INS's (both runs of each seed fly the same
    # turbulence and sensor noise: the comparison is paired)
    for si in (0, 1):
        s = df[df["seed_index"] == si].set_index("navigator")
        final = s["horizontal_error_final_m"]
        assert final["ins_tercom"] < 0.6 * final["ins"]


def test_regression_gate_passes_against_the_committed_baseline(flown, capsys):
    # every run is there already: --resume flies nothing and checks the rows flown by this test session
    assert cli.main(["campaign", str(CI), "--out", str(flown), "--resume", "--quiet",
                     "--check", str(BASELINE)]) == 0
    assert "regression gate passed" in capsys.readouterr().out


def _edited_baseline(tmp_path, factor):
    data = json.loads(BASELINE.read_text())
    data["groups"]["ins_tercom | -"]["horizontal_error_rms_m.p50"]["value"] *= factor
    p = tmp_path / "baseline.json"
    p.write_text(json.dumps(data))
    return p


def test_regression_gate_fails_on_a_worse_figure_and_warns_on_a_much_better_one(flown, tmp_path, capsys):
    # baseline halved: today's figure is twice it, beyond the 20 % + 2 m band -> exit 1
    worse = _edited_baseline(tmp_path, 0.5)
    assert cli.main(["campaign", str(CI), "--out", str(flown), "--resume", "--quiet",
                     "--check", str(worse)]) == 1
    err = capsys.readouterr().err
    assert "regression: ins_tercom | - horizontal_error_rms_m.p50" in err
    # baseline doubled: today's figure is much better -> a warning, exit 0
    better = _edited_baseline(tmp_path, 2.0)
    assert cli.main(["campaign", str(CI), "--out", str(flown), "--resume", "--quiet",
                     "--check", str(better)]) == 0
    err = capsys.readouterr().err
    assert "warning: ins_tercom | - horizontal_error_rms_m.p50 is much better" in err
    assert "regression:" not in err
    # a group the campaign no longer flies: missing, said in words (not "nan vs baseline ... (band ±nan)")
    data = json.loads(BASELINE.read_text())
    data["groups"]["pmf | -"] = {"errors": {"value": 0, "better": "lower", "rel_tol": 0.0, "abs_tol": 0.0}}
    gone = tmp_path / "gone.json"
    gone.write_text(json.dumps(data))
    assert cli.main(["campaign", str(CI), "--out", str(flown), "--resume", "--quiet",
                     "--check", str(gone)]) == 1
    err = capsys.readouterr().err
    assert "regression: pmf | - errors: missing from this campaign (baseline 0)" in err and "nan" not in err


def test_a_run_replays_alone_bit_for_bit_with_trn_env_fly(flown, tmp_path):
    df = read_rows(flown)
    row = df[df["run_id"] == "v001-s0001"].iloc[0]
    argv = shlex.split(row["replay_command"])
    assert argv[:2] == ["trn-env", "fly"] and "--set" in argv     # the navigator settings go by --set
    out = tmp_path / "replay"
    assert cli.main(argv[1:] + ["--out", str(out), "--no-plots", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for k in METRIC_KEYS:      # summary.json carries the same metrics, equal to the last bit
        v = summary[k]
        assert (v is None and not np.isfinite(row[k])) or v == row[k], k
    log = np.load(out / "log.npz")
    err = log["err_ned_m"]
    assert np.array_equal(log["t_s"], row["series_t_s"])
    assert np.array_equal(np.hypot(err[:, 0], err[:, 1]), row["series_err_h_m"])
    assert np.array_equal(-err[:, 2], row["series_err_v_m"])


def test_resume_flies_only_the_missing_run(flown, tmp_path):
    folder = tmp_path / "copy"
    shutil.copytree(flown, folder)
    before = read_rows(folder)
    (folder / "runs" / "v000-s0001.parquet").unlink()
    kept = {p.name: p.stat().st_mtime_ns for p in (folder / "runs").iterdir()}
    assert cli.main(["campaign", str(CI), "--out", str(folder), "--resume", "--quiet", "--workers", "1"]) == 0
    for name, mtime in kept.items():
        assert (folder / "runs" / name).stat().st_mtime_ns == mtime      # untouched
    after = read_rows(folder)
    r0 = before[before["run_id"] == "v000-s0001"].iloc[0]
    r1 = after[after["run_id"] == "v000-s0001"].iloc[0]
    for k in ("horizontal_error_rms_m", "anees", "horizontal_error_final_m", "scenario_hash"):
        assert r1[k] == r0[k]               # the same run, another process: the same bits
    assert np.array_equal(r1["series_err_h_m"], r0["series_err_h_m"])


def test_resume_refuses_a_folder_of_another_campaign(flown, tmp_path, capsys):
    other = tmp_path / "other.toml"
    other.write_text(CI.read_text().replace("root_seed = 16", "root_seed = 17")
                     .replace('"ci_denied_short.toml"', f'"{HERE}/campaigns/ci_denied_short.toml"'))
    listing = sorted(p.name for p in (flown / "runs").iterdir())
    assert cli.main(["campaign", str(other), "--out", str(flown), "--resume", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "different campaign file" in err and "Traceback" not in err
    assert sorted(p.name for p in (flown / "runs").iterdir()) == listing
    # and without --resume an existing campaign folder is refused too
    assert cli.main(["campaign", str(CI), "--out", str(flown), "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err


def test_a_folder_another_campaign_is_writing_is_refused(flown, tmp_path, capsys):
    """Two campaigns into one folder at once (the same file resumed twice, or another file given the same
    --out) would fly the same runs twice or mix two campaigns' rows under one manifest: while another
    process holds the folder, a campaign is refused (exit 2, nothing written); once it lets go, the same
    command resumes. A folder the refused campaign made is not left behind."""
    folder = tmp_path / "copy"
    shutil.copytree(flown, folder)
    (folder / "runs" / "v000-s0001.parquet").unlink()
    listing = sorted(p.name for p in (folder / "runs").iterdir())
    fresh = tmp_path / "fresh"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys\n"
         "fds = [os.open(p, os.O_RDONLY) for p in sys.argv[1:]]\n"
         "[fcntl.flock(fd, fcntl.LOCK_EX) for fd in fds]\nprint('held', flush=True)\nsys.stdin.read()\n",
         str(folder), str(tmp_path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        argv = ["campaign", str(CI), "--out", str(folder), "--resume", "--quiet", "--workers", "1"]
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert err.strip() == (f"error: --out {folder}: another campaign is writing into this folder now (it "
                               "holds the folder's lock); wait for it to end (then --resume flies what it "
                               "left), or choose another folder"), err
        assert sorted(p.name for p in (folder / "runs").iterdir()) == listing
        # a lock on another folder (here the parent) holds nothing of a new folder below it
        from trn_env.campaign.driver import folder_lock
        with folder_lock(load_campaign(CI), fresh):
            assert fresh.is_dir()
        assert not fresh.exists()          # made for the campaign, left empty: removed
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
    assert cli.main(["campaign", str(CI), "--out", str(folder), "--resume", "--quiet", "--workers", "1"]) == 0
    assert sorted(p.name for p in (folder / "runs").iterdir()) == sorted(listing + ["v000-s0001.parquet"])


def test_a_report_of_part_of_a_campaign_says_so_and_why(flown, tmp_path, capsys):
    """A report made while the campaign still flew, or of one interrupted, covered part of its runs with
    only 'report written' on the command line."""
    folder = tmp_path / "copy"
    shutil.copytree(flown, folder)
    assert cli.main(["report", str(folder)]) == 0
    assert "note:" not in capsys.readouterr().err                     # all its runs: nothing to say
    (folder / "runs" / "v000-s0001.parquet").unlink()
    n_runs = json.loads((folder / "campaign.json").read_text())["n_runs"]
    source = json.loads((folder / "campaign.json").read_text())["source"]
    assert cli.main(["report", str(folder)]) == 0
    assert capsys.readouterr().err.strip() == (
        f"note: the report covers {n_runs - 1} of the campaign's {n_runs} runs; the campaign did not finish: "
        f"continue it with trn-env campaign {source} --out {folder} --resume")
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys\nfd = os.open(sys.argv[1], os.O_RDONLY)\n"
         "fcntl.flock(fd, fcntl.LOCK_EX)\nprint('held', flush=True)\nsys.stdin.read()\n", str(folder)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert cli.main(["report", str(folder)]) == 0
        assert capsys.readouterr().err.strip().endswith(
            "runs; the campaign is still flying into this folder: report it again when it ends")
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)


def test_report_pngs_and_self_contained_html(flown, tmp_path):
    assert cli.main(["report", str(flown), "--out", str(tmp_path / "rep")]) == 0
    rep = tmp_path / "rep"
    pngs = sorted(p.name for p in rep.glob("*.png"))
    assert pngs == ["cdf_horizontal_error.png", "envelope_horizontal_error.png", "stanford.png"]
    page = (rep / "report.html").read_text()
    blobs = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)
    assert len(blobs) == 3
    for b, name in zip(blobs, pngs, strict=True):
        assert base64.b64decode(b) == (rep / name).read_bytes()
    assert "ins_tercom | -" in page and "<img" in page and "src='http" not in page
    stats = json.loads((rep / "summary.json").read_text())
    assert stats["ins | -"]["runs"] == 2
    assert stats["ins | -"]["pl_epochs.sum"] > 0         # protection-level epochs pooled over the runs


# ------------------------------------------------------------------------------------------- Ray

@pytest.fixture(scope="module")
def ray_session():
    ray = pytest.importorskip("ray", reason="the ray extra is installed in CI (pip install -e .[ray])")
    # address="local": a new instance even when a cluster (`ray start`) runs on this machine
    init_local_ray()
    yield ray
    ray.shutdown()


def test_ray_workers_import_the_trn_env_the_tests_import(ray_session):
    """Ray puts the driver's working folder first on its workers' path: started from a checkout's root, the
    workers would import its source tree instead of the installed package CI tests (and compile every
    kernel again into the source tree's empty numba cache). init_local_ray starts Ray from tests/."""
    import trn_env

    @ray_session.remote
    def where() -> str:
        import trn_env as worker_trn_env
        return worker_trn_env.__file__

    assert ray_session.get(where.remote(), timeout=120) == trn_env.__file__


def test_ray_backend_gives_the_same_runs_as_the_local_pool(flown, ray_session, tmp_path):
    """ci_small's INS runs again, as Ray tasks on a 2-CPU local instance: rows equal to the local pool's."""
    from trn_env.campaign import run_campaign
    from trn_env.campaign.ray_backend import RayBackend
    sub = tmp_path / "ins_only.toml"
    sub.write_text(CI.read_text().replace('navigators = ["ins", { name = "ins_tercom", settings = '
                                          '{ remove_bias = true } }]', 'navigators = ["ins"]')
                   .replace('"ci_denied_short.toml"', f'"{HERE}/campaigns/ci_denied_short.toml"'))
    camp = load_campaign(sub)
    assert camp.n_runs == 2
    stats = run_campaign(camp, tmp_path / "ray", backend=RayBackend(), progress=False)
    assert stats["flown"] == 2 and stats["failed"] == 0 and stats["backend"].startswith("Ray")
    ray_rows = read_rows(tmp_path / "ray").set_index("seed")
    local = read_rows(flown)
    local = local[local["navigator"] == "ins"].set_index("seed")
    assert sorted(ray_rows.index) == sorted(local.index)
    for seed in local.index:
        a, b = ray_rows.loc[seed], local.loc[seed]
        assert a["scenario_hash"] == b["scenario_hash"]
        for k in METRIC_KEYS:
            assert (a[k] == b[k]) or (not np.isfinite(a[k]) and not np.isfinite(b[k])), k
        assert np.array_equal(a["series_err_h_m"], b["series_err_h_m"])


def test_ray_missing_gives_the_install_command(monkeypatch, tmp_path, capsys):
    import builtins
    real_import = builtins.__import__

    def no_ray(name, *args, **kwargs):
        if name == "ray" or name.startswith("ray."):
            raise ImportError("No module named 'ray'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    out = tmp_path / "out"
    assert cli.main(["campaign", str(CI), "--backend", "ray", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert 'pip install "trn-env[ray]"' in err and "Traceback" not in err
    assert not out.exists()


def test_unreachable_ray_address_fails_within_seconds(tmp_path, capsys):
    pytest.importorskip("ray", reason="the ray extra is installed in CI (pip install -e .[ray])")
    with socket.socket() as s:          # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "out"
    t0 = time.monotonic()
    rc = cli.main(["campaign", str(CI), "--backend", "ray", "--address", f"127.0.0.1:{port}",
                   "--out", str(out), "--quiet"])
    assert rc == 2 and time.monotonic() - t0 < 10.0     # refused before validation; the probe is 3 s at most
    err = capsys.readouterr().err
    assert f"no Ray cluster reachable at 127.0.0.1:{port}" in err
    assert not out.exists()


# ------------------------------------------------------------------------------------------ bad input

def _campaign(tmp_path, body: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(f'scenarios = ["{HERE}/scenarios/ins_only_short.toml"]\nduration_s = 5.0\n' + body)
    return p


@pytest.mark.parametrize(("body", "expect"), [
    ('seeds = 2\n[[sweeps]]\npath = "wind.layerz.0.speed_mps"\nvalues = [1.0]\n',
     "sweeps[0].values[0] (wind.layerz.0.speed_mps = 1.0): wind.layerz: unknown key"),
    ('seeds = 2\n[[sweeps]]\npath = "wind.layers.5.speed_mps"\nvalues = [1.0]\n',
     "sweeps[0].values[0] (wind.layers.5.speed_mps = 1.0): wind.layers.5.speed_mps: index 5 is out of range"),
    ('seeds = 2\n[[sweeps]]\npath = "wind.layers.0.speed_mps"\nvalues = [3.0, "fast"]\n',
     "sweeps[0].values[1] (wind.layers.0.speed_mps = 'fast'): wind.layers[0].speed_mps: 'fast' is not of "
     "type"),
    ('seeds = 0\n', "seeds: 0 seeds: give at least one seed"),
    ('seeds = []\n', "seeds: [] is neither"),
    # seeds are int64 in the rows and TOML integers are 64-bit
    ('seeds = [0, 9223372036854775808]\n', "list of distinct seeds from 0 to 9223372036854775807 (64-bit)"),
    ('seeds = 1\nroot_seed = 9223372036854775808\n',
     "root_seed: 9223372036854775808 is greater than the maximum of 9223372036854775807"),
    ('seeds = 1\nnavigators = ["no_such_nav"]\n',
     "navigators[0] (no_such_nav): navigator.name: unknown navigator"),
    ('seeds = 1\n[[sweeps]]\npath = "navigator.settings.no_such_setting"\nvalues = [1.0]\n',
     "sweeps[0].values[0] (navigator.settings.no_such_setting = 1.0): navigator.settings"),
    ('seeds = 1\nsweep = []\n', "sweep: unknown key"),
    ('seeds = 1\n[[sweeps]]\npath = "x"\nvalues = [1]\ngrid = { start = 0, stop = 1, num = 2 }\n',
     "sweeps[0]: give exactly one of values or grid"),
    # a repeated point or scenario would fly the same runs twice and pool them twice
    ('seeds = 1\n[[sweeps]]\npath = "wind.layers.0.speed_mps"\nvalues = [5, 3.0, 5.0]\n',
     "sweeps[0].values: 5.0 (point 2) repeats point 0"),
    ('seeds = 1\nnavigators = ["ins"]\n[[sweeps]]\npath = "navigator.settings.accel_bias_mps2"\n'
     'grid = { start = 0.001, stop = 0.001, num = 2 }\n', "sweeps[0].grid: 0.001 (point 1) repeats point 0"),
])
def test_bad_campaign_files_exit_2_naming_the_field(tmp_path, capsys, body, expect):
    out = tmp_path / "out"
    assert cli.main(["campaign", str(_campaign(tmp_path, body)), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert expect in err, err
    assert "Traceback" not in err and not out.exists()


def test_a_problem_shared_by_sweep_points_is_said_once(tmp_path, capsys):
    """A sweep over a key the scenario does not have fails at every point; a range partly out of bounds
    fails at several, each message naming its own value. Each is one line listing the points (it was a
    line per point: a 1,000-point grid buried every other problem under 1,000 lines)."""
    body = ('seeds = 1\n'
            '[[sweeps]]\npath = "sensors.radar_altimeter.noise_std_m"\n'
            'grid = { start = 0.5, stop = 5.0, num = 10 }\n'
            '[[sweeps]]\npath = "sensors.radar_altimeter.noise_const_m"\n'
            'values = [-1.0, 0.5, -2.0, 3.0, -4.0, -5.0, -6.0, -7.0, -8.0]\n'
            '[[sweeps]]\npath = "wind.layers.0.speed_mps"\nvalues = [1.0, 1e9]\n')
    out = tmp_path / "out"
    assert cli.main(["campaign", str(_campaign(tmp_path, body)), "--out", str(out), "--quiet"]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("  - ")]
    assert lines == [
        "  - sweeps[0] (sensors.radar_altimeter.noise_std_m, all 10 points): sensors.radar_altimeter."
        "noise_std_m: unknown key (allowed here: beamwidth_deg, lever_arm_b_m, max_range_m, noise_const_m, "
        "noise_fraction, noise_free, rate_hz)",
        "  - sweeps[1].values[0, 2, 4, 5, 6, ...] (sensors.radar_altimeter.noise_const_m = -1.0, -2.0, -4.0, "
        "-5.0, -6.0, ...; 7 points): sensors.radar_altimeter.noise_const_m: -1.0 is less than the minimum of "
        "0.0",
        "  - sweeps[2].values[1] (wind.layers.0.speed_mps = 1000000000.0): wind.layers[0].speed_mps: "
        "1000000000.0 is greater than the maximum of 100"], lines


def test_a_scenario_listed_twice_is_refused(tmp_path, capsys):
    """The same file by a relative and an absolute path: its runs would be flown and pooled twice."""
    shutil.copy(HERE / "scenarios" / "ins_only_short.toml", tmp_path / "s.toml")
    p = tmp_path / "c.toml"
    absolute = (tmp_path / "s.toml").as_posix()
    p.write_text(f'seeds = 1\nduration_s = 5.0\nscenarios = ["s.toml", "{absolute}"]\n')
    assert cli.main(["campaign", str(p), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert f"scenarios[1] ({absolute}): the same scenario as scenarios[0]" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_sweeps_expand_by_dotted_path_as_a_grid(tmp_path):
    p = _campaign(tmp_path, 'seeds = [3, 4]\nnavigators = ["ins"]\n'
                            '[[sweeps]]\npath = "wind.layers.0.speed_mps"\nvalues = [2.0, 6.0]\n'
                            '[[sweeps]]\npath = "navigator.settings.accel_bias_mps2"\n'
                            'grid = { start = 0.001, stop = 0.003, num = 3 }\n')
    c = load_campaign(p)
    assert c.seeds == [3, 4] and len(c.variants) == 6 and c.n_runs == 12
    got = {(v.sections.wind.layers[0].speed_mps, v.sections.navigator.settings.accel_bias_mps2)
           for v in c.variants}
    assert got == {(s, b) for s in (2.0, 6.0) for b in (0.001, 0.002, 0.003)}
    # the other wind layer and the file's other settings are untouched
    assert all(v.sections.wind.layers[1].speed_mps == 9.0 for v in c.variants)
    assert all(v.sections.navigator.table["gyro_bias_rps"] == pytest.approx(4.84813681109536e-06)
               for v in c.variants)


def _dies(task, dems=None):
    """fly_run, except that the worker process dies flying seed 0 on its first attempt, and seed 1 always."""
    import os

    from trn_env.campaign.runs import fly_run
    if task.seed_index == 0 and task.attempt == 1:
        os._exit(3)
    if task.seed_index == 1:
        os._exit(3)
    return fly_run(task, dems)


def test_local_pool_retries_a_dead_worker_and_records_a_run_that_always_kills_it(tmp_path, monkeypatch):
    import trn_env.campaign.local as local
    from trn_env.campaign import run_campaign
    monkeypatch.setattr(local, "fly_run", _dies)
    camp = load_campaign(_campaign(tmp_path, "seeds = 3\n"))
    stats = run_campaign(camp, tmp_path / "out", backend=local.LocalBackend(2, max_attempts=2),
                         progress=False)
    assert stats["flown"] == 3
    df = read_rows(tmp_path / "out").set_index("seed_index")
    assert df.loc[0, "termination"] == "time_limit" and df.loc[0, "attempts"] >= 2    # retried, then flown
    assert df.loc[1, "termination"] == "error" and "worker process died" in df.loc[1, "error"]
    assert df.loc[2, "termination"] == "time_limit"


def test_keep_logs_writes_each_runs_full_log_beside_its_row(tmp_path):
    from trn_env.campaign import run_campaign
    from trn_env.campaign.local import LocalBackend
    camp = load_campaign(_campaign(tmp_path, "seeds = 1\nkeep_logs = true\n"))
    assert run_campaign(camp, tmp_path / "out", backend=LocalBackend(1), progress=False)["flown"] == 1
    row = read_rows(tmp_path / "out").iloc[0]
    log = np.load(tmp_path / "out" / "logs" / f"{row['run_id']}.npz")
    assert "sensor_imu_t_s" in log and np.array_equal(log["t_s"], row["series_t_s"])
    err = log["err_ned_m"]
    assert np.array_equal(np.hypot(err[:, 0], err[:, 1]), row["series_err_h_m"])


def test_a_swept_campaign_has_sweep_columns_and_a_metric_versus_sweep_plot(tmp_path):
    from trn_env.campaign import run_campaign
    from trn_env.campaign.local import LocalBackend
    from trn_env.campaign.report import write_report
    camp = load_campaign(_campaign(tmp_path, 'seeds = 1\n[[sweeps]]\npath = "wind.layers.0.speed_mps"\n'
                                             'values = [0.0, 15.0]\n'))
    run_campaign(camp, tmp_path / "out", backend=LocalBackend(2), progress=False)
    df = read_rows(tmp_path / "out")
    assert sorted(df["sweep.wind.layers.0.speed_mps"]) == [0.0, 15.0]
    assert [json.loads(s) for s in df.sort_values("sweep.wind.layers.0.speed_mps")["sweep_json"]] == \
        [{"wind.layers.0.speed_mps": 0.0}, {"wind.layers.0.speed_mps": 15.0}]
    rep = write_report(tmp_path / "out")
    assert (rep / "sweep_wind_layers_0_speed_mps.png").stat().st_size > 10_000
    assert (rep / "report.html").read_text().count("data:image/png;base64,") == 4   # + Stanford diagrams


def test_report_and_check_refuse_bad_folders_and_baselines(tmp_path, capsys):
    assert cli.main(["report", str(tmp_path)]) == 2
    assert "not a campaign folder" in capsys.readouterr().err
    assert cli.main(["report", str(tmp_path / "nowhere")]) == 2
    assert "no such folder" in capsys.readouterr().err
    out = tmp_path / "out"
    assert cli.main(["campaign", str(CI), "--out", str(out), "--check", str(tmp_path / "none.json")]) == 2
    assert "no such baseline file" in capsys.readouterr().err and not out.exists()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"groups": {"ins | -": {"anees.p50": {"value": 3.0, "rel_tol": -1}}}}))
    assert cli.main(["campaign", str(CI), "--out", str(out), "--check", str(bad)]) == 2
    assert "groups.ins | -.anees.p50.rel_tol: must be a finite number >= 0" in capsys.readouterr().err
    assert not out.exists()


def test_report_never_replaces_a_folder_that_is_not_a_report(flown, tmp_path, capsys):
    """`report --out` replaces an earlier report whole, and refuses (exit 2, the folder untouched) a folder
    holding anything else, a file, or a place where no folder can be made: it used to delete any --out."""
    keep = tmp_path / "mine"
    keep.mkdir()
    (keep / "notes.txt").write_text("mine")
    afile = tmp_path / "a.txt"
    afile.write_text("a file")
    for out, msg in ((keep, "holds no previous report (no report.html)"), (afile, "is not a directory"),
                     (afile / "rep", "is not a directory")):
        assert cli.main(["report", str(flown), "--out", str(out)]) == 2
        assert msg in capsys.readouterr().err
    assert (keep / "notes.txt").read_text() == "mine" and afile.read_text() == "a file"
    assert sorted(p.name for p in keep.iterdir()) == ["notes.txt"]
    rep = tmp_path / "rep"
    assert cli.main(["report", str(flown), "--out", str(rep)]) == 0
    (rep / "stale.png").write_bytes(b"from an earlier report")
    assert cli.main(["report", str(flown), "--out", str(rep)]) == 0
    assert not (rep / "stale.png").exists() and (rep / "report.html").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_write_baseline_target_is_checked_before_the_campaign_flies(tmp_path, capsys):
    out = tmp_path / "out"
    afile = tmp_path / "a.txt"
    afile.write_text("a file")
    for target, msg in ((tmp_path, "is a folder; give a file name"),
                        (afile / "b.json", "is not a directory")):
        assert cli.main(["campaign", str(CI), "--out", str(out), "--write-baseline", str(target)]) == 2
        assert f"--write-baseline {target}: " in (err := capsys.readouterr().err) and msg in err
        assert not out.exists()
    assert cli.main(["campaign", str(CI), "--out", str(afile / "camp")]) == 2
    assert "is not a directory" in capsys.readouterr().err


def test_campaigns_without_out_each_get_a_folder_of_their_own(tmp_path, monkeypatch, capsys):
    """Without --out a campaign writes campaigns/<name>-<UTC second>; one started in the same second gets
    NAME-2 (the folder is made exclusively before the first run) instead of sharing the first one's."""
    from trn_env.campaign import driver

    tiny = tmp_path / "tiny.toml"
    tiny.write_text(f'name = "tiny"\nroot_seed = 1\nseeds = 1\nduration_s = 5.0\nnavigators = ["ins"]\n'
                    f'scenarios = ["{(CI.parent / "ci_denied_short.toml").as_posix()}"]\n')
    monkeypatch.chdir(tmp_path)
    fixed = Path("campaigns") / "tiny-20261206T120000Z"
    monkeypatch.setattr(driver, "default_out_dir", lambda name: fixed)
    for _ in range(2):
        assert cli.main(["campaign", str(tiny), "--workers", "1", "--quiet"]) == 0
    first = tmp_path / fixed
    second = first.with_name(first.name + "-2")
    assert len(read_rows(first)) == len(read_rows(second)) == 1
    assert sorted(p.name for p in (tmp_path / "campaigns").iterdir()) == [first.name, second.name]
    capsys.readouterr()
    assert cli.main(["campaign", str(tiny), "--resume"]) == 2
    assert "--resume: give the campaign's folder with --out" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "campaigns").iterdir()) == [first.name, second.name]


def test_every_row_column_is_documented_in_the_outputs_reference(flown):
    """The docs' campaign-row reference is generated from trn_env.output.fields: a column a run writes but
    the table does not list would be missing from the docs."""
    from trn_env.output.fields import CAMPAIGN_ROW_FIELDS, undocumented

    assert undocumented(read_rows(flown).columns, CAMPAIGN_ROW_FIELDS) == []


def test_report_of_string_and_table_sweeps(tmp_path, capsys):
    """A sweep of strings (a navigator setting's choices) or of tables (a map error model) makes a string
    column, which pandas 3 types as its own "str" dtype: the report's sweep plot crashed on it (numpy could
    not interpret the dtype). Both are drawn as categories now."""
    camp = _campaign(tmp_path, 'name = "words"\nseeds = 1\nnavigators = ["ins"]\n[[sweeps]]\n'
                               'path = "navigator.settings.gravity_model"\nvalues = ["j2", "somigliana"]\n'
                               '[[sweeps]]\npath = "terrain.map.error_model"\n'
                               'values = [{ bias_m = 0.0 }, { bias_m = 5.0 }]\n')
    out = tmp_path / "out"
    assert cli.main(["campaign", str(camp), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    rows = read_rows(out)
    assert len(rows) == 4
    assert not pd.api.types.is_numeric_dtype(rows["sweep.navigator.settings.gravity_model"])
    capsys.readouterr()
    assert cli.main(["report", str(out)]) == 0, capsys.readouterr().err
    pngs = sorted(p.name for p in (out / "report").glob("sweep_*.png"))
    assert pngs == ["sweep_navigator_settings_gravity_model.png", "sweep_terrain_map_error_model.png"]


@pytest.mark.parametrize("backend", ["local", "ray"])
def test_workers_beyond_the_machine_refused_before_any_process_starts(tmp_path, capsys, monkeypatch, backend):
    """--workers above MAX_WORKERS_PER_CORE per usable core (a local pool or a new local Ray instance) is one
    line and exit 2 with nothing started or written: a forked pool launched every worker at once (1e20
    overflowed in it; 1000 started 1000 processes), and a Ray pool starts one actor per worker."""
    from trn_env.campaign.local import MAX_WORKERS_PER_CORE, default_workers

    if backend == "ray":
        pytest.importorskip("ray", reason="the ray extra is installed in CI (pip install -e .[ray])")
        monkeypatch.delenv("RAY_ADDRESS", raising=False)
    limit = MAX_WORKERS_PER_CORE * default_workers()
    ray_before = backend == "ray" and __import__("ray").is_initialized()     # another test's instance
    out = tmp_path / "out"
    for workers in (limit + 1, 99999999999999999999):
        rc = cli.main(["campaign", str(CI), "--backend", backend, "--workers", str(workers),
                       "--out", str(out), "--quiet"])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and err.startswith(f"error: --workers: {workers} is more than")
        assert len(err.splitlines()) == 1
        assert f"at most {limit}" in err and not out.exists()
    if backend == "ray":
        import ray
        assert ray.is_initialized() == ray_before          # no instance started


def test_a_campaign_of_more_than_max_runs_is_refused_before_anything_is_drawn(tmp_path, monkeypatch):
    """The run count comes from the file alone: seeds = 1e9 used to draw a billion seeds (gigabytes, hours)
    before a run or a refusal, and a 400,000-point grid compared its points pairwise."""
    from trn_env.campaign import spec
    from trn_env.campaign.spec import MAX_RUNS, CampaignError

    def no_drawing(*args):
        raise AssertionError(f"seeds drawn {args} before the size was checked")

    monkeypatch.setattr(spec, "draw_seeds", no_drawing)
    monkeypatch.setattr(spec, "grid_values", no_drawing)

    scen = (CI.parent / "ci_denied_short.toml").as_posix()
    cases = [
        ("seeds = 1000000000\nnavigators = [\"ins\", \"pmf\"]\n", "seeds",
         "2,000,000,000 runs (1,000,000,000 seeds x 1 scenarios x 2 navigators)"),
        ("seeds = 3\n[[sweeps]]\npath = \"wind.layers.0.speed_mps\"\n"
         "grid = { start = 0.0, stop = 10.0, num = 400000 }\n", "sweeps[0]",
         "1,200,000 runs (3 seeds x 1 scenarios x 1 navigators x 400,000 points of sweeps[0])"),
    ]
    for body, field, runs in cases:
        f = tmp_path / "big.toml"
        f.write_text(f'name = "big"\nscenarios = ["{scen}"]\n{body}')
        with pytest.raises(CampaignError) as exc:
            load_campaign(f)
        assert exc.value.problems == [f"{field}: the campaign asks for {runs}, more than {MAX_RUNS:,}: "
                                      "split it into campaigns of fewer runs"]


def test_repeated_sweep_points_found_among_numbers_booleans_and_tables(tmp_path):
    from trn_env.campaign.spec import _repeats, _same_value

    values = [1, 2.0, 1.0, True, 1, False, 0.0, True]
    assert _repeats(values) == [(2, 0), (4, 0), (7, 3)]
    tables = [{"a": 1}, [1, 2], {"a": 1.0}, [1.0, 2.0], "x"]
    assert _repeats(tables) == [(2, 0), (3, 1)]
    # against the pairwise definition, on a grid's floats
    grid = [float(x) for x in np.round(np.linspace(0.0, 1.0, 101), 1)]
    brute = [(k, next(i for i, w in enumerate(grid) if _same_value(v, w))) for k, v in enumerate(grid)]
    assert _repeats(grid) == [(k, f) for k, f in brute if f != k]


def test_a_campaign_file_written_as_json_is_named_so(tmp_path, capsys):
    f = tmp_path / "campaign.json"
    f.write_text(json.dumps({"name": "x", "seeds": 2, "scenarios": ["default"]}))
    assert cli.main(["campaign", str(f)]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "file: not valid TOML: Invalid statement (at line 1, column 1) (it looks like JSON: a campaign file "
        "is TOML)")


def test_a_campaign_runs_unguarded_where_the_system_has_no_folder_locks(flown, tmp_path, monkeypatch):
    """Without fcntl (Windows), `import fcntl` at the driver's top was a ModuleNotFoundError for every
    campaign command; now the folder is not locked there, as on a file system without folder locks."""
    from trn_env.campaign import driver
    monkeypatch.setattr(driver, "fcntl", None)
    folder = tmp_path / "copy"
    shutil.copytree(flown, folder)
    (folder / "runs" / "v000-s0001.parquet").unlink()
    assert not driver.folder_busy(folder)
    assert cli.main(["campaign", str(CI), "--out", str(folder), "--resume", "--quiet", "--workers", "1"]) == 0
    assert (folder / "runs" / "v000-s0001.parquet").is_file()
    fresh = tmp_path / "fresh"
    with driver.folder_lock(load_campaign(CI), fresh):
        assert fresh.is_dir()
    assert not fresh.exists()
