"""``cosim build-kernel``: compile the robust MPC's FHOCP kernel for a model (cached)."""

from __future__ import annotations

import argparse

from cosim.commands import add_design_arguments, add_model_argument
from cosim.core.errors import exit_codes_help

__all__ = ["DESCRIPTION", "HELP", "register", "run"]

HELP = "compile the robust MPC's derivative kernel for a model (built on first use anyway)"

DESCRIPTION = """\
Generate and compile (gcc) the C kernel of the robust MPC's FHOCP for a GRU model file and
the controller's design (horizon, weights, constraints; any numbers of inputs and outputs):
the SQP's derivatives, the Hessian's eigenvalue clipping and (as many inputs as outputs) the
equilibrium Newton iteration, checked against the numpy implementation when loaded. The
library is cached by a hash of the model, the design, the generator and the compiler, in
~/.cache/gru-mpc/kernels (GRU_MPC_KERNEL_CACHE): a controller that needs it builds it on
first use (2-4 s); this command builds it ahead (make does, for the shipped model). Without
a C compiler the controller uses the numpy derivatives (same answers, slower) and this
command exits 1 naming the reason. GRU_MPC_KERNEL=0 turns the kernel off."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``build-kernel`` sub-command."""
    p = subparsers.add_parser("build-kernel", help=HELP, description=DESCRIPTION,
                              epilog=exit_codes_help(),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_argument(p, "--model", "FILE")
    add_design_arguments(p, "robust-mpc option that changes the problem (e.g. N=20), repeatable")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build (or find in the cache) the kernel; print its path unless ``--quiet``."""
    import warnings

    from cosim.core import registry
    from cosim.core.errors import SimulationFailed

    options = registry.parse_options(args.option)
    options.pop("kernel", None)
    if args.model is not None:
        options["model"] = args.model
    if args.problem is not None:
        options["problem"] = args.problem
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # reported below, as an error
        ctrl = registry.create("robust-mpc", options)
    fhocp = ctrl.mpc.fhocp
    if fhocp.kernel is None:
        raise SimulationFailed(f"no compiled kernel: {fhocp.kernel_error}")
    if not args.quiet:
        print(f"{fhocp.kernel.path}: compiled kernel for {ctrl.model_path}, problem "
              f"{ctrl.problem.name!r} (n={fhocp.n}, m={fhocp.m}, p={fhocp.p}, N={fhocp.N})")
    return 0
