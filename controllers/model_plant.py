"""The GRU model itself as a plant component: ``eq:perturbed-model`` with bounded ``w_y``.

    x_{k+1} = f(x_k, u_k),   y_k = g(x_k) + w_{y,k},   ‖w_{y,k}‖∞ ≤ w̄_y   (normalised)

Used where the theory's assumptions must hold exactly (the recursive-feasibility test of
``th:feasibility-stability``) and by the benchmark when no FMU is built. Physical units on the
outside (``qa, qb`` in, ``h1, h2`` out) through the model file's normalisation; the output
perturbation is uniform in ``[−w_y_max, w_y_max]`` per output, seeded.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from controllers import gru
from controllers.model import GRUModel
from cosim.component import Component, Signal


class GRUPlant(Component):
    """A discrete-time plant that *is* the GRU model, plus bounded output noise.

    Parameters
    ----------
    model : GRUModel
    y0 : (p,) array, optional
        Initial output (physical); the state starts at the model equilibrium for it.
    w_y_max : float
        Bound of the normalised output perturbation (0: the nominal model).
    seed : int
        Seed of the perturbation.
    """

    direct_feedthrough = False

    def __init__(self, model: GRUModel, y0: np.ndarray | None = None, w_y_max: float = 0.0,
                 seed: int = 0, name: str = "plant") -> None:
        self.model = model
        self.name = name
        self.inputs = tuple(Signal(n, u) for n, u in zip(model.input_names, model.input_units,
                                                          strict=True))
        self.outputs = tuple(Signal(n, u) for n, u in zip(model.output_names,
                                                           model.output_units, strict=True))
        self.sample_time = model.Ts
        self.w_y_max = float(w_y_max)
        self.seed = int(seed)
        self.y0 = None if y0 is None else np.asarray(y0, dtype=float)
        self.setup(0.0)

    def setup(self, t0: float) -> None:
        from controllers.equilibrium import equilibrium_for_output

        self.rng = np.random.default_rng(self.seed)
        y0 = self.model.y_offset if self.y0 is None else self.y0
        self.x, u0 = equilibrium_for_output(self.model, self.model.normalize_y(y0))
        self.u = u0
        self._draw()

    def _draw(self) -> None:
        p = self.model.p
        self.w_y = self.rng.uniform(-self.w_y_max, self.w_y_max, p) if self.w_y_max else (
            np.zeros(p))

    def set_inputs(self, values: Mapping[str, float]) -> None:
        u_phys = self.model.denormalize_u(self.u)
        for i, name in enumerate(self.model.input_names):
            if name in values:
                u_phys[i] = float(values[name])
        self.u = self.model.normalize_u(u_phys)

    def step(self, t: float, dt: float) -> None:
        self.x = gru.step(self.model.params, self.x, self.u)
        self._draw()

    def y_norm(self) -> np.ndarray:
        """Current normalised output ``g(x_k) + w_y,k``."""
        return gru.output(self.model.params, self.x) + self.w_y

    def get_outputs(self) -> dict[str, float]:
        y = self.model.denormalize_y(self.y_norm())
        return {n: float(v) for n, v in zip(self.model.output_names, y, strict=True)}
