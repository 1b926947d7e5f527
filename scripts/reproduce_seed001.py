"""Reproduce seed 001 chapter 5 (the radar-altimeter flight) with the acquisition-and-tracking TRN.

    python scripts/reproduce_seed001.py --out out/seed001            (about 5-10 min on a quiet machine)
    python scripts/reproduce_seed001.py --duration 300 --out /tmp/s1 (a shorter flight)

Set-up (the thesis' where it says, ours marked): the King Air (JSBSim) stands in for the DC-3 at about
80 m/s, 1,050 s of flight sampled at 1 s (~84 km; a lawnmower of north-south legs over the bundled real
Jacksboro DEM, ours), 600 m above the ground (ours; the thesis gives no height), a pulse radar altimeter with
a 17 deg beam returning the shortest range in its cone (trn_env.sensors.radar_altimeter; the replicas model
it: replica_model = "return", the replica samples the map where the predicted shortest return lies;
navigators/acquisition_tracking/beam.py), IRS-grade speed and
heading aiding (aiding_source = "ins": a navigation-grade strapdown INS's velocity; GNSS resets it until
10 s, then it is denied), a map with SRTM-class errors (the real 3" DEM as the navigator's map with a
horizontal shift of 20 m CE90 and a correlated vertical error of 16 m LE90, while the world carries 30 m
fractal detail), transects of N = 25 and N = 50. The truth is flown once (guidance on GNSS) and every
variant replays the same sensor frames (a navigator runs on logs), so the variants differ only in their
settings. Two more flights: a speed ramp (70 -> 100 m/s over 300 s, straight) for the unaided speed loop,
and a flat world for the SNR.

Shown (table + plots in --out): IRS-only dead reckoning drifts; the aided tracker stays in lock with no
drift; the unaided speed loop loses lock on the speed ramp while the aided one does not; roll compensation
(navigator setting roll_compensation) changes the position accuracy (the thesis: 20-65 % better); over
flat terrain the SNR falls below 5 dB and the tracker reports out of lock instead of a wrong position.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy.stats import t as student_t
from trn_env.navigators import registry
from trn_env.terrain.geodesy import latlon_to_ned_offset

from trn_env import terrain
from trn_env.output.run_folder import folder_problem
from trn_env.scenario import build as components
from trn_env.scenario.loading import read_scenario_file, validate
from trn_env.sim.closed_loop import ClosedLoop

LEGS_LON = (-84.39, -84.34, -84.29, -84.24)
LAT_S, LAT_N = 36.465, 36.715
AGL_M = 600.0
TAS_MPS = 80.0
WEAVE_KM = 3.0  # S-turns along each leg: a waypoint every 3 km, alternately WEAVE_OFFSET_DEG east / west
WEAVE_OFFSET_DEG = 0.006  # of longitude (~540 m): track changes of ~+-20 deg, banks of 15-25 deg
# IRS grade (ours, from the thesis' own figure): its IRS-only dead reckoning drifts almost 3 km in 1,050 s,
# which the appendix's intermediate grade gives (0.1-1 mg, 0.1 deg/h); we take 0.5 mg and 0.1 deg/h.
IRS_IMU = {
    "grade": "navigation",
    "accel_bias_mps2": 0.5e-3 * 9.80665,
    "gyro_bias_rps": math.radians(0.1) / 3600.0,
}
# the tracker's aiding model for that IRS: a faster-drifting velocity than the navigator's navigation-grade
# defaults (aiding_source "ins"): the references follow it faster and the dead reckoning walks more
IRS_SETTINGS = {
    "aiding_speed_sigma_mps": 0.5,
    "aiding_heading_sigma_deg": 0.3,
    "reference_gain": 0.05,
    "aiding_walk_m_per_sqrt_s": 3.0,
    # the IRS's velocity error is a north/east vector (reference_frame "ne", the default with INS aiding)
    # that its 0.5 mg accelerometer bias ramps at up to 0.005 m/s^2: a random walk of 0.1 m/s/sqrt(s)
    # covers 0.5 m/s in 25 s
    "aiding_bias_walk_mps_per_sqrt_s": 0.1,
}


class Recorder:
    """Wraps a navigator and keeps every SensorFrames it is given (the log a replay runs on)."""

    def __init__(self, nav):
        self.nav = nav
        self.name = nav.name
        self.frames = []

    def reset(self, initial):
        self.nav.reset(initial)

    def update(self, frames):
        self.frames.append(copy.copy(frames))
        return self.nav.update(frames)


def _scenario(duration_s: float, seed: int, waypoints=None, map_errors: bool = True) -> dict:
    data, _ = read_scenario_file("acq_track")
    data = copy.deepcopy(data)
    data["name"] = "seed001_reproduction"
    data["seed"] = seed
    data["duration_s"] = duration_s
    if waypoints is None:
        waypoints = []
        n_weave = max(int((LAT_N - LAT_S) * 111.0 / WEAVE_KM), 1)
        for k, lon in enumerate(LEGS_LON):
            lats = np.linspace(LAT_S, LAT_N, n_weave + 1)
            if k % 2:
                lats = lats[::-1]
            for j, la in enumerate(lats):
                off = 0.0 if j in (0, n_weave) else WEAVE_OFFSET_DEG * (1 if j % 2 else -1)
                waypoints.append({"lat_deg": float(la), "lon_deg": lon + off, "h_agl_m": AGL_M})
    data["route"] = {"tas_mps": TAS_MPS, "waypoints": waypoints}
    w0, w1 = waypoints[0], waypoints[1]
    data["initial"] = {
        "lat_deg": w0["lat_deg"],
        "lon_deg": w0["lon_deg"],
        "h_agl_m": AGL_M,
        "tas_mps": TAS_MPS,
        "heading_deg": math.degrees(
            math.atan2(
                (w1["lon_deg"] - w0["lon_deg"]) * math.cos(math.radians(w0["lat_deg"])),
                w1["lat_deg"] - w0["lat_deg"],
            )
        )
        % 360.0,
    }
    data["gnss"] = {"outages": []}  # guidance flies on GNSS; the replays deny it after 10 s
    data["sensors"].pop("ira", None)
    data["sensors"]["imu"] = dict(IRS_IMU)
    data["navigator"] = {"name": "acq_track", "rate_hz": 1.0, "settings": {"transect_samples": 25}}
    if map_errors:  # SRTM-class: 20 m CE90 (sigma 9.3 m per axis), 16 m LE90 (sigma 9.7 m)
        rng = np.random.default_rng(seed + 1000)
        sh = rng.normal(0.0, 20.0 / 2.1460, 2)
        data["terrain"]["map"] = {
            "dem": "jacksboro",
            "error_model": {
                "random_sigma_m": 16.0 / 1.6449,
                "correlation_length_m": 500.0,
                "shift_n_m": float(sh[0]),
                "shift_e_m": float(sh[1]),
            },
        }
    return data


def fly(data: dict, commander=None, dems=None):
    """Fly the scenario; returns (logged frames, truth arrays at 1 Hz)."""
    sc = validate(data, source="reproduce_seed001")
    loop = ClosedLoop(sc, pipeline=False, commander=commander, dems=dems, log_sensors=False)
    rec = Recorder(loop._stage.navigator)
    loop._stage.navigator = rec
    res = loop.run()
    a = res.arrays
    truth = {
        k: a[k]
        for k in (
            "t_s",
            "true_lat_rad",
            "true_lon_rad",
            "true_h_msl_m",
            "true_v_ned_mps",
            "true_roll_rad",
            "true_pitch_rad",
            "true_yaw_rad",
        )
    }
    return rec.frames, truth, loop


def replay(frames, truth, dem, name: str, t_deny_s: float = 10.0, **settings):
    """Run navigator `name` on the frames with GNSS removed from t_deny_s on; per-update arrays."""
    nav = registry.create(name, dem=dem, **settings)
    t = truth["t_s"]
    from trn_env.navigators.protocol import Estimate

    cov = np.diag([30.0**2, 30.0**2, 15.0**2, 0.01, 0.01, 0.01, 2.5e-9, 2.5e-9, 1e-6])
    v0 = truth["true_v_ned_mps"][0]
    nav.reset(
        Estimate(
            float(t[0]),
            float(truth["true_lat_rad"][0]),
            float(truth["true_lon_rad"][0]),
            float(truth["true_h_msl_m"][0]),
            np.asarray(v0, float),
            float(truth["true_roll_rad"][0]),
            float(truth["true_pitch_rad"][0]),
            float(truth["true_yaw_rad"][0]),
            cov,
        )
    )
    rows = []
    for fr in frames:
        fr = copy.copy(fr)
        if fr.gnss is not None and fr.t_end_s > t_deny_s + 1e-9:
            fr.gnss = None
        est = nav.update(fr)
        k = int(np.argmin(np.abs(t - est.t_s)))
        dn, de = latlon_to_ned_offset(
            truth["true_lat_rad"][k],
            truth["true_lon_rad"][k],
            truth["true_h_msl_m"][k],
            est.lat_rad,
            est.lon_rad,
        )
        vt = truth["true_v_ned_mps"][k]
        x = est.extra
        rows.append(
            (
                est.t_s,
                math.hypot(dn, de),
                math.sqrt(est.covariance[0, 0] + est.covariance[1, 1]),
                float(est.health.ok),
                x.get("snr_db", math.nan),
                x.get("tracked_speed_mps", math.nan),
                math.hypot(vt[0], vt[1]),
                float(x.get("lock_state") == "tracking"),
            )
        )
    r = np.array(rows)
    return {
        "t_s": r[:, 0],
        "err_m": r[:, 1],
        "sigma_m": r[:, 2],
        "ok": r[:, 3],
        "snr_db": r[:, 4],
        "speed_mps": r[:, 5],
        "true_speed_mps": r[:, 6],
        "tracking": r[:, 7],
    }


def _stats(run: dict, t_from: float = 10.0) -> dict:
    m = run["t_s"] >= t_from
    e = run["err_m"][m]
    dist_km = np.concatenate([[0.0], np.cumsum(0.5 * (run["true_speed_mps"][1:] + run["true_speed_mps"][:-1])
                                               * np.diff(run["t_s"]))]) / 1000.0
    within = run["err_m"][m] <= 3.0 * run["sigma_m"][m]
    return {
        "rms_m": float(np.sqrt(np.mean(e**2))),
        "max_m": float(e.max()),
        "final_m": float(e[-1]),
        "in_lock_fraction": float(np.mean(run["tracking"][m])),
        "within_3sigma": float(np.mean(within)),
        "drift_last_third_m": float(np.mean(e[-len(e) // 3 :]) - np.mean(e[len(e) // 3 : 2 * len(e) // 3])),
        # the error's least-squares slope against the distance flown (m per km): ~0 without drift
        "error_slope_m_per_km": float(np.polyfit(dist_km[m], e, 1)[0]) if m.sum() > 2 else math.nan,
    }


def _finite(x):
    """JSON-safe copy: non-finite floats -> None."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/seed001"))
    ap.add_argument("--duration", type=float, default=1050.0, help="main flight, s (thesis: 1,050 samples)")
    ap.add_argument("--ramp-duration", type=float, default=300.0)
    ap.add_argument("--seed", type=int, default=0, help="seed of the first main flight, the ramp and flat")
    ap.add_argument("--seeds", type=int, default=3, help="main flights (seeds seed, seed + 1, ...)")
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--replica-model", default="return", choices=("return", "footprint", "plumb"))
    args = ap.parse_args(argv)
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    args.out.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    results: dict = {}

    # 1. the main flight (one per seed), replayed by every variant
    irs = dict(aiding_source="ins", replica_model=args.replica_model, **IRS_SETTINGS)
    no_roll = {"roll_compensation": False}
    variants = {
        "irs_only (ins, free inertial)": ("ins", {}),
        "aided N=25": ("acq_track", dict(irs, transect_samples=25)),
        "aided N=50": ("acq_track", dict(irs, transect_samples=50)),
        "aided N=25, no roll compensation": ("acq_track", dict(irs, transect_samples=25, **no_roll)),
        "aided N=50, no roll compensation": ("acq_track", dict(irs, transect_samples=50, **no_roll)),
        "air data + compass N=25": ("acq_track", dict(transect_samples=25, replica_model=args.replica_model)),
    }
    per_seed = []
    runs = None
    for sd in range(args.seed, args.seed + args.seeds):
        frames, truth, loop = fly(_scenario(args.duration, sd))
        seed_runs = {k: replay(frames, truth, loop.map_dem, nav, **kw) for k, (nav, kw) in variants.items()}
        roll_deg = np.degrees(np.abs(truth["true_roll_rad"]))
        st = {k: _stats(v) for k, v in seed_runs.items()}
        st["roll_over_half_beam_fraction"] = float(np.mean(roll_deg > 8.5))
        for n in (25, 50):
            on = st[f"aided N={n}"]["rms_m"]
            off = st[f"aided N={n}, no roll compensation"]["rms_m"]
            st[f"roll_compensation_gain_N{n}"] = (off - on) / off
        per_seed.append(st)
        if runs is None:
            runs, truth0 = seed_runs, truth
        print(f"main flight seed {sd} done ({time.perf_counter() - wall0:.0f} s)", flush=True)
    results["main_flight"] = per_seed[0]
    results["main_flight_per_seed"] = per_seed
    agg = {}
    for k in variants:
        for f in ("rms_m", "final_m", "max_m", "in_lock_fraction", "within_3sigma", "drift_last_third_m",
                  "error_slope_m_per_km"):
            x = np.array([p[k][f] for p in per_seed])
            agg[f"{k}: {f}"] = {"mean": float(x.mean()), "std": float(x.std(ddof=1)) if x.size > 1 else 0.0}
    for n in (25, 50):
        # paired over the seeds (the same flights with and without): mean gain and its 95 % t interval
        g = np.array([p[f"roll_compensation_gain_N{n}"] for p in per_seed])
        sd = float(g.std(ddof=1)) if g.size > 1 else 0.0
        half = float(student_t.ppf(0.975, g.size - 1)) * sd / math.sqrt(g.size) if g.size > 1 else math.nan
        agg[f"roll_compensation_gain_N{n}"] = {
            "mean": float(g.mean()),
            "std": sd,
            "ci95": [float(g.mean()) - half, float(g.mean()) + half],
            "min": float(g.min()),
            "max": float(g.max()),
            "per_seed": g.tolist(),
        }
    results["main_flight_over_seeds"] = agg
    truth = truth0

    # 2. speed ramp (straight, 70 -> 100 m/s): unaided vs aided speed loop
    lon = -84.30
    wps = [
        {"lat_deg": LAT_S, "lon_deg": lon, "h_agl_m": AGL_M},
        {"lat_deg": LAT_N, "lon_deg": lon, "h_agl_m": AGL_M},
    ]
    rdata = _scenario(args.ramp_duration, args.seed, waypoints=wps)
    rdata["initial"]["tas_mps"] = 70.0
    ramp_t0 = 60.0

    def ramp_commander(est, t_s):
        tas = 70.0 + 30.0 * min(max((t_s - ramp_t0) / (args.ramp_duration - ramp_t0 - 20.0), 0.0), 1.0)
        return components.track_agl_targets(0.0, AGL_M, tas)

    rframes, rtruth, rloop = fly(rdata, commander=ramp_commander)
    rruns = {
        "unaided N=25": replay(
            rframes, rtruth, rloop.map_dem, "acq_track", aiding=False, replica_model="footprint"
        ),
        "aided N=25": replay(rframes, rtruth, rloop.map_dem, "acq_track", transect_samples=25, **irs),
    }
    results["speed_ramp"] = {k: _stats(v) for k, v in rruns.items()}
    for k, v in rruns.items():
        before = (v["t_s"] > 30.0) & (v["t_s"] < ramp_t0)
        during = v["t_s"] >= ramp_t0 + 20.0
        results["speed_ramp"][k]["in_lock_before_ramp"] = float(np.mean(v["tracking"][before]))
        results["speed_ramp"][k]["in_lock_during_ramp"] = float(np.mean(v["tracking"][during]))
        err = np.abs(v["speed_mps"] - v["true_speed_mps"])
        rms = float(np.sqrt(np.mean(err[during] ** 2)))
        results["speed_ramp"][k]["speed_error_rms_during_ramp_mps"] = rms

    # 3. flat terrain: SNR < 5 dB, out of lock instead of a wrong position
    base = terrain.load("jacksboro")
    flat = base.with_heights(np.full_like(base.heights_m, 300.0), name="flat")
    fdata = _scenario(200.0, args.seed, waypoints=wps, map_errors=False)
    fframes, ftruth, floop = fly(fdata, dems=(flat, flat))
    frun = replay(fframes, ftruth, flat, "acq_track", transect_samples=25, **irs)
    m = frun["t_s"] > 40.0
    results["flat_terrain"] = {
        "snr_db_median": float(np.nanmedian(frun["snr_db"][m])),
        "fraction_reported_ok": float(np.mean(frun["ok"][m])),
        "fraction_tracking": float(np.mean(frun["tracking"][m])),
        "error_final_m": float(frun["err_m"][-1]),
        "sigma_final_m": float(frun["sigma_m"][-1]),
    }
    results["wall_time_s"] = time.perf_counter() - wall0

    # table
    last = args.seed + args.seeds - 1
    print(f"seed 001 reproduction: {args.duration:.0f} s main flights, seeds {args.seed}..{last}")
    print(f"{'variant':44s} {'RMS m':>8s} {'max m':>8s} {'final m':>8s} {'in lock':>8s} {'<=3sig':>7s}")
    for section in ("main_flight", "speed_ramp"):
        for k, s_ in results[section].items():
            if not isinstance(s_, dict):
                continue
            print(
                f"{section[:5] + ': ' + k:44s} {s_['rms_m']:8.1f} {s_['max_m']:8.1f} {s_['final_m']:8.1f} "
                f"{s_['in_lock_fraction']:8.2f} {s_['within_3sigma']:7.2f}"
            )
    print("over the seeds (mean +- std):")
    for k in variants:
        a_ = [agg[f"{k}: {f}"] for f in ("rms_m", "final_m", "max_m")]
        lk, w3 = agg[f"{k}: in_lock_fraction"], agg[f"{k}: within_3sigma"]
        print(f"  {k:42s} RMS {a_[0]['mean']:7.1f} +- {a_[0]['std']:5.1f}  final {a_[1]['mean']:7.1f} "
              f"+- {a_[1]['std']:5.1f}  max {a_[2]['mean']:7.1f} +- {a_[2]['std']:5.1f}  in lock "
              f"{lk['mean']:.2f} +- {lk['std']:.2f}  <=3sig {w3['mean']:.2f}  slope "
              f"{agg[f'{k}: error_slope_m_per_km']['mean']:+.2f} m/km")
    for n in (25, 50):
        g = agg[f"roll_compensation_gain_N{n}"]
        print(
            f"roll compensation gain N={n}: {100 * g['mean']:+.0f} % (95 % CI {100 * g['ci95'][0]:+.0f} .. "
            f"{100 * g['ci95'][1]:+.0f} %), std {100 * g['std']:.0f} % over {args.seeds} seeds (per seed "
            f"{', '.join(f'{100 * x:+.0f}' for x in g['per_seed'])} %; "
            f"|roll| > 8.5 deg for {100 * per_seed[0]['roll_over_half_beam_fraction']:.0f} % of the flight)"
        )
    for k, v in results["speed_ramp"].items():
        print(f"speed ramp, {k}: in lock {100 * v['in_lock_before_ramp']:.0f} % before the ramp, "
              f"{100 * v['in_lock_during_ramp']:.0f} % during it; tracked speed error "
              f"{v['speed_error_rms_during_ramp_mps']:.2f} m/s RMS during it")
    print("flat terrain:", json.dumps(_finite({k: round(v, 2) for k, v in results["flat_terrain"].items()})))
    (args.out / "results.json").write_text(json.dumps(_finite(results), indent=1))

    if not args.no_plots:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(2, 2, figsize=(13, 8))
        for k, v in runs.items():
            ax[0, 0].plot(v["t_s"], v["err_m"], label=k)
        ax[0, 0].set(
            xlabel="t (s)",
            ylabel="horizontal error (m)",
            yscale="log",
            title="main flight: IRS-only drift vs aided tracker",
        )
        ax[0, 0].legend(fontsize=7)
        for k, v in rruns.items():
            ax[0, 1].plot(v["t_s"], v["speed_mps"] - v["true_speed_mps"], label=f"{k} tracked - true")
            ax[0, 1].plot(v["t_s"], 5.0 * (1 - v["ok"]) - 8.0, lw=0.8, label=f"{k} out of lock (step)")
        ax[0, 1].set(xlabel="t (s)", ylabel="speed error (m/s)", title="speed ramp 70 -> 100 m/s")
        ax[0, 1].legend(fontsize=7)
        for n in (25, 50):
            for k in (f"aided N={n}", f"aided N={n}, no roll compensation"):
                ax[1, 0].plot(runs[k]["t_s"], runs[k]["err_m"], label=k)
        ax[1, 0].set(xlabel="t (s)", ylabel="horizontal error (m)", title="roll compensation")
        ax[1, 0].legend(fontsize=7)
        ax[1, 1].plot(frun["t_s"], frun["snr_db"], label="terrain SNR (dB)")
        ax[1, 1].axhline(5.0, color="k", ls="--", label="5 dB")
        ax[1, 1].plot(frun["t_s"], 10 * frun["ok"], label="health ok x 10")
        ax[1, 1].set(xlabel="t (s)", title="flat terrain")
        ax[1, 1].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(args.out / "seed001.png", dpi=110)
    print(f"written {args.out}/results.json" + ("" if args.no_plots else f", {args.out}/seed001.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
