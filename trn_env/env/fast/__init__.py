"""TerrainNavFast-v0: TerrainNav-v0's route task for N point-mass aircraft per process (a VectorEnv).

Modules: envelope (the King Air's measured point-mass envelope), state (per-aircraft state columns), rng
(per-sub-env random streams), dynamics (one numba call per decision over all aircraft), navigator (INS error,
batch TERCOM, Kalman filter), observation, reset, vector_env (the env), calibration (reference routes against
the full JSBSim loop). User guide: docs/guide/fast_tier.md.
"""

import os

# numba's OpenMP threads wait passively at the end of a parallel call (vector_env's docstring, "Threads"),
# unless the environment says otherwise; set before any kernel starts the OpenMP layer
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
