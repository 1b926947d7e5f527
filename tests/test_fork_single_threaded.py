"""trn-env forks (the warm-up's compile, the pipelined navigator, a campaign's local workers) from a process
with no thread of its own beside the main one: no tqdm monitor thread under the progress bars, no jemalloc
background thread from pyarrow. Python 3.12 and newer warn on a fork of a multi-threaded process, and a
child could deadlock on a lock such a thread held. (OpenBLAS's idle pool threads, also running then, stop
themselves before a fork: their pthread_atfork handler.)"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from _child_processes import NEUTRAL_CWD

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork and /proc: Linux")

# Run a CLI command with os.fork wrapped to record, at each fork, the Python threads and the OS threads'
# names (/proc/self/task/*/comm).
_RECORD_FORKS = r'''
import json, os, sys, threading
forks = []
real_fork = os.fork

def recording_fork():
    names = []
    for task in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{task}/comm") as f:
                names.append(f.read().strip())
        except OSError:
            pass
    forks.append({"python": sorted(t.name for t in threading.enumerate()), "os": sorted(names)})
    return real_fork()

os.fork = recording_fork
from trn_env.cli import main
rc = main(sys.argv[1:])
print(json.dumps({"rc": rc, "forks": forks}))
'''


def _forks(argv: list[str]) -> dict:
    child = subprocess.run([sys.executable, "-c", _RECORD_FORKS, *argv], capture_output=True, text=True,
                           timeout=600, cwd=NEUTRAL_CWD)
    assert child.returncode == 0, child.stderr[-2000:]
    return json.loads(child.stdout.strip().splitlines()[-1])


def test_a_campaign_with_its_progress_bar_forks_its_workers_single_threaded(tmp_path):
    out = _forks(["campaign", str(NEUTRAL_CWD / "campaigns" / "ci_small.toml"), "--out", str(tmp_path / "c"),
                  "--workers", "2"])
    assert out["rc"] == 0 and len(out["forks"]) >= 2            # the two workers, forked with the bar open
    for fork in out["forks"]:
        assert fork["python"] == ["MainThread"], fork             # tqdm_monitor would be here
        assert "jemalloc_bg_thd" not in fork["os"], fork


def test_a_flight_forks_single_threaded(tmp_path):
    out = _forks(["fly", "default", "--duration", "5", "--no-plots", "--out", str(tmp_path / "f")])
    assert out["rc"] == 0 and out["forks"]                      # the warm-up's compile, the pipeline
    for fork in out["forks"]:
        assert fork["python"] == ["MainThread"], fork
        assert "jemalloc_bg_thd" not in fork["os"], fork
