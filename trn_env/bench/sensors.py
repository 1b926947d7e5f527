"""Sensor-generation cost beside the flight core's recording cost for the same truth chunks.

    python -m trn_env.bench.sensors          # prints one JSON object

The default scenario's flight (the King Air ~1,500 m above the refined 30 m Jacksboro world, light
turbulence) is recorded by the flight core (trn_env.flight.Flight.advance) in `n_chunks` chunks of
`chunk_steps` JSBSim steps (100 Hz); then sensor suites sample the same chunks over the same world DEM:

- `sensor_time_fraction`: the default scenario's sensors (IMU 100 Hz, IRA 50 Hz, barometer and air data
  10 Hz, GNSS 1 Hz) - the set the closed loop runs - over the flight-core time (target <= 0.25);
- `sensor_time_fraction_all_sensors`: every sensor model at its default rate (the radar altimeter at 20 Hz
  and the heading sensor added);
- `sensor_ms_per_chunk_by_sensor`: each sensor alone.

Everything is timed in this process, best of `repeats`, single-threaded; numba kernels are compiled (or
loaded from the cache) before timing.
"""

from __future__ import annotations

import json
import time

import numpy as np

from trn_env.sensors.suite import SENSOR_NAMES, SensorSuite

ALL_SENSORS = {name: True for name in SENSOR_NAMES}


def _record(flight, n_chunks: int, chunk_steps: int):
    t0 = time.perf_counter()
    chunks = [flight.advance(chunk_steps) for _ in range(n_chunks)]
    return time.perf_counter() - t0, chunks


def _sense(config, chunks, dem, seed=0) -> float:
    suite = SensorSuite.from_config(config, seed)
    sample = suite.sample
    t0 = time.perf_counter()
    for c in chunks:
        sample(c, dem)
    return time.perf_counter() - t0


def benchmark(n_chunks: int = 30, chunk_steps: int = 100, repeats: int = 3,
              scenario: str = "default") -> dict:
    """Seconds per chunk of the flight core and of the sensor suites, and their ratios."""
    import trn_env.scenario.build as components
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import spawn_rngs

    sc = load_scenario(scenario)
    rngs = spawn_rngs(sc.seed)
    world, _ = components.build_terrain(sc, sc.extras, rngs["map"])
    scenario_sensors = components.sensor_configs(sc)
    warm = components.build_flight(sc, world, np.random.default_rng(0)).advance(20)
    for cfg in (scenario_sensors, ALL_SENSORS):       # compile / load every kernel once
        SensorSuite.from_config(cfg, 0).sample(warm, world)

    flight_s, chunks = [], None
    for _ in range(repeats):
        f_s, chunks = _record(components.build_flight(sc, world, np.random.default_rng(0)), n_chunks,
                              chunk_steps)
        flight_s.append(f_s)
    fl = min(flight_s) / n_chunks

    def per_chunk(cfg) -> float:
        return min(_sense(cfg, chunks, world) for _ in range(repeats)) / n_chunks

    default_s = per_chunk(scenario_sensors)
    all_s = per_chunk(ALL_SENSORS)
    by_sensor = {name: round(per_chunk({name: True}) * 1e3, 4) for name in SENSOR_NAMES}
    return {
        "flight_ms_per_chunk": round(fl * 1e3, 4),
        "sensor_ms_per_chunk": round(default_s * 1e3, 4),
        "sensor_time_fraction": round(default_s / fl, 3),
        "sensor_set": sorted(scenario_sensors),
        "sensor_ms_per_chunk_all_sensors": round(all_s * 1e3, 4),
        "sensor_time_fraction_all_sensors": round(all_s / fl, 3),
        "sensor_ms_per_chunk_by_sensor": by_sensor,
        "sensor_chunk_steps": chunk_steps,
        "sensor_n_chunks": n_chunks,
        "sensor_scenario": scenario,
    }


def main() -> None:
    print(json.dumps(benchmark()))


if __name__ == "__main__":
    main()
