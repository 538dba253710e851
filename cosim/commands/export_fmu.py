"""``cosim export-fmu``: the robust MPC as a controller FMU (FMI 2.0 or 3.0 Co-Simulation)."""

from __future__ import annotations

import argparse

from cosim.commands import add_design_arguments, add_model_argument
from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

HELP = "export the robust MPC as a controller FMU for other simulators"

DESCRIPTION = """\
Build a self-contained Co-Simulation FMU of the whole controller step of the robust MPC: the
GRU observer, the law's FHOCP on the compiled kernel with its answer check and fallback, the
tightening of the certificate (or of the uncertified mode) and the law's reference handling,
in C (gcc). Laws: the default tracking law (the disturbance estimate, an artificial steady
state), or the paper's (--option 'law="paper"'; offset_free and setpoint_rate as in cosim
run) with its reference governor (its default) or without it (--option governor=false: the
paper's controller). Its inputs are the measured outputs, named as the plant's outputs in
the problem, and their set-points ref.<output>; its outputs the inputs to apply, named as
the plant's inputs, the solver status, whether the fallback was applied, the SQP iterations,
the predicted outputs pred.<output> and the steady outputs the model is steered to
target.<output>: all in the problem's units, so that plant and controller connect by name;
its tunable parameters the law's: offset_filter and the weights R.<input>,
du_weight.<input>, offset_weight.<output> (tracking), setpoint_rate (the paper's, when
designed with one). Its sample time is the problem's Ts. The same model, problem and
--options as cosim run give the same inputs (docs: guide/controller-fmu.md); --controller
takes them from a run's controller.json. Run it with:
cosim run SCENARIO --controller Controller.fmu"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export-fmu`` sub-command."""
    p = subparsers.add_parser("export-fmu", help=HELP, description=DESCRIPTION,
                              epilog=exit_codes_help(),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_argument(p, metavar="MODEL.json")
    add_design_arguments(p, "robust-mpc option, as for cosim run (e.g. N=40), repeatable")
    p.add_argument("--controller", metavar="CONTROLLER.json", default=None,
                   help="a run's controller.json: the robust MPC it describes (its model and "
                        "options; --option over them)")
    p.add_argument("--scenario", metavar="SCENARIO.csv", default=None,
                   help="the set-points the FMU will meet, checked against the certified "
                        "design as cosim run checks them (one outside it exports the "
                        "uncertified mode)")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=3,
                   help="FMI version (default: 3)")
    p.add_argument("--out", metavar="FILE.fmu", default="Controller.fmu",
                   help="the FMU to write; its name is the model identifier "
                        "(default: Controller.fmu)")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the controller FMU; print what it is unless ``--quiet``."""
    import fmpy

    from cosim.api import export_fmu
    from cosim.core import registry

    path = export_fmu(args.model, args.out, fmi=args.fmi, problem=args.problem,
                      options=registry.parse_options(args.option), controller=args.controller,
                      scenario=args.scenario)
    if not args.quiet:
        md = fmpy.read_model_description(str(path))
        ins = [v.name for v in md.modelVariables if v.causality == "input"
               and not v.name.startswith("ref.")]
        outs = [v.name for v in md.modelVariables if v.causality == "output"]
        print(f"{path}: FMI {args.fmi}.0 Co-Simulation controller ({md.description}); in: "
              f"{', '.join(ins)} and their ref.*; out: {', '.join(outs)}; Ts = "
              f"{float(md.defaultExperiment.stepSize):g} s")
    return 0
