"""The robust MPC against the PI on plants with measured disturbances (and dead time), on
campaigns (issue 46; docs: design/disturbances.md, "Measured").

Two example plants (``--plant``): ``heater_dead_time`` (its power acts 40 s, two samples,
late; its ambient temperature ``T_in`` measured; set-points 40 -> 55 -> 45 -> 60 degC) and
``furnace_load`` (the 2 x 2 two-zone furnace with its product throughput ``load`` measured;
set-points on both zones). As a user runs them: build the FMU, ``cosim generate-data``,
``cosim train`` (its defaults unless ``--epochs``), then two campaigns of ``--runs`` runs with
the heat capacity drawn +-10 % per run: set-point steps only, and with disturbance steps
(``[disturbances]``: levels drawn in the plant's range, the heater's 4 held 2000 s each, the
furnace's 6 held 1500 s each). Variants: the robust
MPC, the PI with its static feedforward, the PI without. Printed per campaign: the MPC's
summed IAE over each PI's, each controller's set-point overshoot (median and largest, share
of the step) and the runs with a constraint violation.

``--oracle`` also runs the IAE oracle of ``oracle_bound.py`` on every run of both campaigns
(the plant's own equations with the run's drawn heat capacity, its true state, the
disturbance measured now and held, the power still in the pipe; no future set-point or
disturbance): its summed IAE over the PI's is the best ratio a causal controller could reach
(up to the oracle's horizon and IPOPT's local optima), and the MPC's over the oracle's says
how close the MPC comes to it (issue 46's aim: at most 1.15x).

Usage::

    .venv/bin/python benchmarks/disturbance_campaign.py [--plant heater_dead_time]
        [--runs 20] [--steps 12000] [--epochs N] [--out DIR] [--oracle]

An ``--out`` folder keeps the trained model: a second run with it skips identification.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))



@dataclass(frozen=True)
class Case:
    """A plant of the benchmark: its example name, its set-point steps ``(time, set-points
    by output)`` (``None``: the run's end), the measured disturbance's name, its value at the
    start, the range its campaign steps are drawn in, how many and how long each is held."""

    plant: str
    title: str
    steps: tuple[tuple[float, dict[str, float] | None], ...]
    disturbance: str
    start: float
    levels: tuple[float, float]
    count: int
    hold: float

    @property
    def problem(self) -> Path:
        return ROOT / "fmus" / "examples" / self.plant / "problem.toml"

    @property
    def outputs(self) -> list[str]:
        first = self.steps[0][1]
        assert first is not None
        return list(first)


CASES = {c.plant: c for c in (
    Case("heater_dead_time", "heater with a 40 s dead time, ambient measured",
         ((0.0, {"T": 40.0}), (1000.0, {"T": 55.0}), (4000.0, {"T": 45.0}),
          (6000.0, {"T": 60.0}), (8000.0, None)), "T_in", 20.0, (10.0, 30.0), 4, 2000.0),
    Case("furnace_load", "two-zone furnace, product throughput measured",
         ((0.0, {"T1": 150.0, "T2": 150.0}), (1000.0, {"T1": 170.0, "T2": 160.0}),
          (3500.0, {"T1": 155.0, "T2": 170.0}), (6500.0, {"T1": 180.0, "T2": 180.0}),
          (9000.0, None)), "load", 20.0, (0.0, 50.0), 6, 1500.0),
)}
VARIANTS = (("mpc", "robust-mpc", {}), ("pi-ff", "pi", {}),
            ("pi", "pi", {"feedforward": False}))


def _build_plant(folder: Path, plant: str) -> Path:
    spec = importlib.util.spec_from_file_location("example_plants",
                                                  ROOT / "fmus" / "examples" / "build.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(plant, folder)


def _scenario(case: Case) -> str:
    """The campaign's scenario: the set-point steps, the disturbance's start value."""
    refs = [f"ref.{o}" for o in case.outputs]
    lines = [",".join(["time", *refs, f"dist.{case.disturbance}"])]
    for i, (t, ys) in enumerate(case.steps):
        cells = ["" if ys is None else repr(ys[o]) for o in case.outputs]
        lines.append(",".join([f"{t:g}", *cells, repr(case.start) if i == 0 else ""]))
    return "\n".join(lines) + "\n"


def _spec(folder: Path, case: Case, name: str, fmu: Path, model: Path, runs: int,
          disturbed: bool) -> Path:
    lines = ["[campaign]", f'name = "{name}"', f"runs = {runs}", "seed = 7",
             'scenario = "steps.csv"', f'plant = "{fmu}"', f'model = "{model}"',
             f'problem = "{case.problem}"', "", "[draw]",
             '"plant.C_factor" = { uniform = [0.9, 1.1] }', ""]
    if disturbed:
        low, high = case.levels
        lines += ["[disturbances]", f"count = {case.count}", f"hold = {case.hold!r}",
                  f"{case.disturbance} = [{low!r}, {high!r}]", ""]
    for vname, controller, options in VARIANTS:
        lines += ["[[variant]]", f'name = "{vname}"', f'controller = "{controller}"']
        if controller == "pi":
            lines.append(f'model = "{model}"')
        if options:
            lines.append("options = { " + ", ".join(
                f"{k} = {json.dumps(v)}" for k, v in options.items()) + " }")
        lines.append("")
    path = folder / f"{name}.toml"
    path.write_text("\n".join(lines))
    return path


def _overshoot(path: Path, case: Case) -> float:
    """The largest overshoot of the run's set-point steps, as a share of each step (each
    output where its set-point moved)."""
    with open(path, newline="") as fh:
        rows = [r for r in csv.DictReader(fh)]
    time = np.array([float(r["time"]) for r in rows])
    worst = 0.0
    for o in case.outputs:
        y = np.array([float(r[f"plant.{o}"]) for r in rows])
        for (_, a), (t1, b), (t2, _) in zip(case.steps, case.steps[1:], case.steps[2:],
                                            strict=False):
            assert a is not None and b is not None
            if a[o] == b[o]:
                continue
            seg = y[(time >= t1) & (time < t2)]
            over = (seg.max() - b[o]) if b[o] > a[o] else (b[o] - seg.min())
            worst = max(worst, over / abs(b[o] - a[o]))
    return worst


def _oracle(out: Path, fmu: Path, case: Case) -> list[float]:
    """The oracle's summed IAE on each run of the campaign in ``out`` (the MPC variant's
    set-points, disturbances and drawn heat capacity), in run order."""
    import cosim

    found = []
    for folder in sorted((out / "runs").iterdir()):
        if folder.name.split("-", 1)[1] != "mpc":
            continue
        summary = json.loads((folder / "summary.json").read_text())
        draw = {**summary["campaign"]["draws"], **{
            f"plant.{k}": v for k, v in summary["campaign"]["plant_start"].items()}}
        signals = ["time", *(f"ref.{o}" for o in case.outputs), f"dist.{case.disturbance}"]
        with open(folder / "results.csv", newline="") as fh:
            rows = [[r[c] for c in signals] for r in csv.DictReader(fh)]
        # the run's drawn plant parameters, applied to the FMU from the start as the
        # campaign applied them, and known to the oracle
        params = {k[len("plant."):]: v for k, v in draw.items() if k.startswith("plant.")}
        columns = [*signals, *(f"plant.{k}" for k in params)]
        lines = [[*row, *(repr(v) if i == 0 else "" for v in params.values())]
                 for i, row in enumerate(rows)]
        scenario = folder / "oracle_scenario.csv"
        scenario.write_text("".join(",".join(cells) + "\n" for cells in [columns, *lines]))
        run = cosim.run(scenario, plant=fmu, controller="oracle_bound:OracleController",
                        options={"plant": case.plant, "fmu": str(fmu),
                                 "problem": str(case.problem), "parameters": params},
                        problem=case.problem, out=folder.parent.parent / "oracle" / folder.name)
        if run.summary["controller_summary"]["prediction_error_max"] > 1e-6:
            raise SystemExit("disturbance_campaign: the oracle's model is not the plant "
                             f"({folder.name}): "
                             f"{run.summary['controller_summary']['prediction_error_max']:.1e}")
        if run.status != "ok":
            raise SystemExit(f"disturbance_campaign: the oracle's run {run.status}: "
                             f"{run.reason}")
        found.append(sum(run.summary["kpis"]["iae"].values()))   # as _campaign sums it
    return found


def _campaign(out: Path, case: Case) -> dict[str, dict[str, list[float]]]:
    """Per variant: each run's IAE, overshoot and violations."""
    found: dict[str, dict[str, list[float]]] = {}
    for folder in sorted((out / "runs").iterdir()):
        variant = folder.name.split("-", 1)[1]
        summary = json.loads((folder / "summary.json").read_text())
        kpis = summary["kpis"]
        rec = found.setdefault(variant, {"iae": [], "overshoot": [], "violating": []})
        rec["iae"].append(sum(kpis["iae"].values()))
        rec["overshoot"].append(_overshoot(folder / "results.csv", case))
        rec["violating"].append(float(any(v["count"] for v in kpis["violations"].values())))
    return found


def main(argv: list[str] | None = None) -> int:
    from cosim.cli import main as cosim

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plant", choices=sorted(CASES), default="heater_dead_time")
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--steps", type=int, default=12000, help="identification samples")
    parser.add_argument("--epochs", type=int, default=None, help="cosim train --epochs")
    parser.add_argument("--out", type=Path, default=None, help="keep the files here")
    parser.add_argument("--oracle", action="store_true",
                        help="run the IAE oracle on every run too (oracle_bound.py)")
    args = parser.parse_args(argv)
    case = CASES[args.plant]
    with tempfile.TemporaryDirectory(prefix="disturbance-campaign-") as tmp:
        folder = args.out or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        fmu = _build_plant(folder, case.plant)
        data, model = folder / "data.csv", folder / "gru.json"
        if not model.is_file():   # an --out folder keeps its model for the next time
            if cosim(["generate-data", "--plant", str(fmu), "--problem", str(case.problem),
                      "--steps", str(args.steps), "--out", str(data), "--quiet"]) != 0:
                return 1
            train = ["train", str(data), "--out", str(model), "--quiet"]
            if args.epochs is not None:
                train += ["--epochs", str(args.epochs)]
            if cosim(train) != 0:
                return 1
        (folder / "steps.csv").write_text(_scenario(case))
        print(f"{case.title}: {args.runs} runs per campaign, heat capacity +-10 %")
        for name, disturbed in (("setpoints", False), (case.disturbance, True)):
            spec = _spec(folder, case, name, fmu, model, args.runs, disturbed)
            out = folder / f"camp_{name}"
            if cosim(["campaign", str(spec), "--out", str(out), "--force", "--quiet"]) != 0:
                return 1
            found = _campaign(out, case)
            mpc = sum(found["mpc"]["iae"])
            print(f"  {name:9s} MPC summed IAE / PI {mpc / sum(found['pi']['iae']):.3f}, "
                  f"/ PI with feedforward {mpc / sum(found['pi-ff']['iae']):.3f}")
            if args.oracle:
                oracle = sum(_oracle(out, fmu, case))
                pi = sum(found["pi"]["iae"])
                print(f"    oracle / PI {oracle / pi:.3f} (the causal bound), "
                      f"/ PI with feedforward {oracle / sum(found['pi-ff']['iae']):.3f}; "
                      f"MPC / oracle {mpc / oracle:.3f}; the MPC takes "
                      f"{(pi - mpc) / (pi - oracle):.0%} of the room below the PI")
            for variant, rec in found.items():
                ov = np.array(rec["overshoot"]) * 100.0
                print(f"    {variant:6s} overshoot median {np.median(ov):5.1f} %, largest "
                      f"{np.max(ov):5.1f} %; violating runs {int(sum(rec['violating']))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
