"""Flight-core throughput beside its same-run reference (bare JSBSim run() loop, same aircraft and step).

    python -m trn_env.bench_flight            # prints one JSON object

Both loops run in this process, on one trimmed aircraft in level cruise with the autopilot engaged,
alternating in blocks; each figure is its fastest block (see `benchmark`).
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
              block_steps: int = 1000, ic: InitialCondition | None = None) -> dict:
    """Steps per second of the bare JSBSim loop and of Flight.advance (chunks of chunk_steps, recording
    truth), and their ratio (target >= 0.8).

    The two loops alternate in blocks of block_steps (n_steps of each in total) on the same flight, and
    each figure is its fastest block: on a shared machine the minimum is the estimate least disturbed by
    other processes, and alternation exposes both loops to the same conditions.
    """
    if not 1 <= chunk_steps <= block_steps <= n_steps:
        raise ValueError(f"need 1 <= chunk_steps <= block_steps <= n_steps, got {chunk_steps}, "
                         f"{block_steps}, {n_steps}")
    flight = Flight(ic or _default_ic(), aircraft=aircraft, dt_s=dt_s)
    run = flight.fdm.run
    advance = flight.advance
    n_chunks = block_steps // chunk_steps
    block = n_chunks * chunk_steps
    n_blocks = max(1, n_steps // block)
    bare_s, rec_s = [], []
    for _ in range(n_blocks):
        t0 = time.perf_counter()
        for _ in range(block):
            run()
        t1 = time.perf_counter()
        for _ in range(n_chunks):
            advance(chunk_steps)
        t2 = time.perf_counter()
        bare_s.append(t1 - t0)
        rec_s.append(t2 - t1)
    jsbsim_sps = block / min(bare_s)
    flight_sps = block / min(rec_s)
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
