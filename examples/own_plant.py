"""Your own plant, from its FMU to a campaign: the exothermic CSTR (or another example plant).

    python examples/own_plant.py [--plant cstr|heater|mixing_tank|furnace] [--epochs E]
        [--sigma-z-max S] [--option KEY=VALUE ...] [--out DIR]

The walk-through of the user guide (docs/guide/own-plant.md), as one command running the
``cosim`` commands a user types:

1. build the plant's FMU (``fmus/examples``: a pythonfmu model with its ``problem.toml``);
2. ``cosim generate-data --problem``: excite every input inside its box, sample every Ts;
3. ``cosim train --epochs E``: a δISS GRU of the plant (the problem goes into the model file);
4. the set-points a user would pick: steady outputs of the plant itself (inputs held at
   points inside their boxes until it settles), whatever the model makes of them;
5. ``cosim certify --auto-gain-scale --save --setpoint ...``: certified, or not and why;
   ``cosim tune --save``: the MPC's cost weights chosen on the model, against the PI;
6. ``cosim run`` of a set-point scenario with the robust MPC (its default, the tracking law,
   and the paper's law: ``--option law='"paper"'``), certified or uncertified, and, for a
   square plant, with the PI baseline tuned from the model (RGA pairing, SIMC);
7. ``cosim campaign``: plant parameters drawn per run, every controller on the same draws.

It prints what a user would check: the FIT of each output, the certify verdict, the tracking
error at the end of each set-point, the inputs' and outputs' box violations, the IAE of each
controller and its ratio to the PI's (summed over the outputs, each IAE divided by its
output's box width), the same for the inputs' total variation, and the campaign's
violations and median IAE ratio; ``walkthrough.json`` holds the same numbers.
``--epochs 150`` trains briefly (the tests run it so); the default epochs of ``cosim train``
give the numbers quoted in the guide. ``--sigma-z-max`` goes to ``cosim train`` (a faster
certified contraction, a smaller terminal weight) and each ``--option KEY=VALUE`` to every
robust-MPC run and campaign variant (``--option 'Q="outputs"'``: the stage cost on the
outputs): the guide's recipe for plants whose PI loops are hard to beat.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "fmus" / "examples"
#: The closed loops of step 6: report key -> (controller, its ``--option`` values).
CONTROLLERS = {"robust-mpc": ("robust-mpc", ()),
               "robust-mpc-paper": ("robust-mpc", ('law="paper"',)),
               "pi": ("pi", ())}
#: Data steps of step 2 and campaign runs per controller.
STEPS, RUNS = 20000, 20
#: Plant parameters drawn per campaign run (name -> uniform range).
UNCERTAIN = {"cstr": {"k0_factor": (0.9, 1.1), "UA_factor": (0.9, 1.1)},
             "heater": {"C_factor": (0.9, 1.1), "T_amb": (15.0, 25.0)},
             "mixing_tank": {"Cv_factor": (0.9, 1.1), "T_hot": (65.0, 75.0)},
             "furnace": {"K_factor": (0.8, 1.2), "T_amb": (10.0, 30.0)}}
#: Where the inputs are held to find the set-points (fractions of each input's box), by the
#: number of inputs.
SETPOINT_INPUTS = {1: [(0.3,), (0.75,), (0.5,), (0.15,)],
                   2: [(0.3, 0.3), (0.7, 0.35), (0.65, 0.75), (0.25, 0.7)],
                   3: [(0.3, 0.3, 0.3), (0.7, 0.4, 0.5), (0.45, 0.75, 0.3), (0.3, 0.5, 0.75)]}
#: How long each set-point is held [samples]: by default, and per plant (the furnace's slow
#: mode takes 50 samples).
HOLD = 60
HOLDS = {"furnace": 120}


def examples_build() -> Any:
    """``fmus/examples/build.py`` as a module (a script beside the plants)."""
    spec = importlib.util.spec_from_file_location("examples_build", EXAMPLES / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build_plant(name: str, folder: Path) -> Path:
    """``fmus/examples/build.py``: the plant's FMU into ``folder``."""
    return examples_build().build(name, folder)


def cosim_command(*args: Any) -> None:
    """One ``cosim`` command, as a user runs it (its own process: an FMU's native code never
    runs in this one); stops the walk-through when it fails."""
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", *(str(a) for a in args)],
                          check=False)
    if proc.returncode != 0:
        raise SystemExit(f"cosim {args[0]} failed (exit {proc.returncode})")


def identify(fmu: Path, problem: Path, work: Path, epochs: int | None,
             seed: int, train_args: tuple[str, ...] = (), steps: int = STEPS
             ) -> tuple[Path, float]:
    """generate-data (``steps`` samples) and train; the model file and the training's wall
    time [s]."""
    data, model = work / "data" / "plant.csv", work / "models" / "plant_gru.json"
    cosim_command("generate-data", "--plant", fmu, "--problem", problem, "--steps", steps,
                  "--seed", seed, "--out", data, "--quiet")
    extra = [] if epochs is None else ["--epochs", epochs]
    t0 = time.perf_counter()
    cosim_command("train", data, *extra, *train_args, "--seed", seed, "--out", model,
                  "--quiet")
    return model, time.perf_counter() - t0


def certify(model: Path, problem: Any, setpoints: list[np.ndarray],
            unusable_ok: bool = False) -> dict[str, Any]:
    """``cosim certify --auto-gain-scale --save`` at the set-points the runs will use: its
    exit code (0 certified, 1 not, 2 not usable: an error unless ``unusable_ok``), the
    verdict it saved and the contraction rate rho_s of V_s (``lem:Vs``) it printed."""
    named = [",".join(f"{n}={v:.6g}" for n, v in zip(problem.output_names, y, strict=True))
             for y in setpoints]
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "certify", str(model),
                           "--auto-gain-scale", "--save", "--json",
                           *(a for sp in named for a in ("--setpoint", sp))],
                          capture_output=True, text=True, check=False)
    try:
        printed = json.loads(proc.stdout)
    except json.JSONDecodeError:
        printed = None
    if printed is None or proc.returncode not in (0, 1, 2) or (proc.returncode == 2
                                                               and not unusable_ok):
        raise SystemExit(f"cosim certify failed (exit {proc.returncode}): {proc.stderr}")
    doc = printed[0] if isinstance(printed, list) else printed
    verdict = doc["verdict"]                     # as --save wrote it into the model file
    return {"exit": proc.returncode, "certified": verdict["certified"],
            "usable": verdict["usable"],
            "reasons": [f["detail"] for f in verdict["findings"] if not f["holds"]]
            + ([verdict["unusable_reason"]] if verdict["unusable_reason"] else []),
            "admissible": verdict["admissible_setpoints"], "rho_s": doc["rho_s"]}


def tune(model: Path) -> dict[str, Any]:
    """``cosim tune --save``: the robust MPC's weights chosen on the model (the weighting,
    its options and every candidate's IAE and TV ratios on the model)."""
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "tune", str(model), "--save",
                           "--json"], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"cosim tune failed (exit {proc.returncode}): {proc.stderr}")
    return json.loads(proc.stdout)


def plant_setpoints(fmu: Path, problem: Any) -> list[np.ndarray]:
    """Steady outputs of the plant itself (physical units) with its inputs held at the
    points of :data:`SETPOINT_INPUTS` until it settles (300 samples): the set-points a user
    who knows the plant would ask for."""
    from cosim.adapters.problems import bind_plant
    from cosim.core.fmu import FmuComponent

    out = []
    for fractions in SETPOINT_INPUTS[problem.m]:
        plant = FmuComponent(fmu, varmap=bind_plant(problem, fmu))
        try:
            plant.setup(0.0)
            plant.set_inputs({c.name: c.min + f * (c.max - c.min)
                              for c, f in zip(problem.inputs, fractions, strict=True)})
            for k in range(300):
                plant.step(k * problem.Ts, problem.Ts)
            y = plant.get_outputs()
        finally:
            plant.terminate()
        out.append(np.array([y[n] for n in problem.output_names]))
    return out


def hold(problem: Any) -> int:
    """How long the plant of ``problem`` holds each set-point [samples]."""
    return HOLDS.get(problem.name, HOLD)


def write_scenario(path: Path, problem: Any, setpoints: list[np.ndarray]) -> Path:
    """Set-point steps, each held :func:`hold` samples."""
    held = hold(problem)
    names = [f"ref.{n}" for n in problem.output_names]
    lines = [",".join(["time", *names])]
    for k, y in enumerate(setpoints):
        lines.append(",".join([f"{k * held * problem.Ts:g}", *(f"{v:.6g}" for v in y)]))
    lines.append(",".join([f"{len(setpoints) * held * problem.Ts:g}", *[""] * len(names)]))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def run(scenario: Path, fmu: Path, model: Path, controller: str, out: Path,
        problem: Any, setpoints: list[np.ndarray], options: tuple[str, ...] = ()
        ) -> dict[str, Any]:
    """``cosim run`` (``options``: ``KEY=VALUE`` controller options) and what a user checks:
    the tracking error at the end of each set-point (relative to its output's box), the box
    violations of inputs and outputs, the KPIs, and the IAE and total variation summed over
    the signals, each divided by its box width."""
    import pandas as pd

    extra = [arg for option in options for arg in ("--option", option)]
    cosim_command("run", scenario, "--plant", fmu, "--controller", controller, "--model",
                  model, "--out", out, "--quiet", *extra)
    df = pd.read_csv(out / "results.csv")
    summary = json.loads((out / "summary.json").read_text())
    errors = []
    for k, y in enumerate(setpoints):
        row = df.iloc[min((k + 1) * hold(problem), len(df) - 1) - 1]
        rel = [abs(row[f"plant.{c.name}"] - v) / (c.max - c.min)
               for c, v in zip(problem.outputs, y, strict=True)]
        errors.append(max(rel))
    box = {}
    for c in (*problem.inputs, *problem.outputs):
        col = df[f"ctrl.{c.name}"] if c in problem.inputs else df[f"plant.{c.name}"]
        box[c.name] = float(max(0.0, c.min - col.min(), col.max() - c.max))
    kpis = summary["kpis"]
    ctrl = summary.get("controller_summary", {})
    return {"status": summary["status"], "tracking_error": [float(e) for e in errors],
            "box_violation": box, "iae": kpis["iae"], "tv": kpis.get("tv", {}),
            "iae_sum": summed(kpis["iae"], problem.outputs),
            "tv_sum": summed(kpis.get("tv", {}), problem.inputs),
            "certified": ctrl.get("certified")}


def summed(values: dict[str, float], channels: Any) -> float:
    """``Σ value / (max − min)`` over the channels (each signal in units of its box)."""
    return float(sum(values[c.name] / (c.max - c.min) for c in channels))


def _toml(value: Any) -> str:
    """A JSON value (an ``--option``'s) as a TOML inline value."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return json.dumps(value)


def campaign(name: str, fmu: Path, model: Path, problem: Path, scenario: Path, work: Path,
             runs: int, square: bool, mpc_options: dict[str, Any] | None = None
             ) -> dict[str, Any]:
    """A campaign with the plant's parameters drawn per run, every controller on the same
    draws: failed and violating runs per variant and, for a square plant, the median over the
    draws of the robust MPC's summed IAE and total variation divided by the PI's."""
    from controllers.problem_file import load

    draws = "\n".join(f'"plant.{k}" = {{ uniform = [{lo}, {hi}] }}'
                      for k, (lo, hi) in UNCERTAIN[name].items())
    spec = work / "campaign.toml"
    mpc = ", ".join(f"{k} = {_toml(v)}" for k, v in (mpc_options or {}).items())
    # the PI is tuned from the same model (a variant's own model key)
    pi = (f'\n[[variant]]\nname = "pi"\ncontroller = "pi"\nmodel = "{model}"\n' if square
          else "")
    spec.write_text(f"""[campaign]
name = "{name}"
runs = {runs}
seed = 1
scenario = "{scenario}"
plant = "{fmu}"
model = "{model}"
problem = "{problem}"

[draw]
{draws}

[[variant]]
name = "robust-mpc"
options = {{ {mpc} }}

[[variant]]
name = "robust-mpc-paper"
options = {{ law = "paper"{", " + mpc if mpc else ""} }}
{pi}""")
    cosim_command("campaign", spec, "--out", work / "campaign", "--force", "--quiet")
    return campaign_results(work / "campaign", load(problem), square)


def campaign_results(folder: Path, prob: Any, square: bool) -> dict[str, Any]:
    """What a user reads of the campaign in ``folder`` (problem ``prob``): failed and
    violating runs per variant, each run's summed IAE and total variation (each signal over
    its box width) and, for a square plant, the median over the draws of the robust MPC's
    divided by the PI's."""
    import pandas as pd

    summary = json.loads((folder / "summary.json").read_text())
    table = pd.read_parquet(folder / "runs.parquet")
    out: dict[str, Any] = {"status": "ok" if summary.get("failed") == 0 else "failed",
                           "runs": summary.get("runs"),
                           "violating_runs": summary.get("violating_runs"),
                           "failed": summary.get("failed"), "variants": {}}
    for variant, df in table.groupby("variant"):
        df = df.sort_values("run")
        out["variants"][variant] = {
            "failed": int((df["status"] != "ok").sum()),
            "violating": int((df["violation_count"] > 0).sum()),
            "iae_sum": [float(sum(r[f"iae.{c.name}"] / (c.max - c.min) for c in prob.outputs))
                        for _, r in df.iterrows()],
            "tv_sum": [float(sum(r[f"tv.{c.name}"] / (c.max - c.min) for c in prob.inputs))
                       for _, r in df.iterrows()]}
    if square:
        mpc, base = out["variants"]["robust-mpc"], out["variants"]["pi"]
        iae = np.array(mpc["iae_sum"]) / np.array(base["iae_sum"])
        tv = np.array(mpc["tv_sum"]) / np.array(base["tv_sum"])
        out.update(iae_ratio_median=float(np.median(iae)), tv_ratio_median=float(np.median(tv)),
                   mpc_better=int(np.sum(iae < 1.0)))
    return out


def walkthrough(name: str, out: Path, epochs: int | None, runs: int = RUNS,
                seed: int = 0, sigma_z_max: float | None = None,
                options: tuple[str, ...] = ()) -> dict[str, Any]:
    """The whole walk-through for example plant ``name``; the numbers it prints
    (``sigma_z_max``: ``cosim train --sigma-z-max``; ``options``: ``KEY=VALUE`` of every
    robust-MPC run and variant)."""
    from controllers.model import GRUModel
    from controllers.problem_file import load
    from cosim.core.registry import parse_options

    problem_path = EXAMPLES / name / "problem.toml"
    problem = load(problem_path)
    fmu = build_plant(name, out / "fmu")
    train_args = () if sigma_z_max is None else ("--sigma-z-max", str(sigma_z_max))
    model_path, train_s = identify(fmu, problem_path, out, epochs, seed, train_args)
    setpoints = plant_setpoints(fmu, problem)
    verdict = certify(model_path, problem, setpoints)
    tuned = tune(model_path)
    model = GRUModel.load(model_path)
    scenario = write_scenario(out / "scenario.csv", problem, setpoints)
    report: dict[str, Any] = {
        "plant": name, "problem": problem.describe(), "epochs": epochs,
        "train_s": round(train_s, 1), "fit_test": model.training["fit"]["test"],
        "certify": verdict, "tune": tuned, "setpoints": [y.tolist() for y in setpoints]}
    square = problem.m == problem.p
    report["options"] = list(options)
    for key, (controller, own) in CONTROLLERS.items():
        if controller == "pi" and not square:
            continue
        given = (*own, *options) if controller == "robust-mpc" else own
        report[key] = run(scenario, fmu, model_path, controller, out / "runs" / key,
                          problem, setpoints, given)
    if square:
        mpc, pi = report["robust-mpc"], report["pi"]
        report["iae_ratio"] = mpc["iae_sum"] / pi["iae_sum"]
        report["tv_ratio"] = mpc["tv_sum"] / pi["tv_sum"]
    if runs:
        report["campaign"] = campaign(name, fmu, model_path, problem_path, scenario, out, runs,
                                      square, parse_options(list(options)))
    (out / "walkthrough.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plant", choices=sorted(UNCERTAIN), default="cstr")
    parser.add_argument("--epochs", type=int, default=None,
                        help="cosim train --epochs (default: cosim train's)")
    parser.add_argument("--runs", type=int, default=RUNS,
                        help=f"campaign runs per controller (default {RUNS}; 0: none)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sigma-z-max", type=float, default=None,
                        help="cosim train --sigma-z-max (default: no cap)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="robust-MPC option of every run and variant, repeatable")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix=f"own-plant-{args.plant}-"))
    r = walkthrough(args.plant, out, args.epochs, args.runs, args.seed, args.sigma_z_max,
                    tuple(args.option))
    print(r["problem"])
    print(f"training {r['train_s']:.0f} s; test FIT: "
          + ", ".join(f"{k} {v:.1f} %" for k, v in r["fit_test"].items()))
    v = r["certify"]
    print(f"certify: {'certified' if v['certified'] else 'not certified'} (exit {v['exit']})"
          + "".join(f"; {reason}" for reason in v["reasons"][:2]))
    t = r["tune"]
    base = "the PI's" if t["against"] == "pi" else "the default weights'"
    print(f"tune: {t['chosen']} ({', '.join(f'{k}={v}' for k, v in t['options'].items())}; "
          f"on the model {t['candidates'][t['chosen']]['iae']:.3f}x {base} IAE)")
    for controller in CONTROLLERS:
        if controller in r:
            c = r[controller]
            print(f"{controller}: status {c['status']}, certified {c['certified']}; tracking "
                  f"error at the end of each set-point "
                  f"{', '.join(f'{e:.2%}' for e in c['tracking_error'])} of the box; box "
                  f"violations {max(c['box_violation'].values()):.3g}; IAE "
                  + ", ".join(f"{k} {v:.4g}" for k, v in c["iae"].items()))
    if "iae_ratio" in r:
        print(f"robust-mpc / pi: summed IAE {r['iae_ratio']:.3f}x, total variation "
              f"{r['tv_ratio']:.3f}x")
    camp = r.get("campaign")
    if camp:
        line = (f"campaign: status {camp['status']}, {camp['runs']} runs, {camp['failed']} "
                f"failed, {camp['violating_runs']} violating")
        if "iae_ratio_median" in camp:
            line += (f"; robust-mpc / pi median summed IAE {camp['iae_ratio_median']:.3f}x, "
                     f"TV {camp['tv_ratio_median']:.3f}x, better in {camp['mpc_better']} of "
                     f"{len(camp['variants']['pi']['iae_sum'])} draws")
        print(line)
    print(f"files in {out}")


if __name__ == "__main__":
    main()
