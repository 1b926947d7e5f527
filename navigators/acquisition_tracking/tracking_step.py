"""The tracking epoch of the acquisition-and-tracking navigator (seed 001): the early-late loops
(loop_kernel.track_loops), the integrity checks (V-shapes, terrain SNR, false lock), the centroid fix and
its Kalman update (R from the terrain information along / across the track), the references' update and
the loops' sigmas, and the out-of-lock / lost transitions.

A mixin of AcqTrackNavigator (navigator.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math

import numpy as np

from ...terrain.kernels import MapRecord
from . import beam, filter_kernels, loop_kernel, tracking
from .aiding import (
    wrap_rad,
)
from .buffers import (
    _MAD_VARIANCE_FACTOR,
    _inv2,
    _mean,
    _median,
    _nanmean,
    _quad2,
    _rot_diag,
)
from .correlation import Motion
from .integrity import (
    a_priori_sigma_m,
    false_lock,
    terrain_snr_db,
)
from .profile import (
    Sample,
)


class TrackingStep:
    """The tracking epoch of the acquisition-and-tracking navigator (seed 001); a mixin."""

    def _track_map(self, rng: np.ndarray) -> MapRecord:
        """The map record the loops correlate with: the plain map, or its footprint dilation at the
        transect's median range (replica_model), with the configured interpolation."""
        if self._footprint is None:
            return self._map
        key = getattr(self, "_track_grid_key", None)
        if key is not None and key[0] is rng:  # the same transect (its arrays are cached): the same grid
            return key[1]
        ok = np.isfinite(rng)
        rec = MapRecord(*self._footprint.grid(_median(rng[ok]) if ok.any() else math.nan), self._map.cubic)
        self._track_grid_key = (rng, rec)
        return rec

    def _track(self, s: Sample) -> None:
        cfg = self.config
        arrays = self._arrays()
        t, d, valid, dt, m_v, m_psi, rng, r_n, r_e = arrays
        n_valid = int(valid.sum())
        if n_valid < self._n_min:
            self.health.skip(
                s.t_s,
                "transect_too_few_samples",
                f"acq_track: {n_valid} valid samples of {valid.size}; loops skipped",
            )
            self._out_of_lock(s, "too few valid samples")
            return
        b_v0, b_psi0 = self.b_v, self.b_psi
        o_n, o_e = self._beam_arrays(b_psi0)
        # Aided: start-point loops first, at the (slow) references: the whole-replica shift is the position
        # fix, and the speed and heading loops then stretch and turn the shifted replica. Unaided the speed
        # and heading are the loops' own fast estimates, so they go first and the shift follows them. All of
        # it (adaptivity blocks, both stages, bias mitigation) and the prompt's map heights in one numba call.
        rec = self._track_map(rng)
        h_p = np.empty(dt.size)
        its, locks, ran, shp = self._loop_out
        transect = loop_kernel.TransectRecord(
            self.p0[0], self.p0[1], dt, m_v, m_psi, b_v0, b_psi0, r_n, r_e, d, valid, _mean(m_v),
            _mean(m_psi), o_n, o_e,
        )  # fmt: skip
        b_v, b_psi, lat_p, lon_p, sp_v, sp_psi = loop_kernel.track_loops(
            rec, transect, self._loop_settings, loop_kernel.LoopOutputs(its, locks, ran, shp, h_p)
        )
        p_s = (lat_p, lon_p)
        # the kernel's small outputs as Python lists: per-element numpy indexing costs more than tolist
        self.iterations = its.tolist()
        self.spacing = (sp_v, sp_psi)
        shp_rows = shp.tolist()
        self.v_shape = all(row[0] != 0.0 for row, r in zip(shp_rows, ran.tolist(), strict=True) if r)
        shapes = {k: tracking.VShape(bool(shp_rows[k][0]), *shp_rows[k][1:]) for k in (0, 1)}
        locks = locks.tolist()
        r_mean = _nanmean(rng)
        sig0 = a_priori_sigma_m(r_mean, cfg.ra_noise_const_m, cfg.ra_noise_fraction, cfg.map_sigma_m)
        self.snr_db, res_sigma = terrain_snr_db(h_p, d, valid, sig0, cfg.remove_bias)
        fl_v, fl_psi = b_v, b_psi
        if self._ne_frame:  # the plausible bias is the north/east vector's length (the loops' part on top)
            e_try = self.e_ne + self._ne_change(b_v, b_psi, m_v, m_psi)
            fl_v, fl_psi = float(math.hypot(e_try[0], e_try[1])), 0.0
        self.false_lock = false_lock(
            res_sigma,
            sig0,
            cfg.false_lock_sigma_factor,
            fl_v,
            fl_psi,
            cfg.aiding,
            cfg.max_speed_bias_mps,
            math.radians(cfg.max_heading_bias_deg),
        )
        reasons = []
        converged = bool(locks[0] and locks[1])
        if not self.v_shape:
            reasons.append("no V-shape around the correlation minimum")
        if not self.snr_db >= cfg.snr_min_db:
            reasons.append(f"terrain SNR {self.snr_db:.1f} dB < {cfg.snr_min_db:g} dB")
        if self.false_lock:
            reasons.append(f"false lock: {self.false_lock}")
        self.t_epoch = s.t_s
        if reasons:
            self._out_of_lock(s, "; ".join(reasons))
            return
        innov = np.array([b_v - b_v0, float(wrap_rad(b_psi - b_psi0))])
        # The fit pins the transect's centroid best: shift and stretch are uncorrelated about it, while its
        # far end carries the loops' speed / heading noise times half a transect. So the centroid the fit
        # found is the correlation's position fix; a 2-state Kalman filter (north, east of the centroid)
        # weighs it against the dead-reckoned centroid, the references move only part of the way
        # (reference_gain: the aided reference is a slow bias), and the start point follows from both, so the
        # fix is fed back into the start point and the output.
        c = self._centroid_index(valid)
        dla_f, dlo_f = self._offsets(dt, m_v, m_psi, b_v, b_psi, self.p0[0], (r_n, r_e))
        dla_p, dlo_p = self._offsets(dt, m_v, m_psi, b_v0, b_psi0, self.p0[0], (r_n, r_e))
        r_ne = np.array(
            [
                (p_s[0] - self.p0[0] + dla_f[c] - dla_p[c]) * r_n,
                (p_s[1] - self.p0[1] + dlo_f[c] - dlo_p[c]) * r_e,
            ]
        )
        # the fix's covariance: the terrain information along / across the track at the fit
        psi = self._aided_track(s)
        i_al, i_cr = beam.information_at(
            rec, p_s[0], p_s[1], Motion(dt, m_v, m_psi, r_n, r_e), b_v, b_psi, o_n, o_e, valid, psi
        )
        sig_res = max(res_sigma if math.isfinite(res_sigma) else 0.0, sig0)
        k2 = cfg.fix_sigma_scale**2 * _MAD_VARIANCE_FACTOR * sig_res**2
        q_map = self.map_resolution_m**2 / 12.0  # the map's quantisation of the fix
        R = _rot_diag(psi, k2 / max(i_al, 1e-12) + q_map, k2 / max(i_cr, 1e-12) + q_map)
        S = self.Pc + R
        nis = _quad2(r_ne, S)
        if nis > cfg.fix_gate_nis:  # innovation gate: a fix this far from the prediction is a false lock
            self.last_innovation = (s.t_s, r_ne, S)
            self._out_of_lock(s, f"fix innovation NIS {nis:.1f} > gate {cfg.fix_gate_nis:g}")
            return
        # consecutive transects share N - 1 samples: each epoch's fix brings 1/overlap of new information
        if self._ne_frame:  # the 4-state filter: the fix corrects the centroid and the velocity bias
            Ro = self._fix_overlap * R
            X_new, dx = np.empty((4, 4)), np.empty(4)
            if not filter_kernels.ne_fix_gain(self.X, Ro, float(r_ne[0]), float(r_ne[1]), X_new, dx):
                raise np.linalg.LinAlgError("singular 2 x 2 matrix")
            e_new = self.e_ne + dx[2:]
            if math.hypot(e_new[0], e_new[1]) > cfg.max_speed_bias_mps:  # beyond the plausible bias
                self.last_innovation = (s.t_s, r_ne, S)
                lim = cfg.max_speed_bias_mps
                self._out_of_lock(s, f"false lock: velocity bias {math.hypot(*e_new):.1f} m/s beyond {lim:g}")
                return
            self.X = X_new
            dc = dx[:2]
            self.Pc = self.X[:2, :2].copy()
        else:
            K = self.Pc @ _inv2(self.Pc + self._fix_overlap * R)
            IK = np.eye(2) - K
            self.Pc = IK @ self.Pc @ IK.T + self._fix_overlap * (K @ R @ K.T)
            dc = K @ r_ne
        c_new = (self.p0[0] + dla_p[c] + dc[0] / r_n, self.p0[1] + dlo_p[c] + dc[1] / r_e)
        g = 1.0
        if cfg.aiding:  # the aided reference is a slow bias: move it part of the way (reference_gain), but
            # take the loops' values whole for a transect after an acquisition (pull-in: its bins are coarse)
            g = 1.0 if self.pull_in > 0 else cfg.reference_gain
            b_v, b_psi = b_v0 + g * innov[0], b_psi0 + g * innov[1]
        self.pull_in = max(self.pull_in - 1, 0)
        self.b_v, self.b_psi = b_v, b_psi
        if self._ne_frame:  # the fix's velocity part moves e_ne; the start point follows below
            self.e_ne = self.e_ne + dx[2:]
            self.b_v = self.b_psi = 0.0
            _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
            b_v = b_psi = 0.0
        dla_n, dlo_n = self._offsets(dt, m_v, m_psi, b_v, b_psi, self.p0[0], (r_n, r_e))
        self.p0 = (c_new[0] - dla_n[c], c_new[1] - dlo_n[c])
        # loop sigmas: the V's slopes against the cost noise (sigma sqrt((1 - 2/pi)/N), MAD of Gaussians)
        n_ok = max(n_valid, 1)
        cost_noise = sig0 * math.sqrt((1.0 - 2.0 / math.pi) / n_ok)
        mv_mean = _mean(m_v)  # the (corrected) aiding speed over the transect, used twice below
        if self._ne_frame:  # the references' sigma is e_ne's, along / across the track
            (xe00, xe01), (_, xe11) = self.X[2:, 2:].tolist()
            c_, s_ = math.cos(psi), math.sin(psi)
            s_al = c_ * c_ * xe00 + 2 * c_ * s_ * xe01 + s_ * s_ * xe11
            s_cr = s_ * s_ * xe00 - 2 * c_ * s_ * xe01 + c_ * c_ * xe11
            v_ref = max(mv_mean, 1.0)
            sv = [math.sqrt(max(s_al, 0.0)), math.sqrt(max(s_cr, 0.0)) / v_ref]
        else:
            sv = [
                self._loop_sigma(shapes[0], cost_noise, cfg.speed_narrow_spacing_mps),
                self._loop_sigma(shapes[1], cost_noise, math.radians(cfg.heading_narrow_spacing_deg)),
            ]
            if g < 1.0:  # the references are an exponential average of the loops' values (gain g)
                sv = [x * math.sqrt(g / (2.0 - g)) for x in sv]
        self.sigma_v, self.sigma_psi = sv
        self.last_innovation = (s.t_s, r_ne, S)
        verdict = self.integrity.add(s.t_s, nis, 2)
        self.consistency.add(nis, 2)
        self._integrity_extra = verdict.extra()
        if verdict.changed:
            self.health.events.append((s.t_s, f"acq_track: {verdict.message}"))
        self.bad_epochs = 0
        k = 1.0 / max(cfg.transect_samples, 1)  # the references' running mean over about a transect
        self.e_mean = self.e_mean + k * (self.e_ne - self.e_mean)
        self.b_mean = (
            self.b_mean[0] + k * (b_v - self.b_mean[0]),
            self.b_mean[1] + k * (b_psi - self.b_mean[1]),
        )
        # the newest sample's covariance: the centroid's, plus dead reckoning over the rest of the transect
        lever_s = float(t[-1] - t[c])
        v_mean = max(mv_mean + b_v, 1.0)
        walk = self._walk2 * lever_s
        if self._ne_frame:
            self.P = self._ne_output_cov(lever_s)
        else:
            self.P = self.Pc + _rot_diag(
                psi, (lever_s * sv[0]) ** 2 + walk, (v_mean * lever_s * sv[1]) ** 2 + walk
            )
        if converged and self.integrity.degraded:  # in lock, but the references jump: flagged
            self._set_lock("tracking", s.t_s, "degraded", "in lock, innovation test above its band")
        elif converged:
            self._set_lock("tracking", s.t_s, "ok", "in lock")
        else:  # the V is there but a loop hit the 101-iteration break: estimate kept, flagged
            self._set_lock("tracking", s.t_s, "degraded", "a loop did not converge (101-iteration break)")

    @staticmethod
    def _centroid_index(valid: np.ndarray) -> int:
        """The sample nearest the mean index of the valid samples (the fit's pivot)."""
        idx = np.nonzero(valid)[0]
        return int(round(_mean(idx))) if idx.size else (valid.size - 1) // 2

    @staticmethod
    def _loop_sigma(shape, cost_noise: float, narrow: float) -> float:
        slope = min(abs(shape.slope_left), abs(shape.slope_right))
        res = cost_noise / slope if slope > 0 else np.inf
        return float(math.sqrt(min(res, 10.0 * narrow) ** 2 + (narrow / math.sqrt(12.0)) ** 2))

    def _out_of_lock(self, s: Sample, reason: str) -> None:
        cfg = self.config
        self.bad_epochs += 1
        self.sigma_v = cfg.aiding_speed_sigma_mps if cfg.aiding else cfg.unaided_speed_sigma_mps
        self.sigma_psi = math.radians(
            cfg.aiding_heading_sigma_deg if cfg.aiding else cfg.unaided_heading_sigma_deg
        )
        if self.bad_epochs >= cfg.lost_after_epochs:
            if cfg.aiding and self.lock_state != "lost":
                # dead-reckon on the aiding with the references' running mean over the lock: they carry the
                # sensor biases and the wind's data bias the loops learned (zeroing them drops that)
                lim_v, lim_p = cfg.max_speed_bias_mps, math.radians(cfg.max_heading_bias_deg)
                self.b_v = float(np.clip(self.b_mean[0], -lim_v, lim_v))
                self.b_psi = float(np.clip(self.b_mean[1], -lim_p, lim_p))
                if self._ne_frame:  # the filter's e_ne is kept (it is not a loop value)
                    self.b_v = self.b_psi = 0.0
            self.need_acquisition = True
            self._anchored = False
            self._set_lock("lost", s.t_s, "lost", f"out of lock {self.bad_epochs} epochs: {reason}")
        else:
            self._set_lock("out_of_lock", s.t_s, "degraded", reason)
