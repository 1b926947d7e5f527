"""Plug-in navigators in campaigns: the SITAN template plug-in (an installed package, entry point `sitan`)
flown by a small campaign on the local pool and on Ray (2 CPUs), each row's replay_command reproducing its
run; a `module:Name` plug-in that no installed package provides, shipped to Ray's workers.

Small: 2 seeds x 20 s of default_short (GNSS denied from 10 s) with a radar altimeter fitted."""

from __future__ import annotations

import json
import shlex
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from _child_processes import NEUTRAL_CWD
from sitan_support import ensure_sitan_installed

from trn_env import cli
from trn_env.campaign.rows import read_rows

HERE = Path(__file__).resolve().parent
METRICS = ["horizontal_error_rms_m", "horizontal_error_final_m", "vertical_error_rms_m"]


def _campaign(tmp: Path, navigator: str) -> Path:
    sc = tmp / "short_ra.toml"
    sc.write_text((HERE / "scenarios/default_short.toml").read_text() + "\n[sensors.radar_altimeter]\n")
    f = tmp / f"camp_{navigator.replace(':', '_')}.toml"
    f.write_text(textwrap.dedent(f"""\
        name = "plugin_small"
        root_seed = 3
        seeds = 2
        scenarios = ["{sc}"]
        duration_s = 20.0
        navigators = ["{navigator}"]
        """))
    return f


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    ensure_sitan_installed()
    tmp = tmp_path_factory.mktemp("sitan_local")
    out = tmp / "out"
    rc = cli.main(["campaign", str(_campaign(tmp, "sitan")), "--out", str(out), "--workers", "2", "--quiet"])
    assert rc == 0
    return out


def test_sitan_campaign_on_the_local_pool(local_run):
    df = read_rows(local_run)
    assert len(df) == 2 and set(df["navigator_name"]) == {"sitan"}
    assert set(df["termination"]) == {"time_limit"}, df[["termination", "error"]]
    for k in METRICS:
        assert np.all(np.isfinite(df[k].astype(float))), k
    assert float(df["horizontal_error_rms_m"].max()) < 30.0        # 20 s after a GNSS start: metres, not km


def test_replay_command_reproduces_the_row(local_run, tmp_path):
    row = read_rows(local_run).iloc[0]
    argv = shlex.split(row["replay_command"])
    assert argv[:2] == ["trn-env", "fly"] and "sitan" in argv
    out = tmp_path / "replay"
    assert cli.main(argv[1:] + ["--out", str(out), "--no-plots", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for k in METRICS:
        assert summary[k] == row[k], (k, summary[k], row[k])


@pytest.mark.slow
def test_sitan_campaign_on_ray_matches_the_local_pool(local_run, tmp_path, monkeypatch):
    pytest.importorskip("ray", reason="the ray extra is installed in CI")
    monkeypatch.chdir(NEUTRAL_CWD)      # Ray's workers import trn_env from where the tests do
    out = tmp_path / "ray"
    rc = cli.main(["campaign", str(_campaign(tmp_path, "sitan")), "--out", str(out), "--backend", "ray",
                   "--workers", "2", "--quiet"])
    assert rc == 0
    ray_rows = read_rows(out).set_index("seed")
    local = read_rows(local_run).set_index("seed")
    assert sorted(ray_rows.index) == sorted(local.index)
    for seed in local.index:
        for k in METRICS:
            assert ray_rows.loc[seed, k] == local.loc[seed, k], (seed, k)


@pytest.mark.slow
def test_unpackaged_reference_is_shipped_to_ray_workers(tmp_path, monkeypatch):
    """A plug-in module on the driver's sys.path only (no installed package): Ray's workers receive it
    through runtime_env py_modules (plugin_runtime_env)."""
    pytest.importorskip("ray", reason="the ray extra is installed in CI")
    mod_dir = tmp_path / "elsewhere"
    mod_dir.mkdir()
    (mod_dir / "shipped_nav_mod.py").write_text(textwrap.dedent("""\
        from trn_env.navigators.builtin import ins as _ins

        class Ins:
            name = "shipped_ins"

            def __init__(self, **settings):
                self._nav = _ins(**settings)

            def reset(self, initial):
                self._nav.reset(initial)

            def update(self, frames):
                return self._nav.update(frames)
        """))
    monkeypatch.syspath_prepend(str(mod_dir))
    monkeypatch.chdir(NEUTRAL_CWD)      # Ray's workers import trn_env from where the tests do
    out = tmp_path / "ray"
    rc = cli.main(["campaign", str(_campaign(tmp_path, "shipped_nav_mod:Ins")), "--out", str(out),
                   "--backend", "ray", "--workers", "2", "--quiet"])
    assert rc == 0
    from trn_env.campaign.ray_backend import plugin_runtime_env
    env = plugin_runtime_env()
    assert env is not None and sys.modules["shipped_nav_mod"].__file__ in env["py_modules"]
    df = read_rows(out)
    assert set(df["termination"]) == {"time_limit"}, df[["termination", "error"]].to_string()
