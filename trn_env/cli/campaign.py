"""`trn-env campaign` (a Monte Carlo campaign, its regression gate) and `trn-env report`."""

from __future__ import annotations

import sys
from pathlib import Path

from trn_env.cli.common import _interrupt_exit, _print_problems, write_failure


def cmd_campaign(args) -> int:
    from trn_env.campaign import CampaignError, load_campaign, make_backend, run_campaign
    from trn_env.campaign.baseline import read_baseline
    from trn_env.campaign.ray_backend import BackendError
    try:
        backend = make_backend(args.backend, args.workers, args.address)
        backend.preflight()      # Ray importable, its address reachable: before the (slower) validation
        baseline = read_baseline(args.check) if args.check is not None else None
        from trn_env.output.run_folder import file_target_problem, lookup_problem
        if args.write_baseline is not None:          # before the campaign, not after its last run
            problem = file_target_problem(args.write_baseline, "--write-baseline")
            if problem is not None:
                raise ValueError(problem)
        if args.out is not None and (problem := lookup_problem(args.out, "--out")) is not None:
            raise ValueError(problem)
        campaign = load_campaign(args.file)
    except CampaignError as err:
        _print_problems(err, "campaign")
        return 2
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from rich.console import Console

    from trn_env.campaign.driver import reserve_default_out_dir
    out_dir = reserved = None
    try:
        out_dir = args.out
        if out_dir is None:      # a folder of its own, even beside a campaign started in the same second
            if args.resume:
                raise CampaignError(campaign.source, ["--resume: give the campaign's folder with --out"])
            out_dir = reserved = reserve_default_out_dir(campaign.name)
        console = Console()
        if not console.is_terminal:            # a pipe or a CI log: rich would assume 80 columns
            console = Console(width=100)
        stats = run_campaign(campaign, out_dir, backend=backend, resume=args.resume, progress=not args.quiet)
    except CampaignError as err:
        for prob in err.problems:
            print(f"error: {prob}", file=sys.stderr)
        return 2
    except BackendError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:                # the folder could not be made, or a row written (a full disk)
        if out_dir is not None and Path(out_dir, "campaign.json").is_file():
            print(write_failure(exc, f"the campaign {out_dir}",
                                f"the finished runs' rows are in {Path(out_dir, 'runs')}: continue with "
                                "--resume once it can be written"), file=sys.stderr)
        else:
            print(write_failure(exc, f"the campaign folder {out_dir}") + ("; give --out" if args.out is None
                                                                         else ""), file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        code, word = _interrupt_exit(exc)
        print(f"{word}: the finished runs' rows are in {out_dir}/runs (continue with --resume)",
              file=sys.stderr)
        return code
    finally:                              # a reserved folder nothing was written into goes again
        if reserved is not None and reserved.is_dir() and not any(reserved.iterdir()):
            reserved.rmdir()
    return _campaign_outcome(campaign, out_dir, stats, baseline, args, console)


def _campaign_outcome(campaign, out_dir: Path, stats: dict, baseline, args, console) -> int:
    from trn_env.campaign.baseline import compare, comparison_table, make_baseline, write_baseline
    from trn_env.campaign.rows import read_rows
    from trn_env.campaign.stats import summary_table
    df = read_rows(out_dir)
    console.print(summary_table(df, f"campaign {campaign.name}: {len(df)} run(s) -> {out_dir}"))
    rate = f"{stats['runs_per_minute']:.1f} runs/min" if stats["flown"] else "nothing to fly"
    console.print(f"{stats['flown']} flown ({stats['failed']} failed), {stats['already_done']} already done; "
                  f"{rate} on {stats['backend']}")
    status = 0
    if args.write_baseline is not None:
        write_baseline(args.write_baseline, make_baseline(df, campaign.name, campaign.hash))
        console.print(f"baseline written: {args.write_baseline}")
    if baseline is not None:
        comps = compare(df, baseline)
        console.print(comparison_table(comps, f"regression gate against {args.check}"))
        worse = [c for c in comps if c.verdict in ("worse", "missing")]
        better = [c for c in comps if c.verdict == "better"]
        for c in better:
            print(f"warning: {c.group} {c.figure} is much better than the baseline ({c.value:.4g} vs "
                  f"{c.baseline:.4g}); refresh it on purpose with --write-baseline", file=sys.stderr)
        if worse:
            for c in worse:
                if c.verdict == "missing":     # the group or figure is not in this campaign's rows
                    print(f"regression: {c.group} {c.figure}: missing from this campaign (baseline "
                          f"{c.baseline:.4g})", file=sys.stderr)
                    continue
                print(f"regression: {c.group} {c.figure}: {c.value:.4g} vs baseline {c.baseline:.4g} "
                      f"(band ±{c.limit:.3g}): {c.verdict}", file=sys.stderr)
            status = 1
        else:
            console.print(f"regression gate passed ({len(comps)} figure(s), {len(better)} much better)")
    return status


def cmd_report(args) -> int:
    from trn_env.campaign.report import write_report
    try:
        out = write_report(args.dir, args.out)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:            # e.g. a full disk (the report is made in a partial folder, removed)
        where = args.out if args.out is not None else Path(args.dir) / "report"
        print(write_failure(exc, f"the report {where}"), file=sys.stderr)
        return 2
    print(f"report written: {out / 'report.html'}")
    from trn_env.campaign.driver import folder_busy
    from trn_env.campaign.rows import read_manifest, read_rows
    manifest = read_manifest(args.dir) or {}
    planned, have = manifest.get("n_runs"), len(read_rows(args.dir))
    if isinstance(planned, int) and have < planned:
        why = ("the campaign is still flying into this folder: report it again when it ends"
               if folder_busy(Path(args.dir)) else
               f"the campaign did not finish: continue it with trn-env campaign "
               f"{manifest.get('source') or 'FILE'} --out {args.dir} --resume")
        print(f"note: the report covers {have} of the campaign's {planned} runs; {why}", file=sys.stderr)
    return 0
