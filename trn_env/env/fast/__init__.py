"""TerrainNavFast-v0: TerrainNav-v0's route task for N point-mass aircraft per process (a VectorEnv).

Modules: envelope (the King Air's measured point-mass envelope), state (per-aircraft state columns), rng
(per-sub-env random streams), dynamics (one numba call per decision over all aircraft), navigator (INS error,
batch TERCOM, Kalman filter), observation, reset, vector_env (the env), calibration (reference routes against
the full JSBSim loop). User guide: docs/guide/fast_tier.md.
"""
