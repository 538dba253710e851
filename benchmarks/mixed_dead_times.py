"""Inputs with different dead times (issue 46): the robust MPC that knows each input's dead time
against ones that take one dead time for both, on a plant that is the model itself.

The plant is the shipped four-tank GRU with its pump ``qb`` acting ``--lag`` samples after
``qa`` (``model:FILE``: the model with the delays of its problem, so the prediction is exact),
on the paper scenario (``scenarios/paper_steps.csv``). Controllers: the robust MPC on the same
model with both dead times, with ``--lag`` samples for both inputs, and with none; the tracking
law, and the paper's law with its horizon lengthened by the lag (``N = 15 + lag``). Printed per
controller: the summed IAE of the outputs (both levels [m·s]), its ratio to the one that
knows both dead times, fallbacks and output-constraint violations.

Usage::

    .venv/bin/python benchmarks/mixed_dead_times.py [--lag 6]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "paper_steps.csv"


def _model(folder: Path, delays: tuple[int, int]) -> Path:
    """The shipped model with ``delays`` on (qa, qb) (the test's helper)."""
    from tests.cosim.adapters.test_mixed_dead_times import delayed_model

    return delayed_model(folder, f"gru_{delays[0]}_{delays[1]}", delays)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lag", type=int, default=6, help="qb's dead time beyond qa's")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import cosim

    lag = args.lag
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        plant = f"model:{_model(folder, (0, lag))}"
        models = {"both dead times": _model(folder, (0, lag)),
                  f"{lag} samples for both": _model(folder, (lag, lag)),
                  "none": _model(folder, (0, 0))}
        for law, options in (("tracking", {}), ("paper", {"law": "paper", "N": 15 + lag})):
            print(f"{law} law, qb {lag} samples after qa, {SCENARIO.name}")
            first = None
            for name, model in models.items():
                run = cosim.run(SCENARIO, plant=plant, model=model, options=options,
                                figure=False)
                df = run.to_pandas()
                dt = float(df["time"].iloc[1] - df["time"].iloc[0])
                iae = float(sum((df[f"plant.{y}"] - df[f"ref.{y}"]).abs().sum() * dt
                                for y in run.result.references))
                first = first or iae
                viol = sum(v["count"] for v in run.summary["kpis"]["violations"].values())
                print(f"  {name:22s} IAE {iae:8.1f} m·s  ({iae / first:.2f}x)  fallbacks "
                      f"{run.summary['controller_summary'].get('fallbacks', 0):3d}  "
                      f"violations {viol}  status {run.status}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
