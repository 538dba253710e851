"""The controller FMU's step against the Python controller component's, on the same steps.

The paper scenario (``--scenario``) in closed loop with the four-tank FMU and the default
robust MPC records every controller step's measurements and set-points; then the Python
component (the baseline) and the controller FMU exported from it (``cosim export-fmu``, FMI
``--fmi``) each replay them ``--repeats`` times in fresh instances, both as the master steps
a controller (``set_inputs``, ``step``, ``get_outputs``: the FMU through
:class:`cosim.core.fmu_controller.FmuController`, fmpy's ctypes calls included), runs
interleaved. Printed: each one's median and p99 step [ms] over all repeats and the FMU's
ratios to the baseline (issue: no slower at the median and at the p99), and the largest
difference of their inputs (they agree to the bit).

``--option KEY=VALUE`` (repeatable, the value read as JSON, as ``cosim run``'s): the robust
MPC's options, e.g. ``--option 'law="paper"'`` for the paper's law with its reference
governor, ``--option governor=false`` added for the paper's controller without it.

Usage: ``.venv/bin/python benchmarks/bench_controller_fmu.py [--repeats R] [--fmi 2|3]
[--option KEY=VALUE]``
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import cosim  # noqa: E402
from cosim.core import registry  # noqa: E402
from cosim.core.errors import CosimError  # noqa: E402
from cosim.core.fmu_controller import FmuController  # noqa: E402

SCENARIO = HERE.parent / "scenarios" / "paper_steps.csv"


def record(scenario: Path, options: dict[str, object]) -> list[dict[str, float]]:
    """The controller's inputs at every step of the closed loop."""
    from cosim_adapters.robust_mpc import RobustMPCController

    seen: list[dict[str, float]] = []
    original = RobustMPCController.set_inputs

    def recording(self: RobustMPCController, values: dict[str, float]) -> None:
        seen.append(dict(values))
        original(self, values)

    RobustMPCController.set_inputs = recording   # type: ignore[method-assign]
    try:
        out = cosim.run(scenario, options=options, figure=False)
    finally:
        RobustMPCController.set_inputs = original   # type: ignore[method-assign]
    assert out.status == "ok", out.reason
    return seen


def replay(ctrl: object, steps: list[dict[str, float]], dt: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """``(step times [s], inputs)`` of ``ctrl`` stepped through ``steps`` from a fresh
    setup."""
    ctrl.setup(0.0)   # type: ignore[attr-defined]
    times, inputs = np.empty(len(steps)), []
    for k, values in enumerate(steps):
        t0 = time.perf_counter()
        ctrl.set_inputs(values)   # type: ignore[attr-defined]
        ctrl.step(k * dt, dt)   # type: ignore[attr-defined]
        u = ctrl.get_outputs()   # type: ignore[attr-defined]
        times[k] = time.perf_counter() - t0
        inputs.append(list(u.values()))
    return times, np.array(inputs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=3)
    parser.add_argument("--scenario", type=Path, default=SCENARIO)
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="a robust-mpc option (VALUE read as JSON), repeatable")
    args = parser.parse_args(argv)
    try:
        options = registry.parse_options(args.option)   # as cosim run reads --option
    except CosimError as exc:
        parser.error(str(exc))

    steps = record(args.scenario, options)
    with tempfile.TemporaryDirectory() as tmp:
        fmu = cosim.export_fmu(out=Path(tmp) / "Controller.fmu", fmi=args.fmi, options=options)
        python = registry.create("robust-mpc", options)
        exported = FmuController(fmu)
        dt = float(python.sample_time)
        times: dict[str, list[np.ndarray]] = {"python": [], "fmu": []}
        inputs: dict[str, np.ndarray] = {}
        for _ in range(args.repeats):   # interleaved, fresh instances each time
            for name, ctrl in (("python", python), ("fmu", exported)):
                t, u = replay(ctrl, steps, dt)
                times[name].append(t)
                inputs[name] = u
        exported.terminate()
    print(f"{len(steps)} controller steps x {args.repeats} repeats, FMI {args.fmi}.0, "
          f"options {options or 'default'}")
    base = np.concatenate(times["python"])
    for name in ("python", "fmu"):
        t = np.concatenate(times[name]) * 1e3
        med, p99 = float(np.median(t)), float(np.percentile(t, 99))
        ratio = (f"  ({med / (np.median(base) * 1e3):.2f}x, "
                 f"{p99 / (np.percentile(base, 99) * 1e3):.2f}x the Python step)"
                 if name == "fmu" else "  (baseline)")
        print(f"{name:>7}: median {med:.3f} ms, p99 {p99:.3f} ms{ratio}")
    diff = float(np.max(np.abs(inputs["fmu"] - inputs["python"])))
    print(f"largest input difference: {diff:.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
