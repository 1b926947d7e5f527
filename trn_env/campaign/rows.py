"""A campaign's output folder: the manifest, one Parquet row file per run, optional logs.

    DIR/campaign.json        name, hash of the campaign file (and its scenario files), run count, source
    DIR/campaign.toml        a copy of the campaign file
    DIR/runs/<run_id>.parquet   one row per run (written to a temporary name, then renamed: a file there is
                                always complete, whatever interrupted the campaign)
    DIR/logs/<run_id>.npz    the run's full time-series log, when the campaign keeps logs

`--resume` reads the manifest, refuses a folder made by a different campaign file, and flies the runs
without a row file.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from trn_env.output.metrics import METRIC_KEYS

MANIFEST = "campaign.json"
_INT_COLUMNS = ("run_index", "variant_index", "seed_index", "seed", "attempts", "jsbsim_steps", "pid")
_BOOL_COLUMNS = ("track_lost",)
_LIST_COLUMNS = ("series_t_s", "series_err_h_m", "series_err_v_m", "series_sigma_h_m", "series_hpl_m",
                 "series_nav_ok")


def _write_atomic(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def row_table(row: dict[str, Any]) -> pa.Table:
    """One row as a pyarrow table with fixed column types (so every run's file has the same schema)."""
    cols, fields = [], []
    for k, v in row.items():
        if k in _INT_COLUMNS:
            typ = pa.int64()
        elif k in _BOOL_COLUMNS:
            typ = pa.bool_()
        elif k in _LIST_COLUMNS:
            typ = pa.list_(pa.float64())
        elif k in METRIC_KEYS or k in ("wall_time_s", "sim_time_s", "distance_flown_m"):
            typ = pa.float64()
        elif k.startswith("sweep.") and isinstance(v, (int, float)) and not isinstance(v, bool):
            typ, v = pa.float64(), float(v)
        elif k.startswith("sweep.") and not isinstance(v, (str, bool)):
            typ, v = pa.string(), json.dumps(v)      # a list or table value, as JSON text
        else:
            typ = None
        arr = pa.array([v], type=typ) if typ is not None else pa.array([v])
        if arr.type == pa.null():
            arr = pa.array([v], type=pa.string())
        cols.append(arr)
        fields.append(pa.field(k, arr.type))
    return pa.Table.from_arrays(cols, schema=pa.schema(fields))


def write_row(out_dir: Path, row: dict[str, Any]) -> Path:
    path = Path(out_dir) / "runs" / f"{row['run_id']}.parquet"
    table = row_table(row)
    # one row: column statistics and dictionaries buy nothing and cost time (docs/validation/benchmarks.md)
    _write_atomic(path, lambda tmp: pq.write_table(table, tmp, write_statistics=False, use_dictionary=False))
    return path


def write_log(out_dir: Path, run_id: str, log_bytes: bytes) -> Path:
    path = Path(out_dir) / "logs" / f"{run_id}.npz"
    _write_atomic(path, lambda tmp: Path(tmp).write_bytes(log_bytes))
    return path


def done_run_ids(out_dir: Path) -> set[str]:
    runs = Path(out_dir) / "runs"
    return {p.name[:-8] for p in runs.glob("*.parquet")} if runs.is_dir() else set()


def write_manifest(out_dir: Path, manifest: dict, campaign_text: str) -> None:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_atomic(out_dir / "campaign.toml",
                  lambda tmp: Path(tmp).write_text(campaign_text, encoding="utf-8"))
    text = json.dumps(manifest, indent=2) + "\n"
    _write_atomic(out_dir / MANIFEST, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def read_manifest(out_dir: Path) -> dict | None:
    p = Path(out_dir) / MANIFEST
    if not p.is_file():
        return None
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{p}: unreadable campaign manifest ({exc})") from None


def read_rows(out_dir: Path, columns: list[str] | None = None):
    """Every run row of a campaign folder as one pandas DataFrame (sorted by run_index)."""
    import pandas as pd
    out_dir = Path(out_dir)
    if read_manifest(out_dir) is None:
        raise ValueError(f"{out_dir}: not a campaign folder (no {MANIFEST})")
    files = sorted((out_dir / "runs").glob("*.parquet")) if (out_dir / "runs").is_dir() else []
    if not files:
        raise ValueError(f"{out_dir}: the campaign has no run rows yet (runs/*.parquet)")
    frames = []
    for f in files:
        try:
            frames.append(pq.read_table(f, columns=columns).to_pandas())
        except (OSError, pa.ArrowException) as exc:
            raise ValueError(f"{f}: unreadable row file ({exc})") from None
    df = pd.concat(frames, ignore_index=True)
    return df.sort_values("run_index", kind="stable").reset_index(drop=True)
