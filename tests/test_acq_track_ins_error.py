"""acq_track with the INS as aiding: the velocity bias' growth from the IMU's specification and the centroid
fix's noise model, each against an independent Monte Carlo (navigators/acquisition_tracking/ins_error.py,
settings.py's SOURCE_DEFAULTS comment; docs/validation/navigators.md, acq_track)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators.acquisition_tracking import filter_kernels
from trn_env.navigators.acquisition_tracking.ins_error import InsVelocityErrorGrowth
from trn_env.navigators.acquisition_tracking.settings import AcqTrackConfig
from trn_env.navigators.core.imu_spec import G0_MPS2

from trn_env.scenario.navigation import imu_spec


def _route(duration_s: float = 470.0, dt_s: float = 1.0):
    """Heading (rad) and velocity (north, east m/s) of a route like the default one at 100 m/s: north, a turn
    to 85 deg at 170-225 s, then to 180 deg (south) at 310-340 s."""
    t = np.arange(dt_s, duration_s + 0.5 * dt_s, dt_s)
    psi = np.interp(t, [0, 170, 225, 310, 340, 470], np.radians([0, 0, 85, 85, 180, 180]))
    v = 100.0 * np.stack([np.cos(psi), np.sin(psi)], axis=1)
    return t, psi, v


@pytest.mark.parametrize("grade", ["navigation", "tactical"])
def test_ins_velocity_error_growth_against_monte_carlo(grade):
    """The growth's per-axis variance against 20,000 free-INS velocity errors built term by term along the
    route: a body-fixed specific-force error turned by the heading (the sum of R(psi) b dt), an Earth-fixed
    acceleration (initial tilt and a 90 deg turn's misalignment tilt, times g), the gyro biases' tilt ramp
    g eps t^2 / 2, the accelerometer noise's random walk and the initial heading error turning the velocity
    change. Compared per time on the mean of the two axes' variances (the model's heading term is the
    axes' mean) within 5 standard errors of a sample variance, sqrt(2 / n) each."""
    spec = imu_spec({"grade": grade})
    tilt0, yaw0 = 0.05e-3, 1e-3
    t, psi, v = _route()
    dt = 1.0
    n = 20_000
    rng = np.random.default_rng(7)
    b = rng.normal(0.0, spec.body_accel_sigma_mps2, (n, 2))
    a_e = G0_MPS2 * np.hypot(tilt0, spec.turn_tilt_sigma_rad(0.5 * math.pi)) * rng.normal(size=(n, 2))
    j = spec.tilt_accel_rate_sigma_mps3 * rng.normal(size=(n, 2))
    dpsi = yaw0 * rng.normal(size=n)
    growth = InsVelocityErrorGrowth(spec, tilt0, yaw0, np.array([100.0, 0.0]), 0.0)
    c = np.cos(psi) * dt
    s = np.sin(psi) * dt
    C, S = np.cumsum(c), np.cumsum(s)
    noise = np.zeros((n, 2))
    checked = 0
    for k, tk in enumerate(t):
        growth.step(float(tk), dt, float(psi[k]), v[k])
        noise += rng.normal(0.0, spec.accel_noise_density_mps2_rthz * math.sqrt(dt), (n, 2))
        if k % 47 != 46:
            continue
        # body-fixed b = (b_x, b_y) in the body frame: north/east = R(psi) b summed over the samples
        body = np.stack([C[k] * b[:, 0] - S[k] * b[:, 1], S[k] * b[:, 0] + C[k] * b[:, 1]], axis=1)
        dv = v[k] - np.array([100.0, 0.0])
        heading = dpsi[:, None] * np.array([-dv[1], dv[0]])[None, :]
        e = body + a_e * tk + 0.5 * j * tk**2 + noise + heading
        var_mc = float(np.mean(np.var(e, axis=0)))
        model = growth.growth(float(tk), v[k])
        assert abs(var_mc / model - 1.0) < 5.0 * math.sqrt(2.0 / n), (tk, var_mc, model)
        checked += 1
    assert checked >= 9


def test_growth_is_the_velocity_bias_walk():
    """Fed sample by sample as the 4-state filter's velocity-bias walk (filter_kernels.ne_predict, no fix),
    the increments rebuild the prior plus the largest growth so far; none is negative."""
    spec = imu_spec({"grade": "tactical"})
    t, psi, v = _route()
    growth = InsVelocityErrorGrowth(spec, 0.05e-3, 1e-3, v[0], 0.0)
    X = np.zeros((4, 4))
    X[2, 2] = X[3, 3] = 0.01
    top = 0.0
    for k, tk in enumerate(t):
        q = growth.step(float(tk), 1.0, float(psi[k]), v[k])
        assert q >= 0.0
        filter_kernels.ne_predict(X, 1.0, 0.0, q)
        top = max(top, growth.growth(float(tk), v[k]))
    assert X[2, 2] == pytest.approx(0.01 + top, rel=1e-12)
    assert X[3, 3] == pytest.approx(0.01 + top, rel=1e-12)


def test_ins_aiding_fix_noise_defaults():
    """INS aiding: no position walk, the fix's MAD factor alone, N epochs per fix; air data keeps its
    calibration (scale 1.25, N / 2); an explicit setting wins."""
    ins = AcqTrackConfig.build(None, {"aiding_source": "ins"})
    assert (ins.aiding_walk_m_per_sqrt_s, ins.fix_sigma_scale, ins.fix_overlap_epochs) == (0.0, 1.0, 25.0)
    air = AcqTrackConfig.build(None, {})
    assert (air.aiding_walk_m_per_sqrt_s, air.fix_sigma_scale, air.fix_overlap_epochs) == (9.0, 1.25, 12.5)
    assert AcqTrackConfig.build(None, {"aiding_source": "ins", "fix_overlap": 7.0}).fix_overlap_epochs == 7.0


def _fix_filter_mc(overlap: float, n_samples: int = 25, epochs: int = 300, runs: int = 1500):
    """Monte Carlo of the centroid filter's loop on one axis (the navigator's kernels): a constant centroid
    offset and velocity bias drawn from the prior, fixes whose errors are the mean of the transect's N
    per-sample errors (white, sigma 1 per sample, so consecutive transects share N - 1 of them), R = 1/N
    (the mean's variance) fed as overlap x R. Returns (empirical / filter variance) of the centroid and
    of the velocity bias at the end."""
    rng = np.random.default_rng(11)
    var_fix = 1.0 / n_samples
    c_err, e_err = np.empty(runs), np.empty(runs)
    X_end = None
    for r in range(runs):
        c0 = rng.normal(0.0, 30.0)
        e0 = rng.normal(0.0, 0.1)
        w = rng.normal(0.0, 1.0, epochs + n_samples)
        fix_err = np.convolve(w, np.ones(n_samples) / n_samples, mode="valid")[:epochs]
        X = np.diag([900.0, 900.0, 0.01, 0.01])
        x = np.zeros(4)   # estimate of (c_n, c_e, e_n, e_e); only the north axis carries the test
        truth_c = c0
        for k in range(epochs):
            filter_kernels.ne_predict(X, 1.0, 0.0, 0.0)
            x[0] += x[2]
            x[1] += x[3]
            truth_c += e0
            X_new, dx = np.empty((4, 4)), np.empty(4)
            z = truth_c + fix_err[k] - x[0]
            Ro = np.eye(2) * overlap * var_fix
            assert filter_kernels.ne_fix_gain(X, Ro, z, 0.0, X_new, dx)
            X = X_new
            x += dx
        c_err[r], e_err[r] = x[0] - truth_c, x[2] - e0
        X_end = X
    return float(np.mean(c_err**2) / X_end[0, 0]), float(np.mean(e_err**2) / X_end[2, 2])


@pytest.mark.slow
def test_fix_overlap_n_is_consistent_for_overlapping_transects():
    """The transects' shared samples make consecutive fix errors a moving average (autocorrelation
    1 - |k| / N, summing to N): counting N epochs per fix, the filter's centroid and velocity-bias
    variances match the Monte Carlo's (1,500 runs of 300 epochs: a ratio within 15 %, the sample variance's
    standard error 3.7 %; 400 runs gave 0.96 and 0.96), while N / 2 (the former default) is overconfident
    (ratio above 1.5; 400 runs: 1.91 and 1.92)."""
    c_ratio, e_ratio = _fix_filter_mc(25.0)
    assert 0.85 < c_ratio < 1.15 and 0.85 < e_ratio < 1.15, (c_ratio, e_ratio)
    c_half, e_half = _fix_filter_mc(12.5)
    assert c_half > 1.5 and e_half > 1.5, (c_half, e_half)
