"""World minus map height over the protection-level campaign's loop: the terrain detail a map lacks, against
the terrain filters' terrain_model_sigma_m and the map's own spectral estimate (interpolation_sigma_m).

    PYTHONPATH=. python scripts/map_detail_sigma.py

For each terrain (the Jacksboro 3" DEM, the synthetic "rolling" preset) and two refinement seeds: the world
refined to 30 m (terrain.refine.refine, as the campaign's scenarios), heights of world and map at 20,000
uniform points inside the loop (scripts/protection_level_campaign.LOOP's box), and the rms, the 99.9 %
absolute quantile and the kurtosis of their difference; then interpolation_sigma_m of the map.
"""

from __future__ import annotations

import numpy as np


def main() -> int:
    from trn_env.navigators.measurements.ira_seed002 import interpolation_sigma_m
    from trn_env.terrain.refine import refine

    from trn_env import terrain
    from trn_env.scenario.build import world_height
    for name in ("jacksboro", "synthetic:rolling"):
        m = terrain.load(name)
        for seed in (1, 2):
            w = refine(m, seed=np.random.default_rng(seed), spacing_m=30.0)
            rng = np.random.default_rng(0)
            lat = np.radians(rng.uniform(36.53, 36.70, 20000))
            lon = np.radians(rng.uniform(-84.27, -84.11, 20000))
            d = world_height(w, lat, lon) - world_height(m, lat, lon)
            kurt = np.mean((d - d.mean()) ** 4) / d.var() ** 2
            print(f"{name} refinement seed {seed}: world - map rms {np.sqrt(np.mean(d ** 2)):.2f} m, "
                  f"99.9 % |d| {np.quantile(abs(d), 0.999):.1f} m, kurtosis {kurt:.1f}")
        print(f"{name}: interpolation_sigma_m {interpolation_sigma_m(m):.2f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
