"""Pulse radar altimeter: range to the closest terrain point inside the beam cone.

A pulse radar altimeter reports the first return, i.e. the shortest range to any terrain inside its beam
(seed 000 section 2, thesis section 5: 17 and 35 deg beams in the flight tests). The cone's axis is the
body down axis, so roll and pitch move the footprint with the body. Noise is altitude dependent,
sigma = noise_const_m + noise_fraction * range (default 0.6 m + 2 %, the thesis's +-(2 ft + 2 %) read as
1 sigma). Beyond `max_range_m`, or with no terrain in the cone, the sample has no return (valid False).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.frames import RadarAltimeterFrame
from trn_env.sensors.common import (
    EMPTY_B,
    EMPTY_F,
    MappingConfig,
    TimeGridState,
    antenna_positions,
    check_nonneg,
    check_positive,
    check_vector3,
    no_sample_due,
    sample_steps,
    trusted_frame,
)
from trn_env.terrain import queries


@dataclass(frozen=True)
class RadarAltimeterConfig(MappingConfig):
    """Radar altimeter; beamwidth is the full cone angle (deg), lever arm in body FRD metres."""

    rate_hz: float = 20.0
    beamwidth_deg: float = 17.0
    max_range_m: float = 5000.0
    noise_const_m: float = 0.6
    noise_fraction: float = 0.02
    lever_arm_b_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        check_positive("RadarAltimeterConfig", "rate_hz", self.rate_hz)
        check_positive("RadarAltimeterConfig", "max_range_m", self.max_range_m)
        check_nonneg("RadarAltimeterConfig", "noise_const_m", self.noise_const_m)
        check_nonneg("RadarAltimeterConfig", "noise_fraction", self.noise_fraction)
        bw = self.beamwidth_deg
        if not (isinstance(bw, (int, float, np.floating)) and 0.0 < bw < 90.0):
            raise ValueError(f"RadarAltimeterConfig.beamwidth_deg must lie in (0, 90) deg, got {bw!r}")
        object.__setattr__(self, "lever_arm_b_m",
                           check_vector3("RadarAltimeterConfig", "lever_arm_b_m", self.lever_arm_b_m))

    @classmethod
    def noise_free(cls, **overrides: Any) -> RadarAltimeterConfig:
        return replace(cls(noise_const_m=0.0, noise_fraction=0.0), **overrides)


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
    if state is None:
        state = RadarAltimeterState.initial(config, rng)
    elif no_sample_due(truth.t_s, config.rate_hz, state.last_k):
        return trusted_frame(RadarAltimeterFrame, t_s=EMPTY_F, range_m=EMPTY_F, valid=EMPTY_B), state
    idx, last_k = sample_steps(truth.t_s, config.rate_hz, state.last_k)
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
