"""What validating a campaign costs per variant, beside validating the same variants one by one as a
scenario on its own is validated (every DEM read, the trim run and the terrain spectrum fitted each time),
measured in the same run.

    python scripts/campaign_validation_cost.py [--path sensors.ira.range_noise_m] [--points 100] [--alone 30]

The campaign: the built-in default scenario, the navigators ins, pmf and pf, and a sweep of `--path` over
`--points` values from 1 to 11 (3 x points variants, one seed). A sensor's setting leaves the flight's start
alone (one trim for all); the wind (`--path wind.layers.0.speed_mps`) changes it at every point. The
campaign is loaded once to warm the imports and the numba caches, then timed
(`trn_env.campaign.load_campaign`). The reference: the first `--alone` of its variants validated each with
`trn_env.scenario.validate` and the kept answers forgotten before each.
Prints one JSON line: the ms per variant of each, their ratio, the load average. Bad arguments: a message and
exit 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path


def _campaign_text(path: str, points: int) -> str:
    speeds = ", ".join(f"{1.0 + 10.0 * i / points:.6f}" for i in range(points))
    return ('name = "validation_cost"\nseeds = 1\nscenarios = ["default"]\n'
            'navigators = ["ins", "pmf", "pf"]\n'
            f'[[sweeps]]\npath = "{path}"\nvalues = [{speeds}]\n')


def _forget_kept_answers() -> None:
    from trn_env.scenario import build, maps
    build._TRIM_CHECKED.clear()
    maps._SPECTRUM_FITTED.clear()


def measure(path: str, points: int, alone: int) -> dict:
    from trn_env.campaign import load_campaign
    from trn_env.scenario.loading import apply_overrides, read_scenario_file, validate
    from trn_env.scenario.overrides import apply_fields
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp) / "validation_cost.toml"
        file.write_text(_campaign_text(path, points), encoding="utf-8")
        load_campaign(file)                                   # imports, numba caches
        _forget_kept_answers()
        t0 = time.perf_counter()
        campaign = load_campaign(file)
        campaign_s = time.perf_counter() - t0
    data, _ = read_scenario_file("default")
    alone_s = 0.0
    for v in campaign.variants[:alone]:
        d = apply_fields(apply_overrides(data, **v.overrides), v.assignments)
        _forget_kept_answers()
        t0 = time.perf_counter()
        validate(d, source="default")
        alone_s += time.perf_counter() - t0
    n = len(campaign.variants)
    return {"path": path, "variants": n, "campaign_ms_per_variant": round(1e3 * campaign_s / n, 2),
            "alone_variants": min(alone, n), "alone_ms_per_variant": round(1e3 * alone_s / min(alone, n), 2),
            "speedup": round((alone_s / min(alone, n)) / (campaign_s / n), 2),
            "load_average_1min": round(os.getloadavg()[0], 2)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--path", default="sensors.ira.range_noise_m", help="the swept scenario field")
    parser.add_argument("--points", type=int, default=100, help="sweep points (variants = 3 x points)")
    parser.add_argument("--alone", type=int, default=30, help="variants validated one by one (the reference)")
    args = parser.parse_args(argv)
    if not 1 <= args.points <= 10_000:
        print(f"error: --points: give 1 to 10000 (got {args.points})", file=sys.stderr)
        return 2
    if not 1 <= args.alone <= 3 * args.points:
        print(f"error: --alone: give 1 to 3 x --points (got {args.alone})", file=sys.stderr)
        return 2
    from trn_env.campaign import CampaignError
    try:
        print(json.dumps(measure(args.path, args.points, args.alone)))
    except CampaignError as err:
        print(f"error: --path {args.path}: {'; '.join(err.problems)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
