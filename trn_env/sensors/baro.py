"""Barometric altimeter: ISA pressure altitude from the true static pressure, plus bias, noise and lag.

The altimeter knows only pressure: it converts the true ambient static pressure through the International
Standard Atmosphere (ISO 2533 / ICAO; troposphere 0-11 km with -6.5 K/km, isothermal lower stratosphere
11-20 km, +1 K/km layer 20-32 km; geopotential altitudes). On a non-standard day (temperature or pressure
offset in the scenario's atmosphere) the pressure altitude therefore differs from the true height, as a real
altimeter set to standard pressure does. Errors: a constant bias drawn per run (the thesis appendix quotes
60-80 ft for a barometric altimeter), white noise, and a first-order lag run over every truth step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.core.settings import setting
from trn_env.navigators.frames import BaroFrame
from trn_env.sensors.common import (
    MappingConfig,
    sample_steps,
    trusted_frame,
)

ISA_P0_PA = 101325.0
ISA_T0_K = 288.15
ISA_G0_MPS2 = 9.80665
ISA_R_JPKGK = 287.05287          # specific gas constant of dry air
# Layer bases: geopotential altitude (m), temperature (K), lapse rate (K/m), pressure (Pa)
_H_BASE = np.array([0.0, 11000.0, 20000.0])
_LAPSE = np.array([-0.0065, 0.0, 0.001])
_T_BASE = np.array([ISA_T0_K, 216.65, 216.65])


def _layer_pressures() -> np.ndarray:
    p = [ISA_P0_PA]
    for i in range(2):
        dh = _H_BASE[i + 1] - _H_BASE[i]
        if _LAPSE[i] == 0.0:
            p.append(p[-1] * np.exp(-ISA_G0_MPS2 * dh / (ISA_R_JPKGK * _T_BASE[i])))
        else:
            t1 = _T_BASE[i] + _LAPSE[i] * dh
            p.append(p[-1] * (t1 / _T_BASE[i]) ** (-ISA_G0_MPS2 / (ISA_R_JPKGK * _LAPSE[i])))
    return np.array(p)


_P_BASE = _layer_pressures()


def isa_pressure_pa(h_m):
    """ISA static pressure (Pa) at geopotential altitude h_m (valid -0.6 to 32 km); scalars or arrays."""
    h = np.asarray(h_m, float)
    i = np.clip(np.searchsorted(_H_BASE, h, side="right") - 1, 0, 2)
    dh = h - _H_BASE[i]
    lapse, t_b, p_b = _LAPSE[i], _T_BASE[i], _P_BASE[i]
    with np.errstate(divide="ignore", invalid="ignore"):
        exponent = -ISA_G0_MPS2 / (ISA_R_JPKGK * np.where(lapse == 0, 1, lapse))
        grad = p_b * ((t_b + lapse * dh) / t_b) ** exponent
    iso = p_b * np.exp(-ISA_G0_MPS2 * dh / (ISA_R_JPKGK * t_b))
    return np.where(lapse == 0.0, iso, grad)


def isa_pressure_altitude_m(p_pa):
    """ISA pressure altitude (geopotential m) for static pressure p_pa; inverse of isa_pressure_pa."""
    p = np.asarray(p_pa, float)
    # layer index: pressures decrease with altitude
    i = np.where(p > _P_BASE[1], 0, np.where(p > _P_BASE[2], 1, 2))
    lapse, t_b, p_b, h_b = _LAPSE[i], _T_BASE[i], _P_BASE[i], _H_BASE[i]
    with np.errstate(divide="ignore", invalid="ignore"):
        safe_lapse = np.where(lapse == 0, 1.0, lapse)
        grad = h_b + t_b / safe_lapse * ((p / p_b) ** (-ISA_R_JPKGK * safe_lapse / ISA_G0_MPS2) - 1.0)
        iso = h_b - ISA_R_JPKGK * t_b / ISA_G0_MPS2 * np.log(p / p_b)
    return np.where(lapse == 0.0, iso, grad)


@dataclass(frozen=True)
class BaroConfig(MappingConfig):
    """Barometric altimeter. Sigmas are 1 sigma."""

    rate_hz: float = setting(10.0, "samples per second", "Hz", gt=0.0)
    bias_m: float = setting(10.0, "constant bias, drawn N(0, bias^2) per run", "m", ge=0.0)
    noise_m: float = setting(0.5, "white noise per sample", "m", ge=0.0)
    lag_tau_s: float = setting(0.2, "first-order lag time constant (0: none)", "s", ge=0.0)

    # zero in noise_free(): no bias, noise or lag, the ISA pressure altitude of the true static pressure
    ERROR_FIELDS = ("bias_m", "noise_m", "lag_tau_s")



class BaroState(NamedTuple):
    """Carried between chunks: grid index, the run's bias, and the lag's output y at time t."""

    last_k: int | None
    bias_m: float
    lag_y_m: float       # NaN before the first step
    lag_t_s: float

    @classmethod
    def initial(cls, config: BaroConfig, rng: np.random.Generator) -> BaroState:
        return cls(None, float(rng.standard_normal() * config.bias_m), np.nan, np.nan)


_P_BASE_1, _P_BASE_2 = float(_P_BASE[1]), float(_P_BASE[2])


@njit(cache=True)
def _pressure_altitude(p):
    """Scalar ISA pressure altitude (same layers as isa_pressure_altitude_m)."""
    if p > _P_BASE_1:
        return ISA_T0_K / -0.0065 * ((p / ISA_P0_PA) ** (ISA_R_JPKGK * 0.0065 / ISA_G0_MPS2) - 1.0)
    if p > _P_BASE_2:
        return 11000.0 - ISA_R_JPKGK * 216.65 / ISA_G0_MPS2 * np.log(p / _P_BASE_1)
    return 20000.0 + 216.65 / 0.001 * ((p / _P_BASE_2) ** (-ISA_R_JPKGK * 0.001 / ISA_G0_MPS2) - 1.0)


@njit(cache=True)
def _baro_kernel(t_s, p_pa, idx, w, bias_m, noise_m, tau_s, y0, t0):
    """Lag the pressure altitude over every step, sample rows idx. Returns h (m,), valid, y_end, t_end."""
    n = t_s.shape[0]
    m = idx.shape[0]
    h = np.empty(m)
    valid = np.empty(m, dtype=np.bool_)
    y, tp, k = y0, t0, 0
    for i in range(n):
        u = _pressure_altitude(p_pa[i])
        if tau_s <= 0.0 or not np.isfinite(y):
            y = u
        else:
            y = y + (1.0 - np.exp(-(t_s[i] - tp) / tau_s)) * (u - y)
        tp = t_s[i]
        if k < m and idx[k] == i:
            v = y + bias_m + noise_m * w[k]
            valid[k] = np.isfinite(v)
            h[k] = v if valid[k] else np.nan
            k += 1
    return h, valid, y, tp


def sample_baro(truth: TruthChunk, terrain, rng: np.random.Generator, config: BaroConfig,
                state: BaroState | None = None) -> tuple[BaroFrame, BaroState]:
    """Barometric altitude samples over the chunk (terrain unused)."""
    if state is None:
        state = BaroState.initial(config, rng)
    idx, last_k = sample_steps(truth.t_s, config.rate_hz, state.last_k)
    w = rng.standard_normal(idx.shape[0])
    h, valid, y, t = _baro_kernel(truth.t_s, truth.p_static_pa, idx, w, state.bias_m, config.noise_m,
                                  config.lag_tau_s, state.lag_y_m, state.lag_t_s)
    frame = trusted_frame(BaroFrame, t_s=truth.t_s[idx], h_baro_m=h, valid=valid)
    return frame, BaroState(last_k, state.bias_m, y, t)


__all__ = ["BaroConfig", "BaroState", "isa_pressure_altitude_m", "isa_pressure_pa", "sample_baro"]
