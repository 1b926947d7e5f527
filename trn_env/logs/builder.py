"""A sensor log from a user's own data: plain arrays or pandas DataFrames with named columns and units.

    b = LogBuilder(map="my_dem.tif", imu_sample="increment",
                   height_datum={"reference": "ellipsoid", "geoid_offset_m": -31.2},
                   lever_arms_m={"radar_altimeter": [0.0, 0.0, 1.1]}, update_rate_hz=1.0,
                   sensors={"imu": {"grade": "tactical"}, "radar_altimeter": {"noise_const_m": 1.0}})
    b.add("imu", imu_df, units={"t": "s", "dv_x": "m/s", ..., "dtheta_x": "rad", ...})
    b.add("gnss", {"t_s": t, "lat_deg": lat, ...})        # a unit suffix in the name states the unit
    b.add_truth(truth_df, units={...})                      # optional: metrics after a replay
    b.write("my_flight.trnlog")

Columns. Each sensor's quantities (trn_env.logs.format.SENSOR_COLUMNS without the unit suffix, e.g. `lat`,
`range`, `f_x`; the IMU's `dv_x`.. `dtheta_z` with imu_sample="increment") and `t` (time, s). A column is
found as `<quantity>_<unit>` for a unit the builder knows (e.g. `lat_deg`, `t_s`, `range_ft`), or as the
bare `<quantity>` with `units={quantity: unit}`. An optional boolean `valid` column marks samples to skip
(their values may be NaN); without it every sample must be finite.

Every problem raises LogError naming the sensor, the column and the fix, before anything is written:
a missing column or unit, an unknown unit, time that is not finite or does not increase, NaN in a valid
sample, an IMU gap (no valid sample for over 2.5 median intervals, the samples missing or marked invalid:
the INS cannot bridge it), a sample rate that
disagrees with the sensor's stated `rate_hz`, a value outside format.COLUMN_LIMITS once converted (a
latitude in degrees stated as radians, a negative range), and a datum, IMU convention or ranging lever arm
not stated.
`write` goes through LogWriter (all or nothing).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from trn_env.logs.format import (
    IMU_INCREMENT_COLUMNS,
    IMU_SAMPLE_CONVENTIONS,
    SENSOR_COLUMNS,
    SENSORS,
    TRUTH_COLUMNS,
    TRUTH_OPTIONAL,
    LogError,
    imu_gap,
    limit_violation,
)
from trn_env.logs.reader import geoid_offset_m
from trn_env.logs.writer import TRUTH_ROW_COLUMNS, LogWriter

# dimension (the canonical unit) -> {unit name: factor to the canonical unit}
_UNITS = {
    "s": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
    "m": {"m": 1.0, "ft": 0.3048, "km": 1000.0},
    "rad": {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3},
    "m/s": {"m/s": 1.0, "mps": 1.0, "kt": 1852.0 / 3600.0, "ft/s": 0.3048, "km/h": 1.0 / 3.6},
    "m/s^2": {"m/s^2": 1.0, "mps2": 1.0, "g": 9.80665, "ft/s^2": 0.3048},
    "rad/s": {"rad/s": 1.0, "rps": 1.0, "deg/s": math.pi / 180.0, "deg/h": math.pi / 180.0 / 3600.0},
}
_SUFFIX_UNIT = {"s": "s", "ms": "ms", "us": "us", "ns": "ns", "m": "m", "ft": "ft", "km": "km", "rad": "rad",
                "deg": "deg", "mrad": "mrad", "mps": "m/s", "kt": "kt", "mps2": "m/s^2", "g": "g",
                "rps": "rad/s", "dps": "deg/s"}
_RANGING = ("radar_altimeter", "ira")


def _quantities(sensor: str, imu_sample: str | None) -> list[tuple[str, str, str]]:
    """(quantity, stored column, dimension) of a sensor, `t` first."""
    out = [("t", "t_s", "s")]
    if sensor == "imu" and imu_sample == "increment":
        return out + [(inc.rsplit("_", 1)[0], inc, unit) for inc, _, unit in IMU_INCREMENT_COLUMNS]
    return out + [(col.rsplit("_", 1)[0], col, unit) for col, _, _, unit in SENSOR_COLUMNS[sensor]]


def _get(data, name: str):
    try:
        return data[name]
    except (KeyError, IndexError, TypeError, ValueError):    # ValueError: a structured array's missing field
        return None


def _columns_of(data, what: str = "data") -> list[str]:
    if hasattr(data, "columns"):
        return [str(c) for c in data.columns]
    names = getattr(getattr(data, "dtype", None), "names", None)      # a numpy structured array
    if names:
        return list(names)
    if not hasattr(data, "keys"):
        raise LogError(f"{what}: give a pandas DataFrame, a mapping of column names to arrays or a numpy "
                       f"structured array, got {type(data).__name__}")
    return [str(c) for c in data.keys()]


def _column(what: str, data, quantity: str, dim: str, units: dict, required: bool = True):
    """The quantity's values converted to its canonical unit (None if absent and not required)."""
    table = _UNITS[dim]
    have = _columns_of(data, what)
    for c in have:
        if c.startswith(quantity + "_") and c[len(quantity) + 1:] in _SUFFIX_UNIT:
            unit = _SUFFIX_UNIT[c[len(quantity) + 1:]]
            if unit not in table:
                raise LogError(f"{what}: column {c!r} has unit {unit!r}, not a {dim} unit "
                               f"({', '.join(table)})")
            return _array(what, c, _get(data, c)) * table[unit]
    if quantity in have:
        unit = (units or {}).get(quantity)
        if unit is None:
            raise LogError(f"{what}: column {quantity!r} has no unit: give units={{{quantity!r}: ...}} "
                           f"(one of {', '.join(table)}) or name it {quantity}_<unit>")
        if unit not in table:
            raise LogError(f"{what}: column {quantity!r}: unknown unit {unit!r} for a {dim} quantity "
                           f"(known: {', '.join(table)})")
        return _array(what, quantity, _get(data, quantity)) * table[unit]
    if required:
        # a column named as the quantity with a unit the builder does not know (t_min, lat_grad)
        suffixed = [c for c in have if c.startswith(quantity + "_") and "_" not in c[len(quantity) + 1:]]
        if suffixed:
            unit = suffixed[0][len(quantity) + 1:]
            raise LogError(f"{what}: column {suffixed[0]!r}: unknown unit {unit!r} for a {dim} quantity "
                           f"(name it {quantity}_<unit> with one of "
                           f"{', '.join(u for u, d in _SUFFIX_UNIT.items() if d in table)})")
        raise LogError(f"{what}: missing column {quantity!r} (a {dim} quantity: name it {quantity}_<unit>, "
                       f"or {quantity!r} with units={{{quantity!r}: ...}}; columns given: {', '.join(have)})")
    return None


def _array(what: str, col: str, v) -> np.ndarray:
    kind = np.asarray(v).dtype.kind
    if kind in "mM":       # numpy would give the raw nanosecond counts
        raise LogError(f"{what}: column {col!r} holds {'durations' if kind == 'm' else 'dates and times'} "
                       f"({np.asarray(v).dtype}): give seconds as numbers, e.g. "
                       f"(df['time'] - df['time'].iloc[0]).dt.total_seconds()")
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise LogError(f"{what}: column {col!r} is not numeric ({exc})") from exc
    if a.ndim != 1:
        raise LogError(f"{what}: column {col!r} must be one-dimensional, got shape {a.shape}")
    return a


def _check_time(what: str, t: np.ndarray) -> None:
    if not t.size:
        raise LogError(f"{what}: no samples")
    if not np.all(np.isfinite(t)):
        raise LogError(f"{what}: time t is NaN or infinite at row {int(np.flatnonzero(~np.isfinite(t))[0])}")
    hit = limit_violation("t_s", t)
    if hit is not None:
        raise LogError(f"{what}: time t = {float(t[hit[0]]):.10g} s at row {hit[0]} is not {hit[1]}")
    d = np.diff(t)
    if np.any(d <= 0.0):
        i = int(np.flatnonzero(d <= 0.0)[0])
        raise LogError(f"{what}: time must increase: row {i + 1} at {float(t[i + 1])!r} s follows "
                       f"{float(t[i])!r} s")


def _check_limits(what: str, col: str, v: np.ndarray, use: np.ndarray | None, t: np.ndarray) -> None:
    """A column's values (in the log's units, after conversion) inside format.COLUMN_LIMITS: a latitude
    stated in radians but given in degrees, a negative range."""
    hit = limit_violation(col, v, use)
    if hit is not None:
        i, should = hit
        raise LogError(f"{what}: column {col.rsplit('_', 1)[0]!r} = {float(v[i]):.10g} "
                       f"{col.rsplit('_', 1)[1]} at row {i} (t = {t[i]:g} s) is not {should}: check its unit")


class LogBuilder:
    """A log under construction (module docstring). `map`: the DEM the navigator should use (a path or a
    bundled name, terrain.load); `imu_sample`: "rate" or "increment"; `height_datum`: {"reference":
    "msl"} or {"reference": "ellipsoid", "geoid_offset_m": N}; `lever_arms_m`: {sensor: [x, y, z] body
    FRD m} for the radar altimeter and IRA (required for those fitted, zeros allowed); `sensors`: their
    configs as a scenario's [sensors.*] tables (noise figures the navigators' settings are filled from;
    `rate_hz` is checked against the data); `navigator`: {"name", "settings"} replayed by default;
    `update_rate_hz`: the update intervals the frames are cut into; `initial_estimate`: as
    trn_env.logs.record.estimate_metadata (default: the truth at the start, perturbed by `initial_errors`
    with the seed's stream, as the closed loop starts)."""

    def __init__(self, *, map: str, height_datum: dict, imu_sample: str | None = None,
                 lever_arms_m: dict | None = None, sensors: dict | None = None, navigator: dict | None = None,
                 update_rate_hz: float = 1.0, seed: int = 0, initial_estimate: dict | None = None,
                 initial_errors: dict | None = None, description: str = ""):
        if imu_sample is not None and imu_sample not in IMU_SAMPLE_CONVENTIONS:
            raise LogError(f"imu_sample must be one of {', '.join(IMU_SAMPLE_CONVENTIONS)}, got "
                           f"{imu_sample!r}")
        geoid_offset_m({"height_datum": height_datum}, "LogBuilder")          # stated and valid
        if not (isinstance(update_rate_hz, (int, float)) and math.isfinite(update_rate_hz)
                and update_rate_hz > 0):
            raise LogError(f"update_rate_hz must be a positive number, got {update_rate_hz!r}")
        self.meta = {"source": "trn_env.logs.LogBuilder", "description": description, "seed": int(seed),
                     "map": {"dem": str(map)}, "imu_sample": imu_sample, "height_datum": dict(height_datum),
                     "lever_arms_m": {k: [float(x) for x in v] for k, v in (lever_arms_m or {}).items()},
                     "sensors": {k: dict(v) for k, v in (sensors or {}).items()},
                     "navigator": navigator or {"name": "ins", "settings": {}},
                     "update_rate_hz": float(update_rate_hz)}
        for name, arm in self.meta["lever_arms_m"].items():
            if len(arm) != 3 or not all(math.isfinite(x) for x in arm):
                raise LogError(f"lever_arms_m.{name}: three finite numbers (body FRD x, y, z, m), got "
                               f"{arm!r}")
        if initial_estimate is not None:
            self.meta["initial_estimate"] = initial_estimate
        if initial_errors is not None:
            self.meta["initial_errors"] = initial_errors
        self.tables: dict[str, dict[str, np.ndarray]] = {}
        self.truth: dict[str, np.ndarray] | None = None

    def add(self, sensor: str, data, units: dict | None = None) -> LogBuilder:
        """One sensor's samples (a DataFrame or a mapping of arrays), once per sensor."""
        if sensor not in SENSORS:
            raise LogError(f"unknown sensor {sensor!r} (known: {', '.join(SENSORS)})")
        if sensor in self.tables:          # a second table would silently replace the first
            raise LogError(f"{sensor}: added already; add each sensor's samples once, as one table "
                           "(join chunks first, e.g. pandas.concat)")
        if sensor == "imu" and self.meta["imu_sample"] is None:
            raise LogError("imu: the IMU sample convention is not stated: LogBuilder(imu_sample='rate' "
                           "(mean specific force and rate over each sample's interval) or 'increment' "
                           "(velocity and angle increments))")
        if sensor in _RANGING and sensor not in self.meta["lever_arms_m"]:
            raise LogError(f"{sensor}: its lever arm is not stated: LogBuilder(lever_arms_m={{{sensor!r}: "
                           "[x, y, z]}}), body FRD metres from the IMU ([0, 0, 0] if co-located)")
        cols = {stored: _column(sensor, data, q, dim, units or {})
                for q, stored, dim in _quantities(sensor, self.meta["imu_sample"])}
        t = cols["t_s"]
        _check_time(sensor, t)
        valid = _get(data, "valid")
        if valid is not None:
            valid = np.asarray(valid)
            if valid.dtype != bool:
                raise LogError(f"{sensor}: column 'valid' must be boolean, got {valid.dtype}")
        else:
            valid = np.ones(t.shape, bool)
        for c, v in cols.items():
            if v.shape != t.shape:
                raise LogError(f"{sensor}: column {c!r} has {v.shape[0]} rows, t has {t.shape[0]}")
            bad = ~np.isfinite(v) & valid
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise LogError(f"{sensor}: column {c.rsplit('_', 1)[0]!r} is NaN or infinite at row {i} "
                               f"(t = {t[i]:g} s): drop the sample or mark it valid = false")
            _check_limits(sensor, c, v, valid, t)
        dt = np.diff(t)
        med = float(np.median(dt)) if dt.size else float("nan")
        gap = imu_gap(t, valid) if sensor == "imu" else None
        if gap is not None:
            raise LogError(f"imu: a gap of {gap[1]:.3g} s after t = {gap[0]:g} s (median interval "
                           f"{gap[2]:.3g} s): an INS cannot bridge missing IMU samples (or samples marked "
                           "invalid); split the log or fill the gap")
        rate = (self.meta["sensors"].get(sensor) or {}).get("rate_hz")
        if rate is not None and dt.size and abs(med * float(rate) - 1.0) > 0.02:
            raise LogError(f"{sensor}: the samples come every {med:.4g} s (median), the stated rate_hz "
                           f"{rate:g} means every {1.0 / float(rate):.4g} s: fix sensors.{sensor}.rate_hz or "
                           "the time column")
        cols["valid"] = valid
        self.tables[sensor] = cols
        return self

    def add_truth(self, data, units: dict | None = None) -> LogBuilder:
        """The true trajectory (heights in the log's datum), for metrics after a replay."""
        if self.truth is not None:
            raise LogError("truth: added already; add the truth once, as one table (join chunks first)")
        cols = {}
        for col, unit in TRUTH_COLUMNS:
            cols[col] = _column("truth", data, col.rsplit("_", 1)[0], unit, units or {})
        for col, unit in TRUTH_OPTIONAL:
            v = _column("truth", data, col.rsplit("_", 1)[0], unit, units or {}, required=False)
            if v is not None:
                cols[col] = v
        _check_time("truth", cols["t_s"])
        for c, v in cols.items():
            if not np.all(np.isfinite(v)):
                raise LogError(f"truth: column {c.rsplit('_', 1)[0]!r} is NaN or infinite at row "
                               f"{int(np.flatnonzero(~np.isfinite(v))[0])}")
            _check_limits("truth", c, v, None, cols["t_s"])
        self.truth = cols
        return self

    def frame_edges(self) -> np.ndarray:
        """The update intervals' edges: from the first sample, every 1 / update_rate_hz, past the last."""
        t0 = min(float(c["t_s"][0]) for c in self.tables.values())
        t1 = max(float(c["t_s"][-1]) for c in self.tables.values())
        dt = 1.0 / self.meta["update_rate_hz"]
        n = int(math.floor((t1 - t0) / dt)) + 1
        return t0 + dt * np.arange(n + 1)

    def write(self, out: Path | str) -> Path:
        """Write the log folder (all or nothing); returns its path."""
        if not self.tables:
            raise LogError("no sensor data: add at least one sensor")
        if "imu" not in self.tables:
            raise LogError("imu: every navigator dead-reckons on the IMU: add its samples")
        if "initial_estimate" not in self.meta and self.truth is None:
            raise LogError("no initial estimate: give LogBuilder(initial_estimate=...) or add_truth(...)")
        edges = self.frame_edges()
        from trn_env.logs.reader import _FRAME_CLASSES
        from trn_env.navigators import frames as nf
        writer = LogWriter(out, self.meta)
        try:
            idx = {s: np.searchsorted(c["t_s"], edges, side="left") for s, c in self.tables.items()}
            for k in range(len(edges) - 1):
                fr = nf.SensorFrames(float(edges[k]), float(edges[k + 1]))
                for s, c in self.tables.items():
                    a, b = int(idx[s][k]), int(idx[s][k + 1])
                    if b > a:
                        setattr(fr, s, _frame(_FRAME_CLASSES[s], s, c, a, b, self.meta["imu_sample"]))
                writer.write_frames(fr)
            writer.close_frames()
            if self.truth is not None:
                n = self.truth["t_s"].shape[0]
                rows = np.column_stack([self.truth.get(c, np.full(n, np.nan)) for c in TRUTH_ROW_COLUMNS])
                writer.write_ticks(rows, None)
            return writer.commit()
        except BaseException:
            writer.abort()
            raise


def _frame(cls, sensor: str, c: dict, a: int, b: int, imu_sample: str | None):
    """A frame as the writer stores it (increments stay increments, in the rate columns' places)."""
    kw = {"t_s": c["t_s"][a:b], "valid": c["valid"][a:b]}
    vec: dict[str, list] = {}
    for col, fld, comp, _ in SENSOR_COLUMNS[sensor]:
        src = col
        if sensor == "imu" and imu_sample == "increment":
            src = next(inc for inc, rate, _ in IMU_INCREMENT_COLUMNS if rate == col)
        if comp is None:
            kw[fld] = c[src][a:b]
        else:
            vec.setdefault(fld, []).append(c[src][a:b])
    for fld, parts in vec.items():
        kw[fld] = np.column_stack(parts)
    return cls(**kw)
