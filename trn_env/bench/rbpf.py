"""RBPF throughput for `trn-env bench`: seed 002's filter (1,000 particles, IRA at 1 Hz) in the default
closed loop, beside the EKF navigator (ins_tercom) and bare JSBSim measured in the same run.

rbpf_sim_s_per_wall_s (target >= 30), ekf_sim_s_per_wall_s and jsbsim_bare_sim_s_per_wall_s are simulated
seconds per wall second of the full loop (pipelined, as `trn-env fly` runs it) and of a bare `run()` loop;
rbpf_ms_per_epoch is one TRN epoch of the filter alone (time update + IRA model over the cloud + Kalman
update + resampling), measured on the same flight; rbpf_peak_mb the filter's peak traced memory
(tracemalloc, in-process run). The filter holds no per-step history: its state is the cloud (N x (3 + 12 +
144) floats) whatever the flight's length.
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

from trn_env.bench.runner import bare_jsbsim_steps_per_s


def _loop_rate(navigator: str, warm_s: float, sim_s: float, pipeline: bool = True) -> tuple[float, object]:
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario("default", navigator=navigator, duration_s=warm_s + sim_s + 10.0)
    with ClosedLoop(sc, pipeline=pipeline) as loop:
        for _ in range(int(round(warm_s / (loop.steps_per_tick * loop.dt_s)))):
            loop.tick()
        loop.sync()
        s0 = loop.jsbsim_steps
        t0 = time.perf_counter()
        while loop.termination is None and (loop.jsbsim_steps - s0) * loop.dt_s < sim_s:
            loop.tick()
        loop.sync()
        wall = time.perf_counter() - t0
        sim = (loop.jsbsim_steps - s0) * loop.dt_s
        import trn_env.scenario.build as components

        ref = components.build_flight(sc, loop.world_dem, np.random.default_rng(0))
        n = int(round(sim / loop.dt_s))
        bare = bare_jsbsim_steps_per_s(ref.fdm, n) * loop.dt_s
        return sim / wall, bare


def _epoch_cost(n_particles: int, n_epochs: int) -> tuple[float, float]:
    """(ms per epoch, peak traced MB) of the filter alone on a kinematic 240 m/s flight over Jacksboro."""
    import math

    from trn_env import terrain
    from trn_env.flight.kinematic import KinematicTruth, Segment
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF, table1_covariance
    from trn_env.navigators.frames import SensorFrames
    from trn_env.navigators.protocol import Estimate
    from trn_env.sensors.imu import ImuConfig, sample_imu
    from trn_env.sensors.ira import IraConfig, sample_ira

    dem = terrain.load("jacksboro")
    kin = KinematicTruth(math.radians(36.47), math.radians(-84.36), 2500.0, 240.0, math.radians(18.1575),
                         [Segment("straight", n_epochs + 5.0)], rate_hz=100.0)
    rng = np.random.default_rng(0)
    chunks = [kin.advance(100) for _ in range(n_epochs + 2)]
    frames = []
    si = sr = None
    for c in chunks:
        imu, si = sample_imu(c, None, rng, ImuConfig(sampling="instant"), si)
        ira, sr = sample_ira(c, dem, rng, IraConfig(), sr)
        frames.append(SensorFrames(float(c.t_s[0]), float(c.t_s[-1]) + 0.01, imu=imu, ira=ira))
    c0 = chunks[0]
    init = Estimate(0.0, c0.lat_rad[0], c0.lon_rad[0], c0.h_msl_m[0], c0.v_ned_mps[0], 0.0, 0.0,
                    c0.yaw_rad[0], table1_covariance())
    # map = world; 1,000 particles from the start (the acquisition's 5,000 last only until the cloud is
    # below 10 m: the closed-loop figure includes them)
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(1), n_particles=n_particles,
                             imu_samples="instant", terrain_model_sigma_m=0.0, acquisition_particles=0)
    nav.reset(init)
    nav.update(frames[0])
    nav.update(frames[1])          # compiled
    half = 2 + (len(frames) - 2) // 2
    e0 = nav.epochs
    t0 = time.perf_counter()
    for f in frames[2:half]:
        nav.update(f)
    wall = time.perf_counter() - t0
    n_timed = nav.epochs - e0
    tracemalloc.start()            # the peak from the second half (tracemalloc slows allocations)
    for f in frames[half:]:
        nav.update(f)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return 1e3 * wall / max(n_timed, 1), peak / 1e6


def benchmark(quick: bool = False) -> dict:
    warm, sim = (3.0, 8.0) if quick else (10.0, 40.0)
    rbpf_rate, bare = _loop_rate("rbpf", warm, sim)
    ekf_rate, bare2 = _loop_rate("ins_tercom", warm, sim)
    ms, peak = _epoch_cost(1000, 6 if quick else 20)
    return {
        "rbpf_sim_s_per_wall_s": rbpf_rate,
        "ekf_sim_s_per_wall_s": ekf_rate,
        "jsbsim_bare_sim_s_per_wall_s": 0.5 * (bare + bare2),
        "rbpf_vs_ekf_ratio": rbpf_rate / ekf_rate,
        "rbpf_particles": 1000,
        "rbpf_ms_per_epoch": ms,
        "rbpf_peak_mb": peak,
    }


if __name__ == "__main__":
    import json

    print(json.dumps(benchmark(), indent=1))
