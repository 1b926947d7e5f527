"""The closed loop's log: per-update truth rows and estimates, full-rate sensor frames, events; assembled into
arrays once at the end of a run (`SimLog.arrays`).

In memory by default. Given a `sink` (trn_env.logs.writer.LogWriter, handed down by the stage above: sim
does not import logs), the frames go to the sink as they come and the tick rows every `flush_ticks` ticks,
so the memory of a run stays flat whatever its length; `arrays()` then reads the ticks back from the sink
and leaves the sensor arrays on disk (trn_env.logs.read_log reads them), and `est_cov` too: it is a
trn_env.output.chunked.ChunkedRows read from the log a row group at a time by the consumers that walk the
whole flight (the metrics, log.npz), so the end of a long run does not hold the 9 x 9 covariances whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import trn_env.scenario.build as components
from trn_env.flight.truth import TruthChunk
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.integrity.protection_level import EXTRA_PROTECTION_LEVEL
from trn_env.navigators.protocol import Estimate
from trn_env.output.chunked import diagonals
from trn_env.sim.nav_stage import gnss_available_mask
from trn_env.terrain.geodesy import lon_difference_rad, meridian_radius_m, prime_vertical_radius_m

_TRUTH_LOGGED = ("lat_rad", "lon_rad", "h_msl_m", "v_ned_mps", "roll_rad", "pitch_rad", "yaw_rad", "tas_mps",
                 "alpha_rad", "beta_rad", "wind_ned_mps")
# columns of SimLog.truth_rows: t_s, then _TRUTH_LOGGED with the vectors' three components
_TRUTH_ROW = ("t_s", "lat_rad", "lon_rad", "h_msl_m", "v_n", "v_e", "v_d", "roll_rad", "pitch_rad", "yaw_rad",
              "tas_mps", "alpha_rad", "beta_rad", "wind_n", "wind_e", "wind_d")


# nav_status_code in the arrays: the index of the estimate's Health.status here (len: any other word)
NAV_STATUS_CODES = ("ok", "acquiring", "degraded", "diverged", "free_inertial", "lost", "inconsistent")


@dataclass
class SimLog:
    """In-memory log: per-tick truth rows and estimates, full-rate sensor readings, events.

    The per-tick work is appending tuples of the truth row's and the estimate's numbers (the truth chunk
    itself is not kept, so its memory is reused); arrays are assembled once, in `arrays()`.
    """

    truth_rows: list[tuple] = field(default_factory=list)
    est_rows: list[tuple] = field(default_factory=list)
    frames: list[SensorFrames] = field(default_factory=list)
    events: list[tuple[float, str, str]] = field(default_factory=list)
    sink: object = None          # a LogWriter: write_frames, write_ticks, read_ticks (module docstring)
    flush_ticks: int = 600

    def add_tick(self, truth: TruthChunk, i: int, est: Estimate) -> None:
        v, w = truth.v_ned_mps, truth.wind_ned_mps
        # row values in _TRUTH_ROW order
        self.truth_rows.append((truth.t_s[i], truth.lat_rad[i], truth.lon_rad[i], truth.h_msl_m[i],
                                v[i, 0], v[i, 1], v[i, 2], truth.roll_rad[i], truth.pitch_rad[i],
                                truth.yaw_rad[i], truth.tas_mps[i], truth.alpha_rad[i], truth.beta_rad[i],
                                w[i, 0], w[i, 1], w[i, 2]))
        self.est_rows.append((float(est.t_s), float(est.lat_rad), float(est.lon_rad), float(est.h_m),
                              np.array(est.v_ned_mps, float), float(est.roll_rad), float(est.pitch_rad),
                              float(est.yaw_rad), np.array(est.covariance[:9, :9], float),
                              bool(est.health.ok), str(est.health.status),
                              float(est.extra.get(EXTRA_PROTECTION_LEVEL, np.nan))))
        if self.sink is not None and len(self.truth_rows) >= self.flush_ticks:
            self.flush()

    def add_frames(self, frames: SensorFrames) -> None:
        if self.sink is not None:
            self.sink.write_frames(frames)
        else:
            self.frames.append(frames)

    def _columns(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The buffered ticks: truth rows (n, 16) in _TRUTH_ROW order and the estimate columns
        (t_s, lat_rad, lon_rad, h_m, v_n_mps, v_e_mps, v_d_mps, roll_rad, pitch_rad, yaw_rad, cov_i_j,
        nav_ok, nav_status_code, hpl_m)."""
        rows = np.array(self.truth_rows, float).reshape(-1, len(_TRUTH_ROW))
        n = len(self.est_rows)
        cols = list(zip(*self.est_rows, strict=True)) if n else [[]] * 12
        est = {name: np.array(cols[i], float) for i, name in enumerate(("t_s", "lat_rad", "lon_rad", "h_m"))}
        v = np.array(cols[4], float).reshape(n, 3)
        est |= {"v_n_mps": v[:, 0].copy(), "v_e_mps": v[:, 1].copy(), "v_d_mps": v[:, 2].copy()}
        for i, name in enumerate(("roll_rad", "pitch_rad", "yaw_rad")):
            est[name] = np.array(cols[5 + i], float)
        cov = np.array(cols[8], float).reshape(n, 9, 9)
        est |= {f"cov_{i}_{j}": cov[:, i, j].copy() for i in range(9) for j in range(9)}
        est["nav_ok"] = np.array(cols[9], bool)
        est["nav_status_code"] = np.array([NAV_STATUS_CODES.index(x) if x in NAV_STATUS_CODES
                                           else len(NAV_STATUS_CODES) for x in cols[10]], np.int8)
        est["hpl_m"] = np.array(cols[11], float)
        return rows, est

    def flush(self) -> None:
        """Hand the buffered ticks to the sink."""
        if self.sink is not None and self.truth_rows:
            rows, est = self._columns()
            self.sink.write_ticks(rows, est)
            self.truth_rows.clear()
            self.est_rows.clear()

    def sensor_arrays(self) -> dict[str, np.ndarray]:
        """sensor_<sensor>_<field>: every logged frame's arrays, concatenated per sensor and field."""
        parts: dict[str, list] = {}
        for frames in self.frames:
            for name in ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading"):
                fr = getattr(frames, name)
                if fr is None:
                    continue
                for k, v in vars(fr).items():
                    if isinstance(v, np.ndarray):
                        parts.setdefault(f"sensor_{name}_{k}", []).append(v)
        return {k: np.concatenate(v) for k, v in parts.items()}

    def arrays(self, world_dem, outages) -> dict[str, np.ndarray]:
        """Every logged quantity as arrays: t_s, true_*, est_*, err_ned_m (estimate - truth, NED at the true
        position), gnss_available, nav_ok, est_hpl_m (the navigator's horizontal protection level, NaN
        where it published none), and sensor_<sensor>_<field> at the sensors' own rates."""
        out: dict[str, np.ndarray] = {}
        if self.sink is not None:
            self.flush()
            truth, est = self.sink.read_ticks()          # (columns read back one at a time)
        else:
            rows, est = self._columns()
            truth = [rows[:, i].copy() for i in range(len(_TRUTH_ROW))]
            del rows
        n = truth[0].shape[0]
        out["t_s"] = truth[0]
        col = 1
        for name in _TRUTH_LOGGED:
            width = 3 if name in ("v_ned_mps", "wind_ned_mps") else 1
            out[f"true_{name}"] = np.column_stack(truth[col:col + width]) if width == 3 else truth[col]
            col += width
        del truth
        h_ground = components.world_height(world_dem, out["true_lat_rad"], out["true_lon_rad"])
        out["true_h_agl_m"] = out["true_h_msl_m"] - h_ground
        if not est:
            est = self._columns()[1]
        for name, key in (("est_t_s", "t_s"), ("est_lat_rad", "lat_rad"), ("est_lon_rad", "lon_rad"),
                          ("est_h_m", "h_m")):
            out[name] = est[key]
        out["est_v_ned_mps"] = np.column_stack([est["v_n_mps"], est["v_e_mps"], est["v_d_mps"]]).reshape(n, 3)
        for name in ("roll_rad", "pitch_rad", "yaw_rad"):
            out[f"est_{name}"] = est[name]
        if "cov" in est:              # from the sink: read from disk in chunks (LogWriter.read_ticks)
            out["est_cov"] = est.pop("cov")
        else:
            out["est_cov"] = np.stack([est[f"cov_{i}_{j}"] for i in range(9) for j in range(9)],
                                      axis=-1).reshape(n, 9, 9)
        out["nav_ok"] = est["nav_ok"].astype(bool)
        out["nav_status_code"] = est["nav_status_code"].astype(np.int8)
        out["est_hpl_m"] = np.asarray(est["hpl_m"], float) if "hpl_m" in est else np.full(n, np.nan)
        out["est_cov_diag"] = diagonals(out["est_cov"])
        out["err_ned_m"] = error_ned_m(out["true_lat_rad"], out["true_lon_rad"], out["true_h_msl_m"],
                                       out["est_lat_rad"], out["est_lon_rad"], out["est_h_m"])
        out["gnss_available"] = gnss_available_mask(out["t_s"], outages)
        out.update(self.sensor_arrays())
        return out


def error_ned_m(lat_rad, lon_rad, h_m, est_lat_rad, est_lon_rad, est_h_m) -> np.ndarray:
    """Estimate minus truth, NED metres at the true position (seed 000 eq 2 small-offset radii)."""
    lat = np.asarray(lat_rad, float)
    r_n = np.array([meridian_radius_m(x) for x in lat]) + h_m
    r_e = np.array([prime_vertical_radius_m(x) for x in lat]) + h_m
    dn = (np.asarray(est_lat_rad) - lat) * r_n
    de = lon_difference_rad(est_lon_rad, lon_rad) * r_e * np.cos(lat)
    dd = -(np.asarray(est_h_m) - np.asarray(h_m))
    return np.stack([dn, de, dd], axis=-1).reshape(-1, 3)


