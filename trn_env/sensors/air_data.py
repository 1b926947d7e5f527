"""Air data: true airspeed, angle of attack and sideslip with a per-run bias and white noise.

Defaults follow the thesis appendix's airspeed indicator class (+-3 kt = 1.5 m/s): bias 1 m/s and noise
0.5 m/s (1 sigma, together about 1.1 m/s); alpha/beta vanes 0.3 deg bias, 0.2 deg noise (our choice).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.core.settings import setting
from trn_env.navigators.frames import AirDataFrame
from trn_env.sensors.common import (
    EMPTY_B,
    EMPTY_F,
    MappingConfig,
    due_samples,
    trusted_frame,
)


@dataclass(frozen=True)
class AirDataConfig(MappingConfig):
    """Air-data computer; 1 sigma; biases drawn once per run."""

    rate_hz: float = setting(10.0, "samples per second", "Hz", gt=0.0)
    tas_bias_mps: float = setting(1.0, "true-airspeed bias (drawn once per run)", "m/s", ge=0.0)
    tas_noise_mps: float = setting(0.5, "true-airspeed white noise", "m/s", ge=0.0)
    alpha_bias_deg: float = setting(0.3, "angle-of-attack bias", "deg", ge=0.0)
    alpha_noise_deg: float = setting(0.2, "angle-of-attack white noise", "deg", ge=0.0)
    beta_bias_deg: float = setting(0.3, "sideslip bias", "deg", ge=0.0)
    beta_noise_deg: float = setting(0.2, "sideslip white noise", "deg", ge=0.0)

    ERROR_FIELDS = ("tas_bias_mps", "tas_noise_mps", "alpha_bias_deg", "alpha_noise_deg", "beta_bias_deg",
                    "beta_noise_deg")   # zero in noise_free()



class AirDataState(NamedTuple):
    last_k: int | None
    bias: np.ndarray    # (3,) tas (m/s), alpha (rad), beta (rad), drawn once per run
    sigma: np.ndarray   # (3,) white-noise sigmas, same units

    @classmethod
    def initial(cls, config: AirDataConfig, rng: np.random.Generator) -> AirDataState:
        sig_b = np.array([config.tas_bias_mps, np.deg2rad(config.alpha_bias_deg),
                          np.deg2rad(config.beta_bias_deg)])
        sig_w = np.array([config.tas_noise_mps, np.deg2rad(config.alpha_noise_deg),
                          np.deg2rad(config.beta_noise_deg)])
        return cls(None, rng.standard_normal(3) * sig_b, sig_w)


@njit(cache=True)
def _air_kernel(idx, tas, alpha, beta, w, bias, sigma):
    m = idx.shape[0]
    out = np.empty((3, m))
    valid = np.empty(m, dtype=np.bool_)
    for i in range(m):
        j = idx[i]
        out[0, i] = tas[j] + bias[0] + sigma[0] * w[i, 0]
        out[1, i] = alpha[j] + bias[1] + sigma[1] * w[i, 1]
        out[2, i] = beta[j] + bias[2] + sigma[2] * w[i, 2]
        valid[i] = np.isfinite(out[0, i]) and np.isfinite(out[1, i]) and np.isfinite(out[2, i])
        if not valid[i]:
            out[0, i] = out[1, i] = out[2, i] = np.nan
    return out, valid


def sample_air_data(truth: TruthChunk, terrain, rng: np.random.Generator, config: AirDataConfig,
                    state: AirDataState | None = None) -> tuple[AirDataFrame, AirDataState]:
    """Air-data samples over the chunk (terrain unused)."""
    state, idx, last_k = due_samples(truth, config, rng, state, AirDataState)
    if idx is None:
        return trusted_frame(AirDataFrame, t_s=EMPTY_F, tas_mps=EMPTY_F, alpha_rad=EMPTY_F, beta_rad=EMPTY_F,
                             valid=EMPTY_B), state
    w = rng.standard_normal((idx.shape[0], 3))
    out, valid = _air_kernel(idx, truth.tas_mps, truth.alpha_rad, truth.beta_rad, w, state.bias, state.sigma)
    frame = trusted_frame(AirDataFrame, t_s=truth.t_s[idx], tas_mps=out[0], alpha_rad=out[1], beta_rad=out[2],
                          valid=valid)
    return frame, AirDataState(last_k, state.bias, state.sigma)


__all__ = ["AirDataConfig", "AirDataState", "sample_air_data"]
