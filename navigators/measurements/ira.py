"""Interferometric radar altimeter (IRA) measurement models, with the seeds' variants.

The IRA measures the range R and the look angle theta of the nearest terrain on the zero-Doppler line.

Seed 000 (sections 3.2-3.3; the grid and particle filters, the EKF's TERCOM batch): one (R, theta) sample
with an attitude and a velocity gives the closest point's position p relative to the antenna (NED), by the
proposed formula (eqs 14-36, `IRA_FORMULA_CODES["proposed"]`) or the conventional one (eqs 9-13); the
measured terrain height is h_antenna - p_d (eq 2).

- `closest_points`: p for every hypothesis k (heading offset dpsi_k, horizontal velocity offset dv_k) of
  one sample - ira_closest_point.closest_point_ned over hypotheses (numba; `closest_points_reference` is
  its twin through the single-query formulas).
- `predict(rec, ...)`: the predicted terrain height of every hypothesis: the map record's height
  (navigators.core.maps.MapRecord) at the hypothesis' position + p's horizontal part.
- `variance`: the measured height's variance, sigma_R^2 (p_d / R)^2 + (sigma_theta |p_h|)^2 plus the map's
  error class and the terrain it does not resolve.
- `likelihood`: the heavy-tailed terrain likelihood every terrain sensor shares
  (terrain_models.robust_log_likelihood) of the residuals.

Seed 002 (eqs 23-26; the RBPF): the measurement is (R, theta) itself, predicted on the map for each
hypothesis by a search along the zero-Doppler line, linearised in velocity and attitude (eqs 24-25):
`predict_seed002` (ira_seed002.predict_ira), `jacobian_seed002` (ira_seed002.measurement_rows), with the
map's errors as measurement noise (`map_noise_variances`). The PMF's fused IRA pass
(filters/_pmf_kernels.ira_update_pass) is `predict` and `likelihood` in one loop over the cells.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core.maps import map_height
from .ira_closest_point import closest_point_ned
from .ira_seed002 import map_noise_variances
from .ira_seed002 import measurement_rows as jacobian_seed002
from .ira_seed002 import predict_ira as predict_seed002
from .terrain_models import robust_log_likelihood as likelihood

IRA_FORMULA_CODES = {"conventional": 0, "proposed": 1}


def variance(range_m: float, p_d_m, p_h_m, range_sigma_m: float, look_angle_sigma_rad: float,
             map_sigma_m: float, terrain_model_sigma_m: float):
    """Variance (m^2) of the terrain height an IRA sample measures when its closest point is p_d_m below and
    p_h_m horizontally from the antenna (seed 000 eq 2 differentiated in R and theta), plus the map's error
    class and the unresolved terrain."""
    sr, st = range_sigma_m, look_angle_sigma_rad
    return ((sr * p_d_m / range_m) ** 2 + (st * p_h_m) ** 2 + map_sigma_m ** 2 + terrain_model_sigma_m ** 2)


@njit(cache=True, fastmath=False, error_model="numpy")
def closest_points(range_m, theta_rad, C_bn, v_ned, dpsi, dv_ne, code, out):
    """Closest-point vectors p (m, NED) of one IRA sample (range_m, theta_rad) for every hypothesis k.

    C_bn (3, 3), v_ned (3,): the reference (INS) attitude and velocity; hypothesis k has heading C_bn turned
    by dpsi[k] about the down axis and velocity v_ned + (dv_ne[k, 0], dv_ne[k, 1], 0). dpsi has length m
    or 1 (shared), dv_ne shape (m, 2) or (1, 2). code 1: proposed (seed 000 eqs 14-36, branch nearest the
    conventional angle as in navigators.measurements.ira_closest_point); 0: conventional (eqs 9-13, angle
    theta - roll). out (m, 3); a hypothesis without a solution (|sin theta| > |t|) gets NaN. Returns the
    number of NaN rows."""
    m = out.shape[0]
    sth = math.sin(theta_rad)
    roll = math.atan2(C_bn[2, 1], C_bn[2, 2])  # a turn about the down axis leaves the roll unchanged
    ref = theta_rad - roll
    cr, sr = math.cos(ref), math.sin(ref)
    n_bad = 0
    for k in range(m):
        ps = dpsi[k] if dpsi.shape[0] > 1 else dpsi[0]
        kv = k if dv_ne.shape[0] > 1 else 0
        vn = v_ned[0] + dv_ne[kv, 0]
        ve = v_ned[1] + dv_ne[kv, 1]
        vd = v_ned[2]
        vh = math.sqrt(vn * vn + ve * ve)
        vv = math.sqrt(vh * vh + vd * vd)
        if not (vh > 0.0):
            out[k, 0] = out[k, 1] = out[k, 2] = np.nan
            n_bad += 1
            continue
        # eqs 9, 10, 12 without the angles: sin/cos of alpha (up positive) and beta (track)
        sa, ca, sb, cb = -vd / vv, vh / vv, ve / vh, vn / vh
        s1n, s1e, s1d = sa * cb, sa * sb, ca  # eq 12 in NED
        s2n, s2e = -sb, cb
        if code == 0:
            c, s = cr, sr  # eq 13 with the project's sign (theta - roll)
        else:
            cp, sp = math.cos(ps), math.sin(ps)
            # body right axis of the hypothesis: Rz(dpsi) C_bn[:, 1]
            yn = cp * C_bn[0, 1] - sp * C_bn[1, 1]
            ye = sp * C_bn[0, 1] + cp * C_bn[1, 1]
            yd = C_bn[2, 1]
            t1 = yn * s1n + ye * s1e + yd * s1d  # eq 31
            t2 = yn * s2n + ye * s2e
            rho = math.sqrt(t1 * t1 + t2 * t2)
            if not (rho > 0.0) or abs(sth) > rho:
                out[k, 0] = out[k, 1] = out[k, 2] = np.nan
                n_bad += 1
                continue
            # eqs 32-35: sin(eta + xi) = sin(theta) / rho with sin eta = t1 / rho, cos eta = t2 / rho; the two
            # solutions xi_a = asin(.) - eta and xi_b = pi - asin(.) - eta by their sines and cosines
            u = sth / rho
            cu = math.sqrt(max(1.0 - u * u, 0.0))
            se, ce = t1 / rho, t2 / rho
            ca_ = cu * ce + u * se
            sa_ = u * ce - cu * se
            cb_ = -(cu * ce - u * se)
            sb_ = u * ce + cu * se
            # the branch nearest the conventional angle: the larger cos(xi - ref)
            if ca_ * cr + sa_ * sr >= cb_ * cr + sb_ * sr:
                c, s = ca_, sa_
            else:
                c, s = cb_, sb_
        out[k, 0] = range_m * (c * s1n + s * s2n)  # eq 36 (eq 13 for the conventional angle)
        out[k, 1] = range_m * (c * s1e + s * s2e)
        out[k, 2] = range_m * (c * s1d)
    return n_bad


@njit(cache=True, fastmath=False, error_model="numpy")
def predict(rec, lat_ref, lon_ref, r_lat_m, r_lon_m, dn_m, de_m, shift_n_m, shift_e_m, out):
    """Predicted terrain height (m) of an IRA sample for every hypothesis k: the map record's height
    (navigators.core.maps.MapRecord, by its interpolation) at the reference + (dn_m[k] + shift_n_m[k],
    de_m[k] + shift_e_m[k]) - the hypothesis' position plus its closest point's horizontal offset (shift
    arrays of length m, or 1 for a shift shared by all). r_lat_m, r_lon_m: metres per radian of latitude /
    longitude at the reference (terrain_models.radii_m). NaN off the map; returns the NaN count."""
    n_nan = 0
    m = dn_m.shape[0]
    shared = shift_n_m.shape[0] == 1
    for k in range(m):
        sn = shift_n_m[0] if shared else shift_n_m[k]
        se = shift_e_m[0] if shared else shift_e_m[k]
        la = lat_ref + (dn_m[k] + sn) / r_lat_m
        lo = lon_ref + (de_m[k] + se) / r_lon_m
        h = map_height(rec, la, lo)
        out[k] = h
        if h != h:
            n_nan += 1
    return n_nan


def closest_points_reference(range_m: float, theta_rad: float, C_bn: np.ndarray, v_ned: np.ndarray,
                         dpsi: np.ndarray, dv_ne: np.ndarray, formula: str) -> np.ndarray:
    """closest_points through the single-query formulas (ira_closest_point.closest_point_ned)."""
    m = max(len(dpsi), len(dv_ne))
    dpsi = np.broadcast_to(dpsi, (m,))
    dv = np.broadcast_to(dv_ne, (m, 2))
    c, s = np.cos(dpsi), np.sin(dpsi)
    Rz = np.zeros((m, 3, 3))
    Rz[:, 0, 0] = c
    Rz[:, 0, 1] = -s
    Rz[:, 1, 0] = s
    Rz[:, 1, 1] = c
    Rz[:, 2, 2] = 1.0
    C = Rz @ C_bn
    v = np.tile(np.asarray(v_ned, float), (m, 1))
    v[:, :2] += dv
    return closest_point_ned(np.full(m, range_m), np.full(m, theta_rad), None, None, None, v,
                             formula=formula, C_bn=C)


__all__ = ["IRA_FORMULA_CODES", "closest_points", "closest_points_reference", "jacobian_seed002",
           "likelihood", "map_noise_variances", "predict", "predict_seed002", "variance"]
