"""Recording: fly a scenario in closed loop and stream its sensor log to disk (`trn-env record`).

The log holds everything a replay needs to reproduce the closed loop's estimates bit for bit: the frames
exactly as the navigator received them (GNSS already gated by the scenario's outages), the initial
estimate, the resolved scenario (its seed fixes the navigator's map errors and random stream), and the
estimates of the flight for comparison; plus the truth at the log rate and the run's events.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from trn_env.logs.format import LogError
from trn_env.logs.writer import LogWriter
from trn_env.navigators.protocol import Estimate
from trn_env.scenario.loading import Scenario
from trn_env.sim.closed_loop import ClosedLoop, RunResult


def estimate_metadata(est: Estimate) -> dict:
    """An estimate as metadata (floats written with repr round-trip exactly)."""
    return {"t_s": float(est.t_s), "lat_rad": float(est.lat_rad), "lon_rad": float(est.lon_rad),
            "h_m": float(est.h_m), "v_ned_mps": [float(x) for x in est.v_ned_mps],
            "roll_rad": float(est.roll_rad), "pitch_rad": float(est.pitch_rad), "yaw_rad": float(est.yaw_rad),
            "covariance": np.asarray(est.covariance, float)[:9, :9].reshape(-1).tolist()}


def sensor_metadata(sc) -> tuple[dict, dict]:
    """({sensor: its resolved config as a mapping}, {sensor: lever arm, body FRD m}) of a scenario (its
    `sensors` section, in the order of its tables)."""
    configs, arms = {}, {}
    for name in sc.sensors.tables:
        cfg = getattr(sc.sensors, name)
        if cfg is None:
            continue
        configs[name] = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)
                         if not f.name.startswith("_")}
        if hasattr(cfg, "lever_arm_b_m"):
            arms[name] = [float(x) for x in cfg.lever_arm_b_m]
    return configs, arms


def recording_metadata(scenario: Scenario, initial: Estimate) -> dict:
    import trn_env
    configs, arms = sensor_metadata(scenario)
    return {
        "source": "trn-env record",
        "trn_env_version": trn_env.__version__,
        "scenario_name": scenario.name,
        "scenario_source": scenario.source,
        "seed": int(scenario.seed),
        "scenario": scenario.to_dict(),
        "navigator": {"name": scenario.navigator_name, "settings": scenario.navigator.table.to_dict()},
        "update_rate_hz": float(scenario.navigator.rate_hz),
        "imu_sample": "rate",
        "height_datum": {"reference": "msl"},
        "lever_arms_m": arms,
        "map": {"from": "scenario", "terrain": scenario.terrain.to_dict(),
                "note": "the scenario's map (terrain.map, with its error model drawn from the seed's map "
                        "stream), as the navigator flew it"},
        "sensors": configs,
        "gnss_outages": [o.to_dict() for o in scenario.gnss.outages],
        "initial_estimate": estimate_metadata(initial),
    }


def record(scenario: Scenario, out: Path | str, *, pipeline: bool = True, progress=None,
           dems=None, chunk_rows: int = 65536) -> tuple[RunResult, Path]:
    """Fly `scenario` closed loop, streaming its log to `out` (committed only when the run ends; removed
    on any exception or Ctrl-C). Returns the run's result and the log's path."""
    out = Path(out)
    writer = None
    loop = None
    try:
        writer = LogWriter(out, {}, chunk_rows=chunk_rows)
        loop = ClosedLoop(scenario, progress=progress, pipeline=pipeline, dems=dems, log_sink=writer)
        writer.metadata = recording_metadata(scenario, loop.estimate)     # (read at the commit, here)
        wall0 = time.perf_counter()
        while loop.termination is None:
            loop.tick()
        result = loop.result(time.perf_counter() - wall0)
        loop.close()
        writer.write_events(result.events)
        path = writer.commit({"termination": result.termination, "recorded_summary": result.summary})
        writer = None
        return result, path
    finally:
        if loop is not None:
            loop.close()
        if writer is not None:
            writer.abort()


__all__ = ["LogError", "record", "recording_metadata"]
