"""The SITAN template plug-in (examples/sitan_navigator) installed for the tests that use it.

CI installs it (.ci/run: pip install ./examples/sitan_navigator); an environment without it (a developer's,
or a user's fresh one running the README's `pip install ".[test]" && pytest`) gets it installed here once
(pip, no dependencies: trn-env is already there), so the tests run the plug-in exactly as a user's installed
package, through its entry point. pytest-xdist's workers ask at the same time: a file lock lets one install
while the others wait, and every caller then forgets the entry points it had listed (another worker's install
adds one this process may have looked up before)."""

from __future__ import annotations

import fcntl
import subprocess
import sys
import tempfile
from importlib import metadata
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "sitan_navigator"
LOCK = Path(tempfile.gettempdir()) / "trn-env-tests-sitan-install.lock"


def ensure_sitan_installed() -> None:
    from trn_env.navigators import registry

    with open(LOCK, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)      # released when the file closes
        try:
            metadata.distribution("trn-env-sitan")
        except metadata.PackageNotFoundError:
            subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "-q",
                            str(EXAMPLE)], check=True, timeout=600)
    registry.refresh()
