"""The default walk-through on the zoo of the field's benchmark plants (issue 62, goal 5).

    python benchmarks/bench_zoo.py [--plants wood_berry,air_heater,...] [--runs N]
        [--epochs E] [--steps S] [--seed S] [--out DIR] [--reuse]

For each plant of the zoo (``fmus/examples/build.py``'s ``ZOO``: Wood-Berry, the Shell
fractionator, pH neutralisation, the van de Vusse CSTR, a slow thermal process, the air
heater of issue 62), what a user types, each command a ``cosim`` subprocess
(``examples/own_plant.py``'s helpers), with every default:

1. the plant's folder (``problem.toml``, ``scenario.csv``, ``campaign.toml``) copied into
   ``DIR/<plant>``, its FMU built into ``fmu/``;
2. ``cosim generate-data --problem`` (``--steps`` samples) and ``cosim train`` (its default
   epochs, or ``--epochs``), timed;
3. ``cosim certify --auto-gain-scale --save`` at the scenario's set-points: the verdict and
   rho_s, the contraction rate of V_s (``lem:Vs``);
4. ``cosim tune --save`` (when it fails, the robust MPC's default weights; ``zoo.json``
   says why);
5. ``cosim run scenario.csv`` with the robust MPC and with the PI tuned from the model;
6. ``cosim campaign campaign.toml`` with ``runs`` = ``--runs``: both on the same draws.

Nothing here is plant-specific: every plant is its folder. One row per plant: training time,
the certificate's verdict and rho_s, the robust MPC's infeasible steps after its first
horizon N (from the scenario run's ``results.csv``: steps whose problem had no answer,
``ctrl.status`` 1 or 2, or whose solve was not used, ``ctrl.fallback``: a ``QP_Infeasible``
ends so; ``zoo.json`` also counts every failed solve after N and names their statuses from
``summary.json``'s ``failures_by_status``), the summed IAE over the
campaign (each output's IAE over its box width, summed over outputs and runs) divided by the
PI's, and the constraint violations (violating runs of the campaign's MPC and PI, and the
largest violation of the scenario run, in box widths). ``zoo.json`` holds every number.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "examples")]
import own_plant  # noqa: E402  (examples/own_plant.py: the walk-through's helpers)

#: The plant's files a user copies into their folder.
FILES = ("problem.toml", "scenario.csv", "campaign.toml")
#: ``ctrl.status`` codes of a problem without an answer (controllers.ocp.solve_status:
#: infeasible at x-hat, proved infeasible).
INFEASIBLE_STATUS = (1, 2)


def zoo() -> tuple[str, ...]:
    """The zoo's plants, as ``fmus/examples/build.py`` names them."""
    return tuple(own_plant.examples_build().ZOO)


def prepare(plant: str, work: Path, runs: int) -> dict[str, Path]:
    """The plant's files in ``work`` (the campaign's ``runs`` replaced) and its FMU."""
    work.mkdir(parents=True, exist_ok=True)
    for name in FILES:
        shutil.copyfile(own_plant.EXAMPLES / plant / name, work / name)
    spec = work / "campaign.toml"
    text, count = re.subn(r"(?m)^runs\s*=\s*\d+", f"runs = {runs}", spec.read_text())
    if count != 1:
        raise SystemExit(f"{own_plant.EXAMPLES / plant / 'campaign.toml'}: expected one "
                         "'runs = N' line")
    spec.write_text(text)
    return {"fmu": own_plant.build_plant(plant, work / "fmu"), "spec": spec,
            **{name.split(".")[0]: work / name for name in FILES[:2]}}


def scenario_setpoints(scenario: Path, problem: Any) -> list[np.ndarray]:
    """The scenario's set-points in the order they come (each once)."""
    import pandas as pd

    refs = pd.read_csv(scenario)[[f"ref.{n}" for n in problem.output_names]].ffill()
    out: list[np.ndarray] = []
    for row in refs.dropna().to_numpy(dtype=float):
        if not any(np.array_equal(row, seen) for seen in out):
            out.append(row)
    return out


def closed_loop(files: dict[str, Path], model: Path, controller: str, out: Path,
                problem: Any) -> dict[str, Any]:
    """``cosim run`` of the plant's scenario and what it recorded: its status, the summed IAE
    (each output over its box width), the largest box violation of an output or an input (in
    its box widths), and, for the robust MPC, the solver's failures and the steps after the
    first horizon N whose problem had no answer or whose solve was not used."""
    import pandas as pd

    own_plant.cosim_command("run", files["scenario"], "--plant", files["fmu"], "--controller",
                            controller, "--model", model, "--out", out, "--quiet")
    summary = json.loads((out / "summary.json").read_text())
    kpis, ctrl = summary["kpis"], summary.get("controller_summary", {})
    widths = {c.name: c.max - c.min for c in (*problem.inputs, *problem.outputs)}
    report: dict[str, Any] = {
        "status": summary["status"], "steps": summary["steps"],
        "iae_sum": own_plant.summed(kpis["iae"], problem.outputs),
        "violation": max(v["max"] / widths[name] for name, v in kpis["violations"].items())}
    if controller == "robust-mpc":
        df = pd.read_csv(out / "results.csv")
        late = df.iloc[int(ctrl["N"]):]
        status = late["ctrl.status"].to_numpy()
        bad = (late["ctrl.fallback"].to_numpy() > 0) | np.isin(status, INFEASIBLE_STATUS)
        report.update(N=int(ctrl["N"]), infeasible_after_N=int(bad.sum()),
                      failed_after_N=int(np.sum(status != 0)),
                      fallbacks=int(ctrl.get("fallbacks", 0)),
                      failures_by_status=ctrl.get("failures_by_status", {}),
                      certified=ctrl.get("certified"))
    return report


def campaign(files: dict[str, Path], problem: Any) -> dict[str, Any]:
    """``cosim campaign`` of the plant's spec, read as ``examples/own_plant.py`` reads one,
    with the summed IAE over all runs of the robust MPC divided by the PI's."""
    folder = files["spec"].parent / "campaign"
    own_plant.cosim_command("campaign", files["spec"], "--out", folder, "--force", "--quiet")
    result = own_plant.campaign_results(folder, problem, square=problem.m == problem.p)
    variants = result["variants"]
    mpc, pi = sum(variants["robust-mpc"]["iae_sum"]), sum(variants["pi"]["iae_sum"])
    result["iae_ratio"] = mpc / pi if pi > 0 else math.nan
    return result


def tune(model: Path) -> dict[str, Any]:
    """``cosim tune --save``; when it fails, why (its last line), and the walk-through goes on
    with the robust MPC's default weights, as a user would."""
    try:
        return own_plant.tune(model)
    except SystemExit as exc:
        return {"failed": str(exc).strip().splitlines()[-1]}


def walkthrough(plant: str, work: Path, runs: int, epochs: int | None, steps: int,
                seed: int, reuse: bool = False) -> dict[str, Any]:
    """The default walk-through on ``plant`` in ``work``: the numbers of its table row;
    ``reuse``: the model ``work`` holds from an earlier run, not trained again (its training
    time then ``None``)."""
    from controllers.problem_file import load

    files = prepare(plant, work, runs)
    problem = load(files["problem"])
    model, train_s = work / "models" / "plant_gru.json", None
    if not (reuse and model.is_file()):
        model, train_s = own_plant.identify(files["fmu"], files["problem"], work, epochs,
                                            seed, steps=steps)
    setpoints = scenario_setpoints(files["scenario"], problem)
    report: dict[str, Any] = {
        "plant": plant, "problem": problem.describe(), "steps": steps, "epochs": epochs,
        "train_s": None if train_s is None else round(train_s, 1),
        "certify": own_plant.certify(model, problem, setpoints, unusable_ok=True)}
    report["tune"] = tune(model)
    runs_dir = work / "runs"
    report["pi"] = closed_loop(files, model, "pi", runs_dir / "pi", problem)
    if not report["certify"]["usable"]:        # no robust MPC runs this model
        return report
    report["robust-mpc"] = closed_loop(files, model, "robust-mpc", runs_dir / "robust-mpc",
                                       problem)
    report["iae_ratio_run"] = report["robust-mpc"]["iae_sum"] / report["pi"]["iae_sum"]
    if runs:
        report["campaign"] = campaign(files, problem)
    return report


def row(r: dict[str, Any]) -> str:
    """The plant's line of the table."""
    v = r["certify"]
    verdict = ("certified" if v["certified"] else "uncertified" if v["usable"]
               else "not usable")
    mpc, camp = r.get("robust-mpc", {}), r.get("campaign", {})
    violating = ("-" if not camp else
                 f"{camp['variants']['robust-mpc']['violating']}/"
                 f"{camp['variants']['pi']['violating']} runs")
    train = "reused" if r["train_s"] is None else f"{r['train_s']:.0f}"
    return (f"{r['plant']:<19} {train:>8} {verdict:>12} {v['rho_s']:>9.5f} "
            f"{mpc.get('infeasible_after_N', '-'):>11} "
            f"{camp.get('iae_ratio', math.nan):>10.3f} {violating:>13} "
            f"{mpc.get('violation', math.nan):>9.3g}")


HEADER = (f"{'plant':<19} {'train s':>8} {'verdict':>12} {'rho_s':>9} {'infeasible':>11} "
          f"{'IAE÷PI':>10} {'MPC/PI viol.':>13} {'run viol.':>9}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", default=None,
                        help=f"comma-separated, of {', '.join(zoo())} (default: all)")
    parser.add_argument("--runs", type=int, default=own_plant.RUNS,
                        help=f"campaign runs per controller (default {own_plant.RUNS}; 0: none)")
    parser.add_argument("--epochs", type=int, default=None,
                        help="cosim train --epochs (default: cosim train's)")
    parser.add_argument("--steps", type=int, default=own_plant.STEPS,
                        help=f"cosim generate-data --steps (default {own_plant.STEPS})")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--reuse", action="store_true",
                        help="keep the model an earlier run left in --out (certify, tune, "
                             "runs and campaign again; no data or training)")
    args = parser.parse_args(argv)
    plants = args.plants.split(",") if args.plants else list(zoo())
    unknown = [p for p in plants if p not in zoo()]
    if unknown:
        parser.error(f"--plants: unknown {unknown[0]!r} (known: {', '.join(zoo())})")
    out = args.out or Path(tempfile.mkdtemp(prefix="bench-zoo-"))
    print(HEADER, flush=True)
    reports = []
    for plant in plants:
        reports.append(walkthrough(plant, out / plant, args.runs, args.epochs, args.steps,
                                   args.seed, args.reuse))
        print(row(reports[-1]), flush=True)
        if "failed" in reports[-1]["tune"]:
            print(f"  {plant}: cosim tune failed ({reports[-1]['tune']['failed']}): the "
                  "walk-through went on with the robust MPC's default weights", flush=True)
        (out / "zoo.json").write_text(json.dumps(reports, indent=1) + "\n")
    print(f"files in {out}; every number in {out / 'zoo.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
