"""A random δISS GRU model in the paper's convention, for tests that need a model (seeded)."""

from __future__ import annotations

import numpy as np

from controllers.model import GRUModel
from controllers.problem import Channel, ControlProblem
from tests.fourtank_problem import FOURTANK


def test_problem(m: int = 2, p: int = 2) -> ControlProblem:
    """The four-tank's problem for m = p = 2; more or fewer signals of the same kind else."""
    ins = [*FOURTANK.inputs, *(Channel(f"u{j + 1}", "m3/s", 0.0, 1e-3) for j in range(2, m))]
    outs = [*FOURTANK.outputs, *(Channel(f"y{j + 1}", "m", 0.0, 2.0) for j in range(2, p))]
    return ControlProblem(name=f"test{m}x{p}", Ts=FOURTANK.Ts, inputs=tuple(ins[:m]),
                          outputs=tuple(outs[:p]))


def other_problem() -> ControlProblem:
    """A 2×2 problem that is not the four-tank's: other names and units, boxes other than
    [0, 2], Ts = 15 s (a CSTR's feed flow and coolant temperature to its concentration and
    temperature)."""
    return ControlProblem(
        name="cstr", Ts=15.0,
        inputs=(Channel("F", "L/min", 2.0, 12.0, description="feed flow"),
                Channel("Tc", "K", 280.0, 320.0, description="coolant temperature")),
        outputs=(Channel("CA", "mol/L", 0.1, 0.9, description="concentration of A"),
                 Channel("T", "K", 300.0, 360.0, description="reactor temperature")))


def random_gru_model(seed: int = 0, n: int = 20, m: int = 2, p: int = 2,
                     problem: ControlProblem | None = None) -> GRUModel:
    """A small-weight GRU with ``b_z ≈ 2`` (slow, δISS: ν < 1) for ``problem`` (default: the
    four-tank's for m = p = 2, else :func:`test_problem`; a given problem sets m and p).

    Inputs and outputs are normalised by the problem's boxes (``‖u‖∞ ≤ 1``; for the
    four-tank ``y = (h − 1) / 1``, the output box [0, 2] m maps to ``[−1, 1]``).
    """
    if problem is not None:   # the model's inputs: the problem's inputs and disturbances
        m, p = len(problem.model_inputs), problem.p
    rng = np.random.default_rng(seed)

    def mat(rows: int, cols: int, row_sum: float) -> np.ndarray:
        a = rng.uniform(-1.0, 1.0, (rows, cols))
        return a * (row_sum / np.abs(a).sum(axis=1, keepdims=True))

    params = {
        "W_z": mat(n, m, 0.1), "U_z": mat(n, n, 0.05), "b_z": rng.uniform(1.9, 2.1, n),
        "W_r": mat(n, m, 0.3), "U_r": mat(n, n, 0.3), "b_r": rng.uniform(-0.2, 0.2, n),
        "W_h": mat(n, m, 1.2), "U_h": mat(n, n, 0.6), "b_h": rng.uniform(-0.1, 0.1, n),
        "U_o": mat(p, n, 1.5), "b_o": np.zeros(p),
    }
    if problem is None:
        problem = FOURTANK if (m, p) == (2, 2) else test_problem(m, p)
    norm = problem.normalization()
    return GRUModel(params=params, u_offset=norm["u_offset"], u_scale=norm["u_scale"],
                    y_offset=norm["y_offset"], y_scale=norm["y_scale"],
                    input_names=list(problem.model_input_names),
                    input_units=[c.unit for c in problem.model_inputs],
                    output_names=list(problem.output_names),
                    output_units=list(problem.output_units), Ts=problem.Ts,
                    training={"source": f"random_gru_model(seed={seed})"}, problem=problem)


#: Horizon and output box |y| ≤ 0.25 (normalised) of the certified test problem: tight enough
#: for the random model to hit the output constraints.
N = 15
L_BOX = np.vstack([np.eye(2), -np.eye(2)])
H_BOX = np.full(4, 0.25)


def certified_random_problem(setpoints: list[np.ndarray], seed: int = 0):
    """``(model, certificate)`` for :func:`random_gru_model` on the box ``L_BOX y ≤ H_BOX``.

    A small w̄_y (0.002) and the largest observer-gain scale for which every hypothesis of
    ``th:feasibility-stability`` holds at ``setpoints`` (normalised).
    """
    from controllers.certification import gain_design

    model = random_gru_model(seed)
    theta, cert = gain_design.choose_gain_scale(model, setpoints, N=N, w_y_bar=0.002, L=L_BOX,
                                          h=H_BOX)
    assert theta is not None, "test design: the hypotheses must hold"
    return model, cert
