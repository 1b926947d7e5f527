"""TerrainNav-v0's scenario from its constructor arguments, and the goal geometry its steps use.

- `with_fields`: the scenario with `scenario_fields` set (dotted paths, `Scenario.with_fields`), e.g. the
  route task's opt-in decision rates (trn_env.env.route_task.DECISION_RATES);
- `with_rates`: the guidance rate and JSBSim's step (`guidance_rate_hz`, `flight_dt_s`), the IMU lowered to
  the step rate;
- `goal_offset_ne`: north / east of the goal in the local level frame, exact through ECEF (a compiled kernel:
  the env asks for it at every navigator update);
- `_check_number`, `check_point`, `check_region`: the argument checks shared with TerrainNavFast-v0.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from trn_env.flight.core import AutopilotTargets
from trn_env.scenario.loading import Scenario
from trn_env.terrain.geodesy import lla_to_ecef

# AutopilotTargets' defaults that the track / height-above-ground targets leave as they are
BANK_LIMIT_RAD = AutopilotTargets().bank_limit_rad
ALTITUDE_CMD_M = AutopilotTargets().altitude_cmd_m


@njit(cache=True)
def goal_offset_ne(lat_rad: float, lon_rad: float, h_m: float, goal_lat_rad: float,
                   goal_lon_rad: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """North and east (m) of the goal (at the same height h_m) in the local level frame at (lat, lon, h_m):
    C_en(lat, lon)^T (r_goal - r) with both positions in ECEF (terrain.geodesy)."""
    x0, y0, z0 = lla_to_ecef(lat_rad, lon_rad, h_m)
    x1, y1, z1 = lla_to_ecef(goal_lat_rad, goal_lon_rad, h_m)
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    so, co = np.sin(lon_rad), np.cos(lon_rad)
    return -sl * co * dx + -sl * so * dy + cl * dz, -so * dx + co * dy + 0.0 * dz


def with_fields(sc: Scenario, scenario_fields: dict | None, navigator: str | None = None) -> Scenario:
    """The scenario with `scenario_fields` (dotted path -> value, `Scenario.with_fields`) set, and the
    navigator replaced first when given (validated once, together); a ValueError naming `scenario_fields`
    and the field for anything the scenario schema rejects."""
    if scenario_fields is None:
        return sc
    if not isinstance(scenario_fields, dict) or not all(isinstance(k, str) for k in scenario_fields):
        raise ValueError(f"scenario_fields must be a dict of dotted field paths to values (e.g. "
                         f"{{'sensors.ira.rate_hz': 10.0}}), got {scenario_fields!r}")
    if not scenario_fields and navigator is None:
        return sc
    try:
        if navigator is None:
            return sc.with_fields(dict(scenario_fields))
        from trn_env.scenario.overrides import load_scenario_with
        return load_scenario_with(sc, list(scenario_fields.items()), navigator=navigator)
    except ValueError as err:
        raise ValueError(f"scenario_fields: {err}") from None


def with_rates(sc: Scenario, guidance_rate_hz: float | None, flight_dt_s: float | None) -> Scenario:
    """The scenario with `[guidance] rate_hz` set to the env's guidance rate (None = the navigator's update
    rate: one command per update, so the pursuit action re-aims from each new estimate and every other
    action holds its command for the whole decision) and, given `flight_dt_s`, JSBSim's step
    `[aircraft] dt_s` replaced, the IMU's rate lowered to the step rate when it was faster (an integrating
    IMU: its samples are the interval means of the truth rows, sensors.imu); re-validated, so that a rate
    the loop cannot fly (a guidance rate not a whole multiple of the navigator's, a step that does not
    divide the guidance tick, another sensor faster than the step) is a ValueError naming the field."""
    rate = float(sc.navigator.rate_hz) if guidance_rate_hz is None else guidance_rate_hz
    if guidance_rate_hz is not None:
        _check_number("guidance_rate_hz", guidance_rate_hz, positive=True)
    if flight_dt_s is not None:
        _check_number("flight_dt_s", flight_dt_s, positive=True)
        if flight_dt_s > 0.05:
            raise ValueError(f"flight_dt_s must be within (0, 0.05] s, got {flight_dt_s!r}")
    same_dt = flight_dt_s is None or float(sc.aircraft.dt_s) == float(flight_dt_s)
    if float(sc.guidance.rate_hz) == float(rate) and same_dt:
        return sc
    fields: dict = {"guidance.rate_hz": float(rate)}
    what = f"guidance_rate_hz = {rate!r}"
    if not same_dt:
        fields["aircraft.dt_s"] = float(flight_dt_s)
        imu = sc.sensors.imu
        if imu is not None and float(imu.rate_hz) * float(flight_dt_s) > 1.0 + 1e-9:
            fields["sensors.imu.rate_hz"] = 1.0 / float(flight_dt_s)
        what += f", flight_dt_s = {flight_dt_s!r}"
    try:
        return sc.with_fields(fields)
    except ValueError as err:
        raise ValueError(f"{what}: {err}") from None


def _check_number(name: str, v, positive: bool) -> None:
    number = isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool)
    if not number or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, got {v!r} ({type(v).__name__})")
    if positive and v <= 0:
        raise ValueError(f"{name} must be > 0, got {v!r}")
    if not positive and v < 0:
        raise ValueError(f"{name} must be >= 0, got {v!r}")


def check_point(name: str, p, dems) -> tuple[float, float]:
    """The argument `name`, a (lat_deg, lon_deg) pair, as two floats (deg); ValueError naming it unless both
    are finite and inside every DEM of dems = (the terrain, the navigator's map)."""
    try:
        lat, lon = (float(x) for x in p)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (lat_deg, lon_deg) pair of numbers, got {p!r}") from None
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise ValueError(f"{name} must be finite, got {p!r}")
    for which, dem in zip(("terrain", "navigator's map"), dems, strict=True):
        if not dem.contains(math.radians(lat), math.radians(lon)):
            la0, la1, lo0, lo1 = (math.degrees(x) for x in dem.bounds)
            raise ValueError(f"{name} {(lat, lon)} is outside the {which} {dem.name!r} (latitude "
                             f"{la0:.4f} to {la1:.4f} deg, longitude {lo0:.4f} to {lo1:.4f} deg)")
    return lat, lon


def check_region(name: str, r, dems) -> tuple[float, float, float, float] | None:
    """The argument `name`, None or (lat_min, lat_max, lon_min, lon_max) deg, as four floats; ValueError
    naming it unless it is ordered and its corners pass check_point."""
    if r is None:
        return None
    try:
        la0, la1, lo0, lo1 = (float(x) for x in r)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be (lat_min, lat_max, lon_min, lon_max) in degrees, "
                         f"got {r!r}") from None
    if not (la0 < la1 and lo0 < lo1):
        raise ValueError(f"{name} needs lat_min < lat_max and lon_min < lon_max, got {r!r}")
    for p in ((la0, lo0), (la0, lo1), (la1, lo0), (la1, lo1)):
        check_point(f"{name} corner", p, dems)
    return la0, la1, lo0, lo1
