"""trn-env: a closed-loop test range for terrain-referenced navigation.

Importing the package registers the gymnasium environments "trn_env/TerrainNav-v0" (trn_env.env) and
"trn_env/TerrainNavFast-v0" (trn_env.env.fast, a vector env); the env modules are imported only when an env is
made.
"""

__version__ = "0.1.0"


def _source_tree_subpackages() -> None:
    """In a source checkout, terrain/, navigators/ and aircraft/ sit beside trn_env/ (the design's layout)
    and only an install maps them to trn_env.terrain, trn_env.navigators and trn_env.aircraft. When this
    package is imported from the checkout itself (``python -m trn_env.cli`` or a worker process started in
    the repository's root, where the current folder comes first on sys.path), search the checkout's root for
    those subpackages too, so the source tree imports the same modules an install does."""
    from pathlib import Path

    here = Path(__file__).resolve().parent
    root = here.parent
    if not (here / "terrain").is_dir() and all((root / sub / "__init__.py").is_file()
                                               for sub in ("terrain", "navigators")):
        __path__.append(str(root))  # noqa: F821 - the package's own search path


_source_tree_subpackages()


def _arrow_memory_pool() -> None:
    """Arrow's memory pool for this process: the system allocator unless ARROW_DEFAULT_MEMORY_POOL names
    another (pyarrow reads the variable once, when it is imported, so this holds only where trn_env is
    imported before pyarrow, as in the CLI and the scripts). pyarrow's default backend, mimalloc, keeps what
    it freed: reading a long run's log back at its end (trn_env.logs.writer.read_ticks) left the process
    holding about three times the bytes it read; the system allocator returns them (figures and command in
    docs/validation/logs.md).

    pyarrow also starts jemalloc's background purging thread when it loads, whichever pool is used; it is
    turned off too (JE_ARROW_MALLOC_CONF, unless set): with it every later fork (the warm-up's compile, the
    pipelined navigator, a campaign's workers) forks a multi-threaded process, which Python 3.12 and newer
    warn about. Without it jemalloc purges as it allocates; with the system pool it allocates nothing."""
    import os

    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    os.environ.setdefault("JE_ARROW_MALLOC_CONF", "background_thread:false")


_arrow_memory_pool()


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
                           entry_point="trn_env.env.fast.vector_env:single_env_refused",
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
