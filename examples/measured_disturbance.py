"""A measured disturbance and a dead time: feedforward from the robust MPC and the PI.

    python examples/measured_disturbance.py [--out DIR] [--steps 4000] [--epochs 60]

The example heated vessel whose power reaches it 40 s (two samples) late and whose ambient
temperature is measured (``fmus/examples/heater_dead_time``: its problem file declares
``[disturbances.T_in]`` and ``delay = 2``), as a user takes it: build the FMU, excite it
(``cosim generate-data``: the power and the ambient in their boxes), identify a GRU whose
inputs are both (``cosim train``, a short training), then one scenario of a set-point step
and two ambient steps with six controllers: the robust MPC (its tracking law) and the paper's
law (a horizon for the vessel's time constant, offset-free set-points), each with the ambient
measured and with it known ahead (``preview = true``: the scenario's steps seen over the dead
time), the PI with its static feedforward from the model and the PI without it. Prints each
one's IAE over the run and after each ambient step, its largest overshoot, and where the files
are (each run's ``results.csv``, ``summary.json``, ``figure.png`` under ``DIR``, default a
temporary folder).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import tempfile
from pathlib import Path

import cosim
from cosim.cli import main as cosim_cli

ROOT = Path(__file__).resolve().parents[1]
PLANT = "heater_dead_time"
#: a set-point step 40 -> 55 degC, then the ambient 20 -> 10 -> 30 degC
SCENARIO = "time,ref.T,dist.T_in\n0,40,20\n1000,55,20\n3000,55,10\n5000,55,30\n7000,,\n"
#: (title, its folder under --out, controller, options, the ambient known ahead)
CONTROLLERS = (("robust MPC", "mpc", "robust-mpc", {}, False),
               ("MPC, known ahead", "mpc-preview", "robust-mpc", {}, True),
               ("paper's law", "paper", "robust-mpc",
                {"law": "paper", "N": 60, "offset_free": True}, False),
               ("paper, known ahead", "paper-preview", "robust-mpc",
                {"law": "paper", "N": 60, "offset_free": True}, True),
               ("PI + feedforward", "pi-ff", "pi", {}, False),
               ("PI", "pi", "pi", {"feedforward": False}, False))


def _build(folder: Path) -> tuple[Path, Path]:
    """The plant's FMU in ``folder`` and its problem file."""
    spec = importlib.util.spec_from_file_location("example_plants",
                                                  ROOT / "fmus" / "examples" / "build.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(PLANT, folder), module.problem_file(PLANT)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--steps", type=int, default=4000, help="identification samples")
    parser.add_argument("--epochs", type=int, default=60, help="cosim train --epochs")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="measured-disturbance-"))
    out.mkdir(parents=True, exist_ok=True)
    fmu, problem = _build(out)
    data, model = out / "data.csv", out / "gru.json"
    for argv in (["generate-data", "--plant", str(fmu), "--problem", str(problem), "--steps",
                  str(args.steps), "--out", str(data), "--quiet"],
                 ["train", str(data), "--epochs", str(args.epochs), "--n", "6", "--out",
                  str(model), "--quiet"]):
        if cosim_cli(argv) != 0:
            raise SystemExit(f"cosim {argv[0]} failed")
    scenario = out / "steps.csv"
    scenario.write_text(SCENARIO)
    # the same model, its problem declaring the ambient known ahead (as `preview = true` in
    # the problem file before generate-data and train would)
    doc = json.loads(model.read_text())
    for entry in doc["problem"]["disturbances"]:
        entry["preview"] = True
    ahead = out / "gru_preview.json"
    ahead.write_text(json.dumps(doc))
    for title, folder, controller, options, known in CONTROLLERS:
        run = cosim.run(scenario, plant=fmu, controller=controller,
                        model=ahead if known else model, options=options, out=out / folder)
        df = run.to_pandas().set_index("time")
        err = (df["plant.T"] - df["ref.T"]).abs() * 20.0          # 20 s samples
        overshoot = max(0.0, df.loc[1000.0:3000.0, "plant.T"].max() - 55.0)
        print(f"{title:18s} status {run.status}, IAE {err.sum():5.0f} degC·s (after the "
              f"ambient fell {err.loc[3000.0:5000.0].sum():4.0f}, rose "
              f"{err.loc[5000.0:].sum():4.0f}), overshoot {overshoot:.2f} degC")
    print(f"files in {out}")


if __name__ == "__main__":
    main()
