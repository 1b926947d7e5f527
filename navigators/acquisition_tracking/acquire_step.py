"""The acquisition epoch of the acquisition-and-tracking navigator (seed 001): the predicted terrain SNR
that defers a search over flat terrain, and the serial search (acquisition.py) around the dead-reckoned
transect start, its plausibility check against the velocity bias' sigma and the lock it starts.

`_acquisition_epoch` decides when a search is due (a large dead-reckoned sigma, a back-off after failed
searches, the SNR deferral).

A mixin of AcqTrackNavigator (navigator.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import acquisition
from .buffers import (
    _mean,
    _nanmean,
    _quad2,
    _rot_diag,
)
from .correlation import (
    Motion,
    replica_heights,
)
from .integrity import (
    a_priori_sigma_m,
)
from .profile import (
    Sample,
)


class AcquisitionStep:
    """The acquisition epoch of the acquisition-and-tracking navigator (seed 001); a mixin."""

    def _predicted_snr(self) -> float:
        """Terrain SNR (dB) of the map along the dead-reckoned transect against the a-priori noise alone."""
        cfg = self.config
        t, d, valid, dt, m_v, m_psi, rng, r_n, r_e = self._arrays()
        n = dt.size
        h_p = np.empty(n)
        replica_heights(self._map, self.p0[0], self.p0[1], Motion(dt, m_v, m_psi, r_n, r_e), self.b_v,
                        self.b_psi, np.empty(n), np.empty(n), h_p)
        ok = valid & np.isfinite(h_p)
        if ok.sum() < self._n_min:
            return -math.inf
        r_mean = _nanmean(rng)
        sig0 = a_priori_sigma_m(r_mean, cfg.ra_noise_const_m, cfg.ra_noise_fraction, cfg.map_sigma_m)
        var_h = float(np.var(h_p[ok]))
        return 10.0 * math.log10(var_h / sig0**2) if var_h > 0 else -math.inf

    def _acquire(self, s: Sample) -> bool:
        cfg = self.config
        t, d, valid, dt, m_v, m_psi, rng, r_n, r_e = self._arrays()
        sig = self._sigma_h()
        half = min(max(cfg.acquisition_position_half_m, 3.0 * sig), 2.0 * cfg.acquisition_position_half_m)
        w0 = time.perf_counter()
        res = acquisition.serial_search(
            self._map, self.p0[0], self.p0[1], dt, m_v, m_psi, self.b_v, self.b_psi, r_n, r_e, d, valid,
            cost=self._cost, remove_bias=cfg.remove_bias, n_min=self._n_min,
            **acquisition.search_grid(cfg, half),
        )
        self.acquisition_s = time.perf_counter() - w0
        self.acquisition_total_s += self.acquisition_s
        self.acquisitions += 1
        if not res.distinct:
            self.health.events.append(
                (
                    s.t_s,
                    f"acq_track: acquisition failed: {res.reason} ({res.n_hypotheses} cells)",
                )
            )
            self._set_lock(
                "acquiring",
                s.t_s,
                "lost" if self.need_acquisition else "acquiring",
                f"acquisition: {res.reason}; retry with the next transect",
            )
            return False
        if self._ne_frame:  # the acquired velocity against the filter's velocity bias: a false acquisition
            # (a side minimum over weak terrain) moves it far beyond its sigma; R: one bin as 1 sigma
            dv_ne = self._ne_change(res.b_v - self.b_v, res.b_psi_rad - self.b_psi, m_v, m_psi)
            psi_c = _mean(m_psi)
            v_c = max(_mean(m_v), 1.0)
            R_acq = _rot_diag(
                psi_c,
                cfg.acquisition_speed_bin_mps**2,
                (v_c * math.radians(cfg.acquisition_heading_bin_deg)) ** 2,
            )
            nis_v = _quad2(dv_ne, self.X[2:, 2:] + R_acq)
            e_acq = self.e_ne + dv_ne
            if nis_v > cfg.fix_gate_nis or math.hypot(e_acq[0], e_acq[1]) > cfg.max_speed_bias_mps:
                self.health.events.append(
                    (
                        s.t_s,
                        f"acq_track: acquisition rejected: its velocity change {math.hypot(*dv_ne):.1f} m/s "
                        f"has NIS {nis_v:.1f} (gate {cfg.fix_gate_nis:g}) against the velocity bias' sigma, "
                        f"bias {math.hypot(*e_acq):.1f} m/s (limit {cfg.max_speed_bias_mps:g})",
                    )
                )
                self._set_lock(
                    "acquiring",
                    s.t_s,
                    "lost" if self.need_acquisition else "acquiring",
                    "acquisition: implausible velocity; retry with the next transect",
                )
                return False
        self.p0 = (self.p0[0] + res.dn_m / r_n, self.p0[1] + res.de_m / r_e)
        self.b_v, self.b_psi = res.b_v, res.b_psi_rad
        if self._ne_frame:  # the acquired speed / track references as the north/east bias
            self._fold_references(res.b_v, res.b_psi_rad, m_v, m_psi)
        b = cfg.acquisition_position_bin_m
        self.P = np.eye(2) * (b * b + self.sigma_floor_m**2)
        self.Pc = self.P.copy()
        self._set_centroid_cov(self.Pc)
        self.need_acquisition = False
        self.acq_failures = 0
        self.bad_epochs = 0
        self.pull_in = cfg.transect_samples
        self.health.events.append(
            (
                s.t_s,
                f"acq_track: acquired dn={res.dn_m:+.0f} m de={res.de_m:+.0f} m "
                f"b_v={res.b_v:+.2f} m/s b_psi={math.degrees(res.b_psi_rad):+.2f} deg "
                f"({res.n_hypotheses} cells)",
            )
        )
        self.lock_state = "tracking"
        return True

    def _acquisition_epoch(self, s: Sample) -> bool:
        """The acquisition part of an epoch on a full transect: a serial search when one is due (after a
        back-off, and not over terrain whose predicted SNR is below snr_min_db). True when the epoch ends
        here (waiting, deferred or no distinct minimum found); False when tracking follows."""
        cfg = self.config
        # a transect placed by GNSS goes straight to tracking; otherwise a large sigma asks for a search
        # a serial search only when the dead-reckoned start is too uncertain for the loops' pull-in range:
        # after a loss of lock with a small sigma the loops re-lock from the dead-reckoned state (the
        # integrity checks decide), so a low-SNR stretch does not leave the tracker searching to the end
        acq_due = (
            self.need_acquisition or (self.lock_state in ("filling", "acquiring") and not self._anchored)
        ) and self._sigma_h() > cfg.acquire_above_sigma_m
        if not acq_due:
            return False
        if self.acq_wait > 0:
            self.acq_wait -= 1
            return True
        snr_pred = self._predicted_snr()
        if not snr_pred >= cfg.snr_min_db:  # integrity prediction: no search over flat terrain
            if not self._deferred:
                self.health.events.append(
                    (
                        s.t_s,
                        f"acq_track: predicted terrain SNR {snr_pred:.1f} dB < "
                        f"{cfg.snr_min_db:g} dB: acquisition deferred",
                    )
                )
            self._deferred = True
            self.snr_db = snr_pred
            self._set_lock(
                self.lock_state if self.lock_state == "lost" else "acquiring",
                s.t_s,
                "lost" if self.need_acquisition else "acquiring",
                f"predicted terrain SNR {snr_pred:.1f} dB < {cfg.snr_min_db:g} dB: acquisition deferred",
            )
            return True
        self._deferred = False
        if not self._acquire(s):
            # retry with the next transect, backing off to every 4th after repeated failures
            self.acq_failures += 1
            self.acq_wait = (cfg.transect_samples - 1) * min(2 ** (self.acq_failures - 1), 4)
            return True
        return False
