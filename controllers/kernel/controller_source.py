"""The whole controller step in C (``controllers/kernel/controller.c``): its constants, source,
build and a ctypes handle.

An exported controller (the controller FMU, :mod:`cosim.core.controller_fmu`) runs the step of
the robust MPC without Python: the GRU observer (``eq:observer``, ``eq:eo-evolution``) and
its law on the compiled kernel, with its answer check and candidate fallback, in the
problem's units. Each law brings its C files (``controllers/laws/<name>/*.c``: the tracking
law's output-disturbance estimate and tracking FHOCP; the paper's law's reference
``(x̄, ū, α)`` of each set-point checked against the certificate, its governor, the FHOCP and
the fallback of ``eq:mpc``) and its numbers, parameters and switches (its ``export``
module, :mod:`controllers.laws`). :class:`ControllerDesign` is what the C step needs besides
the kernel (:class:`~controllers.kernel.compiled_kernel.KernelProblem`): scalings, input
box, observer gains and bound, tightening, the SQP's options, the warm start's permutations
and the law's own numbers, taken from the Python objects that run the same step
(:meth:`ControllerDesign.of`), so that both give the same inputs. :func:`generate_source`
joins the kernel's source, these constants, ``controller.h``, the law's files and
``controller.c``; :func:`build` compiles it (a self-contained library: no BLAS) and
:class:`CompiledController` steps it from Python (the tests and the benchmark).
"""

from __future__ import annotations

import ctypes
import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controllers.kernel.cbuild import (
    compile_library,
    compiler_id,
    default_cache_dir,
    write_atomic,
)
from controllers.kernel.compiled_kernel import (
    GENERATOR_VERSION,
    PREFIX_PLACEHOLDER,
    KernelProblem,
    kernel_constants,
    loader_source,
    variant_flags,
)
from controllers.kernel.compiled_kernel import (
    generate_source as kernel_source,
)
from controllers.kernel.constants import Constants
from controllers.kernel.kernel_lib import load_data

__all__ = [
    "CONTROLLER_C",
    "CompiledController",
    "ControllerDesign",
    "build",
    "controller_constants",
    "design_data",
    "generate_source",
    "operator_names",
    "parameters",
]

#: The C step (joined after the kernel, the constants, ``controller.h``, the law's files and
#: ``operator.c``).
CONTROLLER_C = Path(__file__).with_name("controller.c")
#: The operator's settings of the C step (:mod:`controllers.operator`'s twin).
OPERATOR_C = Path(__file__).with_name("operator.c")
#: What the step and the laws share, and each law's files, joined in this order
#: (``controller.h`` says what a law defines; the paper's reference governor is its own file).
CONTROLLER_H = Path(__file__).with_name("controller.h")
#: Compiler flags of the exported step: the kernel's, warnings as errors.
CFLAGS = ("-O3", "-fPIC", "-std=gnu99", "-pthread", "-Wall", "-Wextra", "-Werror",
          "-Wno-aggressive-loop-optimizations")


@dataclass(frozen=True)
class ControllerDesign:
    """What the C step needs besides its kernel: arrays in normalised units unless said.

    Attributes
    ----------
    kernel : KernelProblem
        The tracking FHOCP's kernel problem.
    y_offset, y_scale, u_offset, u_scale : arrays
        The model's normalisation (``(raw − offset) / scale``).
    u_lo, u_hi : arrays
        The input box in the problem's units.
    L_z, L_r : (n, p) arrays
        Observer gains (``eq:observer``).
    rho_o, w_bar, e_o0 : float
        ``ê_o,k+1 = ρ_o ê_o,k + w̄`` (``eq:eo-evolution``) from ``ê_o,0``.
    beta : float
        The disturbance filter's gain.
    certified : bool
        False: the output rows are tightened around ``y + d̂`` (the uncertified mode).
    L, h, a, b, w_L, Lbo : arrays
        The output polytope and its tightening (``eq:optimization-constraint``).
    pair_up, pair_lo : int arrays
        The reduced rows' upper and lower ``L`` rows (−1: none).
    perm_x, perm_g : int arrays
        The warm start's shift of the multipliers.
    sqp : dict
        The kernel SQP's options (:class:`controllers.kernel.kernel_abi.SqpOptions` fields).
    feas_tol, defect_tol : float
        The answer check's tolerances.
    law : str
        The law's name (its C files: :attr:`controllers.laws.LawSpec.c_sources`).
    law_data : mapping
        The law's own ``CT_*`` numbers (its ``export_design`` says which); integers are C
        ``int`` constants.
    offset_free : bool
        The paper's law's ``offset_free`` (compiled: it decides the parameters).
    d_offset, d_scale : arrays
        The measured disturbances' normalisation (empty without them).
    W_d : (3n, q) array
        Their columns of ``W_z``, ``W_r``, ``W_h``, stacked: the biases' shift ``W_d d``
        (:class:`controllers.disturbances.BiasShift`).
    lags : int array
        Each disturbance's dead time [samples].
    dead_time : int
        The inputs' shortest dead time ``K`` [samples] (:func:`controllers.dead_time.
        input_delay`).
    delays : int array
        Each input's dead time ``K_j`` [samples] (empty: none).
    y_lo, y_hi : arrays
        The output box in the problem's units (the operator's limits lie inside it).
    max_move : array
        Each input's move limit (the problem's units; the box width where none is
        declared); ``moves``: whether one is declared (:mod:`controllers.operator`).
    limit_rate : array
        How fast each output's operator limit narrows (``inf``: as the plan allows).
    output_limits : bool
        The law takes operator limits on its outputs (:attr:`controllers.laws.base.
        ControlLaw.output_limits`).
    """

    kernel: KernelProblem
    y_offset: np.ndarray
    y_scale: np.ndarray
    u_offset: np.ndarray
    u_scale: np.ndarray
    u_lo: np.ndarray
    u_hi: np.ndarray
    L_z: np.ndarray
    L_r: np.ndarray
    rho_o: float
    w_bar: float
    e_o0: float
    beta: float
    certified: bool
    L: np.ndarray
    h: np.ndarray
    a: np.ndarray
    b: np.ndarray
    w_L: np.ndarray
    Lbo: np.ndarray
    pair_up: np.ndarray
    pair_lo: np.ndarray
    perm_x: np.ndarray
    perm_g: np.ndarray
    sqp: dict[str, float]
    feas_tol: float
    defect_tol: float
    law: str
    law_data: Mapping[str, Any]
    offset_free: bool = False
    d_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    d_scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    W_d: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    lags: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    dead_time: int = 0
    delays: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    y_lo: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y_hi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    max_move: np.ndarray = field(default_factory=lambda: np.zeros(0))
    moves: bool = False
    limit_rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    output_limits: bool = False

    @property
    def q(self) -> int:
        """The number of measured disturbances."""
        return int(np.size(self.d_offset))
    @classmethod
    def of(cls, law: Any, observer: Any, model: Any, u_lo: np.ndarray,
           u_hi: np.ndarray) -> ControllerDesign:
        """The design of the law ``law`` (its FHOCP set up on its compiled kernel's SQP), its
        observer (:class:`controllers.observer.GRUObserver`), the model's normalisation and
        the input box: its law's ``export_design`` (:mod:`controllers.laws`), which gives
        the law's own numbers."""
        from controllers import laws

        return laws.spec(law.name).hook("export", "export_design")(law, observer, model,
                                                                   u_lo, u_hi)

    @classmethod
    def common(cls, fhocp: Any, observer: Any, beta: float, certified: bool, model: Any,
               u_lo: np.ndarray, u_hi: np.ndarray, layout: Any, law: str,
               law_data: dict[str, Any], offset_free: bool = False,
               output_limits: bool = False) -> ControllerDesign:
        """What every law's design holds (a law's ``export_design`` gives it its own numbers
        ``law_data``); ``layout``: where the warm start's permutations are (``perm_x``,
        ``perm_g``); ``output_limits``: the law takes operator limits on its outputs."""
        from controllers.kernel.kernel_sqp import KernelSQP
        from controllers.ocp.solver_settings import DEFECT_TOL, FEAS_TOL

        if not isinstance(fhocp._solver, KernelSQP):
            raise ValueError("the exported controller runs the compiled kernel's SQP: the "
                             "FHOCP must solve with loop=\"kernel\" on a compiled kernel")
        o = fhocp._solver.options
        sqp = {name: getattr(o, name) for name, _ in o._fields_}
        arr = np.asarray
        extra = _measured(model)
        return cls(
            kernel=KernelProblem.of(fhocp), y_offset=arr(model.y_offset, float),
            y_scale=arr(model.y_scale, float), u_offset=arr(model.u_offset, float),
            u_scale=arr(model.u_scale, float), u_lo=arr(u_lo, float), u_hi=arr(u_hi, float),
            L_z=arr(observer.L_z, float), L_r=arr(observer.L_r, float),
            rho_o=float(observer.rho_o), w_bar=float(observer.w_bar),
            e_o0=float(observer.e_o0), beta=float(beta), certified=bool(certified),
            L=fhocp.L, h=fhocp.h, a=fhocp.a, b=fhocp.b, w_L=fhocp.w_L, Lbo=fhocp.Lbo,
            pair_up=fhocp.pair_up, pair_lo=fhocp.pair_lo, perm_x=layout.perm_x,
            perm_g=layout.perm_g, sqp=sqp, feas_tol=FEAS_TOL, defect_tol=DEFECT_TOL,
            law=law, law_data=law_data, offset_free=offset_free, **extra,
            **_operating(model.problem, output_limits))


def _operating(problem: Any, output_limits: bool) -> dict[str, Any]:
    """The operator's numbers of the design (:class:`controllers.operator.Operator`'s)."""
    from controllers.operator import Operator

    op = Operator(problem)
    return {"y_lo": op.y_box[:, 0].copy(), "y_hi": op.y_box[:, 1].copy(),
            "max_move": op.max_move.copy(), "moves": bool(op.moves),
            "limit_rate": op.limit_rate.copy(), "output_limits": bool(output_limits)}


def operator_names(design: ControllerDesign, inputs: Sequence[str],
                   outputs: Sequence[str]) -> list[str]:
    """The C step's operator settings, in ``operator.c``'s order (the controller FMU's inputs
    of these names): ``op.mode``, ``op.service.<input>``, ``op.manual.<input>``, then
    ``op.min.<signal>`` and ``op.max.<signal>`` of the inputs and (a law that takes them) the
    outputs."""
    signals = [*inputs, *(outputs if design.output_limits else [])]
    return ["op.mode", *(f"op.service.{u}" for u in inputs),
            *(f"op.manual.{u}" for u in inputs), *(f"op.min.{s}" for s in signals),
            *(f"op.max.{s}" for s in signals)]


def _measured(model: Any) -> dict[str, Any]:
    """The design's measured disturbances and dead time, from the model the controller runs
    (one holding them in its biases: ``held_from``, :func:`controllers.disturbances.
    condition`)."""
    from controllers.dead_time import input_delay

    problem = getattr(model, "problem", None)
    out: dict[str, Any] = {"dead_time": input_delay(problem), "delays": np.array(
        [c.delay for c in problem.inputs] if problem is not None else [], dtype=int)}
    full = getattr(model, "held_from", None)
    if full is None:
        return out
    q = full.q
    m_u = full.m - q
    out.update(d_offset=np.asarray(full.u_offset, float)[m_u:],
               d_scale=np.asarray(full.u_scale, float)[m_u:],
               W_d=np.vstack([np.asarray(full.params[w], float)[:, m_u:]
                              for w in ("W_z", "W_r", "W_h")]),
               lags=np.array([c.delay for c in full.problem.disturbances], dtype=int))
    return out


def controller_constants(d: ControllerDesign) -> Constants:
    """The ``CT_*`` constants of ``controller.c``: the design's numbers."""
    s = d.sqp
    c = Constants()
    for name, value in (("CT_Y_OFFSET", d.y_offset), ("CT_Y_SCALE", d.y_scale),
                        ("CT_U_OFFSET", d.u_offset), ("CT_U_SCALE", d.u_scale),
                        ("CT_U_LO", d.u_lo), ("CT_U_HI", d.u_hi), ("CT_Y_LO", d.y_lo),
                        ("CT_Y_HI", d.y_hi), ("CT_MAX_MOVE", d.max_move),
                        ("CT_LIMIT_RATE", d.limit_rate), ("CT_LZ", d.L_z),
                        ("CT_LR", d.L_r), ("CT_L", d.L), ("CT_H", d.h), ("CT_A", d.a),
                        ("CT_B", d.b), ("CT_WL", d.w_L), ("CT_LBO", d.Lbo)):
        c.array(name, value, finite=False)   # an unbounded row: +-inf (uncertified mode)
    for name, value in (("CT_PAIR_UP", d.pair_up), ("CT_PAIR_LO", d.pair_lo),
                        ("CT_PERM_X", d.perm_x), ("CT_PERM_G", d.perm_g)):
        c.array(name, value, "int")
    for name, value in (("CT_RHO_O", d.rho_o), ("CT_W_BAR", d.w_bar), ("CT_E_O0", d.e_o0),
                        ("CT_BETA", d.beta), ("CT_FEAS_TOL", d.feas_tol),
                        ("CT_DEFECT_TOL", d.defect_tol),
                        ("CT_SQP_TOL_PR", s["tol_pr"]), ("CT_SQP_TOL_DU", s["tol_du"]),
                        ("CT_SQP_MIN_STEP", s["min_step_size"]), ("CT_SQP_C1", s["c1"]),
                        ("CT_SQP_BETA", s["beta"]), ("CT_SQP_REUSE_STEP", s["reuse_step"])):
        c.scalar(name, float(value))
    if d.kernel.move:   # the move rows' bounds (eq:move-constraint, normalised)
        c.array("CT_MOVE_DELTA", d.max_move / np.abs(d.u_scale[:d.max_move.size]))
    for name, value in (("CT_CERTIFIED", int(d.certified)), ("CT_MOVES", int(d.moves)),
                        ("CT_SQP_MAX_ITER", s["max_iter"]),
                        ("CT_SQP_MAX_ITER_LS", s["max_iter_ls"]),
                        ("CT_SQP_TOL_DU_RELATIVE", s["tol_du_relative"])):
        c.scalar(name, int(value), "int")
    if d.q:   # declared only with disturbances (controller.c: #if CT_NQD)
        for name, value in (("CT_D_OFFSET", d.d_offset), ("CT_D_SCALE", d.d_scale),
                            ("CT_WD", d.W_d)):
            c.array(name, value)
        c.array("CT_LAGS", d.lags, "int")
    if _u_depth(d):   # declared only with dead time (controller.c: #if CT_U_DEPTH)
        c.array("CT_U_DELAYS", d.delays, "int")
    if _u_lag_max(d):   # only with dead times that differ (#if CT_U_LAG_MAX)
        c.array("CT_U_LAGS", d.delays - d.dead_time, "int")
    for name, value in d.law_data.items():
        if isinstance(value, np.ndarray):
            c.array(name, value, finite=False)
        elif isinstance(value, int):
            c.scalar(name, value, "int")
        else:
            c.scalar(name, float(value))
    return c


def design_constants(design: ControllerDesign) -> Constants:
    """Every number of the controller step: its kernel's, then ``controller.c``'s."""
    return kernel_constants(design.kernel) + controller_constants(design)


def parameters(design: ControllerDesign, inputs: Sequence[str], outputs: Sequence[str]
               ) -> tuple[tuple[str, float, float, str, float], ...]:
    """The tunable parameters of the C step, in its order (the law file's ``LAW_P_*``), for
    a problem with these input and output names: ``(name, low, high, description, start)``,
    ``start`` the design's value; each is the option of its name (``R.<input>``: its
    diagonal entry) and a setting of :meth:`controllers.mpc.RobustMPC.set`. The law's
    ``parameters`` say which (:mod:`controllers.laws`). Normalised units, as the options
    (a set-point rate: each output's units per sample)."""
    spec = _spec(design)
    out = tuple(spec.hook("export", "parameters")(design, list(inputs), list(outputs)))
    if len(out) != _parameter_count(design):
        raise ValueError("one name per input and output is needed")
    return out


def _spec(design: ControllerDesign) -> Any:
    from controllers import laws

    return laws.spec(design.law)


def _parameter_count(design: ControllerDesign) -> int:
    """``LAW_N_PARAMETERS`` of the law's file for ``design``."""
    return int(_spec(design).hook("export", "parameter_count")(design))


def _u_depth(d: ControllerDesign) -> int:
    """How many past inputs the step keeps: the longest dead time."""
    return int(np.max(d.delays, initial=0))


def _u_lag_max(d: ControllerDesign) -> int:
    """The longest dead time beyond the shortest: the FHOCP stages fixed at most."""
    return _u_depth(d) - int(d.dead_time)


def generate_source(design: ControllerDesign) -> str:
    """The C source of the controller step (symbol prefix left as ``@PFX@``): the kernel,
    ``controller.h``, the law's files, ``controller.c`` and the loader of its numbers
    (``loader.c``), which are declared, not defined: the source is the same for every design
    of the same dimensions and law (and, for the paper's, ``offset_free`` and whether it has
    a set-point rate), and
    :func:`design_data` is what a design adds (``PFX(load_data)``)."""
    problem, spec = design.kernel, _spec(design)
    law_switches = spec.hook("export", "c_switches")(design)
    kernel, own = kernel_constants(problem), controller_constants(design)
    switches = (f"#define CT_NPARAM {_parameter_count(design)}\n"
                f"#define CT_NQD {design.q}\n#define CT_DEAD {int(design.dead_time)}\n"
                f"#define CT_U_DEPTH {_u_depth(design)}\n"
                f"#define CT_U_LAG_MAX {_u_lag_max(design)}\n"
                f"#define CT_LAG_MAX {int(np.max(design.lags, initial=0))}\n"
                f"#define CT_OUT_LIMITS {int(design.output_limits)}\n" + law_switches)
    return "\n".join([kernel_source(problem, kernel),
                      "/* the controller's constants (controller_source.py) */\n"
                      + switches + own.declarations(),
                      CONTROLLER_H.read_text(), *(f.read_text() for f in spec.c_sources),
                      OPERATOR_C.read_text(), CONTROLLER_C.read_text(),
                      loader_source(kernel + own)])


def design_data(design: ControllerDesign) -> bytes:
    """The data file of ``design``'s numbers (:mod:`controllers.kernel.constants`), which the
    library of :func:`generate_source` loads."""
    return design_constants(design).data()


def build(design: ControllerDesign, prefix: str = "ctl_", cache_dir: Path | None = None,
          cc: str = "gcc") -> tuple[Path, str]:
    """Compile the controller step into a shared library (cached by its source: compiled once
    for every design of the same dimensions) and give ``design`` its own copy (a loaded
    library holds one design's numbers); ``(path, symbol prefix)``. Raises ``RuntimeError``
    with the compiler's first error."""
    flags, _ = variant_flags(design.kernel, (*CFLAGS, "-shared"), blas=False)
    src = generate_source(design).replace(PREFIX_PLACEHOLDER, prefix)
    key = hashlib.sha256("\0".join([GENERATOR_VERSION, compiler_id(cc), " ".join(flags),
                                    src]).encode()).hexdigest()[:16]
    cdir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    shared = cdir / f"ctl{key}.so"
    if not shared.exists():
        reason = compile_library(src, cdir, f"ctl{key}", cc, flags)
        if reason is not None:
            raise RuntimeError(reason)
    so = cdir / f"ctl{key}-{hashlib.sha256(design_data(design)).hexdigest()[:12]}.so"
    if not so.exists():
        write_atomic(so, shared.read_bytes())
    return so, prefix


class CompiledController:
    """One instance of a compiled controller step (:func:`build`) with its design's numbers
    (:func:`design_data`), stepped from Python. A loaded library holds one design's numbers
    (other numbers are refused: ``ValueError``); :func:`build` gives each design its own
    copy."""

    def __init__(self, path: Path, prefix: str, data: bytes, n_inputs: int,
                 n_outputs: int, n_disturbances: int = 0) -> None:
        self.lib = ctypes.CDLL(str(path))
        f = {name: getattr(self.lib, prefix + name) for name in (
            "ctl_new", "ctl_free", "ctl_reset", "ctl_step", "ctl_outputs",
            "ctl_take_warnings")}
        vp = ctypes.c_void_p
        f["ctl_new"].restype = vp
        for name in ("ctl_free", "ctl_reset", "ctl_take_warnings"):
            f[name].argtypes = [vp]
        f["ctl_step"].argtypes = [vp, vp, vp, vp]
        f["ctl_outputs"].argtypes = [vp] * 7
        for name in ("ctl_set_parameter", "ctl_set_operator"):
            f[name] = getattr(self.lib, prefix + name)
            f[name].argtypes = [vp, ctypes.c_int, ctypes.c_double]
            f[name].restype = ctypes.c_char_p
        f["ctl_computed"] = getattr(self.lib, prefix + "ctl_computed")
        f["ctl_computed"].argtypes = [vp, vp]
        self._f = f
        self._st = None
        load_data(self.lib, prefix, data, path)
        self._st = f["ctl_new"]()
        if not self._st:
            raise MemoryError("cannot allocate a controller instance")
        self.m, self.p = n_inputs, n_outputs
        self._y, self._r = np.zeros(n_outputs), np.zeros(n_outputs)
        self._u, self._yp = np.zeros(n_inputs), np.zeros(n_outputs)
        self._yt = np.zeros(n_outputs)
        self._d = np.zeros(max(n_disturbances, 1))
        self._ints = (ctypes.c_int * 3)()

    def step(self, y: np.ndarray, ref: np.ndarray, d: np.ndarray | None = None
             ) -> dict[str, Any]:
        """One step at the measured outputs, set-points and disturbances (the problem's
        units): the inputs ``u``, ``status``, ``fallback``, ``iterations``, ``y_pred``,
        ``y_target`` and ``warnings``."""
        self._y[:], self._r[:] = y, ref
        if d is not None:
            self._d[:len(d)] = d
        self._f["ctl_step"](self._st, self._y.ctypes.data, self._r.ctypes.data,
                            self._d.ctypes.data)
        i = self._ints
        base = ctypes.addressof(i)
        size = ctypes.sizeof(ctypes.c_int)
        self._f["ctl_outputs"](self._st, self._u.ctypes.data, base, base + size,
                               base + 2 * size, self._yp.ctypes.data, self._yt.ctypes.data)
        computed = np.zeros(self.m)
        self._f["ctl_computed"](self._st, computed.ctypes.data)
        return {"u": self._u.copy(), "status": int(i[0]), "fallback": int(i[1]),
                "iterations": int(i[2]), "y_pred": self._yp.copy(),
                "y_target": self._yt.copy(), "computed": computed,
                "warnings": int(self._f["ctl_take_warnings"](self._st))}

    def set_operator(self, i: int, value: float) -> str | None:
        """Operator setting ``i`` (:func:`operator_names`' order) from the next step on;
        ``None``, or why the value is refused (nothing changes then)."""
        why = self._f["ctl_set_operator"](self._st, int(i), float(value))
        return None if why is None else why.decode()

    def set_parameter(self, i: int, value: float) -> str | None:
        """Tunable parameter ``i`` (:func:`parameters`' order) from the next step on;
        ``None``, or why the value is refused (nothing changes then)."""
        why = self._f["ctl_set_parameter"](self._st, int(i), float(value))
        return None if why is None else why.decode()

    def reset(self) -> None:
        self._f["ctl_reset"](self._st)

    def close(self) -> None:
        if getattr(self, "_st", None):
            self._f["ctl_free"](self._st)
            self._st = None

    def __del__(self) -> None:
        self.close()
