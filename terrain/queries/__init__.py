"""Terrain queries (numba, batched over antenna positions): ray cast, radar-altimeter and IRA returns.

One module per search, each stating what it guarantees:
    raycast          ray_cast: first intersection of rays with the terrain
    radar_altimeter  radar_altimeter_return: closest terrain point in the beam cone (seed 001 ch. 4)
    ira              ira_return: closest terrain point on the zero-Doppler line within the look-angle window
                     (seed 000 sections 2.2, 3.2-3.3)
    shared           what they share: the exact-curvature local NED frame (ned_of_points, look_angle_rad),
                     TerrainReturn, the per-DEM tables cached on the Dem, scratch space, argument checks

Every query works on the DEM's bilinear surface in the antenna's local NED frame with the Earth's curvature
to second order (shared's docstring), returns a TerrainReturn ((n,) arrays, NaN where invalid), and is
independent of the other queries in its call unless ira_return's warm_start chains them. Use it as
`from terrain import queries; queries.ira_return(dem, ...)`.
"""

from .ira import COARSE_STEP_M, _ira_box_max, ira_return
from .radar_altimeter import N_SAMP, _cell_min, radar_altimeter_return
from .raycast import ray_cast
from .shared import (
    BLOCK_POSTS,
    IRA_BLOCK_POSTS,
    IRA_HEIGHT_BLOCK_CELLS,
    TerrainReturn,
    look_angle_rad,
    ned_of_points,
)

__all__ = [
    "BLOCK_POSTS",
    "COARSE_STEP_M",
    "IRA_BLOCK_POSTS",
    "IRA_HEIGHT_BLOCK_CELLS",
    "N_SAMP",
    "TerrainReturn",
    "_cell_min",
    "_ira_box_max",
    "ira_return",
    "look_angle_rad",
    "ned_of_points",
    "radar_altimeter_return",
    "ray_cast",
]
