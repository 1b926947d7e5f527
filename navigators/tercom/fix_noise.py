"""Covariance of a batch TERCOM fix from the batch and the map: the least-absolute-deviation shift's.

The MAD fix (seed 000 eqs 1-2) is the horizontal shift d minimising sum_k |h_meas,k - h_map(x_k + d)| over
the batch's M samples (x_k the INS position plus the closest-point offset; residuals mean-removed when the
batch removes its bias): a least-absolute-deviation (LAD) estimate of d in the model r_k(d) = h_meas,k -
h_map(x_k + d), linearised about the match as r_k - g_k^T (d - d_hat), g_k the map's slope at the matched
point. With A = sum_k g_k g_k^T its covariance is

    Cov(d_hat) = (pi / 2) A^-1 B A^-1 + (pi / 2) sigma_t^2 n_post A^-1 + cell^2 / 12 I

- (pi / 2) A^-1 B A^-1: the sandwich of the shift's least-squares estimate under correlated residuals,
  B = sum_{|l| <= L} w_l c(l) sum_k g_k g_{k+l}^T with c(l) the residuals' autocovariance at lag l and
  Bartlett weights w_l = 1 - |l| / (L + 1) over L samples along WINDOW_POSTS post spacings of the map (Newey
  & West 1987), times pi / 2, the LAD's variance over the least-squares one for Gaussian residuals (Koenker
  2005, "Quantile Regression", sec. 4.2): the sensor noise and what of the map's error the residuals at the
  match show;
- (pi / 2) sigma_t^2 n_post A^-1: the terrain the map cannot hold between its posts (sigma_t, from the map's
  own spectrum: navigators.measurements.ira_map_noise.interpolation_sigma_m), one height error per post
  spacing along the track, shared by the n_post samples there: the share of the map's missing detail that
  the fit absorbs into the shift, which the residuals at the match no longer show;
- cell^2 / 12 per axis: the search grid quantises the match (a uniform error over one cell);
- without bias removal (seed 000's plain MAD), sigma_b^2 j j^T, j = A^-1 sum_k g_k: the measured heights'
  common bias b (the barometer's, sigma_b) moves the shift by j b, the slope-weighted mean slope of the
  batch (a batch that climbs a slope matches a biased height profile further along it).

A flat map (A singular) gives no horizontal information (NO_INFORMATION_VAR_M2), which a fixed noise would
not say; rough terrain and long batches give a tight fix.

The same linearisation says what the fix measures when the batch's error is not one rigid shift (the INS
places each sample with its error at that sample's time): the least-squares average of the samples' errors
weighted by the slope products, A^-1 sum_k g_k g_k^T e_k (slope_weighted_mean; the fix's H in
navigators.filters.ins_trn_batch_error).
"""

from __future__ import annotations

import math

import numpy as np

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

# a fix whose covariance is not finite and positive definite is reported with this variance (m^2): no
# information (the Kalman gain of such a fix is ~0 against any prior the filter holds)
NO_INFORMATION_VAR_M2 = 1e12
# the least-absolute-deviation estimate's variance over the least-squares one for Gaussian residuals
LAD_EFFICIENCY_LOSS = 0.5 * math.pi
# the residuals' autocovariance is summed over this many of the map's post spacings
WINDOW_POSTS = 2.0


def post_spacing_m(dem, lat_rad: float) -> float:
    """The map's post spacing (m) at lat_rad: the larger of its north and east steps."""
    _, _, _, dlat, dlon = dem.grid
    return float(max(abs(dlat) * meridian_radius_m(lat_rad),
                     abs(dlon) * prime_vertical_radius_m(lat_rad) * math.cos(lat_rad)))


def lad_fix_covariance(dem, lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m, dn_fix_m: float, de_fix_m: float,
                       cell_m: float, remove_bias: bool, terrain_sigma_m: float = 0.0,
                       height_bias_sigma_m: float = 0.0) -> np.ndarray:
    """Covariance (2 x 2, m^2, north / east) of a TERCOM fix (see the module docstring).

    dem: the navigator's map (terrain.Dem: bilinear height and slope, as the MAD's lookups); lat_rad,
    lon_rad, h_meas_m, dn_rel_m, de_rel_m: the batch's samples in time order (INS positions, measured terrain
    heights, closest-point offsets; non-finite samples are dropped, as correlate() drops them); dn_fix_m,
    de_fix_m: the fix's correction; cell_m: the search cell; remove_bias: the MAD was mean-removed (the
    residuals are then centred on their mean, else on their median); terrain_sigma_m: the map's unresolved
    terrain (m, 1 sigma); height_bias_sigma_m: the measured heights' common bias (m, 1 sigma: the baro's),
    which a MAD without bias removal absorbs into the shift."""
    quantisation = np.eye(2) * cell_m**2 / 12.0
    no_info = np.eye(2) * NO_INFORMATION_VAR_M2
    matched = _matched(dem, lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m, dn_fix_m, de_fix_m)
    if matched is None:
        return no_info
    lat, lon, hm, h_map, g, use, lat_c, r_ns, r_ew = matched
    r = hm - h_map
    r = r - (np.mean(r) if remove_bias else np.median(r))
    m = r.shape[0]
    # the samples' spacing along the INS track (not the closest points, which jitter across it)
    track_m = float(np.hypot(np.diff(lat[use]) * r_ns, np.diff(lon[use]) * r_ew).sum())
    spacing_m = track_m / max(m - 1, 1)
    lag = int(min(m - 1, math.ceil(WINDOW_POSTS * post_spacing_m(dem, lat_c) / max(spacing_m, 1e-3))))
    A = g.T @ g
    B = float(np.mean(r * r)) * A
    for ell in range(1, lag + 1):
        c = g[:-ell].T @ g[ell:]
        B += (1.0 - ell / (lag + 1.0)) * float(np.mean(r[:-ell] * r[ell:])) * (c + c.T)
    try:
        A_inv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return no_info
    cov = LAD_EFFICIENCY_LOSS * (A_inv @ B @ A_inv.T)
    # the terrain the map cannot hold between its posts: one height error per post spacing along the track,
    # shared by the samples there; the shift it moves the fit by has about terrain_sigma^2 n_post A^-1
    n_post = post_spacing_m(dem, lat_c) / max(spacing_m, 1e-3)
    cov = cov + LAD_EFFICIENCY_LOSS * terrain_sigma_m**2 * min(n_post, m) * A_inv
    if not remove_bias:
        # a common height bias b moves the shift of a match without bias removal by A^-1 sum_k g_k b
        j = A_inv @ g.sum(axis=0)
        cov = cov + height_bias_sigma_m**2 * np.outer(j, j)
    cov = 0.5 * (cov + cov.T) + quantisation
    if not np.all(np.isfinite(cov)) or np.linalg.eigvalsh(cov)[0] <= 0.0 or cov.max() > NO_INFORMATION_VAR_M2:
        return no_info
    return cov


def _matched(dem, lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m, dn_fix_m, de_fix_m):
    """The batch's finite samples at the match: (lat, lon of the finite samples; measured and map heights,
    map slopes g (m, 2: north, east) and the finite-samples mask `use` of the m samples whose map lookups
    are finite; the batch's mean latitude and the north / east radii), or None with fewer than 3 samples."""
    lat, lon, hm, dn, de = (np.asarray(x, float) for x in (lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m))
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hm) & np.isfinite(dn) & np.isfinite(de)
    if ok.sum() < 3:
        return None
    lat, lon, hm, dn, de = lat[ok], lon[ok], hm[ok], dn[ok], de[ok]
    lat_c = float(np.mean(lat))
    r_ns = meridian_radius_m(lat_c)
    r_ew = prime_vertical_radius_m(lat_c) * math.cos(lat_c)
    lat_m = lat + (dn + dn_fix_m) / r_ns
    lon_m = lon + (de + de_fix_m) / r_ew
    h_map = dem.height(lat_m, lon_m)
    g_n, g_e = dem.gradient(lat_m, lon_m)
    use = np.isfinite(h_map) & np.isfinite(g_n) & np.isfinite(g_e)
    if use.sum() < 3:
        return None
    g = np.stack([g_n[use], g_e[use]], axis=1)
    return lat, lon, hm[use], h_map[use], g, use, lat_c, r_ns, r_ew


def slope_weighted_mean(dem, lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m, dn_fix_m: float, de_fix_m: float,
                        values: np.ndarray) -> np.ndarray | None:
    """A^-1 sum_k g_k g_k^T values_k (2, n): the shift a least-squares match of the batch takes from
    per-sample horizontal errors values (M, 2, n; the batch's samples in time order, as lad_fix_covariance
    takes them), g_k the map's slope at the matched point, A = sum_k g_k g_k^T (module docstring). None when
    the map gives no horizontal information (fewer than 3 usable samples or A singular)."""
    matched = _matched(dem, lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m, dn_fix_m, de_fix_m)
    if matched is None:
        return None
    lat, lon, hm, dn = (np.asarray(x, float) for x in (lat_rad, lon_rad, h_meas_m, dn_rel_m))
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hm) & np.isfinite(dn) & np.isfinite(
        np.asarray(de_rel_m, float))
    g, use = matched[4], matched[5]
    v = np.asarray(values, float)[ok][use]
    A = g.T @ g
    if not np.all(np.isfinite(A)) or np.linalg.cond(A) > 1e12:
        return None
    gv = np.einsum("ki,kj,kjn->in", g, g, v)
    return np.linalg.solve(A, gv)
