"""Writing a sensor log (trn_env.logs.format) while a flight goes: row groups, then one atomic commit.

    writer = LogWriter(out_dir, metadata)      # a hidden partial folder beside out_dir
    writer.write_frames(frames)                # per update interval, any number of times
    writer.write_ticks(truth_rows, est_rows)   # the run's per-tick truth and estimates, in batches
    writer.commit(metadata_updates)            # closes every table, writes metadata.json, renames

Each table buffers at most `chunk_rows` rows before writing them as a Parquet row group, so the memory a
log needs is bounded whatever the flight's length. Nothing appears at `out_dir` until `commit`: the
tables go into `.NAME.partial-<pid>-<random>` beside it (the run-folder convention of
trn_env.output.run_folder, whose leftover cleaner removes those of killed processes), renamed onto
`out_dir` at the end; `abort()` removes it. The writer may be forked with the estimation stage
(trn_env.sim.nav_stage): the process that writes frames closes their tables (`close_frames`) before the
process that commits renames the folder.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from trn_env.logs.format import (
    ESTIMATE_COLUMNS,
    FORMAT_NAME,
    FORMAT_VERSION,
    IMU_INCREMENT_COLUMNS,
    METADATA_FILE,
    SENSOR_COLUMNS,
    SENSORS,
    LogError,
    units,
)
from trn_env.output.chunked import ChunkedRows
from trn_env.output.run_folder import PARTIAL_MARK, clean_partial_leftovers

# = sim.log's
NAV_STATUS_CODES = ("ok", "acquiring", "degraded", "diverged", "free_inertial", "lost", "inconsistent")

# truth table columns, in trn_env.sim.log's _TRUTH_ROW order
TRUTH_ROW_COLUMNS = ("t_s", "lat_rad", "lon_rad", "h_m", "v_n_mps", "v_e_mps", "v_d_mps", "roll_rad",
                     "pitch_rad", "yaw_rad", "tas_mps", "alpha_rad", "beta_rad", "wind_n_mps", "wind_e_mps",
                     "wind_d_mps")


def _json_safe(o):
    """Metadata values as JSON: NaN/inf as null, numpy scalars and arrays as numbers and lists."""
    if isinstance(o, dict):
        return {str(k): _json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_json_safe(v) for v in o]
    if isinstance(o, np.ndarray):
        return _json_safe(o.tolist())
    if isinstance(o, (bool, np.bool_)):
        return bool(o)
    if isinstance(o, (int, np.integer)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(float(o)) else None
    if o is None or isinstance(o, str):
        return o
    return str(o)


def write_metadata(path: Path, metadata: dict) -> None:
    """metadata.json (floats written with repr: they read back bit for bit)."""
    path.write_text(json.dumps(_json_safe(metadata), indent=1) + "\n", encoding="utf-8")


# a table's buffer is written as a row group when it holds chunk_rows rows, MAX_BUFFER_BYTES of values or
# MAX_PIECES appended pieces (a sparse table's small per-interval arrays, each with its own overhead)
MAX_BUFFER_BYTES = 4 << 20
MAX_PIECES = 256


class _Table:
    """One Parquet table written in row groups (at most chunk_rows rows; see MAX_BUFFER_BYTES)."""

    def __init__(self, path: Path, schema: pa.Schema, chunk_rows: int):
        self.path = path
        self.schema = schema
        self.chunk_rows = chunk_rows
        self.parts: dict[str, list[np.ndarray]] = {f.name: [] for f in schema}
        self.buffered = 0
        self.buffered_bytes = 0
        self.pieces = 0
        self.rows = 0
        self.writer: pq.ParquetWriter | None = None

    def append(self, cols: dict[str, np.ndarray]) -> None:
        n = None
        for name in self.parts:
            v = cols[name]
            n = v.shape[0] if n is None else n
            self.parts[name].append(v)
            self.buffered_bytes += v.nbytes if v.dtype != object else 64 * len(v)
        self.buffered += n or 0
        self.pieces += 1
        if (self.buffered >= self.chunk_rows or self.buffered_bytes >= MAX_BUFFER_BYTES
                or self.pieces >= MAX_PIECES):
            self.flush()

    def flush(self) -> None:
        if self.buffered == 0 and self.writer is not None:
            return
        arrays = [pa.array(np.concatenate(self.parts[f.name]) if self.parts[f.name] else
                           np.empty(0, f.type.to_pandas_dtype()), type=f.type) for f in self.schema]
        table = pa.Table.from_arrays(arrays, schema=self.schema)
        if self.writer is None:
            self.writer = pq.ParquetWriter(self.path, self.schema, compression="zstd")
        self.writer.write_table(table)
        self.rows += table.num_rows
        self.parts = {f.name: [] for f in self.schema}
        self.buffered = self.buffered_bytes = self.pieces = 0

    def close(self) -> int:
        self.flush()
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        return self.rows


def _schema(float_cols, *, frame: bool = False, valid: bool = False, extra=()) -> pa.Schema:
    fields = [pa.field("frame", pa.int64())] if frame else []
    fields += [pa.field(c, pa.float64()) for c in float_cols]
    if valid:
        fields.append(pa.field("valid", pa.bool_()))
    fields += list(extra)
    return pa.schema(fields)


def _stored_names(sensor: str, increment: bool) -> list[str]:
    """The value columns as stored: the IMU's increment columns under imu_sample = "increment"."""
    cols = [c for c, _, _, _ in SENSOR_COLUMNS[sensor]]
    if sensor == "imu" and increment:
        by_rate = {rate: inc for inc, rate, _ in IMU_INCREMENT_COLUMNS}
        cols = [by_rate[c] for c in cols]
    return cols


def sensor_schema(sensor: str, increment: bool = False) -> pa.Schema:
    return _schema(["t_s"] + _stored_names(sensor, increment), frame=True, valid=True)


FRAMES_SCHEMA = pa.schema([pa.field("frame", pa.int64()), pa.field("t_start_s", pa.float64()),
                           pa.field("t_end_s", pa.float64())]
                          + [pa.field(f"{s}_present", pa.bool_()) for s in SENSORS])
TRUTH_SCHEMA = _schema(TRUTH_ROW_COLUMNS)
ESTIMATES_SCHEMA = pa.schema([pa.field(c, pa.float64()) for c, _ in ESTIMATE_COLUMNS[:-2]]
                             + [pa.field("nav_ok", pa.bool_()), pa.field("nav_status_code", pa.int8())])
EVENTS_SCHEMA = pa.schema([pa.field("t_s", pa.float64()), pa.field("source", pa.string()),
                           pa.field("message", pa.string())])


def frame_columns(sensor: str, fr, k: int, increment: bool = False) -> dict[str, np.ndarray]:
    """A frame's sensor arrays as the table's columns (frame index k; `increment`: the IMU frame's arrays
    hold increments, stored under the increment columns' names)."""
    n = fr.t_s.shape[0]
    cols = {"frame": np.full(n, k, np.int64), "t_s": np.asarray(fr.t_s, np.float64)}
    names = _stored_names(sensor, increment)
    for (_, fld, comp, _), col in zip(SENSOR_COLUMNS[sensor], names, strict=True):
        v = np.asarray(getattr(fr, fld), np.float64)
        cols[col] = np.ascontiguousarray(v[:, comp] if comp is not None else v)
    cols["valid"] = np.asarray(fr.valid, bool)
    return cols


def _read_column(pf: pq.ParquetFile, name: str) -> np.ndarray:
    """One column of a Parquet file as a numpy array (it may share Arrow's buffer: copy to keep it)."""
    return pf.read(columns=[name], use_threads=False).column(name).to_numpy()


COV_COLUMNS = tuple(f"cov_{i}_{j}" for i in range(9) for j in range(9))


def covariance_rows(path: Path) -> ChunkedRows:
    """The estimates table's covariance columns as an (n, 9, 9) ChunkedRows read a row group at a time
    (one group's 81 columns in memory at once). The file is opened here and read through that handle, so
    the log folder may be renamed (committed, moved into a run folder) while the array is in use."""
    pf = pq.ParquetFile(pa.OSFile(str(path)))
    sizes = [pf.metadata.row_group(g).num_rows for g in range(pf.metadata.num_row_groups)]

    def chunks():
        start = 0
        for g, k in enumerate(sizes):
            block = np.empty((k, 9, 9))
            flat = block.reshape(k, 81)
            for m, c in enumerate(COV_COLUMNS):
                flat[:, m] = pf.read_row_group(g, columns=[c]).column(0).to_numpy()
            yield start, block
            start += k

    return ChunkedRows((sum(sizes), 9, 9), np.float64, chunks)


class LogWriter:
    """A sensor log being written (module docstring). `metadata`: the log's metadata (format, units and
    version are added); `chunk_rows`: rows per Parquet row group (the memory bound per table)."""

    def __init__(self, out_dir: Path | str, metadata: dict, *, chunk_rows: int = 65536):
        self.out_dir = Path(out_dir)
        parent = self.out_dir.absolute().parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise LogError(f"log {self.out_dir}: cannot create its folder: {exc}") from exc
        if self.out_dir.exists() and (not self.out_dir.is_dir() or any(self.out_dir.iterdir())):
            raise LogError(f"log {self.out_dir}: exists and is not an empty folder (give a new path)")
        clean_partial_leftovers(parent)
        try:
            self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.out_dir.name}{PARTIAL_MARK}{os.getpid()}-",
                                             dir=parent))
        except OSError as exc:            # a read-only or pseudo file system (/proc)
            raise LogError(f"log {self.out_dir}: cannot create it in {parent} ({exc.strerror or exc})"
                           ) from None
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self.tmp, 0o777 & ~umask)     # mkdtemp makes it private; a log folder is not
        self.metadata = dict(metadata)
        self.chunk_rows = int(chunk_rows)
        self._owner_pid = os.getpid()
        self._frames_tables: dict[str, _Table] = {}
        self._tick_tables: dict[str, _Table] = {}
        self.n_frames = 0
        self.counts: dict[str, int] = {}
        self.frames_closed = False

    # ----------------------------------------------------------------------------------- frames
    def _table(self, store: dict, name: str, schema: pa.Schema) -> _Table:
        t = store.get(name)
        if t is None:
            t = store[name] = _Table(self.tmp / f"{name}.parquet", schema, self.chunk_rows)
        return t

    def write_frames(self, frames) -> None:
        """One update interval's SensorFrames (in order)."""
        k = self.n_frames
        row = {"frame": np.array([k], np.int64), "t_start_s": np.array([float(frames.t_start_s)]),
               "t_end_s": np.array([float(frames.t_end_s)])}
        for s in SENSORS:
            fr = getattr(frames, s)
            row[f"{s}_present"] = np.array([fr is not None])
            if fr is not None and fr.t_s.shape[0]:
                inc = s == "imu" and self.metadata.get("imu_sample") == "increment"
                table = self._table(self._frames_tables, s, sensor_schema(s, inc))
                table.append(frame_columns(s, fr, k, inc))
        self._table(self._frames_tables, "frames", FRAMES_SCHEMA).append(row)
        self.n_frames += 1

    def close_frames(self) -> dict[str, int]:
        """Close the frame tables (rows written per table); idempotent."""
        if not self.frames_closed:
            self.counts.update({name: t.close() for name, t in self._frames_tables.items()})
            self.frames_closed = True
        return {name: n for name, n in self.counts.items() if name in SENSORS or name == "frames"}

    # ------------------------------------------------------------------------------------ ticks
    def write_ticks(self, truth_rows: np.ndarray, est: dict[str, np.ndarray]) -> None:
        """Per-tick truth rows ((n, 16), TRUTH_ROW_COLUMNS) and estimate columns (ESTIMATES_SCHEMA)."""
        if truth_rows.shape[0]:
            self._table(self._tick_tables, "truth", TRUTH_SCHEMA).append(
                {c: np.ascontiguousarray(truth_rows[:, i]) for i, c in enumerate(TRUTH_ROW_COLUMNS)})
            if est is not None:
                self._table(self._tick_tables, "estimates", ESTIMATES_SCHEMA).append(est)

    def read_ticks(self) -> tuple[list[np.ndarray], dict]:
        """Every tick written so far, read back (closes the tick tables): the truth columns (a list in
        TRUTH_ROW_COLUMNS order) and the estimate columns, the covariance columns as one (n, 9, 9)
        ChunkedRows "cov" (`covariance_rows`: read from disk a row group at a time by whoever needs them)."""
        for name in ("truth", "estimates"):
            t = self._tick_tables.pop(name, None)
            if t is not None:
                self.counts[name] = t.close()
        if not self.counts.get("truth"):
            return [np.empty(0) for _ in TRUTH_ROW_COLUMNS], {}
        # one column at a time, each copied out of Arrow's memory: the read-back then needs the result's
        # own arrays plus one column, not a whole table beside them (Arrow's allocator keeps what it freed)
        truth = pq.ParquetFile(self.tmp / "truth.parquet")
        cols = [_read_column(truth, c).copy() for c in TRUTH_ROW_COLUMNS]
        es = pq.ParquetFile(self.tmp / "estimates.parquet")
        est = {"cov": covariance_rows(self.tmp / "estimates.parquet")}
        for c in es.schema_arrow.names:
            if not c.startswith("cov_"):
                est[c] = _read_column(es, c).copy()
        return cols, est

    def write_events(self, events) -> None:
        if not events:
            return
        t = self._table(self._tick_tables, "events", EVENTS_SCHEMA)
        t.append({"t_s": np.array([float(e[0]) for e in events]),
                  "source": np.array([str(e[1]) for e in events], object),
                  "message": np.array([str(e[2]) for e in events], object)})

    # ----------------------------------------------------------------------------------- commit
    def commit(self, updates: dict | None = None) -> Path:
        """Close every table, write metadata.json (marked complete, with row counts) and move the folder
        into place. The frames must be closed by the process that wrote them first."""
        self.close_frames()
        for name, t in list(self._tick_tables.items()):
            self.counts[name] = t.close()
        self._tick_tables.clear()
        counts = {p.stem: pq.ParquetFile(p).metadata.num_rows for p in sorted(self.tmp.glob("*.parquet"))}
        meta = self.metadata | (updates or {})
        meta = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION} | meta | {
            "units": units(), "tables": counts, "complete": True}
        write_metadata(self.tmp / METADATA_FILE, meta)
        if self.out_dir.exists():
            try:
                self.out_dir.rmdir()              # (checked empty at the start)
            except OSError:                       # another log landed there meanwhile: kept, never replaced
                raise LogError(f"log {self.out_dir}: another log was written there while this one was "
                               "being recorded (give a new path)") from None
        os.replace(self.tmp, self.out_dir)
        return self.out_dir

    def abort(self) -> None:
        """Remove the partial folder (only the process that created it does)."""
        for t in list(self._frames_tables.values()) + list(self._tick_tables.values()):
            try:
                if t.writer is not None:
                    t.writer.close()
            except Exception:
                pass
        if os.getpid() == self._owner_pid:
            shutil.rmtree(self.tmp, ignore_errors=True)
