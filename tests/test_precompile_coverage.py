"""What the warm-ups cover: after a scenario's warm-up its flight calls no kernel signature the warm-up did
not (the acquisition-and-tracking navigator tracks only after a full transect, which a three-update warm-up
reaches only with its capabilities' warm_up_settings), and after `trn-env precompile`'s fast-tier job an env
of another terrain, navigator, size and action mode calls no env kernel it did not (trn_env.bench.precompile).

Each check runs in a fresh interpreter and compares the numba dispatchers' signatures (compiled or loaded
from the cache: either way a signature the warm-up did not reach) before and after the later run."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest
from _child_processes import NEUTRAL_CWD

SIGNATURES = textwrap.dedent("""
    import json, sys
    from numba.core.registry import CPUDispatcher

    def signatures():
        out = set()
        for name, mod in list(sys.modules.items()):
            if not name.startswith("trn_env") or mod is None:
                continue
            for attr, obj in list(vars(mod).items()):
                if isinstance(obj, CPUDispatcher):
                    qual = obj.py_func.__module__ + "." + obj.py_func.__qualname__
                    out.update(f"{qual}{tuple(str(t) for t in sig)}" for sig in obj.signatures)
        return out
""")


def _new_signatures(body: str, prefix: str = "trn_env") -> list[str]:
    """The signatures of kernels under `prefix` that `body` adds after it sets `before`."""
    code = SIGNATURES + textwrap.dedent(body) + "\nprint(json.dumps(sorted(signatures() - before)))\n"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                          cwd=NEUTRAL_CWD)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return [s for s in json.loads(proc.stdout.strip().splitlines()[-1]) if s.startswith(prefix)]


def test_acq_track_flight_calls_nothing_its_warm_up_did_not():
    new = _new_signatures("""
        from trn_env.scenario.build import build_terrain
        from trn_env.scenario.overrides import load_scenario_with, parse_assignment
        from trn_env.sim.closed_loop import ClosedLoop, spawn_rngs
        from trn_env.sim.warm_up import warm_up

        # GNSS lost at 10 s, the 25-sample transect full at 35 s: tracking from then on
        sc = load_scenario_with("acq_track", [parse_assignment("duration_s=45")])
        dems = build_terrain(sc, sc.extras, spawn_rngs(sc.seed)["map"])
        warm_up(sc, dems, parallel=False)
        before = signatures()
        loop = ClosedLoop(sc, dems=dems, log_sensors=False, pipeline=False)
        result = loop.run()
        loop.close()
        assert any("acq_track: acquiring -> ok: in lock" in str(e) for e in result.events), result.events
    """)
    assert new == []


def test_fast_tier_kernels_do_not_depend_on_the_env_settings():
    new = _new_signatures("""
        import gymnasium as gym
        import numpy as np
        from trn_env.bench.precompile import warm_fast_tier
        from trn_env.env import route_task

        warm_fast_tier()
        before = signatures()
        kw = route_task.fast_tier_kwargs(route_task.env_kwargs("jacksboro"))
        kw.update(navigator="ins", action_mode="turn")
        envs = gym.make_vec("trn_env/TerrainNavFast-v0", num_envs=3, vectorization_mode="vector_entry_point",
                            **kw)
        envs.reset(seed=[4, 5, 6])
        for _ in range(3):
            envs.step(envs.action_space.sample())
        envs.close()
    """, prefix="trn_env.env.")   # (building another terrain's DEMs is the scenario jobs' part)
    assert new == []


def test_precompile_refuses_fewer_than_one_worker(capsys):
    from trn_env.cli import main
    for bad in ("0", "-2"):
        assert main(["precompile", "--workers", bad]) == 2
        err = capsys.readouterr().err
        assert "--workers" in err and bad in err and "Traceback" not in err


def test_ray_workers_read_only_maps_compile_nothing_after_the_scenario_job(tmp_path):
    """Ray's object store hands its workers the campaign's DEMs read-only (checked here on the real store),
    and numba compiles a kernel again for read-only arrays: after precompile's job for the default scenario,
    a run of it as a Ray actor flies it (WarmWorker.prepare's warm-up, then the run, over DEMs from ray.get)
    adds no signature."""
    pytest.importorskip("ray", reason="the ray extra is installed in CI")
    camp = tmp_path / "ray_maps.toml"
    camp.write_text('name = "ray_maps"\nroot_seed = 1\nseeds = 1\nscenarios = ["default"]\n'
                    'duration_s = 20.0\nnavigators = ["ins_tercom"]\n')
    new = _new_signatures(f"""
        import ray
        from trn_env.bench.precompile import warm_job
        from trn_env.campaign import load_campaign
        from trn_env.campaign.driver import tasks
        from trn_env.campaign.ray_pool import warm_run
        from trn_env.campaign.runs import fly_run, set_dems

        warm_job(("default", "ins_tercom", ()))
        before = signatures()
        campaign = load_campaign({str(camp)!r})
        ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
        dems = ray.get(ray.put(campaign.extra["dems"]))
        assert dems and not any(d.heights_m.flags.writeable for d in dems.values())
        task = next(tasks(campaign, set()))
        set_dems(dems)
        warm_run(task)
        row, _ = fly_run(task)
        assert row["termination"] == "time_limit", row["error"]
        ray.shutdown()
    """)
    assert new == []
