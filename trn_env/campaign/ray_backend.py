"""The Ray backend: the same runs as tasks on a local Ray instance or an existing Ray cluster.

Ray is an optional extra (`pip install "trn-env[ray]"`) imported only here and only when this backend is
used. `address=None` (and no RAY_ADDRESS) starts a local instance with `workers` CPUs; otherwise it joins
the cluster at `address` ("host:port" of the head's GCS, "ray://host:port" for Ray Client, or "auto").
The address is checked before anything is flown, so every bad address fails within seconds with one line
(BackendError): a plain TCP connect first (nothing listening), then Ray itself connects in a short-lived
child process with a hard time limit (`probe_with_ray`): a port held by another program (where Ray's own
client would wait for minutes), a raylet's port instead of the head's, a cluster that requires token
authentication (RAY_AUTH_MODE=token), and `ray://` without Ray Client (`ray[client]`) each get their own
one-line message. Ray's console noise of a failed connection goes to a log file, named in the message.

- The runs fly on warm actors, one per CPU (trn_env.campaign.ray_pool: each imports the packages and loads
  the campaign's kernels once); `warm=False` flies them as plain Ray tasks instead.
- The DEMs go into the object store once (`ray.put`); each actor or task gets the reference, not a copy.
- Worker death is retried (by the pool, or by Ray for tasks: `max_retries`); a run's own exception is
  caught inside the worker and comes back as its row (so it is never retried). Each attempt counts itself in
  Ray's key-value store (keyed by this `run` call, campaign hash and run id), so a row flown again after a
  node died says `attempts = 2`.
- Before anything is flown, one task compares the code the workers import with this process's
  (`package_identity`): a local instance whose workers would fly other code is refused.
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

import functools
import os
import socket
from collections.abc import Callable, Iterable
from typing import Any
from urllib.parse import urlparse

from trn_env.campaign.local import check_local_workers
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
        with socket.create_connection((host, port), timeout=timeout_s) as conn:
            speaks_grpc = _speaks_http2(conn, timeout_s)
    except OSError as exc:
        raise BackendError(f"--address {address}: no Ray cluster reachable at {host}:{port} ({exc}); "
                           "start one with `ray start --head` or check the address") from None
    if not speaks_grpc:
        raise BackendError(f"--address {address}: {host}:{port} is held by a program that is not Ray (it "
                           "does not answer gRPC); check the address `ray start --head` printed")


# HTTP/2 client connection preface and an empty SETTINGS frame (RFC 9113 sec. 3.4, 6.5)
_H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"


def _speaks_http2(conn: socket.socket, timeout_s: float) -> bool:
    """Whether the server on `conn` answers the HTTP/2 preface with a SETTINGS frame, as every gRPC server
    (Ray's GCS, its client server) does; a program that is not Ray answers otherwise or not at all."""
    try:
        conn.settimeout(timeout_s)
        conn.sendall(_H2_PREFACE)
        head = b""
        while len(head) < 9:
            chunk = conn.recv(9 - len(head))
            if not chunk:
                return False
            head += chunk
    except OSError:
        return False
    return head[3] == 0x04           # frame type SETTINGS


RAY_DOCS = "docs/guide/ray.md"
PROBE_TIMEOUT_S = 12.0

_PROBE = """
import sys
address = sys.argv[1]
try:                 # the head's GCS directly (about a second): its nodes and their CPUs
    from ray._raylet import GcsClient
except ImportError:
    GcsClient = None
if GcsClient is not None and not address.startswith("ray://"):
    nodes = GcsClient(address=address).get_all_node_info(timeout=5)
    cpus = sum(int(dict(n.resources_total).get("CPU", 0)) for n in nodes.values() if n.state == 0)
else:                # Ray Client, or a Ray without that class: a whole connection
    import ray
    ray.init(address=address, include_dashboard=False, log_to_driver=False, logging_level="error")
    cpus = int(ray.cluster_resources().get("CPU", 0))
    ray.shutdown()
print("CPU", cpus, flush=True)
"""


def classify_failure(address: str, text: str) -> str:
    """The one-line reason of a failed Ray connection from Ray's output `text`."""
    low = text.lower()
    if "unauthenticated" in low or "auth_token" in low or "authentication" in low:
        return (f"--address {address}: the Ray cluster requires token authentication: set "
                "RAY_AUTH_MODE=token and give the cluster's token (RAY_AUTH_TOKEN, or the file "
                f"~/.ray/auth_token of the node that started it) on this machine (see {RAY_DOCS})")
    if "ray[client]" in low or "ray client" in low and "install" in low or "no module named 'grpc'" in low:
        return (f"--address {address}: ray:// needs Ray Client: {INSTALL_HINT} (the extra includes "
                "ray[client])")
    if "version mismatch" in low or "version" in low and "does not match" in low:
        return f"--address {address}: the cluster runs another Ray or Python version than this machine"
    if "rpcerror" in low or "raylet" in low and ("gcs" not in low or "timed out" in low):
        return (f"--address {address}: that port is not a Ray head's GCS (a raylet's port?); give the head's "
                "address as `ray start --head` printed it (default port 6379)")
    return (f"--address {address}: no Ray cluster answered there (a port held by another program, or a Ray "
            "node that is not the head); check the address `ray start --head` printed")


_FATAL_MARKS = ("unauthenticated", "invalidauthtoken", "authenticationerror")


def probe_with_ray(address: str, timeout_s: float = PROBE_TIMEOUT_S) -> int:
    """Connect to `address` with Ray in a child process, stopped after `timeout_s` or as soon as its output
    shows a failure Ray would only retry (an authentication refusal); returns the cluster's CPU count, or
    raises BackendError with one line (Ray's own output kept in a log file)."""
    import subprocess
    import sys
    import tempfile
    import threading
    import time
    proc = subprocess.Popen([sys.executable, "-c", _PROBE, address], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env={**os.environ, "RAY_ADDRESS": ""})
    lines: list[str] = []
    fatal = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            lines.append(line)
            if any(m in line.lower() for m in _FATAL_MARKS):
                fatal.set()
        fatal.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    fatal.wait(timeout_s)
    timed_out = proc.poll() is None and not any(m in "".join(lines).lower() for m in _FATAL_MARKS)
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    reader.join(2.0)
    time.sleep(0)
    out = "".join(lines)
    for line in lines:
        if line.startswith("CPU ") and proc.returncode == 0:
            return int(line.split()[1])
    with tempfile.NamedTemporaryFile("w", prefix="trn-env-ray-connect-", suffix=".log", delete=False) as f:
        f.write(out)
    why = classify_failure(address, out)
    if timed_out:
        why += f" (Ray did not connect within {timeout_s:.0f} s)"
    raise BackendError(f"{why}; Ray's output: {f.name}")


def connect_for_env_runners(ray, address: str | None, num_cpus: int | None, env_runners: int,
                            **init_kw: Any) -> None:
    """For a training script (scripts/train_rllib.py, scripts/route_task.py): join the cluster at `address`
    (probed first: an unreachable or wrong address is one line within seconds, where ray.init waits for
    minutes) or start a local instance of `num_cpus` CPUs (limited as a campaign's --workers); ValueError,
    with Ray shut down again, when the session has fewer CPUs than the EnvRunners need (one each: RLlib
    would wait for the missing ones for ever). `init_kw` goes to ray.init."""
    kw = {"include_dashboard": False, **init_kw}
    if address:
        probe_address(address)
        if address not in ("auto", "local"):
            probe_with_ray(address)
        try:
            ray.init(address=address, **kw)
        except (ConnectionError, RuntimeError, TimeoutError) as exc:
            raise ValueError(classify_failure(address, str(exc))) from None
    else:
        check_local_workers(num_cpus, "--num-cpus")
        ray.init(address="local", num_cpus=num_cpus, **kw)
    cpus = int(ray.cluster_resources().get("CPU", 0))
    if env_runners > cpus:
        ray.shutdown()
        where = f"the cluster at {address}" if address else "the local Ray instance (--num-cpus)"
        raise ValueError(f"--env-runners {env_runners} needs {env_runners} CPUs, one per EnvRunner; "
                         f"{where} has {cpus}")


def _attempt_number(key: str) -> int:
    """This attempt's number (1, 2, ...) of the run `key`, counted in Ray's internal key-value store: Ray
    retries a task whose worker or node died by running it again, and each run counts itself."""
    try:
        from ray.experimental.internal_kv import _internal_kv_get, _internal_kv_put
        prev = _internal_kv_get(key.encode(), namespace="trn_env_attempts")
        n = int(prev.decode()) + 1 if prev else 1
        _internal_kv_put(key.encode(), str(n).encode(), overwrite=True, namespace="trn_env_attempts")
        return n
    except Exception:  # noqa: BLE001 - the count is a record, never a reason to fail the run
        return 1


def _local_version() -> str:
    import trn_env
    return str(trn_env.__version__)


_SUBPACKAGES = ("terrain", "navigators", "aircraft")


@functools.lru_cache(maxsize=1)
def package_identity() -> tuple[str, str, str]:
    """(version, the folder trn_env is imported from, sha256 of its code: the .py and .xml files of trn_env
    and of the folders it ships as trn_env.terrain, .navigators, .aircraft). Two processes with the same
    digest fly the same code, wherever each imports it from (a source checkout, an installed copy)."""
    import hashlib
    import importlib
    from pathlib import Path

    import trn_env
    top = Path(trn_env.__file__).parent
    roots = [("trn_env", top)] + [(f"trn_env.{s}", Path(list(importlib.import_module(f"trn_env.{s}")
                                                                   .__path__)[0])) for s in _SUBPACKAGES]
    digest = hashlib.sha256()
    for name, root in roots:
        for p in sorted(root.rglob("*")):
            rel = p.relative_to(root)
            if (name == "trn_env" and rel.parts[0] in _SUBPACKAGES) or "__pycache__" in rel.parts \
                    or p.suffix not in (".py", ".xml") or not p.is_file():
                continue
            digest.update(f"{name}/{rel.as_posix()}\0".encode())
            digest.update(p.read_bytes())
    return str(trn_env.__version__), str(top), digest.hexdigest()


def _worker_version() -> tuple[str, str, str]:
    return package_identity()


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


def attempt_key(run_key: str, task: RunTask) -> str:
    """The key under which a run's attempts are counted (one `run_key` per RayBackend.run call)."""
    return f"{run_key}:{task.campaign_hash}:{task.run_id}"


def _fly(task: RunTask, dems: dict[str, Any], run_key: str = "") -> tuple[dict, bytes | None]:
    """fly_run on a Ray worker; `run_key` (one per RayBackend.run call) scopes the attempt count, so a
    campaign flown again on the same long-lived cluster starts counting from 1."""
    attempt = _attempt_number(attempt_key(run_key, task))
    row, log = fly_run(task, dems)
    row["attempts"] = max(int(row.get("attempts", 1)), attempt)
    return row, log


class RayBackend:
    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None, max_retries: int = 3,
                 connect_timeout_s: float = 3.0, warm: bool = True):
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise ValueError(f"--workers: must be a whole number >= 1 (got {workers!r})")
        self.address = address or os.environ.get("RAY_ADDRESS") or None
        if self.address is None:
            check_local_workers(workers)     # a new local instance: its workers are processes of this machine
        self.workers = workers
        self.max_retries = int(max_retries)
        self.connect_timeout_s = float(connect_timeout_s)
        self.warm = bool(warm)
        package_identity()        # this process's code, read now: near when its modules were imported
        self._pool = None
        self._started = False
        self.ray = None

    def preflight(self) -> None:
        """The checks that need no connection: Ray importable, the address reachable (BackendError)."""
        self.ray = import_ray()
        if self.address and self.address.startswith("ray://"):
            import importlib.util
            if importlib.util.find_spec("grpc") is None:
                raise BackendError(f"--address {self.address}: ray:// needs Ray Client (ray[client], which "
                                   f"brings grpcio): {INSTALL_HINT}")
        if self.address:
            probe_address(self.address, self.connect_timeout_s)
            if self.address not in ("auto", "local"):
                probe_with_ray(self.address)

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
        try:
            if self.address:
                ray.init(address=self.address, **kw)
            else:
                # address="local": a new instance even when a cluster runs on this machine (`ray start`),
                # which a bare ray.init() would join - and refuse, since num_cpus is given
                ray.init(address="local", num_cpus=self.workers, **kw)
        except (ConnectionError, ValueError, RuntimeError, TimeoutError) as exc:
            raise BackendError(classify_failure(self.address or "(local instance)", str(exc))) from None
        except Exception as exc:  # noqa: BLE001 - Ray's own start-up failure (e.g. its raylet timed out)
            line = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise BackendError(f"--backend ray: Ray did not start ({line})") from None
        self._started = True
        self._check_workers()
        return self

    def _check_workers(self) -> None:
        """One task imports trn_env where the runs will fly: a cluster whose nodes lack it is named in one
        line before any run is handed out, instead of every run failing after retries; workers flying
        other code than this process (package_identity: another version, or a source checkout that
        shadows the installed package) are refused on a local instance, warned about on a cluster."""
        ray = self.ray
        ref = ray.remote(num_cpus=0, max_retries=0)(_worker_version).remote()
        try:
            theirs = ray.get(ref, timeout=120)
        except Exception as exc:  # noqa: BLE001 - any failure here means the runs could not start
            self.__exit__(None, None, None)
            text = str(exc)
            if "No module named" in text:
                raise BackendError(f"--address {self.address}: trn-env is not installed where the cluster's "
                                   "workers run; install the same version on every node (pip install "
                                   f"\"trn-env[ray]=={_local_version()}\"), see {RAY_DOCS}") from None
            raise BackendError(f"--address {self.address}: a test task failed on the cluster: "
                               f"{text.splitlines()[-1] if text else type(exc).__name__}") from None
        ours = package_identity()
        if tuple(theirs) == ours or tuple(theirs)[2] == ours[2]:
            return
        where = (f"the Ray workers import trn-env {theirs[0]} from {theirs[1]}, this process {ours[0]} from "
                 f"{ours[1]}")
        if not self.address:
            # a local instance's workers start in this process's working folder, which comes first on their
            # path: a source checkout of another version there shadows the installed package
            self.__exit__(None, None, None)
            raise BackendError(f"--backend ray: {where}, and their code differs: the rows would not be "
                               "this version's; run the campaign from another folder (or install the "
                               f"checkout you are in: pip install -e .), see {RAY_DOCS}")
        import warnings
        warnings.warn(f"{where}, and their code differs: rows may differ from a local run", stacklevel=2)

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None
        if self._started and self.ray is not None:
            self.ray.shutdown()
            self._started = False

    def describe(self) -> str:
        cpus = int(self.ray.cluster_resources().get("CPU", 0)) if self.ray else 0
        where = self.address or "local instance"
        how = "warm actors, one per CPU" if self.warm else "tasks"
        return f"Ray ({where}), {cpus} CPU(s), {how}"

    def run(self, tasks: Iterable[RunTask], dems: dict[str, Any],
            on_result: Callable[[dict, bytes | None], None]) -> None:
        ray = self.ray
        if ray is None:
            raise RuntimeError("RayBackend.run outside `with RayBackend(...)`")
        if self.warm:
            if self._pool is None:
                from trn_env.campaign.ray_pool import WarmPool
                cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
                self._pool = WarmPool(ray, min(cpus, self.workers or cpus), self.max_retries)
            self._pool.run(tasks, dems, on_result)
            return
        dems_ref = ray.put(dems)
        remote = ray.remote(num_cpus=1, max_retries=self.max_retries, retry_exceptions=False)(_fly)
        import uuid
        run_key = uuid.uuid4().hex[:16]
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
                inflight[remote.remote(task, dems_ref, run_key)] = task
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
                    row["attempts"] = self.max_retries + 1
                on_result(row, log)
