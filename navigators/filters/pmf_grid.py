"""The point-mass filter's grid (navigators.filters.pmf): its geometry, the process noise as a convolution,
the likelihood's application, re-gridding and the grid's moments and protection-level points.

A mixin of PointMassFilter, which owns the belief these methods read and write (see pmf.py's docstring for
the design): log-densities `logw` on an n x n grid of north/east offsets (m) of the INS's horizontal error,
centred at (centre_n, centre_e) with spacing `spacing`, and per cell the mean `bias` of the vertical offset
with the shared variance P_b.

- Process noise (`_apply_process_noise`): the accumulated position growth q as a convolution of exactly
  that covariance, before every update (a three-tap kernel [p, 1 - 2p, p], p = q / (2 d^2), while the
  noise is below the spacing, a normalised sampled Gaussian above it, `_kernel_1d`; a pass along the
  grid's diagonal for the north-east covariance), in the spirit of the Lagrangian grid filters.
- Re-gridding (`_regrid`): the half-span follows span_sigmas times the posterior's largest standard
  deviation (spacing within [spacing_min_m, spacing_max_m], at most halved or doubled at a time), the
  centre follows the mean once it is n/8 cells away; log-densities and biases are interpolated (bilinear).
- Moments (`_moments`): mean and covariance of the grid (+ d^2/12 per axis for the cells' width) and of
  the vertical offset, the velocity offset's Gaussian beside them.
"""

from __future__ import annotations

import math

import numpy as np

from ..integrity import protection_level as pl
from . import _pmf_kernels as kern

LOG_FLOOR = -700.0          # log-density floor relative to the peak (exp underflows below ~ -745)


def _kernel_1d(var_cells: float) -> np.ndarray:
    """Normalised 1-D kernel whose variance is var_cells (in cells^2)."""
    if var_cells <= 2.0 / 3.0:
        p = 0.5 * var_cells
        return np.array([p, 1.0 - 2.0 * p, p])
    s = math.sqrt(var_cells)
    half = int(math.ceil(4.0 * s))
    x = np.arange(-half, half + 1, dtype=float)
    k = np.exp(-0.5 * x * x / var_cells)
    return k / k.sum()


class PmfGrid:
    """The grid's operations of PointMassFilter (a mixin; see the module docstring)."""

    def _set_geometry(self, centre_n: float, centre_e: float, spacing: float) -> None:
        n = self.n
        self.centre_n, self.centre_e, self.spacing = float(centre_n), float(centre_e), float(spacing)
        ax = (np.arange(n) - 0.5 * (n - 1)) * spacing
        self.axis_n = centre_n + ax
        self.axis_e = centre_e + ax
        self.dn_flat = np.ascontiguousarray(np.repeat(self.axis_n, n))
        self.de_flat = np.ascontiguousarray(np.tile(self.axis_e, n))

    def _apply_process_noise(self) -> None:
        """The accumulated process noise as a convolution of exact covariance before every update: a
        separable pass for the diagonal less the north-east covariance's size, a pass along the grid's
        diagonal for the covariance (the heading error couples the north and east velocity errors: dropping
        it missed a Kalman filter's mean by 0.09 sigma in a turn with a 10 mrad heading sigma,
        tests/test_terrain_filter_linear.py). Before every update, not once it reaches some fraction of a
        cell: noise held back is added after the update instead of before it, so the update does not narrow
        it and the reported covariance is too large."""
        q = self._q_pending / self.spacing ** 2
        # Q = diag(q_nn - |c|, q_ee - |c|) + |c| [[1, sign c], [sign c, 1]]: the north-east covariance c as a
        # pass along the grid's diagonal (as much of it as the diagonal leaves room for)
        c = float(np.clip(q[0, 1], -min(max(q[0, 0], 0.0), max(q[1, 1], 0.0)),
                          min(max(q[0, 0], 0.0), max(q[1, 1], 0.0))))
        var_cells = np.clip(np.diag(q) - abs(c), 0.0, None)
        if var_cells.max() <= 0.0 and c == 0.0:
            return
        spread = 0.0
        if var_cells.max() > 0.0:
            spread += kern.convolve_separable(self.logw, self.bias, self.n, _kernel_1d(var_cells[0]),
                                              _kernel_1d(var_cells[1]), self._work, LOG_FLOOR)
        if abs(c) > 1e-6:
            spread += kern.convolve_diagonal(self.logw, self.bias, self.n, _kernel_1d(abs(c)),
                                             1 if c > 0.0 else -1, self._work, LOG_FLOOR)
        self.P_b += spread
        self._height.widen(spread)
        self._moments_cache = None
        self._q_pending = np.zeros((2, 2))

    def _position_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance of z = (dn, de, b) over the grid (b: the cells' means and P_b)."""
        mean, cov = self._moments()
        c = cov[:3, :3].copy()
        xb = np.empty(2)
        kern.grid_cross_moments(self.logw, self.dn_flat, self.de_flat, self.bias, xb)
        c[2, :2] = c[:2, 2] = xb
        return mean[:3].copy(), c

    def _weights(self) -> np.ndarray:
        w = np.exp(self.logw - self.logw.max())
        return w / w.sum()

    def _pl_points(self, risk: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The cells' centres and masses; pad: a cell's half diagonal plus the Gaussian bound of the process
        noise not yet convolved into the grid (navigators.integrity.protection_level)."""
        pad = 0.5 * math.sqrt(2.0) * self.spacing + pl.gaussian_hpl(self._q_pending, risk)
        return self.dn_flat, self.de_flat, np.exp(self.logw - self.logw.max()), pad

    def _apply_loglik(self, t_s: float, ll: np.ndarray, what: str) -> float | None:
        """logw += ll; returns log p(z | past) or None (skipped: every cell underflowed)."""
        log_lik, mx = kern.apply_log_likelihood(self.logw, ll, LOG_FLOOR)
        if not np.isfinite(mx):
            self._underflow(t_s, what)
            return None
        self._n_underflow = 0
        self._moments_cache = None
        return float(log_lik)

    def _underflow(self, t_s: float, what: str) -> None:
        self._n_underflow += 1
        self._degrade(t_s, "likelihood_underflow", f"{what}: every cell's likelihood underflowed "
                      f"(update skipped, {self._n_underflow} in a row)")
        if self._n_underflow >= 10:
            self._reinitialise(t_s)

    def _reinitialise(self, t_s: float) -> None:
        mean, cov = self._moments()
        c9 = np.zeros((9, 9))
        c9[:2, :2] = np.eye(2) * max(1000.0**2, cov[0, 0], cov[1, 1])
        self._init_belief(c9, (float(mean[0]), float(mean[1])), velocity=(self.u_mean, self.C_uu))
        self._degrade(t_s, "reinitialised", "grid re-initialised wide (1 km) after repeated underflows")

    def _regrid(self) -> None:
        mean, cov = self._moments()
        sig = math.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 1e-12))
        d_des = min(max(2.0 * self.span_sigmas * sig / (self.n - 1), self.spacing_min_m), self.spacing_max_m)
        d_new = min(max(d_des, 0.5 * self.spacing), 2.0 * self.spacing)
        off = max(abs(mean[0] - self.centre_n), abs(mean[1] - self.centre_e))
        far = off > (self.n - 1) * self.spacing / 8
        if not far and 0.8 <= d_new / self.spacing <= 1.25:
            return
        old_lw = self.logw.reshape(self.n, self.n)
        old_b = self.bias.reshape(self.n, self.n)
        c_old = 0.5 * (self.n - 1)
        cn_old, ce_old, d_old = self.centre_n, self.centre_e, self.spacing
        self._set_geometry(float(mean[0]), float(mean[1]), d_new)
        fi = (self.axis_n - cn_old) / d_old + c_old
        fj = (self.axis_e - ce_old) / d_old + c_old
        FI, FJ = np.meshgrid(fi, fj, indexing="ij")
        from scipy import ndimage  # at first use: importing scipy.ndimage costs about a second
        lw = ndimage.map_coordinates(old_lw, [FI, FJ], order=1, mode="constant", cval=LOG_FLOOR)
        b = ndimage.map_coordinates(old_b, [FI, FJ], order=1, mode="nearest")
        lw = lw.ravel()
        self.logw = np.maximum(lw - lw.max(), LOG_FLOOR)
        self.bias = np.ascontiguousarray(b.ravel())
        self._moments_cache = None

    def _moments(self) -> tuple[np.ndarray, np.ndarray]:
        if self._moments_cache is None:
            o = np.empty(7)
            kern.grid_moments(self.logw, self.dn_flat, self.de_flat, self.bias, o)
            c = np.array([[o[2], o[3]], [o[3], o[4]]]) + np.eye(2) * self.spacing ** 2 / 12.0
            self._moments_cache = (o[0], o[1], c, o[5], self.P_b + o[6])
        mn, me, c, mb, vb = self._moments_cache
        mean = np.array([mn, me, mb, self.u_mean[0], self.u_mean[1], np.nan])
        cov = np.full((6, 6), np.nan)
        cov[:2, :2] = c + self._q_pending
        cov[2, :2] = cov[:2, 2] = 0.0
        cov[2, 2] = vb
        cov[3:5, 3:5] = self.C_uu[:2, :2]
        cov[3:5, 0:3] = self.C_uz[:2]
        cov[0:3, 3:5] = self.C_uz[:2].T
        return mean, cov

    def _after_frame(self, t_end: float) -> None:
        super()._after_frame(t_end)
        d = self.logw.reshape(self.n, self.n)
        from scipy import ndimage  # at first use: importing scipy.ndimage costs about a second
        peaks = (d == ndimage.maximum_filter(d, size=3, mode="constant", cval=-np.inf)) & (d > math.log(0.01))
        vals = np.sort(d[peaks])[::-1]
        self.extra["pmf_modes"] = int(vals.size)
        self.extra["multimodality"] = float(math.exp(vals[1] - vals[0])) if vals.size > 1 else 0.0
        self.extra["pmf_spacing_m"] = self.spacing
        self.extra["pmf_grid_n"] = self.n
