"""The GRU observer of ``eq:observer`` (Bonassi et al.), with its error bound ``ê_o``.

    ẑ_k   = σ(W_z u_k + U_z x̂_k + b_z + L_z (y_k − ŷ_k))
    r̂_k   = σ(W_r u_k + U_r x̂_k + b_r + L_r (y_k − ŷ_k))
    ĥ_k   = tanh(W_h u_k + U_h (r̂_k ∘ x̂_k) + b_h)
    x̂_k+1 = ẑ_k ∘ x̂_k + (1 − ẑ_k) ∘ ĥ_k,          ŷ_k = U_o x̂_k + b_o

computed by :func:`controllers.gru.step` with ``dz = L_z (y − ŷ)``, ``dr = L_r (y − ŷ)`` (the
one source of the equations), in normalised units. Alongside, the bound
``ê_o,k+1 = ρ_o ê_o,k + w̄`` (``eq:eo-evolution``) of ``‖x_k − x̂_k‖∞`` used by the
constraint tightening.

Timing: at sample ``k`` the controller uses ``x̂_k`` and ``ê_o,k`` to compute ``u_k``; then
``make_step(u_k, y_k)`` returns ``x̂_{k+1}`` (and advances ``ê_o``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from controllers.equilibrium import equilibrium_for_output
from controllers.gru import output, step

__all__ = ["GRUObserver"]


class GRUObserver:
    """State observer ``eq:observer`` for a GRU model (normalised units).

    Parameters
    ----------
    params : mapping of arrays
        GRU weights (``eq:gru``).
    L_z, L_r : (n, p) arrays
        Observer gains.
    rho_o, w_bar : float
        ``ρ_o`` and ``w̄`` of ``lem:Vo``/``eq:w-bar`` for the ``ê_o`` recursion
        (``eq:eo-evolution``); 0 disables the bound's growth.
    e_o0 : float
        ``ê_o,0`` (paper: 0.02).
    x0 : (n,) array, optional
        Initial estimate; default: set by :meth:`init_from_output` at the first step.

    Attributes
    ----------
    x_hat : (n,) array
        Current estimate ``x̂_k``.
    e_o : float
        Current bound ``ê_o,k``.
    k : int
        Number of updates done.
    kernel : kernel_lib.Workspace or None
        When set (by the controller: its FHOCP's kernel workspace, built for the same
        model), the state update runs as one compiled call (:meth:`~controllers.kernel.kernel_lib.
        Workspace.gru_step`); else numpy (:func:`controllers.gru.step`).
    """

    def __init__(self, params: Mapping[str, np.ndarray], L_z: np.ndarray, L_r: np.ndarray,
                 *, rho_o: float = 0.0, w_bar: float = 0.0, e_o0: float = 0.02,
                 x0: np.ndarray | None = None) -> None:
        self.params = {k: np.asarray(v, dtype=float) for k, v in params.items()}
        self.L_z = np.asarray(L_z, dtype=float)
        self.L_r = np.asarray(L_r, dtype=float)
        self.rho_o = float(rho_o)
        self.w_bar = float(w_bar)
        self.e_o0 = float(e_o0)
        self.x_hat: np.ndarray | None = None if x0 is None else np.array(x0, dtype=float)
        self.e_o = self.e_o0
        self.k = 0
        self.kernel: Any = None

    @classmethod
    def from_certificate(cls, cert: Any, x0: np.ndarray | None = None) -> GRUObserver:
        """An observer with the gains, ``ρ_o``, ``w̄`` and ``ê_o,0`` of a
        :class:`~controllers.certification.certificates.Certificate`."""
        return cls(cert.params, cert.L_z, cert.L_r, rho_o=cert.rho_o, w_bar=cert.w_bar,
                   e_o0=cert.e_o0, x0=x0)

    def reset(self, x0: np.ndarray | None = None, e_o0: float | None = None) -> None:
        """Restart: estimate ``x0`` (or unset), ``ê_o`` back to ``ê_o,0``."""
        self.x_hat = None if x0 is None else np.array(x0, dtype=float)
        if e_o0 is not None:
            self.e_o0 = float(e_o0)
        self.e_o = self.e_o0
        self.k = 0

    def init_from_output(self, y0: np.ndarray) -> np.ndarray:
        """Set ``x̂_0`` to the model equilibrium whose output is (closest to) ``y0``
        (normalised), as in the paper's section V (with :attr:`kernel`, its compiled search
        when it has one: :func:`~controllers.equilibrium.equilibrium_for_output`); returns
        ``x̂_0``."""
        self.x_hat, _ = equilibrium_for_output(self.params, y0, self.kernel)
        return self.x_hat

    def y_hat(self) -> np.ndarray:
        """Output estimate ``ŷ_k = U_o x̂_k + b_o`` (with :attr:`kernel`, its compiled sum:
        the exported controller's, to the last bit)."""
        assert self.x_hat is not None
        if self.kernel is not None:
            return self.kernel.output(self.x_hat)
        return output(self.params, self.x_hat)

    def correction(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gate corrections ``(L_z (y − ŷ), L_r (y − ŷ))`` of ``eq:observer``."""
        d = np.asarray(y, dtype=float) - self.y_hat()
        return self.L_z @ d, self.L_r @ d

    def make_step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """One observer update: ``x̂_{k+1}`` from ``x̂_k``, ``u_k``, ``y_k`` (``eq:observer``).

        Initialises ``x̂_0`` from ``y_k`` on the first call when no ``x0`` was given. Also
        advances ``ê_o`` by ``eq:eo-evolution``. Returns a copy of ``x̂_{k+1}``.
        """
        y = np.asarray(y, dtype=float)
        if self.x_hat is None:
            self.init_from_output(y)
        dz, dr = self.correction(y)
        if self.kernel is not None:
            self.x_hat = self.kernel.gru_step(self.x_hat, u, dz, dr)
        else:
            self.x_hat = step(self.params, self.x_hat, np.asarray(u, dtype=float), dz=dz,
                              dr=dr)
        self.e_o = self.rho_o * self.e_o + self.w_bar
        self.k += 1
        return self.x_hat.copy()

    update = make_step
