"""trn-env: a closed-loop test range for terrain-referenced navigation.

Importing the package registers the gymnasium environment "trn_env/TerrainNav-v0" (trn_env.env); the
environment module itself is imported only when an env is made.
"""

__version__ = "0.1.0"


def _register_envs() -> None:
    try:
        import gymnasium
    except ImportError:  # pragma: no cover - gymnasium is a declared dependency
        return
    if "trn_env/TerrainNav-v0" not in gymnasium.registry:
        gymnasium.register(id="trn_env/TerrainNav-v0", entry_point="trn_env.env.terrain_nav:TerrainNavEnv")


_register_envs()
