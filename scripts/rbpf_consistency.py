"""The RBPF on the default route (3" Jacksboro map against the 30 m fractal world, GNSS fused for 10 s then
denied): accuracy and consistency over Monte Carlo seeds, with the innovation test's recovery on (the
default, integrity_alpha 1e-4; 0.01 before) and/or off (integrity_alpha 1e-12).

    PYTHONPATH=$PWD python scripts/rbpf_consistency.py [--seeds 0 1 2] [--duration 600] [--workers 2]
        [--alphas 1e-4 1e-12] [--set n_particles=2000 ...] [--map-is-world]

--map-is-world gives the navigator the 30 m world itself as its map (no map error: the filter's
measurement model is then the truth's; issue 17's consistency criterion holds there:
docs/validation/seed002.md).

Per run: horizontal RMS, final and max error, re-spreads, time-averaged horizontal NEES (2 dof) after 15 s.
Over the seeds (issue 17's criterion: the Monte-Carlo-averaged NEES after convergence inside its 95 %
chi-square bounds):
- pooled: the mean NEES at every 10th epoch (errors decorrelate over ~10 s) against the two-sided 95 %
  bounds for that many independent 2-dof samples, chi2.ppf((1 -+ 0.95) / 2, 2 n) / n;
- per epoch: the NEES averaged over the R runs at each epoch after 15 s against chi2.ppf(., 2 R) / R, and
  the fraction of epochs inside (a consistent filter: about 95 %; >= 91 % with 97.5 % probability for
  ~50 independent epochs, binomial).
"""

from __future__ import annotations

import argparse
import ast
import json
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import chi2

CONVERGED_AFTER_S = 15.0


def one_run(args) -> dict:
    seed, duration_s, alpha, settings, map_is_world = args
    from trn_env.scenario.loading import load_scenario, validate
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario("default", duration_s=duration_s, seed=seed, navigator="rbpf")
    data = sc.to_dict()
    data["navigator"]["settings"] = {"integrity_alpha": alpha, **settings}
    if map_is_world:
        data["terrain"]["map"] = {"dem": "world"}
    res = ClosedLoop(validate(data, source="default"), pipeline=False).run()
    a = res.arrays
    e, cov, t = a["err_ned_m"], a["est_cov"], a["t_s"]
    sel = np.flatnonzero(t >= CONVERGED_AFTER_S)
    nees = np.array([e[k, :2] @ np.linalg.solve(cov[k, :2, :2], e[k, :2]) for k in sel])
    respreads = sum(1 for ev in res.events if "re-spread" in str(ev))
    return {"seed": seed, "alpha": alpha, "rms_m": res.summary["horizontal_error_rms_m"],
            "final_m": res.summary["horizontal_error_final_m"],
            "max_m": res.summary["horizontal_error_max_m"],
            "respreads": respreads, "nees_mean": float(np.mean(nees)), "nees": nees.tolist(),
            "t": t[sel].tolist(), "sim_s": float(t[-1])}


def decorrelation_lag(rows: list[dict], limit: float = 0.1) -> int:
    """First lag (epochs) at which the runs' NEES series, taken about the per-epoch mean over the runs, have
    a mean autocorrelation below `limit` (on the default route 45 s: every 10th epoch is not independent)."""
    m = min(len(r["nees"]) for r in rows)
    A = np.array([np.asarray(r["nees"])[:m] for r in rows])
    D = A - A.mean(axis=0)
    for lag in range(1, m // 2):
        ac = [np.corrcoef(d[:-lag], d[lag:])[0, 1] for d in D if np.std(d[:-lag]) > 0 and np.std(d[lag:]) > 0]
        if ac and float(np.mean(ac)) < limit:
            return lag
    return m // 2


def mc_nees(rows: list[dict], thin: int = 10) -> dict:
    """Pooled and per-epoch Monte-Carlo NEES statistics (see the module docstring), plus the pooled NEES
    thinned at the measured decorrelation lag with its chi-square bounds, and a 95 % t interval of the runs'
    time-averaged NEES (runs are independent; epochs of one run are not)."""
    from scipy.stats import t as student_t

    pooled = np.concatenate([np.asarray(r["nees"])[::thin] for r in rows])
    n = pooled.size
    out = {"pooled": float(np.mean(pooled)), "n": n,
           "pooled_lo": chi2.ppf(0.025, 2 * n) / n, "pooled_hi": chi2.ppf(0.975, 2 * n) / n}
    R = len(rows)
    if R >= 2:
        lag = decorrelation_lag(rows)
        thinned = np.concatenate([np.asarray(r["nees"])[::lag] for r in rows])
        k = thinned.size
        means = np.array([float(np.mean(r["nees"])) for r in rows])
        half = student_t.ppf(0.975, R - 1) * means.std(ddof=1) / np.sqrt(R)
        out.update(lag=lag, thinned=float(np.mean(thinned)), thinned_n=k,
                   thinned_lo=chi2.ppf(0.025, 2 * k) / k, thinned_hi=chi2.ppf(0.975, 2 * k) / k,
                   runs_t=(float(means.mean() - half), float(means.mean() + half)))
    m = min(len(r["nees"]) for r in rows)
    avg = np.mean([np.asarray(r["nees"])[:m] for r in rows], axis=0)
    lo, hi = chi2.ppf(0.025, 2 * R) / R, chi2.ppf(0.975, 2 * R) / R
    out.update(epoch_lo=lo, epoch_hi=hi, epochs=m, inside=float(np.mean((avg >= lo) & (avg <= hi))),
               below=float(np.mean(avg < lo)), above=float(np.mean(avg > hi)), anees=float(np.mean(avg)))
    return out


def _setting(text: str):
    k, _, v = text.partition("=")
    try:
        return k, ast.literal_eval(v)
    except (ValueError, SyntaxError):
        return k, v


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--alphas", type=float, nargs="+", default=[1e-4, 1e-12])
    ap.add_argument("--map-is-world", action="store_true",
                    help="the navigator's map is the 30 m world itself (no map error to model)")
    ap.add_argument("--set", dest="settings", action="append", default=[],
                    help="navigator setting KEY=VALUE (Python literal), repeatable")
    a = ap.parse_args(argv)
    settings = dict(_setting(s) for s in a.settings)
    jobs = [(s, a.duration, alpha, settings, a.map_is_world) for alpha in a.alphas for s in a.seeds]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one_run, jobs))
    for alpha in a.alphas:
        rs = [r for r in rows if r["alpha"] == alpha]
        label = "recovery on" if alpha >= 1e-6 else "recovery off"
        print(f"rbpf, default route, {label} (alpha {alpha:g}) {settings or ''}")
        for r in rs:
            print(f"  seed {r['seed']}: RMS {r['rms_m']:.1f} m, final {r['final_m']:.1f} m, "
                  f"max {r['max_m']:.1f} m, re-spreads {r['respreads']}, "
                  f"NEES mean {r['nees_mean']:.2f} ({r['sim_s']:.0f} s)")
        s = mc_nees(rs)
        print(f"  mean RMS {np.mean([r['rms_m'] for r in rs]):.1f} m; pooled NEES (every 10th epoch, "
              f"n={s['n']}) {s['pooled']:.2f}, 95 % bounds [{s['pooled_lo']:.2f}, {s['pooled_hi']:.2f}]: "
              f"{'inside' if s['pooled_lo'] <= s['pooled'] <= s['pooled_hi'] else 'outside'}")
        if "lag" in s:
            print(f"  decorrelated (every {s['lag']}th epoch: first lag of NEES autocorrelation < 0.1, "
                  f"n={s['thinned_n']}) {s['thinned']:.2f}, 95 % bounds [{s['thinned_lo']:.2f}, "
                  f"{s['thinned_hi']:.2f}]; 95 % t interval of the runs' means [{s['runs_t'][0]:.2f}, "
                  f"{s['runs_t'][1]:.2f}]")
        print(f"  per epoch: MC-averaged NEES over {len(rs)} runs (mean {s['anees']:.2f}) inside "
              f"[{s['epoch_lo']:.2f}, {s['epoch_hi']:.2f}] at {100 * s['inside']:.0f} % of {s['epochs']} "
              f"epochs (below {100 * s['below']:.0f} %, above {100 * s['above']:.0f} %)")
    print(json.dumps([{k: v for k, v in r.items() if k not in ("nees", "t")} for r in rows]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
