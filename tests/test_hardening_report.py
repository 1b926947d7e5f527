"""Issue 39, outputs people read: the campaign's terminal table and report, built from synthetic rows (the
row format of trn_env.campaign.runs, no flights): sweep values in their own columns within 100 terminal
columns, units in every report header, abbreviations defined, terminations as a table, settings and replay
commands per group, sweep plots titled in words, bands only when enough runs back them, outages shaded."""

from __future__ import annotations

import html
import json
import re

import numpy as np
import pytest
from rich.console import Console

from trn_env.campaign import report
from trn_env.campaign.rows import read_rows, write_manifest, write_row
from trn_env.campaign.stats import summary_table

SWEEPS = ("wind.layers.0.speed_mps", "wind.layers.1.direction_from_deg")


def _row(i: int, nav: str, sweep: dict, seed: int, termination: str = "time_limit") -> dict:
    rng = np.random.default_rng(i)
    t = np.arange(0.0, 60.0, 1.0)
    err = 10.0 + rng.random(t.size) * 5.0
    row = {"run_id": f"r{i:04d}", "run_index": i, "seed": seed, "navigator": nav, "navigator_name": nav,
           "sweep_json": json.dumps(sweep, sort_keys=True), "termination": termination, "error": None,
           "replay_command": f"trn-env fly scen.toml --seed {seed} --navigator {nav}",
           "navigator_settings_json": json.dumps({"remove_bias": True} if nav == "ins_tercom" else {}),
           "gnss_outages_json": json.dumps([{"start_s": 20.0, "end_s": 40.0}]),
           "horizontal_error_rms_m": float(np.sqrt(np.mean(err ** 2))), "horizontal_error_cep50_m": 11.0,
           "horizontal_error_cep95_m": 14.0, "horizontal_error_final_m": float(err[-1]),
           "vertical_error_rms_m": 3.0, "anees": 2.8, "fraction_within_3sigma": 0.98,
           "time_to_converge_s": 5.0,
           "track_lost": False, "fraction_healthy": 1.0, "misleading_information_time_s": 0.0,
           "series_t_s": t.tolist(), "series_err_h_m": err.tolist()}
    row.update({f"sweep.{k}": v for k, v in sweep.items()})
    return row


def _campaign_dir(tmp_path, seeds: int):
    out = tmp_path / "camp"
    i = 0
    for nav in ("ins", "ins_tercom"):
        for speed in (3.0, 12.5):
            for direction in (0.0, 270.0):
                for seed in range(seeds):
                    sweep = {SWEEPS[0]: speed, SWEEPS[1]: direction}
                    write_row(out, _row(i, nav, sweep, seed, "diverged" if i == 1 else "time_limit"))
                    i += 1
    write_manifest(out, {"campaign": "t", "campaign_hash": "0" * 16, "source": "t.toml", "n_runs": i,
                         "sweep_paths": list(SWEEPS)}, "")
    return out


def test_terminal_table_gives_sweeps_their_own_columns_within_100_columns(tmp_path):
    df = read_rows(_campaign_dir(tmp_path, 2))
    console = Console(width=100, record=True)
    console.print(summary_table(df, "campaign t: 16 run(s) -> camp"))
    text = console.export_text()
    assert max(len(line) for line in text.splitlines()) <= 100
    rows = [line.split() for line in text.splitlines() if line.strip().startswith(("ins ", "ins_tercom "))]
    assert len(rows) == 8
    combos = {(r[0], r[1], r[2]) for r in rows}             # navigator, speed, direction: all 8 distinct
    assert combos == {(n, s, d) for n in ("ins", "ins_tercom") for s in ("3", "12.5") for d in ("0", "270")}
    flat = " ".join(text.split())
    assert "speed mps = wind.layers.0.speed_mps" in flat and "MI: misleading-information time" in flat


def test_report_headers_units_glossary_terminations_settings(tmp_path):
    rep = report.write_report(_campaign_dir(tmp_path, 2))
    page = (rep / "report.html").read_text()
    summary = page.split("<h2>Summary per navigator and sweep point</h2>", 1)[1].split("</table>", 1)[0]
    heads = [html.unescape(h) for h in re.findall(r"<th>(.*?)</th>", summary)]
    counts = {"navigator | sweep", "runs", "errors", "diverged"}
    assert all(re.search(r"\((m|s|-|% of time|% of runs)\)$", h) for h in heads if h not in counts), heads
    for term, _ in report.GLOSSARY:                          # every abbreviation in the headers is defined
        assert f"<dt>{html.escape(term)}</dt>" in page
    for abbrev in ("MI", "ANEES", "CEP50, CEP95", "converge"):
        assert any(abbrev == t for t, _ in report.GLOSSARY)
    terms = page.split("<h2>How the runs ended</h2>", 1)[1].split("</table>", 1)[0]
    assert "<th>diverged</th>" in terms and "<th>time_limit</th>" in terms and "{" not in terms
    settings = page.split("<h2>Navigator settings and replay commands</h2>", 1)[1].split("</table>", 1)[0]
    assert html.escape('{"remove_bias": true}') in settings and "(defaults)" in settings
    assert "trn-env fly scen.toml --seed 0 --navigator ins_tercom" in settings


def test_sweep_titles_in_words():
    assert report.describe_path("wind.layers.0.speed_mps") == "Wind layers #0: speed (m/s)"
    assert report.describe_path("navigator.rate_hz") == "Navigator: rate (Hz)"
    assert report.describe_path("seed") == "Seed"


@pytest.mark.parametrize("seeds, band", [(2, False), (report.MIN_BAND_RUNS, True)])
def test_bands_only_with_enough_runs_and_outages_shaded(tmp_path, seeds, band):
    out = _campaign_dir(tmp_path, seeds)
    df = read_rows(out)
    labels = report.envelope_plot(tmp_path / "env.png", df)
    n = 4 * seeds                                             # runs per navigator (2 x 2 sweep points)
    assert (f"ins: 5-95 % of {n} runs" in labels) is (n >= report.MIN_BAND_RUNS)
    assert any(lab.startswith("GNSS outage") for lab in labels)
    labels = report.sweep_plot(tmp_path / "sweep.png", df, SWEEPS[0])
    assert ("ins: 5-95 % over seeds" in labels) is band
    assert any(f"({2 * seeds} runs per point)" in lab for lab in labels)
    if not band:
        assert f"ins: each run (< {report.MIN_BAND_RUNS} per point: no band)" in labels
