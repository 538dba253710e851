"""Identification from short records, side by side, in one run: this tool (``cosim train``'s
default), its ARX baseline, and deepSI's subspace encoder (SUBNET, the defaults of deepSI
0.4), with the wall time of each.

    python benchmarks/bench_identification.py [--records DIR] [--only NAME ...] [--quick]

Each record is an estimation experiment and a separate validation experiment. The protocol,
the same for every method: the estimation record is split in time order 80 / 10 / 10 %
(train / validation / test rows: what ``cosim train --split 0.8,0.1`` does), every method
fits on its training rows and may select on its validation rows, and the validation
experiment is only simulated: each method sees its first 50 samples (this tool and the ARX
model to set their initial state, SUBNET's encoder its first 20), and the RMS of the free run
is taken over the rest, in the output's unit.

Records:

- ``heater``: the heated vessel of ``tests/cosim/commands/test_cli_train_logged.py`` (a
  Wiener plant, power [kW] -> temperature [degC], Ts = 5 s, 0.05 degC noise), 1,000 + 1,000 samples;
- ``tanks``: two cascaded tanks with square-root outflows, the upper one overflowing into the
  lower one, a level sensor saturating at 10 V, process and sensor noise (made here, seeded:
  :func:`tanks_record`), pump voltage -> lower level [V], Ts = 4 s, 1,024 + 1,024 samples;
- public real records, from ``--raw DIR`` holding their files as published, in it or in
  folders below it (converted by :func:`real_records`; :data:`REAL` says how each is cut;
  they come from the nonlinear system-identification benchmarks and DaISy, which several
  public repositories mirror): Silverbox (``SNLS80mV.csv``, an electronic Duffing
  oscillator), the heat exchanger (``exchanger.csv``, DaISy 97-002), the dryer
  (``dryer.csv``, DaISy 96-006), Box-Jenkins' gas furnace (``gas_furnace.csv``), the coupled
  electric drives (``DATAUNIF_clean.csv``: the benchmark's DATAUNIF with a time column), the
  hydraulic actuator (``actuator.csv``) and the flexible robot arm (``robot_arm.csv``, DaISy
  96-009); the column names of each are in :data:`REAL`;
- every folder of ``--records DIR`` holding ``est.csv``, ``val.csv`` (``time``, the input and
  output columns) and ``problem.toml``.

deepSI is the ``bench`` extra (``pip install -e '.[bench]'``); without it its rows are
skipped. ``--quick`` trains every method briefly (the test of this script).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
#: Samples of the validation record every method sees before its free run is scored.
SEEN = 50


def siso_problem(name: str, Ts: float, u: dict[str, Any], y: dict[str, Any]) -> str:
    """The problem file of a record ``u`` -> ``y`` (each a table: unit, min, max, ...)."""
    from tests.toml_text import toml_text

    return toml_text({"problem": {"name": name, "Ts": Ts}, "inputs.u": u, "outputs.y": y})


#: The cascaded tanks' problem: the pump voltage to the lower tank's level.
TANKS_PROBLEM = siso_problem(
    "tanks", 4.0, {"unit": "V", "min": 0.0, "max": 10.0, "description": "pump voltage"},
    {"unit": "V", "min": 0.0, "max": 10.0, "description": "lower tank level"})


def tanks_record(seed: int, samples: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """``(u, y)`` of the cascaded tanks: a random-phase multisine of the pump voltage (the
    first 40 harmonics of the record, 1.5–7 V), levels x1, x2 [V] with
    ``dx1 = k4 u − k1 √x1``, ``dx2 = k2 √x1 − k3 √x2`` (+ half the upper tank's overflow),
    both capped at 10 V, process noise 0.01 V per sample, sensor noise 0.03 V, the sensor
    saturating at 10 V; RK4, 0.5 s substeps."""
    from scipy.integrate import solve_ivp

    k1, k2, k3, k4, top = 0.06, 0.055, 0.058, 0.05, 10.0
    rng = np.random.default_rng(seed)
    t = np.arange(samples)
    wave = sum(np.cos(2 * np.pi * k * t / samples + rng.uniform(0, 2 * np.pi))
               for k in range(1, 40))
    u = 1.5 + 5.5 * (wave - wave.min()) / (wave.max() - wave.min())

    def rhs(_t: float, x: np.ndarray, uk: float) -> list[float]:
        q1 = k1 * math.sqrt(max(x[0], 0.0))
        d1 = k4 * uk - q1
        over = 0.0
        if x[0] >= top and d1 > 0:
            over, d1 = d1, 0.0
        d2 = k2 * math.sqrt(max(x[0], 0.0)) + 0.5 * over - k3 * math.sqrt(max(x[1], 0.0))
        if x[1] >= top and d2 > 0:
            d2 = 0.0
        return [d1, d2]

    x = rng.uniform(3.0, 6.0, 2)
    y = np.empty(samples)
    for k in range(samples):
        y[k] = x[1]
        sol = solve_ivp(rhs, (0.0, 4.0), x, args=(u[k],), max_step=0.5)
        x = np.clip(sol.y[:, -1] + rng.normal(0.0, 0.01, 2), 0.0, top)
    return u, np.minimum(y + rng.normal(0.0, 0.03, samples), top)


def write_csv(path: Path, u: np.ndarray, y: np.ndarray, Ts: float, names: tuple[str, str]
              ) -> Path:
    lines = [f"time,{names[0]},{names[1]}"]
    lines += [f"{k * Ts:g},{float(a)!r},{float(b)!r}"
              for k, (a, b) in enumerate(zip(u, y, strict=True))]
    path.write_text("\n".join(lines) + "\n")
    return path


def built_in(work: Path) -> dict[str, Path]:
    """The two records made here, as folders of est.csv, val.csv and problem.toml."""
    from tests.cosim.commands.test_cli_train_logged import PROBLEM as HEATER
    from tests.cosim.commands.test_cli_train_logged import TS, heater

    out = {}
    folder = work / "heater"
    folder.mkdir(parents=True, exist_ok=True)
    for name, seed in (("est", 0), ("val", 1)):
        write_csv(folder / f"{name}.csv", *heater(1000, seed), TS, ("power", "temp"))
    (folder / "problem.toml").write_text(HEATER)
    out["heater"] = folder
    folder = work / "tanks"
    folder.mkdir(parents=True, exist_ok=True)
    for name, seed in (("est", 1), ("val", 2)):
        write_csv(folder / f"{name}.csv", *tanks_record(seed), 4.0, ("u", "y"))
    (folder / "problem.toml").write_text(TANKS_PROBLEM)
    out["tanks"] = folder
    return out


#: How each public record is cut: its file, the estimation and validation experiments (input
#: column, output column, rows), the units and the sample time. A thousand samples or fewer
#: each where the record allows: the case of a short log.
REAL: dict[str, dict[str, Any]] = {
    # Silverbox: two of the multisine realisations after the arrow-head (which starts the
    # file and is the benchmark's usual test), 1,024 samples each, away from their transients
    "silverbox": {"file": "SNLS80mV.csv", "est": ("V1", "V2", (50000, 51024)),
                  "val": ("V1", "V2", (100000, 101024)), "units": ("V", "V"),
                  "Ts": 1 / 610.35},
    # the heat exchanger: the first 1,000 samples estimate, samples 2,000-2,999 validate
    "exchanger": {"file": "exchanger.csv", "est": ("u_flow_rate_q", "y_outlet_temp_th",
                                                   (0, 1000)),
                  "val": ("u_flow_rate_q", "y_outlet_temp_th", (2000, 3000)),
                  "units": ("1", "degC"), "Ts": 1.0},
    # the dryer (DaISy 96-006): its two halves, as the GP state-space literature splits it
    "dryer": {"file": "dryer.csv", "est": ("u_heater_voltage", "y_air_temperature", (0, 500)),
              "val": ("u_heater_voltage", "y_air_temperature", (500, 1000)),
              "units": ("V", "degC"), "Ts": 0.08},
    # Box-Jenkins' gas furnace: its two halves (148 samples each)
    "gas-furnace": {"file": "gas_furnace.csv", "est": ("InputGasRate", "CO2", (0, 148)),
                    "val": ("InputGasRate", "CO2", (148, 296)), "units": ("1", "%"),
                    "Ts": 9.0},
    # the coupled electric drives: estimate on the first uniform experiment, validate on the
    # second (the tech report's and many papers' protocol; the output is |speed|)
    "ced": {"file": "DATAUNIF_clean.csv", "est": ("u11", "z11", (0, 500)),
            "val": ("u12", "z12", (0, 500)), "units": ("V", "V"), "Ts": 0.02},
    # the hydraulic actuator (Sjöberg et al. 1995): 512 samples estimate, 512 validate
    "actuator": {"file": "actuator.csv", "est": ("u_valve_opening", "p_oil_pressure",
                                                 (0, 512)),
                 "val": ("u_valve_opening", "p_oil_pressure", (512, 1024)),
                 "units": ("1", "1"), "Ts": 1.0},
    # the robot arm's periodic sine sweep (DaISy 96-009): its two halves
    "robot-arm": {"file": "robot_arm.csv", "est": ("u_reaction_torque", "y_arm_acceleration",
                                                   (0, 512)),
                  "val": ("u_reaction_torque", "y_arm_acceleration", (512, 1024)),
                  "units": ("1", "1"), "Ts": 1.0},
}


def real_records(raw: Path, work: Path) -> dict[str, Path]:
    """The records of :data:`REAL` whose file is in ``raw`` (or in a folder below it), as
    folders of est.csv, val.csv and problem.toml (boxes: the data's range, widened by a
    tenth)."""
    import pandas as pd

    out = {}
    for name, spec in REAL.items():
        found = sorted(raw.rglob(spec["file"]))
        if not found:
            continue
        data = pd.read_csv(found[0], skipinitialspace=True)
        folder = work / name
        folder.mkdir(parents=True, exist_ok=True)
        us, ys = [], []
        for part in ("est", "val"):
            uc, yc, (a, b) = spec[part]
            u, y = data[uc].to_numpy(float)[a:b], data[yc].to_numpy(float)[a:b]
            write_csv(folder / f"{part}.csv", u, y, spec["Ts"], ("u", "y"))
            us.append(u)
            ys.append(y)
        box = []
        for v in (np.concatenate(us), np.concatenate(ys)):
            lo, hi = float(v.min()), float(v.max())
            box.append((lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)))
        (folder / "problem.toml").write_text(siso_problem(name, spec["Ts"], *(
            {"unit": unit, "min": lo, "max": hi}
            for unit, (lo, hi) in zip(spec["units"], box, strict=True))))
        out[name] = folder
    return out


def ours(folder: Path, work: Path, quick: bool) -> dict[str, Any]:
    """``cosim train est.csv --test val.csv --split 0.8,0.1`` (its own process, as a user
    runs it): the validation experiment's RMS after :data:`SEEN` samples, for the GRU and
    its ARX baseline, from the model file."""
    import json

    from controllers.identification import linear
    from controllers.identification.record import Record
    from controllers.identification.simulation import simulate
    from controllers.model import GRUModel
    from cosim.core import logdata

    model_path = work / f"{folder.name}_gru.json"
    extra = ["--epochs", "30", "--sizes", "4,8", "--seeds", "1"] if quick else []
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cosim.cli", "train", str(folder / "est.csv"),
                    "--test", str(folder / "val.csv"), "--problem",
                    str(folder / "problem.toml"), "--split", "0.8,0.1", "--out",
                    str(model_path), "--quiet", *extra], check=True)
    wall = time.perf_counter() - t0
    model = GRUModel.load(model_path)
    pr = model.problem
    data = logdata.read_logs([(folder / "est.csv", None), (folder / "val.csv", "test")],
                             pr.input_names, pr.output_names, pr.Ts, pr.name, (0.8, 0.1))
    rec = Record(model.normalize_u(data.u), model.normalize_y(data.y), data.split,
                 data.experiment)
    val = data.experiment == data.experiment.max()
    tail = val & (np.cumsum(val) > SEEN)
    xi = simulate(model.params, rec)
    doc = json.loads(model_path.read_text())["training"]
    out = {"GRU (this tool)": (_rms(model, rec.y, xi, tail), wall)}
    arx = linear.fit_arx(rec)
    if arx is not None:
        out[f"ARX ({arx.na},{arx.nb},{arx.nk})"] = (
            _rms(model, rec.y, linear.simulate(arx, rec), tail), None)
    out["_note"] = (f"n={doc['options']['n']}, best of {len(doc['candidates'])} "
                    "candidates")
    return out


def _rms(model: Any, y: np.ndarray, xi: np.ndarray, rows: np.ndarray) -> float:
    err = (y[rows] - xi[rows]) * np.abs(model.y_scale)
    return float(np.sqrt(np.mean(err ** 2)))


def subnet(folder: Path, quick: bool, seed: int = 0) -> dict[str, Any]:
    """deepSI's SUBNET with its defaults (nx 10, na = nb = 20, T = 50, batch 256, Adam),
    fitted on the training rows, its best iteration on the validation rows, 10,000
    iterations (``--quick``: 200)."""
    try:
        import deepSI
        import torch
        from nonlinear_benchmarks import Input_output_data
    except ImportError:
        return {}
    from controllers.problem_file import load
    from cosim.core import logdata

    pr = load(folder / "problem.toml")
    est = logdata.read_log(folder / "est.csv", pr.input_names, pr.output_names, pr.Ts, pr.name,
                           (0.8, 0.1))
    val = logdata.read_log(folder / "val.csv", pr.input_names, pr.output_names, pr.Ts,
                           pr.name, whole_split="test")
    torch.manual_seed(seed)
    torch.set_num_threads(1)

    def part(d: Any, name: str) -> Any:
        rows = d.split == name
        return Input_output_data(u=d.u[rows], y=d.y[rows], sampling_time=pr.Ts)

    train = part(est, "train")
    need = 20 + 1                          # its encoder's past window (na = nb = 20) and more
    if int(np.sum(est.split == "val")) < need:
        return {"_note": f"SUBNET not run: its selection needs more than {need - 1} "
                         f"validation rows, this record has {int(np.sum(est.split == 'val'))}"}
    nu, ny, norm = deepSI.get_nu_ny_and_auto_norm(train)
    model = deepSI.SUBNET(nu, ny, norm)
    t0 = time.perf_counter()
    with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet), \
            contextlib.redirect_stderr(quiet):       # its progress bar and log lines
        fitted = deepSI.fit(model, train, part(est, "val"), n_its=200 if quick else 10000,
                            T=50, batch_size=256, val_freq=100)
    wall = time.perf_counter() - t0
    best = fitted["best_model"]
    sim = best.simulate(Input_output_data(u=val.u, y=val.y, sampling_time=pr.Ts))
    err = (np.asarray(sim.y).reshape(val.y.shape) - val.y)[SEEN:]
    return {"SUBNET (deepSI 0.4, defaults)": (float(np.sqrt(np.mean(err ** 2))), wall)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--raw", type=Path, default=None,
                        help="a folder of public records as published (module docstring)")
    parser.add_argument("--records", type=Path, default=None,
                        help="a folder of records (est.csv, val.csv, problem.toml each)")
    parser.add_argument("--only", nargs="*", default=None, help="the records to run")
    parser.add_argument("--quick", action="store_true", help="brief training (the test)")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-identification-"))
    records = built_in(work / "records")
    if args.raw is not None:
        records.update(real_records(args.raw, work / "records"))
    if args.records is not None:
        records.update({p.name: p for p in sorted(args.records.iterdir())
                        if (p / "est.csv").is_file()})
    if args.only:
        records = {k: v for k, v in records.items() if k in args.only}
    print(f"{'record':<12} {'method':<32} {'validation RMS':>16} {'wall time':>10}")
    for name, folder in records.items():
        from controllers.problem_file import load

        unit = load(folder / "problem.toml").outputs[0].unit
        rows = ours(folder, work, args.quick)
        peer = subnet(folder, args.quick)
        note = "; ".join(n for n in (rows.pop("_note", ""), peer.pop("_note", "")) if n)
        rows.update(peer)
        for method, (value, wall) in rows.items():
            when = "" if wall is None else f"{wall:.0f} s"
            print(f"{name:<12} {method:<32} {value:>12.4g} {unit:<3} {when:>10}")
        if note:
            print(f"{'':<12} ({note})")
    print(f"files in {work}")


if __name__ == "__main__":
    main()
