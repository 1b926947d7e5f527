"""The tests' child processes import the trn_env the tests import (tests/_child_processes.py): CI installs
the package (not editable) and tests it, with the numba cache `trn-env precompile` filled beside it."""

from __future__ import annotations

import multiprocessing as mp
import subprocess
import sys

import pytest
from _child_processes import NEUTRAL_CWD

import trn_env


def _trn_env_file() -> str:
    import trn_env as child_trn_env
    return child_trn_env.__file__


@pytest.mark.parametrize("method", ["forkserver", "spawn"])
def test_multiprocessing_children_import_the_tests_trn_env(method):
    """SubprocVecEnv, AsyncVectorEnv and the campaign's local pool start their children with this process's
    sys.path, as it stands after pytest collected every test file: a module that put the checkout's root on
    it when imported (three scripts the tests load once did) makes them import the source tree."""
    with mp.get_context(method).Pool(1) as pool:
        assert pool.apply(_trn_env_file) == trn_env.__file__


def test_python_children_started_from_the_neutral_folder_import_the_tests_trn_env():
    """`python -c` and `python -m` put their working folder first on sys.path: the tests start them from
    NEUTRAL_CWD, never from the checkout's root."""
    out = subprocess.run([sys.executable, "-c", "import trn_env; print(trn_env.__file__)"], cwd=NEUTRAL_CWD,
                         capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == trn_env.__file__
