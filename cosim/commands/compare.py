"""``cosim compare``: check a result CSV against a reference inside a tolerance band."""

from __future__ import annotations

import argparse
import math

from cosim.core.errors import EXIT_FAILED, EXIT_INPUT_ERROR, EXIT_OK, CosimError, exit_codes_help

__all__ = ["DESCRIPTION", "EPILOG", "EXIT_NOTES", "register", "run"]

#: What the exit codes also mean for ``cosim compare`` (:func:`cosim.core.errors.exit_codes_help`).
EXIT_NOTES = {
    EXIT_OK: "every compared signal within the tolerance band",
    EXIT_FAILED: "at least one signal outside the band",
    EXIT_INPUT_ERROR: "also a signal missing in one file, no common signals, non-increasing "
                      "time, a --atol/--rtol NAME that is not a compared signal",
}

DESCRIPTION = """\
Compare RESULT.csv with REFERENCE.csv signal by signal.

Signals are matched by column name (the first column of each file is the time in
seconds). By default every signal is compared and a signal present in only one file is an
error; --signals chooses a subset. Both files are compared on the union of their time
grids, interpolating piecewise-linearly between samples (values at sample times are taken
exactly); a time covered by only one file counts as a point outside.

Tolerance rules:
  pointwise (default)  |result - reference| <= atol + rtol*|reference|
  --band               the reference's min/max over [t - window, t + window] (default
                       window: one reference sample), widened by atol + rtol*range,
                       range = max - min of the reference; tolerates small time shifts
                       of steps and events (FMI cross-check style)

The report is a table: per signal the largest |result - reference| and its time, the
tolerances, the number and fraction of points outside the band and PASS/FAIL; then, for
each failing signal, its first and worst time outside the band."""

EPILOG = f"""\
tolerances per signal: --atol/--rtol take a number or NAME=VALUE pairs, NAME a compared
signal as its column is named (results.csv: plant.h1, ctrl.qa, ...), e.g.
  --atol 1e-9,plant.h1=1e-4,plant.h2=1e-4  (a bare number is the default for the others;
  a NAME that is not compared is an error)

{exit_codes_help({"compare": EXIT_NOTES})}

example:
  cosim compare results/run/results.csv scenarios/references/paper_steps__pi.csv \\
      --signals plant.h1,plant.h2,ctrl.qa,ctrl.qb --band --plot compare.png"""


def _tolerance(text: str) -> float | dict[str, float]:
    """Parse ``1e-4`` or ``1e-4,h1=1e-3,qa=0`` (a mapping with ``"*"`` as the default)."""
    values: dict[str, float] = {}
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        name, sep, value = part.rpartition("=")
        key = name.strip() if sep else "*"
        if sep and not key:
            raise argparse.ArgumentTypeError(f"'{part}': no signal name before '='")
        values[key] = _window(value)
    if not values:
        raise argparse.ArgumentTypeError("empty tolerance")
    if set(values) == {"*"}:
        return values["*"]
    return values


def _window(text: str) -> float:
    """A finite number >= 0 (a time window, a tolerance)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"'{text}' must be finite and >= 0")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compare`` sub-command."""
    p = subparsers.add_parser(
        "compare",
        help="compare a result CSV with a reference inside a tolerance band",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("result", metavar="RESULT.csv", help="the result to check")
    p.add_argument("reference", metavar="REFERENCE.csv", help="the reference result")
    p.add_argument("--signals", metavar="A,B,...",
                   help="comma-separated signals to compare (default: all; each must be in "
                        "both files)")
    p.add_argument("--rtol", type=_tolerance, metavar="R",
                   help="relative tolerance (default 1e-4)")
    p.add_argument("--atol", type=_tolerance, metavar="A",
                   help="absolute tolerance in the signal's unit (default 1e-9)")
    p.add_argument("--band", action="store_true",
                   help="use the cross-check band (window min/max of the reference) instead "
                        "of the pointwise rule")
    p.add_argument("--window", type=_window, metavar="SECONDS",
                   help="half-width of the --band window (default: one reference sample)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="also write a figure: signal, reference, band, failing points")
    p.add_argument("--quiet", action="store_true",
                   help="print only failing signals and the verdict (nothing on success)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``cosim compare``; returns 0 (pass) or 1 (fail), raises CosimError (exit 2)."""
    from cosim.core.compare import DEFAULT_ATOL, DEFAULT_RTOL, compare
    from cosim.core.plots import compare_figure

    if args.window is not None and not args.band:
        raise CosimError("--window applies only with --band")
    if args.plot:
        from cosim.core.outpaths import figure_file

        figure_file(args.plot, "--plot")
    signals = args.signals.split(",") if args.signals is not None else None
    rtol = DEFAULT_RTOL if args.rtol is None else args.rtol
    atol = DEFAULT_ATOL if args.atol is None else args.atol
    result = compare(args.result, args.reference, signals=signals, rtol=rtol, atol=atol,
                     band=args.band, window=args.window)
    text = result.report(quiet=args.quiet)
    if text:
        print(text)
    if args.plot:
        try:
            path = compare_figure(result, args.plot)  # a failed write: OutputError, exit 1
        except ValueError as exc:
            raise CosimError(f"{args.plot}: cannot draw the figure: {exc}") from None
        if not args.quiet:
            print(f"figure:    {path}")
    return EXIT_OK if result.passed else EXIT_FAILED
