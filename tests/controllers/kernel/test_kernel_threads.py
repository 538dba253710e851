"""FHOCPs of one problem solving concurrently from two threads: the compiled kernel keeps its
state in one workspace per FHOCP (controllers/kernel/memory.c), so the answers are
bit-identical to solving one after the other (a campaign worker with two threads runs two
controllers at once)."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from controllers.equilibrium import equilibrium
from controllers.laws.paper.reference import FixedSetpoint
from controllers.ocp.fhocp import FHOCP
from tests.controllers.kernel.test_compiled_kernel import needs_cc

#: Two closed loops through different set-points (normalised outputs), so that two threads
#: sharing any state would disturb each other.
LOOPS = ([[0.1, 0.1], [0.0, 0.05], [-0.1, -0.1]], [[-0.1, -0.1], [0.1, 0.1], [0.0, 0.05]])
REPEATS = 12


def closed_loop(fh: FHOCP, cert, setpoints: list, start: threading.Barrier | None = None
                ) -> list[tuple]:
    """Every solve's outcome along ``fh``'s closed loop (the nominal model) through
    ``setpoints``: status, iterations, inputs, states, cost and multipliers."""
    x_hat, _ = equilibrium(cert.params, np.array([0.0, 0.0]))
    out = []
    if start is not None:
        start.wait(timeout=60)
    for y in setpoints:
        ref = cert.reference(np.array(y))
        for _ in range(REPEATS):
            r = fh.solve(x_hat, 0.02, ref.x_bar, ref.u_bar, ref.alpha)
            out.append((r.status, r.iterations, r.u, r.x, r.cost, r.lam_x, r.lam_g, r.defect))
            x_hat = fh.rollout(x_hat, r.u)[1]
    return out


def same(a: list[tuple], b: list[tuple]) -> bool:
    return len(a) == len(b) and all(
        all(np.array_equal(np.asarray(p), np.asarray(q)) for p, q in zip(ra, rb, strict=True))
        for ra, rb in zip(a, b, strict=True))


@needs_cc
@pytest.mark.parametrize("loop", ["kernel", "casadi"])
def test_two_fhocps_in_two_threads_solve_as_one_after_the_other(cert, loop: str) -> None:
    def fresh() -> FHOCP:
        fh = FHOCP.from_certificate(cert, reference=FixedSetpoint(),
                                    sqp_options={"loop": loop}).setup()
        assert fh.kernel is not None, fh.kernel_error
        return fh

    sequential = [closed_loop(fresh(), cert, sp) for sp in LOOPS]
    assert any(r[0] != "optimal" or r[1] > 1 for r in sequential[0])   # real solves
    for _ in range(3):
        a, b = fresh(), fresh()
        assert a.kernel is not b.kernel and a.kernel.kernel is b.kernel.kernel   # one library
        start = threading.Barrier(2)
        with ThreadPoolExecutor(max_workers=2) as pool:
            futures = [pool.submit(closed_loop, fh, cert, LOOPS[i], start)
                       for i, fh in enumerate((a, b))]
            results = [f.result(timeout=120) for f in futures]
        assert same(results[0], sequential[0]) and same(results[1], sequential[1])
