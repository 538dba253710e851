"""The GRU model itself as a plant component: ``eq:perturbed-model`` with bounded ``w_y``.

    x_{k+1} = f(x_k, u_k),   y_k = g(x_k) + w_{y,k},   ‖w_{y,k}‖∞ ≤ w̄_y   (normalised)

Used where the theory's assumptions must hold exactly (the paper's theorem checked at scale by
``scenarios/campaigns/theorem.toml``, the recursive-feasibility tests) and by the benchmark
when no FMU is built. ``cosim run --plant model:FILE`` and campaigns (``plant =
"model:FILE"``) run it like an FMU. Physical units on the outside (``qa, qb`` in, ``h1, h2``
out) through the model file's normalisation; the output perturbation is uniform in
``[−w_y_max, w_y_max]`` per output (normalised), drawn each step from a seeded generator.
A model with measured disturbances takes them as inputs (``dist.<name>`` columns set them);
its problem's dead times delay each input as the model was trained
(:mod:`controllers.dead_time`).

Parameters a scenario may set in its first row (``plant.<name>``), before the plant starts:

* ``<output>_start`` (``h1_start``, ``h2_start``): the state starts at the model equilibrium
  whose output is this (physical units; default: the model's output offset, 1 m);
* ``w_y_max``: the normalised noise bound (default 0, or the constructor's);
* ``dx_<i>`` (``dx_1`` … ``dx_n``): an offset added to that equilibrium state, so that an
  observer started at the equilibrium has an initial error ``‖dx‖∞``;
* ``seed``: the noise seed;
* ``gain_<input>`` (``gain_qa``): the plant's gain on that input, a factor on its move from
  where the run starts (``v ← v₀ + g (v − v₀)``, normalised; default 1): the model with a
  multiplicative input uncertainty, what ``cosim tune`` checks a weighting's robustness on
  (:mod:`cosim.tuning`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from controllers import gru
from controllers.model import GRUModel
from cosim.core.component import Capability, Component, Signal
from cosim.core.errors import CosimError

__all__ = ["MODEL_PREFIX", "GRUPlant"]

#: Prefix of a plant argument that names a GRU model file instead of an FMU.
MODEL_PREFIX = "model:"


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
    dx0 : (n,) array, optional
        Offset of the initial state from that equilibrium (normalised).
    name : str
        Component name.
    """

    direct_feedthrough = False
    capabilities = frozenset({Capability.TUNABLE})

    def __init__(self, model: GRUModel, y0: np.ndarray | None = None, w_y_max: float = 0.0,
                 seed: int = 0, dx0: Sequence[float] | None = None,
                 name: str = "plant") -> None:
        self.model = model
        self.name = name
        self.path = getattr(model, "source", None) or "<GRU model>"
        self.fmi_version = "none (GRU model)"
        self.inputs = tuple(Signal(n, u) for n, u in zip(model.input_names, model.input_units,
                                                          strict=True))
        self.outputs = tuple(Signal(n, u) for n, u in zip(model.output_names,
                                                           model.output_units, strict=True))
        self.sample_time = model.Ts
        self.w_y_max = float(w_y_max)
        self.seed = int(seed)
        self.y0 = (np.asarray(model.y_offset, dtype=float).copy() if y0 is None
                   else np.asarray(y0, dtype=float).copy())
        self.dx0 = np.zeros(model.n) if dx0 is None else np.asarray(dx0, dtype=float).copy()
        self._start_names = [f"{n}_start" for n in model.output_names]
        self._dx_names = [f"dx_{i + 1}" for i in range(model.n)]
        self._gain_names = [f"gain_{n}" for n in model.input_names]
        self.gains = np.ones(len(self._gain_names))
        self.setup(0.0)

    @classmethod
    def from_file(cls, path: str, **kwargs: object) -> GRUPlant:
        """A plant from a model file (``path`` may carry the ``model:`` prefix)."""
        if path.startswith(MODEL_PREFIX):
            path = path[len(MODEL_PREFIX):]
        return cls(GRUModel.load(path), **kwargs)  # type: ignore[arg-type]

    @property
    def where(self) -> str:
        """Messages name the plant by its model file."""
        return str(self.path)

    # -- parameters ---------------------------------------------------------------------
    def settable(self, at_start: bool = False) -> set[str]:
        """Plant inputs, and at the start the parameters of the module docstring."""
        names = {s.name for s in self.inputs}
        if at_start:
            names |= {*self._start_names, *self._dx_names, *self._gain_names, "w_y_max",
                      "seed"}
        return names

    def set_parameter(self, name: str, value: float) -> None:
        """Set an input, or (before :meth:`setup`) a start parameter."""
        if name in (s.name for s in self.inputs):
            self.set_inputs({name: value})
            return
        if not math.isfinite(value):
            raise CosimError(f"{self.path}: plant parameter '{name}' = {value!r} is not finite")
        if name in self._start_names:
            self.y0[self._start_names.index(name)] = float(value)
        elif name in self._dx_names:
            self.dx0[self._dx_names.index(name)] = float(value)
        elif name in self._gain_names:
            self.gains[self._gain_names.index(name)] = float(value)
        elif name == "w_y_max":
            if value < 0:
                raise CosimError(f"{self.path}: plant parameter 'w_y_max' = {value!r} is "
                                 "negative")
            self.w_y_max = float(value)
        elif name == "seed":
            if value < 0 or value != int(value):
                raise CosimError(f"{self.path}: plant parameter 'seed' = {value!r} is not a "
                                 "non-negative integer")
            self.seed = int(value)
        else:
            raise CosimError(f"{self.path}: no plant parameter '{name}'")
        self._dirty = True

    # -- Component interface ------------------------------------------------------------
    def setup(self, t0: float) -> None:
        """Start at the equilibrium for ``y0`` plus ``dx0``; restart the noise generator."""
        from controllers.dead_time import DelayLine
        from controllers.disturbances import condition, nominal
        from controllers.equilibrium import equilibrium_for_output

        self.rng = np.random.default_rng(self.seed)
        model = self.model   # at rest with the disturbances at their nominal values
        x_eq, u0 = equilibrium_for_output(condition(model), model.normalize_y(self.y0))
        u0 = np.concatenate([u0, nominal(model)])
        self.x_start = x_eq + self.dx0
        self.x = self.x_start.copy()
        self.u = u0
        self._v0 = u0.copy()   # the inputs the gains act around
        problem = model.problem
        self._line = DelayLine(problem.delays) if problem is not None and any(
            problem.delays) else None
        if self._line is not None:
            self._line.push(u0)   # the inputs before the run
        self._dirty = False
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
        v = self.u
        if self._line is not None:   # each input as the model sees it, its dead time late
            self._line.push(self.u)
            v = self._line.current()
        if np.any(self.gains != 1.0):
            v = self._v0 + self.gains * (v - self._v0)
        self.x = gru.step(self.model.params, self.x, v)
        self._draw()

    def y_norm(self) -> np.ndarray:
        """Current normalised output ``g(x_k) + w_y,k``."""
        return gru.output(self.model.params, self.x) + self.w_y

    def get_outputs(self) -> dict[str, float]:
        y = self.model.denormalize_y(self.y_norm())
        return {n: float(v) for n, v in zip(self.model.output_names, y, strict=True)}
