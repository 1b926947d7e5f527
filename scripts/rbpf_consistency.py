"""The RBPF on the default route (3" Jacksboro map against the 30 m fractal world, GNSS fused for 10 s then
denied): accuracy and consistency over Monte Carlo seeds, with the innovation test's recovery on (the
default, integrity_alpha 0.01) and off (integrity_alpha 1e-12).

    PYTHONPATH=$PWD python scripts/rbpf_consistency.py [--seeds 0 1 2] [--duration 600] [--workers 2]

Per run: horizontal RMS, final and max error, re-spreads, time-averaged horizontal NEES (2 dof) after 15 s.
Pooled over the seeds: the mean NEES at every 10th epoch (errors decorrelate over ~10 s) against the
two-sided 95 % chi-square bounds for that many independent 2-dof samples, chi2.ppf((1 -+ 0.95) / 2, 2 n) / n.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import chi2


def one_run(args) -> dict:
    seed, duration_s, alpha = args
    from trn_env.scenario.loading import load_scenario, validate
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario("default", duration_s=duration_s, seed=seed, navigator="rbpf")
    sc.data["navigator"]["settings"] = {"integrity_alpha": alpha}
    res = ClosedLoop(validate(sc.data, source="default"), pipeline=False).run()
    a = res.arrays
    e, cov, t = a["err_ned_m"], a["est_cov"], a["t_s"]
    sel = np.flatnonzero(t >= 15.0)
    nees = np.array([e[k, :2] @ np.linalg.solve(cov[k, :2, :2], e[k, :2]) for k in sel])
    respreads = sum(1 for ev in res.events if "re-spread" in str(ev))
    return {"seed": seed, "alpha": alpha, "rms_m": res.summary["horizontal_error_rms_m"],
            "final_m": res.summary["horizontal_error_final_m"],
            "max_m": res.summary["horizontal_error_max_m"],
            "respreads": respreads, "nees_mean": float(np.mean(nees)), "nees_thinned": nees[::10].tolist(),
            "sim_s": float(t[-1])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    jobs = [(s, a.duration, alpha) for alpha in (0.01, 1e-12) for s in a.seeds]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one_run, jobs))
    for alpha in (0.01, 1e-12):
        rs = [r for r in rows if r["alpha"] == alpha]
        label = "recovery on (alpha 0.01)" if alpha == 0.01 else "recovery off (alpha 1e-12)"
        print(f"rbpf, default route, {label}")
        for r in rs:
            print(f"  seed {r['seed']}: RMS {r['rms_m']:.1f} m, final {r['final_m']:.1f} m, "
                  f"max {r['max_m']:.1f} m, re-spreads {r['respreads']}, "
                  f"NEES mean {r['nees_mean']:.2f} ({r['sim_s']:.0f} s)")
        pooled = np.concatenate([r["nees_thinned"] for r in rs])
        n = pooled.size
        lo, hi = chi2.ppf(0.025, 2 * n) / n, chi2.ppf(0.975, 2 * n) / n
        mean = float(np.mean(pooled))
        print(f"  mean RMS {np.mean([r['rms_m'] for r in rs]):.1f} m; pooled NEES (every 10th epoch, n={n}) "
              f"{mean:.2f}, 95 % chi-square bounds [{lo:.2f}, {hi:.2f}]: "
              f"{'inside' if lo <= mean <= hi else 'outside'}")
    print(json.dumps([{k: v for k, v in r.items() if k != "nees_thinned"} for r in rows]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
