"""The controller FMU's step against the Python controller component's, on the same steps.

The paper scenario (``--scenario``) in closed loop with the four-tank FMU and the default
robust MPC records every controller step's measurements and set-points; then the Python
component (the baseline) and the controller FMU exported from it (``cosim export-fmu``, FMI
``--fmi``) each replay them ``--repeats`` times in fresh instances, both as the master steps
a controller (``set_inputs``, ``step``, ``get_outputs``: the FMU through
:class:`cosim.core.fmu_controller.FmuController`, fmpy's ctypes calls included), runs
interleaved; and the FMU as ``cosim run`` steps it, in a worker process of its own
(:class:`cosim.core.isolated.IsolatedFmuController`: one round trip per step). Printed: each
one's median and p99 step [ms] over all repeats and its ratios to the baseline (issue: the
FMU no slower at the median and at the p99), what the worker adds per step, and the largest
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
from cosim.core.isolated import IsolatedFmuController  # noqa: E402

SCENARIO = HERE.parent / "scenarios" / "paper_steps.csv"


def record(scenario: Path, options: dict[str, object]) -> list[dict[str, float]]:
    """The controller's inputs at every step of the closed loop."""
    from cosim.adapters.robust_mpc import RobustMPCController

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
        controllers = {"python": registry.create("robust-mpc", options),
                       "fmu": FmuController(fmu), "worker": IsolatedFmuController(fmu)}
        dt = float(controllers["python"].sample_time)
        times: dict[str, list[np.ndarray]] = {name: [] for name in controllers}
        inputs: dict[str, np.ndarray] = {}
        for _ in range(args.repeats):   # interleaved, fresh instances each time
            for name, ctrl in controllers.items():
                t, u = replay(ctrl, steps, dt)
                times[name].append(t)
                inputs[name] = u
        for ctrl in controllers.values():
            ctrl.terminate()
    print(f"{len(steps)} controller steps x {args.repeats} repeats, FMI {args.fmi}.0, "
          f"options {options or 'default'}")
    ms = {name: np.concatenate(t) * 1e3 for name, t in times.items()}
    base = ms["python"]
    for name, t in ms.items():
        med, p99 = float(np.median(t)), float(np.percentile(t, 99))
        ratio = (f"  ({med / np.median(base):.2f}x, {p99 / np.percentile(base, 99):.2f}x the "
                 "Python step)" if name != "python" else "  (baseline)")
        print(f"{name:>7}: median {med:.3f} ms, p99 {p99:.3f} ms{ratio}")
    added = float(np.median(ms["worker"]) - np.median(ms["fmu"]))
    print(f"the worker process adds {added * 1e3:.0f} us per step at the median")
    diff = max(float(np.max(np.abs(inputs[name] - inputs["python"])))
               for name in ("fmu", "worker"))
    print(f"largest input difference: {diff:.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
