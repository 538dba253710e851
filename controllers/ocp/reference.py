"""What a control law brings to the FHOCP ``eq:optimization``: the :class:`Reference` protocol.

One class builds and solves the finite-horizon problem (:class:`controllers.ocp.fhocp.FHOCP`):
the model ``eq:gru`` rolled out from ``x̂``, the stage cost, the terminal weight ``s``, the
tightened output rows (``eq:optimization-constraint``), the input box, the ``i = 0`` test,
the solver, the judge of every answer (:func:`controllers.ocp.fhocp_result.judge`, one status
enum with the kernel) and the warm start. What differs between control laws is a strategy
object given to that class (its pluggable reference), implementing this protocol:

* **the reference**: the paper's set-point ``(x̄, ū)`` given with every solve
  (:class:`controllers.laws.paper.reference.FixedSetpoint`), or an artificial steady state
  ``(x_s(u_s), u_s)`` that is a decision variable, with an offset cost towards a target
  (:class:`controllers.laws.tracking.reference.ArtificialSteadyState`, the tracking law's);
* **the terminal ingredients**: the set-point's ``α(ȳ)`` per solve, or a constant ``α_c``
  with the steady outputs restricted to ``Y_s``;
* **the decision vector and the rows beyond the output rows** (its layout: ``nw``, ``iu``,
  ``it``, ``ng``, ``npar``), the NLP's numpy derivatives (the compiled kernel's twin) and the
  kernel's variant (:meth:`Reference.kernel_terms`);
* **one solve's request** (:meth:`Reference.request`: what the law's controller hands
  :meth:`FHOCP.solve`), written into the solver's buffers (:meth:`Reference.write`), the
  independent check of the solver's answer (:meth:`Reference.check_answer`) and the
  candidate evaluated when ``x̂`` fails the ``i = 0`` row (:meth:`Reference.fallback`).

The Δu weight ``S`` is the problem's (:mod:`controllers.ocp.input_rate`); a reference decides
its terms beyond ``u_0 − u_{−1}`` (the tracking law's ``u_{N−1} − u_s``).

A third law (offset-free MPC with a disturbance model, say) is one new module implementing
this protocol, and its tests: the FHOCP, its solvers, the judge and the controllers that
step it do not change. A reference object serves the one FHOCP it is given to
(:meth:`Reference.attach`): it keeps that problem's layout and buffers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from controllers.errors import DesignError

if TYPE_CHECKING:
    from controllers.ocp.fhocp import FHOCP
    from controllers.ocp.fhocp_result import FHOCPResult

__all__ = ["Reference", "ServesOne"]


class Reference(Protocol):
    """A control law's part of ``eq:optimization`` (module docstring).

    Attributes
    ----------
    name : str
        The law's name (``"paper"``, ``"tracking"``).
    formulations : tuple of str
        The FHOCP formulations it supports (``"single-shooting"``, ``"multiple-shooting"``).
    sqp_overrides : mapping
        Its SQP options over :data:`~controllers.ocp.solver_settings.SQP_OPTIONS`
        (the caller's ``sqp_options`` override these).
    nw, ng, npar, it : int
        Sizes of the decision vector ``w``, of the constraints ``g`` and of the parameters
        ``p``; the index of the terminal epigraph variable ``t`` in ``w`` (set by
        :meth:`attach`).
    iu : (N, m) int array
        Indices of ``u_0 … u_{N−1}`` in ``w``.
    ix : (N + 1, n) int array or None
        Indices of the states in ``w`` (multiple shooting), else ``None``.
    """

    name: str
    formulations: tuple[str, ...]
    sqp_overrides: Mapping[str, Any]
    nw: int
    ng: int
    npar: int
    it: int
    iu: np.ndarray
    ix: np.ndarray | None

    def attach(self, fhocp: FHOCP, data: Any) -> None:
        """Serve ``fhocp`` (built from ``data``, an ``FHOCPData`` or a certificate): check
        the reference against its dimensions, compute the layout."""
        ...

    def kernel_terms(self) -> dict[str, Any]:
        """Its fields of :class:`controllers.kernel.compiled_kernel.KernelProblem`
        (none: the paper's kernel)."""
        ...

    def nlp(self, kernel: Any) -> Any:
        """The single-shooting NLP's numpy evaluations, on ``kernel``'s workspace when
        given (a :class:`~controllers.ocp.nlp_single_shooting.SingleShootingNLP`)."""
        ...

    def request(self, *args: Any, **kwargs: Any) -> Any:
        """One solve's request (:meth:`FHOCP.solve` passes its arguments after ``x̂, ê_o``)."""
        ...

    def write(self, ins: dict[str, np.ndarray], x_hat: np.ndarray, e_o: float,
              request: Any) -> None:
        """The solver's parameters, bounds, initial guess and multipliers (its argument
        buffers ``ins``) for ``request``."""
        ...

    def check_answer(self, wopt: np.ndarray, pv: np.ndarray, x_hat: np.ndarray, e_o: float,
                     request: Any, status: str) -> FHOCPResult:
        """The independent check of the solver's answer ``wopt`` at ``p`` (solver status
        ``status``): a rollout apart from the solver's, the cost, the residuals and the
        defect against the solver's own trajectory."""
        ...

    def fallback(self, x_hat: np.ndarray, e_o: float, request: Any,
                 status: str) -> FHOCPResult:
        """The request's candidate, evaluated, with ``status`` (``x̂`` failed the ``i = 0``
        row: no solver is called)."""
        ...


class ServesOne:
    """What both references share: the one FHOCP a reference serves (:meth:`Reference.
    attach`), ``None`` before."""

    fhocp: FHOCP | None = None

    def _refuse_another(self, fhocp: FHOCP) -> None:
        """Refuse ``fhocp`` when this object already serves another (it holds that one's
        layout)."""
        if self.fhocp is not None and self.fhocp is not fhocp:
            raise DesignError(f"this {type(self).__name__} already serves another FHOCP: "
                              "give each FHOCP its own")

    @property
    def _fh(self) -> FHOCP:
        assert self.fhocp is not None, "the reference serves no FHOCP yet"
        return self.fhocp
