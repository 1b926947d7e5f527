"""The navigator and monitors of a scenario: the settings each gets (its [navigator.settings] plus what its
declared capabilities ask of the scenario: the map, the IMU's specification and bias model, the map's
error model), their construction, and the problems of a navigator or monitor that lacks a sensor it
needs. Part of trn_env.scenario.build (which re-exports every name here).
"""

from __future__ import annotations

import math

import numpy as np

from trn_env.scenario.maps import _table, map_noise_settings


def imu_spec(imu):
    """The scenario IMU's error specification as the navigators take it (navigators.core.imu_spec.ImuSpec,
    from trn_env.sensors.imu.ImuConfig: its grade and overrides; ImuSpec.grade names the preset it equals,
    "" for a preset with overrides); `imu` is an ImuConfig (the scenario's
    `sensors.imu`) or an [sensors.imu] table; None without an IMU or for a table that does not validate
    (the sensors check reports that)."""
    import dataclasses

    from trn_env.navigators.core.imu_spec import ImuSpec
    from trn_env.sensors.imu import IMU_GRADES, ImuConfig
    if imu is None or imu is False:
        return None
    if isinstance(imu, ImuConfig):
        cfg = imu
    else:
        try:
            cfg = ImuConfig.from_mapping(dict(imu))
        except (ValueError, TypeError):
            return None
    # the preset it is exactly (none for a preset with overrides): the grade each navigator's consistency
    # is known for (navigators.core.measured_consistency)
    grade = next((name for name, preset in IMU_GRADES.items() if cfg == preset), "")
    return dataclasses.replace(ImuSpec.from_object(cfg), grade=grade)


def imu_bias_settings(imu, epoch_s: float = 1.0) -> dict:
    """The bias model a navigator should assume for the scenario's IMU (1 sigma per axis, its grade and
    overrides, imu_spec): accel_bias_sigma_mps2 and gyro_bias_sigma_rps, the root sum square of the turn-on
    bias and the bias instability; q_accel_bias_mps2 and q_gyro_bias_rps, the instability's Gauss-Markov
    drive over one filter epoch of epoch_s seconds, sigma sqrt(1 - exp(-2 epoch_s / tau)) (0 for the
    navigation grade, whose biases are constant over a run). Empty without an IMU or for a table that does
    not validate (the sensors check reports that)."""
    spec = imu_spec(imu)
    if spec is None:
        return {}
    return {"accel_bias_sigma_mps2": spec.accel_bias_sigma_mps2,
            "gyro_bias_sigma_rps": spec.gyro_bias_sigma_rps,
            "q_accel_bias_mps2": spec.accel_bias_drive(epoch_s),
            "q_gyro_bias_rps": spec.gyro_bias_drive(epoch_s)}


def _epoch_s(settings: dict) -> float:
    """A navigator's update interval from its trn_rate_hz setting (1 s if absent or not a positive number:
    the navigator's own check then reports a bad one)."""
    try:
        rate = float(settings.get("trn_rate_hz", 1.0))
    except (TypeError, ValueError):
        return 1.0
    return 1.0 / rate if math.isfinite(rate) and rate > 0 else 1.0


def _settings_fields(settings_class) -> set[str]:
    """Names of a navigator settings dataclass's fields (empty for none or not a dataclass)."""
    import dataclasses
    if settings_class is None or not dataclasses.is_dataclass(settings_class):
        return set()
    return {f.name for f in dataclasses.fields(settings_class)}


def navigator_settings(sc, map_dem) -> dict:
    """The keyword settings registry.create gets for the scenario's navigator: its [navigator.settings] and,
    by its declared capabilities (navigators.core.capabilities), the map as dem= (needs_map, and a plug-in
    that declares no settings class when its factory takes dem or **kwargs), the bias priors and bias
    process noise from the IMU (imu_bias_settings), map_sigma_m / map_bias_sigma_m from the map error model
    (uses_map_noise: map_noise_settings), terrain_model_sigma_m = 0 when the map is the world, else
    terrain_detail_spacing_m from the world's refinement (models_map_detail), gnss_drift_sigma_m (pmf, pf)
    or gnss_pos_bias_sigma_m (rbpf: horizontal, vertical) from the GNSS sensor's drift, baro_lag_s (ins,
    ins_tercom, pmf, pf) from the barometer's lag, and
    map_correlation_length_m / map_correlation_function from the map error model's random part
    (monitor_map_settings; navigators that declare those settings), each unless the settings give it.
    Every navigator gets map_horizontal_sigma_m from the map's accuracy class (its protection level covers
    it)."""
    from trn_env.navigators import registry
    from trn_env.terrain import map_error
    caps = registry.capabilities(sc.navigator.name)
    settings = sc.navigator.table.to_dict()
    if caps.needs_map or (caps.settings is None and registry.takes_argument(sc.navigator.name, "dem")):
        settings.setdefault("dem", map_dem)
    if caps.imu_bias_settings:
        for key, val in imu_bias_settings(sc.sensors.imu, _epoch_s(settings)).items():
            settings.setdefault(key, val)
    error_model = sc.terrain.map.error_model
    preset = str((error_model.preset if error_model is not None else None) or "").strip().lower()
    if preset in map_error.ACCURACY_CLASSES:   # the protection level covers the map's horizontal error
        settings.setdefault("map_horizontal_sigma_m", map_error.ACCURACY_CLASSES[preset].sigma_h_m)
    if caps.uses_map_noise:
        for key, val in map_noise_settings(error_model).items():
            settings.setdefault(key, val)
    fields = _settings_fields(caps.settings)
    if "map_correlation_length_m" in fields:   # the map's random error correlated along the ground
        corr = monitor_map_settings(error_model)
        if corr:
            settings.setdefault("map_correlation_length_m", corr["correlation_length_m"])
            settings.setdefault("map_correlation_function", corr["correlation_function"])
    baro = sc.sensors.baro
    if baro is not None and "baro_lag_s" in fields:       # the lag the terrain heights are corrected for
        settings.setdefault("baro_lag_s", float(baro.lag_tau_s))
    gnss = sc.sensors.gnss
    if gnss is not None and "gnss_drift_sigma_m" in fields:
        settings.setdefault("gnss_drift_sigma_m", float(gnss.horizontal_drift_m))   # the receiver's drift
    if gnss is not None and "gnss_pos_bias_sigma_m" in fields:    # rbpf: the drift as a floor (h, v)
        settings.setdefault("gnss_pos_bias_sigma_m", (float(gnss.horizontal_drift_m),
                                                      float(gnss.vertical_drift_m)))
    if caps.models_map_detail and sc.terrain.map.is_world:
        settings.setdefault("terrain_model_sigma_m", 0.0)     # the map is the world: nothing unresolved
    elif caps.models_map_detail:
        refinement = sc.terrain.world.refinement
        spacing = None if refinement is None else refinement.spacing_m
        # the finest terrain below the map's posts is the world's (where it is finer than the posts)
        if (spacing is not None and 5.0 <= float(spacing) < min(getattr(map_dem, "spacing_m", (0.0,)))
                and "terrain_detail_spacing_m" in fields):
            settings.setdefault("terrain_detail_spacing_m", float(spacing))
    return settings


def build_navigator(sc, map_dem, rng: np.random.Generator | None = None):
    """navigators.registry.create(name, rng=<the scenario's navigator stream>, **navigator_settings(sc,
    map_dem)); the rng reaches only navigators that declare takes_rng. A navigator that declares
    uses_imu_spec and has `apply_imu_spec` then takes its INS error model from the scenario IMU's
    specification (navigators.core.imu_spec)."""
    from trn_env.navigators import registry
    from trn_env.navigators.integrity import protection_level as pl
    name = sc.navigator.name
    navigator = registry.create(name, rng=rng, **navigator_settings(sc, map_dem))
    caps = registry.capabilities(name)
    spec = imu_spec(sc.sensors.imu) if caps.uses_imu_spec else None
    if spec is not None and hasattr(navigator, "apply_imu_spec"):
        navigator.apply_imu_spec(spec)
    validated, differ = caps.pl_declaration(sc.navigator.table.to_dict())
    pl.set_condition(navigator, pl_condition(sc), validated, differ, tuple(caps.pl_validated))
    return navigator


def pl_condition(sc) -> str:
    """The scenario's condition as protection levels were validated on (navigators.core.capabilities,
    pl_validated): "<IMU grade>/<map class>". Grade: the first of the presets "navigation", "tactical" whose
    every error term (trn_env.sensors.imu) the scenario IMU's does not exceed, else "beyond_tactical" (or
    "no_imu"). Map class: "world" (the map is the world), "as_published" (no error model), the accuracy
    class's name for a preset error model without explicit overrides, else "custom_error_model"."""
    from trn_env.sensors.imu import _ERROR_FIELDS, IMU_GRADES, ImuConfig
    imu = sc.sensors.imu
    grade = "no_imu"
    if isinstance(imu, ImuConfig):
        grade = "beyond_tactical"
        for g in ("navigation", "tactical"):
            ref = IMU_GRADES[g]
            if all(float(getattr(imu, f)) <= float(getattr(ref, f)) for f in _ERROR_FIELDS):
                grade = g
                break
    m = sc.terrain.map
    table = _table(m.error_model)
    if m.is_world:
        map_class = "world"
    elif not table:
        map_class = "as_published"
    elif set(table) - {"preset"} == set() and table.get("preset"):
        map_class = str(table["preset"]).strip().lower()
    else:
        map_class = "custom_error_model"
    return f"{grade}/{map_class}"


def _navigator_requirements(sc, the_map) -> list[str]:
    try:
        navigator = build_navigator(sc, the_map)
    except (ValueError, TypeError):
        return []          # the navigator.settings check reports it
    return navigator_sensor_problems(sc, navigator)


def navigator_sensor_problems(sc, navigator) -> list[str]:
    """The sensors the navigator requires that the scenario does not fit, each as 'sensors.<name>: ...'
    (its declared capabilities, navigators.registry.sensor_needs; for a plug-in that declares none, its
    `required_sensors()` if it has one), and a transect longer than the flight (a navigator's
    `required_duration_s()`): refused before the flight. (The scenario loader checks the declared sensors
    before any component is built; this also serves an undeclared plug-in and trn_env.testing.)"""
    from trn_env.navigators import registry
    name = sc.navigator.name
    try:
        need = list(registry.sensor_needs(name, sc.navigator.table.to_dict()).required.items())
    except ValueError:
        need = []
    if not need and callable(getattr(navigator, "required_sensors", None)):
        need = list(navigator.required_sensors())
    fitted = set(sc.sensors.fitted)
    problems = [f"sensors.{sensor}: navigator {name!r} needs this sensor ({why}); add a [sensors.{sensor}] "
                "table" for sensor, why in need if sensor not in fitted]
    dur = getattr(navigator, "required_duration_s", None)
    if dur is not None and dur() > float(sc.duration_s):
        problems.append(f"navigator.settings.transect_samples: one transect takes {dur():g} s of flight, "
                        f"more than the scenario's duration_s = {sc.duration_s:g} s (more samples than the "
                        "route provides)")
    return problems


def unused_sensors(sc) -> list[str]:
    """The fitted sensors that neither the navigator nor any monitor reads (by their declared sensor needs);
    summary.json lists them. Empty when a component's needs cannot be read."""
    from trn_env.navigators import registry
    try:
        used = set(registry.sensor_needs(sc.navigator.name, sc.navigator.table.to_dict()).used)
        for mon in sc.monitors:
            used |= set(registry.monitor_sensor_needs(mon.name, mon.settings.to_dict()).used)
    except ValueError:
        return []
    return sorted(set(sc.sensors.fitted) - used)


def monitor_map_settings(error_model) -> dict:
    """The DEM monitor's map model from the scenario's map error model (terrain.map_error): sigma_m (the
    vertical sigma: random and bias parts together), map_bias_fraction, correlation_length_m and
    correlation_function; empty without a random vertical error (the monitor keeps seed 003's model)."""
    from trn_env.terrain import map_error
    s = _table(error_model)
    noise = map_noise_settings(s)
    sig_r, sig_b = noise["map_sigma_m"], noise["map_bias_sigma_m"]
    if not sig_r > 0.0:
        return {}
    preset = str(s.get("preset", "")).strip().lower()
    cls = map_error.ACCURACY_CLASSES.get(preset)
    length = s.get("correlation_length_m", cls.correlation_length_m if cls else
                   map_error.MapErrorModel().correlation_length_m)
    func = s.get("correlation_function",
                 "exponential" if cls else map_error.MapErrorModel().correlation_function)
    total = math.hypot(sig_r, sig_b)
    return {"sigma_m": total, "map_bias_fraction": (sig_b / total) ** 2,
            "correlation_length_m": float(length), "correlation_function": func}


def monitor_navigator_settings(navigator: str) -> dict:
    """The DEM monitor's model of the navigator's error when the navigator is its height and position source
    (GNSS denied; the monitor uses it only on navigator-sourced epochs): navigator_error_time_constant_s and
    navigator_height_time_constant_s from the navigator's declared error_time_constant_s and
    height_time_constant_s (navigators.core.capabilities), each only where declared (> 0); empty for a
    navigator that declares none (the monitor keeps its error constant over the window)."""
    from trn_env.navigators import registry
    try:
        caps = registry.capabilities(navigator)
    except (KeyError, ValueError):
        return {}
    out = {}
    tau_h = float(getattr(caps, "error_time_constant_s", 0.0))
    tau_v = float(getattr(caps, "height_time_constant_s", 0.0))
    if tau_h > 0.0:
        out["navigator_error_time_constant_s"] = tau_h
    if tau_v > 0.0:
        out["navigator_height_time_constant_s"] = tau_v
    return out


def monitor_settings(sc, name: str) -> dict:
    """A monitor's settings: the scenario's [monitors.<name>] table, with the sensor figures it needs
    filled from the scenario's sensors where not given (dem_integrity: the radar altimeter's noise and
    lever arm, the GNSS vertical sigma, and the navigator's error time constants its GNSS-denied path
    models, from the navigator's declared capabilities where it declares them)."""
    settings = sc.monitor(name).settings.to_dict()
    if name == "dem_integrity":
        for key, val in monitor_navigator_settings(sc.navigator.name).items():
            settings.setdefault(key, val)
        cfg = sc.sensors.radar_altimeter
        if cfg is not None:
            settings.setdefault("radar_altimeter_noise_const_m", float(cfg.noise_const_m))
            settings.setdefault("radar_altimeter_noise_fraction", float(cfg.noise_fraction))
            settings.setdefault("lever_arm_m", float(cfg.lever_arm_b_m[2]))   # FRD z: below the GNSS antenna
            settings.setdefault("beam_half_angle_deg", 0.5 * float(cfg.beamwidth_deg))
            settings.setdefault("max_range_m", float(cfg.max_range_m))
        for key, val in monitor_map_settings(sc.terrain.map.error_model).items():
            settings.setdefault(key, val)
        cfg = sc.sensors.gnss
        if cfg is not None:
            settings.setdefault("gnss_vertical_sigma_m", float(math.hypot(cfg.vertical_noise_m,
                                                                           cfg.vertical_drift_m)))
    return settings


def build_monitors(sc, map_dem) -> dict:
    """{name: monitor} of the scenario's [monitors.*] tables, each on the navigator's map."""
    from trn_env.navigators import registry
    return {name: registry.create_monitor(name, dem=map_dem, **monitor_settings(sc, name))
            for name in sorted(m.name for m in sc.monitors)}


def _monitor_problems(sc, map_dem) -> list[str]:
    from trn_env.navigators import registry
    from trn_env.navigators.core.settings import SettingsError
    problems = []
    for name in sorted(m.name for m in sc.monitors):
        try:
            needs = registry.monitor_sensor_needs(name, sc.monitor(name).settings.to_dict())
            if set(needs.required) - set(sc.sensors.fitted):
                continue                          # reported by the loader's sensor check
            registry.create_monitor(name, dem=map_dem, **monitor_settings(sc, name))
        except SettingsError as exc:
            problems += exc.at(f"monitors.{name}")
        except (ValueError, TypeError) as exc:
            problems.append(f"monitors.{name}: {exc}")
    return problems
