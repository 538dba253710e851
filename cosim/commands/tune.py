"""``cosim tune``: the robust MPC's cost weights chosen on the model, as the PI is tuned from it
(:func:`cosim.tuning.tune`, its Python twin ``cosim.tune``)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

HELP = "choose the robust MPC's cost weights on the model itself, against the PI tuned from it"

DESCRIPTION = """\
Run the robust MPC (its tracking law) with a few cost weightings, and the PI baseline tuned
from the same model, in closed loop with the GRU model itself as the plant (no FMU needed)
on a set-point scenario: --scenario, else steps between four steady outputs the model
reaches with its inputs inside their box (inside the output box by a twentieth of it, or two
noise standard deviations where that is more), each held six of its slowest time constants,
with Gaussian sensor noise whose standard deviation is the one cosim train measured on the
data (else the model's one-step prediction error, its 95th percentile, or the largest error
w_y_bar: upper estimates, so that a weighting that passes the noise on to the inputs loses
where the data were noisy). The plant is never the model: each weighting runs again with one
manipulated input's gain 1 + U times the model's, then 1 - U times (--gain-uncertainty,
default 0.5), one input at a time, without the noise: 2 m runs more for each weighting
within the bound below. Of the weightings whose input total variation is at most --tv-ratio
times the PI's (default 1.2), or the defaults' where they move more (none: the defaults),
keep those with the fewest samples outside the output box over all runs, of them those with
the fewest runs that leave it, and of those the lowest summed IAE over every run (each
output's IAE over its box width). A plant that is not square has no PI baseline: the
defaults are the reference then.

The candidates, in normalised units: the defaults (Q = I, R = 0.01 I, S = 0.05); the stage
cost on the outputs (Q = "outputs"); the same with light input weights (R = 0.001, S =
0.01); without the input-rate weight (R = 0.001, S = 0), fast where the sensors are clean
and the model is close; and the defaults with heavier move suppression (S = 0.5, 5, 50),
what a plant whose gains differ from the model's needs to stay stable. The closed loops run
in parallel worker processes (--workers), under one progress bar. --save writes the choice
into the model file's problem as its [mpc] table
(atomically: a failed write, or Ctrl-C at any time, leaves the file as it was), which every
later run of the model uses under its own --option values (a --problem file with an [mpc]
table replaces it).

examples:
  cosim tune models/plant_gru.json                      # the table, nothing written
  cosim tune models/plant_gru.json --save               # and the choice into the model
  cosim tune models/plant_gru.json --scenario steps.csv --tv-ratio 1.0"""

def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``tune`` sub-command."""
    p = subparsers.add_parser("tune", help=HELP, description=DESCRIPTION,
                              epilog=exit_codes_help(),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.json", help="GRU model file with its problem")
    p.add_argument("--scenario", metavar="CSV", default=None,
                   help="set-point scenario to tune on (default: generated from the model)")
    p.add_argument("--tv-ratio", type=float, default=1.2, dest="tv_ratio",
                   help="largest input total variation allowed, times the PI's (default 1.2)")
    p.add_argument("--save", action="store_true",
                   help="write the choice into the model file's problem ([mpc])")
    p.add_argument("--workers", type=int, default=0,
                   help="worker processes for the closed loops (default 0: one per CPU, at "
                        "most one per run, unless the runs are short; 1: in this process); "
                        "the same choice either way")
    p.add_argument("--law", default=None, metavar="LAW",
                   help="the robust MPC's law to tune (tracking, paper, or a law module; "
                        "default: tracking, the default law)")
    p.add_argument("--gain-uncertainty", type=float, default=0.5, dest="gain_uncertainty",
                   metavar="U", help="each weighting also runs with each manipulated input's gain "
                                     "1 + U times the model's (default 0.5; 0: the model alone)")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Tune (:func:`cosim.tuning.tune`), print the table, the hint and what was saved."""
    import sys

    from cosim.core.errors import ParameterError
    from cosim.tuning import tune

    try:
        result = tune(args.model, args.scenario, tv_ratio=args.tv_ratio, save=args.save,
                      progress=not args.quiet and sys.stderr.isatty(), workers=args.workers,
                      law=args.law, gain_uncertainty=args.gain_uncertainty)
    except ParameterError as exc:   # worded for the command line: --tv-ratio
        raise exc.as_option() from None
    if args.json:
        print(json.dumps(result.to_dict(), indent=1))
        return 0
    if args.quiet:
        return 0
    where = f"scenario {result.scenario}" if result.scenario else "the model's own steps"
    of = ("the PI's" if result.against == "pi"
          else "the defaults' (no PI: not a square plant)")
    print(f"{args.model} as the plant, {where}; summed IAE and input TV ÷ {of}:")
    for name, r in result.rows.items():
        mark = "  <- chosen" if name == result.chosen else ""
        robust = ("(not run with the gains: too much input motion)"
                  if r["iae_all"] is None else f"samples out of the box {r['violations_all']}"
                  + (f" (in {r['violating_runs']} runs)" if r["violating_runs"] else "")
                  + f"  IAE of every run {r['iae_all']:.3f}")
        print(f"  {name:26s} IAE {r['iae']:.3f}  TV {r['tv']:.3f}  violations "
              f"{r['violations']:<4d} {robust}{mark}")
    if result.hint:
        print(f"cosim tune: hint: {result.hint}")
    if result.saved:
        print(f"cosim tune: {args.model}: [mpc] {_toml(result.options)}")
    return 0


def _toml(options: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {json.dumps(v)}" for k, v in options.items())
