"""Every benchmark behind `trn-env bench`, each printing figures beside a same-run reference.

runner      `run_all`: the closed loop and env figures, and each component's benchmark below
flight      the flight core against a bare JSBSim loop
sensors     sensor generation time over flight-core time (`python -m trn_env.bench.sensors`)
navigators  the INS and TERCOM kernels
precompile  `trn-env precompile`: every built-in scenario's, navigator's and env tier's kernels compiled ahead
"""
