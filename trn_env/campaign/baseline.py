"""The regression gate: a campaign's group statistics against a stored baseline.

Baseline JSON:

    {"campaign": "ci_small", "campaign_hash": "...", "written": "...",
     "groups": {"ins | -": {"horizontal_error_rms_m.p50": {"value": 31.2, "better": "lower",
                                                           "rel_tol": 0.2, "abs_tol": 2.0}, ...}}}

For a "lower is better" figure with baseline b, the result v is WORSE when v > b + (rel_tol |b| + abs_tol)
and MUCH BETTER when v < b - (rel_tol |b| + abs_tol) (a warning: refresh the baseline on purpose with
`--write-baseline`). "near:X" figures (ANEES, whose consistent value is the position dof 3) compare
|v - X| the same way. A group or figure missing from the results, or a finite baseline against a NaN
result, is worse. Tolerances are per figure in the file; `--write-baseline` writes the defaults below.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from dataclasses import dataclass
from pathlib import Path

from trn_env.campaign.stats import group_stats

# figure -> (better, rel_tol, abs_tol)
GATED: dict[str, tuple[str, float, float]] = {
    "horizontal_error_rms_m.p50": ("lower", 0.2, 2.0),
    "horizontal_error_rms_m.p90": ("lower", 0.25, 2.0),
    "horizontal_error_cep95_m.p50": ("lower", 0.2, 2.0),
    "horizontal_error_final_m.p50": ("lower", 0.25, 3.0),
    "vertical_error_rms_m.p50": ("lower", 0.25, 1.0),
    "anees.p50": ("near:3", 0.5, 1.0),
    "track_lost.mean": ("lower", 0.0, 0.25),
    "errors": ("lower", 0.0, 0.0),
    "diverged": ("lower", 0.0, 0.0),
}


@dataclass
class Comparison:
    group: str
    figure: str
    baseline: float
    value: float
    limit: float            # the band half-width
    verdict: str            # "ok", "worse", "better", "missing"


def make_baseline(df, campaign: str, campaign_hash: str) -> dict:
    stats = group_stats(df)
    groups = {}
    for key, row in stats.items():
        groups[key] = {fig: {"value": _json_float(row.get(fig, float("nan"))), "better": b, "rel_tol": r,
                             "abs_tol": a} for fig, (b, r, a) in GATED.items()}
    return {"campaign": campaign, "campaign_hash": campaign_hash,
            "written": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), "groups": groups}


def _json_float(v: float):
    return float(v) if math.isfinite(float(v)) else None


def write_baseline(path: Path, baseline: dict) -> None:
    import os
    import tempfile
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(json.dumps(baseline, indent=2) + "\n")
    os.replace(tmp, path)


def read_baseline(path: Path) -> dict:
    """The baseline file, checked; ValueError naming the file and field."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"--check {path}: no such baseline file (write one with --write-baseline)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"--check {path}: unreadable baseline ({exc})") from None
    groups = data.get("groups") if isinstance(data, dict) else None
    if not isinstance(groups, dict) or not groups:
        raise ValueError(f"--check {path}: groups: missing or empty")
    for g, figs in groups.items():
        if not isinstance(figs, dict):
            raise ValueError(f"--check {path}: groups.{g}: not a table of figures")
        for fig, spec in figs.items():
            where = f"--check {path}: groups.{g}.{fig}"
            if not isinstance(spec, dict):
                raise ValueError(f"{where}: not a table")
            b = spec.get("better", "lower")
            if not (b in ("lower", "higher") or (isinstance(b, str) and b.startswith("near:"))):
                raise ValueError(f"{where}.better: {b!r} is not lower, higher or near:X")
            for k in ("rel_tol", "abs_tol"):
                v = spec.get(k, 0.0)
                if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v < 0:
                    raise ValueError(f"{where}.{k}: must be a finite number >= 0 (got {v!r})")
            v = spec.get("value")
            if v is not None and (not isinstance(v, (int, float)) or isinstance(v, bool)):
                raise ValueError(f"{where}.value: must be a number or null (got {v!r})")
    return data


def _score(v: float, better: str) -> float:
    """A 'lower is better' score of figure value v."""
    if better == "lower":
        return v
    if better == "higher":
        return -v
    return abs(v - float(better.split(":", 1)[1]))


def compare(df, baseline: dict) -> list[Comparison]:
    stats = group_stats(df)
    out: list[Comparison] = []
    for g, figs in baseline["groups"].items():
        for fig, spec in figs.items():
            b = spec.get("value")
            b = float("nan") if b is None else float(b)
            better = spec.get("better", "lower")
            if g not in stats or fig not in stats[g]:
                out.append(Comparison(g, fig, b, float("nan"), float("nan"), "missing"))
                continue
            v = float(stats[g][fig])
            sb = _score(b, better) if math.isfinite(b) else float("nan")
            limit = float(spec.get("rel_tol", 0.0)) * abs(sb) + float(spec.get("abs_tol", 0.0)) \
                if math.isfinite(sb) else float("nan")
            if not math.isfinite(b):
                verdict = "ok" if not math.isfinite(v) else "better"
            elif not math.isfinite(v):
                verdict = "worse"
            else:
                sv = _score(v, better)
                verdict = "worse" if sv > sb + limit else ("better" if sv < sb - limit else "ok")
            out.append(Comparison(g, fig, b, v, limit, verdict))
    return out


def comparison_table(comps: list[Comparison], title: str):
    from rich.table import Table
    t = Table(title=title)
    for h in ("group", "figure", "baseline", "now", "band ±", "verdict"):
        t.add_column(h, justify="right" if h in ("baseline", "now", "band ±") else "left")
    for c in comps:
        style = {"worse": "bold red", "better": "yellow", "missing": "bold red"}.get(c.verdict, "")
        gone = c.verdict == "missing"          # not in this campaign's rows: no value, no band
        t.add_row(c.group, c.figure, f"{c.baseline:.3g}", "-" if gone else f"{c.value:.3g}",
                  "-" if gone else f"{c.limit:.3g}", c.verdict, style=style)
    return t
