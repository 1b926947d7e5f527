"""Sensor models: pure functions of (truth chunk, true terrain, rng, config[, state]), per chunk.

Each module has a frozen config dataclass (validated; `noise_free()` preset; `from_mapping()` for scenario
files), a state type carried between chunks, and `sample_<sensor>(truth, terrain, rng, config, state=None)
-> (frame, new_state)`. `SensorSuite` (suite.py) builds them all from one mapping and one seed.
"""

from trn_env.sensors.air_data import AirDataConfig, sample_air_data
from trn_env.sensors.baro import BaroConfig, isa_pressure_altitude_m, isa_pressure_pa, sample_baro
from trn_env.sensors.gnss import GnssConfig, sample_gnss
from trn_env.sensors.heading import HeadingConfig, sample_heading
from trn_env.sensors.imu import IMU_GRADES, ImuConfig, sample_imu
from trn_env.sensors.ira import IraConfig, sample_ira
from trn_env.sensors.radar_altimeter import RadarAltimeterConfig, sample_radar_altimeter
from trn_env.sensors.suite import SENSOR_NAMES, SensorSuite

__all__ = [
    "AirDataConfig", "BaroConfig", "GnssConfig", "HeadingConfig", "IMU_GRADES", "ImuConfig", "IraConfig",
    "RadarAltimeterConfig", "SENSOR_NAMES", "SensorSuite", "isa_pressure_altitude_m", "isa_pressure_pa",
    "sample_air_data", "sample_baro", "sample_gnss", "sample_heading", "sample_imu", "sample_ira",
    "sample_radar_altimeter",
]
