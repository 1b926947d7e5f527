"""The documented fields of a run's `summary.json` and of a campaign's Parquet rows.

One table per output, `name -> Field(unit, meaning)`: the docs' output reference is generated from these
tables, and tests check that every key a real run writes is documented here (so the reference cannot go
stale). A key written under a prefix (`sweep.<path>`, `series_<name>`) is documented once by its prefix.
"""

from __future__ import annotations

from typing import NamedTuple


class Field(NamedTuple):
    """One output field: its unit ("" for text, flags and counts) and a one-line meaning."""

    unit: str
    meaning: str


# Figures a run's navigation metrics add to both summary.json and a campaign row (trn_env.output.metrics).
METRIC_FIELDS: dict[str, Field] = {
    "horizontal_error_rms_m": Field("m", "RMS of the horizontal error |(e_n, e_e)| over the logged rows"),
    "vertical_error_rms_m": Field("m", "RMS of the vertical error (estimate minus truth, up positive)"),
    "horizontal_error_cep50_m": Field("m", "50th percentile of the horizontal error over the rows"),
    "horizontal_error_cep95_m": Field("m", "95th percentile of the horizontal error over the rows"),
    "horizontal_error_max_m": Field("m", "largest horizontal error"),
    "horizontal_error_final_m": Field("m", "horizontal error at the last row"),
    "vertical_error_max_m": Field("m", "largest absolute vertical error"),
    "vertical_error_final_m": Field("m", "vertical error at the last row"),
    "anees": Field("", "average normalised estimation error squared of the 3-D position (dof 3)"),
    "anees_lower_95": Field("", "lower two-sided 95 % chi-square bound of the ANEES for the row count"),
    "anees_upper_95": Field("", "upper two-sided 95 % chi-square bound of the ANEES for the row count"),
    "anees_inside_bounds": Field("flag", "1 when the ANEES lies inside its 95 % bounds"),
    "fraction_within_3sigma": Field("", "fraction of rows with |e_n| <= 3 sigma_n and |e_e| <= 3 sigma_e"),
    "time_to_converge_s": Field("s", "first time after which the horizontal error stays below the "
                                     "convergence threshold (NaN if it never does)"),
    "track_lost": Field("flag", "1 when a track loss was declared (error above the threshold or k sigma "
                                "for the minimum time)"),
    "track_loss_time_s": Field("s", "time the first track loss was declared (NaN without one)"),
    "track_lost_duration_s": Field("s", "total time spent in track-loss excursions"),
    "fraction_healthy": Field("", "fraction of time the navigator reported itself healthy"),
    "misleading_information_time_s": Field("s", "time the navigator reported healthy while the error was "
                                                "outside its 3 sigma"),
    "pl_epochs": Field("", "logged rows where the navigator is healthy and publishes a horizontal protection "
                           "level (HPL, navigators.integrity.protection_level)"),
    "pl_misleading_epochs": Field("", "of those, rows with the horizontal error above the HPL (misleading "
                                      "information)"),
    "pl_misleading_rate": Field("", "pl_misleading_epochs / pl_epochs (per epoch; compare with the "
                                    "integrity risk)"),
    "pl_misleading_rate_upper95": Field("", "its one-sided 95 % Clopper-Pearson upper bound (rows counted as "
                                            "independent)"),
    "pl_hazardous_epochs": Field("", "healthy rows with the error above the alert limit while the HPL is not "
                                     "(hazardously misleading)"),
    "pl_hazardous_rate": Field("", "pl_hazardous_epochs / pl_epochs"),
    "pl_availability": Field("", "share of all rows that are healthy with the HPL at most the alert limit "
                                 "(metrics.alert_limit_m, default 185.2 m)"),
    "hpl_median_m": Field("m", "median HPL over the healthy rows"),
}

SUMMARY_FIELDS: dict[str, Field] = {
    "scenario": Field("", "scenario name (built-in name or the file's stem)"),
    "seed": Field("", "the scenario seed that fixes the run bit for bit"),
    "navigator": Field("", "navigator name or plug-in reference"),
    "sim_time_s": Field("s", "simulated time flown"),
    "wall_time_s": Field("s", "wall-clock time of the flight (kernel compilation excluded)"),
    "realtime_factor": Field("", "simulated seconds per wall second"),
    "termination": Field("", "why the run ended: completed, route_not_followed, terrain_collision, off_map, "
                             "diverged, fuel_exhausted, engine_failure or time_limit"),
    "horizontal_error_rms_gnss_denied_m": Field("m", "RMS horizontal error over the rows without GNSS"),
    "north_error_rms_m": Field("m", "RMS of the north error"),
    "east_error_rms_m": Field("m", "RMS of the east error"),
    "horizontal_sigma_final_m": Field("m", "the navigator's horizontal sigma hypot(sigma_n, sigma_e) at the "
                                           "last row"),
    "gnss_denied_time_s": Field("s", "time flown without GNSS"),
    "horizontal_error_at_gnss_loss_m": Field("m", "horizontal error at the last row with GNSS before its "
                                                  "first loss (the hand-over; NaN if GNSS was never lost)"),
    "horizontal_sigma_at_gnss_loss_m": Field("m", "horizontal sigma at the same row"),
    "distance_flown_m": Field("m", "true ground distance flown"),
    "min_true_agl_m": Field("m", "lowest true height above the world's terrain"),
    "jsbsim_steps": Field("", "JSBSim steps run"),
    "closed_loop_steps_per_s": Field("1/s", "JSBSim steps per wall second of the whole loop"),
    "navigator_status": Field("", "the navigator's health status at the end (ok, degraded, lost, ...)"),
    "navigator_skipped": Field("", "measurements the navigator skipped, counted by reason"),
    "scenario_source": Field("", "where the scenario came from (built-in or the file's path)"),
    "duration_limit_s": Field("s", "the scenario's time limit"),
    "warm_up_wall_time_s": Field("s", "wall time until the numba kernels were ready (compile or cache load)"),
    "monitors": Field("", "per monitor (e.g. dem_integrity): its alarm summary (alarms, first alarm, ...)"),
    "map_faults": Field("", "the map faults the scenario placed (kind, region, start)"),
    "wall_time_by_stage_s": Field("s", "wall time spent in each stage of the loop (flight, sensors, "
                                       "navigator, guidance, ...)"),
    "pipelined": Field("flag", "whether sensors and navigator ran in a second process beside the flight"),
    "route_not_followed": Field("", "with termination route_not_followed: what the aircraft could not do"),
    "navigator_latency_updates": Field("", "navigator updates the estimate lags the flight by (pipelining)"),
    "fuel_remaining_kg": Field("kg", "fuel on board at the end"),
    "constant_fuel": Field("flag", "whether the fuel (and the mass) was held constant"),
    "truth_source": Field("", "where the true motion came from: jsbsim or kinematic"),
    "pl_not_validated": Field("", "the navigator's statement on its protection level at the last estimate: "
                                  "'' where validated for the scenario's IMU grade and map class with the "
                                  "navigator's settings, else why not "
                                  "(navigators.integrity.protection_level.set_condition)"),
    "unused_sensors": Field("", "fitted sensors that neither the navigator nor a monitor reads (their "
                                "declared sensor needs)"),
    "files": Field("", "the files written to the run folder"),
    "replay_of": Field("", "replay: the sensor log the navigator ran on"),
    "frames": Field("", "replay: the number of frame intervals fed to the navigator"),
    "truth_in_log": Field("flag", "replay: whether the log holds truth (then errors are computed)"),
    "sensors_in_log": Field("", "replay: the sensors the log holds"),
    "trn_env_version": Field("", "the trn-env version that flew the run"),
    "command_line": Field("", "the command as typed (shell-quoted); scenario.toml's header repeats it"),
    "status_ok_fraction": Field("", "time share of rows whose health status is 'ok'"),
    "status_ok_misleading_fraction": Field("", "share of the 'ok' time with the north or east error outside "
                                               "k sigma"),
    "status_ok_misleading_time_s": Field("s", "that time in seconds"),
} | METRIC_FIELDS

CAMPAIGN_ROW_FIELDS: dict[str, Field] = {
    "campaign": Field("", "campaign name"),
    "campaign_hash": Field("", "sha256 of the campaign file's canonical form"),
    "run_id": Field("", "the run's stable identifier inside the campaign (used by --resume)"),
    "run_index": Field("", "index of the run in the campaign's expansion"),
    "variant_index": Field("", "index of the (scenario, navigator, sweep point) variant"),
    "seed_index": Field("", "index of the seed inside the variant"),
    "seed": Field("", "the run's scenario seed"),
    "scenario": Field("", "scenario name"),
    "scenario_source": Field("", "built-in name or scenario path"),
    "scenario_hash": Field("", "sha256 of the run's resolved scenario (defaults filled, seed set)"),
    "navigator": Field("", "the navigator's label in the campaign file"),
    "navigator_name": Field("", "the registered navigator name or plug-in reference"),
    "sweep_json": Field("", "the run's sweep values as JSON (dotted path -> value)"),
    "sweep.": Field("", "one column per swept dotted path, holding the run's value"),
    "replay_command": Field("", "a `trn-env fly` command that flies this run alone"),
    "navigator_settings_json": Field("", "the navigator's settings as flown, as JSON (shown in the report)"),
    "gnss_outages_json": Field("", "the run's GNSS outage windows (gnss.outages) as JSON (the report shades "
                                   "them)"),
    "error": Field("", "the error message of a run that failed (termination 'error'), else empty"),
    "attempts": Field("", "how many times the run was started (retries included)"),
    "host": Field("", "host name of the worker that flew the run"),
    "pid": Field("", "process id of the worker"),
    "trn_env_version": Field("", "trn-env version of the worker"),
    "jsbsim_version": Field("", "JSBSim version of the worker"),
    "numpy_version": Field("", "numpy version of the worker"),
    "python_version": Field("", "Python version of the worker"),
    "series_": Field("", "a time series of the run (t_s in s, err_h_m / err_v_m / sigma_h_m / hpl_m in m, "
                         "nav_ok 0/1), as lists"),
} | {k: SUMMARY_FIELDS[k] for k in ("termination", "wall_time_s", "sim_time_s", "distance_flown_m",
                                    "jsbsim_steps")} | METRIC_FIELDS


def undocumented(keys, table: dict[str, Field]) -> list[str]:
    """The keys that `table` does not document (by exact name or by a documented prefix ending in . or _)."""
    prefixes = tuple(k for k in table if k.endswith((".", "_")))
    return sorted(k for k in keys if k not in table and not (prefixes and k.startswith(prefixes)))
