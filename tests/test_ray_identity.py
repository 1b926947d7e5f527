"""A local Ray instance whose workers would fly other code than the driver is refused before any run: its
workers start in the driver's working folder, which comes first on their path, so a copy of trn_env there
(a source checkout of another version) shadows the package the driver imported. That made Ray's rows differ
from the local pool's (`campaign_ray_same_results: false`) while the local pool's forked workers agreed."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from trn_env.campaign.ray_backend import BackendError, RayBackend, package_identity

pytestmark = pytest.mark.slow             # starts a Ray instance: 10-25 s on 2 shared cores

ROOT = Path(__file__).resolve().parent.parent


def _copy_checkout(dest: Path) -> None:
    ignore = shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc")
    for sub in ("trn_env", "terrain", "navigators", "aircraft"):
        shutil.copytree(ROOT / sub, dest / sub, ignore=ignore)


def test_workers_flying_other_code_are_refused(tmp_path, monkeypatch):
    pytest.importorskip("ray", reason="the ray extra is installed in CI (pip install -e .[ray])")
    import ray
    if ray.is_initialized():
        pytest.skip("needs to start its own Ray instance")
    other = tmp_path / "other_checkout"
    _copy_checkout(other)
    with open(other / "trn_env" / "campaign" / "runs.py", "a", encoding="utf-8") as f:
        f.write("\n# another version\n")
    monkeypatch.chdir(other)
    with pytest.raises(BackendError) as err:
        with RayBackend(workers=1):
            pass
    msg = str(err.value)
    assert str(other / "trn_env") in msg and package_identity()[1] in msg and "\n" not in msg
    assert not ray.is_initialized()          # the instance it started is shut down
    # the same code copied elsewhere is the same code: accepted
    same = tmp_path / "same_checkout"
    _copy_checkout(same)
    monkeypatch.chdir(same)
    with RayBackend(workers=1) as backend:
        assert backend.describe().startswith("Ray (local instance), 1 CPU(s)")
