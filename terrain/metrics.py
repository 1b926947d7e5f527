"""Terrain metrics: roughness, slope, terrain autocorrelation along a track, terrain-information map.

- `roughness(dem, window_m)`: standard deviation of height over a square window around every post.
- `slope(dem)`: (dh_dn, dh_de, magnitude) in m/m from central differences with metric post spacing.
- `track_acf(...)`: seed 001 section 3.3.3 terrain ACF: a profile of database posts along a heading,
  compared with equal-length profiles on the same heading shifted along track; metric MAD (eq 3.3, the one the
  thesis adopts), Pearson (eq 3.2) or mean squared difference.
- `terrain_information(dem, sigma_m, window_m)`: expected Fisher information of horizontal position from
  altimeter height measurements (noise sigma) at every post of a window: I = sum(grad h grad h^T) / sigma^2
  (2 x 2, north/east), and the CRLB horizontal standard deviation sqrt(trace(I^-1)) (inf where singular).
  It assumes every post of the window is measured.
- `track_crlb(dem, lat, lon, sigma_m, ...)`: the posterior (Bayesian) Cramer-Rao bound of the horizontal
  position for the measurements actually taken along a track: the terrain gradient at each measured point,
  the sensor and map noise, a Gaussian prior and a random-walk process noise between the epochs
  (Tichavsky, Muravchik and Nehorai 1998, IEEE Trans. Signal Processing 46(5): the recursion
  J_k = D22 - D21 (J_(k-1) + D11)^-1 D12 with F = I).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import geodesy
from .dem import Dem


def _window_posts(dem: Dem, window_m: float) -> tuple[int, int]:
    if not (window_m > 0):
        raise ValueError(f"window_m must be positive, got {window_m}")
    dn, de = dem.spacing_m
    return max(1, int(round(window_m / dn)) | 1), max(1, int(round(window_m / de)) | 1)


def _window_sum(a: np.ndarray, size) -> np.ndarray:
    """Sum over a window (NaN where the window touches a void)."""
    valid = np.isfinite(a)
    from scipy import ndimage  # at first use: importing scipy.ndimage costs about a second
    mean = ndimage.uniform_filter(np.where(valid, a, 0.0), size=size, mode="nearest")
    frac = ndimage.uniform_filter(valid.astype(float), size=size, mode="nearest")
    out = mean * size[0] * size[1]
    return np.where(frac > 0.999, out, np.nan)


def roughness(dem: Dem, window_m: float) -> np.ndarray:
    """Standard deviation of height (m) over a window_m x window_m window (odd number of posts)."""
    size = _window_posts(dem, window_m)
    n = size[0] * size[1]
    s1 = _window_sum(dem.heights_m, size)
    s2 = _window_sum(dem.heights_m**2, size)
    var = np.maximum(s2 / n - (s1 / n) ** 2, 0.0)
    return np.sqrt(var)


def slope(dem: Dem):
    """(dh_dn, dh_de, |grad h|) in m/m at every post (central differences; one-sided at the border)."""
    h = dem.heights_m
    lat = dem.lat_rad
    dn_m = dem.dlat_rad * np.array([geodesy.meridian_radius_m(x) for x in lat])
    de_m = dem.dlon_rad * np.array([geodesy.prime_vertical_radius_m(x) for x in lat]) * np.cos(lat)
    g_i, g_j = np.gradient(h)
    dh_dn = g_i / dn_m[:, None]
    dh_de = g_j / de_m[:, None]
    return dh_dn, dh_de, np.hypot(dh_dn, dh_de)


def track_profile(
    dem: Dem,
    lat_rad: float,
    lon_rad: float,
    heading_rad: float,
    n_points: int,
    spacing_m: float | None = None,
    offset_m: float = 0.0,
) -> np.ndarray:
    """Heights (m) at n_points along a straight track from (lat, lon) on heading_rad (clockwise from north),
    spaced spacing_m (default: the DEM's post spacing), starting offset_m along the track."""
    if spacing_m is None:
        spacing_m = float(min(dem.spacing_m))
    d = offset_m + spacing_m * np.arange(n_points)
    la, lo = dem.offset_to_latlon(lat_rad, lon_rad, d * np.cos(heading_rad), d * np.sin(heading_rad))
    return dem.height(la, lo)


def track_acf(
    dem: Dem,
    lat_rad: float,
    lon_rad: float,
    heading_rad: float,
    n_points: int,
    max_shift_posts: int,
    metric: str = "mad",
    spacing_m: float | None = None,
):
    """Terrain ACF (seed 001 section 3.3.3): returns (shift_m, value) for shifts -max..max posts.

    metric: "mad" (eq 3.3, 0 at zero shift, grows with mismatch), "pearson" (eq 3.2, 1 at zero shift),
    "msd" (mean squared difference)."""
    if metric not in ("mad", "pearson", "msd"):
        raise ValueError(f"track_acf: metric must be 'mad', 'pearson' or 'msd', got {metric!r}")
    if spacing_m is None:
        spacing_m = float(min(dem.spacing_m))
    ref = track_profile(dem, lat_rad, lon_rad, heading_rad, n_points, spacing_m)
    shifts = np.arange(-max_shift_posts, max_shift_posts + 1)
    values = np.empty(shifts.shape)
    for k, s in enumerate(shifts):
        other = track_profile(dem, lat_rad, lon_rad, heading_rad, n_points, spacing_m, offset_m=s * spacing_m)
        if metric == "mad":
            values[k] = np.mean(np.abs(ref - other))
        elif metric == "msd":
            values[k] = np.mean((ref - other) ** 2)
        else:
            a = ref - np.mean(ref)
            b = other - np.mean(other)
            values[k] = np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b))
    return shifts * spacing_m, values


def correlation_length_m(shift_m: np.ndarray, pearson: np.ndarray) -> float:
    """First positive shift where a Pearson ACF falls below 1/e (linear interpolation); inf if never."""
    pos = shift_m >= 0
    s, v = shift_m[pos], pearson[pos]
    below = np.nonzero(v < np.exp(-1.0))[0]
    if len(below) == 0:
        return float("inf")
    k = below[0]
    if k == 0:
        return 0.0
    t = (v[k - 1] - np.exp(-1.0)) / (v[k - 1] - v[k])
    return float(s[k - 1] + t * (s[k] - s[k - 1]))


@dataclass
class TerrainInformation:
    """Fisher information of horizontal position (1/m^2) per post and the CRLB horizontal sigma (m)."""

    i_nn: np.ndarray
    i_ne: np.ndarray
    i_ee: np.ndarray
    crlb_sigma_h_m: np.ndarray  # sqrt(trace(I^-1)); inf where I is singular
    crlb_sigma_n_m: np.ndarray
    crlb_sigma_e_m: np.ndarray


def terrain_information(dem: Dem, sigma_m: float, window_m: float) -> TerrainInformation:
    """Expected Fisher information of horizontal position from altimeter heights with noise sigma_m at every
    post of a window_m x window_m window: I = sum(grad h grad h^T) / sigma^2 (see module docstring)."""
    if not (sigma_m > 0):
        raise ValueError(f"terrain_information: sigma_m must be positive, got {sigma_m}")
    size = _window_posts(dem, window_m)
    gn, ge, _ = slope(dem)
    i_nn = _window_sum(gn * gn, size) / sigma_m**2
    i_ne = _window_sum(gn * ge, size) / sigma_m**2
    i_ee = _window_sum(ge * ge, size) / sigma_m**2
    det = i_nn * i_ee - i_ne**2
    scale = np.maximum(i_nn * i_ee, 1e-300)
    singular = ~(det > 1e-12 * scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        var_n = np.where(singular, np.inf, i_ee / det)
        var_e = np.where(singular, np.inf, i_nn / det)
    nan = ~np.isfinite(i_nn)
    var_n[nan] = np.nan
    var_e[nan] = np.nan
    return TerrainInformation(i_nn, i_ne, i_ee, np.sqrt(var_n + var_e), np.sqrt(var_n), np.sqrt(var_e))


@dataclass
class TrackCrlb:
    """Posterior CRLB of the horizontal position (north, east) along a measurement track.

    t_s (n,) s: the epochs; information (n, 2, 2) 1/m^2: J_k after measurement k; covariance_m2 (n, 2, 2)
    m^2: its inverse, the bound on the error covariance; sigma_h_m (n,) m: sqrt(trace J_k^-1) (inf where J_k
    is singular); gradient (n, 2) m/m: terrain slope north / east at the measured point (NaN: off the map,
    the measurement adds nothing); sigma_z_m (n,) m: the measurement noise used (sensor and map)."""

    t_s: np.ndarray
    information: np.ndarray
    covariance_m2: np.ndarray
    sigma_h_m: np.ndarray
    gradient: np.ndarray
    sigma_z_m: np.ndarray

    def rms_m(self, t_from_s: float = -math.inf) -> float:
        """sqrt(mean(sigma_h^2)) over the epochs at or after t_from_s (m): the RMS horizontal error the
        bound allows there."""
        sel = self.t_s >= t_from_s
        if not sel.any():
            raise ValueError(f"TrackCrlb.rms_m: no epoch at or after t_from_s={t_from_s}")
        return float(np.sqrt(np.mean(self.sigma_h_m[sel] ** 2)))


def track_crlb(dem: Dem, lat_rad, lon_rad, sigma_m, t_s=None, prior_sigma_m: float | None = None,
               process_noise_m2_per_s: float = 0.0, map_sigma_m: float = 0.0,
               method: str = "bicubic", velocity_prior_sigma_mps: float = 0.0,
               velocity_noise_mps_per_sqrt_s: float = 0.0,
               acceleration_prior_sigma_mps2: float = 0.0) -> TrackCrlb:
    """Posterior Cramer-Rao bound of the horizontal position from terrain-height measurements along a track.

    Model (north, east; m): the position error is a random walk x_k = x_(k-1) + w_k, w_k ~ N(0, q dt_k I)
    with q = process_noise_m2_per_s (m^2/s) and dt_k = t_k - t_(k-1) (s), prior x_0 ~ N(0, prior_sigma_m^2 I)
    (None: no prior information); at epoch k one height z_k = h(p_k + x_k) + v_k is measured at the point
    (lat_rad[k], lon_rad[k]) (rad; e.g. the IRA's closest point or the altimeter's footprint), with
    v_k ~ N(0, sigma_m[k]^2 + map_sigma_m^2) (m; sigma_m scalar or one per epoch: the sensor's noise on the
    measured height, map_sigma_m the map's random error). h is the map `dem` read with `method` ("bicubic"
    or "bilinear", as the filter reads it); its gradient g_k (m/m) at the measured point gives the
    measurement's Fisher information g_k g_k^T / var_k (1/m^2).

    Recursion (Tichavsky et al. 1998, J_k = D22 - D21 (J_(k-1) + D11)^-1 D12, which for F = I and additive
    Gaussian noise is, by the matrix inversion lemma): J_0 = I / prior_sigma^2,
    J_k = (J_(k-1)^-1 + Q_k)^-1 + g_k g_k^T / var_k, the first epoch taking no process noise. The expectation
    over the state of the information is evaluated at the true track (the usual approximation when the
    errors are small against the terrain's correlation length). Returns a TrackCrlb (units there); its
    covariance_m2 bounds the error covariance of any estimator of the position error from these
    measurements under this model, and equals a Kalman filter's covariance when the terrain is a plane.

    velocity_prior_sigma_mps > 0 adds an unknown velocity offset v (N(0, sigma^2 I) at the first epoch, a
    random walk of velocity_noise_mps_per_sqrt_s): x_k = x_(k-1) + v dt_k + w_k (an INS whose error is a
    ramp); the recursion then runs on (x, v) as J_k = (F J_(k-1)^-1 F' + Q_k)^-1 + H' H / var_k (needs a
    prior) and the returned information and covariance are the position's marginal ones.
    acceleration_prior_sigma_mps2 > 0 (with a velocity offset) adds a constant unknown acceleration a
    (N(0, sigma^2 I): the INS error's tilt and accelerometer bias): x_k = x_(k-1) + v dt_k + a dt_k^2 / 2
    + w_k, v_k = v_(k-1) + a dt_k + w_v.
    """
    lat = np.atleast_1d(np.asarray(lat_rad, float))
    lon = np.atleast_1d(np.asarray(lon_rad, float))
    n = lat.shape[0]
    if lat.ndim != 1 or lon.shape != lat.shape or n == 0:
        raise ValueError("track_crlb: lat_rad and lon_rad must be 1-D arrays of the same non-zero length")
    sig = np.broadcast_to(np.asarray(sigma_m, float), (n,)).astype(float)
    if not np.all(np.isfinite(sig)) or np.any(sig < 0.0):
        raise ValueError("track_crlb: sigma_m must be finite and >= 0 (scalar or one per epoch)")
    if not (math.isfinite(map_sigma_m) and map_sigma_m >= 0.0):
        raise ValueError(f"track_crlb: map_sigma_m must be finite and >= 0, got {map_sigma_m}")
    var = sig**2 + map_sigma_m**2
    if np.any(var <= 0.0):
        raise ValueError("track_crlb: sigma_m^2 + map_sigma_m^2 must be > 0 at every epoch")
    if not (math.isfinite(process_noise_m2_per_s) and process_noise_m2_per_s >= 0.0):
        raise ValueError(f"track_crlb: process_noise_m2_per_s must be finite and >= 0, got "
                         f"{process_noise_m2_per_s}")
    t = np.arange(n, dtype=float) if t_s is None else np.atleast_1d(np.asarray(t_s, float))
    if t.shape != (n,) or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0.0):
        raise ValueError("track_crlb: t_s must be finite, non-decreasing, one per epoch")
    if prior_sigma_m is None:
        J = np.zeros((2, 2))
    else:
        if not (math.isfinite(prior_sigma_m) and prior_sigma_m > 0.0):
            raise ValueError(f"track_crlb: prior_sigma_m must be finite and > 0 (or None), got "
                             f"{prior_sigma_m}")
        J = np.eye(2) / prior_sigma_m**2
    if velocity_prior_sigma_mps > 0.0:
        if prior_sigma_m is None:
            raise ValueError("track_crlb: a velocity offset needs prior_sigma_m")
        if not (math.isfinite(velocity_prior_sigma_mps) and math.isfinite(velocity_noise_mps_per_sqrt_s)
                and velocity_noise_mps_per_sqrt_s >= 0.0):
            raise ValueError("track_crlb: velocity_prior_sigma_mps and velocity_noise_mps_per_sqrt_s must be "
                             "finite and >= 0")
        if not (math.isfinite(acceleration_prior_sigma_mps2) and acceleration_prior_sigma_mps2 >= 0.0):
            raise ValueError(f"track_crlb: acceleration_prior_sigma_mps2 must be finite and >= 0, got "
                             f"{acceleration_prior_sigma_mps2}")
        return _track_crlb_velocity(dem, lat, lon, var, t, prior_sigma_m, process_noise_m2_per_s,
                                    velocity_prior_sigma_mps, velocity_noise_mps_per_sqrt_s, method,
                                    acceleration_prior_sigma_mps2)
    if acceleration_prior_sigma_mps2 != 0.0:
        raise ValueError("track_crlb: an acceleration offset needs a velocity offset "
                         "(velocity_prior_sigma_mps > 0)")
    gn, ge = dem.gradient(lat, lon, method=method)
    g = np.stack([np.atleast_1d(gn), np.atleast_1d(ge)], axis=1)
    info = np.empty((n, 2, 2))
    cov = np.empty((n, 2, 2))
    sig_h = np.empty(n)
    eye = np.eye(2)
    for k in range(n):
        if k > 0 and process_noise_m2_per_s > 0.0:
            Q = eye * process_noise_m2_per_s * (t[k] - t[k - 1])
            J = J @ np.linalg.inv(eye + Q @ J)       # = (J^-1 + Q)^-1, also for a singular J
            J = 0.5 * (J + J.T)
        if np.all(np.isfinite(g[k])):
            J = J + np.outer(g[k], g[k]) / var[k]
        info[k] = J
        det = J[0, 0] * J[1, 1] - J[0, 1] ** 2
        if det > 1e-12 * max(J[0, 0] * J[1, 1], 1e-300):
            cov[k] = np.array([[J[1, 1], -J[0, 1]], [-J[0, 1], J[0, 0]]]) / det
            sig_h[k] = math.sqrt(cov[k, 0, 0] + cov[k, 1, 1])
        else:
            cov[k] = np.inf
            sig_h[k] = math.inf
    return TrackCrlb(t, info, cov, sig_h, g, np.sqrt(var))


def _track_crlb_velocity(dem, lat, lon, var, t, prior_sigma_m, q, sigma_v, s_v, method,
                         sigma_a: float = 0.0) -> TrackCrlb:
    """track_crlb with the velocity offset, and the acceleration offset if sigma_a > 0 (see there): the
    4- (6-) state linear-Gaussian recursion in covariance form, P_k = ((F P_(k-1) F' + Q_k)^-1
    + H' H / var_k)^-1."""
    n = lat.shape[0]
    gn, ge = dem.gradient(lat, lon, method=method)
    g = np.stack([np.atleast_1d(gn), np.atleast_1d(ge)], axis=1)
    m = 6 if sigma_a > 0.0 else 4
    P = np.diag([prior_sigma_m**2, prior_sigma_m**2, sigma_v**2, sigma_v**2, sigma_a**2, sigma_a**2][:m])
    info = np.empty((n, 2, 2))
    cov = np.empty((n, 2, 2))
    sig_h = np.empty(n)
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            F = np.eye(m)
            F[0, 2] = F[1, 3] = dt
            if m == 6:
                F[0, 4] = F[1, 5] = 0.5 * dt * dt
                F[2, 4] = F[3, 5] = dt
            P = F @ P @ F.T + np.diag([q * dt, q * dt, s_v**2 * dt, s_v**2 * dt, 0.0, 0.0][:m])
        if np.all(np.isfinite(g[k])):
            h = np.zeros(m)
            h[:2] = g[k]
            ph = P @ h
            P = P - np.outer(ph, ph) / (var[k] + h @ ph)
        P = 0.5 * (P + P.T)
        cov[k] = P[:2, :2]
        info[k] = np.linalg.inv(P[:2, :2])
        sig_h[k] = math.sqrt(P[0, 0] + P[1, 1])
    return TrackCrlb(t, info, cov, sig_h, g, np.sqrt(var))
