"""What the terrain sensors' measurement models share, over many position hypotheses of one epoch.

Every hypothesis k (a grid cell, a particle) is an offset of the aircraft from a reference (the INS
position): north/east dn_k, de_k (m) and, where the filter carries them, a horizontal velocity offset dv_k
(m/s) and a heading offset dpsi_k (rad). The per-sensor models are radar_altimeter.py and ira.py (with the
seeds' variants); they share:

- `radii_m`: metres per radian of latitude and longitude at the reference (seed 000 eq 2: offsets of a
  few km go through the meridian and prime-vertical radii, not a flat plane).
- `robust_log_likelihood`: a heavy-tailed mixture (1 - eps) N(r; 0, S) + eps / width of the residuals, so
  one bad return (an outlier, a multipath, a map void) cannot zero a hypothesis; a NaN residual (a lookup
  off the map) gets the outlier density only. `robust_ll_one` is its scalar, for kernels that fuse it with
  their lookups (the point-mass filter's IRA pass); `robust_log_likelihood_reference` its numpy twin.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

LOG_2PI = math.log(2.0 * math.pi)


def radii_m(lat_rad: float, h_m: float) -> tuple[float, float]:
    """(R_N + h, (R_E + h) cos lat): metres per radian of latitude and of longitude (seed 000 eq 2)."""
    return (float(meridian_radius_m(lat_rad)) + h_m,
            (float(prime_vertical_radius_m(lat_rad)) + h_m) * math.cos(lat_rad))


@njit(cache=True, fastmath=False, error_model="numpy")
def robust_ll_one(r, s, lg, le):
    """log((1 - eps) N(r; 0, s) + eps u) of one residual r (m) with variance s (m^2); lg = log(1 - eps),
    le = log(eps u) (-inf: no outlier term). NaN r: le. The scalar behind robust_log_likelihood, for kernels
    that fuse it with their lookups (the point-mass filter's)."""
    if r != r:
        return le
    a = lg - 0.5 * (r * r / s + math.log(s) + LOG_2PI)
    if le == -np.inf:
        return a
    if a > le:
        return a + math.log1p(math.exp(le - a))
    return le + math.log1p(math.exp(a - le))


@njit(cache=True, fastmath=False, error_model="numpy")
def robust_log_likelihood(residual_m, var_m2, outlier_prob, log_outlier_density, out):
    """log((1 - eps) N(r; 0, S) + eps * u) per hypothesis (eps = outlier_prob, log u = log_outlier_density);
    var_m2 has length m or 1. A NaN residual gets log(eps u) (no information but not impossible; -inf when
    eps = 0). Returns the number of NaN residuals."""
    m = residual_m.shape[0]
    le = math.log(outlier_prob) + log_outlier_density if outlier_prob > 0.0 else -np.inf
    lg = math.log1p(-outlier_prob) if outlier_prob < 1.0 else -np.inf
    n_nan = 0
    for k in range(m):
        s = var_m2[0] if var_m2.shape[0] == 1 else var_m2[k]
        r = residual_m[k]
        if r != r:
            n_nan += 1
        out[k] = robust_ll_one(r, s, lg, le)
    return n_nan


def robust_log_likelihood_reference(residual_m, var_m2, outlier_prob, log_outlier_density):
    """robust_log_likelihood in numpy (logaddexp of the two mixture terms)."""
    r = np.asarray(residual_m, float)
    s = np.broadcast_to(np.asarray(var_m2, float), r.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.log1p(-outlier_prob) - 0.5 * (r * r / s + np.log(s) + LOG_2PI)
        le = np.log(outlier_prob) + log_outlier_density
        return np.where(np.isnan(r), le, np.logaddexp(a, le))


def ra_cone_ranges(heights, lat0, lon0, dlat, dlon, *args):
    """The former loose-grid entry of the radar altimeter's cone model, kept for plug-ins written against
    it (the sitan example as installed before): radar_altimeter.predict on the bilinear map record."""
    from ...terrain.kernels import MapRecord
    from .radar_altimeter import predict

    return predict(MapRecord(heights, float(lat0), float(lon0), float(dlat), float(dlon), False), *args)
