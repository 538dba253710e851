"""``cosim certify``: the paper's certificates for a GRU model file
(``controllers.certification.certificates``).

Prints every quantity of the theory (δISS, observer, tightening, terminal ingredients) with its
paper reference, or JSON with the paper's names; checks the hypotheses of
``th:feasibility-stability`` at the requested set-points; the exit codes are
:data:`cosim.core.errors.EXIT_CODES` with this command's :data:`EXIT_NOTES`. ``--save`` writes
the observer gains into the model file only when every check passes, atomically (a failed
write leaves the file unchanged).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from cosim.commands import add_model_argument, add_problem_argument
from cosim.commands.certify_report import figure, print_table, print_verdict
from cosim.core.errors import (
    EXIT_FAILED,
    EXIT_INPUT_ERROR,
    EXIT_OK,
    CosimError,
    exit_codes_help,
)

__all__ = ["EPILOG", "EXIT_NOTES", "HELP", "figure", "register", "run"]

#: What the exit codes also mean for ``cosim certify`` (:func:`cosim.core.errors.exit_codes_help`).
EXIT_NOTES = {
    EXIT_OK: "certified: every hypothesis holds",
    EXIT_FAILED: "usable but not certified: a hypothesis fails (named, with what would fix "
                 "it); the robust MPC runs uncertified with this model",
    EXIT_INPUT_ERROR: "not usable: no robust MPC runs this model, certified or not (named "
                      "why, with what would fix it); cosim run refuses it in the same words",
}


HELP = """Compute and check the certificates of the robust GRU MPC (Schimperna & Magni) for a
model file: the gate bounds and the δISS index nu (th:stability-bonassi), rho_s and c_s
(lem:Vs), the observer gains L_z, L_r (one LP per row minimising nu_o, optionally scaled by
theta), nu_o, rho_o, c_o, kappa, L_max (lem:Vo), w_y_bar, w_bar (eq:w-bar), w_L, the
tightening a_i, b_i (eq:constraint_tightening_parameters), e_o and e_inf (eq:eo-evolution), the
terminal weight s (eq:definition_s) and, per set-point, alpha (eq:def-alpha), Assumption 1
(ass:setpoint) and the recursive-feasibility inequality (eq:condition-recursive-feasibility).
Values are in the model's normalised units; set-points are given in the control problem's
units, by output name (--setpoint CA=0.6,T=330) or in the problem's output order. By default
(--law tracking, the robust MPC's default law) at its horizon N = 80 and with the tracking
law's own hypotheses; --law paper: the paper's law at N = 15."""

EPILOG = """design levers:
  --gain-scale THETA     observer gains THETA x the LP gains (0 = open-loop observer)
  --auto-gain-scale      the largest THETA in [0, 1] for which every hypothesis holds at the
                         set-points (default: the grid at 25, 50 and 75 % of each output's
                         box, 3^p points; a star of 2p + 1 points beyond 81); exit 1 when
                         no THETA passes
  --N, --e-o0            horizon and initial observer-error bound (defaults 80 with the
                         tracking law, 15 with --law paper; 0.02)
  --data DATA.csv        estimate w_y_bar as the largest test-set output error (normalised)

The verdict comes last, in the problem's signals and units: which hypothesis holds and which
fails, by how much, what would fix it (the largest test error a model could have for the
set-points to pass), and the set-points that pass.

--save writes what was computed, certified or not: the observer gains, w_y_bar and the
verdict (the model file's 'certificate'), atomically: a failed write (full disk) leaves the
previous file byte-identical.

""" + exit_codes_help({"certify": EXIT_NOTES})


def register(subparsers: Any) -> None:
    """Add the ``certify`` sub-command."""
    p = subparsers.add_parser("certify", help="compute and check the paper's certificates",
                              description=HELP, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_argument(p)
    p.add_argument("--setpoint", action="append", metavar="NAME=VALUE,...", default=[],
                   help="set-point in the problem's units, every output once by name "
                        "(e.g. h1=1.0,h2=0.8), or the values in the problem's output order "
                        "(1.0,0.8); repeat for several")
    add_problem_argument(p)
    p.add_argument("--quiet", action="store_true",
                   help="print nothing but errors and the one-line verdict of an uncertified "
                        "model (the exit status says certified: 0, uncertified: 1)")
    p.add_argument("--json", action="store_true",
                   help="print JSON with the paper's names (a list when several set-points)")
    p.add_argument("--N", type=int, default=None,
                   help="prediction horizon N (default: the problem's [mpc] N, else 80, the "
                        "tracking law's; 15 with --law paper)")
    p.add_argument("--law", default=None, metavar="LAW",
                   help="the robust MPC's law to certify for (tracking, paper, or a law "
                        "module; default: the problem's [mpc] law, else tracking, as "
                        "robust-mpc's): tracking also computes and "
                        "checks the tracking law's hypotheses (its defaults: zero observer "
                        "gains, alpha_c = alpha_min(N) of the design above; docs: "
                        "design/tracking.md); paper: the certificate alone")
    p.add_argument("--e-o0", type=float, default=None, dest="e_o0",
                   help="initial observer-error bound ê_o,0 (default: the problem's [mpc] "
                        "e_o0, else 0.02)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--gain-scale", type=float, metavar="THETA",
                   help="observer gains = THETA × LP-optimal gains")
    g.add_argument("--auto-gain-scale", action="store_true",
                   help="choose the largest THETA in [0, 1] passing every hypothesis")
    p.add_argument("--data", metavar="DATA.csv",
                   help="estimate w̄_y from this data set's test split (cosim generate-data)")
    p.add_argument("--save", action="store_true",
                   help="write L_z, L_r, w̄_y and the verdict into the model file, certified "
                        "or not (atomic: a failed write leaves the file unchanged)")
    p.add_argument("--plot", metavar="PNG",
                   help="also draw a figure: α over the set-points with the admissible and "
                        "reachable ones (one or two outputs), ê_o,k, and the tightened "
                        "output bounds")
    p.set_defaults(func=run)


def _parse_setpoint(text: str, names: list[str]) -> list[float]:
    """One ``--setpoint``: ``NAME=VALUE,...`` with every output once (any order), or the
    values in the problem's output order; the values in the problem's units."""
    parts = [part.strip() for part in text.split(",")]
    form = ",".join(f"{n}=V" for n in names)
    named = ["=" in part for part in parts]
    if any(named) and not all(named):
        raise CosimError(f"--setpoint {text!r}: give every output by name ({form}) or none")
    if any(named):
        values: dict[str, float] = {}
        for part in parts:
            key, _, val = (x.strip() for x in part.partition("="))
            if key not in names:
                raise CosimError(f"--setpoint {text!r}: no output {key!r} in the problem "
                                 f"(outputs: {', '.join(names)})")
            if key in values:
                raise CosimError(f"--setpoint {text!r}: output {key!r} given twice")
            try:
                values[key] = float(val)
            except ValueError:
                raise CosimError(f"--setpoint {text!r}: {key}={val!r} is not a number") from None
        missing = [n for n in names if n not in values]
        if missing:
            raise CosimError(f"--setpoint {text!r}: no value for {', '.join(missing)} "
                             f"(expected {form})")
        out = [values[n] for n in names]
    else:
        try:
            out = [float(v) for v in parts]
        except ValueError:
            raise CosimError(f"--setpoint {text!r}: expected {len(names)} numbers "
                             f"({','.join(names)}) separated by commas, or {form}") from None
        if len(out) != len(names):
            raise CosimError(f"--setpoint {text!r}: expected {len(names)} numbers "
                             f"({','.join(names)}), or {form}")
    bad = [f"{n}={v:g}" for n, v in zip(names, out, strict=True) if not math.isfinite(v)]
    if bad:
        raise CosimError(f"--setpoint {text!r}: not finite: {', '.join(bad)}")
    return out


def _w_y_bar_from_csv(model: Any, path: str) -> float:
    """``w̄_y`` from a ``cosim generate-data`` record (``--data``): the full model's (inputs
    and disturbances, each its dead time late)."""
    from controllers.certification.prediction_error import w_y_bar_from_data
    from controllers.dead_time import delayed
    from controllers.errors import DataError
    from cosim.core.datagen import read_csv

    data = read_csv(path, input_names=list(model.input_names))
    u = data.u[:, [data.input_names.index(n) for n in model.input_names]]
    if model.problem is not None:
        u = delayed(u, model.problem.delays)
    try:
        return w_y_bar_from_data(model, u, data.outputs(list(model.output_names)), data.split)
    except DataError as exc:
        raise CosimError(f"{path}: {exc}") from None


def _certificate(args: argparse.Namespace, model: Any, setpoints: list,
                 kwargs: dict) -> tuple[Any, str, str | None]:
    """The certificate for the options in ``args``, a note on the observer gains, and the
    failure of ``--auto-gain-scale`` when no θ passes (else ``None``)."""
    import numpy as np

    from controllers.certification import certificates as certs
    from controllers.certification import gain_design

    if args.auto_gain_scale:
        targets = setpoints or [model.normalize_y(np.array(s))
                                for s in gain_design.default_setpoints(model.problem)]
        theta, cert = gain_design.choose_gain_scale(model, targets, **kwargs)
        note = ("LP gains × θ = 0 (no θ in [0, 1] passes)" if theta is None
                else f"LP gains × θ = {theta:.6g} (auto)")
        if theta is None:
            where = "the given set-points" if setpoints else (
                f"the {len(targets)} default set-points over the output box")
            return cert, note, f"gain scale: no θ in [0, 1] passes every hypothesis at {where}"
    else:
        cert = certs.compute_certificate(model, gain_scale=args.gain_scale, **kwargs)
        if cert.gain_scale is not None:
            note = f"LP gains × θ = {cert.gain_scale:.6g}"
        else:
            note = "gains from the model file"
    return cert, note, None


def run(args: argparse.Namespace) -> int:
    """Compute the certificate, print it, check it; returns the exit code."""
    import numpy as np

    from controllers.disturbances import condition
    from controllers.errors import ControllersError
    from controllers.model import GRUModel
    from cosim.adapters.problems import problem_for

    _check_args(args)
    full = GRUModel.load(args.model)
    full.problem = problem_for(full, getattr(args, "problem", None))
    # measured disturbances: the controller's design, on the model holding them at their
    # nominal values, its bounds the full model's over the whole box (controllers.disturbances)
    model = condition(full)
    names = list(model.output_names)
    setpoints_phys = [_parse_setpoint(s, names) for s in args.setpoint]
    setpoints = [model.normalize_y(np.array(s)) for s in setpoints_phys]

    w_y_bar = _w_y_bar_from_csv(full, args.data) if args.data else None
    if w_y_bar is None and model.w_y_bar is None:
        raise CosimError(f"{args.model}: no 'w_y_bar' in the model file; estimate it with "
                         "--data DATA.csv")
    kwargs = {**_design(args, model), "w_y_bar": w_y_bar}
    try:
        cert, note, no_theta = _certificate(args, model, setpoints, kwargs)
    except (CosimError, ControllersError) as exc:
        if str(exc).startswith((f"{args.model}:", f"{Path(args.model)}:")):
            raise CosimError(str(exc)) from None
        raise CosimError(f"{args.model}: {exc}") from None

    per_setpoint, failures = _setpoint_checks(model, cert, setpoints_phys, setpoints)
    law = _law_verdict(args, model, cert, kwargs, setpoints, setpoints_phys, failures,
                       no_theta)
    verdict = law.verdict
    if args.json:
        docs = [cert.to_json(sp) for _, sp, _, _ in per_setpoint] or [cert.to_json()]
        docs = [{**d, **law.report, "verdict": verdict.to_json()} for d in docs]
        print(json.dumps(docs[0] if len(docs) == 1 else docs, indent=1))
    elif not args.quiet:
        print_table(args.model, model, cert, note, per_setpoint)
        for line in law.lines:
            print(line)
        print_verdict(verdict)
    if args.plot:
        path = figure(args.plot, model, cert, setpoints_phys)
        print(f"figure written to {path}", file=sys.stderr)
    if args.save:
        _save(args.model, full, cert, verdict, setpoints_phys, args.quiet)
    return _exit_code(verdict)


def _law_verdict(args: argparse.Namespace, model: Any, cert: Any, kwargs: dict,
                 setpoints: list, setpoints_phys: list, failures: list[str],
                 no_theta: str | None) -> Any:
    """The law's judgement of the certificate (its ``certify`` hook: the verdict, what its
    JSON adds, its lines), with ``failures`` (and the failed ``--auto-gain-scale``); an
    uncertified design that the run would refuse is not usable (:func:`_refusal`)."""
    from controllers import laws
    from controllers.errors import ControllersError

    n_design = len(cert.failures())
    if no_theta:
        failures.append(no_theta)
    spec = laws.spec(args.law)
    try:
        law = spec.hook("certify", "certify")(model, cert, kwargs, setpoints, failures,
                                              n_design, no_theta)
    except ControllersError as exc:
        raise CosimError(f"{model.source}: {spec.title}: {exc}") from None
    verdict = law.verdict
    if verdict.usable and not verdict.certified:
        verdict.unusable = _refusal(args, setpoints_phys)   # the run's own judgement
        verdict.usable = not verdict.unusable
    return law


def _exit_code(verdict: Any) -> int:
    """0 certified, 1 usable but not certified, 2 not usable; the reason on standard
    error."""
    if not verdict.usable:
        print(f"cosim certify: not usable: {verdict.unusable}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    if not verdict.certified:
        print(f"cosim certify: not certified ({len(verdict.reasons())} hypothesis check(s) "
              "failed); the robust MPC runs this model uncertified, or refuses with "
              "--require-certificate", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _refusal(args: argparse.Namespace, setpoints_phys: list) -> str:
    """Why the robust MPC of the design certified refuses the model in its uncertified mode
    (``""`` when it runs it): the controller ``cosim run`` would build, for these set-points
    (:class:`controllers.certification.grade.NotUsable`), so that the verdict and the run never
    disagree."""
    import warnings

    from controllers.certification.grade import NotUsable
    from controllers.model import GRUModel
    from controllers.mpc import RobustMPC
    from controllers.mpc_options import MPCOptions
    from cosim.adapters.problems import problem_for

    options: dict[str, Any] = {"law": args.law, "N": args.N}
    for key in ("e_o0", "gain_scale"):
        if getattr(args, key, None) is not None:
            options[key] = getattr(args, key)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # a slow fallback is not a refusal
            gru = GRUModel.load(args.model)
            gru.problem = problem_for(gru, getattr(args, "problem", None))
            mpc = RobustMPC(gru, MPCOptions.resolve(options, gru.problem))
            names = list(gru.output_names)
            mpc.expect_setpoints([dict(zip(names, map(float, sp), strict=True))
                                  for sp in setpoints_phys])
    except NotUsable as exc:
        return exc.why
    return ""


def _check_args(args: argparse.Namespace) -> None:
    """Default ``--model`` and ``--N`` (the law's), and reject bad numbers in one line."""
    from controllers.model import DEFAULT_MODEL

    if args.model is None:
        args.model = str(DEFAULT_MODEL)
    if args.N is not None and args.N < 1:
        raise CosimError(f"--N must be >= 1, got {args.N}")
    if args.e_o0 is not None and not (math.isfinite(args.e_o0) and args.e_o0 >= 0):
        raise CosimError(f"--e-o0 must be a non-negative number, got {args.e_o0}")
    if args.gain_scale is not None and not (math.isfinite(args.gain_scale)
                                            and args.gain_scale >= 0):
        raise CosimError(f"--gain-scale must be a non-negative number, got {args.gain_scale}")
    if args.plot:
        from cosim.core.outpaths import figure_file

        figure_file(args.plot, "--plot")


def _design(args: argparse.Namespace, model: Any) -> dict[str, Any]:
    """The design certified: ``--law``, ``--N`` and ``--e-o0`` over the problem's ``[mpc]``
    table (its ``Q`` and ``R`` too: the weights the run will use), the law's defaults
    (:meth:`controllers.mpc_options.MPCOptions.resolve`); sets ``args.law`` and
    ``args.N``."""
    from controllers.mpc_options import MPCOptions, design_arguments

    given = {k: v for k, v in (("law", args.law), ("N", args.N), ("e_o0", args.e_o0))
             if v is not None}
    options = MPCOptions.resolve(given, model.problem)
    args.law, args.N = options.law, options.N
    return design_arguments(options, model)


def _setpoint_checks(model: Any, cert: Any, setpoints_phys: list, setpoints: list
                     ) -> tuple[list, list[str]]:
    """Each set-point's label, normalised value, equilibrium input and failed hypotheses,
    and every failure in words (the design's first, then each set-point's, then an empty
    admissible set)."""
    from controllers.certification.output_ranges import admissible_ranges
    from controllers.equilibrium import equilibrium
    from controllers.errors import UnreachableSetpoint

    names = list(model.output_names)
    failures = cert.failures()
    n_design = len(failures)
    per_setpoint = []
    for sp_phys, sp in zip(setpoints_phys, setpoints, strict=True):
        label = ", ".join(f"{n}={v:g}" for n, v in zip(names, sp_phys, strict=True))
        f = cert.failures(sp)[n_design:]
        u_bar = None
        try:
            _, u = equilibrium(model, sp)
            u_bar = model.denormalize_u(u)
        except UnreachableSetpoint as exc:
            f.append(f"equilibrium: {exc}")
        per_setpoint.append((label, sp, u_bar, f))
        failures += [f"set-point {label}: {msg}" for msg in f]
    empty = [name for name, lo, _ in admissible_ranges(cert, model) if lo is None]
    if empty:
        failures.append("admissible set-points (ass:setpoint and eq:condition-recursive-"
                        f"feasibility): none for {', '.join(empty)}")
    return per_setpoint, failures


def _save(path: str, model: Any, cert: Any, verdict: Any, setpoints_phys: list,
          quiet: bool = False) -> None:
    """``--save``: the observer gains, ``w̄_y`` and the verdict into the model file (atomic)."""
    from cosim.core.atomicio import output_error

    names = list(model.output_names)
    model.L_z, model.L_r, model.w_y_bar = cert.L_z, cert.L_r, cert.w_y_bar
    model.certificate = {**verdict.to_json(), "N": cert.N, "e_o0": cert.e_o0,
                         "gain_scale": cert.gain_scale,
                         "setpoints": [dict(zip(names, map(float, sp), strict=True))
                                       for sp in setpoints_phys]}
    try:
        model.save(path)
    except OSError as exc:
        raise output_error(path, exc) from None
    if not quiet:
        print(f"saved L_z, L_r, w_y_bar and the verdict (certified: "
              f"{str(verdict.certified).lower()}) to {path}", file=sys.stderr)
