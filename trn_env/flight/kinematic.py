"""Kinematic truth: a prescribed motion profile of straight, turning and climbing segments, as TruthChunks.

For conditions beyond the King Air (seed 002's 240 m/s at 2,500 m) the truth comes from a motion profile
instead of JSBSim, and fills the same `TruthChunk`, so the same sensors (trn_env.sensors) and navigators run
on it.

Profile. Constant true airspeed V along the body x axis (alpha = beta = 0) and a constant wind w (NED,
default none): the ground velocity is v = v_air + w, so in a crosswind the heading psi differs from the
ground track by the crab angle asin(w_cross / V) (`heading_for_track`). Each segment holds a bank angle phi
(a coordinated turn: psi_dot = g0 tan(phi) / (V cos(gamma))) and a flight-path angle gamma (a climb or
descent); at its start both move from the previous segment's values by a raised cosine over
`transition_s`, so rates and accelerations are continuous. Attitude: roll phi,
pitch gamma, yaw psi (3-2-1 Euler). With the wind constant, v_dot = d(v_air)/dt.

Consistency with the INS (navigators.inertial.strapdown, the same WGS84 radii, Earth rate and J2 gravity):
    f^n = v_dot + (2 w_ie + w_en) x v - g^n(lat, h)      f_b = C_bn^T f^n
    w_nb^b from the Euler rates,  w_ib^b = w_nb^b + C_bn^T (w_ie + w_en),  w_eb^b = w_nb^b + C_bn^T w_en
with v_dot, the Euler rates and their ingredients analytic; heading and position are integrated on a grid
`substeps` times finer than the output (trapezoid), so they agree with the analytic rates to ~1e-9.
Samples are instantaneous values at the output times: sample an IMU on it with `sampling="instant"` and run
the INS with `imu_samples="instant"` (tests/test_kinematic_truth.py: a noise-free IMU, the INS follows it
to centimetres over minutes).

`KinematicFlight` wraps a profile in the interface the closed loop uses of trn_env.flight.Flight (snapshot,
record/take, targets, fuel), so a scenario's `[truth] source = "kinematic"` flies the same sensors and
navigators (trn_env.scenario.build.build_flight). Guidance runs but cannot steer a prescribed profile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from trn_env.flight.atmosphere import Atmosphere, static_p_T
from trn_env.flight.truth import StepClock, TruthChunk
from trn_env.navigators.inertial.strapdown import gravity_ned
from trn_env.terrain.geodesy import OMEGA_EARTH_RPS, WGS84_A_M, WGS84_E2

G0_MPS2 = 9.80665
SEGMENT_KINDS = ("straight", "turn", "climb")


@dataclass(frozen=True)
class Segment:
    """One leg of the profile: hold bank_deg and flight_path_deg for duration_s (the first transition_s
    blend from the previous leg's values). kind is descriptive and checked against the values:
    "straight" (bank 0, level unless flight_path_deg set), "turn" (bank != 0), "climb" (flight path != 0)."""

    kind: str
    duration_s: float
    bank_deg: float = 0.0
    flight_path_deg: float = 0.0
    transition_s: float = 5.0

    def __post_init__(self):
        if self.kind not in SEGMENT_KINDS:
            raise ValueError(f"Segment.kind must be one of {SEGMENT_KINDS}, got {self.kind!r}")
        for name in ("duration_s", "bank_deg", "flight_path_deg", "transition_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"Segment.{name} must be a finite number, got {v!r}")
        if not self.duration_s > 0:
            raise ValueError(f"Segment.duration_s must be positive, got {self.duration_s}")
        if not 0 < self.transition_s <= self.duration_s:
            raise ValueError(f"Segment.transition_s must lie in (0, duration_s], got {self.transition_s}")
        if not abs(self.bank_deg) < 75.0:
            raise ValueError(f"Segment.bank_deg must lie in (-75, 75), got {self.bank_deg}")
        if not abs(self.flight_path_deg) < 45.0:
            raise ValueError(f"Segment.flight_path_deg must lie in (-45, 45), got {self.flight_path_deg}")
        if self.kind == "turn" and self.bank_deg == 0.0:
            raise ValueError("Segment.bank_deg must be non-zero for a turn")
        if self.kind == "climb" and self.flight_path_deg == 0.0:
            raise ValueError("Segment.flight_path_deg must be non-zero for a climb")
        if self.kind == "straight" and self.bank_deg != 0.0:
            raise ValueError("Segment.bank_deg must be 0 for a straight segment")

    @classmethod
    def from_mapping(cls, m: dict[str, Any]) -> Segment:
        unknown = sorted(set(m) - {"kind", "duration_s", "bank_deg", "flight_path_deg", "transition_s"})
        if unknown:
            raise ValueError(f"Segment: unknown field(s) {unknown}")
        return cls(**m)


def _blend(t, starts, trans, values, initial):
    """Piecewise raised-cosine profile: value and derivative at times t (arrays)."""
    k = np.searchsorted(starts, t, side="right") - 1
    k = np.clip(k, 0, len(starts) - 1)
    prev = np.where(k > 0, values[np.maximum(k - 1, 0)], initial)
    u = np.clip((t - starts[k]) / trans[k], 0.0, 1.0)
    s = 0.5 * (1.0 - np.cos(np.pi * u))
    ds = np.where((u > 0.0) & (u < 1.0), 0.5 * np.pi * np.sin(np.pi * u) / trans[k], 0.0)
    d = values[k] - prev
    return prev + d * s, d * ds


def _radii(lat, h):
    sl = np.sin(lat)
    w = 1.0 - WGS84_E2 * sl * sl
    return WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w)) + h, WGS84_A_M / np.sqrt(w) + h


class KinematicTruth:
    """Truth chunks of a prescribed profile (see the module docstring).

    lat0_rad, lon0_rad, h0_m: start (geodetic, height above MSL); speed_mps: true airspeed (the ground speed
    without wind); heading_rad: initial heading (the track without wind); segments: Segment or mappings;
    rate_hz: truth rate; terrain: optional terrain.Dem for h_agl_m (NaN without); wind_ned_mps: constant
    wind (m/s NED, toward), its magnitude below speed_mps; atmosphere: the day's trn_env.flight.Atmosphere
    for the static pressure and temperature (standard by default). After the last segment the profile holds
    its last values.
    """

    def __init__(self, lat0_rad: float, lon0_rad: float, h0_m: float, speed_mps: float, heading_rad: float,
                 segments, rate_hz: float = 100.0, terrain=None, substeps: int = 8,
                 wind_ned_mps=(0.0, 0.0, 0.0), atmosphere: Atmosphere | None = None):
        for name, v in (("lat0_rad", lat0_rad), ("lon0_rad", lon0_rad), ("h0_m", h0_m),
                        ("speed_mps", speed_mps), ("heading_rad", heading_rad), ("rate_hz", rate_hz)):
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"kinematic truth: {name} must be a finite number, got {v!r}")
        if not speed_mps > 1.0:
            raise ValueError(f"kinematic truth: speed_mps must exceed 1 m/s, got {speed_mps}")
        wind = np.asarray(wind_ned_mps, dtype=float)
        if wind.shape != (3,) or not np.all(np.isfinite(wind)):
            raise ValueError(f"kinematic truth: wind_ned_mps must be 3 finite numbers, got {wind_ned_mps!r}")
        if not np.linalg.norm(wind) < speed_mps:
            raise ValueError(f"kinematic truth: the wind ({np.linalg.norm(wind):g} m/s) must be slower than "
                             f"speed_mps ({speed_mps:g})")
        self.wind_ned_mps = wind
        self.atmosphere = atmosphere if atmosphere is not None else Atmosphere()
        if not rate_hz > 0:
            raise ValueError(f"kinematic truth: rate_hz must be positive, got {rate_hz}")
        if not abs(lat0_rad) < math.radians(85.0):
            raise ValueError("kinematic truth: lat0_rad must lie within +-85 deg")
        segs = [s if isinstance(s, Segment) else Segment.from_mapping(dict(s)) for s in segments]
        if not segs:
            raise ValueError("kinematic truth: segments must not be empty")
        self.segments = tuple(segs)
        self.speed_mps = float(speed_mps)
        self.dt_s = 1.0 / float(rate_hz)
        self.substeps = int(substeps)
        self.terrain = terrain
        self._starts = np.cumsum([0.0] + [s.duration_s for s in segs[:-1]])
        self._trans = np.array([s.transition_s for s in segs])
        self._bank = np.radians([s.bank_deg for s in segs])
        self._gamma = np.radians([s.flight_path_deg for s in segs])
        self.duration_s = float(sum(s.duration_s for s in segs))
        self._state = np.array([lat0_rad, lon0_rad, h0_m, heading_rad], float)
        self._k = 0   # index of the last emitted row
        self._started = False

    def _profile(self, t):
        phi, dphi = _blend(t, self._starts, self._trans, self._bank, 0.0)
        gam, dgam = _blend(t, self._starts, self._trans, self._gamma, 0.0)
        dpsi = G0_MPS2 * np.tan(phi) / (self.speed_mps * np.cos(gam))
        return phi, dphi, gam, dgam, dpsi

    def _v_ned(self, psi, gam):
        """Ground velocity: the air velocity along the body x axis plus the wind."""
        V = self.speed_mps
        return np.stack([V * np.cos(gam) * np.cos(psi), V * np.cos(gam) * np.sin(psi), -V * np.sin(gam)],
                        -1) + self.wind_ned_mps

    def advance(self, n: int) -> TruthChunk:
        """The next n truth rows (the first call starts at t = 0)."""
        n = int(n)
        if n <= 0:
            return TruthChunk.empty(0)
        sub = self.substeps
        dt = self.dt_s
        first = not self._started
        k0 = 0 if first else self._k
        t_out = (k0 + (np.arange(n) if first else np.arange(1, n + 1))) * dt
        # fine grid from the last emitted time (its state known) to the chunk's last output time
        m = (n - 1) * sub if first else n * sub
        t_fine = (k0 * sub + np.arange(m + 1)) * (dt / sub)
        phi_f, _, gam_f, _, dpsi_f = self._profile(t_fine)
        lat0, lon0, h0, psi0 = self._state
        psi_f = psi0 + np.concatenate([[0.0], np.cumsum(0.5 * (dpsi_f[1:] + dpsi_f[:-1]) * (dt / sub))])
        v_f = self._v_ned(psi_f, gam_f)
        # position: trapezoid with the radii at the running state (two passes for the radii's dependence)
        lat_f = np.full(m + 1, lat0)
        h_f = h0 + np.concatenate([[0.0], np.cumsum(-0.5 * (v_f[1:, 2] + v_f[:-1, 2]) * (dt / sub))])
        for _ in range(3):
            rn, re = _radii(lat_f, h_f)
            dlat = v_f[:, 0] / rn
            lat_f = lat0 + np.concatenate([[0.0], np.cumsum(0.5 * (dlat[1:] + dlat[:-1]) * (dt / sub))])
        rn, re = _radii(lat_f, h_f)
        dlon = v_f[:, 1] / (re * np.cos(lat_f))
        lon_f = lon0 + np.concatenate([[0.0], np.cumsum(0.5 * (dlon[1:] + dlon[:-1]) * (dt / sub))])
        idx = np.arange(0, m + 1, sub) if first else np.arange(sub, m + 1, sub)
        t = t_out
        lat, lon, h, psi = lat_f[idx], lon_f[idx], h_f[idx], psi_f[idx]
        self._state = np.array([lat_f[-1], lon_f[-1], h_f[-1], psi_f[-1]])
        self._k = k0 + (n - 1 if first else n)
        self._started = True
        phi, dphi, gam, dgam, dpsi = self._profile(t)
        V = self.speed_mps
        v = self._v_ned(psi, gam)
        cg, sg, cp, sp = np.cos(gam), np.sin(gam), np.cos(psi), np.sin(psi)
        vdot = np.stack([V * (-sg * dgam * cp - cg * sp * dpsi), V * (-sg * dgam * sp + cg * cp * dpsi),
                         -V * cg * dgam], -1)
        cf, sf = np.cos(phi), np.sin(phi)
        # C_bn of 3-2-1 Euler (roll phi, pitch gam, yaw psi)
        C = np.empty((n, 3, 3))
        C[:, 0, 0] = cg * cp
        C[:, 0, 1] = sf * sg * cp - cf * sp
        C[:, 0, 2] = cf * sg * cp + sf * sp
        C[:, 1, 0] = cg * sp
        C[:, 1, 1] = sf * sg * sp + cf * cp
        C[:, 1, 2] = cf * sg * sp - sf * cp
        C[:, 2, 0] = -sg
        C[:, 2, 1] = sf * cg
        C[:, 2, 2] = cf * cg
        rn, re = _radii(lat, h)
        w_ie = np.stack([OMEGA_EARTH_RPS * np.cos(lat), np.zeros(n), -OMEGA_EARTH_RPS * np.sin(lat)], -1)
        w_en = np.stack([v[:, 1] / re, -v[:, 0] / rn, -v[:, 1] * np.tan(lat) / re], -1)
        w_nb_b = np.stack([dphi - dpsi * sg, dgam * cf + dpsi * cg * sf, -dgam * sf + dpsi * cg * cf], -1)
        g = np.array([gravity_ned(float(la), float(hh), 1) for la, hh in zip(lat, h, strict=True)])
        f_n = vdot + np.cross(2.0 * w_ie + w_en, v) - g
        Ct = np.transpose(C, (0, 2, 1))
        f_b = np.einsum("kij,kj->ki", Ct, f_n)
        w_ib_b = w_nb_b + np.einsum("kij,kj->ki", Ct, w_ie + w_en)
        w_eb_b = w_nb_b + np.einsum("kij,kj->ki", Ct, w_en)
        chunk = TruthChunk.empty(n)
        chunk.t_s[:] = t
        chunk.lat_rad[:] = lat
        chunk.lon_rad[:] = lon
        chunk.h_msl_m[:] = h
        chunk.v_ned_mps[:] = v
        chunk.roll_rad[:] = phi
        chunk.pitch_rad[:] = gam
        chunk.yaw_rad[:] = np.angle(np.exp(1j * psi))
        chunk.C_bn[:] = C
        chunk.omega_ib_b_rps[:] = w_ib_b
        chunk.omega_eb_b_rps[:] = w_eb_b
        chunk.f_b_mps2[:] = f_b
        chunk.tas_mps[:] = V
        chunk.alpha_rad[:] = 0.0
        chunk.beta_rad[:] = 0.0
        for i in range(n):
            chunk.p_static_pa[i], chunk.T_static_K[i] = static_p_T(lat[i], lon[i], h[i],
                                                                    self.atmosphere.delta_T_K,
                                                                    self.atmosphere.p_sl_pa)
        chunk.wind_ned_mps[:] = self.wind_ned_mps
        if self.terrain is not None:
            chunk.h_agl_m[:] = h - self.terrain.height(lat, lon)
        return chunk

    def truth(self, duration_s: float | None = None) -> TruthChunk:
        """The whole profile (or its first duration_s) as one chunk, from t = 0 (a fresh generator)."""
        d = self.duration_s if duration_s is None else float(duration_s)
        n = int(round(d / self.dt_s)) + 1
        return self.advance(n)


def wind_ned_from(speed_mps: float, from_deg: float) -> np.ndarray:
    """Horizontal wind (m/s NED, the direction it blows toward) of a wind `speed_mps` FROM `from_deg`."""
    a = math.radians(from_deg)
    return np.array([-speed_mps * math.cos(a), -speed_mps * math.sin(a), 0.0])


def heading_for_track(track_rad: float, speed_mps: float, wind_ned_mps) -> float:
    """Heading (rad) whose air velocity speed_mps plus the horizontal wind points along track_rad (level
    flight): heading = track - asin(w_cross / V), w_cross the wind's component to the right of the track."""
    w = np.asarray(wind_ned_mps, float)
    cross = -w[0] * math.sin(track_rad) + w[1] * math.cos(track_rad)
    if not abs(cross) < speed_mps:
        raise ValueError(f"a crosswind of {cross:g} m/s cannot be held at {speed_mps:g} m/s")
    return track_rad - math.asin(cross / speed_mps)


class KinematicFlight(StepClock):
    """A KinematicTruth behind the part of trn_env.flight.Flight's interface the closed loop uses.

    Steps are the profile's rows (dt_s = 1 / its rate); snapshot() is the state at t = 0 before any step.
    Targets and the terrain elevation are accepted and kept but change nothing (the motion is prescribed);
    there is no engine or fuel (fuel_kg NaN, constant_fuel True). Past the profile's end it holds its last
    bank and flight-path angle."""

    constant_fuel = True

    def __init__(self, truth: KinematicTruth):
        self.truth = truth
        self.dt_s = truth.dt_s
        self._steps = 0
        self._pending: list[TruthChunk] = []
        self._n_pending = 0
        self._last = truth.advance(1)
        self._targets = None
        self._terrain_elevation_m = math.nan

    @property
    def fuel_kg(self) -> float:
        return math.nan

    @property
    def pending_steps(self) -> int:
        return self._n_pending

    @property
    def targets(self):
        return self._targets

    def set_targets(self, targets) -> None:
        self._targets = targets

    def set_terrain_elevation(self, h_m: float) -> None:
        self._terrain_elevation_m = float(h_m)

    def engine_stop(self) -> None:
        return None

    def snapshot(self) -> TruthChunk:
        """The current state as a one-row TruthChunk."""
        return self._last.slice(len(self._last) - 1, len(self._last)).copy()

    def record(self, n_steps: int) -> None:
        if n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {n_steps}")
        chunk = self.truth.advance(int(n_steps))
        self._pending.append(chunk)
        self._n_pending += len(chunk)
        self._steps += len(chunk)
        self._last = chunk

    def take(self) -> TruthChunk:
        if not self._n_pending:
            raise ValueError("KinematicFlight.take: no steps recorded since the last take()")
        out = self._pending[0] if len(self._pending) == 1 else TruthChunk.concatenate(self._pending)
        self._pending = []
        self._n_pending = 0
        return out

    def advance(self, n_steps: int) -> TruthChunk:
        self.record(n_steps)
        return self.take()


__all__ = ["SEGMENT_KINDS", "KinematicFlight", "KinematicTruth", "Segment", "heading_for_track",
           "wind_ned_from"]
