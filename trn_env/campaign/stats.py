"""Statistics over a campaign's rows per group (navigator x sweep point): the summary table the CLI
prints and the report shows, and the figures the regression gate compares."""

from __future__ import annotations

import json

import numpy as np

# (column, statistic) pairs of the summary table, in display order
TABLE_STATS = (
    ("horizontal_error_rms_m", "mean"), ("horizontal_error_rms_m", "p50"), ("horizontal_error_rms_m", "p90"),
    ("horizontal_error_cep50_m", "p50"), ("horizontal_error_cep95_m", "p50"),
    ("horizontal_error_final_m", "p50"), ("horizontal_error_final_m", "p90"),
    ("vertical_error_rms_m", "p50"), ("anees", "p50"), ("fraction_within_3sigma", "mean"),
    ("time_to_converge_s", "p50"), ("track_lost", "mean"), ("fraction_healthy", "mean"),
    ("misleading_information_time_s", "mean"),
)


def sweep_label_of(sweep_json: str) -> str:
    sweep = json.loads(sweep_json) if sweep_json else {}
    return ", ".join(f"{p}={v}" for p, v in sweep.items()) or "-"


def group_key(navigator: str, sweep_json: str) -> str:
    return f"{navigator} | {sweep_label_of(sweep_json)}"


def statistic(values: np.ndarray, stat: str) -> float:
    """mean, pNN (percentile NN) of the finite values; NaN if none."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    if not x.size:
        return float("nan")
    if stat == "mean":
        return float(np.mean(x))
    if stat.startswith("p"):
        return float(np.percentile(x, float(stat[1:])))
    raise ValueError(f"unknown statistic {stat!r}")


def pooled_protection_level(g) -> dict[str, float]:
    """The protection-level epochs of a group's runs pooled: epochs, misleading epochs, the pooled
    misleading-information rate with its one-sided 95 % Clopper-Pearson bound, hazardous epochs."""
    from trn_env.output.integrity_metrics import clopper_pearson_upper
    if "pl_epochs" not in g:
        return {}
    n = int(np.nansum(g["pl_epochs"].to_numpy(dtype=float)))
    k = int(np.nansum(g["pl_misleading_epochs"].to_numpy(dtype=float)))
    h = int(np.nansum(g["pl_hazardous_epochs"].to_numpy(dtype=float)))
    return {"pl_epochs.sum": n, "pl_misleading_epochs.sum": k,
            "pl_misleading_rate.pooled": k / n if n else float("nan"),
            "pl_misleading_rate.pooled_upper95": clopper_pearson_upper(k, n), "pl_hazardous_epochs.sum": h}


def group_stats(df, stats=TABLE_STATS) -> dict[str, dict[str, float]]:
    """{group key: {'column.stat': value, 'runs': n, 'errors': n, ...}} over the rows of each group."""
    out: dict[str, dict[str, float]] = {}
    keys = [group_key(n, s) for n, s in zip(df["navigator"], df["sweep_json"], strict=True)]
    df = df.assign(_group=keys)
    for key, g in df.groupby("_group", sort=False):
        ok = g[g["termination"] != "error"]
        row: dict[str, float] = {"runs": int(len(g)), "errors": int((g["termination"] == "error").sum()),
                                 "diverged": int((g["termination"] == "diverged").sum())}
        for col, stat in stats:
            vals = ok[col].to_numpy(dtype=float) if col in ok else np.array([])
            row[f"{col}.{stat}"] = statistic(vals, stat)
        row.update(pooled_protection_level(ok))
        out[str(key)] = row
    return out


def summary_table(df, title: str):
    """A rich Table: one line per navigator x sweep point."""
    from rich.table import Table
    stats = group_stats(df)
    t = Table(title=title)
    t.add_column("navigator | sweep")
    t.add_column("runs", justify="right")
    t.add_column("err", justify="right")
    heads = [("h RMS mean", "horizontal_error_rms_m.mean"), ("h RMS p50", "horizontal_error_rms_m.p50"),
             ("h RMS p90", "horizontal_error_rms_m.p90"), ("CEP50", "horizontal_error_cep50_m.p50"),
             ("CEP95", "horizontal_error_cep95_m.p50"), ("final p50", "horizontal_error_final_m.p50"),
             ("v RMS p50", "vertical_error_rms_m.p50"), ("ANEES p50", "anees.p50"),
             ("in 3σ", "fraction_within_3sigma.mean"), ("lost", "track_lost.mean"),
             ("MI s", "misleading_information_time_s.mean")]
    for h, _ in heads:
        t.add_column(h, justify="right")
    for key, row in stats.items():
        cells = [key, str(row["runs"]), str(row["errors"])]
        for h, k in heads:
            v = row[k]
            pct = h in ("in 3σ", "lost")
            cells.append("-" if not np.isfinite(v) else (f"{100 * v:.0f} %" if pct else f"{v:.1f}"))
        t.add_row(*cells)
    return t
