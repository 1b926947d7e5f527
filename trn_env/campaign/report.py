"""`trn-env report DIR`: what a navigation engineer reads from a campaign folder.

- the summary table per navigator x sweep point (runs, failures, mean and percentiles of the metrics);
- cdf_horizontal_error.png: the empirical CDF of the horizontal error over every logged row of every run,
  one line per navigator (CEP50 / CEP95 can be read off at 0.5 / 0.95);
- envelope_horizontal_error.png: horizontal error versus time over runs, per navigator: the median and the
  5-95 % band (90 % of the runs) on the runs' common time grid, each run holding its value until its next row
  and leaving the statistics when it ends; GNSS outages shaded;
- sweep_<path>.png for each swept field, titled in words with the dotted path below: median horizontal RMS
  versus the swept value per navigator, with the 5-95 % band over seeds;
- report.html: the table (units in every header, abbreviations defined on the page), the terminations per
  group as a table, per group the navigator's settings and a replay command, and every PNG embedded
  (base64), one self-contained file.

A 5-95 % band is drawn only where at least MIN_BAND_RUNS runs back it (fewer runs make its edges the
extreme runs, not percentiles); below that the runs themselves are drawn and the legend says how many.
Each navigator has its own colour and band hatching, so overlapping bands stay apart.

The report folder (default DIR/report) is written to a temporary folder and renamed into place.
"""

from __future__ import annotations

import base64
import html
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
from pandas.api.types import is_bool_dtype, is_numeric_dtype

from trn_env.campaign.rows import read_manifest, read_rows
from trn_env.campaign.stats import group_stats
from trn_env.output.metrics import MetricSettings
from trn_env.output.run_folder import lookup_problem, target_problem

MIN_BAND_RUNS = 20
COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2")
HATCHES = ("//", "\\\\", "..", "xx", "++", "--", "oo", "||")

# words for the parts of a dotted scenario path (sweep plot titles); unit suffixes become units
_UNITS = {"mps": "m/s", "m": "m", "s": "s", "deg": "deg", "hz": "Hz", "kg": "kg", "mrad": "mrad", "k": "K",
          "pa": "Pa", "rad": "rad"}


def describe_path(path: str) -> str:
    """A dotted scenario path in words: `wind.layers.0.speed_mps` -> `Wind layers #0: speed (m/s)`."""
    parts = path.split(".")
    words, unit = [], ""
    for i, part in enumerate(parts):
        if part.isdigit():
            words[-1] = f"{words[-1]} #{part}" if words else f"#{part}"
            continue
        tokens = part.split("_")
        if i == len(parts) - 1 and len(tokens) > 1 and tokens[-1].lower() in _UNITS:
            unit = _UNITS[tokens[-1].lower()]
            tokens = tokens[:-1]
        words.append(" ".join(tokens))
    text = ": ".join([" ".join(words[:-1]), words[-1]]) if len(words) > 1 else (words[0] if words else path)
    text = text[:1].upper() + text[1:]
    return f"{text} ({unit})" if unit else text


def _style(k: int) -> tuple[str, str]:
    return COLOURS[k % len(COLOURS)], HATCHES[k % len(HATCHES)]


def outage_windows(df) -> list[tuple[float, float | None, int]]:
    """The distinct GNSS outage windows of the campaign's runs: (start_s, end_s or None, runs with it)."""
    if "gnss_outages_json" not in df:
        return []
    counts: dict[tuple[float, float | None], int] = {}
    for text in df["gnss_outages_json"]:
        if not isinstance(text, str) or not text:
            continue
        for o in json.loads(text):
            key = (float(o["start_s"]), float(o["end_s"]) if "end_s" in o else None)
            counts[key] = counts.get(key, 0) + 1
    return [(a, b, n) for (a, b), n in sorted(counts.items(), key=lambda kv: kv[0][0])]


def shade_outages(ax, df, t_max: float) -> None:
    """Grey spans over the time axis where GNSS was denied (labelled once; with the share of runs when
    not every run had that window)."""
    n_runs = len(df)
    labelled = False
    for a, b, n in outage_windows(df):
        share = "" if n >= n_runs else f" ({n} of {n_runs} runs)"
        ax.axvspan(a, b if b is not None else t_max, color="0.5", alpha=0.13 if n >= n_runs else 0.07, lw=0,
                   label=None if labelled and not share else f"GNSS outage{share}")
        labelled = True


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def cdf_plot(path: Path, df) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for nav, g in df.groupby("navigator", sort=True):
        e = np.concatenate([np.asarray(s, float) for s in g["series_err_h_m"]] or [np.array([])])
        e = np.sort(e[np.isfinite(e)])
        if e.size:
            ax.step(e, np.arange(1, e.size + 1) / e.size, where="post", label=f"{nav} ({len(g)} runs)")
    ax.axhline(0.5, color="0.6", lw=0.8, ls=":")
    ax.axhline(0.95, color="0.6", lw=0.8, ls=":")
    ax.set_xlabel("horizontal error (m)")
    ax.set_ylabel("fraction of time samples")
    ax.set_title("CDF of the horizontal error, all runs")
    ax.grid(alpha=0.3)
    ax.legend()
    _save(plt, fig, path)


def stanford_plot(path: Path, df, alert_limit_m: float) -> bool:
    """Stanford diagrams (navigators.integrity.protection_level): per navigator, the healthy epochs'
    horizontal error against their horizontal protection level as a 2-D histogram (log colour), the
    diagonal (misleading information below it) and the alert limit. False if no run has an HPL."""
    if "series_hpl_m" not in df:
        return False
    navs = []
    for nav, g in df.groupby("navigator", sort=True):
        e = np.concatenate([np.asarray(x, float) for x in g["series_err_h_m"]] or [np.array([])])
        h = np.concatenate([np.asarray(x, float) for x in g["series_hpl_m"]] or [np.array([])])
        ok = np.concatenate([np.asarray(x, float) for x in g["series_nav_ok"]] or [np.array([])]) > 0.5
        keep = ok & np.isfinite(e) & np.isfinite(h) if ok.size == e.size else np.isfinite(e) & np.isfinite(h)
        if keep.any():
            navs.append((nav, e[keep], h[keep]))
    if not navs:
        return False
    plt = _plt()
    from matplotlib.colors import LogNorm
    fig, axes = plt.subplots(1, len(navs), figsize=(4.6 * len(navs), 4.4), squeeze=False)
    for ax, (nav, e, h) in zip(axes[0], navs, strict=True):
        top = max(float(np.percentile(np.r_[e, h], 99.9)) * 1.2, 1.5 * alert_limit_m)
        bins = np.linspace(0.0, top, 80)
        hist = ax.hist2d(np.clip(e, 0, top), np.clip(h, 0, top), bins=[bins, bins], norm=LogNorm(),
                         cmap="viridis")
        ax.plot([0, top], [0, top], "k-", lw=0.8)
        ax.axvline(alert_limit_m, color="r", lw=0.8, ls="--")
        ax.axhline(alert_limit_m, color="r", lw=0.8, ls="--")
        mi = int(np.count_nonzero(e > h))
        ax.set_title(f"{nav}: {e.size} epochs, {mi} MI", fontsize=9)
        ax.set_xlabel("horizontal error (m)")
        ax.set_ylabel("horizontal protection level (m)")
        fig.colorbar(hist[3], ax=ax, label="epochs")
    _save(plt, fig, path)
    return True


def envelope(series_t: list, series_v: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t grid, median, 5th, 95th percentile) over runs; a run holds each value until its next row and
    counts only up to its last row."""
    pairs = [(np.asarray(t, float), np.asarray(v, float)) for t, v in zip(series_t, series_v, strict=True)
             if len(t)]
    if not pairs:
        return (np.array([]),) * 4
    ts = [t for t, _ in pairs]
    diffs = [np.diff(t) for t in ts if t.size > 1]
    dt = float(np.median(np.concatenate(diffs))) if diffs else 1.0
    t0 = min(t[0] for t in ts)
    t1 = max(t[-1] for t in ts)
    grid = t0 + dt * np.arange(int(np.floor((t1 - t0) / dt + 1e-9)) + 1)
    vals = np.full((len(ts), grid.size), np.nan)
    for i, (t, v) in enumerate(pairs):
        k = np.searchsorted(t, grid, side="right") - 1
        inside = (k >= 0) & (grid <= t[-1] + 1e-9)
        vals[i, inside] = v[k[inside]]
    n = np.sum(np.isfinite(vals), axis=0)
    keep = n > 0
    vals = vals[:, keep]
    q = np.nanpercentile(vals, [50, 5, 95], axis=0)
    return grid[keep], q[0], q[1], q[2]


def _save(plt, fig, path: Path) -> None:
    """Lay the figure out, write it to path (110 dpi) and close it."""
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _finish(plt, fig, ax, path: Path) -> list[str]:
    """Grid and legend on ax, then _save; returns the legend's labels."""
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    leg = ax.get_legend()
    labels = [t.get_text() for t in leg.get_texts()] if leg is not None else []
    _save(plt, fig, path)
    return labels


def envelope_plot(path: Path, df) -> list[str]:
    """Horizontal error versus time per navigator (see the module docstring); returns the legend's labels."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    t_max = 0.0
    for k, (nav, g) in enumerate(df.groupby("navigator", sort=True)):
        colour, hatch = _style(k)
        t, med, lo, hi = envelope(list(g["series_t_s"]), list(g["series_err_h_m"]))
        if not t.size:
            continue
        t_max = max(t_max, float(t[-1]))
        n = len(g)
        if n >= MIN_BAND_RUNS:
            ax.plot(t, med, color=colour, label=f"{nav}: median of {n} runs")
            ax.fill_between(t, lo, hi, facecolor=colour, alpha=0.15, hatch=hatch, edgecolor=colour, lw=0.0,
                            label=f"{nav}: 5-95 % of {n} runs")
        else:
            for j, (ts, vs) in enumerate(zip(g["series_t_s"], g["series_err_h_m"], strict=True)):
                ax.plot(ts, vs, color=colour, lw=0.6, alpha=0.35,
                        label=f"{nav}: each of {n} runs (< {MIN_BAND_RUNS}: no band)" if j == 0 else None)
            ax.plot(t, med, color=colour, lw=1.8, label=f"{nav}: median of {n} runs")
    shade_outages(ax, df, t_max)
    ax.set_xlabel("time since start (s)")
    ax.set_ylabel("horizontal error (m)")
    ax.set_title("Horizontal error over time across runs")
    return _finish(plt, fig, ax, path)


def sweep_plot(path: Path, df, sweep_path: str, metric: str = "horizontal_error_rms_m") -> list[str]:
    """`metric` versus the swept value per navigator; returns the legend's labels ([] and no file if the
    rows have no such sweep column)."""
    col = f"sweep.{sweep_path}"
    if col not in df:
        return []
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.8))
    # pandas' own dtypes (a string sweep's "str", nullable numbers) are not numpy dtypes
    numeric = is_numeric_dtype(df[col]) and not is_bool_dtype(df[col])
    cats = sorted(df[col].astype(str).unique()) if not numeric else None
    for k, (nav, g) in enumerate(df[df["termination"] != "error"].groupby("navigator", sort=True)):
        colour, hatch = _style(k)
        xs, med, lo, hi, ns, scatter = [], [], [], [], [], []
        for x, gg in g.groupby(col, sort=True):
            v = gg[metric].to_numpy(float)
            v = v[np.isfinite(v)]
            if not v.size:
                continue
            xv = float(x) if numeric else cats.index(str(x))
            xs.append(xv)
            med.append(np.median(v))
            lo.append(np.percentile(v, 5))
            hi.append(np.percentile(v, 95))
            ns.append(v.size)
            scatter += [(xv, float(e)) for e in v]
        if not xs:
            continue
        n_min = min(ns)
        ax.plot(xs, med, "o-", color=colour, label=f"{nav}: median ({n_min}-{max(ns)} runs per point)"
                if n_min != max(ns) else f"{nav}: median ({n_min} runs per point)")
        if n_min >= MIN_BAND_RUNS:
            ax.fill_between(xs, lo, hi, facecolor=colour, alpha=0.15, hatch=hatch, edgecolor=colour, lw=0.0,
                            label=f"{nav}: 5-95 % over seeds")
        else:
            ax.plot([a for a, _ in scatter], [b for _, b in scatter], ".", color=colour, alpha=0.45,
                    label=f"{nav}: each run (< {MIN_BAND_RUNS} per point: no band)")
    if cats is not None:
        ax.set_xticks(range(len(cats)), cats)
    unit = metric.rsplit("_", 1)[-1]
    ax.set_xlabel(describe_path(sweep_path))
    ax.set_ylabel(f"{metric.replace('_', ' ').removesuffix(' ' + unit)} ({unit})")
    fig.suptitle(f"Horizontal error RMS versus {describe_path(sweep_path).lower()}", fontsize=11)
    ax.set_title(sweep_path, fontsize=8, family="monospace", color="0.3")
    return _finish(plt, fig, ax, path)


_TABLE_COLS = [
    ("horizontal_error_rms_m.mean", "h RMS mean (m)"), ("horizontal_error_rms_m.p50", "h RMS p50 (m)"),
    ("horizontal_error_rms_m.p90", "h RMS p90 (m)"), ("horizontal_error_cep50_m.p50", "CEP50 p50 (m)"),
    ("horizontal_error_cep95_m.p50", "CEP95 p50 (m)"), ("horizontal_error_final_m.p50", "final h p50 (m)"),
    ("horizontal_error_final_m.p90", "final h p90 (m)"), ("vertical_error_rms_m.p50", "v RMS p50 (m)"),
    ("anees.p50", "ANEES p50 (-)"), ("fraction_within_3sigma.mean", "in 3σ (% of time)"),
    ("time_to_converge_s.p50", "converge p50 (s)"), ("track_lost.mean", "track lost (% of runs)"),
    ("fraction_healthy.mean", "healthy (% of time)"), ("misleading_information_time_s.mean", "MI mean (s)"),
]

GLOSSARY = [
    ("h, v", "horizontal (north-east) and vertical components of the navigation error (estimate - truth)"),
    ("RMS", "root mean square of a run's error over its logged rows"),
    ("mean, p50, p90", "mean, median and 90th percentile over the group's runs (one value per run)"),
    ("CEP50, CEP95", "circular error probable: the radius holding 50 % / 95 % of a run's horizontal errors"),
    ("final h", "horizontal error at the run's last row"),
    ("ANEES", "average normalised estimation error squared of the position (e' P^-1 e averaged over the "
              "run); 3 for a consistent filter (3 degrees of freedom)"),
    ("in 3σ", "share of the run's time with the north and east errors inside 3 of the navigator's sigma"),
    ("converge", "time to converge: the first time after which the horizontal error stays below the "
                 "campaign's convergence threshold (50 m unless the campaign sets it) to the run's end"),
    ("track lost", "share of runs whose navigator lost track (horizontal error beyond the track-loss "
                   "threshold or k sigma for longer than the campaign's minimum time)"),
    ("healthy", "share of the run's time with the navigator reporting itself healthy"),
    ("MI", "misleading-information time: seconds the navigator reported itself healthy while its error was "
           "outside 3 sigma"),
    ("errors, diverged", "runs that failed with an exception / ended as 'diverged'"),
]


def _pct(h: str) -> bool:
    return "%" in h


def _html_table(stats: dict) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in ["navigator | sweep", "runs", "errors", "diverged"]
                   + [h for _, h in _TABLE_COLS])
    rows = []
    for key, r in stats.items():
        cells = [html.escape(key), str(r["runs"]), str(r["errors"]), str(r["diverged"])]
        for k, h in _TABLE_COLS:
            v = r[k]
            cells.append("-" if not np.isfinite(v) else (f"{100 * v:.0f}" if _pct(h) else f"{v:.2f}"))
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def _group_of(df):
    from trn_env.campaign.stats import group_key
    return [group_key(n, s) for n, s in zip(df["navigator"], df["sweep_json"], strict=True)]


def _termination_table(df) -> str:
    """Runs per group (rows) and termination (columns)."""
    d = df.assign(_group=_group_of(df))
    kinds = sorted(d["termination"].astype(str).unique())
    head = "".join(f"<th>{html.escape(h)}</th>" for h in ["navigator | sweep", *kinds, "all"])
    rows = []
    for key, g in d.groupby("_group", sort=False):
        counts = g["termination"].astype(str).value_counts()
        cells = [html.escape(str(key))] + [str(int(counts.get(k, 0))) for k in kinds] + [str(len(g))]
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def _settings_table(df) -> str:
    """Per group: the navigator, its settings as flown, and the command that replays the group's first run."""
    d = df.assign(_group=_group_of(df))
    rows = []
    for key, g in d.groupby("_group", sort=False):
        first = g.sort_values("run_index").iloc[0] if "run_index" in g else g.iloc[0]
        settings = first.get("navigator_settings_json", None)
        settings = settings if isinstance(settings, str) and settings not in ("", "{}") else "(defaults)"
        replay = str(first.get("replay_command", "") or "")
        rows.append(f"<tr><td>{html.escape(str(key))}</td><td>{html.escape(str(first['navigator_name']))}"
                    f"</td><td><code>{html.escape(settings)}</code></td><td><code>{html.escape(replay)}</code>"
                    f" <small>(run {html.escape(str(first['run_id']))})</small></td></tr>")
    head = "".join(f"<th>{h}</th>" for h in ("navigator | sweep", "navigator", "settings",
                                              "replay one run (trn-env fly ...)"))
    return f"<table class='left'><tr>{head}</tr>{''.join(rows)}</table>"


def write_report(campaign_dir: Path | str, out_dir: Path | str | None = None) -> Path:
    """Write the report of a campaign folder; returns the report folder (default: campaign_dir / "report"),
    which replaces an earlier report there as a whole. ValueError naming the folder if it is not a campaign
    folder or has no rows, or if `out_dir` is a file, a non-empty folder that holds no earlier report (no
    report.html: it is never replaced) or a place where no folder can be made."""
    campaign_dir = Path(campaign_dir)
    problem = lookup_problem(campaign_dir, "report:")
    if problem is not None:         # a name too long to look up is the input's fault, not the output's
        raise ValueError(problem)
    if not campaign_dir.is_dir():
        raise ValueError(f"report: {campaign_dir}: no such folder")
    manifest = read_manifest(campaign_dir)
    df = read_rows(campaign_dir)
    out_dir = Path(out_dir) if out_dir is not None else campaign_dir / "report"
    problem = target_problem(out_dir, overwrite=True, marker="report.html", what="report")
    if problem is not None:         # never replace a folder that is not an earlier report
        raise ValueError(f"report: {problem}")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        pngs = [("CDF of the horizontal error", "cdf_horizontal_error.png"),
                ("Horizontal error versus time", "envelope_horizontal_error.png")]
        cdf_plot(tmp / pngs[0][1], df)
        envelope_plot(tmp / pngs[1][1], df)
        al = float((manifest.get("metrics") or {}).get("alert_limit_m", MetricSettings().alert_limit_m))
        if stanford_plot(tmp / "stanford.png", df, al):
            pngs.append((f"Stanford diagrams (alert limit {al:g} m)", "stanford.png"))
        for p in manifest.get("sweep_paths", []):
            name = f"sweep_{p.replace('.', '_')}.png"
            if sweep_plot(tmp / name, df, p):
                pngs.append((f"Horizontal error RMS versus {describe_path(p).lower()} ({p})", name))
        stats = group_stats(df)
        (tmp / "summary.json").write_text(json.dumps(stats, indent=2, default=float) + "\n", encoding="utf-8")
        errors = df[df["termination"] == "error"]
        err_html = "".join(f"<li><code>{html.escape(r.run_id)}</code>: {html.escape(str(r.error)[:300])}</li>"
                           for r in errors.itertuples())
        figs = "".join(
            f"<h2>{html.escape(title)}</h2><img alt='{html.escape(title)}' src='data:image/png;base64,"
            f"{base64.b64encode((tmp / name).read_bytes()).decode()}'>" for title, name in pngs)
        glossary = "".join(f"<dt>{html.escape(a)}</dt><dd>{html.escape(b)}</dd>" for a, b in GLOSSARY)
        page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>campaign {html.escape(str(manifest.get('campaign')))}</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse;font-size:0.85em}}
td,th{{border:1px solid #bbb;padding:3px 6px;text-align:right}} td:first-child{{text-align:left}}
table.left td{{text-align:left}} dt{{font-weight:bold;float:left;clear:left;width:9em}}
dd{{margin-left:10em;margin-bottom:0.2em}} img{{max-width:100%}}</style></head><body>
<h1>campaign {html.escape(str(manifest.get('campaign')))}</h1>
<p>{html.escape(str(manifest.get('description', '')))}</p>
<p>{len(df)} of {manifest.get('n_runs')} run(s); source {html.escape(str(manifest.get('source')))};
campaign hash <code>{html.escape(str(manifest.get('campaign_hash'))[:16])}</code></p>
<h2>Summary per navigator and sweep point</h2>{_html_table(stats)}
<h3>Abbreviations</h3><dl>{glossary}</dl>
<h2>How the runs ended</h2>{_termination_table(df)}
<h2>Navigator settings and replay commands</h2>{_settings_table(df)}
<p>Bands (5-95 %) are drawn only where at least {MIN_BAND_RUNS} runs back them; with fewer, the plots show
the runs themselves. Grey spans on time plots: GNSS outages.</p>
{figs}
{'<h2>Failed runs</h2><ul>' + err_html + '</ul>' if err_html else ''}
</body></html>
"""
        (tmp / "report.html").write_text(page, encoding="utf-8")
        old = None
        if out_dir.exists():      # the earlier report aside, the new one in, then the earlier one removed
            old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
            os.replace(out_dir, old / "report")
        os.replace(tmp, out_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out_dir
