"""Suite-wide set-up: compile the numba kernels once before the test workers start.

With pytest-xdist every worker would otherwise compile the same kernels at the same time on a fresh
install (numba's cache is empty): `trn-env precompile` compiles each once, on all cores, into the cache
the workers then load. It runs only in the controlling process (not in each worker) and is skipped with
TRN_ENV_NO_PRECOMPILE=1.
"""

from __future__ import annotations

import os
import subprocess
import sys


def pytest_configure(config):
    if hasattr(config, "workerinput") or os.environ.get("TRN_ENV_NO_PRECOMPILE"):
        return
    if config.getoption("collectonly", False):
        return
    # a separate process, so that this one (which may fork xdist workers) imports no numba kernels; run
    # from tests/ so that it imports trn_env from where the tests do (the installed package, not the
    # checkout's source tree: `python -m` from the repository's root would put the source first)
    code = "from trn_env.cli import main; raise SystemExit(main(['precompile']))"
    subprocess.run([sys.executable, "-c", code], check=False, stdout=subprocess.DEVNULL,
                   cwd=os.path.dirname(os.path.abspath(__file__)))
