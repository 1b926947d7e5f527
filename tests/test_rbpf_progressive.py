"""The rbpf's progressive correction (navigators.filters.rbpf_progressive: Oudjane & Musso 2000; the
conditional ESS of Zhou, Johansen & Aston 2016) against independent computations: the stage's predictive
density against scipy's multivariate normal, the conditional ESS against its definition summed by hand, the
stages of one measurement against the single Kalman update (the rbpf's own kernel) and the share against the
bisection's bracket."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from trn_env.navigators.filters import _rbpf_kernels as kern
from trn_env.navigators.filters import rbpf_progressive as prog


def _spd(rng, n, m, scale):
    a = rng.standard_normal((n, m, m)) * scale
    return np.einsum("kij,klj->kil", a, a) + 1e-3 * np.eye(m)


@pytest.mark.parametrize("m", [1, 2])
def test_predictive_loglik_is_the_gaussian_density(m):
    rng = np.random.default_rng(3)
    n = 50
    S0 = _spd(rng, n, m, 4.0)
    nu = rng.standard_normal((n, m)) * 10.0
    r_var = np.array([12.25, 3e-6])[:m]
    for share in (1.0, 0.3, 0.01):
        got = prog.predictive_loglik(S0, nu, r_var, share)
        ref = [stats.multivariate_normal(np.zeros(m), S0[k] + np.diag(r_var / share)).logpdf(nu[k])
               for k in range(n)]
        assert got == pytest.approx(np.array(ref), rel=1e-10, abs=1e-10)


def test_conditional_ess_fraction_by_its_definition():
    rng = np.random.default_rng(4)
    w = rng.random(200)
    g = rng.standard_normal(200) * 3.0
    W = w / w.sum()
    G = np.exp(g)
    ref = sum(W[k] * G[k] for k in range(200)) ** 2 / sum(W[k] * G[k] ** 2 for k in range(200))
    assert prog.conditional_ess_fraction(w, g) == pytest.approx(ref, rel=1e-12)
    # a flat likelihood keeps every particle; one particle explaining the measurement keeps its weight
    assert prog.conditional_ess_fraction(w, np.zeros(200)) == pytest.approx(1.0)
    g1 = np.full(200, -1e4)
    g1[7] = 0.0
    assert prog.conditional_ess_fraction(w, g1) == pytest.approx(W[7], rel=1e-9)
    assert prog.conditional_ess_fraction(w, np.full(200, -np.inf)) == 0.0


@pytest.mark.parametrize("shares", [(0.5, 0.5), (0.1, 0.3, 0.6), (0.02, 0.08, 0.4, 0.5)])
def test_stages_of_one_measurement_compose_to_the_single_update(shares):
    """Shares lambda_i summing to 1: the Kalman parts after the stages with R / lambda_i are the single
    update's with R, and the stages' summed log predictive densities differ from the single one by a constant
    common to the particles (the pseudo-measurements' residual)."""
    rng = np.random.default_rng(5)
    n, m = 6, 2
    a = rng.standard_normal((n, 12, 12)) * 0.3
    P0 = np.einsum("kij,klj->kil", a, a) + 0.05 * np.eye(12)
    xl0 = rng.standard_normal((n, 12))
    H = rng.standard_normal((n, m, 12))
    e = rng.standard_normal((n, m)) * 3.0
    r_var = np.array([2.0, 0.5])
    ok = np.ones(n, bool)
    xl1, P1, lw1, ll1 = xl0.copy(), P0.copy(), np.zeros(n), np.empty(n)
    kern.linear_update(xl1, P1, H, e, r_var, lw1, ok, ll1)
    xls, Ps, lws, lls = xl0.copy(), P0.copy(), np.zeros(n), np.empty(n)
    for s in shares:
        kern.linear_update(xls, Ps, H, e, r_var / s, lws, ok, lls)
    assert xls == pytest.approx(xl1, rel=1e-8, abs=1e-9)
    assert Ps == pytest.approx(P1, rel=1e-8, abs=1e-10)
    diff = lws - lw1
    assert np.ptp(diff) < 1e-9 * max(1.0, float(np.abs(diff).max()))
    # that constant is the zero residual's density, independent of the prior
    S0, nu = prog.innovations(H, xl0, P0, e)
    assert prog.predictive_loglik(S0, nu, r_var, 1.0) == pytest.approx(lw1, rel=1e-10)


def test_stage_share_keeps_the_conditional_ess_at_its_target():
    rng = np.random.default_rng(6)
    n = 2000
    S0 = np.zeros((n, 1, 1))
    nu = rng.standard_normal((n, 1)) * 30.0          # a cloud 30 m wide against a 1 m measurement
    r_var = np.array([1.0])
    w = np.ones(n)
    full = prog.conditional_ess_fraction(w, prog.predictive_loglik(S0, nu, r_var, 1.0))
    assert full < 0.1
    s = prog.stage_share(w, S0, nu, r_var, 1.0, 0.5)
    assert 0.0 < s < 1.0
    assert prog.conditional_ess_fraction(w, prog.predictive_loglik(S0, nu, r_var, s)) >= 0.5
    assert prog.conditional_ess_fraction(w, prog.predictive_loglik(S0, nu, r_var, s * 1.01)) < 0.5
    # a Gaussian cloud (variance c = 900) and a Gaussian likelihood of variance v = r / share: E[G]^2 / E[G^2]
    # = sqrt(v (v + 2 c)) / (v + c) in closed form, 0.5 at v = 0.155 c (sampling error of 2,000 particles)
    v = r_var[0] / s
    assert math.sqrt(v * (v + 1800.0)) / (v + 900.0) == pytest.approx(0.5, abs=0.05)
    # what is left, when the cloud represents it, in one stage
    assert prog.stage_share(w, S0, nu * 0.01, r_var, 0.4, 0.5) == 0.4
    # nothing representable: the smallest share
    g_hard = np.zeros((n, 1))
    g_hard[0, 0] = 0.0
    g_hard[1:, 0] = 1e6
    assert prog.stage_share(w, S0, g_hard, r_var, 1.0, 0.5) == pytest.approx(prog.MIN_SHARE)


def test_rbpf_sharp_first_update_keeps_its_particles_with_progressive_correction():
    """The acquisition cloud (5,000 particles over Table 1's 50 m) against one IRA sample (3.5 m) without
    tempering: taken at once the weights collapse onto a few dozen particles; in stages the effective sample
    size before the epoch's last resampling stays above a quarter of the cloud, and both target the same
    posterior (the estimates agree within the single update's Monte Carlo error, sigma / sqrt(ESS))."""
    from test_rbpf import _frames, _initial
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
    from trn_env.navigators.measurements.ira_seed002 import predict_ira
    from trn_env.navigators.protocol import EXTRA_ESS
    from trn_env.terrain.geodesy import euler_to_C_bn

    from trn_env import terrain

    dem = terrain.load("jacksboro")
    e0 = _initial(dem)
    y = predict_ira(dem, [e0.lat_rad], [e0.lon_rad], [e0.h_m], e0.v_ned_mps,
                    euler_to_C_bn(0.0, 0.0, e0.yaw_rad))[0]
    out = {}
    for staged in (False, True):
        nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(2), tempering="none",
                                 progressive_correction=staged)
        nav.reset(e0)
        out[staged] = (nav.update(_frames(0.0, 1.0, rng_m=float(y[0]), theta=float(y[1]))), nav.n)
    (single, n), (staged, _) = out[False], out[True]
    assert single.extra[EXTRA_ESS] < 0.02 * n
    assert staged.extra[EXTRA_ESS] > 0.25 * n
    sd = math.sqrt(max(single.covariance[0, 0], single.covariance[1, 1]))
    r_n = 6.371e6
    d_m = r_n * math.hypot(staged.lat_rad - single.lat_rad,
                           (staged.lon_rad - single.lon_rad) * math.cos(single.lat_rad))
    assert d_m < 4.0 * sd / math.sqrt(single.extra[EXTRA_ESS])
    ratio = np.trace(staged.covariance[:2, :2]) / np.trace(single.covariance[:2, :2])
    assert 0.5 < ratio < 2.0


@pytest.mark.parametrize("mode", ["acquisition", "spread", "none"])
def test_tempering_modes_inflate_the_ira_variances_when_they_say(mode):
    """_r_var_now's factor (spread / acquisition_spread_m)^2 on a cloud 28.3 m wide (sqrt(400 + 400)): 8 while
    acquiring (the acquisition cloud, or re-acquiring after a recovery) for "acquisition" and "spread", on
    the converged cloud for "spread" only, never for "none"."""
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF

    from trn_env import terrain

    nav = RaoBlackwellizedPF(dem=terrain.load("jacksboro"), rng=np.random.default_rng(0), tempering=mode,
                             terrain_model_sigma_m=0.0)
    nav._cov9 = np.diag([400.0, 400.0, 1.0, 0.1, 0.1, 0.1, 1e-6, 1e-6, 1e-6])
    base = nav.r_var
    f = (math.sqrt(800.0) / nav.acquisition_spread_m) ** 2
    for n, reacquiring, acquiring in ((nav.n_acquisition, False, True), (nav.n_particles, True, True),
                                      (nav.n_particles, False, False)):
        nav.n, nav._reacquiring = n, reacquiring
        inflated = mode == "spread" or (mode == "acquisition" and acquiring)
        assert nav._r_var_now(1500.0) == pytest.approx(base * (f if inflated else 1.0), rel=1e-12)
