"""The day's atmosphere: JSBSim's 1976 standard atmosphere with a temperature offset and a sea-level pressure.

    Flight(ic, atmosphere=Atmosphere(delta_T_K=20.0, p_sl_pa=100500.0))   # ISA+20, QNH 1005 hPa

`Atmosphere.apply(fdm)` writes JSBSim's own settings (FGStandardAtmosphere: `atmosphere/delta-T`, a
temperature bias in degrees Rankine added at every altitude, and `atmosphere/P-sl-psf`, the sea-level
pressure), so the aircraft flies (trims, produces lift and thrust) in that air. `static_p_T` evaluates the
same model in SI for the truth: temperature T(H) = T_ISA(H) + delta_T, pressure by the hydrostatic equation
through that temperature from p_sl at geopotential altitude H = r0 h / (r0 + h) of JSBSim's height above its
sea-level radius. A barometric altimeter converting this pressure through the STANDARD atmosphere then reads
the realistic non-standard-day error (about h delta_T / T_ISA too low on a hot day).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from trn_env.flight.checks import finite

M_PER_FT = 0.3048
PSF_TO_PA = 47.88025898033584
G0_MPS2 = 9.80665
RANKINE_PER_K = 1.8

# JSBSim's standard atmosphere (FGStandardAtmosphere, layers below 20 km) in SI: sea-level temperature,
# R* / M_air as JSBSim defines them, lapse rate of the first layer, the tropopause (geopotential), and the
# radius JSBSim uses for geopotential altitude.
ATM_T0_K = 288.15
ATM_R_JPKGK = 8.31432 / 0.0289645
ATM_LAPSE_KPM = -0.0065
ATM_H11_M = 11000.0
ATM_RE_M = 20855531.5 * M_PER_FT
JSBSIM_P_SL_PA = 2116.228 * PSF_TO_PA      # JSBSim's own default sea-level pressure (101325.54 Pa)
ISA_P_SL_PA = 101325.0
_WGS84_A = 6378137.0
_WGS84_B = 6356752.314245179
_WGS84_E2 = 1.0 - (_WGS84_B / _WGS84_A) ** 2

DELTA_T_LIMIT_K = 60.0
P_SL_RANGE_PA = (85000.0, 110000.0)


@njit(cache=True)
def static_p_T(lat_rad, lon_rad, h_m, delta_T_K, p_sl_pa):  # pragma: no cover - compiled
    """(p_static_pa, T_static_K) of JSBSim's standard atmosphere offset by delta_T_K (every altitude) with
    sea-level pressure p_sl_pa, at a WGS84 geodetic position (h_m: height above the ellipsoid, m). Valid
    below 20 km geopotential."""
    s, c = np.sin(lat_rad), np.cos(lat_rad)
    n = _WGS84_A / np.sqrt(1.0 - _WGS84_E2 * s * s)
    rxy = (n + h_m) * c
    z = (n * (1.0 - _WGS84_E2) + h_m) * s
    radius = np.sqrt(rxy * rxy + z * z)
    s_gc = z / radius                                   # sine of the geocentric latitude
    sea_level_radius = _WGS84_A / np.sqrt(1.0 + _WGS84_E2 * s_gc * s_gc / (1.0 - _WGS84_E2))
    h_sl = radius - sea_level_radius                    # JSBSim's altitude ASL (position/h-sl-ft)
    hgp = ATM_RE_M * h_sl / (ATM_RE_M + h_sl)
    t0 = ATM_T0_K + delta_T_K
    expo = -G0_MPS2 / (ATM_R_JPKGK * ATM_LAPSE_KPM)
    if hgp < ATM_H11_M:
        t = t0 + ATM_LAPSE_KPM * hgp
        p = p_sl_pa * (t / t0) ** expo
    else:
        t = t0 + ATM_LAPSE_KPM * ATM_H11_M
        p = p_sl_pa * (t / t0) ** expo * np.exp(-G0_MPS2 * (hgp - ATM_H11_M) / (ATM_R_JPKGK * t))
    return p, t


@dataclass(frozen=True)
class Atmosphere:
    """The day's atmosphere. delta_T_K: temperature offset from ISA at every altitude (K, within +-60);
    p_sl_pa: pressure at sea level (Pa, 85-110 kPa). Atmosphere() is the standard day."""

    delta_T_K: float = 0.0
    p_sl_pa: float = ISA_P_SL_PA

    def __post_init__(self):
        dt = finite("Atmosphere.delta_T_K", self.delta_T_K)
        p = finite("Atmosphere.p_sl_pa", self.p_sl_pa)
        if abs(dt) > DELTA_T_LIMIT_K:
            raise ValueError(f"Atmosphere.delta_T_K must be within +-{DELTA_T_LIMIT_K:.0f} K, got {dt}")
        if not P_SL_RANGE_PA[0] <= p <= P_SL_RANGE_PA[1]:
            lo, hi = P_SL_RANGE_PA
            raise ValueError(f"Atmosphere.p_sl_pa must be within {lo:.0f}..{hi:.0f} Pa, got {p}")
        object.__setattr__(self, "delta_T_K", dt)
        object.__setattr__(self, "p_sl_pa", p)

    @classmethod
    def standard(cls) -> Atmosphere:
        return cls()

    @classmethod
    def from_mapping(cls, mapping: dict[str, Any] | None) -> Atmosphere:
        """From a scenario's [atmosphere] table (keys delta_T_K, p_sl_pa; absent = standard)."""
        m = dict(mapping or {})
        unknown = sorted(set(m) - {"delta_T_K", "p_sl_pa"})
        if unknown:
            raise ValueError(f"atmosphere.{unknown[0]}: unknown key (allowed: delta_T_K, p_sl_pa)")
        return cls(**m)

    def apply(self, fdm) -> None:
        """Write this atmosphere to JSBSim (temperature bias in Rankine, sea-level pressure in psf)."""
        fdm["atmosphere/delta-T"] = self.delta_T_K * RANKINE_PER_K
        fdm["atmosphere/P-sl-psf"] = self.p_sl_pa / PSF_TO_PA

    def pressure_temperature(self, lat_rad: float, lon_rad: float, h_m: float) -> tuple[float, float]:
        """(static pressure Pa, temperature K) at a geodetic position (h_m above the WGS84 ellipsoid)."""
        p, t = static_p_T(float(lat_rad), float(lon_rad), float(h_m), self.delta_T_K, self.p_sl_pa)
        return float(p), float(t)


__all__ = ["Atmosphere", "static_p_T"]
