"""Env and planner throughput, each beside bare JSBSim measured in the same run.

    python -m trn_env.bench.env [--quick]     # prints one JSON object

- env_sim_seconds_per_wall_second: simulated seconds per wall second of TerrainNav-v0 (default scenario,
  random actions, resets included), beside env_jsbsim_reference_sim_seconds_per_wall_second (a bare
  `fdm.run()` loop of the same aircraft and step, timed right before and after; the faster is kept) and
  their ratio env_ratio;
- subproc_vec_env_steps_per_s: env steps per wall second of a 2-env stable-baselines3 SubprocVecEnv
  (falls back to gymnasium's AsyncVectorEnv when sb3 is not installed: subproc_vec_env_kind says which),
  basin_route scenario, 1 s decisions, INS navigator; subproc_vec_env_sim_seconds_per_wall_second (both envs
  together) beside the same bare-JSBSim reference (one process: the machine has 2 cores);
- env_route_*: TerrainNav-v0 at the route benchmark's settings (trn_env.env.route_task, basin terrain,
  pursuit actions, 30 s decisions, JSBSim at 50 Hz (flight_dt_s 0.02), the task's TASK_RATES: IRA samples
  averaged by 3 into the TERCOM batch, covariance steps at 10 Hz, an estimate every 2 s, guidance at 1 Hz;
  random actions, resets included; each env warmed up for WARM_UP_DECISIONS first):
  env_route_agent_steps_per_s (wall) beside env_route_agent_steps_per_s_before (the same env with the rates
  it had before: guidance at the scenario's 10 Hz, JSBSim at its 100 Hz, the scenario's sensor and navigator
  rates, BEFORE_RATES), measured interleaved, median of the repeats; the same as CPU
  figures (env_route_cpu_*, this process's CPU time: the shared machine's load moves wall figures more);
  env_route_decision_rates_* the same figures with the task's opt-in DECISION_RATES (IRA and covariance
  steps at 10 Hz, an estimate every 2 s, guidance at 1 Hz; `env_kwargs("basin", decision_rates=True)`),
  its speedup over "before" and its ratios to the King Air gym loop;
  env_route_speedup (after / before, CPU; env_route_speedup_wall the wall ratio);
  env_route_pipelined_agent_steps_per_s (`pipeline=True`: sensors and navigator in a second process;
  wall); env_route_sim_seconds_per_wall_second (and per CPU second) beside two bare JSBSim gymnasium loops
  in the shape of gymnasium-jsbsim's HeadingControlTask (JSBSim at its 60 Hz, 0.2 s agent steps: three
  controls written, run() twelve times, its custom properties updated, 17 state properties read, the
  terminal test, a two-component reward, all by property name; `_gym_jsbsim_rates`), each measured right
  before and after (the faster kept): env_gym_jsbsim_reference_* flies the default scenario's King Air,
  wind and turbulence at gymnasium-jsbsim's 60 Hz (the target's reference), env_gym_jsbsim_c172p_*
  gymnasium-jsbsim's own default (the Cessna 172P shipped with JSBSim, calm air),
  env_gym_jsbsim_reference_100hz_* the King Air at the scenario's 100 Hz (the reference of earlier
  sessions); their ratios env_route_ratio_to_gym_jsbsim(_c172p, _100hz) (wall) and
  env_route_cpu_ratio_to_gym_jsbsim(_c172p, _100hz) (CPU); with the `bench` extra installed, the
  gymnasium-jsbsim package itself (its own Cessna 172P HeadingControlTask env, made with `gymnasium.make`,
  GYMNASIUM_JSBSIM_ENV_ID; env_gymnasium_jsbsim_package names its version, None when not installed, and the
  keys below are then absent): env_gymnasium_jsbsim_package_sim_seconds_per_wall_second (and per CPU
  second), env_route_ratio_to_gymnasium_jsbsim_package (wall; _cpu_ the CPU ratio) and
  env_gym_jsbsim_c172p_ratio_to_gymnasium_jsbsim_package (the stand-in loop on the same Cessna against the
  package: above 1, the stand-in is the stricter reference); the ceiling of the env's figure:
  env_route_jsbsim_alone_sim_seconds_per_wall_second (and per CPU second), bare `run()` calls on the task
  env's own JSBSim flight (its King Air at 50 Hz, wind and autopilot; nothing read or written), measured
  right before and after the envs (the faster kept), its ratios env_route_jsbsim_alone_ratio_to_gym_jsbsim
  and env_route_jsbsim_alone_ratio_to_gymnasium_jsbsim_package (the env's ratio if everything but JSBSim
  cost nothing) and env_route_share_of_jsbsim_alone (the env's figure over it); env_construct_first_s (the
  first env of the process: terrain, map, numba caches), env_construct_second_s (the next one) and
  env_reset_s (median reset); load_average_1min (the machine's load during the measurement).
- planner_40km_route_s: one `TerrainInformationPlanner.plan` of a corner-to-corner route on the bundled DEM
  (straight distance planner_route_straight_km >= 40 km; numba compiled beforehand; the climb limit on,
  planner_climb_gradient; the whole plan: search, string pulling, turn thinning), beside the cost-map build
  (planner_cost_map_s, done once per map); the search alone (planner_astar_s, the numba A* kernel) beside
  a same-run reference, scipy's compiled Dijkstra (`scipy.sparse.csgraph.dijkstra`, from the start state to
  every state) over the same (cell, featureless bin) graph with the same costs and climb-excluded edges
  (planner_reference_scipy_dijkstra_s; graph built beforehand, not timed) and their ratio
  planner_astar_ratio_to_scipy_dijkstra.
"""

from __future__ import annotations

import collections
import json
import math
import sys
import time
from functools import partial

import gymnasium as gym
import numpy as np


def _bare_jsbsim_sim_s_per_wall_s(n_steps: int) -> float:
    """Simulated seconds per wall second of a bare run() loop of the default scenario's aircraft."""
    import trn_env.scenario.build as components
    from trn_env.scenario.loading import load_scenario

    sc = load_scenario("default")
    world = components.build_terrain(sc, sc.extras, np.random.default_rng(0))[0]
    fl = components.build_flight(sc, world, np.random.default_rng(0))
    run = fl.fdm.run
    t0 = time.perf_counter()
    for _ in range(n_steps):
        run()
    return n_steps * float(sc.aircraft.dt_s) / (time.perf_counter() - t0)


def env_figures(quick: bool = False, n_steps: int | None = None, decision_interval_s: float = 5.0) -> dict:
    from trn_env.env.terrain_nav import TerrainNavEnv

    env = TerrainNavEnv(
        "default", decision_interval_s=decision_interval_s, max_episode_s=60.0 if quick else 120.0
    )
    env.action_space.seed(0)
    n_steps = n_steps or (12 if quick else 40)
    ref_steps = 5000 if quick else 20000
    ref0 = _bare_jsbsim_sim_s_per_wall_s(ref_steps)
    t0 = time.perf_counter()
    env.reset(seed=0)
    sim_s = 0.0
    for _ in range(n_steps):
        t_before = env._loop.t_s
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        sim_s += env._loop.t_s - t_before
        if term or trunc:
            env.reset()
    wall = time.perf_counter() - t0
    env.close()
    ref = max(ref0, _bare_jsbsim_sim_s_per_wall_s(ref_steps))
    fig = sim_s / wall if wall > 0 else math.nan
    return {
        "env_sim_seconds_per_wall_second": fig,
        "env_jsbsim_reference_sim_seconds_per_wall_second": ref,
        "env_ratio": fig / ref,
        "env_decision_interval_s": env.decision_interval_s,
        "env_steps_measured": n_steps,
        "env_sim_seconds_measured": sim_s,
    }


# gymnasium-jsbsim's HeadingControlTask (jsbgym: environment.JsbSimEnv, tasks.HeadingControlTask): JSBSim at
# JSBSIM_DT_HZ = 60 whatever the aircraft, 5 agent steps per second; per step three controls written, run()
# twelve times, its custom properties updated (track and altitude errors, steps left), 17 state properties
# read (13 base + 4 task), the terminal test's three reads, two reward components, two reward properties
# written. All by property name through FGFDMExec's item access, as its Simulation class does.
GYM_JSBSIM_DT_HZ = 60
_GYM_STATE = ("position/h-sl-ft", "attitude/pitch-rad", "attitude/roll-rad", "velocities/u-fps",
              "velocities/v-fps", "velocities/w-fps", "velocities/p-rad_sec", "velocities/q-rad_sec",
              "velocities/r-rad_sec", "fcs/left-aileron-pos-norm", "fcs/right-aileron-pos-norm",
              "fcs/elevator-pos-norm", "fcs/rudder-pos-norm", "error/altitude-error-ft", "aero/beta-deg",
              "error/track-error-deg", "info/steps_left")
_GYM_ACT = ("fcs/aileron-cmd-norm", "fcs/elevator-cmd-norm", "fcs/rudder-cmd-norm")


def _c172p_fdm(dt_s: float):
    """gymnasium-jsbsim's default aircraft and start: the Cessna 172P shipped with JSBSim, trimmed at 5,000 ft
    and 120 ft/s near Bath (its initial conditions), engine running, calm air."""
    import jsbsim

    fdm = jsbsim.FGFDMExec(None)
    fdm.set_debug_level(0)
    fdm.load_model("c172p")
    fdm.set_dt(dt_s)
    for name, v in {"ic/h-sl-ft": 5000.0, "ic/terrain-elevation-ft": 1e-8, "ic/long-gc-deg": -2.3273,
                    "ic/lat-geod-deg": 51.3781, "ic/u-fps": 120.0, "ic/v-fps": 0.0, "ic/w-fps": 0.0,
                    "ic/p-rad_sec": 0.0, "ic/q-rad_sec": 0.0, "ic/r-rad_sec": 0.0, "ic/roc-fpm": 0.0,
                    "ic/psi-true-deg": 100.0}.items():
        fdm[name] = v
    fdm.run_ic()
    fdm["propulsion/set-running"] = -1
    fdm["fcs/mixture-cmd-norm"] = 0.8
    return fdm


def _asymptotic_reward(error: float, scale: float) -> float:
    """gymnasium-jsbsim's AsymptoticErrorComponent: 1 at zero error, toward 0 as |error| / scale grows."""
    e = abs(error) / scale
    return 1.0 - e / (1.0 + e)


def gym_reference_fdm(aircraft: str = "kingair", dt_s: float | None = None):
    """(FGFDMExec, JSBSim step s) of the gym loop: "kingair" the default scenario's aircraft, wind and
    turbulence; "c172p" gymnasium-jsbsim's own default, the Cessna 172P in calm air. dt_s default
    1 / GYM_JSBSIM_DT_HZ, the rate gymnasium-jsbsim flies every aircraft at."""
    dt = 1.0 / GYM_JSBSIM_DT_HZ if dt_s is None else float(dt_s)
    if aircraft == "c172p":
        return _c172p_fdm(dt), dt
    if aircraft != "kingair":
        raise ValueError(f"aircraft must be 'kingair' or 'c172p', got {aircraft!r}")
    import trn_env.scenario.build as components
    from trn_env.scenario.loading import load_scenario

    sc = load_scenario("default")
    # the IMU no faster than the truth's steps, as the env lowers it (its samples are not flown here)
    imu_hz = min(float(sc.sensors.imu.rate_hz), 1.0 / dt)
    sc = sc.with_fields({"aircraft.dt_s": dt, "sensors.imu.rate_hz": imu_hz})
    world = components.build_terrain(sc, sc.extras, np.random.default_rng(0))[0]
    return components.build_flight(sc, world, np.random.default_rng(0)).fdm, dt


_GymState = collections.namedtuple("_GymState", [p.replace("/", "_").replace("-", "_") for p in _GYM_STATE])


class GymJsbsimReference(gym.Env):
    """A bare JSBSim gymnasium env in the shape of gymnasium-jsbsim's HeadingControlTask (see _GYM_STATE):
    per agent step of agent_step_s, three controls written, run() agent_step_s / dt_s times, the custom
    properties updated, the state read into a namedtuple, the terminal test, a two-component reward,
    two reward properties written; episodes of 60 s (or until the altitude error passes 1,000 ft), reset to
    the initial conditions. `fdm`: a JSBSim FGFDMExec (or anything with its item access, run() and
    reset_to_initial_conditions)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (len(_GYM_STATE),), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (len(_GYM_ACT),), np.float64)

    def __init__(self, fdm, dt_s: float, agent_step_s: float = 0.2):
        self.fdm = fdm
        self.n_run = max(1, int(round(agent_step_s / dt_s)))
        self.agent_step_s = self.n_run * dt_s
        self.episode_steps = int(math.ceil(60.0 / self.agent_step_s))
        self.target_alt_ft = 0.0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        fdm = self.fdm
        fdm.reset_to_initial_conditions(0)
        fdm["fcs/throttle-cmd-norm"] = 0.8
        fdm["info/steps_left"] = self.episode_steps
        fdm["target/track-deg"] = math.degrees(math.atan2(fdm["velocities/v-east-fps"],
                                                          fdm["velocities/v-north-fps"])) % 360.0
        self.target_alt_ft = fdm["position/h-sl-ft"]
        fdm["reward/last_agent_reward"] = fdm["reward/last_assess_reward"] = 1.0
        self._update_custom_properties()
        return np.array(_GymState(*(fdm[p] for p in _GYM_STATE))), {}

    def _update_custom_properties(self) -> None:
        fdm = self.fdm
        track_deg = math.degrees(math.atan2(fdm["velocities/v-east-fps"], fdm["velocities/v-north-fps"]))
        fdm["error/track-error-deg"] = (track_deg - fdm["target/track-deg"] + 180.0) % 360.0 - 180.0
        fdm["error/altitude-error-ft"] = fdm["position/h-sl-ft"] - self.target_alt_ft
        fdm["info/steps_left"] = fdm["info/steps_left"] - 1

    def step(self, action):
        fdm = self.fdm
        for p, a in zip(_GYM_ACT, action, strict=True):
            fdm[p] = float(a)
        for _ in range(self.n_run):
            fdm.run()
        self._update_custom_properties()
        state = _GymState(*(fdm[p] for p in _GYM_STATE))
        done = (fdm["info/steps_left"] <= 0 or fdm["reward/last_assess_reward"] < 0.0
                or abs(fdm["error/altitude-error-ft"]) > 1000.0)
        reward = 0.5 * (_asymptotic_reward(state.error_altitude_error_ft, 150.0)
                        + _asymptotic_reward(state.error_track_error_deg, 8.0))
        fdm["reward/last_agent_reward"] = reward
        fdm["reward/last_assess_reward"] = reward
        return np.array(state), reward, bool(done), False, {"reward": reward}


def _gym_jsbsim_rates(wall_s: float = 2.0, agent_step_s: float = 0.2, aircraft: str = "kingair",
                      dt_s: float | None = None) -> tuple[float, float]:
    """(simulated seconds per wall second, per CPU second) of GymJsbsimReference (gymnasium-jsbsim's
    shape) on gym_reference_fdm(aircraft, dt_s), controls centred (the aircraft flies on from its trim),
    resets included."""
    fdm, dt = gym_reference_fdm(aircraft, dt_s)
    env = GymJsbsimReference(fdm, dt, agent_step_s)
    env.reset(seed=0)
    act = np.zeros(len(_GYM_ACT))
    sim = 0.0
    t0, c0 = time.perf_counter(), time.process_time()
    while time.perf_counter() - t0 < wall_s:
        _, _, term, _, _ = env.step(act)
        sim += env.agent_step_s
        if term:
            env.reset()
    return sim / (time.perf_counter() - t0), sim / max(time.process_time() - c0, 1e-9)


# gymnasium-jsbsim itself (PyPI `gymnasium-jsbsim`, the `bench` extra): its default env as its README makes
# it, the HeadingControlTask on its Cessna 172P without FlightGear
GYMNASIUM_JSBSIM_ENV_ID = "JSBSim-HeadingControlTask-Cessna172P-Shaping.STANDARD-NoFG-v0"


def gymnasium_jsbsim_package_rates(wall_s: float = 2.0) -> tuple[float, float] | None:
    """(simulated seconds per wall second, per CPU second) of the gymnasium-jsbsim package's own env
    (GYMNASIUM_JSBSIM_ENV_ID, made by `gymnasium.make` as its users make it: with gymnasium's checker and
    order wrappers), controls centred, resets included; None when the package is not installed. Its
    JSBSim start-up banner is kept off stdout (the bench prints JSON there)."""
    try:
        import gymnasium_jsbsim  # noqa: F401 - registers its env ids
    except ImportError:
        return None
    from trn_env.scenario.build import quiet_stdout

    with quiet_stdout():                     # resets too: a new simulation would print the banner again
        env = gym.make(GYMNASIUM_JSBSIM_ENV_ID)
        try:
            env.reset(seed=0)
            u = env.unwrapped
            step_s = u.sim_steps_per_agent_step * u.sim.sim_dt
            act = np.zeros(env.action_space.shape, env.action_space.dtype)
            sim = 0.0
            t0, c0 = time.perf_counter(), time.process_time()
            while time.perf_counter() - t0 < wall_s:
                _, _, term, trunc, _ = env.step(act)
                sim += step_s
                if term or trunc:
                    env.reset()
            return sim / (time.perf_counter() - t0), sim / max(time.process_time() - c0, 1e-9)
        finally:
            env.close()


# decisions each env flies before the timed repeats (90 s at 30 s decisions: past the first fix)
WARM_UP_DECISIONS = 3

# the default scenario's JSBSim step (the King Air gym loop's continuity figure, `*_100hz`: the reference of
# the sessions before it was set to gymnasium-jsbsim's 60 Hz)
SCENARIO_DT_S = 0.01

# the env before issue 34's rate changes: guidance at the scenario's 10 Hz, JSBSim at its 100 Hz, the
# scenario's own sensor and navigator rates (no scenario_fields)
BEFORE_RATES = {"guidance_rate_hz": 10.0, "flight_dt_s": 0.01, "scenario_fields": {}}


def route_env_figures(quick: bool = False) -> dict:
    """TerrainNav-v0 at the route benchmark's settings (trn_env.env.route_task: JSBSim at 50 Hz, TASK_RATES)
    and with the rates of before (BEFORE_RATES) interleaved, pipelined, construction and
    reset, beside bare JSBSim gym loops in gymnasium-jsbsim's shape (the King Air at 60 Hz and at the
    scenario's 100 Hz, gymnasium-jsbsim's Cessna 172P at 60 Hz)."""
    from trn_env.env.route_task import env_kwargs
    from trn_env.env.terrain_nav import TerrainNavEnv

    kw = env_kwargs("basin")
    t0 = time.perf_counter()
    after = TerrainNavEnv(**kw)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    before = TerrainNavEnv(**{**kw, **BEFORE_RATES})
    t_second = time.perf_counter() - t0
    piped = TerrainNavEnv(**kw, pipeline=True)
    rated = TerrainNavEnv(**env_kwargs("basin", decision_rates=True))
    envs = {"after": after, "before": before, "pipelined": piped, "decision_rates": rated}
    rng = np.random.default_rng(0)
    n_steps, reps = (4, 2) if quick else (10, 4)
    wall = {k: [] for k in envs}
    cpu = {k: [] for k in envs}
    sims = {k: 0.0 for k in envs}
    walls = {k: 0.0 for k in envs}
    cpus = {k: 0.0 for k in envs}
    resets = []
    for e in envs.values():                  # warm-up, not timed: numba caches and the first flight, past
        e.reset(seed=0)                      # the first TERCOM fix (GNSS lost at 10 s, 40 s batches), whose
        for _ in range(WARM_UP_DECISIONS):   # kernels load from the cache on their first call
            e.step(np.zeros(2, np.float32))
    ref_s = 1.0 if quick else 3.0
    kinds = ({}, {"aircraft": "c172p"}, {"dt_s": SCENARIO_DT_S})
    refs = [_gym_jsbsim_rates(ref_s, **k) for k in kinds]
    package = [gymnasium_jsbsim_package_rates(ref_s)]
    alone = [_jsbsim_alone_rates(after._loop.flight, ref_s)]   # each rep below resets it first
    for rep in range(reps):
        for k, e in envs.items():
            c0, w0 = time.process_time(), time.perf_counter()
            e.reset(seed=100 + rep)
            resets.append(time.perf_counter() - w0)
            sim = 0.0
            for _ in range(n_steps):
                tb = e._loop.t_s
                _, _, term, trunc, _ = e.step(rng.uniform(-1, 1, 2).astype(np.float32))
                sim += e._loop.t_s - tb
                if term or trunc:
                    t1 = time.perf_counter()
                    e.reset()
                    resets.append(time.perf_counter() - t1)
            w, c = time.perf_counter() - w0, time.process_time() - c0
            wall[k].append(n_steps / w)
            cpu[k].append(n_steps / c)
            sims[k] += sim
            walls[k] += w
            cpus[k] += c
    alone.append(_jsbsim_alone_rates(after._loop.flight, ref_s))
    for e in envs.values():
        e.close()
    refs += [_gym_jsbsim_rates(ref_s, **k) for k in kinds]
    package.append(gymnasium_jsbsim_package_rates(ref_s))
    alone_wall, alone_cpu = max(a[0] for a in alone), max(a[1] for a in alone)
    ka_wall, ka_cpu = max(refs[0][0], refs[3][0]), max(refs[0][1], refs[3][1])
    c172_wall, c172_cpu = max(refs[1][0], refs[4][0]), max(refs[1][1], refs[4][1])
    ka100_wall, ka100_cpu = max(refs[2][0], refs[5][0]), max(refs[2][1], refs[5][1])
    med = {k: float(np.median(v)) for k, v in wall.items()}
    med_cpu = {k: float(np.median(v)) for k, v in cpu.items()}
    sim_rate = sims["after"] / walls["after"]
    sim_rate_cpu = sims["after"] / cpus["after"]
    rated_wall = sims["decision_rates"] / walls["decision_rates"]
    rated_cpu = sims["decision_rates"] / cpus["decision_rates"]
    pkg = {}
    if package[0] is not None:
        pkg_wall, pkg_cpu = max(package[0][0], package[1][0]), max(package[0][1], package[1][1])
        pkg = {"env_gymnasium_jsbsim_package_sim_seconds_per_wall_second": pkg_wall,
               "env_gymnasium_jsbsim_package_sim_seconds_per_cpu_second": pkg_cpu,
               "env_route_ratio_to_gymnasium_jsbsim_package": sim_rate / pkg_wall,
               "env_route_cpu_ratio_to_gymnasium_jsbsim_package": sim_rate_cpu / pkg_cpu,
               "env_gym_jsbsim_c172p_ratio_to_gymnasium_jsbsim_package": c172_wall / pkg_wall,
               "env_route_jsbsim_alone_ratio_to_gymnasium_jsbsim_package": alone_wall / pkg_wall}
    return {
        **pkg,
        "env_gymnasium_jsbsim_package": _package_version("gymnasium-jsbsim"),
        "env_route_agent_steps_per_s": med["after"],
        "env_route_agent_steps_per_s_before": med["before"],
        "env_route_pipelined_agent_steps_per_s": med["pipelined"],
        "env_route_cpu_agent_steps_per_s": med_cpu["after"],
        "env_route_cpu_agent_steps_per_s_before": med_cpu["before"],
        "env_route_speedup": med_cpu["after"] / med_cpu["before"],
        "env_route_decision_rates_agent_steps_per_s": med["decision_rates"],
        "env_route_decision_rates_cpu_agent_steps_per_s": med_cpu["decision_rates"],
        "env_route_decision_rates_speedup": med_cpu["decision_rates"] / med_cpu["before"],
        "env_route_decision_rates_speedup_wall": med["decision_rates"] / med["before"],
        "env_route_decision_rates_sim_seconds_per_wall_second": rated_wall,
        "env_route_decision_rates_sim_seconds_per_cpu_second": rated_cpu,
        "env_route_decision_rates_ratio_to_gym_jsbsim": rated_wall / ka_wall,
        "env_route_decision_rates_cpu_ratio_to_gym_jsbsim": rated_cpu / ka_cpu,
        "env_route_speedup_wall": med["after"] / med["before"],
        "env_route_pipelined_speedup_wall": med["pipelined"] / med["before"],
        "env_route_flight_dt_s": after.scenario.aircraft.dt_s,
        "env_route_sim_seconds_per_wall_second": sim_rate,
        "env_route_sim_seconds_per_cpu_second": sim_rate_cpu,
        "env_route_pipelined_sim_seconds_per_wall_second": sims["pipelined"] / walls["pipelined"],
        "env_route_jsbsim_alone_sim_seconds_per_wall_second": alone_wall,
        "env_route_jsbsim_alone_sim_seconds_per_cpu_second": alone_cpu,
        "env_route_jsbsim_alone_ratio_to_gym_jsbsim": alone_wall / ka_wall,
        "env_route_share_of_jsbsim_alone": sim_rate / alone_wall,
        "env_gym_jsbsim_reference_sim_seconds_per_wall_second": ka_wall,
        "env_gym_jsbsim_reference_sim_seconds_per_cpu_second": ka_cpu,
        "env_route_ratio_to_gym_jsbsim": sim_rate / ka_wall,
        "env_route_cpu_ratio_to_gym_jsbsim": sim_rate_cpu / ka_cpu,
        "env_route_pipelined_ratio_to_gym_jsbsim": sims["pipelined"] / walls["pipelined"] / ka_wall,
        "env_gym_jsbsim_reference_100hz_sim_seconds_per_wall_second": ka100_wall,
        "env_gym_jsbsim_reference_100hz_sim_seconds_per_cpu_second": ka100_cpu,
        "env_route_ratio_to_gym_jsbsim_100hz": sim_rate / ka100_wall,
        "env_route_cpu_ratio_to_gym_jsbsim_100hz": sim_rate_cpu / ka100_cpu,
        "env_gym_jsbsim_c172p_sim_seconds_per_wall_second": c172_wall,
        "env_gym_jsbsim_c172p_sim_seconds_per_cpu_second": c172_cpu,
        "env_route_ratio_to_gym_jsbsim_c172p": sim_rate / c172_wall,
        "env_route_cpu_ratio_to_gym_jsbsim_c172p": sim_rate_cpu / c172_cpu,
        "env_construct_first_s": t_first,
        "env_construct_second_s": t_second,
        "env_reset_s": float(np.median(resets)),
        "env_route_steps_measured": n_steps * reps,
        "load_average_1min": _load_average(),
    }


def _jsbsim_alone_rates(flight, wall_s: float) -> tuple[float, float]:
    """(simulated seconds per wall second, per CPU second) of bare `run()` calls on an env's own JSBSim
    flight (its aircraft, step, wind and autopilot; nothing read or written): what the env would reach if
    everything but JSBSim cost nothing. Advances the flight: measure only before a reset."""
    run = flight.fdm.run
    n = 0
    t0, c0 = time.perf_counter(), time.process_time()
    while time.perf_counter() - t0 < wall_s:
        for _ in range(100):
            run()
        n += 100
    sim = n * float(flight.dt_s)
    return sim / (time.perf_counter() - t0), sim / max(time.process_time() - c0, 1e-9)


def _package_version(name: str) -> str | None:
    """The installed version of a distribution, None when it is not installed."""
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _load_average() -> float:
    try:
        import os
        return float(os.getloadavg()[0])
    except (OSError, AttributeError):
        return math.nan


def subproc_figures(quick: bool = False, n_steps: int | None = None) -> dict:
    from trn_env.env.terrain_nav import TerrainNavEnv

    make = partial(
        TerrainNavEnv, scenario="basin_route", decision_interval_s=1.0, max_episode_s=60.0, navigator="ins"
    )
    n_steps = n_steps or (100 if quick else 400)
    try:
        from stable_baselines3.common.vec_env import SubprocVecEnv

        venv = SubprocVecEnv([make, make], start_method="forkserver")
        kind = "stable_baselines3.SubprocVecEnv"

        def reset():
            venv.seed(0)
            return venv.reset()

        def step(a):
            venv.step(a)
    except ImportError:
        import gymnasium as gym

        venv = gym.vector.AsyncVectorEnv([make, make])
        kind = "gymnasium.AsyncVectorEnv"

        def reset():
            return venv.reset(seed=0)

        def step(a):
            venv.step(a)

    try:
        reset()
        rng = np.random.default_rng(0)
        for _ in range(10):  # warm-up: worker imports and numba caches
            step(rng.uniform(-1, 1, (2, 2)).astype(np.float32))
        ref0 = _bare_jsbsim_sim_s_per_wall_s(5000 if quick else 20000)
        t0 = time.perf_counter()
        for _ in range(n_steps):
            step(rng.uniform(-1, 1, (2, 2)).astype(np.float32))
        wall = time.perf_counter() - t0
    finally:
        venv.close()
    ref = max(ref0, _bare_jsbsim_sim_s_per_wall_s(5000 if quick else 20000))
    steps_per_s = 2 * n_steps / wall
    return {
        "subproc_vec_env_steps_per_s": steps_per_s,
        "subproc_vec_env_sim_seconds_per_wall_second": steps_per_s * 1.0,
        "subproc_vec_env_jsbsim_reference_sim_seconds_per_wall_second": ref,
        "subproc_vec_env_ratio": steps_per_s * 1.0 / ref,
        "subproc_vec_env_kind": kind,
        "subproc_vec_env_n_envs": 2,
        "subproc_vec_env_decision_interval_s": 1.0,
    }


def _search_times_s(planner, s, g, repeats: int) -> tuple[float, float]:
    """Best wall times of (the planner's A* kernel alone, scipy's Dijkstra from the start state) over the
    same graph: states (cell, featureless-stretch bin), 16-connected moves, the same edge costs, blocked
    cells and climb-excluded edges; the scipy graph is built with numpy beforehand (not timed)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    from trn_env.guidance.planner import FEATURELESS_EDGE, MOVES, astar_kernel, edge_featureless

    grid, c = planner.grid, planner.config
    u, h, blocked = grid.featureless, planner._height, planner.blocked
    ni, nj = u.shape
    gamma = c.climb_gradient
    bin_m = planner._bin_m
    nb = 1 if c.max_featureless_m is None else int(math.floor(c.max_featureless_m / bin_m)) + 1
    rows, cols, vals = [], [], []
    ii, jj = np.meshgrid(np.arange(ni), np.arange(nj), indexing="ij")
    for di, dj in MOVES:
        i0, j0 = ii.ravel(), jj.ravel()
        i1, j1 = i0 + di, j0 + dj
        ok = (i1 >= 0) & (i1 < ni) & (j1 >= 0) & (j1 < nj)
        i0, j0, i1, j1 = i0[ok], j0[ok], i1[ok], j1[ok]
        ok = ~blocked[i1, j1]
        length = math.hypot(di * grid.cell_n_m, dj * grid.cell_e_m)
        if gamma is not None:
            ok &= (h[i1, j1] - h[i0, j0]) <= gamma * length
        i0, j0, i1, j1 = i0[ok], j0[ok], i1[ok], j1[ok]
        ue = np.array([edge_featureless(u, a, b, int(di), int(dj)) for a, b in zip(i0, j0, strict=True)])
        feat = (ue > FEATURELESS_EDGE) & (nb > 1)
        for b in range(nb):
            b2 = np.where(feat, np.round(b + length / bin_m).astype(np.int64), 0)
            keep = b2 < nb
            rows.append((i0[keep] * nj + j0[keep]) * nb + b)
            cols.append((i1[keep] * nj + j1[keep]) * nb + b2[keep])
            vals.append(length * (1.0 + c.weight * ue[keep]))
    n = ni * nj * nb
    graph = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n, n)).tocsr()
    si, sj = grid.cell_of(*s)
    gi, gj = grid.cell_of(*g)
    args = ((u, h, blocked, grid.cell_n_m, grid.cell_e_m),
            (MOVES, float(c.weight), nb > 1, nb, bin_m, -1.0 if gamma is None else float(gamma)),
            (si, sj), (gi, gj))
    astar_kernel(*args)                 # compiled / cache loaded, not timed
    t_astar = t_ref = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        astar_kernel(*args)
        t_astar = min(t_astar, time.perf_counter() - t0)
        t0 = time.perf_counter()
        dijkstra(graph, indices=(si * nj + sj) * nb)
        t_ref = min(t_ref, time.perf_counter() - t0)
    return t_astar, t_ref


def planner_figures(quick: bool = False) -> dict:
    from trn_env import terrain
    from trn_env.guidance.planner import PlannerConfig, TerrainInformationPlanner

    dem = terrain.load("jacksboro")
    la0, la1, lo0, lo1 = dem.bounds
    s = (la0 + 0.025 * (la1 - la0), lo0 + 0.03 * (lo1 - lo0))
    g = (la0 + 0.97 * (la1 - la0), lo0 + 0.965 * (lo1 - lo0))
    cfg = PlannerConfig(weight=1.0, max_featureless_m=3000.0, edge_margin_cells=1)
    t0 = time.perf_counter()
    planner = TerrainInformationPlanner(dem, cfg)
    t_map = time.perf_counter() - t0
    planner.plan(*s, *g)  # numba compile / cache load, not timed
    times = []
    for _ in range(1 if quick else 5):
        t0 = time.perf_counter()
        r = planner.plan(*s, *g)
        times.append(time.perf_counter() - t0)
    astar_s, ref_s = _search_times_s(planner, s, g, repeats=1 if quick else 3)
    return {
        "planner_40km_route_s": float(np.median(times)),
        "planner_astar_s": astar_s,
        "planner_reference_scipy_dijkstra_s": ref_s,
        "planner_astar_ratio_to_scipy_dijkstra": astar_s / ref_s,
        "planner_climb_gradient": cfg.climb_gradient,
        "planner_cost_map_s": t_map,
        "planner_route_straight_km": r.straight_length_m / 1000.0,
        "planner_route_km": r.length_m / 1000.0,
        "planner_grid_cells": int(np.prod(planner.grid.shape)),
    }


def benchmark(quick: bool = False) -> dict:
    out = {}
    for fn in (env_figures, route_env_figures, subproc_figures, planner_figures):
        out.update(fn(quick))
    return out


if __name__ == "__main__":
    print(json.dumps(benchmark(quick="--quick" in sys.argv[1:]), indent=2))
