"""A closed-loop run's summary: the summary.json fields from its log arrays (DESIGN.md's fields first, then
extras, then every navigation metric of trn_env.output.metrics, the same figures a campaign row holds)."""

from __future__ import annotations

import numpy as np

from trn_env.navigators.protocol import Estimate
from trn_env.output.metrics import MetricSettings, navigation_metrics
from trn_env.scenario.loading import Scenario
from trn_env.terrain.geodesy import lon_difference_rad


def _rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def _at_loss(x: np.ndarray, denied: np.ndarray) -> float:
    """x at the last row with GNSS before the first row without it (NaN without such a hand-over)."""
    up = np.flatnonzero(~denied[:-1] & denied[1:])
    return float(x[up[0]]) if up.size else float("nan")


def summarise(scenario: Scenario, termination: str, a: dict[str, np.ndarray], wall_time_s: float,
              jsbsim_steps: int, final: Estimate, metric_settings: MetricSettings | None = None) -> dict:
    """summary.json contents (DESIGN.md fields first, then extras, then every navigation metric of
    trn_env.output.metrics, the same figures a campaign row holds)."""
    t = a["t_s"]
    err = a["err_ned_m"]
    e_h = np.hypot(err[:, 0], err[:, 1])
    e_v = -err[:, 2]
    sig = np.sqrt(np.clip(a["est_cov_diag"][:, :3], 0.0, None))
    sig_h = np.hypot(sig[:, 0], sig[:, 1])
    denied = ~a["gnss_available"].astype(bool)
    sim_time = float(t[-1] - t[0]) if t.size else 0.0
    step = np.hypot(np.diff(a["true_lat_rad"]) * 6.371e6,
                    lon_difference_rad(a["true_lon_rad"][1:], a["true_lon_rad"][:-1]) * 6.371e6
                    * np.cos(a["true_lat_rad"][:-1]))
    within3 = (np.abs(err[:, 0]) <= 3 * sig[:, 0]) & (np.abs(err[:, 1]) <= 3 * sig[:, 1])
    out = {
        "scenario": scenario.name,
        "seed": scenario.seed,
        "navigator": scenario.navigator_name,
        "sim_time_s": sim_time,
        "wall_time_s": float(wall_time_s),
        "realtime_factor": sim_time / wall_time_s if wall_time_s > 0 else float("nan"),
        "horizontal_error_rms_m": _rms(e_h),
        "horizontal_error_final_m": float(e_h[-1]) if e_h.size else float("nan"),
        "vertical_error_rms_m": _rms(e_v),
        "termination": termination,
        "horizontal_error_max_m": float(np.nanmax(e_h)) if e_h.size else float("nan"),
        "horizontal_error_rms_gnss_denied_m": _rms(e_h[denied]),
        "north_error_rms_m": _rms(err[:, 0]),
        "east_error_rms_m": _rms(err[:, 1]),
        "vertical_error_final_m": float(e_v[-1]) if e_v.size else float("nan"),
        "horizontal_sigma_final_m": float(sig_h[-1]) if sig_h.size else float("nan"),
        "fraction_within_3sigma": float(np.mean(within3)) if within3.size else float("nan"),
        "gnss_denied_time_s": float(np.sum(denied[1:]) * np.median(np.diff(t))) if t.size > 1 else 0.0,
        # the hand-over: the last logged row with GNSS before its first loss (NaN if GNSS never was lost)
        "horizontal_error_at_gnss_loss_m": _at_loss(e_h, denied),
        "horizontal_sigma_at_gnss_loss_m": _at_loss(sig_h, denied),
        "distance_flown_m": float(np.sum(step)),
        # NaN where the world has no height under the truth (a replay over a map that does not reach there)
        "min_true_agl_m": (float(np.nanmin(a["true_h_agl_m"])) if np.isfinite(a["true_h_agl_m"]).any()
                           else float("nan")),
        "jsbsim_steps": int(jsbsim_steps),
        "closed_loop_steps_per_s": jsbsim_steps / wall_time_s if wall_time_s > 0 else float("nan"),
        "navigator_status": final.health.status,
        "navigator_skipped": dict(final.health.skipped),
        "scenario_source": scenario.source,
        "duration_limit_s": scenario.duration_s,
    } | navigation_metrics(a, metric_settings)
    if "nav_status_code" in a:   # status-based integrity figures (trn_env.output.integrity_metrics)
        from trn_env.output.integrity_metrics import integrity_metrics
        out.update(integrity_metrics(t, err, a["est_cov_diag"], a["nav_status_code"]))
    return out
