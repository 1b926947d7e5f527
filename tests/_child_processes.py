"""Child processes (Python subprocesses, Ray workers) that import trn_env from where the tests do.

A Python child started in the repository's root imports the checkout's source tree, not the installed
package the tests import: `python -c` and `python -m` put the current folder first on sys.path, and Ray puts
the driver's working folder on its workers' sys.path when it starts (ray._private.worker.connect). CI
installs the package (not editable), so such a child would test the source tree instead, and compile every
numba kernel again into the source tree's empty cache (`trn-env precompile` filled the installed package's).
These helpers start children from NEUTRAL_CWD, a folder with no trn_env in it.
"""

from __future__ import annotations

import os
from pathlib import Path

# the tests' folder: no trn_env package here (conftest.py runs `trn-env precompile` from it too)
NEUTRAL_CWD = Path(__file__).resolve().parent


def init_local_ray(num_cpus: int = 2) -> None:
    """A new local Ray instance (never another's: address="local") whose workers import the installed
    trn_env: Ray records the driver's working folder for its workers' sys.path in ray.init, so init runs
    from NEUTRAL_CWD, and the test's own working folder is restored afterwards."""
    import ray

    here = os.getcwd()
    os.chdir(NEUTRAL_CWD)
    try:
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
    finally:
        os.chdir(here)
