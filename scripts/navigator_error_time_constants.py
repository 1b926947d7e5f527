"""First-order Gauss-Markov time constants of each navigator's horizontal and vertical position error, fitted
to the GNSS-denied error series the protection-level campaign saved (scripts/protection_level_campaign.py,
OUT/epochs/<nav>/<condition>/s<seed>.npz, key err_ned_m):

    python scripts/navigator_error_time_constants.py --out out/pl_campaign

(Run it from the repository root with PYTHONPATH=. so the worktree's trn_env is the one imported.)

The DEM integrity monitor's GNSS-denied path models the navigator's error as first-order Gauss-Markov in
time (navigators.integrity.dem_monitor: navigator_error_time_constant_s, navigator_height_time_constant_s;
docs/guide/integrity.md: "a GM fit to the navigator's error over flights gives tau"). The fit: per navigator
and axis, the autocorrelation rho(k) = sum x_t x_{t+k} / sqrt(sum x_t^2 sum x_{t+k}^2) of the healthy
denied rows (pooled over flights and conditions, pairs only inside one flight, no mean removed: a GM error
has zero mean), and tau the least-squares slope of -k / ln rho(k) over the lags 1 .. 60 s where rho(k) >
0.2 (rho(k) = exp(-k / tau) for a GM process): tau = sum k^2 / sum(-k ln rho). Horizontal: north and east
pooled. Prints one line per navigator and writes OUT/error_time_constants.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def series(out: Path, nav: str) -> list[np.ndarray]:
    """The (n, 3) NED error series of the healthy GNSS-denied rows, one per saved flight (rows with a gap
    split the series)."""
    runs = []
    for f in sorted((out / "epochs" / nav).glob("*/s*.npz")):
        z = np.load(f)
        if "err_ned_m" not in z:
            continue
        keep = z["denied"] & z["ok"]
        err = np.asarray(z["err_ned_m"], float)
        idx = np.flatnonzero(keep)
        if idx.size < 2:
            continue
        for part in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
            if part.size > 10:
                runs.append(err[part])
    return runs


def autocorrelation(runs: list[np.ndarray], axes: tuple[int, ...], max_lag: int) -> np.ndarray:
    """rho(k), k = 0 .. max_lag, pooled over runs and axes (pairs inside one run)."""
    rho = np.full(max_lag + 1, np.nan)
    for k in range(max_lag + 1):
        num = a2 = b2 = 0.0
        for r in runs:
            if r.shape[0] <= k:
                continue
            for ax in axes:
                x = r[:, ax]
                a, b = x[: x.size - k], x[k:]
                num += float(a @ b)
                a2 += float(a @ a)
                b2 += float(b @ b)
        if a2 > 0 and b2 > 0:
            rho[k] = num / np.sqrt(a2 * b2)
    return rho


def fit_tau(rho: np.ndarray, floor: float = 0.2) -> float:
    """Least-squares tau of rho(k) = exp(-k / tau) over the lags k >= 1 before rho first falls below floor."""
    k = np.arange(rho.size)
    ok = np.zeros(rho.size, bool)
    for i in range(1, rho.size):
        if not (np.isfinite(rho[i]) and rho[i] > floor):
            break
        ok[i] = True
    if not ok.any():
        return float("nan")
    kk, lr = k[ok].astype(float), np.log(rho[ok])
    return float(np.sum(kk * kk) / np.sum(-kk * lr))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="pl_campaign", help="the protection-level campaign's folder")
    ap.add_argument("--max-lag-s", type=int, default=60)
    args = ap.parse_args(argv)
    out = Path(args.out)
    if not (out / "epochs").is_dir():
        ap.error(f"--out: {out / 'epochs'} does not exist (run scripts/protection_level_campaign.py first)")
    if args.max_lag_s < 2:
        ap.error(f"--max-lag-s: must be >= 2, got {args.max_lag_s}")
    res = {}
    for nav_dir in sorted(p for p in (out / "epochs").iterdir() if p.is_dir()):
        runs = series(out, nav_dir.name)
        if not runs:
            continue
        rho_h = autocorrelation(runs, (0, 1), args.max_lag_s)
        rho_v = autocorrelation(runs, (2,), args.max_lag_s)
        lags = [k for k in (10, 30, 60) if k < rho_h.size]
        res[nav_dir.name] = m = {"runs": len(runs), "rows": int(sum(r.shape[0] for r in runs)),
                                 "tau_horizontal_s": fit_tau(rho_h), "tau_vertical_s": fit_tau(rho_v),
                                 "rho_horizontal_10_30_60": [float(rho_h[k]) for k in lags],
                                 "rho_vertical_10_30_60": [float(rho_v[k]) for k in lags]}
        print(f"{nav_dir.name}: {m['runs']} series, {m['rows']} rows: tau horizontal "
              f"{m['tau_horizontal_s']:.0f} s "
              f"(rho at 10/30/60 s {np.round(m['rho_horizontal_10_30_60'], 2).tolist()}), vertical "
              f"{m['tau_vertical_s']:.0f} s (rho {np.round(m['rho_vertical_10_30_60'], 2).tolist()})")
    (out / "error_time_constants.json").write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
