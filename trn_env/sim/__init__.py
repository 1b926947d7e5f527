"""Simulation stage: the multi-rate closed loop flight -> sensors -> navigator -> guidance -> flight.

closed_loop    `ClosedLoop`, `run_scenario`, termination
summary        the run's summary (summary.json)
nav_stage      the estimation stage (inline, or a second process one update behind the flight)
interval_plan  the guidance commands of one update interval
log            `SimLog`, the in-memory log of a run
"""

from trn_env.sim.closed_loop import (
    RNG_STREAMS,
    TERMINATIONS,
    ClosedLoop,
    RunResult,
    run_scenario,
    spawn_rngs,
    spawn_seeds,
    summarise,
)
from trn_env.sim.log import SimLog, error_ned_m

__all__ = ["RNG_STREAMS", "TERMINATIONS", "ClosedLoop", "RunResult", "SimLog", "error_ned_m", "run_scenario",
           "spawn_rngs", "spawn_seeds", "summarise"]
