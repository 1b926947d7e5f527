"""`trn-env report DIR`: what a navigation engineer reads from a campaign folder.

- the summary table per navigator x sweep point (runs, failures, mean and percentiles of the metrics);
- cdf_horizontal_error.png: the empirical CDF of the horizontal error over every logged row of every run,
  one line per navigator (CEP50 / CEP95 can be read off at 0.5 / 0.95);
- envelope_horizontal_error.png: horizontal error versus time over runs, per navigator: the median and the
  5-95 % band (90 % of the runs) on the runs' common time grid, each run holding its value until its next row
  and leaving the statistics when it ends;
- sweep_<path>.png for each swept field: median horizontal RMS versus the swept value per navigator, with
  the 5-95 % band over seeds;
- report.html: the table and every PNG embedded (base64), one self-contained file.

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

from trn_env.campaign.rows import read_manifest, read_rows
from trn_env.campaign.stats import group_stats
from trn_env.output.metrics import MetricSettings


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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
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


def envelope_plot(path: Path, df) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for nav, g in df.groupby("navigator", sort=True):
        t, med, lo, hi = envelope(list(g["series_t_s"]), list(g["series_err_h_m"]))
        if t.size:
            line, = ax.plot(t, med, label=f"{nav} median ({len(g)} runs)")
            ax.fill_between(t, lo, hi, color=line.get_color(), alpha=0.2, label=f"{nav} 5-95 %")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("horizontal error (m)")
    ax.set_title("horizontal error over runs: median and 90 % band")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sweep_plot(path: Path, df, sweep_path: str, metric: str = "horizontal_error_rms_m") -> bool:
    col = f"sweep.{sweep_path}"
    if col not in df:
        return False
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    numeric = np.issubdtype(df[col].dtype, np.number)
    cats = sorted(df[col].astype(str).unique()) if not numeric else None
    for nav, g in df[df["termination"] != "error"].groupby("navigator", sort=True):
        xs, med, lo, hi = [], [], [], []
        for x, gg in g.groupby(col, sort=True):
            v = gg[metric].to_numpy(float)
            v = v[np.isfinite(v)]
            if not v.size:
                continue
            xs.append(float(x) if numeric else cats.index(str(x)))
            med.append(np.median(v))
            lo.append(np.percentile(v, 5))
            hi.append(np.percentile(v, 95))
        if xs:
            line, = ax.plot(xs, med, "o-", label=f"{nav} median")
            ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
    if cats is not None:
        ax.set_xticks(range(len(cats)), cats)
    ax.set_xlabel(sweep_path)
    ax.set_ylabel(metric.replace("_", " "))
    ax.set_title(f"{metric} vs {sweep_path} (median, 5-95 % over seeds)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


_TABLE_COLS = [("horizontal_error_rms_m.mean", "h RMS mean"), ("horizontal_error_rms_m.p50", "h RMS p50"),
               ("horizontal_error_rms_m.p90", "h RMS p90"), ("horizontal_error_cep50_m.p50", "CEP50 p50"),
               ("horizontal_error_cep95_m.p50", "CEP95 p50"), ("horizontal_error_final_m.p50", "final p50"),
               ("horizontal_error_final_m.p90", "final p90"), ("vertical_error_rms_m.p50", "v RMS p50"),
               ("anees.p50", "ANEES p50"), ("fraction_within_3sigma.mean", "in 3σ"),
               ("time_to_converge_s.p50", "converge s p50"), ("track_lost.mean", "track lost"),
               ("fraction_healthy.mean", "healthy"), ("misleading_information_time_s.mean", "MI s mean")]


def _html_table(stats: dict) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in ["navigator | sweep", "runs", "errors", "diverged"]
                   + [h for _, h in _TABLE_COLS])
    rows = []
    for key, r in stats.items():
        cells = [html.escape(key), str(r["runs"]), str(r["errors"]), str(r["diverged"])]
        for k, h in _TABLE_COLS:
            v = r[k]
            pct = h in ("in 3σ", "track lost", "healthy")
            cells.append("-" if not np.isfinite(v) else (f"{100 * v:.0f} %" if pct else f"{v:.2f}"))
        rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def write_report(campaign_dir: Path | str, out_dir: Path | str | None = None) -> Path:
    """Write the report of a campaign folder; returns the report folder. ValueError naming the folder if it
    is not a campaign folder or has no rows."""
    campaign_dir = Path(campaign_dir)
    if not campaign_dir.is_dir():
        raise ValueError(f"report: {campaign_dir}: no such folder")
    manifest = read_manifest(campaign_dir)
    df = read_rows(campaign_dir)
    out_dir = Path(out_dir) if out_dir is not None else campaign_dir / "report"
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
                pngs.append((f"Horizontal RMS versus {p}", name))
        stats = group_stats(df)
        (tmp / "summary.json").write_text(json.dumps(stats, indent=2, default=float) + "\n", encoding="utf-8")
        errors = df[df["termination"] == "error"]
        err_html = "".join(f"<li><code>{html.escape(r.run_id)}</code>: {html.escape(str(r.error)[:300])}</li>"
                           for r in errors.itertuples())
        figs = "".join(
            f"<h2>{html.escape(title)}</h2><img alt='{html.escape(title)}' src='data:image/png;base64,"
            f"{base64.b64encode((tmp / name).read_bytes()).decode()}'>" for title, name in pngs)
        terms = df["termination"].value_counts().to_dict()
        page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>campaign {html.escape(str(manifest.get('campaign')))}</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse;font-size:0.85em}}
td,th{{border:1px solid #bbb;padding:3px 6px;text-align:right}} td:first-child{{text-align:left}}
img{{max-width:100%}}</style></head><body>
<h1>campaign {html.escape(str(manifest.get('campaign')))}</h1>
<p>{html.escape(str(manifest.get('description', '')))}</p>
<p>{len(df)} of {manifest.get('n_runs')} run(s); terminations: {html.escape(json.dumps(terms))};
source {html.escape(str(manifest.get('source')))}; campaign hash
<code>{html.escape(str(manifest.get('campaign_hash'))[:16])}</code></p>
<h2>Summary per navigator and sweep point</h2>{_html_table(stats)}
<p>p50/p90: percentiles over runs; ANEES: mean position NEES of a run (3 for a consistent filter).</p>
{figs}
{'<h2>Failed runs</h2><ul>' + err_html + '</ul>' if err_html else ''}
</body></html>
"""
        (tmp / "report.html").write_text(page, encoding="utf-8")
        if out_dir.exists():
            shutil.rmtree(out_dir)
        os.replace(tmp, out_dir)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out_dir
