"""How the INS error at a TERCOM fix moves the batch's matched shift: the fix's rows of H.

The batch's samples x_k (k = 1..M, times t_k, tau_k = t_fix - t_k) are placed by the free INS, whose
horizontal position error at t_k is dr_h(t_k); the MAD match (seed 000 eqs 1-2) fits one rigid shift to a
batch whose error is not rigid. Linearised about the match, the shift is the least-squares average of the
samples' errors weighted by the map's slope products g_k g_k^T at the matched points (the normal equations
of r_k = g_k^T (d - dr_h(t_k))):

    z = A^-1 sum_k g_k g_k^T dr_h(t_k),    A = sum_k g_k g_k^T

(navigators.tercom.fix_noise.slope_weighted_mean). Each dr_h(t_k) is the error at the fix run back along the
psi-angle error model of ins_trn_ekf.py (the Coriolis, transport and gravity couplings are below 1 % over a
batch and left out):

    dr_h(t_k) = dr_h - tau_k dv_h + int_{t_k}^{t_fix} (s - t_k) a_h(s) ds,
    a(s) = f^n(s) x psi(s) + C_bn(s) b_a,   psi(s) = psi + C_bn(s)[:, 2] b_gz (t_fix - s)

with f^n(s) and C_bn(s) the INS's specific force and attitude along the batch (BatchKinematics logs them as
the INS runs). So each sample's error is M_k x (M_k: 2 x 13, linear in the error state at the fix) and
H = A^-1 sum_k g_k g_k^T M_k: the velocity error enters with the slope-weighted lag, not the mean lag (a
batch whose informative terrain lies at its start measures the error of its start), and the attitude,
accelerometer-bias and z-gyro-bias errors with the double integral of the specific force the INS flew along
the batch (a turn's centripetal force times the heading error bends the batch's track).
"""

from __future__ import annotations

import numpy as np

from ..core.error_states import BAX, BGZ, DRE, DRN, DVE, DVN, N_EKF13, PSIN
from ..inertial.strapdown import quat_to_dcm

# the kinematics log keeps one IMU sample in this many (the specific force and attitude change over
# seconds along a batch of tens of seconds; the IMU runs at 50-100 Hz)
LOG_DECIMATION = 10
# columns of a log row: t, f^n (3), C_bn row-major (9)
_N_COLS = 13


class BatchKinematics:
    """Decimated log of the INS's time, specific force in NED and body-to-NED matrix along the batch."""

    def __init__(self) -> None:
        self._chunks: list[np.ndarray] = []

    def clear(self) -> None:
        self._chunks = []

    def add(self, t_s: np.ndarray, f_b_mps2: np.ndarray, hist: np.ndarray,
            accel_bias_b_mps2: np.ndarray) -> None:
        """Log every LOG_DECIMATION-th of the segment's IMU samples: times t_s (n,), specific force f_b_mps2
        (n, 3, body FRD), the INS history hist (n, 10: lat, lon, h, v_ned, quaternion) and the accelerometer
        bias the INS removes (3,)."""
        n = min(t_s.shape[0], hist.shape[0])
        if n == 0:
            return
        idx = np.arange(0, n, LOG_DECIMATION)
        if idx[-1] != n - 1:
            idx = np.append(idx, n - 1)
        q = hist[idx, 6:10]
        ok = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(f_b_mps2[idx]), axis=1)
        if not ok.any():
            return
        idx, q = idx[ok], q[ok]
        C = np.stack([quat_to_dcm(qk) for qk in q])
        f_n = np.einsum("kij,kj->ki", C, f_b_mps2[idx] - accel_bias_b_mps2)
        rows = np.empty((idx.shape[0], _N_COLS))
        rows[:, 0] = t_s[idx]
        rows[:, 1:4] = f_n
        rows[:, 4:] = C.reshape(-1, 9)
        self._chunks.append(rows)

    def since(self, t0_s: float) -> np.ndarray:
        """The logged rows from t0_s on (K, 13), time-ordered; older rows are dropped."""
        if not self._chunks:
            return np.empty((0, _N_COLS))
        rows = np.concatenate(self._chunks) if len(self._chunks) > 1 else self._chunks[0]
        rows = rows[rows[:, 0] >= t0_s]
        self._chunks = [rows]
        return rows


def sample_error_rows(t_k_s: np.ndarray, t_fix_s: float, log: np.ndarray) -> np.ndarray:
    """M_k (M, 2, 13): each sample's horizontal INS position error per unit of the error state at the fix
    (module docstring), from the kinematics log (K, 13) of BatchKinematics.since. Without a log the
    acceleration terms are left out (the position and velocity columns stay)."""
    t_k = np.asarray(t_k_s, float)
    m = t_k.shape[0]
    M = np.zeros((m, 2, N_EKF13))
    M[:, 0, DRN] = M[:, 1, DRE] = 1.0
    M[:, 0, DVN] = M[:, 1, DVE] = -(t_fix_s - t_k)
    log = log[log[:, 0] <= t_fix_s + 1e-9]
    if log.shape[0] < 2:
        return M
    s = log[:, 0]
    f = log[:, 1:4]
    C = log[:, 4:].reshape(-1, 3, 3)
    # G(s) (K, 2, 13): the horizontal acceleration error per unit of the error state at the fix
    G = np.zeros((s.shape[0], 2, N_EKF13))
    fn, fe, fd = f[:, 0], f[:, 1], f[:, 2]
    # (f x psi)_n = f_e psi_d - f_d psi_e ; (f x psi)_e = f_d psi_n - f_n psi_d
    G[:, 0, PSIN + 1], G[:, 0, PSIN + 2] = -fd, fe
    G[:, 1, PSIN], G[:, 1, PSIN + 2] = fd, -fn
    G[:, :, BAX:BAX + 3] = C[:, :2, :]
    c = C[:, :, 2]                                   # psi per unit b_gz per second before the fix
    fxc_n = fe * c[:, 2] - fd * c[:, 1]
    fxc_e = fd * c[:, 0] - fn * c[:, 2]
    G[:, 0, BGZ] = fxc_n * (t_fix_s - s)
    G[:, 1, BGZ] = fxc_e * (t_fix_s - s)
    # I1(t) = int_t^tf G ds, I2(t) = int_t^tf s G ds (trapezoids on the log, backwards from its end); the
    # log's end is the fix (the last segment's last IMU sample)
    ds = np.diff(s)[:, None, None]
    seg1 = 0.5 * ds * (G[1:] + G[:-1])
    seg2 = 0.5 * ds * (s[1:, None, None] * G[1:] + s[:-1, None, None] * G[:-1])
    I1 = np.zeros_like(G)
    I2 = np.zeros_like(G)
    I1[:-1] = np.cumsum(seg1[::-1], axis=0)[::-1]
    I2[:-1] = np.cumsum(seg2[::-1], axis=0)[::-1]
    # at each sample time (linear between log rows; before the log's start, its start's integrals)
    j = np.clip(np.searchsorted(s, t_k, side="right") - 1, 0, s.shape[0] - 1)
    j1 = np.minimum(j + 1, s.shape[0] - 1)
    span = s[j1] - s[j]
    w = np.where(span > 0.0, np.clip((t_k - s[j]) / np.where(span > 0.0, span, 1.0), 0.0, 1.0), 0.0)
    w = w[:, None, None]
    i1 = (1.0 - w) * I1[j] + w * I1[j1]
    i2 = (1.0 - w) * I2[j] + w * I2[j1]
    M += i2 - t_k[:, None, None] * i1
    return M
