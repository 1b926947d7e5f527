"""The IRA measurement update of the Rao-Blackwellized particle filter (seed 002 eqs 9-12, 23-26).

Each particle's predicted range and look angle (eqs 23, 26) and their step-wise linearisation in velocity
and attitude (eqs 24-25, navigators.measurements.ira_seed002) form H; the weights take eq 9's predictive
density and every particle's Kalman part eqs 10-12 (_rbpf_kernels.linear_update). The look angle is dropped
(the range alone) where eqs 24-25 do not describe the sample: a return on the look window's edge, a
closest point that can jump to another basin (by the velocity's tilt of the zero-Doppler line or by the
map's height errors), a look angle beyond its gate on a converged cloud, a look angle not linear in the
velocity over the cloud's spread, or one that would collapse the effective sample size. The measurement
noise adds the map's error class and its unresolved terrain (ira_seed002.map_noise_variances).

A mixin of RaoBlackwellizedPF (rbpf.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erfc as _erfc

from ..measurements import ira_seed002 as ira_model
from ..protocol import update_extra
from . import _rbpf_kernels as kern
from . import map_shift as shift_share
from . import rbpf_progressive as prog

OUTLIER_SIGMA = 10.0  # an IRA sample farther than this from every particle's prediction is rejected
REINIT_AFTER_REJECTS = 3  # consecutive rejections that re-initialise the cloud around the INS


class RbpfIraUpdate:
    """The IRA measurement update of RaoBlackwellizedPF; a mixin."""

    _share_left = 1.0        # share of this epoch's IRA information not yet applied (rbpf_progressive)

    def _ira_update(self, te, y_ira, lat, lon, h, v, C, sc, logw_prev, ll, stage: int = 0) -> bool:
        """One stage of the IRA update (stage 0: the first, which also runs the innovation test and
        publishes the update's Estimate.extra); True when the cloud was updated. The stage applies the share
        rbpf_progressive.stage_share picks of what is left of the measurement's information
        (progressive_correction; else all of it)."""
        edge = abs(y_ira[1]) > self.half_window_rad - self.edge_margin_rad
        if edge and not self.window_edge_range:
            # the return sits on the look window's edge: the window, not the terrain's minimum, fixed the
            # point, so its range depends on roll and its look angle is the window's - eqs 24-25 (an
            # interior minimum on the zero-Doppler line) do not describe it
            sk = self.health.skipped
            sk["ira_window_edge"] = sk.get("ira_window_edge", 0) + 1
            return False
        lat_i = lat - self.xn[:, 0] / sc[0]
        lon_i = lon - self.xn[:, 1] / sc[1]
        h_i = h - self.xn[:, 2]
        out = self._predict(lat_i, lon_i, h_i, v, C)
        Hs = np.zeros((self.n, 2, 6))
        ira_model.measurement_rows(out, v, C, Hs)
        theta_curv = 0.0
        if edge:
            # on the window's edge (see window_edge_range): the range alone, its velocity and attitude rows
            # by differences, as eqs 24-25 describe an interior minimum only
            Hs[:, 0, :] = self._edge_range_row(out, lat_i, lon_i, h_i, v, C)
        elif self.theta_velocity_rows:
            Hs[:, 1, :3], theta_curv = self._theta_velocity_row(out, lat_i, lon_i, h_i, v, C)
        H = np.zeros((self.n, 2, 12))
        H[:, :, :6] = Hs
        ok = out[:, ira_model.OUT_VALID] > 0.5
        if not ok.any():
            self.health.skip(te, "ira_no_hypothesis",
                             "IRA update skipped: no particle has a return (off map?)")
            self.health.status, self.health.ok = "degraded", True
            self._integrity_test(te, math.inf, 2)
            return False
        # a point of the zero-Doppler line more than 1.5 scan steps (68 m) across track from the closest
        # one, in another basin or on the far side of a flat minimum, within ambiguity_gap_m of its range:
        # the closest point can jump there (a velocity error of a few tenths of m/s tilts the line enough),
        # and theta with it by degrees - what eqs 24-25 cannot linearise (the range, a minimum, stays
        # continuous). When such particles carry ambiguity_weight of the cloud, the range alone.
        wq = np.exp(self.logw - np.max(self.logw))
        wq = np.where(ok, wq, 0.0)
        gap = out[:, ira_model.OUT_R2] - out[:, ira_model.OUT_R]
        near = ok & np.isfinite(gap) & (gap < self.ambiguity_gap_m)
        dims = 1 if float(wq[near].sum()) > self.ambiguity_weight * float(wq.sum()) else 2
        # the same jump made by the map: its height errors move the two minima's ranges independently, so
        # the map's closest point lies in the runner-up's basin where the world's does not with probability
        # Phi(-gap / (sqrt 2 sigma_h)); above ambiguity_probability, the range alone
        if dims == 2 and self._basin_jump_probability(gap, ok, wq) > self.ambiguity_probability:
            dims = 1
        wp = np.exp(logw_prev - logw_prev.max())
        wp = np.where(ok, wp, 0.0)
        wp /= wp.sum()
        # the look angle's variance as this update uses it (with any tempering): the yardstick of
        # the theta-velocity row's linearity (_theta_velocity_row)
        theta_var = self._r_var_now(float(np.sum(wp * np.where(ok, out[:, ira_model.OUT_R], 0.0))))[1]
        sk = self.health.skipped
        if edge:
            dims = 1
            sk["ira_window_edge"] = sk.get("ira_window_edge", 0) + 1
        elif not self.look_angle:
            dims = 1          # the range alone by choice (setting look_angle)
        elif dims == 1:
            sk["ira_theta_ambiguous"] = sk.get("ira_theta_ambiguous", 0) + 1
        elif self.theta_linearity_sigmas > 0.0 and not theta_curv < self.theta_linearity_sigmas * math.sqrt(
                theta_var):
            dims = 1
            sk["ira_theta_nonlinear"] = sk.get("ira_theta_nonlinear", 0) + 1
        H_full = H
        saved = (self.xl.copy(), self.P.copy(), self.logw.copy())
        # the collapse guard below is for a converged cloud: while acquiring, a
        # look angle that selects a few particles is the bootstrap's normal work
        converged = math.sqrt(max(self._cov9[0, 0] + self._cov9[1, 1], 0.0)) <= self.acquisition_spread_m
        # the look-angle gate only on a converged cloud the innovation test trusts: a lost or re-acquiring
        # one needs exactly the large innovations a gate would reject (after a 120 m range bias, gated at
        # 3 sigma throughout, the cloud stayed 930 m off)
        gate = self.theta_gate_sigmas > 0.0 and converged and self.health.status == "ok"
        while True:
            y = np.array(y_ira)[:dims]
            pred = np.stack([out[:, ira_model.OUT_R], out[:, ira_model.OUT_THETA]], axis=1)[:, :dims]
            H = np.ascontiguousarray(H_full[:, :dims, :])
            e = np.where(ok[:, None], y[None, :] - pred, 0.0)
            # innovation moments of the mixture (before the update): the fixed Estimate.extra keys
            pred_ok = np.ascontiguousarray(np.where(ok[:, None], pred, 0.0))
            self._last_range_m = float(np.sum(wp * pred_ok[:, 0]))
            r_var = np.ascontiguousarray(self._r_var_now(self._last_range_m)[:dims])
            ybar, S = kern.predictive_moments(H, self.xl, self.P, r_var, pred_ok, ok, wp)
            nu = y - ybar
            if dims == 2 and gate and not nu[1] ** 2 <= self.theta_gate_sigmas ** 2 * S[1, 1]:
                # a look angle beyond the gate of the mixture's predictive spread: the map's error at the
                # closest point is heavy-tailed (a few samples beyond 3 sigma hold much of the variance:
                # docs/validation/seed002.md), which a Gaussian update would read as position and attitude;
                # the range alone (map_noise_calibration trims the same)
                dims = 1
                sk["ira_theta_gated"] = sk.get("ira_theta_gated", 0) + 1
                continue
            S0, nu_k = prog.innovations(H, self.xl, self.P, e)
            share = self._share_left
            if self.progressive_correction:
                share = prog.stage_share(wp, S0, nu_k, r_var, share, self.ess_threshold)
            n_bad = kern.linear_update(self.xl, self.P, H, e, r_var / share, self.logw, ok, ll)
            if (dims == 1 or self.theta_collapse_ess <= 0.0 or not converged
                    or self._ess(self.logw) >= self.theta_collapse_ess * self.n):
                break
            # the look angle alone would leave (nearly) one particle: theta is then a function of position
            # sharper than the cloud can sample (a flat minimum, or the closest point at a bilinear cell's
            # kink, where it jumps): its information cannot be represented, and taking it collapses every
            # Kalman part onto one ancestor's. The range alone instead.
            self.xl, self.P, self.logw = (a.copy() for a in saved)
            dims = 1
            sk["ira_theta_collapse"] = sk.get("ira_theta_collapse", 0) + 1
        # every particle's predictive density of the whole measurement (eq 9; ll holds the stage's)
        ll_full = np.where(ok & np.isfinite(ll), prog.predictive_loglik(S0, nu_k, r_var, 1.0), -np.inf)
        fin_ll = ll_full[np.isfinite(ll_full)]
        # log N at OUTLIER_SIGMA for the variances inflated at most 100x: the rejection floor
        ll_floor = (-0.5 * OUTLIER_SIGMA**2 - 0.5 * math.log(float(np.prod(r_var)) * 100.0 ** dims)
                    - 0.5 * dims * math.log(2 * math.pi))
        # no particle within OUTLIER_SIGMA of the measurement: in linear weights every one underflows
        if stage > 0 and (fin_ll.size == 0 or fin_ll.max() < ll_floor):
            self.xl, self.P, self.logw = saved
            self._share_left = 0.0
            return False
        if fin_ll.size == 0 or fin_ll.max() < ll_floor:
            self.xl, self.P, self.logw = saved
            self._n_rejected += 1
            if self._n_rejected >= REINIT_AFTER_REJECTS:
                self.health.skip(te, "weights_underflow",
                                 f"{self._n_rejected} IRA samples unexplained by every particle: "
                                 "cloud re-initialised")
                self._init_cloud()
                self._n_rejected = 0
            else:
                self.health.skip(te, "ira_outlier", "IRA sample unexplained by every particle: skipped")
            self.health.status, self.health.ok = "degraded", True
            self._integrity_test(te, math.inf, dims)
            return False
        self._share_left = 0.0 if share >= self._share_left else self._share_left - share
        if stage > 0:
            return True
        if self.map_horizontal_sigma_m > 0.0:     # the map's shift follows the mean's response (map_shift)
            self._shift_response(ok & np.isfinite(ll_full), wp, ll_full, S0, nu_k, r_var)
        self._n_rejected = 0
        if n_bad:
            sk = self.health.skipped
            sk["ira_particle_no_return"] = sk.get("ira_particle_no_return", 0) + n_bad
        # log sum_k w_k p(y | particle k) of the whole measurement (the weights before the update)
        m = np.max(logw_prev)
        w_all = np.exp(logw_prev - m)
        w_all /= w_all.sum()
        fin = np.isfinite(ll_full) & (w_all > 0.0)
        if fin.any():
            mm = np.max(ll_full[fin])
            lse = mm + math.log(np.sum(w_all[fin] * np.exp(ll_full[fin] - mm)))
        else:
            lse = -np.inf
        lse_prev = 0.0
        try:
            nis = float(nu @ np.linalg.solve(S, nu))
        except np.linalg.LinAlgError:
            nis = float("nan")
        self._extra = update_extra(nu, S, nis, dims, float(lse - lse_prev), te)
        self._integrity_test(te, nis, dims)
        return True

    def _shift_response(self, use, wp, ll_full, S0, nu, r_var) -> None:
        """The share of the map's horizontal shift the cloud's mean took on at this IRA update
        (map_shift.particle_mean_response): the particles' positions xn, the weights before (wp) and after
        the whole measurement (wp times its predictive density), each particle's score -S^-1 nu with
        S = S0 + diag(r_var) its predictive covariance, its prediction y - nu."""
        w0 = np.where(use, wp, 0.0)
        lw = np.where(use, ll_full, -np.inf)
        if not np.isfinite(lw).any():
            return
        w1 = w0 * np.exp(lw - np.max(lw))
        S = S0 + np.diag(np.asarray(r_var, float))[None, :, :]
        score = np.zeros_like(nu)
        score[use] = -np.linalg.solve(S[use], nu[use][..., None])[..., 0]
        M = shift_share.particle_mean_response(self.xn[:, :2], w0, w1, score, -nu)
        if M is not None:
            self._map_shift.respond(M)

    def _predict(self, lat, lon, h, v, C) -> np.ndarray:
        """eqs 23-26 on the map for hypotheses (lat, lon rad, h m): ira_seed002.predict_ira with the sensor's
        look window and this filter's coarse-scan step (search_step_m)."""
        return ira_model.predict_ira(self.dem, lat, lon, h, v, C, self.half_window_rad, self.max_range_m,
                                     ds_m=self.search_step_m)

    def _edge_range_row(self, out, lat_i, lon_i, h_i, v, C) -> np.ndarray:
        """Range sensitivity (1 x 6: dv_ned m/s, eps_ned rad) of a return on the look window's edge, where the
        window's boundary ray, not the terrain's minimum, fixes the point: eq 24's envelope argument does
        not hold there (the range moves with the ray, so with roll), so central differences of eq 23 (the
        exact constrained search) at the cloud's weighted-mean position, shared by the particles. Errors
        computed minus true: R_true = R(v - dv, (I + [eps x]) C), so H_v = -dR/dv, H_eps = +dR/deps."""
        ok = out[:, ira_model.OUT_VALID] > 0.5
        w = np.where(ok, np.exp(self.logw - np.max(self.logw)), 0.0)
        row = np.zeros(6)
        if not w.sum() > 0:
            return row
        w /= w.sum()
        la, lo, hh = (np.array([float(w @ np.where(ok, x, 0.0))]) for x in (lat_i, lon_i, h_i))
        dv, de = 0.2, 2e-3     # de: eq 23's search resolves ~5 mm; R is smooth in the ray angle

        def rng_at(vv, CC):
            r = self._predict(la, lo, hh, vv, CC)
            return r[0, ira_model.OUT_R] if r[0, ira_model.OUT_VALID] > 0.5 else math.nan

        for j in range(3):
            d = np.zeros(3)
            d[j] = dv
            row[j] = -(rng_at(v + d, C) - rng_at(v - d, C)) / (2 * dv)
            e = np.zeros(3)
            e[j] = de
            Ep = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
            row[3 + j] = (rng_at(v, (np.eye(3) + Ep) @ C) - rng_at(v, (np.eye(3) - Ep) @ C)) / (2 * de)
        return np.where(np.isfinite(row), row, 0.0)

    def _theta_velocity_row(self, out, lat_i, lon_i, h_i, v, C) -> tuple[np.ndarray, float]:
        """Look-angle sensitivity to the velocity error (1 x 3, rad per m/s), which eq 23's look-angle row
        leaves out: a velocity error tilts and turns the zero-Doppler line (the shift eq 24 applies to the
        range), and the closest point moves along the terrain, so theta moves too (on the seed002 flight
        ~0.1 deg per m/s of vertical velocity, up to 0.5). Central differences of eqs 23/26 (the exact
        search) at the cloud's weighted-mean position, shared by the particles; H = -dtheta/dv (errors
        computed minus true, as eq 24's range row).

        Also how far theta departs from that line over the cloud's velocity spread: the second difference's
        term, 0.5 sum_j |theta''_jj| sigma_vj^2 (rad; inf when a perturbed search has no return), which
        _ira_update compares with theta_linearity_sigmas look-angle sigmas (a flat minimum, or a closest
        point at a bilinear cell's kink, jumps under a small tilt of the line; a Kalman update through this
        row would then read the jump as velocity information)."""
        ok = out[:, ira_model.OUT_VALID] > 0.5
        w = np.where(ok, np.exp(self.logw - np.max(self.logw)), 0.0)
        if not w.sum() > 0:
            return np.zeros(3), math.inf
        w /= w.sum()
        la, lo, hh = (np.array([float(w @ np.where(ok, x, 0.0))]) for x in (lat_i, lon_i, h_i))
        row = np.zeros(3)
        dv = 0.2
        c = self._predict(la, lo, hh, v, C)
        linear = bool(c[0, ira_model.OUT_VALID] > 0.5)
        sig_v2 = np.clip(np.diag(self._cov9)[3:6], 0.0, None)
        curv = 0.0
        for j in range(3):
            d = np.zeros(3)
            d[j] = dv
            a = self._predict(la, lo, hh, v + d, C)
            b = self._predict(la, lo, hh, v - d, C)
            if a[0, ira_model.OUT_VALID] > 0.5 and b[0, ira_model.OUT_VALID] > 0.5:
                ta, tb = a[0, ira_model.OUT_THETA], b[0, ira_model.OUT_THETA]
                row[j] = -(ta - tb) / (2 * dv)
                if linear:
                    curv += 0.5 * abs(ta - 2.0 * c[0, ira_model.OUT_THETA] + tb) / dv**2 * sig_v2[j]
            else:
                linear = False
        return row, (curv if linear else math.inf)

    def _basin_jump_probability(self, gap: np.ndarray, ok: np.ndarray, w: np.ndarray) -> float:
        """Probability, weighted over the cloud, that the map's closest point on the zero-Doppler line lies
        in another basin than the world's: per particle, the map's height errors (sigma_h = hypot(map_sigma_m,
        terrain_model_sigma_m), independent between two basins 68 m or more apart, each seen near the
        vertical so a height error is a range error) change the runner-up's range margin gap by
        N(0, 2 sigma_h^2), which closes it with probability Phi(-gap / (sqrt 2 sigma_h)) =
        erfc(gap / (2 sigma_h)) / 2. Such a jump moves theta by degrees (13 deg at t = 399 s on the
        default route's seed 0, map gap 2.0 m), which eqs 25-26 would read as attitude and position. 0 for a
        map that is the world (sigma_h = 0) or when no particle has a runner-up (gap inf)."""
        sigma_h = math.hypot(self.map_sigma_m, self.terrain_model_sigma_m)
        if not sigma_h > 0.0:
            return 0.0
        use = ok & np.isfinite(gap)
        tot = float(w[ok].sum())
        if not tot > 0.0 or not use.any():
            return 0.0
        p = 0.5 * _erfc(np.maximum(gap[use], 0.0) / (2.0 * sigma_h))
        return float(np.sum(w[use] * p)) / tot

    def terrain_factors(self, range_m: float) -> tuple[float, float]:
        """(range, look angle) factors on the flat-ground map-noise variances of terrain_model_sigma_m at a
        slant range range_m (m): ira_seed002.map_noise_calibration on this map ("calibrated") at the height
        calibration_height_m(range_m) above it, 1-6 s the first time per map and height, then read from the
        process's and the disk's caches (navigators.core.disk_cache); or (1, 1)
        ("flat_ground", or nothing unresolved: terrain_model_sigma_m 0). The look angle's factor depends on
        the height (its error falls with height faster than the flat-ground model's 1 / R): calibrated at
        1,500 m and applied at 600 m it underrates the look angle's map-error variance 1.7-2x
        (docs/validation/integrity.md, section 6.8)."""
        if self.map_noise_model != "calibrated" or not self.terrain_model_sigma_m > 0.0:
            return (1.0, 1.0)
        agl_m = ira_model.calibration_height_m(range_m)
        f = self._terrain_factors.get(agl_m)
        if f is None:
            f = self._terrain_factors[agl_m] = ira_model.map_noise_calibration(
                self.dem, self.terrain_detail_spacing_m, agl_m=agl_m,
                ambiguity_probability=self.ambiguity_probability, gate_sigmas=self.theta_gate_sigmas,
                theta_sensor_var=float(self.r_var[1]))
        return f

    def _r_var_now(self, range_m: float) -> np.ndarray:
        """IRA measurement variances (range m^2, look angle rad^2) at a slant range range_m: the sensor's,
        plus the map's errors (ira_seed002.map_noise_variances: terrain_model_sigma_m, map_sigma_m, and
        map_bias_sigma_m while GNSS pins the height, which then cannot absorb a map bias; with
        map_error_in_height, the bias and a correlated map_sigma_m until the cloud's up coordinate takes
        them on: RaoBlackwellizedPF._map_release). With tempering
        "spread" they are inflated by (spread / acquisition_spread_m)^2 (at most 100x) while the cloud's
        horizontal spread exceeds acquisition_spread_m, "acquisition" the same only while the cloud is the
        acquisition's or re-acquires after a recovery: against the collapse of 1,000 particles spread over
        50 m onto a 3.5 m likelihood, where the survivors' Kalman parts absorb their position's look-angle
        mismatch as attitude error (default "spread"). It discards the rest of the measurement's
        information (the published covariance is then that of a filter which never had it); "none" leaves
        the variances as they are. Outside the tempering the progressive correction (rbpf_progressive)
        keeps the cloud from collapsing onto a sharp likelihood."""
        if self.map_error_in_height:
            released = getattr(self, "_map_released", False)
            bias = 0.0 if released else self.map_bias_sigma_m
            sigma = 0.0 if released and self.map_correlation_length_m > 0.0 else self.map_sigma_m
        else:
            bias = self.map_bias_sigma_m if getattr(self, "_gnss_now", False) else 0.0
            sigma = self.map_sigma_m
        r = self.r_var + ira_model.map_noise_variances(math.hypot(sigma, bias),
                                                       self.terrain_model_sigma_m, range_m,
                                                       self.terrain_factors(range_m))
        if self.acquisition_spread_m <= 0.0 or self.tempering == "none" or (
                self.tempering == "acquisition" and not (self.n > self.n_particles or self._reacquiring)):
            return r
        spread = math.sqrt(max(self._cov9[0, 0] + self._cov9[1, 1], 0.0))
        f = min(max((spread / self.acquisition_spread_m) ** 2, 1.0), 100.0)
        return r * f
