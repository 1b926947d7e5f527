"""Shared helpers for the King Air JSBSim validation tests (SI in, JSBSim units converted here)."""

from __future__ import annotations

import math

import jsbsim
import numpy as np

from trn_env.flight.aircraft_data import new_fdm

FT_PER_M = 1.0 / 0.3048
KT_PER_MPS = 1.0 / 0.514444
LBS_PER_KG = 1.0 / 0.45359237
G0_MPS2 = 9.80665
WING_AREA_M2 = 27.3
MTOW_KG = 4580.0


def isa_density_kgpm3(h_m: float) -> float:
    """ISA troposphere density (kg/m^3) at geopotential height h_m (m), valid below 11 km."""
    T_K = 288.15 - 0.0065 * h_m
    return 1.225 * (T_K / 288.15) ** 4.2559


def start_in_flight(
    h_m: float,
    tas_mps: float,
    psi_rad: float = 0.0,
    *,
    lat_rad: float = math.radians(33.2),
    lon_rad: float = math.radians(-98.2),
    gamma_rad: float = 0.0,
    flaps_norm: float = 0.0,
    trim: bool = True,
    fdm: jsbsim.FGFDMExec | None = None,
) -> jsbsim.FGFDMExec:
    """King Air at altitude h_m (MSL), true airspeed tas_mps, true heading psi_rad, engines running at
    2,200 propeller rpm (advance lever 1), gear up, flaps at flaps_norm (0 up, 1 = 35 deg), flight-path
    angle gamma_rad (0 = level), calm air; trimmed by JSBSim (full trim) when `trim`. Raises
    RuntimeError if the trim fails."""
    if fdm is None:
        fdm = new_fdm("kingair", 0.01)
    fdm["ic/h-sl-ft"] = h_m * FT_PER_M
    fdm["ic/vt-kts"] = tas_mps * KT_PER_MPS
    fdm["ic/gamma-deg"] = math.degrees(gamma_rad)
    fdm["ic/psi-true-deg"] = math.degrees(psi_rad)
    fdm["ic/lat-geod-deg"] = math.degrees(lat_rad)
    fdm["ic/long-gc-deg"] = math.degrees(lon_rad)
    for i in range(2):
        fdm[f"propulsion/engine[{i}]/set-running"] = 1
        fdm[f"fcs/advance-cmd-norm[{i}]"] = 1.0
        fdm[f"fcs/mixture-cmd-norm[{i}]"] = 1.0
    fdm["gear/gear-cmd-norm"] = 0.0
    fdm["gear/gear-pos-norm"] = 0.0
    fdm["fcs/flap-cmd-norm"] = flaps_norm
    fdm["fcs/flap-pos-deg"] = 35.0 * flaps_norm  # 0..1 -> 0..35 deg; set directly, no deployment transient
    fdm.run_ic()
    if trim:
        try:
            fdm["simulation/do_simple_trim"] = 1
        except jsbsim.TrimFailureError as exc:
            raise RuntimeError(f"JSBSim trim failed at h={h_m} m, TAS={tas_mps} m/s") from exc
    return fdm


def set_payload_kg(fdm: jsbsim.FGFDMExec, payload_kg: float) -> None:
    """Set the cabin payload point mass (kg); with full fuel and 170 kg crew, 250 kg gives ~MTOW."""
    fdm["inertia/pointmass-weight-lbs[1]"] = payload_kg * LBS_PER_KG


def mass_kg(fdm: jsbsim.FGFDMExec) -> float:
    return fdm["inertia/weight-lbs"] / LBS_PER_KG


def engage_autopilot(
    fdm: jsbsim.FGFDMExec,
    *,
    lateral_mode: int = 1,
    heading_rad: float | None = None,
    vertical_mode: int = 1,
    altitude_m: float | None = None,
    speed_mode: int = 1,
    tas_mps: float | None = None,
) -> None:
    """Engage the autopilot holding the current heading / altitude / TAS unless targets are given."""
    fdm["ap/lateral-mode"] = lateral_mode
    fdm["ap/heading-cmd-rad"] = fdm["attitude/psi-rad"] if heading_rad is None else heading_rad
    fdm["ap/vertical-mode"] = vertical_mode
    fdm["ap/altitude-cmd-m"] = fdm["position/h-sl-ft"] / FT_PER_M if altitude_m is None else altitude_m
    fdm["ap/speed-mode"] = speed_mode
    fdm["ap/tas-cmd-mps"] = fdm["velocities/vtrue-fps"] * 0.3048 if tas_mps is None else tas_mps
    fdm["ap/engage"] = 1


def fly(fdm: jsbsim.FGFDMExec, n_steps: int, props: list[str]) -> np.ndarray:
    """Run n_steps JSBSim steps, recording `props` after each step -> (n_steps, len(props))."""
    out = np.empty((n_steps, len(props)))
    run = fdm.run
    get = fdm.get_property_value
    for k in range(n_steps):
        run()
        for j, p in enumerate(props):
            out[k, j] = get(p)
    return out
