"""The move limit of the FHOCP (eq:move-constraint, controllers.ocp.input_rate.MoveRows): the
compiled kernel's rows and Jacobian against numpy's for both laws, a solve's plan within it
(its terminal row included), the candidate of lem:move-candidate within it, and no rows
without one."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from controllers.equilibrium import equilibrium
from controllers.kernel import compiled_kernel as ck
from controllers.laws.paper.reference import FixedSetpoint
from controllers.laws.tracking.reference import ArtificialSteadyState
from controllers.ocp.fhocp import FHOCP
from controllers.ocp.operator_terms import OperatorTerms
from tests.controllers.kernel.test_kernel_sqp import check_lagrangian_gradient

needs_cc = pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None,
                              reason="no C compiler")
DELTA = np.array([0.05, 0.08])


def _fhocp(cert, law: str, move: np.ndarray | None = DELTA) -> FHOCP:
    ref = (FixedSetpoint() if law == "paper"
           else ArtificialSteadyState(1e4, 0.05, control_horizon=6))
    return FHOCP.from_certificate(cert, reference=ref, max_move=move).setup()


@needs_cc
@pytest.mark.parametrize("law", ["paper", "tracking"])
def test_kernel_rows_match_numpy_and_a_plan_keeps_them(cert, law: str) -> None:
    fh = _fhocp(cert, law)
    M = fh.reference.control_horizon if law == "tracking" else fh.N
    assert fh.nmv == M * fh.m and fh.kernel is not None, fh.kernel_error
    src = ck.generate_source(ck.KernelProblem.of(fh))
    assert "#define HAS_MOVE 1" in src
    nlp = fh.numpy_nlp()
    assert nlp.self_test(fh.kernel, fh.sqp_options.get("hessian_eigen_clip")) \
        < ck.KERNEL_SELF_TEST_TOL   # g and ∂g/∂w, the move rows among them
    # the stopping test's ∇L with the move rows' multipliers in it (without them every solve
    # a move limit bound stalled short of its dual test)
    check_lagrangian_gradient(fh.kernel, np.random.default_rng(3), 3)
    x_hat, u0 = equilibrium(cert.params, np.array([0.0, 0.0]))
    last = np.clip(u0, -1, 1)
    fh.set_operator(OperatorTerms(np.maximum(last - DELTA, -1), np.minimum(last + DELTA, 1),
                                  -np.ones(2), np.ones(2), np.zeros(fh.q)))
    y = np.array([0.1, 0.1])
    if law == "paper":
        ref = cert.reference(y)
        res = fh.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
        end = ref.u_bar
    else:
        res = fh.solve(x_hat, 0.02, y, np.tile(last, (fh.N, 1)), last, x_hat, last)
        end = res.u_s
    assert res.success, res.status
    chain = np.vstack([last, res.u[:M], end])
    moves = np.abs(np.diff(chain, axis=0))
    assert np.all(moves <= DELTA + 1e-9), moves.max(axis=0)
    # lem:move-candidate: the plan shifted with u_end appended keeps every row
    cand = np.vstack([res.u[0], res.u[1:M], end, end])
    assert np.all(np.abs(np.diff(cand, axis=0)) <= DELTA + 1e-9)


def test_no_rows_without_a_move_limit(cert) -> None:
    fh = _fhocp(cert, "paper", None)
    assert fh.move is None and fh.nmv == 0
    assert fh.ng == (fh.N - 1) * fh.qr + 2 * fh.n
