"""Consistency of the PMF's and the PF's reported horizontal covariance: the Monte-Carlo-averaged NEES.

A small fixed-seed version of scripts/filter_statistics.py "nees" (100 runs of 3 min): the default
scenario's JSBSim flight recorded once (120 s), then per run fresh sensor noise, world detail (the 30 m
fractal terrain the 3" map lacks) and initial error (the scenario's 30 m per axis, 0.1 m/s), the filters
built as the scenario builds them (its IMU's specification, its barometer's lag) run open-loop on the frames,
GNSS denied (the script's own functions).

At each epoch after T_FROM_S the NEES e' P^-1 e (2 degrees of freedom) averaged over the N runs is, for a
consistent filter, chi2(2N) / N; the test computes its two-sided 99 % interval and asks (a) that the
fraction of epochs inside it is at least the binomial 1 % quantile of a 99 % coverage over the epochs
thinned to one every THIN_S s (neighbouring epochs of one run are strongly correlated: the errors' own
correlation time is tens of seconds), and (b) that the pooled ANEES over runs and epochs lies inside the
99 % interval of the mean of the N runs' time averages (a t interval from their spread, which holds with
correlated epochs)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import filter_statistics as fs  # noqa: E402

DURATION_S = 120.0
SIGMA0_M = 30.0
T_FROM_S = 20.0
THIN_S = 10.0
pytestmark = pytest.mark.slow        # a Monte Carlo over RUNS flights: the slow group (pytest -m slow)

RUNS = 8


@pytest.fixture(scope="module")
def mc():
    flight = fs.record_flight(duration_s=DURATION_S)
    res = fs.monte_carlo(RUNS, DURATION_S, SIGMA0_M, {"pmf": ("pmf", {}), "pf": ("pf", {})}, seed0=500,
                         flight=flight, log=None)
    out = {}
    for name, runs in res.items():
        nees = [np.einsum("ti,tij,tj->t", r["err"], np.linalg.inv(r["cov"]), r["err"]) for r in runs]
        out[name] = [(r["t"], n) for r, n in zip(runs, nees, strict=True)]
    return out


def _figures(mc, name):
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
    return anees[thin], (lo, hi), inside, least, pooled, half


@pytest.mark.parametrize("name", ["pmf", "pf"])
def test_monte_carlo_nees_inside_its_chi_square_bounds_at_every_epoch(mc, name):
    """(a): the thinned epochs' ANEES inside the 99 % interval, all but the binomial allowance."""
    anees, _, inside, least, _, _ = _figures(mc, name)
    assert inside.mean() >= least, (inside.mean(), least, anees)


@pytest.mark.parametrize("name", ["pmf", "pf"])
def test_monte_carlo_nees_pooled_inside_its_interval(mc, name):
    """(b): the pooled ANEES inside the 99 % interval of the mean of the runs' time averages."""
    _, _, _, _, pooled, half = _figures(mc, name)
    assert abs(pooled - 2.0) <= half, (pooled, half)
