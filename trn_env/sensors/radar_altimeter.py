"""Pulse radar altimeter: range to the closest terrain point inside the beam cone.

A pulse radar altimeter reports the first return, i.e. the shortest range to any terrain inside its beam
(seed 000 section 2, thesis section 5: 17 and 35 deg beams in the flight tests). The cone's axis is the
body down axis, so roll and pitch move the footprint with the body. Noise is altitude dependent,
sigma = noise_const_m + noise_fraction * range (default 0.6 m + 2 %, the thesis's +-(2 ft + 2 %) read as
1 sigma). Beyond `max_range_m`, or with no terrain in the cone, the sample has no return (valid False).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.core.settings import setting
from trn_env.navigators.frames import RadarAltimeterFrame
from trn_env.sensors.common import (
    EMPTY_B,
    EMPTY_F,
    MappingConfig,
    TimeGridState,
    antenna_positions,
    due_samples,
    trusted_frame,
)
from trn_env.terrain import queries


@dataclass(frozen=True)
class RadarAltimeterConfig(MappingConfig):
    """Radar altimeter; beamwidth is the full cone angle (deg), lever arm in body FRD metres."""

    rate_hz: float = setting(20.0, "samples per second", "Hz", gt=0.0)
    beamwidth_deg: float = setting(17.0, "full cone angle of the beam", "deg", gt=0.0, lt=90.0)
    max_range_m: float = setting(5000.0, "maximum range (no return beyond)", "m", gt=0.0)
    noise_const_m: float = setting(0.6, "range noise, constant part (1 sigma = const + fraction x R)", "m",
                                   ge=0.0)
    noise_fraction: float = setting(0.02, "range noise, fraction of the range", "1", ge=0.0)
    lever_arm_b_m: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "antenna offset from the IMU, body "
                                                                         "FRD", "m", length=3)

    ERROR_FIELDS = ("noise_const_m", "noise_fraction")   # zero in noise_free()


RadarAltimeterState = TimeGridState   # white errors only: the sample grid is all it carries


@njit(cache=True)
def _ra_noise(q_valid, q_range, w, a_m, b, max_range):
    n = q_range.shape[0]
    out = np.empty(n)
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        r = q_range[i]
        ok = q_valid[i] and np.isfinite(r) and r <= max_range
        valid[i] = ok
        out[i] = max(r + w[i] * (a_m + b * r), 0.0) if ok else np.nan
    return out, valid


def sample_radar_altimeter(truth: TruthChunk, terrain, rng: np.random.Generator, config: RadarAltimeterConfig,
                           state: RadarAltimeterState | None = None
                           ) -> tuple[RadarAltimeterFrame, RadarAltimeterState]:
    """Radar-altimeter ranges over the chunk against the true terrain `terrain` (a terrain.Dem)."""
    state, idx, last_k = due_samples(truth, config, rng, state, RadarAltimeterState)
    if idx is None:
        return trusted_frame(RadarAltimeterFrame, t_s=EMPTY_F, range_m=EMPTY_F, valid=EMPTY_B), state
    w = rng.standard_normal(idx.shape[0])
    t = truth.t_s[idx]
    if idx.shape[0] == 0:
        return RadarAltimeterFrame(t_s=t, range_m=np.zeros(0), valid=np.zeros(0, bool)), \
            RadarAltimeterState(last_k)
    C_bn = truth.C_bn[idx]
    lat, lon, h = antenna_positions(truth.lat_rad[idx], truth.lon_rad[idx], truth.h_msl_m[idx], C_bn,
                                    config.lever_arm_b_m)
    ret = queries.radar_altimeter_return(terrain, lat, lon, h, C_bn, np.deg2rad(0.5 * config.beamwidth_deg),
                                         config.max_range_m)
    r, valid = _ra_noise(ret.valid, ret.range_m, w, config.noise_const_m, config.noise_fraction,
                         config.max_range_m)
    return trusted_frame(RadarAltimeterFrame, t_s=t, range_m=r, valid=valid), RadarAltimeterState(last_k)


__all__ = ["RadarAltimeterConfig", "RadarAltimeterState", "sample_radar_altimeter"]
