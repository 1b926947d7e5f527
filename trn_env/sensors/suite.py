"""SensorSuite: every configured sensor, one random stream each, sampling truth chunks into SensorFrames.

Config mapping: sensor name -> a config object, a mapping of its fields (see each config's `from_mapping`;
`{"noise_free": true}` or, for the IMU, `{"grade": "tactical"}` select presets), True for the defaults, or
None/False for absent. Names: imu, baro, radar_altimeter, ira, gnss, air_data, heading.

Randomness: the scenario seed (int or numpy SeedSequence) is spawned into one child per sensor *name*, in the
fixed order above, so each sensor's stream does not depend on which other sensors are configured.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.frames import SensorFrames
from trn_env.sensors.air_data import AirDataConfig, sample_air_data
from trn_env.sensors.baro import BaroConfig, sample_baro
from trn_env.sensors.gnss import GnssConfig, sample_gnss
from trn_env.sensors.heading import HeadingConfig, sample_heading
from trn_env.sensors.imu import ImuConfig, sample_imu
from trn_env.sensors.ira import IraConfig, sample_ira
from trn_env.sensors.radar_altimeter import RadarAltimeterConfig, sample_radar_altimeter


@dataclass(frozen=True)
class SensorModel:
    config_cls: type
    sample: Callable
    needs_terrain: bool


SENSOR_MODELS: dict[str, SensorModel] = {
    "imu": SensorModel(ImuConfig, sample_imu, False),
    "baro": SensorModel(BaroConfig, sample_baro, False),
    "radar_altimeter": SensorModel(RadarAltimeterConfig, sample_radar_altimeter, True),
    "ira": SensorModel(IraConfig, sample_ira, True),
    "gnss": SensorModel(GnssConfig, sample_gnss, False),
    "air_data": SensorModel(AirDataConfig, sample_air_data, False),
    "heading": SensorModel(HeadingConfig, sample_heading, False),
}
SENSOR_NAMES: tuple[str, ...] = tuple(SENSOR_MODELS)


def _make_config(name: str, value: Any):
    model = SENSOR_MODELS[name]
    if value is None or value is False:
        return None
    if value is True:
        return model.config_cls()
    if isinstance(value, model.config_cls):
        return value
    if isinstance(value, dict):
        return model.config_cls.from_mapping(value)
    raise ValueError(f"sensors.{name}: expected a table of settings, true or null; "
                     f"got {type(value).__name__}")


class SensorSuite:
    """The configured sensors and their carried states; `sample` is called once per truth chunk, in order."""

    def __init__(self, configs: dict[str, Any], rngs: dict[str, np.random.Generator]):
        unknown = sorted(set(configs) - set(SENSOR_NAMES))
        if unknown:
            raise ValueError(f"sensors: unknown sensor(s) {', '.join(unknown)}; "
                             f"known: {', '.join(SENSOR_NAMES)}")
        self.configs = {name: _make_config(name, configs.get(name)) for name in SENSOR_NAMES}
        missing = [n for n, c in self.configs.items() if c is not None and n not in rngs]
        if missing:
            raise ValueError(f"sensors: no random generator for {', '.join(missing)}")
        self.rngs = dict(rngs)
        self.states: dict[str, Any] = {name: None for name in SENSOR_NAMES}
        self._t_next_s: float | None = None
        self._dt_s = 0.01
        self._plan = self._make_plan()

    def _make_plan(self) -> tuple:
        """(name, sample function, config, rng, needs terrain) of each configured sensor, in order (the
        configs and generators are fixed at construction)."""
        models = SENSOR_MODELS
        return tuple((n, models[n].sample, self.configs[n], self.rngs[n], models[n].needs_terrain)
                     for n in SENSOR_NAMES if self.configs[n] is not None)

    @classmethod
    def from_config(cls, mapping: dict[str, Any], seed: int | np.random.SeedSequence | None) -> SensorSuite:
        """Build from a config mapping and a seed (int, SeedSequence or None for fresh entropy)."""
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        children = ss.spawn(len(SENSOR_NAMES))
        pairs = zip(SENSOR_NAMES, children, strict=True)
        rngs = {name: np.random.default_rng(child) for name, child in pairs}
        return cls(dict(mapping or {}), rngs)

    @property
    def active(self) -> tuple[str, ...]:
        return tuple(n for n in SENSOR_NAMES if self.configs[n] is not None)

    def sample(self, truth: TruthChunk, terrain=None) -> SensorFrames:
        """Frames of every configured sensor for the chunk's interval [t_s[0], t_s[-1] + dt)."""
        n = len(truth)
        if n >= 2:
            self._dt_s = float(truth.t_s[-1] - truth.t_s[-2])
        t0 = float(truth.t_s[0]) if n else (self._t_next_s or 0.0)
        t1 = float(truth.t_s[-1]) + self._dt_s if n else t0
        self._t_next_s = t1
        frames = SensorFrames(t_start_s=t0, t_end_s=t1)
        states = self.states
        for name, sample, config, rng, needs_terrain in self._plan:
            if needs_terrain and terrain is None:
                raise ValueError(f"sensors.{name} needs the true terrain (a terrain.Dem); got None")
            frame, states[name] = sample(truth, terrain, rng, config, states[name])
            setattr(frames, name, frame)
        return frames


__all__ = ["SENSOR_MODELS", "SENSOR_NAMES", "SensorModel", "SensorSuite"]
