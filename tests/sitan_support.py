"""The SITAN template plug-in (examples/sitan_navigator) installed for the tests that use it.

CI installs it (.ci/run: pip install ./examples/sitan_navigator); a development environment without it gets
it installed here once (pip, no dependencies: trn-env is already there), so the tests run the plug-in
exactly as a user's installed package, through its entry point."""

from __future__ import annotations

import subprocess
import sys
from importlib import metadata
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "sitan_navigator"


def ensure_sitan_installed() -> None:
    try:
        metadata.distribution("trn-env-sitan")
    except metadata.PackageNotFoundError:
        subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "-q",
                        str(EXAMPLE)], check=True, timeout=600)
        from trn_env.navigators import registry
        registry.refresh()
