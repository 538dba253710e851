"""The robust MPC's design, described once: :class:`MPCOptions`.

Everything a user chooses about the robust MPC beyond the model and its control problem (the
problem file holds the signals, units, boxes and Ts): the law and its horizon, the cost
weights, the observer's start, the certificate mode, the solver's settings and the law's own
options. One frozen, serialisable object, validated in one place (:meth:`MPCOptions.
from_mapping`: one-line errors naming the option, the law's defaults filled in, each from the
law's spec, :mod:`controllers.laws`), which the controller (:class:`controllers.mpc.RobustMPC`)
takes and every part of the design reads (the certificate, the FHOCP, the compiled kernel
and the exported FMU take ``N`` and the weights from it), the run summary records
(:meth:`MPCOptions.to_dict`), and ``--option KEY=VALUE``, campaign variants and the Python API
all reach through the same keys.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers import laws
from controllers.errors import OptionError

__all__ = ["CERTIFICATE_MODES", "COMMON", "OUTPUT_WEIGHT_EPS", "MPCOptions", "design_arguments",
           "plain"]

#: The ``certificate`` option (:mod:`controllers.certification.grade`).
CERTIFICATE_MODES = ("auto", "require", "keep")


@dataclass(frozen=True)
class MPCOptions:
    """The robust MPC's design (module docstring); ``None``: the law's default.

    Attributes
    ----------
    law : {"tracking", "paper"}
        ``"tracking"`` (default): the tracking FHOCP (:mod:`controllers.laws.tracking.law`,
        :mod:`controllers.laws.tracking.reference`): an artificial steady state as a decision
        variable, offset-free through ``d̂`` in the cost, no governor, nothing rejected (an
        unreachable or inadmissible set-point is tracked to the closest admissible steady
        state); zero observer gains. ``"paper"``: the paper's FHOCP with the set-point's
        equilibrium, the governor and set-point rejection.
    N : int, optional
        Prediction horizon (default 80, :data:`controllers.laws.tracking.reference.DEFAULTS`; the
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
        :mod:`cosim.adapters.robust_mpc`).
    offset_filter : float, optional
        Filter constant ``β`` of ``d̂ ← d̂ + β (y − ŷ − d̂)`` (default 0.3; 0.05 with
        ``law="paper"``).
    governor : bool, optional
        ``law="paper"``: admissible reference governor after set-point changes (default on; see
        :mod:`cosim.adapters.robust_mpc` and :mod:`controllers.laws.paper.governor`). ``False``: the
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
        :class:`controllers.laws.tracking.reference.ArtificialSteadyState`). Default
        ``⌈N / 4⌉`` (20 at the default N = 80).
    certificate : {"auto", "require", "keep"}
        Where the certificate does not cover the run (a hypothesis fails, or a set-point of
        the run lies outside the certified set): ``"auto"`` runs uncertified, with the
        model's measured prediction error as the tightening; ``"require"`` refuses
        (:class:`cosim.core.errors.CosimError`, exit 2); ``"keep"`` keeps the certified design
        (the tracking law tracks such a set-point to the closest admissible steady output,
        the paper's law refuses it; a design whose hypotheses fail is an error), as before
        graded guarantees (:mod:`controllers.certification.grade`).
    hard_constraints : bool
        ``False`` (default): the output rows, the terminal set and the tracking law's
        ``Y_s`` are softened with an exact penalty (:mod:`controllers.ocp.soft`): the same
        answer wherever the hard problem is feasible, an answer from every state where it is
        not. ``True``: the paper's hard FHOCP (a step whose problem has no solution falls
        back on the candidate).
    max_iter : int, optional
        Iteration cap of one FHOCP solve, the real-time bound (default 40; 15 with
        ``law="paper"``). A solve that reaches it applies its feasible iterate
        (suboptimal MPC) or the fallback; that iterate depends on the last bits of the
        arithmetic, so the regression references are recorded with a cap every solve
        converges within (``max_iter=200``).
    """

    law: str = laws.DEFAULT
    N: int | None = None
    Q: Any = None
    R: Any = None
    e_o0: float = 0.02
    gain_scale: float | None = None
    offset_filter: float | None = None
    solver: str | None = None
    ipopt_options: Mapping[str, Any] | None = None
    max_iter: int | None = None
    kernel: str = "auto"
    du_weight: float | Mapping[str, float] | None = None
    certificate: str = "auto"
    hard_constraints: bool = False
    #: the law's own options (:attr:`controllers.laws.LawSpec.options`), its defaults filled
    law_options: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Every option's key: the common ones and every known law's own."""
        own = [o.name for name in laws.known() for o in laws.spec(name).options]
        return (*COMMON, *dict.fromkeys(own))

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any]) -> MPCOptions:
        """The options of ``options`` (keys as ``--option``'s), checked, with the law's
        defaults filled in (:attr:`controllers.laws.LawSpec.defaults`)."""
        spec = laws.spec(options.get("law", laws.DEFAULT))
        unknown = sorted(k for k in options if k not in COMMON and k not in spec.option_names
                         and k not in cls.names())
        if unknown:
            raise OptionError(f"controller 'robust-mpc' has no option {unknown[0]!r} "
                              f"(options: {', '.join(cls.names())})")
        _check_foreign(spec, options)
        common = {k: v for k, v in options.items() if k in COMMON and k != "law"}
        own = {o.name: options.get(o.name, o.default) for o in spec.options}
        given = cls(**common, law=options.get("law", laws.DEFAULT), law_options=own)
        given.check(spec)
        defaults = {k: v for k, v in spec.defaults.items() if getattr(given, k) is None}
        return dataclasses.replace(given, **defaults)

    @classmethod
    def resolve(cls, given: Mapping[str, Any], problem: Any = None) -> MPCOptions:
        """A run's options: ``given`` (its ``--option`` values) over the problem's ``[mpc]``
        table (:attr:`controllers.problem.ControlProblem.mpc`: the tuning chosen for the
        plant), checked, with the law's defaults filled in.

        The problem's options of another law than the run's are left out (a plant tuned
        for the tracking law still runs the paper's law); a bad one is an error naming the
        problem file and line.
        """
        tuned = dict(getattr(problem, "mpc", None) or {})
        if not tuned:
            return cls.from_mapping(given)
        cls.from_mapping(given)                 # the run's own errors first, as they are
        if "law" in tuned:                      # the table's own law, where it says it
            _located(problem, "law", {"law": tuned["law"]})
        spec = laws.spec(given.get("law", tuned.get("law", laws.DEFAULT)))
        tuned = {k: v for k, v in tuned.items()
                 if k in COMMON or k in spec.option_names or k not in cls.names()}
        for key in sorted(tuned, key=lambda k: k != "law"):
            _located(problem, key, {"law": spec.name, key: tuned[key]} if key != "law"
                     else {key: tuned[key]})
        return cls.from_mapping({**tuned, **given})

    def to_dict(self) -> dict[str, Any]:
        """The options as plain data, the law's own among them (the run summary's
        ``options``; JSON-serialisable for numbers, lists and objects)."""
        out = {name: getattr(self, name) for name in COMMON}
        out.update(self.law_options)
        return out

    @property
    def spec(self) -> laws.LawSpec:
        """The law's spec."""
        return laws.spec(self.law)

    def option(self, name: str) -> Any:
        """The value of the law's own option ``name``."""
        return self.law_options[name]

    # -- validation ------------------------------------------------------------------------
    def check(self, spec: laws.LawSpec | None = None) -> None:
        """Reject options of the wrong type or range in one line (the law's own by its
        spec)."""
        spec = spec or self.spec
        for o in spec.options:
            why = o.check(self.law_options.get(o.name, o.default))
            if why:
                raise OptionError(f"option {o.name}={self.law_options[o.name]!r}: {why}")
        if self.certificate not in CERTIFICATE_MODES:
            raise OptionError(f"option certificate={self.certificate!r}: expected one of "
                              f"{', '.join(map(repr, CERTIFICATE_MODES))}")
        if not isinstance(self.hard_constraints, bool):
            raise OptionError(f"option hard_constraints={self.hard_constraints!r}: expected "
                              "true or false")
        f = self.offset_filter
        if f is not None and (not _number(f) or not 0 < f <= 1):
            raise OptionError(f"option offset_filter={f!r}: expected a number in (0, 1]")
        it = self.max_iter
        if it is not None and (isinstance(it, bool) or not isinstance(it, int)
                               or not 1 <= it <= 10000):
            raise OptionError(f"option max_iter={it!r}: expected an integer in [1, 10000]")
        if self.kernel not in ("auto", "numpy"):
            raise OptionError(f"option kernel={self.kernel!r}: expected \"auto\" or \"numpy\"")
        if self.solver is not None and self.solver not in ("sqp", "ipopt"):
            raise OptionError(f"option solver={self.solver!r}: expected \"sqp\" or \"ipopt\"")
        ip = self.ipopt_options
        if ip is not None and (not isinstance(ip, Mapping)
                               or not all(isinstance(k, str) for k in ip)):
            raise OptionError(f"option ipopt_options={ip!r}: expected an object of IPOPT "
                              "option names and values")
        d = self.du_weight
        weights = list(d.values()) if isinstance(d, Mapping) else [] if d is None else [d]
        if not all(_number(v) and v >= 0 for v in weights):
            raise OptionError(f"option du_weight={d!r}: expected a non-negative number or an "
                              "object of non-negative numbers by input name (normalised units)")


#: The options every law has (the fields of :class:`MPCOptions` but ``law_options``).
COMMON = tuple(f.name for f in dataclasses.fields(MPCOptions) if f.name != "law_options")


def _located(problem: Any, key: str, options: Mapping[str, Any]) -> None:
    """:meth:`MPCOptions.from_mapping` of one key of the problem's ``[mpc]`` table; an error
    names its file and line."""
    from controllers.problem_file import locate_key

    try:
        MPCOptions.from_mapping(options)
    except OptionError as exc:
        raise OptionError(f"{locate_key(problem, 'mpc', key)}: [mpc] {exc}") from None


def _check_foreign(spec: laws.LawSpec, options: Mapping[str, Any]) -> None:
    """Refuse another law's option given to ``spec``'s law at a value other than "not
    used", naming the law it belongs to."""
    for name in laws.known():
        other = laws.spec(name)
        if other.name == spec.name:
            continue
        for o in other.options:
            if o.name in options and o.name not in spec.option_names \
                    and options[o.name] not in o.off:
                raise OptionError(f"option {o.name}={options[o.name]!r} belongs to "
                                  f"law=\"{other.name}\" {spec.foreign_note}".rstrip())


def _number(value: Any) -> bool:
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))


def positive(value: Any) -> bool:
    """A finite number > 0 (not a bool)."""
    return _number(value) and value > 0


def positive_weights(value: Any) -> bool:
    """``None``, a positive number, or an object of positive numbers (by signal name)."""
    weights = (list(value.values()) if isinstance(value, Mapping) else []
               if value is None else [value])
    return all(positive(v) for v in weights)


def _weight(key: str, value: Any, size: int, names: list[str] | None) -> np.ndarray | None:
    """A cost weight option as a matrix: ``None`` (the default), a number (times the
    identity), an object by signal name (diagonal; ``names`` given) or a matrix."""
    if value is None:
        return None
    given = value
    if isinstance(value, Mapping) and names is not None:
        unknown = sorted(set(value) - set(names))
        if unknown:
            raise OptionError(f"option {key}: {unknown[0]!r} is not one of {', '.join(names)}")
        value = np.diag([float(value.get(n, 0.01)) for n in names])
    try:
        w = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise OptionError(f"option {key}={value!r}: expected a number, a {size}x{size} matrix"
                         + (" or an object by input name" if names else "")) from None
    if w.ndim == 0:
        w = float(w) * np.eye(size)
    if w.shape != (size, size):
        raise OptionError(f"option {key}: expected a number or a {size}x{size} matrix, got "
                         f"shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise OptionError(f"option {key}={plain(given)!r}: expected finite numbers")
    return w


#: ``Q="outputs"``: the stage cost on the model's outputs, ``Q = U_oᵀ U_o + ε I`` (ε keeps Q
#: positive definite, as the theorem needs, and the hidden states all but free).
OUTPUT_WEIGHT_EPS = 1e-3


def _state_weight(value: Any, params: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """The state weight ``Q``: :func:`_weight`, or ``"outputs"``: ``U_oᵀ U_o + ε I``
    (:data:`OUTPUT_WEIGHT_EPS`), the outputs' tracking error rather than every hidden
    state's distance to the reference."""
    n = params["U_o"].shape[1]
    if isinstance(value, str):
        if value != "outputs":
            raise OptionError(f"option Q={value!r}: expected a number, a {n}x{n} matrix or "
                             "\"outputs\"")
        Uo = np.asarray(params["U_o"], dtype=float)
        return Uo.T @ Uo + OUTPUT_WEIGHT_EPS * np.eye(n)
    return _weight("Q", value, n, None)


def design_arguments(o: MPCOptions, model: Any) -> dict[str, Any]:
    """The certificate's design arguments of the options ``o`` on ``model`` (its problem's
    inputs): ``N``, ``Q`` (``"outputs"`` built from its ``U_o``), ``R`` (an object by input
    name as a diagonal) and ``e_o0``; what the controller and ``cosim certify`` compute the
    certificate (:func:`controllers.certification.certificates.compute_certificate`) with."""
    inputs = list(model.problem.input_names)
    return {"N": o.N, "Q": _state_weight(o.Q, model.params),
            "R": _weight("R", o.R, len(inputs), inputs), "e_o0": o.e_o0}


def plain(value: Any) -> Any:
    """``value`` as JSON data (arrays as nested lists, mappings as objects)."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray | list | tuple):
        return [plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value
