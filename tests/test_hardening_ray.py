"""Issue 39, Ray clusters: every bad address fails within seconds with one line (exit 2), the token-auth
refusal says what to set, ray:// without Ray Client names the extra, and Ray's retries are recorded."""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

import pytest
from _child_processes import init_local_ray

from trn_env import cli
from trn_env.campaign import ray_backend

CI = Path(__file__).parent / "campaigns" / "ci_small.toml"
pytest.importorskip("ray", reason="the ray extra is installed in CI (pip install -e .[ray])")


def _one_line_refusal(capsys, args, tmp_path, within_s: float) -> str:
    out = tmp_path / "out"
    t0 = time.monotonic()
    rc = cli.main(["campaign", str(CI), "--backend", "ray", *args, "--out", str(out), "--quiet"])
    elapsed = time.monotonic() - t0
    err = capsys.readouterr().err.strip()
    assert rc == 2 and elapsed < within_s, (rc, elapsed, err)
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not out.exists()
    return err


def test_a_port_held_by_another_program_fails_within_seconds(tmp_path, capsys):
    """A listener that accepts and never answers (where Ray's own client waits for minutes)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    held = []
    threading.Thread(target=lambda: [held.append(srv.accept()) for _ in range(4)], daemon=True).start()
    port = srv.getsockname()[1]
    try:
        err = _one_line_refusal(capsys, ["--address", f"127.0.0.1:{port}"], tmp_path, within_s=15.0)
    finally:
        srv.close()
    assert "is held by a program that is not Ray" in err


def test_ray_client_address_without_ray_client_names_the_extra(tmp_path, capsys, monkeypatch):
    import importlib.util
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "grpc" else real(name, *a))
    err = _one_line_refusal(capsys, ["--address", "ray://127.0.0.1:10001"], tmp_path, within_s=15.0)
    assert "ray[client]" in err and 'pip install "trn-env[ray]"' in err


def test_failures_are_classified_in_one_line():
    auth = ("ray.exceptions.AuthenticationError: RPC error: InvalidAuthToken: Authentication token is "
            "missing or incorrect. Note: RAY_AUTH_MODE is currently 'disabled' (not 'token').")
    msg = ray_backend.classify_failure("10.0.0.5:6379", auth)
    assert "RAY_AUTH_MODE=token" in msg and "docs/guide/ray.md" in msg and "\n" not in msg
    msg = ray_backend.classify_failure("10.0.0.5:40123", "ray.exceptions.RpcError: RPC error: ")
    assert "not a Ray head's GCS" in msg


_ATTEMPTS = """
import os
from trn_env.campaign.ray_backend import _attempt_number
def flaky(key):
    n = _attempt_number(key)
    if n == 1:
        os._exit(1)          # the worker dies, as on a node killed mid-run: Ray runs the task again
    return n
"""


def test_ray_retries_are_counted_as_attempts():
    """A task whose worker dies on its first attempt comes back from Ray's retry as attempt 2."""
    import ray
    started = not ray.is_initialized()
    if started:
        init_local_ray()
    try:
        ns: dict = {}
        exec(_ATTEMPTS, ns)
        flaky = ray.remote(max_retries=2)(ns["flaky"])
        key = f"test-{os.getpid()}-{time.time_ns()}"
        assert ray.get(flaky.remote(key), timeout=120) == 2
        assert ray_backend._attempt_number(key) == 3       # the store holds the count across processes
    finally:
        if started:
            ray.shutdown()
