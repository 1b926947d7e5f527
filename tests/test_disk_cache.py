"""navigators.core.disk_cache: a result computed once is read back bit for bit by later processes, and
nothing (a corrupt file, a code change, an unwritable or disabled cache, a non-finite result) makes it
return anything but what the computation gives."""
from __future__ import annotations

import json

import pytest
from trn_env.navigators.core import disk_cache
from trn_env.navigators.core.disk_cache import ENV_VAR, cached_floats, code_digest
from trn_env.navigators.measurements import ira_map_noise

from trn_env import terrain


class Counted:
    """A computation that counts its calls."""

    def __init__(self, values):
        self.values, self.calls = values, 0

    def __call__(self):
        self.calls += 1
        return self.values


@pytest.fixture()
def code(tmp_path):
    """A package folder of its own, so a test can change 'the code' a result depends on."""
    d = tmp_path / "pkg"
    (d / "sub").mkdir(parents=True)
    (d / "a.py").write_text("x = 1\n")
    (d / "sub" / "b.py").write_text("y = 2\n")
    code_digest.cache_clear()
    yield (str(d),)
    code_digest.cache_clear()


def _files(folder):
    return sorted(p for p in folder.rglob("*") if p.is_file())


def test_computed_once_then_read_back_exactly(tmp_path, monkeypatch, code):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    values = (0.1 + 0.2, 1.0 / 3.0, -2.5e-300)      # values whose decimal forms are long
    f = Counted(values)
    assert cached_floats("ns", ("k", 1.5, (2, 3)), 3, f, code) == values and f.calls == 1
    again = Counted((9.0, 9.0, 9.0))
    got = cached_floats("ns", ("k", 1.5, (2, 3)), 3, again, code)
    assert got == values and again.calls == 0
    assert all(a.hex() == b.hex() for a, b in zip(got, values, strict=True))
    files = _files(tmp_path / "cache")
    assert len(files) == 1 and files[0].parent.name == "ns" and files[0].suffix == ".json"
    # another key is another entry
    assert cached_floats("ns", ("k", 1.5, (2, 4)), 3, Counted((1.0, 2.0, 3.0)), code) == (1.0, 2.0, 3.0)
    assert len(_files(tmp_path / "cache")) == 2


def test_a_code_change_is_a_miss(tmp_path, monkeypatch, code):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    cached_floats("ns", ("k",), 1, Counted((1.0,)), code)
    (tmp_path / "pkg" / "sub" / "b.py").write_text("y = 3\n")
    code_digest.cache_clear()                  # a new process reads the edited code
    f = Counted((2.0,))
    assert cached_floats("ns", ("k",), 1, f, code) == (2.0,) and f.calls == 1


def test_corrupt_or_foreign_files_are_recomputed_and_replaced(tmp_path, monkeypatch, code):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    cached_floats("ns", ("k",), 2, Counted((1.0, 2.0)), code)
    (path,) = _files(tmp_path / "cache")
    good = path.read_text()
    bad_contents = ["", "{not json", json.dumps({"values": [1.0, 2.0]}), "[1.0, 2.0]",
                    good.replace("[1.0, 2.0]", '"12"'), good.replace("[1.0, 2.0]", "[true, 2.0]"),
                    good.replace("[1.0, 2.0]", "[1.0, NaN]"), good.replace("[1.0, 2.0]", "[1.0]"),
                    good.replace('"key": "', '"key": "x')]
    for bad in bad_contents:
        path.write_text(bad)
        f = Counted((1.0, 2.0))
        assert cached_floats("ns", ("k",), 2, f, code) == (1.0, 2.0) and f.calls == 1, bad
        assert path.read_text() == good
    assert [p.name for p in _files(tmp_path / "cache")] == [path.name]     # no temporary file left


def test_unwritable_disabled_or_non_finite_changes_nothing_but_the_time(tmp_path, monkeypatch, code):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv(ENV_VAR, str(blocker / "cache"))           # cannot be created: under a file
    for _ in range(2):
        f = Counted((1.0, 2.0))
        assert cached_floats("ns", ("k",), 2, f, code) == (1.0, 2.0) and f.calls == 1
    monkeypatch.setenv(ENV_VAR, "")                                # off
    assert disk_cache.cache_dir() is None
    for _ in range(2):
        f = Counted((1.0, 2.0))
        assert cached_floats("ns", ("k",), 2, f, code) == (1.0, 2.0) and f.calls == 1
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    for _ in range(2):                                             # not stored, so computed each time
        f = Counted((1.0, float("nan")))
        assert cached_floats("ns", ("k",), 2, f, code)[0] == 1.0 and f.calls == 1
    assert not (tmp_path / "cache").exists() and blocker.read_text() == ""


def test_entries_unused_for_a_month_are_removed_by_the_next_write(tmp_path, monkeypatch, code):
    """A hit refreshes its entry; a new entry removes the namespace's entries untouched for MAX_UNUSED_DAYS
    and temporary files older than a day, and nothing else (recent entries, other namespaces, other
    files)."""
    import os
    import time

    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    day = 86400.0
    now = time.time()

    def entry(ns, key):
        cached_floats(ns, key, 1, lambda: (1.0,), code)
        made = [p for p in _files(tmp_path / "cache" / ns) if p not in seen]
        seen.extend(made)
        return made[0]

    def age(path, days):
        os.utime(path, (now - days * day, now - days * day))

    seen = []
    stale, recent, used = (entry("ns", (k,)) for k in ("stale", "recent", "used"))
    elsewhere = entry("other", ("stale",))
    for path, days in ((stale, 10), (recent, -5), (used, 10), (elsewhere, 10)):
        age(path, disk_cache.MAX_UNUSED_DAYS + days)
    folder = tmp_path / "cache" / "ns"
    old_tmp, new_tmp, other = folder / ".tmp-abc.json", folder / ".tmp-def.json", folder / "notes.txt"
    for path, days in ((old_tmp, 2.0), (new_tmp, 0.1), (other, 400.0)):
        path.write_text("{")
        age(path, days)
    hit = Counted((5.0,))
    assert cached_floats("ns", ("used",), 1, hit, code) == (1.0,) and hit.calls == 0     # a hit ...
    assert now - used.stat().st_mtime < 60.0                                               # ... touches it
    assert stale.exists()                                     # reading prunes nothing
    assert cached_floats("ns", ("new",), 1, lambda: (2.0,), code) == (2.0,)            # a write prunes
    assert not stale.exists() and not old_tmp.exists()
    assert recent.exists() and used.exists() and new_tmp.exists() and other.exists() and elsewhere.exists()
    assert len(_files(folder)) == 5                          # recent, used, new, the new tmp, notes.txt


def test_unreadable_code_means_no_cache(tmp_path, monkeypatch, code):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    missing = (str(tmp_path / "pkg"), str(tmp_path / "no_such_folder" / "x.py"))
    bad = tmp_path / "pkg" / "unreadable.py"
    bad.mkdir()                                                    # a "file" that cannot be read
    for _ in range(2):
        f = Counted((1.0,))
        assert cached_floats("ns", ("k",), 1, f, missing) == (1.0,) and f.calls == 1
    assert not (tmp_path / "cache").exists()


def test_cache_dir_defaults_to_the_users_cache_folder(monkeypatch):
    import platformdirs
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert disk_cache.cache_dir() == platformdirs.user_cache_path("trn-env", appauthor=False)
    monkeypatch.setenv(ENV_VAR, "~/elsewhere")
    assert str(disk_cache.cache_dir()).endswith("elsewhere") and "~" not in str(disk_cache.cache_dir())


def test_map_noise_calibration_is_read_back_in_a_new_process(tmp_path, monkeypatch):
    """The rbpf's calibration through the disk cache: a process that finds it on disk gets the computation's
    own figures without computing (the map's refinement is made to fail), and a map of other content or
    other settings is not served another's."""
    dem = terrain.load("jacksboro")
    kw = {"agl_m": 1500.0, "n_states": 120, "realisations": 1}
    monkeypatch.setattr(ira_map_noise, "_CALIBRATION_CACHE", {})
    monkeypatch.setenv(ENV_VAR, "")
    fresh = ira_map_noise.map_noise_calibration(dem, 30.0, **kw)           # computed, cache off
    assert fresh != (1.0, 1.0)
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    monkeypatch.setattr(ira_map_noise, "_CALIBRATION_CACHE", {})           # a new process
    assert ira_map_noise.map_noise_calibration(dem, 30.0, **kw) == fresh
    assert len(_files(tmp_path / "cache")) == 1

    def no_refine(*a, **k):
        raise AssertionError("computed again")

    monkeypatch.setattr(ira_map_noise, "_CALIBRATION_CACHE", {})           # another new process
    monkeypatch.setattr(terrain.refine, "refine", no_refine)
    got = ira_map_noise.map_noise_calibration(terrain.load("jacksboro"), 30.0, **kw)
    assert got == fresh and all(a.hex() == b.hex() for a, b in zip(got, fresh, strict=True))
    with pytest.raises(AssertionError, match="computed again"):            # other settings: a miss
        ira_map_noise.map_noise_calibration(dem, 30.0, **{**kw, "agl_m": 750.0})


def test_dem_monitors_kalman_threshold_is_read_back_in_a_new_process(tmp_path, monkeypatch):
    """The DEM monitor's eq 5 threshold (Imhof's integral) through the disk cache, as the calibration."""
    from trn_env.navigators.integrity import correlated_disparity
    from trn_env.navigators.integrity import dem_monitor_thresholds as th
    args = (1e-3, 24, 0.01, "innovation")
    monkeypatch.setenv(ENV_VAR, "")
    th.kalman_threshold.cache_clear()
    fresh = th.kalman_threshold(*args)
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "cache"))
    th.kalman_threshold.cache_clear()                                      # a new process
    assert th.kalman_threshold(*args) == fresh and len(_files(tmp_path / "cache")) == 1

    def no_imhof(*a, **k):
        raise AssertionError("computed again")

    th.kalman_threshold.cache_clear()                                      # another new process
    monkeypatch.setattr(correlated_disparity, "gchi2_isf", no_imhof)
    assert th.kalman_threshold(*args).hex() == fresh.hex()
    with pytest.raises(AssertionError, match="computed again"):
        th.kalman_threshold(1e-3, 24, 0.01, "rw_posterior")
    th.kalman_threshold.cache_clear()
