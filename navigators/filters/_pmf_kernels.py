"""numba kernels of the point-mass filter (navigators.filters.pmf): one pass over the grid's cells each."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core.maps import map_height
from ..measurements.terrain_models import LOG_2PI

NEGLIGIBLE = -60.0   # log-weight below which a cell's weight (< 1e-26) is left out of sums of weights


@njit(cache=True, fastmath=False, error_model="numpy")
def grid_moments(logw, dn, de, bias, out):
    """Weighted moments of the grid (weights exp(logw - max), normalised) into out (6,): mean north, mean
    east, var north, cov north-east, var east (m, m^2), mean of the per-cell bias, and its spread
    (sum w (b - mean b)^2) as out[6]. out must have 7 entries."""
    m = logw.shape[0]
    mx = -np.inf
    for k in range(m):
        if logw[k] > mx:
            mx = logw[k]
    s = sn = se = sb = 0.0
    for k in range(m):
        w = math.exp(logw[k] - mx)
        s += w
        sn += w * dn[k]
        se += w * de[k]
        sb += w * bias[k]
    mn, me, mb = sn / s, se / s, sb / s
    cnn = cne = cee = vb = 0.0
    for k in range(m):
        w = math.exp(logw[k] - mx) / s
        x = dn[k] - mn
        y = de[k] - me
        cnn += w * x * x
        cne += w * x * y
        cee += w * y * y
        vb += w * (bias[k] - mb) ** 2
    out[0] = mn
    out[1] = me
    out[2] = cnn
    out[3] = cne
    out[4] = cee
    out[5] = mb
    out[6] = vb


@njit(cache=True, fastmath=False, error_model="numpy")
def grid_cross_moments(logw, dn, de, bias, out):
    """Weighted covariance of the vertical offset's per-cell mean with the position over the grid (weights
    exp(logw - max), normalised) into out (2,): sum w (dn - mean)(b - mean b), the same with de (m^2)."""
    m = logw.shape[0]
    mx = -np.inf
    for k in range(m):
        if logw[k] > mx:
            mx = logw[k]
    s = sn = se = sb = snb = seb = 0.0
    for k in range(m):
        v = logw[k] - mx
        if v > NEGLIGIBLE:
            w = math.exp(v)
            s += w
            sn += w * dn[k]
            se += w * de[k]
            sb += w * bias[k]
            snb += w * dn[k] * bias[k]
            seb += w * de[k] * bias[k]
    out[0] = snb / s - sn * sb / (s * s)
    out[1] = seb / s - se * sb / (s * s)


@njit(cache=True, fastmath=False, error_model="numpy")
def apply_log_likelihood(logw, ll, floor):
    """logw += ll, renormalised so that its maximum is 0 and floored at `floor`; returns (log sum_k w_k
    exp(ll_k) with w the normalised prior weights, i.e. log p(z | past); the new maximum before
    renormalising). logw is left unchanged when every cell's posterior is -inf or NaN (returns -inf, -inf)."""
    m = logw.shape[0]
    mx0 = -np.inf
    mx = -np.inf
    for k in range(m):
        if logw[k] > mx0:
            mx0 = logw[k]
        v = logw[k] + ll[k]
        if v > mx:
            mx = v
    if not (mx > -np.inf) or mx != mx:
        return -np.inf, -np.inf
    s0 = 0.0
    s1 = 0.0
    for k in range(m):
        s0 += math.exp(logw[k] - mx0)
        v = logw[k] + ll[k]
        if v == v:
            s1 += math.exp(v - mx)
    for k in range(m):
        v = logw[k] + ll[k] - mx
        logw[k] = v if v > floor else floor
    # log sum w0 exp(ll) = log(sum exp(logw + ll)) - log(sum exp(logw))
    return (mx + math.log(s1)) - (mx0 + math.log(s0)), mx


@njit(cache=True, fastmath=False, error_model="numpy")
def predicted_moments(logw, pred):
    """Mean and variance of pred under the normalised weights exp(logw) over the finite entries."""
    mx = -np.inf
    for k in range(logw.shape[0]):
        if logw[k] > mx:
            mx = logw[k]
    s = sp = 0.0
    for k in range(logw.shape[0]):
        if pred[k] == pred[k]:
            w = math.exp(logw[k] - mx)
            s += w
            sp += w * pred[k]
    if s <= 0.0:
        return np.nan, np.nan
    mu = sp / s
    v = 0.0
    for k in range(logw.shape[0]):
        if pred[k] == pred[k]:
            v += math.exp(logw[k] - mx) * (pred[k] - mu) ** 2
    return mu, v / s


@njit(cache=True, fastmath=False, error_model="numpy")
def bias_update(bias, resid, gain):
    """bias += gain * resid where the residual is finite (the per-cell vertical offset's Kalman update)."""
    for k in range(bias.shape[0]):
        r = resid[k]
        if r == r:
            bias[k] += gain * r


@njit(cache=True, fastmath=False, error_model="numpy")
def ira_update_pass(rec, ref, grid, meas, robust, gam, out):
    """One IRA terrain update of the whole grid, fused (one map lookup per cell): the predicted terrain
    height map(cell + p) + bias (the map bicubic if cubic, else bilinear: terrain.kernels), the heavy-tailed
    log-likelihood (measurements.robust_ll_one inlined, its constants hoisted; variance S),
    logw += ll (renormalised to a maximum of 0, floored), bias += gamma gain residual with gamma the
    probability that the sample is an inlier under that cell (so an outlier return does not drag the vertical
    offsets: gam (n * n) receives it); and the moments. out[12]: the posterior mean of gamma.

    logw must hold log-densities with maximum 0 on entry (the filter keeps it so). out (14,): log p(z |
    past), prior mean and variance of the predicted height (over all cells; off-map cells count as 0 -
    negligible when few), number of cells off the map, the posterior's maximum before renormalising (-inf:
    every cell underflowed - logw and bias are then garbage: the caller restores them), then
    grid_moments' seven values of the posterior, the posterior mean of gamma, and the prior's probability
    mass on cells where the map has no height (off it, or a void).

    Records (numba tuples): ref = (lat, lon rad, r_lat, r_lon m) the INS position and the radii of the map
    lookups; grid = (dn, de m, logw, bias m) the cells' offsets, log-weights and vertical offsets (the last
    two updated in place); meas = (pn, pe m the closest point's horizontal offset, h_meas m, S m^2 its
    variance, gain the vertical offset's Kalman gain); robust = (lg, le, floor) the heavy-tailed
    likelihood's log inlier / outlier terms and the log-weight floor."""
    lat, lon, r_lat, r_lon = ref
    dn, de, logw, bias = grid
    pn, pe, h_meas, S, gain = meas
    lg, le, floor = robust
    m = logw.shape[0]
    s0 = sp = spp = s_nan = 0.0
    mx = -np.inf
    n_nan = 0
    c0 = lg - 0.5 * (math.log(S) + LOG_2PI)
    inv2s = 0.5 / S
    for k in range(m):
        la = lat + (dn[k] + pn) / r_lat
        lo = lon + (de[k] + pe) / r_lon
        h = map_height(rec, la, lo)
        lw = logw[k]
        w0 = math.exp(lw) if lw > NEGLIGIBLE else 0.0
        s0 += w0
        if h != h:
            n_nan += 1
            s_nan += w0
            v = lw + le
            gam[k] = 0.0
        else:
            pred = h + bias[k]
            sp += w0 * pred
            spp += w0 * pred * pred
            r = h_meas - pred
            a = c0 - inv2s * r * r      # robust_ll_one, with the constants hoisted
            d = a - le
            if le == -np.inf or d > 36.0:     # log1p(exp(-36)) < 3e-16: the Gaussian term alone
                v = lw + a
                g = 1.0
            elif d < -36.0:                   # the outlier term alone
                v = lw + le
                g = 0.0
            else:                             # ll = max(a, le) + log1p(e), gamma = exp(a - ll)
                e = math.exp(-abs(d))
                if d > 0.0:
                    v = lw + a + math.log1p(e)
                    g = 1.0 / (1.0 + e)
                else:
                    v = lw + le + math.log1p(e)
                    g = e / (1.0 + e)
            bias[k] += g * gain * r
            gam[k] = g
        logw[k] = v
        if v > mx:
            mx = v
    out[3] = n_nan
    out[4] = mx
    out[13] = s_nan / s0 if s0 > 0.0 else 0.0
    if not (mx > -np.inf) or mx != mx:
        out[0] = -np.inf
        return
    s1 = sn = se = sb = snn = sne = see = sbb = sg = 0.0
    for k in range(m):
        v = logw[k] - mx
        if v < floor:
            v = floor
        logw[k] = v
        if v > NEGLIGIBLE:
            w = math.exp(v)
            x = dn[k]
            y = de[k]
            b = bias[k]
            s1 += w
            sn += w * x
            se += w * y
            sb += w * b
            snn += w * x * x
            sne += w * x * y
            see += w * y * y
            sbb += w * b * b
            sg += w * gam[k]
    mn, me, mb = sn / s1, se / s1, sb / s1
    out[0] = (mx + math.log(s1)) - math.log(s0)
    out[1] = sp / s0
    out[2] = max(spp / s0 - (sp / s0) ** 2, 0.0)
    out[5] = mn
    out[6] = me
    out[7] = max(snn / s1 - mn * mn, 0.0)
    out[8] = sne / s1 - mn * me
    out[9] = max(see / s1 - me * me, 0.0)
    out[10] = mb
    out[11] = max(sbb / s1 - mb * mb, 0.0)
    out[12] = sg / s1


@njit(cache=True, fastmath=False, error_model="numpy")
def _pack_moments(logw, bias, work, m, floor):
    """Rows 0..2 of work: the grid's mass w = exp(logw), w b and w b^2 (b the per-cell vertical offset)."""
    for k in range(m):
        w = math.exp(logw[k]) if logw[k] > floor else 0.0
        work[0, k] = w
        work[1, k] = w * bias[k]
        work[2, k] = w * bias[k] * bias[k]


@njit(cache=True, fastmath=False, error_model="numpy")
def _unpack_moments(logw, bias, work, row, m, floor):
    """Back from convolved rows row..row+2 (w, w b, w b^2): logw (renormalised to a maximum of 0, floored),
    the cells' offsets, and the mass-weighted spread of the sources' offsets (returned)."""
    mx = -np.inf
    s = sv = 0.0
    for k in range(m):
        w = work[row, k]
        if w > 1e-300:
            b = work[row + 1, k] / w
            var = work[row + 2, k] / w - b * b
            bias[k] = b
            s += w
            sv += w * (var if var > 0.0 else 0.0)
            v = math.log(w)
        else:
            v = -np.inf
        logw[k] = v
        if v > mx:
            mx = v
    for k in range(m):
        v = logw[k] - mx
        logw[k] = v if v > floor else floor
    return sv / s if s > 0.0 else 0.0


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _convolve_along(work, src, dst, kern, n, di, dj):
    """Rows dst..dst+2 of work = rows src..src+2 (n x n grids, row-major) convolved with kern (odd length)
    along the grid direction (di, dj): cell (i, j) from (i + di s, j + dj s), s = -L/2..L/2 - (0, 1) east,
    (1, 0) north, (1, +-1) the diagonals; zero beyond the grid's edge."""
    L = kern.shape[0]
    h = L // 2
    for a in range(3):
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for q in range(L):
                    ii = i + di * (q - h)
                    jj = j + dj * (q - h)
                    if 0 <= ii < n and 0 <= jj < n:
                        acc += kern[q] * work[src + a, ii * n + jj]
                work[dst + a, i * n + j] = acc


@njit(cache=True, fastmath=False, error_model="numpy")
def convolve_separable(logw, bias, n, kern_n, kern_e, work, floor):
    """The prediction's convolution of a Rao-Blackwellised grid: the density w = exp(logw) (n * n, rows
    north) convolved with kern_e along east and kern_n along north (odd lengths, zero outside the grid), and
    the per-cell vertical offset
    carried with its mass - the new cell's mean is the kernel-weighted mean of its sources' means,
    conv(w b) / conv(w) - with the sources' spread of means, conv(w b^2) / conv(w) - mean^2, returned as
    its posterior-weighted average (the caller adds it to the shared variance). logw is renormalised to a
    maximum of 0 and floored. work: scratch (6, n * n)."""
    m = n * n
    _pack_moments(logw, bias, work, m, floor)
    _convolve_along(work, 0, 3, kern_e, n, 0, 1)     # along east (j), into rows 3..5
    _convolve_along(work, 3, 0, kern_n, n, 1, 0)     # along north (i), back into rows 0..2
    return _unpack_moments(logw, bias, work, 0, m, floor)


@njit(cache=True, fastmath=False, error_model="numpy")
def convolve_diagonal(logw, bias, n, kern, sign, work, floor):
    """One 1-D convolution of the Rao-Blackwellised grid along its diagonal (sign +1: cell (i, j) from
    (i + s, j + s), north and east together; -1: from (i + s, j - s)), kernel kern (odd length, zero outside
    the grid): a noise whose north and east parts are the same draw (sign +1) or opposite ones (-1), i.e. a
    covariance var [[1, sign], [sign, 1]] with var the kernel's variance in cells^2 - the north-east term of
    the process noise the separable convolution cannot carry. Offsets carried with their mass and the
    spread returned as convolve_separable does; logw renormalised and floored. work: scratch (6, n * n)."""
    m = n * n
    _pack_moments(logw, bias, work, m, floor)
    _convolve_along(work, 0, 3, kern, n, 1, sign)
    return _unpack_moments(logw, bias, work, 3, m, floor)
