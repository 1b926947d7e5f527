"""Independent brute-force closest-point searches for the terrain query tests (numpy, exact ECEF).

Kept apart from terrain/queries.py on purpose: exact WGS84 ECEF conversions written here in numpy, a
numpy bilinear interpolation, and dense sampling instead of the product's coarse-to-fine search.
"""

from __future__ import annotations

import numpy as np

A = 6378137.0
F = 1.0 / 298.257223563
E2 = F * (2.0 - F)


def lla_to_ecef(lat, lon, h):
    lat, lon, h = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float))
    n = A / np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
    return np.stack([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - E2) + h) * np.sin(lat)], axis=-1)


def ecef_to_lla(xyz):
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - E2))
    h = np.zeros_like(p)
    for _ in range(10):
        n = A / np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - E2 * n / (n + h)))
    return lat, lon, h


def ned_to_ecef_matrix(lat, lon):
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])


def bilinear(dem, lat, lon):
    h = dem.heights_m
    fi = (np.asarray(lat) - dem.lat0_rad) / dem.dlat_rad
    fj = (np.asarray(lon) - dem.lon0_rad) / dem.dlon_rad
    ok = (fi >= 0) & (fj >= 0) & (fi <= h.shape[0] - 1) & (fj <= h.shape[1] - 1)
    i = np.clip(np.floor(fi).astype(int), 0, h.shape[0] - 2)
    j = np.clip(np.floor(fj).astype(int), 0, h.shape[1] - 2)
    u = fi - i
    v = fj - j
    out = ((1 - u) * (1 - v) * h[i, j] + (1 - u) * v * h[i, j + 1] + u * (1 - v) * h[i + 1, j]
           + u * v * h[i + 1, j + 1])
    return np.where(ok, out, np.nan)


def _ra_grid(dem, a_ecef, axis_ecef, cosb, lat_c, lon_c, half_m, step_m, max_range):
    m = 6.37e6
    n_s = int(np.ceil(2 * half_m / step_m)) + 1
    off = np.linspace(-half_m, half_m, n_s)
    lat = lat_c + off / m
    lon = lon_c + off / (m * np.cos(lat_c))
    lat_g, lon_g = np.meshgrid(lat, lon, indexing="ij")
    hg = bilinear(dem, lat_g, lon_g)
    p = lla_to_ecef(lat_g, lon_g, np.nan_to_num(hg, nan=-1e4))
    d = p - a_ecef
    r = np.linalg.norm(d, axis=-1)
    ok = np.isfinite(hg) & (d @ axis_ecef >= cosb * r) & (r <= max_range)
    r = np.where(ok, r, np.inf)
    return r, lat_g, lon_g, hg


def radar_altimeter(dem, lat, lon, h, C_bn, half_beam, max_range=8000.0, search_half_m=4000.0, coarse_m=8.0):
    """Closest in-cone terrain point by dense sampling (coarse grid over the search square, then nested
    fine grids around the best few coarse samples). Returns (range, lat, lon, h) or NaNs."""
    a = lla_to_ecef(lat, lon, h)
    cen = ned_to_ecef_matrix(lat, lon)
    axis = cen @ C_bn[:, 2]
    cosb = np.cos(half_beam)
    r, lat_g, lon_g, _ = _ra_grid(dem, a, axis, cosb, lat, lon, search_half_m, coarse_m, max_range)
    if not np.isfinite(r).any():
        return np.nan, np.nan, np.nan, np.nan
    order = np.argsort(r, axis=None)[:40]
    best = (np.inf, np.nan, np.nan, np.nan)
    seeds = []
    for idx in order:
        if not np.isfinite(r.flat[idx]) or r.flat[idx] > r.flat[order[0]] + 3.0:
            break
        la, lo = lat_g.flat[idx], lon_g.flat[idx]
        if any(abs(la - s[0]) * 6.37e6 < 3 * coarse_m and abs(lo - s[1]) * 5e6 < 3 * coarse_m for s in seeds):
            continue
        seeds.append((la, lo))
        half, step = 2.0 * coarse_m, 0.05 * coarse_m
        for _ in range(4):
            rr, la_g, lo_g, hh = _ra_grid(dem, a, axis, cosb, la, lo, half, step, max_range)
            k = np.argmin(rr)
            la, lo = la_g.flat[k], lo_g.flat[k]
            half, step = 3 * step, step / 20.0
        if rr.flat[k] < best[0]:
            best = (rr.flat[k], la, lo, hh.flat[k])
    return best


def ira(dem, lat, lon, h, v_ned, C_bn, half_window, max_range=12000.0, s_half_m=5000.0, coarse_m=2.0):
    """Closest terrain point on the zero-Doppler plane within the look-angle window, by scanning the plane:
    columns s (across, along w) with a dense z scan for every terrain crossing, then fine columns around the
    best with bisection in z. Returns (range, lat, lon, h, theta)."""
    a = lla_to_ecef(lat, lon, h)
    cen = ned_to_ecef_matrix(lat, lon)
    vhat = v_ned / np.linalg.norm(v_ned)
    w = np.cross([0.0, 0.0, 1.0], vhat)  # down x v: right-pointing horizontal
    w /= np.linalg.norm(w)
    q = np.cross(vhat, w)
    q /= np.linalg.norm(q)
    hmin, hmax = np.nanmin(dem.heights_m), np.nanmax(dem.heights_m)
    z_top, z_bot = h - hmax - 30.0, h - hmin + 30.0

    def crossings(s_vals, z_vals):
        pts_ned = s_vals[:, None, None] * w + z_vals[None, :, None] * q
        ecef = a + pts_ned @ cen.T
        la, lo, hh = ecef_to_lla(ecef)
        above = hh - bilinear(dem, la, lo)
        sign_change = (above[:, :-1] >= 0) & (above[:, 1:] < 0) | (above[:, :-1] < 0) & (above[:, 1:] >= 0)
        return sign_change

    s_all = np.arange(-s_half_m, s_half_m, coarse_m)
    z_all = np.arange(z_top, z_bot, 1.0)
    col_r = np.full(s_all.shape, np.inf)
    col_z = np.zeros(s_all.shape)
    for chunk in np.array_split(np.arange(len(s_all)), max(1, len(s_all) // 400)):
        ii, kk = np.nonzero(crossings(s_all[chunk], z_all))
        zz = 0.5 * (z_all[kk] + z_all[kk + 1])
        ned = s_all[chunk][ii, None] * w + zz[:, None] * q
        b = ned @ C_bn
        theta = np.arctan2(b[:, 1], b[:, 2])
        r = np.linalg.norm(ned, axis=1)
        r = np.where((b[:, 2] > 0) & (np.abs(theta) <= half_window), r, np.inf)
        for i_loc, rv, zv in zip(ii, r, zz):
            g = chunk[i_loc]
            if rv < col_r[g]:
                col_r[g], col_z[g] = rv, zv
    if not np.isfinite(col_r).any():
        return (np.nan,) * 5
    near = np.nonzero(col_r <= col_r.min() + 1.5)[0]
    # fine columns around every near-best coarse column; each crossing refined by bisection in z
    s_fine = np.unique(np.concatenate([np.arange(s_all[g] - 1.5 * coarse_m, s_all[g] + 1.5 * coarse_m, 0.01)
                                       for g in near]))
    z_c = col_z[near]
    z_vals = np.arange(max(z_top, z_c.min() - 40.0), min(z_bot, z_c.max() + 40.0), 0.5)
    ii, kk = np.nonzero(crossings(s_fine, z_vals))
    if len(ii) == 0:
        return (np.nan,) * 5
    s_c, z_lo, z_hi = s_fine[ii], z_vals[kk], z_vals[kk + 1]

    def above(zv):
        ecef = a + (s_c[:, None] * w + zv[:, None] * q) @ cen.T
        la, lo, hh = ecef_to_lla(ecef)
        return hh - bilinear(dem, la, lo)

    a_lo = above(z_lo)
    for _ in range(40):
        zm = 0.5 * (z_lo + z_hi)
        a_m = above(zm)
        same = (a_m >= 0) == (a_lo >= 0)
        z_lo = np.where(same, zm, z_lo)
        a_lo = np.where(same, a_m, a_lo)
        z_hi = np.where(same, z_hi, zm)
    zm = 0.5 * (z_lo + z_hi)
    ned = s_c[:, None] * w + zm[:, None] * q
    b = ned @ C_bn
    theta = np.arctan2(b[:, 1], b[:, 2])
    r = np.linalg.norm(ned, axis=1)
    r = np.where((b[:, 2] > 0) & (np.abs(theta) <= half_window) & (r <= max_range), r, np.inf)
    k = int(np.argmin(r))
    if not np.isfinite(r[k]):
        return (np.nan,) * 5
    la, lo, hh = ecef_to_lla(a + cen @ ned[k])
    return float(r[k]), float(la), float(lo), float(hh), float(theta[k])


def _first_hits(dem, a, dirs_ecef, t_lo, t_hi, dt):
    """First terrain crossing along each ECEF ray (rows of dirs_ecef) in [t_lo, t_hi]: dense march, then
    bisection. Returns t (inf where no crossing)."""
    t_vals = np.arange(t_lo, t_hi + dt, dt)
    p = a + dirs_ecef[:, None, :] * t_vals[None, :, None]
    la, lo, hh = ecef_to_lla(p)
    above = hh - bilinear(dem, la, lo)
    below = above < 0
    has = below.any(axis=1)
    k = np.argmax(below, axis=1)
    ok = has & (k > 0)
    t_a = np.where(ok, t_vals[np.maximum(k - 1, 0)], np.nan)
    t_b = np.where(ok, t_vals[k], np.nan)
    for _ in range(45):
        tm = 0.5 * (t_a + t_b)
        la, lo, hh = ecef_to_lla(a + dirs_ecef * tm[:, None])
        am = hh - bilinear(dem, la, lo)
        t_a = np.where(am >= 0, tm, t_a)
        t_b = np.where(am >= 0, t_b, tm)
    return np.where(ok, 0.5 * (t_a + t_b), np.inf)


def radar_altimeter_boundary(dem, lat, lon, h, C_bn, half_beam, max_range=8000.0):
    """Closest terrain point ON the cone boundary: dense azimuth scan of boundary rays (first hits), then a
    fine scan around the best. Returns (range, lat, lon, h)."""
    a = lla_to_ecef(lat, lon, h)
    cen = ned_to_ecef_matrix(lat, lon)
    ax = C_bn[:, 2]
    e1 = np.cross(ax, [0.0, 0.0, 1.0] if abs(ax[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(ax, e1)
    hmin, hmax = np.nanmin(dem.heights_m), np.nanmax(dem.heights_m)

    def dirs(c):
        d = np.cos(half_beam) * ax + np.sin(half_beam) * (np.cos(c)[:, None] * e1 + np.sin(c)[:, None] * e2)
        return d @ cen.T, d

    def hits(c, t_lo, t_hi, dt):
        de, dn = dirs(c)
        lo = t_lo if np.ndim(t_lo) == 0 else t_lo
        return _first_hits(dem, a, de, lo, t_hi, dt), dn

    c = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    de, dn = dirs(c)
    down = np.clip(dn[:, 2], 1e-3, None)
    t_lo = max(0.0, (h - hmax - 5.0) / down.max())
    t_hi = min(max_range, (h - hmin + 10.0) / max(down.min(), 0.05))
    t = _first_hits(dem, a, de, t_lo, t_hi, 2.0)
    if not np.isfinite(t).any():
        return np.nan, np.nan, np.nan, np.nan
    k = int(np.argmin(t))
    c_f = np.linspace(c[k] - np.radians(1.0), c[k] + np.radians(1.0), 2001)
    de_f, _ = dirs(c_f)
    t_f = _first_hits(dem, a, de_f, max(0.0, t[k] - 40.0), t[k] + 40.0, 0.5)
    k = int(np.argmin(t_f))
    la, lo, hh = ecef_to_lla(a + de_f[k] * t_f[k])
    return float(t_f[k]), float(la), float(lo), float(hh)
