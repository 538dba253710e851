""":class:`controllers.kernel.controller_source.CompiledController`, the exported controller's
C step alone, fed the measurements the Python controller saw gives its inputs, statuses and
fallbacks step by step (to the bit): the tracking law with settings changed between steps, the
paper's law with and without its governor, and the softened phase."""

from __future__ import annotations

import pytest

from cosim.core.errors import CosimError
from tests.cosim.adapters.export_cases import GOVERNED, PAPER_LAW, replayed


def test_the_compiled_step_replays_the_python_controller() -> None:
    """:class:`CompiledController` fed the measurements the Python controller saw gives its
    inputs, statuses and fallbacks, step by step; a setting changed between two steps
    (:meth:`controllers.mpc.RobustMPC.set`: the weights, ``d̂``'s gain) is the C step's
    tunable parameter of that name: the same inputs to the bit after it, and after a new
    run (the design's settings again)."""
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
        parameters,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController()
    design = ctrl.mpc.export_design()
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    names = [p[0] for p in parameters(design, ("qa", "qb"), ("h1", "h2"))]
    assert names == [s[0] for s in ctrl.mpc.settings()]
    changes = {20: {"R.qa": 0.05, "offset_weight.h2": 300.0},
               35: {"offset_filter": 0.6, "du_weight.qb": 0.5}}
    for run in range(2):
        ctrl.setup(0.0)
        compiled.reset()
        refs = [(0.65, 0.65)] * 30 + [(1.3, 1.4)] * 30
        for k, _ in enumerate(replayed(ctrl, compiled, refs)):
            for name, value in changes.get(k, {}).items() if run == 0 else ():
                assert compiled.set_parameter(names.index(name), value) is None
                assert ctrl.set(name, value).startswith(f"{name} = {value:g}: ")
        assert dict((s[0], s[4]) for s in ctrl.mpc.settings())["R.qa"] == (
            0.05 if run == 0 else 0.01)
    with pytest.raises(CosimError, match=r"setting R\.qa=-1\.0: must keep R positive definite"):
        ctrl.set("R.qa", -1.0)
    assert compiled.set_parameter(names.index("R.qa"), -1.0) is not None
    with pytest.raises(CosimError, match=r"no setting 'R\.zz'"):
        ctrl.set("R.zz", 1.0)
    compiled.close()


@pytest.mark.parametrize(("options", "refs", "first_outside", "named"), [
    ({}, ((0.65, 0.65), (1.3, 1.4), (3.0, 0.3)), False, 1),
    ({"offset_free": True, "setpoint_rate": 0.05, "du_weight": 0.1},
     ((0.65, 0.65), (0.9, 1.0), (3.0, 0.3)), False, 0),
    ({}, ((3.0, 0.3), (0.8, 0.9), (0.7, 0.8)), True, 1),
    (GOVERNED, ((0.65, 0.65), (1.3, 1.4), (0.5, 0.6), (3.0, 0.3), (1.0, 1.2)), False, 1),
    ({**GOVERNED, "offset_free": True, "setpoint_rate": 0.05, "du_weight": 0.1},
     ((0.65, 0.65), (1.3, 1.4), (0.5, 0.6), (1.9, 0.2), (1.0, 1.2)), False, 0),
    (GOVERNED, ((3.0, 0.3), (0.8, 0.9), (0.3, 0.4)), True, 1)],
    ids=["paper", "offset-free-rate-limited", "uncertified-first-outside", "governor",
         "governor-offset-free-rate-limited", "governor-uncertified-first-outside"])
def test_the_compiled_paper_step_replays_the_python_law(options: dict, refs: tuple,
                                                        first_outside: bool,
                                                        named: int) -> None:
    """The paper's law in C (``law_paper.c``) fed the measurements the Python law saw:
    its inputs, statuses and fallbacks step by step (to the bit), through set-point steps,
    the offset-free shift and the rate limit, a set-point outside the theory (refused, the
    last admissible one kept: one warning per refused request, where the Python law names
    one; rate-limited, the set-point stops at the boundary, refused step by step, unnamed,
    as in Python) and, uncertified, a first set-point outside (the closest admissible
    one); with the reference governor (``governor=true``, the Python law's default) through
    its moves by fractions of the step, ``λ_max`` halved after failed solves and grown
    again, and its holds."""
    from controllers.kernel.controller_source import (
        CompiledController,
        build,
        design_data,
        parameters,
    )
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(**{**PAPER_LAW, **options})
    if first_outside:
        ctrl.expect_setpoints([{"h1": 3.0, "h2": 0.3}])
        assert not ctrl.mpc.law.certified
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    names = [p[0] for p in parameters(design, ("qa", "qb"), ("h1", "h2"))]
    assert names == (["offset_filter"] if "offset_free" in options else []) + [
        "R.qa", "R.qb"] + (["du_weight.qa", "du_weight.qb"] if "du_weight" in options else []
                           ) + (["setpoint_rate"] if "setpoint_rate" in options else [])
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    refused, fractions = 0, set()
    for k, out in enumerate(replayed(ctrl, compiled, [r for r in refs for _ in range(25)])):
        assert bool(out["warnings"] & 4) == (len(ctrl.mpc.law.rejections) > refused), k
        refused = len(ctrl.mpc.law.rejections)
        fractions.add(ctrl.mpc.law.lam)
    assert refused == named
    assert ctrl.mpc.law.rejected > 0
    if "governor" in options and not first_outside:   # it moved by fractions of the step
        assert ctrl.mpc.law.governed_steps > 0 and min(fractions - {0.0}) < 0.5, fractions
    compiled.close()


@pytest.mark.parametrize("law", [{}, PAPER_LAW], ids=["tracking", "paper"])
def test_the_compiled_step_replays_the_softened_phase(law: dict) -> None:
    """Measurements at the top of h1's box, where the estimated state fails the tightened
    rows at the first step: the Python controller solves its softened problem
    (:mod:`controllers.ocp.soft`) instead of falling back, and the compiled step gives the
    same inputs (to the bit), statuses and fallbacks."""
    from controllers.kernel.controller_source import CompiledController, build, design_data
    from cosim.adapters.robust_mpc import RobustMPCController

    ctrl = RobustMPCController(**law)
    ctrl.setup(0.0)
    design = ctrl.mpc.export_design()
    compiled = CompiledController(*build(design), design_data(design), n_inputs=2,
                                  n_outputs=2)
    softened = [ctrl.diagnostics()["softened"]
                for _ in replayed(ctrl, compiled, [(1.0, 0.9)] * 12, y0=(1.99, 0.9))]
    assert softened[0] > 0.0, softened   # the estimate starts from the first measurement
    assert ctrl.mpc.summary()["fallbacks"] == 0
    compiled.close()
