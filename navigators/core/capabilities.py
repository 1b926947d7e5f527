"""What a navigator or monitor declares about itself, read by the registry and the simulator.

A component class carries ``capabilities = Capabilities(...)``; a plug-in registered without one gets
`Capabilities()` (no map, no rng, no sensors declared). Nothing is inferred from the component's name:
the simulator gives a map to a component that `needs_map`, the scenario's navigator random stream to one
that `takes_rng`, its IMU's error specification to one that `uses_imu_spec`, and refuses a scenario, log or
env that lacks one of the `required` sensors before anything runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

SENSOR_NAMES = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")


@dataclass(frozen=True)
class SensorNeeds:
    """The sensors a component needs with these settings: `required` {sensor: why}, `optional` the ones it
    uses when fitted."""

    required: dict[str, str] = field(default_factory=dict)
    optional: tuple[str, ...] = ()

    @property
    def used(self) -> tuple[str, ...]:
        """Every sensor the component reads (required first)."""
        return tuple(self.required) + tuple(s for s in self.optional if s not in self.required)


@dataclass(frozen=True)
class Capabilities:
    """A navigator's or monitor's declarations.

    settings: its Settings class (navigators.core.settings), or None for a plug-in that takes free keyword
    arguments. needs_map: it takes the navigator's terrain map as ``dem=``. takes_rng: it draws random
    numbers and takes ``rng=`` (a numpy Generator). uses_imu_spec: it takes its INS error model from the
    scenario IMU's specification (navigators.core.imu_spec.ImuSpec, through its ``apply_imu_spec``).
    imu_bias_settings: the build fills its accel/gyro bias priors and bias process noise settings
    (accel_bias_sigma_mps2, gyro_bias_sigma_rps, q_accel_bias_mps2, q_gyro_bias_rps) from the IMU where the
    settings leave them unset.
    uses_map_noise: it takes the map's error model as measurement noise (map_sigma_m, map_bias_sigma_m).
    models_map_detail: it models the terrain a coarse map cannot hold (terrain_model_sigma_m 0 when the map
    is the world, terrain_detail_spacing_m from the world's refinement). required_sensors: (sensor, why)
    pairs needed whatever the settings; optional_sensors: those it uses when fitted. A Settings class may
    refine both with a ``sensor_needs()`` method (sensors that depend on settings, e.g. the aiding source).
    warm_up_settings: rate_hz -> settings that make a three-update warm-up flight reach every kernel the
    component calls (e.g. a TERCOM fix due at the third update), or None.
    error_time_constant_s, height_time_constant_s: first-order Gauss-Markov time constants (s) of its
    horizontal and vertical position error with GNSS denied (0: not declared); the build gives them to the
    DEM integrity monitor, whose GNSS-denied path correlates the navigator's error across its window with
    them (navigators.integrity.dem_monitor). Fitted to the navigator's error over recorded flights
    (scripts/navigator_error_time_constants.py; docs/validation/integrity.md).
    pl_validated: the conditions "<IMU grade>/<map class>" (grades "navigation", "tactical": the scenario
    IMU's presets; map classes "as_published": a coarser DEM without an error model, "dted1": that DEM with
    the DTED-1 class's error model) on which its protection level's misleading-information rate was measured
    at or below the default integrity risk (1e-3 per epoch, one-sided 95 % Clopper-Pearson bound) on every
    terrain tried (scripts/protection_level_campaign.py; docs/validation/integrity.md section 6.6). Under
    any other condition it publishes Estimate.extra["pl_not_validated"] naming the condition
    (navigators.integrity.protection_level.publish; the build sets the condition).
    pl_settings: the settings, where not the defaults, the campaign measured it with (scripts/
    protection_level_campaign.py's NAVIGATORS; a test ties the two): pl_validated holds for a navigator
    whose settings agree with them, and one set otherwise states which settings differ. pl_variants:
    further (settings, conditions) pairs measured the same way, an opt-in validated on other conditions
    (`pl_declaration`).
    """

    settings: type | None = None
    needs_map: bool = False
    takes_rng: bool = False
    uses_imu_spec: bool = False
    imu_bias_settings: bool = False
    uses_map_noise: bool = False
    models_map_detail: bool = False
    required_sensors: tuple[tuple[str, str], ...] = ()
    optional_sensors: tuple[str, ...] = ()
    warm_up_settings: Callable[[float], dict[str, Any]] | None = None
    error_time_constant_s: float = 0.0
    height_time_constant_s: float = 0.0
    pl_validated: tuple[str, ...] = ()
    pl_settings: tuple[tuple[str, Any], ...] = ()
    pl_variants: tuple[tuple[tuple[tuple[str, Any], ...], tuple[str, ...]], ...] = ()

    def pl_declaration(self, settings: dict[str, Any]) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(validated conditions, settings that differ) for a navigator given `settings` (its user's: a
        scenario's [navigator.settings]; the rest are the defaults): the conditions of the first of
        pl_variants, then of the campaign's own settings (pl_settings, pl_validated), whose settings it
        agrees with on every setting either names, and no difference; else no condition and the settings
        that differ from the campaign's, "name=value (validated with other)" each."""
        defaults = self.settings() if self.settings is not None else None

        def value(d: dict, k: str):
            v = d[k] if k in d else getattr(defaults, k, None)
            return tuple(v) if isinstance(v, list) else v

        def differ(campaign: dict) -> list[str]:
            keys = sorted(set(settings) | set(campaign))
            return [f"{k}={value(settings, k)!r} (validated with {value(campaign, k)!r})"
                    for k in keys if value(settings, k) != value(campaign, k)]

        main = dict(self.pl_settings)
        for extra, conditions in self.pl_variants:
            if not differ(main | dict(extra)):
                return tuple(conditions), ()
        diffs = differ(main)
        return (tuple(self.pl_validated), ()) if not diffs else ((), tuple(diffs))

    def sensor_needs(self, settings: Any = None) -> SensorNeeds:
        """The sensors needed with `settings` (a Settings instance, or None for the defaults)."""
        if settings is None and self.settings is not None:
            settings = self.settings()
        refine = getattr(settings, "sensor_needs", None)
        if callable(refine):
            return refine()
        return SensorNeeds(dict(self.required_sensors), tuple(self.optional_sensors))
