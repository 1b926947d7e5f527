"""Sensor logs (trn_env.logs): record -> replay bit for bit, fly's streamed log, the builder's and the
reader's bad-input errors, the CLI's exit codes, and an independently generated log replayed by the
navigators (tests/log_reference_flight.py)."""

from __future__ import annotations

import json
import re
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from trn_env import cli
from trn_env.logs import FORMAT_VERSION, LogError, read_log
from trn_env.logs.builder import LogBuilder
from trn_env.logs.record import record
from trn_env.logs.replay import replay
from trn_env.scenario.overrides import load_scenario_with
from trn_env.sim.closed_loop import ClosedLoop

sys.path.insert(0, str(Path(__file__).parent))
import log_reference_flight as ref  # noqa: E402

SCEN = Path(__file__).parent / "scenarios"
EST_COLS = (["t_s", "lat_rad", "lon_rad", "h_m", "v_n_mps", "v_e_mps", "v_d_mps", "roll_rad", "pitch_rad",
             "yaw_rad"] + [f"cov_{i}_{j}" for i in range(9) for j in range(9)])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 12 s pf flight (the particle filter draws from the seed's navigator stream) with an IRA lever
    arm, recorded pipelined; and the same flight without a log sink, in memory."""
    tmp = tmp_path_factory.mktemp("rec")
    sc = load_scenario_with(SCEN / "default_short.toml", [("sensors.ira.lever_arm_b_m", [0.5, 0.3, 1.2])],
                            navigator="pf", duration_s=12.0, seed=5)
    result, path = record(sc, tmp / "pf.trnlog", pipeline=True)
    plain = ClosedLoop(sc, pipeline=False).run()
    return sc, result, path, plain


def test_replay_reproduces_the_recorded_flight_bit_for_bit(recorded):
    sc, result, path, plain = recorded
    log = read_log(path)
    assert log.metadata["format_version"] == FORMAT_VERSION and log.metadata["lever_arms_m"]["ira"] == [
        0.5, 0.3, 1.2]
    rec = log.estimates()
    rep = replay(path)                                   # the log's own navigator, settings and seed
    a = rep.arrays
    idx = np.searchsorted(a["est_t_s"], rec["t_s"].to_numpy())
    assert np.array_equal(a["est_t_s"][idx], rec["t_s"].to_numpy())
    got = {"t_s": a["est_t_s"], "lat_rad": a["est_lat_rad"], "lon_rad": a["est_lon_rad"], "h_m": a["est_h_m"],
           "v_n_mps": a["est_v_ned_mps"][:, 0], "v_e_mps": a["est_v_ned_mps"][:, 1],
           "v_d_mps": a["est_v_ned_mps"][:, 2], "roll_rad": a["est_roll_rad"],
           "pitch_rad": a["est_pitch_rad"],
           "yaw_rad": a["est_yaw_rad"]} | {f"cov_{i}_{j}": a["est_cov"][:, i, j] for i in range(9) for j in
                                           range(9)}
    for c in EST_COLS:
        assert np.array_equal(got[c][idx], rec[c].to_numpy()), c
    assert rep.summary["horizontal_error_rms_m"] == result.summary["horizontal_error_rms_m"]
    # a different navigator runs on the same frames (open loop)
    other = replay(path, "ins_tercom")
    assert other.summary["navigator"] == "ins_tercom" and other.summary["horizontal_error_rms_m"] < 100.0
    # the summary names the log's sensors the navigator does not read: the free INS reads no terrain sensor
    ins = replay(path, "ins")
    assert "ira" in ins.summary["unused_sensors"] and "ira" not in rep.summary["unused_sensors"]
    assert "imu" not in ins.summary["unused_sensors"]
    for bad in (-1, 2**63, 1.5, True):          # a seed is a 64-bit count, as the scenario's
        with pytest.raises(LogError, match=r"seed: .* is not a seed from 0 to 9223372036854775807"):
            replay(path, "ins", seed=bad)


def test_a_map_that_does_not_cover_the_log_is_refused(recorded, tmp_path, capsys):
    """A map elsewhere ran the whole replay off its grid and said 'completed'; it is refused by name with both
    spans, nothing written."""
    _, _, path, _ = recorded
    out = tmp_path / "out"
    assert cli.main(["replay", str(path), "--navigator", "pmf", "--map", "synthetic:rolling",
                     "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "map 'synthetic:rolling' does not cover the log's start (36." in err
    assert "it spans latitude 36.5000 to 36.7701 deg" in err and "Traceback" not in err and not out.exists()


def test_streamed_log_equals_the_in_memory_one(recorded):
    """The run's arrays are the same with the log streamed to disk; the sensor arrays log.npz held are
    read back from the log (SensorLog.arrays) bit for bit."""
    _, result, path, plain = recorded
    for k, v in plain.arrays.items():
        if not k.startswith("sensor_"):
            assert np.array_equal(v, result.arrays[k], equal_nan=True), k
    back = read_log(path).arrays()
    sensor_keys = [k for k in plain.arrays if k.startswith("sensor_")]
    assert sensor_keys and set(sensor_keys) <= set(back)
    for k in sensor_keys:
        assert np.array_equal(plain.arrays[k], back[k], equal_nan=True), k
    # pandas and numpy read the tables as they are
    imu = pd.read_parquet(path / "imu.parquet")
    assert list(imu.columns[:3]) == ["frame", "t_s", "f_x_mps2"] and np.all(np.diff(imu["t_s"]) > 0)


def test_frames_and_arrays_read_from_a_log_are_writable(recorded):
    """pyarrow reads single-chunk numeric columns as read-only zero-copy views; the reader hands the
    navigators writable arrays, the live loop's type, so a replay compiles no read-only specialisation of
    their numba kernels (a second compile of each, on first use)."""
    import dataclasses

    from trn_env.logs.format import SENSORS
    _, _, path, _ = recorded
    log = read_log(path)
    # the premise, so that this test exercises the copy: pyarrow hands out a read-only view here (if a newer
    # pyarrow hands out writable arrays, the copy in reader._writable is no longer needed)
    assert not log.arrow("imu").column("t_s").to_numpy().flags.writeable, "pyarrow's column is writable"
    seen = 0
    for frames in log.frames():
        for s in SENSORS:
            frame = getattr(frames, s)
            if frame is None:
                continue
            for f in dataclasses.fields(frame):
                v = getattr(frame, f.name)
                if isinstance(v, np.ndarray) and v.size:
                    assert v.flags.writeable, (s, f.name)
                    seen += 1
    assert seen > 100
    for k, v in log.arrays().items():
        assert v.flags.writeable, k


def test_fly_writes_a_replayable_log_folder(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli.main(["fly", str(SCEN / "default_short.toml"), "--out", str(out), "--quiet", "--duration", "4",
                     "--no-plots"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "log" in summary["files"] and "log.npz" in summary["files"]
    npz = np.load(out / "log.npz")          # the per-update arrays; the sensor arrays are in log/
    assert "err_ned_m" in npz and not [k for k in npz.files if k.startswith("sensor_")]
    log = read_log(out / "log")
    assert log.n_frames == 4 and len(log.truth()) == 5            # t = 0 and each 1 s update
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]     # no partial folder left
    rep = tmp_path / "replayed"
    assert cli.main(["replay", str(out / "log"), "--out", str(rep), "--no-plots"]) == 0
    s2 = json.loads((rep / "summary.json").read_text())
    assert s2["horizontal_error_rms_m"] == pytest.approx(summary["horizontal_error_rms_m"], rel=0, abs=0)
    assert pd.read_parquet(rep / "log" / "estimates.parquet").shape[0] == 5
    capsys.readouterr()
    # trn-env record of the same flight writes the same log (the estimates to the last bit)
    assert cli.main(["record", str(SCEN / "default_short.toml"), "--out", str(tmp_path / "rec"), "--quiet",
                     "--duration", "4"]) == 0
    assert "recorded" in capsys.readouterr().out
    a, b = read_log(tmp_path / "rec").estimates(), log.estimates()
    assert a.equals(b) and read_log(tmp_path / "rec").table("imu").equals(log.table("imu"))


# ---------------------------------------------------------------------------------------------- bad input

def _builder(**kw):
    args = dict(map="jacksboro", imu_sample="rate", height_datum={"reference": "msl"},
                lever_arms_m={"radar_altimeter": [0.0, 0.0, 0.0]}, sensors={"imu": {"rate_hz": 100.0}})
    return LogBuilder(**(args | kw))


def _imu(n=300, dt=0.01):
    t = 0.01 + dt * np.arange(n)
    return {"t_s": t, "f_x_mps2": np.zeros(n), "f_y_mps2": np.zeros(n), "f_z_mps2": np.full(n, -9.8),
            "omega_x_rps": np.zeros(n), "omega_y_rps": np.zeros(n), "omega_z_rps": np.zeros(n)}


@pytest.mark.parametrize("make, words", [
    (lambda: _builder(height_datum={}), "height_datum is not stated"),
    (lambda: _builder(height_datum={"reference": "ellipsoid"}), "geoid_offset_m"),
    (lambda: _builder(height_datum={"reference": "ellipsoid", "geoid_model": "EGM96"}), "geoid models"),
    (lambda: _builder(imu_sample=None).add("imu", _imu()), "IMU sample convention is not stated"),
    (lambda: _builder(imu_sample="averaged"), "imu_sample must be one of"),
    (lambda: _builder(lever_arms_m={}).add("radar_altimeter", {"t_s": [1.0], "range_m": [100.0]}),
     "lever arm is not stated"),
    (lambda: _builder().add("imu", {k: v for k, v in _imu().items() if k != "f_y_mps2"}),
     "missing column 'f_y'"),
    (lambda: _builder().add("imu", {**{k: v for k, v in _imu().items() if k != "f_x_mps2"},
                                    "f_x": np.zeros(300)}), "column 'f_x' has no unit"),
    (lambda: _builder().add("imu", {**{k: v for k, v in _imu().items() if k != "f_x_mps2"},
                                    "f_x": np.zeros(300)}, units={"f_x": "furlongs"}),
     "unknown unit 'furlongs'"),
    (lambda: _builder().add("imu", _imu() | {"t_s": np.r_[0.01 * np.arange(1, 150),
                                                          0.01 * np.arange(148, 299)]}),
     "time must increase"),
    (lambda: _builder().add("imu", _imu() | {"f_z_mps2": np.r_[np.full(10, -9.8), np.nan,
                                                               np.full(289, -9.8)]}),
     "NaN or infinite at row 10"),
    (lambda: _builder().add("imu", _imu() | {"t_s": np.r_[0.01 * np.arange(1, 151),
                                                          2.0 + 0.01 * np.arange(150)]}),
     "a gap of"),
    (lambda: _builder().add("imu", _imu() | {"valid": np.r_[np.ones(100, bool), np.zeros(5, bool),
                                                            np.ones(195, bool)]}),
     r"imu: a gap of 0.06 s after t = 1 s .* \(or samples marked invalid\)"),
    (lambda: _builder().add("imu", _imu(dt=0.02)), "stated rate_hz 100"),
    (lambda: _builder().add("lidar", {}), "unknown sensor 'lidar'"),
    # a second table replaced the first without a word (chunks added one by one kept only the last)
    (lambda: _builder().add("imu", _imu()).add("imu", _imu()), "imu: added already"),
    # datetimes became nanosecond counts ("the samples come every 1e+07 s"); a list had no .keys()
    (lambda: _builder().add("imu", pd.DataFrame(_imu()).assign(t_s=lambda d: pd.to_datetime(d.t_s,
                                                                                             unit="s"))),
     r"column 't_s' holds dates and times \(datetime64\[ns\]\): give seconds as numbers"),
    (lambda: _builder().add("imu", pd.DataFrame(_imu()).assign(t_s=lambda d: pd.to_timedelta(d.t_s,
                                                                                              unit="s"))),
     r"column 't_s' holds durations"),
    (lambda: _builder().add("imu", [1.0, 2.0]), "imu: give a pandas DataFrame, a mapping of column names to "
                                                "arrays or a numpy structured array, got list"),
    # degrees stated as radians, a negative range: flown before, kilometres off
    (lambda: _builder().add("gnss", {"t_s": [1.0, 2.0], "lat": [36.5, 36.5], "lon_deg": [-84.3, -84.3],
                                     "h_m": [2000.0] * 2, "v_n_mps": [0.0] * 2, "v_e_mps": [0.0] * 2,
                                     "v_d_mps": [0.0] * 2}, units={"lat": "rad"}),
     r"gnss: column 'lat' = 36.5 rad at row 0 \(t = 1 s\) is not a latitude in radians"),
    (lambda: _builder().add("radar_altimeter", {"t_s": [1.0, 2.0], "range_m": [100.0, -3.0]}),
     r"radar_altimeter: column 'range' = -3 m at row 1 \(t = 2 s\) is not a range in metres"),
    (lambda: _builder().add_truth({"t_s": [0.0, 4.0], "lat_rad": [36.5, 36.5], "lon_deg": [-84.3, -84.3],
                                   "h_m": [2000.0] * 2, "v_n_mps": [0.0] * 2, "v_e_mps": [0.0] * 2,
                                   "v_d_mps": [0.0] * 2, "roll_rad": [0.0] * 2, "pitch_rad": [0.0] * 2,
                                   "yaw_rad": [0.0] * 2}),
     r"truth: column 'lat' = 36.5 rad at row 0 \(t = 0 s\) is not a latitude in radians"),
    # a time column with a unit the builder did not know was 'missing' although named t_<unit>; a count of
    # nanoseconds stated as seconds was taken for a flight 5e10 years long
    (lambda: _builder().add("imu", {**{k: v for k, v in _imu().items() if k != "t_s"},
                                    "t_min": np.arange(300) / 6000.0}),
     r"imu: column 't_min': unknown unit 'min' for a s quantity \(name it t_<unit> with one of s, ms, us, "
     r"ns\)"),
    (lambda: _builder().add("imu", _imu() | {"t_s": np.round((1.7e9 + _imu()["t_s"]) * 1e9)}),
     r"imu: time t = 1.7e\+18 s at row 0 is not a time in seconds \(within \+-1e11 s; "
     r"microseconds or nanoseconds\? name the column t_us or t_ns\)"),
], ids=["datum", "geoid-offset", "geoid-model", "imu-convention", "imu-convention-word", "lever-arm",
        "missing-column", "no-unit", "unknown-unit", "time", "nan", "imu-gap", "imu-invalid", "rate",
        "sensor", "twice", "datetime", "timedelta", "list", "degrees-as-radians", "negative-range",
        "truth-degrees", "time-unit", "nanoseconds-as-seconds"])
def test_builder_refuses_bad_input_with_the_field(make, words):
    with pytest.raises(LogError, match=words):
        make()


def test_builder_reads_time_in_microseconds_and_nanoseconds_since_an_epoch(tmp_path):
    """Integer microsecond and nanosecond counts since the Unix epoch (a ROS bag's stamps) give the same
    log as seconds."""
    truth = {"t_s": [0.0, 4.0], "lat_deg": [36.5, 36.5], "lon_deg": [-84.3, -84.3], "h_m": [2000.0] * 2,
             "v_n_mps": [0.0] * 2, "v_e_mps": [0.0] * 2, "v_d_mps": [0.0] * 2, "roll_rad": [0.0] * 2,
             "pitch_rad": [0.0] * 2, "yaw_rad": [0.0] * 2}
    epoch_s = 1_700_000_000
    logs = {}
    for unit, per_s in (("s", 1), ("us", 10**6), ("ns", 10**9)):
        imu, tr = _imu(), dict(truth)
        t_imu = np.round(imu.pop("t_s") * 100).astype(np.int64)          # hundredths of a second
        t_tr = np.round(np.asarray(tr.pop("t_s")) * 100).astype(np.int64)
        imu[f"t_{unit}"] = (epoch_s * 100 + t_imu) * (per_s // 100) if per_s > 1 else epoch_s + t_imu / 100
        tr[f"t_{unit}"] = (epoch_s * 100 + t_tr) * (per_s // 100) if per_s > 1 else epoch_s + t_tr / 100
        logs[unit] = read_log(_builder().add("imu", imu).add_truth(tr).write(tmp_path / unit))
    for unit in ("us", "ns"):              # the same to float64's resolution at 1.7e9 s (2.4e-7 s)
        for a, b in ((logs[unit].table("imu"), logs["s"].table("imu")),
                     (logs[unit].truth(), logs["s"].truth())):
            np.testing.assert_allclose(a["t_s"], b["t_s"], rtol=0.0, atol=5e-7)
            assert a.drop(columns="t_s").equals(b.drop(columns="t_s")), unit
    assert logs["ns"].table("imu")["t_s"].iloc[0] == pytest.approx(epoch_s + 0.01, abs=1e-6)
    assert logs["ns"].n_frames == logs["s"].n_frames == 3


def test_builder_takes_a_numpy_structured_array_as_a_dataframe(tmp_path):
    imu = pd.DataFrame(_imu())
    records = imu.to_records(index=False)
    a = _builder().add("imu", imu).tables["imu"]
    b = _builder().add("imu", records).tables["imu"]
    assert set(a) == set(b) and all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a)


def test_builder_converts_units_and_nan_in_invalid_samples_is_allowed(tmp_path):
    b = _builder()
    imu = pd.DataFrame(_imu())
    imu = imu.rename(columns={"omega_z_rps": "omega_z"})
    imu["omega_z"] = 3600.0          # deg/h
    b.add("imu", imu, units={"omega_z": "deg/h"})
    ra = {"t_s": [0.5, 1.0, 1.5], "range_ft": [1000.0, np.nan, 1010.0],
          "valid": np.array([True, False, True])}
    b.add("radar_altimeter", ra)
    with pytest.raises(LogError, match="no initial estimate"):
        b.write(tmp_path / "x")
    assert not (tmp_path / "x").exists() and not list(tmp_path.iterdir())
    b.add_truth({"t_s": [0.0, 4.0], "lat_deg": [36.5, 36.5], "lon_deg": [-84.3, -84.3], "h_m": [2000.0] * 2,
                 "v_n_mps": [0.0] * 2, "v_e_mps": [0.0] * 2, "v_d_mps": [0.0] * 2, "roll_rad": [0.0] * 2,
                 "pitch_rad": [0.0] * 2, "yaw_rad": [0.0] * 2})
    with pytest.raises(LogError, match="truth: added already"):
        b.add_truth({"t_s": [0.0, 1.0], "lat_deg": [36.5] * 2, "lon_deg": [-84.3] * 2, "h_m": [2000.0] * 2,
                     "v_n_mps": [0.0] * 2, "v_e_mps": [0.0] * 2, "v_d_mps": [0.0] * 2, "roll_rad": [0.0] * 2,
                     "pitch_rad": [0.0] * 2, "yaw_rad": [0.0] * 2})
    log = read_log(b.write(tmp_path / "x"))
    assert log.truth()["t_s"].iloc[-1] == 4.0                        # the first truth table, kept whole
    imu_back = log.table("imu")
    assert np.allclose(imu_back["omega_z_rps"], np.radians(1.0) / 1.0)          # 3600 deg/h = 1 deg/s
    ra_back = log.table("radar_altimeter")
    assert ra_back["range_m"].iloc[0] == pytest.approx(304.8) and np.isnan(ra_back["range_m"].iloc[1])
    assert log.truth()["lat_rad"].iloc[0] == pytest.approx(np.radians(36.5))
    assert log.n_frames == 3                                      # 0.01 .. 3.00 s in 1 s intervals


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    b = _builder()
    b.add("imu", _imu())
    b.add_truth({"t_s": [0.0, 4.0], "lat_deg": [36.5, 36.5], "lon_deg": [-84.3, -84.3], "h_m": [2000.0] * 2,
                 "v_n_mps": [0.0] * 2, "v_e_mps": [0.0] * 2, "v_d_mps": [0.0] * 2, "roll_rad": [0.0] * 2,
                 "pitch_rad": [0.0] * 2, "yaw_rad": [0.0] * 2})
    return b.write(tmp_path_factory.mktemp("small") / "small")


def _damaged(small_log, tmp_path, how):
    p = tmp_path / "damaged"
    shutil.copytree(small_log, p)
    meta = json.loads((p / "metadata.json").read_text())
    if how == "newer":
        meta["format_version"] = FORMAT_VERSION + 1
    elif how == "incomplete":
        meta["complete"] = False
    elif how == "count":
        meta["tables"]["imu"] += 1
    elif how == "no-convention":
        meta.pop("imu_sample")
    elif how == "truncated":
        data = (p / "imu.parquet").read_bytes()
        (p / "imu.parquet").write_bytes(data[: len(data) // 2])
    elif how == "corrupt-json":
        (p / "metadata.json").write_text('{"format": "trn-env sensor log", "format_ver')
        return p
    elif how == "missing-table":
        (p / "frames.parquet").unlink()
    (p / "metadata.json").write_text(json.dumps(meta))
    return p


@pytest.mark.parametrize("how, words", [
    ("newer", "newer than this trn-env reads"), ("incomplete", "did not finish"),
    ("count", "rows, the metadata"),
    ("no-convention", "imu_sample is not stated"), ("truncated", "corrupt or truncated"),
    ("corrupt-json", "corrupt or truncated"), ("missing-table", "is missing"),
])
def test_reader_refuses_damaged_logs(small_log, tmp_path, how, words):
    with pytest.raises(LogError, match=words):
        read_log(_damaged(small_log, tmp_path, how))


def _set_column(log: Path, table: str, column: str, change) -> None:
    """Rewrite one column of a log's table: change(values) -> new values (any type pyarrow takes)."""
    import pyarrow as pa
    t = pq.read_table(log / f"{table}.parquet")
    i = t.column_names.index(column)
    pq.write_table(t.set_column(i, column, pa.array(change(t.column(column).to_numpy().copy()))),
                   log / f"{table}.parquet")


def _degrees(a):
    return np.degrees(a)


def _negate_one(a):
    a[7] = -abs(a[7]) - 1.0
    return a


def _nan_at_3(a):
    a[3] = np.nan
    return a


def _last_of_frame_4_in_5(a):
    a[int(np.flatnonzero(a == 4)[-1])] = 5
    return a


@pytest.mark.parametrize("table, column, change, words", [
    # a column of the wrong kind was read silently wrong (any non-empty text is true) or failed deep inside
    ("baro", "h_baro_m", lambda a: a.astype(str), "column h_baro_m holds string values; the format's are "
                                                  "numbers (float64)"),
    ("baro", "valid", lambda a: np.where(a, "yes", "no"), "column valid holds string values; the format's "
                                                          "are true / false (bool)"),
    ("imu", "frame", lambda a: a + 0.5, "column frame holds double values; the format's are whole numbers"),
    ("frames", "gnss_present", lambda a: a.astype(np.int64), "column gnss_present holds int64 values"),
    ("estimates", "cov_0_0", lambda a: a.astype(str), "column cov_0_0 holds string values"),
    ("truth", "h_m", lambda a: a.astype(str), "column h_m holds string values"),
    # a unit or sign slip was flown: degrees as radians gave kilometres of error and an ANEES of millions
    ("gnss", "lat_rad", _degrees, "gnss.parquet: column lat_rad = 36.4"),
    ("truth", "lon_rad", _degrees, "truth.parquet: column lon_rad = -84.3"),
    ("estimates", "lat_rad", _degrees, "estimates.parquet: column lat_rad = 36.4"),
    ("ira", "range_m", _negate_one, "ira.parquet: column range_m = -"),
    # NaN truth left a hole in the metrics
    ("truth", "lat_rad", _nan_at_3,
     "truth.parquet: column lat_rad is NaN or infinite at row 3 (drop the row)"),
    # a sample given the next frame was handed to the navigator in the wrong interval
    ("imu", "frame", _last_of_frame_4_in_5, "is in frame 5, whose interval is"),
    # samples of a frame whose sensor is marked absent were dropped
    ("frames", "baro_present", lambda a: np.r_[a[:2], False, a[3:]],
     "baro.parquet: row 20 is in frame 2, where frames.parquet's baro_present is false"),
    # IMU samples marked invalid are held over: a whole log of them flew 257 m off, "completed"
    ("imu", "valid", lambda a: np.zeros_like(a),
     "imu.parquet: no valid IMU sample for 12 s after t = 0.01 s"),
    ("imu", "valid", lambda a: np.r_[a[:300], np.zeros(2, bool), a[302:]],
     "imu.parquet: no valid IMU sample for 0.03 s after t = 3 s (median interval 0.01 s)"),
], ids=["text-number", "text-flag", "float-frame", "int-flag", "text-estimate", "text-truth", "gnss-degrees",
        "truth-degrees", "estimate-degrees", "negative-range", "nan-truth", "wrong-frame", "absent-sensor",
        "imu-all-invalid", "imu-invalid-stretch"])
def test_reader_refuses_tables_a_navigator_would_misread(recorded, tmp_path, table, column, change, words):
    """What a log from someone's own data can get wrong in its tables, each refused naming the table, the
    column and the fix; the recorded log itself passes, and so did every case here before."""
    log = tmp_path / "log"
    shutil.copytree(recorded[2], log)
    read_log(log)
    _set_column(log, table, column, change)
    with pytest.raises(LogError, match=re.escape(words)):
        read_log(log)


def test_one_invalid_imu_sample_is_bridged(recorded, tmp_path):
    """One invalid sample leaves 0.02 s between valid ones, within IMU_MAX_GAP_INTERVALS (2.5) x 0.01 s,
    as one missing sample is in the builder: accepted; two are refused (the parametrised case above)."""
    log = tmp_path / "log"
    shutil.copytree(recorded[2], log)
    _set_column(log, "imu", "valid", lambda a: np.r_[a[:300], np.zeros(1, bool), a[301:]])
    read_log(log)


def test_an_initial_estimate_in_degrees_is_refused(recorded, tmp_path):
    p = tmp_path / "deg"
    shutil.copytree(recorded[2], p)
    meta = json.loads((p / "metadata.json").read_text())
    meta["initial_estimate"]["lat_rad"] = 36.5
    (p / "metadata.json").write_text(json.dumps(meta))
    words = "initial_estimate.lat_rad = 36.5 is not a latitude in radians (-pi/2 .. pi/2; degrees?)"
    with pytest.raises(LogError, match=re.escape(words)):
        read_log(p).initial_estimate()


def test_cli_bad_input_exits_2_and_writes_nothing(small_log, tmp_path, capsys):
    bad = _damaged(small_log, tmp_path, "newer")
    out = tmp_path / "out"
    assert cli.main(["replay", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "newer" in err and "Traceback" not in err and not out.exists()
    # a navigator that needs a sensor the log lacks (acq_track: the radar altimeter and the barometer)
    assert cli.main(["replay", str(small_log), "--navigator", "acq_track", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "'acq_track' needs" in err and "radar_altimeter" in err and not out.exists()
    # pmf declares the IRA: refused on an IMU-only log
    assert cli.main(["replay", str(small_log), "--navigator", "pmf", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "'pmf' needs" in err and "ira" in err and not out.exists()
    assert cli.main(["replay", str(tmp_path / "nowhere"), "--out", str(out)]) == 2
    assert "no such folder" in capsys.readouterr().err
    # record refuses a non-empty --out before flying
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "x").write_text("x")
    assert cli.main(["record", str(SCEN / "default_short.toml"), "--out", str(busy), "--quiet"]) == 2
    assert "not an empty folder" in capsys.readouterr().err
    assert sorted(p.name for p in busy.iterdir()) == ["x"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


# ------------------------------------------------------------------------------- an independent log

@pytest.fixture(scope="module")
def independent(tmp_path_factory):
    return ref.build(tmp_path_factory.mktemp("ind") / "ind.trnlog", duration_s=150.0)


def _check(summary, rms_max_m):
    """Accuracy and consistency of one replay: horizontal RMS below its bound, each of north and east
    inside 3 sigma at >= 85 % of the 1 Hz epochs (a consistent filter: 99.7 %; the margin covers the
    epochs' correlation over a single 150 s flight), ANEES below 3x its 3-dof ideal."""
    assert summary["termination"] == "completed"
    assert summary["horizontal_error_rms_m"] < rms_max_m, summary["horizontal_error_rms_m"]
    assert summary["fraction_within_3sigma"] >= 0.85, summary["fraction_within_3sigma"]
    assert summary["anees"] < 9.0, summary["anees"]


def test_independent_log_pmf_and_the_datum_and_lever_arms_matter(independent, tmp_path):
    """pmf on the independent log: accurate and consistent; read as MSL heights (the geoid offset
    ignored: 31 m), it is not; without the lever arms its vertical error grows."""
    good = replay(independent, "pmf").summary
    _check(good, 10.0)
    wrong = tmp_path / "msl"
    shutil.copytree(independent, wrong)
    meta = json.loads((wrong / "metadata.json").read_text())
    meta["height_datum"] = {"reference": "msl"}
    (wrong / "metadata.json").write_text(json.dumps(meta))
    bad = replay(wrong, "pmf").summary
    assert bad["horizontal_error_rms_m"] > 3.0 * good["horizontal_error_rms_m"]
    meta["height_datum"] = {"reference": "ellipsoid", "geoid_offset_m": ref.GEOID_N_M}
    meta["lever_arms_m"] = {"ira": [0.0, 0.0, 0.0], "radar_altimeter": [0.0, 0.0, 0.0]}
    (wrong / "metadata.json").write_text(json.dumps(meta))
    no_arm = replay(wrong, "pmf").summary
    assert no_arm["vertical_error_rms_m"] > good["vertical_error_rms_m"] + 0.3


@pytest.mark.slow
@pytest.mark.parametrize("navigator, rms_max_m", [("ins", 20.0), ("ins_tercom", 15.0), ("pf", 15.0),
                                                  ("rbpf", 10.0), ("acq_track", 30.0)])
def test_independent_log_each_navigator(independent, navigator, rms_max_m):
    _check(replay(independent, navigator).summary, rms_max_m)


def test_independent_log_reads_in_the_navigators_conventions(independent):
    """The reader turns the log's increments into rates and its ellipsoid heights into MSL ones."""
    log = read_log(independent)
    frames = next(log.frames())
    raw = log.table("imu")
    n = frames.imu.t_s.shape[0]
    assert np.allclose(frames.imu.f_b_mps2[1:, 0], raw["dv_x_mps"].to_numpy()[1:n] / 0.01, rtol=1e-9)
    truth = log.truth()
    assert np.allclose(truth["h_m"].to_numpy(), pq.read_table(independent / "truth.parquet").column(
        "h_m").to_numpy() - ref.GEOID_N_M)


def test_a_campaign_replays_logs_across_navigators_and_seeds(independent, tmp_path, capsys):
    """`logs = [...]` in a campaign file: every (log, navigator, sweep point) at every navigator seed, one
    row each; pmf is deterministic (equal rows over seeds), pf draws from the seed; a row's replay_command
    gives its numbers again."""
    import shlex

    from trn_env.campaign.rows import read_rows
    camp = tmp_path / "logs.toml"
    camp.write_text(f'name = "log_replay"\nlogs = ["{independent}"]\nseeds = [1, 2]\n'
                    'navigators = ["pmf", { name = "pf", label = "pf_small", '
                    'settings = { n_particles = 2000 } }]\n')
    out = tmp_path / "camp"
    assert cli.main(["campaign", str(camp), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    df = read_rows(out)
    assert len(df) == 4 and set(df["termination"]) == {"completed"}
    pmf = df[df["navigator"] == "pmf"]["horizontal_error_rms_m"].to_numpy()
    pf = df[df["navigator"] == "pf_small"]["horizontal_error_rms_m"].to_numpy()
    assert pmf[0] == pmf[1] and pf[0] != pf[1] and np.all(np.r_[pmf, pf] < 15.0)
    row = df[df["navigator"] == "pf_small"].iloc[0]
    argv = shlex.split(row["replay_command"])
    assert argv[:2] == ["trn-env", "replay"]
    assert cli.main(argv[1:] + ["--out", str(tmp_path / "one"), "--no-plots"]) == 0
    one = json.loads((tmp_path / "one" / "summary.json").read_text())
    assert one["horizontal_error_rms_m"] == row["horizontal_error_rms_m"]
    bad = tmp_path / "bad.toml"
    bad.write_text('logs = ["nowhere.trnlog"]\nnavigators = ["pmf", "acq_track"]\n'
                   '[[sweeps]]\npath = "wind.layers.0.speed_mps"\nvalues = [1.0]\n')
    assert cli.main(["campaign", str(bad), "--out", str(tmp_path / "c2"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "logs[0] (nowhere.trnlog)" in err and "sweeps[0].path" in err and not (tmp_path / "c2").exists()


def test_a_log_campaign_file_is_checked_as_a_flight_campaigns(tmp_path):
    """A log campaign's file against its schema (the flight campaign's keys), before any log is read: a bad
    grid was a traceback (KeyError, numpy's errors without the field; num = 1e9 tried to allocate 7 GB), a
    repeated sweep point or seed flew its runs twice."""
    from trn_env.campaign import load_campaign
    from trn_env.campaign.spec import CampaignError

    def problems(body: str) -> list[str]:
        f = tmp_path / "c.toml"
        f.write_text('name = "c"\nlogs = ["nowhere.trnlog"]\nnavigators = ["pmf"]\n' + body)
        with pytest.raises(CampaignError) as exc:
            load_campaign(f)
        return exc.value.problems

    sweep = '[[sweeps]]\npath = "navigator.settings.outlier_prob"\n'
    assert problems(sweep + "grid = { start = 0.0, num = 3 }\n") == [
        "sweeps[0].grid.stop: required key is missing"]
    assert problems(sweep + "grid = { start = 0.0, stop = 0.1, num = -1 }\n") == [
        "sweeps[0].grid.num: -1 is less than the minimum of 1"]
    assert problems(sweep + 'grid = { start = 0.0, stop = 0.1, num = "x" }\n') == [
        "sweeps[0].grid.num: 'x' is not of type 'integer'"]
    big = problems("seeds = [0, 1]\n" + sweep + "grid = { start = 0.0, stop = 0.1, num = 1000000000 }\n")
    assert big[0].startswith("sweeps[0]: the campaign asks for 2,000,000,000 runs (2 seeds x 1 logs x 1 "
                             "navigators x 1,000,000,000 points of sweeps[0])")
    assert problems("seeds = [3, 3]\n") == ["seeds: [3, 3] has non-unique elements"]
    repeated = problems(sweep + "values = [0.01, 0.02, 0.01]\n")
    assert "sweeps[0].values: 0.01 (point 2) repeats point 0: give each value once" in repeated
    assert problems("bogus = 1\n")[0].startswith("bogus: unknown key")


def test_a_log_written_meanwhile_into_the_same_path_is_kept(tmp_path):
    """Two recordings to one --out: the one that finishes second is refused by name at its commit and the
    first one's log stays whole (the old commit failed in rmdir with an OSError traceback)."""
    from trn_env.logs.writer import LogWriter

    out = tmp_path / "same.trnlog"
    first, second = LogWriter(out, {"who": "first"}), LogWriter(out, {"who": "second"})
    first.commit()
    with pytest.raises(LogError, match="another log was written there while this one was being recorded"):
        second.commit()
    second.abort()
    assert json.loads((out / "metadata.json").read_text())["who"] == "first"
    assert [p.name for p in tmp_path.iterdir()] == ["same.trnlog"]


def test_a_run_folder_given_as_a_log_names_its_log(tmp_path, capsys):
    """`trn-env replay runs/X` (a fly run folder) points at `runs/X/log` instead of 'not a trn-env log'."""
    run = tmp_path / "run"
    (run / "log").mkdir(parents=True)
    (run / "log" / "metadata.json").write_text("{}")
    (run / "summary.json").write_text("{}")
    assert cli.main(["replay", str(run), "--navigator", "pf", "--out", str(tmp_path / "out")]) == 2
    assert f"a run folder, not a log; its log is {run / 'log'}" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_replay_of_a_run_folders_log_is_named_after_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["fly", "--out", "flight1", "--duration", "5", "--no-plots", "--quiet"]) == 0
    assert cli.main(["replay", "flight1/log", "--navigator", "ins", "--no-plots"]) == 0
    assert [p.name.rsplit("-", 1)[0] for p in (tmp_path / "runs").iterdir()] == ["replay-flight1"]


def test_a_log_path_where_nothing_can_be_made_is_named(tmp_path):
    """A read-only or pseudo file system (here /proc): LogError naming the log, not the temporary folder's
    FileNotFoundError."""
    from trn_env.logs.writer import LogWriter

    with pytest.raises(LogError, match=r"log /proc/trn_env_log: cannot create it in /proc"):
        LogWriter(Path("/proc/trn_env_log"), {})
