"""Consistency of the PMF's and the PF's reported horizontal covariance: the Monte-Carlo-averaged NEES.

A small fixed-seed version of scripts/filter_statistics.py "nees" (100 runs of the default JSBSim flight):
a kinematic level flight (trn_env.flight.kinematic) at 85 m/s, ~1,500 m above the rough start of the
default route; the world is the 3" DEM refined to 30 m with fractal detail drawn per run, the map the 3"
DEM; real sensor models (navigation IMU, IRA, baro), the initial error N(0, 30 m) per axis and the INS
started with the true velocity plus N(0, 0.1 m/s) per axis (the default scenario's initial errors). Every
run has its own noise, world detail and initial error; the filters are the defaults.

At each epoch after T_FROM_S the NEES e' P^-1 e (2 degrees of freedom) averaged over the N runs is, for a
consistent filter, chi2(2N) / N; the test computes its two-sided 99 % interval and asks (a) that the
fraction of epochs inside it is at least the binomial 1 % quantile of a 99 % coverage over the epochs
thinned to one every THIN_S s (neighbouring epochs of one run are strongly correlated: the errors' own
correlation time is tens of seconds), and (b) that the pooled ANEES over runs and epochs lies inside the
99 % interval of the mean of the N runs' time averages (a t interval from their spread, which holds with
correlated epochs). Before the INS reset fix and the PMF's velocity offset, the PMF's pooled ANEES was 1.8
with a per-epoch fraction of 0.7 on the default flight (README)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import terrain
from navigators import registry
from navigators.frames import SensorFrames
from navigators.protocol import Estimate
from terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from terrain.refine import refine
from trn_env.flight.kinematic import KinematicTruth, Segment
from trn_env.sensors.baro import BaroConfig, sample_baro
from trn_env.sensors.imu import ImuConfig, sample_imu
from trn_env.sensors.ira import IraConfig, sample_ira

LAT0, LON0, HEADING = math.radians(36.49), math.radians(-84.37), math.radians(8.0)
H0_M, SPEED_MPS, DURATION_S = 2200.0, 85.0, 100.0
SIGMA0_M, SIGMA_V0_MPS = 30.0, 0.1
T_FROM_S = 30.0
THIN_S = 10.0
RUNS = 10


@pytest.fixture(scope="module")
def mc():
    the_map = terrain.load("jacksboro")
    region = (LAT0 - 0.003, LAT0 + math.radians(0.09), LON0 - math.radians(0.03), LON0 + math.radians(0.03))
    kin = KinematicTruth(LAT0, LON0, H0_M, SPEED_MPS, HEADING, [Segment("straight", DURATION_S)],
                         rate_hz=100.0)
    truth0 = kin.advance(1)           # the reset state; the sensors sample from the next step on
    chunks = [kin.advance(99)]
    while chunks[-1].t_s[-1] < DURATION_S - 1e-9:
        chunks.append(kin.advance(100))
    out = {"pmf": [], "pf": []}
    for r in range(RUNS):
        world = refine(the_map, spacing_m=30.0, seed=np.random.default_rng([r, 31]), region=region)
        frames = _frames(chunks, world, r)
        init = _initial(truth0, np.random.default_rng([r, 23]))
        for name in out:
            kw = {"rng": np.random.default_rng([r, 29])} if name == "pf" else {}
            nav = registry.create(name, dem=the_map, **kw)
            out[name].append(_run(nav, init, chunks, frames))
    return out


def _frames(chunks, world, seed):
    r_imu, r_ira, r_baro = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 5]).spawn(3))
    imu_cfg, ira_cfg, baro_cfg = ImuConfig(), IraConfig(), BaroConfig()
    si = sa = sb = None
    frames = []
    for ch in chunks:
        imu, si = sample_imu(ch, None, r_imu, imu_cfg, si)
        ira, sa = sample_ira(ch, world, r_ira, ira_cfg, sa)
        baro, sb = sample_baro(ch, world, r_baro, baro_cfg, sb)
        frames.append(SensorFrames(float(ch.t_s[0]) - 0.01, float(ch.t_s[-1]), imu=imu, ira=ira, baro=baro))
    return frames


def _radii(lat, h):
    return meridian_radius_m(lat) + h, (prime_vertical_radius_m(lat) + h) * math.cos(lat)


def _initial(ch, rng):
    lat, lon, h = float(ch.lat_rad[0]), float(ch.lon_rad[0]), float(ch.h_msl_m[0])
    rn, re = _radii(lat, h)
    e = rng.normal(0.0, SIGMA0_M, 2)
    v = ch.v_ned_mps[0] + np.append(rng.normal(0.0, SIGMA_V0_MPS, 2), 0.0)
    cov = np.diag([SIGMA0_M**2, SIGMA0_M**2, 15.0**2, SIGMA_V0_MPS**2, SIGMA_V0_MPS**2, 0.01, 1e-8, 1e-8,
                   1e-6])
    return Estimate(float(ch.t_s[0]), lat + e[0] / rn, lon + e[1] / re, h, v, float(ch.roll_rad[0]),
                    float(ch.pitch_rad[0]), float(ch.yaw_rad[0]), cov)


def _run(nav, init, chunks, frames):
    nav.reset(init)
    t, nees = [], []
    for fr, ch in zip(frames, chunks, strict=True):
        est = nav.update(fr)
        lat, lon, h = float(ch.lat_rad[-1]), float(ch.lon_rad[-1]), float(ch.h_msl_m[-1])
        assert est.t_s == pytest.approx(float(ch.t_s[-1]))
        rn, re = _radii(lat, h)
        e = np.array([(est.lat_rad - lat) * rn, (est.lon_rad - lon) * re])
        t.append(est.t_s)
        nees.append(float(e @ np.linalg.solve(est.covariance[:2, :2], e)))
    return np.array(t), np.array(nees)


@pytest.mark.parametrize("name", ["pmf", "pf"])
def test_monte_carlo_nees_inside_its_chi_square_bounds(mc, name):
    t = mc[name][0][0]
    sel = t >= T_FROM_S
    nees = np.array([r[1][sel] for r in mc[name]])          # runs x epochs
    n = nees.shape[0]
    anees = nees.mean(axis=0)
    lo, hi = stats.chi2.ppf([0.005, 0.995], 2 * n) / n
    ts = t[sel]
    thin = np.isclose(np.mod(ts - ts[0] + 1e-6, THIN_S), 0.0, atol=1e-3)
    e_thin = int(thin.sum())
    inside = (anees[thin] >= lo) & (anees[thin] <= hi)
    least = stats.binom.ppf(0.01, e_thin, 0.99) / e_thin
    per_run = nees.mean(axis=1)
    half = stats.t.ppf(0.995, n - 1) * per_run.std(ddof=1) / math.sqrt(n)
    pooled = float(per_run.mean())
    print(f"{name}: {n} runs, pooled ANEES {pooled:.2f} (99 % interval of a consistent filter 2 +- "
          f"{half:.2f}), epochs inside [{lo:.2f}, {hi:.2f}]: {inside.mean():.2f} (least {least:.2f}) of "
          f"{e_thin}, all epochs {np.mean((anees >= lo) & (anees <= hi)):.2f}")
    assert inside.mean() >= least, (inside.mean(), least, anees[thin])
    assert abs(pooled - 2.0) <= half, (pooled, half)
