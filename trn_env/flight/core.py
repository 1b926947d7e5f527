"""Flight core: JSBSim flying the aircraft, truth recorded per step in SI units.

    flight = Flight(InitialCondition(lat_rad, lon_rad, h_msl_m, tas_mps, heading_rad), wind=WindConfig(...),
                    seed=7)
    truth = flight.advance(10)                 # TruthChunk, 10 JSBSim steps of dt_s = 0.01 s
    flight.set_targets(AutopilotTargets(...))  # writes the ap/* properties of the aircraft's autopilot
    flight.set_terrain_elevation(h_m)          # terrain under the aircraft, for height-above-ground hold

The per-step Python work in `advance` is `run()` plus copying 16 cached property nodes (19 with turbulence
or gusts: the total wind) into one preallocated float64 buffer with one struct.pack_into call; unit
conversions, Euler/C_bn assembly, the Earth-rate correction of body rates, air data and the atmosphere are
computed after the loop in one numba kernel, which writes three preallocated blocks that the TruthChunk's
fields view (built on first access, TruthChunk.from_blocks).

Frames. JSBSim 1.3's local frame (v-north-fps, phi/theta/psi, wind) is the geodetic NED frame of the WGS84
ellipsoid at the vehicle (checked in tests/test_flight.py against ECEF velocity and the Earth-rate part of the
body rates), so vectors and Euler angles are used as they are. Heights are geodetic (position/geod-alt-ft,
the WGS84 height; position/h-sl-ft is the radial height above the sea-level radius, off by centimetres),
which this project uses as "MSL" (the DEM's datum).

Timing. Row k holds the state after the k-th step, t_s = k * dt_s from the start of the flight. JSBSim 1.3
integrates first and then evaluates every model at the new state, so all fields of a row describe the same
instant: f_b_mps2 is the specific force at that state (what an ideal accelerometer senses), TAS, alpha and
beta follow from the row's velocity, attitude and wind, and p/T are the flight's atmosphere (JSBSim's
standard atmosphere with the day's temperature offset and sea-level pressure, flight.atmosphere) at the
row's altitude. The IMU is at the centre of gravity: f_b = (total non-gravitational force) / mass, FRD.
"""

from __future__ import annotations

import math

import jsbsim
import numpy as np

from trn_env.flight.aircraft_data import KG_PER_LB, fuel_tanks_kg, new_fdm
from trn_env.flight.atmosphere import Atmosphere
from trn_env.flight.autopilot import (
    AP_PROPERTIES,
    AutopilotTargets,
    LateralMode,
    SpeedMode,
    VerticalMode,
)
from trn_env.flight.checks import finite
from trn_env.flight.initial import InitialCondition
from trn_env.flight.raw_record import (
    _N_STATE,
    _NAN_NAMES,
    _RECORDED,
    _S_ROWS,
    _V_ROWS,
    M_PER_FT,
    _convert_raw,
    _record_state,
    _record_state_wind,
    _std_atmosphere,
)
from trn_env.flight.truth import StepClock, TruthChunk
from trn_env.flight.wind import FT_PER_M, WindConfig

PSF_TO_PA = 47.88025898033584
RANKINE_TO_K = 5.0 / 9.0

# re-exported: the flight's public names stay importable from trn_env.flight.core
__all__ = ["AP_PROPERTIES", "AutopilotTargets", "Flight", "FlightDiverged", "InitialCondition", "LateralMode",
           "SpeedMode", "TrimError", "VerticalMode", "_std_atmosphere"]


class TrimError(RuntimeError):
    """JSBSim could not trim the aircraft at the requested initial condition."""


class FlightDiverged(RuntimeError):
    """The simulated state turned NaN (or infinite)."""

    def __init__(self, message: str, quantity: str, t_s: float):
        super().__init__(message)
        self.quantity = quantity
        self.t_s = t_s


class Flight(StepClock):
    """One JSBSim flight: loads the aircraft, applies and trims the initial condition, advances in chunks.

    A flight whose engines stop (fuel exhausted, or cut off) flies on as a glider; ``engine_stop()`` says so.

    Parameters
    ----------
    ic : InitialCondition
        Where and how the flight starts.
    aircraft : str
        Folder name under the aircraft data (``kingair``).
    dt_s : float
        JSBSim's integration step, s.
    wind : WindConfig, optional
        Wind layers, turbulence and gusts (default calm).
    seed : int
        JSBSim's random seed (turbulence): the same seed gives the same truth.
    terrain_elevation_m : float
        Terrain height under the aircraft at the start, m.
    targets : AutopilotTargets, optional
        Autopilot targets engaged after the trim (default: hold the trimmed track, altitude and TAS).
    atmosphere : Atmosphere, optional
        The day's temperature offset and sea-level pressure (default standard), set before the trim.
    constant_fuel : bool
        Keep the tanks' contents (and the mass) fixed for the whole flight (JSBSim's fuel freeze), for
        flights longer than the fuel lasts.

    Raises
    ------
    ValueError
        For an unknown aircraft or a bad argument, naming it; when the start cannot be trimmed.
    """

    def __init__(self, ic: InitialCondition, *, aircraft: str = "kingair", dt_s: float = 0.01,
                 wind: WindConfig | None = None, seed: int = 0, terrain_elevation_m: float = 0.0,
                 targets: AutopilotTargets | None = None, atmosphere: Atmosphere | None = None,
                 constant_fuel: bool = False):
        if not isinstance(ic, InitialCondition):
            raise ValueError(f"ic must be an InitialCondition, got {type(ic).__name__}")
        dt_s = finite("Flight.dt_s", dt_s)
        if not 0.0 < dt_s <= 0.05:
            raise ValueError(f"Flight.dt_s must be within (0, 0.05] s, got {dt_s}")
        terrain_elevation_m = finite("Flight.terrain_elevation_m", terrain_elevation_m)
        if terrain_elevation_m >= ic.h_msl_m:
            raise ValueError(f"InitialCondition.h_msl_m ({ic.h_msl_m} m) is not above the terrain "
                             f"({terrain_elevation_m} m)")
        if wind is None:
            wind = WindConfig()
        if not isinstance(wind, WindConfig):
            raise ValueError(f"wind must be a WindConfig, got {type(wind).__name__}")
        if atmosphere is None:
            atmosphere = Atmosphere()
        if not isinstance(atmosphere, Atmosphere):
            raise ValueError(f"atmosphere must be an Atmosphere, got {type(atmosphere).__name__}")
        if not isinstance(constant_fuel, bool):
            raise ValueError(f"Flight.constant_fuel must be True or False, got {constant_fuel!r}")
        self.ic = ic
        self.aircraft = aircraft
        self.constant_fuel = constant_fuel
        self.dt_s = dt_s
        self.wind = wind
        self.seed = int(seed)
        self.fdm = fdm = new_fdm(aircraft, dt_s)   # ValueError for an unknown aircraft
        pm = fdm.get_property_manager()
        self._node = lambda name: pm.get_node(name, True)
        self._run = fdm.run
        self._all_getters = tuple(self._node(n).get_double_value for n in _RECORDED)
        self._wind_setters = tuple(self._node(f"atmosphere/wind-{a}-fps").set_double_value
                                   for a in ("north", "east", "down"))
        self._terrain_setter = self._node("position/terrain-elevation-asl-ft").set_double_value
        self._ap_setters = tuple(self._node(n).set_double_value for n in AP_PROPERTIES)
        self._ap_written: list[float | None] = [None] * len(AP_PROPERTIES)
        self._terrain_elevation_m = terrain_elevation_m
        self._written_wind: tuple[float, float, float] | None = None
        self._steady_wind_mps = np.zeros(3)
        self._steady_wind_t = (0.0, 0.0, 0.0)
        self._raw = np.empty(0)
        self._row_wind = np.empty((0, 3))     # per pending step: the steady wind written (m/s NED)
        self._row_terrain_m = np.empty(0)     # per pending step: JSBSim's terrain elevation (m)
        self._pending = 0                     # steps recorded since the last take()
        self._steps = 0
        self._gust_index = 0
        self._targets: AutopilotTargets | None = None
        self._last_h_m = ic.h_msl_m
        self._select_recorder()

        fdm["simulation/randomseed"] = float(self.seed % 2**31)
        self.atmosphere = atmosphere
        atmosphere.apply(fdm)
        self._tanks = fuel_tanks_kg(aircraft)
        self._apply_ic(ic, terrain_elevation_m)
        self._trim()
        self._tank_getters = tuple(self._node(f"propulsion/tank[{i}]/contents-lbs").get_double_value
                                   for i in self._tanks)
        n_engines = 0
        while pm.hasNode(f"propulsion/engine[{n_engines}]/set-running"):
            n_engines += 1
        self._running_getters = tuple(self._node(f"propulsion/engine[{i}]/set-running").get_double_value
                                      for i in range(n_engines))
        fdm["propulsion/fuel_freeze"] = 1.0 if constant_fuel else 0.0
        self._add_wind_to_trim()
        wind.apply_turbulence(fdm)
        self._write_steady_wind(ic.h_msl_m)
        if targets is None:
            row = self.snapshot()
            v = row.v_ned_mps[0]
            targets = AutopilotTargets(
                lateral_mode=LateralMode.TRACK, heading_cmd_rad=float(row.yaw_rad[0]),
                track_cmd_rad=math.atan2(v[1], v[0]), vertical_mode=VerticalMode.ALTITUDE_MSL,
                altitude_cmd_m=ic.h_msl_m, agl_cmd_m=max(ic.h_msl_m - terrain_elevation_m, 1.0),
                speed_mode=SpeedMode.TAS, tas_cmd_mps=ic.tas_mps)
        self.set_targets(targets)

    # ----------------------------------------------------------------------------------------- set-up
    def _apply_ic(self, ic: InitialCondition, terrain_elevation_m: float) -> None:
        fdm = self.fdm
        h_ft = ic.h_msl_m * FT_PER_M
        fdm["ic/terrain-elevation-ft"] = terrain_elevation_m * FT_PER_M
        fdm["ic/h-sl-ft"] = h_ft
        fdm["ic/lat-geod-rad"] = ic.lat_rad
        fdm["ic/long-gc-rad"] = ic.lon_rad
        # ic/h-sl-ft is the radial height above the sea-level radius; correct it to the geodetic height.
        for _ in range(3):
            fdm["ic/h-sl-ft"] = fdm["ic/h-sl-ft"] + (h_ft - fdm["ic/geod-alt-ft"])
        fdm["ic/psi-true-rad"] = ic.heading_rad
        fdm["ic/phi-rad"] = 0.0
        # Trim in calm air: the air velocity along the heading (zero sideslip) at the flight-path angle.
        # The wind is added afterwards by _add_wind_to_trim (JSBSim's own trim in wind is unreliable).
        v_h = ic.tas_mps * math.cos(ic.gamma_rad)
        fdm["ic/vn-fps"] = v_h * math.cos(ic.heading_rad) * FT_PER_M
        fdm["ic/ve-fps"] = v_h * math.sin(ic.heading_rad) * FT_PER_M
        fdm["ic/vd-fps"] = -ic.tas_mps * math.sin(ic.gamma_rad) * FT_PER_M
        fdm["fcs/flap-cmd-norm"] = ic.flaps
        fdm["gear/gear-cmd-norm"] = 0.0
        if ic.fuel_fraction is not None or ic.fuel_kg is not None:
            self._set_fuel(ic)
        if not fdm.run_ic():
            raise TrimError(f"JSBSim rejected the initial condition {ic}")
        fdm["gear/gear-pos-norm"] = 0.0
        fdm["propulsion/set-running"] = -1
        self._terrain_setter(terrain_elevation_m * FT_PER_M)

    def _set_fuel(self, ic: InitialCondition) -> None:
        """Fill every fuel tank to the same fraction of its capacity (from the aircraft file)."""
        capacity_kg = sum(self._tanks.values())
        if capacity_kg <= 0.0:
            raise ValueError(f"InitialCondition.fuel_kg/fuel_fraction: {self.aircraft!r} has no fuel tank "
                             "with a capacity in its aircraft file")
        if ic.fuel_kg is not None:
            if ic.fuel_kg > capacity_kg * (1.0 + 1e-9):
                raise ValueError(f"InitialCondition.fuel_kg: {ic.fuel_kg} kg is more than the fuel tanks of "
                                 f"{self.aircraft!r} hold ({capacity_kg:.1f} kg)")
            fraction = ic.fuel_kg / capacity_kg
        else:
            fraction = float(ic.fuel_fraction)
        for i, cap_kg in self._tanks.items():
            self._node(f"propulsion/tank[{i}]/contents-lbs").set_double_value(fraction * cap_kg / KG_PER_LB)

    @property
    def fuel_kg(self) -> float:
        """Fuel on board now (kg, all fuel tanks)."""
        return sum(g() for g in self._tank_getters) * KG_PER_LB

    def engine_stop(self) -> tuple[str, str] | None:
        """(reason, message) if an engine is not running, else None: reason `fuel_exhausted` when a fuel
        tank is empty (JSBSim starves the engine it feeds), `engine_failure` otherwise (e.g. cut off).
        Cheap (a few property reads): the closed loop asks once per update interval."""
        stopped = [i for i, running in enumerate(self._running_getters) if running() < 0.5]
        if not stopped:
            return None
        empty = [i for i, g in zip(self._tanks, self._tank_getters, strict=True) if g() <= 0.0]
        engines = ", ".join(str(i) for i in stopped)
        if empty:
            tanks = ", ".join(str(i) for i in empty)
            return "fuel_exhausted", (f"engine {engines} stopped at t = {self.t_s:.1f} s: fuel tank {tanks} "
                                      f"empty ({self.fuel_kg:.1f} kg left on board)")
        return "engine_failure", (f"engine {engines} stopped at t = {self.t_s:.1f} s with "
                                  f"{self.fuel_kg:.1f} kg of fuel on board")

    def _trim(self) -> None:
        ic, fdm = self.ic, self.fdm
        what = (f"level flight at h = {ic.h_msl_m:.0f} m, TAS = {ic.tas_mps:.1f} m/s, "
                f"flight-path angle = {math.degrees(ic.gamma_rad):.1f} deg, flaps = {ic.flaps:.2f}")
        try:
            fdm["simulation/do_simple_trim"] = 1   # full longitudinal + lateral trim
        except jsbsim.TrimFailureError:
            raise TrimError(f"JSBSim cannot trim {self.aircraft!r} in {what}") from None
        state = np.array([g() for g in self._all_getters])
        if not np.all(np.isfinite(state)):
            raise TrimError(f"JSBSim's trim of {self.aircraft!r} in {what} gave a non-finite state")

    def _add_wind_to_trim(self) -> None:
        """Move the calm-air trim into the steady wind at the initial altitude: same attitude, controls and
        air-relative velocity; ground velocity = air velocity + wind (a trim point of the air mass)."""
        fdm = self.fdm
        w_n, w_e, w_d = self.wind.steady_wind_ned_tuple(self.ic.h_msl_m)
        if w_n == 0.0 and w_e == 0.0 and w_d == 0.0:
            return
        att = [fdm[f"attitude/{a}-rad"] for a in ("phi", "theta", "psi")]
        v_air = [fdm[f"velocities/v-{a}-fps"] for a in ("north", "east", "down")]
        fdm["ic/phi-rad"], fdm["ic/theta-rad"], fdm["ic/psi-true-rad"] = att
        fdm["ic/vw-mag-fps"] = math.hypot(w_n, w_e) * FT_PER_M
        fdm["ic/vw-dir-deg"] = math.degrees(math.atan2(w_e, w_n))   # direction the air moves TOWARDS
        fdm["ic/vn-fps"] = v_air[0] + w_n * FT_PER_M
        fdm["ic/ve-fps"] = v_air[1] + w_e * FT_PER_M
        fdm["ic/vd-fps"] = v_air[2] + w_d * FT_PER_M
        for a in ("p", "q", "r"):
            fdm[f"ic/{a}-rad_sec"] = 0.0
        if not fdm.run_ic():
            raise TrimError(f"JSBSim rejected the wind of the initial condition {self.ic}")
        self._terrain_setter(self._terrain_elevation_m * FT_PER_M)

    # ---------------------------------------------------------------------------------------- control
    @property
    def targets(self) -> AutopilotTargets | None:
        return self._targets

    def set_targets(self, targets: AutopilotTargets) -> None:
        """Write autopilot targets to the ap/* properties (Python sets targets; JSBSim flies)."""
        if not isinstance(targets, AutopilotTargets):
            raise ValueError(f"targets must be AutopilotTargets, got {type(targets).__name__}")
        written = self._ap_written
        for k, value in enumerate(targets.property_values()):
            if value != written[k]:         # only the values that changed (nothing else writes ap/*)
                self._ap_setters[k](value)
                written[k] = value
        self._targets = targets

    def set_terrain_elevation(self, h_m: float) -> None:
        """Terrain height (WGS84 / MSL, m) under the aircraft, read by the autopilot's AGL hold."""
        h_m = finite("Flight.terrain_elevation_m", h_m)
        self._terrain_elevation_m = h_m
        self._terrain_setter(h_m * FT_PER_M)

    @property
    def terrain_elevation_m(self) -> float:
        return self._terrain_elevation_m

    def set_wind(self, wind: WindConfig) -> None:
        """Replace the wind configuration (steady layers take effect at the next advance)."""
        if not isinstance(wind, WindConfig):
            raise ValueError(f"wind must be a WindConfig, got {type(wind).__name__}")
        self._no_pending("set_wind")
        self.wind = wind
        self._written_wind = None
        self._gust_index = 0
        while (self._gust_index < len(wind.gusts)
               and wind.gusts[self._gust_index].start_time_s < self.t_s - 0.5 * self.dt_s):
            self._gust_index += 1
        wind.apply_turbulence(self.fdm)
        self._select_recorder()
        self._write_steady_wind(self._last_h_m)

    def set_atmosphere(self, atmosphere: Atmosphere) -> None:
        """Change the day's atmosphere in flight (JSBSim's air and the truth's p/T from the next step)."""
        if not isinstance(atmosphere, Atmosphere):
            raise ValueError(f"atmosphere must be an Atmosphere, got {type(atmosphere).__name__}")
        self._no_pending("set_atmosphere")
        atmosphere.apply(self.fdm)
        self.atmosphere = atmosphere

    def _no_pending(self, what: str) -> None:
        # the recorded-but-unconverted steps would be converted with the new settings
        if self._pending:
            raise RuntimeError(f"Flight.{what}: take() the {self._pending} recorded steps first")

    def _write_steady_wind(self, h_m: float) -> None:
        w_ned = self.wind.steady_wind_ned_tuple(h_m)
        if w_ned != self._written_wind:
            for setter, value in zip(self._wind_setters, w_ned, strict=True):
                setter(value * FT_PER_M)
            self._written_wind = w_ned
            self._steady_wind_mps = np.array(w_ned)
            self._steady_wind_t = w_ned

    # ---------------------------------------------------------------------------------------- stepping
    def snapshot(self) -> TruthChunk:
        """The current state as a one-row TruthChunk (no step taken)."""
        return self._convert(np.array([g() for g in self._getters]), self._steps)

    def advance(self, n_steps: int) -> TruthChunk:
        """Run n_steps JSBSim steps; return their truth (one row per step, SI). Raises FlightDiverged if
        the state turns NaN. The steady wind is set for the current altitude first; gusts start on time.
        Equivalent to record(n_steps) then take()."""
        self.record(n_steps)
        return self.take()

    def record(self, n_steps: int) -> None:
        """Run n_steps JSBSim steps and keep their raw state, unconverted, for the next take(): the closed
        loop records every guidance tick and converts once per navigator update. Targets and the terrain
        elevation may change between records; each step's truth uses the values it was flown with."""
        if n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {n_steps}")
        if self._wind_varies:
            self._write_steady_wind(self._last_h_m)
        ncol = self._ncol
        p = self._pending
        need = p + n_steps
        if len(self._row_terrain_m) < need:     # grow the reused buffers (kept across takes)
            cap = max(need, 2 * len(self._row_terrain_m), 128)
            raw = np.empty(cap * ncol)
            raw[:p * ncol] = self._raw[:p * ncol]
            wind = np.empty((cap, 3))
            wind[:p] = self._row_wind[:p]
            terr = np.empty(cap)
            terr[:p] = self._row_terrain_m[:p]
            self._raw, self._row_wind, self._row_terrain_m = raw, wind, terr
        buf = self._raw
        if self._gust_index < self._n_gusts:
            self._record_with_gusts(int(n_steps), buf, p)
        else:
            self._recorder(n_steps, self._run, buf, 8 * p * ncol, self._getters)
        self._row_wind[p:need] = self._steady_wind_mps
        self._row_terrain_m[p:need] = self._terrain_elevation_m
        self._pending = need
        self._steps += n_steps
        self._last_h_m = float(buf[(need - 1) * ncol + 2]) * M_PER_FT

    @property
    def pending_steps(self) -> int:
        """Steps recorded since the last take()."""
        return self._pending

    def take(self) -> TruthChunk:
        """Truth of every step recorded since the last take() (one row per step, SI; ValueError if none)."""
        n = self._pending
        if n < 1:
            raise ValueError("Flight.take: no steps recorded since the last take()")
        self._pending = 0
        return self._convert(self._raw, self._steps - n + 1, n, self._row_wind, self._row_terrain_m)

    def _record_with_gusts(self, n_steps: int, buf: np.ndarray, first_row: int) -> None:
        gusts = self.wind.gusts
        done = 0
        while done < n_steps:
            seg = n_steps - done
            if self._gust_index < len(gusts):
                k_start = int(round(gusts[self._gust_index].start_time_s / self.dt_s))
                until = k_start - (self._steps + done)
                if until <= 0:
                    WindConfig.start_gust(self.fdm, gusts[self._gust_index])
                    self._gust_index += 1
                    continue
                seg = min(seg, until)
            self._recorder(seg, self._run, buf, (first_row + done) * 8 * self._ncol, self._getters)
            done += seg

    def _select_recorder(self) -> None:
        self._n_gusts = len(self.wind.gusts)
        self._wind_varies = len(self.wind.layers) > 1
        self._read_wind = self.wind.turbulence.model != "none" or bool(self.wind.gusts)
        self._ncol = len(_RECORDED) if self._read_wind else _N_STATE
        self._getters = self._all_getters[:self._ncol]
        self._recorder = _record_state_wind if self._read_wind else _record_state

    def _convert(self, raw: np.ndarray, first_step: int, n_steps: int | None = None,
                 row_wind: np.ndarray | None = None, row_terrain_m: np.ndarray | None = None) -> TruthChunk:
        """The recorded raw buffer -> TruthChunk: one numba pass into three preallocated blocks (scalar fields
        are rows of one block, vector fields (n, 3) views of another, C_bn its own array); the per-field views
        are built on the chunk's first field access (TruthChunk.from_blocks)."""
        ncol = self._ncol
        n = int(n_steps) if n_steps is not None else len(raw) // ncol
        s = np.empty((_S_ROWS, n))
        vb = np.empty((_V_ROWS, 3, n))
        c_bn = np.empty((n, 3, 3))
        if row_wind is None:
            row_wind = np.empty((n, 3))
            row_wind[:] = self._steady_wind_t
            row_terrain_m = np.full(n, self._terrain_elevation_m)
        atm = self.atmosphere
        bad = _convert_raw(raw, n, ncol, row_wind, row_terrain_m, first_step, self.dt_s,
                           atm.delta_T_K, atm.p_sl_pa, s, vb, c_bn)
        if bad >= 0:
            row, col = divmod(bad, ncol)
            t = (first_step + row) * self.dt_s
            name = _NAN_NAMES[col]
            raise FlightDiverged(f"flight diverged: {name} turned {raw[bad]} at t = {t:.2f} s "
                                 f"(aircraft {self.aircraft!r})", name, t)
        return TruthChunk.from_blocks(s, vb, c_bn)
