"""The regularised resampling of the particle filters (navigators.core.resampling: Musso, Oudjane & Le Gland
2001) and the rbpf's use of it (regularisation "gaussian"), against independent computations: the bandwidth
against a numerical minimum of the Gaussian kernel estimate's asymptotic MISE, the kernel's moves against
chi-square bounds, and the rbpf's resampled copies identified by their ancestors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.optimize import minimize_scalar
from synthetic_terrain import wave_map
from trn_env.navigators.core.resampling import regularisation_bandwidth, regularise_gaussian
from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF


def _amise(h: float, n: int, d: int) -> float:
    """Asymptotic MISE of a Gaussian kernel estimate (bandwidth h I) of N(0, I_d) from n samples: the
    variance term R(K) / (n h^d) with R(K) = (4 pi)^(-d/2), the bias term h^4 / 4 int (laplacian f)^2 with
    int (laplacian f)^2 = d (d + 2) / 4 (4 pi)^(-d/2) for the standard normal."""
    c = (4.0 * math.pi) ** (-0.5 * d)
    return c / (n * h ** d) + 0.25 * h ** 4 * d * (d + 2) / 4.0 * c


@pytest.mark.parametrize("n,d", [(1000, 1), (1000, 2), (1000, 3), (5000, 3), (200, 5)])
def test_bandwidth_minimises_the_kernel_estimates_mise(n, d):
    best = minimize_scalar(_amise, bounds=(1e-3, 5.0), args=(n, d), method="bounded",
                           options={"xatol": 1e-10}).x
    assert regularisation_bandwidth(n, d) == pytest.approx(best, rel=1e-5)


def test_bandwidth_in_one_dimension_is_silvermans_rule():
    # Silverman's normal reference rule: 1.06 sigma n^(-1/5)
    assert regularisation_bandwidth(10_000, 1) == pytest.approx(1.0592 * 10_000 ** -0.2, rel=1e-4)
    with pytest.raises(ValueError, match="n and d"):
        regularisation_bandwidth(0, 2)


def test_kernel_moves_have_the_scaled_covariance_and_no_mean():
    rng = np.random.default_rng(5)
    cov = np.array([[400.0, 120.0, 0.0], [120.0, 100.0, -10.0], [0.0, -10.0, 25.0]])
    n, h = 100_000, 0.4
    x = regularise_gaussian(np.zeros((n, 3)), cov, h, rng)
    z = x @ np.linalg.inv(np.linalg.cholesky(h * h * cov)).T      # N(0, I) if the moves are h D eps
    q = float(np.sum(z * z))
    assert stats.chi2.ppf(5e-4, 3 * n) < q < stats.chi2.ppf(1 - 5e-4, 3 * n)
    assert np.all(np.abs(z.mean(axis=0)) < 4.0 / math.sqrt(n))
    c = np.cov(z.T)
    assert np.all(np.abs(c - np.eye(3)) < 5.0 * math.sqrt(2.0 / n))
    # a rank-deficient covariance (a flat direction) moves along its range only
    y = regularise_gaussian(np.zeros((1000, 2)), np.array([[4.0, 4.0], [4.0, 4.0 - 1e-12]]), 1.0, rng)
    assert np.max(np.abs(y[:, 0] - y[:, 1])) < 1e-4
    assert 1.5 < float(np.std(y[:, 0])) < 2.5


def _acquiring_rbpf(mode: str, seed: int, **kw) -> RaoBlackwellizedPF:
    """An rbpf with a 4,000-particle acquisition cloud (Kalman parts at the identity) to resample by hand."""
    nav = RaoBlackwellizedPF(dem=wave_map(0), rng=np.random.default_rng(seed), regularisation=mode,
                             acquisition_particles=4000, n_particles=1000, **kw)
    nav.n = 4000
    nav.xl = np.zeros((nav.n, 12))
    nav.P = np.broadcast_to(np.eye(12), (nav.n, 12, 12)).copy()
    nav._extra = {}
    nav.resamples = 0
    return nav


def _tetrahedron_cloud(nav, r_m):
    """Weights on four particles at a regular tetrahedron's vertices (circumradius r_m), the rest ~0:
    the weighted covariance is r^2 / 3 I."""
    v = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
    v *= r_m / math.sqrt(3)
    n = nav.n
    xn = nav.rng.standard_normal((n, 3)) * 1e4
    xn[:4] = v
    nav.xn = xn
    logw = np.full(n, -800.0)
    logw[:4] = 0.0
    nav.logw = logw
    return v


@pytest.mark.parametrize("mode", ["gaussian", "none"])
def test_rbpf_resampled_copies_are_moved_by_the_kernel(mode):
    nav = _acquiring_rbpf(mode, 11)
    r = 600.0
    v = _tetrahedron_cloud(nav, r)
    nav._normalise_resample(0.0, nav.logw.copy())
    assert nav.resamples == 1
    d = np.linalg.norm(nav.xn[:, None, :] - v[None, :, :], axis=2)
    anc = np.argmin(d, axis=1)
    assert np.all(np.bincount(anc, minlength=4) == nav.n // 4)     # systematic: n / 4 copies each
    if mode == "none":
        assert np.max(d.min(axis=1)) == 0.0          # the copies sit on their ancestors
        return
    # h of the independent formula (d = 3), sigma r / sqrt 3 per axis
    h = (4.0 / 5.0) ** (1.0 / 7.0) * nav.n ** (-1.0 / 7.0)
    z = (nav.xn - v[anc]) / (h * r / math.sqrt(3.0))
    q = float(np.sum(z * z))
    assert stats.chi2.ppf(5e-4, 3 * nav.n) < q < stats.chi2.ppf(1 - 5e-4, 3 * nav.n)
    assert np.all(np.abs(z.mean(axis=0)) < 4.0 / math.sqrt(nav.n))


def test_rbpf_hand_over_regularises_at_the_smaller_clouds_bandwidth():
    nav = _acquiring_rbpf("gaussian", 3, acquisition_spread_m=1e6)
    r = 600.0
    v = _tetrahedron_cloud(nav, r)
    nav._handover()
    assert nav.n == 1000
    anc = np.argmin(np.linalg.norm(nav.xn[:, None, :] - v[None, :, :], axis=2), axis=1)
    h = (4.0 / 5.0) ** (1.0 / 7.0) * 1000 ** (-1.0 / 7.0)
    z = (nav.xn - v[anc]) / (h * r / math.sqrt(3.0))
    q = float(np.sum(z * z))
    assert stats.chi2.ppf(5e-4, 3000) < q < stats.chi2.ppf(1 - 5e-4, 3000)


def test_shrunk_kernel_keeps_the_clouds_mean_and_covariance():
    # an equally weighted cloud (a resampled one) of a known Gaussian: after the shrunk kernel its sample mean
    # and covariance are those before (to sampling error), and each particle moved (diversity)
    rng = np.random.default_rng(8)
    cov = np.array([[900.0, -200.0, 0.0], [-200.0, 400.0, 30.0], [0.0, 30.0, 50.0]])
    n = 200_000
    x = rng.multivariate_normal([10.0, -5.0, 2.0], cov, size=n)
    before = x.copy()
    h = regularisation_bandwidth(1000, 3)
    regularise_gaussian(x, np.cov(before.T), h, rng, shrink=True)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(x.mean(axis=0) - before.mean(axis=0)) < 4.0 * sd * h / math.sqrt(n))
    c0, c1 = np.cov(before.T), np.cov(x.T)
    tol = 5.0 * np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov ** 2) / n) * h
    assert np.all(np.abs(c1 - c0) < tol + 1e-9)
    # the moves themselves: x - a before - (1 - a) mean ~ N(0, h^2 cov)
    a = math.sqrt(1.0 - h * h)
    z = (x - a * before - (1.0 - a) * before.mean(axis=0)) @ np.linalg.inv(np.linalg.cholesky(h * h * c0)).T
    q = float(np.sum(z * z))
    assert stats.chi2.ppf(5e-4, 3 * n) < q < stats.chi2.ppf(1 - 5e-4, 3 * n)
    with pytest.raises(ValueError, match="shrink"):
        regularise_gaussian(x, cov, 1.0, rng, shrink=True)


def test_rbpf_shrunk_regularisation_keeps_the_resampled_clouds_covariance():
    nav = _acquiring_rbpf("shrunk", 4)
    r = 600.0
    v = _tetrahedron_cloud(nav, r)
    nav._normalise_resample(0.0, nav.logw.copy())
    # the weighted cloud before: mean 0, covariance r^2 / 3 I (the tetrahedron); after: the same moments
    n = nav.n
    c = np.cov(nav.xn.T)
    assert np.all(np.abs(nav.xn.mean(axis=0)) < 4.0 * r / math.sqrt(3.0 * n))
    assert np.all(np.abs(c - r * r / 3.0 * np.eye(3)) < 5.0 * math.sqrt(2.0 / n) * r * r / 3.0)
    assert np.unique(nav.xn[:, 0]).size == n         # every copy moved
    assert np.min(np.linalg.norm(nav.xn[:, None, :] - v[None, :, :], axis=2)) > 0.0


def test_rbpf_does_not_regularise_a_re_spread_cloud_until_ok():
    from trn_env.navigators.core.recovery import IntegrityRecovery
    from trn_env.navigators.protocol import Health
    nav = _acquiring_rbpf("shrunk", 6)
    nav.health = Health(status="ok", ok=True)
    nav._recovery = IntegrityRecovery(nav.integrity, 100.0)
    nav.xn = np.zeros((nav.n, 3))
    nav.logw = np.full(nav.n, -math.log(nav.n))
    nav._respread(0.0)                                   # a recovery: the cloud re-spread
    assert nav._reacquiring
    v = _tetrahedron_cloud(nav, 600.0)
    nav._normalise_resample(0.0, nav.logw.copy())
    d = np.linalg.norm(nav.xn[:, None, :] - v[None, :, :], axis=2)
    assert np.max(d.min(axis=1)) == 0.0                  # copies left on their ancestors: no kernel
