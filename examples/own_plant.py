"""Your own plant, from its FMU to a campaign: the exothermic CSTR (or another example plant).

    python examples/own_plant.py [--plant cstr|heater|mixing_tank] [--quick] [--out DIR]

The walk-through of the user guide (docs/guide/own-plant.md), as one command running the
``cosim`` commands a user types:

1. build the plant's FMU (``fmus/examples``: a pythonfmu model with its ``problem.toml``);
2. ``cosim generate-data --problem``: excite every input inside its box, sample every Ts;
3. ``cosim train``: a δISS GRU of the plant (the problem goes into the model file);
4. set-points the model can hold and the theory admits, from the model's equilibria (the
   Python API: :mod:`controllers.equilibrium`, :mod:`controllers.certificates`);
5. ``cosim certify --auto-gain-scale --save --setpoint ...``: the observer gains for them;
6. ``cosim run`` of a set-point scenario with the robust MPC (its default, the tracking law,
   and the paper's law: ``--option law='"paper"'``) and, for a square plant, with the PI
   baseline tuned from the model (RGA pairing, SIMC);
7. ``cosim campaign``: plant parameters drawn per run, every controller on the same draws.

It prints what a user would check: the FIT of each output, the gain scale, the tracking error
at the end of each set-point, the inputs' and outputs' box violations, the IAE of each
controller, and the campaign's violations; ``walkthrough.json`` holds the same numbers.
``--quick`` trains briefly (the tests run it so); the full settings give the numbers quoted
in the guide.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "fmus" / "examples"
#: The closed loops of step 6: report key -> (controller, its ``--option`` values).
CONTROLLERS = {"robust-mpc": ("robust-mpc", ()),
               "robust-mpc-paper": ("robust-mpc", ('law="paper"',)),
               "pi": ("pi", ())}

#: Settings per mode: data steps, GRU states, epochs, learning rate (first and last), runs
#: of the campaign per controller.
SETTINGS = {"quick": {"steps": 3000, "n": 8, "epochs": 300, "lr": 0.02, "lr_final": 0.002,
                      "runs": 3},
            "full": {"steps": 6000, "n": 12, "epochs": 800, "lr": 0.01, "lr_final": 0.0005,
                     "runs": 20}}
#: Plant parameters drawn per campaign run (name -> uniform range) and sensor noise.
UNCERTAIN = {"cstr": {"k0_factor": (0.9, 1.1), "UA_factor": (0.9, 1.1)},
             "heater": {"C_factor": (0.9, 1.1), "T_amb": (15.0, 25.0)},
             "mixing_tank": {"Cv_factor": (0.9, 1.1), "T_hot": (65.0, 75.0)}}
#: Set-points per run and how long each is held [samples].
SETPOINTS, HOLD = 3, 60


def build_plant(name: str, folder: Path) -> Path:
    """``fmus/examples/build.py``: the plant's FMU into ``folder``."""
    spec = importlib.util.spec_from_file_location("examples_build", EXAMPLES / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(name, folder)


def cosim_command(*args: Any) -> None:
    """One ``cosim`` command, as a user runs it (its own process: an FMU's native code never
    runs in this one); stops the walk-through when it fails."""
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", *(str(a) for a in args)],
                          check=False)
    if proc.returncode != 0:
        raise SystemExit(f"cosim {args[0]} failed (exit {proc.returncode})")


def identify(fmu: Path, problem: Path, work: Path, settings: dict[str, Any],
             seed: int) -> Path:
    """generate-data and train; the model file."""
    data, model = work / "data" / "plant.csv", work / "models" / "plant_gru.json"
    cosim_command("generate-data", "--plant", fmu, "--problem", problem, "--steps",
                  settings["steps"], "--seed", seed, "--out", data, "--quiet")
    cosim_command("train", data, "--n", settings["n"], "--epochs", settings["epochs"],
                  "--lr", settings["lr"], "--lr-final", settings["lr_final"], "--seed", seed,
                  "--out", model, "--quiet")
    return model


def certify(model: Path, problem: Any, setpoints: list[np.ndarray]) -> None:
    """``cosim certify --auto-gain-scale --save`` at the set-points the runs will use."""
    named = [",".join(f"{n}={v:.6g}" for n, v in zip(problem.output_names, y, strict=True))
             for y in setpoints]
    cosim_command("certify", model, "--auto-gain-scale", "--save",
                  *(a for sp in named for a in ("--setpoint", sp)))


def admissible_setpoints(model_path: Path, count: int) -> list[np.ndarray]:
    """``count`` set-points (physical units) the model can hold and that pass every
    hypothesis of the theorem with the open-loop observer (gain scale 0, so that
    ``certify --auto-gain-scale`` finds a scale for them), at the horizons of both laws the
    walk-through runs (the paper's N = 15, which its law checks at run time, and the
    tracking law's, which ``certify`` checks by default): equilibria of inputs spread over
    the inner part of the box, kept when admissible."""
    from controllers.certificates import compute_certificate
    from controllers.equilibrium import equilibrium_output
    from controllers.fhocp_tracking import DEFAULTS
    from controllers.model import GRUModel

    model = GRUModel.load(model_path)
    certs = [compute_certificate(model, gain_scale=0.0, N=N) for N in (15, DEFAULTS["N"])]
    found: list[np.ndarray] = []
    rng = np.random.default_rng(0)
    for _ in range(400):
        u = rng.uniform(-0.6, 0.6, model.m)
        _, y = equilibrium_output(model.params, u)
        if (any(cert.failures(y) for cert in certs)
                or any(np.max(np.abs(y - f)) < 0.1 for f in found)):
            continue
        found.append(y)
        if len(found) == count:
            break
    if len(found) < count:
        raise SystemExit(f"{model_path}: fewer than {count} admissible set-points found")
    return [model.denormalize_y(y) for y in found]


def write_scenario(path: Path, problem: Any, setpoints: list[np.ndarray]) -> Path:
    """Set-point steps, each held :data:`HOLD` samples."""
    names = [f"ref.{n}" for n in problem.output_names]
    lines = [",".join(["time", *names])]
    for k, y in enumerate(setpoints):
        lines.append(",".join([f"{k * HOLD * problem.Ts:g}", *(f"{v:.6g}" for v in y)]))
    lines.append(",".join([f"{len(setpoints) * HOLD * problem.Ts:g}", *[""] * len(names)]))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def run(scenario: Path, fmu: Path, model: Path, controller: str, out: Path,
        problem: Any, setpoints: list[np.ndarray], options: tuple[str, ...] = ()
        ) -> dict[str, Any]:
    """``cosim run`` (``options``: ``KEY=VALUE`` controller options) and what a user checks:
    the tracking error at the end of each set-point (relative to its output's box), the box
    violations of inputs and outputs, the KPIs."""
    import pandas as pd

    extra = [arg for option in options for arg in ("--option", option)]
    cosim_command("run", scenario, "--plant", fmu, "--controller", controller, "--model",
                  model, "--out", out, "--quiet", *extra)
    df = pd.read_csv(out / "results.csv")
    summary = json.loads((out / "summary.json").read_text())
    errors = []
    for k, y in enumerate(setpoints):
        row = df.iloc[min((k + 1) * HOLD, len(df) - 1) - 1]
        rel = [abs(row[f"plant.{c.name}"] - v) / (c.max - c.min)
               for c, v in zip(problem.outputs, y, strict=True)]
        errors.append(max(rel))
    box = {}
    for c in (*problem.inputs, *problem.outputs):
        col = df[f"ctrl.{c.name}"] if c in problem.inputs else df[f"plant.{c.name}"]
        box[c.name] = float(max(0.0, c.min - col.min(), col.max() - c.max))
    kpis = summary["kpis"]
    return {"status": summary["status"], "tracking_error": [float(e) for e in errors],
            "box_violation": box, "iae": kpis["iae"], "tv": kpis.get("tv", {})}


def campaign(name: str, fmu: Path, model: Path, problem: Path, scenario: Path, work: Path,
             runs: int, square: bool) -> dict[str, Any]:
    """A small campaign with the plant's parameters drawn per run."""
    draws = "\n".join(f'"plant.{k}" = {{ uniform = [{lo}, {hi}] }}'
                      for k, (lo, hi) in UNCERTAIN[name].items())
    spec = work / "campaign.toml"
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

[[variant]]
name = "robust-mpc-paper"
options = {{ law = "paper" }}
{pi}""")
    cosim_command("campaign", spec, "--out", work / "campaign", "--workers", 1, "--force",
                  "--quiet")
    summary = json.loads((work / "campaign" / "summary.json").read_text())
    return {"status": "ok" if summary.get("failed") == 0 else "failed",
            "runs": summary.get("runs"), "violating_runs": summary.get("violating_runs"),
            "failed": summary.get("failed")}


def walkthrough(name: str, out: Path, quick: bool, seed: int = 0) -> dict[str, Any]:
    """The whole walk-through for example plant ``name``; the numbers it prints."""
    from controllers.model import GRUModel
    from controllers.problem_file import load

    settings = SETTINGS["quick" if quick else "full"]
    problem_path = EXAMPLES / name / "problem.toml"
    problem = load(problem_path)
    fmu = build_plant(name, out / "fmu")
    model_path = identify(fmu, problem_path, out, settings, seed)
    setpoints = admissible_setpoints(model_path, SETPOINTS)
    certify(model_path, problem, setpoints)
    model = GRUModel.load(model_path)
    scenario = write_scenario(out / "scenario.csv", problem, setpoints)
    report: dict[str, Any] = {
        "plant": name, "problem": problem.describe(), "settings": settings,
        "fit_test": model.training["fit"]["test"],
        "admissible": _admissible(model), "setpoints": [y.tolist() for y in setpoints]}
    square = problem.m == problem.p
    for key, (controller, options) in CONTROLLERS.items():
        if controller == "pi" and not square:
            continue
        report[key] = run(scenario, fmu, model_path, controller, out / "runs" / key,
                          problem, setpoints, options)
    report["campaign"] = campaign(name, fmu, model_path, problem_path, scenario, out,
                                  settings["runs"], square)
    (out / "walkthrough.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def _admissible(model: Any) -> dict[str, list[float] | None]:
    """The certified admissible set-point interval of each output (physical units)."""
    from controllers.certificates import admissible_ranges, compute_certificate

    cert = compute_certificate(model)
    return {name: None if lo is None else [lo, hi]
            for name, lo, hi in admissible_ranges(cert, model)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plant", choices=sorted(UNCERTAIN), default="cstr")
    parser.add_argument("--quick", action="store_true", help="brief training (the tests)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix=f"own-plant-{args.plant}-"))
    r = walkthrough(args.plant, out, args.quick, args.seed)
    print(r["problem"])
    print("test FIT: " + ", ".join(f"{k} {v:.1f} %" for k, v in r["fit_test"].items()))
    print("admissible set-points: " + ", ".join(
        f"{k} in [{v[0]:.4g}, {v[1]:.4g}]" if v else f"{k}: none"
        for k, v in r["admissible"].items()))
    for controller in CONTROLLERS:
        if controller in r:
            c = r[controller]
            print(f"{controller}: status {c['status']}; tracking error at the end of each "
                  f"set-point {', '.join(f'{e:.2%}' for e in c['tracking_error'])} of the "
                  f"box; box violations {max(c['box_violation'].values()):.3g}; IAE "
                  + ", ".join(f"{k} {v:.4g}" for k, v in c["iae"].items()))
    camp = r["campaign"]
    print(f"campaign: status {camp['status']}, {camp['runs']} runs, {camp['failed']} failed, "
          f"{camp['violating_runs']} violating; files in {out}")


if __name__ == "__main__":
    main()
