"""The control laws of the ``robust-mpc`` component as strategies (cosim_adapters.law): both
laws implement one protocol, own their state, and the controller runs whatever law it holds."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

import cosim_adapters.robust_mpc as adapter
from cosim_adapters.law import ControlLaw, LawStep
from cosim_adapters.paper_law import PaperLaw
from cosim_adapters.robust_mpc import RobustMPCController
from cosim_adapters.tracking import TrackingLaw

MEMBERS = [name for name, _ in inspect.getmembers(ControlLaw) if not name.startswith("_")]


@pytest.fixture(scope="module", params=["tracking", "paper"])
def ctrl(request: pytest.FixtureRequest) -> RobustMPCController:
    return RobustMPCController(law=request.param)


def test_both_laws_implement_the_protocol(ctrl: RobustMPCController) -> None:
    law = ctrl.law
    assert isinstance(law, TrackingLaw if law.name == "tracking" else PaperLaw)
    assert {"alpha", "records", "reset", "setpoint_reason", "step", "summary",
            "uncertified"} <= set(MEMBERS)
    for name in [*MEMBERS, "name", "fhocp", "cert"]:
        assert hasattr(law, name), f"{type(law).__name__} lacks {name}"
    assert law.fhocp is ctrl.fhocp and law.cert is ctrl.cert


def test_the_controller_does_not_branch_on_the_law() -> None:
    """The step, the reset and the summary go through the law object only (issue 31: the law
    was a string threaded through 15 branches)."""
    for method in (RobustMPCController.step, RobustMPCController.setup,
                   RobustMPCController.summary):
        source = inspect.getsource(method)
        assert '"tracking"' not in source and '"paper"' not in source
        assert "tracker" not in source and ".mpc" not in source
    assert "update_reference" not in inspect.getsource(adapter)


def test_a_third_law_is_one_object(ctrl: RobustMPCController) -> None:
    """A law that wraps another (here: the set-point clipped to a band, a stand-in for a new
    set-point policy) plugs in without touching the controller."""

    class Clipped:
        def __init__(self, inner: ControlLaw) -> None:
            self.inner, self.name = inner, f"clipped-{inner.name}"
            self.fhocp, self.cert = inner.fhocp, inner.cert
            self.steps = 0

        records = property(lambda self: self.inner.records)
        alpha = property(lambda self: self.inner.alpha)

        def reset(self) -> None:
            self.inner.reset()

        def step(self, observer, y, y_ref, t) -> LawStep:
            self.steps += 1
            return self.inner.step(observer, y, np.clip(y_ref, -0.5, 0.5), t)

        def setpoint_reason(self, y) -> str:
            return self.inner.setpoint_reason(y)

        def uncertified(self, cert, reason):
            return Clipped(self.inner.uncertified(cert, reason))

        def summary(self) -> dict:
            return self.inner.summary()

    original = ctrl.law
    try:
        ctrl.law = Clipped(original)
        ctrl.setup(0.0)
        ctrl.set_inputs({"h1": 0.5, "h2": 0.5, "ref.h1": 0.6, "ref.h2": 0.6})
        ctrl.step(0.0, 25.0)
        assert ctrl.law.steps == 1 and ctrl.summary()["law"] == f"clipped-{original.name}"
        assert all(np.isfinite(v) for v in ctrl.get_outputs().values())
    finally:
        ctrl.law = original
        ctrl.setup(0.0)


def test_the_uncertified_variant_is_the_same_law(ctrl: RobustMPCController) -> None:
    from controllers.certification.certificates import uncertified_certificate
    from cosim_adapters.certification import measured_margins

    cert_u = uncertified_certificate(ctrl.cert, measured_margins(ctrl, ctrl.cert)[0])
    law = ctrl.law.uncertified(cert_u, "a test")
    assert type(law) is type(ctrl.law) and law.cert is not ctrl.cert
    assert law.certified is False and ctrl.law.certified is True
