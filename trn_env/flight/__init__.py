"""Flight stage: the JSBSim flight core and what it flies through.

core           `Flight` (trim, autopilot targets, chunked truth)
initial        `InitialCondition`: where and how the flight starts
autopilot      the autopilot's modes and `AutopilotTargets`
raw_record     the per-step JSBSim record and its numba conversion to SI truth
truth          `TruthChunk`: the true flight in SI units, one array per quantity
wind           altitude wind layers, Milspec/Tustin turbulence, 1-cosine gusts (`WindConfig`)
atmosphere     the non-standard day JSBSim flies in and the barometer feels (`Atmosphere`)
aircraft_data  where the JSBSim aircraft data lives; a bare FGFDMExec loaded with it
"""

from trn_env.flight.atmosphere import Atmosphere
from trn_env.flight.core import (
    AutopilotTargets,
    Flight,
    FlightDiverged,
    InitialCondition,
    LateralMode,
    SpeedMode,
    TrimError,
    VerticalMode,
)
from trn_env.flight.truth import TruthChunk
from trn_env.flight.wind import CosineGust, Turbulence, WindConfig

__all__ = ["Atmosphere", "AutopilotTargets", "CosineGust", "Flight", "FlightDiverged", "InitialCondition",
           "LateralMode", "SpeedMode", "TrimError", "Turbulence", "TruthChunk", "VerticalMode", "WindConfig"]
