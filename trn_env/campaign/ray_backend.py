"""The Ray backend: the same runs as tasks on a local Ray instance or an existing Ray cluster.

Ray is an optional extra (`pip install "trn-env[ray]"`) imported only here and only when this backend is
used. `address=None` (and no RAY_ADDRESS) starts a local instance with `workers` CPUs; otherwise it joins
the cluster at `address` ("host:port" of the head's GCS, "ray://host:port" for Ray Client, or "auto").
The address is probed with a plain TCP connect first, so an unreachable one fails within seconds.

- The DEMs go into the object store once (`ray.put`); each task gets the reference, not a copy.
- Worker death is retried by Ray (`max_retries`); a run's own exception is caught inside the task and
  comes back as its row (so it is never retried).
- At most 2 x cluster CPUs tasks are in flight; rows are taken with `ray.wait` as they finish and handed
  to the driver, which writes them, so a large campaign never holds everything in the driver.
- Plug-in navigators and monitors: an installed plug-in (an entry point of a package installed in the
  workers' Python environment, as on a local instance that shares this interpreter) is found by the workers
  as in the driver. A `package.module:Name` reference to a module that no installed distribution provides
  is shipped to the workers in the job's runtime environment (`ray.init(runtime_env={"py_modules": [...]})`,
  `plugin_runtime_env`) when this backend connects or starts the instance; a session the caller initialised
  keeps its own runtime_env (pass the module there). On a cluster whose nodes lack an installed plug-in,
  install it on the nodes, or connect with your own runtime_env (e.g. `ray.init(address=...,
  runtime_env={"pip": ["./my_plugin"]})`) before the campaign.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Iterable
from typing import Any
from urllib.parse import urlparse

from trn_env.campaign.runs import RunTask, died_row, fly_run

INSTALL_HINT = 'pip install "trn-env[ray]"   (or: pip install "ray>=2.9")'


class BackendError(ValueError):
    """The backend cannot start (Ray missing, address unreachable); nothing has been flown or written."""


def import_ray():
    try:
        import ray
    except ImportError as exc:
        raise BackendError(f"--backend ray: Ray is not installed ({exc}); install it with: {INSTALL_HINT}") \
            from None
    return ray


def probe_address(address: str, timeout_s: float = 3.0) -> None:
    """TCP-connect to a Ray address's host and port; BackendError within `timeout_s` if unreachable."""
    if address in ("auto", "local"):
        return
    url = urlparse(address if "://" in address else f"tcp://{address}")
    default_port = 10001 if url.scheme == "ray" else 6379
    try:
        host, port = url.hostname, url.port or default_port
    except ValueError:
        raise BackendError(f"--address {address!r}: not HOST:PORT or ray://HOST:PORT") from None
    if not host:
        raise BackendError(f"--address {address!r}: not HOST:PORT or ray://HOST:PORT")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        raise BackendError(f"--address {address}: no Ray cluster reachable at {host}:{port} ({exc}); "
                           "start one with `ray start --head` or check the address") from None


def plugin_runtime_env() -> dict[str, Any] | None:
    """Ray's runtime_env shipping the plug-in modules the driver resolved that no installed distribution
    provides (navigators.registry.plugin_modules), or None when there are none."""
    import sys

    from trn_env.navigators.registry import plugin_modules
    paths = []
    for name in plugin_modules():
        mod = sys.modules[name]
        # a package's folder, or a single-file module's .py (Ray's per-task runtime_env takes paths)
        paths.append(list(mod.__path__)[0] if hasattr(mod, "__path__") else mod.__file__)
    return {"py_modules": paths} if paths else None


def _fly(task: RunTask, dems: dict[str, Any]) -> tuple[dict, bytes | None]:
    return fly_run(task, dems)


class RayBackend:
    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None, max_retries: int = 3,
                 connect_timeout_s: float = 3.0):
        if workers is not None and (not isinstance(workers, int) or workers < 1):
            raise ValueError(f"--workers: must be a whole number >= 1 (got {workers!r})")
        self.address = address or os.environ.get("RAY_ADDRESS") or None
        self.workers = workers
        self.max_retries = int(max_retries)
        self.connect_timeout_s = float(connect_timeout_s)
        self._started = False
        self.ray = None

    def preflight(self) -> None:
        """The checks that need no connection: Ray importable, the address reachable (BackendError)."""
        self.ray = import_ray()
        if self.address:
            probe_address(self.address, self.connect_timeout_s)

    def __enter__(self) -> RayBackend:
        """Import Ray, probe the address, connect (or start a local instance)."""
        self.preflight()
        ray = self.ray
        if ray.is_initialized():       # the caller's session (e.g. a test's or a notebook's)
            return self
        kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "ignore_reinit_error": True}
        runtime_env = plugin_runtime_env()      # the campaign's plug-ins were resolved when it was loaded
        if runtime_env is not None:
            kw["runtime_env"] = runtime_env
        if self.address:
            ray.init(address=self.address, **kw)
        else:
            # "local": a new instance even when a cluster started on this machine (`ray start`) is about,
            # which a bare ray.init() would join (and then refuse num_cpus)
            ray.init(address="local", num_cpus=self.workers, **kw)
        self._started = True
        return self

    def __exit__(self, *exc) -> None:
        if self._started and self.ray is not None:
            self.ray.shutdown()
            self._started = False

    def describe(self) -> str:
        cpus = int(self.ray.cluster_resources().get("CPU", 0)) if self.ray else 0
        where = self.address or "local instance"
        return f"Ray ({where}), {cpus} CPU(s)"

    def run(self, tasks: Iterable[RunTask], dems: dict[str, Any],
            on_result: Callable[[dict, bytes | None], None]) -> None:
        ray = self.ray
        if ray is None:
            raise RuntimeError("RayBackend.run outside `with RayBackend(...)`")
        dems_ref = ray.put(dems)
        remote = ray.remote(num_cpus=1, max_retries=self.max_retries, retry_exceptions=False)(_fly)
        window = 2 * max(1, int(ray.cluster_resources().get("CPU", 1)))
        it = iter(tasks)
        inflight: dict = {}
        exhausted = False
        while True:
            while not exhausted and len(inflight) < window:
                task = next(it, None)
                if task is None:
                    exhausted = True
                    break
                inflight[remote.remote(task, dems_ref)] = task
            if not inflight:
                break
            ready, _ = ray.wait(list(inflight), num_returns=1)
            for ref in ready:
                task = inflight.pop(ref)
                try:
                    row, log = ray.get(ref)
                except ray.exceptions.RayError as exc:   # the worker died on every retry
                    row, log = died_row(task, f"Ray task failed after {self.max_retries} retries: "
                                              f"{type(exc).__name__}: {exc}"), None
                on_result(row, log)
