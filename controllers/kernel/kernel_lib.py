"""A loaded compiled kernel (:class:`Kernel`) and its per-instance workspaces (:class:`Workspace`).

A kernel library (:func:`controllers.kernel.compiled_kernel.build`; its interface:
``controllers/kernel/gru_fhocp.h``) holds only code and constants; everything a call writes
lives in a C solver instance (``gk_ws``: the memory kept between calls and the per-call
workspace, ``controllers/kernel/memory.c``) that the caller passes first. One
:class:`Kernel` per library and process, shared by every FHOCP of the same problem; one
:class:`Workspace` per FHOCP instance, holding its C workspace and the argument buffers of
its calls (numpy arrays whose addresses are taken once). Two FHOCPs with their own
workspaces may therefore solve concurrently from two threads (ctypes releases the GIL during
each call) and get the same answers as one after the other; one
workspace must not be used by two threads at once (an FHOCP is not, either).

The casadi ``external`` functions of a library (:meth:`Kernel.external`, the ``"casadi"``
SQP loop) evaluate in the work vector casadi gives each call.
"""

from __future__ import annotations

import ctypes
import weakref
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from controllers.equilibrium import EQ_TOL, NEWTON_MAX_ITER
from controllers.kernel.kernel_abi import (
    ABI_COUNT,
    Assessment,
    Counters,
    Dims,
    QpStatus,
    SqpInfo,
    SqpOptions,
    SqpStatus,
    check_layout,
)

__all__ = ["Kernel", "Workspace"]

_VP, _CD, _CI = ctypes.c_void_p, ctypes.c_double, ctypes.c_int
#: ctypes signatures of the entry points taking a workspace first: (arguments after it, result)
_WS_CALLS: dict[str, tuple[list[Any], Any]] = {
    "simulate": ([_VP] * 3, None), "xtraj": ([_VP] * 3, None),
    "assess": ([_VP] * 6 + [_CD, _VP, _VP], None),
    "assess_w": ([_VP, _VP, _VP, _CD, _VP, _VP, _VP, _VP], None),
    "terminal_gap": ([_VP] * 2, _CD),
    "plan_slacks": ([_VP, _VP, _VP, _CD], _CD),
    "set_soft": ([ctypes.c_int], None),
    "sqp": ([_VP] * 12, _CI), "qp": ([_VP] * 11, _CI), "grad_l": ([_VP] * 5, None),
    "counters": ([_VP], None), "invalidate": ([], None), "clip": ([_VP], _CI),
    "set_weights": ([_VP] * 3, None)}


def load_data(lib: ctypes.CDLL, prefix: str, data: bytes, path: Path) -> None:
    """Give the library ``lib`` its numbers, the data file ``data``
    (:mod:`controllers.kernel.constants`); ``ValueError`` naming ``path`` and the reason when
    the library refuses them (another layout, or another problem's numbers already loaded)."""
    f = getattr(lib, prefix + "load_data")
    f.restype = ctypes.c_char_p
    f.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_size_t]
    msg = ctypes.create_string_buffer(512)
    why = f(data, len(data), msg, len(msg))
    if why is not None:
        raise ValueError(f"{path}: its numbers are refused: {why.decode()}")


class Kernel:
    """A loaded kernel library: its dimensions, its entry points and casadi external
    functions; :meth:`workspace` gives each user its own C state."""

    def __init__(self, path: Path, prefix: str, data: bytes) -> None:
        self.path = Path(path)
        self.prefix = prefix
        self.lib = ctypes.CDLL(str(self.path))
        abi = (ctypes.c_long * ABI_COUNT)()
        self._fn("abi")(abi)
        check_layout(tuple(abi))
        load_data(self.lib, prefix, data, self.path)
        self.workspace_bytes = int(abi[ABI_COUNT - 1])
        dims = Dims()
        self._fn("dims")(ctypes.byref(dims))
        self.n, self.m, self.N = dims.n_states, dims.n_inputs, dims.horizon
        self.q, self.nw, self.ng = dims.n_reduced_rows, dims.n_decision, dims.n_constraints
        self.npar, self.M, self.nl = dims.n_parameters, dims.control_horizon, dims.n_assess_rows
        self.p = dims.n_outputs
        self.flags: tuple[str, ...] = ()
        self._externals: dict[str, Any] = {}
        self.c: dict[str, Any] = {}
        for name, (args, rest) in _WS_CALLS.items():
            f = self._fn(name)
            f.argtypes, f.restype = [_VP, *args], rest
            self.c[name] = f
        f = self._fn("gru_step")
        f.argtypes, f.restype = [_VP] * 5, None
        self.c["gru_step"] = f
        f = self._fn("output")
        f.argtypes, f.restype = [_VP] * 2, None
        self.c["output"] = f
        if hasattr(self.lib, prefix + "steady"):
            f = self._fn("steady")
            f.argtypes, f.restype = [_VP] * 4, _CI
            self.c["steady"] = f
        if hasattr(self.lib, prefix + "equilibrium"):
            f = self._fn("equilibrium")
            f.argtypes, f.restype = [_VP] * 4, _CI
            self.c["equilibrium"] = f
        if hasattr(self.lib, prefix + "eq_newton"):
            f = self._fn("eq_newton")
            f.argtypes, f.restype = [_VP, _VP, _VP, _CI, _CD, _VP, _VP], _CI
            self.c["eq_newton"] = f
        f = self._fn("set_bias_shift")
        f.argtypes, f.restype = [_VP], None
        self.c["set_bias_shift"] = f
        self.c["ws_new"] = self._fn("ws_new")
        self.c["ws_new"].argtypes, self.c["ws_new"].restype = [], _VP
        self.c["ws_free"] = self._fn("ws_free")
        self.c["ws_free"].argtypes, self.c["ws_free"].restype = [_VP], None

    def _fn(self, name: str) -> Any:
        return getattr(self.lib, self.prefix + name)

    def external(self, name: str) -> Any:
        """casadi Function ``name`` in {"fg", "jac_fg", "hess_l", "hess_raw"} (loaded once;
        each call evaluates in casadi's work vector)."""
        if name not in self._externals:
            import casadi as ca

            self._externals[name] = ca.external(self.prefix + name, str(self.path))
        return self._externals[name]

    def set_bias_shift(self, db: np.ndarray) -> None:
        """The calling thread's shift of the biases ``(Δb_z, Δb_r, Δb_h)`` (``3n``): the
        measured disturbances held (:mod:`controllers.disturbances`); every later call on
        this thread sees it, in every workspace (whose cached rollouts are not forgotten:
        :meth:`Workspace.invalidate` them)."""
        # the caller's own array (two threads may set theirs at once): C copies it
        shift = np.ascontiguousarray(db, dtype=float).reshape(3 * self.n)
        self.c["set_bias_shift"](shift.ctypes.data)

    def workspace(self) -> Workspace:
        """A new workspace: the C state and argument buffers of one user (one FHOCP)."""
        return Workspace(self)


class Workspace:
    """One user's C workspace of a :class:`Kernel` and the argument buffers of its calls.

    Every method writes only this workspace (and the arrays it returns), so workspaces of
    one kernel may be used from several threads at once, one thread per workspace. The C
    memory is freed when the object is collected.

    Attributes
    ----------
    kernel : Kernel
        The library.
    n, m, N, q, nw, ng, npar, nl : int
        Its dimensions (states, inputs, horizon, constraint rows, decision variables,
        constraints, parameters, answer-check rows).
    """

    def __init__(self, kernel: Kernel) -> None:
        self.kernel = kernel
        ptr = kernel.c["ws_new"]()
        if not ptr:
            raise MemoryError(f"cannot allocate a kernel workspace ({kernel.workspace_bytes} "
                              "bytes)")
        self._ws = ptr
        self._finalizer = weakref.finalize(self, kernel.c["ws_free"], ptr)
        n, m, N = kernel.n, kernel.m, kernel.N
        self._buf = {name: np.zeros(shape) for name, shape in (
            ("x0", n), ("u", (N, m)), ("w", kernel.nw), ("p", kernel.npar), ("xb", n),
            ("ub", m), ("up", m), ("dz", n), ("dr", n), ("bnd", (N + 1, max(kernel.nl, 1))),
            ("xs", n),
            ("x", (N + 1, n)), ("uc", (N, m)), ("xn", n), ("y", kernel.p), ("xe", n),
            ("ue", m), ("yp", kernel.p))}
        self._addr = {name: int(a.ctypes.data) for name, a in self._buf.items()}
        self._out = Assessment()
        self._addr["out"] = ctypes.addressof(self._out)
        self._c = {name: kernel.c[name] for name in _WS_CALLS}
        self.path = kernel.path
        self.n, self.m, self.N, self.q = kernel.n, kernel.m, kernel.N, kernel.q
        self.nw, self.ng, self.npar, self.nl = kernel.nw, kernel.ng, kernel.npar, kernel.nl

    @property
    def flags(self) -> tuple[str, ...]:
        """The compiler flags of the library (its build-time variant)."""
        return self.kernel.flags

    def external(self, name: str) -> Any:
        """The library's casadi external function ``name`` (:meth:`Kernel.external`)."""
        return self.kernel.external(name)

    def simulate(self, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
        """States ``x_0 … x_N`` (N+1, n) from ``x0`` under ``u`` (N, m); no cache involved."""
        b, a = self._buf, self._addr
        b["x0"][:] = x0
        b["u"][:] = u
        self._c["simulate"](self._ws, a["x0"], a["u"], a["x"])
        return b["x"].copy()

    def xtraj(self, w: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The kernel's trajectory at ``(w, p)`` (its cached rollout when it matches)."""
        b, a = self._buf, self._addr
        b["w"][:] = np.ravel(w)
        b["p"][:] = np.ravel(p)
        self._c["xtraj"](self._ws, a["w"], a["p"], a["x"])
        return b["x"].copy()

    def steady_state(self, u_s: np.ndarray, x0: np.ndarray) -> np.ndarray | None:
        """The steady state ``x_s(u_s)`` by Newton from ``x0`` (a tracking FHOCP's kernel:
        :mod:`controllers.ocp.steady_state` in C); ``None`` when it did not converge."""
        b, a = self._buf, self._addr
        b["ue"][:] = u_s
        b["xe"][:] = x0
        rc = self.kernel.c["steady"](self._ws, a["ue"], a["xe"], a["xn"])
        return b["xn"].copy() if rc == 0 else None

    @property
    def has_equilibrium(self) -> bool:
        """The library has :meth:`equilibrium` (every kernel of this generator)."""
        return "equilibrium" in self.kernel.c

    def equilibrium(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """``(x, u, reached)``: the equilibrium whose output is closest to ``y`` over
        ``‖u‖∞ ≤ 1`` (:func:`controllers.equilibrium.equilibrium_for_output` in C: the same
        starting inputs and choice between them, a projected Gauss–Newton on the steady
        state's Newton in place of scipy's bounded least squares); ``reached``: ``y`` itself
        (to :data:`~controllers.equilibrium.REACH_TOL`)."""
        b, a = self._buf, self._addr
        b["yp"][:] = y
        rc = self.kernel.c["equilibrium"](self._ws, a["yp"], a["xe"], a["ue"])
        return b["xe"].copy(), b["ue"].copy(), rc == 0

    def output(self, x: np.ndarray) -> np.ndarray:
        """``U_o x + b_o`` (:func:`controllers.gru.output`, summed in a fixed order: the
        exported controller's)."""
        b, a = self._buf, self._addr
        b["xn"][:] = x
        self.kernel.c["output"](a["xn"], a["yp"])
        return b["yp"].copy()

    def gru_step(self, x: np.ndarray, u: np.ndarray, dz: np.ndarray, dr: np.ndarray
                 ) -> np.ndarray:
        """One step of ``eq:gru`` with extra gate inputs (``eq:observer``), as
        :func:`controllers.gru.step`; a new array."""
        b, a = self._buf, self._addr
        b["x0"][:] = x
        b["ub"][:] = u
        b["dz"][:] = dz
        b["dr"][:] = dr
        self.kernel.c["gru_step"](a["x0"], a["ub"], a["dz"], a["dr"], a["xn"])
        return b["xn"].copy()

    def assess(self, x0: np.ndarray, u: np.ndarray, x_bar: np.ndarray, u_bar: np.ndarray,
               bounds: np.ndarray, alpha: float, u_prev: np.ndarray | None = None
               ) -> tuple[np.ndarray, Assessment]:
        """The check of an input sequence in one call: states ``x_0 … x_N`` from ``x0`` under
        ``u`` (N, m) and their :class:`~controllers.kernel.kernel_abi.Assessment` (cost, worst
        output rows at ``i = 0`` and ``i ≥ 1``, ``max |u|``, ``‖x_N − x̄‖∞``, active
        constraints: as ``FHOCP.cost`` with ``t = ‖x_N − x̄‖∞`` and ``u_{−1} = u_prev``, and
        ``FHOCP._residuals``; ``bounds``: the tightened bounds, N×q). ``u_prev`` is read only
        by a kernel with an input-rate term (then ``None`` means zeros)."""
        b, a = self._buf, self._addr
        b["x0"][:] = x0
        b["u"][:] = u
        b["xb"][:] = x_bar
        b["ub"][:] = u_bar
        b["up"][:] = 0.0 if u_prev is None else u_prev
        b["bnd"][:bounds.shape[0], :self.nl] = bounds
        self._c["assess"](self._ws, a["x0"], a["u"], a["xb"], a["ub"], a["up"], a["bnd"],
                          float(alpha), a["x"], a["out"])
        return b["x"].copy(), Assessment.from_buffer_copy(self._out)

    def assess_w(self, w: np.ndarray, p: np.ndarray, bounds: np.ndarray, alpha: float
                 ) -> tuple[np.ndarray, np.ndarray, Assessment, np.ndarray]:
        """:meth:`assess` of the solver's answer ``w`` at ``p = (x̂, x̄, ū[, u_{−1}])``:
        ``(u, x, out, x_s)`` with ``u = clip(w_u, −1, 1)`` and ``out.defect`` the defect
        ``max |x_solver − x|`` against the solver's trajectory at ``(w, p)``. A tracking
        FHOCP's kernel (``p = (x̂, x_s0, r[, u_{−1}])``) checks against ``x_s(u_s)`` of the
        clipped ``u_s``, returned as ``x_s``: ``out.cost`` is :meth:`~controllers.laws.
        tracking.reference.ArtificialSteadyState.cost`, ``out.steady_residual`` the fixed-point
        residual ``‖f(x_s, u_s) − x_s‖∞`` (NaN when Newton failed); otherwise ``x_s`` is
        zeros and the residual 0. ``bounds``: N×q, or (N + 1)×q with ``Y_s``'s right-hand
        side last (a softened tracking FHOCP's kernel prices its excess)."""
        b, a = self._buf, self._addr
        b["w"][:] = w
        b["p"][:] = p
        b["bnd"][:bounds.shape[0], :self.nl] = bounds
        self._c["assess_w"](self._ws, a["w"], a["p"], a["bnd"], float(alpha), a["uc"], a["x"],
                            a["out"], a["xs"])
        return (b["uc"].copy(), b["x"].copy(), Assessment.from_buffer_copy(self._out),
                b["xs"].copy())

    def plan_slacks(self, w: np.ndarray, p: np.ndarray, bounds: np.ndarray, alpha: float
                    ) -> float:
        """The smallest slacks of the plan at ``(w, p)`` written into ``w`` in place (a
        softened FHOCP's kernel, :meth:`controllers.ocp.soft.Slacks.initial`; ``bounds`` as
        :meth:`assess_w`'s) and the terminal gap returned (:meth:`terminal_gap`)."""
        b, a = self._buf, self._addr
        b["w"][:] = w
        b["p"][:] = p
        b["bnd"][:bounds.shape[0], :self.nl] = bounds
        gap = float(self._c["plan_slacks"](self._ws, a["w"], a["p"], a["bnd"], float(alpha)))
        w[:] = b["w"]
        return gap

    def set_soft(self, on: bool) -> None:
        """This instance's softened-row weights: the design's (``on``) or 0, the hard phase
        (a softened FHOCP's kernel; :mod:`controllers.ocp.soft`)."""
        self._c["set_soft"](self._ws, int(on))

    def terminal_gap(self, w: np.ndarray, p: np.ndarray) -> float:
        """``‖x_N − x_ref‖∞`` of the rollout at ``(w, p)`` (``x_ref``: ``x̄``, or ``x_s(u_s)``
        for a tracking FHOCP): the smallest feasible terminal slack. The rollout stays cached
        for the next solve at the same inputs (the slack is not part of its key)."""
        b, a = self._buf, self._addr
        b["w"][:] = w
        b["p"][:] = p
        return float(self._c["terminal_gap"](self._ws, a["w"], a["p"]))

    def eq_newton(self, y: np.ndarray, x0: np.ndarray, u0: np.ndarray,
                  max_iter: int = NEWTON_MAX_ITER, tol: float = EQ_TOL
                  ) -> tuple[np.ndarray, np.ndarray] | None:
        """:func:`controllers.equilibrium.equilibrium_newton`, compiled (at least as many
        inputs as outputs; with more, its minimum-norm steps by the normal equations):
        ``(x, u)`` or ``None``."""
        b, a = self._buf, self._addr
        b["y"][:] = y
        b["x0"][:] = x0
        b["ub"][:] = u0
        rc = self.kernel.c["eq_newton"](a["y"], a["x0"], a["ub"], int(max_iter), float(tol),
                                        a["xe"], a["ue"])
        uo = b["ue"]
        if rc != 0 or max(abs(uo)) > 1.0:
            return None
        return b["xe"].copy(), uo.copy()

    def sqp_call(self, arrays: Mapping[str, np.ndarray], options: SqpOptions,
                 info: SqpInfo) -> Any:
        """A function running the kernel's SQP (``sqp.c``) in this workspace on these
        persistent arrays: ``p, lbx, ubx, lbg, ubg, w, lam_x, lam_g, g, f`` (float64,
        contiguous; ``w``, ``lam_x``, ``lam_g`` hold the initial guess and receive the answer),
        with ``options`` and into ``info``; it returns the :class:`SqpStatus`. Addresses are
        taken once: calling it costs ~1 µs besides the solve."""
        names = ("p", "lbx", "ubx", "lbg", "ubg", "w", "lam_x", "lam_g", "g", "f")
        for name in names:
            a = arrays[name]
            if a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError(f"sqp array {name!r} must be contiguous float64")
        # alive with the function: the arrays, the options, the info and this workspace (the
        # C memory at self._ws is freed with it)
        keep = ({name: arrays[name] for name in names}, options, info, self)
        addr = [self._ws, *(int(keep[0][name].ctypes.data) for name in names),
                ctypes.addressof(options), ctypes.addressof(info)]
        fn = self._c["sqp"]
        return lambda _keep=keep: SqpStatus(fn(*addr))

    def qp(self, H: np.ndarray, g: np.ndarray, A: np.ndarray, lbx: np.ndarray,
           ubx: np.ndarray, lba: np.ndarray, uba: np.ndarray
           ) -> tuple[QpStatus, np.ndarray, np.ndarray, np.ndarray, int]:
        """The kernel's QP (``qp.c``) on one problem of its dimensions (H: nw×nw, A:
        ng×nw; infinite bounds allowed): ``(status, d, lam_x, lam_a, working-set changes)``.
        A test hook: the SQP calls the QP inside the kernel."""
        def arr(a: np.ndarray, order: str = "C") -> np.ndarray:
            return np.clip(np.array(a, dtype=float, order=order), -1e301, 1e301)
        k = self.kernel
        args = [arr(H), arr(g), arr(A, "F"), arr(lbx), arr(ubx), arr(lba), arr(uba)]
        d, lx, la = np.zeros(k.nw), np.zeros(k.nw), np.zeros(k.ng)
        changes = ctypes.c_int(0)
        status = self._c["qp"](self._ws, *(a.ctypes.data for a in (*args, d, lx, la)),
                               ctypes.addressof(changes))
        return QpStatus(status), d, lx, la, int(changes.value)

    def grad_l(self, w: np.ndarray, p: np.ndarray, lam_x: np.ndarray, lam_g: np.ndarray
               ) -> np.ndarray:
        """∇L = ∇f + Jᵀλ_g + λ_x at ``(w, p)`` by the SQP's adjoint sweep (a test hook)."""
        arrs = [np.ascontiguousarray(a, dtype=float) for a in (w, p, lam_x, lam_g)]
        out = np.zeros(self.kernel.nw)
        self._c["grad_l"](self._ws, *(a.ctypes.data for a in (*arrs, out)))
        return out

    def clip(self, H: np.ndarray) -> np.ndarray:
        """The eigenvalue-clipped copy of a symmetric nw×nw matrix (a test hook)."""
        Hc = np.array(H, dtype=float, order="C")
        if self._c["clip"](self._ws, Hc.ctypes.data) != 0:
            raise ArithmeticError("eigenvalue decomposition did not converge")
        return Hc

    def counters(self) -> dict[str, int]:
        """This workspace's eigenvalue-clipping counts."""
        c = Counters()
        self._c["counters"](self._ws, ctypes.byref(c))
        return {name: int(getattr(c, name)) for name, _ in Counters._fields_}

    def invalidate(self) -> None:
        """Forget the cached rollout."""
        self._c["invalidate"](self._ws)

    def set_weights(self, R: np.ndarray, du: np.ndarray | None, T: np.ndarray | None) -> None:
        """The instance's cost weights ``R`` (m, m), the input-rate weights ``du`` (m) and the
        offset weights ``T`` (p), where the variant has them."""
        rw = np.ascontiguousarray(R, dtype=float)
        dw = np.ascontiguousarray(du if du is not None else np.zeros(self.m), dtype=float)
        tw = np.ascontiguousarray(T if T is not None else np.zeros(max(self.kernel.p, 1)),
                                  dtype=float)
        self._c["set_weights"](self._ws, rw.ctypes.data, dw.ctypes.data, tw.ctypes.data)
