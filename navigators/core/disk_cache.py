"""Numbers that cost seconds to compute and are fixed by their inputs and the code, kept on disk between
processes (numba's `cache=True` does the same for the kernels).

A `trn-env fly`, each campaign worker and each env runner is a new process: an in-process cache alone makes
every one of them pay again for the same result (the `rbpf`'s map-noise calibration: 1-2.5 s per map and
height). `cached_floats` keeps such a result in one small JSON file per key under `cache_dir()`:

- the file's name is a hash of the caller's key and of `code_digest()`, the content of the modules that
  compute it and the versions of numpy, scipy and numba, so editing that code or upgrading them is a miss,
  never a stale hit;
- a file is written whole (a temporary file renamed over it), so a reader sees all of it or none, and two
  processes computing the same key write the same bytes;
- anything unreadable, malformed or not finite counts as a miss (it is computed again and rewritten), and a
  cache that cannot be written is skipped: the cache changes how long a result takes, never what it is;
- a hit touches its file; each new entry removes the namespace's entries unused for `MAX_UNUSED_DAYS` (those
  of code since edited or upgraded, of maps no longer flown) and temporary files a killed writer left, so
  the folder does not grow with every release while two installations that share it keep their entries.

Where: `$TRN_ENV_CACHE_DIR` when set (an empty value turns the cache off), else the platform's user cache
folder for "trn-env" (platformdirs; ~/.cache/trn-env on Linux).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Iterable
from functools import cache
from pathlib import Path

ENV_VAR = "TRN_ENV_CACHE_DIR"
MAX_UNUSED_DAYS = 30.0     # an entry neither read nor written for this long is removed by the next write
_TMP_PREFIX = ".tmp-"


def cache_dir() -> Path | None:
    """The cache's folder, or None when `$TRN_ENV_CACHE_DIR` is set empty (cache off)."""
    value = os.environ.get(ENV_VAR)
    if value is not None:
        return Path(value).expanduser() if value.strip() else None
    import platformdirs

    return Path(platformdirs.user_cache_dir("trn-env", appauthor=False))


@cache
def code_digest(package_dirs: tuple[str, ...]) -> str:
    """Hash of every .py file below package_dirs (relative path and bytes, in sorted order) and of the
    numpy, scipy and numba versions: what a cached result was computed with."""
    import numba
    import numpy
    import scipy

    h = hashlib.blake2b(digest_size=16)
    for root in package_dirs:
        base = Path(root)
        for path in sorted(base.rglob("*.py")):
            h.update(path.relative_to(base).as_posix().encode())
            h.update(path.read_bytes())
    h.update(f"numpy {numpy.__version__} scipy {scipy.__version__} numba {numba.__version__}".encode())
    return h.hexdigest()


def _read(path: Path, key_text: str, size: int) -> tuple[float, ...] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        values = data["values"]
        if data["key"] != key_text or not isinstance(values, list) or len(values) != size:
            return None
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            return None
        out = tuple(float(v) for v in values)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return out if all(math.isfinite(v) for v in out) else None


def _write(path: Path, key_text: str, values: tuple[float, ...]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_TMP_PREFIX, suffix=".json")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump({"key": key_text, "values": list(values)}, f)   # floats by repr: exact
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        pass   # a read-only or full disk: the result stands, only the next process recomputes it


def _prune(folder: Path, keep: Path) -> None:
    """Remove the entries of `folder` unused for MAX_UNUSED_DAYS, and temporary files older than a day (a
    writer killed between writing and renaming); `keep` (just written) stays. Errors are ignored: another
    process may be pruning too."""
    import time

    now = time.time()
    try:
        paths = list(folder.iterdir())
    except OSError:
        return
    for path in paths:
        if path == keep or path.suffix != ".json":
            continue
        max_age_s = 86400.0 if path.name.startswith(_TMP_PREFIX) else MAX_UNUSED_DAYS * 86400.0
        try:
            if now - path.stat().st_mtime > max_age_s:
                path.unlink()
        except OSError:
            pass


def cached_floats(namespace: str, key: tuple, size: int, compute: Callable[[], Iterable[float]],
                  code_dirs: tuple[str, ...]) -> tuple[float, ...]:
    """compute()'s `size` finite floats for `key` (a tuple whose repr is stable across processes: strings,
    numbers, tuples), read from `cache_dir()/namespace` when a process computed them before with the same
    code (code_digest of code_dirs), else computed and stored. A result that is not `size` finite floats is
    returned as it is and not stored."""
    folder = cache_dir()
    try:
        digest = code_digest(tuple(code_dirs)) if folder is not None else ""
    except OSError:          # the code cannot be read whole (a file removed while installing): no cache
        folder = None
    if folder is None:
        return tuple(compute())
    key_text = repr((key, digest))
    name = hashlib.blake2b(key_text.encode(), digest_size=20).hexdigest()
    path = folder / namespace / f"{name}.json"
    hit = _read(path, key_text, size)
    if hit is not None:
        try:
            os.utime(path)        # in use: kept by the pruning
        except OSError:
            pass                  # a read-only cache still serves its entries
        return hit
    values = tuple(compute())
    if len(values) == size and all(isinstance(v, float) and math.isfinite(v) for v in values):
        _write(path, key_text, values)
        _prune(path.parent, keep=path)
    return values
