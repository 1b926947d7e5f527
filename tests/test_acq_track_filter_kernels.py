"""filter_kernels (acq_track's small per-epoch algebra) against numpy written out independently."""

import math

import numpy as np
from trn_env.navigators.acquisition_tracking import filter_kernels as fk


def _spd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def test_ne_fix_gain_is_the_joseph_form_kalman_update():
    rng = np.random.default_rng(3)
    for _ in range(20):
        X, Ro = _spd(rng, 4), _spd(rng, 2)
        r = rng.normal(size=2) * 30.0
        H = np.hstack([np.eye(2), np.zeros((2, 2))])
        K = X @ H.T @ np.linalg.inv(H @ X @ H.T + Ro)
        IKH = np.eye(4) - K @ H
        X_ref = IKH @ X @ IKH.T + K @ Ro @ K.T
        X_out, dx = np.empty((4, 4)), np.empty(4)
        assert fk.ne_fix_gain(X, Ro, float(r[0]), float(r[1]), X_out, dx)
        np.testing.assert_allclose(dx, K @ r, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(X_out, X_ref, rtol=1e-11, atol=1e-9)
    # singular innovation covariance: refused, outputs untouched
    X_out[:] = 7.0
    assert not fk.ne_fix_gain(np.zeros((4, 4)), np.zeros((2, 2)), 1.0, 1.0, X_out, dx)
    assert np.all(X_out == 7.0)


def test_ne_predict_is_f_x_ft_plus_q():
    rng = np.random.default_rng(4)
    X, T, w, b = _spd(rng, 4), 1.0, 2.5, 0.01
    F = np.eye(4)
    F[0, 2] = F[1, 3] = T
    ref = F @ X @ F.T + np.diag([w, w, b, b])
    fk.ne_predict(X, T, w, b)
    np.testing.assert_allclose(X, ref, rtol=1e-12)


def test_ne_change_corrected_aiding_and_ins_rows():
    rng = np.random.default_rng(5)
    m_v, m_psi = 80.0 + rng.normal(size=25), 0.6 + 0.1 * rng.normal(size=25)
    dn, de = fk.ne_change(0.7, 0.02, m_v, m_psi)
    assert math.isclose(dn, np.mean((m_v + 0.7) * np.cos(m_psi + 0.02) - m_v * np.cos(m_psi)), rel_tol=1e-12)
    assert math.isclose(de, np.mean((m_v + 0.7) * np.sin(m_psi + 0.02) - m_v * np.sin(m_psi)), rel_tol=1e-12)
    v, p = np.empty(25), np.empty(25)
    fk.corrected_aiding(m_v, m_psi, 3.0, -2.0, v, p)
    vn, ve = m_v * np.cos(m_psi) + 3.0, m_v * np.sin(m_psi) - 2.0
    np.testing.assert_allclose(v, np.hypot(vn, ve), rtol=1e-14)
    np.testing.assert_allclose(p, np.arctan2(ve, vn), rtol=1e-14)
    # INS rows: the attitude of a quaternion built from known Euler angles (3-2-1), a NaN row flagged
    roll, pitch, yaw = 0.3, -0.1, 2.0
    cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
         cr * cp * sy - sr * sp * cy]  # fmt: skip
    hist = np.zeros((5, 12))
    hist[:, 3], hist[:, 4], hist[:, 6:10] = 50.0, -20.0, q
    hist[3, 11] = np.nan
    out = np.empty((3, 6))
    assert fk.ins_rows(hist, 2, out) == 3
    np.testing.assert_allclose(out[[0, 2], :5], [[50.0, -20.0, roll, pitch, yaw]] * 2, atol=1e-12)
    hist[2, 0] = np.nan
    fk.ins_rows(hist, 2, out)
    assert out[1, 5] == 0.0 and math.isnan(out[1, 2]) and math.isnan(out[1, 3])
    assert out[0, 5] == 1.0 and out[2, 5] == 1.0
