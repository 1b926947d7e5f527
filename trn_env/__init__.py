"""trn-env: a closed-loop test range for terrain-referenced navigation.

Importing the package registers the gymnasium environments "trn_env/TerrainNav-v0" (trn_env.env) and
"trn_env/TerrainNavFast-v0" (trn_env.env.fast, a vector env); the env modules are imported only when an env is
made.
"""

__version__ = "0.1.0"


def _register_envs() -> None:
    try:
        import gymnasium
    except ImportError:  # pragma: no cover - gymnasium is a declared dependency
        return
    if "trn_env/TerrainNav-v0" not in gymnasium.registry:
        gymnasium.register(id="trn_env/TerrainNav-v0", entry_point="trn_env.env.terrain_nav:TerrainNavEnv")
    if "trn_env/TerrainNavFast-v0" not in gymnasium.registry:
        # N point-mass aircraft per process (a native VectorEnv): gymnasium.make_vec(..., num_envs=N,
        # vectorization_mode="vector_entry_point")
        gymnasium.register(id="trn_env/TerrainNavFast-v0",
                           vector_entry_point="trn_env.env.fast.vector_env:TerrainNavFastVectorEnv")


try:
    _register_envs()
except KeyboardInterrupt:
    import os as _os
    import sys as _sys

    # Ctrl-C while the `trn-env` command starts (this import runs before its main()): no traceback
    if _os.path.basename(_sys.argv[0] or "") in ("trn-env", "-m", "cli.py"):
        _sys.stderr.write("interrupted: nothing written\n")
        _sys.stderr.flush()
        _os._exit(130)
    raise
