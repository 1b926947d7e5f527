"""GNSS hand-over in closed loop (tests/scenarios/gnss_recovery_short.toml): GNSS up for 20 s, jammed
20-60 s, back from 60 s, INS + TERCOM. The error at the loss is the GNSS-aided one, the outage edges and
the navigator's loss and recovery are in the events, and after the recovery the error is back at the
GNSS level. Bounds from the receiver model (trn_env.sensors.gnss defaults: 1 m white + 1.5 m
Gauss-Markov per horizontal axis), not from an earlier run."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from trn_env.scenario.loading import load_scenario
from trn_env.sim.closed_loop import ClosedLoop

SCEN = Path(__file__).parent / "scenarios"
# 2-D error of the receiver: per axis sigma = hypot(1, 1.5) m; a Rayleigh variable exceeds 4.3 sigma with
# probability 1e-4, and the filter's average of fixes is tighter than one fix
GNSS_SIGMA_M = math.hypot(1.0, 1.5)
GNSS_BOUND_M = GNSS_SIGMA_M * math.sqrt(-2.0 * math.log(1e-4))


@pytest.fixture(scope="module")
def run():
    return ClosedLoop(load_scenario(SCEN / "gnss_recovery_short.toml")).run()


def test_error_at_loss_is_gnss_aided_and_recovery_shows(run):
    a = run.arrays
    t = a["t_s"]
    e_h = np.hypot(a["err_ned_m"][:, 0], a["err_ned_m"][:, 1])
    sig_h = np.sqrt(a["est_cov_diag"][:, 0] + a["est_cov_diag"][:, 1])
    assert e_h[0] > 20.0                                   # the initial error (30 m 1-sigma per axis)
    up = (t >= 5.0) & (t < 20.0)
    assert e_h[up].max() < GNSS_BOUND_M and sig_h[up].max() < 3.0
    k_loss = int(np.searchsorted(t, 20.0)) - 1
    assert e_h[k_loss] < GNSS_BOUND_M and sig_h[k_loss] < 3.0
    assert run.summary["horizontal_error_at_gnss_loss_m"] == e_h[k_loss]
    # the summary takes hypot(sigma_n, sigma_e), this test sqrt(var_n + var_e): equal to rounding (1 ulp
    # apart on the INS's corrected first IMU step)
    assert run.summary["horizontal_sigma_at_gnss_loss_m"] == pytest.approx(sig_h[k_loss], rel=1e-12)
    back = t >= 65.0
    assert back.sum() >= 10 and e_h[back].max() < GNSS_BOUND_M
    ev = [(te, src, msg) for te, src, msg in run.events]
    assert any(src == "gnss" and te == 20.0 and "outage begins" in msg for te, src, msg in ev)
    assert any(src == "gnss" and te == 60.0 and "outage ends" in msg for te, src, msg in ev)
    lost = [te for te, src, msg in ev if msg.startswith("GNSS lost")]
    rec = [te for te, src, msg in ev if msg.startswith("GNSS recovered")]
    assert lost == [19.0] and len(rec) == 1 and 60.0 <= rec[0] <= 61.0
    assert run.termination == "completed"
