"""Flight-core throughput beside its same-run reference (bare JSBSim run() loop, same aircraft and step).

    python -m trn_env.bench_flight            # prints one JSON object

Both loops run in this process on a trimmed aircraft in level cruise with the autopilot engaged; the
bare loop is timed before and after the recording loop and the faster of the two bare timings is used,
so machine load drifting during the run does not flatter the ratio.
"""

from __future__ import annotations

import json
import math
import time

from trn_env.flight import Flight, InitialCondition


def _default_ic() -> InitialCondition:
    return InitialCondition(lat_rad=math.radians(33.2), lon_rad=math.radians(-98.2), h_msl_m=1500.0,
                            tas_mps=85.0, heading_rad=math.radians(45.0))


def benchmark(n_steps: int = 20000, aircraft: str = "kingair", dt_s: float = 0.01, chunk_steps: int = 10,
              repeats: int = 3, ic: InitialCondition | None = None) -> dict:
    """Steps per second of the bare JSBSim loop and of Flight.advance (chunks of chunk_steps, recording
    truth), and their ratio (target >= 0.8). Each figure is the best of `repeats` timings."""
    if n_steps < chunk_steps or chunk_steps < 1:
        raise ValueError(f"need n_steps >= chunk_steps >= 1, got {n_steps}, {chunk_steps}")
    flight = Flight(ic or _default_ic(), aircraft=aircraft, dt_s=dt_s)
    fdm = flight.fdm
    run = fdm.run
    n_chunks = n_steps // chunk_steps
    n_rec = n_chunks * chunk_steps

    def bare() -> float:
        t0 = time.perf_counter()
        for _ in range(n_rec):
            run()
        return time.perf_counter() - t0

    def recorded() -> float:
        t0 = time.perf_counter()
        for _ in range(n_chunks):
            flight.advance(chunk_steps)
        return time.perf_counter() - t0

    bare_s, rec_s = [], []
    for _ in range(repeats):
        bare_s.append(bare())
        rec_s.append(recorded())
    bare_s.append(bare())
    jsbsim_sps = n_rec / min(bare_s)
    flight_sps = n_rec / min(rec_s)
    return {
        "jsbsim_steps_per_s": round(jsbsim_sps, 1),
        "flight_steps_per_s": round(flight_sps, 1),
        "flight_ratio": round(flight_sps / jsbsim_sps, 3),
        "flight_chunk_steps": chunk_steps,
        "flight_dt_s": dt_s,
    }


def main() -> None:
    print(json.dumps(benchmark()))


if __name__ == "__main__":
    main()
