"""Env stage: the gymnasium environment over the closed loop (`trn_env/TerrainNav-v0`).

terrain_nav  `TerrainNavEnv`
"""

from trn_env.env.terrain_nav import TerrainNavEnv

__all__ = ["TerrainNavEnv"]
