"""The particle cloud's maintenance in the Rao-Blackwellized particle filter (seed 002): its prior and
initial draw, the GNSS update (position moves the cloud onto the Kalman posterior of its moments, a
square-root update; the velocity updates each particle's Kalman part), normalisation and ESS-triggered
systematic resampling, the hand-over from the acquisition cloud to n_particles, the integrity test on each
update's NIS and the re-spread it asks for, the feedback of the weighted mean error into the INS, and the
cloud's protection level (the mixture of its particles' Gaussians).

A mixin of RaoBlackwellizedPF (rbpf.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.resampling import regularisation_bandwidth, regularise_gaussian, systematic_indices_u0
from ..integrity import protection_level as pl
from ..protocol import (
    EXTRA_ESS,
    Estimate,
)
from . import _rbpf_kernels as kern


class RbpfCloud:
    """The cloud's prior, GNSS update, resampling, integrity and feedback of RaoBlackwellizedPF; a mixin."""

    # set by RaoBlackwellizedPF.apply_imu_spec for a grade beyond its small-angle error model
    _consistency_warning = ""
    _reacquiring = False     # a recovery's re-spread cloud not yet back to "ok" (_regularise)

    def _set_prior(self, initial: Estimate) -> None:
        """The cloud's and the Kalman parts' initial spread. prior_from_initial (default) and a 9 x 9
        initial.covariance (NED position m, velocity m/s, attitude rad, as every navigator's reset reads it):
        position sigmas from its diagonal (floored at 0.1 m), P0's velocity-attitude block from it (cross
        terms kept), the bias priors from the settings - as the EKF, PMF and PF start. Otherwise (or without
        a covariance) Table 1's priors, the init_* settings. On the default route the scenario's initial
        errors are 0.05 mrad of tilt and 0.1 m/s, against Table 1's 1.75 mrad and 0.71 m/s: starting from
        Table 1 there leaves the filter's velocity and attitude sigmas several times its errors."""
        self.init_pos_sigma = self.init_pos_sigma_settings.copy()
        self.P0 = self.P0_settings.copy()
        cov = getattr(initial, "covariance", None)
        if not self.prior_from_initial or cov is None:
            return
        c = np.asarray(cov, float)
        if c.shape != (9, 9):
            raise ValueError(f"initial.covariance must be 9 x 9 (position, velocity, attitude),"
                             f" not {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("initial.covariance must be finite (prior_from_initial)")
        if not np.allclose(c, c.T, rtol=1e-9, atol=1e-12):
            raise ValueError("initial.covariance must be symmetric (prior_from_initial)")
        w_min = float(np.linalg.eigvalsh(c).min())
        if w_min < -1e-9 * max(1.0, float(np.abs(c).max())):
            raise ValueError("initial.covariance must be positive semi-definite (it has a negative "
                             f"eigenvalue {w_min:.3g})")
        d = np.diag(c)
        if np.any(np.sqrt(d[6:9]) > 0.1):
            raise ValueError("initial.covariance (a scenario's initial_errors.attitude_mrad): attitude sigma "
                             "above 0.1 rad (100 mrad), outside the error model's small-angle range "
                             "(prior_from_initial; set prior_from_initial=false and init_att_sigma_deg "
                             "instead)")
        self.init_pos_sigma = np.maximum(np.sqrt(d[:3]), 0.1)
        blk = c[3:9, 3:9].copy()
        blk[np.diag_indices(6)] = np.maximum(np.diag(blk), 1e-12)
        P0 = self.P0_settings.copy()
        P0[:6, :6] = blk          # the Kalman parts' velocity and attitude are NED, as initial's
        self.P0 = P0

    def _init_cloud(self) -> None:
        n = self.n = self.n_acquisition
        self.xn = self.rng.standard_normal((n, 3)) * self.init_pos_sigma
        self.xl = np.zeros((n, 12))
        self.P = np.broadcast_to(self.P0, (n, 12, 12)).copy()
        self.logw = np.full(n, -math.log(n))

    @staticmethod
    def _ess(logw: np.ndarray) -> float:
        fin = np.isfinite(logw)
        if not fin.any():
            return 0.0
        w = np.exp(logw[fin] - np.max(logw[fin]))
        return float(w.sum() ** 2 / np.sum(w * w))

    def _integrity_test(self, te: float, nis: float, dof: int) -> None:
        """Feed the innovation test through the shared recovery policy (navigators.core.recovery); on a
        recovery re-spread the particles' positions (logged)."""
        decision = self._recovery.add(te, nis, dof)
        verdict = decision.verdict
        self._integrity_extra = verdict.extra()
        if verdict.changed:
            self.health.events.append((float(te), verdict.message))
        if verdict.degraded:
            self.health.status, self.health.ok = "degraded", False
            if decision.recover:
                self.recoveries = self._recovery.recoveries
                self._respread(te)
        elif verdict.changed:
            self.health.status, self.health.ok = "acquiring", True

    def _respread(self, te: float) -> None:
        """Resample by weight, then N(0, recovery_sigma_m^2) on every particle's horizontal position."""
        w = self._weights()
        idx = systematic_indices_u0(w, float(self.rng.random()))
        self.xn, self.xl, self.P = kern.gather(self.xn, self.xl, self.P, idx)
        sig = self._recovery.sigma_now_m
        self.xn[:, :2] += self.rng.standard_normal((self.n, 2)) * sig
        self._reacquiring = True       # no regularisation until "ok" again (_regularise)
        if self.recovery_reset_kalman:
            # the Kalman parts' velocity and attitude share the position's failed test: back to the prior
            # spread (plus the cloud's), so the cloud re-converges without inheriting their overconfidence
            c = kern.moments(self.xn, self.xl, self.P, np.full(self.n, 1.0 / self.n))[1][3:9, 3:9]
            blk = c + self.P0[:6, :6]
            self.P[:, :6, :6] = blk
            self.P[:, :6, 6:] = 0.0
            self.P[:, 6:, :6] = 0.0
        self.logw = np.full(self.n, -math.log(self.n))
        self._cov9 = self._covariance9()
        self.health.events.append((float(te), f"recovery: {self.n} particles re-spread, horizontal 1-sigma "
                                               f"+{sig:.0f} m"))

    def _gnss_update(self, te, gnss, lat, lon, h, v, sc, ll) -> None:
        """GNSS position: a linear-Gaussian measurement of x^n. Weighting the cloud by it cannot represent a
        2 m fix on a 50 m cloud (about one particle in 1,000 lies in the posterior's 1-sigma box), so the
        cloud is moved instead: the weighted mean m and covariance Pc are fused with the fix by a Kalman
        update (m', P') and every particle is mapped x -> m' + L' L^-1 (x - m) (L, L' Cholesky factors of Pc,
        P'), keeping its weight: the weighted cloud then has exactly the posterior's first two moments, its
        shape otherwise kept (an ensemble square-root update). The receiver's error has a white part
        (gnss_pos_sigma_m) and a slowly drifting one (gnss_pos_bias_sigma_m, constant over a fix's
        neighbours): the update uses their sum and P' is kept above the drift's variance, so ten fixes do not
        claim to beat the receiver's own bias. GNSS velocity: each particle's Kalman update (eqs 9-12)."""
        _, glat, glon, gh, gv = gnss
        y = np.array([(lat - glat) * sc[0], (lon - glon) * sc[1], h - gh])
        self._gnss_cloud_update(y)
        H = np.zeros((self.n, 3, 12))
        H[:, 0, 0] = H[:, 1, 1] = H[:, 2, 2] = 1.0
        e = np.broadcast_to(v - gv, (self.n, 3)).copy()
        kern.linear_update(self.xl, self.P, H, e, self.gnss_vel_var, self.logw, np.ones(self.n, bool), ll)

    def _gnss_cloud_update(self, y: np.ndarray) -> None:
        w = self._weights()
        m = w @ self.xn
        d = self.xn - m
        Pc = (d * w[:, None]).T @ d
        Rg = np.diag(self.gnss_pos_var + self.gnss_bias_var)
        # the share of the map's shift the mean took on from the terrain is error relative to the Earth,
        # which the fix sees: the prior is the cloud's spread plus its covariance, and the share restarts
        # (map_shift; fused against the cloud alone, a fix after a long terrain segment would be an outlier)
        Pp = Pc
        if self.map_horizontal_sigma_m > 0.0 and self._map_shift.any():
            Pp = Pc.copy()
            Pp[:2, :2] += self._map_shift.covariance(self.map_horizontal_sigma_m)
            self._map_shift.reset()
        try:
            L = np.linalg.cholesky(Pc + 1e-9 * np.eye(3))
            K = Pp @ np.linalg.inv(Pp + Rg)
        except np.linalg.LinAlgError:
            return
        m_new = m + K @ (y - m)
        P_new = (np.eye(3) - K) @ Pp
        P_new = 0.5 * (P_new + P_new.T)
        # the receiver's drift is common to consecutive fixes: no position better than it
        # (never wider than the cloud before the fix)
        floor = np.sqrt(np.minimum(self.gnss_bias_var, np.diag(Pp)))
        sd = np.sqrt(np.clip(np.diag(P_new), 1e-12, None))
        f = np.maximum(floor / sd, 1.0)
        P_new = P_new * f[:, None] * f[None, :]
        try:
            L_new = np.linalg.cholesky(P_new + 1e-9 * np.eye(3))
        except np.linalg.LinAlgError:
            return
        A = L_new @ np.linalg.inv(L)
        self.xn = m_new + d @ A.T

    def _normalise_resample(self, te, logw_prev) -> None:
        fin = np.isfinite(self.logw)
        if not fin.any():
            self.health.skip(te, "weights_underflow", "all particle weights vanished: cloud re-initialised")
            self.health.status, self.health.ok = "degraded", True
            self._init_cloud()
            self.xn += 0.0
            self._extra[EXTRA_ESS] = 0.0
            return
        m = np.max(self.logw[fin])
        w = np.where(fin, np.exp(self.logw - m), 0.0)
        w /= w.sum()
        ess = 1.0 / float(np.sum(w * w))
        self._extra[EXTRA_ESS] = ess
        if ess < self.ess_threshold * self.n:
            cov = self._cloud_cov(w)
            idx = systematic_indices_u0(w, float(self.rng.random()))
            self.xn, self.xl, self.P = kern.gather(self.xn, self.xl, self.P, idx)
            self._regularise(cov)
            self.logw = np.full(self.n, -math.log(self.n))
            self.resamples += 1
        else:
            self.logw = np.log(np.where(w > 0, w, 1e-300))

    def _handover(self) -> None:
        """Acquisition over: the cloud of acquisition_particles is resampled (systematic, by weight) down to
        n_particles once its horizontal spread is below acquisition_spread_m (see the class docstring)."""
        if self.n <= self.n_particles:
            return
        c = kern.moments(self.xn, self.xl, self.P, self._weights())[1]
        if math.sqrt(max(c[0, 0] + c[1, 1], 0.0)) >= max(self.acquisition_spread_m, 1e-9):
            return
        w = self._weights()
        cov = self._cloud_cov(w)
        cw = np.cumsum(w)
        u = (float(self.rng.random()) + np.arange(self.n_particles)) / self.n_particles
        idx = np.minimum(np.searchsorted(cw, u * cw[-1], side="left"), self.n - 1).astype(np.int64)
        self.xn, self.xl, self.P = kern.gather(self.xn, self.xl, self.P, idx)
        self.n = self.n_particles
        self._regularise(cov)
        self.logw = np.full(self.n, -math.log(self.n))

    def _cloud_cov(self, w: np.ndarray) -> np.ndarray:
        """Weighted covariance (3 x 3, m^2) of the particles' positions x^n."""
        d = self.xn - w @ self.xn
        return (d * w[:, None]).T @ d

    def _regularise(self, cov: np.ndarray) -> None:
        """regularisation "gaussian": the resampled copies moved by a Gaussian kernel of the cloud's
        covariance before resampling, cov, with the optimal bandwidth for n particles in the three
        dimensions of x^n (the regularised particle filter of Musso, Oudjane & Le Gland 2001,
        navigators.core.resampling; the cloud's covariance grows by h^2 cov); "shrunk": the same kernel with
        Liu & West's shrinkage towards the mean, which keeps the cloud's mean and covariance and adds only
        diversity; the Kalman parts stay their ancestors'. "none": nothing. Not while the cloud re-acquires
        after a recovery's re-spread (until the status is "ok" again): the kernel of one global covariance
        is the optimal one for a unimodal posterior (the regularised filter's assumption), and a cloud
        re-spread over hundreds of metres of terrain holds several modes, which it would blur and, shrunk,
        draw together."""
        if self.regularisation != "none" and not self._reacquiring:
            regularise_gaussian(self.xn, cov, regularisation_bandwidth(self.n, 3), self.rng,
                                shrink=self.regularisation == "shrunk")

    def _weights(self) -> np.ndarray:
        m = np.max(self.logw)
        w = np.exp(self.logw - m)
        return w / w.sum()

    def _feedback(self) -> None:
        """Correct the INS by the weighted mean error and subtract it from the particles (an exact change of
        the linearisation point of the error model)."""
        w = self._weights()
        mu, _ = kern.moments(self.xn, self.xl, self.P, w)
        if not np.all(np.isfinite(mu)):
            return
        self.ins.correct(np.array([mu[0], mu[1], -mu[2]]), mu[3:6], mu[6:9])
        self.ins.accel_bias_b -= mu[9:12]
        self.ins.gyro_bias_b -= mu[12:15]
        kern.shift(self.xn, self.xl, mu)

    def _mixture_hpl(self, risk: float) -> float:
        """HPL of the marginal position posterior (navigators.integrity.protection_level.mixture_hpl):
        particle k is N(xn_k, B P_k B' + Q^n) horizontally (eq 5's spread with its own Kalman covariance);
        before the first time update the particles are points."""
        B = getattr(self, "_pl_B", None)
        n = self.xn.shape[0]
        if B is None or B.shape[1] != self.P.shape[1]:
            cov = np.zeros((n, 2, 2))
        else:
            cov = np.einsum("ij,kjl,ml->kim", B, self.P, B)
            cov[:, 0, 0] += self.qn_var[0]
            cov[:, 1, 1] += self.qn_var[1]
        return pl.mixture_hpl(self.xn[:, 0], self.xn[:, 1], cov, self._weights(), risk)
