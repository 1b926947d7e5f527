"""
First flight: fly the default scenario and plot the navigation error
=====================================================================

`trn_env.sim.run_scenario` loads a scenario (here the built-in ``default``: the King Air over the real
Jacksboro DEM, GNSS lost after 10 s, INS + IRA TERCOM), flies it in closed loop and returns the summary
(the same fields as ``summary.json``) and the log arrays. This example flies its first two minutes.
"""

# %%
# Fly
# ---
import matplotlib.pyplot as plt
import numpy as np

from trn_env.sim import run_scenario

result = run_scenario("default", seed=1, duration_s=120.0, pipeline=False)
summary = result.summary
print(f"termination: {summary['termination']}")
rms_m, sim_s = summary["horizontal_error_rms_m"], summary["sim_time_s"]
print(f"horizontal RMS error: {rms_m:.1f} m over {sim_s:.0f} s")

# %%
# The horizontal error against the navigator's 3-sigma bound
# -----------------------------------------------------------
# ``err_ned_m`` is estimate minus truth (north, east, down, m); ``est_cov_diag`` holds the estimate's
# covariance diagonal, its first two entries the north and east variances (m²).
a = result.arrays
t = a["t_s"]
e_h = np.hypot(a["err_ned_m"][:, 0], a["err_ned_m"][:, 1])
sigma_h = np.sqrt(a["est_cov_diag"][:, 0] + a["est_cov_diag"][:, 1])
fig, ax = plt.subplots(figsize=(7, 3.5))
ax.plot(t, e_h, label="horizontal error")
ax.plot(t, 3 * sigma_h, "--", label="3 sigma (navigator)")
t_denied = t[~a["gnss_available"].astype(bool)][0]
ax.axvspan(t_denied, t[-1], color="0.9", zorder=0, label="GNSS denied")
ax.set_xlabel("time since start (s)")
ax.set_ylabel("metres")
ax.legend()
fig.tight_layout()
