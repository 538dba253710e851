"""``cosim tune``'s wall time per example plant, in one process and in parallel workers
(issue 48; aim: at most 60 s on 2 cores for every example plant, the 3 x 3 three-zone furnace
included, the same choice).

For each plant: its FMU built (``fmus/examples``), identification data generated, a GRU
trained with ``cosim train``'s defaults (``--epochs`` shortens it; ``--models DIR`` keeps
the models for the next time) — or the shipped four-tank model — then ``cosim tune`` timed
three times: first with the default workers (one per CPU) as a user meets it on a new model
(its compiled kernels built then, unless an earlier run left them in the cache), then, the
kernels cached, with ``--workers 1`` (the baseline, in the same run) and with the default
workers again. Printed: the three times, the ratio of the last two, and whether every run
chose the same weighting.

Usage::

    .venv/bin/python benchmarks/bench_tune.py
        [--plants fourtank,cstr,heater,mixing_tank,furnace,furnace3] [--epochs E] [--models DIR]
        [--gain-uncertainty U]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PLANTS = ("fourtank", "cstr", "heater", "mixing_tank", "furnace", "furnace3")


def model_of(plant: str, folder: Path, epochs: int | None) -> Path:
    """The plant's GRU: the shipped one for the four tanks, else trained here."""
    from controllers.model import DEFAULT_MODEL
    from cosim.cli import main

    out = folder / f"{plant}_gru.json"
    if out.is_file():
        return out
    if plant == "fourtank":
        out.write_bytes(Path(DEFAULT_MODEL).read_bytes())
        return out
    spec = importlib.util.spec_from_file_location("example_plants",
                                                  ROOT / "fmus" / "examples" / "build.py")
    examples = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(examples)  # type: ignore[union-attr]
    fmu = examples.build(plant, folder / plant)
    problem = examples.problem_file(plant)
    data = folder / f"{plant}.csv"
    quiet = contextlib.redirect_stdout(io.StringIO())
    with quiet:
        assert main(["generate-data", "--plant", str(fmu), "--problem", str(problem),
                     "--steps", "20000", "--out", str(data), "--quiet"]) == 0
        train = ["train", str(data), "--out", str(out), "--quiet"]
        assert main(train + (["--epochs", str(epochs)] if epochs else [])) == 0
    return out


def timed_tune(model: Path, workers: int, gain_uncertainty: float | None
               ) -> tuple[float, str]:
    from cosim.tuning import tune

    more = {} if gain_uncertainty is None else {"gain_uncertainty": gain_uncertainty}
    t0 = time.perf_counter()
    result = tune(model, workers=workers, **more)
    return time.perf_counter() - t0, result.chosen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plants", default=",".join(PLANTS),
                        help=f"comma-separated, of {', '.join(PLANTS)}")
    parser.add_argument("--epochs", type=int, default=None,
                        help="training epochs (default: cosim train's)")
    parser.add_argument("--models", metavar="DIR", default=None,
                        help="keep the trained models there, and use those found there")
    parser.add_argument("--gain-uncertainty", type=float, default=None,
                        help="cosim tune's --gain-uncertainty (default: its default; 0 times "
                             "the runs on the model alone)")
    args = parser.parse_args()
    plants = [p.strip() for p in args.plants.split(",") if p.strip()]
    bad = [p for p in plants if p not in PLANTS]
    if bad:
        raise SystemExit(f"--plants: unknown {bad[0]!r} (known: {', '.join(PLANTS)})")
    gains = "tune's" if args.gain_uncertainty is None else f"{args.gain_uncertainty:g}"
    print(f"cosim tune per plant, {os.cpu_count()} CPUs, gain uncertainty {gains}; training: "
          f"{'cosim train defaults' if args.epochs is None else f'{args.epochs} epochs'}")
    print(f"{'plant':12s} {'m x p':>5s} {'first':>8s} {'1 process':>10s} {'workers':>9s} "
          f"{'ratio':>6s}  same choice")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.models) if args.models else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for plant in plants:
            from controllers.model import GRUModel

            model = model_of(plant, folder, args.epochs)
            pr = GRUModel.load(model).problem
            first, chosen = timed_tune(model, 0, args.gain_uncertainty)
            one, chosen_one = timed_tune(model, 1, args.gain_uncertainty)
            par, chosen_par = timed_tune(model, 0, args.gain_uncertainty)
            worst = max(worst, first, par)
            same = "yes" if chosen == chosen_one == chosen_par else "NO"
            print(f"{plant:12s} {pr.m:>2d} x {pr.p:<2d} {first:6.1f} s {one:8.1f} s "
                  f"{par:7.1f} s {one / par:5.2f}x  {same} ({chosen})", flush=True)
    print(f"slowest tune with workers: {worst:.1f} s (aim: at most 60 s)")


if __name__ == "__main__":
    main()
