"""Horizontal consistency of every navigator on each IMU grade over Monte Carlo seeds of the default route.

One JSBSim flight of the default scenario is flown once on the free INS (filter_statistics.record_flight);
each seed regenerates the real sensor suite with the grade's IMU (trn_env.sensors, the seed's own noise,
turn-on biases and bias instabilities), the initial estimate's error and the world's fractal detail, and
runs each navigator open-loop on those frames, built as a scenario builds it (trn_env.scenario.build.
build_navigator: the IMU's specification reaches the navigators that declare they use it). GNSS is denied
from t = 0.

    PYTHONPATH=$PWD python scripts/grade_consistency.py [--grades navigation tactical consumer]
        [--navigators ins ins_tercom pmf pf rbpf] [--seeds 20] [--duration 300] [--out FILE]

Per navigator and grade, over the epochs after --from-s (15 s):
- ANEES: the horizontal NEES e' P^-1 e (2 dof) pooled over runs and epochs, thinned to decorrelated epochs
  (filter_statistics.pooled_nees_figures: every k-th epoch, k the lag where the NEES autocorrelation about
  the per-epoch mean falls below 0.1), with the two-sided 95 % chi-square bounds of that many samples;
- inside_3sigma: the fraction of all epochs with NEES <= 9 (the error inside the 3-sigma ellipse: 98.9 %
  for a consistent filter);
- rms_m: horizontal RMS error;
- verdict: the ANEES over all epochs against the thinned sample count's bounds: "inside", "conservative"
  (below) or "overconfident" (above, or fewer than 90 % of the epochs inside 3 sigma). The mean over all
  epochs is the average of the k thinned means (one per phase of the thinning grid): each has the same
  expectation (2 for a consistent filter) and about the thinned count's variance, and an average of k
  such means has no larger a variance (Cauchy-Schwarz), so the thinned count's chi-square bounds hold for
  it, while it does not depend on where the grid starts. With a long memory (k near the run's length, the
  free INS) the first phase alone is the NEES at --from-s; "verdict_first_phase" keeps that figure's
  verdict (the project's earlier criterion).

    PYTHONPATH=$PWD python scripts/grade_consistency.py --table a.json b.json    # the docs' grid
"""

from __future__ import annotations

import argparse
import ast
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import filter_statistics as fs  # noqa: E402

import trn_env.scenario.build as components  # noqa: E402
from trn_env.output.run_folder import file_target_problem
from trn_env.scenario.sections import from_dict  # noqa: E402

INSIDE_NEES = 9.0  # Mahalanobis distance 3 in 2 dof


SETTINGS: dict = {}  # --set name=value: navigator settings on top of the defaults


# per navigator: settings on top of its defaults, and the sensors it needs beyond the default scenario's. The
# acq_track flies as in its regression scenario (tests/scenarios/acq_track_short.toml): a 17 deg radar
# altimeter, air data and compass, the returns' replica, the INS as its aiding (so the IMU grade reaches it)
NAV_SETTINGS: dict = {"ins_tercom": {"remove_bias": True},
                      "acq_track": {"aiding_source": "ins", "replica_model": "return"}}
EXTRA_SENSORS: dict = {"acq_track": {"radar_altimeter": {"beamwidth_deg": 17.0}, "air_data": {},
                                     "heading": {}}}


def scenario_for(d: dict, name: str, grade: str) -> dict:
    """The default scenario's data with the grade's IMU and the navigator (its settings as the default's but
    NAV_SETTINGS and --set; its sensors with EXTRA_SENSORS)."""
    settings = {**NAV_SETTINGS.get(name, {}), **SETTINGS.get(name, {})}
    return {**d, "sensors": {**d["sensors"], **EXTRA_SENSORS.get(name, {}), "imu": {"grade": grade}},
            "navigator": {"name": name, "settings": settings}}


def run_seed(d: dict, names: list[str], grade: str, seed: int, flight, world_detail: str = "redraw") -> dict:
    """{navigator: run} of every navigator on one seed's sensor frames (the grade's IMU). Navigators that
    need more sensors (EXTRA_SENSORS) get frames of their own suite (same seed; the others' frames do not
    depend on them)."""
    _, chunks, world, the_map, truth0 = flight
    dd = scenario_for(d, names[0], grade)
    w = fs.run_world(dd, world, seed, world_detail)
    init = fs.initial_estimate(dd, truth0, seed, float(dd["initial_errors"]["position_ned_m"][0]))
    frames: dict = {}
    out = {}
    for name in names:
        key = tuple(sorted(EXTRA_SENSORS.get(name, {})))
        if key not in frames:
            frames[key] = fs.sensor_frames(scenario_for(d, name, grade), chunks, w, seed)
        out[name] = run_one(scenario_for(d, name, grade), frames[key], chunks, the_map, init, seed)
    return out


def run_one(dd: dict, frames, chunks, the_map, init, seed: int) -> dict:
    nav = components.build_navigator(from_dict(dd), the_map, np.random.default_rng([seed, 29]))
    nav.reset(init)
    t, err, cov, status = [], [], [], []
    w0 = time.perf_counter()
    for fr, ch in zip(frames, chunks, strict=True):
        est = nav.update(fr)
        t.append(est.t_s)
        err.append(fs.error_ne(est, ch))
        cov.append(est.covariance[:2, :2].copy())
        status.append(est.health.status)
    return {"t": np.array(t), "err": np.array(err), "cov": np.array(cov), "status": status,
            "warning": getattr(est.health, "consistency_warning", ""), "wall_s": time.perf_counter() - w0}


def run_nees(runs: list[dict], t_from_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(NEES (runs x epochs), squared horizontal error) after t_from_s."""
    sel = runs[0]["t"] >= t_from_s
    E = np.array([r["err"][sel] for r in runs])
    P = np.array([r["cov"][sel] for r in runs])
    det = P[..., 0, 0] * P[..., 1, 1] - P[..., 0, 1] * P[..., 1, 0]
    good = np.isfinite(det) & (det > 0.0) & (P[..., 0, 0] > 0.0)
    Pi = np.zeros_like(P)      # a covariance that is not positive definite (a diverged filter): NEES inf
    Pi[good] = np.linalg.inv(P[good])
    nees = np.einsum("rti,rtij,rtj->rt", E, Pi, E)
    nees[~good] = np.inf
    return nees, np.sum(E ** 2, axis=2)


def figures(runs: list[dict], t_from_s: float) -> dict:
    nees, e2 = run_nees(runs, t_from_s)
    return nees_summary(nees, e2, runs)


def nees_summary(nees: np.ndarray, e2: np.ndarray, runs: list[dict] | None = None) -> dict:
    """The figures of the module docstring from the runs' NEES and squared errors (runs x epochs)."""
    runs = runs or []
    out = {"runs": int(nees.shape[0]), "epochs": int(nees.shape[1]),
           "rms_m": float(np.sqrt(np.mean(e2))),
           "inside_3sigma": float(np.mean(nees <= INSIDE_NEES)),
           "run_inside_3sigma_min": float(np.min(np.mean(nees <= INSIDE_NEES, axis=1))),
           "wall_s_per_run": float(np.mean([r["wall_s"] for r in runs])) if runs else float("nan"),
           "health_consistency_warning": runs[0].get("warning", "") if runs else ""}
    if nees.shape[0] >= 2:
        p = fs.pooled_nees_figures(nees)
        out.update(anees=p["anees_thinned"], bounds_95=p["bounds_95_thinned"],
                   thinning=p["thinning_epochs"], anees_all_epochs=p["anees_pooled"],
                   runs_t_interval_95=p["runs_time_average_t_interval_95"])
        lo, hi = p["bounds_95_thinned"]
        out["thinned_samples"] = p["thinned_samples"]
        out["verdict"] = verdict(p["anees_pooled"], lo, hi, out["inside_3sigma"])
        out["verdict_first_phase"] = verdict(p["anees_thinned"], lo, hi, out["inside_3sigma"])
        out["consistent"] = out["verdict"] == "inside"
    return out


def verdict(anees: float, lo: float, hi: float, inside_3sigma: float) -> str:
    """"inside", "conservative" (ANEES below its bounds) or "overconfident" (above them, or fewer than 90 %
    of the epochs inside 3 sigma)."""
    if anees > hi or inside_3sigma < 0.9:
        return "overconfident"
    return "conservative" if anees < lo else "inside"


GRADES = ("navigation", "tactical", "consumer")
NAMES = ("ins", "ins_tercom", "pmf", "pf", "rbpf", "acq_track")


def table(paths: list[str]) -> str:
    """The markdown grids of docs/validation/navigators.md and docs/guide/navigators.md from --out files
    (figures recomputed from their runs' NEES; rows in grade, navigator order)."""
    figs: dict = {}
    for path in paths:
        for key, f in json.loads(Path(path).read_text())["figures"].items():
            nees, e2 = np.asarray(f["raw"]["nees"]), np.asarray(f["raw"]["e2"])
            figs[key] = {**nees_summary(nees, e2),
                         "health_consistency_warning": f.get("health_consistency_warning")}
    return validation_table(figs) + "\n\n" + guide_table(figs)


def _num(x: float) -> str:
    return f"{x:,.0f}" if abs(x) >= 100 else f"{x:.2f}"


def guide_table(figs: dict) -> str:
    """The guide's grid: per navigator and grade the verdict and the all-epoch ANEES (and the share inside
    3 sigma when under 90 %)."""
    rows = ["| navigator | " + " | ".join(GRADES) + " |", "|---" * (len(GRADES) + 1) + "|"]
    for n in NAMES:
        cells = []
        for g in GRADES:
            f = figs.get(f"{n}/{g}")
            if f is None or "verdict" not in f:
                cells.append("not run")
                continue
            c = f"{f['verdict']} ({_num(f['anees_all_epochs'])})"
            if f["inside_3sigma"] < 0.9:
                c += f", {100 * f['inside_3sigma']:.0f} % inside 3σ"
            cells.append(c)
        rows.append(f"| `{n}` | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def health_now(name: str, grade: str) -> str:
    """What Health.consistency_warning states for navigator `name` on the preset `grade` with this code: the
    measured direction (navigators.core.measured_consistency) and/or the small-angle warning (checked at
    120 s, the shortest of the navigators' memories), or "no"."""
    from trn_env.navigators.core.imu_spec import consistency_warning
    from trn_env.navigators.core.measured_consistency import measured_direction

    from trn_env.scenario.navigation import imu_spec
    parts = ["small-angle"] if consistency_warning(imu_spec({"grade": grade}), 120.0, name) else []
    parts += [d for d in (measured_direction(name, grade),) if d]
    return ", ".join(parts) or "no"


def validation_table(figs: dict) -> str:
    """The validation page's grid (see table)."""
    rows = ["| grade | navigator | runs | ANEES (all epochs) | 95 % bounds (thinned samples) | first-phase "
            "thinned ANEES | epochs inside 3σ | horizontal RMS | verdict | Health warns |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]

    for g in GRADES:
        for n in NAMES:
            f = figs.get(f"{n}/{g}")
            if f is None or "bounds_95" not in f:
                continue
            lo, hi = f["bounds_95"]
            rms = f["rms_m"]
            warns = health_now(n, g)
            rows.append(f"| {g} | {n} | {f['runs']} | {_num(f['anees_all_epochs'])} | [{lo:.2f}, {hi:.2f}] "
                        f"({f['thinned_samples']}) | {_num(f['anees'])} | {100 * f['inside_3sigma']:.1f} % | "
                        f"{f'{rms:,.0f}' if rms >= 100 else f'{rms:.1f}'} m | {f['verdict']} | {warns} |")
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grades", nargs="+", default=["navigation", "tactical", "consumer"])
    ap.add_argument("--navigators", nargs="+", default=["ins", "ins_tercom", "pmf", "pf", "rbpf"])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--from-s", type=float, default=15.0)
    ap.add_argument("--out", default=None)
    ap.add_argument("--flight-cache", default=None,
                    help="pickle of the recorded flight: read if it exists (same duration), else written")
    ap.add_argument("--merge", nargs="+", default=None,
                    help="pool the runs of these --out files (same duration) instead of running")
    ap.add_argument("--table", nargs="+", default=None,
                    help="print the markdown grid of these --out files instead of running")
    ap.add_argument("--set", dest="settings", action="append", default=[],
                    help="navigator.setting=value (a Python literal), e.g. pmf.span_sigmas=6")
    a = ap.parse_args(argv)
    if a.out is not None and (problem := file_target_problem(a.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    for item in a.settings:
        key, _, value = item.partition("=")
        nav, _, setting = key.partition(".")
        SETTINGS.setdefault(nav, {})[setting] = ast.literal_eval(value)
    if a.table:
        print(table(a.table))
        return 0
    if a.merge:
        pooled: dict = {}
        warn: dict = {}
        for path in a.merge:
            for key, f in json.loads(Path(path).read_text())["figures"].items():
                pooled.setdefault(key, []).append(f["raw"])
                warn[key] = f.get("health_consistency_warning", "")
        merged = {}
        for key, parts in pooled.items():
            m = min(len(p["nees"][0]) for p in parts)
            nees = np.concatenate([np.asarray(p["nees"])[:, :m] for p in parts])
            e2 = np.concatenate([np.asarray(p["e2"])[:, :m] for p in parts])
            merged[key] = {**nees_summary(nees, e2), "health_consistency_warning": warn[key]}
            print(json.dumps({key: merged[key]}), flush=True)
            merged[key]["raw"] = {"nees": nees.tolist(), "e2": e2.tolist()}
        if a.out:
            Path(a.out).write_text(json.dumps({"merged": a.merge, "figures": merged}, indent=1))
        return 0
    cache = Path(a.flight_cache) if a.flight_cache else None
    if cache is not None and cache.exists():
        duration_s, flight = pickle.loads(cache.read_bytes())
        if duration_s != a.duration:
            raise SystemExit(f"{cache}: recorded for {duration_s} s, not {a.duration} s")
    else:
        flight = fs.record_flight(duration_s=a.duration)
        if cache is not None:
            cache.write_bytes(pickle.dumps((a.duration, flight)))
    d = flight[0]
    result = {"duration_s": a.duration, "seeds": a.seeds, "seed0": a.seed0, "from_s": a.from_s, "figures": {}}
    for grade in a.grades:
        runs = {name: [] for name in a.navigators}
        for s in range(a.seeds):
            for name, run in run_seed(d, a.navigators, grade, a.seed0 + s, flight).items():
                runs[name].append(run)
            last = s == a.seeds - 1
            if a.out or last:   # after every seed: a campaign stopped early keeps the runs it finished
                result["seeds_done"] = {**result.get("seeds_done", {}), grade: s + 1}
                for name in a.navigators:
                    f = figures(runs[name], a.from_s)
                    nees, e2 = run_nees(runs[name], a.from_s)
                    f["raw"] = {"nees": nees.tolist(), "e2": e2.tolist()}
                    result["figures"][f"{name}/{grade}"] = f
                    if last:
                        print(json.dumps({f"{name}/{grade}": {k: v for k, v in f.items() if k != "raw"}}),
                              flush=True)
                if a.out:
                    Path(a.out).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
