"""Fly a route in wind (flight core and guidance only)
===================================================

Fly the King Air along a three-waypoint route in wind, guided on the truth, and print a summary.

Run it as::

    python examples/gallery/fly_route.py [--wind-from-deg 270] [--wind-mps 15] [--turbulence light] [--seed 1]

A thin example of the flight core (trn_env.flight), wind and guidance (trn_env.guidance);
the closed loop with sensors and navigators is `trn-env fly`.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from trn_env.terrain.geodesy import ned_offset_to_latlon

from trn_env.flight.core import Flight, InitialCondition
from trn_env.flight.truth import TruthChunk
from trn_env.flight.wind import Turbulence, WindConfig
from trn_env.guidance.route_following import Guidance, Route, Waypoint, position_from_truth


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wind-from-deg", type=float, default=270.0)
    ap.add_argument("--wind-mps", type=float, default=15.0)
    ap.add_argument("--turbulence", default="none", choices=["none", "light", "moderate", "severe"],
                    help="Milspec turbulence severity")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tas-mps", type=float, default=85.0)
    args = ap.parse_args(argv)

    lat0, lon0 = math.radians(33.2), math.radians(-98.2)

    def wp(n_m: float, e_m: float, alt_m: float) -> Waypoint:
        return Waypoint(*ned_offset_to_latlon(lat0, lon0, 0.0, n_m, e_m), alt_m)

    route = Route([wp(0.0, 0.0, 1500.0), wp(15000.0, 4000.0, 1500.0), wp(22000.0, -10000.0, 1800.0)])
    turbulence = Turbulence() if args.turbulence == "none" else Turbulence("milspec", args.turbulence)
    wind = WindConfig(layers=[(0.0, args.wind_from_deg, 0.6 * args.wind_mps),
                              (1500.0, args.wind_from_deg, args.wind_mps)], turbulence=turbulence)
    flight = Flight(InitialCondition(lat0, lon0, 1500.0, args.tas_mps, math.atan2(4000.0, 15000.0)),
                    wind=wind, seed=args.seed)
    guide = Guidance(route, tas_mps=args.tas_mps)

    chunks: list[TruthChunk] = []
    cross_m: list[float] = []
    est = position_from_truth(flight.snapshot())
    t0 = time.perf_counter()
    while not guide.done and flight.t_s < 1200.0:
        flight.set_targets(guide.command(est, flight.t_s))    # 10 Hz guidance on the truth
        chunk = flight.advance(10)
        chunks.append(chunk)
        est = position_from_truth(chunk)
        cross_m.append(guide.leg_state(est).cross_m)
    wall = time.perf_counter() - t0
    truth = TruthChunk.concatenate(chunks)
    xte = np.abs(np.array(cross_m))
    track = np.arctan2(truth.v_ned_mps[:, 1], truth.v_ned_mps[:, 0])
    crab_deg = np.degrees(np.angle(np.exp(1j * (truth.yaw_rad - track))))
    wind_h = np.hypot(truth.wind_ned_mps[:, 0], truth.wind_ned_mps[:, 1])
    bank_deg = np.degrees(np.abs(truth.roll_rad)).max()
    status = "completed" if guide.done else "NOT completed"
    print(f"route {route.length_m() / 1000:.1f} km {status} in {flight.t_s:.0f} s simulated, "
          f"{wall:.2f} s wall ({flight.t_s / wall:.0f}x real time)")
    print(f"cross-track |error|: median {np.median(xte):.1f} m, "
          f"95th percentile {np.percentile(xte, 95):.1f} m")
    print(f"height {truth.h_msl_m.min():.0f}..{truth.h_msl_m.max():.0f} m, "
          f"TAS {truth.tas_mps.mean():.1f} m/s (sd {truth.tas_mps.std():.2f}), max bank {bank_deg:.1f} deg")
    print(f"wind speed {wind_h.mean():.1f} m/s (sd {wind_h.std():.2f}), mean crab {crab_deg.mean():.1f} deg")

if __name__ == "__main__":
    main()
