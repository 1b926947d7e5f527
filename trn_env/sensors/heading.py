"""Compensated magnetic compass, reported as true heading (rad, clockwise from north, (-pi, pi]).

The compass error after compensation and declination correction is the classical deviation series
delta(psi) = A + B sin(psi) + C cos(psi) + D sin(2 psi) + E cos(2 psi) (coefficients drawn once per run:
A with `bias_deg`, B-E with `deviation_deg`) plus white noise. Defaults (0.3, 0.2, 0.2 deg; 1 sigma, about
0.5 deg in all) put it in the thesis appendix's "compensated magnetic compass < 0.7 deg" class.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.core.settings import setting
from trn_env.navigators.frames import HeadingFrame
from trn_env.sensors.common import (
    EMPTY_B,
    EMPTY_F,
    MappingConfig,
    due_samples,
    trusted_frame,
)


@dataclass(frozen=True)
class HeadingConfig(MappingConfig):
    """Compass model, degrees, 1 sigma."""

    rate_hz: float = setting(10.0, "samples per second", "Hz", gt=0.0)
    bias_deg: float = setting(0.3, "constant deviation A", "deg", ge=0.0)
    deviation_deg: float = setting(0.2, "heading-dependent deviation coefficients B, C, D, E", "deg", ge=0.0)
    noise_deg: float = setting(0.2, "white noise per sample", "deg", ge=0.0)

    ERROR_FIELDS = ("bias_deg", "deviation_deg", "noise_deg")   # zero in noise_free()



class HeadingState(NamedTuple):
    last_k: int | None
    coefficients_rad: np.ndarray   # (5,) A, B, C, D, E drawn once per run
    noise_rad: float

    @classmethod
    def initial(cls, config: HeadingConfig, rng: np.random.Generator) -> HeadingState:
        sig = np.deg2rad([config.bias_deg] + [config.deviation_deg] * 4)
        return cls(None, rng.standard_normal(5) * sig, float(np.deg2rad(config.noise_deg)))


def deviation_rad(psi_rad, coefficients_rad: np.ndarray):
    """Residual compass deviation A + B sin psi + C cos psi + D sin 2psi + E cos 2psi (rad)."""
    a, b, c, d, e = coefficients_rad
    return a + b * np.sin(psi_rad) + c * np.cos(psi_rad) + d * np.sin(2 * psi_rad) + e * np.cos(2 * psi_rad)


@njit(cache=True)
def _heading_kernel(idx, yaw, w, coef, noise_rad):
    m = idx.shape[0]
    out = np.empty(m)
    valid = np.empty(m, dtype=np.bool_)
    for i in range(m):
        psi = yaw[idx[i]]
        v = (psi + coef[0] + coef[1] * np.sin(psi) + coef[2] * np.cos(psi) + coef[3] * np.sin(2 * psi)
             + coef[4] * np.cos(2 * psi) + noise_rad * w[i])
        v = np.mod(v + np.pi, 2.0 * np.pi) - np.pi
        if v == -np.pi:
            v = np.pi
        valid[i] = np.isfinite(v)
        out[i] = v if valid[i] else np.nan
    return out, valid


def sample_heading(truth: TruthChunk, terrain, rng: np.random.Generator, config: HeadingConfig,
                   state: HeadingState | None = None) -> tuple[HeadingFrame, HeadingState]:
    """Heading samples over the chunk (terrain unused)."""
    state, idx, last_k = due_samples(truth, config, rng, state, HeadingState)
    if idx is None:
        return trusted_frame(HeadingFrame, t_s=EMPTY_F, heading_rad=EMPTY_F, valid=EMPTY_B), state
    w = rng.standard_normal(idx.shape[0])
    out, valid = _heading_kernel(idx, truth.yaw_rad, w, state.coefficients_rad, state.noise_rad)
    frame = trusted_frame(HeadingFrame, t_s=truth.t_s[idx], heading_rad=out, valid=valid)
    return frame, HeadingState(last_k, state.coefficients_rad, state.noise_rad)


__all__ = ["HeadingConfig", "HeadingState", "deviation_rad", "sample_heading"]
