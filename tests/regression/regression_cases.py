"""The regression cases: every shipped scenario × controller (× third-party plant).

Each case runs through the ``cosim run`` command line in its own process (exactly what a user
runs), and its ``results.csv`` is compared by :mod:`cosim.core.compare` with
``scenarios/references/<scenario>__<controller>[__<plant>].csv``.

References hold every column of ``results.csv`` except :data:`NOT_COMPARED` (wall-clock
timings, which differ from run to run, and solver bookkeeping such as iteration counts, which
may differ between machines without changing the closed loop).
"""

from __future__ import annotations

import csv
import importlib.util
import os
import subprocess
import sys
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
REFERENCES = SCENARIOS / "references"
THIRDPARTY = ROOT / "fmus" / "thirdparty"
#: Controllers every scenario is run with (the robust MPC with its default, the tracking law).
CONTROLLERS = ("pi", "robust-mpc")
#: Name of the third-party plant in reference file names; it runs with this controller.
THIRDPARTY_PLANT = "quadruple_tank"
THIRDPARTY_CONTROLLER = "robust-mpc"
#: The robust MPC's other law, recorded wherever the robust MPC is: (label, options). The
#: paper's law keeps the references it had while it was the default (renamed, not re-recorded).
OTHER_LAWS = (("robust-mpc-paper", ("--option", 'law="paper"')),)
#: Column-name endings that are recorded but never compared (nor stored in references):
#: solver bookkeeping that may differ between machines without any change of the closed
#: loop (iteration counts, status codes, and the count of constraints within 1e-6 of their
#: bound, a threshold that a converged answer can sit on). Wall-clock solve times are not in
#: results.csv at all: they go to timings.csv.
NOT_COMPARED = (".iterations", ".status", ".active_constraints")
#: Controller options every case of a controller is recorded with. The robust MPC solves
#: each FHOCP to convergence: its default 15-iteration cap applies, at a few steps after large
#: set-point changes, an unconverged iterate whose value depends on the last bits of the
#: arithmetic (the OpenBLAS kernel of the machine: 4e-4 relative on qa at one step of the
#: paper scenario); a converged optimum does not. ``max_iter=200``: the largest count
#: measured on the shipped scenarios is 60.
RECORDING_OPTIONS: dict[str, tuple[str, ...]] = {
    "robust-mpc": ("--option", "max_iter=200"),
}
#: How to regenerate references (quoted in failure messages).
UPDATE_HINT = ("regenerate deliberately with `.venv/bin/pytest tests/regression "
               "--update-references` and commit scenarios/references/")


@dataclass(frozen=True)
class Case:
    """One regression run."""

    scenario: Path
    controller: str
    plant: str | None = None           # None: the project's FourTank.fmu
    options: tuple[str, ...] = field(default=())
    label: str | None = None           # the controller's name in the id (default: its own)

    @property
    def id(self) -> str:
        parts = [self.scenario.stem, self.label or self.controller]
        if self.plant:
            parts.append(self.plant)
        return "__".join(parts)

    @property
    def reference(self) -> Path:
        return REFERENCES / f"{self.id}.csv"


def recording_options(controller: str, base: str | None = None) -> tuple[str, ...]:
    """:data:`RECORDING_OPTIONS` of ``controller`` (or of ``base``, the one it perturbs)."""
    return RECORDING_OPTIONS.get(base or controller, ())


def shipped_cases() -> list[Case]:
    """Every scenario × :data:`CONTROLLERS`, plus every scenario on the third-party plant;
    each robust-MPC case also with each of :data:`OTHER_LAWS`."""
    cases = []
    for scenario in sorted(SCENARIOS.glob("*.csv")):
        runs = [Case(scenario, c, options=recording_options(c)) for c in CONTROLLERS]
        runs.append(Case(scenario, THIRDPARTY_CONTROLLER, THIRDPARTY_PLANT,
                         options=recording_options(THIRDPARTY_CONTROLLER)))
        for case in runs:
            cases.append(case)
            if case.controller == "robust-mpc":
                cases += [Case(scenario, case.controller, case.plant, (*case.options, *options),
                               label) for label, options in OTHER_LAWS]
    return cases


def map_of(case: Case) -> Path | None:
    """The variable map a case's plant needs (``None`` for the project's FMU)."""
    if case.plant == THIRDPARTY_PLANT:
        return THIRDPARTY / f"{THIRDPARTY_PLANT}.map.toml"
    return None


#: Start levels of the four tanks, as scenario columns (``plant.<name>``).
START_LEVELS = ("h1_start", "h2_start", "h3_start", "h4_start")


def perturbed_scenario(case: Case, fmu: Path, dest: Path, dh: float = 1e-12) -> Path:
    """A copy of the case's scenario whose plant starts with every level ``dh`` metres higher.

    The start levels are the FMU's own start values (read through the case's variable map),
    set in the first row as ``plant.h1_start`` … columns. The copy keeps the scenario's file
    name, so the case id and its reference are unchanged.
    """
    from cosim.core import varmap
    from cosim.core.fmu import FmuComponent

    vmap = map_of(case)
    plant = FmuComponent(fmu, varmap=varmap.load(vmap) if vmap else None)
    starts = {}
    for name in START_LEVELS:
        m = plant.varmap.lookup(name)
        starts[name] = m.from_plant(float(plant.variable_of(name).start)) + dh
    with case.scenario.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    header, first = rows[0], rows[1]
    for name, value in starts.items():
        col = f"plant.{name}"
        if col in header:
            raise ValueError(f"{case.scenario}: already sets {col}")
        header.append(col)
        first.append(repr(value))
        for row in rows[2:]:
            row.append("")
    dest.mkdir(parents=True, exist_ok=True)
    out = dest / case.scenario.name
    with out.open("w", newline="", encoding="utf-8") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)
    return out


def controller_available(name: str) -> str | None:
    """``None`` when the controller can be imported, else the reason it cannot."""
    from cosim.core import registry
    from cosim.core.errors import CosimError

    try:
        registry.resolve(name)
    except CosimError as exc:
        return str(exc)
    return None


def build_thirdparty(out_dir: Path) -> Path:
    """Build the third-party example FMU with ``fmus/thirdparty/build.py``."""
    spec = importlib.util.spec_from_file_location("thirdparty_build", THIRDPARTY / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(out_dir)


def compared_columns(names: Iterable[str]) -> list[str]:
    """The signal columns that are compared (and stored in references)."""
    return [n for n in names if not n.endswith(NOT_COMPARED)]


@dataclass
class Run:
    """Outcome of running one case."""

    case: Case
    out: Path
    returncode: int
    output: str

    @property
    def results(self) -> Path:
        return self.out / "results.csv"


def run_case(case: Case, out: Path, fmus: dict[str | None, Path]) -> Run:
    """Run one case with ``python -m cosim.cli run`` in a fresh process."""
    cmd = [sys.executable, "-m", "cosim.cli", "run", str(case.scenario),
           "--controller", case.controller, "--plant", str(fmus[case.plant]),
           "--out", str(out), "--quiet", "--no-figure", *case.options]
    vmap = map_of(case)
    if vmap is not None:
        cmd += ["--map", str(vmap)]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               PYTHONHASHSEED="0")
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    return Run(case, out, proc.returncode, (proc.stdout + proc.stderr).strip())


def run_cases(cases: list[Case], out_root: Path, fmus: dict[str | None, Path],
              workers: int = 2) -> dict[str, Run]:
    """Run cases in parallel processes (``workers`` at a time); results by case id."""
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures = {c.id: pool.submit(run_case, c, out_root / c.id, fmus) for c in cases}
        return {k: f.result() for k, f in futures.items()}


def write_reference(results: Path, reference: Path) -> None:
    """Copy the compared columns of ``results`` to ``reference`` (values as written)."""
    with results.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    keep = [0] + [j for j, n in enumerate(rows[0]) if j and n in compared_columns([n])]
    from cosim.core import atomicio

    # a temporary file renamed into place: an interrupted update never truncates a reference
    with atomicio.open_replacing(reference, "w", newline="") as fh:
        writer = csv.writer(fh, quoting=csv.QUOTE_MINIMAL, lineterminator="\n")
        for row in rows:
            writer.writerow([row[j] for j in keep])
