"""Terrain-database (DEM) integrity monitor in the vertical domain (seed 003, eqs 1-5).

Runs beside any navigator on the same sensor frames and the navigator's estimate; it never imports the
simulator, so it runs on logs of real flights too:

    mon = DemIntegrityMonitor(dem=the_navigators_map)              # N = 50, threshold 96, DTED-1 sigma
    out = mon.update(frames, estimate)                             # MonitorOutput, one row per epoch

Per monitor epoch (one radar-altimeter sample every `sample_period_s`):

    h_synt = h_pos - h_radalt - lever_arm_m                        eq 1 (h_pos: GNSS height, or the
                                                                   navigator's when GNSS is denied)
    p      = h_synt - h_map(lat, lon)                              eq 2, the map at the position in use
    s      = p - p_prev                                            eq 3 (reported, not tested)
    T      = sum over the last N epochs of p^2 / sigma^2           eq 4
    T_KF   = sum over the last N epochs of x_hat^2 / P             eq 5 (variant "kalman": x_hat, P from
                                                                   a scalar Kalman filter of the disparity)
    T_KI   = sum over the last N epochs of nu^2 / S                eq 5 read on the same filter's
                                                                   innovations nu = p - x_hat_prior, S =
                                                                   P_prior + sigma^2 (variant
                                                                   "kalman_innovation": the reading that
                                                                   reproduces the paper's claims)

Beam model: a pulse radar altimeter reports the shortest range inside its beam, not the height above the
ground under the aircraft; over rough terrain at 600 m above ground that is 20-40 m less, which eq 2 with
the map's nadir height takes for a map error. With `beam_half_angle_deg` > 0 (the scenario sets the fitted
altimeter's) the map's height in eq 2 is the one the beam would see on the map: h_pos - lever arm - R_map,
R_map the map's shortest return in the same cone (terrain.queries, exact); 0 keeps eq 2's nadir height.

An alarm is T > threshold. sigma is the disparity's standard deviation: the map error class's (seed 003:
DTED-1 absolute disparities ~ N(0, 18.9^2) m; the other classes: LE90 / 1.6449 of terrain.map_error) or
`sigma_m`, plus, per epoch, the radar altimeter's noise (noise_const_m + noise_fraction * range, the
sensor's specification) and the height source's variance (GNSS vertical sigma, or the navigator's own
down variance and its horizontal covariance through the map's slope). With independent Gaussian
disparities T is chi-square with N degrees of freedom, so the threshold may be given as a false-alarm
probability instead: threshold = chi2.ppf(1 - P_fa, N) (96.0 for 1e-4 at N = 50, the paper's pair). The
chi-square design needs independent disparities. A real map's error is correlated along the track: with
`correlation_length_m` > 0 (the map error model's, terrain.map_error; the scenario fills it in) the plain
variant tests the whitened statistic T_w = p' Sigma^-1 p of the window instead (Sigma from the model's
correlation function at the epochs' own distances, its bias share `map_bias_fraction`, the white
radar-altimeter and GNSS variances, and the navigator's position error when it is the height source:
navigators.integrity.correlated_disparity). T_w is chi-square with N dof for any spacing, so the threshold
and P_fa keep their chi-square design; the price is detection (a correlated map error and a bias look alike
over a window): docs/validation/integrity.md measures both.

GNSS denied, the height and position come from the navigator, whose error is correlated across the window:
its horizontal error reaches every disparity through the map's slope under that epoch, and the same error
(not an independent one per epoch) lies under the whole window. Whenever the window holds such an epoch the
plain variant whitens (even with a white map), the navigator's error taken as first-order Gauss-Markov in
time with `navigator_error_time_constant_s` (horizontal) and `navigator_height_time_constant_s` (0: constant
over the window); eq 4's per-epoch sum would treat the window's 50 slope terms as independent.

Option `bias_glrt_false_alarm_probability` > 0 adds the generalised likelihood-ratio test of a bias common
to the window on the whitened disparities, T_b = (1' Sigma^-1 p)^2 / (1' Sigma^-1 1), chi-square with 1 dof,
with its own threshold chi2.isf(P_fa_b, 1); an alarm is T_w > threshold or T_b > its threshold (the
combined false-alarm probability is at most the sum). A bias spends all its energy in the one direction
T_b looks at, so it is found sooner than by T_w's N dof when the map error is white or short-correlated;
under long correlation a bias and the map's own slow error look alike to both.

Eq 5's x_hat values are correlated from epoch to epoch, so T_KF is not chi-square with N dof; given a
false-alarm probability the "kalman" variant's threshold is the exact quantile of T_KF's generalised
chi-square under no fault (`kalman_threshold`), and an explicit threshold (default 96, as in the paper) is
used as it is. docs/validation/integrity.md shows which readings of eq 5 were tried and that none
reproduces the paper's claims.

Source codes in the output: SOURCE_GNSS = 0 (GNSS fix within `gnss_max_age_s`), SOURCE_NAVIGATOR = 1.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...terrain.geodesy import radii_m
from ...terrain.kernels import map_height
from ...terrain.queries.radar_altimeter import _ra_batch
from ...terrain.queries.shared import _ra_tables, _ra_workspace
from ..core.maps import load_map
from ..frames import SensorFrames
from ..protocol import Estimate
from .correlated_disparity import whitened_statistic
from .dem_monitor_settings import (  # noqa: F401 - re-exported
    CAPABILITIES,
    CORRELATION_CODES,
    DEFAULT_N,
    DEFAULT_THRESHOLD,
    VARIANTS,
    DemMonitorConfig,
)
from .dem_monitor_thresholds import (  # noqa: F401 - re-exported
    DTED1_DISPARITY_SIGMA_M,
    DTED1_SUCCESSIVE_SIGMA_M,
    chi2_threshold,
    class_sigma_m,
    kalman_statistic_moments,
    kalman_threshold,
    kf_steady_state,
)

SOURCE_GNSS = 0
SOURCE_NAVIGATOR = 1
SOURCE_NAMES = ("gnss", "navigator")

class MonitorOutput:
    """One update's monitor epochs (possibly none): `rows` (m, 7) = time (s), absolute disparity p (m, eq 2),
    successive disparity s (m, eq 3), sigma (m), the statistic (eq 4 or 5; NaN until the window holds N
    epochs), alarm (0/1), height source (SOURCE_GNSS / SOURCE_NAVIGATOR); the columns are also attributes.
    `threshold`; `events`: (t_s, message) of alarms raised and cleared."""

    __slots__ = ("rows", "threshold", "events")
    COLUMNS = ("t_s", "disparity_m", "successive_m", "sigma_m", "statistic", "alarm", "source")

    def __init__(self, rows: np.ndarray, threshold: float, events: list):
        self.rows = rows
        self.threshold = threshold
        self.events = events

    def __getstate__(self):
        return self.rows, self.threshold, self.events

    def __setstate__(self, state):
        self.rows, self.threshold, self.events = state

    t_s = property(lambda self: self.rows[:, 0])
    disparity_m = property(lambda self: self.rows[:, 1])
    successive_m = property(lambda self: self.rows[:, 2])
    sigma_m = property(lambda self: self.rows[:, 3])
    statistic = property(lambda self: self.rows[:, 4])
    alarm = property(lambda self: self.rows[:, 5] > 0.5)
    source = property(lambda self: self.rows[:, 6].astype(np.int8))

    @property
    def source_names(self) -> list[str]:
        return [SOURCE_NAMES[int(s)] for s in self.source]


@njit(cache=True)
def _epoch_kernel(ra, gnss, est, rec, cfg, state, out):
    """Pick the frame's monitor epochs (one valid radar-altimeter sample per period) and their positions:
    rows [t, lat, lon, h, measured range, nadir map height, height-source variance, source, map slope north,
    east (navigator source only)] into `out`;
    returns their number. The position is the GNSS fix nearest in time (within cfg[7]) moved to the sample
    time with its velocity, else the navigator's estimate dead-reckoned to it.

    Records (numba tuples): ra = the radar altimeter's (t_s, range_m, valid); gnss = the fixes' (t_s,
    lat_rad, lon_rad, h_m, v_ned_mps (n, 3), valid); rec = the map (terrain.kernels.MapRecord, bilinear).
    est: [t, lat, lon, h, vn, ve, vd, P_nn, P_ne, P_ee, P_dd] of the navigator's estimate.
    cfg: [N, period, lever arm, map sigma, ra const, ra fraction, gnss sigma, gnss max age, variant (0/1),
          kf q ratio, threshold]; state[0]: the next epoch's earliest time."""
    t_ra, r_ra, v_ra = ra
    t_g, lat_g, lon_g, h_g, v_g, ok_g = gnss
    dlat = rec[3]
    period = cfg[1]
    m = 0
    n_g = t_g.shape[0]
    jg = 0
    for i in range(t_ra.shape[0]):
        t = t_ra[i]
        if t < state[0] - 1e-9 or not v_ra[i]:
            continue
        r = r_ra[i]
        if not (r == r) or r <= 0.0:
            continue
        best = -1
        best_dt = cfg[7]
        while jg + 1 < n_g and t_g[jg + 1] <= t:
            jg += 1
        for j in (jg, jg + 1):
            if j < n_g and ok_g[j] and abs(t_g[j] - t) <= best_dt:
                best_dt = abs(t_g[j] - t)
                best = j
        if best >= 0:
            dt = t - t_g[best]
            lat, lon, h = lat_g[best], lon_g[best], h_g[best]
            vn, ve, vd = v_g[best, 0], v_g[best, 1], v_g[best, 2]
            var_pos = cfg[6] * cfg[6]
            src = 0
        else:
            dt = t - est[0]
            lat, lon, h = est[1], est[2], est[3]
            vn, ve, vd = est[4], est[5], est[6]
            var_pos = est[10]
            src = 1
        if not (vn == vn and ve == ve and vd == vd):
            vn = ve = vd = 0.0
        rn, re = radii_m(lat)
        lat_t = lat + vn * dt / (rn + h)
        lon_t = lon + ve * dt / ((re + h) * math.cos(lat))
        h_t = h - vd * dt
        h_map = map_height(rec, lat_t, lon_t)
        if not (h_map == h_map) or not (h_t == h_t):
            continue
        if src == 1:
            # the navigator's horizontal uncertainty through the map's slope (central differences)
            e = 0.5 * dlat
            gn = (map_height(rec, lat_t + e, lon_t) - map_height(rec, lat_t - e, lon_t)) / (2.0 * e * rn)
            ge = (map_height(rec, lat_t, lon_t + e)
                  - map_height(rec, lat_t, lon_t - e)) / (2.0 * e * re * math.cos(lat_t))
            if gn == gn and ge == ge:
                var_pos += gn * gn * est[7] + 2.0 * gn * ge * est[8] + ge * ge * est[9]
                out[m, 8] = gn
                out[m, 9] = ge
            else:
                out[m, 8] = 0.0
                out[m, 9] = 0.0
        out[m, 0] = t
        out[m, 1] = lat_t
        out[m, 2] = lon_t
        out[m, 3] = h_t
        out[m, 4] = r
        out[m, 5] = h_map
        out[m, 6] = var_pos
        out[m, 7] = src
        if src == 0:
            out[m, 8] = 0.0
            out[m, 9] = 0.0
        m += 1
        state[0] = (math.floor(t / period + 1e-9) + 1.0) * period
    return m


@njit(cache=True)
def _est_terms(est):
    """[P_dd, -, -, P_nn, P_ne, P_ee] of the navigator's estimate for the whitened statistic's ring."""
    return np.array([est[10], 0.0, 0.0, est[7], est[8], est[9]])


@njit(cache=True)
def _statistic_kernel(rows, r_map, cfg, state, ring, wring, est_terms, out):
    """Eqs 1-5 over the epochs `rows` (_epoch_kernel's); r_map: the map's predicted radar-altimeter range
    at each epoch (beam model "cone") or an empty array (nadir: eq 2's map height under the position).
    Writes [t, p, s, sigma, T, alarm, source] into `out`.
    state: [next epoch time, count, ring position, last p, kf x, kf P, alarm seen]; ring (N, 3): the
    terms p^2/sigma^2, x^2/P and nu^2/S; wring (N, 11): the ring of correlated_disparity.whitened_statistic
    (used when cfg[16] > 0: a correlated map error, when the window holds an epoch whose position came from
    the navigator - its error is correlated across the window - or when the bias GLRT is on, cfg[21] > 0,
    an alarm also when T_b > cfg[21]); est_terms: the navigator's [P_dd, -, -, P_nn, P_ne, P_ee] for it."""
    n_win = int(cfg[0])
    sig_map2 = cfg[3] * cfg[3]
    kalman = cfg[8] > 0.5                              # 1: eq 5 on x_hat, 2: on the innovations
    q_ratio = cfg[9]
    thr = cfg[10]
    cone = r_map.shape[0] > 0
    corr_len = cfg[16]
    whiten = (corr_len > 0.0 or cfg[21] > 0.0) and not kalman
    sig_b2 = cfg[18] * sig_map2
    sig_r2 = sig_map2 - sig_b2
    m = 0
    for i in range(rows.shape[0]):
        r = rows[i, 4]
        h_synt = rows[i, 3] - r - cfg[2]               # seed 003 eq 1
        if cone:
            if not (r_map[i] == r_map[i]):
                continue
            h_db = rows[i, 3] - cfg[2] - r_map[i]      # the map's height as the beam sees it
        else:
            h_db = rows[i, 5]
        p = h_synt - h_db                              # eq 2
        sig_ra = cfg[4] + cfg[5] * r
        var = sig_map2 + sig_ra * sig_ra + rows[i, 6]
        if not (p == p and var == var and var < np.inf):
            continue                                   # a non-finite estimate: the epoch is skipped
        s = p - state[3] if state[1] > 0 else np.nan   # eq 3
        state[3] = p
        # eq 5's scalar filter of the disparity (random walk, q = q_ratio * sigma^2 per epoch), started at
        # its steady state
        if state[1] == 0:
            q = q_ratio * var
            pp = 0.5 * (q + math.sqrt(q * q + 4.0 * q * var))
            state[4] = 0.0
            state[5] = pp * var / (pp + var)
        p_prior = state[5] + q_ratio * var
        innov_term = (p - state[4]) ** 2 / (p_prior + var)   # eq 5 read on the innovations (before update)
        k = p_prior / (p_prior + var)
        state[4] += k * (p - state[4])
        state[5] = (1.0 - k) * p_prior
        pos = int(state[2])
        ring[pos, 0] = p * p / var                     # eq 4 term
        ring[pos, 1] = state[4] * state[4] / state[5]  # eq 5 term
        ring[pos, 2] = innov_term                      # eq 5, innovation reading
        wring[pos, 0] = p
        wring[pos, 1] = rows[i, 1]
        wring[pos, 2] = rows[i, 2]
        nav_src = rows[i, 7] > 0.5                     # the navigator's height: common to the window
        wring[pos, 3] = sig_ra * sig_ra + (0.0 if nav_src else rows[i, 6])
        for c9 in range(6):                            # P_dd, g_n, g_e, P_nn, P_ne, P_ee (navigator only)
            wring[pos, 4 + c9] = est_terms[c9] if nav_src else 0.0
        if nav_src:
            wring[pos, 5] = rows[i, 8]                 # the map's slope under the epoch
            wring[pos, 6] = rows[i, 9]
        wring[pos, 10] = rows[i, 0]
        state[2] = (pos + 1) % n_win
        state[1] += 1
        col = int(cfg[8])
        tot = np.nan
        t_bias = 0.0
        nav_in_window = False
        if state[1] >= n_win and not kalman and not whiten:
            for k2 in range(n_win):
                if wring[k2, 4] > 0.0 or wring[k2, 7] > 0.0 or wring[k2, 9] > 0.0:
                    nav_in_window = True
                    break
        if state[1] >= n_win and (whiten or nav_in_window):   # p' Sigma^-1 p: chi2(N) under the model
            tot, t_bias = whitened_statistic(wring, int(state[2]), n_win, sig_r2, sig_b2, corr_len,
                                             int(cfg[17]), cfg[19], cfg[20])
        elif state[1] >= n_win:
            tot = 0.0
            for k2 in range(n_win):
                tot += ring[k2, col]
        out[m, 0] = rows[i, 0]
        out[m, 1] = p
        out[m, 2] = s
        out[m, 3] = math.sqrt(var)
        out[m, 4] = tot
        out[m, 5] = 1.0 if tot > thr or (cfg[21] > 0.0 and t_bias > cfg[21]) else 0.0
        if out[m, 5] > 0.0:
            state[6] = 1.0                             # an alarm epoch in this update
        out[m, 6] = rows[i, 7]
        m += 1
    return m


@njit(cache=True)
def window_statistics(terms, n_win):
    """Sliding sums of n_win consecutive terms along axis 1 of a (M, K) array (eq 4 / eq 5 over every
    window of each row): (M, K - n_win + 1). Vectorised false-alarm and detection studies use this."""
    mrows, k = terms.shape
    out = np.empty((mrows, k - n_win + 1))
    for a in range(mrows):
        tot = 0.0
        for j in range(n_win):
            tot += terms[a, j]
        out[a, 0] = tot
        for j in range(n_win, k):
            tot += terms[a, j] - terms[a, j - n_win]
            out[a, j - n_win + 1] = tot
    return out


@njit(cache=True)
def kalman_terms(p, var, q_ratio):
    """Eq 5's terms x_hat^2 / P along each row of disparities p (M, K) with variances var (M, K), by the
    same scalar filter as the monitor (started at its steady state)."""
    mrows, k = p.shape
    out = np.empty((mrows, k))
    for a in range(mrows):
        x = 0.0
        q = q_ratio * var[a, 0]
        pp = 0.5 * (q + math.sqrt(q * q + 4.0 * q * var[a, 0]))
        P = pp * var[a, 0] / (pp + var[a, 0])
        for j in range(k):
            r = var[a, j]
            prior = P + q_ratio * r
            g = prior / (prior + r)
            x += g * (p[a, j] - x)
            P = (1.0 - g) * prior
            out[a, j] = x * x / P
    return out


@njit(cache=True)
def _update_kernel(ra, gnss, est, rec, mon, tables):
    """One monitor update in one call: the epochs (_epoch_kernel), with the beam model the map's own
    radar-altimeter return at each (terrain.queries' exact cone search, the body down axis of the estimate's
    roll/pitch/yaw in cfg[11:14]), then the statistic (_statistic_kernel). Returns the rows written.
    ra, gnss, est, rec: as _epoch_kernel's; mon = the monitor's (cfg, state, ring, wring, rows, out) arrays;
    tables = (cone, cell_m, bs, bmax, bmin, h_min, h_max, blk_lb, blk_id): whether the beam model runs and
    terrain.queries' search tables and workspace for it."""
    cfg, state, ring, wring, rows, out = mon
    cone, cell_m, bs, bmax, bmin, h_min, h_max, blk_lb, blk_id = tables
    m = _epoch_kernel(ra, gnss, est, rec, cfg, state, rows)
    if m == 0:
        return 0
    if not cone:
        return _statistic_kernel(rows[:m], rows[:0, 0], cfg, state, ring, wring, _est_terms(est), out)
    cr, sr = math.cos(est[11]), math.sin(est[11])
    cp, sp = math.cos(est[12]), math.sin(est[12])
    cy, sy = math.cos(est[13]), math.sin(est[13])
    C = np.empty((m, 3, 3))
    lat = np.empty(m)
    lon = np.empty(m)
    h = np.empty(m)
    for i in range(m):
        lat[i] = rows[i, 1]
        lon[i] = rows[i, 2]
        h[i] = rows[i, 3] - cfg[2]
        # the beam axis: the third column of the body-to-NED DCM (3-2-1, terrain.geodesy.euler_to_C_bn), the
        # only part the search reads (the other entries stay unset)
        C[i, 0, 2] = cr * sp * cy + sr * sy
        C[i, 1, 2] = cr * sp * sy - sr * cy
        C[i, 2, 2] = cr * cp
    valid = np.zeros(m, np.bool_)
    rng = np.empty(m)
    la = np.empty(m)
    lo = np.empty(m)
    hh = np.empty(m)
    _ra_batch(rec, cell_m, (lat, lon, h, C), cfg[14], cfg[15], (bs, bmax, bmin, h_min, h_max),
              (blk_lb, blk_id), (valid, rng, la, lo, hh))
    for i in range(m):
        if not valid[i]:
            rng[i] = np.nan
    return _statistic_kernel(rows[:m], rng, cfg, state, ring, wring, _est_terms(est), out)


_EMPTY = np.zeros(0)
_EMPTY_B = np.zeros(0, np.bool_)
_EMPTY3 = np.zeros((0, 3))
_EMPTY_I = np.zeros(0, np.int64)
_NO_TABLES = (1, np.zeros((1, 1)), np.zeros((1, 1)), 0.0, 0.0, 1.0)


class DemIntegrityMonitor:
    """The seed 003 monitor over the navigator's map `dem` (terrain.Dem); settings: DemMonitorConfig's
    fields. `update(frames, estimate)` -> MonitorOutput; it needs frames.radar_altimeter (epochs are
    skipped without it) and uses frames.gnss while fixes are there."""

    name = "dem_integrity"
    capabilities = CAPABILITIES
    settings_class = DemMonitorConfig        # what `trn-env navigators` lists as its settings
    _NONE = np.zeros((0, 7))

    def __init__(self, dem=None, settings: DemMonitorConfig | None = None, **overrides):
        dem = load_map(dem, "the DEM integrity monitor")
        self.config = self.settings = DemMonitorConfig.build(settings, overrides)
        if self.config.correlation_length_m > 0.0:
            from ...terrain.map_error import check_fits
            check_fits(dem, self.config.correlation_length_m)
        self.dem = dem
        c = self.config
        self.threshold = c.effective_threshold
        # the bias GLRT's chi2(1) threshold (0: off)
        self.bias_threshold = (chi2_threshold(c.bias_glrt_false_alarm_probability, 1)
                               if c.bias_glrt_false_alarm_probability > 0.0 else 0.0)
        self._cfg = np.array([c.n_window, c.sample_period_s, c.lever_arm_m, c.map_sigma_m,
                              c.radar_altimeter_noise_const_m, c.radar_altimeter_noise_fraction,
                              c.gnss_vertical_sigma_m, c.gnss_max_age_s,
                              float(VARIANTS.index(c.variant)),
                              c.kf_process_ratio, self.threshold, 0.0, 0.0, 0.0,
                              math.radians(c.beam_half_angle_deg), c.max_range_m,
                              c.correlation_length_m, CORRELATION_CODES[c.correlation_function],
                              c.map_bias_fraction, c.navigator_error_time_constant_s,
                              c.navigator_height_time_constant_s, self.bias_threshold], float)
        self._est = np.zeros(14)
        self._rows = np.empty((64, 10))
        self._out = np.empty((64, 7))
        self._half_beam = math.radians(c.beam_half_angle_deg)
        self.reset()

    def reset(self) -> None:
        self._state = np.array([-np.inf, 0.0, 0.0, np.nan, 0.0, 1.0, 0.0])
        self._ring = np.zeros((int(self.config.n_window), 3))
        self._wring = np.zeros((int(self.config.n_window), 11))
        self._alarm = False

    def update(self, frames: SensorFrames, estimate: Estimate) -> MonitorOutput:
        ra = frames.radar_altimeter
        if ra is None or ra.t_s.shape[0] == 0:
            return MonitorOutput(self._NONE, self.threshold, [])
        g = frames.gnss
        if g is not None and g.t_s.shape[0]:
            gargs = (g.t_s, g.lat_rad, g.lon_rad, g.h_m, g.v_ned_mps, g.valid)
        else:
            gargs = (_EMPTY, _EMPTY, _EMPTY, _EMPTY, _EMPTY3, _EMPTY_B)
        e = self._est
        c = estimate.covariance
        v = estimate.v_ned_mps
        e[0], e[1], e[2], e[3] = estimate.t_s, estimate.lat_rad, estimate.lon_rad, estimate.h_m
        e[4], e[5], e[6] = v[0], v[1], v[2]
        e[7], e[8], e[9], e[10] = c[0, 0], c[0, 1], c[1, 1], c[2, 2]
        e[11], e[12], e[13] = estimate.roll_rad, estimate.pitch_rad, estimate.yaw_rad
        n = ra.t_s.shape[0]
        if self._out.shape[0] < n:
            self._out = np.empty((n, 7))
            self._rows = np.empty((n, 10))
        cone = self._half_beam > 0.0
        if cone:        # the map's search tables (cached on the Dem, rebuilt when its heights change)
            bs, bmax, bmin, h_min, h_max, cell_m = _ra_tables(self.dem)
            lb, ids = _ra_workspace(bmax.size)
        else:
            bs, bmax, bmin, h_min, h_max, cell_m = _NO_TABLES
            lb, ids = _EMPTY, _EMPTY_I
        m = _update_kernel((ra.t_s, ra.range_m, ra.valid), gargs, e, self.dem.record(),
                           (self._cfg, self._state, self._ring, self._wring, self._rows, self._out),
                           (cone, cell_m, bs, bmax, bmin, h_min, h_max, lb, ids))
        if m == 0:
            return MonitorOutput(self._NONE, self.threshold, [])
        rows = self._out[:m].copy()
        events = []
        if self._alarm or self._state[6] > 0.0:       # an alarm was on or came on in this update
            alarm = rows[:, 5] > 0.5
            flips = np.flatnonzero(np.diff(np.r_[self._alarm, alarm].astype(np.int8)))
            for k in flips:
                t_k = float(rows[k, 0])
                if alarm[k]:
                    events.append((t_k, f"DEM integrity alarm: T={rows[k, 4]:.1f} > {self.threshold:.1f} "
                                        f"(source {SOURCE_NAMES[int(rows[k, 6])]})"))
                else:
                    events.append((t_k, f"DEM integrity alarm cleared: T={rows[k, 4]:.1f}"))
            self._alarm = bool(alarm[-1])
            self._state[6] = 0.0
        return MonitorOutput(rows, self.threshold, events)


def output_problem(out) -> str | None:
    """Why a monitor's update output is not a MonitorOutput's shape (rows (m, 7) of MonitorOutput.COLUMNS,
    a threshold, an events list), or None when it is: what the loop concatenates at a run's end."""
    rows, events = getattr(out, "rows", None), getattr(out, "events", None)
    width = len(MonitorOutput.COLUMNS)
    if (isinstance(rows, np.ndarray) and rows.ndim == 2 and rows.shape[1] == width
            and isinstance(events, list) and hasattr(out, "threshold")):
        return None
    return (f"update() returned {type(out).__name__} (rows of shape {getattr(rows, 'shape', None)}, events "
            f"{type(events).__name__}), not a MonitorOutput with rows (m, {width}) of "
            f"{', '.join(MonitorOutput.COLUMNS)}, a threshold and an events list")


def concatenate(outputs: list[MonitorOutput]) -> dict[str, np.ndarray]:
    """Arrays of a run's monitor outputs, concatenated: t_s, disparity_m, successive_m, sigma_m, statistic,
    alarm (bool), source (int8), threshold."""
    rows = np.concatenate([o.rows for o in outputs]) if outputs else np.zeros((0, 7))
    out = {k: rows[:, i].copy() for i, k in enumerate(MonitorOutput.COLUMNS)}
    out["alarm"] = out["alarm"] > 0.5
    out["source"] = out["source"].astype(np.int8)
    out["threshold"] = np.full(rows.shape[0], outputs[0].threshold if outputs else np.nan)
    return out


def alarm_summary(arrays: dict[str, np.ndarray]) -> dict:
    """Time of the first alarm (s; None without one), alarm epochs, alarm episodes (rising edges),
    epochs, and the fraction of epochs on each height source."""
    alarm = np.asarray(arrays["alarm"], bool)
    src = np.asarray(arrays["source"])
    rises = int(np.count_nonzero(np.diff(np.r_[False, alarm].astype(np.int8)) > 0))
    return {
        "first_alarm_t_s": float(arrays["t_s"][np.argmax(alarm)]) if alarm.any() else None,
        "alarm_epochs": int(alarm.sum()),
        "alarm_count": rises,
        "epochs": int(alarm.size),
        "threshold": float(arrays["threshold"][0]) if alarm.size else None,
        "statistic_max": float(np.nanmax(arrays["statistic"])) if np.isfinite(arrays["statistic"]).any()
        else None,
        "fraction_source_gnss": float(np.mean(src == SOURCE_GNSS)) if src.size else None,
        "fraction_source_navigator": float(np.mean(src == SOURCE_NAVIGATOR)) if src.size else None,
    }


def replay_log(monitor: DemIntegrityMonitor, log: dict, period_s: float = 1.0) -> dict[str, np.ndarray]:
    """Run a monitor over a recorded flight: `log` holds arrays named as a run's `result.arrays` (on disk:
    trn_env.logs.read_log(run / "log").arrays(), the sensor log's tables under these names)
    (sensor_radar_altimeter_{t_s, range_m, valid}, sensor_gnss_{t_s, lat_rad, lon_rad, h_m, v_ned_mps, valid}
    if GNSS was recorded, and the estimates est_{t_s, lat_rad, lon_rad, h_m, v_ned_mps, roll_rad, pitch_rad,
    yaw_rad, cov}). The samples are handed over in intervals (a, b] of period_s (the closed loop's update
    intervals at its default 1 Hz), each with the first estimate at or after b; returns `concatenate` of
    the outputs."""
    from ..frames import GnssFrame, RadarAltimeterFrame
    from ..protocol import Health
    monitor.reset()
    t_ra = np.asarray(log["sensor_radar_altimeter_t_s"], float)
    has_g = "sensor_gnss_t_s" in log
    t_g = np.asarray(log["sensor_gnss_t_s"], float) if has_g else np.zeros(0)
    t_est = np.asarray(log["est_t_s"], float)
    outs = []
    t0 = (math.ceil(t_ra[0] / period_s) - 1.0) * period_s if t_ra.size else 0.0
    edges = np.arange(t0, t_ra[-1] + period_s, period_s) if t_ra.size else np.zeros(0)
    for a, b in zip(edges[:-1], edges[1:], strict=True):    # intervals (a, b], as the closed loop's
        ka = np.searchsorted(t_ra, a, "right")
        kb = np.searchsorted(t_ra, b, "right")
        if kb == ka:
            continue
        ra = RadarAltimeterFrame(t_ra[ka:kb], np.asarray(log["sensor_radar_altimeter_range_m"])[ka:kb],
                                 np.asarray(log["sensor_radar_altimeter_valid"])[ka:kb])
        g = None
        if has_g:
            ga, gb = np.searchsorted(t_g, a, "right"), np.searchsorted(t_g, b, "right")
            if gb > ga:
                g = GnssFrame(*(np.asarray(log[f"sensor_gnss_{k}"])[ga:gb]
                                for k in ("t_s", "lat_rad", "lon_rad", "h_m", "v_ned_mps", "valid")))
        i = min(int(np.searchsorted(t_est, b - 1e-9, "left")), t_est.size - 1)
        est = Estimate(float(t_est[i]), float(log["est_lat_rad"][i]), float(log["est_lon_rad"][i]),
                       float(log["est_h_m"][i]), np.asarray(log["est_v_ned_mps"][i], float),
                       float(log["est_roll_rad"][i]), float(log["est_pitch_rad"][i]),
                       float(log["est_yaw_rad"][i]),
                       np.asarray(log["est_cov"][i], float), Health())
        outs.append(monitor.update(SensorFrames(float(a), float(b), radar_altimeter=ra, gnss=g), est))
    return concatenate(outs)
