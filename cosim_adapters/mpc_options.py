"""The robust MPC's design, described once: :class:`MPCOptions`.

Everything a user chooses about the ``robust-mpc`` component beyond the model and its control
problem (the problem file holds the signals, units, boxes and Ts): the law and its horizon,
the cost weights, the observer's start, the certificate mode and the solver's settings. One
frozen, serialisable object, validated in one place (:meth:`MPCOptions.from_mapping`: one-line
errors naming the option, the law's defaults filled in), which
:class:`cosim_adapters.robust_mpc.RobustMPCController` takes, the run summary records
(:meth:`MPCOptions.to_dict`), and ``--option KEY=VALUE``, campaign variants and the Python API
all reach through the same keys. The meaning of each option:
:class:`~cosim_adapters.robust_mpc.RobustMPCController`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["CERTIFICATE_MODES", "LAWS", "LAW_DEFAULTS", "MPCOptions"]

#: The control laws of the ``robust-mpc`` component.
LAWS = ("paper", "tracking")
#: The ``certificate`` option (:mod:`cosim_adapters.certification`).
CERTIFICATE_MODES = ("auto", "require", "keep")
#: The defaults that depend on the law (the tracking law's: :data:`controllers.ocp.
#: law_tracking.DEFAULTS`; the paper's: its section V, N = 15, and the SQP's 15 iterations).
LAW_DEFAULTS: dict[str, dict[str, Any]] = {
    "tracking": {"N": 80, "max_iter": 40, "governor": False, "offset_filter": 0.3,
                 "du_weight": 0.05},
    "paper": {"N": 15, "max_iter": 15, "governor": True, "offset_filter": 0.05,
              "du_weight": 0.0},
}
#: Options of one law only: setting one under the other law is an error.
PAPER_ONLY = ("governor", "offset_free", "setpoint_rate")
TRACKING_ONLY = ("control_horizon", "offset_weight", "alpha_c")


@dataclass(frozen=True)
class MPCOptions:
    """The robust MPC's design (module docstring); ``None``: the law's default.

    Attributes
    ----------
    law : {"tracking", "paper"}
        ``"tracking"`` (default): the tracking FHOCP (:mod:`cosim_adapters.tracking`,
        :mod:`controllers.ocp.reference_tracking`): an artificial steady state as a decision
        variable, offset-free through ``d̂`` in the cost, no governor, nothing rejected (an
        unreachable or inadmissible set-point is tracked to the closest admissible steady
        state); zero observer gains. ``"paper"``: the paper's FHOCP with the set-point's
        equilibrium, the governor and set-point rejection.
    N : int, optional
        Prediction horizon (default 80, :data:`controllers.ocp.reference_tracking.DEFAULTS`; the
        paper's 15 with ``law="paper"``).
    Q, R : array, number or mapping, optional
        Cost weights in normalised units (default ``I_n`` and ``0.01 I_m``, paper section V):
        a matrix, one number (times the identity) or, for ``R``, an object of diagonal
        weights by input name (inputs not named: 0.01). ``Q="outputs"``: the stage cost on
        the model's outputs, ``U_oᵀ U_o + 10⁻³ I`` (positive definite, as the theorem needs;
        the terminal weight ``s`` follows from it as from any Q).
    e_o0 : float
        ``ê_o,0`` (paper: 0.02).
    gain_scale : float, optional
        Observer gains = ``gain_scale`` × the LP gains; default: the gains in the model file
        (``cosim certify --save``), else the largest scale passing every hypothesis at
        :func:`controllers.certification.gain_design.default_setpoints` (a grid over the output box)
        (:func:`controllers.certification.gain_design.choose_gain_scale`).
    offset_free : bool
        ``law="paper"``: offset-free set-point correction (outside the theorem, see
        :mod:`cosim_adapters.robust_mpc`).
    offset_filter : float, optional
        Filter constant ``β`` of ``d̂ ← d̂ + β (y − ŷ − d̂)`` (default 0.3; 0.05 with
        ``law="paper"``).
    governor : bool, optional
        ``law="paper"``: admissible reference governor after set-point changes (default on; see
        :mod:`cosim_adapters.robust_mpc` and :mod:`controllers.ocp.governor`). ``False``: the
        paper's FHOCP with the new ``(x̄, ū, α)`` at once.
    setpoint_rate : float, optional
        ``law="paper"``, outside the theorem: move the set-point given to the FHOCP towards
        the requested one by at most this much per sample, in the outputs' units (a
        rate-limiting reference governor), so that the terminal set stays reachable after
        large steps. Off by default.
    solver : {"sqp", "ipopt"}, optional
        NLP solver of the FHOCP (default: SQP with a dense QP, or IPOPT when
        ``ipopt_options`` are given; see :class:`controllers.ocp.fhocp.FHOCP`).
    ipopt_options : dict, optional
        Overrides of :data:`controllers.ocp.solver_settings.FAST_IPOPT_OPTIONS`.
    kernel : {"auto", "numpy"}
        Where the SQP's derivatives come from: the compiled kernel (``"auto"``, built on
        first use; the numpy callbacks when no C compiler is found) or the numpy callbacks
        (``"numpy"``, the reference implementation). Same answers either way.
    du_weight : float or mapping, optional
        Weight ``S`` of the input-rate penalty ``Σ_i (u_i − u_{i−1})ᵀ S (u_i − u_{i−1})`` in
        normalised units (``u`` ∈ [−1, 1]; ``u_{−1}`` the input applied at the previous
        step), one number for every input or an object by the problem's input names
        (``{"qa": 5, "qb": 5}``; inputs not named: 0). Default 0.05 (the tracking law,
        which adds the terminal term ``‖u_{N−1} − u_s‖²_S``); 0 with ``law="paper"``: the
        paper's cost, which the term leaves.
    offset_weight : float or mapping
        ``law="tracking"``: diagonal of the offset weight ``T`` of ``‖g(x_s) + d̂ − ȳ‖²_T``
        (normalised outputs; one number or an object by output name, outputs not named:
        10⁴). Default 10⁴.
    alpha_c : float, optional
        ``law="tracking"``: the terminal set's radius (normalised state, ∞-norm); default the
        certified design's ``α_min(N)``, which makes ``Y_s`` its admissible box.
    control_horizon : int, optional
        ``law="tracking"``: the number ``M ≤ N`` of free inputs ``u_0 … u_{M−1}``; the
        others are held at the artificial steady input ``u_s`` (the guarantees unchanged:
        :class:`controllers.ocp.reference_tracking.ArtificialSteadyState`). Default
        ``⌈N / 4⌉`` (20 at the default N = 80).
    certificate : {"auto", "require", "keep"}
        Where the certificate does not cover the run (a hypothesis fails, or a set-point of
        the run lies outside the certified set): ``"auto"`` runs uncertified, with the
        model's measured prediction error as the tightening; ``"require"`` refuses
        (:class:`cosim.core.errors.CosimError`, exit 2); ``"keep"`` keeps the certified design
        (the tracking law tracks such a set-point to the closest admissible steady output,
        the paper's law refuses it; a design whose hypotheses fail is an error), as before
        graded guarantees (:mod:`cosim_adapters.certification`).
    max_iter : int, optional
        Iteration cap of one FHOCP solve, the real-time bound (default 40; 15 with
        ``law="paper"``). A solve that reaches it applies its feasible iterate
        (suboptimal MPC) or the fallback; that iterate depends on the last bits of the
        arithmetic, so the regression references are recorded with a cap every solve
        converges within (``max_iter=200``).
    """

    law: str = "tracking"
    N: int | None = None
    Q: Any = None
    R: Any = None
    e_o0: float = 0.02
    gain_scale: float | None = None
    offset_free: bool = False
    offset_filter: float | None = None
    setpoint_rate: float | None = None
    governor: bool | None = None
    solver: str | None = None
    ipopt_options: Mapping[str, Any] | None = None
    max_iter: int | None = None
    kernel: str = "auto"
    du_weight: float | Mapping[str, float] | None = None
    offset_weight: float | Mapping[str, float] | None = None
    alpha_c: float | None = None
    control_horizon: int | None = None
    certificate: str = "auto"

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Every option's key."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any]) -> MPCOptions:
        """The options of ``options`` (keys as ``--option``'s), checked, with the law's
        defaults filled in (:data:`LAW_DEFAULTS`)."""
        unknown = sorted(set(options) - set(cls.names()))
        if unknown:
            raise CosimError(f"controller 'robust-mpc' has no option {unknown[0]!r} "
                             f"(options: {', '.join(cls.names())})")
        given = cls(**options)
        given.check()
        defaults = {k: v for k, v in LAW_DEFAULTS[given.law].items()
                    if getattr(given, k) is None}
        return dataclasses.replace(given, **defaults)

    @classmethod
    def resolve(cls, given: Mapping[str, Any], problem: Any = None) -> MPCOptions:
        """A run's options: ``given`` (its ``--option`` values) over the problem's ``[mpc]``
        table (:attr:`controllers.problem.ControlProblem.mpc`: the tuning chosen for the
        plant), checked, with the law's defaults filled in.

        The problem's options of the other law than the run's are left out (a plant tuned
        for the tracking law still runs the paper's law); a bad one is an error naming the
        problem file and line.
        """
        tuned = dict(getattr(problem, "mpc", None) or {})
        if not tuned:
            return cls.from_mapping(given)
        from controllers.problem_file import locate_key

        cls.from_mapping(given)                 # the run's own errors first, as they are
        law = given.get("law", tuned.get("law", "tracking"))
        other = PAPER_ONLY if law == "tracking" else TRACKING_ONLY
        tuned = {k: v for k, v in tuned.items() if k not in other}
        for key in sorted(tuned, key=lambda k: k != "law"):
            try:
                cls.from_mapping({"law": law, key: tuned[key]} if key != "law"
                                 else {key: tuned[key]})
            except CosimError as exc:
                raise CosimError(f"{locate_key(problem, 'mpc', key)}: [mpc] {exc}") from None
        return cls.from_mapping({**tuned, **given})

    def to_dict(self) -> dict[str, Any]:
        """The options as plain data (the run summary's ``options``; JSON-serialisable for
        numbers, lists and objects)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @property
    def tracking(self) -> bool:
        return self.law == "tracking"

    # -- validation ------------------------------------------------------------------------
    def check(self) -> None:
        """Reject options of the wrong type or range, or of the other law, in one line."""
        if self.law not in LAWS:
            raise CosimError(f"option law={self.law!r}: expected one of "
                             f"{', '.join(map(repr, LAWS))}")
        self._check_law_options()
        if self.certificate not in CERTIFICATE_MODES:
            raise CosimError(f"option certificate={self.certificate!r}: expected one of "
                             f"{', '.join(map(repr, CERTIFICATE_MODES))}")
        for key in ("offset_free", "governor"):
            value = getattr(self, key)
            if value is not None and not isinstance(value, bool):
                raise CosimError(f"option {key}={value!r}: expected true or false")
        f = self.offset_filter
        if f is not None and (not _number(f) or not 0 < f <= 1):
            raise CosimError(f"option offset_filter={f!r}: expected a number in (0, 1]")
        if self.setpoint_rate is not None and not _positive(self.setpoint_rate):
            raise CosimError(f"option setpoint_rate={self.setpoint_rate!r}: expected a "
                             "positive number of output units per sample")
        it = self.max_iter
        if it is not None and (isinstance(it, bool) or not isinstance(it, int)
                               or not 1 <= it <= 10000):
            raise CosimError(f"option max_iter={it!r}: expected an integer in [1, 10000]")
        if self.kernel not in ("auto", "numpy"):
            raise CosimError(f"option kernel={self.kernel!r}: expected \"auto\" or \"numpy\"")
        if self.solver is not None and self.solver not in ("sqp", "ipopt"):
            raise CosimError(f"option solver={self.solver!r}: expected \"sqp\" or \"ipopt\"")
        ip = self.ipopt_options
        if ip is not None and (not isinstance(ip, Mapping)
                               or not all(isinstance(k, str) for k in ip)):
            raise CosimError(f"option ipopt_options={ip!r}: expected an object of IPOPT "
                             "option names and values")
        self._check_weights()

    def _check_law_options(self) -> None:
        if self.tracking:
            for key, off in (("governor", (None, False)), ("offset_free", (False,)),
                             ("setpoint_rate", (None,))):
                value = getattr(self, key)
                if value not in off:
                    raise CosimError(f"option {key}={value!r} belongs to law=\"paper\" (the "
                                     "default tracking law needs no governor and is "
                                     "offset-free)")
        else:
            for key in TRACKING_ONLY:
                value = getattr(self, key)
                if value is not None:
                    raise CosimError(f"option {key}={value!r} belongs to law=\"tracking\" "
                                     "(the default; the paper's law has no artificial "
                                     "steady state)")
        M = self.control_horizon
        if M is not None and (isinstance(M, bool) or not isinstance(M, int) or M < 1):
            raise CosimError(f"option control_horizon={M!r}: expected a positive integer "
                             "(at most N)")

    def _check_weights(self) -> None:
        w = self.offset_weight
        weights = list(w.values()) if isinstance(w, Mapping) else [] if w is None else [w]
        if not all(_positive(v) for v in weights):
            raise CosimError(f"option offset_weight={w!r}: expected a positive number or an "
                             "object of positive numbers by output name")
        if self.alpha_c is not None and not _positive(self.alpha_c):
            raise CosimError(f"option alpha_c={self.alpha_c!r}: expected a positive number")
        d = self.du_weight
        weights = list(d.values()) if isinstance(d, Mapping) else [] if d is None else [d]
        if not all(_number(v) and v >= 0 for v in weights):
            raise CosimError(f"option du_weight={d!r}: expected a non-negative number or an "
                             "object of non-negative numbers by input name (normalised units)")


def _number(value: Any) -> bool:
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))


def _positive(value: Any) -> bool:
    return _number(value) and value > 0
