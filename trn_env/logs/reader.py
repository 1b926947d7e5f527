"""Reading a sensor log (trn_env.logs.format) back: validated, and converted to trn-env's conventions.

    log = read_log("flight.trnlog")     # LogError naming the file and the fix if anything is wrong
    log.metadata                        # dict (metadata.json)
    log.table("gnss")                   # pandas DataFrame of a table as stored
    for frames in log.frames(): ...     # navigators.frames.SensorFrames per update interval, in the
                                        # navigators' conventions: IMU rates, heights above the map's MSL
    log.truth()                         # DataFrame, heights above MSL, or None

`read_log` checks what a navigator would otherwise meet silently: a log from a newer format version, a
recording that did not finish, a truncated or corrupt table, a table whose row count disagrees with the
metadata, missing columns, a column of the wrong kind (text, or floats where the format has flags or frame
indices), time that does not increase, a sample outside its frame's interval, samples in a frame whose
sensor is marked absent, NaN in a sample marked valid or in the truth, a stretch without a valid IMU
sample longer than format.IMU_MAX_GAP_INTERVALS median intervals, a latitude, longitude or range
outside format.COLUMN_LIMITS (degrees stated as radians), and an IMU sample convention or height datum
that is not stated.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from trn_env.logs.format import (
    ESTIMATE_COLUMNS,
    FORMAT_NAME,
    FORMAT_VERSION,
    HEIGHT_REFERENCES,
    IMU_INCREMENT_COLUMNS,
    IMU_SAMPLE_CONVENTIONS,
    METADATA_FILE,
    SENSOR_COLUMNS,
    SENSORS,
    TRUTH_COLUMNS,
    TRUTH_OPTIONAL,
    LogError,
    imu_gap,
    limit_violation,
)
from trn_env.navigators import frames as nf
from trn_env.navigators.protocol import Estimate, Health

_FRAME_CLASSES = {"imu": nf.ImuFrame, "baro": nf.BaroFrame, "radar_altimeter": nf.RadarAltimeterFrame,
                  "ira": nf.IraFrame, "gnss": nf.GnssFrame, "air_data": nf.AirDataFrame,
                  "heading": nf.HeadingFrame}


def geoid_offset_m(metadata: dict, where: str = "metadata.json") -> float:
    """N (m) to subtract from the log's heights to get heights above MSL: 0 for an MSL log."""
    datum = metadata.get("height_datum")
    if not isinstance(datum, dict) or datum.get("reference") not in HEIGHT_REFERENCES:
        raise LogError(f"{where}: height_datum is not stated: give {{\"reference\": \"msl\"}} (heights above "
                       "the map's MSL) or {\"reference\": \"ellipsoid\", \"geoid_offset_m\": N} (WGS84 "
                       "ellipsoid heights, N the geoid's height above the ellipsoid here)")
    if datum["reference"] == "msl":
        return 0.0
    if "geoid_model" in datum and "geoid_offset_m" not in datum:
        raise LogError(f"{where}: height_datum.geoid_model {datum['geoid_model']!r}: "
                       "geoid models by name are "
                       "not supported (no geoid grid ships with trn-env); give geoid_offset_m, the geoid "
                       "height above the ellipsoid over the log's area, in metres")
    n = datum.get("geoid_offset_m")
    if not isinstance(n, (int, float)) or isinstance(n, bool) or not math.isfinite(n) or abs(n) > 150.0:
        raise LogError(f"{where}: height_datum.geoid_offset_m must be a finite number of metres within "
                       f"+-150 (ellipsoid heights need it), got {n!r}")
    return float(n)


def _writable(a: np.ndarray) -> np.ndarray:
    """`a`, copied if it is read-only. pyarrow hands out read-only zero-copy views of single-chunk numeric
    columns, and numba compiles a separate specialisation of a kernel for read-only arrays: frames read from
    a log would compile every navigator kernel they reach a second time. Copies give them the live loop's
    array type."""
    return a if a.flags.writeable else a.copy()


def _open_table(path: Path) -> pa.Table:
    try:
        return pq.read_table(path)
    except (pa.ArrowInvalid, pa.ArrowIOError, OSError, ValueError) as exc:
        raise LogError(f"log table {path}: corrupt or truncated Parquet file ({exc}); record it again or "
                       "restore the file") from exc


def _check_column(name: Path | str, col: str, a: np.ndarray, valid: np.ndarray | None) -> None:
    bad = ~np.isfinite(a) if valid is None else (~np.isfinite(a) & valid)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        why, fix = ("", "drop the row") if valid is None else (" in a sample marked valid",
                                                              "mark the sample valid = false, or drop it")
        raise LogError(f"log table {name}: column {col} is NaN or infinite{why} at row {i} ({fix})")


def _check_limits(name: Path | str, col: str, a: np.ndarray, use: np.ndarray | None = None) -> None:
    """The values of a column named in COLUMN_LIMITS (where `use`) inside their range."""
    hit = limit_violation(col, a, use)
    if hit is not None:
        i, what = hit
        raise LogError(f"log table {name}: column {col} = {float(a[i])!r} at row {i} is not {what}")


_TYPE_WORDS = {"integer": "whole numbers (int64)", "number": "numbers (float64)",
               "boolean": "true / false (bool)", "text": "text (string)"}


def _kind(t: pa.DataType) -> str:
    if pa.types.is_boolean(t):
        return "boolean"
    if pa.types.is_integer(t):
        return "integer"
    if pa.types.is_floating(t):
        return "number"
    return "text" if pa.types.is_string(t) or pa.types.is_large_string(t) else str(t)


def _check_types(log: SensorLog, name: str, wanted: dict[str, str]) -> None:
    """Each of the table's columns named in `wanted` holds that kind of value (a whole number also passes
    as a number): a column of text or of floats where the format has flags or frame indices would be read
    silently wrong (any non-empty text is true), or fail deep inside a navigator."""
    schema = log.arrow(name).schema
    for col, want in wanted.items():
        if col not in schema.names:
            continue
        got = _kind(schema.field(col).type)
        if got != want and not (want == "number" and got == "integer"):
            raise LogError(f"log table {log.path / (name + '.parquet')}: column {col} holds "
                           f"{schema.field(col).type} values; the format's are {_TYPE_WORDS[want]} "
                           "(docs/guide/logs.md)")


class SensorLog:
    """A validated log on disk (see the module docstring)."""

    def __init__(self, path: Path, metadata: dict):
        self.path = Path(path)
        self.metadata = metadata
        self.sensors = tuple(s for s in SENSORS if s in metadata.get("tables", {}))
        self.geoid_offset_m = geoid_offset_m(metadata, f"log {self.path}: {METADATA_FILE}")
        self._cache: dict[str, pa.Table] = {}

    # --------------------------------------------------------------------------------- tables
    def has(self, name: str) -> bool:
        return name in self.metadata.get("tables", {})

    def arrow(self, name: str) -> pa.Table:
        if not self.has(name):
            raise LogError(f"log {self.path}: has no {name} table")
        if name not in self._cache:
            self._cache[name] = _open_table(self.path / f"{name}.parquet")
        return self._cache[name]

    def table(self, name: str) -> pd.DataFrame:
        """A table as stored (pandas)."""
        return self.arrow(name).to_pandas()

    def column(self, name: str, col: str) -> np.ndarray:
        return self.arrow(name).column(col).to_numpy()

    @property
    def n_frames(self) -> int:
        return int(self.metadata["tables"].get("frames", 0))

    # --------------------------------------------------------------------------------- frames
    def _sensor_columns(self, s: str) -> dict[str, np.ndarray]:
        """A sensor's columns in the navigators' conventions (IMU rates, heights above MSL), writable (see
        _writable)."""
        t = self.arrow(s)
        cols = {c: _writable(t.column(c).to_numpy()) for c in t.column_names}
        if s == "imu" and self.metadata.get("imu_sample") == "increment":
            ts = cols["t_s"]
            dt = np.diff(ts)
            dt = np.concatenate([[np.median(dt) if dt.size else 0.0], dt])
            for inc, rate, _ in IMU_INCREMENT_COLUMNS:
                cols[rate] = cols.pop(inc) / dt
        if s == "gnss" and self.geoid_offset_m:
            cols["h_m"] = cols["h_m"] - self.geoid_offset_m
        return cols

    def frames(self):
        """SensorFrames per update interval, in order (a generator)."""
        fr = self.arrow("frames")
        t0, t1 = fr.column("t_start_s").to_numpy(), fr.column("t_end_s").to_numpy()
        present = {s: fr.column(f"{s}_present").to_numpy() for s in SENSORS}
        data = {}
        for s in self.sensors:
            cols = self._sensor_columns(s)
            bounds = np.searchsorted(cols["frame"], np.arange(len(t0) + 1), side="left")
            data[s] = (cols, bounds)
        for k in range(len(t0)):
            out = nf.SensorFrames(float(t0[k]), float(t1[k]))
            for s in SENSORS:
                if not present[s][k]:
                    continue
                if s in data:
                    cols, b = data[s]
                    setattr(out, s, _frame(s, cols, int(b[k]), int(b[k + 1])))
                else:
                    setattr(out, s, _frame(s, None, 0, 0))
            yield out

    def arrays(self) -> dict[str, np.ndarray]:
        """The log as the arrays `log.npz` held (trn_env.sim.SimLog.arrays' names): sensor_<sensor>_<field>
        per sensor field (the navigators' conventions), and, when the log holds them, the estimates as
        est_t_s, est_lat_rad, ..., est_cov (n, 9, 9), nav_ok, nav_status_code and the truth as t_s,
        true_lat_rad, true_lon_rad, true_h_msl_m, true_v_ned_mps, ... (what e.g.
        navigators.integrity.dem_monitor.replay_log reads), all writable (_writable)."""
        out: dict[str, np.ndarray] = {}
        for s in self.sensors:
            cols = self._sensor_columns(s)
            out[f"sensor_{s}_t_s"] = cols["t_s"]
            vec: dict[str, list] = {}
            for col, fld, comp, _ in SENSOR_COLUMNS[s]:
                if comp is None:
                    out[f"sensor_{s}_{fld}"] = cols[col]
                else:
                    vec.setdefault(fld, []).append(cols[col])
            for fld, parts in vec.items():
                out[f"sensor_{s}_{fld}"] = np.column_stack(parts)
            out[f"sensor_{s}_valid"] = cols["valid"].astype(bool)
        est = self.estimates()
        if est is not None:
            out["est_t_s"] = est["t_s"].to_numpy()
            for c in ("lat_rad", "lon_rad", "h_m", "roll_rad", "pitch_rad", "yaw_rad"):
                out[f"est_{c}"] = est[c].to_numpy()
            out["est_v_ned_mps"] = est[["v_n_mps", "v_e_mps", "v_d_mps"]].to_numpy()
            out["est_cov"] = est[[f"cov_{i}_{j}" for i in range(9) for j in range(9)]].to_numpy().reshape(
                -1, 9, 9)
            out["nav_ok"] = est["nav_ok"].to_numpy().astype(bool)
            out["nav_status_code"] = est["nav_status_code"].to_numpy()
        truth = self.truth()
        if truth is not None:
            out["t_s"] = truth["t_s"].to_numpy()
            out["true_lat_rad"] = truth["lat_rad"].to_numpy()
            out["true_lon_rad"] = truth["lon_rad"].to_numpy()
            out["true_h_msl_m"] = truth["h_m"].to_numpy()
            out["true_v_ned_mps"] = truth[["v_n_mps", "v_e_mps", "v_d_mps"]].to_numpy()
            for c in ("roll_rad", "pitch_rad", "yaw_rad", "tas_mps", "alpha_rad", "beta_rad"):
                if c in truth:
                    out[f"true_{c}"] = truth[c].to_numpy()
        return {k: _writable(v) for k, v in out.items()}

    # ---------------------------------------------------------------------------------- truth
    def truth(self) -> pd.DataFrame | None:
        """The truth table with heights above the map's MSL, or None."""
        if not self.has("truth"):
            return None
        df = self.table("truth")
        if self.geoid_offset_m:
            df["h_m"] = df["h_m"] - self.geoid_offset_m
        return df

    def estimates(self) -> pd.DataFrame | None:
        return self.table("estimates") if self.has("estimates") else None

    def initial_estimate(self) -> Estimate | None:
        """The initial estimate stated in the metadata (heights converted to MSL), or None."""
        ie = self.metadata.get("initial_estimate")
        if ie is None:
            return None
        try:
            cov = np.array(ie["covariance"], float).reshape(9, 9)
            estimate = Estimate(float(ie["t_s"]), float(ie["lat_rad"]), float(ie["lon_rad"]),
                                float(ie["h_m"]) - self.geoid_offset_m, np.array(ie["v_ned_mps"], float),
                                float(ie["roll_rad"]), float(ie["pitch_rad"]), float(ie["yaw_rad"]), cov,
                                Health())
        except (KeyError, TypeError, ValueError) as exc:
            raise LogError(f"log {self.path}: {METADATA_FILE}: initial_estimate is malformed "
                           f"({exc})") from exc
        for col, value in (("lat_rad", estimate.lat_rad), ("lon_rad", estimate.lon_rad)):
            hit = limit_violation(col, [value])
            if hit is not None:
                raise LogError(f"log {self.path}: {METADATA_FILE}: initial_estimate.{col} = {value!r} is not "
                               f"{hit[1]}")
        return estimate


def _frame(s: str, cols: dict | None, i0: int, i1: int):
    cls = _FRAME_CLASSES[s]
    if cols is None:
        empty = np.empty(0)
        kw = {"t_s": empty, "valid": np.empty(0, bool)}
        for _, fld, comp, _ in SENSOR_COLUMNS[s]:
            kw[fld] = np.empty((0, 3)) if comp is not None else empty
        return cls(**kw)
    kw = {"t_s": cols["t_s"][i0:i1], "valid": cols["valid"][i0:i1]}
    vectors: dict[str, list] = {}
    for col, fld, comp, _ in SENSOR_COLUMNS[s]:
        if comp is None:
            kw[fld] = cols[col][i0:i1]
        else:
            vectors.setdefault(fld, []).append(cols[col][i0:i1])
    for fld, parts in vectors.items():
        kw[fld] = np.column_stack(parts)
    return cls(**kw)


def read_metadata(path: Path) -> dict:
    path = Path(path)
    if not path.exists():
        raise LogError(f"log {path}: no such folder")
    if not path.is_dir():
        raise LogError(f"log {path}: not a folder (a trn-env log is a folder of Parquet tables with a "
                       f"{METADATA_FILE})")
    mfile = path / METADATA_FILE
    if not mfile.is_file():
        if (path / "log" / METADATA_FILE).is_file():          # a `trn-env fly` run folder
            raise LogError(f"log {path}: a run folder, not a log; its log is {path / 'log'}")
        raise LogError(f"log {path}: no {METADATA_FILE}: not a trn-env log, or a recording that did not "
                       "finish")
    try:
        meta = json.loads(mfile.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LogError(f"log {mfile}: corrupt or truncated ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise LogError(f"log {mfile}: not a {FORMAT_NAME} (format = {got!r})")
    v = meta.get("format_version")
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise LogError(f"log {mfile}: format_version must be a positive whole number, got {v!r}")
    if v > FORMAT_VERSION:
        raise LogError(f"log {mfile}: written in format version {v}, newer than this trn-env reads (up to "
                       f"{FORMAT_VERSION}); upgrade trn-env to read it")
    if meta.get("complete") is not True:
        raise LogError(f"log {mfile}: the recording did not finish (complete is not true): truncated log")
    tables = meta.get("tables")
    if not isinstance(tables, dict) or ("frames" not in tables and any(s in tables for s in SENSORS)):
        raise LogError(f"log {mfile}: tables must list each table's row count, the frames table among them "
                       "when the log holds sensor tables")
    return meta


def read_log(path: Path | str, *, check: bool = True) -> SensorLog:
    """Open and validate a log folder (LogError naming the file and the fix)."""
    path = Path(path)
    meta = read_metadata(path)
    log = SensorLog(path, meta)
    if "imu" in log.sensors and meta.get("imu_sample") not in IMU_SAMPLE_CONVENTIONS:
        raise LogError(f"log {path / METADATA_FILE}: imu_sample is not stated: one of "
                       f"{', '.join(IMU_SAMPLE_CONVENTIONS)} (docs/guide/logs.md says what each means)")
    for name, rows in meta["tables"].items():
        f = path / f"{name}.parquet"
        if not f.is_file():
            raise LogError(f"log {path}: table {f.name} is missing (the metadata lists it): truncated log")
        try:
            n = pq.ParquetFile(f).metadata.num_rows
        except (pa.ArrowInvalid, pa.ArrowIOError, OSError, ValueError) as exc:
            raise LogError(f"log table {f}: corrupt or truncated Parquet file ({exc})") from exc
        if n != rows:
            raise LogError(f"log table {f}: {n} rows, the metadata says {rows}: truncated or replaced")
    if check:
        _check_contents(log)
    return log


def _required(log: SensorLog, name: str, cols: list[str]) -> None:
    have = set(log.arrow(name).column_names)
    missing = [c for c in cols if c not in have]
    if missing:
        raise LogError(f"log table {log.path / (name + '.parquet')}: missing column(s) {', '.join(missing)}")


def _check_contents(log: SensorLog) -> None:
    n_frames = log.n_frames
    for name, wanted in (("truth", dict.fromkeys([c for c, _ in TRUTH_COLUMNS + TRUTH_OPTIONAL], "number")),
                         ("estimates", {**dict.fromkeys([c for c, _ in ESTIMATE_COLUMNS], "number"),
                                        "nav_ok": "boolean", "nav_status_code": "integer"}),
                         ("events", {"t_s": "number", "source": "text", "message": "text"})):
        if log.has(name):
            _check_types(log, name, wanted)
    if log.has("frames"):
        _check_frames(log, n_frames)
    if log.has("truth"):
        _required(log, "truth", [c for c, _ in TRUTH_COLUMNS])
        t = log.column("truth", "t_s")
        if np.any(np.diff(t) <= 0.0):
            raise LogError(f"log table {log.path / 'truth.parquet'}: t_s must increase")
        for c, _ in TRUTH_COLUMNS:
            a = log.column("truth", c)
            _check_column(log.path / "truth.parquet", c, a, None)
            _check_limits(log.path / "truth.parquet", c, a)
    if log.has("estimates"):
        for c in ("lat_rad", "lon_rad"):
            if c in log.arrow("estimates").column_names:
                a = log.column("estimates", c)
                _check_limits(log.path / "estimates.parquet", c, a, np.isfinite(a))


def _check_frames(log: SensorLog, n_frames: int) -> None:
    """The frames table and every sensor table against it: types, time, frame indices, each sample inside
    its frame's interval, a sensor's samples only in frames that say it is present, finite valid samples
    within COLUMN_LIMITS."""
    _required(log, "frames", ["frame", "t_start_s", "t_end_s"] + [f"{s}_present" for s in SENSORS])
    _check_types(log, "frames", {"frame": "integer", "t_start_s": "number", "t_end_s": "number",
                                 **{f"{s}_present": "boolean" for s in SENSORS}})
    t0, t1 = log.column("frames", "t_start_s"), log.column("frames", "t_end_s")
    _check_column(log.path / "frames.parquet", "t_start_s", t0, None)
    _check_column(log.path / "frames.parquet", "t_end_s", t1, None)
    if np.any(t1 < t0) or np.any(t0[1:] < t1[:-1]) or np.any(np.diff(log.column("frames", "frame")) != 1):
        raise LogError(f"log table {log.path / 'frames.parquet'}: frames must follow each other in time "
                       "(frame k+1 starting at or after frame k ends, t_end_s >= t_start_s, frame = 0, 1, "
                       "...)")
    for s in log.sensors:
        table = log.path / (s + ".parquet")
        imu_inc = s == "imu" and log.metadata.get("imu_sample") == "increment"
        cols = [c for c, _, _, _ in SENSOR_COLUMNS[s]]
        if imu_inc:
            cols = [inc for inc, _, _ in IMU_INCREMENT_COLUMNS]
        _required(log, s, ["frame", "t_s", "valid"] + cols)
        _check_types(log, s, {"frame": "integer", "t_s": "number", "valid": "boolean",
                              **dict.fromkeys(cols, "number")})
        t = log.column(s, "t_s")
        _check_column(table, "t_s", t, None)
        if np.any(np.diff(t) <= 0.0):
            i = int(np.flatnonzero(np.diff(t) <= 0.0)[0])
            raise LogError(f"log table {table}: t_s does not increase at row {i + 1} "
                           f"({float(t[i])!r} then {float(t[i + 1])!r} s)")
        k = log.column(s, "frame")
        if k.size and (np.any(np.diff(k) < 0) or k[0] < 0 or k[-1] >= n_frames):
            raise LogError(f"log table {table}: frame must be non-decreasing within 0 .. {n_frames - 1}")
        # a sample belongs to the interval holding its time (its end included: an integrating sensor's
        # sample closes its interval); a rounding's worth of slack either side
        slack = 1e-9 * np.maximum(1.0, np.abs(t))
        outside = (t < t0[k] - slack) | (t > t1[k] + slack)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            raise LogError(f"log table {table}: the sample at row {i} (t_s = {float(t[i])!r}) is in frame "
                           f"{int(k[i])}, whose interval is [{float(t0[k[i]])!r}, {float(t1[k[i]])!r}] s: "
                           "give each sample the frame whose interval holds its time")
        absent = ~log.column("frames", f"{s}_present").astype(bool)[k]
        if absent.any():
            i = int(np.flatnonzero(absent)[0])
            raise LogError(f"log table {table}: row {i} is in frame {int(k[i])}, where frames.parquet's "
                           f"{s}_present is false: its samples would be dropped (set it true)")
        valid = log.column(s, "valid")
        for c in cols:
            a = log.column(s, c)
            _check_column(table, c, a, valid)
            _check_limits(table, c, a, valid)
        gap = imu_gap(t, valid) if s == "imu" else None
        if gap is not None:
            raise LogError(f"log table {table}: no valid IMU sample for {gap[1]:.3g} s after t = "
                           f"{gap[0]:g} s (median interval {gap[2]:.3g} s): an INS cannot bridge that; split "
                           "the log")
