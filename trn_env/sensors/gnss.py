"""GNSS receiver: position and velocity fixes with noise, and outage (jamming) windows.

Position error per NED axis = white noise + first-order Gauss-Markov (slowly wandering satellite-geometry
and atmosphere errors); velocity error = white noise. Inside an outage window [t_start, t_end) the fix is
invalid (values NaN): the situation TRN exists for.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.core.settings import setting
from trn_env.navigators.frames import GnssFrame
from trn_env.sensors.common import (
    EMPTY_B,
    EMPTY_F,
    EMPTY_F3,
    MappingConfig,
    due_samples,
    gm_coefficients,
    trusted_frame,
)
from trn_env.terrain.geodesy import WGS84_A_M, WGS84_E2


def _check_outages(value) -> tuple[tuple[float, float], ...]:
    try:
        windows = tuple((float(a), float(b)) for a, b in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"must be a list of (t_start_s, t_end_s) pairs, got {value!r}") from exc
    for i, (a, b) in enumerate(windows):
        if not (np.isfinite(a) and np.isfinite(b)):
            raise ValueError(f"[{i}] = {(a, b)} must be finite times")
        if not b > a:
            raise ValueError(f"[{i}] = {(a, b)} runs backwards or is empty "
                             "(t_end <= t_start)")
        if i and a < windows[i - 1][1]:
            raise ValueError(f"[{i}] = {(a, b)} overlaps or precedes outages[{i - 1}] = "
                             f"{windows[i - 1]} (windows must be sorted and disjoint)")
    return windows


@dataclass(frozen=True)
class GnssConfig(MappingConfig):
    """GNSS fix model, SI, 1 sigma per axis."""

    rate_hz: float = setting(1.0, "fixes per second", "Hz", gt=0.0)
    horizontal_noise_m: float = setting(1.0, "white position noise per north/east axis", "m", ge=0.0)
    vertical_noise_m: float = setting(2.0, "white position noise, down axis", "m", ge=0.0)
    horizontal_drift_m: float = setting(1.5, "Gauss-Markov position error std per north/east axis", "m",
                                        ge=0.0)
    vertical_drift_m: float = setting(3.0, "Gauss-Markov position error std, down axis", "m", ge=0.0)
    drift_tau_s: float = setting(300.0, "Gauss-Markov correlation time", "s", gt=0.0)
    velocity_noise_mps: float = setting(0.05, "white velocity noise per NED axis", "m/s", ge=0.0)
    outages: tuple[tuple[float, float], ...] = setting((), "sorted, disjoint [t_start_s, t_end_s) windows "
                                                           "without fixes", "s")

    def check(self) -> list[tuple[str, str]]:
        try:
            object.__setattr__(self, "outages", _check_outages(self.outages))
        except ValueError as exc:
            return [("outages", str(exc))]
        return []

    ERROR_FIELDS = ("horizontal_noise_m", "vertical_noise_m", "horizontal_drift_m", "vertical_drift_m",
                    "velocity_noise_mps")   # zero in noise_free()


    def available(self, t_s: np.ndarray) -> np.ndarray:
        """True where t_s lies outside every outage window."""
        t = np.asarray(t_s, float)
        ok = np.ones(t.shape, dtype=bool)
        for a, b in self.outages:
            ok &= ~((t >= a) & (t < b))
        return ok


class GnssState(NamedTuple):
    """Carried between chunks: grid index, Gauss-Markov position error (NED, m), model constants."""

    last_k: int | None
    drift_ned_m: np.ndarray   # (3,)
    params: np.ndarray        # phi (3), drive (3), white sigma (3), velocity sigma
    outages: np.ndarray       # (k, 2)

    @classmethod
    def initial(cls, config: GnssConfig, rng: np.random.Generator) -> GnssState:
        sig = np.array([config.horizontal_drift_m, config.horizontal_drift_m, config.vertical_drift_m])
        phi, drive = gm_coefficients(sig, np.full(3, config.drift_tau_s), 1.0 / config.rate_hz)
        white = [config.horizontal_noise_m, config.horizontal_noise_m, config.vertical_noise_m]
        params = np.concatenate([phi, drive, white, [config.velocity_noise_mps]])
        outages = np.array(config.outages, dtype=float).reshape(-1, 2)
        return cls(None, rng.standard_normal(3) * sig, params, outages)


@njit(cache=True)
def _gnss_kernel(idx, t_s, lat, lon, h, v_ned, w, params, drift0, outages):
    m = idx.shape[0]
    o_t = np.empty(m)
    o_lat, o_lon, o_h = np.empty(m), np.empty(m), np.empty(m)
    o_v = np.empty((m, 3))
    valid = np.empty(m, dtype=np.bool_)
    d = drift0.copy()
    for i in range(m):
        j = idx[i]
        t = t_s[j]
        o_t[i] = t
        e = np.empty(3)
        for a in range(3):
            d[a] = params[a] * d[a] + params[3 + a] * w[i, 3 + a]
            e[a] = d[a] + params[6 + a] * w[i, a]
        ok = np.isfinite(lat[j]) and np.isfinite(lon[j]) and np.isfinite(h[j])
        for k in range(outages.shape[0]):
            if outages[k, 0] <= t < outages[k, 1]:
                ok = False
        valid[i] = ok
        if not ok:
            o_lat[i] = o_lon[i] = o_h[i] = np.nan
            o_v[i, 0] = o_v[i, 1] = o_v[i, 2] = np.nan
            continue
        s2 = np.sin(lat[j]) ** 2
        r_n = WGS84_A_M * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s2) ** 1.5 + h[j]
        r_e = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s2) + h[j]
        o_lat[i] = lat[j] + e[0] / r_n
        o_lon[i] = lon[j] + e[1] / (r_e * np.cos(lat[j]))
        o_h[i] = h[j] - e[2]
        for a in range(3):
            o_v[i, a] = v_ned[j, a] + params[9] * w[i, 6 + a]
    return o_t, o_lat, o_lon, o_h, o_v, valid, d


def sample_gnss(truth: TruthChunk, terrain, rng: np.random.Generator, config: GnssConfig,
                state: GnssState | None = None) -> tuple[GnssFrame, GnssState]:
    """GNSS fixes over the chunk (terrain unused); invalid (NaN) inside outage windows."""
    state, idx, last_k = due_samples(truth, config, rng, state, GnssState)
    if idx is None:
        return trusted_frame(GnssFrame, t_s=EMPTY_F, lat_rad=EMPTY_F, lon_rad=EMPTY_F, h_m=EMPTY_F,
                             v_ned_mps=EMPTY_F3, valid=EMPTY_B), state
    w = rng.standard_normal((idx.shape[0], 9))
    t, lat, lon, h, v, valid, drift = _gnss_kernel(
        idx, truth.t_s, truth.lat_rad, truth.lon_rad, truth.h_msl_m, truth.v_ned_mps, w, state.params,
        state.drift_ned_m, state.outages)
    frame = trusted_frame(GnssFrame, t_s=t, lat_rad=lat, lon_rad=lon, h_m=h, v_ned_mps=v, valid=valid)
    return frame, GnssState(last_k, drift, state.params, state.outages)


__all__ = ["GnssConfig", "GnssState", "sample_gnss"]
