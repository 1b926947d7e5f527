"""Terrain metrics: roughness, slope, terrain autocorrelation along a track, terrain-information map.

- `roughness(dem, window_m)`: standard deviation of height over a square window around every post.
- `slope(dem)`: (dh_dn, dh_de, magnitude) in m/m from central differences with metric post spacing.
- `track_acf(...)`: seed 001 section 3.3.3 terrain ACF: a profile of database posts along a heading,
  compared with equal-length profiles on the same heading shifted along track; metric MAD (eq 3.3, the one the
  thesis adopts), Pearson (eq 3.2) or mean squared difference.
- `terrain_information(dem, sigma_m, window_m)`: expected Fisher information of horizontal position from
  altimeter height measurements (noise sigma) at every post of a window: I = sum(grad h grad h^T) / sigma^2
  (2 x 2, north/east), and the CRLB horizontal standard deviation sqrt(trace(I^-1)) (inf where singular).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from terrain import geodesy
from terrain.dem import Dem


def _window_posts(dem: Dem, window_m: float) -> tuple[int, int]:
    if not (window_m > 0):
        raise ValueError(f"window_m must be positive, got {window_m}")
    dn, de = dem.spacing_m
    return max(1, int(round(window_m / dn)) | 1), max(1, int(round(window_m / de)) | 1)


def _window_sum(a: np.ndarray, size) -> np.ndarray:
    """Sum over a window (NaN where the window touches a void)."""
    valid = np.isfinite(a)
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
