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


def short_names(paths: list[str]) -> dict[str, str]:
    """A short column name per swept dotted path: its last part, or as many trailing parts as make the
    names distinct (`wind.layers.0.speed_mps` -> `speed_mps`; two layers' speeds -> `0.speed_mps`, ...)."""
    names = {}
    for k in range(1, max((len(p.split(".")) for p in paths), default=1) + 1):
        names = {p: ".".join(p.split(".")[-k:]) for p in paths}
        if len(set(names.values())) == len(paths):
            break
    return names


def _sweep_value(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


# (header, unit, group_stats key) of the terminal table: what fits 100 columns beside two sweep columns
TERMINAL_COLUMNS = (
    ("h RMS p50", "m", "horizontal_error_rms_m.p50"), ("h RMS p90", "m", "horizontal_error_rms_m.p90"),
    ("CEP95 p50", "m", "horizontal_error_cep95_m.p50"), ("final p50", "m", "horizontal_error_final_m.p50"),
    ("ANEES p50", "", "anees.p50"),
    ("in 3σ", "%", "fraction_within_3sigma.mean"), ("MI mean", "s", "misleading_information_time_s.mean"),
)


def summary_table(df, title: str):
    """A rich Table: one line per navigator x sweep point, each swept field in its own short column (the
    caption maps the short names to the dotted paths and spells out the abbreviations); fits 100 columns
    with two sweeps (the vertical error and the other figures are in the report)."""
    from rich import box
    from rich.table import Table
    stats = group_stats(df)
    groups: dict[str, tuple[str, dict]] = {}
    for nav, sj in zip(df["navigator"], df["sweep_json"], strict=True):
        groups.setdefault(group_key(nav, sj), (str(nav), json.loads(sj) if sj else {}))
    paths: list[str] = []
    for _, sweep in groups.values():
        paths += [p for p in sweep if p not in paths]
    short = short_names(paths)
    caption = ["h: horizontal; pNN: percentile over runs; CEP95: 95 % circular error; ANEES: "
               "average normalised estimation error squared (3 = consistent); in 3σ: share of time inside "
               "3 sigma; MI: misleading-information time; err: runs that failed"]
    caption += [f"{short[p].replace('_', ' ')} = {p}" for p in paths if short[p] != p]
    t = Table(title=title, caption="\n".join(caption), box=box.SIMPLE_HEAD, pad_edge=False,
              padding=(0, 1), caption_justify="left")
    t.add_column("navigator", no_wrap=True)
    for p in paths:
        t.add_column(short[p].replace("_", "\n"), justify="right", no_wrap=True)
    t.add_column("runs", justify="right")
    t.add_column("err", justify="right")
    for h, unit, _ in TERMINAL_COLUMNS:
        t.add_column(h.replace(" ", "\n") + f"\n{unit}", justify="right", no_wrap=True)
    for key, row in stats.items():
        nav, sweep = groups.get(key, (key, {}))
        cells = [nav] + [_sweep_value(sweep[p]) if p in sweep else "-" for p in paths]
        cells += [str(row["runs"]), str(row["errors"])]
        for _, unit, k in TERMINAL_COLUMNS:
            v = row[k]
            cells.append("-" if not np.isfinite(v) else (f"{100 * v:.0f}" if unit == "%" else
                                                        f"{v:.2f}" if unit == "" else f"{v:.1f}"))
        t.add_row(*cells)
    return t
