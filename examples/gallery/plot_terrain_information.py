"""
Terrain information: where terrain-referenced navigation can fix a position
============================================================================

TRN works where the terrain is rough. `trn_env.terrain.metrics.terrain_information` turns a DEM into the
expected Fisher information of horizontal position from altimeter heights (noise sigma) over a window, and
its Cramér-Rao bound: the best horizontal sigma any navigator can reach from one window of measurements
there. The route planner (``trn-env plan``) and the env's observation use the same map.
"""

# %%
import matplotlib.pyplot as plt
import numpy as np
from trn_env.terrain.metrics import terrain_information

from trn_env import terrain

dem = terrain.load("jacksboro")
print(dem)
info = terrain_information(dem, sigma_m=5.0, window_m=2000.0)

# %%
# The height map and the position bound
# -------------------------------------
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 4), sharey=True)
n_lat, n_lon = dem.heights_m.shape
extent = [np.degrees(dem.lon0_rad), np.degrees(dem.lon0_rad + (n_lon - 1) * dem.dlon_rad),
          np.degrees(dem.lat0_rad), np.degrees(dem.lat0_rad + (n_lat - 1) * dem.dlat_rad)]
im0 = ax0.imshow(dem.heights_m, origin="lower", extent=extent, cmap="terrain", aspect="auto")
fig.colorbar(im0, ax=ax0, label="height above MSL (m)")
ax0.set_title("Jacksboro DEM")
bound_m = np.clip(info.crlb_sigma_h_m, 0, 50)
im1 = ax1.imshow(bound_m, origin="lower", extent=extent, cmap="magma_r", aspect="auto")
fig.colorbar(im1, ax=ax1, label="position CRLB (m), clipped at 50")
ax1.set_title("horizontal position bound, 2 km window")
for ax in (ax0, ax1):
    ax.set_xlabel("longitude (deg)")
ax0.set_ylabel("latitude (deg)")
fig.tight_layout()
