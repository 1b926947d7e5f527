"""Sensor logs: one versioned on-disk format for sensor frames, truth and metadata (trn_env.logs.format);
writing while a flight goes, reading with validation, building from a user's arrays or DataFrames,
recording a scenario and replaying navigators on a log.

format   the format: tables, columns, units, conventions (IMU samples, datum, frames, lever arms)
writer   `LogWriter`: tables in row groups, one atomic commit
reader   `read_log` -> `SensorLog`: validated, frames in the navigators' conventions
builder  `LogBuilder`: a log from arrays or pandas DataFrames with named columns and units
record   `record(scenario, out)`: fly closed loop and stream the log
replay   `replay(log, navigator=...)`: run navigators (and monitors) open loop over a log's frames
"""

from trn_env.logs.builder import LogBuilder
from trn_env.logs.format import FORMAT_VERSION, LogError
from trn_env.logs.reader import SensorLog, read_log
from trn_env.logs.writer import LogWriter

__all__ = ["FORMAT_VERSION", "LogBuilder", "LogError", "LogWriter", "SensorLog", "read_log"]
