"""Sensor-generation cost beside the flight core's recording cost for the same truth chunks.

    python -m trn_env.sensors.bench          # prints one JSON object

The flight core (trn_env.flight.Flight.advance) records `n_chunks` chunks of `chunk_steps` JSBSim steps
(100 Hz) over the bundled real DEM; then a SensorSuite with every sensor at its default rate (IMU 100 Hz,
IRA 50 Hz, radar altimeter 20 Hz, baro/air data/heading 10 Hz, GNSS 1 Hz) samples the same chunks. Both
are timed in this process, best of `repeats`; `sensor_time_fraction` = sensor time / flight time (target
<= 0.25). The figure is repeated for 10-step chunks (a 10 Hz closed-loop tick), where fixed per-call costs
weigh more. Numba kernels are compiled (or loaded from cache) before timing.
"""

from __future__ import annotations

import json
import math
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


def benchmark(n_chunks: int = 50, chunk_steps: int = 100, repeats: int = 3, dem=None,
              sensors: dict | None = None) -> dict:
    """Figures (seconds per chunk and their ratio) for `chunk_steps`-step chunks and for 10-step chunks."""
    import terrain
    from trn_env.flight import Flight, InitialCondition

    dem = dem if dem is not None else terrain.load("jacksboro")
    sensors = dict(ALL_SENSORS if sensors is None else sensors)
    lat, lon = dem.center_rad
    ground = float(np.nanmax(dem.heights_m))

    def new_flight():
        ic = InitialCondition(lat_rad=lat, lon_rad=lon, h_msl_m=ground + 700.0, tas_mps=100.0,
                              heading_rad=math.radians(30.0))
        return Flight(ic, terrain_elevation_m=float(dem.height(lat, lon)))

    # compile / load every kernel once
    warm = new_flight().advance(20)
    SensorSuite.from_config(sensors, 0).sample(warm, dem)

    out: dict = {}
    for steps, count, suffix in ((chunk_steps, n_chunks, ""), (10, n_chunks * chunk_steps // 10, "_chunk10")):
        flight_s, sensor_s, per = [], [], {}
        for _ in range(repeats):
            f_s, chunks = _record(new_flight(), count, steps)
            flight_s.append(f_s)
            sensor_s.append(_sense(sensors, chunks, dem))
        for name in sensors:
            if sensors[name]:
                per[name] = min(_sense({name: sensors[name]}, chunks, dem) for _ in range(repeats)) / count
        fl, se = min(flight_s) / count, min(sensor_s) / count
        out[f"flight_ms_per_chunk{suffix}"] = round(fl * 1e3, 4)
        out[f"sensor_ms_per_chunk{suffix}"] = round(se * 1e3, 4)
        out[f"sensor_time_fraction{suffix}"] = round(se / fl, 3)
        out[f"sensor_ms_per_chunk_by_sensor{suffix}"] = {k: round(v * 1e3, 4) for k, v in per.items()}
    out["sensor_chunk_steps"] = chunk_steps
    out["sensor_n_chunks"] = n_chunks
    return out


def main() -> None:
    print(json.dumps(benchmark()))


if __name__ == "__main__":
    main()
