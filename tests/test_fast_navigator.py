"""The fast tier's navigator kernels (trn_env.env.fast.navigator) against independent computations: the
Kalman update against numpy's algebra, the innovation test and recovery against the full navigator's own
classes, and the TERCOM search against direct map look-ups and known shifts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators.core.recovery import IntegrityRecovery
from trn_env.navigators.integrity.innovation_monitor import InnovationMonitor
from trn_env.terrain import kernels

from trn_env.env.fast import navigator as nv
from trn_env.env.fast import state as S
from trn_env.env.fast.vector_env import TerrainNavFastVectorEnv

BASIN = dict(scenario="basin_route", agl_min_m=300.0, agl_max_m=900.0)
P_COLS = (S.P00, S.P01, S.P02, S.P11, S.P12, S.P22)


def _set_cov(X, i, P):
    for col, (a, b) in zip(P_COLS, [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)], strict=True):
        X[i, col] = P[a, b]


def _cov(X, i):
    P = np.empty((3, 3))
    for col, (a, b) in zip(P_COLS, [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)], strict=True):
        P[a, b] = P[b, a] = X[i, col]
    return P


@pytest.mark.parametrize("lag", [0.0, 19.5])
def test_measurement_update_is_the_kalman_update(lag):
    """z = p - lag v + noise per axis: the kernel's gain, state feedback and covariance equal numpy's
    K = P H^T (H P H^T + R)^-1, P+ = (I - K H) P on a random positive definite P."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(3, 3)) * np.array([30.0, 0.5, 0.01])[:, None]
    P = A @ A.T + np.diag([1.0, 1e-3, 1e-6])
    X = np.zeros((2, S.N_STATE))
    _set_cov(X, 1, P)
    X[1, [S.EP_N, S.EP_E, S.EV_N, S.EV_E]] = [12.0, -7.0, 0.3, -0.2]
    z = np.array([15.0, -4.0])
    r_var = 100.0
    nv.measurement_update(X, 1, z[0], z[1], 1.0, -lag, r_var)
    H = np.array([[1.0, -lag, 0.0]])
    K = (P @ H.T) / float((H @ P @ H.T)[0, 0] + r_var)
    np.testing.assert_allclose(_cov(X, 1), (np.eye(3) - K @ H) @ P, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(X[1, [S.EP_N, S.EP_E]], [12.0 - K[0, 0] * z[0], -7.0 - K[0, 0] * z[1]])
    np.testing.assert_allclose(X[1, [S.EV_N, S.EV_E]], [0.3 - K[1, 0] * z[0], -0.2 - K[1, 0] * z[1]])
    np.testing.assert_allclose(X[1, [S.CA_N, S.CA_E]], K[2, 0] * z)
    assert not X[0].any()  # another aircraft's row untouched


def test_innovation_test_and_recovery_follow_the_full_navigators():
    """The windowed NIS test and its once-per-entry recovery (covariance inflated by recovery_sigma_m^2)
    step for step against navigators.integrity.InnovationMonitor + navigators.core.recovery.
    IntegrityRecovery as ins_tercom builds them (window 3, alpha 0.01, repeat and cap off)."""
    settings = {"integrity_window": 3, "integrity_alpha": 0.01, "recovery_sigma_m": 100.0}
    imu = {"accel_noise_density_mps2_rthz": 1e-4}
    nav = nv.navigator_params("ins_tercom", settings, imu, 10.0, 3.5, 50.0)
    rec = IntegrityRecovery(InnovationMonitor(3, 0.01), 100.0, repeat=False, cap_nis=False)
    rng = np.random.default_rng(7)
    seq = [1.0, 12.0, 2.0, 0.5, 0.3, math.inf, 1.0, 2.0, 1.0, 0.2, 7.0, 7.0, 7.0, 0.1, 0.1, 0.1]
    seq += list(rng.chisquare(2, 40) * rng.choice([1.0, 4.0], 40))
    X = np.zeros((1, S.N_STATE))
    X[0, S.P00] = 400.0
    n_recoveries = 0
    for k, nis in enumerate(seq):
        p_before = X[0, S.P00]
        nv.integrity_add(X, 0, nav, nis)
        d = rec.add(float(k), nis, 2)
        assert (X[0, S.DEGRADED] > 0.5) == d.verdict.degraded, k
        assert X[0, S.P00] - p_before == pytest.approx(d.sigma_m**2 if d.recover else 0.0), k
        n_recoveries += d.recover
    assert n_recoveries >= 3  # the sequence exercises entries, stays and exits


@pytest.fixture(scope="module")
def basin_map():
    e = TerrainNavFastVectorEnv(num_envs=1, **BASIN)
    grid = e._records()[1]
    nav = e._nav.copy()
    e.close()
    return grid, nav


def _profile(grid, lat_start, lon_start, shift_n_m, shift_e_m, n=40, step_m=85.0):
    """A northbound profile: INS-indicated points, and the map heights at the TRUE points, the indicated
    ones shifted by (shift_n_m, shift_e_m)."""
    h, lat0, lon0, dlat, dlon, _ = grid
    m_lat = 6_371_000.0
    m_lon = m_lat * math.cos(lat_start)
    plat = lat_start + np.arange(n) * step_m / m_lat
    plon = np.full(n, lon_start)
    meas = np.array([kernels.bilinear(h, lat0, lon0, dlat, dlon, plat[k] + shift_n_m / m_lat,
                                      plon[k] + shift_e_m / m_lon) for k in range(n)])
    return meas, plat, plon, m_lat, m_lon


def _search(grid, nav, meas, plat, plon, m_lat, m_lon, half_m):
    n = meas.size
    rows = nv.tercom_table_rows(nav)
    return nv.tercom_offset((meas, plat, plon), n, grid, half_m, 5.0, True, (m_lat, m_lon),
                            (np.zeros((3, n)), np.zeros((4, rows, n))), (nv.COARSE_STEP_M, nv.COARSE_STRIDE))


def _direct_mad(grid, meas, plat, plon, dn, de, m_lat, m_lon, stride):
    h, lat0, lon0, dlat, dlon, _ = grid
    d = np.array([meas[k] - kernels.bilinear(h, lat0, lon0, dlat, dlon, plat[k] + dn / m_lat,
                                             plon[k] + de / m_lon) for k in range(0, meas.size, stride)])
    return float(np.mean(np.abs(d - d.mean())))


@pytest.mark.parametrize("shift", [(35.0, -60.0), (-120.0, 90.0), (0.0, 0.0)])
def test_tercom_finds_a_known_shift_over_the_hills(basin_map, shift):
    """Over the rolling hills west of the basin a noise-free profile taken 'shift' away from the indicated
    track is matched to within the 5 m search cell, and the returned MAD is the mean-removed MAD computed by
    direct look-ups at that offset."""
    grid, nav = basin_map
    meas, plat, plon, m_lat, m_lon = _profile(grid, math.radians(36.56), math.radians(-84.245), *shift)
    dn, de, mad = _search(grid, nav, meas, plat, plon, m_lat, m_lon, 250.0)
    assert abs(dn - shift[0]) <= 5.0 and abs(de - shift[1]) <= 5.0, (dn, de)
    assert mad == pytest.approx(_direct_mad(grid, meas, plat, plon, dn, de, m_lat, m_lon, 1), rel=1e-9,
                                abs=1e-9)
    # the coarse stage's best, by brute force over its lattice with direct look-ups, lies next to it
    lattice = np.arange(-250.0, 250.0 + 1e-9, nv.COARSE_STEP_M)
    surf = [[_direct_mad(grid, meas, plat, plon, a, b, m_lat, m_lon, nv.COARSE_STRIDE) for b in lattice]
            for a in lattice]
    ia, ib = np.unravel_index(int(np.argmin(surf)), (lattice.size, lattice.size))
    assert abs(lattice[ia] - dn) <= 45.0 and abs(lattice[ib] - de) <= 45.0


def test_tercom_beyond_the_window_ends_on_its_edge(basin_map):
    """A shift larger than the search window: the best match lies on the window's edge, which tercom_fix
    counts as a failed fix (an infinite NIS)."""
    grid, nav = basin_map
    meas, plat, plon, m_lat, m_lon = _profile(grid, math.radians(36.56), math.radians(-84.245), 420.0, 0.0)
    dn, de, _ = _search(grid, nav, meas, plat, plon, m_lat, m_lon, 250.0)
    assert abs(dn) >= 250.0 - 1e-6 or abs(de) >= 250.0 - 1e-6, (dn, de)
    dn, de, _ = _search(grid, nav, meas, plat, plon, m_lat, m_lon, 500.0)  # the recovery window holds it
    assert abs(dn - 420.0) <= 5.0 and abs(de) <= 5.0, (dn, de)


@pytest.mark.parametrize("fix_noise", [0.0, 1.0])
def test_tercom_fix_fuses_the_batch_covariance(basin_map, fix_noise):
    """tercom_fix with fix_noise "batch" (1) fuses the fix with the batch's covariance
    (fix_noise.lad_fix_covariance, checked against the full navigator's in test_fast_fix_noise.py): the
    update is the Kalman update of z = p - lag v with its mean per-axis variance, computed here with numpy;
    with "fixed" (0), with fix_sigma_m^2."""
    from trn_env.env.fast import fix_noise as fn

    grid, nav = basin_map
    nav = nav.copy()
    nav[nv.NP_FIX_NOISE] = fix_noise
    nav[nv.NP_TERRAIN_SIGMA] = 2.0
    meas, plat, plon, m_lat, m_lon = _profile(grid, math.radians(36.56), math.radians(-84.245), 35.0, -60.0)
    meas = meas + np.random.default_rng(3).normal(0.0, 3.0, meas.size)
    n = meas.size
    half = nav[nv.NP_HALF_WINDOW]
    dn, de, _ = _search(grid, nav, meas, plat, plon, m_lat, m_lon, half)
    if fix_noise:
        c_nn, c_ne, c_ee = fn.lad_fix_covariance((meas, plat, plon), n, grid, dn, de, (m_lat, m_lon), 5.0,
                                                 True, 2.0, np.zeros((3, n)))
        assert 1.0 < c_nn < 1e4 and 1.0 < c_ee < 1e4 and c_nn != c_ee  # informative, not isotropic
        r_var = 0.5 * (c_nn + c_ee)
        assert abs(r_var - nav[nv.NP_FIX_SIGMA] ** 2) > 10.0  # the test tells the two models apart
    else:
        r_var = nav[nv.NP_FIX_SIGMA] ** 2
    P = np.diag([2500.0, 0.04, 1e-6])  # a prior that keeps the fix's NIS inside the innovation test's band
    X = np.zeros((1, S.N_STATE))
    _set_cov(X, 0, P)
    X[0, S.N_PROF] = n
    nav[nv.NP_REMOVE_BIAS] = 1.0
    ok = nv.tercom_fix(X, 0, (meas[None], plat[None], plon[None]), grid, nav, (m_lat, m_lon),
                       (np.zeros((3, n)), np.zeros((4, nv.tercom_table_rows(nav), n))))
    assert ok
    lag = 0.5 * (n - 1) * nav[nv.NP_SAMPLE_DT]
    H = np.array([[1.0, -lag, 0.0]])
    K = P @ H.T / (H @ P @ H.T + r_var)
    np.testing.assert_allclose(_cov(X, 0), (np.eye(3) - K @ H) @ P, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(X[0, [S.EP_N, S.EP_E]], [K[0, 0] * dn, K[0, 0] * de], rtol=1e-9)
    assert X[0, S.DEGRADED] == 0.0


@pytest.mark.parametrize("window", [0, 9])
def test_innovation_window_the_fast_tier_cannot_hold_is_refused(window):
    imu = {"accel_noise_density_mps2_rthz": 1e-4}
    with pytest.raises(ValueError, match=r"integrity_window: the fast tier models windows of 1 to 8"):
        nv.navigator_params("ins_tercom", {"integrity_window": window}, imu, 10.0, 3.5, 50.0)
