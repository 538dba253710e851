"""``cosim campaign``: many seeded closed-loop runs on Dask (``cosim.campaign``)."""

from __future__ import annotations

import argparse
import sys

from cosim.core.errors import (
    EXIT_FAILED,
    EXIT_INPUT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_OK,
    exit_codes_help,
)

#: What the exit codes also mean for ``cosim campaign`` (:func:`cosim.core.errors.exit_codes_help`).
EXIT_NOTES = {
    EXIT_OK: "every run ran (violations are results, not errors)",
    EXIT_FAILED: "some runs failed (the campaign went on; they are in runs.parquet)",
    EXIT_INPUT_ERROR: "a bad spec (file:line) or option",
    EXIT_INTERRUPTED: "finished runs are kept (--resume runs the missing ones)",
}

HELP = "run a campaign: many seeded runs of a scenario on Dask, with violation statistics"

DESCRIPTION = """\
Run one scenario many times, each run with its own seeded draws (plant parameters, sensor
noise and bias, set-point sequences, initial states), once per controller variant, on a local
Dask cluster (default: one worker process per core) or on an existing one (--scheduler). Run
i's draws depend on (seed, i) only: one worker, many or a cluster give the same per-run KPIs.

Writes into DIR (default results/campaigns/<name>):
  runs/<run>-<variant>/  results.csv and summary.json of each run, as cosim run writes them
  runs.parquet           one row per run and variant: draws, status, reason, KPIs, those
                         of each signal named after it (iae.<output>, tv.<input>, ...)
  summary.json           runs, ok, failed, violating runs, the one-sided 95 % Clopper-Pearson
                         bound on the violation probability, KPI quantiles per variant,
                         failures grouped by reason
  report.png             violations and KPI distributions per variant, the worst run
                         (a panel per output and input, in the problem's units)
  campaign.json          the spec and its fingerprint (for --resume)

A run that fails or exceeds its timeout is recorded as failed with its reason (an internal
error also leaves runs/<run>-<variant>/traceback.txt) and the campaign goes on. A run whose
worker process dies under it is run again, 3 tries at most (column tries); one that kills its
worker every time is recorded as failed. Ctrl-C or SIGTERM keeps every finished run;
--resume then runs only the missing ones. The spec format is in the docs
(docs/guide/campaigns.md) and in scenarios/campaigns/*.toml."""

EPILOG = """\
an existing Dask cluster (scheduler and workers need this project installed; any number
of worker processes and threads; 127.0.0.1 here):
  dask scheduler --host 127.0.0.1 --port 8786 &
  dask worker tcp://127.0.0.1:8786 &
  cosim campaign spec.toml --scheduler tcp://127.0.0.1:8786
  (a scheduler that cannot be reached within 10 s: exit 2; with the scheduler's
  distributed.scheduler.allowed-failures at 0 the tries counted are the only ones)

examples:
  cosim campaign scenarios/campaigns/theorem.toml
  cosim campaign spec.toml --workers 2 --out results/my-campaign
  cosim campaign spec.toml --resume            # after Ctrl-C: only the missing runs

""" + exit_codes_help({"campaign": EXIT_NOTES})


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``campaign`` sub-command."""
    p = subparsers.add_parser("campaign", help=HELP, description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("spec", metavar="SPEC.toml", help="campaign specification (TOML)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="output folder (default: results/campaigns/<name>)")
    p.add_argument("--workers", metavar="N", type=int, default=None,
                   help="local Dask worker processes, one thread each (default: the number "
                        "of cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="use an existing Dask cluster, e.g. tcp://127.0.0.1:8786 (exit 2 when "
                        "it cannot be reached within 10 s)")
    p.add_argument("--worker-timeout", metavar="SECONDS", type=float, default=None,
                   help="seconds the cluster may have no worker before the campaign stops, the "
                        "runs still waiting not run (exit 1; default 120 on the local "
                        "cluster, 600 with --scheduler; --resume runs them later)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--resume", action="store_true",
                   help="run only the runs missing in DIR (the spec must be unchanged)")
    g.add_argument("--force", action="store_true",
                   help="start over in a DIR that holds a campaign (its runs are removed)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    from cosim.commands import add_hmi_arguments

    add_hmi_arguments(p, "the campaign's page (its runs and their KPIs as they finish, each "
                         "linked to its page)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``cosim campaign``; returns the exit code."""
    import contextlib
    from pathlib import Path

    from cosim.campaign import engine
    from cosim.campaign.spec import load
    from cosim.commands import hmi_options
    from cosim.core.errors import EXIT_FAILED, EXIT_OK

    hmi = hmi_options(args)
    spec = load(args.spec)
    page = contextlib.nullcontext()
    if hmi is not None:
        from cosim.hmi.serving import serving_campaign

        out = Path(args.out) if args.out else Path("results") / "campaigns" / spec.name
        page = serving_campaign(out, hmi, lambda text: print(f"cosim campaign: {text}",
                                                             file=sys.stderr, flush=True))
    with page:
        result = engine.run_campaign(spec, args.out, workers=args.workers,
                                     scheduler=args.scheduler, resume=args.resume,
                                     force=args.force, worker_timeout=args.worker_timeout,
                                     progress=not args.quiet and sys.stderr.isatty())
    if not args.quiet:
        _print_summary(result)
    if result.error is not None:
        raise result.error
    return EXIT_FAILED if result.status == "failed" else EXIT_OK


def _print_summary(result: object) -> None:
    """Per variant: runs, failed, violating, the bound, and the median IAE of each output
    (in its unit × s); then the most frequent failure reasons."""
    from cosim.campaign import report
    from cosim.core.plots import times_s

    s = result.summary  # type: ignore[attr-defined]
    print(f"cosim campaign: {s.get('campaign')}: {s.get('runs', 0)} of {s.get('planned')} runs "
          f"on disk, {s.get('failed', 0)} failed; results in {result.out}")  # type: ignore
    table = getattr(result, "table", None)
    signals = {} if table is None else report.run_signals(
        result.out / "runs", table)  # type: ignore[attr-defined]
    units = {o: (v or {}).get("unit") or "" for o, v in (signals.get("outputs") or {}).items()}
    for name, v in (s.get("variants") or {}).items():
        p = v.get("violation_probability_upper_95")
        line = (f"  {name}: {v['runs']} runs, {v['failed']} failed, {v['violating_runs']} "
                f"violating (P(violation) <= {p:.3g} at 95 %)" if p is not None else
                f"  {name}: {v['runs']} runs")
        medians = [f"{o} {q['q50']:.4g} {times_s(units.get(o))}"
                   for kpi, q in (v.get("quantiles") or {}).items()
                   if kpi.startswith("iae.") and q and (o := kpi[len("iae."):])]
        if medians:
            line += "; median IAE " + ", ".join(medians)
        print(line)
    for group in list((s.get("failures_by_reason") or {}).values())[:5]:
        print(f"  failed ({group['count']}): {group['example']}")
